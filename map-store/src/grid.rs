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

/// An occupancy grid with its placement in the map frame.
#[derive(Debug, Clone, PartialEq)]
pub struct OccupancyGrid {
    width_cells: u32,
    height_cells: u32,
    resolution_m: f64,
    origin: Pose2D,
    cells: Vec<u8>,
}

impl OccupancyGrid {
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
        let expected = width_cells as usize * height_cells as usize;
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
        Ok(Self {
            width_cells,
            height_cells,
            resolution_m,
            origin,
            cells,
        })
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

    #[must_use]
    pub fn width_cells(&self) -> u32 {
        self.width_cells
    }

    #[must_use]
    pub fn height_cells(&self) -> u32 {
        self.height_cells
    }

    #[must_use]
    pub fn resolution_m(&self) -> f64 {
        self.resolution_m
    }

    #[must_use]
    pub fn origin(&self) -> Pose2D {
        self.origin
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

    /// The value at (cx, cy), or `None` off the grid.
    #[inline]
    #[must_use]
    pub fn get(&self, cx: i64, cy: i64) -> Option<u8> {
        if cx < 0
            || cy < 0
            || cx >= i64::from(self.width_cells)
            || cy >= i64::from(self.height_cells)
        {
            return None;
        }
        // In bounds checked above, so the casts are lossless.
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        Some(self.cells[self.index(cx as u32, cy as u32)])
    }

    /// Sets one cell; off-grid writes are ignored because callers rasterize shapes that may
    /// overhang the map edge.
    pub fn set(&mut self, cx: i64, cy: i64, value: u8) {
        if cx < 0
            || cy < 0
            || cx >= i64::from(self.width_cells)
            || cy >= i64::from(self.height_cells)
        {
            return;
        }
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let i = self.index(cx as u32, cy as u32);
        self.cells[i] = value;
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
        let (s, c) = self.origin.yaw_rad.sin_cos();
        let dx = x_m - self.origin.x_m;
        let dy = y_m - self.origin.y_m;
        // Rotate by -yaw into the grid frame.
        let gx = c * dx + s * dy;
        let gy = -s * dx + c * dy;
        (gx / self.resolution_m, gy / self.resolution_m)
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

    /// Whether the cell lies on the grid.
    #[inline]
    #[must_use]
    pub fn contains(&self, cx: i64, cy: i64) -> bool {
        cx >= 0 && cy >= 0 && cx < i64::from(self.width_cells) && cy < i64::from(self.height_cells)
    }

    /// The map-frame centre of cell (cx, cy).
    #[inline]
    #[must_use]
    pub fn cell_to_world(&self, cx: i64, cy: i64) -> (f64, f64) {
        #[allow(clippy::cast_precision_loss)]
        let (gx, gy) = (
            (cx as f64 + 0.5) * self.resolution_m,
            (cy as f64 + 0.5) * self.resolution_m,
        );
        let (s, c) = self.origin.yaw_rad.sin_cos();
        (
            self.origin.x_m + c * gx - s * gy,
            self.origin.y_m + s * gx + c * gy,
        )
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
