//! A picture of a map with a planned path, for people: `planner-service plan --picture`.
//!
//! One image pixel per map cell in the grid frame, north (grid +y) up. Large maps are cropped
//! to the path's bounding box plus a margin, so a 50 m path on a 100 m map stays legible.

use std::path::Path as FsPath;

use image::{ImageFormat, Rgb, RgbImage};
use map_core::{CellClass, OccupancyGrid};
use protocol::Pose2D;

/// Maps wider or taller than this many cells are cropped around the path.
pub const CROP_ABOVE_CELLS: u32 = 800;
/// Margin around the path's bounding box when cropping.
pub const CROP_MARGIN_M: f64 = 3.0;

const FREE: Rgb<u8> = Rgb([255, 255, 255]);
const OCCUPIED: Rgb<u8> = Rgb([0, 0, 0]);
const UNKNOWN: Rgb<u8> = Rgb([160, 160, 160]);
const PATH: Rgb<u8> = Rgb([0, 0, 255]);
const ROUTE: Rgb<u8> = Rgb([255, 140, 0]);
const START: Rgb<u8> = Rgb([0, 170, 0]);
const GOAL: Rgb<u8> = Rgb([220, 0, 0]);

/// A picture that could not be written.
#[derive(Debug, thiserror::Error)]
#[error("cannot write picture {path}: {reason}")]
pub struct PictureError {
    pub path: String,
    pub reason: String,
}

/// Renders `grid` with `path` (map frame) on it; start green, goal red, path blue.
#[must_use]
pub fn render_picture(grid: &OccupancyGrid, path: &[Pose2D]) -> RgbImage {
    render_picture_with_route(grid, path, &[])
}

/// [`render_picture`] with `route` (map frame, a polyline: the floor plan's route the `route`
/// DLM measures) drawn in orange under the path.
#[must_use]
pub fn render_picture_with_route(
    grid: &OccupancyGrid,
    path: &[Pose2D],
    route: &[Pose2D],
) -> RgbImage {
    let (w, h) = (
        i64::from(grid.width_cells()),
        i64::from(grid.height_cells()),
    );
    let cells: Vec<(i64, i64)> = path
        .iter()
        .map(|p| {
            let (gx, gy) = grid.world_to_grid(p.x_m, p.y_m);
            #[allow(clippy::cast_possible_truncation)]
            (gx.floor() as i64, gy.floor() as i64)
        })
        .collect();
    let (mut x0, mut y0, mut x1, mut y1) = (0, 0, w - 1, h - 1);
    if (w > i64::from(CROP_ABOVE_CELLS) || h > i64::from(CROP_ABOVE_CELLS)) && !cells.is_empty() {
        #[allow(clippy::cast_possible_truncation)]
        let margin = (CROP_MARGIN_M / grid.resolution_m()).ceil() as i64;
        x0 = (cells.iter().map(|c| c.0).min().unwrap_or(0) - margin).clamp(0, w - 1);
        x1 = (cells.iter().map(|c| c.0).max().unwrap_or(w - 1) + margin).clamp(0, w - 1);
        y0 = (cells.iter().map(|c| c.1).min().unwrap_or(0) - margin).clamp(0, h - 1);
        y1 = (cells.iter().map(|c| c.1).max().unwrap_or(h - 1) + margin).clamp(0, h - 1);
    }
    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
    let (iw, ih) = ((x1 - x0 + 1) as u32, (y1 - y0 + 1) as u32);
    let mut img = RgbImage::new(iw, ih);
    // Grid row y is image row (y1 - y): north up.
    let to_px = |cx: i64, cy: i64| -> Option<(u32, u32)> {
        if cx < x0 || cx > x1 || cy < y0 || cy > y1 {
            return None;
        }
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        Some(((cx - x0) as u32, (y1 - cy) as u32))
    };
    for cy in y0..=y1 {
        for cx in x0..=x1 {
            let colour = match grid.class_at(cx, cy) {
                CellClass::Free => FREE,
                CellClass::Occupied => OCCUPIED,
                CellClass::Unknown => UNKNOWN,
            };
            if let Some((u, v)) = to_px(cx, cy) {
                img.put_pixel(u, v, colour);
            }
        }
    }
    let step_m = 0.5 * grid.resolution_m();
    for w in route.windows(2) {
        let length_m = w[0].distance_m(&w[1]);
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let n = (length_m / step_m).ceil().max(1.0) as u32;
        for k in 0..=n {
            let t = f64::from(k) / f64::from(n);
            let (gx, gy) = grid.world_to_grid(
                w[0].x_m + t * (w[1].x_m - w[0].x_m),
                w[0].y_m + t * (w[1].y_m - w[0].y_m),
            );
            #[allow(clippy::cast_possible_truncation)]
            let (cx, cy) = (gx.floor() as i64, gy.floor() as i64);
            for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                if let Some((u, v)) = to_px(cx + dx, cy + dy) {
                    img.put_pixel(u, v, ROUTE);
                }
            }
        }
    }
    for &(cx, cy) in &cells {
        if let Some((u, v)) = to_px(cx, cy) {
            img.put_pixel(u, v, PATH);
        }
    }
    for (cell, colour) in [(cells.first(), START), (cells.last(), GOAL)] {
        let Some(&(cx, cy)) = cell else { continue };
        for dy in -3..=3_i64 {
            for dx in -3..=3_i64 {
                if dx * dx + dy * dy <= 9 {
                    if let Some((u, v)) = to_px(cx + dx, cy + dy) {
                        img.put_pixel(u, v, colour);
                    }
                }
            }
        }
    }
    img
}

/// Writes a picture as PNG.
///
/// # Errors
/// [`PictureError`] naming the path.
pub fn save_picture(img: &RgbImage, path: &FsPath) -> Result<(), PictureError> {
    img.save_with_format(path, ImageFormat::Png)
        .map_err(|e| PictureError {
            path: path.display().to_string(),
            reason: e.to_string(),
        })
}

#[cfg(test)]
mod tests {
    use super::*;
    use map_core::{FREE as FREE_CELL, OCCUPIED as OCC_CELL};

    #[test]
    fn north_up_with_start_and_goal_marked() {
        let mut g =
            OccupancyGrid::filled(40, 30, 0.1, Pose2D::new(0.0, 0.0, 0.0), FREE_CELL).unwrap();
        g.set(0, 29, OCC_CELL); // top-left in the picture
        let path = vec![Pose2D::new(0.55, 0.55, 0.0), Pose2D::new(3.05, 2.05, 0.0)];
        let img = render_picture(&g, &path);
        assert_eq!(img.dimensions(), (40, 30));
        assert_eq!(*img.get_pixel(0, 0), OCCUPIED);
        assert_eq!(*img.get_pixel(5, 29 - 5), START);
        assert_eq!(*img.get_pixel(30, 29 - 20), GOAL);
    }

    #[test]
    fn the_route_is_drawn_under_the_path() {
        let g = OccupancyGrid::filled(40, 30, 0.1, Pose2D::new(0.0, 0.0, 0.0), FREE_CELL).unwrap();
        let path = vec![Pose2D::new(0.55, 0.55, 0.0), Pose2D::new(3.05, 0.55, 0.0)];
        // Up from the start, then east: an L apart from the path but at the start.
        let route = vec![
            Pose2D::new(0.55, 0.55, 0.0),
            Pose2D::new(0.55, 2.05, 0.0),
            Pose2D::new(3.05, 2.05, 0.0),
        ];
        let img = render_picture_with_route(&g, &path, &route);
        assert_eq!(*img.get_pixel(5, 29 - 15), ROUTE);
        assert_eq!(*img.get_pixel(20, 29 - 20), ROUTE);
        assert_eq!(*img.get_pixel(20, 29 - 10), FREE);
        assert_eq!(
            render_picture(&g, &path),
            render_picture_with_route(&g, &path, &[])
        );
    }

    #[test]
    fn large_maps_are_cropped_to_the_path() {
        let g =
            OccupancyGrid::filled(1000, 1000, 0.05, Pose2D::new(0.0, 0.0, 0.0), FREE_CELL).unwrap();
        let path = vec![Pose2D::new(10.0, 10.0, 0.0), Pose2D::new(12.0, 11.0, 0.0)];
        let img = render_picture(&g, &path);
        // 2 m x 1 m of path plus 3 m margins at 0.05 m per pixel.
        assert_eq!(img.dimensions(), (161, 141));
    }
}
