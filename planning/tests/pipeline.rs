//! The intention pipeline on a real Nav2 map: a pose in, the intention for a task's goals out,
//! as the fleet service and the evaluation call it.

#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use std::sync::Arc;

use common::{along, estimate};
use planning::sample::sample_pairs;
use planning::{
    Answer, DlmMeasure, DlmParams, Goal, GoalProgress, IntentionConfig, IntentionPlanner,
    Neighbour, PlanningMap,
};
use protocol::{Dlm, Header, Pose2D, TaskId};

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

/// What one drive of the test's six depot routes measured.
struct Agreement {
    cycles: u32,
    same_dlm: u32,
    same_reference: u32,
    reused: u32,
    /// Per cycle, the share of the LPE image's pixels that differ between the two answers.
    lpe_differs: Vec<f64>,
}

impl Agreement {
    fn same(&self) -> f64 {
        f64::from(self.same_dlm) / f64::from(self.cycles)
    }

    fn repeatable(&self) -> f64 {
        f64::from(self.same_reference) / f64::from(self.cycles)
    }
}

/// Drives six depot routes with path reuse and, at every cycle, answers the same pose with a
/// new search too (and a new search from other jitter, the reference's own repeatability).
fn kept_against_new(dlm: DlmParams) -> Agreement {
    let mut fresh_config = IntentionConfig {
        dlm,
        ..IntentionConfig::default()
    };
    fresh_config.reuse.enabled = false;
    let mut reuse_config = fresh_config.clone();
    reuse_config.reuse.enabled = true;
    let map =
        Arc::new(PlanningMap::new(test_support::nav2_map("depot"), &fresh_config.planner).unwrap());
    let pairs = sample_pairs(&map, 6, 23, 6.0, "depot").unwrap();
    let mut fresh = IntentionPlanner::new(Arc::clone(&map), fresh_config.clone()).unwrap();
    let mut kept = IntentionPlanner::new(Arc::clone(&map), reuse_config).unwrap();
    // The reference's own repeatability: a second new search every cycle from the same true
    // pose with other jitter of the same size.
    let mut other = IntentionPlanner::new(Arc::clone(&map), fresh_config.clone()).unwrap();
    let (mut cycles, mut same_dlm, mut reused) = (0_u32, 0_u32, 0_u32);
    let mut same_reference = 0_u32;
    let mut lpe_differs: Vec<f64> = Vec::new();
    for (k, (start, end)) in pairs.iter().enumerate() {
        let goals = [Goal::at(end.x_m, end.y_m)];
        let progress = GoalProgress::new(&goals, 0);
        let mut robot = *start;
        for step in 0..400_u64 {
            // AMCL-like jitter on the pose the robot reports (deterministic).
            let jitter = ((step * 7 + k as u64) as f64).sin();
            let reported = Pose2D::new(
                robot.x_m + 0.03 * jitter,
                robot.y_m - 0.03 * jitter,
                robot.yaw_rad + 0.03 * jitter,
            );
            let pose = estimate(reported, step);
            let (Answer::Heading { plan: a, .. }, Answer::Heading { plan: b, .. }) = (
                fresh.answer(&pose, &progress, true),
                kept.answer(&pose, &progress, true),
            ) else {
                break;
            };
            let (Ok(a), Ok(b)) = (a, b) else { break };
            if let (Some(la), Some(lb)) = (&a.lpe, &b.lpe) {
                lpe_differs.push(differing_share(&la.image, &lb.image));
            }
            // As the fleet's workers do once the answer has gone out.
            kept.refresh().unwrap();
            cycles += 1;
            same_dlm += u32::from(a.dlm == b.dlm);
            reused += u32::from(b.reused);
            let jitter = ((step * 7 + k as u64 + 3) as f64).sin();
            let other_pose = Pose2D::new(
                robot.x_m + 0.03 * jitter,
                robot.y_m - 0.03 * jitter,
                robot.yaw_rad + 0.03 * jitter,
            );
            if let Answer::Heading { plan: Ok(c), .. } =
                other.answer(&estimate(other_pose, step), &progress, false)
            {
                same_reference += u32::from(c.dlm == a.dlm);
            }
            assert!(!a.reused, "the reference searches every cycle");
            assert!(
                b.path[0].distance_m(&reported) < 1e-9,
                "the path starts at the robot"
            );
            // A search may find a shortcut that only shows from further along; max_cycles
            // bounds how long a kept route stays this much longer.
            assert!(
                b.length_m <= 2.0 * a.length_m + 1.0,
                "kept route {:.1} m against a new search's {:.1} m",
                b.length_m,
                a.length_m
            );
            // 0.5 m/s at 10 Hz along the path the robot was sent.
            robot = along(&b.path, 0.05);
        }
    }
    Agreement {
        cycles,
        same_dlm,
        same_reference,
        reused,
        lpe_differs,
    }
}

#[test]
fn a_kept_plan_answers_like_a_new_search_while_the_robot_follows_it() {
    let Agreement {
        cycles,
        same_dlm,
        same_reference,
        reused,
        mut lpe_differs,
    } = kept_against_new(DlmParams::curvature());
    println!(
        "{cycles} cycles: same DLM {same_dlm}, kept plan answered {reused}, \
         a new search with other jitter gives the same DLM in {same_reference}"
    );
    lpe_differs.sort_by(f64::total_cmp);
    let lpe_mean = lpe_differs.iter().sum::<f64>() / lpe_differs.len() as f64;
    let lpe_p99 = lpe_differs[lpe_differs.len() * 99 / 100];
    println!(
        "LPE image: {:.2} % of pixels differ on average, {:.2} % at the 99th percentile, {:.2} % at most",
        100.0 * lpe_mean,
        100.0 * lpe_p99,
        100.0 * lpe_differs[lpe_differs.len() - 1]
    );
    assert!(cycles > 300, "{cycles} cycles");
    assert_eq!(
        lpe_differs.len(),
        cycles as usize,
        "every answer has its image"
    );
    // Measured 2026-11-26: see docs/benchmarks.md, "Path reuse".
    assert!(
        lpe_mean < 0.02,
        "LPE images differ in {lpe_mean:.4} of pixels"
    );
    let same = f64::from(same_dlm) / f64::from(cycles);
    let repeatable = f64::from(same_reference) / f64::from(cycles);
    let kept_share = f64::from(reused) / f64::from(cycles);
    // Measured 0.962 (1263 of 1313 cycles) against 0.957 (1257) for the reference against
    // itself since the due search runs after the answer (2026-11-26; the robot drives another
    // trajectory); 0.980 (1263 of 1289) against 0.974 (1256) before, and 0.952 against 0.955
    // before the kept path rejoined 0.5 m ahead. Nearly all
    // differences are curvatures within ±0.1/m of the 0.3/m turn threshold, where 3 cm /
    // 0.03 rad of jitter flips a new search's DLM as often as reuse does (docs/benchmarks.md,
    // "Path reuse"). Issue 16's 0.99 is above the reference's own agreement.
    assert!(same >= 0.93, "same DLM in {same:.3} of {cycles} cycles");
    assert!(
        same >= repeatable - 0.01,
        "reuse agrees with a new search in {same:.3}, a new search with itself in {repeatable:.3}"
    );
    assert!(
        kept_share >= 0.8,
        "kept plan answered {kept_share:.3} of {cycles} cycles"
    );
}

/// Issue 16's measure with the heading DLM (planning `DlmMeasure::Heading`): the direction of
/// the route 1-2 m ahead with hysteresis, instead of one point's bearing.
#[test]
fn with_the_heading_dlm_a_kept_plan_gives_the_dlm_of_a_new_search_as_often_as_a_new_search_does() {
    let heading = kept_against_new(DlmParams::heading());
    println!(
        "heading DLM, {} cycles: same as a new search {}, a new search with other jitter {}",
        heading.cycles, heading.same_dlm, heading.same_reference
    );
    // Measured 2026-11-27: 1 313 of 1 313 (kept = new) and 1 309 (new = new) on these six
    // routes; over 210 routes on seven maps 98.8 % and 98.9 % (docs/benchmarks.md, "A DLM
    // that holds"). With paths kept to the middle of passages (planning::centring, the
    // default since the fourteenth session) 1 277 and 1 275 of 1 291: a kept plan agrees with
    // a new search as often as a new search with itself, and that is now just under 99 %.
    assert!(heading.cycles > 300, "{} cycles", heading.cycles);
    assert!(
        heading.same() >= 0.985 && heading.same() >= heading.repeatable() - 0.005,
        "same DLM in {:.3} of {} cycles, a new search with itself {:.3}",
        heading.same(),
        heading.cycles,
        heading.repeatable()
    );
    assert!(
        heading.repeatable() >= 0.98,
        "a new search with itself: {:.3}",
        heading.repeatable()
    );
}

/// With the route DLM (planning `DlmMeasure::Route`) the DLM comes from the floor plan's route
/// from the robot, so a kept plan gives exactly the DLM of a new search from the same pose.
#[test]
fn with_the_route_dlm_a_kept_plan_gives_the_dlm_of_a_new_search_in_every_cycle() {
    let route = kept_against_new(DlmParams {
        measure: DlmMeasure::Route,
        ..DlmParams::heading()
    });
    println!(
        "route DLM, {} cycles: same as a new search {}, a new search with other jitter {}",
        route.cycles, route.same_dlm, route.same_reference
    );
    assert!(route.cycles > 300, "{} cycles", route.cycles);
    assert_eq!(route.same_dlm, route.cycles);
    assert!(
        route.repeatable() >= 0.98,
        "a new search with itself: {:.3}",
        route.repeatable()
    );
}

/// A kept path is answered from the robot straight to the pose `rejoin_m` along the path past
/// the robot's nearest one: a shallow merge, as a new search curves out of the robot's heading,
/// not a sideways step at the robot (which the LPE image would draw).
#[test]
fn a_kept_path_rejoins_ahead_of_the_robot() {
    let config = IntentionConfig::default();
    let map = Arc::new(PlanningMap::new(test_support::nav2_map("depot"), &config.planner).unwrap());
    let (start, end) = sample_pairs(&map, 1, 5, 6.0, "depot").unwrap()[0];
    let mut planner = planning::Planner::new(Arc::clone(&map), config.planner.clone()).unwrap();
    let poses = planner.plan(start, end).unwrap().poses;
    let near = poses[10];
    // 5 cm to the left of the path, same heading.
    let robot = Pose2D::new(
        near.x_m - 0.05 * near.yaw_rad.sin(),
        near.y_m + 0.05 * near.yaw_rad.cos(),
        near.yaw_rad,
    );
    let along_from_near = |p: &Pose2D| -> f64 {
        let i = poses.iter().position(|q| q == p).unwrap();
        poses[10..=i]
            .windows(2)
            .map(|w| w[0].distance_m(&w[1]))
            .sum()
    };
    for (rejoin_m, want_m) in [(0.5, 0.5), (0.0, 0.0)] {
        let params = planning::ReuseParams {
            enabled: true,
            rejoin_m,
            ..planning::ReuseParams::default()
        };
        let mut kept = planning::intention::KeptPlan::new(map.key(), end, false, poses.clone());
        let rest = kept.follow(&map, robot, end, false, &params).unwrap().poses;
        assert_eq!(rest[0], robot);
        let ahead = along_from_near(&rest[1]);
        assert!(
            ahead >= want_m && ahead < want_m + 0.2,
            "rejoins {ahead} m ahead"
        );
        assert_eq!(rest.last(), poses.last());
    }
    let bad = planning::ReuseParams {
        rejoin_m: -1.0,
        ..planning::ReuseParams::default()
    };
    assert!(bad
        .validate()
        .unwrap_err()
        .to_string()
        .contains("reuse.rejoin_m"));
}

#[test]
fn a_kept_plan_is_dropped_off_its_corridor_for_a_new_goal_and_searched_again_after_max_cycles() {
    let mut config = IntentionConfig::default();
    config.reuse.enabled = true;
    config.reuse.max_cycles = 3;
    let map = Arc::new(PlanningMap::new(test_support::nav2_map("depot"), &config.planner).unwrap());
    let (start, end) = sample_pairs(&map, 1, 5, 6.0, "depot").unwrap()[0];
    let mut p = IntentionPlanner::new(Arc::clone(&map), config).unwrap();
    let goals = [Goal::at(end.x_m, end.y_m)];
    let plan = planned;
    let first = plan(&mut p, start, &goals);
    assert!(!first.reused, "the first answer is a search");
    let on_path = along(&first.path, 0.1);
    // Three reused answers, then a search (max_cycles = 3).
    let kinds: Vec<bool> = (0..4)
        .map(|_| plan(&mut p, on_path, &goals).reused)
        .collect();
    assert_eq!(kinds, [true, true, true, false]);
    assert!(plan(&mut p, on_path, &goals).reused);
    // The due search run after the third answer, off the answer's path: the fourth is
    // answered from the new plan.
    assert!(!p.refresh().unwrap(), "no search is due after one answer");
    assert_eq!(
        (0..2)
            .map(|_| plan(&mut p, on_path, &goals).reused)
            .collect::<Vec<_>>(),
        [true, true]
    );
    assert!(
        p.refresh().unwrap(),
        "three answers in a row: the search ran"
    );
    assert!(!p.refresh().unwrap(), "and is not due again");
    let after = (0..3)
        .map(|_| plan(&mut p, on_path, &goals).reused)
        .collect::<Vec<_>>();
    assert_eq!(after, [true, true, true], "every answer from a plan");
    assert!(p.refresh().unwrap());
    // Turned around: off the corridor's heading.
    let turned = Pose2D::new(on_path.x_m, on_path.y_m, on_path.yaw_rad + 2.0);
    assert!(!plan(&mut p, turned, &goals).reused);
    assert!(
        plan(&mut p, turned, &goals).reused,
        "the new search is kept"
    );
    // Another goal: a new search.
    let other = [Goal::at(start.x_m, start.y_m)];
    let far = along(&first.path, 1.0);
    assert!(!plan(&mut p, far, &other).reused);
    // A bad corridor is refused with its field.
    let mut bad = IntentionConfig::default();
    bad.reuse.corridor_m = f64::NAN;
    let err = IntentionPlanner::new(map, bad).err().expect("refused");
    assert!(err.to_string().contains("reuse.corridor_m"), "{err}");
}

/// A due search taken out of the pipeline runs elsewhere while the kept plan answers on; its
/// result replaces the plan it refreshes, but not one searched since.
#[test]
fn a_due_search_runs_off_the_pipeline_and_only_refreshes_the_plan_it_was_taken_from() {
    let mut config = IntentionConfig::default();
    config.reuse.enabled = true;
    config.reuse.max_cycles = 2;
    let map = Arc::new(PlanningMap::new(test_support::nav2_map("depot"), &config.planner).unwrap());
    let (start, end) = sample_pairs(&map, 1, 5, 6.0, "depot").unwrap()[0];
    let mut p = IntentionPlanner::new(Arc::clone(&map), config.clone()).unwrap();
    let mut elsewhere = planning::Planner::new(Arc::clone(&map), config.planner.clone()).unwrap();
    let goals = [Goal::at(end.x_m, end.y_m)];
    let plan = |p: &mut IntentionPlanner, pose: Pose2D| planned(p, pose, &goals);
    let first = plan(&mut p, start);
    let on_path = along(&first.path, 0.1);
    assert!(plan(&mut p, on_path).reused);
    assert!(p.take_refresh().is_none(), "one answer: nothing due");
    assert!(plan(&mut p, on_path).reused);
    let job = p
        .take_refresh()
        .expect("two answers in a row: a search is due");
    assert!(p.take_refresh().is_none(), "taken once");
    // While it runs elsewhere, the kept plan answers beyond max_cycles.
    for _ in 0..4 {
        assert!(plan(&mut p, on_path).reused);
    }
    let refreshed = job.run(&mut elsewhere);
    p.adopt(refreshed).unwrap();
    assert!(plan(&mut p, on_path).reused, "the new plan answers");

    // A search taken, then the robot turns off the corridor: the answer searches anew, and
    // the stale result does not replace that plan.
    assert!(plan(&mut p, on_path).reused);
    let stale = p.take_refresh().expect("due again");
    let turned = Pose2D::new(on_path.x_m, on_path.y_m, on_path.yaw_rad + 2.0);
    assert!(!plan(&mut p, turned).reused);
    let from_turned = plan(&mut p, turned);
    assert!(from_turned.reused);
    p.adopt(stale.run(&mut elsewhere)).unwrap();
    let after = plan(&mut p, turned);
    assert!(
        after.reused,
        "the stale plan, off the corridor here, would search"
    );
    assert_eq!(after.path, from_turned.path);
}

/// The share of pixels whose colour differs between two images of the same size.
fn differing_share(a: &image::RgbImage, b: &image::RgbImage) -> f64 {
    assert_eq!(a.dimensions(), b.dimensions());
    let differ = a.pixels().zip(b.pixels()).filter(|(p, q)| p != q).count();
    differ as f64 / f64::from(a.width() * a.height())
}

/// The pipeline's plan for `pose` heading for the first of `goals`.
fn planned(p: &mut IntentionPlanner, pose: Pose2D, goals: &[Goal]) -> planning::Planned {
    match p.answer(&estimate(pose, 0), &GoalProgress::new(goals, 0), false) {
        Answer::Heading { plan, .. } => plan.unwrap(),
        Answer::Done => panic!("not done at {pose:?}"),
    }
}

/// The corridor of the parked-robot scenario (sim/scenarios/behaviour_robot_parked.yaml): the
/// robot starts at (2, 5.2) facing a goal at (25.5, 5.2) down the corridor.
fn corridor_planner() -> IntentionPlanner {
    let config = IntentionConfig::default();
    IntentionPlanner::new(scenario_map("corridor", &config), config).unwrap()
}

/// A floor plan of the scenarios (`sim/scenarios/maps/<name>.yaml`), ready for `config`.
fn scenario_map(name: &str, config: &IntentionConfig) -> Arc<PlanningMap> {
    let grid = map_core::load_ros_map(
        &test_support::scenarios_dir().join(format!("maps/{name}.yaml")),
        &map_core::ImportLimits::default(),
    )
    .unwrap()
    .grid;
    Arc::new(PlanningMap::new(grid, &config.planner).unwrap())
}

/// Closest approach of `path` to `point`.
fn closest_m(path: &[Pose2D], point: Pose2D) -> f64 {
    path.iter()
        .map(|p| p.distance_m(&point))
        .fold(f64::INFINITY, f64::min)
}

#[test]
fn a_plan_keeps_clear_of_another_robot_in_the_corridor() {
    let goals = [Goal::at(25.5, 5.2)];
    let progress = GoalProgress::new(&goals, 0);
    let start = estimate(Pose2D::new(2.0, 5.2, 0.0), 1);
    // The robot of the scenario, parked on the corridor's centre line.
    let other = Pose2D::new(12.0, 5.2, std::f64::consts::PI);

    let mut alone = corridor_planner();
    let Answer::Heading {
        plan: Ok(blind), ..
    } = alone.answer(&start, &progress, false)
    else {
        panic!("no plan on the floor plan");
    };
    assert!(closest_m(&blind.path, other) < 0.2, "runs through it");
    assert_eq!(blind.avoided_robots, 0);

    let mut among = corridor_planner();
    let Answer::Heading {
        plan: Ok(round), ..
    } = among.answer_among(&start, &progress, false, &[Neighbour::standing(other)])
    else {
        panic!("no plan round the other robot");
    };
    let config = IntentionConfig::default();
    let berth_m = config.avoid.radius_m + config.planner.robot_radius_m;
    // Every pose of the full path keeps the berth; the thinned one may cut a chord by a hair.
    assert!(
        closest_m(&round.path, other) >= berth_m - 0.02,
        "{} m from the other robot",
        closest_m(&round.path, other)
    );
    assert_eq!(round.avoided_robots, 1);
    assert!(
        round.length_m < blind.length_m + 1.0,
        "a detour, not a tour"
    );

    // Kept while it holds; a robot that steps onto the kept path sends it to a new search.
    let next = estimate(along(&round.path, 0.05), 2);
    let Answer::Heading { plan: Ok(kept), .. } =
        among.answer_among(&next, &progress, false, &[Neighbour::standing(other)])
    else {
        panic!("no plan");
    };
    assert!(kept.reused);
    let in_the_way = along(&round.path, 5.0);
    let Answer::Heading {
        plan: Ok(moved), ..
    } = among.answer_among(&next, &progress, false, &[Neighbour::standing(in_the_way)])
    else {
        panic!("no plan");
    };
    assert!(!moved.reused);
    assert!(closest_m(&moved.path, in_the_way) >= berth_m - 0.02);
}

#[test]
fn a_robot_on_the_goal_or_filling_the_way_leaves_the_plan_on_the_floor_plan() {
    let goals = [Goal::at(25.5, 5.2)];
    let progress = GoalProgress::new(&goals, 0);
    let start = estimate(Pose2D::new(2.0, 5.2, 0.0), 1);
    let mut planner = corridor_planner();
    // On the goal: no path could end there, so the plan goes there all the same.
    let Answer::Heading {
        plan: Ok(to_goal), ..
    } = planner.answer_among(
        &start,
        &progress,
        false,
        &[Neighbour::standing(Pose2D::new(25.4, 5.2, 0.0))],
    )
    else {
        panic!("no plan");
    };
    assert_eq!(to_goal.avoided_robots, 0);
    // A wall of robots across the corridor: the search round them fails within its budget
    // and the plan on the floor plan answers (the collision monitor holds the robot back).
    let wall: Vec<Neighbour> = (0..8)
        .map(|i| Neighbour::standing(Pose2D::new(12.0, 3.0 + 0.5 * f64::from(i), 0.0)))
        .collect();
    let mut blocked = corridor_planner();
    let Answer::Heading {
        plan: Ok(through), ..
    } = blocked.answer_among(&start, &progress, false, &wall)
    else {
        panic!("no plan");
    };
    assert_eq!(through.avoided_robots, 0);
    assert!(closest_m(&through.path, Pose2D::new(12.0, 5.2, 0.0)) < 0.3);
}

/// Two robots sent towards each other down the bottom corridor of the junctions floor plan (2 m
/// wide), each following its answered path exactly at 0.5 m/s and 10 Hz, each planner given
/// the other's pose: both keep right and pass with room between them. On the floor plan alone
/// they drive into each other.
#[test]
fn two_robots_meeting_head_on_pass_each_other() {
    let config = IntentionConfig::default();
    let map = scenario_map("junctions", &config);
    let drive = |among: bool| -> (f64, [bool; 2]) {
        let mut robots = [
            Pose2D::new(4.0, 4.0, 0.0),
            Pose2D::new(20.0, 4.0, std::f64::consts::PI),
        ];
        let goals = [[Goal::at(20.0, 4.0)], [Goal::at(4.0, 4.0)]];
        let mut planners = [
            IntentionPlanner::new(Arc::clone(&map), config.clone()).unwrap(),
            IntentionPlanner::new(Arc::clone(&map), config.clone()).unwrap(),
        ];
        let mut closest_m = f64::INFINITY;
        let mut done = [false, false];
        let mut previous = robots;
        for step in 0..600_u64 {
            let before = robots;
            for i in 0..2 {
                if done[i] {
                    continue;
                }
                // Each sees the other where it was, moving as it moved over the last step.
                let other = Neighbour {
                    pose: before[1 - i],
                    vx_mps: (before[1 - i].x_m - previous[1 - i].x_m) / 0.1,
                    vy_mps: (before[1 - i].y_m - previous[1 - i].y_m) / 0.1,
                };
                let others = if among { vec![other] } else { Vec::new() };
                match planners[i].answer_among(
                    &estimate(before[i], step),
                    &GoalProgress::new(&goals[i], 0),
                    false,
                    &others,
                ) {
                    Answer::Heading { plan: Ok(p), .. } => robots[i] = along(&p.path, 0.05),
                    Answer::Heading { plan: Err(e), .. } => panic!("robot {i}: {e}"),
                    Answer::Done => done[i] = true,
                }
            }
            previous = before;
            closest_m = closest_m.min(robots[0].distance_m(&robots[1]));
            if done == [true, true] {
                break;
            }
        }
        (closest_m, done)
    };
    let (blind_m, _) = drive(false);
    assert!(
        blind_m < 0.5,
        "on the floor plan alone they meet: {blind_m} m"
    );
    let (passing_m, done) = drive(true);
    assert_eq!(done, [true, true]);
    // Two 0.25 m robots touch at 0.5 m between centres; the berth is 0.65 m (0.15 m between
    // them), kept to within the path's 5 cm steps.
    let berth_m = config.avoid.radius_m + config.planner.robot_radius_m;
    assert!(passing_m >= berth_m - 0.03, "closest {passing_m} m");
}

/// A robot ahead driving away is followed, not gone round; the same robot standing is.
#[test]
fn a_robot_ahead_driving_away_is_followed_and_one_standing_is_gone_round() {
    let config = IntentionConfig::default();
    let map = scenario_map("junctions", &config);
    let goals = [Goal::at(20.0, 4.0)];
    let start = estimate(Pose2D::new(5.0, 4.0, 0.0), 1);
    let leader = Pose2D::new(7.5, 4.0, 0.0);
    let plan_with = |other: Neighbour| {
        let mut p = IntentionPlanner::new(Arc::clone(&map), config.clone()).unwrap();
        let Answer::Heading { plan: Ok(plan), .. } =
            p.answer_among(&start, &GoalProgress::new(&goals, 0), false, &[other])
        else {
            panic!("no plan");
        };
        plan
    };
    let off_centre_m = |plan: &planning::Planned| {
        plan.path
            .iter()
            .filter(|q| q.x_m < 10.0)
            .map(|q| (q.y_m - 4.0).abs())
            .fold(0.0, f64::max)
    };
    let followed = plan_with(Neighbour {
        pose: leader,
        vx_mps: 0.5,
        vy_mps: 0.0,
    });
    assert_eq!(followed.avoided_robots, 0);
    assert!(off_centre_m(&followed) < 0.1, "{}", off_centre_m(&followed));
    let passed = plan_with(Neighbour::standing(leader));
    assert_eq!(passed.avoided_robots, 1);
    assert!(off_centre_m(&passed) > 0.5, "{}", off_centre_m(&passed));
}

/// The face and sides of a cabinet standing out from the corridor's north wall (y = 6.4) to its
/// centre line, at x = 11.6..12.4, as the agent's obstacle layer reports it: points 0.1 m apart.
fn cabinet_points() -> Vec<[f64; 2]> {
    let mut points = Vec::new();
    for i in 0..=8 {
        points.push([11.6 + 0.1 * f64::from(i), 5.2]);
    }
    for j in 1..=10 {
        let y = 5.2 + 0.1 * f64::from(j);
        points.push([11.6, y]);
        points.push([12.4, y]);
    }
    points
}

fn closest_to_points_m(path: &[Pose2D], points: &[[f64; 2]]) -> f64 {
    points
        .iter()
        .map(|&[x, y]| closest_m(path, Pose2D::new(x, y, 0.0)))
        .fold(f64::INFINITY, f64::min)
}

#[test]
fn a_plan_goes_round_an_obstacle_the_robot_reports_seeing_where_the_floor_plan_is_free() {
    let goals = [Goal::at(25.5, 5.2)];
    let progress = GoalProgress::new(&goals, 0);
    // 4 m before it: within the planner's `range_m`.
    let mut seeing = estimate(Pose2D::new(8.0, 5.2, 0.0), 1);
    seeing.unmapped_obstacles_m = cabinet_points();

    // Off (the paper's planner, the floor plan alone): straight through it.
    let mut config = IntentionConfig::default();
    config.seen.enabled = false;
    let mut blind = IntentionPlanner::new(scenario_map("corridor", &config), config).unwrap();
    let Answer::Heading {
        plan: Ok(through), ..
    } = blind.answer(&seeing, &progress, false)
    else {
        panic!("no plan on the floor plan");
    };
    assert!(closest_to_points_m(&through.path, &cabinet_points()) < 0.2);

    let mut planner = corridor_planner();
    let Answer::Heading {
        plan: Ok(round), ..
    } = planner.answer(&seeing, &progress, false)
    else {
        panic!("no plan round the cabinet");
    };
    let config = IntentionConfig::default();
    let berth_m = config.seen.radius_m + config.planner.robot_radius_m;
    let gap_m = closest_to_points_m(&round.path, &cabinet_points());
    assert!(gap_m >= berth_m - 0.02, "{gap_m} m from the cabinet");
    assert!(
        round.length_m < through.length_m + 1.0,
        "a detour, not a tour"
    );
    assert_eq!(round.avoided_robots, 0, "a cabinet is not a robot");

    // The kept path holds while the cabinet is out of sight (no points reported); seen again,
    // the answer keeps its berth (kept, or searched again where it passes within the berth
    // and `kept_margin_m`); a new point on it sends it to a new search.
    let mut next = estimate(along(&round.path, 0.05), 2);
    let Answer::Heading { plan: Ok(kept), .. } = planner.answer(&next, &progress, false) else {
        panic!("no plan");
    };
    assert!(kept.reused);
    next = estimate(along(&round.path, 0.1), 3);
    next.unmapped_obstacles_m = cabinet_points();
    let Answer::Heading {
        plan: Ok(again), ..
    } = planner.answer(&next, &progress, false)
    else {
        panic!("no plan");
    };
    let gap_m = closest_to_points_m(&again.path, &cabinet_points());
    assert!(gap_m >= berth_m - 0.02, "{gap_m} m from the cabinet");
    let in_the_way = along(&round.path, 5.0);
    let mut next = estimate(along(&round.path, 0.2), 5);
    next.unmapped_obstacles_m = vec![[in_the_way.x_m, in_the_way.y_m]];
    let Answer::Heading {
        plan: Ok(moved), ..
    } = planner.answer(&next, &progress, false)
    else {
        panic!("no plan");
    };
    assert!(!moved.reused);
    assert!(closest_m(&moved.path, in_the_way) >= berth_m - 0.02);
}

#[test]
fn obstacles_closing_the_corridor_leave_the_plan_on_the_floor_plan_within_the_expansion_budget() {
    let goals = [Goal::at(25.5, 5.2)];
    let progress = GoalProgress::new(&goals, 0);
    let mut seeing = estimate(Pose2D::new(8.0, 5.2, 0.0), 1);
    // A row of people standing across the corridor, as the laser sees their fronts.
    seeing.unmapped_obstacles_m = (0..25).map(|i| [12.0, 4.0 + 0.1 * f64::from(i)]).collect();
    let mut planner = corridor_planner();
    let Answer::Heading {
        plan: Ok(through), ..
    } = planner.answer(&seeing, &progress, false)
    else {
        panic!("no plan");
    };
    assert!(closest_m(&through.path, Pose2D::new(12.0, 5.2, 0.0)) < 0.3);
}

/// Round the end of a thin wall of task E's maze (a hairpin: the route runs east round the
/// wall's end at (23.9, 15.6) and back north on its other side to the goal): DLM-Net r4,
/// facing north at the wall's end, was told `go_forward` by the route measure, whose chord
/// 1–2 m ahead already runs north on the far side, and stood there (task E seed 0, 2026-11-28).
/// The first-turn measure tells it to turn right round the end, and left again once round it.
#[test]
fn the_first_turn_measure_turns_round_the_end_of_a_thin_wall() {
    let config = IntentionConfig::default();
    let map = scenario_map("maze", &config);
    let goal = Pose2D::new(25.0, 17.2, 0.0);
    let dlm = |measure: DlmMeasure, robot: Pose2D| {
        // The route measure as r4 had it (its chord 1-2 m ahead); first_turn as r5 drove it
        // (no arriving Stop: the goal is 1.2 m beyond the wall's end).
        let params = match measure {
            DlmMeasure::Route => DlmParams {
                measure,
                ..DlmParams::heading()
            },
            _ => DlmParams {
                measure,
                ..DlmParams::as_before()
            },
        };
        let route = planning::intention::floor_plan_route(&map, robot, goal, 2.0).unwrap();
        planning::intention::next_dlm_along(&route, Some(&route), robot, &params, None)
    };
    let at_the_end = Pose2D::new(23.03, 15.74, std::f64::consts::FRAC_PI_2);
    assert_eq!(dlm(DlmMeasure::Route, at_the_end), Dlm::GoForward);
    assert_eq!(dlm(DlmMeasure::FirstTurn, at_the_end), Dlm::TurnRight);
    // Facing east past the end, the way on is north: left.
    let round = Pose2D::new(24.4, 15.3, 0.0);
    assert_eq!(dlm(DlmMeasure::FirstTurn, round), Dlm::TurnLeft);
    // Facing north on the far side, straight on to the goal.
    let beyond = Pose2D::new(24.7, 16.0, std::f64::consts::FRAC_PI_2);
    assert_eq!(dlm(DlmMeasure::FirstTurn, beyond), Dlm::GoForward);
}

/// With `dlm.arrive_distance_m`, a robot walked along its plan on the depot map is told an
/// arriving `Stop` over its last straight metres (and the intention says so), never farther
/// out than the arrive distance, and never a rest before the goal is reached.
#[test]
fn the_last_straight_metres_before_a_goal_are_an_arriving_stop() {
    let config = IntentionConfig {
        dlm: DlmParams {
            arrive_distance_m: 1.5,
            ..DlmParams::default()
        },
        ..IntentionConfig::default()
    };
    let map = Arc::new(PlanningMap::new(test_support::nav2_map("depot"), &config.planner).unwrap());
    let pairs = sample_pairs(&map, 6, 31, 6.0, "depot").unwrap();
    let mut pipeline = IntentionPlanner::new(map, config).unwrap();
    let task = Some(TaskId::new("t-000002").unwrap());
    let mut arrived = 0;
    for (k, (start, end)) in pairs.iter().enumerate() {
        let goals = [Goal::at(end.x_m, end.y_m)];
        let progress = GoalProgress::new(&goals, 0);
        let first = match pipeline.answer(&estimate(*start, 0), &progress, false) {
            Answer::Heading { plan: Ok(p), .. } => p,
            _ => continue,
        };
        let mut arriving_seen = false;
        let mut d_m = 0.0;
        while d_m < first.length_m {
            let robot = along(&first.path, d_m);
            let seq = 1 + (d_m * 10.0) as u64 + 1000 * k as u64;
            let pose = estimate(robot, seq);
            let Answer::Heading { plan: Ok(p), .. } = pipeline.answer(&pose, &progress, false)
            else {
                break;
            };
            let left_m = planning::intention::path_left_m(&p.path, robot);
            let i = p.intention(Header::new(seq, seq), &pose, task.clone(), 0, false);
            assert_eq!(i.arriving, p.arriving);
            if p.arriving {
                assert_eq!(p.dlm, Dlm::Stop);
                assert!(left_m <= 1.5 + 1e-6, "arriving {left_m} m before the goal");
                assert!(!i.rests(), "an arriving Stop is driven");
                arriving_seen = true;
            } else if p.dlm == Dlm::Stop {
                assert!(left_m <= 0.3 + 1e-6, "a rest {left_m} m before the goal");
            }
            d_m += 0.1;
        }
        arrived += usize::from(arriving_seen);
    }
    assert!(
        arrived >= 4,
        "only {arrived} of {} routes arrived",
        pairs.len()
    );
}

/// A robot that keeps to the corridor's centre line towards the cabinet is told to turn away
/// from it where the plan goes round it (`dlm.sidestep_ahead_m`): the floor plan's route, which
/// the DLM measures, runs straight through the cabinet, so without the rule it hears
/// `go_forward` all the way in (DLM-Net r49 on task C, round 51).
#[test]
fn a_robot_heading_for_a_seen_cabinet_is_told_to_turn_away_from_it() {
    // From 4.6 m short of the cabinet's face to 0.6 m short, heading east on y 5.2.
    let xs_m: Vec<f64> = (0..=20).map(|k| 7.0 + 0.2 * f64::from(k)).collect();
    let drive = |sidestep_ahead_m: f64| {
        let mut config = IntentionConfig::default();
        config.dlm.sidestep_ahead_m = sidestep_ahead_m;
        let poses = xs_m.iter().map(|&x_m| Pose2D::new(x_m, 5.2, 0.0));
        let told = told_along(
            "corridor",
            config,
            Goal::at(25.5, 5.2),
            poses,
            &cabinet_points(),
        );
        xs_m.iter().copied().zip(told).collect::<Vec<_>>()
    };
    let off = drive(0.0);
    assert!(off.iter().all(|&(_, d)| d == Dlm::GoForward), "{off:?}");
    let on = drive(2.0);
    // The cabinet stands on the corridor's north (left) half: the way round is to the right.
    assert!(on.iter().all(|&(_, d)| d != Dlm::TurnLeft), "{on:?}");
    let first = on.iter().find(|&&(_, d)| d == Dlm::TurnRight);
    assert!(
        first.is_some_and(|&(x_m, _)| x_m < 10.6),
        "told the turn at least a metre before the cabinet: {on:?}"
    );
    // Far from it, the rule is silent.
    assert_eq!(on[0].1, Dlm::GoForward, "{on:?}");
}

/// Where the floor plan's route turns by itself (task E's maze, a box standing in the corner
/// it turns round), the path's bend round the box is the route's: the sidestep rule stays
/// silent and the DLM is the measure's. Told the turn here, DLM-Net r49 cut the corner of the
/// wall before the gap (task E seed 6, round 51: this pose, its path and what its laser saw).
#[test]
fn a_seen_box_in_a_corner_the_route_turns_round_changes_no_dlm() {
    let config = IntentionConfig::default();
    let map = scenario_map("maze", &config);
    let goal = Pose2D::new(25.0, 17.2, 0.0);
    let robot = Pose2D::new(5.074, 4.441, 0.268);
    let mut path: Vec<Pose2D> = [
        (5.07, 4.44),
        (5.51, 4.77),
        (5.69, 4.86),
        (5.92, 4.95),
        (6.15, 5.04),
        (6.39, 5.14),
        (6.51, 5.22),
        (6.68, 5.4),
        (6.88, 5.54),
        (7.09, 5.68),
        (7.29, 5.81),
        (7.5, 5.95),
    ]
    .iter()
    .map(|&(x, y)| Pose2D::new(x, y, 0.0))
    .collect();
    path.push(goal);
    let seen = [planning::Disc {
        x_m: 7.15,
        y_m: 4.8,
        radius_m: config.seen.radius_m,
    }];
    // On by default; off as before round 51.
    let off = DlmParams {
        sidestep_ahead_m: 0.0,
        ..config.dlm.clone()
    };
    for previous in [None, Some(Dlm::GoForward), Some(Dlm::TurnLeft)] {
        let dlm = |params: &DlmParams| {
            planning::intention::dlm_on_map(&map, &path, robot, goal, params, previous, &seen)
        };
        assert_eq!(dlm(&off), Dlm::GoForward, "after {previous:?}");
        assert_eq!(dlm(&config.dlm), Dlm::GoForward, "after {previous:?}");
    }
}

/// The DLMs one pipeline with `config` tells a robot at each of `poses` in turn on its way to
/// `goal` on scenario map `map`, its laser seeing `seen_m` (map frame, m) the floor plan lacks.
fn told_along(
    map: &str,
    config: IntentionConfig,
    goal: Goal,
    poses: impl Iterator<Item = Pose2D>,
    seen_m: &[[f64; 2]],
) -> Vec<Dlm> {
    let mut planner = IntentionPlanner::new(scenario_map(map, &config), config).unwrap();
    let goals = [goal];
    let progress = GoalProgress::new(&goals, 0);
    poses
        .zip(1..)
        .map(|(robot, seq)| {
            let mut seeing = estimate(robot, seq);
            seeing.unmapped_obstacles_m = seen_m.to_vec();
            match planner.answer(&seeing, &progress, false) {
                Answer::Heading { plan: Ok(p), .. } => p.dlm,
                other => panic!("no plan at {robot:?}: {other:?}"),
            }
        })
        .collect()
}

/// The DLM the pipeline tells a robot at `robot` on the way to `goal` on scenario map `map`,
/// with `dlm.about_turn_rad` at `about_turn_rad`.
fn told(map: &str, about_turn_rad: f64, robot: Pose2D, goal: Goal) -> Dlm {
    let mut config = IntentionConfig::default();
    config.dlm.about_turn_rad = about_turn_rad;
    let mut planner = IntentionPlanner::new(scenario_map(map, &config), config).unwrap();
    let goals = [goal];
    match planner.answer(&estimate(robot, 1), &GoalProgress::new(&goals, 0), false) {
        Answer::Heading { plan: Ok(p), .. } => p.dlm,
        other => panic!("no plan from {robot:?}: {other:?}"),
    }
}

/// A robot that has just reached a goal and must turn round for the next is told the turn
/// towards the side where the floor plan closes in, not the side the route lies on by a hair
/// (`dlm.about_turn_rad`): told the turn towards an open passage, DLM-Net r49 drove into it as
/// into a junction ahead (16 of its 28 interventions alone over tasks A–E × 20, round 52). The
/// poses are where r49 reached task E's goals 3 and 2 and task C's goal 2.
#[test]
fn a_robot_turning_round_after_a_goal_is_told_the_side_of_the_wall() {
    // The shipped default (DLM-Net r49's card, and r55's).
    let about = DlmParams::default().about_turn_rad;
    // Task E's goal 3, reached heading west: the next leg starts back east. The wall is to the
    // north, 0.9 m off; south-west, the passage towards the start lies open.
    let e3 = Goal::at(1.6, 17.2);
    for yaw_rad in [-3.0, 3.1] {
        let robot = Pose2D::new(12.19, 9.5, yaw_rad);
        assert_eq!(told("maze", about, robot, e3), Dlm::TurnRight, "{yaw_rad}");
    }
    // Turning right on the spot, it hears the same side all the way round.
    for turned_rad in [0.2, 0.6, 1.2, 2.0] {
        let robot = Pose2D::new(12.19, 9.5, -3.0 - turned_rad);
        assert_eq!(
            told("maze", about, robot, e3),
            Dlm::TurnRight,
            "{turned_rad}"
        );
    }
    // Off, as before round 53: the route's side by a hair, the open passage's.
    assert_eq!(
        told("maze", 0.0, Pose2D::new(12.19, 9.5, -3.0), e3),
        Dlm::TurnLeft
    );
    // Task E's goal 2, reached heading south by the east wall; the bottom corridor runs west.
    let robot = Pose2D::new(25.0, 1.9, -std::f64::consts::FRAC_PI_2);
    assert_eq!(
        told("maze", about, robot, Goal::at(12.0, 9.4)),
        Dlm::TurnLeft
    );
    // Task C's goal 2 in the outer corridor's north-east corner, reached heading north: the
    // next leg starts back south, and the north corridor runs west.
    let robot = Pose2D::new(32.8, 22.7, std::f64::consts::FRAC_PI_2);
    assert_eq!(
        told("hospital", about, robot, Goal::at(8.0, 8.0)),
        Dlm::TurnRight
    );
    // Out of range, named.
    let bad = DlmParams {
        about_turn_rad: 4.0,
        ..DlmParams::default()
    };
    assert_eq!(bad.validate().unwrap_err().field, "about_turn_rad");
}

/// The laser's view of task D's cabinet by the room's door (0.5 m by 1 m at (8.6, 8.0)): its
/// west and south faces, as a robot coming south along x 7.85 sees them.
fn door_cabinet_points() -> Vec<[f64; 2]> {
    let mut points = Vec::new();
    for j in 0..=10 {
        points.push([8.35, 7.5 + 0.1 * f64::from(j)]);
    }
    for i in 1..=5 {
        points.push([8.35 + 0.1 * f64::from(i), 7.5]);
    }
    points
}

/// A robot coming south beside task D's cabinet by the room's door, on its way east into the
/// room: the floor plan's route turns east through the cabinet, so the measure tells
/// `turn_left` while the cabinet is still beside the robot. With `dlm.sidestep_over_turn_rad`
/// the turn is measured on the path, which goes on south past the cabinet's end first: the
/// turn comes there (DLM-Net alone turned into this cabinet in 6 of 100 runs, round 54).
#[test]
fn a_robot_beside_a_seen_cabinet_is_told_the_turn_past_its_end() {
    // From 2 m north of the cabinet's north face to level with its south face (y 7.5).
    let ys_m: Vec<f64> = (0..=20).map(|k| 10.5 - 0.15 * f64::from(k)).collect();
    let drive = |over_rad: f64| {
        let mut config = IntentionConfig::default();
        config.dlm.sidestep_over_turn_rad = over_rad;
        let poses = ys_m.iter().map(|&y_m| Pose2D::new(7.85, y_m, -1.62));
        let told = told_along(
            "campus",
            config,
            Goal::at(12.0, 6.0),
            poses,
            &door_cabinet_points(),
        );
        ys_m.iter().copied().zip(told).collect::<Vec<_>>()
    };
    let off = drive(0.0);
    assert!(
        off.iter().any(|&(y_m, d)| y_m > 8.5 && d == Dlm::TurnLeft),
        "as before round 55 the turn comes beside the cabinet: {off:?}"
    );
    let on = drive(std::f64::consts::PI);
    assert!(
        on.iter().all(|&(y_m, d)| y_m < 7.9 || d == Dlm::GoForward),
        "{on:?}"
    );
    assert_eq!(on.last().map(|&(_, d)| d), Some(Dlm::TurnLeft), "{on:?}");
    // A turn the measure only holds is left to it: measured on the path every other cycle,
    // the DLM would flip between the two.
    assert!(
        on.windows(3)
            .all(|w| !(w[0].1 == w[2].1 && w[1].1 != w[0].1)),
        "{on:?}"
    );
}
