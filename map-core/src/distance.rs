//! Exact Euclidean distance field and inflation by a robot radius.
//!
//! The field holds, for every cell, the distance in metres from its centre to the centre of the
//! nearest obstacle cell (Felzenszwalb & Huttenlocher 2012: two separable passes of the exact 1-D
//! squared-distance transform, O(cells)). The planner checks collisions against it, AMCL's
//! likelihood field reads it, and inflation is a threshold on it, so it is computed once per
//! map version and shared.

use crate::grid::{classify, CellClass, OccupancyGrid};

/// Distance from every cell to the nearest obstacle, in metres.
#[derive(Debug, Clone, PartialEq)]
pub struct DistanceField {
    width_cells: u32,
    height_cells: u32,
    resolution_m: f64,
    /// Row-major like the grid; `f32::INFINITY` when the map has no obstacle at all.
    distance_m: Vec<f32>,
}

/// Which cells are sources (distance zero) of a distance field.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Sources {
    /// Occupied cells only: what a laser sees (AMCL's likelihood field).
    Occupied,
    /// Occupied and unknown cells: what a planner must keep clear of.
    OccupiedOrUnknown,
}

impl DistanceField {
    /// Computes the exact field of `grid` for the chosen sources.
    #[must_use]
    pub fn compute(grid: &OccupancyGrid, sources: Sources) -> Self {
        let w = grid.width_cells() as usize;
        let h = grid.height_cells() as usize;
        let is_source = |v: u8| match (classify(v), sources) {
            (CellClass::Occupied, _) | (CellClass::Unknown, Sources::OccupiedOrUnknown) => true,
            (CellClass::Free, _) | (CellClass::Unknown, Sources::Occupied) => false,
        };
        // Squared distances in cells; "infinite" is a large finite value so the parabola
        // arithmetic stays finite.
        let inf = 1e20_f64;
        let mut sq: Vec<f64> = grid
            .cells()
            .iter()
            .map(|&v| if is_source(v) { 0.0 } else { inf })
            .collect();

        let n = w.max(h);
        let mut f = vec![0.0; n];
        let mut d = vec![0.0; n];
        let mut v = vec![0usize; n];
        let mut z = vec![0.0; n + 1];

        // Columns first, then rows: each pass is the exact 1-D transform.
        for x in 0..w {
            for y in 0..h {
                f[y] = sq[y * w + x];
            }
            edt_1d(&f[..h], &mut d[..h], &mut v, &mut z);
            for y in 0..h {
                sq[y * w + x] = d[y];
            }
        }
        for y in 0..h {
            let row = &mut sq[y * w..(y + 1) * w];
            f[..w].copy_from_slice(row);
            edt_1d(&f[..w], &mut d[..w], &mut v, &mut z);
            row.copy_from_slice(&d[..w]);
        }

        let res = grid.resolution_m();
        #[allow(clippy::cast_possible_truncation)]
        let distance_m = sq
            .into_iter()
            .map(|s| {
                if s >= inf * 0.5 {
                    f32::INFINITY
                } else {
                    (s.sqrt() * res) as f32
                }
            })
            .collect();
        Self {
            width_cells: grid.width_cells(),
            height_cells: grid.height_cells(),
            resolution_m: res,
            distance_m,
        }
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

    /// Row-major distances in metres, row 0 at the bottom.
    #[must_use]
    pub fn as_slice(&self) -> &[f32] {
        &self.distance_m
    }

    /// Distance at cell (cx, cy); `0.0` off the grid, because off the map is never safe.
    #[inline]
    #[must_use]
    pub fn at(&self, cx: i64, cy: i64) -> f32 {
        if cx < 0
            || cy < 0
            || cx >= i64::from(self.width_cells)
            || cy >= i64::from(self.height_cells)
        {
            return 0.0;
        }
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        self.distance_m[cy as usize * self.width_cells as usize + cx as usize]
    }

    /// Cells whose centre lies closer than `radius_m` to an obstacle: the map inflated by the
    /// robot radius. `true` means blocked.
    #[must_use]
    pub fn inflate(&self, radius_m: f64) -> Vec<bool> {
        #[allow(clippy::cast_possible_truncation)]
        let r = radius_m as f32;
        self.distance_m.iter().map(|&d| d < r).collect()
    }
}

/// Exact 1-D squared Euclidean distance transform of `f` into `d` (lower envelope of
/// parabolas). `v` and `z` are scratch buffers of at least `f.len()` and `f.len() + 1`.
fn edt_1d(f: &[f64], d: &mut [f64], v: &mut [usize], z: &mut [f64]) {
    let n = f.len();
    if n == 0 {
        return;
    }
    let mut k = 0usize;
    v[0] = 0;
    z[0] = f64::NEG_INFINITY;
    z[1] = f64::INFINITY;
    #[allow(clippy::cast_precision_loss)]
    for q in 1..n {
        let qf = q as f64;
        loop {
            let p = v[k];
            let pf = p as f64;
            let s = ((f[q] + qf * qf) - (f[p] + pf * pf)) / (2.0 * qf - 2.0 * pf);
            if s <= z[k] {
                if k == 0 {
                    // The new parabola dominates everything so far.
                    v[0] = q;
                    z[0] = f64::NEG_INFINITY;
                    z[1] = f64::INFINITY;
                    break;
                }
                k -= 1;
            } else {
                k += 1;
                v[k] = q;
                z[k] = s;
                z[k + 1] = f64::INFINITY;
                break;
            }
        }
    }
    k = 0;
    #[allow(clippy::cast_precision_loss)]
    for (q, out) in d.iter_mut().enumerate().take(n) {
        let qf = q as f64;
        while z[k + 1] < qf {
            k += 1;
        }
        let p = v[k];
        let dq = qf - p as f64;
        *out = dq * dq + f[p];
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::{FREE, OCCUPIED, UNKNOWN};
    use protocol::Pose2D;
    use rand::{Rng, SeedableRng};

    fn brute_force(grid: &OccupancyGrid, sources: Sources) -> Vec<f32> {
        let w = i64::from(grid.width_cells());
        let h = i64::from(grid.height_cells());
        let src: Vec<(i64, i64)> = (0..h)
            .flat_map(|y| (0..w).map(move |x| (x, y)))
            .filter(|&(x, y)| {
                let c = grid.class_at(x, y);
                c == CellClass::Occupied
                    || (c == CellClass::Unknown && sources == Sources::OccupiedOrUnknown)
            })
            .collect();
        (0..h)
            .flat_map(|y| (0..w).map(move |x| (x, y)))
            .map(|(x, y)| {
                src.iter()
                    .map(|&(sx, sy)| (((sx - x).pow(2) + (sy - y).pow(2)) as f64).sqrt())
                    .fold(f64::INFINITY, f64::min) as f32
                    * grid.resolution_m() as f32
            })
            .collect()
    }

    #[test]
    fn matches_brute_force_on_random_grids() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        for trial in 0..20 {
            let w = rng.gen_range(1..40);
            let h = rng.gen_range(1..40);
            let cells: Vec<u8> = (0..w * h)
                .map(|_| match rng.gen_range(0..20) {
                    0 => OCCUPIED,
                    1 => UNKNOWN,
                    _ => FREE,
                })
                .collect();
            let g = OccupancyGrid::new(w, h, 0.05, Pose2D::new(0.0, 0.0, 0.0), cells).unwrap();
            for sources in [Sources::Occupied, Sources::OccupiedOrUnknown] {
                let df = DistanceField::compute(&g, sources);
                let bf = brute_force(&g, sources);
                for (i, (a, b)) in df.as_slice().iter().zip(&bf).enumerate() {
                    assert!(
                        (a.is_infinite() && b.is_infinite()) || (a - b).abs() < 1e-4,
                        "trial {trial} cell {i}: {a} vs {b}"
                    );
                }
            }
        }
    }

    #[test]
    fn inflation_blocks_cells_within_radius() {
        let mut g = OccupancyGrid::filled(21, 21, 0.1, Pose2D::new(0.0, 0.0, 0.0), FREE).unwrap();
        g.set(10, 10, OCCUPIED);
        let df = DistanceField::compute(&g, Sources::Occupied);
        let blocked = df.inflate(0.25);
        assert!(blocked[g.index(10, 12)]); // 0.2 m away
        assert!(!blocked[g.index(10, 13)]); // 0.3 m away
        assert!(blocked[g.index(11, 11)]); // 0.141 m
        assert!(!blocked[g.index(12, 12)]); // 0.283 m
        assert_eq!(df.at(-1, 0), 0.0);
    }
}
