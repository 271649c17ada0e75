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
use planning::{Goal, IntentionConfig};
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
    let map = common::scenario_map("maze");
    let goals = [Goal::at(1.6, 17.2)];
    let goal = Pose2D::new(1.6, 17.2, 0.0);
    let drive =
        |config: IntentionConfig| common::answered(&map, "maze", config, &goals, turn(), &[]);
    let answered = drive(config(2.6));
    common::rule_off_on(
        c,
        "about_turn_maze_goal_3",
        &map,
        &answered,
        (goal, &[]),
        [("off", config(0.0)), ("on", config(2.6))],
        drive,
    );
}

criterion_group!(benches, about_turn);
criterion_main!(benches);
