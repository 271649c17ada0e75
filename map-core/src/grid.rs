//! The occupancy grid every other crate plans, localizes and renders on.
//!
//! Cells hold ROS `nav_msgs/OccupancyGrid` values: `0..=100` is the occupancy probability in
//! percent and [`UNKNOWN`] (255, the `-1` of ROS as an unsigned byte) is unknown. Storage is
//! row-major with row 0 at the *bottom* of the map (smallest y in the grid frame), exactly as ROS
//! publishes grids, so cell values travel over the wire unchanged. The grid frame is the map
//! frame moved to `origin` (the pose of the lower-left corner of cell (0, 0)) and rotated by
//! `origin.yaw_rad`; every transform here honours that rotation.

use protocol::Pose2D;

use crate::error::MapError;

/// Cell value for an unknown cell (ROS `-1` stored as `u8`).
pub const UNKNOWN: u8 = 255;
/// Cell value for a certainly free cell.
pub const FREE: u8 = 0;
/// Cell value for a certainly occupied cell.
pub const OCCUPIED: u8 = 100;
/// Cells at or above this occupancy (percent) count as obstacles for planning, the distance
/// field and ray casting; scale-mode cells in between thresholds below it count as free space.
pub const OBSTACLE_MIN_PCT: u8 = 65;

/// What a cell means to a planner or a sensor model.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum CellClass {
    Free,
    Occupied,
    Unknown,
}

/// Classifies one ROS cell value.
#[inline]
#[must_use]
pub fn classify(value: u8) -> CellClass {
    if value > OCCUPIED {
        CellClass::Unknown
    } else if value >= OBSTACLE_MIN_PCT {
        CellClass::Occupied
    } else {
        CellClass::Free
    }
}

/// Counts of cells per class, as printed by `map-store import`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct CellCounts {
    pub free: u64,
    pub occupied: u64,
    pub unknown: u64,
}

/// Where a grid lies in the map frame: size, resolution and origin, with the origin's rotation
/// cached. Every raster over a floor plan (the occupancy grid, AMCL's likelihood field, the
/// simulator's wall grid) converts coordinates through this one type.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GridGeometry {
    width_cells: u32,
    height_cells: u32,
    resolution_m: f64,
    origin: Pose2D,
    cos_yaw: f64,
    sin_yaw: f64,
}

impl GridGeometry {
    /// Checks size, resolution and origin.
    ///
    /// # Errors
    /// [`MapError::Invalid`] naming the offending field and value.
    pub fn new(
        width_cells: u32,
        height_cells: u32,
        resolution_m: f64,
        origin: Pose2D,
    ) -> Result<Self, MapError> {
        if width_cells == 0 || height_cells == 0 {
            return Err(MapError::invalid(
                "size",
                format!("{width_cells}x{height_cells}"),
                "a map needs at least one cell",
            ));
        }
        if !resolution_m.is_finite() || resolution_m <= 0.0 {
            return Err(MapError::invalid(
                "resolution",
                resolution_m,
                "must be a positive, finite number of metres per cell",
            ));
        }
        for (field, v) in [
            ("origin.x", origin.x_m),
            ("origin.y", origin.y_m),
            ("origin.yaw", origin.yaw_rad),
        ] {
            if !v.is_finite() {
                return Err(MapError::invalid(field, v, "must be finite"));
            }
        }
        let (sin_yaw, cos_yaw) = origin.yaw_rad.sin_cos();
        Ok(Self {
            width_cells,
            height_cells,
            resolution_m,
            origin,
            cos_yaw,
            sin_yaw,
        })
    }

    #[inline]
    #[must_use]
    pub fn width_cells(&self) -> u32 {
        self.width_cells
    }

    #[inline]
    #[must_use]
    pub fn height_cells(&self) -> u32 {
        self.height_cells
    }

    #[inline]
    #[must_use]
    pub fn resolution_m(&self) -> f64 {
        self.resolution_m
    }

    /// Pose of the lower-left corner of cell (0, 0) in the map frame.
    #[inline]
    #[must_use]
    pub fn origin(&self) -> Pose2D {
        self.origin
    }

    /// Number of cells.
    #[must_use]
    pub fn len(&self) -> usize {
        self.width_cells as usize * self.height_cells as usize
    }

    /// Never true: a geometry has at least one cell.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Width and height of the mapped area in metres.
    #[must_use]
    pub fn extent_m(&self) -> (f64, f64) {
        (
            f64::from(self.width_cells) * self.resolution_m,
            f64::from(self.height_cells) * self.resolution_m,
        )
    }

    /// Linear index of cell (cx, cy); callers guarantee bounds.
    #[inline]
    #[must_use]
    pub fn index(&self, cx: u32, cy: u32) -> usize {
        cy as usize * self.width_cells as usize + cx as usize
    }

    /// Linear index of cell (cx, cy), or `None` off the grid.
    #[inline]
    #[must_use]
    pub fn checked_index(&self, cx: i64, cy: i64) -> Option<usize> {
        // In bounds once `contains` holds, so the casts are lossless.
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        self.contains(cx, cy)
            .then(|| self.index(cx as u32, cy as u32))
    }

    /// Whether the cell lies on the grid.
    #[inline]
    #[must_use]
    pub fn contains(&self, cx: i64, cy: i64) -> bool {
        cx >= 0 && cy >= 0 && cx < i64::from(self.width_cells) && cy < i64::from(self.height_cells)
    }

    /// A map-frame point in continuous grid coordinates (cells, not rounded).
    #[inline]
    #[must_use]
    pub fn world_to_grid(&self, x_m: f64, y_m: f64) -> (f64, f64) {
        let dx = x_m - self.origin.x_m;
        let dy = y_m - self.origin.y_m;
        // Rotate by -yaw into the grid frame.
        let gx = self.cos_yaw * dx + self.sin_yaw * dy;
        let gy = -self.sin_yaw * dx + self.cos_yaw * dy;
        (gx / self.resolution_m, gy / self.resolution_m)
    }

    /// A map-frame direction (unit-free) rotated into the grid frame; ray casters step along it.
    #[inline]
    #[must_use]
    pub fn world_dir_to_grid(&self, dx: f64, dy: f64) -> (f64, f64) {
        (
            self.cos_yaw * dx + self.sin_yaw * dy,
            -self.sin_yaw * dx + self.cos_yaw * dy,
        )
    }

    /// The map-frame point of continuous grid coordinates (cells).
    #[inline]
    #[must_use]
    pub fn grid_to_world(&self, gx: f64, gy: f64) -> (f64, f64) {
        let (ux, uy) = (gx * self.resolution_m, gy * self.resolution_m);
        (
            self.origin.x_m + self.cos_yaw * ux - self.sin_yaw * uy,
            self.origin.y_m + self.sin_yaw * ux + self.cos_yaw * uy,
        )
    }

    /// The cell holding a map-frame point (may be off the grid: check with [`Self::contains`]).
    #[inline]
    #[must_use]
    pub fn world_to_cell(&self, x_m: f64, y_m: f64) -> (i64, i64) {
        let (gx, gy) = self.world_to_grid(x_m, y_m);
        // Saturating float->int cast is the intent for points far off the map.
        #[allow(clippy::cast_possible_truncation)]
        (gx.floor() as i64, gy.floor() as i64)
    }

    /// The map-frame centre of cell (cx, cy).
    #[inline]
    #[must_use]
    pub fn cell_to_world(&self, cx: i64, cy: i64) -> (f64, f64) {
        #[allow(clippy::cast_precision_loss)]
        self.grid_to_world(cx as f64 + 0.5, cy as f64 + 0.5)
    }
}

/// An occupancy grid with its placement in the map frame.
#[derive(Debug, Clone, PartialEq)]
pub struct OccupancyGrid {
    geometry: GridGeometry,
    cells: Vec<u8>,
}

impl OccupancyGrid {
    /// Hex sha256 over the little-endian width, height, resolution, origin (x, y, yaw) and
    /// cells: what names a map version in the map store and in run logs.
    #[must_use]
    pub fn content_hash(&self) -> String {
        use sha2::{Digest, Sha256};
        let mut h = Sha256::new();
        h.update(self.width_cells().to_le_bytes());
        h.update(self.height_cells().to_le_bytes());
        h.update(self.resolution_m().to_le_bytes());
        let o = self.origin();
        for v in [o.x_m, o.y_m, o.yaw_rad] {
            h.update(v.to_le_bytes());
        }
        h.update(self.cells());
        hex::encode(h.finalize())
    }

    /// Builds a grid, checking that the cell buffer, size and resolution agree.
    ///
    /// # Errors
    /// [`MapError::Invalid`] naming the offending field and value.
    pub fn new(
        width_cells: u32,
        height_cells: u32,
        resolution_m: f64,
        origin: Pose2D,
        cells: Vec<u8>,
    ) -> Result<Self, MapError> {
        let geometry = GridGeometry::new(width_cells, height_cells, resolution_m, origin)?;
        let expected = geometry.len();
        if cells.len() != expected {
            return Err(MapError::invalid(
                "cells",
                cells.len(),
                format!("expected {width_cells}x{height_cells} = {expected} cells"),
            ));
        }
        if let Some(bad) = cells.iter().find(|&&v| v > OCCUPIED && v != UNKNOWN) {
            return Err(MapError::invalid(
                "cells",
                *bad,
                "cell values are 0..=100 or 255 (unknown)",
            ));
        }
        Ok(Self { geometry, cells })
    }

    /// A grid of one value everywhere; handy for tests and synthetic worlds.
    ///
    /// # Errors
    /// As [`OccupancyGrid::new`].
    pub fn filled(
        width_cells: u32,
        height_cells: u32,
        resolution_m: f64,
        origin: Pose2D,
        value: u8,
    ) -> Result<Self, MapError> {
        let n = width_cells as usize * height_cells as usize;
        Self::new(
            width_cells,
            height_cells,
            resolution_m,
            origin,
            vec![value; n],
        )
    }

    /// Where this grid lies in the map frame.
    #[must_use]
    pub fn geometry(&self) -> &GridGeometry {
        &self.geometry
    }

    #[must_use]
    pub fn width_cells(&self) -> u32 {
        self.geometry.width_cells
    }

    #[must_use]
    pub fn height_cells(&self) -> u32 {
        self.geometry.height_cells
    }

    #[must_use]
    pub fn resolution_m(&self) -> f64 {
        self.geometry.resolution_m
    }

    #[must_use]
    pub fn origin(&self) -> Pose2D {
        self.geometry.origin
    }

    /// Row-major cells, row 0 at the bottom.
    #[must_use]
    pub fn cells(&self) -> &[u8] {
        &self.cells
    }

    /// Consumes the grid, returning its cells.
    #[must_use]
    pub fn into_cells(self) -> Vec<u8> {
        self.cells
    }

    /// Width and height of the mapped area in metres.
    #[must_use]
    pub fn extent_m(&self) -> (f64, f64) {
        self.geometry.extent_m()
    }

    /// Linear index of cell (cx, cy); callers guarantee bounds.
    #[inline]
    #[must_use]
    pub fn index(&self, cx: u32, cy: u32) -> usize {
        self.geometry.index(cx, cy)
    }

    /// The value at (cx, cy), or `None` off the grid.
    #[inline]
    #[must_use]
    pub fn get(&self, cx: i64, cy: i64) -> Option<u8> {
        self.geometry.checked_index(cx, cy).map(|i| self.cells[i])
    }

    /// Sets one cell; off-grid writes are ignored because callers rasterize shapes that may
    /// overhang the map edge.
    pub fn set(&mut self, cx: i64, cy: i64, value: u8) {
        if let Some(i) = self.geometry.checked_index(cx, cy) {
            self.cells[i] = value;
        }
    }

    /// The class of cell (cx, cy); off the grid counts as unknown.
    #[inline]
    #[must_use]
    pub fn class_at(&self, cx: i64, cy: i64) -> CellClass {
        self.get(cx, cy).map_or(CellClass::Unknown, classify)
    }

    /// A map-frame point in continuous grid coordinates (cells, not rounded).
    #[inline]
    #[must_use]
    pub fn world_to_grid(&self, x_m: f64, y_m: f64) -> (f64, f64) {
        self.geometry.world_to_grid(x_m, y_m)
    }

    /// The cell holding a map-frame point (may be off the grid: check with [`Self::contains`]).
    #[inline]
    #[must_use]
    pub fn world_to_cell(&self, x_m: f64, y_m: f64) -> (i64, i64) {
        self.geometry.world_to_cell(x_m, y_m)
    }

    /// Whether the cell lies on the grid.
    #[inline]
    #[must_use]
    pub fn contains(&self, cx: i64, cy: i64) -> bool {
        self.geometry.contains(cx, cy)
    }

    /// The map-frame centre of cell (cx, cy).
    #[inline]
    #[must_use]
    pub fn cell_to_world(&self, cx: i64, cy: i64) -> (f64, f64) {
        self.geometry.cell_to_world(cx, cy)
    }

    /// Counts of free, occupied and unknown cells.
    #[must_use]
    pub fn counts(&self) -> CellCounts {
        let mut counts = CellCounts::default();
        for &v in &self.cells {
            match classify(v) {
                CellClass::Free => counts.free += 1,
                CellClass::Occupied => counts.occupied += 1,
                CellClass::Unknown => counts.unknown += 1,
            }
        }
        counts
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(yaw: f64) -> OccupancyGrid {
        OccupancyGrid::filled(10, 20, 0.1, Pose2D::new(2.0, 3.0, yaw), FREE).unwrap()
    }

    #[test]
    fn world_cell_round_trip_honours_origin_and_yaw() {
        for yaw in [0.0, 1.0, -2.5] {
            let g = grid(yaw);
            for (cx, cy) in [(0, 0), (9, 19), (4, 7)] {
                let (x, y) = g.cell_to_world(cx, cy);
                assert_eq!(g.world_to_cell(x, y), (cx, cy), "yaw {yaw}");
            }
        }
        let g = grid(0.0);
        assert_eq!(g.world_to_cell(2.05, 3.05), (0, 0));
        assert_eq!(g.world_to_cell(1.99, 3.05), (-1, 0));
        assert!(!g.contains(-1, 0));
        // With a quarter turn, +x of the grid points along +y of the map.
        let g = grid(std::f64::consts::FRAC_PI_2);
        assert_eq!(g.world_to_cell(1.95, 3.25), (2, 0));
    }

    #[test]
    fn rejects_bad_shapes() {
        let o = Pose2D::new(0.0, 0.0, 0.0);
        assert!(OccupancyGrid::new(2, 2, 0.1, o, vec![0; 3]).is_err());
        assert!(OccupancyGrid::new(2, 2, 0.0, o, vec![0; 4]).is_err());
        assert!(OccupancyGrid::new(2, 2, f64::NAN, o, vec![0; 4]).is_err());
        assert!(OccupancyGrid::new(0, 2, 0.1, o, vec![]).is_err());
        assert!(OccupancyGrid::new(1, 1, 0.1, o, vec![101]).is_err());
    }

    #[test]
    fn classes_and_counts() {
        let o = Pose2D::new(0.0, 0.0, 0.0);
        let g = OccupancyGrid::new(2, 2, 0.1, o, vec![0, 100, UNKNOWN, 40]).unwrap();
        assert_eq!(
            g.counts(),
            CellCounts {
                free: 2,
                occupied: 1,
                unknown: 1
            }
        );
        assert_eq!(g.class_at(5, 5), CellClass::Unknown);
    }
}
