//! The planner service's configuration file: `[planner]`, `[dlm]`, `[lpe]` tables.
//!
//! Every table has defaults, so a file names only what it changes; unknown keys are errors.
//! `planner.example.toml` in the crate documents every key (a test parses it).

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::intention::{DlmParams, LpeParams};
use crate::planning::PlannerConfig;

/// The whole configuration file.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ServiceConfig {
    pub planner: PlannerConfig,
    pub dlm: DlmParams,
    pub lpe: LpeParams,
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
    #[error("invalid config {path}: {reason}")]
    Invalid { path: String, reason: String },
}

impl ServiceConfig {
    /// Parses and validates TOML text; `origin` names it in errors.
    ///
    /// # Errors
    /// [`ConfigError::Parse`] or [`ConfigError::Invalid`] naming the field.
    pub fn from_toml_str(text: &str, origin: &str) -> Result<Self, ConfigError> {
        let cfg: Self = toml::from_str(text).map_err(|e| ConfigError::Parse {
            path: origin.to_string(),
            reason: e.to_string(),
        })?;
        cfg.validate().map_err(|reason| ConfigError::Invalid {
            path: origin.to_string(),
            reason,
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
    /// A message naming the field and value.
    pub fn validate(&self) -> Result<(), String> {
        self.planner.validate().map_err(|e| e.to_string())?;
        self.dlm.validate()?;
        self.lpe.validate().map_err(|e| e.to_string())?;
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
    }
}
