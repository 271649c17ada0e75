//! The controllers that turn what the robot knows into a velocity command.
//!
//! Every controller answers one question per control cycle: given the pose estimate, the
//! current velocity, the newest laser scan, camera frame and intention, what normalized
//! command μ = (v, ω) ∈ [-1, 1]² should the base get? The agent scales μ by the robot's
//! [`Limits`] (the networks are trained on normalized outputs, DESIGN §5) and applies the
//! safety rules on top; controllers never see stale-intention or localization logic.

pub mod dynamic_window;
pub mod intention_net;
pub mod path_tracker;

pub use dynamic_window::{Choice, DynamicWindow, DynamicWindowConfig};
pub use intention_net::{
    IntentionNet, IntentionNetError, IntentionNetOptions, ModelCard, ModelExpectation, ModelKind,
};
pub use path_tracker::{PathTracker, PathTrackerConfig};

use protocol::{CameraFrame, Intention, LaserScan, Pose2D};

use crate::config::{ControllerKind, Limits};

/// The scan's returns within `reach_m` of the laser as robot-frame points (x forward, y left):
/// what the dynamic window and the collision monitor check arcs against.
pub fn scan_points(scan: &LaserScan, reach_m: f64) -> impl Iterator<Item = (f64, f64)> + '_ {
    (0..scan.ranges_m.len())
        .filter(|&i| scan.is_return(i))
        .filter_map(move |i| {
            let r = f64::from(scan.ranges_m[i]);
            let a = f64::from(scan.beam_angle_rad(i));
            (r <= reach_m).then(|| (r * a.cos(), r * a.sin()))
        })
}

/// What a controller may look at in one cycle. All poses are in the map frame.
#[derive(Debug, Clone, Copy)]
pub struct ControlInput<'a> {
    /// The localization estimate of the robot.
    pub pose: Pose2D,
    /// Current forward speed from odometry.
    pub v_mps: f64,
    /// Current turn rate from odometry.
    pub omega_radps: f64,
    /// Newest laser scan (robot frame).
    pub scan: Option<&'a LaserScan>,
    /// Newest camera frame.
    pub camera: Option<&'a CameraFrame>,
    /// Newest fresh intention (the agent filters stale ones out before calling).
    pub intention: Option<&'a Intention>,
    /// Robot limits, for controllers that plan in physical units (DWA, pure pursuit).
    pub limits: &'a Limits,
    /// Length of one control cycle.
    pub dt_s: f64,
}

/// A normalized command: both components in [-1, 1], scaled by [`Limits`] at the base.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Control {
    pub v_norm: f64,
    pub omega_norm: f64,
}

impl Control {
    /// Clamps both components into [-1, 1]; NaN becomes 0 so a broken output stops the robot.
    #[must_use]
    pub fn clamped(self) -> Self {
        let c = |x: f64| if x.is_nan() { 0.0 } else { x.clamp(-1.0, 1.0) };
        Self {
            v_norm: c(self.v_norm),
            omega_norm: c(self.omega_norm),
        }
    }

    /// A physical command from normalized μ.
    #[must_use]
    pub fn from_physical(v_mps: f64, omega_radps: f64, limits: &Limits) -> Self {
        Self {
            v_norm: v_mps / limits.max_speed_mps,
            omega_norm: omega_radps / limits.max_turn_radps,
        }
        .clamped()
    }

    /// (v in m/s, ω in rad/s) within the limits.
    #[must_use]
    pub fn to_physical(self, limits: &Limits) -> (f64, f64) {
        let c = self.clamped();
        (
            c.v_norm * limits.max_speed_mps,
            c.omega_norm * limits.max_turn_radps,
        )
    }
}

/// Why a controller could not produce a command; the agent stops and reports it.
#[derive(Debug, thiserror::Error)]
pub enum ControllerError {
    /// An input the controller needs is absent (e.g. no camera frame yet for a network).
    #[error("controller {controller} needs {input}, which has not arrived")]
    MissingInput {
        controller: &'static str,
        input: &'static str,
    },
    /// An input is present but unusable (wrong image size, empty path, …).
    #[error("controller {controller}: bad {input}: {reason}")]
    BadInput {
        controller: &'static str,
        input: &'static str,
        reason: String,
    },
    /// The model could not be loaded or does not match the configuration.
    #[error("model {path}: {reason}")]
    Model { path: String, reason: String },
    /// Inference failed at run time.
    #[error("inference failed: {0}")]
    Inference(String),
}

/// One controller of the agent (DESIGN §5, the paper's four methods plus the DWA expert).
pub trait Controller: Send {
    /// Which kind this is, as configured.
    fn kind(&self) -> ControllerKind;

    /// The command for this cycle.
    ///
    /// # Errors
    /// [`ControllerError`] when an input is missing or unusable; the agent then stops.
    fn control(&mut self, input: &ControlInput<'_>) -> Result<Control, ControllerError>;

    /// What the last [`Controller::control`] steered towards before the controller's own
    /// smoothing, (speed m/s, turn rate rad/s) (a privileged expert's chosen target), `None`
    /// for a controller without one. A recording labels speed with it: the smoothed command is
    /// the current motion plus a bounded step, which a network that does not see the current
    /// speed cannot learn to set off from.
    fn target(&self) -> Option<(f64, f64)> {
        None
    }

    /// Forgets per-run state (e.g. after a new task or a safety stop).
    fn reset(&mut self) {}
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normalization_round_trips_and_clamps() {
        let limits = Limits::default();
        let c = Control::from_physical(0.35, -0.6, &limits);
        let (v, w) = c.to_physical(&limits);
        assert!((v - 0.35).abs() < 1e-12 && (w + 0.6).abs() < 1e-12);
        let big = Control::from_physical(10.0, -10.0, &limits);
        assert_eq!(
            big,
            Control {
                v_norm: 1.0,
                omega_norm: -1.0
            }
        );
        let nan = Control {
            v_norm: f64::NAN,
            omega_norm: 0.5,
        }
        .clamped();
        assert_eq!(
            nan,
            Control {
                v_norm: 0.0,
                omega_norm: 0.5
            }
        );
    }
}
