//! The floor plan's route from the robot towards its goal: what the `route` DLM measures
//! (`[dlm] measure = "route"`, issue 16).
//!
//! A hybrid-A* path bends a little differently in every search: a start pose 3 cm away, or a
//! kept plan searched a second earlier, takes a corner 10–30 cm wider or tighter, and any
//! measure of "how much the path turns ahead" crosses its threshold a few cycles earlier or
//! later. Measured on seven maps, a new search agrees with another new search on the DLM in
//! only 98.85 % of cycles, whatever the measure's parameters or a debounce
//! (docs/benchmarks.md, "A DLM that holds").
//!
//! The route is a function of the floor plan, the goal and the robot's position alone, as the
//! navfn path the paper's authors took their DLM from (a grid potential's gradient, not the
//! driven path). It is the steepest descent of the obstacle heuristic's coarse distance field
//! (the floor plan's 2-D shortest distances to the goal, which the planner keeps per goal
//! anyway), pulled taut from the robot's position: straight to the farthest point of the
//! descent in sight (a line that keeps [`SIGHT_CLEARANCE_FRACTION`] of the robot's radius from
//! walls), and on from there the same way, so a corner slides along with the robot instead of
//! jumping from one coarse cell to the next. Where the descent reaches the goal's cell, the
//! goal ends it. A kept plan and a new search, asked from the same pose, get the same route, so
//! the same DLM; the hybrid-A* path still draws the LPE image and is what the robot is sent.
//! Other robots are not on the floor plan, so going round one is not a turn the DLM announces
//! (the LPE image shows it).

use std::sync::PoisonError;

use protocol::Pose2D;

use crate::heuristic::NEIGHBOURS;
use crate::map::PlanningMap;

/// A point of the descent is in sight when the line to it keeps this fraction of the robot
/// radius from the walls. Coarse cells are free when any of their map cells is, so a descent
/// cell's centre may lie up to half a coarse-cell diagonal inside the inflation; the full
/// radius would stop the pulling at every such cell.
pub const SIGHT_CLEARANCE_FRACTION: f64 = 0.5;

/// The floor plan's route (map frame; each pose faces along its segment, the last along the
/// one before it) from `robot`'s position towards `goal`, at least `length_m` of it where the
/// goal is farther, pulled taut (see the module docs). `None` when the robot or the goal is
/// off the map, or no route joins them on the coarse grid.
#[must_use]
pub fn floor_plan_route(
    map: &PlanningMap,
    robot: Pose2D,
    goal: Pose2D,
    length_m: f64,
) -> Option<Vec<Pose2D>> {
    let on_map = |p: Pose2D| {
        let g = map.to_grid(p);
        let (w_m, h_m) = map.grid().extent_m();
        (g.x_m.is_finite() && g.y_m.is_finite())
            .then_some(g)
            .filter(|g| g.x_m >= 0.0 && g.y_m >= 0.0 && g.x_m < w_m && g.y_m < h_m)
    };
    let (start, end) = (on_map(robot)?, on_map(goal)?);
    let coarse = map.coarse();
    let start_cell = map.coarse_cell(start.x_m, start.y_m);
    let goal_cell = map.coarse_cell(end.x_m, end.y_m);
    let (shared, _) = map.obstacle_heuristic(goal_cell, start_cell);
    let mut field = shared.lock().unwrap_or_else(PoisonError::into_inner);
    let (width, height) = (i64::from(coarse.width), i64::from(coarse.height));
    let centre = |c: (u32, u32)| {
        (
            (f64::from(c.0) + 0.5) * coarse.cell_m,
            (f64::from(c.1) + 0.5) * coarse.cell_m,
        )
    };

    // The descent: a few metres more than asked, since pulling it taut shortens it.
    let mut points = vec![(start.x_m, start.y_m)];
    let mut cell = start_cell;
    let mut distance = field.distance_cells(coarse, cell);
    if !distance.is_finite() {
        return None;
    }
    let mut descended_m = 0.0;
    while cell != goal_cell && descended_m < 1.5 * length_m + 1.0 {
        let mut best: Option<((u32, u32), f32, f32)> = None;
        for (dx, dy, step) in NEIGHBOURS {
            let (nx, ny) = (
                i64::from(cell.0) + i64::from(dx),
                i64::from(cell.1) + i64::from(dy),
            );
            if nx < 0 || ny < 0 || nx >= width || ny >= height {
                continue;
            }
            #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
            let next = (nx as u32, ny as u32);
            let d = field.distance_cells(coarse, next);
            // The move on a shortest way down; of equals, the one that gets farthest down
            // (a diagonal), so the descent runs as straight as the grid allows.
            let better = best.is_none_or(|(_, bd, bstep)| {
                d + step < bd + bstep - 1e-4 || (d + step <= bd + bstep + 1e-4 && d < bd)
            });
            if d.is_finite() && better {
                best = Some((next, d, step));
            }
        }
        let Some((next, d, step)) = best.filter(|&(_, d, _)| d < distance) else {
            break;
        };
        descended_m += f64::from(step) * coarse.cell_m;
        (cell, distance) = (next, d);
        points.push(if cell == goal_cell {
            (end.x_m, end.y_m)
        } else {
            centre(cell)
        });
    }
    if cell == goal_cell && points.len() == 1 {
        points.push((end.x_m, end.y_m));
    }
    drop(field);

    let taut = pull_taut(map, &points);
    let mut route: Vec<Pose2D> = Vec::with_capacity(taut.len());
    for (i, &(x, y)) in taut.iter().enumerate() {
        let (fx, fy, tx, ty) = match (taut.get(i + 1), i.checked_sub(1).map(|j| taut[j])) {
            (Some(&(nx, ny)), _) => (x, y, nx, ny),
            (None, Some((px, py))) => (px, py, x, y),
            (None, None) => (x, y, x, y),
        };
        let yaw = (ty - fy).atan2(tx - fx);
        route.push(map.to_world(crate::map::GridPose {
            x_m: x,
            y_m: y,
            yaw_rad: yaw,
        }));
    }
    Some(route)
}

/// The descent `points` (grid frame) pulled taut: from the first, straight to the farthest
/// point of the descent in sight, and on from there the same way; the first and last are
/// kept.
fn pull_taut(map: &PlanningMap, points: &[(f64, f64)]) -> Vec<(f64, f64)> {
    let Some(&first) = points.first() else {
        return Vec::new();
    };
    let min_clearance_m = SIGHT_CLEARANCE_FRACTION * map.robot_radius_m();
    let step_m = 0.5 * map.grid().resolution_m();
    let sees = |a: (f64, f64), b: (f64, f64)| {
        let length = (b.0 - a.0).hypot(b.1 - a.1);
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let n = (length / step_m).ceil().max(1.0) as u32;
        (0..=n).all(|k| {
            let t = f64::from(k) / f64::from(n);
            map.clearance_m(a.0 + t * (b.0 - a.0), a.1 + t * (b.1 - a.1)) >= min_clearance_m
        })
    };
    let lerp =
        |a: (f64, f64), b: (f64, f64), t: f64| (a.0 + t * (b.0 - a.0), a.1 + t * (b.1 - a.1));
    let mut out = vec![first];
    // From `from`, the descent goes on at vertex `next`.
    let (mut from, mut next) = (first, 1);
    while next < points.len() {
        if !sees(from, points[next]) {
            // Even the next vertex is out of sight (the descent grazes a wall): take it.
            from = points[next];
            out.push(from);
            next += 1;
            continue;
        }
        let mut last = next;
        while last + 1 < points.len() && sees(from, points[last + 1]) {
            last += 1;
        }
        if last + 1 == points.len() {
            out.push(points[last]);
            break;
        }
        // The farthest point in sight on the segment after the last vertex in sight: the
        // corner moves with the robot instead of jumping from cell centre to cell centre.
        let (a, b) = (points[last], points[last + 1]);
        let (mut seen, mut hidden) = (0.0, 1.0);
        for _ in 0..8 {
            let mid = 0.5 * (seen + hidden);
            if sees(from, lerp(a, b, mid)) {
                seen = mid;
            } else {
                hidden = mid;
            }
        }
        from = lerp(a, b, seen);
        out.push(from);
        next = last + 1;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::PlannerConfig;
    use map_core::OccupancyGrid;
    use std::sync::Arc;

    /// An L-shaped corridor, 2 m wide: east along y 1..3 from x 0 to 10, then north along
    /// x 8..10 up to y 12 (0.05 m cells).
    fn l_corridor() -> Arc<PlanningMap> {
        let res = 0.05;
        let (w, h) = (220_u32, 260_u32);
        let mut cells = vec![map_core::grid::OCCUPIED; (w * h) as usize];
        for y in 0..h {
            for x in 0..w {
                let (xm, ym) = (f64::from(x) * res, f64::from(y) * res);
                let east = (0.5..10.0).contains(&xm) && (1.0..3.0).contains(&ym);
                let north = (8.0..10.0).contains(&xm) && (1.0..12.0).contains(&ym);
                if east || north {
                    cells[(y * w + x) as usize] = map_core::grid::FREE;
                }
            }
        }
        let grid = OccupancyGrid::new(w, h, res, Pose2D::new(0.0, 0.0, 0.0), cells).unwrap();
        Arc::new(PlanningMap::new(grid, &PlannerConfig::default()).unwrap())
    }

    #[test]
    fn the_route_follows_the_corridor_round_its_corner() {
        let map = l_corridor();
        let goal = Pose2D::new(9.0, 11.0, 0.0);
        let robot = Pose2D::new(2.0, 2.0, 0.0);
        let route = floor_plan_route(&map, robot, goal, 20.0).unwrap();
        assert!((route[0].x_m - 2.0).abs() < 1e-9 && (route[0].y_m - 2.0).abs() < 1e-9);
        let last = route[route.len() - 1];
        assert!(last.distance_m(&goal) < 1e-9, "{last:?}");
        // Taut: a few points, not a cell every 0.2 m; every leg keeps off the walls.
        assert!(route.len() <= 6, "{route:?}");
        for w in route.windows(2) {
            for k in 0..=20 {
                let t = f64::from(k) / 20.0;
                let (x, y) = (
                    w[0].x_m + t * (w[1].x_m - w[0].x_m),
                    w[0].y_m + t * (w[1].y_m - w[0].y_m),
                );
                assert!(map.clearance_m(x, y) >= 0.1, "({x}, {y}) in {route:?}");
            }
        }
        // It turns north at the inside of the corner (8, 3), not before x = 7.
        let corner = route
            .iter()
            .find(|p| p.y_m > 2.2 && p.y_m < 10.0)
            .expect("a point at the corner");
        assert!(corner.x_m > 7.0 && corner.x_m < 8.5, "{route:?}");
    }

    #[test]
    fn the_route_depends_on_the_position_only_and_barely_on_centimetres() {
        let map = l_corridor();
        let goal = Pose2D::new(9.0, 11.0, 0.0);
        let a = floor_plan_route(&map, Pose2D::new(5.0, 2.0, 0.0), goal, 4.0).unwrap();
        let b = floor_plan_route(&map, Pose2D::new(5.0, 2.0, 2.5), goal, 4.0).unwrap();
        assert_eq!(a, b);
        let c = floor_plan_route(&map, Pose2D::new(5.03, 1.97, 0.0), goal, 4.0).unwrap();
        assert_eq!(a.len(), c.len());
        for (p, q) in a.iter().zip(&c).skip(1) {
            assert!(p.distance_m(q) < 0.25, "{a:?} against {c:?}");
        }
    }

    #[test]
    fn no_route_off_the_map_or_to_a_walled_off_goal() {
        let map = l_corridor();
        let goal = Pose2D::new(9.0, 11.0, 0.0);
        assert!(floor_plan_route(&map, Pose2D::new(-1.0, 2.0, 0.0), goal, 4.0).is_none());
        assert!(floor_plan_route(
            &map,
            Pose2D::new(2.0, 2.0, 0.0),
            Pose2D::new(2.0, 9.0, 0.0),
            4.0
        )
        .is_none());
        // At the goal: the goal itself.
        let at = floor_plan_route(&map, goal, goal, 4.0).unwrap();
        assert!(at.iter().all(|p| p.distance_m(&goal) < 0.2), "{at:?}");
    }
}
