//! Glue between the codec and Zenoh: how every process configures and opens its session
//! ([`SessionArgs`]), encodings, publishing, replying and decoding samples.
//!
//! Publishers declare what they send through the Zenoh `Encoding`: JSON kinds are
//! `application/json`, framed kinds `application/octet-stream` with schema
//! `intention-fleet/<kind>`, so tools on the wire can tell payloads apart without decoding them.

use std::path::{Path, PathBuf};

use zenoh::bytes::Encoding;
use zenoh::key_expr::KeyExpr;
use zenoh::pubsub::Publisher;
use zenoh::query::Query;
use zenoh::sample::Sample;
use zenoh::Session;

use crate::codec::{decode, encode, DecodeError, EncodeError, WireMessage, SCHEMA_PREFIX};

/// Why a message could not be published.
#[derive(Debug, thiserror::Error)]
pub enum PublishError {
    #[error(transparent)]
    Encode(#[from] EncodeError),
    #[error("zenoh could not send {kind}: {source}")]
    Zenoh {
        kind: &'static str,
        #[source]
        source: zenoh::Error,
    },
}

/// The Zenoh encoding a message kind is sent with.
pub fn encoding_for<M: WireMessage>() -> Encoding {
    if M::FRAMED {
        Encoding::APPLICATION_OCTET_STREAM.with_schema(format!("{SCHEMA_PREFIX}{}", M::KIND))
    } else {
        Encoding::APPLICATION_JSON
    }
}

/// Encodes `msg` and puts it on `key` through the session (one-off publication).
pub async fn put<M: WireMessage>(
    session: &Session,
    key: &KeyExpr<'_>,
    msg: &M,
) -> Result<(), PublishError> {
    let bytes = encode(msg)?;
    session
        .put(key, bytes)
        .encoding(encoding_for::<M>())
        .await
        .map_err(|source| PublishError::Zenoh {
            kind: M::KIND,
            source,
        })
}

/// Encodes `msg` and sends it through a declared publisher (the streaming path).
pub async fn publish<M: WireMessage>(
    publisher: &Publisher<'_>,
    msg: &M,
) -> Result<(), PublishError> {
    let bytes = encode(msg)?;
    publisher
        .put(bytes)
        .encoding(encoding_for::<M>())
        .await
        .map_err(|source| PublishError::Zenoh {
            kind: M::KIND,
            source,
        })
}

/// Encodes `msg` and answers `query` with it on `key` (e.g. the map store serving a grid).
pub async fn reply<M: WireMessage>(
    query: &Query,
    key: &KeyExpr<'_>,
    msg: &M,
) -> Result<(), PublishError> {
    let bytes = encode(msg)?;
    query
        .reply(key, bytes)
        .encoding(encoding_for::<M>())
        .await
        .map_err(|source| PublishError::Zenoh {
            kind: M::KIND,
            source,
        })
}

/// Decodes a received sample's payload as `M`; the wire version and kind inside the payload are
/// authoritative, the sample's Zenoh encoding is informational.
pub fn decode_sample<M: WireMessage>(sample: &Sample) -> Result<M, DecodeError> {
    decode(&sample.payload().to_bytes())
}

/// Why a Zenoh session could not be configured or opened.
#[derive(Debug, thiserror::Error)]
pub enum SessionError {
    /// An endpoint Zenoh cannot parse; `field` is `listen` or `connect`.
    #[error("invalid zenoh {field} endpoint {endpoint:?}: {reason}")]
    Endpoint {
        field: &'static str,
        endpoint: String,
        reason: String,
    },
    /// A setting Zenoh refused; `field` is Zenoh's configuration path.
    #[error("invalid zenoh {field} = {value}: {reason}")]
    Config {
        field: &'static str,
        value: String,
        reason: String,
    },
    /// A TLS or access-control file that cannot be read; `field` is the setting naming it.
    #[error("cannot read zenoh {field} {}: {reason}", path.display())]
    File {
        field: &'static str,
        path: PathBuf,
        reason: String,
    },
    #[error("cannot open zenoh session: {0}")]
    Open(zenoh::Error),
    #[error("zenoh session listens on no locator")]
    NoLocator,
}

/// How a fleet process joins Zenoh: the one place that turns endpoints and the scouting choice
/// into a `zenoh::Config`, shared by every binary (flags) and configuration file (`[zenoh]`).
///
/// Fleet processes find each other through the endpoints they are given (a router between
/// hosts, loopback on one host). Multicast scouting is off unless asked for, so a test or a demo
/// never picks up a stranger's session on the same network, and a session given no listen
/// endpoint listens on loopback only (Zenoh's own default is every interface).
///
/// With `tls_ca`, `tls_cert` and `tls_key` the session speaks mutual TLS only: it accepts peers
/// whose certificate the site CA signed and presents its own; every endpoint must then be
/// `tls/…`. `acl` loads Zenoh access-control rules that match those certificates' names (see
/// [`crate::security`]).
///
/// With the `cli` feature this is also a clap [`Args`](clap::Args) group that every binary
/// flattens: `--zenoh-listen ENDPOINT`, `--zenoh-connect ENDPOINT` (both repeatable) and
/// `--zenoh-multicast-scouting`. In a configuration file the keys are `listen`, `connect` and
/// `multicast` (alias `multicast_scouting`).
#[derive(Debug, Clone, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
pub struct SessionArgs {
    /// Zenoh endpoint to listen on, e.g. tcp/0.0.0.0:7447 (repeatable).
    #[cfg_attr(
        feature = "cli",
        arg(id = SessionArgs::LISTEN_ID, long = "zenoh-listen", value_name = "ENDPOINT")
    )]
    pub listen: Vec<String>,
    /// Zenoh endpoint to connect to, e.g. tcp/192.168.1.10:7447 (repeatable).
    #[cfg_attr(
        feature = "cli",
        arg(id = SessionArgs::CONNECT_ID, long = "zenoh-connect", value_name = "ENDPOINT")
    )]
    pub connect: Vec<String>,
    /// Also find Zenoh peers on the LAN by multicast scouting (off: only through the endpoints).
    #[cfg_attr(
        feature = "cli",
        arg(id = SessionArgs::MULTICAST_ID, long = "zenoh-multicast-scouting")
    )]
    #[serde(rename = "multicast", alias = "multicast_scouting")]
    pub multicast_scouting: bool,
    /// `peer` (default) or `client`. A client talks only through the router it connects to:
    /// what processes on different hosts use behind a router (docs/deploy.md), since peers
    /// expect to reach each other directly and a router does not forward between them.
    #[cfg_attr(
        feature = "cli",
        arg(long = "zenoh-mode", value_name = "MODE", value_enum, default_value_t)
    )]
    pub mode: SessionMode,
    /// The site CA's certificate (PEM) that peers' certificates must chain to; with
    /// --zenoh-tls-cert and --zenoh-tls-key it turns on mutual TLS (tls/ endpoints only).
    #[cfg_attr(
        feature = "cli",
        arg(long = "zenoh-tls-ca", value_name = "PEM", requires_all = ["tls_cert", "tls_key"])
    )]
    #[serde(skip_serializing_if = "Option::is_none")]
    pub tls_ca: Option<PathBuf>,
    /// This process's certificate (PEM), signed by the site CA.
    #[cfg_attr(feature = "cli", arg(long = "zenoh-tls-cert", value_name = "PEM"))]
    #[serde(skip_serializing_if = "Option::is_none")]
    pub tls_cert: Option<PathBuf>,
    /// This process's private key (PEM).
    #[cfg_attr(feature = "cli", arg(long = "zenoh-tls-key", value_name = "PEM"))]
    #[serde(skip_serializing_if = "Option::is_none")]
    pub tls_key: Option<PathBuf>,
    /// Zenoh access-control rules (JSON5, e.g. acl.json5 from `planner-service certs`); they
    /// match certificate names, so they need TLS.
    #[cfg_attr(feature = "cli", arg(long = "zenoh-acl", value_name = "JSON5"))]
    #[serde(skip_serializing_if = "Option::is_none")]
    pub acl: Option<PathBuf>,
}

/// How a session takes part in the Zenoh network.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
pub enum SessionMode {
    /// Talks to the sessions it reaches directly (and through routers to their peers' routers).
    #[default]
    Peer,
    /// Talks only through the router it connects to, and listens on nothing.
    Client,
}

impl SessionMode {
    fn as_str(self) -> &'static str {
        match self {
            SessionMode::Peer => "peer",
            SessionMode::Client => "client",
        }
    }
}

/// The TLS files of a session, all three present.
struct TlsFiles<'a> {
    ca: &'a Path,
    cert: &'a Path,
    key: &'a Path,
}

impl SessionArgs {
    /// Clap id of `--zenoh-listen` (for `mut_arg`, e.g. to add a `--listen` alias).
    pub const LISTEN_ID: &'static str = "zenoh_listen";
    /// Clap id of `--zenoh-connect`.
    pub const CONNECT_ID: &'static str = "zenoh_connect";
    /// Clap id of `--zenoh-multicast-scouting`.
    pub const MULTICAST_ID: &'static str = "zenoh_multicast_scouting";

    /// A peer with these endpoints and multicast scouting off.
    #[must_use]
    pub fn new(listen: &[String], connect: &[String]) -> Self {
        Self {
            listen: listen.to_vec(),
            connect: connect.to_vec(),
            ..Self::default()
        }
    }

    /// Lays command-line flags over these settings (from a file or defaults): a non-empty
    /// endpoint list of `flags` replaces the list here, and `--zenoh-multicast-scouting`
    /// turns scouting on.
    pub fn override_with(&mut self, flags: &SessionArgs) {
        if !flags.listen.is_empty() {
            self.listen.clone_from(&flags.listen);
        }
        if !flags.connect.is_empty() {
            self.connect.clone_from(&flags.connect);
        }
        self.multicast_scouting |= flags.multicast_scouting;
        if flags.mode != SessionMode::default() {
            self.mode = flags.mode;
        }
        for (mine, theirs) in [
            (&mut self.tls_ca, &flags.tls_ca),
            (&mut self.tls_cert, &flags.tls_cert),
            (&mut self.tls_key, &flags.tls_key),
            (&mut self.acl, &flags.acl),
        ] {
            if theirs.is_some() {
                mine.clone_from(theirs);
            }
        }
    }

    /// True when the session speaks mutual TLS.
    #[must_use]
    pub fn is_tls(&self) -> bool {
        self.tls_ca.is_some() || self.tls_cert.is_some() || self.tls_key.is_some()
    }

    /// The TLS files, checked readable: none, or all three.
    fn tls_files(&self) -> Result<Option<TlsFiles<'_>>, SessionError> {
        let fields = [
            ("tls_ca", &self.tls_ca),
            ("tls_cert", &self.tls_cert),
            ("tls_key", &self.tls_key),
        ];
        if !self.is_tls() {
            return Ok(None);
        }
        for (field, path) in fields {
            let Some(path) = path else {
                return Err(SessionError::Config {
                    field,
                    value: "(missing)".into(),
                    reason: "mutual TLS needs tls_ca, tls_cert and tls_key together".into(),
                });
            };
            std::fs::File::open(path).map_err(|e| SessionError::File {
                field,
                path: path.clone(),
                reason: e.to_string(),
            })?;
        }
        match (&self.tls_ca, &self.tls_cert, &self.tls_key) {
            (Some(ca), Some(cert), Some(key)) => Ok(Some(TlsFiles { ca, cert, key })),
            _ => Ok(None),
        }
    }

    /// The listen endpoints Zenoh gets: those given, or loopback with an OS-chosen port (a
    /// client listens on nothing).
    fn listen_endpoints(&self) -> Vec<String> {
        if self.listen.is_empty() && self.mode == SessionMode::Client {
            Vec::new()
        } else if self.listen.is_empty() {
            let scheme = if self.is_tls() { "tls" } else { "tcp" };
            vec![format!("{scheme}/127.0.0.1:0")]
        } else {
            self.listen.clone()
        }
    }

    /// The Zenoh configuration: peer mode, these endpoints (listening on loopback when none is
    /// given), multicast scouting as asked, mutual TLS and access control when configured.
    ///
    /// # Errors
    /// [`SessionError::Endpoint`] naming the first endpoint Zenoh cannot parse or that does not
    /// match the TLS setting, [`SessionError::File`] for a TLS or rules file that cannot be read,
    /// [`SessionError::Config`] for a setting Zenoh refused.
    pub fn config(&self) -> Result<zenoh::Config, SessionError> {
        let mut config = zenoh::Config::default();
        let tls = self.tls_files()?;
        let listen = self.listen_endpoints();
        for (field, path, endpoints) in [
            ("listen", "listen/endpoints", &listen),
            ("connect", "connect/endpoints", &self.connect),
        ] {
            for endpoint in endpoints {
                let parsed = endpoint.parse::<zenoh::config::EndPoint>().map_err(|e| {
                    SessionError::Endpoint {
                        field,
                        endpoint: endpoint.clone(),
                        reason: e.to_string(),
                    }
                })?;
                let is_tls = parsed.protocol().as_str() == "tls";
                if tls.is_some() != is_tls {
                    return Err(SessionError::Endpoint {
                        field,
                        endpoint: endpoint.clone(),
                        reason: if is_tls {
                            "a tls/ endpoint needs tls_ca, tls_cert and tls_key".into()
                        } else {
                            "mutual TLS is on: every endpoint must be tls/, so that nothing \
                             unauthenticated can connect"
                                .into()
                        },
                    });
                }
            }
            // A client's empty listen list is written out: Zenoh's own default listens on
            // every interface in peer and router mode.
            if endpoints.is_empty() && !(field == "listen" && self.mode == SessionMode::Client) {
                continue;
            }
            let value = serde_json::to_string(endpoints).map_err(|e| SessionError::Config {
                field: path,
                value: format!("{endpoints:?}"),
                reason: e.to_string(),
            })?;
            config
                .insert_json5(path, &value)
                .map_err(|e| SessionError::Config {
                    field: path,
                    value: value.clone(),
                    reason: e.to_string(),
                })?;
        }
        let mode = format!("\"{}\"", self.mode.as_str());
        config
            .insert_json5("mode", &mode)
            .map_err(|e| SessionError::Config {
                field: "mode",
                value: mode.clone(),
                reason: e.to_string(),
            })?;
        let multicast = if self.multicast_scouting {
            "true"
        } else {
            "false"
        };
        config
            .insert_json5("scouting/multicast/enabled", multicast)
            .map_err(|e| SessionError::Config {
                field: "scouting/multicast/enabled",
                value: multicast.into(),
                reason: e.to_string(),
            })?;
        Self::configure_tx_queue(&mut config)?;
        if let Some(tls) = &tls {
            Self::configure_tls(&mut config, tls)?;
        }
        if let Some(path) = &self.acl {
            if tls.is_none() {
                return Err(SessionError::Config {
                    field: "acl",
                    value: path.display().to_string(),
                    reason: "access-control rules match certificate names: they need tls_ca, \
                             tls_cert and tls_key"
                        .into(),
                });
            }
            let rules = std::fs::read_to_string(path).map_err(|e| SessionError::File {
                field: "acl",
                path: path.clone(),
                reason: e.to_string(),
            })?;
            config
                .insert_json5("access_control", &rules)
                .map_err(|e| SessionError::Config {
                    field: "access_control",
                    value: path.display().to_string(),
                    reason: e.to_string(),
                })?;
        }
        Ok(config)
    }

    /// The transmission queue of every link, sized for a fleet: one service answers hundreds
    /// of robots over one link to each router or peer.
    ///
    /// Zenoh's defaults (2 batches per priority, a message dropped after 1 ms without a free
    /// batch) drop about 2 % of the intentions that one service sends to 250 robots at 10 Hz
    /// on two cores: a link's transmit thread that waits over a millisecond for a core is
    /// common there. 8 batches of 64 KiB (allocated when needed) and 10 ms before a drop keep
    /// them; a message that waits longer than that is stale for a 10 Hz loop anyway.
    fn configure_tx_queue(config: &mut zenoh::Config) -> Result<(), SessionError> {
        let settings = [
            ("transport/link/tx/queue/size/data", "8"),
            ("transport/link/tx/queue/size/data_high", "8"),
            (
                "transport/link/tx/queue/congestion_control/drop/wait_before_drop",
                "10000",
            ),
        ];
        for (field, value) in settings {
            config
                .insert_json5(field, value)
                .map_err(|e| SessionError::Config {
                    field,
                    value: value.into(),
                    reason: e.to_string(),
                })?;
        }
        Ok(())
    }

    /// Mutual TLS on both ends of every link: the same certificate listens and connects, and a
    /// peer's name is checked against the endpoint it was reached on.
    fn configure_tls(config: &mut zenoh::Config, tls: &TlsFiles<'_>) -> Result<(), SessionError> {
        let path_value =
            |path: &Path| serde_json::to_string(&path.display().to_string()).unwrap_or_default();
        let settings = [
            ("transport/link/tls/root_ca_certificate", path_value(tls.ca)),
            (
                "transport/link/tls/listen_certificate",
                path_value(tls.cert),
            ),
            ("transport/link/tls/listen_private_key", path_value(tls.key)),
            (
                "transport/link/tls/connect_certificate",
                path_value(tls.cert),
            ),
            (
                "transport/link/tls/connect_private_key",
                path_value(tls.key),
            ),
            ("transport/link/tls/enable_mtls", "true".to_string()),
            (
                "transport/link/tls/verify_name_on_connect",
                "true".to_string(),
            ),
        ];
        for (field, value) in settings {
            config
                .insert_json5(field, &value)
                .map_err(|e| SessionError::Config {
                    field,
                    value: value.clone(),
                    reason: e.to_string(),
                })?;
        }
        Ok(())
    }

    /// The configuration of a Zenoh router with these settings ([`Self::config`] in router
    /// mode): it forwards between every session connected to it, so processes on networks that
    /// cannot reach each other meet through it (docs/deploy.md).
    ///
    /// # Errors
    /// As [`Self::config`].
    pub fn router_config(&self) -> Result<zenoh::Config, SessionError> {
        let mut config = self.config()?;
        config
            .insert_json5("mode", "\"router\"")
            .map_err(|e| SessionError::Config {
                field: "mode",
                value: "router".into(),
                reason: e.to_string(),
            })?;
        Ok(config)
    }

    /// Opens a Zenoh router ([`Self::router_config`]).
    ///
    /// # Errors
    /// As [`Self::open`].
    pub async fn open_router(&self) -> Result<Session, SessionError> {
        zenoh::open(self.router_config()?)
            .await
            .map_err(SessionError::Open)
    }

    /// Opens the session.
    ///
    /// # Errors
    /// As [`Self::config`], or [`SessionError::Open`] when Zenoh cannot start it (e.g. a listen
    /// port in use).
    pub async fn open(&self) -> Result<Session, SessionError> {
        let config = self.config()?;
        if self.listen.is_empty() && self.connect.is_empty() && !self.multicast_scouting {
            tracing::warn!(
                "zenoh session without endpoints and with multicast scouting off: it listens on \
                 loopback only and finds no peers by itself (give --zenoh-connect, \
                 --zenoh-listen or --zenoh-multicast-scouting)"
            );
        }
        zenoh::open(config).await.map_err(SessionError::Open)
    }
}

/// A peer configuration with explicit endpoints and multicast scouting off: shorthand for
/// [`SessionArgs::new`] then [`SessionArgs::config`].
///
/// # Errors
/// As [`SessionArgs::config`].
pub fn peer_config(listen: &[String], connect: &[String]) -> Result<zenoh::Config, SessionError> {
    SessionArgs::new(listen, connect).config()
}

/// The endpoints `session` listens on, e.g. `tcp/127.0.0.1:40123`.
pub async fn locators(session: &Session) -> Vec<String> {
    session
        .info()
        .locators()
        .await
        .iter()
        .map(ToString::to_string)
        .collect()
}

/// Opens a session listening on `127.0.0.1:0` and a second session connected to it: two
/// processes' worth of Zenoh on loopback with an OS-chosen port, for tests and local demos.
///
/// # Errors
/// [`SessionError`] if either session cannot be opened.
pub async fn loopback_pair() -> Result<(Session, Session), SessionError> {
    let listener = SessionArgs::new(&["tcp/127.0.0.1:0".to_string()], &[])
        .open()
        .await?;
    let endpoints = locators(&listener).await;
    if endpoints.is_empty() {
        return Err(SessionError::NoLocator);
    }
    let connected = SessionArgs::new(&[], &endpoints).open().await?;
    Ok((listener, connected))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::messages::{CameraFrame, CmdVel, Intention, MapGrid, PoseEstimate};

    #[test]
    fn encodings() {
        assert_eq!(encoding_for::<CmdVel>(), Encoding::APPLICATION_JSON);
        assert_eq!(encoding_for::<PoseEstimate>(), Encoding::APPLICATION_JSON);
        assert_eq!(
            encoding_for::<CameraFrame>().to_string(),
            "application/octet-stream;intention-fleet/camera"
        );
        assert_eq!(
            encoding_for::<Intention>(),
            Encoding::APPLICATION_OCTET_STREAM.with_schema("intention-fleet/intention")
        );
        assert_eq!(
            encoding_for::<MapGrid>(),
            Encoding::APPLICATION_OCTET_STREAM.with_schema("intention-fleet/map_grid")
        );
    }
}

#[cfg(test)]
mod session_args_tests {
    // Test code: a failed unwrap is a failed test.
    #![allow(clippy::unwrap_used)]

    use super::*;

    fn json(config: &zenoh::Config, key: &str) -> serde_json::Value {
        serde_json::from_str(&config.get_json(key).unwrap()).unwrap()
    }

    #[test]
    fn multicast_scouting_is_off_by_default() {
        let args = SessionArgs::default();
        assert!(!args.multicast_scouting);
        let config = args.config().unwrap();
        assert_eq!(
            json(&config, "scouting/multicast/enabled"),
            serde_json::Value::Bool(false)
        );
        let on = SessionArgs {
            multicast_scouting: true,
            ..SessionArgs::default()
        };
        assert_eq!(
            json(&on.config().unwrap(), "scouting/multicast/enabled"),
            serde_json::Value::Bool(true)
        );
    }

    /// Every session, the router's too, keeps a droppable message up to 10 ms for a free
    /// batch of its link's eight (Zenoh's defaults: 1 ms, two batches).
    #[test]
    fn links_queue_eight_batches_and_drop_after_ten_ms() {
        for config in [
            SessionArgs::default().config().unwrap(),
            SessionArgs::default().router_config().unwrap(),
        ] {
            let queue = "transport/link/tx/queue";
            assert_eq!(json(&config, &format!("{queue}/size/data")), 8);
            assert_eq!(json(&config, &format!("{queue}/size/data_high")), 8);
            assert_eq!(
                json(
                    &config,
                    &format!("{queue}/congestion_control/drop/wait_before_drop")
                ),
                10_000
            );
        }
    }

    /// A client behind a router listens on nothing and says it is a client; the router
    /// configuration is the same settings in router mode; a file's `mode` reads as text.
    #[test]
    fn client_and_router_modes() {
        let peer = SessionArgs::default().config().unwrap();
        assert_eq!(json(&peer, "mode"), serde_json::json!("peer"));
        let client = SessionArgs {
            connect: vec!["tcp/10.0.0.1:7447".into()],
            mode: SessionMode::Client,
            ..SessionArgs::default()
        };
        let config = client.config().unwrap();
        assert_eq!(json(&config, "mode"), serde_json::json!("client"));
        assert_eq!(json(&config, "listen/endpoints"), serde_json::json!([]));
        let router = SessionArgs::new(&["tcp/0.0.0.0:7447".into()], &[])
            .router_config()
            .unwrap();
        assert_eq!(json(&router, "mode"), serde_json::json!("router"));
        let parsed: SessionArgs = serde_json::from_str(r#"{"mode": "client"}"#).unwrap();
        assert_eq!(parsed.mode, SessionMode::Client);
        assert!(serde_json::from_str::<SessionArgs>(r#"{"mode": "router"}"#).is_err());
    }

    #[test]
    fn listen_and_connect_endpoints_are_set() {
        let args = SessionArgs::new(
            &["tcp/127.0.0.1:7447".to_string()],
            &[
                "tcp/10.0.0.2:7447".to_string(),
                "udp/10.0.0.3:7447".to_string(),
            ],
        );
        let config = args.config().unwrap();
        let listen = json(&config, "listen/endpoints").to_string();
        let connect = json(&config, "connect/endpoints").to_string();
        assert!(listen.contains("tcp/127.0.0.1:7447"), "{listen}");
        assert!(connect.contains("tcp/10.0.0.2:7447"), "{connect}");
        assert!(connect.contains("udp/10.0.0.3:7447"), "{connect}");
        // The shorthand builds the same configuration.
        let short = peer_config(&args.listen, &args.connect).unwrap();
        assert_eq!(
            short.get_json("connect/endpoints").unwrap(),
            config.get_json("connect/endpoints").unwrap()
        );
    }

    #[test]
    fn a_bad_endpoint_is_an_error_naming_it() {
        let args = SessionArgs::new(
            &["tcp/127.0.0.1:7447".to_string()],
            &["nonsense".to_string()],
        );
        let err = args.config().unwrap_err();
        assert!(
            matches!(&err, SessionError::Endpoint { field: "connect", endpoint, .. } if endpoint == "nonsense"),
            "{err:?}"
        );
        let text = err.to_string();
        assert!(
            text.contains("connect") && text.contains("nonsense"),
            "{text}"
        );
        let err = SessionArgs::new(&["tcp-no-address".to_string()], &[])
            .config()
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("listen") && err.contains("tcp-no-address"),
            "{err}"
        );
    }

    #[test]
    fn flags_override_the_file() {
        let mut file = SessionArgs::new(
            &["tcp/0.0.0.0:7447".to_string()],
            &["tcp/10.0.0.2:7447".to_string()],
        );
        file.override_with(&SessionArgs::default());
        assert_eq!(file.listen, ["tcp/0.0.0.0:7447"]);
        assert!(!file.multicast_scouting);
        file.override_with(&SessionArgs {
            listen: vec![],
            connect: vec!["tcp/10.0.0.9:7447".to_string()],
            multicast_scouting: true,
            ..SessionArgs::default()
        });
        assert_eq!(file.listen, ["tcp/0.0.0.0:7447"]);
        assert_eq!(file.connect, ["tcp/10.0.0.9:7447"]);
        assert!(file.multicast_scouting);
    }

    #[test]
    fn file_keys_are_listen_connect_and_multicast() {
        let args: SessionArgs =
            serde_json::from_str(r#"{"listen":["tcp/0.0.0.0:7448"],"multicast":true}"#).unwrap();
        assert_eq!(args.listen, ["tcp/0.0.0.0:7448"]);
        assert!(args.multicast_scouting && args.connect.is_empty());
        let alias: SessionArgs = serde_json::from_str(r#"{"multicast_scouting":true}"#).unwrap();
        assert!(alias.multicast_scouting);
        assert!(serde_json::from_str::<SessionArgs>(r#"{"lisen":[]}"#).is_err());
    }

    #[cfg(feature = "cli")]
    #[test]
    fn every_binary_gets_the_same_flags() {
        use clap::{CommandFactory, Parser};

        #[derive(Debug, Parser)]
        struct Cli {
            #[command(flatten)]
            zenoh: SessionArgs,
        }
        Cli::command().debug_assert();
        let cli = Cli::try_parse_from(["x"]).unwrap();
        assert_eq!(cli.zenoh, SessionArgs::default());
        let cli = Cli::try_parse_from([
            "x",
            "--zenoh-listen",
            "tcp/0.0.0.0:7447",
            "--zenoh-connect",
            "tcp/10.0.0.2:7447",
            "--zenoh-connect",
            "tcp/10.0.0.3:7447",
            "--zenoh-multicast-scouting",
        ])
        .unwrap();
        assert_eq!(cli.zenoh.listen, ["tcp/0.0.0.0:7447"]);
        assert_eq!(cli.zenoh.connect.len(), 2);
        assert!(cli.zenoh.multicast_scouting);
    }
}
