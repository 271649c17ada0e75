//! Configuration of the `map-store` binary, read from TOML (see `map-store.example.toml`).
//!
//! Every field has a default, so an empty file is a valid configuration; unknown keys are
//! errors so a typo never silently falls back to a default.

use std::path::{Path, PathBuf};

use protocol::SiteId;
use serde::{Deserialize, Serialize};

use crate::error::MapError;
use crate::ros::ImportLimits;

/// The site used when none is configured.
pub const DEFAULT_SITE: &str = "default";

/// Settings of the map store process.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MapStoreConfig {
    /// The site whose `fleet/<site>/map/**` keys are served.
    pub site: SiteId,
    /// Folder of the database; `None` means the user's data directory.
    pub data_dir: Option<PathBuf>,
    /// Image limits checked before decoding.
    pub limits: ImportLimits,
    pub zenoh: ZenohEndpoints,
}

/// Zenoh endpoints, e.g. `tcp/127.0.0.1:7447`.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ZenohEndpoints {
    /// Endpoints to connect to (a router or a peer).
    pub connect: Vec<String>,
    /// Endpoints to listen on.
    pub listen: Vec<String>,
}

impl Default for MapStoreConfig {
    fn default() -> Self {
        Self {
            site: default_site(),
            data_dir: None,
            limits: ImportLimits::default(),
            zenoh: ZenohEndpoints::default(),
        }
    }
}

fn default_site() -> SiteId {
    match SiteId::new(DEFAULT_SITE) {
        Ok(site) => site,
        // The literal is a valid id; the config test checks it.
        Err(e) => unreachable!("default site {DEFAULT_SITE:?} is invalid: {e}"),
    }
}

impl MapStoreConfig {
    /// Parses TOML text; `origin` labels errors.
    ///
    /// # Errors
    /// [`MapError::Invalid`] on `config` naming the file and the TOML error (field and value).
    pub fn from_toml(text: &str, origin: &Path) -> Result<Self, MapError> {
        toml::from_str(text)
            .map_err(|e| MapError::invalid("config", origin.display(), e.to_string()))
    }

    /// Reads and parses a TOML file.
    ///
    /// # Errors
    /// [`MapError::Io`] or as [`Self::from_toml`].
    pub fn load(path: &Path) -> Result<Self, MapError> {
        let text = std::fs::read_to_string(path).map_err(|e| MapError::io(path, e))?;
        Self::from_toml(&text, path)
    }

    /// A Zenoh configuration with the endpoints set (multicast scouting stays at Zenoh's default).
    ///
    /// # Errors
    /// [`MapError::Invalid`] naming the endpoint list Zenoh refused.
    pub fn zenoh_config(&self) -> Result<zenoh::Config, MapError> {
        let mut c = zenoh::Config::default();
        for (field, list) in [
            ("zenoh.connect", &self.zenoh.connect),
            ("zenoh.listen", &self.zenoh.listen),
        ] {
            if list.is_empty() {
                continue;
            }
            let json = serde_json::to_string(list)
                .map_err(|e| MapError::invalid(field, format!("{list:?}"), e.to_string()))?;
            let key = if field == "zenoh.connect" {
                "connect/endpoints"
            } else {
                "listen/endpoints"
            };
            c.insert_json5(key, &json)
                .map_err(|e| MapError::invalid(field, format!("{list:?}"), e.to_string()))?;
        }
        Ok(c)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn example_file_parses_and_defaults_hold() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("map-store.example.toml");
        let cfg = MapStoreConfig::load(&path).unwrap();
        assert_eq!(cfg.site.as_str(), "hq");
        assert_eq!(cfg.limits, ImportLimits::default());
        assert_eq!(cfg.zenoh.listen, vec!["tcp/0.0.0.0:7448".to_string()]);
        cfg.zenoh_config().unwrap();
        let empty = MapStoreConfig::from_toml("", Path::new("empty")).unwrap();
        assert_eq!(empty, MapStoreConfig::default());
        assert_eq!(empty.site.as_str(), DEFAULT_SITE);
    }

    #[test]
    fn unknown_and_bad_fields_are_named() {
        let e = MapStoreConfig::from_toml("sight = \"x\"", Path::new("c.toml")).unwrap_err();
        assert!(e.to_string().contains("sight"), "{e}");
        let e = MapStoreConfig::from_toml("site = \"a/b\"", Path::new("c.toml")).unwrap_err();
        assert!(e.to_string().contains("a/b"), "{e}");
        let e =
            MapStoreConfig::from_toml("[limits]\nmax_pixel = 3", Path::new("c.toml")).unwrap_err();
        assert!(e.to_string().contains("max_pixel"), "{e}");
        let bad = MapStoreConfig::from_toml("[zenoh]\nlisten = [\"nonsense\"]", Path::new("c"))
            .unwrap()
            .zenoh_config();
        assert!(bad.is_err());
    }
}
