//! Planner parameters: the robot's kinematics, search resolution, costs and budgets.
//!
//! One serde struct with defaults so a configuration file only names what it changes, and
//! `deny_unknown_fields` so a misspelt key is an error rather than a silently ignored setting.

use serde::{Deserialize, Serialize};

use crate::centring::CentringParams;
use crate::error::PlanError;

/// Parameters of hybrid A* for one robot model (the `[planner]` table of the config file).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PlannerConfig {
    /// Radius of the (circular) robot footprint; the map is inflated by it.
    pub robot_radius_m: f64,
    /// Minimum turning radius of the forward and reverse arcs.
    pub min_turning_radius_m: f64,
    /// Heading bins of the search lattice (Dolgov et al. use 72: 5 degrees).
    pub heading_bins: u32,
    /// Cell size of the search lattice in x and y (the closed set), not of the map.
    pub xy_resolution_m: f64,
    /// Arc length of one motion primitive; longer than the lattice diagonal so every
    /// primitive leaves its cell.
    pub step_m: f64,
    /// Whether the robot may drive backwards.
    pub allow_reverse: bool,
    /// Cost multiplier on reverse arcs.
    pub reverse_cost_factor: f64,
    /// Extra cost (metres) when the driving direction changes.
    pub direction_switch_cost_m: f64,
    /// Whether the robot may rotate in place (a differential drive can).
    pub allow_turn_in_place: bool,
    /// Heading change of one turn-in-place primitive.
    pub turn_in_place_step_rad: f64,
    /// Cost of turning in place, metres per radian.
    pub turn_in_place_cost_m_per_rad: f64,
    /// Cost multiplier on curved arcs relative to straight ones (prefers straight paths).
    pub turn_cost_factor: f64,
    /// Weight on the heuristic (1.0 = A*; larger is faster and less optimal).
    pub heuristic_weight: f64,
    /// Downsampling factor of the obstacle heuristic's 2-D grid relative to the map.
    pub heuristic_downsample: u32,
    /// Obstacle heuristics (one per goal) kept per map version. Every robot driving to its own
    /// goal needs one, so this should exceed the robots on a map: with fewer, the cache evicts
    /// in a cycle and nearly every new search rebuilds its heuristic (250 robots: 88 % of poses
    /// answered at 128, 97 % at 320; docs/benchmarks.md). About 1.3 MB each on a
    /// 100 m x 100 m map at 5 cm, taken only by goals in use: 320 goals there hold ~420 MB.
    pub heuristic_cache_size: usize,
    /// Try an analytic (Dubins) shot to the goal every this many expansions.
    pub analytic_expansion_every: u32,
    /// ... and on every expansion closer than this to the goal (obstacle heuristic distance).
    pub analytic_near_goal_m: f64,
    /// Within two turning radii of the goal also try a turn in place to face it and a straight
    /// line to it (with `allow_turn_in_place`), taken where it costs less than the Dubins shot:
    /// a goal beside or behind the robot, which the Dubins curve loops round.
    pub analytic_turn_straight: bool,
    /// Goal reached when the position is within this distance.
    pub goal_position_tolerance_m: f64,
    /// ... and the heading within this angle (or the robot can turn in place to it).
    pub goal_yaw_tolerance_rad: f64,
    /// Wall-clock budget of one plan.
    pub time_budget_ms: u64,
    /// Expansion budget of one plan (a guard independent of machine speed).
    pub max_expansions: u64,
    /// Spacing of the output poses along the path.
    pub path_spacing_m: f64,
    /// Whether to shortcut-smooth the path with collision-checked Dubins curves.
    pub smooth: bool,
    /// Moving the smoothed path to the middle of corridors and doorways (`[planner.centring]`).
    pub centring: CentringParams,
}

impl Default for PlannerConfig {
    fn default() -> Self {
        Self {
            robot_radius_m: 0.25,
            min_turning_radius_m: 0.5,
            heading_bins: 72,
            xy_resolution_m: 0.1,
            step_m: 0.2,
            allow_reverse: false,
            reverse_cost_factor: 2.0,
            direction_switch_cost_m: 1.0,
            allow_turn_in_place: true,
            turn_in_place_step_rad: std::f64::consts::PI / 9.0,
            turn_in_place_cost_m_per_rad: 0.3,
            turn_cost_factor: 1.05,
            heuristic_weight: 1.3,
            heuristic_downsample: 4,
            heuristic_cache_size: 320,
            analytic_expansion_every: 8,
            analytic_near_goal_m: 4.0,
            analytic_turn_straight: true,
            goal_position_tolerance_m: 0.1,
            goal_yaw_tolerance_rad: 0.1,
            time_budget_ms: 1000,
            max_expansions: 1_000_000,
            path_spacing_m: 0.05,
            smooth: true,
            centring: CentringParams::default(),
        }
    }
}

impl PlannerConfig {
    /// Checks every field, naming the first bad one.
    ///
    /// # Errors
    /// [`PlanError::InvalidConfig`] with the field, its value and why.
    pub fn validate(&self) -> Result<(), PlanError> {
        let positive = [
            ("robot_radius_m", self.robot_radius_m),
            ("min_turning_radius_m", self.min_turning_radius_m),
            ("xy_resolution_m", self.xy_resolution_m),
            ("step_m", self.step_m),
            ("reverse_cost_factor", self.reverse_cost_factor),
            ("turn_in_place_step_rad", self.turn_in_place_step_rad),
            ("turn_cost_factor", self.turn_cost_factor),
            ("heuristic_weight", self.heuristic_weight),
            ("path_spacing_m", self.path_spacing_m),
            ("goal_position_tolerance_m", self.goal_position_tolerance_m),
            ("goal_yaw_tolerance_rad", self.goal_yaw_tolerance_rad),
        ];
        for (field, value) in positive {
            if !value.is_finite() || value <= 0.0 {
                return Err(PlanError::invalid_config(
                    field,
                    value,
                    "must be positive and finite",
                ));
            }
        }
        let non_negative = [
            ("direction_switch_cost_m", self.direction_switch_cost_m),
            (
                "turn_in_place_cost_m_per_rad",
                self.turn_in_place_cost_m_per_rad,
            ),
            ("analytic_near_goal_m", self.analytic_near_goal_m),
        ];
        for (field, value) in non_negative {
            if !value.is_finite() || value < 0.0 {
                return Err(PlanError::invalid_config(
                    field,
                    value,
                    "must be >= 0 and finite",
                ));
            }
        }
        if !(8..=360).contains(&self.heading_bins) {
            return Err(PlanError::invalid_config(
                "heading_bins",
                self.heading_bins,
                "must be in 8..=360",
            ));
        }
        if self.step_m < self.xy_resolution_m * std::f64::consts::SQRT_2 {
            return Err(PlanError::invalid_config(
                "step_m",
                self.step_m,
                "must be at least xy_resolution_m * sqrt(2) so a primitive leaves its cell",
            ));
        }
        if !(1..=16).contains(&self.heuristic_downsample) {
            return Err(PlanError::invalid_config(
                "heuristic_downsample",
                self.heuristic_downsample,
                "must be in 1..=16",
            ));
        }
        if self.heuristic_cache_size == 0 {
            return Err(PlanError::invalid_config(
                "heuristic_cache_size",
                0,
                "must be >= 1",
            ));
        }
        if self.analytic_expansion_every == 0 {
            return Err(PlanError::invalid_config(
                "analytic_expansion_every",
                0,
                "must be >= 1",
            ));
        }
        if self.time_budget_ms == 0 {
            return Err(PlanError::invalid_config(
                "time_budget_ms",
                0,
                "must be >= 1",
            ));
        }
        if self.max_expansions == 0 {
            return Err(PlanError::invalid_config(
                "max_expansions",
                0,
                "must be >= 1",
            ));
        }
        if let Some((field, value)) = self.centring.invalid() {
            return Err(PlanError::invalid_config(
                field,
                value,
                "must be >= 0 and finite",
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_valid_and_bad_values_are_named() {
        PlannerConfig::default().validate().unwrap();
        let bad = PlannerConfig {
            step_m: 0.05,
            ..PlannerConfig::default()
        };
        let err = bad.validate().unwrap_err().to_string();
        assert!(err.contains("step_m"), "{err}");
        let bad = PlannerConfig {
            robot_radius_m: -1.0,
            ..PlannerConfig::default()
        };
        assert!(bad
            .validate()
            .unwrap_err()
            .to_string()
            .contains("robot_radius_m"));
    }

    #[test]
    fn unknown_fields_are_rejected() {
        let err = toml::from_str::<PlannerConfig>("robot_radius = 0.3").unwrap_err();
        assert!(err.to_string().contains("robot_radius"), "{err}");
        let cfg: PlannerConfig = toml::from_str("robot_radius_m = 0.3").unwrap();
        assert!((cfg.robot_radius_m - 0.3).abs() < 1e-12);
        assert_eq!(cfg.heading_bins, 72);
    }
}
