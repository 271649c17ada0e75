//! Simulator settings that are not part of a scenario: the robot base, its sensors and noise.
//!
//! Defaults model a Pioneer 3-DX with a Sick LMS-200 and one forward camera (paper §4); a YAML
//! file (`sim/config.example.yaml`, every field commented) may override any of them.

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::scenario::ScenarioError;

/// Differential-drive base limits.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BaseConfig {
    pub radius_m: f64,
    pub max_speed_mps: f64,
    /// Fastest reverse speed (positive number).
    pub max_reverse_mps: f64,
    pub max_turn_radps: f64,
    pub max_accel_mps2: f64,
    pub max_turn_accel_radps2: f64,
}

impl Default for BaseConfig {
    fn default() -> Self {
        Self {
            radius_m: 0.25,
            max_speed_mps: 1.2,
            max_reverse_mps: 0.3,
            max_turn_radps: 1.2,
            max_accel_mps2: 1.0,
            max_turn_accel_radps2: 3.0,
        }
    }
}

/// Planar LIDAR (Sick LMS-200 defaults).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LidarConfig {
    pub beams: u32,
    pub fov_rad: f64,
    pub range_min_m: f64,
    pub range_max_m: f64,
    /// Standard deviation of the Gaussian range noise.
    pub noise_std_m: f64,
    /// Whether glass reflects the beams (real LIDARs mostly see through it).
    pub sees_glass: bool,
}

impl Default for LidarConfig {
    fn default() -> Self {
        Self {
            beams: 181,
            fov_rad: std::f64::consts::PI,
            range_min_m: 0.05,
            range_max_m: 8.0,
            noise_std_m: 0.01,
            sees_glass: false,
        }
    }
}

/// Monocular forward camera.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CameraConfig {
    pub width_px: u32,
    pub height_px: u32,
    pub hfov_rad: f64,
    /// Height of the optical centre above the floor.
    pub height_m: f64,
    pub wall_height_m: f64,
    /// Beyond this distance nothing is drawn (fog colour).
    pub max_range_m: f64,
}

impl Default for CameraConfig {
    fn default() -> Self {
        Self {
            width_px: 224,
            height_px: 224,
            hfov_rad: 70f64.to_radians(),
            height_m: 0.6,
            wall_height_m: 2.6,
            max_range_m: 40.0,
        }
    }
}

/// Thrun's odometry motion-model noise (as AMCL's `odom_alpha1..4`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct OdometryNoise {
    /// Rotation noise from rotation.
    pub alpha1: f64,
    /// Rotation noise from translation.
    pub alpha2: f64,
    /// Translation noise from translation.
    pub alpha3: f64,
    /// Translation noise from rotation.
    pub alpha4: f64,
}

impl Default for OdometryNoise {
    fn default() -> Self {
        Self {
            alpha1: 0.05,
            alpha2: 0.01,
            alpha3: 0.02,
            alpha4: 0.01,
        }
    }
}

/// Everything configurable about the simulated robots.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SimConfig {
    pub base: BaseConfig,
    pub lidar: LidarConfig,
    pub camera: CameraConfig,
    pub odometry: OdometryNoise,
}

impl SimConfig {
    /// Reads and validates a config YAML.
    ///
    /// # Errors
    /// [`ScenarioError::Io`], [`ScenarioError::Parse`] or [`ScenarioError::Invalid`].
    pub fn load(path: &Path) -> Result<Self, ScenarioError> {
        let text = std::fs::read_to_string(path).map_err(|source| ScenarioError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let config: SimConfig = serde_yaml::from_str(&text).map_err(|e| ScenarioError::Parse {
            path: path.to_path_buf(),
            reason: e.to_string(),
        })?;
        config.validate()?;
        Ok(config)
    }

    /// Checks ranges.
    ///
    /// # Errors
    /// [`ScenarioError::Invalid`] naming the field and value.
    pub fn validate(&self) -> Result<(), ScenarioError> {
        let b = &self.base;
        let l = &self.lidar;
        let c = &self.camera;
        for (field, v) in [
            ("base.radius_m", b.radius_m),
            ("base.max_speed_mps", b.max_speed_mps),
            ("base.max_turn_radps", b.max_turn_radps),
            ("base.max_accel_mps2", b.max_accel_mps2),
            ("base.max_turn_accel_radps2", b.max_turn_accel_radps2),
            ("lidar.fov_rad", l.fov_rad),
            ("lidar.range_max_m", l.range_max_m),
            ("camera.hfov_rad", c.hfov_rad),
            ("camera.height_m", c.height_m),
            ("camera.wall_height_m", c.wall_height_m),
            ("camera.max_range_m", c.max_range_m),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(ScenarioError::invalid(
                    field,
                    v,
                    "must be a positive finite number",
                ));
            }
        }
        for (field, v) in [
            ("base.max_reverse_mps", b.max_reverse_mps),
            ("lidar.range_min_m", l.range_min_m),
            ("lidar.noise_std_m", l.noise_std_m),
            ("odometry.alpha1", self.odometry.alpha1),
            ("odometry.alpha2", self.odometry.alpha2),
            ("odometry.alpha3", self.odometry.alpha3),
            ("odometry.alpha4", self.odometry.alpha4),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(ScenarioError::invalid(
                    field,
                    v,
                    "must be a non-negative finite number",
                ));
            }
        }
        if l.range_min_m >= l.range_max_m {
            return Err(ScenarioError::invalid(
                "lidar.range_min_m",
                l.range_min_m,
                format!("must be below range_max_m = {}", l.range_max_m),
            ));
        }
        if l.beams < 2 {
            return Err(ScenarioError::invalid(
                "lidar.beams",
                l.beams,
                "need at least 2 beams",
            ));
        }
        if c.hfov_rad >= std::f64::consts::PI * 0.95 {
            return Err(ScenarioError::invalid(
                "camera.hfov_rad",
                c.hfov_rad,
                "must be below 0.95 pi",
            ));
        }
        if c.width_px == 0 || c.height_px == 0 || c.width_px > 4096 || c.height_px > 4096 {
            return Err(ScenarioError::invalid(
                "camera.width_px",
                format!("{}x{}", c.width_px, c.height_px),
                "each side must lie in 1..=4096",
            ));
        }
        if c.height_m >= c.wall_height_m {
            return Err(ScenarioError::invalid(
                "camera.height_m",
                c.height_m,
                format!("must be below wall_height_m = {}", c.wall_height_m),
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn example_file_parses_to_the_defaults() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("config.example.yaml");
        let mut c = SimConfig::load(&path).unwrap();
        let d = SimConfig::default();
        assert!((c.camera.hfov_rad - d.camera.hfov_rad).abs() < 1e-12);
        c.camera.hfov_rad = d.camera.hfov_rad;
        assert_eq!(c, d);
    }

    #[test]
    fn bad_values_name_the_field() {
        let c: Result<SimConfig, _> = serde_yaml::from_str("lidar: {beams: 181, range_mx_m: 3}");
        assert!(c.unwrap_err().to_string().contains("range_mx_m"));
        let mut c = SimConfig::default();
        c.lidar.range_min_m = 9.0;
        let e = c.validate().unwrap_err().to_string();
        assert!(e.contains("lidar.range_min_m") && e.contains('9'), "{e}");
        let mut c = SimConfig::default();
        c.base.max_speed_mps = -1.0;
        assert!(c
            .validate()
            .unwrap_err()
            .to_string()
            .contains("base.max_speed_mps"));
    }
}
