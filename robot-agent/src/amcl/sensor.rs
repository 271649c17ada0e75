//! Likelihood-field laser model (Thrun et al., Table 6.3; Nav2's `likelihood_field`).
//!
//! A beam's endpoint is projected into the map, and its likelihood is
//! `p = z_hit · exp(-d² / (2σ²)) + z_rand / range_max`, where `d` is the endpoint's distance to
//! the nearest occupied cell (clamped at `laser_likelihood_max_dist_m`). Beams without a return
//! (range ≥ `range_max_m`, below `range_min_m`, or not finite) are skipped, like Nav2 skips
//! max-range readings. Per scan, the used beams' endpoints are precomputed in the robot frame
//! and `p` (or `p³`) is tabulated over the field's 256 quantization levels, so weighing a
//! particle costs one rotation, one table lookup per beam and no transcendental function.

use protocol::{LaserScan, Pose2D};

use super::config::{AmclConfig, BeamCombination};
use super::field::{LikelihoodField, FIELD_LEVELS};

const LUT_LEN: usize = FIELD_LEVELS as usize + 1;

/// The laser model prepared for one scan on one field.
#[derive(Debug, Clone)]
pub struct ScanModel<'a> {
    field: &'a LikelihoodField,
    /// Used beam endpoints in the robot frame, in grid cells (divided by the resolution).
    endpoints_cells: Vec<[f64; 2]>,
    /// Per quantized distance: `p³` (sum of cubes) or `ln p` (product).
    table: [f64; LUT_LEN],
    combination: BeamCombination,
}

/// Indices of `max_beams` beams spread evenly over `n` (all of them if `n <= max_beams`).
pub(crate) fn beam_indices(n: usize, max_beams: usize) -> impl Iterator<Item = usize> {
    let used = n.min(max_beams);
    (0..used).map(move |k| {
        if used <= 1 {
            0
        } else {
            // Integer arithmetic: the first and last beams are always used.
            (k * (n - 1) + (used - 1) / 2) / (used - 1)
        }
    })
}

/// The per-beam likelihood `z_hit · exp(-d²/(2σ²)) + z_rand / range_max`.
#[must_use]
pub fn beam_likelihood(config: &AmclConfig, distance_m: f64, range_max_m: f64) -> f64 {
    let s = config.sigma_hit_m;
    config.z_hit * (-(distance_m * distance_m) / (2.0 * s * s)).exp() + config.z_rand / range_max_m
}

impl<'a> ScanModel<'a> {
    /// Prepares the model for `scan`, using at most `config.max_beams` beams.
    #[must_use]
    pub fn new(field: &'a LikelihoodField, config: &AmclConfig, scan: &LaserScan) -> Self {
        let range_max_m = f64::from(scan.range_max_m);
        let mut table = [0.0; LUT_LEN];
        for (level, entry) in table.iter_mut().enumerate() {
            #[allow(clippy::cast_precision_loss)]
            let d = level as f64 * field.level_m();
            let p = beam_likelihood(config, d, range_max_m);
            *entry = match config.beam_combination {
                BeamCombination::SumOfCubes => p * p * p,
                BeamCombination::Product => p.ln(),
            };
        }
        let laser = config.robot_from_laser;
        let (ls, lc) = laser.yaw_rad.sin_cos();
        let inv_res = 1.0 / field.resolution_m();
        let endpoints_cells = beam_indices(scan.ranges_m.len(), config.max_beams)
            .filter(|&i| scan.is_return(i))
            .map(|i| {
                let r = f64::from(scan.ranges_m[i]);
                let (s, c) = f64::from(scan.beam_angle_rad(i)).sin_cos();
                let (lx, ly) = (r * c, r * s);
                [
                    (laser.x_m + lc * lx - ls * ly) * inv_res,
                    (laser.y_m + ls * lx + lc * ly) * inv_res,
                ]
            })
            .collect();
        Self {
            field,
            endpoints_cells,
            table,
            combination: config.beam_combination,
        }
    }

    /// Number of beams the model evaluates per particle (returns among the subsample).
    #[must_use]
    pub fn beam_count(&self) -> usize {
        self.endpoints_cells.len()
    }

    /// The weight factor of a robot pose in the map frame.
    #[must_use]
    pub fn likelihood(&self, pose: &Pose2D) -> f64 {
        let (gx, gy) = self.field.world_to_grid(pose.x_m, pose.y_m);
        let (s, c) = (pose.yaw_rad - self.field.origin().yaw_rad).sin_cos();
        self.likelihood_in_grid(gx, gy, c, s)
    }

    /// As [`Self::likelihood`] with the pose already in grid coordinates and its heading's
    /// cosine and sine.
    #[inline]
    #[must_use]
    pub fn likelihood_in_grid(&self, gx: f64, gy: f64, c: f64, s: f64) -> f64 {
        let mut acc = 0.0;
        for &[bx, by] in &self.endpoints_cells {
            let ex = gx + c * bx - s * by;
            let ey = gy + s * bx + c * by;
            acc += self.table[usize::from(self.field.level_at_grid(ex, ey))];
        }
        self.finish(acc)
    }

    /// The quantized field level at every beam endpoint of a pose in grid coordinates; `out`
    /// must hold [`Self::beam_count`] entries.
    #[inline]
    pub fn levels_in_grid(&self, gx: f64, gy: f64, c: f64, s: f64, out: &mut [u8]) {
        for (&[bx, by], level) in self.endpoints_cells.iter().zip(out.iter_mut()) {
            *level = self
                .field
                .level_at_grid(gx + c * bx - s * by, gy + s * bx + c * by);
        }
    }

    /// The weight factor from per-beam levels, using only the beams marked in `keep`.
    ///
    /// A skipped beam counts as a beam at the clamp distance: the same factor for every
    /// particle, so the ranking of particles is as if the beam were left out, while the
    /// average likelihood that recovery watches stays comparable between scans that skip
    /// different numbers of beams (a kidnapped robot's scan must still look unlikely).
    #[inline]
    #[must_use]
    pub fn likelihood_of_levels(&self, levels: &[u8], keep: &[bool]) -> f64 {
        let far = self.table[usize::from(FIELD_LEVELS)];
        let acc: f64 = levels
            .iter()
            .zip(keep)
            .map(|(&level, &k)| {
                if k {
                    self.table[usize::from(level)]
                } else {
                    far
                }
            })
            .sum();
        self.finish(acc)
    }

    #[inline]
    fn finish(&self, acc: f64) -> f64 {
        match self.combination {
            BeamCombination::SumOfCubes => 1.0 + acc,
            BeamCombination::Product => acc.exp(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn beam_subsample_is_even_and_keeps_both_ends() {
        let v: Vec<usize> = beam_indices(181, 60).collect();
        assert_eq!(v.len(), 60);
        assert_eq!(v[0], 0);
        assert_eq!(v[59], 180);
        assert!(v.windows(2).all(|w| w[1] > w[0] && w[1] - w[0] <= 4));
        assert_eq!(
            beam_indices(10, 60).collect::<Vec<_>>(),
            (0..10).collect::<Vec<_>>()
        );
        assert_eq!(beam_indices(0, 60).count(), 0);
    }
}
