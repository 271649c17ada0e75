//! Why a fleet operation was refused or failed, and how the HTTP layer should answer it.

use map_store::MapError;
use planning::PlanError;

use super::store::StoreError;

/// How the HTTP layer should answer a [`FleetError`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ErrorKind {
    BadRequest,
    NotFound,
    Conflict,
    Internal,
}

/// Why a fleet operation was refused or failed; nothing was changed.
#[derive(Debug, thiserror::Error)]
pub enum FleetError {
    #[error("invalid {field} = {value}: {reason}")]
    Invalid {
        field: String,
        value: String,
        reason: String,
    },
    #[error("no {what} {id}")]
    NotFound { what: &'static str, id: String },
    #[error("{0}")]
    Conflict(String),
    #[error(transparent)]
    Store(#[from] StoreError),
    #[error(transparent)]
    Map(#[from] MapError),
    #[error("planning map {map}: {source}")]
    Planning {
        map: String,
        #[source]
        source: PlanError,
    },
    #[error("invalid configuration: {0}")]
    Config(String),
    #[error("zenoh {action}: {reason}")]
    Zenoh {
        action: &'static str,
        reason: String,
    },
}

impl FleetError {
    #[must_use]
    pub fn kind(&self) -> ErrorKind {
        match self {
            FleetError::Invalid { .. } => ErrorKind::BadRequest,
            FleetError::NotFound { .. }
            | FleetError::Store(StoreError::NotFound(_))
            | FleetError::Map(MapError::NotFound { .. }) => ErrorKind::NotFound,
            FleetError::Conflict(_) => ErrorKind::Conflict,
            _ => ErrorKind::Internal,
        }
    }

    /// A map the map store does not have, named as the caller asked for it.
    pub(super) fn from_map(e: MapError, id: impl FnOnce() -> String) -> Self {
        match e {
            MapError::NotFound { .. } => FleetError::NotFound {
                what: "map",
                id: id(),
            },
            other => FleetError::Map(other),
        }
    }
}

pub(super) fn zenoh_err(action: &'static str) -> impl FnOnce(zenoh::Error) -> FleetError {
    move |e| FleetError::Zenoh {
        action,
        reason: e.to_string(),
    }
}
