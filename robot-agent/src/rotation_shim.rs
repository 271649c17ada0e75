//! The rotation shim: a turn on the spot towards the path before the driving controller takes
//! the robot on (Nav2's `RotationShimController`).
//!
//! When a goal is reached and the next one lies behind the robot, the new path starts with a
//! turn in place. LPE-Net, trained on paths that lead ahead, drives on away from it for a metre
//! or two, slowly turns, and crawls back: on task E the turn-round at goal 3 cost 6 of
//! LPE-Net's 14 interventions in 20 runs (2026-11-27), as the person watching saw no progress
//! for 10 s. Nav2 puts a shim in front of its controllers for this: while the robot faces away
//! from the path by more than a threshold, the shim turns it on the spot, and hands back once
//! it faces the path.
//!
//! Here the heading to follow is the direction to the path point `forward_sampling_distance_m`
//! ahead of the robot's nearest path point. A robot rounding a corner may face 90 degrees off
//! that point for a moment without anything being wrong, so while the robot drives faster than
//! `engage_below_mps` the shim only takes over for a path behind it (`behind_rad`); once slower,
//! from `angular_dist_threshold_rad`. It hands back below `release_rad`.
//! That threshold is Nav2's default, 0.8 rad (0.785 there). From 1.2 rad (2026-11-27 to
//! 2026-11-29), DLM-Net crept towards the corridor's wall outside task D's first room for 3-4 s,
//! told `turn_right` and facing 0.9 rad off its path, until the recovery relieved it; at 0.8 the
//! shim turns it, and task D took 233 s instead of 242 (the dynamic window's 214: +9 % instead
//! of +13 %; docs/evaluation.md, round 26).
//!
//! A new goal is different: there the robot is not rounding a corner of its path but starting
//! one, and (as Nav2's shim does on every new path) the shim takes over from
//! `angular_dist_threshold_rad` at any speed, until the robot has faced the new path once
//! (`new_goal_turn`). The error is then measured against the path's own heading at the sampled
//! point, not the bearing to it: a new path starts with the planner's turn in place, and the
//! bearing to a point 0.6 m on lies half-way round that turn.
//! DLM-Net reached task D's first goal driving south at 0.56 m/s with the next path leading
//! east, 1.8 rad off: short of `behind_rad`, it drove a loop at its turning radius and came
//! back past the goal, 20 s of task D's 35 s behind the dynamic window (2026-11-29).
//!
//! Plain data in (pose, speed, the intention's path), a command out; the
//! [`Supervisor`](crate::Supervisor) gives the shim precedence over the driving controller, not
//! over the dynamic window while that recovers.

use protocol::{normalize_angle, Pose2D};

use crate::config::ConfigError;
use crate::controllers::path_tracker::{check_non_negative, check_positive};

/// The `[rotation_shim]` table.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RotationShimConfig {
    /// Off: the driving controller turns the robot round itself (the paper's setting).
    pub enabled: bool,
    /// The path direction is towards the path point this far along from the robot's nearest
    /// one.
    pub forward_sampling_distance_m: f64,
    /// A robot slower than this that faces further than `angular_dist_threshold_rad` from the
    /// path direction is turned on the spot ...
    pub engage_below_mps: f64,
    pub angular_dist_threshold_rad: f64,
    /// ... and at any speed when it faces further than this from it (the path is behind it).
    pub behind_rad: f64,
    /// The driving controller takes over again once the robot faces the path within this.
    pub release_rad: f64,
    /// Turn rate on the spot (within the limits' turn rate).
    pub rotate_to_heading_radps: f64,
    /// Within this much path of its end (the goal) the shim takes over from
    /// `angular_dist_threshold_rad` at any speed, and turns towards the goal itself once the
    /// path is shorter than `forward_sampling_distance_m`: a robot that drove past the goal a
    /// little to its side turns to it on the spot instead of looping round. 0: never.
    pub goal_near_m: f64,
    /// On a new goal's path the shim takes over from `angular_dist_threshold_rad` at any speed,
    /// turning to the path's own heading, until the robot has faced that path once.
    pub new_goal_turn: bool,
}

impl Default for RotationShimConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            forward_sampling_distance_m: 0.6,
            engage_below_mps: 0.15,
            angular_dist_threshold_rad: 0.8,
            behind_rad: 2.0,
            release_rad: 0.35,
            rotate_to_heading_radps: 1.0,
            goal_near_m: 1.0,
            new_goal_turn: true,
        }
    }
}

impl RotationShimConfig {
    /// Checks ranges that serde cannot express.
    ///
    /// # Errors
    /// [`ConfigError::Invalid`] naming the first bad field and its value.
    pub fn validate(&self) -> Result<(), ConfigError> {
        check_positive(&[
            (
                "rotation_shim.forward_sampling_distance_m",
                self.forward_sampling_distance_m,
            ),
            ("rotation_shim.engage_below_mps", self.engage_below_mps),
            (
                "rotation_shim.angular_dist_threshold_rad",
                self.angular_dist_threshold_rad,
            ),
            ("rotation_shim.behind_rad", self.behind_rad),
            ("rotation_shim.release_rad", self.release_rad),
            (
                "rotation_shim.rotate_to_heading_radps",
                self.rotate_to_heading_radps,
            ),
        ])?;
        check_non_negative(&[("rotation_shim.goal_near_m", self.goal_near_m)])?;
        let invalid = |field, v: f64, reason| {
            Err(ConfigError::Invalid {
                field,
                value: v.to_string(),
                reason,
            })
        };
        if self.release_rad >= self.angular_dist_threshold_rad {
            return invalid(
                "rotation_shim.release_rad",
                self.release_rad,
                "must be below angular_dist_threshold_rad",
            );
        }
        if self.angular_dist_threshold_rad > self.behind_rad {
            return invalid(
                "rotation_shim.angular_dist_threshold_rad",
                self.angular_dist_threshold_rad,
                "must not exceed behind_rad",
            );
        }
        if self.behind_rad > std::f64::consts::PI {
            return invalid(
                "rotation_shim.behind_rad",
                self.behind_rad,
                "must not exceed pi",
            );
        }
        Ok(())
    }
}

/// How far along the path the robot's nearest point is looked for: the intention's path starts
/// at the pose it answered, a cycle or two old, and a later stretch passing close by (a path
/// that turns back) must not be taken for it.
const NEAREST_WINDOW_M: f64 = 1.5;
/// Below this heading error the turn rate falls off in proportion, so the turn ends without
/// overshooting.
const SLOWDOWN_RAD: f64 = 0.6;
/// Closer to the goal than this its bearing is noise (and the goal is reached: the fleet's
/// tolerance is 0.35 m).
const GOAL_BEARING_MIN_M: f64 = 0.1;
/// Slowest turn rate on the spot (static friction, and a turn that ends).
const MIN_TURN_RADPS: f64 = 0.25;
/// The path's end moving this far is a new goal (replanning towards the same goal keeps it to
/// within a grid cell).
const NEW_GOAL_M: f64 = 0.5;

/// The shim's state: whether it is turning the robot.
#[derive(Debug, Clone, Default)]
pub struct RotationShim {
    config: RotationShimConfig,
    turning: bool,
    turns: u32,
    /// The end of the last path seen (the goal).
    goal: Option<Pose2D>,
    /// A new goal's path the robot has not yet faced.
    fresh: bool,
}

impl RotationShim {
    #[must_use]
    pub fn new(config: RotationShimConfig) -> Self {
        Self {
            config,
            turning: false,
            turns: 0,
            goal: None,
            fresh: false,
        }
    }

    /// Whether the shim turned the robot in the last cycle.
    #[must_use]
    pub fn turning(&self) -> bool {
        self.turning
    }

    /// How many turns on the spot the shim has made.
    #[must_use]
    pub fn turns(&self) -> u32 {
        self.turns
    }

    /// Forgets a turn under way (a stop, an intervention, the recovery taking over), and that
    /// the path is new: whoever drove since left the robot where it is.
    pub fn reset(&mut self) {
        self.turning = false;
        self.fresh = false;
    }

    /// The command (v, ω) for this cycle while the robot must turn towards `path`, `None` when
    /// the driving controller drives. `v_mps` is the robot's speed now, `max_turn_radps` the
    /// base's turn rate limit.
    pub fn command(
        &mut self,
        pose: Pose2D,
        v_mps: f64,
        path: &[Pose2D],
        max_turn_radps: f64,
    ) -> Option<(f64, f64)> {
        let c = self.config;
        if let Some(&end) = path.last() {
            if c.new_goal_turn && self.goal.is_none_or(|g| g.distance_m(&end) >= NEW_GOAL_M) {
                self.fresh = true;
            }
            self.goal = Some(end);
        }
        let near_goal = path_left_m(pose, path) < c.goal_near_m;
        let Some(error) = c
            .enabled
            .then(|| {
                if self.fresh {
                    path_yaw_error_rad(pose, path, c.forward_sampling_distance_m)
                } else {
                    heading_error_rad(pose, path, c.forward_sampling_distance_m)
                }
                .or_else(|| near_goal.then(|| goal_error_rad(pose, path)).flatten())
            })
            .flatten()
        else {
            self.turning = false;
            return None;
        };
        let engage = if self.fresh || near_goal || v_mps.abs() < c.engage_below_mps {
            c.angular_dist_threshold_rad
        } else {
            c.behind_rad
        };
        let turning = if self.turning {
            error.abs() > c.release_rad
        } else {
            error.abs() > engage
        };
        if turning && !self.turning {
            self.turns += 1;
            tracing::debug!(
                error_rad = error,
                v_mps,
                "rotation shim turns towards the path"
            );
        }
        self.turning = turning;
        if !turning {
            // Facing the new path (or turned to it): from here on corners are corners.
            self.fresh = false;
        }
        turning.then(|| {
            let rate = c.rotate_to_heading_radps.min(max_turn_radps);
            let w = (rate * (error.abs() / SLOWDOWN_RAD).min(1.0)).max(MIN_TURN_RADPS.min(rate));
            (0.0, w.copysign(error))
        })
    }
}

/// The signed angle (radians, counter-clockwise positive) from the robot's heading to the
/// direction of the path point `ahead_m` along from the robot's nearest point; `None` when the
/// path ends closer than that (the goal is near: see [`goal_error_rad`]).
#[must_use]
pub fn heading_error_rad(pose: Pose2D, path: &[Pose2D], ahead_m: f64) -> Option<f64> {
    let target = point_ahead(pose, path, ahead_m)?;
    let bearing = (target.y_m - pose.y_m).atan2(target.x_m - pose.x_m);
    Some(normalize_angle(bearing - pose.yaw_rad))
}

/// The signed angle from the robot's heading to the path's own heading at the point `ahead_m`
/// along from the robot's nearest point; `None` when the path ends closer than that. A new
/// goal's path starts with the planner's turn in place where the robot stands: the bearing to a
/// point 0.6 m on lies half-way round that turn (task D's first goal: 1.05 rad against the
/// path's 1.9), the path's heading there is where the turn ends.
#[must_use]
pub fn path_yaw_error_rad(pose: Pose2D, path: &[Pose2D], ahead_m: f64) -> Option<f64> {
    let target = point_ahead(pose, path, ahead_m)?;
    Some(normalize_angle(target.yaw_rad - pose.yaw_rad))
}

/// The first path pose at least `ahead_m` from the robot, from its nearest one on; `None` for a
/// path of fewer than two poses or one that ends closer.
fn point_ahead(pose: Pose2D, path: &[Pose2D], ahead_m: f64) -> Option<&Pose2D> {
    if path.len() < 2 {
        return None;
    }
    path[nearest_index(pose, path)..]
        .iter()
        .find(|p| p.distance_m(&pose) >= ahead_m)
}

/// The signed angle from the robot's heading to the direction of the path's end (the goal);
/// `None` for a path of fewer than two poses or an end within [`GOAL_BEARING_MIN_M`].
fn goal_error_rad(pose: Pose2D, path: &[Pose2D]) -> Option<f64> {
    let goal = path.get(1..)?.last()?;
    (goal.distance_m(&pose) >= GOAL_BEARING_MIN_M)
        .then(|| normalize_angle((goal.y_m - pose.y_m).atan2(goal.x_m - pose.x_m) - pose.yaw_rad))
}

/// The length of `path` from the robot's nearest point to its end (infinite for a path of
/// fewer than two poses: no goal to be near).
fn path_left_m(pose: Pose2D, path: &[Pose2D]) -> f64 {
    if path.len() < 2 {
        return f64::INFINITY;
    }
    path[nearest_index(pose, path)..]
        .windows(2)
        .map(|w| w[0].distance_m(&w[1]))
        .sum()
}

/// The index of the path pose nearest to `pose` among those within [`NEAREST_WINDOW_M`] of the
/// path's start (0 for an empty path): where the robot is along the path it was sent.
pub(crate) fn nearest_index(pose: Pose2D, path: &[Pose2D]) -> usize {
    let mut along_m = 0.0;
    let mut nearest = (f64::INFINITY, 0);
    for (i, p) in path.iter().enumerate() {
        if i > 0 {
            along_m += path[i - 1].distance_m(p);
        }
        if along_m > NEAREST_WINDOW_M {
            break;
        }
        let d = p.distance_m(&pose);
        if d < nearest.0 {
            nearest = (d, i);
        }
    }
    nearest.1
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A straight path east from (x0, 0), 0.2 m spacing, `n` poses.
    fn east(x0: f64, n: usize) -> Vec<Pose2D> {
        (0..n)
            .map(|i| Pose2D::new(x0 + 0.2 * i as f64, 0.0, 0.0))
            .collect()
    }

    #[test]
    fn turns_round_when_the_next_path_is_behind_and_hands_back_facing_it() {
        let mut shim = RotationShim::new(RotationShimConfig::default());
        // At a goal, facing west; the next leg starts with a turn in place and leads east.
        let mut path = vec![Pose2D::new(0.0, 0.0, std::f64::consts::PI); 3];
        path.extend(east(0.0, 20));
        let mut pose = Pose2D::new(0.0, 0.05, std::f64::consts::PI);
        // Still driving at 0.4 m/s: a path behind engages the shim at any speed.
        let (v, w) = shim.command(pose, 0.4, &path, 1.2).expect("turns");
        assert_eq!(v, 0.0);
        assert!(w.abs() > 0.9, "full turn rate far off the heading: {w}");
        turn_until_handed_back(&mut shim, &mut pose, &path);
        let error = heading_error_rad(pose, &path, 0.6).expect("a direction");
        assert!(error.abs() <= 0.35, "hands back facing the path: {error}");
        assert!(!shim.turning());
        assert_eq!(shim.turns(), 1);
        // Facing it, the controller drives; the shim stays out of the way.
        assert!(shim.command(pose, 0.3, &path, 1.2).is_none());
    }

    /// The robot standing at `pose` turns on the spot at the shim's rate, 0.1 s a cycle, until
    /// the shim hands back (within 100 cycles).
    fn turn_until_handed_back(shim: &mut RotationShim, pose: &mut Pose2D, path: &[Pose2D]) {
        let mut cycles = 0;
        while let Some((_, w)) = shim.command(*pose, 0.0, path, 1.2) {
            pose.yaw_rad = normalize_angle(pose.yaw_rad + 0.1 * w);
            cycles += 1;
            assert!(cycles < 100, "the turn ends");
        }
    }

    /// A shim that has seen `path` from its start, the robot facing along it: a path being
    /// followed, not a new goal's.
    fn following(path: &[Pose2D]) -> RotationShim {
        following_with(RotationShimConfig::default(), path)
    }

    fn following_with(config: RotationShimConfig, path: &[Pose2D]) -> RotationShim {
        let mut shim = RotationShim::new(config);
        let mut start = path[0];
        start.yaw_rad += path_yaw_error_rad(start, path, 0.6).unwrap_or(0.0);
        assert!(shim.command(start, 0.5, path, 1.2).is_none());
        shim
    }

    #[test]
    fn leaves_a_robot_rounding_a_corner_alone() {
        // East to (1, 0), then north: the robot at the corner still faces east.
        let mut path = east(0.0, 6);
        path.extend((1..10).map(|i| Pose2D::new(1.0, 0.2 * f64::from(i), 1.57)));
        let mut shim = following(&path);
        let pose = Pose2D::new(0.95, 0.0, 0.0);
        let error = heading_error_rad(pose, &path, 0.6).expect("a direction");
        assert!(error > 1.2 && error < 2.0, "a corner's error: {error}");
        assert!(
            shim.command(pose, 0.5, &path, 1.2).is_none(),
            "driving on round the corner"
        );
        // Standing there that far off, it turns.
        assert!(shim.command(pose, 0.0, &path, 1.2).is_some());
    }

    /// Task D's path out of its first room's door and south down the corridor (2026-11-29,
    /// seed 0, the planner's answer at 49.6 s): the robot stood at (8.54, 19.44) with the
    /// corridor's east wall 0.5 m ahead.
    fn out_of_task_ds_door() -> Vec<Pose2D> {
        [
            (8.54, 19.44, -0.71),
            (8.55, 18.93, -1.78),
            (8.50, 18.73, -1.87),
            (8.43, 18.53, -1.93),
            (8.35, 18.33, -1.95),
            (8.27, 18.12, -1.93),
            (8.21, 17.92, -1.85),
            (8.16, 17.72, -1.77),
            (8.13, 17.52, -1.68),
            (8.11, 17.32, -1.62),
            (8.10, 17.07, -1.59),
            (8.10, 16.82, -1.56),
        ]
        .iter()
        .map(|&(x, y, yaw)| Pose2D::new(x, y, yaw))
        .collect()
    }

    #[test]
    fn turns_a_robot_creeping_at_a_wall_from_nav2s_threshold() {
        // DLM-Net, told turn_right, crept at 0.03 m/s towards the wall for 3-4 s, facing
        // 0.94 rad off its path, until the recovery's cornered trigger relieved it.
        let path = out_of_task_ds_door();
        let mut pose = Pose2D::new(8.54, 19.44, -0.69);
        let error = heading_error_rad(pose, &path, 0.6).expect("a direction");
        assert!(error < -0.8 && error > -1.2, "{error}");
        let mut shim = following(&path);
        let (v, w) = shim.command(pose, 0.03, &path, 1.2).expect("turns");
        assert_eq!(v, 0.0);
        assert!(w < -0.9, "clockwise, towards the corridor: {w}");
        turn_until_handed_back(&mut shim, &mut pose, &path);
        let error = heading_error_rad(pose, &path, 0.6).expect("a direction");
        assert!(error.abs() <= 0.35, "faces down the corridor: {error}");
        // Driving at speed that far off is rounding the corner: left to the controller.
        let corner = Pose2D::new(8.54, 19.44, -0.69);
        assert!(following(&path).command(corner, 0.5, &path, 1.2).is_none());
        // From round 24's 1.2 rad, the creep went on.
        let mut old = following_with(
            RotationShimConfig {
                angular_dist_threshold_rad: 1.2,
                ..RotationShimConfig::default()
            },
            &path,
        );
        assert!(old.command(corner, 0.03, &path, 1.2).is_none());
    }

    #[test]
    fn turns_to_a_goal_passed_to_its_side_instead_of_looping_round() {
        // Task B's last goal (2026-11-29): the robot drove north past it 0.39 m to its west at
        // 0.58 m/s, its path now 0.39 m east; DLM-Net looped a 1.5 m circle round and the
        // person watching intervened after 10 s without progress.
        let mut shim = RotationShim::new(RotationShimConfig::default());
        let path = vec![Pose2D::new(29.61, 16.02, 0.0), Pose2D::new(30.0, 16.0, 0.0)];
        let mut pose = Pose2D::new(29.61, 16.02, 1.57);
        let (v, w) = shim
            .command(pose, 0.58, &path, 1.2)
            .expect("turns at speed");
        assert_eq!(v, 0.0);
        assert!(w < -0.9, "clockwise, towards the goal: {w}");
        turn_until_handed_back(&mut shim, &mut pose, &path);
        assert!(
            pose.yaw_rad.abs() <= 0.35,
            "faces the goal: {}",
            pose.yaw_rad
        );
        // Facing it and on the goal itself: nothing to turn to.
        assert!(shim.command(pose, 0.0, &path, 1.2).is_none());
        let at_goal = Pose2D::new(29.95, 16.0, 2.0);
        assert!(shim.command(at_goal, 0.0, &path, 1.2).is_none());
        // Far from the goal a path beside the robot is a corner being rounded: left alone.
        let mut long = vec![Pose2D::new(29.61, 16.02, 0.0)];
        long.extend((1..20).map(|i| Pose2D::new(29.61 + 0.2 * f64::from(i), 16.0, 0.0)));
        assert!(following(&long)
            .command(Pose2D::new(29.61, 16.02, 1.57), 0.58, &long, 1.2)
            .is_none());
    }

    /// Task D's next path from its first goal (2026-11-29, planner's answer): a turn in place
    /// from -1.83 to -0.9 rad where the robot stands, 0.3 m straight on, a left arc of 0.5 m
    /// radius to east, and east; 0.1 m spacing.
    fn turn_then_arc_east() -> Vec<Pose2D> {
        let mut path: Vec<Pose2D> = (0..=4)
            .map(|i| Pose2D::new(0.0, 0.0, -1.83 + 0.2325 * f64::from(i)))
            .collect();
        let mut p = Pose2D::new(0.0, 0.0, -0.9);
        for k in 0..60 {
            let turn = if (3..12).contains(&k) { 0.1 } else { 0.0 };
            p.yaw_rad += turn;
            p.x_m += 0.1 * p.yaw_rad.cos();
            p.y_m += 0.1 * p.yaw_rad.sin();
            path.push(p);
        }
        path
    }

    #[test]
    fn turns_at_speed_to_a_new_goal_path_but_not_at_its_corners() {
        // DLM-Net reached task D's first goal driving south at 0.56 m/s; the path to the next
        // goal starts with a turn in place. The bearing to the point 0.6 m on is 1.05 rad off,
        // short of the threshold; the path's own heading there is 1.6 rad off.
        let path = turn_then_arc_east();
        let mut pose = Pose2D::new(0.0, 0.0, -1.83);
        let bearing = heading_error_rad(pose, &path, 0.6).expect("a direction");
        assert!(bearing > 0.9 && bearing < 1.2, "{bearing}");
        let mut shim = following(&east(-4.0, 20));
        let (v, w) = shim
            .command(pose, 0.56, &path, 1.2)
            .expect("a new goal's path: turns at speed");
        assert_eq!(v, 0.0);
        assert!(w > 0.9, "counter-clockwise, towards east: {w}");
        turn_until_handed_back(&mut shim, &mut pose, &path);
        let error = path_yaw_error_rad(pose, &path, 0.6).expect("a direction");
        assert!(error.abs() <= 0.35, "faces the path's heading: {error}");
        // Once faced, the same goal's path is an ordinary one: far off it at speed (a corner)
        // is left to the controller.
        let corner = Pose2D::new(0.0, 0.0, -1.83);
        assert!(shim.command(corner, 0.56, &path, 1.2).is_none());
        // The same arrival with the old goal's path still in force: left alone too.
        let mut same = following(&path);
        assert!(same.command(corner, 0.56, &path, 1.2).is_none());
        // Told not to: a new goal's path is any other.
        let mut off = RotationShim::new(RotationShimConfig {
            new_goal_turn: false,
            ..RotationShimConfig::default()
        });
        assert!(off.command(corner, 0.56, &path, 1.2).is_none());
    }

    #[test]
    fn stays_out_near_the_goal_when_told_and_when_off() {
        let mut shim = RotationShim::new(RotationShimConfig {
            goal_near_m: 0.0,
            ..RotationShimConfig::default()
        });
        let pose = Pose2D::new(0.0, 0.0, std::f64::consts::PI);
        // The path ends within the sampling distance: the goal is the controller's business.
        assert!(shim.command(pose, 0.0, &east(0.0, 3), 1.2).is_none());
        let mut off = RotationShim::new(RotationShimConfig {
            enabled: false,
            ..RotationShimConfig::default()
        });
        assert!(off.command(pose, 0.0, &east(0.0, 20), 1.2).is_none());
    }

    #[test]
    fn the_nearest_point_is_not_taken_from_a_later_stretch_passing_close_by() {
        // Out east 3 m and back west 0.3 m to the north: the robot at the start, facing east.
        let mut path = east(0.0, 16);
        path.extend(
            (0..16)
                .rev()
                .map(|i| Pose2D::new(0.2 * i as f64, 0.3, std::f64::consts::PI)),
        );
        let pose = Pose2D::new(0.0, 0.15, 0.0);
        let error = heading_error_rad(pose, &path, 0.6).expect("a direction");
        assert!(error.abs() < 0.4, "follows the path's start, east: {error}");
    }

    #[test]
    fn bad_values_are_named() {
        for (bad, field) in [
            (
                RotationShimConfig {
                    release_rad: 1.5,
                    ..RotationShimConfig::default()
                },
                "rotation_shim.release_rad",
            ),
            (
                RotationShimConfig {
                    behind_rad: 4.0,
                    ..RotationShimConfig::default()
                },
                "rotation_shim.behind_rad",
            ),
            (
                RotationShimConfig {
                    rotate_to_heading_radps: 0.0,
                    ..RotationShimConfig::default()
                },
                "rotation_shim.rotate_to_heading_radps",
            ),
        ] {
            match bad.validate() {
                Err(ConfigError::Invalid { field: f, .. }) => assert_eq!(f, field),
                other => panic!("{field}: {other:?}"),
            }
        }
        RotationShimConfig::default().validate().expect("defaults");
    }
}
