//! Walls of the ground truth as a grid, with exact DDA ray traversal and disc-overlap tests.
//!
//! The walls are the occupied and unknown cells of the floor plan (off the grid counts as wall,
//! so nothing ever leaves the building). Rays walk the grid cell by cell (Amanatides & Woo), which
//! costs one step per crossed cell and never misses a thin wall.

use map_core::{CellClass, GridGeometry, OccupancyGrid};

/// What a ray hit on the wall grid.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WallHit {
    /// Distance along the ray from its origin.
    pub dist_m: f64,
    /// 0 when the ray crossed a cell boundary of constant grid x, 1 for constant grid y.
    pub side: u8,
    /// Position along the wall face in metres (for textures).
    pub along_m: f64,
    /// Hit point in the map frame.
    pub x_m: f64,
    pub y_m: f64,
}

/// The wall cells of a floor plan and the grid placement.
#[derive(Debug, Clone)]
pub struct WallGrid {
    geometry: GridGeometry,
    wall: Vec<bool>,
    /// Distance from each cell centre to the nearest wall-cell centre (collision early-out).
    clearance_m: Vec<f32>,
}

impl WallGrid {
    pub fn from_grid(grid: &OccupancyGrid) -> Self {
        let wall: Vec<bool> = grid
            .cells()
            .iter()
            .map(|&v| map_core::classify(v) != CellClass::Free)
            .collect();
        let df = map_core::DistanceField::compute(grid, map_core::Sources::OccupiedOrUnknown);
        Self {
            geometry: *grid.geometry(),
            wall,
            clearance_m: df.as_slice().to_vec(),
        }
    }

    pub fn resolution_m(&self) -> f64 {
        self.geometry.resolution_m()
    }

    /// Grid width and height in cells.
    pub fn size_cells(&self) -> (i64, i64) {
        (
            i64::from(self.geometry.width_cells()),
            i64::from(self.geometry.height_cells()),
        )
    }

    /// Map-frame centre of cell (cx, cy).
    pub fn cell_centre(&self, cx: i64, cy: i64) -> (f64, f64) {
        self.geometry.cell_to_world(cx, cy)
    }

    #[inline]
    fn index(&self, cx: i64, cy: i64) -> Option<usize> {
        self.geometry.checked_index(cx, cy)
    }

    /// Whether cell (cx, cy) is a wall; off the grid is.
    #[inline]
    pub fn is_wall(&self, cx: i64, cy: i64) -> bool {
        self.index(cx, cy).is_none_or(|i| self.wall[i])
    }

    /// Map-frame point to continuous grid coordinates (cells).
    #[inline]
    pub fn to_grid(&self, x: f64, y: f64) -> (f64, f64) {
        self.geometry.world_to_grid(x, y)
    }

    /// Map-frame point to its cell.
    #[inline]
    pub fn cell_of(&self, x: f64, y: f64) -> (i64, i64) {
        self.geometry.world_to_cell(x, y)
    }

    /// Whether a disc of radius `r` centred at (x, y) overlaps any wall cell.
    pub fn disc_hits_wall(&self, x: f64, y: f64, r: f64) -> bool {
        let (cx, cy) = self.cell_of(x, y);
        let Some(i) = self.index(cx, cy) else {
            return true;
        };
        // Cell-centre distances are within a cell diagonal of exact: only look closer when near.
        if f64::from(self.clearance_m[i]) > r + 1.5 * self.geometry.resolution_m() {
            return false;
        }
        let (gx, gy) = self.to_grid(x, y);
        let rc = r / self.geometry.resolution_m();
        #[allow(clippy::cast_possible_truncation)]
        let (x0, x1, y0, y1) = (
            (gx - rc).floor() as i64,
            (gx + rc).floor() as i64,
            (gy - rc).floor() as i64,
            (gy + rc).floor() as i64,
        );
        for ky in y0..=y1 {
            for kx in x0..=x1 {
                if !self.is_wall(kx, ky) {
                    continue;
                }
                #[allow(clippy::cast_precision_loss)]
                let (fx, fy) = (kx as f64, ky as f64);
                let ex = (fx - gx).max(gx - (fx + 1.0)).max(0.0);
                let ey = (fy - gy).max(gy - (fy + 1.0)).max(0.0);
                if ex * ex + ey * ey < rc * rc {
                    return true;
                }
            }
        }
        false
    }

    /// Walks the ray from (x, y) along the unit map-frame direction (dx, dy) up to `max_m`.
    #[inline]
    pub fn cast(&self, x: f64, y: f64, dx: f64, dy: f64, max_m: f64) -> Option<WallHit> {
        let (gx, gy) = self.to_grid(x, y);
        let (ux, uy) = self.geometry.world_dir_to_grid(dx, dy);
        #[allow(clippy::cast_possible_truncation)]
        let (mut cx, mut cy) = (gx.floor() as i64, gy.floor() as i64);
        if self.is_wall(cx, cy) {
            return Some(WallHit {
                dist_m: 0.0,
                side: 0,
                along_m: 0.0,
                x_m: x,
                y_m: y,
            });
        }
        let step_x: i64 = if ux > 0.0 { 1 } else { -1 };
        let step_y: i64 = if uy > 0.0 { 1 } else { -1 };
        let delta_x = if ux == 0.0 {
            f64::INFINITY
        } else {
            1.0 / ux.abs()
        };
        let delta_y = if uy == 0.0 {
            f64::INFINITY
        } else {
            1.0 / uy.abs()
        };
        #[allow(clippy::cast_precision_loss)]
        let mut next_x = if ux == 0.0 {
            f64::INFINITY
        } else if ux > 0.0 {
            (cx as f64 + 1.0 - gx) * delta_x
        } else {
            (gx - cx as f64) * delta_x
        };
        #[allow(clippy::cast_precision_loss)]
        let mut next_y = if uy == 0.0 {
            f64::INFINITY
        } else if uy > 0.0 {
            (cy as f64 + 1.0 - gy) * delta_y
        } else {
            (gy - cy as f64) * delta_y
        };
        let max_cells = max_m / self.geometry.resolution_m();
        loop {
            let (t, side) = if next_x < next_y {
                cx += step_x;
                let t = next_x;
                next_x += delta_x;
                (t, 0u8)
            } else {
                cy += step_y;
                let t = next_y;
                next_y += delta_y;
                (t, 1u8)
            };
            if t > max_cells {
                return None;
            }
            if self.is_wall(cx, cy) {
                let along_cells = if side == 0 { gy + t * uy } else { gx + t * ux };
                let dist_m = t * self.geometry.resolution_m();
                return Some(WallHit {
                    dist_m,
                    side,
                    along_m: along_cells * self.geometry.resolution_m(),
                    x_m: x + dist_m * dx,
                    y_m: y + dist_m * dy,
                });
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use protocol::Pose2D;

    fn room() -> WallGrid {
        // 4 m x 4 m at 0.1 m with a 1-cell wall border.
        let mut g = OccupancyGrid::filled(40, 40, 0.1, Pose2D::default(), 0).unwrap();
        for i in 0..40 {
            g.set(i, 0, 100);
            g.set(i, 39, 100);
            g.set(0, i, 100);
            g.set(39, i, 100);
        }
        WallGrid::from_grid(&g)
    }

    #[test]
    fn cast_hits_walls_at_exact_distance() {
        let w = room();
        let h = w.cast(2.0, 2.0, 1.0, 0.0, 10.0).unwrap();
        assert!((h.dist_m - 1.9).abs() < 1e-9, "{h:?}");
        assert_eq!(h.side, 0);
        let h = w.cast(2.0, 2.0, 0.0, -1.0, 10.0).unwrap();
        assert!((h.dist_m - 1.9).abs() < 1e-9);
        assert_eq!(h.side, 1);
        let d = std::f64::consts::FRAC_1_SQRT_2;
        let h = w.cast(2.0, 2.0, d, d, 10.0).unwrap();
        assert!((h.dist_m - 1.9 * 2f64.sqrt()).abs() < 1e-9);
        assert!(w.cast(2.0, 2.0, 1.0, 0.0, 1.0).is_none());
    }

    #[test]
    fn disc_overlap() {
        let w = room();
        assert!(!w.disc_hits_wall(2.0, 2.0, 0.25));
        assert!(!w.disc_hits_wall(0.36, 2.0, 0.25));
        assert!(w.disc_hits_wall(0.34, 2.0, 0.25));
        assert!(w.disc_hits_wall(-5.0, 2.0, 0.25));
    }
}
