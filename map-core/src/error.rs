//! Errors of the map store: each names the field or file and the offending value.

use std::path::PathBuf;

/// Everything that can go wrong importing, storing, exporting or serving a map.
#[derive(Debug, thiserror::Error)]
pub enum MapError {
    /// A value that parsed but is not acceptable.
    #[error("invalid {field} = {value}: {reason}")]
    Invalid {
        field: &'static str,
        value: String,
        reason: String,
    },

    /// A required field is absent from a map description.
    #[error("missing field `{field}` in {path}")]
    MissingField { field: &'static str, path: PathBuf },

    /// A file could not be read or written.
    #[error("cannot access {path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },

    /// The map YAML is not YAML, or not a mapping.
    #[error("cannot parse map YAML {path}: {reason}")]
    Yaml { path: PathBuf, reason: String },

    /// The image could not be decoded (unknown format, truncated, corrupt).
    #[error("cannot decode image {path}: {reason}")]
    Image { path: PathBuf, reason: String },

    /// The image exceeds a configured limit; raised before decoding the pixels.
    #[error("image {path} too large: {field} = {value} exceeds the limit {limit}")]
    TooLarge {
        path: PathBuf,
        field: &'static str,
        value: u64,
        limit: u64,
    },

    /// The embedded database failed (open, transaction, commit) or holds something unreadable.
    #[error("map database {action} failed: {reason}")]
    Store {
        action: &'static str,
        reason: String,
    },

    /// No stored map matches the request.
    #[error("no map {what}")]
    NotFound { what: String },

    /// A map id or name that the protocol's id rules reject.
    #[error(transparent)]
    Id(#[from] protocol::IdError),

    /// A map store answered a query with an error (unknown map, bad key).
    #[error("map store refused {key}: {reason}")]
    Remote { key: String, reason: String },

    /// Serving or fetching a map over Zenoh failed.
    #[error("zenoh {action} failed: {reason}")]
    Zenoh {
        action: &'static str,
        reason: String,
    },
}

impl MapError {
    /// Shorthand for [`MapError::Invalid`].
    pub fn invalid(
        field: &'static str,
        value: impl std::fmt::Display,
        reason: impl Into<String>,
    ) -> Self {
        Self::Invalid {
            field,
            value: value.to_string(),
            reason: reason.into(),
        }
    }

    /// Wraps a database error with what the store was doing.
    pub fn store(action: &'static str, e: impl std::fmt::Display) -> Self {
        Self::Store {
            action,
            reason: e.to_string(),
        }
    }

    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Self::Io {
            path: path.into(),
            source,
        }
    }
}
