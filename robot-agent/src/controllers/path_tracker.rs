//! The paper's Path Tracker: pure pursuit on the planned path, with no camera and no obstacle
//! sensing (paper §4, the ablation that replaces the intention-net by a standard motion
//! controller). It drives well on an accurate floor plan and blindly into anything the plan does
//! not show, which is the point of the comparison.
//!
//! The module also holds the path geometry (projection onto the path, the look-ahead point) that
//! the dynamic window controller shares.

use protocol::Pose2D;

use super::{Control, ControlInput, Controller, ControllerError};
use crate::config::{ConfigError, ControllerKind, Limits};

const NAME: &str = "path-tracker";

/// Pure pursuit parameters (TOML table `[path_tracker]`, see `controllers.example.toml`).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PathTrackerConfig {
    /// Look-ahead distance at standstill.
    pub lookahead_m: f64,
    /// Extra look-ahead per unit of current speed (0 disables speed scaling).
    pub lookahead_per_speed_s: f64,
    /// Upper bound of the speed-scaled look-ahead.
    pub max_lookahead_m: f64,
    /// The goal (last path pose) counts as reached within this distance: the command is then 0.
    pub goal_tolerance_m: f64,
    /// Speed is capped so that v² · curvature stays below this, for the sharpest curvature within
    /// `curvature_window_m` beyond the look-ahead point.
    pub max_lateral_accel_mps2: f64,
    /// How far beyond the look-ahead point the path is scanned for sharp curvature.
    pub curvature_window_m: f64,
    /// When the look-ahead point is further off the heading than this, turn on the spot.
    pub rotate_in_place_rad: f64,
    /// Turn rate per radian of heading error while turning on the spot.
    pub rotate_gain_per_s: f64,
}

impl Default for PathTrackerConfig {
    fn default() -> Self {
        Self {
            lookahead_m: 0.6,
            lookahead_per_speed_s: 0.8,
            max_lookahead_m: 1.5,
            goal_tolerance_m: 0.2,
            max_lateral_accel_mps2: 0.35,
            curvature_window_m: 1.0,
            rotate_in_place_rad: 1.2,
            rotate_gain_per_s: 1.5,
        }
    }
}

impl PathTrackerConfig {
    /// Checks ranges that serde cannot express.
    ///
    /// # Errors
    /// [`ConfigError::Invalid`] naming the first bad field and its value.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let positive = [
            ("path_tracker.lookahead_m", self.lookahead_m),
            ("path_tracker.max_lookahead_m", self.max_lookahead_m),
            ("path_tracker.goal_tolerance_m", self.goal_tolerance_m),
            (
                "path_tracker.max_lateral_accel_mps2",
                self.max_lateral_accel_mps2,
            ),
            ("path_tracker.rotate_in_place_rad", self.rotate_in_place_rad),
            ("path_tracker.rotate_gain_per_s", self.rotate_gain_per_s),
        ];
        check_positive(&positive)?;
        check_non_negative(&[
            (
                "path_tracker.lookahead_per_speed_s",
                self.lookahead_per_speed_s,
            ),
            ("path_tracker.curvature_window_m", self.curvature_window_m),
        ])?;
        if self.max_lookahead_m < self.lookahead_m {
            return Err(ConfigError::Invalid {
                field: "path_tracker.max_lookahead_m",
                value: self.max_lookahead_m.to_string(),
                reason: "must be at least path_tracker.lookahead_m",
            });
        }
        Ok(())
    }
}

pub(crate) fn check_positive(values: &[(&'static str, f64)]) -> Result<(), ConfigError> {
    for &(field, v) in values {
        if !v.is_finite() || v <= 0.0 {
            return Err(ConfigError::Invalid {
                field,
                value: v.to_string(),
                reason: "must be a positive, finite number",
            });
        }
    }
    Ok(())
}

pub(crate) fn check_non_negative(values: &[(&'static str, f64)]) -> Result<(), ConfigError> {
    for &(field, v) in values {
        if !v.is_finite() || v < 0.0 {
            return Err(ConfigError::Invalid {
                field,
                value: v.to_string(),
                reason: "must be a finite number >= 0",
            });
        }
    }
    Ok(())
}

/// Pure pursuit on `intention.path` (the paper's Path Tracker).
#[derive(Debug, Clone)]
pub struct PathTracker {
    config: PathTrackerConfig,
}

impl PathTracker {
    /// A tracker with a checked configuration.
    ///
    /// # Errors
    /// [`ConfigError::Invalid`] when a parameter is out of range.
    pub fn new(config: PathTrackerConfig) -> Result<Self, ConfigError> {
        config.validate()?;
        Ok(Self { config })
    }

    #[must_use]
    pub fn config(&self) -> &PathTrackerConfig {
        &self.config
    }
}

impl Controller for PathTracker {
    fn kind(&self) -> ControllerKind {
        ControllerKind::PathTracker
    }

    fn control(&mut self, input: &ControlInput<'_>) -> Result<Control, ControllerError> {
        let c = &self.config;
        let Some(task) = checked_task(NAME, input, c.goal_tolerance_m)? else {
            return Ok(Control::default());
        };
        let limits = input.limits;
        let lookahead_m =
            (c.lookahead_m + c.lookahead_per_speed_s * input.v_mps.abs()).min(c.max_lookahead_m);
        // Near the goal the planner's path can loop (a hybrid-A* search from a pose heading past
        // the goal comes round at its minimum turning radius); pure pursuit along the loop passed
        // the goal just outside the tolerance and circled it. After Coulter's rule (the goal is
        // the look-ahead point when no path point lies beyond the look-ahead circle), with the
        // largest look-ahead circle: a loop at speed reaches beyond the speed-scaled one.
        let target = if task.path.stays_within(
            &task.projection,
            (input.pose.x_m, input.pose.y_m),
            c.max_lookahead_m,
        ) {
            task.path.goal()
        } else {
            task.path.point_ahead(&task.projection, lookahead_m)
        };
        let (tx, ty) = to_robot_frame(&input.pose, target);
        let alpha = ty.atan2(tx);

        let (v_des, omega_des) = if alpha.abs() > c.rotate_in_place_rad {
            // Pure pursuit would swing a wide loop towards a point behind; turn first.
            (0.0, c.rotate_gain_per_s * alpha)
        } else {
            let kappa = pursuit_curvature(tx, ty);
            // The sharpest curvature the robot will need soon: look past the look-ahead point
            // so that it is already slow when the bend arrives.
            let mut kappa_ahead = kappa.abs();
            let mut s = lookahead_m;
            while s < lookahead_m + c.curvature_window_m {
                s += 0.25;
                let p = task.path.point_ahead(&task.projection, s);
                let (px, py) = to_robot_frame(&input.pose, p);
                kappa_ahead = kappa_ahead.max(pursuit_curvature(px, py).abs());
            }
            let v = limits
                .max_speed_mps
                .min((c.max_lateral_accel_mps2 / kappa_ahead.max(1e-9)).sqrt())
                .min(limits.max_turn_radps / kappa.abs().max(1e-9))
                .min(goal_speed_cap(
                    task.goal_distance_m,
                    c.goal_tolerance_m,
                    limits,
                ));
            (v, f64::NAN)
        };
        let (v_lo, v_hi) = window(
            input.v_mps,
            limits.max_accel_mps2,
            input.dt_s,
            0.0,
            limits.max_speed_mps,
        );
        let v = v_des.clamp(v_lo, v_hi);
        // With the speed fixed, the curvature fixes the turn rate (ω = v κ).
        let omega_des = if omega_des.is_nan() {
            v * pursuit_curvature(tx, ty)
        } else {
            omega_des
        };
        let (w_lo, w_hi) = window(
            input.omega_radps,
            limits.max_turn_accel_radps2,
            input.dt_s,
            -limits.max_turn_radps,
            limits.max_turn_radps,
        );
        Ok(Control::from_physical(
            v,
            omega_des.clamp(w_lo, w_hi),
            limits,
        ))
    }
}

/// Curvature of the circle through the robot (tangent to its heading) and the point (x, y) in
/// the robot frame: pure pursuit's steering law, positive to the left.
#[must_use]
pub fn pursuit_curvature(x_m: f64, y_m: f64) -> f64 {
    let d2 = x_m * x_m + y_m * y_m;
    if d2 < 1e-12 {
        0.0
    } else {
        2.0 * y_m / d2
    }
}

/// The velocities reachable within one cycle from `now` at `accel` (Fox's dynamic window),
/// intersected with [lo, hi]. Always a valid interval, even when `now` lies outside [lo, hi].
pub(crate) fn window(now: f64, accel: f64, dt_s: f64, lo: f64, hi: f64) -> (f64, f64) {
    let reach = accel * dt_s;
    ((now - reach).clamp(lo, hi), (now + reach).clamp(lo, hi))
}

/// The highest speed from which the robot can still stop at the goal, braking at the limit.
pub(crate) fn goal_speed_cap(goal_distance_m: f64, tolerance_m: f64, limits: &Limits) -> f64 {
    // Aim to stop halfway into the tolerance disc, so that noise cannot leave it just outside.
    let d = (goal_distance_m - 0.5 * tolerance_m).max(0.0);
    (2.0 * limits.max_accel_mps2 * d).sqrt()
}

/// A map-frame point expressed in the robot frame of `pose`.
#[must_use]
pub fn to_robot_frame(pose: &Pose2D, (x_m, y_m): (f64, f64)) -> (f64, f64) {
    let (s, c) = pose.yaw_rad.sin_cos();
    let dx = x_m - pose.x_m;
    let dy = y_m - pose.y_m;
    (c * dx + s * dy, -s * dx + c * dy)
}

/// A checked, non-empty path in the map frame.
#[derive(Debug, Clone, Copy)]
pub(crate) struct PathRef<'a> {
    poses: &'a [Pose2D],
}

/// The closest point of a path to the robot: segment `segment` (from pose `segment` to
/// `segment + 1`) at fraction `t`.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Projection {
    segment: usize,
    t: f64,
}

impl<'a> PathRef<'a> {
    fn new(controller: &'static str, poses: &'a [Pose2D]) -> Result<Self, ControllerError> {
        if poses.is_empty() {
            return Err(ControllerError::BadInput {
                controller,
                input: "intention.path",
                reason: "the path is empty".into(),
            });
        }
        if let Some((i, p)) = poses
            .iter()
            .enumerate()
            .find(|(_, p)| !(p.x_m.is_finite() && p.y_m.is_finite()))
        {
            return Err(ControllerError::BadInput {
                controller,
                input: "intention.path",
                reason: format!("pose {i} is not finite: ({}, {})", p.x_m, p.y_m),
            });
        }
        Ok(Self { poses })
    }

    pub(crate) fn goal(&self) -> (f64, f64) {
        let p = self.poses[self.poses.len() - 1];
        (p.x_m, p.y_m)
    }

    /// The point of the path nearest to (x, y); the earliest one on ties, since the path starts
    /// at the robot.
    pub(crate) fn project(&self, x_m: f64, y_m: f64) -> Projection {
        let mut best = Projection { segment: 0, t: 0.0 };
        let mut best_d2 = f64::INFINITY;
        for (i, w) in self.poses.windows(2).enumerate() {
            let (ax, ay, bx, by) = (w[0].x_m, w[0].y_m, w[1].x_m, w[1].y_m);
            let (ex, ey) = (bx - ax, by - ay);
            let len2 = ex * ex + ey * ey;
            let t = if len2 < 1e-18 {
                0.0
            } else {
                (((x_m - ax) * ex + (y_m - ay) * ey) / len2).clamp(0.0, 1.0)
            };
            let (px, py) = (ax + t * ex, ay + t * ey);
            let d2 = (px - x_m).powi(2) + (py - y_m).powi(2);
            if d2 < best_d2 - 1e-12 {
                best_d2 = d2;
                best = Projection { segment: i, t };
            }
        }
        best
    }

    /// Whether every path point from `from` to the goal lies within `radius_m` of `centre`.
    pub(crate) fn stays_within(
        &self,
        from: &Projection,
        centre: (f64, f64),
        radius_m: f64,
    ) -> bool {
        self.poses[from.segment + 1..]
            .iter()
            .all(|p| (p.x_m - centre.0).hypot(p.y_m - centre.1) <= radius_m)
    }

    /// The point `distance_m` further along the path from `from`; the goal if the path ends first.
    pub(crate) fn point_ahead(&self, from: &Projection, distance_m: f64) -> (f64, f64) {
        let mut left = distance_m;
        let mut seg = from.segment;
        let mut t = from.t;
        while seg + 1 < self.poses.len() {
            let (a, b) = (self.poses[seg], self.poses[seg + 1]);
            let len = (b.x_m - a.x_m).hypot(b.y_m - a.y_m);
            let rest = (1.0 - t) * len;
            if rest >= left && len > 0.0 {
                let u = t + left / len;
                return (a.x_m + u * (b.x_m - a.x_m), a.y_m + u * (b.y_m - a.y_m));
            }
            left -= rest;
            seg += 1;
            t = 0.0;
        }
        self.goal()
    }
}

/// What both path-following controllers need once the common checks pass.
pub(crate) struct Task<'a> {
    pub(crate) path: PathRef<'a>,
    pub(crate) projection: Projection,
    pub(crate) goal_distance_m: f64,
}

/// The checks shared by the path-following controllers: `Ok(None)` means "stand still" (the
/// planner says stop, or the goal is reached).
pub(crate) fn checked_task<'a>(
    controller: &'static str,
    input: &ControlInput<'a>,
    goal_tolerance_m: f64,
) -> Result<Option<Task<'a>>, ControllerError> {
    let intention = input.intention.ok_or(ControllerError::MissingInput {
        controller,
        input: "intention",
    })?;
    if !(input.dt_s.is_finite() && input.dt_s > 0.0) {
        return Err(ControllerError::BadInput {
            controller,
            input: "dt_s",
            reason: format!("{} is not a positive, finite cycle length", input.dt_s),
        });
    }
    let p = input.pose;
    let finite = [p.x_m, p.y_m, p.yaw_rad, input.v_mps, input.omega_radps]
        .iter()
        .all(|v| v.is_finite());
    if !finite {
        return Err(ControllerError::BadInput {
            controller,
            input: "pose or velocity",
            reason: format!(
                "not finite: pose ({}, {}, {}), v {} m/s, omega {} rad/s",
                p.x_m, p.y_m, p.yaw_rad, input.v_mps, input.omega_radps
            ),
        });
    }
    if intention.stops() {
        return Ok(None);
    }
    let path = PathRef::new(controller, &intention.path)?;
    let (gx, gy) = path.goal();
    let goal_distance_m = (gx - p.x_m).hypot(gy - p.y_m);
    if goal_distance_m <= goal_tolerance_m {
        return Ok(None);
    }
    Ok(Some(Task {
        path,
        projection: path.project(p.x_m, p.y_m),
        goal_distance_m,
    }))
}

#[cfg(test)]
mod tests {
    use super::*;
    use protocol::{Dlm, Intention};

    pub(crate) fn intention(path: Vec<Pose2D>, dlm: Dlm) -> Intention {
        test_support::fixtures::intention(path, dlm)
    }

    fn input<'a>(
        pose: Pose2D,
        v: f64,
        intention: Option<&'a Intention>,
        limits: &'a Limits,
    ) -> ControlInput<'a> {
        ControlInput {
            pose,
            v_mps: v,
            omega_radps: 0.0,
            scan: None,
            camera: None,
            intention,
            limits,
            dt_s: 0.1,
        }
    }

    /// A path that goes 1 m straight, then bends by `bend_rad` (positive = left).
    fn bending_path(bend_rad: f64) -> Vec<Pose2D> {
        let mut path: Vec<Pose2D> = (0..=10)
            .map(|i| Pose2D::new(0.1 * f64::from(i), 0.0, 0.0))
            .collect();
        for i in 1..=20 {
            let s = 0.1 * f64::from(i);
            path.push(Pose2D::new(
                1.0 + s * bend_rad.cos(),
                s * bend_rad.sin(),
                bend_rad,
            ));
        }
        path
    }

    #[test]
    fn curvature_sign_follows_the_bend() {
        let limits = Limits::default();
        let mut pt = PathTracker::new(PathTrackerConfig::default()).unwrap();
        for (bend, sign) in [(0.8, 1.0), (-0.8, -1.0)] {
            let it = intention(bending_path(bend), Dlm::GoForward);
            // Near the bend, moving: the look-ahead point lies past it.
            let pose = Pose2D::new(0.7, 0.0, 0.0);
            let c = pt.control(&input(pose, 0.4, Some(&it), &limits)).unwrap();
            assert!(c.omega_norm * sign > 0.05, "bend {bend}: {c:?}");
            assert!(c.v_norm > 0.0, "bend {bend}: {c:?}");
        }
        assert!(pursuit_curvature(1.0, 0.5) > 0.0 && pursuit_curvature(1.0, -0.5) < 0.0);
        assert_eq!(pursuit_curvature(2.0, 0.0), 0.0);
    }

    #[test]
    fn straight_path_drives_straight_and_accelerates_within_limits() {
        let limits = Limits::default();
        let mut pt = PathTracker::new(PathTrackerConfig::default()).unwrap();
        let it = intention(bending_path(0.0), Dlm::GoForward);
        let c = pt
            .control(&input(Pose2D::new(0.0, 0.0, 0.0), 0.0, Some(&it), &limits))
            .unwrap();
        let (v, w) = c.to_physical(&limits);
        assert!((v - limits.max_accel_mps2 * 0.1).abs() < 1e-9, "{v}");
        assert!(w.abs() < 1e-9, "{w}");
    }

    #[test]
    fn sharp_bend_ahead_slows_down() {
        let limits = Limits::default();
        let mut pt = PathTracker::new(PathTrackerConfig::default()).unwrap();
        let pose = Pose2D::new(0.2, 0.0, 0.0);
        let speed = |bend: f64, pt: &mut PathTracker| {
            let it = intention(bending_path(bend), Dlm::GoForward);
            pt.control(&input(pose, limits.max_speed_mps, Some(&it), &limits))
                .unwrap()
                .v_norm
        };
        let straight = speed(0.0, &mut pt);
        let sharp = speed(1.5, &mut pt);
        assert!((straight - 1.0).abs() < 1e-9, "{straight}");
        assert!(sharp < straight - 0.05, "sharp {sharp} straight {straight}");
    }

    #[test]
    fn stops_at_goal_on_stop_and_errors_without_intention() {
        let limits = Limits::default();
        let mut pt = PathTracker::new(PathTrackerConfig::default()).unwrap();
        let path = bending_path(0.0);
        let goal = *path.last().unwrap();
        let it = intention(path.clone(), Dlm::GoForward);
        let near = Pose2D::new(goal.x_m - 0.1, goal.y_m, 0.0);
        assert_eq!(
            pt.control(&input(near, 0.1, Some(&it), &limits)).unwrap(),
            Control::default()
        );
        let stop = intention(path, Dlm::Stop);
        assert_eq!(
            pt.control(&input(Pose2D::default(), 0.5, Some(&stop), &limits))
                .unwrap(),
            Control::default()
        );
        // An arriving `Stop` is driven on to the goal.
        let arriving = Intention {
            arriving: true,
            ..stop
        };
        let cmd = pt
            .control(&input(Pose2D::default(), 0.5, Some(&arriving), &limits))
            .unwrap();
        assert!(cmd.v_norm > 0.0, "{cmd:?}");
        let err = pt
            .control(&input(Pose2D::default(), 0.0, None, &limits))
            .unwrap_err();
        assert!(
            matches!(
                err,
                ControllerError::MissingInput {
                    input: "intention",
                    ..
                }
            ),
            "{err}"
        );
        let empty = intention(Vec::new(), Dlm::GoForward);
        let err = pt
            .control(&input(Pose2D::default(), 0.0, Some(&empty), &limits))
            .unwrap_err();
        assert!(err.to_string().contains("intention.path"), "{err}");
    }

    #[test]
    fn decelerates_towards_the_goal() {
        let limits = Limits::default();
        let mut pt = PathTracker::new(PathTrackerConfig::default()).unwrap();
        let it = intention(bending_path(0.0), Dlm::GoForward);
        // 0.25 m before a 3 m path's end at full speed: braking must be under way.
        let pose = Pose2D::new(2.75, 0.0, 0.0);
        let (v, _) = pt
            .control(&input(pose, limits.max_speed_mps, Some(&it), &limits))
            .unwrap()
            .to_physical(&limits);
        assert!(v < limits.max_speed_mps - 0.05, "{v}");
    }

    #[test]
    fn aims_at_the_goal_when_the_rest_of_the_path_loops_close_by() {
        let limits = Limits::default();
        let mut pt = PathTracker::new(PathTrackerConfig::default()).unwrap();
        // A loop out to the left and back to a goal 1 m straight ahead.
        let it = intention(test_support::fixtures::loop_path(1.0), Dlm::GoForward);
        let (_, w) = pt
            .control(&input(Pose2D::default(), 0.5, Some(&it), &limits))
            .unwrap()
            .to_physical(&limits);
        assert!(w.abs() < 1e-9, "{w}");
        // The same loop reaching 2 m out is a path to follow, not a loop to cut.
        let it = intention(test_support::fixtures::loop_path(2.0), Dlm::GoForward);
        let (_, w) = pt
            .control(&input(Pose2D::default(), 0.5, Some(&it), &limits))
            .unwrap()
            .to_physical(&limits);
        assert!(w > 0.1, "{w}");
    }

    #[test]
    fn turns_in_place_towards_a_path_behind() {
        let limits = Limits::default();
        let mut pt = PathTracker::new(PathTrackerConfig::default()).unwrap();
        let it = intention(bending_path(0.0), Dlm::GoForward);
        let pose = Pose2D::new(0.0, 0.0, std::f64::consts::PI - 0.3);
        let c = pt.control(&input(pose, 0.0, Some(&it), &limits)).unwrap();
        assert_eq!(c.v_norm, 0.0);
        // Path is at bearing +0.3 - pi (to the right when facing almost backwards).
        assert!(c.omega_norm < 0.0, "{c:?}");
    }

    #[test]
    fn projection_and_lookahead_walk_along_the_path() {
        let poses = bending_path(std::f64::consts::FRAC_PI_2);
        let path = PathRef::new("t", &poses).unwrap();
        let proj = path.project(0.5, 0.3);
        let (x, y) = path.point_ahead(&proj, 0.8);
        assert!(
            (x - 1.0).abs() < 1e-9 && (y - 0.3).abs() < 1e-9,
            "({x}, {y})"
        );
        assert_eq!(path.point_ahead(&proj, 100.0), path.goal());
    }

    #[test]
    fn config_rejects_bad_values_by_name() {
        let bad = PathTrackerConfig {
            lookahead_m: -1.0,
            ..PathTrackerConfig::default()
        };
        let err = bad.validate().unwrap_err().to_string();
        assert!(err.contains("path_tracker.lookahead_m = -1"), "{err}");
        let bad = PathTrackerConfig {
            max_lookahead_m: 0.1,
            ..PathTrackerConfig::default()
        };
        assert!(PathTracker::new(bad).is_err());
    }
}
