//! Keeping to the middle of passages (`planning::centring`, `[planner.centring]`): the planned
//! path runs down the middle of a corridor after a turn and past a door in its wall, stays as
//! it was in an open room, and keeps every property the search guarantees (free poses, the
//! turning radius, the pose spacing), also on the real office map of tasks A–E.

// Integration tests: helpers outside #[test] functions panic on failure by design.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::sync::Arc;

use map_core::grid::{FREE, OCCUPIED};
use map_core::OccupancyGrid;
use planning::{CentringParams, Goal, Path, Planner, PlannerConfig, PlanningMap};
use protocol::{normalize_angle, Pose2D};

const RES_M: f64 = 0.1;

/// Walls everywhere but the given free rectangles (x0, y0, x1, y1), on a 24 m x 18 m grid.
fn carved(free: &[(f64, f64, f64, f64)]) -> OccupancyGrid {
    let mut g =
        OccupancyGrid::filled(240, 180, RES_M, Pose2D::new(0.0, 0.0, 0.0), OCCUPIED).unwrap();
    for &(x0, y0, x1, y1) in free {
        #[allow(clippy::cast_possible_truncation)]
        let cells = |a: f64, b: f64| ((a / RES_M).round() as i64)..((b / RES_M).round() as i64);
        for cx in cells(x0, x1) {
            for cy in cells(y0, y1) {
                g.set(cx, cy, FREE);
            }
        }
    }
    g
}

/// A 2 m corridor along y = 4..6 from x = 1 to 20, turning north up x = 18..20 to y = 16.
fn l_corridor() -> Vec<(f64, f64, f64, f64)> {
    vec![(1.0, 4.0, 20.0, 6.0), (18.0, 4.0, 20.0, 16.0)]
}

fn plan(grid: &OccupancyGrid, cfg: &PlannerConfig, start: Pose2D, goal: (f64, f64)) -> Path {
    let map = Arc::new(PlanningMap::new(grid.clone(), cfg).unwrap());
    let mut planner = Planner::new(map, cfg.clone()).unwrap();
    planner
        .plan(start, Goal::at(goal.0, goal.1).pose_from(start))
        .unwrap()
}

fn without_centring() -> PlannerConfig {
    let mut cfg = PlannerConfig::default();
    cfg.centring.enabled = false;
    cfg
}

/// Largest |coordinate - centre| over the poses `on` selects, of the coordinate `of` picks.
fn off_centre(
    path: &Path,
    on: impl Fn(&Pose2D) -> bool,
    of: impl Fn(&Pose2D) -> f64,
    centre: f64,
) -> f64 {
    let offs: Vec<f64> = path
        .poses
        .iter()
        .filter(|p| on(p))
        .map(|p| (of(p) - centre).abs())
        .collect();
    assert!(offs.len() > 20, "too few poses on the stretch");
    offs.into_iter().fold(0.0, f64::max)
}

/// What the search guarantees of a path, after centring too.
fn check_drivable(grid: &OccupancyGrid, cfg: &PlannerConfig, path: &Path) {
    let map = PlanningMap::new(grid.clone(), cfg).unwrap();
    for w in path.poses.windows(2) {
        let (a, b) = (w[0], w[1]);
        let g = map.to_grid(b);
        assert!(
            map.clearance_m(g.x_m, g.y_m) >= cfg.robot_radius_m,
            "{b:?} not free"
        );
        let d = a.distance_m(&b);
        assert!(
            d <= 1.5 * cfg.path_spacing_m + 1e-6,
            "poses {a:?} {b:?} {d} m apart"
        );
        if d > 1e-9 {
            let dyaw = normalize_angle(b.yaw_rad - a.yaw_rad).abs();
            // Centring may bend a moved stretch down to its own radius.
            let rho_m = cfg.min_turning_radius_m.min(cfg.centring.min_radius_m);
            assert!(
                dyaw <= d / rho_m * 1.05 + 1e-6,
                "turns {dyaw} over {d} m at {a:?}"
            );
        }
    }
}

#[test]
fn after_a_turn_the_path_runs_down_the_middle_of_the_corridor() {
    let grid = carved(&l_corridor());
    let start = Pose2D::new(2.0, 5.0, 0.0);
    let goal = (19.0, 15.0);
    let shortest = plan(&grid, &without_centring(), start, goal);
    let cfg = PlannerConfig::default();
    let centred = plan(&grid, &cfg, start, goal);
    let up = |p: &Pose2D| (9.0..13.0).contains(&p.y_m);
    let along = |p: &Pose2D| (4.0..15.0).contains(&p.x_m) && p.y_m < 6.0;
    // The shortest path cuts the corner and comes out of it hugging the inner wall ...
    let hugging_m = off_centre(&shortest, up, |p| p.x_m, 19.0);
    assert!(
        hugging_m > 0.3,
        "the shortest path is only {hugging_m} m off the middle"
    );
    // ... the centred one keeps to the middle of both stretches.
    let up_m = off_centre(&centred, up, |p| p.x_m, 19.0);
    let along_m = off_centre(&centred, along, |p| p.y_m, 5.0);
    assert!(up_m < 0.1, "{up_m} m off the middle going north");
    // Going east the shortest path ends 0.76 m off the middle, past `max_shift_m`.
    assert!(along_m < 0.2, "{along_m} m off the middle going east");
    check_drivable(&grid, &cfg, &centred);
    assert!(centred.poses[0].distance_m(&start) < 1e-9);
    let last = centred.poses[centred.poses.len() - 1];
    assert!((last.x_m - goal.0).hypot(last.y_m - goal.1) <= cfg.goal_position_tolerance_m + 1e-6);
}

#[test]
fn a_door_in_the_corridor_wall_does_not_pull_the_path_aside() {
    // A 1 m door in the corridor's north wall at x = 10..11 into a room above.
    let mut free = l_corridor();
    free.push((10.0, 6.0, 11.0, 7.0));
    free.push((6.0, 7.0, 15.0, 12.0));
    let grid = carved(&free);
    // Start off the middle, as a robot does after a turn.
    let start = Pose2D::new(2.0, 4.5, 0.0);
    let centred = plan(&grid, &PlannerConfig::default(), start, (19.0, 15.0));
    let by_door = |p: &Pose2D| (9.0..12.0).contains(&p.x_m) && p.y_m < 6.0;
    let off_m = off_centre(&centred, by_door, |p| p.y_m, 5.0);
    assert!(off_m < 0.1, "{off_m} m off the middle by the door");
    check_drivable(&grid, &PlannerConfig::default(), &centred);
}

#[test]
fn in_an_open_room_the_path_is_the_shortest() {
    let grid = carved(&[(1.0, 1.0, 23.0, 17.0)]);
    let start = Pose2D::new(3.0, 3.0, 0.3);
    let shortest = plan(&grid, &without_centring(), start, (20.0, 14.0));
    let centred = plan(&grid, &PlannerConfig::default(), start, (20.0, 14.0));
    assert_eq!(shortest.poses, centred.poses);
}

#[test]
fn on_the_office_map_centred_paths_stay_drivable_and_clear_the_walls() {
    let path = test_support::scenarios_dir()
        .join("maps")
        .join("office.yaml");
    let grid = map_core::load_ros_map(&path, &map_core::ImportLimits::default())
        .unwrap()
        .grid;
    let cfg = PlannerConfig::default();
    let map = Arc::new(PlanningMap::new(grid.clone(), &cfg).unwrap());
    let pairs = planning::sample::sample_pairs(&map, 12, 5, 8.0, "office").unwrap();
    let (mut clear_shortest, mut clear_centred) = (0.0, 0.0);
    for (s, g) in pairs {
        let goal = (g.x_m, g.y_m);
        let shortest = plan(&grid, &without_centring(), s, goal);
        let centred = plan(&grid, &cfg, s, goal);
        check_drivable(&grid, &cfg, &centred);
        let mean_clearance = |p: &Path| {
            let sum: f64 = p
                .poses
                .iter()
                .map(|q| {
                    let c = map.to_grid(*q);
                    map.clearance_m(c.x_m, c.y_m)
                })
                .sum();
            #[allow(clippy::cast_precision_loss)]
            let n = p.poses.len() as f64;
            sum / n
        };
        clear_shortest += mean_clearance(&shortest);
        clear_centred += mean_clearance(&centred);
        // Barely longer: it eases across, it does not wander.
        assert!(
            centred.length_m <= shortest.length_m * 1.05 + 0.3,
            "{} m against {} m",
            centred.length_m,
            shortest.length_m
        );
    }
    assert!(
        clear_centred > clear_shortest * 1.1,
        "mean clearance {clear_centred} against {clear_shortest}"
    );
}

#[test]
fn bad_centring_values_are_named() {
    let cfg = PlannerConfig {
        centring: CentringParams {
            window_m: -1.0,
            ..CentringParams::default()
        },
        ..PlannerConfig::default()
    };
    let e = cfg.validate().unwrap_err().to_string();
    assert!(e.contains("centring.window_m"), "{e}");
    let parsed: Result<PlannerConfig, _> = toml::from_str("[centring]\nwidth_m = 2.0\n");
    assert!(parsed.is_err(), "an unknown centring key was accepted");
}
