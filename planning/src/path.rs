//! The planner's output.

use protocol::Pose2D;
use serde::Serialize;

/// A planned path in the map frame with how it was found.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Path {
    /// Poses from the start to the goal, about `path_spacing_m` apart (turns in place add
    /// poses at one position).
    pub poses: Vec<Pose2D>,
    /// Driven length (turns in place count zero).
    pub length_m: f64,
    /// Hybrid A* nodes expanded.
    pub states_expanded: u64,
    /// Wall-clock planning time.
    pub plan_time_us: u64,
    /// Statistics of the search.
    pub stats: PathStats,
}

/// Details of one plan, for benchmarks and logs.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct PathStats {
    /// The obstacle heuristic for this goal came from the cache.
    pub heuristic_cache_hit: bool,
    /// Coarse cells the obstacle heuristic had closed after this plan (all queries so far).
    pub heuristic_cells_settled: u64,
    /// The search ended with an analytic (Dubins) shot rather than a lattice node.
    pub analytic_expansion: bool,
    /// Length before smoothing.
    pub raw_length_m: f64,
}

/// Driven length of a pose sequence.
#[must_use]
pub fn length_of(poses: &[Pose2D]) -> f64 {
    poses.windows(2).map(|w| w[0].distance_m(&w[1])).sum()
}

/// The point `d_m` of driven length along `poses`, between its poses, facing along the segment
/// it lies on; the last pose past the end; `None` when empty.
#[must_use]
pub fn point_along(poses: &[Pose2D], d_m: f64) -> Option<Pose2D> {
    let mut left = d_m;
    for w in poses.windows(2) {
        let seg = w[0].distance_m(&w[1]);
        if seg > 1e-9 && left <= seg {
            let t = left / seg;
            return Some(Pose2D::new(
                w[0].x_m + t * (w[1].x_m - w[0].x_m),
                w[0].y_m + t * (w[1].y_m - w[0].y_m),
                (w[1].y_m - w[0].y_m).atan2(w[1].x_m - w[0].x_m),
            ));
        }
        left -= seg;
    }
    poses.last().copied()
}

/// Index of the pose of `path` nearest to `robot` (the first of equals); `None` when empty.
#[must_use]
pub fn nearest_index(path: &[Pose2D], robot: Pose2D) -> Option<usize> {
    let mut best: Option<(usize, f64)> = None;
    for (i, p) in path.iter().enumerate() {
        let d = robot.distance_sq_m2(p);
        if best.is_none_or(|(_, b)| d < b) {
            best = Some((i, d));
        }
    }
    best.map(|(i, _)| i)
}
