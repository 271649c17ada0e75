//! The one encode/decode pair of the fleet, with an explicit wire version.
//!
//! Two forms, fixed per message kind (see [`WireMessage::FRAMED`]):
//!
//! * **JSON** (structured messages): the UTF-8 JSON object
//!   `{"wire_version":1,"kind":"pose","msg":{…}}`.
//! * **Framed** (messages with a byte blob: camera, intention, map grid):
//!
//!   | bytes | content |
//!   |---|---|
//!   | 4 | magic `IFLT` |
//!   | 2 | wire version, u16 little-endian |
//!   | 4 | header length `H`, u32 little-endian |
//!   | H | JSON envelope `{"wire_version":1,"kind":"camera","blob_len":N,"msg":{…}}` (blob fields left out) |
//!   | N | the raw blob bytes (image data, LPE image data, or map cells) |
//!
//! The version is checked first, before anything else is interpreted, so a future version may
//! change everything after it; a receiver gets [`DecodeError::UnsupportedVersion`] with both
//! versions named. Messages are validated on encode and on decode.

use std::collections::BTreeMap;

use serde::de::DeserializeOwned;
use serde::Serialize;
use serde_json::value::RawValue;

use crate::messages::{
    AgentStatus, CameraFrame, CmdVel, Intention, LaserScan, MapGrid, MapMeta, Odometry,
    PoseEstimate, TaskEvent, ValidationError,
};

/// The wire version this build speaks; bump on any incompatible change of the encoding or of a
/// message's fields.
pub const WIRE_VERSION: u16 = 1;

/// First bytes of a framed message.
pub const FRAME_MAGIC: [u8; 4] = *b"IFLT";

/// Bytes before the JSON header of a framed message: magic, version, header length.
pub const FRAME_PREFIX_LEN: usize = 4 + 2 + 4;

/// Prefix of the Zenoh encoding schema of framed messages (`intention-fleet/<kind>`).
pub const SCHEMA_PREFIX: &str = "intention-fleet/";

/// A message that can travel on the wire.
///
/// JSON-only messages only name their kind (and usually forward `validate`). Messages with a blob
/// keep it in `#[serde(skip)]` fields, set `FRAMED`, expose it through [`blob`](Self::blob) for
/// encoding and take it back through [`put_blob`](Self::put_blob) after the JSON part is decoded.
pub trait WireMessage: Serialize + DeserializeOwned {
    /// The `kind` string in the envelope.
    const KIND: &'static str;
    /// Whether this kind is sent framed (binary prefix + JSON header + blob).
    const FRAMED: bool = false;

    /// The blob to send after the JSON header (framed kinds only).
    fn blob(&self) -> Option<&[u8]> {
        None
    }

    /// Restores the blob into the message decoded from the JSON header.
    fn put_blob(&mut self, blob: Vec<u8>) -> Result<(), ValidationError> {
        if blob.is_empty() {
            Ok(())
        } else {
            Err(ValidationError::new(
                "blob",
                format!(
                    "kind {} carries no blob, got {} bytes",
                    Self::KIND,
                    blob.len()
                ),
            ))
        }
    }

    /// Invariants checked on encode and decode.
    fn validate(&self) -> Result<(), ValidationError> {
        Ok(())
    }
}

/// Why a message could not be encoded.
#[derive(Debug, thiserror::Error)]
pub enum EncodeError {
    #[error("cannot encode {kind}: {source}")]
    Invalid {
        kind: &'static str,
        #[source]
        source: ValidationError,
    },
    #[error("cannot encode {kind} as JSON: {source}")]
    Json {
        kind: &'static str,
        #[source]
        source: serde_json::Error,
    },
    #[error("cannot encode {kind}: {what} is {len} bytes, the frame allows at most {max}")]
    TooLarge {
        kind: &'static str,
        what: &'static str,
        len: usize,
        max: usize,
    },
}

/// Why received bytes were rejected.
#[derive(Debug, thiserror::Error)]
pub enum DecodeError {
    #[error("unsupported wire version {got} (this build speaks {supported})")]
    UnsupportedVersion { got: u16, supported: u16 },
    #[error("wrong message kind: expected {expected}, got {got:?}")]
    WrongKind { expected: &'static str, got: String },
    #[error("truncated message: needed {needed} bytes, got {got}")]
    Truncated { needed: usize, got: usize },
    #[error("bad magic: neither a JSON envelope nor an IFLT frame")]
    BadMagic,
    #[error("malformed JSON: {0}")]
    Json(#[from] serde_json::Error),
    #[error("invalid {field}: {reason}")]
    Invalid { field: &'static str, reason: String },
}

impl From<ValidationError> for DecodeError {
    fn from(e: ValidationError) -> Self {
        DecodeError::Invalid {
            field: e.field,
            reason: e.reason,
        }
    }
}

#[derive(Serialize)]
struct EnvelopeOut<'a, M> {
    wire_version: u16,
    kind: &'static str,
    #[serde(skip_serializing_if = "Option::is_none")]
    blob_len: Option<u64>,
    msg: &'a M,
}

/// Encodes `msg` in the form its kind uses (JSON or framed).
pub fn encode<M: WireMessage>(msg: &M) -> Result<Vec<u8>, EncodeError> {
    msg.validate().map_err(|source| EncodeError::Invalid {
        kind: M::KIND,
        source,
    })?;
    let json_err = |source| EncodeError::Json {
        kind: M::KIND,
        source,
    };
    if !M::FRAMED {
        let envelope = EnvelopeOut {
            wire_version: WIRE_VERSION,
            kind: M::KIND,
            blob_len: None,
            msg,
        };
        return serde_json::to_vec(&envelope).map_err(json_err);
    }
    let blob = msg.blob().unwrap_or_default();
    let envelope = EnvelopeOut {
        wire_version: WIRE_VERSION,
        kind: M::KIND,
        blob_len: Some(blob.len() as u64),
        msg,
    };
    let header = serde_json::to_vec(&envelope).map_err(json_err)?;
    let header_len = u32::try_from(header.len()).map_err(|_| EncodeError::TooLarge {
        kind: M::KIND,
        what: "JSON header",
        len: header.len(),
        max: u32::MAX as usize,
    })?;
    let mut out = Vec::with_capacity(FRAME_PREFIX_LEN + header.len() + blob.len());
    out.extend_from_slice(&FRAME_MAGIC);
    out.extend_from_slice(&WIRE_VERSION.to_le_bytes());
    out.extend_from_slice(&header_len.to_le_bytes());
    out.extend_from_slice(&header);
    out.extend_from_slice(blob);
    Ok(out)
}

/// Decodes and validates a message of kind `M::KIND`.
pub fn decode<M: WireMessage>(bytes: &[u8]) -> Result<M, DecodeError> {
    if bytes.starts_with(&FRAME_MAGIC) {
        return decode_framed(bytes);
    }
    match bytes.iter().find(|b| !b.is_ascii_whitespace()) {
        Some(b'{') => decode_json(bytes),
        // A frame cut inside its magic is still recognisably a frame.
        _ if !bytes.is_empty() && FRAME_MAGIC.starts_with(bytes) => Err(DecodeError::Truncated {
            needed: FRAME_PREFIX_LEN,
            got: bytes.len(),
        }),
        None if bytes.is_empty() => Err(DecodeError::Truncated { needed: 1, got: 0 }),
        _ => Err(DecodeError::BadMagic),
    }
}

/// Reads the wire version and kind of an encoded message without decoding its body, e.g. for
/// logging or routing by kind.
pub fn peek_kind(bytes: &[u8]) -> Result<(u16, String), DecodeError> {
    let header: &[u8] = if bytes.starts_with(&FRAME_MAGIC) {
        let (version, header, _) = split_frame(bytes)?;
        if version != WIRE_VERSION {
            return Err(DecodeError::UnsupportedVersion {
                got: version,
                supported: WIRE_VERSION,
            });
        }
        header
    } else {
        bytes
    };
    let fields = envelope_fields(header)?;
    let version = read_version(&fields)?;
    let kind = read_kind(&fields)?;
    Ok((version, kind))
}

fn decode_json<M: WireMessage>(bytes: &[u8]) -> Result<M, DecodeError> {
    let fields = envelope_fields(bytes)?;
    let (msg, blob_len) = open_envelope::<M>(&fields)?;
    if M::FRAMED {
        return Err(DecodeError::Invalid {
            field: "framing",
            reason: format!(
                "kind {} must be sent as an IFLT frame, got plain JSON",
                M::KIND
            ),
        });
    }
    if blob_len.is_some() {
        return Err(DecodeError::Invalid {
            field: "blob_len",
            reason: "a JSON envelope carries no blob".to_string(),
        });
    }
    let msg: M = serde_json::from_str(msg.get())?;
    msg.validate()?;
    Ok(msg)
}

/// Splits a frame into (version, JSON header, blob), checking the version before anything else.
fn split_frame(bytes: &[u8]) -> Result<(u16, &[u8], &[u8]), DecodeError> {
    if bytes.len() < FRAME_PREFIX_LEN {
        return Err(DecodeError::Truncated {
            needed: FRAME_PREFIX_LEN,
            got: bytes.len(),
        });
    }
    let version = u16::from_le_bytes([bytes[4], bytes[5]]);
    if version != WIRE_VERSION {
        return Err(DecodeError::UnsupportedVersion {
            got: version,
            supported: WIRE_VERSION,
        });
    }
    let header_len = u32::from_le_bytes([bytes[6], bytes[7], bytes[8], bytes[9]]) as usize;
    let header_end = FRAME_PREFIX_LEN.saturating_add(header_len);
    if bytes.len() < header_end {
        return Err(DecodeError::Truncated {
            needed: header_end,
            got: bytes.len(),
        });
    }
    Ok((
        version,
        &bytes[FRAME_PREFIX_LEN..header_end],
        &bytes[header_end..],
    ))
}

fn decode_framed<M: WireMessage>(bytes: &[u8]) -> Result<M, DecodeError> {
    let (_, header, blob) = split_frame(bytes)?;
    let fields = envelope_fields(header)?;
    let (msg, blob_len) = open_envelope::<M>(&fields)?;
    if !M::FRAMED {
        return Err(DecodeError::Invalid {
            field: "framing",
            reason: format!(
                "kind {} must be sent as plain JSON, got an IFLT frame",
                M::KIND
            ),
        });
    }
    let blob_len = blob_len.ok_or_else(|| DecodeError::Invalid {
        field: "blob_len",
        reason: "missing from the frame header".to_string(),
    })?;
    let blob_len = usize::try_from(blob_len).map_err(|_| DecodeError::Invalid {
        field: "blob_len",
        reason: format!("{blob_len} does not fit this platform"),
    })?;
    if blob.len() < blob_len {
        return Err(DecodeError::Truncated {
            needed: (bytes.len() - blob.len()).saturating_add(blob_len),
            got: bytes.len(),
        });
    }
    if blob.len() > blob_len {
        return Err(DecodeError::Invalid {
            field: "blob_len",
            reason: format!(
                "{} trailing bytes after the {blob_len}-byte blob",
                blob.len() - blob_len
            ),
        });
    }
    let mut msg: M = serde_json::from_str(msg.get())?;
    msg.put_blob(blob.to_vec())?;
    msg.validate()?;
    Ok(msg)
}

/// The envelope's fields, each still its raw JSON text: the version and kind are checked before
/// the message is interpreted, and the message is then parsed once, straight into its type.
type EnvelopeFields<'a> = BTreeMap<String, &'a RawValue>;

fn envelope_fields(bytes: &[u8]) -> Result<EnvelopeFields<'_>, DecodeError> {
    if bytes.iter().find(|b| !b.is_ascii_whitespace()) != Some(&b'{') {
        return Err(DecodeError::Invalid {
            field: "envelope",
            reason: "not a JSON object".to_string(),
        });
    }
    Ok(serde_json::from_slice(bytes)?)
}

/// A field's JSON as `T`, `None` when it is not a `T`.
fn field_as<'a, T: serde::Deserialize<'a>>(fields: &EnvelopeFields<'a>, name: &str) -> Option<T> {
    fields
        .get(name)
        .and_then(|raw| serde_json::from_str(raw.get()).ok())
}

fn read_version(fields: &EnvelopeFields<'_>) -> Result<u16, DecodeError> {
    let raw: u64 = field_as(fields, "wire_version").ok_or_else(|| DecodeError::Invalid {
        field: "wire_version",
        reason: "missing or not an unsigned integer".to_string(),
    })?;
    let got = u16::try_from(raw).map_err(|_| DecodeError::Invalid {
        field: "wire_version",
        reason: format!("{raw} is out of range (this build speaks {WIRE_VERSION})"),
    })?;
    if got != WIRE_VERSION {
        return Err(DecodeError::UnsupportedVersion {
            got,
            supported: WIRE_VERSION,
        });
    }
    Ok(got)
}

fn read_kind(fields: &EnvelopeFields<'_>) -> Result<String, DecodeError> {
    field_as(fields, "kind").ok_or_else(|| DecodeError::Invalid {
        field: "kind",
        reason: "missing or not a string".to_string(),
    })
}

/// Checks version, kind and envelope shape; returns the raw `msg` and `blob_len`.
fn open_envelope<'a, M: WireMessage>(
    fields: &EnvelopeFields<'a>,
) -> Result<(&'a RawValue, Option<u64>), DecodeError> {
    // Version before kind: a newer version may have renamed kinds.
    read_version(fields)?;
    let kind = read_kind(fields)?;
    if kind != M::KIND {
        return Err(DecodeError::WrongKind {
            expected: M::KIND,
            got: kind,
        });
    }
    if let Some(unknown) = fields
        .keys()
        .find(|k| !matches!(k.as_str(), "wire_version" | "kind" | "blob_len" | "msg"))
    {
        return Err(DecodeError::Invalid {
            field: "envelope",
            reason: format!("unknown field {unknown:?}"),
        });
    }
    let blob_len = match fields.get("blob_len") {
        None => None,
        Some(raw) => Some(
            serde_json::from_str(raw.get()).map_err(|_| DecodeError::Invalid {
                field: "blob_len",
                reason: "not an unsigned integer".to_string(),
            })?,
        ),
    };
    let msg = fields
        .get("msg")
        .copied()
        .ok_or_else(|| DecodeError::Invalid {
            field: "msg",
            reason: "missing".to_string(),
        })?;
    Ok((msg, blob_len))
}

macro_rules! json_message {
    ($ty:ty, $kind:literal) => {
        impl WireMessage for $ty {
            const KIND: &'static str = $kind;
            fn validate(&self) -> Result<(), ValidationError> {
                <$ty>::validate(self)
            }
        }
    };
}

json_message!(LaserScan, "scan");
json_message!(Odometry, "odom");
json_message!(CmdVel, "cmd_vel");
json_message!(PoseEstimate, "pose");
json_message!(AgentStatus, "status");
json_message!(MapMeta, "map_meta");

impl WireMessage for TaskEvent {
    const KIND: &'static str = "task_event";
}

impl WireMessage for CameraFrame {
    const KIND: &'static str = "camera";
    const FRAMED: bool = true;

    fn blob(&self) -> Option<&[u8]> {
        Some(&self.image.data)
    }

    fn put_blob(&mut self, blob: Vec<u8>) -> Result<(), ValidationError> {
        self.image.data = blob;
        Ok(())
    }

    fn validate(&self) -> Result<(), ValidationError> {
        self.image.validate()
    }
}

impl WireMessage for Intention {
    const KIND: &'static str = "intention";
    const FRAMED: bool = true;

    /// The LPE image bytes; an intention without LPE has an empty blob.
    fn blob(&self) -> Option<&[u8]> {
        self.lpe.as_ref().map(|image| image.data.as_slice())
    }

    fn put_blob(&mut self, blob: Vec<u8>) -> Result<(), ValidationError> {
        match &mut self.lpe {
            Some(image) => {
                image.data = blob;
                Ok(())
            }
            None if blob.is_empty() => Ok(()),
            None => Err(ValidationError::new(
                "lpe",
                format!(
                    "no LPE image described, but {} blob bytes follow",
                    blob.len()
                ),
            )),
        }
    }

    fn validate(&self) -> Result<(), ValidationError> {
        Intention::validate(self)
    }
}

impl WireMessage for MapGrid {
    const KIND: &'static str = "map_grid";
    const FRAMED: bool = true;

    fn blob(&self) -> Option<&[u8]> {
        Some(&self.cells)
    }

    fn put_blob(&mut self, blob: Vec<u8>) -> Result<(), ValidationError> {
        self.cells = blob;
        Ok(())
    }

    fn validate(&self) -> Result<(), ValidationError> {
        MapGrid::validate(self)
    }
}
