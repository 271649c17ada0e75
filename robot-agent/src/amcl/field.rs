//! The likelihood field: for every map cell, the distance to the nearest occupied cell, clamped
//! at `laser_likelihood_max_dist_m` and quantized to one byte.
//!
//! One byte per cell keeps the field of a large floor (2000 × 2000 cells = 4 MB) mostly in cache,
//! and the quantization step (max_dist / 255, 7.8 mm for 2 m) is far below a map cell (5 cm), so
//! the sensor model looks a beam's likelihood up in a 256-entry table instead of evaluating a
//! Gaussian per beam. The field is computed once per map version and shared by `Arc`.

use map_core::{classify, CellClass, DistanceField, GridGeometry, OccupancyGrid, Sources};
use protocol::Pose2D;

use super::AmclError;

/// Largest quantized value: "at or beyond the clamp distance" (also used off the map).
pub const FIELD_LEVELS: u8 = u8::MAX;

/// Distance-to-obstacle field of one map, clamped and quantized, plus the free cells from which
/// random particles are drawn.
#[derive(Debug, Clone)]
pub struct LikelihoodField {
    geometry: GridGeometry,
    max_dist_m: f64,
    quantized: Vec<u8>,
    /// The same for the distance to the nearest occupied *or unknown* cell: where a ray cast
    /// on the map stops (as Nav2's `map_calc_range` stops at any cell not known free; floor
    /// plans often draw outer walls as unknown).
    ray_quantized: Vec<u8>,
    free_cells: Vec<u32>,
}

impl LikelihoodField {
    /// Builds the field of `grid` with distances clamped at `max_dist_m`.
    ///
    /// # Errors
    /// [`AmclError::Config`] if `max_dist_m` is not positive and finite, or the map has more
    /// cells than a `u32` index holds.
    pub fn new(grid: &OccupancyGrid, max_dist_m: f64) -> Result<Self, AmclError> {
        if !(max_dist_m.is_finite() && max_dist_m > 0.0) {
            return Err(AmclError::Config {
                field: "laser_likelihood_max_dist_m",
                value: max_dist_m.to_string(),
                reason: "must be a positive finite number".into(),
            });
        }
        if grid.cells().len() > u32::MAX as usize {
            return Err(AmclError::Config {
                field: "map",
                value: grid.cells().len().to_string(),
                reason: "more cells than AMCL indexes".into(),
            });
        }
        let scale = f64::from(FIELD_LEVELS) / max_dist_m;
        let quantized_field = |sources| {
            DistanceField::compute(grid, sources)
                .as_slice()
                .iter()
                .map(|&d| quantize(f64::from(d), max_dist_m, scale))
                .collect::<Vec<u8>>()
        };
        let quantized = quantized_field(Sources::Occupied);
        let ray_quantized = quantized_field(Sources::OccupiedOrUnknown);
        #[allow(clippy::cast_possible_truncation)]
        let free_cells = grid
            .cells()
            .iter()
            .enumerate()
            .filter(|(_, &v)| classify(v) == CellClass::Free)
            .map(|(i, _)| i as u32)
            .collect();
        Ok(Self {
            geometry: *grid.geometry(),
            max_dist_m,
            quantized,
            ray_quantized,
            free_cells,
        })
    }

    /// Where the field lies in the map frame (the map's own geometry).
    #[must_use]
    pub fn geometry(&self) -> &GridGeometry {
        &self.geometry
    }

    #[must_use]
    pub fn width_cells(&self) -> u32 {
        self.geometry.width_cells()
    }

    #[must_use]
    pub fn height_cells(&self) -> u32 {
        self.geometry.height_cells()
    }

    #[must_use]
    pub fn resolution_m(&self) -> f64 {
        self.geometry.resolution_m()
    }

    /// Pose of the lower-left corner of cell (0, 0) in the map frame.
    #[must_use]
    pub fn origin(&self) -> Pose2D {
        self.geometry.origin()
    }

    #[must_use]
    pub fn max_dist_m(&self) -> f64 {
        self.max_dist_m
    }

    /// Number of free cells (where random particles may be placed).
    #[must_use]
    pub fn free_cell_count(&self) -> usize {
        self.free_cells.len()
    }

    /// Metres per quantization level.
    #[must_use]
    pub fn level_m(&self) -> f64 {
        self.max_dist_m / f64::from(FIELD_LEVELS)
    }

    /// Quantized distance at continuous grid coordinates (cells); [`FIELD_LEVELS`] off the map,
    /// as Nav2 treats endpoints off the map as maximally far from any obstacle.
    #[inline]
    #[must_use]
    pub fn level_at_grid(&self, gx: f64, gy: f64) -> u8 {
        self.index_at_grid(gx, gy)
            .map_or(FIELD_LEVELS, |i| self.quantized[i])
    }

    /// As [`Self::level_at_grid`] for the distance to the nearest occupied or unknown cell
    /// (0: the point is in one, where a ray stops).
    #[inline]
    #[must_use]
    pub fn ray_level_at_grid(&self, gx: f64, gy: f64) -> u8 {
        self.index_at_grid(gx, gy)
            .map_or(FIELD_LEVELS, |i| self.ray_quantized[i])
    }

    /// Clamped distance to the nearest occupied or unknown cell at a map-frame point.
    #[must_use]
    pub fn ray_distance_m(&self, x_m: f64, y_m: f64) -> f64 {
        let (gx, gy) = self.world_to_grid(x_m, y_m);
        f64::from(self.ray_level_at_grid(gx, gy)) * self.level_m()
    }

    #[inline]
    fn index_at_grid(&self, gx: f64, gy: f64) -> Option<usize> {
        // Truncation equals floor for non-negative values and, unlike `floor`, compiles to one
        // instruction on baseline x86-64 (no SSE4.1); this is the innermost loop of AMCL.
        // NaN fails the comparison and lands off the map too.
        if !(gx >= 0.0 && gy >= 0.0) {
            return None;
        }
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let (ix, iy) = (gx as usize, gy as usize);
        let w = self.geometry.width_cells() as usize;
        if ix >= w || iy >= self.geometry.height_cells() as usize {
            return None;
        }
        Some(iy * w + ix)
    }

    /// Clamped distance to the nearest obstacle at a map-frame point, to the quantization step.
    #[must_use]
    pub fn distance_m(&self, x_m: f64, y_m: f64) -> f64 {
        let (gx, gy) = self.world_to_grid(x_m, y_m);
        f64::from(self.level_at_grid(gx, gy)) * self.level_m()
    }

    /// A map-frame point in continuous grid coordinates (cells), honouring the origin's yaw.
    #[inline]
    #[must_use]
    pub fn world_to_grid(&self, x_m: f64, y_m: f64) -> (f64, f64) {
        self.geometry.world_to_grid(x_m, y_m)
    }

    /// Map-frame position of continuous grid coordinates (cells).
    #[must_use]
    pub fn grid_to_world(&self, gx: f64, gy: f64) -> (f64, f64) {
        self.geometry.grid_to_world(gx, gy)
    }

    /// Grid coordinates (column, row) of the `k`-th free cell.
    pub(crate) fn free_cell(&self, k: usize) -> Option<(u32, u32)> {
        let i = *self.free_cells.get(k)?;
        let w = self.geometry.width_cells();
        Some((i % w, i / w))
    }
}

#[inline]
fn quantize(d_m: f64, max_dist_m: f64, scale: f64) -> u8 {
    // Infinite distances (a map without obstacles) clamp like any far cell.
    let clamped = d_m.min(max_dist_m);
    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
    let q = (clamped * scale).round() as u8;
    q
}

#[cfg(test)]
mod tests {
    use super::*;
    use map_core::{FREE, OCCUPIED};

    #[test]
    fn distances_are_clamped_and_quantized() {
        let mut g = OccupancyGrid::filled(40, 20, 0.05, Pose2D::new(1.0, -2.0, 0.0), FREE).unwrap();
        g.set(5, 5, OCCUPIED);
        let f = LikelihoodField::new(&g, 0.5).unwrap();
        let (x, y) = g.cell_to_world(5, 5);
        assert_eq!(f.distance_m(x, y), 0.0);
        let (x, y) = g.cell_to_world(9, 5);
        assert!((f.distance_m(x, y) - 0.2).abs() <= f.level_m() / 2.0 + 1e-9);
        let (x, y) = g.cell_to_world(39, 19);
        assert!((f.distance_m(x, y) - 0.5).abs() < 1e-12);
        assert!((f.distance_m(-100.0, 0.0) - 0.5).abs() < 1e-12);
        assert_eq!(f.free_cell_count(), 799);
        assert!(LikelihoodField::new(&g, 0.0).is_err());
        assert!(LikelihoodField::new(&g, f64::NAN).is_err());
    }

    #[test]
    fn grid_transform_round_trips_with_rotated_origin() {
        let g = OccupancyGrid::filled(10, 10, 0.1, Pose2D::new(2.0, 3.0, 1.0), FREE).unwrap();
        let f = LikelihoodField::new(&g, 1.0).unwrap();
        let (gx, gy) = f.world_to_grid(2.5, 3.7);
        let (x, y) = f.grid_to_world(gx, gy);
        assert!((x - 2.5).abs() < 1e-12 && (y - 3.7).abs() < 1e-12);
        let (cx, cy) = g.world_to_cell(2.5, 3.7);
        assert_eq!((gx.floor() as i64, gy.floor() as i64), (cx, cy));
    }
}
