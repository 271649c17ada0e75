//! The agent's configuration: which controller drives, the robot's limits, the safety
//! thresholds that make it stop rather than drive on stale or doubtful information, and the
//! nested parameters of localization (`[amcl]`) and of each controller.

use std::path::PathBuf;

pub use protocol::{ControllerKind, UnknownController};
use protocol::{MapName, Pose2D, SiteId};

use crate::amcl::{AmclConfig, AmclError};
use crate::camera_hold::CameraHoldConfig;
use crate::collision_monitor::CollisionMonitorConfig;
use crate::controllers::{DynamicWindowConfig, PathTrackerConfig};
use crate::give_way::GiveWayConfig;
use crate::recovery::RecoveryConfig;
use crate::rotation_shim::RotationShimConfig;
use crate::unmapped::UnmappedConfig;

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
    /// While AMCL relocalizes after losing itself, the robot turns in place at this rate so
    /// that the laser sweeps the surroundings (Nav2's spin recovery); 0 stands still.
    pub relocalize_spin_radps: f64,
    /// The last check on every command, against the laser scan.
    pub collision_monitor: CollisionMonitorConfig,
    /// The dynamic window takes over while the monitor keeps the controller from moving on.
    pub recovery: RecoveryConfig,
    /// A camera-driven controller that brakes for what the laser does not see stays behind
    /// where it meant to stop.
    pub camera_hold: CameraHoldConfig,
}

impl Default for Safety {
    fn default() -> Self {
        Self {
            intention_deadline_ms: 300,
            max_position_std_m: 0.5,
            stop_decel_mps2: 1.0,
            relocalize_spin_radps: 1.0,
            collision_monitor: CollisionMonitorConfig::default(),
            recovery: RecoveryConfig::default(),
            camera_hold: CameraHoldConfig::default(),
        }
    }
}

/// Where the robot starts believing it is (the `[localization]` table).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Localization {
    /// Initial pose in the map frame; `None` means global localization (particles spread over
    /// the whole free space of the map).
    pub initial_pose: Option<Pose2D>,
    /// Standard deviation of the initial particle cloud in x and in y.
    pub initial_position_std_m: f64,
    /// Standard deviation of the initial particle cloud in heading.
    pub initial_yaw_std_rad: f64,
}

impl Default for Localization {
    fn default() -> Self {
        Self {
            initial_pose: None,
            initial_position_std_m: 0.15,
            initial_yaw_std_rad: 0.1,
        }
    }
}

impl Localization {
    /// The initial covariance (3x3 row-major over x, y, yaw) from the standard deviations.
    #[must_use]
    pub fn initial_covariance(&self) -> [f64; 9] {
        let p = self.initial_position_std_m * self.initial_position_std_m;
        let y = self.initial_yaw_std_rad * self.initial_yaw_std_rad;
        [p, 0.0, 0.0, 0.0, p, 0.0, 0.0, 0.0, y]
    }
}

/// How ONNX Runtime runs the intention-net controllers (the `[intention_net]` table).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct IntentionNetSettings {
    /// Threads ONNX Runtime may use inside one operator.
    pub intra_threads: usize,
}

impl Default for IntentionNetSettings {
    fn default() -> Self {
        Self { intra_threads: 1 }
    }
}

/// The whole agent configuration (TOML); every field has a default.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct AgentConfig {
    pub site: SiteId,
    /// The floor plan to localize on, as the map store names it.
    pub map: Option<MapName>,
    /// The map version; `None` takes the latest the map store has.
    pub map_version: Option<u32>,
    pub controller: ControllerKind,
    /// ONNX model for the network controllers.
    pub model: Option<PathBuf>,
    pub control_rate_hz: f64,
    /// Rate of the periodic `AgentStatus` (it is also sent on every state change).
    pub status_rate_hz: f64,
    /// How long one map query waits for the map store before it is retried.
    pub map_fetch_timeout_ms: u64,
    pub limits: Limits,
    pub safety: Safety,
    pub localization: Localization,
    pub amcl: AmclConfig,
    pub path_tracker: PathTrackerConfig,
    pub dynamic_window: DynamicWindowConfig,
    pub intention_net: IntentionNetSettings,
    /// What the laser sees where the floor plan is free, sent with each pose to the planner.
    pub unmapped_obstacles: UnmappedConfig,
    /// A turn on the spot towards the path before the driving controller drives on.
    pub rotation_shim: RotationShimConfig,
    /// Waiting short of a narrow passage while someone comes through it.
    pub give_way: GiveWayConfig,
}

impl Default for AgentConfig {
    fn default() -> Self {
        Self {
            site: SiteId::default(),
            map: None,
            map_version: None,
            controller: ControllerKind::DynamicWindow,
            model: None,
            control_rate_hz: 10.0,
            status_rate_hz: 2.0,
            map_fetch_timeout_ms: 2000,
            limits: Limits::default(),
            safety: Safety::default(),
            localization: Localization::default(),
            amcl: AmclConfig::default(),
            path_tracker: PathTrackerConfig::default(),
            dynamic_window: DynamicWindowConfig::default(),
            intention_net: IntentionNetSettings::default(),
            unmapped_obstacles: UnmappedConfig::default(),
            rotation_shim: RotationShimConfig::default(),
            give_way: GiveWayConfig::default(),
        }
    }
}

/// A configuration value that parsed but makes no sense.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    #[error("cannot parse agent config: {0}")]
    Parse(#[from] toml::de::Error),
    #[error("[amcl] {0}")]
    Amcl(#[from] AmclError),
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
            ("status_rate_hz", self.status_rate_hz),
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
        let spin = self.safety.relocalize_spin_radps;
        if !(spin.is_finite() && spin >= 0.0 && spin <= self.limits.max_turn_radps) {
            return Err(ConfigError::Invalid {
                field: "safety.relocalize_spin_radps",
                value: spin.to_string(),
                reason: "must lie between 0 and limits.max_turn_radps",
            });
        }
        self.safety.collision_monitor.validate()?;
        self.safety.recovery.validate()?;
        self.safety.camera_hold.validate()?;
        self.unmapped_obstacles.validate()?;
        self.rotation_shim.validate()?;
        self.give_way.validate()?;
        if self.safety.intention_deadline_ms == 0 {
            return Err(ConfigError::Invalid {
                field: "safety.intention_deadline_ms",
                value: "0".into(),
                reason: "must be at least 1 ms",
            });
        }
        if self.map_fetch_timeout_ms == 0 {
            return Err(ConfigError::Invalid {
                field: "map_fetch_timeout_ms",
                value: "0".into(),
                reason: "must be at least 1 ms",
            });
        }
        if self.map_version == Some(0) {
            return Err(ConfigError::Invalid {
                field: "map_version",
                value: "0".into(),
                reason: "map versions start at 1",
            });
        }
        let l = &self.localization;
        for (field, v) in [
            (
                "localization.initial_position_std_m",
                l.initial_position_std_m,
            ),
            ("localization.initial_yaw_std_rad", l.initial_yaw_std_rad),
        ] {
            if !v.is_finite() || v < 0.0 {
                return Err(ConfigError::Invalid {
                    field,
                    value: v.to_string(),
                    reason: "must be a finite number >= 0",
                });
            }
        }
        if let Some(p) = l.initial_pose {
            if p.validate("localization.initial_pose").is_err() {
                return Err(ConfigError::Invalid {
                    field: "localization.initial_pose",
                    value: format!("({}, {}, {})", p.x_m, p.y_m, p.yaw_rad),
                    reason: "must be finite",
                });
            }
        }
        if !(1..=64).contains(&self.intention_net.intra_threads) {
            return Err(ConfigError::Invalid {
                field: "intention_net.intra_threads",
                value: self.intention_net.intra_threads.to_string(),
                reason: "must lie in 1..=64",
            });
        }
        self.amcl.validate()?;
        self.path_tracker.validate()?;
        self.dynamic_window.validate()?;
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
        // Every value in the example is the default; drift between the two fails here.
        assert_eq!(config, AgentConfig::default());
        assert_eq!(config.amcl, AmclConfig::default());
        assert_eq!(config.dynamic_window, DynamicWindowConfig::default());
        assert_eq!(config.site.as_str(), "default");
        // The commented-out lines are valid too once uncommented.
        let uncommented: String = text
            .lines()
            .map(|l| {
                let t = l.trim_start();
                for key in ["# map = ", "# map_version = ", "# initial_pose = "] {
                    if t.starts_with(key) {
                        return t.trim_start_matches("# ").to_string();
                    }
                }
                l.to_string()
            })
            .collect::<Vec<_>>()
            .join("\n");
        let config = AgentConfig::from_toml(&uncommented).unwrap();
        assert_eq!(config.map.unwrap().as_str(), "office");
        assert_eq!(config.map_version, Some(1));
        assert_eq!(
            config.localization.initial_pose,
            Some(Pose2D::new(3.0, 4.0, 0.0))
        );
    }

    #[test]
    fn controller_kinds_round_trip_through_their_names() {
        for kind in ControllerKind::ALL {
            assert_eq!(kind.as_str().parse::<ControllerKind>().unwrap(), kind);
            let toml_text = format!("controller = \"{kind}\"\nmodel = \"m.onnx\"\n");
            assert_eq!(AgentConfig::from_toml(&toml_text).unwrap().controller, kind);
        }
        let err = "teleport".parse::<ControllerKind>().unwrap_err();
        assert!(err.to_string().contains("teleport"), "{err}");
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
        let err = AgentConfig::from_toml("[amcl]\nmax_particles = 10\n").unwrap_err();
        assert!(err.to_string().contains("max_particles = 10"), "{err}");
        let err = AgentConfig::from_toml("[dynamic_window]\nv_samples = 1\n").unwrap_err();
        assert!(
            err.to_string().contains("dynamic_window.v_samples"),
            "{err}"
        );
        let err =
            AgentConfig::from_toml("[localization]\ninitial_yaw_std_rad = -1.0\n").unwrap_err();
        assert!(
            err.to_string()
                .contains("localization.initial_yaw_std_rad = -1"),
            "{err}"
        );
        let err = AgentConfig::from_toml("map = \"bad/name\"\n").unwrap_err();
        assert!(err.to_string().contains("bad/name"), "{err}");
    }
}
