//! Glue between the codec and Zenoh: encodings, publishing, replying and decoding samples.
//!
//! Publishers declare what they send through the Zenoh `Encoding`: JSON kinds are
//! `application/json`, framed kinds `application/octet-stream` with schema
//! `intention-fleet/<kind>`, so tools on the wire can tell payloads apart without decoding them.

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
    #[error("invalid zenoh {field} = {value}: {reason}")]
    Config {
        field: &'static str,
        value: String,
        reason: String,
    },
    #[error("cannot open zenoh session: {0}")]
    Open(zenoh::Error),
    #[error("zenoh session listens on no locator")]
    NoLocator,
}

/// A peer configuration with explicit endpoints and multicast scouting off.
///
/// Fleet processes find each other through the endpoints they are given (a router between
/// hosts, loopback on one host), never by multicast, so a test or a demo cannot pick up a
/// stranger's session on the same network.
///
/// # Errors
/// [`SessionError::Config`] naming the endpoint list that Zenoh refused.
pub fn peer_config(listen: &[String], connect: &[String]) -> Result<zenoh::Config, SessionError> {
    let mut config = zenoh::Config::default();
    for (field, endpoints) in [("listen/endpoints", listen), ("connect/endpoints", connect)] {
        if endpoints.is_empty() {
            continue;
        }
        let value = serde_json::to_string(endpoints).map_err(|e| SessionError::Config {
            field,
            value: format!("{endpoints:?}"),
            reason: e.to_string(),
        })?;
        config
            .insert_json5(field, &value)
            .map_err(|e| SessionError::Config {
                field,
                value: value.clone(),
                reason: e.to_string(),
            })?;
    }
    config
        .insert_json5("scouting/multicast/enabled", "false")
        .map_err(|e| SessionError::Config {
            field: "scouting/multicast/enabled",
            value: "false".into(),
            reason: e.to_string(),
        })?;
    Ok(config)
}

/// Opens a session listening on `127.0.0.1:0` and a second session connected to it: two
/// processes' worth of Zenoh on loopback with an OS-chosen port, for tests and local demos.
///
/// # Errors
/// [`SessionError`] if either session cannot be opened.
pub async fn loopback_pair() -> Result<(Session, Session), SessionError> {
    let listener = zenoh::open(peer_config(&["tcp/127.0.0.1:0".to_string()], &[])?)
        .await
        .map_err(SessionError::Open)?;
    let endpoints: Vec<String> = listener
        .info()
        .locators()
        .await
        .iter()
        .map(ToString::to_string)
        .collect();
    if endpoints.is_empty() {
        return Err(SessionError::NoLocator);
    }
    let connected = zenoh::open(peer_config(&[], &endpoints)?)
        .await
        .map_err(SessionError::Open)?;
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
