//! What the grid searches around the maps share (the judge's and the dynamic window's
//! Dijkstra, the expert's A*): the 8-neighbourhood and a priority-queue entry ordered for a
//! min-first pop.

use std::cmp::Ordering;

/// The 8-connected neighbourhood of a grid cell as (dx, dy) offsets: the four sides first, then
/// the diagonals.
pub const NEIGHBOURS_8: [(i64, i64); 8] = [
    (1, 0),
    (-1, 0),
    (0, 1),
    (0, -1),
    (1, 1),
    (1, -1),
    (-1, 1),
    (-1, -1),
];

/// A cost that can be totally ordered (floats by `total_cmp`, so NaN cannot break a heap).
pub trait Cost: Copy + PartialEq {
    fn total_order(&self, other: &Self) -> Ordering;
}

impl Cost for f32 {
    fn total_order(&self, other: &Self) -> Ordering {
        self.total_cmp(other)
    }
}

impl Cost for f64 {
    fn total_order(&self, other: &Self) -> Ordering {
        self.total_cmp(other)
    }
}

/// An entry of `std::collections::BinaryHeap` (a max-heap) that pops the lowest cost first;
/// equal costs pop the lowest item first, so a search is deterministic.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MinCost<C, T>(pub C, pub T);

impl<C: Cost, T: Ord> Eq for MinCost<C, T> {}

impl<C: Cost, T: Ord> PartialOrd for MinCost<C, T> {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

impl<C: Cost, T: Ord> Ord for MinCost<C, T> {
    fn cmp(&self, other: &Self) -> Ordering {
        other
            .0
            .total_order(&self.0)
            .then_with(|| other.1.cmp(&self.1))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BinaryHeap;

    #[test]
    fn pops_lowest_cost_then_lowest_item() {
        let mut heap = BinaryHeap::new();
        for (c, i) in [
            (2.0f64, 1u32),
            (1.0, 7),
            (1.0, 3),
            (f64::INFINITY, 0),
            (0.5, 9),
        ] {
            heap.push(MinCost(c, i));
        }
        let order: Vec<u32> = std::iter::from_fn(|| heap.pop().map(|e| e.1)).collect();
        assert_eq!(order, vec![9, 3, 7, 1, 0]);
    }
}
