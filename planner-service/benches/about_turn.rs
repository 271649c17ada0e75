//! Criterion benchmark of the DLM's turn round (planner `[dlm] about_turn_rad`, round 53) where
//! it acts: a robot that has reached task E's goal 3 (sim/scenarios/maps/maze, at (12.19, 9.5)
//! heading west) turns on the spot towards the next leg, which starts behind it, answered every
//! 0.1 rad over 2 rad of the turn, with the rule off (0) and on (2.6, the default) in the same
//! run. `dlm_on_map_*` times the DLM alone over the 21 answered paths (the rule adds, while the
//! route's first piece lies 150° or more off the heading, two fans of five rays over the
//! distance field); `answers_*` times the whole turn through the intention pipeline, a fresh
//! planner each time.

// A benchmark harness has no caller to hand errors to: failing loudly is the intent.
#![allow(clippy::expect_used, clippy::unwrap_used)]

mod common;

use criterion::{criterion_group, criterion_main, Criterion};
use planning::intention::dlm_on_map;
use planning::{DlmParams, Goal, IntentionConfig};
use protocol::Pose2D;

/// The turn: from heading west (-3.0 rad) 2 rad clockwise, every 0.1 rad.
fn turn() -> impl Iterator<Item = (u64, Pose2D)> {
    (0..=20_u32).map(|k| {
        (
            u64::from(k) + 1,
            Pose2D::new(12.19, 9.5, -3.0 - 0.1 * f64::from(k)),
        )
    })
}

fn config(about_turn_rad: f64) -> IntentionConfig {
    let mut config = IntentionConfig::default();
    config.dlm.about_turn_rad = about_turn_rad;
    config
}

fn about_turn(c: &mut Criterion) {
    let base = IntentionConfig::default();
    let map = common::scenario_map("maze");
    let goals = [Goal::at(1.6, 17.2)];
    let goal = Pose2D::new(1.6, 17.2, 0.0);
    let drive =
        |config: IntentionConfig| common::answered(&map, "maze", config, &goals, turn(), &[]);
    let answered = drive(config(2.6));

    let mut group = c.benchmark_group("about_turn_maze_goal_3");
    group.sample_size(20);
    for (name, about_rad) in [("off", 0.0), ("on", 2.6)] {
        let params = DlmParams {
            about_turn_rad: about_rad,
            ..base.dlm.clone()
        };
        group.bench_function(format!("dlm_on_map_x21_{name}"), |b| {
            b.iter(|| {
                let mut previous = None;
                for (robot, path) in &answered {
                    previous = Some(dlm_on_map(&map, path, *robot, goal, &params, previous, &[]));
                }
                previous
            });
        });
    }
    for (name, about_rad) in [("off", 0.0), ("on", 2.6)] {
        group.bench_function(format!("answers_x21_{name}"), |b| {
            b.iter(|| drive(config(about_rad)));
        });
    }
    group.finish();
}

criterion_group!(benches, about_turn);
criterion_main!(benches);
