//! Beam (ray-cast) laser model (Thrun et al., Table 6.1; Nav2's `beam` model), with the
//! expected range found by sphere tracing the likelihood field.
//!
//! The likelihood field only asks whether a beam's endpoint lies near some wall. It cannot see
//! that a beam passed through a wall on its way, or that a beam without a return should have hit
//! the end of a corridor: down a long corridor it pins the robot sideways but hardly along. The
//! beam model compares each measured range `r` with the range `r̂` the map predicts from the
//! particle's pose:
//! `p = z_hit · exp(-(r - r̂)² / (2σ²)) + z_short · λ e^{-λr} [r < r̂] + z_max [r = r_max]
//!  + z_rand / r_max [r < r_max]`, exactly Nav2's `BeamModel::sensorFunction`.
//!
//! Nav2 casts each ray of each particle cell by cell (Bresenham), which makes its filter 30-50x
//! slower than a likelihood field. Here a ray jumps by the distance to the nearest obstacle,
//! which the likelihood field already holds (sphere tracing): a few lookups down open corridors,
//! more only where it grazes a wall. And rays are shared: a ray is cast once per map cell and
//! direction bin (0.7°) from the cell's centre and kept in a [`RayCache`] that lives as long as
//! the filter; a particle's range is that ray's, shifted by how far the particle's laser sits
//! from the cell's centre along the ray. Tracking particles crowd into a few cells and
//! directions, and move a cell or so per update, so an update casts a few hundred rays instead
//! of 120,000.

use std::f64::consts::{SQRT_2, TAU};

use protocol::{LaserScan, Pose2D};

use super::config::{AmclConfig, BeamCombination};
use super::field::LikelihoodField;

/// Entries per metre of the tabulated per-beam term (1 cm steps, far below σ).
const TABLE_PER_M: f64 = 100.0;
/// Beyond this many σ from the predicted range the hit term is below 3e-4 of `z_hit`: the
/// table ends there and the beam's term is its constant tail.
const TABLE_SIGMAS: f64 = 4.0;
/// Rays are cached per direction bin of a full turn divided by this (0.7°: 5 cm across at 4 m);
/// a power of two, so that wrapping is a mask.
const DIRECTION_BINS: usize = 512;
/// Slots of the ray cache (direct-mapped: a colliding ray is cast again).
const CACHE_SLOTS: usize = 1 << 15;
const SLOT_SHIFT: u32 = 64 - 15;

/// The ranges of the rays cast so far from cell centres, per (cell, direction bin), for one
/// field and one maximum range. Only a memo: a hit returns what casting again would.
#[derive(Debug, Clone)]
pub struct RayCache {
    /// `((cell + 1) << 16) | bin`, 0 for an empty slot.
    keys: Vec<u64>,
    ranges_cells: Vec<f32>,
    /// The maximum range the cached rays were cast to, in cells.
    limit_cells: f64,
    /// Unit vector of each direction bin's centre, in the grid frame.
    directions: Vec<[f64; 2]>,
}

impl Default for RayCache {
    fn default() -> Self {
        #[allow(clippy::cast_precision_loss)]
        let directions = (0..DIRECTION_BINS)
            .map(|b| {
                let (s, c) = (b as f64 * TAU / DIRECTION_BINS as f64).sin_cos();
                [c, s]
            })
            .collect();
        Self {
            keys: vec![0; CACHE_SLOTS],
            ranges_cells: vec![0.0; CACHE_SLOTS],
            limit_cells: 0.0,
            directions,
        }
    }
}

impl RayCache {
    /// Forgets every ray (the map changed).
    pub fn clear(&mut self) {
        self.keys.fill(0);
    }

    /// Keeps the rays if they were cast to `limit_cells`, forgets them otherwise.
    fn prepare(&mut self, limit_cells: f64) {
        if (self.limit_cells - limit_cells).abs() > 1e-9 {
            self.clear();
            self.limit_cells = limit_cells;
        }
    }
}

/// A particle's laser in grid coordinates, prepared for one scan.
#[derive(Debug, Clone, Copy)]
struct Laser {
    ox: f64,
    oy: f64,
    /// Heading in direction bins, in `[0, DIRECTION_BINS)`.
    heading_bins: f64,
    /// Index of the map cell the laser is in, plus one and shifted into a cache key; `None` off
    /// the map.
    cell_key: Option<u64>,
    /// Offset of the laser from its cell's centre, in cells.
    from_centre: [f64; 2],
}

/// One used beam of a scan, prepared for ray casting.
#[derive(Debug, Clone, Copy)]
struct Beam {
    /// Bearing in the laser frame.
    angle_rad: f64,
    /// Measured range, in cells.
    range_cells: f64,
    /// Offset of this beam's rows in the term table.
    row: usize,
}

/// The beam model prepared for one scan on one field.
#[derive(Debug)]
pub struct BeamScanModel<'a> {
    field: &'a LikelihoodField,
    beams: Vec<Beam>,
    /// Per beam two rows (`r < r̂`, then `r ≥ r̂`) of `len` entries: the combined term (`ln p`
    /// or `p³`) per centimetre of `|r - r̂|`; the last entry is the tail beyond the table.
    terms: Vec<f64>,
    len: usize,
    /// Metres per cell, to index the table from cell distances.
    resolution_m: f64,
    /// Field level to cells (distance to the nearest obstacle, in cells).
    cells_per_level: f64,
    /// The laser's pose in the robot frame, in cells for the position.
    laser_x_cells: f64,
    laser_y_cells: f64,
    laser_yaw_rad: f64,
    /// The sensor's maximum range, in cells: rays are cast this far.
    range_max_cells: f64,
    /// The particles' lasers of the current batch.
    lasers: Vec<Laser>,
    cache: &'a mut RayCache,
    combination: BeamCombination,
    /// The log-likelihood is divided by this (1: the model as is).
    temperature: f64,
}

impl<'a> BeamScanModel<'a> {
    /// Prepares the model for `scan`, using at most `config.max_beams` beams (returns and
    /// no-returns alike; beams below `range_min_m` or not finite are left out).
    #[must_use]
    pub fn new(
        field: &'a LikelihoodField,
        config: &AmclConfig,
        scan: &LaserScan,
        cache: &'a mut RayCache,
    ) -> Self {
        Self::build(field, config, scan, cache, true)
    }

    /// The model without its likelihood tables, for [`Self::agreement`] only (it weighs every
    /// pose alike): the lost-localization check runs every update and needs no logarithms.
    #[must_use]
    pub fn for_agreement(
        field: &'a LikelihoodField,
        config: &AmclConfig,
        scan: &LaserScan,
        cache: &'a mut RayCache,
    ) -> Self {
        Self::build(field, config, scan, cache, false)
    }

    fn build(
        field: &'a LikelihoodField,
        config: &AmclConfig,
        scan: &LaserScan,
        cache: &'a mut RayCache,
        tables: bool,
    ) -> Self {
        let resolution_m = field.resolution_m();
        let range_max_m = f64::from(scan.range_max_m);
        let sigma = config.sigma_hit_m;
        let lambda = config.lambda_short_per_m;
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let len = (TABLE_SIGMAS * sigma * TABLE_PER_M).ceil() as usize + 2;
        let combine = |p: f64| match config.beam_combination {
            BeamCombination::SumOfCubes => p * p * p,
            BeamCombination::Product => p.ln(),
        };
        #[allow(clippy::cast_precision_loss)]
        let hits: Vec<f64> = (0..len)
            .map(|k| {
                let d = k as f64 / TABLE_PER_M;
                if k + 1 == len {
                    0.0
                } else {
                    config.z_hit * (-(d * d) / (2.0 * sigma * sigma)).exp()
                }
            })
            .collect();
        let mut beams = Vec::new();
        let mut terms = Vec::new();
        for i in super::sensor::beam_indices(scan.ranges_m.len(), config.max_beams) {
            let r = f64::from(scan.ranges_m[i]);
            if !(r.is_finite() && r >= f64::from(scan.range_min_m)) {
                continue;
            }
            let is_max = !scan.is_return(i);
            let r = r.min(range_max_m);
            let (base, short) = if is_max {
                (config.z_max, 0.0)
            } else {
                (
                    config.z_rand / range_max_m,
                    config.z_short * lambda * (-lambda * r).exp(),
                )
            };
            let row = terms.len();
            if tables {
                for extra in [short, 0.0] {
                    terms.extend(hits.iter().map(|hit| combine(hit + base + extra)));
                }
            }
            beams.push(Beam {
                angle_rad: f64::from(scan.beam_angle_rad(i)),
                range_cells: r / resolution_m,
                row,
            });
        }
        let laser = config.robot_from_laser;
        let range_max_cells = range_max_m / resolution_m;
        cache.prepare(range_max_cells);
        Self {
            field,
            beams,
            terms,
            len,
            resolution_m,
            cells_per_level: field.level_m() / resolution_m,
            laser_x_cells: laser.x_m / resolution_m,
            laser_y_cells: laser.y_m / resolution_m,
            laser_yaw_rad: laser.yaw_rad,
            range_max_cells,
            lasers: Vec::new(),
            cache,
            combination: config.beam_combination,
            temperature: 1.0,
        }
    }

    /// Flattens the model: every weight factor `L` becomes `L^(1/temperature)` (`temperature`
    /// ≥ 1; 1 leaves it as is). Sixty beams
    /// multiplied make a likelihood so peaked that, among particles spread over a whole map,
    /// the few near the true pose are rarely near enough to win; a flatter model lets the
    /// neighbourhood of the truth survive until the filter concentrates there.
    #[must_use]
    pub fn with_temperature(mut self, temperature: f64) -> Self {
        self.temperature = temperature;
        self
    }

    /// Number of beams the model casts per particle.
    #[must_use]
    pub fn beam_count(&self) -> usize {
        self.beams.len()
    }

    /// The weight factor of a robot pose in the map frame.
    pub fn likelihood(&mut self, pose: &Pose2D) -> f64 {
        let (gx, gy) = self.field.world_to_grid(pose.x_m, pose.y_m);
        let mut out = [0.0];
        self.likelihoods_in_grid(
            &[[gx, gy, pose.yaw_rad - self.field.origin().yaw_rad]],
            &mut out,
        );
        out[0]
    }

    /// The weight factors of many robot poses given in grid coordinates as `[gx, gy, yaw_rad]`
    /// (yaw relative to the grid), into `out` (same length).
    ///
    /// Beams are the outer loop so that the rays of one beam, shared among the particles,
    /// stay in a cache small enough for L1.
    pub fn likelihoods_in_grid(&mut self, poses: &[[f64; 3]], out: &mut [f64]) {
        if self.terms.is_empty() {
            // A model for agreement only says nothing about the particles.
            out.fill(1.0);
            return;
        }
        #[allow(clippy::cast_precision_loss)]
        let bins_per_rad = DIRECTION_BINS as f64 / TAU;
        let mut lasers = std::mem::take(&mut self.lasers);
        lasers.clear();
        let (width, height) = (self.field.width_cells(), self.field.height_cells());
        lasers.extend(poses.iter().map(|&[gx, gy, yaw]| {
            let (s, c) = yaw.sin_cos();
            let (ox, oy) = self.laser_origin(gx, gy, c, s);
            let heading_bins = (yaw + self.laser_yaw_rad).rem_euclid(TAU) * bins_per_rad;
            let inside = ox >= 0.0 && oy >= 0.0 && ox < f64::from(width) && oy < f64::from(height);
            #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
            let (ix, iy) = (ox as u64, oy as u64);
            #[allow(clippy::cast_precision_loss)]
            let from_centre = [ox - (ix as f64 + 0.5), oy - (iy as f64 + 0.5)];
            Laser {
                ox,
                oy,
                heading_bins,
                cell_key: inside.then(|| (iy * u64::from(width) + ix + 1) << 16),
                from_centre,
            }
        }));
        out.fill(0.0);
        for k in 0..self.beams.len() {
            let beam = self.beams[k];
            // Plus half a bin, so that truncation rounds to the nearest bin.
            let bearing_bins = beam.angle_rad.rem_euclid(TAU) * bins_per_rad + 0.5;
            for (laser, acc) in lasers.iter().zip(out.iter_mut()) {
                #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
                let bin = ((laser.heading_bins + bearing_bins) as usize) & (DIRECTION_BINS - 1);
                let expected = self.expected_cells(laser, bin);
                let miss_cells = (beam.range_cells - expected).abs();
                #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
                let index =
                    ((miss_cells * self.resolution_m * TABLE_PER_M) as usize).min(self.len - 1);
                let row = if beam.range_cells < expected {
                    beam.row
                } else {
                    beam.row + self.len
                };
                *acc += self.terms[row + index];
            }
        }
        self.lasers = lasers;
        for acc in out.iter_mut() {
            *acc = match self.combination {
                BeamCombination::SumOfCubes => (1.0 + *acc).powf(1.0 / self.temperature),
                BeamCombination::Product => (*acc / self.temperature).exp(),
            };
        }
    }

    /// The laser's position in grid coordinates for a robot pose in grid coordinates.
    #[inline]
    fn laser_origin(&self, gx: f64, gy: f64, c: f64, s: f64) -> (f64, f64) {
        (
            gx + c * self.laser_x_cells - s * self.laser_y_cells,
            gy + s * self.laser_x_cells + c * self.laser_y_cells,
        )
    }

    /// The range (cells) the map predicts from `laser` along direction bin `bin` (grid frame),
    /// through the cache.
    #[inline]
    fn expected_cells(&mut self, laser: &Laser, bin: usize) -> f64 {
        let [dx, dy] = self.cache.directions[bin];
        let Some(cell_key) = laser.cell_key else {
            return self.cast(laser.ox, laser.oy, dx, dy);
        };
        let key = cell_key | bin as u64;
        #[allow(clippy::cast_possible_truncation)]
        let slot = (key.wrapping_mul(0x9E37_79B9_7F4A_7C15) >> SLOT_SHIFT) as usize;
        let [fx, fy] = laser.from_centre;
        let from_centre = if self.cache.keys[slot] == key {
            f64::from(self.cache.ranges_cells[slot])
        } else {
            let range = self.cast(laser.ox - fx, laser.oy - fy, dx, dy);
            self.cache.keys[slot] = key;
            #[allow(clippy::cast_possible_truncation)]
            let stored = range as f32;
            self.cache.ranges_cells[slot] = stored;
            f64::from(stored)
        };
        // The particle's laser is ahead of (or behind) the cell's centre along the ray.
        (from_centre - (fx * dx + fy * dy)).max(0.0)
    }

    /// Distance (cells) from `(x, y)` along the unit direction `(dx, dy)` to the first occupied
    /// or unknown cell, or the sensor's maximum range if there is none before it (sphere
    /// tracing).
    ///
    /// The field stores each cell centre's distance to the nearest such cell's centre; from
    /// any point of the cell, no occupied cell's boundary is nearer than that minus `√2` cells,
    /// so a step of that length cannot cross an obstacle. Near walls the step is half a cell,
    /// which may cut the corner of a single occupied cell: a few centimetres of range, far below
    /// the model's σ.
    #[inline]
    fn cast(&self, x: f64, y: f64, dx: f64, dy: f64) -> f64 {
        let limit = self.range_max_cells;
        let mut t = 0.0;
        while t < limit {
            let level = self.field.ray_level_at_grid(x + t * dx, y + t * dy);
            if level == 0 {
                return t;
            }
            let clearance = f64::from(level) * self.cells_per_level;
            t += (clearance - SQRT_2).max(0.5);
        }
        limit
    }

    /// How well the scan agrees with the map from `pose`: of the beams that either match the
    /// range the map predicts (within `tolerance_m`) or contradict it (the reading is longer
    /// than the map allows: the beam went through a mapped wall, or got no return where a wall
    /// is in range), the fraction that match. Shorter readings are left out: furniture and
    /// people stand in front of walls everywhere, but nothing lets a laser see through one.
    /// `None` when no beam matches or contradicts.
    #[must_use]
    pub fn agreement(&self, pose: &Pose2D, tolerance_m: f64) -> Option<f64> {
        let tolerance_cells = tolerance_m / self.resolution_m;
        let (mut matches, mut contradictions) = (0usize, 0usize);
        for k in 0..self.beams.len() {
            let Some(expected_m) = self.expected_range_m(pose, k) else {
                continue;
            };
            let expected = expected_m / self.resolution_m;
            let measured = self.beams[k].range_cells;
            if (measured - expected).abs() <= tolerance_cells {
                matches += 1;
            } else if measured > expected {
                contradictions += 1;
            }
        }
        #[allow(clippy::cast_precision_loss)]
        (matches + contradictions > 0).then(|| matches as f64 / (matches + contradictions) as f64)
    }

    /// The range (m) the map predicts for the `k`-th used beam from a pose, cast exactly from
    /// the pose (no cache), for tests and diagnostics.
    #[must_use]
    pub fn expected_range_m(&self, pose: &Pose2D, k: usize) -> Option<f64> {
        let beam = self.beams.get(k)?;
        let (gx, gy) = self.field.world_to_grid(pose.x_m, pose.y_m);
        let (s, c) = (pose.yaw_rad - self.field.origin().yaw_rad).sin_cos();
        let (ox, oy) = self.laser_origin(gx, gy, c, s);
        let (dy, dx) =
            (pose.yaw_rad - self.field.origin().yaw_rad + self.laser_yaw_rad + beam.angle_rad)
                .sin_cos();
        Some(self.cast(ox, oy, dx, dy) * self.resolution_m)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::amcl::config::LaserModel;
    use map_core::{OccupancyGrid, FREE, OCCUPIED};
    use protocol::Header;

    /// A 10 m × 2 m corridor (5 cm cells) walled all round, its left end at x = 0.
    fn corridor() -> LikelihoodField {
        let mut g = OccupancyGrid::filled(200, 40, 0.05, Pose2D::new(0.0, 0.0, 0.0), FREE).unwrap();
        for x in 0..200 {
            g.set(x, 0, OCCUPIED);
            g.set(x, 39, OCCUPIED);
        }
        for y in 0..40 {
            g.set(0, y, OCCUPIED);
            g.set(199, y, OCCUPIED);
        }
        LikelihoodField::new(&g, 2.0).unwrap()
    }

    fn scan(ranges_m: Vec<f32>) -> LaserScan {
        let n = ranges_m.len();
        LaserScan {
            header: Header::default(),
            angle_min_rad: -std::f32::consts::FRAC_PI_2,
            angle_increment_rad: std::f32::consts::PI / (n - 1) as f32,
            range_min_m: 0.05,
            range_max_m: 8.0,
            ranges_m,
        }
    }

    fn config() -> AmclConfig {
        AmclConfig {
            laser_model: LaserModel::Beam,
            ..AmclConfig::default()
        }
    }

    #[test]
    fn rays_stop_at_the_first_wall_within_a_cell() {
        let field = corridor();
        let s = scan(vec![1.0, 1.0, 1.0]);
        let mut cache = RayCache::default();
        let model = BeamScanModel::new(&field, &config(), &s, &mut cache);
        // From (2, 1) facing +x: the right beam hits the wall at y = 0.05, the left one the wall
        // at y = 1.95.
        let pose = Pose2D::new(2.0, 1.0, 0.0);
        let right = model.expected_range_m(&pose, 0).unwrap();
        assert!((right - 0.95).abs() <= 0.05, "{right}");
        let left = model.expected_range_m(&pose, 2).unwrap();
        assert!((left - 0.95).abs() <= 0.05, "{left}");
        // Ahead, the end wall is 7.95 m away, whatever the reading; from x = 1 it is beyond the
        // sensor's range.
        let ahead = model.expected_range_m(&pose, 1).unwrap();
        assert!((ahead - 7.95).abs() <= 0.05, "{ahead}");
        let ahead = model.expected_range_m(&pose, 1).unwrap();
        assert!((ahead - 7.95).abs() <= 0.05, "{ahead}");
        let ahead = model
            .expected_range_m(&Pose2D::new(1.0, 1.0, 0.0), 1)
            .unwrap();
        assert!((ahead - 8.0).abs() < 1e-9, "{ahead}");
    }

    #[test]
    fn a_no_return_down_the_corridor_pins_the_position_along_it() {
        // The robot at x = 1.5 facing +x sees both side walls and nothing ahead within 8 m; the
        // likelihood field cannot tell x = 1.5 from x = 3 (the side walls look the same), the
        // beam model can: from x = 3 the end wall would be within range.
        let field = corridor();
        let n = 31;
        let truth = Pose2D::new(1.5, 1.0, 0.0);
        let mut cache = RayCache::default();
        let ranges: Vec<f32> = {
            let probe = scan(vec![8.0; n]);
            let probe_model = BeamScanModel::new(&field, &config(), &probe, &mut cache);
            (0..n)
                .map(|k| probe_model.expected_range_m(&truth, k).unwrap() as f32)
                .collect()
        };
        let s = scan(ranges);
        let mut beam = BeamScanModel::new(&field, &config(), &s, &mut cache);
        let at_truth = beam.likelihood(&truth);
        let shifted = beam.likelihood(&Pose2D::new(3.0, 1.0, 0.0));
        assert!(at_truth > shifted * 100.0, "{at_truth} vs {shifted}");
        let lf = crate::amcl::ScanModel::new(&field, &AmclConfig::default(), &s);
        let lf_ratio = lf.likelihood(&truth) / lf.likelihood(&Pose2D::new(3.0, 1.0, 0.0));
        assert!(
            lf_ratio < 1.5,
            "the likelihood field sees no difference: {lf_ratio}"
        );
    }

    #[test]
    fn sum_of_cubes_matches_nav2s_formula_for_one_beam() {
        let field = corridor();
        let cfg = AmclConfig {
            beam_combination: BeamCombination::SumOfCubes,
            max_beams: 2,
            ..config()
        };
        // Two beams, right (-90°) and left (+90°), from (2, 1) facing +x: both walls 0.95 m away.
        let s = scan(vec![0.9, 8.0]);
        let mut cache = RayCache::default();
        let mut model = BeamScanModel::new(&field, &cfg, &s, &mut cache);
        let pose = Pose2D::new(2.0, 1.0, 0.0);
        let right_hat = model.expected_range_m(&pose, 0).unwrap();
        let left_hat = model.expected_range_m(&pose, 1).unwrap();
        let sigma = cfg.sigma_hit_m;
        let hit = |d: f64| cfg.z_hit * (-(d * d) / (2.0 * sigma * sigma)).exp();
        let lambda = cfg.lambda_short_per_m;
        let p_right =
            hit(0.9 - right_hat) + cfg.z_short * lambda * (-lambda * 0.9).exp() + cfg.z_rand / 8.0;
        let p_left = hit(8.0 - left_hat) + cfg.z_max;
        let want = 1.0 + p_right.powi(3) + p_left.powi(3);
        let got = model.likelihood(&pose);
        assert!((got - want).abs() < 0.03 * want, "{got} vs {want}");
    }
}
