//! What the DLM benchmarks share: a scenario's floor plan prepared for planning, and the paths
//! the intention pipeline answers along a drive.

use std::sync::Arc;

use map_store::{load_ros_map, ImportLimits};
use planning::{Answer, Goal, GoalProgress, IntentionConfig, IntentionPlanner, PlanningMap};
use protocol::Pose2D;

/// Scenario map `name` (sim/scenarios/maps) prepared with the default planner configuration.
pub fn scenario_map(name: &str) -> Arc<PlanningMap> {
    let path = test_support::scenarios_dir().join(format!("maps/{name}.yaml"));
    let ros = load_ros_map(&path, &ImportLimits::default()).expect("map loads");
    Arc::new(PlanningMap::new(ros.grid, &IntentionConfig::default().planner).expect("map prepares"))
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
