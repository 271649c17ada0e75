//! `planner-service demo` as a user runs it: one process that starts the simulator and the
//! agents, and survives an agent that dies (issue 17, item 7).

#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::time::Duration;

use fleet_tests::{
    bin_dir, child_pids, history_kinds, repo_root, resumed_after_a_pause_and_completed, robot_xy,
    state_kind, Service,
};
use serde_json::Value;

const TOKEN: &str = "demo-test-token-0123456789abcdef";

fn agent_pid(demo: &Service, robot_id: &str) -> Option<u32> {
    child_pids(demo.proc.pid(), &["--robot-id", robot_id])
        .first()
        .copied()
}

/// robot_1's task across the junctions map, once it is online.
fn task_once_online(demo: &Service) -> String {
    fleet_tests::task_once_online(demo, "robot_1", "junctions", (9.0, 4.0)).unwrap()
}

#[test]
fn a_killed_agent_is_restarted_and_its_task_resumes_and_completes() {
    let bins = bin_dir().unwrap();
    let data = tempfile::tempdir().unwrap();
    // A restart delay longer than the silence timeout (2 s), so the pause is seen.
    let config = data.path().join("demo.toml");
    std::fs::write(&config, "[demo.agent_restart]\ninitial_backoff_ms = 4000\n").unwrap();
    let scenario = repo_root().join("sim/scenarios/task_a.yaml");
    let logs = data.path().join("logs");
    let mut demo = Service::start_demo(
        &bins,
        &data.path().join("data"),
        &scenario,
        1,
        TOKEN,
        Some(&config),
        &["--record-dir", logs.to_str().unwrap()],
    )
    .unwrap();
    assert!(demo.zenoh.starts_with("tcp/127.0.0.1:"), "{}", demo.zenoh);
    let id = task_once_online(&demo);
    let task_path = format!("/api/v1/tasks/{id}");
    let wait_state = |kind: &str, secs: u64| -> Value {
        demo.wait_for(&task_path, Duration::from_secs(secs), |t| {
            (state_kind(t) == kind).then(|| t.clone())
        })
        .unwrap()
    };
    wait_state("active", 30);
    demo.wait_for("/api/v1/robots/robot_1", Duration::from_secs(30), |r| {
        (r["status"]["state"] == "driving").then_some(())
    })
    .unwrap();

    // A crash: SIGKILL, no goodbye.
    let first = agent_pid(&demo, "robot_1").expect("the demo runs an agent for robot_1");
    let killed = std::process::Command::new("kill")
        .args(["-KILL", &first.to_string()])
        .status()
        .unwrap();
    assert!(killed.success());

    let paused = wait_state("paused", 15);
    let reason = paused["state"]["reason"].as_str().unwrap();
    assert!(
        reason.contains("robot_1") || reason.contains("liveliness"),
        "{reason}"
    );
    let offline = demo.get("/api/v1/robots/robot_1").unwrap();
    assert_eq!(offline["online"], false, "{offline}");
    assert!(
        offline["status"].is_null(),
        "an offline robot still reports a status: {offline}"
    );
    // The demo itself stays up: restarted with back-off, the task resumes and the robot gets
    // there.
    wait_state("active", 60);
    let second = agent_pid(&demo, "robot_1").expect("a new agent for robot_1");
    assert_ne!(first, second);
    let done = wait_state("completed", 180);
    assert!(
        resumed_after_a_pause_and_completed(&done),
        "{:?}",
        history_kinds(&done)
    );
    let (x, y) = robot_xy(&demo, "robot_1").unwrap().unwrap();
    assert!(
        (x - 9.0).hypot(y - 4.0) < 0.6,
        "robot_1 ended at ({x}, {y})"
    );

    // The run was recorded: the killed agent's log stays unfinished (`.partial`), the
    // restarted agent's and the simulator's are finished when the demo stops (SIGTERM).
    demo.proc.request_stop();
    demo.proc
        .wait_or_kill(std::time::Instant::now() + Duration::from_secs(30));
    let files: Vec<String> = std::fs::read_dir(&logs)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert!(logs.join("robot_1.mcap.partial").is_file(), "{files:?}");
    let agent = fleet_log::RunLog::open(&logs.join("robot_1-restart1.mcap"))
        .unwrap_or_else(|e| panic!("{e} in {files:?}"));
    let counts = agent.counts();
    for topic in [
        fleet_log::Topic::Scan,
        fleet_log::Topic::Odom,
        fleet_log::Topic::AmclPose,
        fleet_log::Topic::Intention,
        fleet_log::Topic::CmdVel,
    ] {
        assert!(
            counts.get(&topic).copied().unwrap_or(0) > 10,
            "{topic}: {counts:?}"
        );
    }
    assert_eq!(agent.map().unwrap().name, "junctions");
    let sim = fleet_log::RunLog::open(&logs.join("sim.mcap")).unwrap();
    let truth = sim.ground_truth();
    let last = truth.last().unwrap().pose;
    assert!((last.x_m - 9.0).hypot(last.y_m - 4.0) < 0.6, "{last:?}");
}

#[test]
fn a_secured_demo_drives_over_mutual_tls_with_access_control() {
    let bins = bin_dir().unwrap();
    let data = tempfile::tempdir().unwrap();
    let scenario = repo_root().join("sim/scenarios/task_a.yaml");
    let data_dir = data.path().join("data");
    let demo =
        Service::start_demo(&bins, &data_dir, &scenario, 1, TOKEN, None, &["--secure"]).unwrap();
    // The robots' network is TLS on loopback only, with the site's certificates and rules.
    assert!(demo.zenoh.starts_with("tls/127.0.0.1:"), "{}", demo.zenoh);
    let site = data_dir.join("zenoh-site");
    for file in [
        "ca.pem",
        "planner.pem",
        "sim.pem",
        "agent.robot_1.pem",
        "acl.json5",
    ] {
        assert!(site.join(file).is_file(), "{file} missing");
    }
    // Poses, status and liveliness (the agent's) reach the planner; intentions (the planner's)
    // reach the agent and commands (the agent's) the simulated base: the task completes.
    let id = task_once_online(&demo);
    demo.wait_for(
        &format!("/api/v1/tasks/{id}"),
        Duration::from_secs(180),
        |t| (state_kind(t) == "completed").then_some(()),
    )
    .unwrap();
}

/// A demo killed outright (SIGKILL: no chance to stop its children) does not leave its
/// simulator and agents running: they see their stdin close and stop by themselves. They used
/// to run on, retrying the dead service's Zenoh endpoint, ready to join whatever listened on
/// that port next with a second `robot_1`. They stop the orderly way, finishing their run logs:
/// the pipes of their stdout and stderr died with the demo, and their first log line after it
/// used to panic in the log subscriber (its fallback `eprintln!` to the same dead stderr) and
/// abort, leaving every log `.partial` (seen in CI's core dumps, 2026-12-01).
#[test]
fn a_demo_killed_outright_leaves_no_simulator_or_agent_behind() {
    let bins = bin_dir().unwrap();
    let data = tempfile::tempdir().unwrap();
    let scenario = repo_root().join("sim/scenarios/task_a.yaml");
    let logs = data.path().join("logs");
    let mut demo = Service::start_demo(
        &bins,
        &data.path().join("data"),
        &scenario,
        2,
        TOKEN,
        None,
        &["--record-dir", logs.to_str().unwrap()],
    )
    .unwrap();
    demo.wait_for("/api/v1/robots", Duration::from_secs(90), |v| {
        let robots = v.as_array()?;
        (robots.len() == 2 && robots.iter().all(|r| r["online"] == true)).then_some(())
    })
    .unwrap();
    let demo_pid = demo.proc.pid();
    let sim = child_pids(demo_pid, &["run", "--scenario"]);
    let agents = [
        agent_pid(&demo, "robot_1").unwrap(),
        agent_pid(&demo, "robot_2").unwrap(),
    ];
    assert_eq!(sim.len(), 1, "the demo runs one simulator: {sim:?}");
    let children: Vec<u32> = sim.iter().copied().chain(agents).collect();

    demo.proc.kill();
    let deadline = std::time::Instant::now() + Duration::from_secs(20);
    let running = || -> Vec<u32> {
        children
            .iter()
            .copied()
            .filter(|pid| {
                // Gone, or a zombie waiting for whoever adopted it to reap it: not running.
                std::fs::read_to_string(format!("/proc/{pid}/stat")).is_ok_and(|stat| {
                    stat.rsplit_once(')')
                        .and_then(|(_, rest)| rest.split_whitespace().next())
                        .is_some_and(|state| state != "Z" && state != "X")
                })
            })
            .collect()
    };
    while !running().is_empty() && std::time::Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(100));
    }
    assert!(
        running().is_empty(),
        "still running 20 s after the demo was killed: {:?} of {children:?}",
        running()
    );
    let files: Vec<String> = std::fs::read_dir(&logs)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    let finished = |name: &str| {
        fleet_log::RunLog::open(&logs.join(name))
            .unwrap_or_else(|e| panic!("{name}: {e}; the logs: {files:?}"))
    };
    assert!(!finished("sim.mcap").ground_truth().is_empty());
    for name in ["robot_1.mcap", "robot_2.mcap"] {
        let counts = finished(name).counts();
        assert!(
            counts.get(&fleet_log::Topic::Odom).copied().unwrap_or(0) > 0,
            "{name}: {counts:?}"
        );
    }
}
