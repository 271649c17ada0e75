//! The obstacle-aware half of the hybrid A* heuristic: 2-D shortest distances to the goal.
//!
//! A full Dijkstra over a 2000 x 2000 map costs tens of milliseconds per goal, more than a whole
//! plan may take. Instead each goal gets a *reverse resumable A\** (Silver 2005) on a coarse
//! grid (the map downsampled by `heuristic_downsample`, a coarse cell free when any of its map
//! cells is free in the inflated map): a backward 8-connected A\* from the goal towards the first
//! start that asked, with the octile distance to that start as its (consistent) heuristic. Every
//! cell it closes has its exact coarse distance to the goal. A query for a cell that is not
//! closed yet resumes the same search until that cell closes, so later queries (the hybrid
//! search's neighbours, a replan from a moved start, another robot with the same goal) cost
//! nothing or a few more expansions. The search state lives as long as the cache keeps it.
//!
//! Admissibility: the coarse "any free" rule can only shorten routes; 8-connected distances
//! overestimate straight ones by at most 8 %, partly offset by subtracting one coarse-cell
//! diagonal (both ends may lie anywhere in their cells). So it is admissible up to that 8 %,
//! which acts like a mild heuristic weight.

use std::cmp::Ordering;
use std::collections::BinaryHeap;

/// The downsampled free/blocked grid the obstacle heuristic searches.
#[derive(Debug, Clone)]
pub struct CoarseGrid {
    pub(crate) factor: u32,
    pub(crate) width: u32,
    pub(crate) height: u32,
    pub(crate) cell_m: f64,
    pub(crate) free: Vec<bool>,
}

impl CoarseGrid {
    /// Downsamples a fine free mask (`true` = free) of `width` x `height` cells by `factor`.
    #[must_use]
    pub fn from_fine(fine_free: &[bool], width: u32, height: u32, res_m: f64, factor: u32) -> Self {
        let factor = factor.max(1);
        let cw = width.div_ceil(factor);
        let ch = height.div_ceil(factor);
        let mut free = vec![false; cw as usize * ch as usize];
        for y in 0..height as usize {
            let cy = y / factor as usize;
            let row = &fine_free[y * width as usize..(y + 1) * width as usize];
            for (x, &f) in row.iter().enumerate() {
                if f {
                    free[cy * cw as usize + x / factor as usize] = true;
                }
            }
        }
        Self {
            factor,
            width: cw,
            height: ch,
            cell_m: res_m * f64::from(factor),
            free,
        }
    }

    /// Coarse cell of a fine cell.
    #[inline]
    #[must_use]
    pub fn cell_of(&self, fine_x: u32, fine_y: u32) -> (u32, u32) {
        (fine_x / self.factor, fine_y / self.factor)
    }
}

/// Min-heap entry keyed on a non-negative `f32` (its bit pattern orders like the float),
/// ties broken by index so searches are deterministic.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct MinKey {
    f_bits: u32,
    idx: u32,
}

impl MinKey {
    pub(crate) fn new(f: f32, idx: u32) -> Self {
        Self {
            f_bits: f.max(0.0).to_bits(),
            idx,
        }
    }
    #[cfg(test)]
    pub(crate) fn f(self) -> f32 {
        f32::from_bits(self.f_bits)
    }
    pub(crate) fn idx(self) -> u32 {
        self.idx
    }
}

impl Ord for MinKey {
    fn cmp(&self, other: &Self) -> Ordering {
        other
            .f_bits
            .cmp(&self.f_bits)
            .then_with(|| other.idx.cmp(&self.idx))
    }
}
impl PartialOrd for MinKey {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

/// Distances to one goal on the coarse grid, computed lazily (see the module docs).
#[derive(Debug)]
pub struct ObstacleHeuristic {
    goal: (u32, u32),
    target: (u32, u32),
    g: Vec<f32>,
    closed: Vec<bool>,
    open: BinaryHeap<MinKey>,
    settled: u64,
}

/// The 8-connected moves of the coarse grid and their lengths in cells.
pub(crate) const NEIGHBOURS: [(i32, i32, f32); 8] = [
    (1, 0, 1.0),
    (-1, 0, 1.0),
    (0, 1, 1.0),
    (0, -1, 1.0),
    (1, 1, std::f32::consts::SQRT_2),
    (1, -1, std::f32::consts::SQRT_2),
    (-1, 1, std::f32::consts::SQRT_2),
    (-1, -1, std::f32::consts::SQRT_2),
];

impl ObstacleHeuristic {
    /// Starts a reverse search from coarse cell `goal` directed at coarse cell `target`.
    #[must_use]
    pub fn new(grid: &CoarseGrid, goal: (u32, u32), target: (u32, u32)) -> Self {
        let n = grid.width as usize * grid.height as usize;
        let mut h = Self {
            goal,
            target,
            g: vec![f32::INFINITY; n],
            closed: vec![false; n],
            open: BinaryHeap::new(),
            settled: 0,
        };
        let gi = goal.1 as usize * grid.width as usize + goal.0 as usize;
        if grid.free.get(gi).copied().unwrap_or(false) {
            h.g[gi] = 0.0;
            let f = h.octile(goal);
            #[allow(clippy::cast_possible_truncation)]
            h.open.push(MinKey::new(f, gi as u32));
        }
        h
    }

    /// The goal cell this heuristic measures distances to.
    #[must_use]
    pub fn goal(&self) -> (u32, u32) {
        self.goal
    }

    /// Coarse cells closed so far (the work done, summed over all queries).
    #[must_use]
    pub fn settled(&self) -> u64 {
        self.settled
    }

    fn octile(&self, c: (u32, u32)) -> f32 {
        let dx = c.0.abs_diff(self.target.0);
        let dy = c.1.abs_diff(self.target.1);
        let (lo, hi) = if dx < dy { (dx, dy) } else { (dy, dx) };
        #[allow(clippy::cast_precision_loss)]
        let v = (hi - lo) as f32 + std::f32::consts::SQRT_2 * lo as f32;
        v
    }

    /// Coarse 8-connected distance in coarse cells from `cell` to the goal, or infinity when
    /// no route exists. Resumes the search until `cell` is closed.
    pub fn distance_cells(&mut self, grid: &CoarseGrid, cell: (u32, u32)) -> f32 {
        let w = grid.width as usize;
        let qi = cell.1 as usize * w + cell.0 as usize;
        if qi >= self.closed.len() {
            return f32::INFINITY;
        }
        if self.closed[qi] {
            return self.g[qi];
        }
        if !grid.free[qi] {
            return f32::INFINITY;
        }
        while let Some(top) = self.open.pop() {
            let i = top.idx() as usize;
            if self.closed[i] {
                continue;
            }
            self.closed[i] = true;
            self.settled += 1;
            let gi = self.g[i];
            #[allow(clippy::cast_possible_truncation)]
            let (x, y) = ((i % w) as i32, (i / w) as i32);
            #[allow(clippy::cast_possible_wrap)]
            let (gw, gh) = (grid.width as i32, grid.height as i32);
            for (dx, dy, cost) in NEIGHBOURS {
                let (nx, ny) = (x + dx, y + dy);
                if nx < 0 || ny < 0 || nx >= gw || ny >= gh {
                    continue;
                }
                #[allow(clippy::cast_sign_loss)]
                let ni = ny as usize * w + nx as usize;
                if self.closed[ni] || !grid.free[ni] {
                    continue;
                }
                let ng = gi + cost;
                if ng < self.g[ni] {
                    self.g[ni] = ng;
                    #[allow(clippy::cast_sign_loss)]
                    let f = ng + self.octile((nx as u32, ny as u32));
                    #[allow(clippy::cast_possible_truncation)]
                    self.open.push(MinKey::new(f, ni as u32));
                }
            }
            if i == qi {
                return gi;
            }
        }
        f32::INFINITY
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Plain Dijkstra for comparison.
    fn dijkstra(grid: &CoarseGrid, goal: (u32, u32)) -> Vec<f32> {
        let w = grid.width as usize;
        let mut g = vec![f32::INFINITY; grid.free.len()];
        let mut heap = BinaryHeap::new();
        let gi = goal.1 as usize * w + goal.0 as usize;
        g[gi] = 0.0;
        heap.push(MinKey::new(0.0, gi as u32));
        while let Some(top) = heap.pop() {
            let i = top.idx() as usize;
            if top.f() > g[i] {
                continue;
            }
            let (x, y) = ((i % w) as i32, (i / w) as i32);
            for (dx, dy, c) in NEIGHBOURS {
                let (nx, ny) = (x + dx, y + dy);
                if nx < 0 || ny < 0 || nx >= grid.width as i32 || ny >= grid.height as i32 {
                    continue;
                }
                let ni = ny as usize * w + nx as usize;
                if grid.free[ni] && g[i] + c < g[ni] {
                    g[ni] = g[i] + c;
                    heap.push(MinKey::new(g[ni], ni as u32));
                }
            }
        }
        g
    }

    #[test]
    fn lazy_queries_match_dijkstra() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        let (w, h) = (40u32, 30u32);
        let fine: Vec<bool> = (0..w * h).map(|_| rng.gen_range(0..10) > 2).collect();
        let grid = CoarseGrid::from_fine(&fine, w, h, 0.05, 1);
        let goal = (0..grid.free.len()).find(|&i| grid.free[i]).unwrap();
        let goal = ((goal % 40) as u32, (goal / 40) as u32);
        let reference = dijkstra(&grid, goal);
        let mut lazy = ObstacleHeuristic::new(&grid, goal, (39, 29));
        for _ in 0..300 {
            let c = (rng.gen_range(0..w), rng.gen_range(0..h));
            let got = lazy.distance_cells(&grid, c);
            let want = reference[c.1 as usize * 40 + c.0 as usize];
            assert!(
                (got.is_infinite() && want.is_infinite()) || (got - want).abs() < 1e-3,
                "{c:?}: {got} vs {want}"
            );
        }
    }

    #[test]
    fn downsampling_keeps_any_free_cell() {
        let fine = vec![false, true, false, false, false, false, false, false, false];
        let g = CoarseGrid::from_fine(&fine, 3, 3, 0.05, 2);
        assert_eq!((g.width, g.height), (2, 2));
        assert_eq!(g.free, vec![true, false, false, false]);
        assert!((g.cell_m - 0.1).abs() < 1e-12);
    }
}
