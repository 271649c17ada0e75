//! What the DLM benchmarks share: a scenario's floor plan prepared for planning, the paths the
//! intention pipeline answers along a drive, and a DLM rule timed off and on.

use std::sync::Arc;

use criterion::Criterion;
use map_store::{load_ros_map, ImportLimits};
use planning::intention::dlm_on_map;
use planning::{Answer, Disc, Goal, GoalProgress, IntentionConfig, IntentionPlanner, PlanningMap};
use protocol::Pose2D;

/// Scenario map `name` (sim/scenarios/maps) prepared with the default planner configuration.
pub fn scenario_map(name: &str) -> Arc<PlanningMap> {
    let path = test_support::scenarios_dir().join(format!("maps/{name}.yaml"));
    let ros = load_ros_map(&path, &ImportLimits::default()).expect("map loads");
    Arc::new(PlanningMap::new(ros.grid, &IntentionConfig::default().planner).expect("map prepares"))
}

/// The discs the intention pipeline keeps out of round `points` (map frame, m) the laser sees,
/// at the default `[seen_obstacles] radius_m`.
// Each bench compiles this module on its own; the turn round's sees nothing.
#[allow(dead_code)]
pub fn seen_discs(points: &[[f64; 2]]) -> Vec<Disc> {
    let radius_m = IntentionConfig::default().seen.radius_m;
    points
        .iter()
        .map(|&[x_m, y_m]| Disc { x_m, y_m, radius_m })
        .collect()
}

/// The path a fresh intention pipeline with `config` answers to a robot at each of `poses`
/// (sequence number, pose) on its way to `goals` on scenario map `map_name`, its laser seeing
/// `obstacles` (map frame, m) the floor plan lacks.
pub fn answered(
    map: &Arc<PlanningMap>,
    map_name: &str,
    config: IntentionConfig,
    goals: &[Goal],
    poses: impl Iterator<Item = (u64, Pose2D)>,
    obstacles: &[[f64; 2]],
) -> Vec<(Pose2D, Vec<Pose2D>)> {
    let mut planner = IntentionPlanner::new(Arc::clone(map), config).expect("planner");
    let progress = GoalProgress::new(goals, 0);
    poses
        .map(|(seq, pose)| {
            let estimate =
                test_support::fixtures::pose_estimate(map_name, pose, seq, obstacles.to_vec());
            match planner.answer(&estimate, &progress, false) {
                Answer::Heading { plan, .. } => (pose, plan.expect("a plan").path),
                Answer::Done => panic!("done at {pose:?}"),
            }
        })
        .collect()
}

/// A DLM rule timed with each of `settings` (name, configuration; the rule off and on) in the
/// criterion group `group_name`: `dlm_on_map_x21_<name>` the DLM alone over the `answered`
/// drive's paths (towards `goal`, the laser seeing `seen`), `answers_x21_<name>` the whole drive
/// through the intention pipeline (`drive`).
pub fn rule_off_on<T>(
    c: &mut Criterion,
    group_name: &str,
    map: &PlanningMap,
    answered: &[(Pose2D, Vec<Pose2D>)],
    (goal, seen): (Pose2D, &[Disc]),
    settings: [(&str, IntentionConfig); 2],
    drive: impl Fn(IntentionConfig) -> T,
) {
    let mut group = c.benchmark_group(group_name);
    group.sample_size(20);
    for (name, config) in &settings {
        group.bench_function(format!("dlm_on_map_x21_{name}"), |b| {
            b.iter(|| {
                let mut previous = None;
                for (robot, path) in answered {
                    previous = Some(dlm_on_map(
                        map,
                        path,
                        *robot,
                        goal,
                        &config.dlm,
                        previous,
                        seen,
                    ));
                }
                previous
            });
        });
    }
    for (name, config) in &settings {
        group.bench_function(format!("answers_x21_{name}"), |b| {
            b.iter(|| drive(config.clone()));
        });
    }
    group.finish();
}
