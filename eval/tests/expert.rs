//! The privileged expert in closed loop on the shipped scenarios: the simulator steps, the
//! planning crate's intention pipeline answers the true pose (no AMCL, to keep the tests fast
//! and about the expert alone), the expert reads the truth and drives.

#![allow(clippy::unwrap_used)]

use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use eval::expert::{Expert, ExpertConfig, SharedTruth, TruthView};
use planning::PlanningMap;
use planning::{stop_intention, Answer, Goal, GoalProgress, IntentionConfig, IntentionPlanner};
use protocol::{Header, MapName, MapRef, Pose2D, PoseEstimate};
use robot_agent::controllers::{ControlInput, Controller, ControllerError};
use robot_agent::{ControllerKind, Limits};
use sim::scenario::{BoxSpec, Scenario};
use sim::{Command, SimConfig, World};

/// What one closed-loop run did.
#[derive(Debug)]
struct Run {
    /// Every collision, as the simulator names what was hit.
    collisions: Vec<String>,
    goals_reached: usize,
    /// Smallest gap between the robot's disc and a person's disc.
    min_person_gap_m: f64,
    /// Smallest gap between the robot's disc and any piece of glass or furniture.
    min_box_gap_m: f64,
    /// Smallest gap between the robot's disc and another robot's.
    min_robot_gap_m: f64,
    /// Longest time the robot went without moving 0.5 m.
    longest_still_s: f64,
    /// Whether the expert ever followed a detour of its own.
    detoured: bool,
    trajectory: Vec<Pose2D>,
    /// Time spent in `Expert::control`, and how many calls.
    control_time: Duration,
    controls: u32,
}

fn load(name: &str) -> Scenario {
    let path = test_support::scenario(name);
    Scenario::load(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn plan_of(name: &str, scenario: &Scenario) -> map_core::OccupancyGrid {
    let path = scenario.floor_plan_path(&test_support::scenario(name));
    map_core::load_ros_map(&path, &map_core::ImportLimits::default())
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .grid
}

/// Drives `scenario` (on the plan of the shipped scenario `name`) for at most `max_s`.
fn run(name: &str, scenario: Scenario, max_s: f64) -> Run {
    let plan = plan_of(name, &scenario);
    let goals: Vec<Goal> = scenario
        .goals
        .iter()
        .map(|g| Goal::at(g.x_m, g.y_m))
        .collect();
    let mut world = World::new(scenario, plan.clone(), SimConfig::default()).unwrap();
    world.add_robots_at_start(1).unwrap();
    world.add_parked_robots().unwrap();
    let radius_m = world.config.base.radius_m;
    let truth: SharedTruth = Arc::new(Mutex::new(TruthView::of(&world, 0)));
    let mut expert = Expert::new(&world, ExpertConfig::default(), Arc::clone(&truth)).unwrap();
    assert_eq!(expert.kind(), ControllerKind::Expert);
    let intention_config = IntentionConfig::default();
    let map = Arc::new(PlanningMap::new(plan, &intention_config.planner).unwrap());
    let mut pipeline = IntentionPlanner::new(map, intention_config).unwrap();
    let map_ref = MapRef {
        name: MapName::new("plan").unwrap(),
        version: 1,
    };
    let limits = Limits::default();
    let dt_s = 0.1;
    let mut out = Run {
        collisions: Vec::new(),
        goals_reached: 0,
        min_person_gap_m: f64::INFINITY,
        min_box_gap_m: f64::INFINITY,
        min_robot_gap_m: f64::INFINITY,
        longest_still_s: 0.0,
        detoured: false,
        trajectory: Vec::new(),
        control_time: Duration::ZERO,
        controls: 0,
    };
    let mut cmd = Command::default();
    let (mut still_at, mut still_since_s) = (world.ground_truth_pose(0).unwrap(), 0.0);
    let mut t_s = 0.0;
    let mut seq = 0u64;
    while t_s < max_s {
        let obs = world.step(&[cmd], dt_s);
        t_s += dt_s;
        seq += 1;
        let o = &obs.robots[0];
        let pose = o.ground_truth_pose;
        out.trajectory.push(pose);
        out.collisions
            .extend(o.collisions.iter().map(|c| c.with.to_string()));
        for p in &world.people {
            let gap = (p.x_m - pose.x_m).hypot(p.y_m - pose.y_m) - p.radius_m - radius_m;
            out.min_person_gap_m = out.min_person_gap_m.min(gap);
        }
        for j in 1..world.robot_count() {
            let q = world.ground_truth_pose(j).unwrap();
            out.min_robot_gap_m = out
                .min_robot_gap_m
                .min(pose.distance_m(&q) - 2.0 * radius_m);
        }
        let boxes = world.furniture.iter().map(|f| f.shape);
        for b in boxes.chain(world.glass.iter().map(|g| g.shape)) {
            out.min_box_gap_m = out
                .min_box_gap_m
                .min(b.distance(pose.x_m, pose.y_m) - radius_m);
        }
        if pose.distance_m(&still_at) >= 0.5 {
            (still_at, still_since_s) = (pose, t_s);
        }
        out.longest_still_s = out.longest_still_s.max(t_s - still_since_s);

        *truth.lock().unwrap() = TruthView::of(&world, 0);
        let header = Header::new(seq, obs.time_ns);
        let estimate = PoseEstimate {
            header,
            pose,
            covariance: [0.0; 9],
            sensor_stamp_ns: obs.time_ns,
            map: map_ref.clone(),
            unmapped_obstacles_m: Vec::new(),
        };
        let intention = match pipeline.answer(
            &estimate,
            &GoalProgress::new(&goals, out.goals_reached),
            false,
        ) {
            Answer::Done => {
                out.goals_reached = goals.len();
                break;
            }
            Answer::Heading { goal_index, plan } => {
                out.goals_reached = goal_index;
                match plan {
                    Ok(p) => p.intention(header, &estimate, None, goal_index, false),
                    Err(_) => stop_intention(header, &estimate, None, goal_index),
                }
            }
        };
        let input = ControlInput {
            // The expert reads the truth; a pose estimate off by a metre must not matter.
            pose: Pose2D::new(pose.x_m + 1.0, pose.y_m - 1.0, pose.yaw_rad + 0.5),
            v_mps: o.odom.v_mps,
            omega_radps: o.odom.omega_radps,
            scan: Some(&o.scan),
            camera: None,
            intention: Some(&intention),
            limits: &limits,
            dt_s,
        };
        let started = Instant::now();
        let control = expert.control(&input).unwrap();
        out.control_time += started.elapsed();
        out.controls += 1;
        out.detoured |= expert.on_detour();
        let (v_mps, omega_radps) = control.to_physical(&limits);
        // The supervisor's acceleration limits hold by construction: the agent would pass the
        // command through unchanged.
        assert!(
            (v_mps - cmd.v_mps).abs() <= limits.max_accel_mps2 * dt_s + 1e-9,
            "t {t_s:.1} s: speed jumps from {} to {v_mps}",
            cmd.v_mps
        );
        assert!(
            (omega_radps - cmd.omega_radps).abs() <= limits.max_turn_accel_radps2 * dt_s + 1e-9,
            "t {t_s:.1} s: turn rate jumps from {} to {omega_radps}",
            cmd.omega_radps
        );
        cmd = Command { v_mps, omega_radps };
    }
    out
}

#[test]
fn stops_short_of_a_shut_glass_door_without_touching_it_and_waits() {
    let scenario = load("behaviour_glass_door");
    let door_x_m = scenario.glass[0].x0_m;
    let r = run("behaviour_glass_door", scenario, 35.0);
    assert!(r.collisions.is_empty(), "{:?}", r.collisions);
    assert_eq!(r.goals_reached, 0);
    let end = r.trajectory.last().copied().unwrap();
    // In front of the door, close enough to have tried, with the margin kept, and far enough
    // that the door's frame is still in the camera's view where it stands
    // (`obstruction_stop_m`): its centre at least 0.95 m from the pane.
    assert!(
        end.x_m < door_x_m - 0.95 && end.x_m > door_x_m - 2.0,
        "{end:?}"
    );
    assert!(
        r.min_box_gap_m >= ExpertConfig::default().static_margin_m - 0.02,
        "{}",
        r.min_box_gap_m
    );
    // Waiting: the last ten seconds without moving.
    let before = r.trajectory[r.trajectory.len() - 100];
    assert!(end.distance_m(&before) < 0.01, "{before:?} -> {end:?}");
}

#[test]
fn drives_round_furniture_standing_on_the_planned_path() {
    let mut scenario = load("behaviour_glass_door");
    scenario.glass.clear();
    // A cabinet on the corridor's centre line, where the planner (who does not know it) sends
    // the robot: free on both sides.
    let table = BoxSpec {
        x_m: 12.0,
        y_m: scenario.start.y_m,
        size_x_m: 1.0,
        size_y_m: 0.6,
        yaw_rad: 0.3,
        height_m: 0.9,
        color: [140, 95, 55],
    };
    scenario.furniture = vec![table];
    let r = run("behaviour_glass_door", scenario, 60.0);
    assert!(r.collisions.is_empty(), "{:?}", r.collisions);
    assert_eq!(r.goals_reached, 1, "end {:?}", r.trajectory.last());
    assert!(r.detoured, "the planner's path runs through the cabinet");
    assert!(
        r.min_box_gap_m >= ExpertConfig::default().static_margin_m - 0.02,
        "{}",
        r.min_box_gap_m
    );
}

#[test]
fn drives_round_a_robot_standing_on_the_planned_path() {
    // Following a robot that never moves on would wait behind it for ever.
    let scenario = load("behaviour_robot_parked");
    let parked = scenario.parked_robots[0];
    let r = run("behaviour_robot_parked", scenario, 90.0);
    assert!(r.collisions.is_empty(), "{:?}", r.collisions);
    assert_eq!(r.goals_reached, 1, "end {:?}", r.trajectory.last());
    assert!(
        r.detoured,
        "the planner's path runs through the parked robot"
    );
    assert!(
        r.min_robot_gap_m >= ExpertConfig::default().robot_margin_m,
        "{}",
        r.min_robot_gap_m
    );
    // It waited no longer than it takes to see that the robot stands.
    assert!(r.longest_still_s < 10.0, "{}", r.longest_still_s);
    assert!(r.trajectory.iter().any(|p| p.x_m > parked.x_m + 1.0));
}

#[test]
fn passes_a_person_walking_towards_it_without_contact() {
    let r = run(
        "behaviour_person_oncoming",
        load("behaviour_person_oncoming"),
        90.0,
    );
    assert!(r.collisions.is_empty(), "{:?}", r.collisions);
    assert_eq!(r.goals_reached, 1);
    // It passed them with room, rather than making them squeeze by.
    assert!(r.min_person_gap_m > 0.1, "{}", r.min_person_gap_m);
    assert!(r.longest_still_s < 10.0, "{}", r.longest_still_s);
}

#[test]
fn follows_a_slower_person_at_a_distance() {
    let r = run(
        "behaviour_person_ahead",
        load("behaviour_person_ahead"),
        150.0,
    );
    assert!(r.collisions.is_empty(), "{:?}", r.collisions);
    assert_eq!(r.goals_reached, 1);
    assert!(r.min_person_gap_m > 0.5, "{}", r.min_person_gap_m);
}

#[test]
fn waits_beside_a_narrow_passage_for_a_person_coming_through_it() {
    // A cabinet narrows the corridor to 1.1 m, too narrow to meet a person in; the person
    // walks towards the robot along the free side.
    let mut scenario = load("behaviour_person_oncoming");
    scenario.furniture = vec![BoxSpec {
        x_m: 12.0,
        y_m: 5.75,
        size_x_m: 1.0,
        size_y_m: 1.3,
        yaw_rad: 0.0,
        height_m: 0.9,
        color: [110, 115, 120],
    }];
    for p in &mut scenario.people[0].route {
        p.y_m = 4.55;
    }
    let r = run("behaviour_person_oncoming", scenario, 90.0);
    assert!(r.collisions.is_empty(), "{:?}", r.collisions);
    assert_eq!(r.goals_reached, 1, "end {:?}", r.trajectory.last());
    // Nobody had to wait for ever (the person waits for a robot in their way).
    assert!(r.longest_still_s < 10.0, "{}", r.longest_still_s);
    // It waited beside the passage: the person came through without squeezing past.
    assert!(r.min_person_gap_m > 0.2, "{}", r.min_person_gap_m);
}

#[test]
fn is_deterministic_and_cheap() {
    let a = run(
        "behaviour_person_oncoming",
        load("behaviour_person_oncoming"),
        20.0,
    );
    let b = run(
        "behaviour_person_oncoming",
        load("behaviour_person_oncoming"),
        20.0,
    );
    assert_eq!(a.trajectory, b.trajectory);
    let mean = a.control_time / a.controls.max(1);
    // Generous for a loaded CI machine; about 0.3 ms on a laptop core.
    assert!(mean < Duration::from_millis(5), "{mean:?} per cycle");
}

#[test]
fn truth_view_has_the_people_walking_their_routes_and_the_other_robots() {
    let path = test_support::scenario("behaviour_person_oncoming");
    let mut world = World::from_scenario_file(&path, SimConfig::default()).unwrap();
    world.add_robots_at_start(2).unwrap();
    let view = TruthView::of(&world, 0);
    assert_eq!(view.pose, world.ground_truth_pose(0).unwrap());
    assert_eq!(view.people.len(), 1);
    // Walking west down the corridor at 0.6 m/s.
    let p = view.people[0];
    assert!(
        (p.vx_mps + 0.6).abs() < 1e-9 && p.vy_mps.abs() < 1e-9,
        "{p:?}"
    );
    assert_eq!(view.robots.len(), 1);
    let other = world.ground_truth_pose(1).unwrap();
    assert_eq!(
        (view.robots[0].x_m, view.robots[0].y_m),
        (other.x_m, other.y_m)
    );
    assert_eq!(view.robots[0].radius_m, world.config.base.radius_m);
}

#[test]
fn refuses_bad_input_and_configuration_by_name() {
    let path = test_support::scenario("behaviour_person_oncoming");
    let mut world = World::from_scenario_file(&path, SimConfig::default()).unwrap();
    world.add_robots_at_start(1).unwrap();
    let truth: SharedTruth = Arc::new(Mutex::new(TruthView::of(&world, 0)));
    let bad = ExpertConfig {
        horizon_s: -1.0,
        ..ExpertConfig::default()
    };
    let err = Expert::new(&world, bad, Arc::clone(&truth)).unwrap_err();
    assert!(err.to_string().contains("horizon_s = -1"), "{err}");
    let err = toml_like_parse("{\"horizon\": 2.0}").unwrap_err();
    assert!(err.contains("horizon"), "{err}");

    let mut expert = Expert::new(&world, ExpertConfig::default(), truth).unwrap();
    let limits = Limits::default();
    let input = ControlInput {
        pose: Pose2D::default(),
        v_mps: 0.0,
        omega_radps: 0.0,
        scan: None,
        camera: None,
        intention: None,
        limits: &limits,
        dt_s: 0.1,
    };
    assert!(matches!(
        expert.control(&input),
        Err(ControllerError::MissingInput {
            input: "intention",
            ..
        })
    ));
}

/// The configuration as the harness reads it (JSON here): unknown fields are refused.
fn toml_like_parse(text: &str) -> Result<ExpertConfig, String> {
    serde_json::from_str(text).map_err(|e| e.to_string())
}
