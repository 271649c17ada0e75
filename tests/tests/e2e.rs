//! End to end: the planner service, the simulator and robot agents as separate processes over
//! real Zenoh on loopback, a real task database, tasks submitted over HTTP.
//!
//! The tests run one at a time (a lock): each starts a simulator and agents, and two of those
//! at once would fight over 2 cores and make real-time driving meaningless.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::PathBuf;
use std::sync::Mutex;
use std::time::{Duration, Instant};

use fleet_tests::{
    bin_dir, free_port, history_kinds, repo_root, robot, robot_xy, start_robots, state_kind,
    Robots, Service,
};
use protocol::ControllerKind;
use serde_json::{json, Value};

static ONE_AT_A_TIME: Mutex<()> = Mutex::new(());
const TOKEN: &str = "e2e-test-token-0123456789abcdef";
const MAP: &str = "junctions";

fn scenario() -> PathBuf {
    repo_root().join("sim/scenarios/task_a.yaml")
}

fn plan_yaml() -> PathBuf {
    repo_root().join("sim/scenarios/maps/junctions.yaml")
}

/// Service + map + simulator + one dynamic-window agent per robot, all robots online.
struct Fleet {
    service: Service,
    /// The simulator and the agents, started by the launcher `planner-service demo` uses.
    robots: Robots,
    data: tempfile::TempDir,
    zenoh_port: u16,
}

fn start_fleet(robots: usize) -> Fleet {
    let bins = bin_dir().unwrap();
    let data = tempfile::tempdir().unwrap();
    let zenoh_port = free_port().unwrap();
    let service = Service::start(&bins, data.path(), zenoh_port, TOKEN).unwrap();
    let meta = service.upload_ros_map(MAP, &plan_yaml()).unwrap();
    assert_eq!(meta["name"], MAP);
    let robots = start_robots(
        &bins,
        &scenario(),
        robots,
        MAP,
        ControllerKind::DynamicWindow,
        &service.zenoh,
    )
    .unwrap();
    let ids: Vec<String> = robots
        .roster
        .robots
        .iter()
        .map(|r| r.id.to_string())
        .collect();
    service
        .wait_for("/api/v1/robots", Duration::from_secs(90), |v| {
            ids.iter()
                .all(|id| {
                    robot(v, id).is_some_and(|r| r["online"] == true && r["pose"].is_object())
                })
                .then_some(())
        })
        .unwrap();
    Fleet {
        service,
        robots,
        data,
        zenoh_port,
    }
}

fn create_task(service: &Service, robot_id: &str, goals: &[(f64, f64)]) -> String {
    let goals: Vec<Value> = goals
        .iter()
        .map(|(x, y)| json!({"x_m": x, "y_m": y}))
        .collect();
    let (status, body) = service
        .post(
            "/api/v1/tasks",
            &json!({"map": MAP, "robot_id": robot_id, "goals": goals}),
        )
        .unwrap();
    assert_eq!(status, 201, "{body}");
    body["id"].as_str().unwrap().to_string()
}

fn wait_task(service: &Service, id: &str, kind: &str, timeout: Duration) -> Value {
    service
        .wait_for(&format!("/api/v1/tasks/{id}"), timeout, |t| {
            (state_kind(t) == kind).then(|| t.clone())
        })
        .unwrap()
}

fn pose_of(service: &Service, id: &str) -> (f64, f64) {
    robot_xy(service, id).unwrap().unwrap()
}

fn moved_m(a: (f64, f64), b: (f64, f64)) -> f64 {
    (a.0 - b.0).hypot(a.1 - b.1)
}

#[test]
fn a_two_goal_task_is_driven_to_completion_and_a_cancelled_robot_stops() {
    let _one = ONE_AT_A_TIME
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    let fleet = start_fleet(2);
    let s = &fleet.service;

    // robot_1: two goals along the first corridor of task A's plan.
    let task = create_task(s, "robot_1", &[(6.0, 4.0), (9.0, 4.0)]);
    let active = wait_task(s, &task, "active", Duration::from_secs(30));
    assert_eq!(active["robot_id"], "robot_1");

    // robot_2: a far goal, cancelled once it is under way.
    let far = create_task(s, "robot_2", &[(23.0, 4.0)]);
    wait_task(s, &far, "active", Duration::from_secs(30));
    let start = pose_of(s, "robot_2");
    s.wait_for("/api/v1/robots/robot_2", Duration::from_secs(60), |r| {
        let p = (r["pose"]["x_m"].as_f64()?, r["pose"]["y_m"].as_f64()?);
        (moved_m(p, start) > 0.5).then_some(())
    })
    .unwrap();
    let (status, cancelled) = s
        .post(&format!("/api/v1/tasks/{far}/cancel"), &json!({}))
        .unwrap();
    assert_eq!(status, 200, "{cancelled}");
    assert_eq!(state_kind(&cancelled), "cancelled");
    // Stopped: within a few seconds the pose no longer changes.
    std::thread::sleep(Duration::from_secs(4));
    let a = pose_of(s, "robot_2");
    std::thread::sleep(Duration::from_secs(2));
    let b = pose_of(s, "robot_2");
    assert!(
        moved_m(a, b) < 0.05,
        "robot_2 still moves after cancel: {a:?} -> {b:?}"
    );
    let (status, again) = s
        .post(&format!("/api/v1/tasks/{far}/cancel"), &json!({}))
        .unwrap();
    assert_eq!(status, 409, "{again}");

    let done = wait_task(s, &task, "completed", Duration::from_secs(180));
    let kinds = history_kinds(&done);
    assert!(
        kinds.contains(&"active") && kinds.last() == Some(&"completed"),
        "{kinds:?}"
    );
    let end = pose_of(s, "robot_1");
    assert!(moved_m(end, (9.0, 4.0)) < 0.6, "robot_1 ended at {end:?}");
    let metrics = reqwest::blocking::get(format!("{}/metrics", s.url))
        .unwrap()
        .text()
        .unwrap();
    assert!(
        metrics.contains("fleet_replan_latency_seconds_count"),
        "{metrics}"
    );
    drop(fleet);
}

#[test]
fn a_killed_agent_pauses_its_task_and_the_other_robot_carries_on() {
    let _one = ONE_AT_A_TIME
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    let mut fleet = start_fleet(2);
    let t1 = create_task(&fleet.service, "robot_1", &[(8.0, 4.0)]);
    let t2 = create_task(&fleet.service, "robot_2", &[(13.0, 10.0)]);
    wait_task(&fleet.service, &t2, "active", Duration::from_secs(30));
    let victim = fleet
        .robots
        .agents
        .iter_mut()
        .find(|a| a.name == "agent robot_2")
        .unwrap();
    victim.kill();
    let paused = wait_task(&fleet.service, &t2, "paused", Duration::from_secs(15));
    let reason = paused["state"]["reason"].as_str().unwrap();
    assert!(
        reason.contains("robot_2") || reason.contains("liveliness"),
        "{reason}"
    );
    let r2 = fleet.service.get("/api/v1/robots/robot_2").unwrap();
    assert_eq!(r2["online"], false);
    wait_task(&fleet.service, &t1, "completed", Duration::from_secs(180));
    assert!(fleet.robots.sim.is_running());
}

#[test]
fn a_restarted_service_resumes_the_task_from_its_database() {
    let _one = ONE_AT_A_TIME
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    let mut fleet = start_fleet(1);
    let task = create_task(&fleet.service, "robot_1", &[(6.0, 4.0), (10.0, 4.0)]);
    wait_task(&fleet.service, &task, "active", Duration::from_secs(30));
    let bins = bin_dir().unwrap();
    // A crash mid-task: no goodbye, no flush beyond what was committed.
    fleet.service.proc.kill();
    let t0 = Instant::now();
    fleet.service = Service::start(&bins, fleet.data.path(), fleet.zenoh_port, TOKEN).unwrap();
    let s = &fleet.service;
    let stored = s.get(&format!("/api/v1/tasks/{task}")).unwrap();
    assert!(
        matches!(state_kind(&stored), "active" | "paused"),
        "after restart: {stored}"
    );
    s.wait_for("/api/v1/robots/robot_1", Duration::from_secs(60), |r| {
        (r["online"] == true).then_some(())
    })
    .unwrap();
    let done = wait_task(s, &task, "completed", Duration::from_secs(180));
    assert!(done["history"].as_array().unwrap().len() >= 3, "{done}");
    eprintln!(
        "resumed and completed {:.1} s after the restart",
        t0.elapsed().as_secs_f64()
    );
}
