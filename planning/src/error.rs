//! Why a plan failed: every error carries the numbers a caller needs to act on it.

use std::fmt;

use protocol::LpeParamsError;

use crate::intention::dlm::DlmParamsError;

/// Which end of a planning query an error is about.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Endpoint {
    Start,
    Goal,
}

impl fmt::Display for Endpoint {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Endpoint::Start => "start",
            Endpoint::Goal => "goal",
        })
    }
}

/// DLM or LPE parameters out of range: which table, field and value.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum IntentionParamsError {
    #[error(transparent)]
    Dlm(#[from] DlmParamsError),
    #[error(transparent)]
    Lpe(#[from] LpeParamsError),
}

impl From<DlmParamsError> for PlanError {
    fn from(e: DlmParamsError) -> Self {
        Self::InvalidParams(e.into())
    }
}

impl From<LpeParamsError> for PlanError {
    fn from(e: LpeParamsError) -> Self {
        Self::InvalidParams(e.into())
    }
}

/// A planning failure with its reason.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PlanError {
    /// A pose has a NaN or infinite coordinate.
    #[error("{which} pose ({x_m}, {y_m}, {yaw_rad}) is not finite")]
    NotFinite {
        which: Endpoint,
        x_m: f64,
        y_m: f64,
        yaw_rad: f64,
    },

    /// A pose lies outside the map.
    #[error("{which} pose ({x_m:.3}, {y_m:.3}) is off the map (cell {cell_x}, {cell_y} of {width_cells}x{height_cells})")]
    OffMap {
        which: Endpoint,
        x_m: f64,
        y_m: f64,
        cell_x: i64,
        cell_y: i64,
        width_cells: u32,
        height_cells: u32,
    },

    /// A pose is inside an obstacle inflated by the robot radius.
    #[error("{which} pose ({x_m:.3}, {y_m:.3}) is in an obstacle: clearance {clearance_m:.3} m < robot radius {robot_radius_m:.3} m")]
    InCollision {
        which: Endpoint,
        x_m: f64,
        y_m: f64,
        clearance_m: f64,
        robot_radius_m: f64,
    },

    /// The search ran out of states without reaching the goal.
    #[error("goal unreachable from start: {states_expanded} states explored ({reason})")]
    Unreachable {
        states_expanded: u64,
        reason: &'static str,
    },

    /// The time or expansion budget ran out first.
    #[error(
        "planning budget exceeded ({limit}) after {elapsed_ms} ms and {states_expanded} states"
    )]
    BudgetExceeded {
        limit: String,
        elapsed_ms: u64,
        states_expanded: u64,
    },

    /// A configuration value is out of range.
    #[error("invalid planner config {field} = {value}: {reason}")]
    InvalidConfig {
        field: &'static str,
        value: String,
        reason: &'static str,
    },

    /// DLM or LPE parameters out of range (the message names the field and value).
    #[error(transparent)]
    InvalidParams(#[from] IntentionParamsError),

    /// The planning map was built for a different robot radius than the planner's.
    #[error("planning map is inflated for robot radius {map_m} m but the planner is configured for {config_m} m")]
    RadiusMismatch { map_m: f64, config_m: f64 },
}

impl PlanError {
    pub fn invalid_config(
        field: &'static str,
        value: impl fmt::Display,
        reason: &'static str,
    ) -> Self {
        Self::InvalidConfig {
            field,
            value: value.to_string(),
            reason,
        }
    }

    /// Number of search states explored before failing, where the search ran at all.
    #[must_use]
    pub fn states_expanded(&self) -> Option<u64> {
        match self {
            Self::Unreachable {
                states_expanded, ..
            }
            | Self::BudgetExceeded {
                states_expanded, ..
            } => Some(*states_expanded),
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn intention_params_errors_stay_typed_and_name_the_field() {
        let e: PlanError = DlmParamsError {
            field: "window_m",
            value: 0.0,
            reason: "must be positive",
        }
        .into();
        assert!(
            matches!(&e, PlanError::InvalidParams(IntentionParamsError::Dlm(d)) if d.field == "window_m"),
            "{e:?}"
        );
        assert_eq!(e.to_string(), "invalid dlm.window_m = 0: must be positive");
        let e: PlanError = LpeParamsError {
            field: "size_px",
            value: "3".into(),
            reason: "must be in 8..=4096",
        }
        .into();
        assert!(e.to_string().contains("lpe.size_px = 3"), "{e}");
    }
}
