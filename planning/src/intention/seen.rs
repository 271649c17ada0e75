//! What the robot's laser sees that the floor plan lacks: plans go round it.
//!
//! The crude floor plan has walls, not furniture. A cabinet standing out from a corridor's wall
//! is in the planned path, and every controller that follows the path (the dynamic window, the
//! LPE-Net reading its image) is led into it; the collision monitor then holds the robot short
//! and it stands there (tasks C and D, docs/evaluation.md). Nav2's global costmap has an
//! obstacle layer for this: what the sensors see is marked on the map the global planner
//! searches. Here the agent does the marking (`robot_agent::unmapped`: laser returns that stand
//! where the floor plan is free and stay put), sends the points with its pose
//! ([`protocol::PoseEstimate::unmapped_obstacles_m`]), and the pipeline turns each into a
//! [`Disc`] the search keeps out of, as it does for the fleet's other robots.
//!
//! Plain data: points and poses in, discs out.

use protocol::Pose2D;
use serde::{Deserialize, Serialize};

use crate::error::PlanError;
use crate::intention::avoid::START_GAP_M;
use crate::map::Disc;

/// The `[seen_obstacles]` table: how plans keep clear of what the robot reports seeing.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SeenObstacleParams {
    /// Off: plans see the floor plan (and the fleet's robots) only, as the paper's planner did.
    pub enabled: bool,
    /// Kept clear round each reported point, on top of the planning robot's own radius.
    pub radius_m: f64,
    /// Points farther than this from the robot are left out: the plan only needs to change
    /// where the robot is about to be, and far points cost every collision check.
    pub range_m: f64,
    /// A kept path passing a seen obstacle's disc by less than this is searched again: near
    /// what the laser sees the plan follows what it sees now (a cabinet seen whole, a person
    /// who stopped), as a new search every cycle would; elsewhere the kept path answers.
    pub kept_margin_m: f64,
    /// Time budget of a search round seen obstacles (with the fleet's robots, when there are
    /// any); when it finds no path, the plan on the floor plan answers and the collision
    /// monitor holds the robot back.
    pub budget_ms: u64,
    /// Expansion budget of that search: a way the obstacles close is given up on at this many
    /// states rather than searched to the planner's full budget.
    pub max_expansions: u64,
}

impl Default for SeenObstacleParams {
    fn default() -> Self {
        Self {
            enabled: true,
            radius_m: 0.25,
            range_m: 6.0,
            kept_margin_m: 0.1,
            budget_ms: 100,
            max_expansions: 200_000,
        }
    }
}

impl SeenObstacleParams {
    /// # Errors
    /// [`PlanError::InvalidConfig`] naming the field and value.
    pub fn validate(&self) -> Result<(), PlanError> {
        for (field, v) in [
            ("seen_obstacles.radius_m", self.radius_m),
            ("seen_obstacles.range_m", self.range_m),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(PlanError::invalid_config(field, v, "must be positive"));
            }
        }
        if !(self.kept_margin_m.is_finite() && self.kept_margin_m >= 0.0) {
            return Err(PlanError::invalid_config(
                "seen_obstacles.kept_margin_m",
                self.kept_margin_m,
                "must be zero or positive",
            ));
        }
        if self.budget_ms == 0 {
            return Err(PlanError::invalid_config(
                "seen_obstacles.budget_ms",
                self.budget_ms,
                "must be at least 1",
            ));
        }
        if self.max_expansions == 0 {
            return Err(PlanError::invalid_config(
                "seen_obstacles.max_expansions",
                self.max_expansions,
                "must be at least 1",
            ));
        }
        Ok(())
    }

    /// The discs (map frame) a plan from `robot` to `goal` keeps out of, one per reported point
    /// within `range_m`. A point closer to the robot than the full berth gets a disc shrunk to
    /// leave [`START_GAP_M`] round the robot, so the search can start, down to half of
    /// `radius_m`; closer than that the robot all but touches it and the collision monitor
    /// decides. A point within the berth of the goal is left out: no path could end there.
    #[must_use]
    pub fn discs(
        &self,
        points_m: &[[f64; 2]],
        robot: Pose2D,
        goal: Pose2D,
        own_radius_m: f64,
    ) -> Vec<Disc> {
        if !self.enabled {
            return Vec::new();
        }
        points_m
            .iter()
            .filter_map(|&[x_m, y_m]| {
                let from_robot_m = (x_m - robot.x_m).hypot(y_m - robot.y_m);
                let from_goal_m = (x_m - goal.x_m).hypot(y_m - goal.y_m);
                if from_robot_m > self.range_m || from_goal_m <= self.radius_m + own_radius_m {
                    return None;
                }
                let radius_m = self.radius_m.min(from_robot_m - own_radius_m - START_GAP_M);
                (radius_m >= 0.5 * self.radius_m).then_some(Disc { x_m, y_m, radius_m })
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn discs_leave_out_far_points_and_the_goal_and_shrink_next_to_the_robot() {
        let params = SeenObstacleParams {
            radius_m: 0.15,
            ..SeenObstacleParams::default()
        };
        let robot = Pose2D::new(0.0, 0.0, 0.0);
        let goal = Pose2D::new(10.0, 0.0, 0.0);
        let points = [
            [2.0, 0.0],   // ahead: full disc
            [0.4, 0.0],   // 0.4 m away: shrunk to 0.4 - 0.25 - 0.05 = 0.10
            [0.3, 0.0],   // too close to leave a half disc: the monitor's business
            [10.2, 0.0],  // beside the goal
            [7.0, 0.0],   // beyond range_m
            [-1.0, -1.0], // behind: still a disc (the robot may turn)
        ];
        let discs = params.discs(&points, robot, goal, 0.25);
        assert_eq!(discs.len(), 3, "{discs:?}");
        assert!((discs[0].radius_m - 0.15).abs() < 1e-12);
        assert!((discs[1].radius_m - 0.10).abs() < 1e-12);
        assert!((discs[2].x_m + 1.0).abs() < 1e-12);
        let off = SeenObstacleParams {
            enabled: false,
            ..params
        };
        assert!(off.discs(&points, robot, goal, 0.25).is_empty());
    }

    #[test]
    fn validation_names_the_field() {
        let bad = SeenObstacleParams {
            radius_m: -0.1,
            ..SeenObstacleParams::default()
        };
        let err = bad.validate().unwrap_err().to_string();
        assert!(err.contains("seen_obstacles.radius_m"), "{err}");
        let bad = SeenObstacleParams {
            max_expansions: 0,
            ..SeenObstacleParams::default()
        };
        assert!(bad
            .validate()
            .unwrap_err()
            .to_string()
            .contains("max_expansions"));
    }
}
