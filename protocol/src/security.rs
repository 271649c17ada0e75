//! Who may say what on a site's Zenoh network: mutual-TLS identities and access control.
//!
//! Every fleet process proves who it is with a certificate from the site's own CA (mutual TLS:
//! a session without one cannot even connect), and every session enforces the same
//! access-control rules on what arrives from the others, keyed by the certificate's common name:
//!
//! | identity (common name) | may publish | may read |
//! |---|---|---|
//! | `planner` | intentions, task events, map replies, cycle replies | poses, status, cameras, liveliness, maps, cycle outcomes |
//! | `worker` (every `planner-service worker`) | intentions, cycle queries and outcomes, its liveliness | poses, workers' liveliness, maps |
//! | `map-store` | map replies | – |
//! | `sim` (the robots' drivers) | scans, odometry, cameras of every robot | velocity commands |
//! | `agent.<robot_id>` | that robot's pose, status, velocity command, liveliness | that robot's sensors and intention, maps |
//! | `observer` (recorders, debugging) | – | everything of the site |
//! | `router` (a `zenohd` between hosts) | what it forwards | what it forwards |
//!
//! A router enforces the same rules on the sessions that connect to it (its configuration,
//! `router.json5`, embeds them), so the sessions behind it trust what it forwards.
//!
//! So an agent cannot fake another robot's pose, nothing but the planner can steer a robot's
//! intention, and nothing but the robot's own agent can drive its base. Rules are checked on
//! ingress (what a remote session publishes, subscribes to, queries or answers) with
//! `default_permission: deny`; egress is open, because a peer only receives what its own
//! subscriptions (already checked on ingress) asked for.
//!
//! [`access_control`] writes Zenoh's `access_control` block for a site, [`issue`] makes the CA,
//! the certificates and that block in a folder (`planner-service certs`), and
//! [`crate::SessionArgs`] loads them (`--zenoh-tls-*`, `--zenoh-acl`).

use std::collections::BTreeSet;
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::time::{SystemTime, UNIX_EPOCH};

use rcgen::{
    BasicConstraints, CertificateParams, DnType, ExtendedKeyUsagePurpose, IsCa, Issuer, KeyPair,
    KeyUsagePurpose,
};
use serde_json::{json, Value};
use zenoh::key_expr::OwnedKeyExpr;

use crate::ids::{RobotId, SiteId};
use crate::keys::{self, RobotTopic};

/// A fleet process's identity: the common name of its certificate.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord)]
pub enum Identity {
    /// The planner service (task book, replanning, the embedded map store, the HTTP API).
    Planner,
    /// A stand-alone map store.
    MapStore,
    /// The simulator: the drivers of every simulated robot base.
    Sim,
    /// A read-only session: recorders, debugging tools.
    Observer,
    /// A Zenoh router between hosts; it checks the rules on its own ingress.
    Router,
    /// A replanning worker (`planner-service worker`); the site's workers share it.
    Worker,
    /// The agent of one robot.
    Agent(RobotId),
}

/// The prefix of an agent's common name: `agent.<robot_id>`.
const AGENT_PREFIX: &str = "agent.";

impl Identity {
    /// The identities every site has, besides one agent per robot.
    pub const SERVICES: [Identity; 6] = [
        Identity::Planner,
        Identity::MapStore,
        Identity::Sim,
        Identity::Observer,
        Identity::Router,
        Identity::Worker,
    ];

    /// The certificate's common name, which the access-control rules match.
    #[must_use]
    pub fn common_name(&self) -> String {
        match self {
            Identity::Planner => "planner".into(),
            Identity::MapStore => "map-store".into(),
            Identity::Sim => "sim".into(),
            Identity::Observer => "observer".into(),
            Identity::Router => "router".into(),
            Identity::Worker => "worker".into(),
            Identity::Agent(robot) => format!("{AGENT_PREFIX}{robot}"),
        }
    }

    /// The identity a common name stands for.
    #[must_use]
    pub fn from_common_name(name: &str) -> Option<Identity> {
        if let Some(robot) = name.strip_prefix(AGENT_PREFIX) {
            return RobotId::new(robot).ok().map(Identity::Agent);
        }
        Self::SERVICES
            .into_iter()
            .find(|identity| identity.common_name() == name)
    }

    /// What this identity may do, as (Zenoh ACL message kinds, keys) pairs checked on ingress.
    fn grants(&self, site: &SiteId) -> Vec<(&'static [&'static str], Vec<OwnedKeyExpr>)> {
        const PUBLISH: &[&str] = &["put"];
        const SUBSCRIBE: &[&str] = &["declare_subscriber"];
        const WATCH_LIVELINESS: &[&str] = &["declare_liveliness_subscriber", "liveliness_query"];
        const SERVE: &[&str] = &["declare_queryable", "reply"];
        const QUERY: &[&str] = &["query"];
        const TOKEN: &[&str] = &["liveliness_token"];
        let every = |topic| keys::all_robots(site, topic);
        let maps = || vec![keys::map_queryable(site)];
        match self {
            Identity::Planner => vec![
                (
                    PUBLISH,
                    vec![every(RobotTopic::Intention), keys::all_tasks(site)],
                ),
                (
                    SUBSCRIBE,
                    vec![
                        every(RobotTopic::Pose),
                        every(RobotTopic::Status),
                        every(RobotTopic::Camera),
                        keys::all_cycle_outcomes(site),
                    ],
                ),
                (
                    WATCH_LIVELINESS,
                    vec![keys::alive_all(site), keys::workers_alive(site)],
                ),
                (
                    SERVE,
                    vec![keys::map_queryable(site), keys::cycle_queryable(site)],
                ),
                (QUERY, maps()),
            ],
            Identity::Worker => vec![
                (
                    PUBLISH,
                    vec![every(RobotTopic::Intention), keys::all_cycle_outcomes(site)],
                ),
                (SUBSCRIBE, vec![every(RobotTopic::Pose)]),
                (WATCH_LIVELINESS, vec![keys::workers_alive(site)]),
                (TOKEN, vec![keys::workers_alive(site)]),
                (
                    QUERY,
                    vec![keys::map_queryable(site), keys::cycle_queryable(site)],
                ),
            ],
            Identity::MapStore => vec![(SERVE, maps())],
            Identity::Sim => vec![
                (
                    PUBLISH,
                    vec![
                        every(RobotTopic::Scan),
                        every(RobotTopic::Odom),
                        every(RobotTopic::Camera),
                    ],
                ),
                (SUBSCRIBE, vec![every(RobotTopic::CmdVel)]),
            ],
            Identity::Observer => vec![
                (SUBSCRIBE, vec![keys::site_all(site)]),
                (WATCH_LIVELINESS, vec![keys::site_all(site)]),
                (QUERY, maps()),
            ],
            Identity::Router => vec![(&ALL_MESSAGES, vec![keys::site_all(site)])],
            Identity::Agent(robot) => {
                let own = |topic| keys::robot(site, robot, topic);
                vec![
                    (
                        PUBLISH,
                        vec![
                            own(RobotTopic::Pose),
                            own(RobotTopic::Status),
                            own(RobotTopic::CmdVel),
                        ],
                    ),
                    (TOKEN, vec![own(RobotTopic::Alive)]),
                    (
                        SUBSCRIBE,
                        vec![
                            own(RobotTopic::Odom),
                            own(RobotTopic::Scan),
                            own(RobotTopic::Camera),
                            own(RobotTopic::Intention),
                        ],
                    ),
                    (QUERY, maps()),
                ]
            }
        }
    }
}

impl std::fmt::Display for Identity {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.common_name())
    }
}

/// Every ACL message kind, for the open egress rule.
const ALL_MESSAGES: [&str; 9] = [
    "put",
    "delete",
    "declare_subscriber",
    "query",
    "declare_queryable",
    "reply",
    "liveliness_token",
    "declare_liveliness_subscriber",
    "liveliness_query",
];

/// Zenoh's `access_control` block for a site with these robots: deny by default, each identity
/// allowed on ingress exactly what the module table says, egress open.
#[must_use]
pub fn access_control(site: &SiteId, robots: &[RobotId]) -> Value {
    let mut identities: Vec<Identity> = Identity::SERVICES.to_vec();
    let robots: BTreeSet<&RobotId> = robots.iter().collect();
    identities.extend(robots.into_iter().cloned().map(Identity::Agent));

    let mut rules = vec![json!({
        "id": "egress",
        "permission": "allow",
        "flows": ["egress"],
        "messages": ALL_MESSAGES,
        "key_exprs": ["**"],
    })];
    let mut subjects = vec![json!({ "id": "anyone" })];
    let mut policies = vec![json!({ "rules": ["egress"], "subjects": ["anyone"] })];
    for identity in &identities {
        let name = identity.common_name();
        let mut rule_ids = Vec::new();
        for (i, (messages, key_exprs)) in identity.grants(site).into_iter().enumerate() {
            let id = format!("{name}/{i}");
            let key_exprs: Vec<&str> = key_exprs.iter().map(|k| k.as_str()).collect();
            rules.push(json!({
                "id": id,
                "permission": "allow",
                "flows": ["ingress"],
                "messages": messages,
                "key_exprs": key_exprs,
            }));
            rule_ids.push(id);
        }
        subjects.push(json!({ "id": name, "cert_common_names": [name] }));
        policies.push(json!({ "rules": rule_ids, "subjects": [name] }));
    }
    json!({
        "enabled": true,
        "default_permission": "deny",
        "rules": rules,
        "subjects": subjects,
        "policies": policies,
    })
}

/// Why a site's certificates could not be issued.
#[derive(Debug, thiserror::Error)]
pub enum SecurityError {
    #[error("cannot {action} {}: {source}", path.display())]
    Io {
        action: &'static str,
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("cannot {action}: {reason}")]
    Certificate { action: String, reason: String },
    #[error("{} holds {what} but not {missing}: restore it or start a new folder", dir.display())]
    Incomplete {
        dir: PathBuf,
        what: &'static str,
        missing: &'static str,
    },
    #[error("invalid host name {host:?} for a certificate: {reason}")]
    Host { host: String, reason: String },
}

/// Where a site's security files lie in the folder `planner-service certs` writes.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SiteFiles {
    pub dir: PathBuf,
}

impl SiteFiles {
    #[must_use]
    pub fn new(dir: impl Into<PathBuf>) -> Self {
        Self { dir: dir.into() }
    }
    /// The CA certificate every session trusts.
    #[must_use]
    pub fn ca_cert(&self) -> PathBuf {
        self.dir.join("ca.pem")
    }
    /// The CA's private key: needed only to issue more certificates; keep it off the robots.
    #[must_use]
    pub fn ca_key(&self) -> PathBuf {
        self.dir.join("ca.key")
    }
    /// An identity's certificate.
    #[must_use]
    pub fn cert(&self, identity: &Identity) -> PathBuf {
        self.dir.join(format!("{}.pem", identity.common_name()))
    }
    /// An identity's private key.
    #[must_use]
    pub fn key(&self, identity: &Identity) -> PathBuf {
        self.dir.join(format!("{}.key", identity.common_name()))
    }
    /// The access-control rules every session loads.
    #[must_use]
    pub fn acl(&self) -> PathBuf {
        self.dir.join("acl.json5")
    }
    /// A `zenohd` configuration: router mode, mutual TLS with the router's certificate, the
    /// rules embedded.
    #[must_use]
    pub fn router_config(&self) -> PathBuf {
        self.dir.join("router.json5")
    }

    /// Sets a session's TLS files and rules to those of `identity` in this folder.
    pub fn secure(&self, session: &mut crate::SessionArgs, identity: &Identity) {
        session.tls_ca = Some(self.ca_cert());
        session.tls_cert = Some(self.cert(identity));
        session.tls_key = Some(self.key(identity));
        session.acl = Some(self.acl());
    }

    /// The robots that have an agent certificate here.
    ///
    /// # Errors
    /// [`SecurityError::Io`] when the folder cannot be read.
    pub fn robots(&self) -> Result<Vec<RobotId>, SecurityError> {
        let entries = match std::fs::read_dir(&self.dir) {
            Ok(entries) => entries,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
            Err(source) => {
                return Err(SecurityError::Io {
                    action: "list",
                    path: self.dir.clone(),
                    source,
                })
            }
        };
        let mut robots = BTreeSet::new();
        for entry in entries.flatten() {
            let name = entry.file_name();
            let Some(stem) = name.to_str().and_then(|n| n.strip_suffix(".pem")) else {
                continue;
            };
            if let Some(Identity::Agent(robot)) = Identity::from_common_name(stem) {
                robots.insert(robot);
            }
        }
        Ok(robots.into_iter().collect())
    }
}

/// What [`issue`] did.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct IssueReport {
    /// True when a new CA was made (every certificate is then new).
    pub new_ca: bool,
    /// Identities that got a new certificate.
    pub issued: Vec<Identity>,
    /// Identities whose certificate was already there and kept.
    pub kept: Vec<Identity>,
    /// Every robot the rules now name.
    pub robots: Vec<RobotId>,
}

/// The host names every certificate carries besides those asked for, so that sessions on one
/// host verify each other's names on loopback.
pub const LOOPBACK_HOSTS: [&str; 3] = ["localhost", "127.0.0.1", "::1"];

/// Makes (or completes) a site's security folder: a CA (kept when `ca.pem` and `ca.key` are
/// there), a certificate per service identity and per robot's agent (existing ones kept), and
/// `acl.json5` naming every robot that has a certificate. `hosts` are the DNS names or IP
/// addresses the processes listen on besides loopback: a session checks the certificate of the
/// peer it connects to against the endpoint's host. Keys are written readable by the owner only;
/// every file is written atomically.
///
/// # Errors
/// [`SecurityError`] naming the file or the host that failed.
pub fn issue(
    files: &SiteFiles,
    site: &SiteId,
    robots: &[RobotId],
    hosts: &[String],
) -> Result<IssueReport, SecurityError> {
    std::fs::create_dir_all(&files.dir).map_err(|source| SecurityError::Io {
        action: "create",
        path: files.dir.clone(),
        source,
    })?;
    let mut names: Vec<String> = LOOPBACK_HOSTS.iter().map(|h| (*h).to_string()).collect();
    for host in hosts {
        if host.is_empty() || host.len() > 253 || host.chars().any(|c| c.is_whitespace()) {
            return Err(SecurityError::Host {
                host: host.clone(),
                reason: "empty, longer than 253 characters or with spaces".into(),
            });
        }
        if !names.contains(host) {
            names.push(host.clone());
        }
    }

    let year = current_year();
    let (issuer, new_ca) = load_or_make_ca(files, site, year)?;

    let mut all_robots: BTreeSet<RobotId> = files.robots()?.into_iter().collect();
    all_robots.extend(robots.iter().cloned());
    let mut identities: Vec<Identity> = Identity::SERVICES.to_vec();
    identities.extend(all_robots.iter().cloned().map(Identity::Agent));

    let mut report = IssueReport {
        new_ca,
        issued: Vec::new(),
        kept: Vec::new(),
        robots: all_robots.iter().cloned().collect(),
    };
    for identity in identities {
        let (cert_path, key_path) = (files.cert(&identity), files.key(&identity));
        if !new_ca && cert_path.exists() && key_path.exists() {
            report.kept.push(identity);
            continue;
        }
        let name = identity.common_name();
        let fail = |reason: rcgen::Error| SecurityError::Certificate {
            action: format!("issue the certificate of {name}"),
            reason: reason.to_string(),
        };
        let key = KeyPair::generate().map_err(fail)?;
        let mut params =
            CertificateParams::new(names.clone()).map_err(|e| SecurityError::Host {
                host: names.join(", "),
                reason: e.to_string(),
            })?;
        params.distinguished_name.push(DnType::CommonName, &name);
        params.distinguished_name.push(
            DnType::OrganizationName,
            format!("intention-fleet site {site}"),
        );
        params.key_usages = vec![
            KeyUsagePurpose::DigitalSignature,
            KeyUsagePurpose::KeyEncipherment,
        ];
        // One certificate serves both ends of a peer link: it listens and it connects.
        params.extended_key_usages = vec![
            ExtendedKeyUsagePurpose::ServerAuth,
            ExtendedKeyUsagePurpose::ClientAuth,
        ];
        params.not_before = rcgen::date_time_ymd(year, 1, 1);
        params.not_after = rcgen::date_time_ymd(year + 3, 1, 1);
        let cert = params.signed_by(&key, &issuer).map_err(fail)?;
        write_atomic(&key_path, key.serialize_pem().as_bytes(), 0o600)?;
        write_atomic(&cert_path, cert.pem().as_bytes(), 0o644)?;
        report.issued.push(identity);
    }

    let acl = access_control(site, &report.robots);
    let text = format!(
        "// Zenoh access control of site {site}, written by `planner-service certs`: load it with\n\
         // --zenoh-acl (or `acl` in a [zenoh] table). Regenerated when robots are added.\n{}\n",
        serde_json::to_string_pretty(&acl).unwrap_or_default()
    );
    write_atomic(&files.acl(), text.as_bytes(), 0o644)?;
    let router = router_config(files, &acl);
    let text = format!(
        "// zenohd configuration of site {site}, written by `planner-service certs`: a router \
         between hosts,\n// mutual TLS only, checking the site's rules on every session that \
         connects (`zenohd -c router.json5`).\n// Paths are where `certs` wrote the files; \
         change them where the router's copies lie.\n{}\n",
        serde_json::to_string_pretty(&router).unwrap_or_default()
    );
    write_atomic(&files.router_config(), text.as_bytes(), 0o644)?;
    Ok(report)
}

/// A router's configuration: TLS on every interface at Zenoh's router port, the router's own
/// certificate on both ends of its links, the site's rules.
fn router_config(files: &SiteFiles, acl: &Value) -> Value {
    let path = |p: PathBuf| p.display().to_string();
    let router = Identity::Router;
    json!({
        "mode": "router",
        "listen": { "endpoints": ["tls/0.0.0.0:7447"] },
        "scouting": { "multicast": { "enabled": false } },
        "transport": { "link": { "tls": {
            "root_ca_certificate": path(files.ca_cert()),
            "listen_certificate": path(files.cert(&router)),
            "listen_private_key": path(files.key(&router)),
            "connect_certificate": path(files.cert(&router)),
            "connect_private_key": path(files.key(&router)),
            "enable_mtls": true,
            "verify_name_on_connect": true,
        } } },
        "access_control": acl,
    })
}

fn load_or_make_ca(
    files: &SiteFiles,
    site: &SiteId,
    year: i32,
) -> Result<(Issuer<'static, KeyPair>, bool), SecurityError> {
    let (cert_path, key_path) = (files.ca_cert(), files.ca_key());
    let read = |path: &Path| {
        std::fs::read_to_string(path).map_err(|source| SecurityError::Io {
            action: "read",
            path: path.to_path_buf(),
            source,
        })
    };
    match (cert_path.exists(), key_path.exists()) {
        (true, true) => {
            let key =
                KeyPair::from_pem(&read(&key_path)?).map_err(|e| SecurityError::Certificate {
                    action: format!("read the CA key {}", key_path.display()),
                    reason: e.to_string(),
                })?;
            let issuer = Issuer::from_ca_cert_pem(&read(&cert_path)?, key).map_err(|e| {
                SecurityError::Certificate {
                    action: format!("read the CA certificate {}", cert_path.display()),
                    reason: e.to_string(),
                }
            })?;
            Ok((issuer, false))
        }
        (true, false) => Err(SecurityError::Incomplete {
            dir: files.dir.clone(),
            what: "ca.pem",
            missing: "ca.key",
        }),
        (false, true) => Err(SecurityError::Incomplete {
            dir: files.dir.clone(),
            what: "ca.key",
            missing: "ca.pem",
        }),
        (false, false) => {
            let fail = |e: rcgen::Error| SecurityError::Certificate {
                action: "make the site CA".into(),
                reason: e.to_string(),
            };
            let key = KeyPair::generate().map_err(fail)?;
            let mut params = CertificateParams::new(Vec::<String>::new()).map_err(fail)?;
            params.is_ca = IsCa::Ca(BasicConstraints::Constrained(0));
            params
                .distinguished_name
                .push(DnType::CommonName, format!("intention-fleet {site} CA"));
            params.key_usages = vec![
                KeyUsagePurpose::KeyCertSign,
                KeyUsagePurpose::CrlSign,
                KeyUsagePurpose::DigitalSignature,
            ];
            params.not_before = rcgen::date_time_ymd(year, 1, 1);
            params.not_after = rcgen::date_time_ymd(year + 10, 1, 1);
            let cert = params.self_signed(&key).map_err(fail)?;
            write_atomic(&key_path, key.serialize_pem().as_bytes(), 0o600)?;
            write_atomic(&cert_path, cert.pem().as_bytes(), 0o644)?;
            Ok((Issuer::new(params, key), true))
        }
    }
}

/// The calendar year now (UTC), near enough for validity periods that start on 1 January.
fn current_year() -> i32 {
    const SECONDS_PER_YEAR: u64 = 31_556_952; // 365.2425 days
    let secs = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    1970 + i32::try_from(secs / SECONDS_PER_YEAR).unwrap_or(0)
}

/// Writes through a temporary file in the same folder, synced, then renamed over `path`: a crash
/// leaves the old file or the new one, never half of a key.
fn write_atomic(path: &Path, bytes: &[u8], mode: u32) -> Result<(), SecurityError> {
    let io = |action: &'static str| {
        move |source: std::io::Error| SecurityError::Io {
            action,
            path: path.to_path_buf(),
            source,
        }
    };
    let dir = path.parent().unwrap_or(Path::new("."));
    let mut tmp = tempfile::NamedTempFile::new_in(dir).map_err(io("create a file beside"))?;
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt as _;
        tmp.as_file()
            .set_permissions(std::fs::Permissions::from_mode(mode))
            .map_err(io("set the permissions of"))?;
    }
    #[cfg(not(unix))]
    let _ = mode;
    tmp.write_all(bytes).map_err(io("write"))?;
    tmp.as_file().sync_all().map_err(io("sync"))?;
    tmp.persist(path).map_err(|e| io("replace")(e.error))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    // Test code: a failed unwrap is a failed test.
    #![allow(clippy::unwrap_used)]

    use super::*;

    fn site() -> SiteId {
        SiteId::new("s1").unwrap()
    }

    #[test]
    fn common_names_round_trip() {
        let r = RobotId::new("robot_1").unwrap();
        for identity in Identity::SERVICES
            .into_iter()
            .chain([Identity::Agent(r.clone())])
        {
            assert_eq!(
                Identity::from_common_name(&identity.common_name()),
                Some(identity)
            );
        }
        assert_eq!(Identity::Agent(r).common_name(), "agent.robot_1");
        assert_eq!(Identity::from_common_name("agent."), None);
        assert_eq!(Identity::from_common_name("root"), None);
    }

    #[test]
    fn the_rules_bind_each_robot_to_its_own_agent() {
        let robots = [RobotId::new("r1").unwrap(), RobotId::new("r2").unwrap()];
        let acl = access_control(&site(), &robots);
        assert_eq!(acl["default_permission"], "deny");
        let rules = acl["rules"].as_array().unwrap();
        let keys_of = |subject: &str, message: &str| -> Vec<String> {
            let policy = acl["policies"]
                .as_array()
                .unwrap()
                .iter()
                .find(|p| p["subjects"][0] == subject)
                .unwrap();
            let mut keys = Vec::new();
            for id in policy["rules"].as_array().unwrap() {
                let rule = rules.iter().find(|r| &r["id"] == id).unwrap();
                if rule["messages"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .any(|m| m == message)
                {
                    for k in rule["key_exprs"].as_array().unwrap() {
                        keys.push(k.as_str().unwrap().to_string());
                    }
                }
            }
            keys
        };
        assert_eq!(
            keys_of("agent.r1", "put"),
            [
                "fleet/s1/robot/r1/pose",
                "fleet/s1/robot/r1/status",
                "fleet/s1/robot/r1/cmd_vel"
            ]
        );
        assert_eq!(
            keys_of("planner", "put"),
            ["fleet/s1/robot/*/intention", "fleet/s1/task/*"]
        );
        assert_eq!(
            keys_of("sim", "declare_subscriber"),
            ["fleet/s1/robot/*/cmd_vel"]
        );
        assert!(keys_of("observer", "put").is_empty());
        assert!(keys_of("map-store", "put").is_empty());
        // Every subject named by a policy exists, every rule named exists, ids are unique.
        let subject_ids: BTreeSet<&str> = acl["subjects"]
            .as_array()
            .unwrap()
            .iter()
            .map(|s| s["id"].as_str().unwrap())
            .collect();
        assert_eq!(subject_ids.len(), acl["subjects"].as_array().unwrap().len());
        assert!(subject_ids.contains("agent.r2"));
        let rule_ids: BTreeSet<&str> = rules.iter().map(|r| r["id"].as_str().unwrap()).collect();
        assert_eq!(rule_ids.len(), rules.len());
        // Zenoh itself accepts the block.
        let mut config = zenoh::Config::default();
        config
            .insert_json5("access_control", &acl.to_string())
            .unwrap();
    }

    #[test]
    fn issuing_keeps_the_ca_and_adds_robots() {
        let dir = tempfile::tempdir().unwrap();
        let files = SiteFiles::new(dir.path().join("site"));
        let r1 = RobotId::new("r1").unwrap();
        let first = issue(&files, &site(), std::slice::from_ref(&r1), &[]).unwrap();
        assert!(first.new_ca);
        assert_eq!(first.issued.len(), Identity::SERVICES.len() + 1);
        // The router's configuration is one Zenoh accepts.
        let router = std::fs::read_to_string(files.router_config()).unwrap();
        let config = zenoh::Config::from_json5(&router).unwrap();
        assert_eq!(
            config
                .get_json("access_control/default_permission")
                .unwrap(),
            "\"deny\""
        );
        let ca = std::fs::read(files.ca_cert()).unwrap();
        let planner_cert = std::fs::read(files.cert(&Identity::Planner)).unwrap();
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt as _;
            let mode = std::fs::metadata(files.key(&Identity::Planner))
                .unwrap()
                .permissions()
                .mode();
            assert_eq!(mode & 0o777, 0o600, "keys are the owner's only");
        }

        let r2 = RobotId::new("r2").unwrap();
        let second = issue(
            &files,
            &site(),
            std::slice::from_ref(&r2),
            &["fleet-1".into()],
        )
        .unwrap();
        assert!(!second.new_ca);
        assert_eq!(second.issued, [Identity::Agent(r2.clone())]);
        assert_eq!(second.robots, [r1, r2]);
        assert_eq!(std::fs::read(files.ca_cert()).unwrap(), ca);
        assert_eq!(
            std::fs::read(files.cert(&Identity::Planner)).unwrap(),
            planner_cert
        );
        let acl = std::fs::read_to_string(files.acl()).unwrap();
        assert!(acl.contains("agent.r1") && acl.contains("agent.r2"));

        // A folder with a CA certificate but no key is refused, not silently re-keyed.
        std::fs::remove_file(files.ca_key()).unwrap();
        let err = issue(&files, &site(), &[], &[]).unwrap_err().to_string();
        assert!(err.contains("ca.key"), "{err}");
        let err = issue(&files, &site(), &[], &["bad host".into()])
            .unwrap_err()
            .to_string();
        assert!(err.contains("bad host"), "{err}");
    }
}
