//! Configuration of the `map-store` binary, read from TOML (see `map-store.example.toml`).
//!
//! Every field has a default, so an empty file is a valid configuration; unknown keys are
//! errors so a typo never silently falls back to a default.

use std::path::{Path, PathBuf};

use protocol::{SessionArgs, SessionError, SiteId};
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
    /// The Zenoh session (`[zenoh]`: `listen`, `connect`, `multicast`); endpoints such as
    /// `tcp/127.0.0.1:7447`, multicast scouting off unless `multicast = true`.
    pub zenoh: SessionArgs,
}

impl Default for MapStoreConfig {
    fn default() -> Self {
        Self {
            site: default_site(),
            data_dir: None,
            limits: ImportLimits::default(),
            zenoh: SessionArgs::default(),
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
    /// Parses TOML text and checks it (the Zenoh endpoints included); `origin` labels errors.
    ///
    /// # Errors
    /// [`MapError::Invalid`] on `config` naming the file and the TOML error (field and value),
    /// or on `zenoh` naming the endpoint Zenoh cannot parse.
    pub fn from_toml(text: &str, origin: &Path) -> Result<Self, MapError> {
        let config: Self = toml::from_str(text)
            .map_err(|e| MapError::invalid("config", origin.display(), e.to_string()))?;
        config.zenoh_config()?;
        Ok(config)
    }

    /// Reads, parses and checks a TOML file.
    ///
    /// # Errors
    /// [`MapError::Io`] or as [`Self::from_toml`].
    pub fn load(path: &Path) -> Result<Self, MapError> {
        let text = std::fs::read_to_string(path).map_err(|e| MapError::io(path, e))?;
        Self::from_toml(&text, path)
    }

    /// The Zenoh configuration of the `[zenoh]` table (built by [`SessionArgs::config`]).
    ///
    /// # Errors
    /// [`MapError::Invalid`] on `zenoh` naming the endpoint or setting Zenoh refused.
    pub fn zenoh_config(&self) -> Result<zenoh::Config, MapError> {
        self.zenoh.config().map_err(|e| match e {
            SessionError::Endpoint {
                field,
                endpoint,
                reason,
            } => {
                let field = if field == "listen" {
                    "zenoh.listen"
                } else {
                    "zenoh.connect"
                };
                MapError::invalid(field, format!("{endpoint:?}"), reason)
            }
            other => MapError::invalid("zenoh", "[zenoh]", other.to_string()),
        })
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
        // Endpoints are checked when the file is loaded, naming the bad one.
        let e = MapStoreConfig::from_toml("[zenoh]\nlisten = [\"nonsense\"]", Path::new("c"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("listen") && e.contains("nonsense"), "{e}");
        let e = MapStoreConfig::from_toml("[zenoh]\nmulticast = 1", Path::new("c"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("multicast"), "{e}");
    }

    #[test]
    fn zenoh_table_is_the_shared_session_args() {
        let cfg = MapStoreConfig::from_toml("", Path::new("empty")).unwrap();
        assert!(!cfg.zenoh.multicast_scouting, "multicast is off by default");
        let cfg = MapStoreConfig::from_toml(
            "[zenoh]\nconnect = [\"tcp/10.0.0.2:7447\"]\nmulticast = true\n",
            Path::new("c"),
        )
        .unwrap();
        assert_eq!(cfg.zenoh.connect, ["tcp/10.0.0.2:7447"]);
        assert!(cfg.zenoh.multicast_scouting);
        let z = cfg.zenoh_config().unwrap();
        assert_eq!(z.get_json("scouting/multicast/enabled").unwrap(), "true");
    }
}
