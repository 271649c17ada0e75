//! The planner service's configuration file: `[planner]`, `[dlm]`, `[lpe]`, `[http]`, `[zenoh]`,
//! `[fleet]` and `[demo]` tables.
//!
//! Every table has defaults, so a file names only what it changes; unknown keys are errors.
//! `planner.example.toml` in the crate documents every key (a test parses it). `serve` applies
//! the environment (`FLEET_*`) and its flags on top of the file (CLI > env > file > defaults).

use std::net::SocketAddr;
use std::path::{Path, PathBuf};

use map_store::ImportLimits;
use serde::{Deserialize, Serialize};

use crate::fleet::FleetConfig;
use crate::restart::{RestartPolicy, RestartPolicyError};
use planning::intention::dlm::DlmParamsError;
use planning::intention::{DlmParams, LpeParams};
use planning::{AvoidParams, PlanError, PlannerConfig, ReuseParams, SeenObstacleParams};
use protocol::{LpeParamsError, SessionArgs, SessionError, SessionMode, SiteId};

/// The whole configuration file.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ServiceConfig {
    pub planner: PlannerConfig,
    pub dlm: DlmParams,
    pub lpe: LpeParams,
    /// When a robot's previous plan answers instead of a new search (`[path_reuse]`).
    pub path_reuse: ReuseParams,
    /// How plans keep clear of the fleet's other robots (`[other_robots]`; which robots:
    /// `[fleet] neighbour_radius_m`).
    pub other_robots: AvoidParams,
    /// How plans keep clear of what the robots' lasers see where the floor plan is free
    /// (`[seen_obstacles]`; the agents report it with their poses).
    pub seen_obstacles: SeenObstacleParams,
    pub http: HttpConfig,
    pub zenoh: ZenohConfig,
    /// The fleet core (`[fleet]`): goal tolerance, timeouts of silent robots and paused tasks.
    pub fleet: FleetConfig,
    /// `planner-service demo` only (`[demo]`): how it supervises its child processes.
    pub demo: DemoConfig,
}

/// How `planner-service demo` supervises the processes it starts (`[demo]`).
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DemoConfig {
    /// A robot agent that exits is started again after this back-off
    /// (`[demo.agent_restart]`).
    pub agent_restart: RestartPolicy,
}

/// The HTTP API (`[http]`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct HttpConfig {
    /// Address the API listens on; port 0 picks a free port.
    pub listen: SocketAddr,
    /// Largest request body of a floor-plan upload or preview (multipart), in bytes.
    pub max_upload_bytes: u64,
    /// Largest body of any other request (JSON), in bytes.
    pub max_json_bytes: u64,
    /// The bearer token of mutating routes; `None` generates one in `<data-dir>/token`.
    pub token: Option<String>,
    /// Whether read routes need the token too (header or `access_token=` query parameter).
    pub protect_reads: bool,
    /// Origins allowed to call the API from a browser page served elsewhere (`"*"`: any).
    pub cors: Vec<String>,
    /// Image limits of uploaded floor plans, checked before decoding.
    pub import_limits: ImportLimits,
    /// Longest wait for a request's complete head (request line and headers), in
    /// milliseconds, counted from when the server starts waiting for it: on a new connection,
    /// and on a kept-alive one after the previous response. A connection that sends no
    /// complete head in time (a slow or silent client, an idle keep-alive) is closed.
    pub header_read_timeout_ms: u64,
    /// A connection on which no byte moves either way for this long, in milliseconds, is
    /// closed (a stalled request body, a client that stops reading the answer, a handler that
    /// takes longer). The event stream sends a comment line at least every half of it.
    pub idle_timeout_ms: u64,
    /// Most connections open at once; the next one is answered `503` with `Retry-After` and
    /// closed.
    pub max_connections: u32,
    /// Memory all floor-plan decodes (uploads and previews) may take together, in bytes,
    /// estimated from each picture's header before it is decoded. One that needs more than all
    /// of it is refused with `413`.
    pub decode_budget_bytes: u64,
    /// How long a decode waits for room in the budget, in milliseconds, before `503` with
    /// `Retry-After`.
    pub decode_wait_ms: u64,
    /// Rendered map images (`GET /maps/{name}/image`) kept in memory, in bytes, per map
    /// version; 0 renders every request.
    pub image_cache_bytes: u64,
}

impl Default for HttpConfig {
    fn default() -> Self {
        Self {
            listen: SocketAddr::from(([127, 0, 0, 1], 8080)),
            max_upload_bytes: 64 << 20,
            max_json_bytes: 1 << 20,
            token: None,
            protect_reads: false,
            cors: Vec::new(),
            import_limits: ImportLimits::default(),
            header_read_timeout_ms: 10_000,
            idle_timeout_ms: 60_000,
            max_connections: 256,
            decode_budget_bytes: 1 << 30,
            decode_wait_ms: 10_000,
            image_cache_bytes: 64 << 20,
        }
    }
}

/// Shortest token accepted: anything shorter is guessable.
pub const MIN_TOKEN_LEN: usize = 16;

/// A value of the `[http]` table out of range.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum HttpConfigError {
    #[error("invalid {field} = {value_bytes}: must be positive and fit in memory")]
    BodyLimit {
        /// `http.max_upload_bytes` or `http.max_json_bytes`.
        field: &'static str,
        value_bytes: u64,
    },
    /// The token itself is not repeated: it is a secret.
    #[error("invalid http.token: {0}")]
    Token(#[source] TokenRejection),
    #[error(
        "invalid http.cors entry {origin:?}: expected \"*\" or an origin like \"http://host:port\""
    )]
    CorsOrigin { origin: String },
    #[error("invalid {field} = {value}: must be within {min}..={max}")]
    OutOfRange {
        /// `http.header_read_timeout_ms`, `http.idle_timeout_ms`, `http.max_connections`,
        /// `http.decode_budget_bytes`, `http.decode_wait_ms` or `http.image_cache_bytes`.
        field: &'static str,
        value: u64,
        min: u64,
        max: u64,
    },
}

/// Longest accepted `http.header_read_timeout_ms` and `http.idle_timeout_ms`: one hour.
pub const MAX_HTTP_TIMEOUT_MS: u64 = 3_600_000;

/// Most accepted `http.max_connections`.
pub const MAX_HTTP_CONNECTIONS: u32 = 65_536;

impl HttpConfig {
    /// Checks limits, token and CORS origins.
    ///
    /// # Errors
    /// [`HttpConfigError`] naming the field and value (never the token's value).
    pub fn validate(&self) -> Result<(), HttpConfigError> {
        for (field, value_bytes) in [
            ("http.max_upload_bytes", self.max_upload_bytes),
            ("http.max_json_bytes", self.max_json_bytes),
        ] {
            if value_bytes == 0 || usize::try_from(value_bytes).is_err() {
                return Err(HttpConfigError::BodyLimit { field, value_bytes });
            }
        }
        for (field, value, min, max) in [
            (
                "http.header_read_timeout_ms",
                self.header_read_timeout_ms,
                1,
                MAX_HTTP_TIMEOUT_MS,
            ),
            (
                "http.idle_timeout_ms",
                self.idle_timeout_ms,
                1,
                MAX_HTTP_TIMEOUT_MS,
            ),
            (
                "http.max_connections",
                u64::from(self.max_connections),
                1,
                u64::from(MAX_HTTP_CONNECTIONS),
            ),
            (
                "http.decode_budget_bytes",
                self.decode_budget_bytes,
                1 << 20,
                1 << 42,
            ),
            (
                "http.decode_wait_ms",
                self.decode_wait_ms,
                0,
                MAX_HTTP_TIMEOUT_MS,
            ),
            ("http.image_cache_bytes", self.image_cache_bytes, 0, 1 << 40),
        ] {
            if !(min..=max).contains(&value) {
                return Err(HttpConfigError::OutOfRange {
                    field,
                    value,
                    min,
                    max,
                });
            }
        }
        if let Some(token) = &self.token {
            validate_token(token).map_err(HttpConfigError::Token)?;
        }
        for origin in &self.cors {
            let host = origin
                .strip_prefix("http://")
                .or_else(|| origin.strip_prefix("https://"));
            let ok = origin == "*"
                || host.is_some_and(|h| {
                    !h.is_empty() && h.chars().all(|c| c.is_ascii_graphic() && c != '/')
                });
            if !ok {
                return Err(HttpConfigError::CorsOrigin {
                    origin: origin.clone(),
                });
            }
        }
        Ok(())
    }
}

/// Why a bearer token is refused; never repeats the token (it is a secret).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum TokenRejection {
    #[error("length {len} is outside {MIN_TOKEN_LEN}..=256 characters")]
    Length { len: usize },
    #[error("only visible ASCII characters are allowed (no spaces)")]
    NotVisibleAscii,
}

/// Checks a bearer token: at least [`MIN_TOKEN_LEN`] visible ASCII characters, at most 256.
///
/// # Errors
/// [`TokenRejection`], which does not repeat the token.
pub fn validate_token(token: &str) -> Result<(), TokenRejection> {
    if token.len() < MIN_TOKEN_LEN || token.len() > 256 {
        return Err(TokenRejection::Length { len: token.len() });
    }
    if !token.chars().all(|c| c.is_ascii_graphic()) {
        return Err(TokenRejection::NotVisibleAscii);
    }
    Ok(())
}

/// The Zenoh session of the service (`[zenoh]`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ZenohConfig {
    /// The site: every key is under `fleet/<site>/`.
    pub site: SiteId,
    /// Endpoints to listen on, e.g. `tcp/0.0.0.0:7447`; empty: loopback, an OS-chosen port.
    pub listen: Vec<String>,
    /// Endpoints to connect to (a router, or the robots' peers).
    pub connect: Vec<String>,
    /// Multicast scouting (finds peers on the LAN by itself; off so a stranger's session on
    /// the same network is never picked up).
    pub multicast: bool,
    /// `peer`, or `client` behind a router on another host (docs/deploy.md).
    pub mode: SessionMode,
    /// Mutual TLS: the site CA, this service's certificate and key (PEM; `planner-service
    /// certs` makes them). All three or none; with them every endpoint must be `tls/…`.
    pub tls_ca: Option<PathBuf>,
    pub tls_cert: Option<PathBuf>,
    pub tls_key: Option<PathBuf>,
    /// Zenoh access-control rules (`acl.json5` from `planner-service certs`); needs TLS.
    pub acl: Option<PathBuf>,
}

impl Default for ZenohConfig {
    fn default() -> Self {
        Self {
            site: default_site(),
            listen: Vec::new(),
            connect: Vec::new(),
            multicast: false,
            mode: SessionMode::Peer,
            tls_ca: None,
            tls_cert: None,
            tls_key: None,
            acl: None,
        }
    }
}

fn default_site() -> SiteId {
    match SiteId::new(map_store::config::DEFAULT_SITE) {
        Ok(site) => site,
        // The literal is a valid id; the example-file test checks it.
        Err(e) => unreachable!("default site is invalid: {e}"),
    }
}

impl ZenohConfig {
    /// The session part of the table (`listen`, `connect`, `multicast`).
    #[must_use]
    pub fn session_args(&self) -> SessionArgs {
        SessionArgs {
            listen: self.listen.clone(),
            connect: self.connect.clone(),
            multicast_scouting: self.multicast,
            mode: self.mode,
            tls_ca: self.tls_ca.clone(),
            tls_cert: self.tls_cert.clone(),
            tls_key: self.tls_key.clone(),
            acl: self.acl.clone(),
        }
    }

    /// Lays the `--zenoh-*` flags over the table (see [`SessionArgs::override_with`]).
    pub fn override_with(&mut self, flags: &SessionArgs) {
        let mut session = self.session_args();
        session.override_with(flags);
        self.listen = session.listen;
        self.connect = session.connect;
        self.multicast = session.multicast_scouting;
        self.mode = session.mode;
        self.tls_ca = session.tls_ca;
        self.tls_cert = session.tls_cert;
        self.tls_key = session.tls_key;
        self.acl = session.acl;
    }

    /// The Zenoh configuration of the service's peer session.
    ///
    /// # Errors
    /// [`SessionError`] naming the endpoint Zenoh refused.
    pub fn session_config(&self) -> Result<zenoh::Config, SessionError> {
        self.session_args().config()
    }
}

/// A configuration file that cannot be read, parsed or validated.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    #[error("cannot read config {path}: {source}")]
    Io {
        path: String,
        #[source]
        source: std::io::Error,
    },
    #[error("cannot parse config {path}: {reason}")]
    Parse { path: String, reason: String },
    #[error("invalid config {path}: {source}")]
    Invalid {
        path: String,
        #[source]
        source: ServiceConfigError,
    },
}

/// A table of the configuration with a value out of range; the message names the field and
/// value.
#[derive(Debug, thiserror::Error)]
pub enum ServiceConfigError {
    #[error(transparent)]
    Planner(#[from] PlanError),
    #[error(transparent)]
    Dlm(#[from] DlmParamsError),
    #[error(transparent)]
    Lpe(#[from] LpeParamsError),
    #[error(transparent)]
    Http(#[from] HttpConfigError),
    #[error(transparent)]
    Zenoh(#[from] SessionError),
    /// `[fleet]`, as the fleet core words it.
    #[error("{0}")]
    Fleet(#[from] crate::fleet::InvalidFleetConfig),
    #[error("[demo.agent_restart] {0}")]
    DemoRestart(#[from] RestartPolicyError),
}

impl ServiceConfig {
    /// The intention pipeline's settings: `[planner]`, `[dlm]`, `[lpe]` and the goal
    /// tolerance, path spacing and trail length of `[fleet]`.
    #[must_use]
    pub fn intention(&self) -> planning::IntentionConfig {
        planning::IntentionConfig {
            planner: self.planner.clone(),
            dlm: self.dlm.clone(),
            lpe: self.lpe.clone(),
            goal_tolerance_m: self.fleet.goal_tolerance_m,
            path_spacing_m: self.fleet.intention_path_spacing_m,
            trail_poses: self.fleet.trail_poses,
            reuse: self.path_reuse.clone(),
            avoid: self.other_robots.clone(),
            seen: self.seen_obstacles.clone(),
        }
    }

    /// Parses and validates TOML text; `origin` names it in errors.
    ///
    /// # Errors
    /// [`ConfigError::Parse`] or [`ConfigError::Invalid`] naming the field.
    pub fn from_toml_str(text: &str, origin: &str) -> Result<Self, ConfigError> {
        let cfg: Self = toml::from_str(text).map_err(|e| ConfigError::Parse {
            path: origin.to_string(),
            reason: e.to_string(),
        })?;
        cfg.validate().map_err(|source| ConfigError::Invalid {
            path: origin.to_string(),
            source,
        })?;
        Ok(cfg)
    }

    /// Reads, parses and validates a TOML file.
    ///
    /// # Errors
    /// As [`Self::from_toml_str`], or [`ConfigError::Io`].
    pub fn load(path: &Path) -> Result<Self, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Io {
            path: path.display().to_string(),
            source,
        })?;
        Self::from_toml_str(&text, &path.display().to_string())
    }

    /// Checks every table.
    ///
    /// # Errors
    /// [`ServiceConfigError`] naming the field and value.
    pub fn validate(&self) -> Result<(), ServiceConfigError> {
        self.planner.validate()?;
        self.dlm.validate()?;
        self.lpe.validate()?;
        self.path_reuse.validate()?;
        self.other_robots.validate()?;
        self.seen_obstacles.validate()?;
        self.http.validate()?;
        self.zenoh.session_config()?;
        self.fleet.validate()?;
        self.demo.agent_restart.validate()?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn example_file_parses_and_documents_the_defaults() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("planner.example.toml");
        let cfg = ServiceConfig::load(&path).unwrap();
        assert_eq!(cfg, ServiceConfig::default());
    }

    #[test]
    fn bad_values_and_unknown_keys_are_named() {
        let err = ServiceConfig::from_toml_str("[planner]\nstep_m = -1.0\n", "t").unwrap_err();
        assert!(err.to_string().contains("step_m"), "{err}");
        let err = ServiceConfig::from_toml_str("[dlm]\nwindow = 1.0\n", "t").unwrap_err();
        assert!(err.to_string().contains("window"), "{err}");
        let err = ServiceConfig::from_toml_str("[lpe]\nmetres_per_px = 0.0\n", "t").unwrap_err();
        assert!(err.to_string().contains("metres_per_px"), "{err}");
        let err = ServiceConfig::from_toml_str("[http]\nmax_upload_bytes = 0\n", "t").unwrap_err();
        assert!(err.to_string().contains("max_upload_bytes"), "{err}");
        let err = ServiceConfig::from_toml_str("[http]\ntoken = \"short\"\n", "t").unwrap_err();
        assert!(err.to_string().contains("http.token"), "{err}");
        let err =
            ServiceConfig::from_toml_str("[demo.agent_restart]\ninitial_backoff_ms = 0\n", "t")
                .unwrap_err();
        assert!(err.to_string().contains("initial_backoff_ms = 0"), "{err}");
        let err =
            ServiceConfig::from_toml_str("[http]\ncors = [\"example.com\"]\n", "t").unwrap_err();
        assert!(err.to_string().contains("example.com"), "{err}");
        let err = ServiceConfig::from_toml_str("[http]\nidle_timeout_ms = 0\n", "t").unwrap_err();
        assert!(
            err.to_string().contains("http.idle_timeout_ms = 0"),
            "{err}"
        );
        let err = ServiceConfig::from_toml_str("[http]\nheader_read_timeout_ms = 3600001\n", "t")
            .unwrap_err();
        assert!(err.to_string().contains("header_read_timeout_ms"), "{err}");
        let err = ServiceConfig::from_toml_str("[http]\nmax_connections = 0\n", "t").unwrap_err();
        assert!(
            err.to_string().contains("http.max_connections = 0"),
            "{err}"
        );
        let err = ServiceConfig::from_toml_str("[http]\nidle_timeout = 5\n", "t").unwrap_err();
        assert!(err.to_string().contains("idle_timeout"), "{err}");
        let err = ServiceConfig::from_toml_str("[http]\nlisten = \"nowhere\"\n", "t").unwrap_err();
        assert!(err.to_string().contains("listen"), "{err}");
        let err = ServiceConfig::from_toml_str("[zenoh]\nsite = \"a/b\"\n", "t").unwrap_err();
        assert!(err.to_string().contains("a/b"), "{err}");
        let err =
            ServiceConfig::from_toml_str("[zenoh]\nlisten = [\"nonsense\"]\n", "t").unwrap_err();
        assert!(err.to_string().contains("nonsense"), "{err}");
        let err = ServiceConfig::from_toml_str(
            "[zenoh]\nconnect = [\"tcp/10.0.0.2:7447\", \"bogus\"]\n",
            "t",
        )
        .unwrap_err();
        assert!(
            err.to_string().contains("connect") && err.to_string().contains("bogus"),
            "{err}"
        );
        let ok = ServiceConfig::from_toml_str(
            "[http]\ncors = [\"*\", \"http://localhost:3000\"]\nprotect_reads = true\n",
            "t",
        )
        .unwrap();
        assert!(ok.http.protect_reads);
    }

    #[test]
    fn typed_errors_name_field_and_value() {
        let invalid = |text: &str| match ServiceConfig::from_toml_str(text, "t.toml") {
            Err(ConfigError::Invalid { path, source }) => {
                assert_eq!(path, "t.toml");
                source
            }
            other => panic!("expected ConfigError::Invalid, got {other:?}"),
        };
        let e = invalid("[dlm]\nwindow_m = 0.0\n");
        assert!(
            matches!(&e, ServiceConfigError::Dlm(d) if d.field == "window_m" && d.value == 0.0),
            "{e:?}"
        );
        assert_eq!(e.to_string(), "invalid dlm.window_m = 0: must be positive");
        let e = invalid("[http]\nmax_json_bytes = 0\n");
        assert!(matches!(
            e,
            ServiceConfigError::Http(HttpConfigError::BodyLimit {
                field: "http.max_json_bytes",
                value_bytes: 0
            })
        ));
        assert_eq!(
            e.to_string(),
            "invalid http.max_json_bytes = 0: must be positive and fit in memory"
        );
        let e = invalid("[http]\ntoken = \"has spaces but is long\"\n");
        assert!(matches!(
            e,
            ServiceConfigError::Http(HttpConfigError::Token(TokenRejection::NotVisibleAscii))
        ));
        assert!(
            !e.to_string().contains("has spaces"),
            "the token is a secret: {e}"
        );
        let e = invalid("[http]\ncors = [\"ftp://x\"]\n");
        assert!(e.to_string().contains("http.cors") && e.to_string().contains("ftp://x"));
        let e = invalid("[zenoh]\nlisten = [\"nonsense\"]\n");
        assert!(
            matches!(&e, ServiceConfigError::Zenoh(SessionError::Endpoint { field: "listen", endpoint, .. }) if endpoint == "nonsense"),
            "{e:?}"
        );
        let e = invalid("[planner]\nstep_m = -1.0\n");
        assert!(matches!(e, ServiceConfigError::Planner(_)));
        assert!(e.to_string().contains("step_m = -1"), "{e}");
        assert_eq!(
            validate_token("short"),
            Err(TokenRejection::Length { len: 5 })
        );
    }

    #[test]
    fn zenoh_flags_override_the_table() {
        let mut zenoh = ZenohConfig {
            listen: vec!["tcp/0.0.0.0:7447".into()],
            ..ZenohConfig::default()
        };
        assert!(!zenoh.session_args().multicast_scouting);
        zenoh.override_with(&SessionArgs {
            listen: vec![],
            connect: vec!["tcp/10.0.0.2:7447".into()],
            multicast_scouting: true,
            ..SessionArgs::default()
        });
        assert_eq!(zenoh.listen, ["tcp/0.0.0.0:7447"]);
        assert_eq!(zenoh.connect, ["tcp/10.0.0.2:7447"]);
        assert!(zenoh.multicast);
        zenoh.session_config().unwrap();
    }
}
