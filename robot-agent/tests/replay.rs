//! `robot-agent replay` on a run log made here from the simulator: the robot drives a scripted
//! path down task A's start corridor while the agent's own supervisor localizes it (its poses
//! recorded as `/amcl_pose`, the truth as `/ground_truth`, one re-initialisation on the way).
//! The replay reproduces the recorded poses exactly, measures the error against the truth, and
//! the binary prints the summary and writes the estimates; a file that is not MCAP is refused.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::{Path, PathBuf};
use std::process::Command as Process;
use std::time::{Duration, Instant};

use fleet_log::{InitialPose, LogOptions, LogWriter, MapInfo, RunLog};
use protocol::{Header, MapName, MapRef};
use robot_agent::controllers::DynamicWindow;
use robot_agent::{AgentConfig, Supervisor};
use sim::{Command, SimConfig, World};
use test_support::scenario;

fn plan_path() -> PathBuf {
    let path = scenario("task_a");
    sim::Scenario::load(&path).unwrap().floor_plan_path(&path)
}

/// Records 12 s of a scripted drive (10 Hz) with the agent localizing live; re-initialises the
/// filter at the true pose after 6 s. Returns the mean live error against the truth.
fn record(path: &Path, seed: u64) -> f64 {
    let mut world = World::from_scenario_file(&scenario("task_a"), SimConfig::default()).unwrap();
    world.add_robots_at_start(1).unwrap();
    let start = world.ground_truth_pose(0).unwrap();
    let mut config = AgentConfig::default();
    config.amcl.seed = seed;
    config.localization.initial_pose = Some(start);
    let covariance = config.localization.initial_covariance();
    let mut writer = LogWriter::create(path, LogOptions::default()).unwrap();
    writer
        .map(&MapInfo {
            stamp_ns: 0,
            name: "junctions".into(),
            version: 1,
            path: Some(plan_path().display().to_string()),
            content_hash: Some(world.plan.content_hash()),
            initial_pose: Some(start),
            initial_covariance: Some(covariance),
            source: "test".into(),
        })
        .unwrap();
    writer.agent_config(0, &config).unwrap();
    let map = MapRef {
        name: MapName::new("junctions").unwrap(),
        version: 1,
    };
    let mut agent = Supervisor::new(
        config,
        map,
        &world.plan,
        Box::new(DynamicWindow::new(Default::default()).unwrap()),
    )
    .unwrap();
    let epoch = Instant::now();
    let (mut sum, mut n) = (0.0, 0);
    for k in 0..120u64 {
        // Along the corridor, weaving a little.
        let cmd = Command {
            v_mps: 0.4,
            omega_radps: if (k / 20) % 2 == 0 { 0.08 } else { -0.08 },
        };
        let obs = world.step(&[cmd], 0.1);
        let o = &obs.robots[0];
        writer.odom(&o.odom).unwrap();
        writer.scan(&o.scan).unwrap();
        writer
            .ground_truth(o.odom.header, o.ground_truth_pose)
            .unwrap();
        agent.on_odometry(o.odom.clone());
        let now = epoch + Duration::from_nanos(obs.time_ns);
        if let Some(pose) = agent.on_scan(o.scan.clone(), now, obs.time_ns).unwrap() {
            sum += pose.pose.distance_m(&o.ground_truth_pose);
            n += 1;
            writer.amcl_pose(&pose).unwrap();
        }
        if k == 60 {
            let header = Header::new(1, obs.time_ns);
            agent.set_pose(o.ground_truth_pose, covariance).unwrap();
            writer
                .initial_pose(&InitialPose {
                    header,
                    pose: o.ground_truth_pose,
                    covariance,
                })
                .unwrap();
        }
    }
    writer.finish().unwrap();
    sum / f64::from(n)
}

#[test]
fn a_replay_reproduces_the_live_estimates_and_measures_the_error() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("drive.mcap");
    let live_mean_m = record(&path, 11);
    let log = RunLog::open(&path).unwrap();
    let counts = log.counts();
    assert_eq!(counts[&fleet_log::Topic::Scan], 120);
    assert_eq!(counts[&fleet_log::Topic::AmclPose], 120);
    assert_eq!(counts[&fleet_log::Topic::InitialPose], 1);

    let grid = map_core::load_ros_map(&plan_path(), &map_core::ImportLimits::default())
        .unwrap()
        .grid;
    let config = robot_agent::replay::recorded_config(&log).unwrap();
    assert_eq!(config.amcl.seed, 11);
    let replay = robot_agent::replay::replay(&log, &grid, &config).unwrap();
    let s = &replay.summary;
    println!("{}", robot_agent::replay::markdown(std::slice::from_ref(s)));
    assert_eq!(s.scans, 120);
    assert_eq!(s.reinitialisations, 1);
    assert_eq!(s.map_matches, Some(true));
    assert_eq!(replay.poses.len(), 120);
    // Exactly the live estimates, and so exactly the live error.
    assert_eq!(s.max_live_difference_m, Some(0.0));
    let pos = s.position_error_m.unwrap();
    assert_eq!(pos.count, 120);
    assert!(
        (pos.mean - live_mean_m).abs() < 1e-12,
        "{pos:?} vs {live_mean_m}"
    );
    assert_eq!(s.live_position_error_m.unwrap().mean, pos.mean);
    assert!(pos.mean < 0.15 && pos.max < 0.5, "{pos:?}");
    assert!(s.heading_error_deg.unwrap().mean < 5.0, "{s:?}");
    // 12 s at 0.4 m/s.
    assert!((s.distance_m - 4.8).abs() < 0.2, "{}", s.distance_m);
    assert!(s.update_ms.mean > 0.0 && s.update_ms.max >= s.update_ms.mean);

    // Another seed: other random numbers, so other estimates, but as good.
    let mut other = config.clone();
    other.amcl.seed = 12;
    let reseeded = robot_agent::replay::replay(&log, &grid, &other).unwrap();
    let d = reseeded.summary.max_live_difference_m.unwrap();
    assert!(d > 0.0 && d < 0.3, "{d}");
    assert!(reseeded.summary.position_error_m.unwrap().mean < 0.15);
    // The wrong map is noticed.
    let mut moved = map_core::OccupancyGrid::new(
        grid.width_cells(),
        grid.height_cells(),
        grid.resolution_m(),
        grid.origin(),
        grid.cells().to_vec(),
    )
    .unwrap();
    let flipped = if moved.get(0, 0) == Some(0) { 100 } else { 0 };
    moved.set(0, 0, flipped);
    let wrong = robot_agent::replay::replay(&log, &moved, &config).unwrap();
    assert_eq!(wrong.summary.map_matches, Some(false));
}

#[test]
fn the_binary_prints_the_summary_and_writes_the_estimates() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("drive.mcap");
    record(&log, 3);
    let csv = dir.path().join("poses.csv");
    let summary = dir.path().join("summary.json");
    let out = Process::new(env!("CARGO_BIN_EXE_robot-agent"))
        .args(["replay", "--log"])
        .arg(&log)
        .arg("--map")
        .arg(plan_path())
        .arg("--out")
        .arg(&csv)
        .arg("--summary")
        .arg(&summary)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(stdout.contains("| drive.mcap | 120 | 1 |"), "{stdout}");
    let text = std::fs::read_to_string(&csv).unwrap();
    let mut lines = text.lines();
    assert_eq!(
        lines.next().unwrap(),
        "stamp_ns,x_m,y_m,yaw_rad,position_error_m,heading_error_deg,live_difference_m,update_ms,filter_ran"
    );
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    assert_eq!(rows.len(), 120);
    assert_eq!(rows[0][0], "100000000");
    assert_eq!(rows[0][6], "0");
    // The first scan always runs the filter; a scripted drive that keeps moving runs it on
    // most scans, and a scan without enough motion only carries the estimate forward.
    assert_eq!(rows[0][8], "true");
    let ran = rows.iter().filter(|r| r[8] == "true").count();
    assert!(ran > 60 && ran <= 120, "{ran} of 120 scans ran the filter");
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&summary).unwrap()).unwrap();
    assert_eq!(json["max_live_difference_m"], 0.0);

    // JSON lines by default; another configuration through --config.
    let config = dir.path().join("agent.toml");
    std::fs::write(&config, "[amcl]\nseed = 99\nmax_particles = 1000\n").unwrap();
    let jsonl = dir.path().join("poses.jsonl");
    let out = Process::new(env!("CARGO_BIN_EXE_robot-agent"))
        .args(["replay", "--log"])
        .arg(&log)
        .arg("--map")
        .arg(plan_path())
        .arg("--config")
        .arg(&config)
        .arg("--out")
        .arg(&jsonl)
        .output()
        .unwrap();
    assert!(out.status.success());
    let first: serde_json::Value = serde_json::from_str(
        std::fs::read_to_string(&jsonl)
            .unwrap()
            .lines()
            .next()
            .unwrap(),
    )
    .unwrap();
    assert!(first["position_error_m"].as_f64().unwrap() < 0.5, "{first}");

    // --particles pins the count; a count the configuration refuses is named.
    let pinned = |n: &str| {
        Process::new(env!("CARGO_BIN_EXE_robot-agent"))
            .args(["replay", "--log"])
            .arg(&log)
            .arg("--map")
            .arg(plan_path())
            .args(["--particles", n])
            .output()
            .unwrap()
    };
    let out = pinned("300");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let out = pinned("0");
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("--particles 0"), "{stderr}");

    // Not MCAP: a clear error naming the file, non-zero exit.
    let out = Process::new(env!("CARGO_BIN_EXE_robot-agent"))
        .args(["replay", "--log"])
        .arg(&csv)
        .arg("--map")
        .arg(plan_path())
        .output()
        .unwrap();
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("poses.csv") && stderr.contains("not an MCAP file"),
        "{stderr}"
    );
    // `replay` needs no --robot-id; the agent without a subcommand still does.
    let out = Process::new(env!("CARGO_BIN_EXE_robot-agent"))
        .args(["--map", "office"])
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("--robot-id"));
}
