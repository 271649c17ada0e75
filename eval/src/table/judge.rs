//! The human watching a run (paper §4.1): the only code besides the privileged expert that reads
//! the ground truth. It decides when a robot needs an intervention (it collided, or it made no
//! progress towards its goal for a while) and where to put it down, and it keeps the figures
//! of a run (collisions by obstacle kind, distances to people and glass).

use std::collections::BinaryHeap;

use map_core::search::{MinCost, NEIGHBOURS_8};
use map_core::{classify, CellClass, OccupancyGrid};
use protocol::Pose2D;
use sim::{Obstacle, World};

/// Free space kept around the robot's disc where an intervention puts it down.
const PUT_DOWN_CLEARANCE_M: f64 = 0.15;

/// Geodesic distance to one goal on the floor plan: 8-connected Dijkstra over the plan's free
/// cells, in metres. It measures progress the way a person watching would ("is it getting
/// closer along the corridors?"), so a robot circling or dithering in place is not progressing
/// even though it moves.
#[derive(Debug, Clone)]
pub struct GoalDistance {
    width: u32,
    height: u32,
    resolution_m: f64,
    origin: Pose2D,
    distance_m: Vec<f32>,
    goal: (f64, f64),
}

impl GoalDistance {
    /// Distances from every free plan cell to the goal at (`x_m`, `y_m`).
    #[must_use]
    pub fn new(plan: &OccupancyGrid, x_m: f64, y_m: f64) -> Self {
        let (w, h) = (plan.width_cells(), plan.height_cells());
        let res = plan.resolution_m();
        let mut distance_m = vec![f32::INFINITY; plan.cells().len()];
        let free = |cx: i64, cy: i64| {
            plan.get(cx, cy)
                .is_some_and(|v| classify(v) == CellClass::Free)
        };
        let mut heap = BinaryHeap::new();
        let (gx, gy) = plan.world_to_cell(x_m, y_m);
        if let Some(i) = plan.geometry().checked_index(gx, gy) {
            distance_m[i] = 0.0;
            #[allow(clippy::cast_possible_truncation)]
            heap.push(MinCost(0.0f32, i as u32));
        }
        #[allow(clippy::cast_possible_truncation)]
        let (step, diag) = (res as f32, (res * std::f64::consts::SQRT_2) as f32);
        while let Some(MinCost(d, i)) = heap.pop() {
            if d > distance_m[i as usize] {
                continue;
            }
            let (cx, cy) = (i64::from(i % w), i64::from(i / w));
            for (dx, dy) in NEIGHBOURS_8 {
                let (nx, ny) = (cx + dx, cy + dy);
                if !free(nx, ny) {
                    continue;
                }
                // No corner cutting between two blocked cells.
                if dx != 0 && dy != 0 && !(free(cx + dx, cy) || free(cx, cy + dy)) {
                    continue;
                }
                let Some(j) = plan.geometry().checked_index(nx, ny) else {
                    continue;
                };
                let nd = d + if dx != 0 && dy != 0 { diag } else { step };
                if nd < distance_m[j] {
                    distance_m[j] = nd;
                    #[allow(clippy::cast_possible_truncation)]
                    heap.push(MinCost(nd, j as u32));
                }
            }
        }
        Self {
            width: w,
            height: h,
            resolution_m: res,
            origin: plan.origin(),
            distance_m,
            goal: (x_m, y_m),
        }
    }

    /// Distance to the goal from (`x_m`, `y_m`): the nearest reachable cell within 0.5 m (the
    /// robot's centre may sit on a cell the plan marks occupied, e.g. a door jamb), else the
    /// straight-line distance.
    #[must_use]
    pub fn at(&self, x_m: f64, y_m: f64) -> f64 {
        let (c, s) = (self.origin.yaw_rad.cos(), self.origin.yaw_rad.sin());
        let (dx, dy) = (x_m - self.origin.x_m, y_m - self.origin.y_m);
        let (gx, gy) = (
            (c * dx + s * dy) / self.resolution_m,
            (-s * dx + c * dy) / self.resolution_m,
        );
        #[allow(clippy::cast_possible_truncation)]
        let (cx, cy) = (gx.floor() as i64, gy.floor() as i64);
        #[allow(clippy::cast_possible_truncation)]
        let reach = (0.5 / self.resolution_m).ceil() as i64;
        let mut best = f64::INFINITY;
        for r in 0..=reach {
            for oy in -r..=r {
                for ox in -r..=r {
                    if ox.abs().max(oy.abs()) != r {
                        continue;
                    }
                    let (x, y) = (cx + ox, cy + oy);
                    if x < 0 || y < 0 || x >= i64::from(self.width) || y >= i64::from(self.height) {
                        continue;
                    }
                    #[allow(clippy::cast_sign_loss, clippy::cast_possible_truncation)]
                    let d = self.distance_m[(y as usize) * self.width as usize + x as usize];
                    if d.is_finite() {
                        #[allow(clippy::cast_precision_loss)]
                        let off = (ox as f64).hypot(oy as f64) * self.resolution_m;
                        best = best.min(f64::from(d) + off);
                    }
                }
            }
            if best.is_finite() {
                return best;
            }
        }
        (x_m - self.goal.0).hypot(y_m - self.goal.1)
    }
}

/// Collisions of one run by what was hit.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Collisions {
    pub wall: u32,
    pub furniture: u32,
    pub glass: u32,
    pub person: u32,
    pub robot: u32,
}

impl Collisions {
    pub fn count(&mut self, with: &Obstacle) {
        let slot = match with {
            Obstacle::Wall => &mut self.wall,
            Obstacle::Furniture(_) => &mut self.furniture,
            Obstacle::Glass(_) => &mut self.glass,
            Obstacle::Person(_) => &mut self.person,
            Obstacle::Robot(_) => &mut self.robot,
        };
        *slot += 1;
    }

    /// Adds another run's contacts, kind by kind.
    pub fn add(&mut self, other: &Self) {
        self.wall += other.wall;
        self.furniture += other.furniture;
        self.glass += other.glass;
        self.person += other.person;
        self.robot += other.robot;
    }

    #[must_use]
    pub fn total(&self) -> u32 {
        self.wall + self.furniture + self.glass + self.person + self.robot
    }
}

/// The kind of obstacle as the table names it.
#[must_use]
pub fn obstacle_kind(o: &Obstacle) -> &'static str {
    match o {
        Obstacle::Wall => "wall",
        Obstacle::Furniture(_) => "furniture",
        Obstacle::Glass(_) => "glass",
        Obstacle::Person(_) => "person",
        Obstacle::Robot(_) => "robot",
    }
}

/// Where the person or robot `with` names was, seen by the camera of the robot at `pose`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContactSight {
    /// Their centre's bearing from the robot's centre against its heading (rad, left
    /// positive, in (-π, π]).
    pub bearing_rad: f64,
    /// Whether any of their disc lies inside the camera's horizontal field of view, seen from
    /// the camera ([`sim::camera::CAMERA_FORWARD_M`] ahead of the centre).
    pub in_camera_view: bool,
}

/// [`ContactSight`] of `with` from robot `index` at `pose`; `None` for walls, furniture and
/// glass, which have no one centre.
#[must_use]
pub fn contact_sight(
    world: &World,
    index: usize,
    pose: Pose2D,
    with: &Obstacle,
) -> Option<ContactSight> {
    let (x_m, y_m, radius_m) = match *with {
        Obstacle::Person(i) => world.people.get(i).map(|p| (p.x_m, p.y_m, p.radius_m))?,
        Obstacle::Robot(i) if i != index => world
            .ground_truth_pose(i)
            .map(|p| (p.x_m, p.y_m, world.config.base.radius_m))?,
        _ => return None,
    };
    let bearing_rad =
        protocol::normalize_angle((y_m - pose.y_m).atan2(x_m - pose.x_m) - pose.yaw_rad);
    let (cx, cy, _) = sim::camera::camera_origin(pose);
    let d_m = (x_m - cx).hypot(y_m - cy);
    let from_camera = protocol::normalize_angle((y_m - cy).atan2(x_m - cx) - pose.yaw_rad).abs();
    // The disc's angular half-width; a disc round the camera fills the view.
    let half_rad = if d_m > radius_m {
        (radius_m / d_m).asin()
    } else {
        std::f64::consts::PI
    };
    Some(ContactSight {
        bearing_rad,
        in_camera_view: from_camera - half_rad < 0.5 * world.config.camera.hfov_rad,
    })
}

/// Gap between robot `index`'s disc and the nearest person's (0 at contact); `None` without
/// people.
#[must_use]
pub fn person_gap_m(world: &World, index: usize) -> Option<f64> {
    let pose = world.ground_truth_pose(index)?;
    let r = world.config.base.radius_m;
    world
        .people
        .iter()
        .map(|p| ((p.x_m - pose.x_m).hypot(p.y_m - pose.y_m) - p.radius_m - r).max(0.0))
        .min_by(f64::total_cmp)
}

/// Gap between robot `index`'s disc and the nearest glass pane (0 at contact); `None` without
/// glass.
#[must_use]
pub fn glass_gap_m(world: &World, index: usize) -> Option<f64> {
    let pose = world.ground_truth_pose(index)?;
    let r = world.config.base.radius_m;
    world
        .glass
        .iter()
        .map(|g| (g.shape.distance(pose.x_m, pose.y_m) - r).max(0.0))
        .min_by(f64::total_cmp)
}

/// Where an intervention puts the robot down: the first pose on `path`, at least `ahead_m`
/// along it beyond the point nearest to the true position, where the robot's disc (plus a
/// margin) overlaps nothing, people included, facing along the path. Near the end of the path
/// (a goal closer than `ahead_m`) the farthest free pose ahead does; without any, the free spot
/// nearest to the robot within 1 m, facing the way it faced. `None` when nothing is free.
#[must_use]
pub fn put_down_pose(
    world: &World,
    index: usize,
    path: &[Pose2D],
    truth: Pose2D,
    ahead_m: f64,
) -> Option<Pose2D> {
    let radius_m = world.config.base.radius_m + PUT_DOWN_CLEARANCE_M;
    let free = |p: &Pose2D| {
        world
            .disc_overlap(p.x_m, p.y_m, radius_m, Some(index), true)
            .is_none()
    };
    if let Some(nearest) = path
        .iter()
        .enumerate()
        .min_by(|a, b| a.1.distance_m(&truth).total_cmp(&b.1.distance_m(&truth)))
        .map(|(k, _)| k)
    {
        let mut along_m = 0.0;
        let mut farthest_free = None;
        for k in nearest..path.len() {
            if k > nearest {
                along_m += path[k].distance_m(&path[k - 1]);
            }
            if free(&path[k]) {
                if along_m >= ahead_m {
                    return Some(path[k]);
                }
                if k > nearest {
                    farthest_free = Some(path[k]);
                }
            }
        }
        if farthest_free.is_some() {
            return farthest_free;
        }
    }
    // Rings of candidate spots around the robot, nearest first.
    let step_m = 0.05;
    for ring in 1..=20u32 {
        let r = f64::from(ring) * step_m;
        let n = 8 * ring;
        for k in 0..n {
            let a = std::f64::consts::TAU * f64::from(k) / f64::from(n);
            let p = Pose2D::new(
                truth.x_m + r * a.cos(),
                truth.y_m + r * a.sin(),
                truth.yaw_rad,
            );
            if free(&p) {
                return Some(p);
            }
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    fn corridor() -> OccupancyGrid {
        // 4 m × 1 m free corridor inside walls, 0.1 m cells, with a wall stub at x = 2 m that
        // leaves a gap at the top.
        let (w, h) = (42u32, 12u32);
        let mut cells = vec![map_core::OCCUPIED; (w * h) as usize];
        for y in 1..h - 1 {
            for x in 1..w - 1 {
                cells[(y * w + x) as usize] = map_core::FREE;
            }
        }
        for y in 1..8 {
            cells[(y * w + 20) as usize] = map_core::OCCUPIED;
        }
        OccupancyGrid::new(w, h, 0.1, Pose2D::new(0.0, 0.0, 0.0), cells).unwrap()
    }

    #[test]
    fn geodesic_distance_goes_around_walls() {
        let plan = corridor();
        let d = GoalDistance::new(&plan, 3.5, 0.5);
        assert!(d.at(3.5, 0.5) < 0.1);
        // Straight line 3 m; over the stub (up to y ≈ 0.85 and back down) it is longer.
        let around = d.at(0.5, 0.5);
        assert!(around > 3.05 && around < 4.0, "{around}");
        // Inside the wall stub: the nearest free cell within 0.5 m.
        assert!(d.at(2.05, 0.3).is_finite());
    }

    #[test]
    fn collisions_count_by_kind() {
        let mut c = Collisions::default();
        c.count(&Obstacle::Glass(0));
        c.count(&Obstacle::Glass(1));
        c.count(&Obstacle::Person(0));
        assert_eq!((c.glass, c.person, c.total()), (2, 1, 3));
    }

    #[test]
    fn contact_sight_is_where_the_person_stands_and_whether_the_camera_sees_them() {
        let world = World::from_scenario_file(
            &test_support::scenario("behaviour_person_oncoming"),
            sim::SimConfig::default(),
        )
        .unwrap();
        let p = &world.people[0];
        let person = Obstacle::Person(0);
        let beside = |bearing_deg: f64, d_m: f64| {
            let b = bearing_deg.to_radians();
            // The robot `d_m` from them, heading so that they are at `bearing_deg`.
            let pose = Pose2D::new(p.x_m - d_m, p.y_m, -b);
            contact_sight(&world, 0, pose, &person).unwrap()
        };
        let ahead = beside(0.0, 1.0);
        assert!(
            ahead.bearing_rad.abs() < 1e-9 && ahead.in_camera_view,
            "{ahead:?}"
        );
        // Touching (0.5 m centre to centre) at 35° right: their disc reaches well into the
        // 70° view; at 53° right, as task C's and D's stand-offs, only its nearest 1.5° is
        // inside, seen from the camera 0.15 m ahead of the centre; at 60° none of it.
        assert!(beside(-35.0, 0.5).in_camera_view);
        let stand_off = beside(-53.0, 0.5);
        assert!(
            (stand_off.bearing_rad + 53f64.to_radians()).abs() < 1e-9,
            "{stand_off:?}"
        );
        assert!(stand_off.in_camera_view, "{stand_off:?}");
        assert!(!beside(-60.0, 0.5).in_camera_view);
        assert!(!beside(90.0, 0.5).in_camera_view);
        let north = Pose2D::new(p.x_m - 1.0, p.y_m, std::f64::consts::FRAC_PI_2);
        assert_eq!(contact_sight(&world, 0, north, &Obstacle::Wall), None);
        assert_eq!(contact_sight(&world, 0, north, &Obstacle::Person(99)), None);
    }
}
