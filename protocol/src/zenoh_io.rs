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
