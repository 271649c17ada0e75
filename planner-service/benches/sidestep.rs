//! Criterion benchmark of the DLM's sidestep (planner `[dlm] sidestep_ahead_m`, round 51) on its
//! hot path: a robot on the corridor's centre line (sim/scenarios/maps/corridor) drives up to a
//! cabinet its laser sees, answered every 0.2 m, with the rule off (0) and on (2.0, the
//! default) in the same run. `dlm_on_*` times the DLM alone over the approach's 21 answered
//! paths (the rule adds a check of the path and, near the cabinet, a second floor-plan route);
//! `answers_*` times the whole approach through the intention pipeline, a fresh planner each
//! time (its searches round the cabinet included).

// A benchmark harness has no caller to hand errors to: failing loudly is the intent.
#![allow(clippy::expect_used, clippy::unwrap_used)]

mod common;

use criterion::{criterion_group, criterion_main, Criterion};
use planning::{Goal, IntentionConfig};
use protocol::Pose2D;

/// The face and sides of a cabinet standing out from the corridor's north wall to its centre
/// line (x 11.6..12.4), as the agent's obstacle layer reports it: points 0.1 m apart.
fn cabinet_points() -> Vec<[f64; 2]> {
    let mut points: Vec<[f64; 2]> = (0..=8).map(|i| [11.6 + 0.1 * f64::from(i), 5.2]).collect();
    for j in 1..=10 {
        let y = 5.2 + 0.1 * f64::from(j);
        points.push([11.6, y]);
        points.push([12.4, y]);
    }
    points
}

/// The approach: 4.6 m to 0.6 m short of the cabinet's face, heading east on y 5.2.
fn approach() -> impl Iterator<Item = (u64, Pose2D)> {
    (0..=20_u32).map(|k| {
        (
            u64::from(k) + 1,
            Pose2D::new(7.0 + 0.2 * f64::from(k), 5.2, 0.0),
        )
    })
}

fn config(sidestep_ahead_m: f64) -> IntentionConfig {
    let mut config = IntentionConfig::default();
    config.dlm.sidestep_ahead_m = sidestep_ahead_m;
    config
}

fn sidestep(c: &mut Criterion) {
    let map = common::scenario_map("corridor");
    let goals = [Goal::at(25.5, 5.2)];
    let goal = Pose2D::new(25.5, 5.2, 0.0);
    let cabinet = cabinet_points();
    let drive = |config: IntentionConfig| {
        common::answered(&map, "corridor", config, &goals, approach(), &cabinet)
    };
    let answered = drive(config(2.0));
    let seen = common::seen_discs(&cabinet);

    common::rule_off_on(
        c,
        "sidestep_corridor_cabinet",
        &map,
        &answered,
        (goal, &seen),
        [("off", config(0.0)), ("on", config(2.0))],
        drive,
    );
}

criterion_group!(benches, sidestep);
criterion_main!(benches);
