//! How often the DLM of a kept plan (path reuse) is the DLM of a new search from the same pose,
//! and how often a new search agrees with a new search from other AMCL-sized jitter, for both
//! DLM measures on seven maps (issue 16; docs/benchmarks.md, "A DLM that holds"). A
//! measurement, not a check: run it with
//! `cargo test --release -p planning --test dlm_agreement -- --ignored --nocapture`
//! (`DLM_ROUTES`, default 30 routes per map; about a minute).

#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use std::sync::Arc;

use common::{along, estimate};
use planning::sample::sample_pairs;
use planning::{
    Answer, DlmMeasure, Goal, GoalProgress, IntentionConfig, IntentionPlanner, PlanningMap,
};
use protocol::{Dlm, Pose2D};

/// ±3 cm, ±0.03 rad of deterministic jitter, as the pipeline test's.
fn jittered(robot: Pose2D, phase: u64) -> Pose2D {
    let j = (phase as f64).sin();
    Pose2D::new(
        robot.x_m + 0.03 * j,
        robot.y_m - 0.03 * j,
        robot.yaw_rad + 0.03 * j,
    )
}

#[derive(Default)]
struct Tally {
    cycles: u32,
    kept_same: u32,
    new_same: u32,
    changes: u32,
    /// Changes of a DLM that had lasted at most 3 cycles (0.3 s).
    short: u32,
}

impl Tally {
    fn add(&mut self, o: &Tally) {
        self.cycles += o.cycles;
        self.kept_same += o.kept_same;
        self.new_same += o.new_same;
        self.changes += o.changes;
        self.short += o.short;
    }

    fn line(&self, name: &str) -> String {
        let pct = |n: u32| 100.0 * f64::from(n) / f64::from(self.cycles.max(1));
        format!(
            "| {name} | {} | {:.2} % | {:.2} % | {} | {} |",
            self.cycles,
            pct(self.kept_same),
            pct(self.new_same),
            self.changes,
            self.short
        )
    }
}

fn drive(map: &Arc<PlanningMap>, name: &str, routes: usize, measure: DlmMeasure) -> Tally {
    let mut config = IntentionConfig::default();
    config.dlm.measure = measure;
    config.reuse.enabled = false;
    let mut reuse = config.clone();
    reuse.reuse.enabled = true;
    let mut t = Tally::default();
    for (k, (start, end)) in sample_pairs(map, routes, 23, 6.0, name)
        .unwrap()
        .iter()
        .enumerate()
    {
        let mut fresh = IntentionPlanner::new(Arc::clone(map), config.clone()).unwrap();
        let mut kept = IntentionPlanner::new(Arc::clone(map), reuse.clone()).unwrap();
        let mut other = IntentionPlanner::new(Arc::clone(map), config.clone()).unwrap();
        let goals = [Goal::at(end.x_m, end.y_m)];
        let progress = GoalProgress::new(&goals, 0);
        let mut robot = *start;
        let (mut previous, mut lasted): (Option<Dlm>, u32) = (None, 0);
        for step in 0..600_u64 {
            let reported = jittered(robot, step * 7 + k as u64);
            let pose = estimate(reported, step);
            let (Answer::Heading { plan: Ok(a), .. }, Answer::Heading { plan: Ok(b), .. }) = (
                fresh.answer(&pose, &progress, false),
                kept.answer(&pose, &progress, false),
            ) else {
                break;
            };
            kept.refresh().unwrap();
            let other_pose = jittered(robot, step * 7 + k as u64 + 3);
            if let Answer::Heading { plan: Ok(c), .. } =
                other.answer(&estimate(other_pose, step), &progress, false)
            {
                t.new_same += u32::from(c.dlm == a.dlm);
            }
            t.cycles += 1;
            t.kept_same += u32::from(a.dlm == b.dlm);
            if previous.is_some_and(|p| p != a.dlm) {
                t.changes += 1;
                t.short += u32::from(lasted <= 3);
                lasted = 0;
            }
            lasted += 1;
            previous = Some(a.dlm);
            // 0.5 m/s at 10 Hz along the path the robot was sent.
            robot = along(&b.path, 0.05);
        }
    }
    t
}

#[test]
#[ignore = "a measurement for docs/benchmarks.md; about a minute in release"]
fn dlm_agreement_on_seven_maps() {
    let routes: usize = std::env::var("DLM_ROUTES")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(30);
    let scenario_maps = test_support::scenarios_dir().join("maps");
    let config = IntentionConfig::default();
    for measure in [
        DlmMeasure::Curvature,
        DlmMeasure::Heading,
        DlmMeasure::Route,
        DlmMeasure::FirstTurn,
    ] {
        println!(
            "\n{} measure, {routes} routes per map\n\n| map | cycles | kept plan = new search | new search = new search, other jitter | DLM changes | after at most 0.3 s |\n|---|---|---|---|---|---|",
            measure.as_str()
        );
        let mut all = Tally::default();
        for name in [
            "depot",
            "warehouse",
            "hospital",
            "junctions",
            "campus",
            "hall",
            "corridor",
        ] {
            let grid = if matches!(name, "depot" | "warehouse") {
                test_support::nav2_map(name)
            } else {
                map_core::load_ros_map(
                    &scenario_maps.join(format!("{name}.yaml")),
                    &map_core::ImportLimits::default(),
                )
                .unwrap()
                .grid
            };
            let map = Arc::new(PlanningMap::new(grid, &config.planner).unwrap());
            let t = drive(&map, name, routes, measure);
            println!("{}", t.line(name));
            all.add(&t);
        }
        println!("{}", all.line("all"));
    }
}
