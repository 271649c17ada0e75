//! The agent's configuration: which controller drives, the robot's limits, and the safety
//! thresholds that make it stop rather than drive on stale or doubtful information.

use std::path::PathBuf;

use protocol::SiteId;

/// Which controller turns observations and intentions into (v, ω).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ControllerKind {
    /// Intention-net with the discretized-local-move intention (ONNX model).
    Dlm,
    /// Intention-net with the local-path-and-environment image (ONNX model).
    Lpe,
    /// Camera-only network, the paper's Non-Intention Net ablation (ONNX model).
    None,
    /// Pure pursuit on the planned path, no camera.
    PathTracker,
    /// Dynamic window approach on the laser scan and the planned path.
    DynamicWindow,
}

impl ControllerKind {
    /// Whether this controller runs a neural network and so needs a model file.
    #[must_use]
    pub fn needs_model(self) -> bool {
        matches!(self, Self::Dlm | Self::Lpe | Self::None)
    }
}

/// Velocity and acceleration limits of the base; network outputs in [-1, 1] scale by these.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Limits {
    pub max_speed_mps: f64,
    pub max_turn_radps: f64,
    pub max_accel_mps2: f64,
    pub max_turn_accel_radps2: f64,
}

impl Default for Limits {
    fn default() -> Self {
        // A Pioneer 3-DX driven indoors among people: well under its 1.2 m/s top speed.
        Self {
            max_speed_mps: 0.7,
            max_turn_radps: 1.2,
            max_accel_mps2: 0.8,
            max_turn_accel_radps2: 2.0,
        }
    }
}

/// When to stop: the agent never drives on a stale intention or a doubtful pose.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Safety {
    /// An intention older than this (from the pose it answers) is stale.
    pub intention_deadline_ms: u64,
    /// Localization counts as lost above this position standard deviation.
    pub max_position_std_m: f64,
    /// Deceleration used to come to a safety stop.
    pub stop_decel_mps2: f64,
}

impl Default for Safety {
    fn default() -> Self {
        Self {
            intention_deadline_ms: 300,
            max_position_std_m: 0.5,
            stop_decel_mps2: 1.0,
        }
    }
}

/// The whole agent configuration (TOML); every field has a default.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct AgentConfig {
    pub site: SiteId,
    pub controller: ControllerKind,
    /// ONNX model for the network controllers.
    pub model: Option<PathBuf>,
    pub control_rate_hz: f64,
    pub limits: Limits,
    pub safety: Safety,
}

impl Default for AgentConfig {
    fn default() -> Self {
        Self {
            site: SiteId::default(),
            controller: ControllerKind::DynamicWindow,
            model: None,
            control_rate_hz: 10.0,
            limits: Limits::default(),
            safety: Safety::default(),
        }
    }
}

/// A configuration value that parsed but makes no sense.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    #[error("cannot parse agent config: {0}")]
    Parse(#[from] toml::de::Error),
    #[error("invalid {field} = {value}: {reason}")]
    Invalid {
        field: &'static str,
        value: String,
        reason: &'static str,
    },
}

impl AgentConfig {
    /// Parses TOML and checks every value.
    ///
    /// # Errors
    /// [`ConfigError`] naming the field and value.
    pub fn from_toml(text: &str) -> Result<Self, ConfigError> {
        let config: Self = toml::from_str(text)?;
        config.validate()?;
        Ok(config)
    }

    /// Checks ranges that serde cannot express.
    ///
    /// # Errors
    /// [`ConfigError::Invalid`] naming the first bad field.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let positive = [
            ("control_rate_hz", self.control_rate_hz),
            ("limits.max_speed_mps", self.limits.max_speed_mps),
            ("limits.max_turn_radps", self.limits.max_turn_radps),
            ("limits.max_accel_mps2", self.limits.max_accel_mps2),
            (
                "limits.max_turn_accel_radps2",
                self.limits.max_turn_accel_radps2,
            ),
            ("safety.max_position_std_m", self.safety.max_position_std_m),
            ("safety.stop_decel_mps2", self.safety.stop_decel_mps2),
        ];
        for (field, v) in positive {
            if !v.is_finite() || v <= 0.0 {
                return Err(ConfigError::Invalid {
                    field,
                    value: v.to_string(),
                    reason: "must be a positive, finite number",
                });
            }
        }
        if self.safety.intention_deadline_ms == 0 {
            return Err(ConfigError::Invalid {
                field: "safety.intention_deadline_ms",
                value: "0".into(),
                reason: "must be at least 1 ms",
            });
        }
        if self.controller.needs_model() && self.model.is_none() {
            return Err(ConfigError::Invalid {
                field: "model",
                value: "(none)".into(),
                reason: "the dlm, lpe and none controllers need an ONNX model",
            });
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn example_file_parses_and_matches_defaults_where_it_says_so() {
        let text = include_str!("../agent.example.toml");
        let config = AgentConfig::from_toml(text).unwrap();
        assert_eq!(config.controller, ControllerKind::DynamicWindow);
        assert_eq!(config.safety, Safety::default());
        assert_eq!(config.limits, Limits::default());
        assert_eq!(config.site.as_str(), "default");
    }

    #[test]
    fn empty_file_gives_defaults() {
        assert_eq!(AgentConfig::from_toml("").unwrap(), AgentConfig::default());
    }

    #[test]
    fn rejects_unknown_fields_and_bad_values_by_name() {
        let err = AgentConfig::from_toml("[safety]\nintention_deadline_msec = 3\n").unwrap_err();
        assert!(err.to_string().contains("intention_deadline_msec"), "{err}");
        let err = AgentConfig::from_toml("[limits]\nmax_speed_mps = -1.0\n").unwrap_err();
        assert!(
            err.to_string().contains("limits.max_speed_mps = -1"),
            "{err}"
        );
        let err = AgentConfig::from_toml("controller = \"dlm\"\n").unwrap_err();
        assert!(err.to_string().contains("model"), "{err}");
        let err = AgentConfig::from_toml("controller = \"teleport\"\n").unwrap_err();
        assert!(err.to_string().contains("teleport"), "{err}");
    }
}
