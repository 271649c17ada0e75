//! A map version prepared for planning: inflated free space and the obstacle-heuristic cache.
//!
//! Built once per (map version, robot radius) and shared by every robot's [`super::Planner`]
//! as `Arc<PlanningMap>`. Planning happens in the *grid frame* in metres (the map frame moved to
//! the grid origin and rotated by its yaw), so cell lookups are a multiply and a floor.

use std::collections::VecDeque;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, PoisonError};

use map_core::{DistanceField, OccupancyGrid, Sources};
use protocol::{normalize_angle, Pose2D};

use crate::config::PlannerConfig;
use crate::error::{Endpoint, PlanError};
use crate::heuristic::{CoarseGrid, ObstacleHeuristic};

/// Identifies a map version: the grid content hash, or a key the caller assigns.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct MapKey(pub u64);

impl MapKey {
    /// FNV-1a over the grid's size, resolution, origin and cells.
    #[must_use]
    pub fn of_grid(grid: &OccupancyGrid) -> Self {
        let mut h: u64 = 0xcbf2_9ce4_8422_2325;
        let mut eat = |bytes: &[u8]| {
            for &b in bytes {
                h ^= u64::from(b);
                h = h.wrapping_mul(0x0100_0000_01b3);
            }
        };
        eat(&grid.width_cells().to_le_bytes());
        eat(&grid.height_cells().to_le_bytes());
        eat(&grid.resolution_m().to_le_bytes());
        let o = grid.origin();
        for v in [o.x_m, o.y_m, o.yaw_rad] {
            eat(&v.to_le_bytes());
        }
        eat(grid.cells());
        Self(h)
    }
}

/// Counters of the obstacle-heuristic cache.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct CacheStats {
    pub hits: u64,
    pub misses: u64,
    pub entries: usize,
}

/// A shared, locked obstacle heuristic for one goal cell.
pub type SharedHeuristic = Arc<Mutex<ObstacleHeuristic>>;

/// A map version ready for planning (see the module docs).
#[derive(Debug)]
pub struct PlanningMap {
    key: MapKey,
    grid: OccupancyGrid,
    distance: DistanceField,
    robot_radius_m: f64,
    coarse: CoarseGrid,
    fine_free: Vec<bool>,
    cache_size: usize,
    cache: Mutex<VecDeque<((u32, u32), SharedHeuristic)>>,
    hits: AtomicU64,
    misses: AtomicU64,
}

/// A disc the robot must keep out of, on top of the floor plan (another robot of the fleet):
/// the robot's centre stays at least `radius_m` plus the robot's own radius from its centre.
/// In the map frame where the pipeline makes them ([`crate::AvoidParams::discs`],
/// [`crate::Planner::plan_avoiding`]), in the grid frame inside the search.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Disc {
    pub x_m: f64,
    pub y_m: f64,
    pub radius_m: f64,
}

impl Disc {
    /// Distance from a grid-frame point to the disc's edge (negative inside).
    #[inline]
    #[must_use]
    pub fn gap_m(&self, x_m: f64, y_m: f64) -> f64 {
        (x_m - self.x_m).hypot(y_m - self.y_m) - self.radius_m
    }
}

/// A pose in the grid frame: metres from the grid origin along the grid axes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GridPose {
    pub x_m: f64,
    pub y_m: f64,
    pub yaw_rad: f64,
}

impl GridPose {
    /// The arc length from the first of `poses` to each of them, along the straight steps.
    #[must_use]
    pub fn arc_lengths(poses: &[GridPose]) -> Vec<f64> {
        let mut acc = 0.0;
        let mut out = Vec::with_capacity(poses.len());
        out.push(0.0);
        for w in poses.windows(2) {
            acc += (w[1].x_m - w[0].x_m).hypot(w[1].y_m - w[0].y_m);
            out.push(acc);
        }
        out
    }
}

impl PlanningMap {
    /// Prepares `grid` for a robot of `config.robot_radius_m`, keyed by its content hash.
    ///
    /// # Errors
    /// [`PlanError::InvalidConfig`] for a bad configuration.
    pub fn new(grid: OccupancyGrid, config: &PlannerConfig) -> Result<Self, PlanError> {
        let key = MapKey::of_grid(&grid);
        Self::with_key(grid, key, config)
    }

    /// As [`Self::new`] with a caller-given version key (e.g. the map store's version).
    ///
    /// # Errors
    /// [`PlanError::InvalidConfig`] for a bad configuration.
    pub fn with_key(
        grid: OccupancyGrid,
        key: MapKey,
        config: &PlannerConfig,
    ) -> Result<Self, PlanError> {
        config.validate()?;
        // Unknown space is not traversable.
        let distance = DistanceField::compute(&grid, Sources::OccupiedOrUnknown);
        #[allow(clippy::cast_possible_truncation)]
        let r = config.robot_radius_m as f32;
        let fine_free: Vec<bool> = distance.as_slice().iter().map(|&d| d >= r).collect();
        let coarse = CoarseGrid::from_fine(
            &fine_free,
            grid.width_cells(),
            grid.height_cells(),
            grid.resolution_m(),
            config.heuristic_downsample,
        );
        Ok(Self {
            key,
            grid,
            distance,
            robot_radius_m: config.robot_radius_m,
            coarse,
            fine_free,
            cache_size: config.heuristic_cache_size,
            cache: Mutex::new(VecDeque::new()),
            hits: AtomicU64::new(0),
            misses: AtomicU64::new(0),
        })
    }

    #[must_use]
    pub fn key(&self) -> MapKey {
        self.key
    }

    #[must_use]
    pub fn grid(&self) -> &OccupancyGrid {
        &self.grid
    }

    /// Distance field with occupied and unknown cells as obstacles.
    #[must_use]
    pub fn distance(&self) -> &DistanceField {
        &self.distance
    }

    #[must_use]
    pub fn robot_radius_m(&self) -> f64 {
        self.robot_radius_m
    }

    pub(crate) fn coarse(&self) -> &CoarseGrid {
        &self.coarse
    }

    /// Row-major inflated free mask of the map cells (`true` = a robot centred there is free).
    #[must_use]
    pub fn free_mask(&self) -> &[bool] {
        &self.fine_free
    }

    /// Whether a curve of length `length_m`, parametrized by arc length through `at`, keeps
    /// the robot collision-free. Sphere tracing on the distance field: from a point with
    /// clearance `c`, the next `c - radius - one cell diagonal` metres cannot collide (the
    /// field is 1-Lipschitz up to the cell quantization), so open space costs few lookups;
    /// near obstacles it samples every quarter cell. The points where the path's output poses
    /// will lie (`length_m * j / ceil(length_m / spacing_m)`) are always among the checked
    /// ones, so every output pose is exactly free.
    pub fn curve_free(
        &self,
        length_m: f64,
        spacing_m: f64,
        at: impl Fn(f64) -> (f64, f64),
    ) -> bool {
        self.curve_free_among(&[], length_m, spacing_m, at)
    }

    /// [`Self::curve_free`] with `discs` (grid frame) as obstacles too. The distance to a
    /// disc's edge is 1-Lipschitz like the field, so the same sphere tracing holds.
    pub fn curve_free_among(
        &self,
        discs: &[Disc],
        length_m: f64,
        spacing_m: f64,
        at: impl Fn(f64) -> (f64, f64),
    ) -> bool {
        let res = self.grid.resolution_m();
        let slack = res * std::f64::consts::SQRT_2;
        let (w_m, h_m) = self.grid.extent_m();
        let mut s = 0.0;
        loop {
            let (x, y) = at(s);
            let c = self.clearance_among(discs, x, y);
            if c < self.robot_radius_m {
                return false;
            }
            if s >= length_m {
                break;
            }
            // The map border bounds the step too: beyond it the field says nothing.
            let border = x.min(w_m - x).min(y).min(h_m - y);
            let advance = (c - self.robot_radius_m - slack)
                .min(border)
                .max(res * 0.25);
            s = (s + advance).min(length_m);
        }
        // Most candidate curves fail the trace above; only those that pass pay for checking
        // every output pose.
        let steps = (length_m / spacing_m).ceil().max(1.0);
        let mut j = 1.0;
        while j < steps {
            let (x, y) = at(length_m * j / steps);
            if self.clearance_among(discs, x, y) < self.robot_radius_m {
                return false;
            }
            j += 1.0;
        }
        true
    }

    /// Map-frame pose to grid frame.
    #[must_use]
    pub fn to_grid(&self, p: Pose2D) -> GridPose {
        let (gx, gy) = self.grid.world_to_grid(p.x_m, p.y_m);
        let res = self.grid.resolution_m();
        GridPose {
            x_m: gx * res,
            y_m: gy * res,
            yaw_rad: normalize_angle(p.yaw_rad - self.grid.origin().yaw_rad),
        }
    }

    /// Grid-frame pose to map frame.
    #[must_use]
    pub fn to_world(&self, p: GridPose) -> Pose2D {
        let o = self.grid.origin();
        let (s, c) = o.yaw_rad.sin_cos();
        Pose2D::new(
            o.x_m + c * p.x_m - s * p.y_m,
            o.y_m + s * p.x_m + c * p.y_m,
            normalize_angle(p.yaw_rad + o.yaw_rad),
        )
    }

    /// Cell of a grid-frame point (may be off the grid).
    #[inline]
    #[must_use]
    pub fn cell_of(&self, x_m: f64, y_m: f64) -> (i64, i64) {
        let res = self.grid.resolution_m();
        #[allow(clippy::cast_possible_truncation)]
        ((x_m / res).floor() as i64, (y_m / res).floor() as i64)
    }

    /// Clearance (distance to the nearest obstacle or unknown cell) at a grid-frame point;
    /// zero off the map.
    #[inline]
    #[must_use]
    pub fn clearance_m(&self, x_m: f64, y_m: f64) -> f64 {
        let (cx, cy) = self.cell_of(x_m, y_m);
        f64::from(self.distance.at(cx, cy))
    }

    /// [`Self::clearance_m`], or the distance to the nearest of `discs`' edges if less.
    #[inline]
    #[must_use]
    pub fn clearance_among(&self, discs: &[Disc], x_m: f64, y_m: f64) -> f64 {
        discs
            .iter()
            .fold(self.clearance_m(x_m, y_m), |c, d| c.min(d.gap_m(x_m, y_m)))
    }

    /// How far a band `half_width_m` either side of the heading of map-frame `p` runs straight
    /// ahead before an obstacle or unknown cell enters it, up to `max_m`; 0 when one is
    /// already within `half_width_m` of `p`. Sampled every half cell.
    #[must_use]
    pub fn free_ahead_m(&self, p: Pose2D, half_width_m: f64, max_m: f64) -> f64 {
        let g = self.to_grid(p);
        let (sin, cos) = g.yaw_rad.sin_cos();
        let step_m = 0.5 * self.grid.resolution_m();
        let mut ahead_m = 0.0;
        while ahead_m < max_m {
            if self.clearance_m(g.x_m + cos * ahead_m, g.y_m + sin * ahead_m) < half_width_m {
                return ahead_m;
            }
            ahead_m += step_m;
        }
        max_m
    }

    /// Whether a robot centred at this grid-frame point is collision-free.
    #[inline]
    #[must_use]
    pub fn is_free(&self, x_m: f64, y_m: f64) -> bool {
        self.clearance_m(x_m, y_m) >= self.robot_radius_m
    }

    /// Checks that a map-frame pose is finite, on the map and free; returns it in grid frame.
    ///
    /// # Errors
    /// [`PlanError::NotFinite`], [`PlanError::OffMap`] or [`PlanError::InCollision`].
    pub fn check_endpoint(&self, which: Endpoint, p: Pose2D) -> Result<GridPose, PlanError> {
        if !(p.x_m.is_finite() && p.y_m.is_finite() && p.yaw_rad.is_finite()) {
            return Err(PlanError::NotFinite {
                which,
                x_m: p.x_m,
                y_m: p.y_m,
                yaw_rad: p.yaw_rad,
            });
        }
        let g = self.to_grid(p);
        let (cx, cy) = self.cell_of(g.x_m, g.y_m);
        if !self.grid.contains(cx, cy) {
            return Err(PlanError::OffMap {
                which,
                x_m: p.x_m,
                y_m: p.y_m,
                cell_x: cx,
                cell_y: cy,
                width_cells: self.grid.width_cells(),
                height_cells: self.grid.height_cells(),
            });
        }
        let clearance_m = self.clearance_m(g.x_m, g.y_m);
        if clearance_m < self.robot_radius_m {
            return Err(PlanError::InCollision {
                which,
                x_m: p.x_m,
                y_m: p.y_m,
                clearance_m,
                robot_radius_m: self.robot_radius_m,
            });
        }
        Ok(g)
    }

    /// Coarse heuristic cell of a grid-frame point known to be on the map.
    pub(crate) fn coarse_cell(&self, x_m: f64, y_m: f64) -> (u32, u32) {
        let (cx, cy) = self.cell_of(x_m, y_m);
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        self.coarse.cell_of(cx.max(0) as u32, cy.max(0) as u32)
    }

    /// The obstacle heuristic for a goal coarse cell: cached, or started towards `start_cell`.
    /// Returns it and whether it was a cache hit.
    pub(crate) fn obstacle_heuristic(
        &self,
        goal_cell: (u32, u32),
        start_cell: (u32, u32),
    ) -> (SharedHeuristic, bool) {
        let mut cache = self.cache.lock().unwrap_or_else(PoisonError::into_inner);
        if let Some(pos) = cache.iter().position(|(g, _)| *g == goal_cell) {
            // Move to the back: the front is the least recently used.
            if let Some(entry) = cache.remove(pos) {
                let h = Arc::clone(&entry.1);
                cache.push_back(entry);
                self.hits.fetch_add(1, Ordering::Relaxed);
                return (h, true);
            }
        }
        self.misses.fetch_add(1, Ordering::Relaxed);
        let h = Arc::new(Mutex::new(ObstacleHeuristic::new(
            &self.coarse,
            goal_cell,
            start_cell,
        )));
        cache.push_back((goal_cell, Arc::clone(&h)));
        while cache.len() > self.cache_size {
            cache.pop_front();
        }
        (h, false)
    }

    /// Drops every cached obstacle heuristic (benchmarks of first plans use it).
    pub fn clear_heuristic_cache(&self) {
        self.cache
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .clear();
    }

    /// Cache hit and miss counts since the map was built.
    #[must_use]
    pub fn cache_stats(&self) -> CacheStats {
        let entries = self.cache.lock().map_or(0, |c| c.len());
        CacheStats {
            hits: self.hits.load(Ordering::Relaxed),
            misses: self.misses.load(Ordering::Relaxed),
            entries,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use map_core::{FREE, OCCUPIED};

    /// 5 m x 3 m, 5 cm cells, free but for a wall across it whose cells start at x = 3.5 m.
    fn wall_at_3_5_m() -> PlanningMap {
        let mut g = OccupancyGrid::filled(100, 60, 0.05, Pose2D::new(0.0, 0.0, 0.0), FREE).unwrap();
        for y in 0..60 {
            g.set(70, y, OCCUPIED);
        }
        PlanningMap::new(g, &PlannerConfig::default()).unwrap()
    }

    #[test]
    fn curve_check_terminates_and_sees_walls() {
        let map = wall_at_3_5_m();
        // Lengths whose output spacing does not divide evenly, which once stalled the walk.
        for len in [0.2, 0.3, 0.7, 1.1, 0.123_456_7, 1.9] {
            assert!(map.curve_free(len, 0.05, |s| (1.0 + s, 1.5)), "{len}");
        }
        // A line into the wall at x = 3.5 m (robot radius 0.25 m) collides.
        assert!(!map.curve_free(2.5, 0.05, |s| (1.0 + s, 1.5)));
        assert!(map.is_free(3.18, 1.5) && !map.is_free(3.32, 1.5));
    }

    #[test]
    fn free_ahead_runs_to_the_band_touching_a_wall() {
        let map = wall_at_3_5_m();
        // The wall's cells start at x = 3.5 m; a band 0.15 m wide each side meets it 0.15 m
        // before, 2.35 m from x = 1 (to within the field's cell, 0.05 m, on either side).
        let east = map.free_ahead_m(Pose2D::new(1.0, 1.5, 0.0), 0.15, 5.0);
        assert!((east - 2.35).abs() <= 0.1, "{east}");
        // Capped at the distance asked for.
        assert!((map.free_ahead_m(Pose2D::new(1.0, 1.5, 0.0), 0.15, 1.0) - 1.0).abs() < 1e-9);
        // Obliquely, the band meets it later: 2.35 m / cos(0.5).
        let oblique = map.free_ahead_m(Pose2D::new(1.0, 0.5, 0.5), 0.15, 5.0);
        assert!((oblique - 2.35 / 0.5_f64.cos()).abs() <= 0.15, "{oblique}");
        // Within the band's width already: nothing ahead is free.
        assert!(map.free_ahead_m(Pose2D::new(3.4, 1.5, 0.0), 0.15, 5.0) < 1e-9);
    }
}
