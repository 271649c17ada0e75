//! DLM (discretized local move): `TurnLeft | TurnRight | GoForward | Stop` from a path.
//!
//! Paper §3.1: the sign and size of the path's local signed curvature at the robot. The
//! curvature is measured in the robot's frame, as pure pursuit does: the circle through the
//! robot, tangent to its heading, through the path point `window_m` of arc length ahead of the
//! path point closest to the robot, has curvature `2 y / (x^2 + y^2)` (x forward, y left).
//! So "left" means left of where the robot faces, even when the path starts with a turn in
//! place; a path point behind the robot is always a turn towards its side. `Stop` when the
//! remaining path is shorter than `stop_distance_m`.

use protocol::{Dlm, Pose2D};
use serde::{Deserialize, Serialize};

/// DLM parameters (the `[dlm]` table of the config file; recorded in DLM-Net model cards).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DlmParams {
    /// Arc length ahead of the robot at which the path point is taken.
    pub window_m: f64,
    /// |curvature| at or above which the move is a turn (1/m; 0.3 = a 3.3 m radius).
    pub curvature_threshold_per_m: f64,
    /// `Stop` when the path left to drive is at most this long.
    pub stop_distance_m: f64,
}

impl Default for DlmParams {
    fn default() -> Self {
        Self {
            window_m: 1.5,
            curvature_threshold_per_m: 0.3,
            stop_distance_m: 0.3,
        }
    }
}

/// A DLM parameter out of range (the `[dlm]` table).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("invalid dlm.{field} = {value}: {reason}")]
pub struct DlmParamsError {
    /// The field inside `[dlm]`, e.g. `window_m`.
    pub field: &'static str,
    pub value: f64,
    pub reason: &'static str,
}

impl DlmParams {
    /// Checks the fields, naming the first bad one.
    ///
    /// # Errors
    /// [`DlmParamsError`] naming the field and value.
    pub fn validate(&self) -> Result<(), DlmParamsError> {
        for (field, value) in [
            ("window_m", self.window_m),
            ("curvature_threshold_per_m", self.curvature_threshold_per_m),
            ("stop_distance_m", self.stop_distance_m),
        ] {
            if !value.is_finite() || value < 0.0 {
                return Err(DlmParamsError {
                    field,
                    value,
                    reason: "must be >= 0 and finite",
                });
            }
        }
        if self.window_m <= 0.0 {
            return Err(DlmParamsError {
                field: "window_m",
                value: self.window_m,
                reason: "must be positive",
            });
        }
        Ok(())
    }
}

/// Signed curvature (1/m, positive to the left) of the path ahead of `robot`, in the robot's
/// frame (infinite, with the side's sign, when the path point lies behind the robot), and the
/// remaining path length from the closest path point. `None` for an empty path.
#[must_use]
pub fn curvature_ahead(path: &[Pose2D], robot: Pose2D, window_m: f64) -> Option<(f64, f64)> {
    let closest = crate::path::nearest_index(path, robot)?;
    let rest = &path[closest..];
    let remaining_m: f64 = rest.windows(2).map(|w| w[0].distance_m(&w[1])).sum();
    let mut acc = 0.0;
    let mut target = rest[rest.len() - 1];
    for w in rest.windows(2) {
        acc += w[0].distance_m(&w[1]);
        if acc >= window_m {
            target = w[1];
            break;
        }
    }
    let (s, c) = robot.yaw_rad.sin_cos();
    let dx = target.x_m - robot.x_m;
    let dy = target.y_m - robot.y_m;
    let fwd = c * dx + s * dy;
    let left = -s * dx + c * dy;
    let d_sq = fwd * fwd + left * left;
    if d_sq < 1e-12 {
        return Some((0.0, remaining_m));
    }
    if fwd < 0.0 {
        // Behind the robot: a turn whatever the threshold, towards the point's side (left,
        // counter-clockwise, when straight behind).
        return Some((
            if left >= -1e-9 {
                f64::INFINITY
            } else {
                f64::NEG_INFINITY
            },
            remaining_m,
        ));
    }
    Some((2.0 * left / d_sq, remaining_m))
}

/// The DLM for a robot at `robot` following `path` (see the module docs). An empty path means
/// there is nothing left to do: `Stop`.
#[must_use]
pub fn dlm_from_path(path: &[Pose2D], robot: Pose2D, params: &DlmParams) -> Dlm {
    let Some((kappa, remaining_m)) = curvature_ahead(path, robot, params.window_m) else {
        return Dlm::Stop;
    };
    let to_end = path.last().map_or(0.0, |g| g.distance_m(&robot));
    if remaining_m.max(to_end) <= params.stop_distance_m {
        return Dlm::Stop;
    }
    if kappa.abs() < params.curvature_threshold_per_m {
        Dlm::GoForward
    } else if kappa > 0.0 {
        Dlm::TurnLeft
    } else {
        Dlm::TurnRight
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::{FRAC_PI_2, PI};

    #[test]
    fn bad_params_name_the_field_and_value() {
        DlmParams::default().validate().unwrap();
        let bad = DlmParams {
            window_m: 0.0,
            ..DlmParams::default()
        };
        let e = bad.validate().unwrap_err();
        assert_eq!(e.field, "window_m");
        assert_eq!(e.to_string(), "invalid dlm.window_m = 0: must be positive");
        let bad = DlmParams {
            stop_distance_m: f64::NAN,
            ..DlmParams::default()
        };
        let e = bad.validate().unwrap_err();
        assert_eq!(e.field, "stop_distance_m");
        assert!(e.to_string().contains("dlm.stop_distance_m = NaN"), "{e}");
    }

    /// Poses along an arc (positive curvature = left) from `start`, `step` metres apart.
    fn arc(start: Pose2D, curvature: f64, length_m: f64, step: f64) -> Vec<Pose2D> {
        let n = (length_m / step).round() as usize;
        let mut out = vec![start];
        let mut p = start;
        for _ in 0..n {
            let yaw2 = p.yaw_rad + curvature * step;
            p = if curvature.abs() < 1e-12 {
                Pose2D::new(
                    p.x_m + step * p.yaw_rad.cos(),
                    p.y_m + step * p.yaw_rad.sin(),
                    p.yaw_rad,
                )
            } else {
                Pose2D::new(
                    p.x_m + (yaw2.sin() - p.yaw_rad.sin()) / curvature,
                    p.y_m - (yaw2.cos() - p.yaw_rad.cos()) / curvature,
                    yaw2,
                )
            };
            out.push(p);
        }
        out
    }

    fn params() -> DlmParams {
        DlmParams::default()
    }

    #[test]
    fn straight_is_go_forward() {
        let path = arc(Pose2D::new(1.0, 2.0, 0.7), 0.0, 10.0, 0.05);
        assert_eq!(dlm_from_path(&path, path[0], &params()), Dlm::GoForward);
        // A small lateral offset from the path does not make it a turn.
        let off = Pose2D::new(
            path[0].x_m + 0.05 * (0.7f64 + FRAC_PI_2).cos(),
            path[0].y_m + 0.05 * (0.7f64 + FRAC_PI_2).sin(),
            0.7,
        );
        assert_eq!(dlm_from_path(&path, off, &params()), Dlm::GoForward);
    }

    #[test]
    fn left_and_right_bends() {
        let left = arc(Pose2D::new(0.0, 0.0, -2.0), 1.0, 5.0, 0.05);
        assert_eq!(dlm_from_path(&left, left[0], &params()), Dlm::TurnLeft);
        let right = arc(Pose2D::new(0.0, 0.0, 2.0), -1.0, 5.0, 0.05);
        assert_eq!(dlm_from_path(&right, right[0], &params()), Dlm::TurnRight);
        // Gentle curves below the threshold are still forward.
        let gentle = arc(Pose2D::new(0.0, 0.0, 0.0), 0.1, 5.0, 0.05);
        assert_eq!(dlm_from_path(&gentle, gentle[0], &params()), Dlm::GoForward);
    }

    #[test]
    fn s_bend_turns_left_then_right() {
        let mut path = arc(Pose2D::new(0.0, 0.0, 0.0), 1.0, 2.0, 0.05);
        let mid = path[path.len() - 1];
        let second = arc(mid, -1.0, 2.0, 0.05);
        path.extend_from_slice(&second[1..]);
        path.extend_from_slice(&arc(path[path.len() - 1], 0.0, 3.0, 0.05)[1..]);
        assert_eq!(dlm_from_path(&path, path[0], &params()), Dlm::TurnLeft);
        assert_eq!(dlm_from_path(&path, mid, &params()), Dlm::TurnRight);
        let last = second[second.len() - 1];
        assert_eq!(dlm_from_path(&path, last, &params()), Dlm::GoForward);
    }

    #[test]
    fn measured_in_the_robot_frame() {
        // The path runs north; a robot facing east must turn left onto it, one facing west right.
        let path = arc(Pose2D::new(0.0, 0.0, FRAC_PI_2), 0.0, 5.0, 0.05);
        assert_eq!(
            dlm_from_path(&path, Pose2D::new(0.0, 0.0, 0.0), &params()),
            Dlm::TurnLeft
        );
        assert_eq!(
            dlm_from_path(&path, Pose2D::new(0.0, 0.0, PI), &params()),
            Dlm::TurnRight
        );
        // Straight behind: a turn, not forward.
        let behind = dlm_from_path(&path, Pose2D::new(0.0, 0.0, -FRAC_PI_2), &params());
        assert_eq!(behind, Dlm::TurnLeft);
    }

    #[test]
    fn stop_near_the_goal() {
        let path = arc(Pose2D::new(0.0, 0.0, 0.0), 0.0, 3.0, 0.05);
        let near = path[path.len() - 4]; // 0.15 m before the end
        assert_eq!(dlm_from_path(&path, near, &params()), Dlm::Stop);
        let far = path[path.len() - 20]; // 0.95 m before the end
        assert_eq!(dlm_from_path(&path, far, &params()), Dlm::GoForward);
        assert_eq!(
            dlm_from_path(&[], Pose2D::new(0.0, 0.0, 0.0), &params()),
            Dlm::Stop
        );
        let tight = DlmParams {
            stop_distance_m: 1.0,
            ..params()
        };
        assert_eq!(dlm_from_path(&path, far, &tight), Dlm::Stop);
    }
}
