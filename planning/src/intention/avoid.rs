//! Other robots as obstacles: a robot's plan keeps clear of the fleet's robots near it.
//!
//! The floor plan knows walls, not the fleet. Two robots sent down one corridor towards each
//! other each planned straight through the other, and their controllers met head-on: each held
//! back by its collision monitor, each stepping aside the same way, until they touched and stood
//! (observed in the two-robot demo, docs/benchmarks.md "Robots that meet"). The fleet knows
//! where every robot is, so the planner can route each robot round the others it is about to
//! meet, as a local costmap's robot layer would. Each other robot is a disc; one ahead has its
//! disc moved to the planning robot's left (`keep_right_m`), so two robots meeting head-on both
//! keep right; one coming towards the planning robot gets discs along its way up to where the
//! two would meet; one ahead driving away is followed, not gone round.
//!
//! Plain data: the caller passes the other robots' poses and velocities ([`Neighbour`]; the
//! fleet sends those within its `neighbour_radius_m`); [`AvoidParams`] say how wide a berth and
//! how long a search may try.
//! When no path keeps clear (the other robot stands on the goal or fills the corridor), the
//! robot gets the plan on the floor plan alone, as before, and its collision monitor holds it
//! back; the avoiding search is not tried again for `retry_cycles`, so a blocked robot does not
//! pay a failed search every cycle.

use protocol::Pose2D;
use serde::{Deserialize, Serialize};

use crate::error::PlanError;
use crate::map::Disc;

/// Another robot of the fleet as a planner sees it (map frame): where it is and how it moves.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Neighbour {
    pub pose: Pose2D,
    /// Velocity from its last poses; 0 when not known (a first pose), as for a robot standing.
    #[serde(default)]
    pub vx_mps: f64,
    #[serde(default)]
    pub vy_mps: f64,
}

impl Neighbour {
    /// A robot standing at `pose`.
    #[must_use]
    pub fn standing(pose: Pose2D) -> Self {
        Self {
            pose,
            vx_mps: 0.0,
            vy_mps: 0.0,
        }
    }

    /// Its speed along the unit vector (`ux`, `uy`).
    fn speed_along(&self, ux: f64, uy: f64) -> f64 {
        self.vx_mps * ux + self.vy_mps * uy
    }
}

/// A robot ahead that moves away from the planning robot at least this fast is clearing the
/// way: following it is the collision monitor's business, and a disc would send the follower
/// round it for as long as it keeps pace.
pub const CLEARING_MPS: f64 = 0.2;

/// Room left between the planning robot and a disc shrunk to let its search start.
pub const START_GAP_M: f64 = 0.05;

/// The `[other_robots]` table: how a plan keeps clear of the fleet's other robots.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct AvoidParams {
    /// Off: plans see the floor plan only (the paper's single robot).
    pub enabled: bool,
    /// Radius of the disc kept clear round another robot's centre, on top of the planning
    /// robot's own radius (the planner's `robot_radius_m`): the other robot's radius plus a
    /// margin.
    pub radius_m: f64,
    /// Time budget of a search round other robots (the configured budget is for the floor
    /// plan alone; a closed way exhausts this one).
    pub budget_ms: u64,
    /// After a search round other robots found no path, this many cycles plan on the floor
    /// plan alone before the next try.
    pub retry_cycles: u32,
    /// The disc of a robot ahead is moved this far to the planning robot's left and grown by
    /// as much, so the berth on its right stays `radius_m` and the one on its left grows by
    /// twice this: the shorter way round is on the right, and two robots meeting head-on each
    /// keep right and pass, instead of both picking the same side and meeting again. 0:
    /// centred discs.
    pub keep_right_m: f64,
}

impl Default for AvoidParams {
    fn default() -> Self {
        Self {
            enabled: true,
            radius_m: 0.4,
            budget_ms: 60,
            retry_cycles: 10,
            keep_right_m: 0.15,
        }
    }
}

impl AvoidParams {
    /// # Errors
    /// [`PlanError::InvalidConfig`] naming the field and value.
    pub fn validate(&self) -> Result<(), PlanError> {
        if !(self.radius_m.is_finite() && self.radius_m > 0.0) {
            return Err(PlanError::invalid_config(
                "other_robots.radius_m",
                self.radius_m,
                "must be positive",
            ));
        }
        if !(self.keep_right_m.is_finite() && self.keep_right_m >= 0.0) {
            return Err(PlanError::invalid_config(
                "other_robots.keep_right_m",
                self.keep_right_m,
                "must be zero or positive",
            ));
        }
        if self.budget_ms == 0 {
            return Err(PlanError::invalid_config(
                "other_robots.budget_ms",
                self.budget_ms,
                "must be at least 1",
            ));
        }
        Ok(())
    }

    /// The discs (map frame) a plan from `robot` to `goal` keeps out of (see
    /// `oncoming_trail` and `keep_right_m`), and how many robots they stand for. A robot that
    /// moves away at [`CLEARING_MPS`] or more gets none. A robot closer than the full berth gets a disc shrunk to leave the planning robot
    /// [`START_GAP_M`] outside it, so the search can start (a robot standing right in front
    /// is still gone round), down to half of `radius_m`: closer than that, the robots are all
    /// but touching and the collision monitor decides. A robot within the berth of the goal is
    /// left out: no path could end there. `own_radius_m` is the planning robot's radius.
    #[must_use]
    pub fn discs(
        &self,
        others: &[Neighbour],
        robot: Pose2D,
        goal: Pose2D,
        own_radius_m: f64,
    ) -> (Vec<Disc>, usize) {
        let mut discs = Vec::new();
        let mut robots = 0;
        if !self.enabled {
            return (discs, robots);
        }
        let (sin, cos) = robot.yaw_rad.sin_cos();
        for other in others
            .iter()
            .filter(|o| o.pose.distance_m(&goal) > self.radius_m + own_radius_m)
        {
            let (dx, dy) = (other.pose.x_m - robot.x_m, other.pose.y_m - robot.y_m);
            let gap_m = dx.hypot(dy);
            if gap_m > 1e-9 && other.speed_along(dx / gap_m, dy / gap_m) >= CLEARING_MPS {
                continue;
            }
            let before = discs.len();
            discs.extend(oncoming_trail(other, robot).into_iter().filter_map(|o| {
                let ahead = (o.x_m - robot.x_m) * cos + (o.y_m - robot.y_m) * sin > 0.0;
                let shift_m = if ahead { self.keep_right_m } else { 0.0 };
                let (x_m, y_m) = (o.x_m - shift_m * sin, o.y_m + shift_m * cos);
                let room_m = (x_m - robot.x_m).hypot(y_m - robot.y_m) - own_radius_m - START_GAP_M;
                let radius_m = (self.radius_m + shift_m).min(room_m);
                (radius_m >= 0.5 * self.radius_m).then_some(Disc { x_m, y_m, radius_m })
            }));
            robots += usize::from(discs.len() > before);
        }
        (discs, robots)
    }
}

/// Spacing of the discs laid along an oncoming robot's way.
pub const TRAIL_STEP_M: f64 = 0.5;

/// Slowest a robot may move to count as coming towards the planning robot.
pub const ONCOMING_MPS: f64 = 0.1;

/// Where another robot will be while the two close in: its pose, and when it moves towards the
/// planning robot (at [`ONCOMING_MPS`] or more, within 60 degrees of the direction to it) also
/// points along its way every [`TRAIL_STEP_M`] up to half the gap between them. Two robots
/// driving at each other meet halfway; a disc only where the other robot is now would have
/// each swerve by the time it reaches that spot, too late.
fn oncoming_trail(other: &Neighbour, robot: Pose2D) -> Vec<Pose2D> {
    let o = other.pose;
    let (dx, dy) = (robot.x_m - o.x_m, robot.y_m - o.y_m);
    let gap_m = dx.hypot(dy);
    let speed_mps = other.vx_mps.hypot(other.vy_mps);
    let mut trail = vec![o];
    if gap_m > 1e-9
        && speed_mps >= ONCOMING_MPS
        && other.speed_along(dx / gap_m, dy / gap_m) >= 0.5 * speed_mps
    {
        let (ux, uy) = (other.vx_mps / speed_mps, other.vy_mps / speed_mps);
        let mut s = TRAIL_STEP_M;
        while s <= 0.5 * gap_m {
            trail.push(Pose2D::new(o.x_m + s * ux, o.y_m + s * uy, o.yaw_rad));
            s += TRAIL_STEP_M;
        }
    }
    trail
}

/// Whether a robot of radius `own_radius_m` following `path` (map frame) keeps out of every one
/// of `discs` (map frame).
#[must_use]
pub fn path_clear_of(path: &[Pose2D], discs: &[Disc], own_radius_m: f64) -> bool {
    discs
        .iter()
        .all(|d| path.iter().all(|p| d.gap_m(p.x_m, p.y_m) >= own_radius_m))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn discs_shrink_for_a_robot_close_by_and_leave_out_one_touching_or_on_the_goal() {
        let params = AvoidParams {
            keep_right_m: 0.0,
            ..AvoidParams::default()
        };
        let robot = Pose2D::new(0.0, 0.0, 0.0);
        let goal = Pose2D::new(10.0, 0.0, 0.0);
        let others = [
            // Standing: one disc.
            Pose2D::new(5.0, 0.0, 3.1),
            // 0.6 m ahead: within the full berth (0.65 m), so shrunk to leave 5 cm.
            Pose2D::new(0.6, 0.0, 0.0),
            // Touching, and on the goal: left out.
            Pose2D::new(0.4, 0.1, 0.0),
            Pose2D::new(9.6, 0.2, 0.0),
        ]
        .map(Neighbour::standing);
        let (discs, robots) = params.discs(&others, robot, goal, 0.25);
        assert_eq!(robots, 2);
        assert_eq!(discs.len(), 2, "{discs:?}");
        assert_eq!(
            discs[0],
            Disc {
                x_m: 5.0,
                y_m: 0.0,
                radius_m: 0.4
            }
        );
        assert!((discs[1].radius_m - 0.3).abs() < 1e-9, "{discs:?}");
        let off = AvoidParams {
            enabled: false,
            ..params
        };
        assert!(off.discs(&others, robot, goal, 0.25).0.is_empty());
    }

    #[test]
    fn a_robot_ahead_is_passed_on_the_right_from_either_side() {
        let params = AvoidParams::default();
        let east = Pose2D::new(0.0, 0.0, 0.0);
        let west = Pose2D::new(4.0, 0.0, std::f64::consts::PI);
        let driving = |pose: Pose2D| Neighbour {
            pose,
            vx_mps: 0.5 * pose.yaw_rad.cos(),
            vy_mps: 0.5 * pose.yaw_rad.sin(),
        };
        // Each sees the other's disc moved to its own left: north for the one facing east,
        // south for the one facing west; both go round on their right.
        let (seen_by_east, _) =
            params.discs(&[driving(west)], east, Pose2D::new(10.0, 0.0, 0.0), 0.25);
        let (seen_by_west, _) =
            params.discs(&[driving(east)], west, Pose2D::new(-4.0, 0.0, 0.0), 0.25);
        assert!(
            (seen_by_east[0].y_m - 0.15).abs() < 1e-9,
            "{seen_by_east:?}"
        );
        // Grown by as much: the berth on the right is the configured one.
        assert!(
            (seen_by_east[0].radius_m - 0.55).abs() < 1e-9,
            "{seen_by_east:?}"
        );
        assert!(
            (seen_by_west[0].y_m + 0.15).abs() < 1e-9,
            "{seen_by_west:?}"
        );
        // Facing each other 4 m apart: a disc every 0.5 m of the other's way up to halfway.
        assert_eq!(seen_by_east.len(), 5, "{seen_by_east:?}");
        assert!((seen_by_east[4].x_m - 2.0).abs() < 1e-9, "{seen_by_east:?}");
        // A robot behind keeps its place.
        let goal = Pose2D::new(10.0, 0.0, 0.0);
        let (behind, _) = params.discs(
            &[Neighbour::standing(Pose2D::new(-3.0, 0.0, 0.0))],
            east,
            goal,
            0.25,
        );
        assert!(behind[0].y_m.abs() < 1e-9);
        // Standing and facing us: one disc, no trail.
        let (parked, _) = params.discs(&[Neighbour::standing(west)], east, goal, 0.25);
        assert_eq!(parked.len(), 1);
        // Ahead and driving away: clearing the way, no disc.
        let leader = driving(Pose2D::new(2.0, 0.0, 0.0));
        assert_eq!(params.discs(&[leader], east, goal, 0.25), (Vec::new(), 0));
    }

    #[test]
    fn a_path_through_a_disc_is_not_clear() {
        let disc = Disc {
            x_m: 2.0,
            y_m: 0.0,
            radius_m: 0.4,
        };
        let straight: Vec<Pose2D> = (0..40)
            .map(|i| Pose2D::new(0.1 * f64::from(i), 0.0, 0.0))
            .collect();
        assert!(!path_clear_of(&straight, &[disc], 0.25));
        let aside: Vec<Pose2D> = straight
            .iter()
            .map(|p| Pose2D::new(p.x_m, 0.7, 0.0))
            .collect();
        assert!(path_clear_of(&aside, &[disc], 0.25));
        assert!(!path_clear_of(&aside, &[Disc { y_m: 0.1, ..disc }], 0.25));
    }

    #[test]
    fn bad_params_name_the_field_and_value() {
        let bad = AvoidParams {
            radius_m: -1.0,
            ..AvoidParams::default()
        };
        assert!(bad
            .validate()
            .unwrap_err()
            .to_string()
            .contains("other_robots.radius_m"));
        let bad = AvoidParams {
            budget_ms: 0,
            ..AvoidParams::default()
        };
        assert!(bad
            .validate()
            .unwrap_err()
            .to_string()
            .contains("other_robots.budget_ms"));
    }
}
