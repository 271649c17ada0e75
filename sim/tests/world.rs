//! Lock-step world on the shipped scenarios: determinism, limits, collisions, LIDAR, odometry,
//! camera equivalence and appearance.

// Test code: a failed unwrap is a failed test.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::PathBuf;

use protocol::{Pose2D, RobotId};
use sim::camera::{render, render_per_pixel};
use sim::{Command, Obstacle, SimConfig, World};

fn scenario(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("scenarios")
        .join(format!("{name}.yaml"))
}

fn world(name: &str) -> World {
    World::from_scenario_file(&scenario(name), SimConfig::default()).unwrap()
}

fn id(s: &str) -> RobotId {
    RobotId::new(s).unwrap()
}

/// Runs a scripted drive and returns every observation as bytes plus camera frames.
fn scripted_run(name: &str) -> (Vec<u8>, Vec<Vec<u8>>) {
    let mut w = world(name);
    w.add_robots_at_start(2).unwrap();
    let mut log = Vec::new();
    let mut frames = Vec::new();
    for k in 0..120 {
        let t = f64::from(k) * 0.1;
        let cmds = [
            Command {
                v_mps: 0.9,
                omega_radps: 0.5 * (0.4 * t).sin(),
            },
            Command {
                v_mps: 0.4,
                omega_radps: -0.3,
            },
        ];
        let obs = w.step(&cmds, 0.1);
        for o in &obs.robots {
            log.extend(serde_json::to_vec(&o.scan).unwrap());
            log.extend(serde_json::to_vec(&o.odom).unwrap());
            log.extend(serde_json::to_vec(&o.collisions).unwrap());
            for v in [
                o.ground_truth_pose.x_m,
                o.ground_truth_pose.y_m,
                o.ground_truth_pose.yaw_rad,
            ] {
                log.extend(v.to_le_bytes());
            }
        }
        if k % 20 == 0 {
            frames.push(w.render_camera(0).unwrap().data);
        }
    }
    (log, frames)
}

#[test]
fn lockstep_is_bitwise_deterministic() {
    let a = scripted_run("task_a");
    let b = scripted_run("task_a");
    assert!(
        a.0 == b.0,
        "observation bytes differ between identical runs"
    );
    assert!(a.1 == b.1, "camera frames differ between identical runs");
    // And the seed matters: another scenario on the same map gives other bytes.
    let c = scripted_run("train_junctions");
    assert!(a.0 != c.0);
}

#[test]
fn camera_does_not_disturb_the_random_streams() {
    let run = |with_camera: bool| {
        let mut w = world("task_b");
        w.add_robots_at_start(1).unwrap();
        let mut out = Vec::new();
        for _ in 0..30 {
            let obs = w.step(
                &[Command {
                    v_mps: 0.5,
                    omega_radps: 0.1,
                }],
                0.1,
            );
            if with_camera {
                let _ = w.camera_frame(0).unwrap();
            }
            out.push(obs.robots[0].odom.pose);
            out.push(Pose2D::new(
                f64::from(obs.robots[0].scan.ranges_m[90]),
                0.0,
                0.0,
            ));
        }
        out
    };
    assert_eq!(run(true), run(false));
}

#[test]
fn base_respects_speed_turn_and_acceleration_limits() {
    let mut w = world("task_c");
    w.add_robots_at_start(1).unwrap();
    let cfg = w.config.base;
    let mut prev_v = 0.0;
    for _ in 0..20 {
        let before = w.ground_truth_pose(0).unwrap();
        let obs = w.step(
            &[Command {
                v_mps: 5.0,
                omega_radps: 0.0,
            }],
            0.05,
        );
        let o = &obs.robots[0];
        assert!(o.collisions.is_empty());
        // True speed never exceeds the limit whatever the command.
        let true_v = before.distance_m(&o.ground_truth_pose) / 0.05;
        assert!(true_v <= cfg.max_speed_mps + 1e-9);
        prev_v = true_v;
    }
    assert!(
        prev_v > 0.5,
        "the robot should have accelerated, v = {prev_v}"
    );
    // From standstill one step of 0.1 s at 1 m/s² moves at most 0.5 * a * t² + v·t = 0.01 m.
    let mut w = world("task_c");
    w.add_robots_at_start(1).unwrap();
    let before = w.ground_truth_pose(0).unwrap();
    let _ = w.step(
        &[Command {
            v_mps: 1.2,
            omega_radps: 0.0,
        }],
        0.1,
    );
    let after = w.ground_truth_pose(0).unwrap();
    assert!(before.distance_m(&after) <= cfg.max_accel_mps2 * 0.1 * 0.1 + 1e-9);
    // Turn rate clamp: after spinning up, yaw change per 0.1 s stays within max_turn_radps.
    for _ in 0..30 {
        let _ = w.step(
            &[Command {
                v_mps: 0.0,
                omega_radps: 10.0,
            }],
            0.1,
        );
    }
    let a = w.ground_truth_pose(0).unwrap().yaw_rad;
    let _ = w.step(
        &[Command {
            v_mps: 0.0,
            omega_radps: 10.0,
        }],
        0.1,
    );
    let b = w.ground_truth_pose(0).unwrap().yaw_rad;
    let dyaw = protocol::normalize_angle(b - a);
    assert!(
        (dyaw - cfg.max_turn_radps * 0.1).abs() < 1e-9,
        "yaw step {dyaw}"
    );
}

#[test]
fn collisions_stop_the_robot_and_are_reported() {
    // Drive straight at the wall south of the junction start (corridor y 3..5).
    let mut w = world("task_a");
    w.add_robot(
        id("robot_1"),
        Pose2D::new(3.0, 4.0, -std::f64::consts::FRAC_PI_2),
    )
    .unwrap();
    let mut hit = None;
    for _ in 0..60 {
        let obs = w.step(
            &[Command {
                v_mps: 1.0,
                omega_radps: 0.0,
            }],
            0.1,
        );
        if let Some(c) = obs.robots[0].collisions.first() {
            hit = Some(c.clone());
            break;
        }
    }
    let c = hit.expect("no collision reported");
    assert_eq!(c.with, Obstacle::Wall);
    let p = w.ground_truth_pose(0).unwrap();
    assert!(
        p.y_m >= 3.0 + 0.25 - 1e-9 && p.y_m < 3.0 + 0.25 + 0.03,
        "stopped at {p:?}"
    );
    // Pushing on does not go through.
    for _ in 0..20 {
        let _ = w.step(
            &[Command {
                v_mps: 1.0,
                omega_radps: 0.0,
            }],
            0.1,
        );
    }
    assert!(w.ground_truth_pose(0).unwrap().y_m >= 3.25 - 1e-9);
}

#[test]
fn glass_furniture_and_robots_block_and_are_named() {
    // Task A has a glass door across the x = 8 corridor (y 9..11), panes at y 9..9.4.
    let mut w = world("task_a");
    w.add_robot(id("robot_1"), Pose2D::new(6.5, 9.3, 0.0))
        .unwrap();
    let mut with = None;
    for _ in 0..40 {
        let obs = w.step(
            &[Command {
                v_mps: 1.0,
                omega_radps: 0.0,
            }],
            0.1,
        );
        if let Some(c) = obs.robots[0].collisions.first() {
            with = Some(c.with.clone());
            break;
        }
    }
    assert_eq!(with, Some(Obstacle::Glass(0)));
    // Furniture: the bench at (8.0, 3.35).
    let mut w = world("task_a");
    w.add_robot(id("robot_1"), Pose2D::new(6.0, 3.5, 0.0))
        .unwrap();
    let mut with = None;
    for _ in 0..40 {
        let obs = w.step(
            &[Command {
                v_mps: 1.0,
                omega_radps: 0.0,
            }],
            0.1,
        );
        if let Some(c) = obs.robots[0].collisions.first() {
            with = Some(c.with.clone());
            break;
        }
    }
    assert_eq!(with, Some(Obstacle::Furniture(0)));
    // Two robots head-on.
    let mut w = world("task_a");
    w.add_robot(id("a"), Pose2D::new(15.0, 4.0, 0.0)).unwrap();
    w.add_robot(id("b"), Pose2D::new(17.0, 4.0, std::f64::consts::PI))
        .unwrap();
    let mut seen = false;
    for _ in 0..40 {
        let obs = w.step(
            &[
                Command {
                    v_mps: 0.8,
                    omega_radps: 0.0,
                },
                Command {
                    v_mps: 0.8,
                    omega_radps: 0.0,
                },
            ],
            0.1,
        );
        if obs.robots[0]
            .collisions
            .iter()
            .any(|c| c.with == Obstacle::Robot(1))
        {
            seen = true;
            break;
        }
    }
    assert!(seen);
    let (a, b) = (
        w.ground_truth_pose(0).unwrap(),
        w.ground_truth_pose(1).unwrap(),
    );
    assert!(a.distance_m(&b) >= 0.5 - 1e-9);
    assert!(w.add_robot(id("c"), Pose2D::new(3.0, 4.0, 0.0)).is_ok());
    assert!(w.add_robot(id("d"), Pose2D::new(3.2, 4.0, 0.0)).is_err());
}

#[test]
fn lidar_sees_walls_people_robots_but_not_glass() {
    let mut w = world("task_a");
    // Facing +x down the y = 10 corridor from x = 6.5: glass door at x = 8 is transparent.
    w.add_robot(id("robot_1"), Pose2D::new(6.5, 9.3, 0.0))
        .unwrap();
    w.add_robot(id("robot_2"), Pose2D::new(6.5, 10.5, 0.0))
        .unwrap();
    let obs = w.step(&[], 0.0);
    let scan = &obs.robots[0].scan;
    assert_eq!(scan.ranges_m.len(), 181);
    assert!((scan.angle_increment_rad - std::f32::consts::PI / 180.0).abs() < 1e-6);
    assert_eq!(scan.range_max_m, 8.0);
    // Straight ahead (beam 90): no glass, far wall beyond 8 m or the person; must be > 1.5 m.
    assert!(scan.ranges_m[90] > 1.5, "beam 90 = {}", scan.ranges_m[90]);
    // Right (beam 0, -90°): corridor wall at y = 9, 0.3 m away.
    assert!(
        (scan.ranges_m[0] - 0.3).abs() < 0.05,
        "beam 0 = {}",
        scan.ranges_m[0]
    );
    // Left (beam 180, +90°): the other robot, surface at 1.2 - 0.25 = 0.95 m.
    assert!(
        (scan.ranges_m[180] - 0.95).abs() < 0.05,
        "beam 180 = {}",
        scan.ranges_m[180]
    );
    assert!(scan
        .ranges_m
        .iter()
        .all(|r| r.is_finite() && *r >= 0.0 && *r <= 8.0));
    // With glass visible, the pane at x = 8 (0.3 m off the corridor edge) blocks beam 90.
    let mut cfg = SimConfig::default();
    cfg.lidar.sees_glass = true;
    let mut w = World::from_scenario_file(&scenario("task_a"), cfg).unwrap();
    w.add_robot(id("robot_1"), Pose2D::new(6.5, 9.3, 0.0))
        .unwrap();
    let obs = w.step(&[], 0.0);
    assert!((obs.robots[0].scan.ranges_m[90] - 1.48).abs() < 0.05);
}

#[test]
fn odometry_drifts_from_the_truth_but_tracks_it() {
    let mut w = world("train_hall");
    w.add_robots_at_start(1).unwrap();
    let start = w.ground_truth_pose(0).unwrap();
    let mut last = None;
    for _ in 0..50 {
        last = Some(w.step(
            &[Command {
                v_mps: 0.6,
                omega_radps: 0.0,
            }],
            0.1,
        ));
    }
    let obs = last.take().unwrap();
    let truth = obs.robots[0].ground_truth_pose;
    let odom = obs.robots[0].odom.pose;
    let travelled = start.distance_m(&truth);
    let odom_travelled = odom.x_m.hypot(odom.y_m);
    assert!(travelled > 2.0);
    assert!(
        (odom_travelled - travelled).abs() < 0.3 * travelled,
        "{odom_travelled} vs {travelled}"
    );
    assert!(
        (odom_travelled - travelled).abs() > 1e-6,
        "odometry must be noisy"
    );
    // Zero noise gives exact odometry in the odom frame.
    let cfg = SimConfig {
        odometry: sim::config::OdometryNoise {
            alpha1: 0.0,
            alpha2: 0.0,
            alpha3: 0.0,
            alpha4: 0.0,
        },
        ..SimConfig::default()
    };
    let mut w = World::from_scenario_file(&scenario("train_hall"), cfg).unwrap();
    w.add_robots_at_start(1).unwrap();
    for _ in 0..30 {
        last = Some(w.step(
            &[Command {
                v_mps: 0.6,
                omega_radps: 0.2,
            }],
            0.1,
        ));
    }
    let obs = last.unwrap();
    let (t, o) = (obs.robots[0].ground_truth_pose, obs.robots[0].odom.pose);
    // Odom frame = map frame moved to the start pose.
    let (s, c) = start.yaw_rad.sin_cos();
    let (dx, dy) = (t.x_m - start.x_m, t.y_m - start.y_m);
    assert!((c * dx + s * dy - o.x_m).abs() < 1e-6 && (-s * dx + c * dy - o.y_m).abs() < 1e-6);
}

#[test]
fn people_walk_their_routes() {
    let mut w = world("task_b");
    let p0 = (w.people[0].x_m, w.people[0].y_m);
    for _ in 0..20 {
        let _ = w.step(&[], 0.1);
    }
    let p1 = (w.people[0].x_m, w.people[0].y_m);
    let moved = (p1.0 - p0.0).hypot(p1.1 - p0.1);
    assert!((moved - 0.7 * 2.0).abs() < 1e-6, "moved {moved}");
}

#[test]
fn column_renderer_equals_per_pixel_reference() {
    let mut w = world("task_a");
    w.add_robot(id("robot_1"), Pose2D::new(19.0, 10.0, 0.0))
        .unwrap();
    let mut cfg = w.config.camera;
    cfg.width_px = 64;
    cfg.height_px = 48;
    let model = sim::camera::CameraModel::new(&cfg);
    let (mut a, mut b) = (Vec::new(), Vec::new());
    for pose in [
        Pose2D::new(4.0, 10.0, 0.0),
        Pose2D::new(3.0, 4.0, 0.7),
        Pose2D::new(19.0, 15.0, 2.0),
    ] {
        render(&w, &model, pose, Some(0), &mut a);
        render_per_pixel(&w, &model, pose, Some(0), &mut b);
        assert_eq!(a.len(), 64 * 48 * 3);
        assert!(a == b, "renderers differ at {pose:?}");
    }
}

fn mean_rgb(data: &[u8]) -> [f64; 3] {
    let mut m = [0.0; 3];
    for px in data.chunks(3) {
        for k in 0..3 {
            m[k] += f64::from(px[k]);
        }
    }
    let n = (data.len() / 3) as f64;
    m.map(|v| v / n)
}

#[test]
fn camera_shows_structure_and_environments_differ() {
    let mut a = world("task_a");
    a.add_robots_at_start(1).unwrap();
    let img = a.render_camera(0).unwrap();
    assert_eq!(
        (img.width_px, img.height_px, img.data.len()),
        (224, 224, 224 * 224 * 3)
    );
    img.validate().unwrap();
    // Rows differ (ceiling, wall, floor) and there is texture.
    let row = |r: usize| mean_rgb(&img.data[r * 224 * 3..(r + 1) * 224 * 3]);
    let (top, mid, bottom) = (row(5), row(112), row(218));
    assert!(top != mid && mid != bottom);
    let distinct: std::collections::BTreeSet<[u8; 3]> =
        img.data.chunks(3).map(|p| [p[0], p[1], p[2]]).collect();
    assert!(distinct.len() > 200, "only {} colours", distinct.len());
    let mut b = world("train_ring");
    b.add_robots_at_start(1).unwrap();
    let other = b.render_camera(0).unwrap();
    let (ma, mb) = (mean_rgb(&img.data), mean_rgb(&other.data));
    let diff: f64 = ma.iter().zip(mb.iter()).map(|(x, y)| (x - y).abs()).sum();
    assert!(diff > 20.0, "environments look alike: {ma:?} vs {mb:?}");
}

#[test]
fn camera_sees_people_and_other_robots() {
    let mut w = world("task_a");
    w.add_robot(id("robot_1"), Pose2D::new(9.0, 10.0, 0.0))
        .unwrap();
    let empty = w.render_camera(0).unwrap().data;
    w.add_robot(id("robot_2"), Pose2D::new(11.0, 10.0, 0.0))
        .unwrap();
    let with_robot = w.render_camera(0).unwrap().data;
    // The robot is low and centred: the lower middle of the image changes.
    let changed = (150..200)
        .flat_map(|r| (100..124).map(move |c| (r * 224 + c) * 3))
        .filter(|&i| empty[i..i + 3] != with_robot[i..i + 3])
        .count();
    assert!(
        changed > 100,
        "robot not visible ({changed} pixels changed)"
    );
}

/// A shared Nav2 map (tb3_sandbox), here given a rotated origin (yaw 0.7 rad), works as a floor
/// plan: the LIDAR's shortest beam matches the plan's distance field.
#[test]
fn rotated_nav2_plan_lidar_matches_distance_field() {
    use map_core::{DistanceField, ImportLimits, Sources};
    let path = test_support::nav2_maps_dir().join("tb3_sandbox.yaml");
    let loaded = map_core::load_ros_map(&path, &ImportLimits::default())
        .unwrap()
        .grid;
    let o = loaded.origin();
    let plan = map_core::OccupancyGrid::new(
        loaded.width_cells(),
        loaded.height_cells(),
        loaded.resolution_m(),
        Pose2D::new(o.x_m, o.y_m, 0.7),
        loaded.cells().to_vec(),
    )
    .unwrap();
    let df = DistanceField::compute(&plan, Sources::OccupiedOrUnknown);
    // The free cell with the largest clearance below 3 m (so walls are within LIDAR range).
    let (w, h) = (
        i64::from(plan.width_cells()),
        i64::from(plan.height_cells()),
    );
    let mut best = None;
    for cy in 0..h {
        for cx in 0..w {
            let d = df.at(cx, cy);
            if plan.class_at(cx, cy) == map_core::CellClass::Free
                && d < 3.0
                && d > 0.6
                && best.is_none_or(|(bd, _, _)| d > bd)
            {
                best = Some((d, cx, cy));
            }
        }
    }
    let (d, cx, cy) = best.expect("no free cell");
    let (x, y) = plan.cell_to_world(cx, cy);
    let text = format!(
        "name: nav2\nrole: training\nfloor_plan: {}\nseed: 3\ntime_limit_s: 10\n\
         start: {{x_m: {x}, y_m: {y}}}\ngoals: [{{x_m: {x}, y_m: {y}}}]\n",
        path.display()
    );
    let scenario = sim::Scenario::from_yaml(&text, &path).unwrap();
    let mut cfg = SimConfig::default();
    cfg.lidar.noise_std_m = 0.0;
    cfg.lidar.beams = 721;
    cfg.lidar.fov_rad = 2.0 * std::f64::consts::PI * 720.0 / 721.0;
    let mut world = World::new(scenario, plan.clone(), cfg).unwrap();
    assert!((world.plan.origin().yaw_rad - 0.7).abs() < 1e-12);
    world.add_robots_at_start(1).unwrap();
    let obs = world.step(&[], 0.0);
    let min = obs.robots[0]
        .scan
        .ranges_m
        .iter()
        .copied()
        .fold(f32::INFINITY, f32::min);
    // Centre-to-centre distance vs ray to the cell face: within one cell.
    let res = plan.resolution_m() as f32;
    assert!(
        (min - d).abs() <= res,
        "lidar min {min} vs distance field {d}"
    );
    assert_eq!(world.render_camera(0).unwrap().data.len(), 224 * 224 * 3);
}

/// One 0.1 s step of a world with one robot standing still and a person walking: neither
/// touches anything nor comes closer than touching. The person's position and the robot's pose.
fn step_standing_robot(w: &mut World) -> ((f64, f64), Pose2D) {
    let obs = w.step(&[], 0.1);
    assert!(obs.robots[0].collisions.is_empty());
    let p = &w.people[0];
    let r = w.ground_truth_pose(0).unwrap();
    assert!((p.x_m - r.x_m).hypot(p.y_m - r.y_m) >= p.radius_m + 0.25 - 1e-9);
    ((p.x_m, p.y_m), r)
}

#[test]
fn a_person_steps_around_a_robot_standing_in_the_way() {
    // Task A's person walks along y = 10 from x = 5 to 21; a robot stands on the route.
    let mut w = world("task_a");
    w.add_robot(id("robot_1"), Pose2D::new(10.0, 10.0, 0.0))
        .unwrap();
    let x0 = w.people[0].x_m;
    assert!(x0 < 8.0, "{x0}");
    let mut passed = false;
    for _ in 0..200 {
        let ((x_m, _), _) = step_standing_robot(&mut w);
        passed |= x_m > 11.0;
    }
    assert!(passed, "the person never got past the robot");
}

#[test]
fn a_person_pressed_to_a_wall_by_a_robot_walks_round_it() {
    // Task B's first person walks the 2 m corridor (y 9-11) east along y = 9.7. A robot stands
    // just north of that line: the person's side-step away from it ends at the wall with no
    // room to pass, so the only way on is round the robot's open north side (where task B's
    // deployed runs stood deadlocked, 2026-11-29).
    let mut w = world("task_b");
    w.add_robot(id("robot_1"), Pose2D::new(10.0, 9.72, 0.5))
        .unwrap();
    assert!(w.people[0].x_m < 4.0);
    let mut passed_at = None;
    let mut north_m = f64::NEG_INFINITY;
    for step in 0..400 {
        let ((x_m, y_m), r) = step_standing_robot(&mut w);
        if (x_m - r.x_m).abs() < 0.1 {
            north_m = north_m.max(y_m);
        }
        if x_m > 11.0 {
            passed_at = Some(step);
            break;
        }
    }
    let step = passed_at.expect("the person never got past the robot");
    assert!(
        north_m > 10.25,
        "passed the robot at y {north_m}, not round its north side"
    );
    // 7 m to the robot and 1 m on at 0.7 m/s is 11.4 s; the way round adds a few seconds.
    assert!(step < 250, "took {step} steps");
}

#[test]
fn a_person_turns_back_short_of_a_route_end_a_robot_stands_on() {
    // Task D's first person walks y = 13 between x = 10 and 25.5; a robot stands on the east
    // end (where task D's robot stood, person and robot each waiting for the other, 2026-11-29).
    let mut w = world("task_d");
    w.add_robot(id("robot_1"), Pose2D::new(25.6, 13.0, 3.0))
        .unwrap();
    let mut furthest_m = f64::NEG_INFINITY;
    let mut back_at = None;
    for step in 0..600 {
        let ((x_m, _), _) = step_standing_robot(&mut w);
        furthest_m = furthest_m.max(x_m);
        if furthest_m > 24.0 && x_m < 20.0 {
            back_at = Some(step);
            break;
        }
    }
    assert!(
        back_at.is_some(),
        "the person never turned back (got to x {furthest_m})"
    );
    // It turned where the robot stopped it, not after walking round it.
    assert!(furthest_m < 25.1, "walked on to x {furthest_m}");
}

#[test]
fn carrying_a_robot_moves_the_truth_but_not_the_odometry() {
    let mut w = world("task_a");
    w.add_robots_at_start(1).unwrap();
    let before = w.step(&[], 0.1).robots[0].odom.pose;
    let put = Pose2D::new(4.0, 4.2, 0.5);
    w.carry_robot(0, put).unwrap();
    assert_eq!(w.ground_truth_pose(0), Some(put));
    let after = w.step(&[], 0.1).robots[0].odom.pose;
    assert!(before.distance_m(&after) < 1e-9, "{before:?} {after:?}");
    // Into a wall: refused, nothing moves.
    let err = w.carry_robot(0, Pose2D::new(0.0, 0.0, 0.0)).unwrap_err();
    assert!(err.to_string().contains("overlap"), "{err}");
    assert_eq!(w.ground_truth_pose(0), Some(put));
    assert!(w.carry_robot(3, put).is_err());
}
