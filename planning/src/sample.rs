//! Seeded random poses on a planning map: start/goal pairs for benchmarks, tests and
//! recordings, and points along a planned path.

use protocol::Pose2D;
use rand::{Rng, SeedableRng};

use crate::map::PlanningMap;

/// The map has no room for the requested pairs.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("map {map} has fewer than two free cells {min_m} m apart")]
pub struct NoPairs {
    pub map: String,
    pub min_m: f64,
}

fn sample_pose(map: &PlanningMap, rng: &mut impl Rng) -> Option<Pose2D> {
    let grid = map.grid();
    let free = map.free_mask();
    for _ in 0..100_000 {
        let cx = rng.gen_range(0..grid.width_cells());
        let cy = rng.gen_range(0..grid.height_cells());
        if free[grid.index(cx, cy)] {
            let (x, y) = grid.cell_to_world(i64::from(cx), i64::from(cy));
            let yaw = rng.gen_range(-std::f64::consts::PI..std::f64::consts::PI);
            return Some(Pose2D::new(x, y, yaw));
        }
    }
    None
}

/// Seeded random start/goal pairs in inflated free space, at least `min_m` apart.
///
/// # Errors
/// [`NoPairs`] if the map has no room for them.
pub fn sample_pairs(
    map: &PlanningMap,
    n: usize,
    seed: u64,
    min_m: f64,
    name: &str,
) -> Result<Vec<(Pose2D, Pose2D)>, NoPairs> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let none = || NoPairs {
        map: name.to_string(),
        min_m,
    };
    let mut out = Vec::with_capacity(n);
    let mut starts_left = n.saturating_mul(100).max(1000);
    while out.len() < n {
        // A start with no goal far enough away is replaced by another start.
        starts_left = starts_left.checked_sub(1).ok_or_else(none)?;
        let s = sample_pose(map, &mut rng).ok_or_else(none)?;
        for _ in 0..200 {
            let g = sample_pose(map, &mut rng).ok_or_else(none)?;
            if g.distance_m(&s) >= min_m {
                out.push((s, g));
                break;
            }
        }
    }
    Ok(out)
}

/// The pose `offset_m` of driven length along `poses` (the last pose if shorter).
#[must_use]
pub fn pose_along(poses: &[Pose2D], offset_m: f64) -> Option<Pose2D> {
    let mut acc = 0.0;
    for w in poses.windows(2) {
        acc += w[0].distance_m(&w[1]);
        if acc >= offset_m {
            return Some(w[1]);
        }
    }
    poses.last().copied()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pose_along_walks_the_path() {
        let poses: Vec<Pose2D> = (0..10)
            .map(|i| Pose2D::new(f64::from(i) * 0.1, 0.0, 0.0))
            .collect();
        let p = pose_along(&poses, 0.5).unwrap();
        assert!((p.x_m - 0.5).abs() < 1e-9);
        assert!((pose_along(&poses, 5.0).unwrap().x_m - 0.9).abs() < 1e-9);
    }
}
