//! Time per control step of the dynamic window controller on the Nav2 depot map (181-beam
//! ray-cast scan with an unmapped box on the path), against references in the same run: the
//! same controller without the local navigation function (plain Fox), with a denser window
//! (21 x 41 samples), and the pure-pursuit path tracker; and the default window with the goal in
//! straight sight (it heads for the goal, checking the line to it on the scan), and standing
//! inside its inflation beside the box with the path round it (the navigation function starts
//! from the way out). Then the collision monitor's check of
//! one command on the same scan (what the agent adds after any controller), against the path
//! tracker's step.
//!
//! Run: `cargo bench -p robot-agent --bench controllers`

// A benchmark whose setup fails has nothing to measure: aborting with the reason is right.
#![allow(clippy::expect_used)]

#[path = "../tests/amcl_world/mod.rs"]
mod amcl_world;

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion};
use protocol::{Dlm, Intention, Pose2D};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use robot_agent::collision_monitor::{self, CollisionMonitorConfig};
use robot_agent::controllers::{
    ControlInput, Controller, DynamicWindow, DynamicWindowConfig, PathTracker, PathTrackerConfig,
};
use robot_agent::movers::Track;
use robot_agent::recovery::{self, Recovery, RecoveryConfig};
use robot_agent::Limits;
use test_support::fixtures;

fn bench_step(c: &mut Criterion) {
    let mut truth = amcl_world::load_nav2("depot");
    amcl_world::add_box(&mut truth, 7.0, 7.5, 0.6, 0.6, 0.0);
    // 1.5 m before the box, cruising: the box hides the look-ahead point, the detour is searched.
    let pose = Pose2D::new(5.2, 7.5, 0.0);
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let scan = amcl_world::Laser::default().scan(&truth, &pose, 0, &mut rng);
    // A straight path along y = 7.5 from `x0_m`, `n` poses 0.1 m apart.
    let straight = |x0_m: f64, n: u32| Intention {
        map: fixtures::map_ref("depot"),
        ..fixtures::intention(
            (0..n)
                .map(|i| Pose2D::new(x0_m + 0.1 * f64::from(i), 7.5, 0.0))
                .collect(),
            Dlm::GoForward,
        )
    };
    let intention = straight(2.0, 101);
    let limits = Limits::default();
    let input = ControlInput {
        pose,
        v_mps: 0.6,
        omega_radps: 0.0,
        scan: Some(&scan),
        camera: None,
        intention: Some(&intention),
        limits: &limits,
        dt_s: 0.1,
    };
    // The same scan and pose, the goal 1.2 m ahead before the box: in straight sight, so the
    // window heads for the goal and checks its line of sight on the scan.
    let near_goal = straight(5.2, 13);
    let goal_input = ControlInput {
        intention: Some(&near_goal),
        ..input
    };
    // Standing beside the box's south face, 0.31 m from it (inside the window's 0.35 m
    // inflation), the path round its east end and back west along its north face: the look-ahead
    // point lies beyond the box, and the navigation function starts from the way out of the
    // inflation.
    let beside = Pose2D::new(7.0, 6.89, 0.0);
    let beside_scan = amcl_world::Laser::default().scan(&truth, &beside, 0, &mut rng);
    let nearest_m = beside_scan
        .ranges_m
        .iter()
        .copied()
        .filter(|r| r.is_finite())
        .fold(f32::INFINITY, f32::min);
    assert!(nearest_m < 0.35, "not inside the inflation: {nearest_m} m");
    let corners = [
        (7.0, 6.89),
        (7.5, 7.1),
        (7.65, 7.5),
        (7.5, 7.95),
        (7.0, 8.1),
        (4.0, 8.1),
    ];
    let mut round: Vec<Pose2D> = Vec::new();
    for w in corners.windows(2) {
        let ((x0, y0), (x1, y1)): ((f64, f64), (f64, f64)) = (w[0], w[1]);
        let yaw = (y1 - y0).atan2(x1 - x0);
        for k in 0..10 {
            let f = f64::from(k) / 10.0;
            round.push(Pose2D::new(x0 + f * (x1 - x0), y0 + f * (y1 - y0), yaw));
        }
    }
    round.push(Pose2D::new(4.0, 8.1, std::f64::consts::PI));
    let round_the_end = Intention {
        map: fixtures::map_ref("depot"),
        ..fixtures::intention(round, Dlm::GoForward)
    };
    let beside_input = ControlInput {
        pose: beside,
        v_mps: 0.0,
        scan: Some(&beside_scan),
        intention: Some(&round_the_end),
        ..input
    };
    let default = DynamicWindowConfig::default();
    let cases: [(&str, Box<dyn Controller>); 6] = [
        (
            "dwa_default_11x21",
            Box::new(DynamicWindow::new(default).expect("config")),
        ),
        (
            "dwa_plain_fox_no_nav_grid",
            Box::new(
                DynamicWindow::new(DynamicWindowConfig {
                    local_grid_resolution_m: 0.0,
                    ..default
                })
                .expect("config"),
            ),
        ),
        (
            "dwa_dense_21x41",
            Box::new(
                DynamicWindow::new(DynamicWindowConfig {
                    v_samples: 21,
                    omega_samples: 41,
                    ..default
                })
                .expect("config"),
            ),
        ),
        (
            "path_tracker",
            Box::new(PathTracker::new(PathTrackerConfig::default()).expect("config")),
        ),
        (
            "dwa_default_goal_in_sight",
            Box::new(DynamicWindow::new(default).expect("config")),
        ),
        (
            "dwa_default_inside_the_inflation",
            Box::new(DynamicWindow::new(default).expect("config")),
        ),
    ];
    let mut group = c.benchmark_group("control_step");
    group.sample_size(30);
    for (name, mut controller) in cases {
        let step_input = if name.ends_with("goal_in_sight") {
            &goal_input
        } else if name.ends_with("inside_the_inflation") {
            &beside_input
        } else {
            &input
        };
        group.bench_function(name, |b| {
            b.iter(|| black_box(controller.control(black_box(step_input)).expect("control")));
        });
    }
    group.finish();

    let monitor = CollisionMonitorConfig::default();
    // 0.8 m before the box's face: at 0.7 m/s the disc would touch it within the horizon.
    let near = Pose2D::new(5.9, 7.5, 0.0);
    let near_scan = amcl_world::Laser::default().scan(&truth, &near, 0, &mut rng);
    assert!(collision_monitor::check(&monitor, &near_scan, &[], 0.7, 0.0).limited());
    let mut group = c.benchmark_group("collision_monitor");
    group.sample_size(30);
    // Straight at the box at full speed: limited, the arc checked again at lower speeds.
    group.bench_function("check_towards_the_box", |b| {
        b.iter(|| {
            black_box(collision_monitor::check(
                &monitor,
                black_box(&near_scan),
                &[],
                0.7,
                0.0,
            ))
        });
    });
    // The same, with the box's near face taken for someone walking across at 1 m/s: every
    // return within reach looked up against the body, and the body's returns moved each step.
    let walking = [collision_monitor::MovingBody {
        x_m: 0.8,
        y_m: 0.0,
        reach_m: 0.6,
        vx_mps: 0.0,
        vy_mps: 1.0,
    }];
    group.bench_function("check_towards_someone_crossing", |b| {
        b.iter(|| {
            black_box(collision_monitor::check(
                &monitor,
                black_box(&near_scan),
                black_box(&walking),
                0.7,
                0.0,
            ))
        });
    });
    // Slow and turning: nothing within the reach of 1.2 s at 0.3 m/s.
    group.bench_function("check_nothing_in_reach", |b| {
        b.iter(|| {
            black_box(collision_monitor::check(
                &monitor,
                black_box(&scan),
                &[],
                0.3,
                1.0,
            ))
        });
    });
    group.finish();

    // The agent's recovery after every controller step: the laser's reading straight ahead
    // and the triggers' bookkeeping (a robot standing 0.8 m before the box, so the cornered
    // trigger's tracker keeps its pose and compares every cycle).
    let mut group = c.benchmark_group("recovery");
    group.sample_size(30);
    group.bench_function("ahead_m", |b| {
        b.iter(|| black_box(recovery::ahead_m(black_box(&near_scan))));
    });
    let mut rec = Recovery::new(RecoveryConfig {
        cornered_stall_s: f64::INFINITY,
        ..RecoveryConfig::default()
    });
    let goal = Some(protocol::Pose2D::new(near.x_m + 5.0, near.y_m, 0.0));
    group.bench_function("ahead_m_and_drive", |b| {
        b.iter(|| {
            let ahead = recovery::ahead_m(black_box(&near_scan));
            black_box(rec.drive(0.1, near, goal, None, f64::INFINITY, ahead))
        });
    });
    // The obstacle layer's most (96 points, a ring 1-3 m round the robot) through the beside
    // trigger's sector, and eight walking tracks for the held trigger: the agent's worst case.
    let points: Vec<[f64; 2]> = (0..96)
        .map(|k| {
            let (s, c) = (f64::from(k) * 0.3).sin_cos();
            let r_m = 1.0 + f64::from(k % 20) * 0.1;
            [near.x_m + r_m * c, near.y_m + r_m * s]
        })
        .collect();
    group.bench_function("beside_m_96_points", |b| {
        b.iter(|| black_box(recovery::beside_m(black_box(&points), near)));
    });
    let tracks: Vec<Track> = (0..8)
        .map(|k| Track {
            x_m: near.x_m + f64::from(k) * 0.5,
            y_m: near.y_m + 1.0,
            vx_mps: 0.6,
            vy_mps: 0.1,
            age_s: 2.0,
            points_m: vec![[near.x_m + f64::from(k) * 0.5, near.y_m + 1.0]],
        })
        .collect();
    group.bench_function("walker_m_8_tracks", |b| {
        b.iter(|| black_box(recovery::walker_m(black_box(&tracks), near)));
    });
    group.finish();
}

criterion_group!(benches, bench_step);
criterion_main!(benches);
