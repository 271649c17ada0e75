//! LPE (local path and environment): the 224 x 224 RGB intention image of paper §3.1.
//!
//! A heading-up window of the floor plan around the robot (DESIGN.md §4): the robot sits at a
//! fixed pixel facing the top of the image, so image up is robot forward and image left is
//! robot left. Each pixel shows the map class at its centre (free, occupied, unknown; off the
//! map is unknown), then the path already travelled is drawn in red and the path ahead in
//! blue. Every rendering choice is in [`LpeParams`], which model cards record: a model is only
//! valid for the rendering it was trained on.

use std::io::Cursor;
use std::path::Path as FsPath;

use image::{ImageFormat, RgbImage};
use map_core::{CellClass, OccupancyGrid};
use protocol::Pose2D;

pub use protocol::LpeParams;

/// A bad LPE parameter or an image that could not be written.
#[derive(Debug, thiserror::Error)]
pub enum LpeError {
    #[error(transparent)]
    Invalid(#[from] protocol::LpeParamsError),
    #[error("cannot encode or write LPE image {path}: {reason}")]
    Write { path: String, reason: String },
}

/// A rendered LPE image (RGB, row-major from the top-left).
#[derive(Debug, Clone, PartialEq)]
pub struct LpeImage {
    pub image: RgbImage,
}

impl LpeImage {
    /// PNG bytes of the image.
    ///
    /// # Errors
    /// [`LpeError::Write`] if encoding fails.
    pub fn to_png(&self) -> Result<Vec<u8>, LpeError> {
        let mut out = Cursor::new(Vec::new());
        self.image
            .write_to(&mut out, ImageFormat::Png)
            .map_err(|e| LpeError::Write {
                path: "<memory>".into(),
                reason: e.to_string(),
            })?;
        Ok(out.into_inner())
    }

    /// Writes the image as PNG.
    ///
    /// # Errors
    /// [`LpeError::Write`] naming the path.
    pub fn save_png(&self, path: &FsPath) -> Result<(), LpeError> {
        self.image
            .save_with_format(path, ImageFormat::Png)
            .map_err(|e| LpeError::Write {
                path: path.display().to_string(),
                reason: e.to_string(),
            })
    }
}

/// Maps between the map frame and image pixels for one robot pose.
struct View {
    robot: Pose2D,
    sin: f64,
    cos: f64,
    mpp: f64,
    ru: f64,
    rv: f64,
}

impl View {
    fn new(robot: Pose2D, p: &LpeParams) -> Self {
        let (sin, cos) = robot.yaw_rad.sin_cos();
        Self {
            robot,
            sin,
            cos,
            mpp: p.metres_per_px,
            ru: f64::from(p.robot_px[0]),
            rv: f64::from(p.robot_px[1]),
        }
    }

    /// Map-frame point at the centre of pixel (u, v).
    fn pixel_to_world(&self, u: f64, v: f64) -> (f64, f64) {
        let fwd = (self.rv - v) * self.mpp;
        let left = (self.ru - u) * self.mpp;
        (
            self.robot.x_m + self.cos * fwd - self.sin * left,
            self.robot.y_m + self.sin * fwd + self.cos * left,
        )
    }

    /// Continuous pixel coordinates (u, v) of a map-frame point.
    fn world_to_pixel(&self, x: f64, y: f64) -> (f64, f64) {
        let dx = x - self.robot.x_m;
        let dy = y - self.robot.y_m;
        let fwd = self.cos * dx + self.sin * dy;
        let left = -self.sin * dx + self.cos * dy;
        (self.ru - left / self.mpp, self.rv - fwd / self.mpp)
    }
}

/// Renders the LPE image for a robot at `robot` that has driven `travelled` and will follow
/// `ahead` (both map-frame pose sequences; either may be empty).
///
/// # Errors
/// [`LpeError::Invalid`] for bad parameters.
pub fn render_lpe(
    grid: &OccupancyGrid,
    robot: Pose2D,
    travelled: &[Pose2D],
    ahead: &[Pose2D],
    params: &LpeParams,
) -> Result<LpeImage, LpeError> {
    params.validate()?;
    let n = params.size_px;
    let view = View::new(robot, params);
    let mut image = RgbImage::new(n, n);
    for v in 0..n {
        for u in 0..n {
            let (x, y) = view.pixel_to_world(f64::from(u), f64::from(v));
            let (cx, cy) = grid.world_to_cell(x, y);
            let rgb = match grid.class_at(cx, cy) {
                CellClass::Free => params.free_rgb,
                CellClass::Occupied => params.occupied_rgb,
                CellClass::Unknown => params.unknown_rgb,
            };
            image.put_pixel(u, v, image::Rgb(rgb));
        }
    }
    draw_polyline(
        &mut image,
        &view,
        travelled,
        params.travelled_width_px,
        params.travelled_rgb,
    );
    draw_polyline(
        &mut image,
        &view,
        ahead,
        params.ahead_width_px,
        params.ahead_rgb,
    );
    Ok(LpeImage { image })
}

/// Draws a thick polyline: discs of diameter `width_px` stamped every quarter pixel.
fn draw_polyline(image: &mut RgbImage, view: &View, poses: &[Pose2D], width_px: f64, rgb: [u8; 3]) {
    if poses.is_empty() || width_px <= 0.0 {
        return;
    }
    let r = width_px / 2.0;
    let size = f64::from(image.width());
    let mut stamp = |u: f64, v: f64| {
        if u < -r || v < -r || u > size + r || v > size + r {
            return;
        }
        let (u0, u1) = ((u - r).floor(), (u + r).ceil());
        let (v0, v1) = ((v - r).floor(), (v + r).ceil());
        let mut pv = v0;
        while pv <= v1 {
            let mut pu = u0;
            while pu <= u1 {
                let inside = (pu - u).powi(2) + (pv - v).powi(2) <= r * r;
                if inside && pu >= 0.0 && pv >= 0.0 && pu < size && pv < size {
                    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
                    image.put_pixel(pu as u32, pv as u32, image::Rgb(rgb));
                }
                pu += 1.0;
            }
            pv += 1.0;
        }
    };
    let pts: Vec<(f64, f64)> = poses
        .iter()
        .map(|p| view.world_to_pixel(p.x_m, p.y_m))
        .collect();
    stamp(pts[0].0, pts[0].1);
    for w in pts.windows(2) {
        let (a, b) = (w[0], w[1]);
        let len = (b.0 - a.0).hypot(b.1 - a.1);
        // Segments far outside the image cost nothing but their bounds test.
        if len > 4.0 * size {
            continue;
        }
        let steps = (len * 4.0).ceil().max(1.0);
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        for k in 1..=(steps as u32) {
            let t = f64::from(k) / steps;
            stamp(a.0 + (b.0 - a.0) * t, a.1 + (b.1 - a.1) * t);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn params_validate_and_reject_unknown_fields() {
        LpeParams::default().validate().unwrap();
        let bad = LpeParams {
            robot_px: [300, 10],
            ..LpeParams::default()
        };
        assert!(bad.validate().unwrap_err().to_string().contains("robot_px"));
        assert!(toml::from_str::<LpeParams>("size = 3").is_err());
        let p: LpeParams = toml::from_str("metres_per_px = 0.1").unwrap();
        assert_eq!(p.size_px, 224);
    }

    #[test]
    fn pixel_and_world_round_trip() {
        let v = View::new(Pose2D::new(3.0, -2.0, 0.8), &LpeParams::default());
        let (x, y) = v.pixel_to_world(40.0, 200.0);
        let (u, w) = v.world_to_pixel(x, y);
        assert!((u - 40.0).abs() < 1e-9 && (w - 200.0).abs() < 1e-9);
        // One metre ahead of the robot is 20 pixels up.
        let (u, w) = v.world_to_pixel(3.0 + 0.8f64.cos(), -2.0 + 0.8f64.sin());
        assert!((u - 112.0).abs() < 1e-9 && (w - 148.0).abs() < 1e-9);
    }
}
