//! The `[fleet]` table of the service configuration and its checks.

use serde::{Deserialize, Serialize};

/// The `[fleet]` table of the service configuration.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FleetConfig {
    /// A goal counts as reached when the pose estimate is this close to it.
    pub goal_tolerance_m: f64,
    /// A robot that sent no pose for this long is silent: its task pauses.
    pub robot_timeout_ms: u64,
    /// A paused task fails after this long without its robot.
    pub pause_timeout_ms: u64,
    /// Consecutive failed replans after which the task fails.
    pub max_plan_failures: u32,
    /// LPE images for the dashboard (robots whose controller does not use them) at most this often.
    pub lpe_preview_interval_ms: u64,
    /// Camera frames kept for the dashboard at most this often per robot.
    pub camera_sample_interval_ms: u64,
    /// Recent poses kept per robot (the travelled part of the LPE image).
    pub trail_poses: usize,
    /// Robot events on the live stream at most this often per robot.
    pub robot_event_interval_ms: u64,
    /// Events buffered for each live-stream subscriber; a slower one skips events.
    pub event_buffer: usize,
    /// Most goals one task may have.
    pub max_goals: usize,
    /// Spacing of the path sent in an intention (the planner's own is finer); turns in place
    /// are kept whatever the spacing.
    pub intention_path_spacing_m: f64,
    /// Finished tasks (completed, failed, cancelled) that ended longer ago than this are
    /// pruned (exported first to `<data-dir>/tasks-export.jsonl`); 0 keeps them whatever
    /// their age.
    pub retain_finished_s: u64,
    /// At most this many finished tasks are kept, the newest; older ones are pruned (exported
    /// first); 0 keeps any number.
    pub retain_finished_max: u64,
    /// How often finished tasks are swept.
    pub retention_sweep_interval_s: u64,
    /// Other online robots on the same map within this distance of a robot are given to its
    /// planner, which keeps its path clear of them (`[other_robots]`); 0 gives none.
    pub neighbour_radius_m: f64,
}

impl Default for FleetConfig {
    fn default() -> Self {
        Self {
            goal_tolerance_m: 0.35,
            robot_timeout_ms: 2000,
            pause_timeout_ms: 120_000,
            max_plan_failures: 30,
            lpe_preview_interval_ms: 1000,
            camera_sample_interval_ms: 500,
            trail_poses: 60,
            robot_event_interval_ms: 100,
            event_buffer: 1024,
            max_goals: 64,
            intention_path_spacing_m: 0.2,
            retain_finished_s: 30 * 24 * 3600,
            retain_finished_max: 100_000,
            retention_sweep_interval_s: 60,
            neighbour_radius_m: 4.0,
        }
    }
}

/// A `[fleet]` value out of its range: which field, its value and what it must be.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("fleet.{field} = {value}: {reason}")]
pub struct InvalidFleetConfig {
    pub field: &'static str,
    pub value: String,
    pub reason: &'static str,
}

impl InvalidFleetConfig {
    fn new(field: &'static str, value: impl ToString, reason: &'static str) -> Self {
        Self {
            field,
            value: value.to_string(),
            reason,
        }
    }
}

impl FleetConfig {
    /// The retention policy of the task store (0 is no bound).
    #[must_use]
    pub fn retention(&self) -> super::store::Retention {
        super::store::Retention {
            max_age_ns: (self.retain_finished_s > 0)
                .then(|| self.retain_finished_s.saturating_mul(1_000_000_000)),
            max_count: (self.retain_finished_max > 0)
                .then(|| usize::try_from(self.retain_finished_max).unwrap_or(usize::MAX)),
        }
    }

    /// Checks every value, naming the first bad one.
    ///
    /// # Errors
    /// [`InvalidFleetConfig`] naming the field and value.
    pub fn validate(&self) -> Result<(), InvalidFleetConfig> {
        let spacing = self.intention_path_spacing_m;
        if !(spacing.is_finite() && spacing >= 0.0) {
            return Err(InvalidFleetConfig::new(
                "intention_path_spacing_m",
                spacing,
                "must be zero or positive",
            ));
        }
        let radius = self.neighbour_radius_m;
        if !(radius.is_finite() && radius >= 0.0) {
            return Err(InvalidFleetConfig::new(
                "neighbour_radius_m",
                radius,
                "must be zero or positive",
            ));
        }
        let tolerance = self.goal_tolerance_m;
        if !(tolerance.is_finite() && tolerance > 0.0) {
            return Err(InvalidFleetConfig::new(
                "goal_tolerance_m",
                tolerance,
                "must be positive",
            ));
        }
        let counts = [
            ("robot_timeout_ms", self.robot_timeout_ms),
            ("pause_timeout_ms", self.pause_timeout_ms),
            ("lpe_preview_interval_ms", self.lpe_preview_interval_ms),
            ("camera_sample_interval_ms", self.camera_sample_interval_ms),
            ("max_plan_failures", u64::from(self.max_plan_failures)),
            ("event_buffer", self.event_buffer as u64),
            ("max_goals", self.max_goals as u64),
            (
                "retention_sweep_interval_s",
                self.retention_sweep_interval_s,
            ),
        ];
        match counts.into_iter().find(|(_, v)| *v == 0) {
            Some((field, _)) => Err(InvalidFleetConfig::new(field, 0, "must be positive")),
            None => Ok(()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_first_bad_value_is_named_with_its_field() {
        assert_eq!(FleetConfig::default().validate(), Ok(()));
        let bad = FleetConfig {
            goal_tolerance_m: -0.5,
            ..FleetConfig::default()
        };
        let err = bad.validate().unwrap_err();
        assert_eq!(err.field, "goal_tolerance_m");
        assert_eq!(
            err.to_string(),
            "fleet.goal_tolerance_m = -0.5: must be positive"
        );
        let bad = FleetConfig {
            max_goals: 0,
            ..FleetConfig::default()
        };
        assert_eq!(
            bad.validate().unwrap_err().to_string(),
            "fleet.max_goals = 0: must be positive"
        );
        let bad = FleetConfig {
            intention_path_spacing_m: f64::NAN,
            ..FleetConfig::default()
        };
        assert_eq!(
            bad.validate().unwrap_err().field,
            "intention_path_spacing_m"
        );
        let bad = FleetConfig {
            retention_sweep_interval_s: 0,
            ..FleetConfig::default()
        };
        assert_eq!(
            bad.validate().unwrap_err().field,
            "retention_sweep_interval_s"
        );
    }

    #[test]
    fn retention_defaults_to_30_days_and_100000_and_zero_is_no_bound() {
        let r = FleetConfig::default().retention();
        assert_eq!(r.max_age_ns, Some(30 * 24 * 3600 * 1_000_000_000));
        assert_eq!(r.max_count, Some(100_000));
        let unbounded = FleetConfig {
            retain_finished_s: 0,
            retain_finished_max: 0,
            ..FleetConfig::default()
        };
        assert_eq!(
            unbounded.retention(),
            super::super::store::Retention::default()
        );
    }
}
