//! The intention pipeline on a real Nav2 map: a pose in, the intention for a task's goals out,
//! as the fleet service and the evaluation call it.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::sync::Arc;

use planning::sample::sample_pairs;
use planning::{Answer, Goal, GoalProgress, IntentionConfig, IntentionPlanner, PlanningMap};
use protocol::{Dlm, Header, MapName, MapRef, Pose2D, PoseEstimate, TaskId};

fn estimate(pose: Pose2D, seq: u64) -> PoseEstimate {
    PoseEstimate {
        header: Header::new(seq, 1_000 + seq),
        pose,
        covariance: [0.0; 9],
        sensor_stamp_ns: 1_000 + seq,
        map: MapRef {
            name: MapName::new("depot").unwrap(),
            version: 1,
        },
    }
}

fn pipeline() -> (IntentionPlanner, Vec<(Pose2D, Pose2D)>) {
    let config = IntentionConfig::default();
    let map = Arc::new(PlanningMap::new(test_support::nav2_map("depot"), &config.planner).unwrap());
    let pairs = sample_pairs(&map, 8, 11, 6.0, "depot").unwrap();
    (IntentionPlanner::new(map, config).unwrap(), pairs)
}

#[test]
fn a_pose_is_answered_with_a_thinned_path_to_the_next_goal_then_done_at_the_last() {
    let (mut pipeline, pairs) = pipeline();
    let spacing_m = pipeline.config().path_spacing_m;
    let tolerance_m = pipeline.config().goal_tolerance_m;
    let mut answered = 0;
    for (k, (start, end)) in pairs.iter().enumerate() {
        let goals = [Goal::at(end.x_m, end.y_m)];
        let pose = estimate(*start, k as u64);
        let Answer::Heading { goal_index, plan } =
            pipeline.answer(&pose, &GoalProgress::new(&goals, 0), false)
        else {
            panic!("a start {start:?} far from the goal is not done");
        };
        assert_eq!(goal_index, 0);
        let Ok(planned) = plan else { continue };
        answered += 1;
        // The path runs from the robot to the goal, thinned to the spacing (turns kept).
        let (first, last) = (planned.path[0], *planned.path.last().unwrap());
        assert!(first.distance_m(start) < 1e-6, "{first:?} vs {start:?}");
        assert!(
            (last.x_m - end.x_m).hypot(last.y_m - end.y_m) < 0.5,
            "{last:?} vs {end:?}"
        );
        assert!(planned.length_m >= start.distance_m(end) - 1e-6);
        for w in planned
            .path
            .windows(2)
            .take(planned.path.len().saturating_sub(2))
        {
            let turned = protocol::normalize_angle(w[1].yaw_rad - w[0].yaw_rad).abs();
            assert!(
                w[0].distance_m(&w[1]) >= spacing_m - 1e-6 || turned >= 0.2 - 1e-9,
                "thinned path keeps only spaced poses and turns: {w:?}"
            );
        }
        assert!(planned.lpe.is_none(), "no LPE image unless asked");
        assert_ne!(planned.dlm, Dlm::Stop, "6 m from the goal is no stop");
        // The intention answers that pose and carries the image only when asked.
        let task = Some(TaskId::new("t-000001").unwrap());
        let i = planned.intention(Header::new(9, 9), &pose, task.clone(), 0, true);
        assert_eq!(
            (i.answers_pose_seq, i.answers_pose_stamp_ns),
            (pose.header.seq, pose.header.stamp_ns)
        );
        assert_eq!((i.task_id, i.goal_index, &i.path), (task, 0, &planned.path));
        assert!(i.lpe.is_none());

        // At the goal: done.
        let at_goal = estimate(Pose2D::new(end.x_m + 0.5 * tolerance_m, end.y_m, 0.0), 99);
        assert_eq!(
            pipeline.answer(&at_goal, &GoalProgress::new(&goals, 0), false),
            Answer::Done
        );
    }
    assert!(
        answered >= 6,
        "most sampled pairs are reachable: {answered}/8"
    );
}

#[test]
fn lpe_images_are_rendered_when_asked_and_reach_the_wire_only_when_sent() {
    let (mut pipeline, pairs) = pipeline();
    let (start, end) = pairs
        .iter()
        .copied()
        .find(|(s, e)| {
            let goals = [Goal::at(e.x_m, e.y_m)];
            matches!(
                pipeline.answer(&estimate(*s, 0), &GoalProgress::new(&goals, 0), false),
                Answer::Heading { plan: Ok(_), .. }
            )
        })
        .unwrap();
    let goals = [Goal::at(end.x_m, end.y_m)];
    let pose = estimate(start, 1);
    let Answer::Heading {
        plan: Ok(planned), ..
    } = pipeline.answer(&pose, &GoalProgress::new(&goals, 0), true)
    else {
        panic!("the same pose plans again");
    };
    let lpe = planned.lpe.as_ref().expect("rendered when asked");
    let size = pipeline.config().lpe.size_px;
    assert_eq!(lpe.image.dimensions(), (size, size));
    let sent = planned.intention(Header::default(), &pose, None, 0, true);
    let image = sent.lpe.expect("sent when asked");
    assert_eq!((image.width_px, image.height_px), (size, size));
    assert!(planned
        .intention(Header::default(), &pose, None, 0, false)
        .lpe
        .is_none());
}

#[test]
fn a_bad_configuration_is_refused_with_its_field() {
    let config = IntentionConfig {
        goal_tolerance_m: -1.0,
        ..IntentionConfig::default()
    };
    let map = Arc::new(PlanningMap::new(test_support::nav2_map("depot"), &config.planner).unwrap());
    let err = IntentionPlanner::new(map, config).err().expect("refused");
    assert!(err.to_string().contains("goal_tolerance_m"), "{err}");
}
