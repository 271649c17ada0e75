//! Replanning in worker processes (issue 16, docs/deploy.md): the service keeps the task book,
//! two `planner-service worker` processes plan the robots, each those rendezvous hashing gives
//! it. Killing the worker that plans a robot hands the robot to the other within a second,
//! without pausing its task; with no worker left the service plans again; the task completes.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::process::Command;
use std::time::{Duration, Instant};

use fleet_tests::{
    alive_workers, bin_dir, free_port, history_kinds, planned_by, repo_root, robot_xy,
    start_robots, start_worker, state_kind, task_once_online, Service,
};
use protocol::ControllerKind;
use serde_json::Value;

const TOKEN: &str = "workers-test-token-0123456789abcdef";
const MAP: &str = "junctions";

/// Polls every 20 ms until robot `robot` is planned by a worker `accept` takes, up to
/// `timeout`; who, and how long it took.
fn wait_planned_by(
    service: &Service,
    robot: &str,
    timeout: Duration,
    accept: impl Fn(&str) -> bool,
) -> (String, Duration) {
    let start = Instant::now();
    loop {
        if let Some(w) = planned_by(service, robot).unwrap() {
            if accept(&w) {
                return (w, start.elapsed());
            }
        }
        assert!(
            start.elapsed() < timeout,
            "{robot} not handed over within {timeout:?}: {}",
            service.get("/api/v1/workers").unwrap()
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

#[test]
fn workers_share_the_replanning_and_a_dead_workers_robot_moves_within_a_second() {
    let bins = bin_dir().unwrap();
    let data = tempfile::tempdir().unwrap();
    let service = Service::start(&bins, data.path(), free_port().unwrap(), TOKEN).unwrap();
    service
        .upload_ros_map(MAP, &repo_root().join("sim/scenarios/maps/junctions.yaml"))
        .unwrap();
    let exe = || Command::new(bins.join("planner-service"));
    let mut w1 = Some(start_worker(exe(), "w1", &service.zenoh, &[]).unwrap());
    let mut w2 = Some(start_worker(exe(), "w2", &service.zenoh, &[]).unwrap());
    service
        .wait_for("/api/v1/workers", Duration::from_secs(10), |_| {
            let alive = alive_workers(&service).ok()?;
            (alive.contains(&"w1".into()) && alive.contains(&"w2".into())).then_some(())
        })
        .unwrap();

    let robots = start_robots(
        &bins,
        &repo_root().join("sim/scenarios/task_a.yaml"),
        1,
        MAP,
        ControllerKind::DynamicWindow,
        &service.zenoh,
    )
    .unwrap();
    let id = task_once_online(&service, "robot_1", MAP, (9.0, 4.0)).unwrap();
    let task_path = format!("/api/v1/tasks/{id}");
    service
        .wait_for(&task_path, Duration::from_secs(30), |t| {
            (state_kind(t) == "active").then_some(())
        })
        .unwrap();
    // A worker plans the robot, not the service.
    let (first, _) = wait_planned_by(&service, "robot_1", Duration::from_secs(10), |w| {
        w == "w1" || w == "w2"
    });
    std::thread::sleep(Duration::from_secs(2));
    assert_eq!(
        planned_by(&service, "robot_1").unwrap().as_deref(),
        Some(first.as_str())
    );

    // The robot's worker dies: the other takes the robot over within a second.
    let (dead, other) = if first == "w1" {
        (&mut w1, "w2")
    } else {
        (&mut w2, "w1")
    };
    dead.take().unwrap().kill();
    let (_, handover) =
        wait_planned_by(&service, "robot_1", Duration::from_secs(5), |w| w == other);
    eprintln!("handover {first} -> {other}: {handover:?}");
    assert!(
        handover < Duration::from_secs(1),
        "handover took {handover:?}"
    );

    // The last worker goes: the service plans the robot itself again.
    let last = if other == "w1" { &mut w1 } else { &mut w2 };
    last.take().unwrap().kill();
    let (_, back) = wait_planned_by(&service, "robot_1", Duration::from_secs(5), |w| {
        w == "service"
    });
    eprintln!("handover {other} -> service: {back:?}");
    assert!(back < Duration::from_secs(1), "the service took {back:?}");

    let done: Value = service
        .wait_for(&task_path, Duration::from_secs(180), |t| {
            (state_kind(t) == "completed").then(|| t.clone())
        })
        .unwrap();
    assert!(
        !history_kinds(&done).contains(&"paused"),
        "the task paused during a handover: {:?}",
        history_kinds(&done)
    );
    let (x, y) = robot_xy(&service, "robot_1").unwrap().unwrap();
    assert!(
        (x - 9.0).hypot(y - 4.0) < 0.6,
        "robot_1 ended at ({x}, {y})"
    );

    // Each worker's replans are in /metrics under its name.
    let metrics = reqwest::blocking::get(format!("{}/metrics", service.url))
        .unwrap()
        .text()
        .unwrap();
    for w in ["w1", "w2", "service"] {
        let line = metrics
            .lines()
            .find(|l| l.starts_with(&format!("fleet_worker_replans_total{{worker=\"{w}\"}}")))
            .unwrap_or_else(|| panic!("no replans of {w} in /metrics"));
        let n: u64 = line.rsplit(' ').next().unwrap().parse().unwrap();
        assert!(n > 0, "{line}");
    }
    robots.stop(Duration::from_secs(5));
}
