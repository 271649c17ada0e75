//! Criterion benchmark of the DLM's turn beside a seen obstacle measured on the path (planner
//! `[dlm] sidestep_over_turn_rad`, round 55) where it acts: a robot comes south along x 7.85
//! past task D's cabinet by the room's door (sim/scenarios/maps/campus, 0.5 × 1 m at (8.6, 8.0))
//! on its way east to (12, 6), answered every 0.15 m over 3 m, with the rule off (0) and on
//! (π, the default) in the same run. `dlm_on_map_*` times the DLM alone over the 21 answered
//! paths (the rule adds, where the route's measure tells a turn there, the measure once more
//! without the previous move and once on the path); `answers_*` times the whole walk through
//! the intention pipeline, a fresh planner each time (its searches round the cabinet, and to a
//! goal without a heading, included).

// A benchmark harness has no caller to hand errors to: failing loudly is the intent.
#![allow(clippy::expect_used, clippy::unwrap_used)]

mod common;

use criterion::{criterion_group, criterion_main, Criterion};
use planning::{Goal, IntentionConfig};
use protocol::Pose2D;

/// The cabinet's west and south faces, as the agent's obstacle layer reports them: points
/// 0.1 m apart.
fn cabinet_points() -> Vec<[f64; 2]> {
    let mut points: Vec<[f64; 2]> = (0..=10).map(|j| [8.35, 7.5 + 0.1 * f64::from(j)]).collect();
    points.extend((1..=5).map(|i| [8.35 + 0.1 * f64::from(i), 7.5]));
    points
}

/// The walk: from y 10.5 to 7.5 (level with the cabinet's south face), heading south.
fn walk() -> impl Iterator<Item = (u64, Pose2D)> {
    (0..=20_u32).map(|k| {
        (
            u64::from(k) + 1,
            Pose2D::new(7.85, 10.5 - 0.15 * f64::from(k), -1.62),
        )
    })
}

fn config(sidestep_over_turn_rad: f64) -> IntentionConfig {
    let mut config = IntentionConfig::default();
    config.dlm.sidestep_over_turn_rad = sidestep_over_turn_rad;
    config
}

fn over_turn(c: &mut Criterion) {
    let map = common::scenario_map("campus");
    let goals = [Goal::at(12.0, 6.0)];
    let goal = Pose2D::new(12.0, 6.0, 0.0);
    let cabinet = cabinet_points();
    let drive = |config: IntentionConfig| {
        common::answered(&map, "campus", config, &goals, walk(), &cabinet)
    };
    let answered = drive(config(std::f64::consts::PI));
    let seen = common::seen_discs(&cabinet);
    common::rule_off_on(
        c,
        "over_turn_campus_door_cabinet",
        &map,
        &answered,
        (goal, &seen),
        [("off", config(0.0)), ("on", config(std::f64::consts::PI))],
        drive,
    );
}

criterion_group!(benches, over_turn);
criterion_main!(benches);
