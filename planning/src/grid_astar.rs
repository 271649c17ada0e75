//! Plain 8-connected 2-D A* on the inflated map: the benchmark's reference and its
//! "reachable" oracle.
//!
//! Diagonal moves may not cut a blocked corner. Buffers are reused between queries with a
//! generation counter, so a query never clears the 4 M-cell arrays of a large map.

use std::collections::BinaryHeap;

use protocol::Pose2D;

use crate::heuristic::MinKey;
use crate::map::PlanningMap;

/// A 2-D A* result.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GridPath {
    /// Length of the 8-connected cell path (cell centres) in metres.
    pub length_m: f64,
    /// Cells expanded.
    pub expanded: u64,
}

/// Reusable 2-D A* buffers for one map size.
#[derive(Debug, Default)]
pub struct GridAstar {
    g: Vec<f32>,
    seen_gen: Vec<u32>,
    closed_gen: Vec<u32>,
    generation: u32,
    open: BinaryHeap<MinKey>,
}

impl GridAstar {
    #[must_use]
    pub fn new() -> Self {
        Self::default()
    }

    /// Shortest 8-connected path between the cells of two map-frame poses, or `None` when
    /// either is off the map or blocked, or no path exists.
    pub fn plan(&mut self, map: &PlanningMap, start: Pose2D, goal: Pose2D) -> Option<GridPath> {
        let grid = map.grid();
        let (w, h) = (grid.width_cells() as usize, grid.height_cells() as usize);
        let n = w * h;
        if self.g.len() != n {
            self.g = vec![f32::INFINITY; n];
            self.seen_gen = vec![0; n];
            self.closed_gen = vec![0; n];
            self.generation = 0;
        }
        self.generation = self.generation.wrapping_add(1);
        if self.generation == 0 {
            self.seen_gen.fill(0);
            self.closed_gen.fill(0);
            self.generation = 1;
        }
        let gen = self.generation;
        let free = map.free_mask();
        let s = map.to_grid(start);
        let t = map.to_grid(goal);
        let (sx, sy) = map.cell_of(s.x_m, s.y_m);
        let (tx, ty) = map.cell_of(t.x_m, t.y_m);
        if !grid.contains(sx, sy) || !grid.contains(tx, ty) {
            return None;
        }
        #[allow(clippy::cast_sign_loss, clippy::cast_possible_truncation)]
        let (sx, sy, tx, ty) = (sx as usize, sy as usize, tx as usize, ty as usize);
        let si = sy * w + sx;
        let ti = ty * w + tx;
        if !free[si] || !free[ti] {
            return None;
        }
        let octile = |i: usize| -> f32 {
            let (x, y) = (i % w, i / w);
            let dx = x.abs_diff(tx);
            let dy = y.abs_diff(ty);
            let (lo, hi) = if dx < dy { (dx, dy) } else { (dy, dx) };
            #[allow(clippy::cast_precision_loss)]
            let v = (hi - lo) as f32 + std::f32::consts::SQRT_2 * lo as f32;
            v
        };
        self.open.clear();
        self.g[si] = 0.0;
        self.seen_gen[si] = gen;
        #[allow(clippy::cast_possible_truncation)]
        self.open.push(MinKey::new(octile(si), si as u32));
        let mut expanded = 0u64;
        let diag = std::f32::consts::SQRT_2;
        while let Some(top) = self.open.pop() {
            let i = top.idx() as usize;
            if self.closed_gen[i] == gen {
                continue;
            }
            self.closed_gen[i] = gen;
            expanded += 1;
            if i == ti {
                return Some(GridPath {
                    length_m: f64::from(self.g[i]) * grid.resolution_m(),
                    expanded,
                });
            }
            let (x, y) = (i % w, i / w);
            let gi = self.g[i];
            let left = x > 0 && free[i - 1];
            let right = x + 1 < w && free[i + 1];
            let down = y > 0 && free[i - w];
            let up = y + 1 < h && free[i + w];
            let relax = |j: usize, cost: f32, this: &mut Self| {
                if this.closed_gen[j] == gen {
                    return;
                }
                let ng = gi + cost;
                if this.seen_gen[j] != gen || ng < this.g[j] {
                    this.seen_gen[j] = gen;
                    this.g[j] = ng;
                    #[allow(clippy::cast_possible_truncation)]
                    this.open.push(MinKey::new(ng + octile(j), j as u32));
                }
            };
            if left {
                relax(i - 1, 1.0, self);
            }
            if right {
                relax(i + 1, 1.0, self);
            }
            if down {
                relax(i - w, 1.0, self);
            }
            if up {
                relax(i + w, 1.0, self);
            }
            if left && down && free[i - w - 1] {
                relax(i - w - 1, diag, self);
            }
            if right && down && free[i - w + 1] {
                relax(i - w + 1, diag, self);
            }
            if left && up && free[i + w - 1] {
                relax(i + w - 1, diag, self);
            }
            if right && up && free[i + w + 1] {
                relax(i + w + 1, diag, self);
            }
        }
        None
    }
}
