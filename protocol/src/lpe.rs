//! How an LPE (local path and environment) image is rendered: the contract between the planner
//! that draws it and the intention-net that was trained on it (DESIGN §4).
//!
//! The planner renders with these parameters and a model card records the ones its model was
//! trained on; the agent refuses a model whose card disagrees with its configuration, because
//! a network is only valid for the rendering it learnt from. One definition serves both sides.

use serde::{Deserialize, Serialize};

/// Rendering parameters of the LPE image (the planner's `[lpe]` table, a model card's
/// `lpe_rendering`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LpeParams {
    /// Width and height of the square image.
    pub size_px: u32,
    /// Map metres per image pixel (the window is `size_px * metres_per_px` wide).
    pub metres_per_px: f64,
    /// Robot pixel `[column, row]`, row 0 at the top.
    pub robot_px: [u32; 2],
    /// Line width of the travelled path.
    pub travelled_width_px: f64,
    /// Line width of the path ahead.
    pub ahead_width_px: f64,
    pub free_rgb: [u8; 3],
    pub occupied_rgb: [u8; 3],
    pub unknown_rgb: [u8; 3],
    pub travelled_rgb: [u8; 3],
    pub ahead_rgb: [u8; 3],
}

impl Default for LpeParams {
    fn default() -> Self {
        Self {
            size_px: 224,
            metres_per_px: 0.05,
            // Below the centre: the path ahead matters more than the path behind.
            robot_px: [112, 168],
            travelled_width_px: 3.0,
            ahead_width_px: 3.0,
            free_rgb: [255, 255, 255],
            occupied_rgb: [0, 0, 0],
            unknown_rgb: [128, 128, 128],
            travelled_rgb: [255, 0, 0],
            ahead_rgb: [0, 0, 255],
        }
    }
}

/// An LPE parameter out of range.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("invalid lpe.{field} = {value}: {reason}")]
pub struct LpeParamsError {
    pub field: &'static str,
    pub value: String,
    pub reason: &'static str,
}

impl LpeParams {
    /// Checks the fields, naming the first bad one.
    ///
    /// # Errors
    /// [`LpeParamsError`] naming the field and value.
    pub fn validate(&self) -> Result<(), LpeParamsError> {
        if !(8..=4096).contains(&self.size_px) {
            return Err(LpeParamsError {
                field: "size_px",
                value: self.size_px.to_string(),
                reason: "must be in 8..=4096",
            });
        }
        if !self.metres_per_px.is_finite() || self.metres_per_px <= 0.0 {
            return Err(LpeParamsError {
                field: "metres_per_px",
                value: self.metres_per_px.to_string(),
                reason: "must be positive and finite",
            });
        }
        if self.robot_px[0] >= self.size_px || self.robot_px[1] >= self.size_px {
            return Err(LpeParamsError {
                field: "robot_px",
                value: format!("{:?}", self.robot_px),
                reason: "must lie inside the image",
            });
        }
        for (field, w) in [
            ("travelled_width_px", self.travelled_width_px),
            ("ahead_width_px", self.ahead_width_px),
        ] {
            if !w.is_finite() || !(0.0..=64.0).contains(&w) {
                return Err(LpeParamsError {
                    field,
                    value: w.to_string(),
                    reason: "must be in 0..=64",
                });
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_valid_and_bad_values_are_named() {
        LpeParams::default().validate().unwrap();
        let bad = LpeParams {
            robot_px: [300, 10],
            ..LpeParams::default()
        };
        let err = bad.validate().unwrap_err();
        assert_eq!(err.field, "robot_px");
        assert!(
            err.to_string().contains("lpe.robot_px = [300, 10]"),
            "{err}"
        );
    }
}
