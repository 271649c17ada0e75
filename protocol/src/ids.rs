//! Validated identifiers that each fit exactly one Zenoh key-expression chunk.
//!
//! Every id that ends up inside a key expression (`fleet/<site>/robot/<robot_id>/…`) is a newtype
//! that can only be built through validation, so the `keys` module can assemble key expressions
//! without any runtime failure path and nobody can smuggle a `/`, `*` or `$` into a key.
//!
//! The accepted form is 1..=64 characters of `[A-Za-z0-9_.-]`, not starting with `.` (which also
//! rules out `.` and `..`). [`MapName`] is shorter (51 characters) so that the content-addressed
//! [`MapId`] `<name>-<12 hex>` built from it always fits the same 64-character limit.

use std::borrow::Borrow;
use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

/// Longest id accepted, in characters (all accepted characters are ASCII, so also bytes).
pub const MAX_ID_LEN: usize = 64;

/// Hex characters of the content hash that make a [`MapId`] unique.
pub const MAP_ID_HASH_LEN: usize = 12;

/// Longest map name: leaves room for `-` and the hash in a [`MapId`].
pub const MAX_MAP_NAME_LEN: usize = MAX_ID_LEN - 1 - MAP_ID_HASH_LEN;

/// Why a candidate id was rejected.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum IdRejection {
    Empty,
    TooLong {
        len: usize,
        max: usize,
    },
    BadChar {
        ch: char,
        position: usize,
    },
    LeadingDot,
    /// Only for [`MapId::from_name_and_hash`]: the hash is not at least 12 hex digits.
    BadHash {
        reason: String,
    },
}

impl fmt::Display for IdRejection {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Empty => f.write_str("must not be empty"),
            Self::TooLong { len, max } => {
                write!(f, "is {len} characters long, at most {max} are allowed")
            }
            Self::BadChar { ch, position } => write!(
                f,
                "character {ch:?} at position {position} is not allowed (use A-Z a-z 0-9 _ . -)"
            ),
            Self::LeadingDot => f.write_str("must not start with '.'"),
            Self::BadHash { reason } => write!(f, "bad content hash: {reason}"),
        }
    }
}

/// A rejected id: which field it was meant for, the offending value and why.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("invalid {kind} {value:?}: {reason}")]
pub struct IdError {
    /// The id's field name, e.g. `"robot_id"`.
    pub kind: &'static str,
    pub value: String,
    pub reason: IdRejection,
}

/// Checks `value` against the key-chunk rules; `max_len` is per id type.
fn validate(value: &str, max_len: usize) -> Result<(), IdRejection> {
    if value.is_empty() {
        return Err(IdRejection::Empty);
    }
    let len = value.chars().count();
    if len > max_len {
        return Err(IdRejection::TooLong { len, max: max_len });
    }
    if let Some((position, ch)) = value
        .chars()
        .enumerate()
        .find(|(_, c)| !(c.is_ascii_alphanumeric() || matches!(c, '_' | '.' | '-')))
    {
        return Err(IdRejection::BadChar { ch, position });
    }
    // A leading dot would allow "." and "..", which read as path navigation to humans and tools.
    if value.starts_with('.') {
        return Err(IdRejection::LeadingDot);
    }
    Ok(())
}

macro_rules! define_id {
    ($(#[$meta:meta])* $name:ident, $kind:literal, $max:expr) => {
        $(#[$meta])*
        #[derive(Debug, Clone, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
        #[serde(try_from = "String", into = "String")]
        pub struct $name(String);

        impl $name {
            /// Field name used in errors.
            pub const KIND: &'static str = $kind;
            /// Longest accepted value, in characters.
            pub const MAX_LEN: usize = $max;

            /// Validates and wraps `value`.
            pub fn new(value: impl Into<String>) -> Result<Self, IdError> {
                let value = value.into();
                match validate(&value, Self::MAX_LEN) {
                    Ok(()) => Ok(Self(value)),
                    Err(reason) => Err(IdError { kind: Self::KIND, value, reason }),
                }
            }

            pub fn as_str(&self) -> &str {
                &self.0
            }

            pub fn into_string(self) -> String {
                self.0
            }
        }

        impl fmt::Display for $name {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                // `pad` honours width and alignment, so ids line up in tables.
                f.pad(&self.0)
            }
        }

        impl FromStr for $name {
            type Err = IdError;
            fn from_str(s: &str) -> Result<Self, Self::Err> {
                Self::new(s)
            }
        }

        impl TryFrom<String> for $name {
            type Error = IdError;
            fn try_from(value: String) -> Result<Self, Self::Error> {
                Self::new(value)
            }
        }

        impl TryFrom<&str> for $name {
            type Error = IdError;
            fn try_from(value: &str) -> Result<Self, Self::Error> {
                Self::new(value)
            }
        }

        impl From<$name> for String {
            fn from(id: $name) -> String {
                id.0
            }
        }

        impl AsRef<str> for $name {
            fn as_ref(&self) -> &str {
                &self.0
            }
        }

        // Derived Hash/Eq/Ord delegate to the inner String, so they agree with str's: maps keyed
        // by the id can be looked up with a plain &str.
        impl Borrow<str> for $name {
            fn borrow(&self) -> &str {
                &self.0
            }
        }
    };
}

define_id!(
    /// A site (building / deployment); the second chunk of every key expression.
    SiteId,
    "site_id",
    MAX_ID_LEN
);
define_id!(
    /// One robot of the fleet.
    RobotId,
    "robot_id",
    MAX_ID_LEN
);
define_id!(
    /// A floor plan's human-chosen name; its versions share it.
    MapName,
    "map_name",
    MAX_MAP_NAME_LEN
);
define_id!(
    /// The content-addressed id of one stored map version: `<name>-<12 hex chars of sha256>`.
    MapId,
    "map_id",
    MAX_ID_LEN
);
define_id!(
    /// A delivery task; made by the planner service.
    TaskId,
    "task_id",
    MAX_ID_LEN
);
define_id!(
    /// A replanning worker process (`planner-service worker`).
    WorkerId,
    "worker_id",
    MAX_ID_LEN
);

impl SiteId {
    /// The site every process uses when none is configured.
    pub const DEFAULT: &'static str = "default";
}

impl Default for SiteId {
    /// `default`: one building needs no site configuration.
    fn default() -> Self {
        Self(Self::DEFAULT.to_string())
    }
}

impl MapId {
    /// Builds `<name>-<first 12 hex chars of hash_hex>` (lower-cased).
    ///
    /// `hash_hex` is the hex digest of the map content (sha256 in the map store); it must have at
    /// least 12 hex digits. Because [`MapName`] is at most 51 characters the result always fits.
    pub fn from_name_and_hash(name: &MapName, hash_hex: &str) -> Result<Self, IdError> {
        let bad_hash = |reason: String| IdError {
            kind: Self::KIND,
            value: format!("{name}-{hash_hex}"),
            reason: IdRejection::BadHash { reason },
        };
        let prefix: String = hash_hex.chars().take(MAP_ID_HASH_LEN).collect();
        if prefix.chars().count() < MAP_ID_HASH_LEN {
            return Err(bad_hash(format!(
                "needs at least {MAP_ID_HASH_LEN} hex digits, got {}",
                hash_hex.chars().count()
            )));
        }
        if let Some(c) = hash_hex.chars().find(|c| !c.is_ascii_hexdigit()) {
            return Err(bad_hash(format!("{c:?} is not a hex digit")));
        }
        Self::new(format!("{name}-{}", prefix.to_ascii_lowercase()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn display_honours_width_for_tables() {
        let name = MapName::new("depot").unwrap();
        assert_eq!(format!("[{name:<8}]"), "[depot   ]");
        assert_eq!(format!("[{name:>8}]"), "[   depot]");
    }

    #[test]
    fn default_site_is_a_valid_id() {
        assert_eq!(SiteId::new(SiteId::DEFAULT).unwrap(), SiteId::default());
    }

    #[test]
    fn accepts_valid_ids() {
        for ok in ["robot_1", "r-2.b", "A", "a..b", "x-", "0", &"z".repeat(64)] {
            assert_eq!(RobotId::new(ok).map(|r| r.to_string()), Ok(ok.to_string()));
        }
    }

    #[test]
    fn rejects_invalid_ids_naming_field_and_value() {
        let bad = [
            "",
            "a/b",
            "a*",
            "$x",
            "..",
            ".",
            ".hidden",
            "a b",
            "a?b",
            "a#b",
            "@a",
            "ünï",
            "robot\u{1F916}",
            &"z".repeat(65),
        ];
        for value in bad {
            let err = match RobotId::new(value) {
                Ok(id) => panic!("{id} should have been rejected"),
                Err(e) => e,
            };
            assert_eq!(err.kind, "robot_id");
            assert_eq!(err.value, value);
            let msg = err.to_string();
            assert!(msg.contains("robot_id"), "{msg}");
            assert!(msg.contains(&format!("{value:?}")), "{msg}");
        }
    }

    #[test]
    fn rejection_reasons_are_specific() {
        assert_eq!(TaskId::new("").unwrap_err().reason, IdRejection::Empty);
        assert_eq!(
            TaskId::new("a/b").unwrap_err().reason,
            IdRejection::BadChar {
                ch: '/',
                position: 1
            }
        );
        assert_eq!(
            TaskId::new("..").unwrap_err().reason,
            IdRejection::LeadingDot
        );
        assert_eq!(
            TaskId::new("x".repeat(65)).unwrap_err().reason,
            IdRejection::TooLong { len: 65, max: 64 }
        );
        let e = SiteId::new("a*").unwrap_err();
        assert_eq!(e.to_string(), "invalid site_id \"a*\": character '*' at position 1 is not allowed (use A-Z a-z 0-9 _ . -)");
    }

    #[test]
    fn serde_is_a_plain_string_and_validates() {
        let id = RobotId::new("robot_1").unwrap();
        assert_eq!(serde_json::to_string(&id).unwrap(), "\"robot_1\"");
        let back: RobotId = serde_json::from_str("\"robot_1\"").unwrap();
        assert_eq!(back, id);
        let err = serde_json::from_str::<RobotId>("\"a/b\"")
            .unwrap_err()
            .to_string();
        assert!(err.contains("robot_id") && err.contains("a/b"), "{err}");
    }

    #[test]
    fn parse_and_borrow() {
        let id: MapName = "floor_3".parse().unwrap();
        let mut m = std::collections::HashMap::new();
        m.insert(id.clone(), 1);
        assert_eq!(m.get("floor_3"), Some(&1));
        assert_eq!(id.as_str(), "floor_3");
        assert_eq!(String::from(id), "floor_3");
    }

    #[test]
    fn map_id_from_name_and_hash() {
        let name = MapName::new("office").unwrap();
        let id = MapId::from_name_and_hash(&name, "ABCDEF0123456789deadbeef").unwrap();
        assert_eq!(id.as_str(), "office-abcdef012345");
        let longest = MapName::new("m".repeat(MAX_MAP_NAME_LEN)).unwrap();
        let id = MapId::from_name_and_hash(&longest, &"0".repeat(64)).unwrap();
        assert_eq!(id.as_str().len(), MAX_ID_LEN);
        assert!(MapName::new("m".repeat(MAX_MAP_NAME_LEN + 1)).is_err());
        let short = MapId::from_name_and_hash(&name, "abc").unwrap_err();
        assert!(matches!(short.reason, IdRejection::BadHash { .. }));
        assert!(short.to_string().contains("map_id"));
        assert!(MapId::from_name_and_hash(&name, "xyz0123456789").is_err());
    }
}
