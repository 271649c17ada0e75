//! Run logs of lock-step runs on task A (seed 1, cut to 20 simulated seconds): what the log
//! holds, that the agent's AMCL replayed over it reproduces the live run (same filter, same
//! seed, same inputs in the same order: the same estimates exactly), re-initialisations after
//! interventions included, and that `eval amcl-accuracy --log` prints the same row as the run.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::{Path, PathBuf};

use eval::amcl_accuracy::{self, AccuracyOptions};
use eval::table::log::{log_path, RecordSettings};
use eval::table::{self, TableOptions};
use fleet_log::{LogMessage, LogOptions, RunLog, Topic};
use protocol::ControllerKind;

fn task_a() -> PathBuf {
    let scenarios = Path::new(env!("CARGO_MANIFEST_DIR")).join("../sim/scenarios");
    table::task_scenario(&scenarios, "a").unwrap()
}

/// Drives task A for `seconds` with seed 1, recording into `dir`.
fn drive(dir: &Path, seconds: f64, stuck_timeout_s: f64) -> amcl_accuracy::TaskAccuracy {
    let options = AccuracyOptions {
        seed: 1,
        controller: ControllerKind::DynamicWindow,
        run: TableOptions {
            time_limit_s: Some(seconds),
            stuck_timeout_s,
            record: Some(RecordSettings {
                dir: dir.to_path_buf(),
                log: LogOptions::default(),
            }),
            ..TableOptions::default()
        },
    };
    amcl_accuracy::run_task(&task_a(), &options, |_| {}).unwrap()
}

fn stamps(log: &RunLog, topic: Topic) -> Vec<u64> {
    log.as_recorded()
        .iter()
        .filter(|e| e.message.topic() == topic)
        .map(|e| e.log_time_ns)
        .collect()
}

#[test]
fn a_recorded_run_replays_to_the_live_estimates() {
    let dir = tempfile::tempdir().unwrap();
    let live = drive(dir.path(), 20.0, 10.0);
    let file = log_path(dir.path(), "task_a", ControllerKind::DynamicWindow, 1);
    assert_eq!(file, dir.path().join("task_a-dynamic-window-seed1.mcap"));
    assert!(file.is_file());
    assert!(!fleet_log::partial_path(&file).exists());

    let log = RunLog::open(&file).unwrap();
    let counts = log.counts();
    println!("{counts:?}");
    // 20 s at 10 Hz: a scan, an odometry reading, a true pose, a published pose and a command
    // every cycle; an intention every cycle it was answered.
    for topic in [Topic::Odom, Topic::Scan, Topic::AmclPose, Topic::CmdVel] {
        assert_eq!(counts[&topic], 200, "{topic}: {counts:?}");
    }
    // The truth also at the start and after each carry.
    assert_eq!(
        counts[&Topic::GroundTruth],
        201 + live.interventions as usize
    );
    assert!(counts[&Topic::Intention] > 150, "{counts:?}");
    assert_eq!(counts[&Topic::Map], 1);
    assert_eq!(counts[&Topic::AgentConfig], 1);
    assert_eq!(counts[&Topic::RunSummary], 1);
    assert!(!counts.contains_key(&Topic::Camera));
    // Who drove: written when it changes, numbered, the dynamic window driving itself.
    let statuses = log.agent_statuses();
    assert!(!statuses.is_empty() && statuses.len() < 200, "{counts:?}");
    assert!(statuses
        .iter()
        .enumerate()
        .all(|(i, s)| s.header.seq == i as u64 + 1
            && s.controller == ControllerKind::DynamicWindow
            && !s.recovering));
    assert!(statuses
        .iter()
        .any(|s| s.state == protocol::AgentState::Driving));
    for pair in statuses.windows(2) {
        let (a, b) = (pair[0], pair[1]);
        assert!(
            (
                a.state,
                &a.stop_reason,
                a.localized,
                a.rotating_in_place,
                a.giving_way
            ) != (
                b.state,
                &b.stop_reason,
                b.localized,
                b.rotating_in_place,
                b.giving_way
            ),
            "{a:?} repeated"
        );
    }
    assert_eq!(
        counts.get(&Topic::InitialPose).copied().unwrap_or(0),
        live.interventions as usize
    );
    // Stamps: the simulated clock, every 100 ms, increasing on each topic; the whole log in
    // time order from the /map record at 0 to the summary at 20 s.
    let scans = stamps(&log, Topic::Scan);
    assert_eq!(scans[0], 100_000_000);
    assert_eq!(*scans.last().unwrap(), 20_000_000_000);
    assert!(scans.windows(2).all(|w| w[1] - w[0] == 100_000_000));
    for topic in [Topic::Odom, Topic::AmclPose, Topic::CmdVel] {
        assert!(
            stamps(&log, topic).windows(2).all(|w| w[0] < w[1]),
            "{topic}"
        );
    }
    assert!(stamps(&log, Topic::GroundTruth)
        .windows(2)
        .all(|w| w[0] <= w[1]));
    let all: Vec<u64> = log.messages().iter().map(|e| e.log_time_ns).collect();
    assert!(all.windows(2).all(|w| w[0] <= w[1]));
    assert_eq!(all.first(), Some(&0));
    for e in log.as_recorded() {
        assert_eq!(e.log_time_ns, e.message.stamp_ns());
    }
    let map = log.map().unwrap();
    assert_eq!(map.name, "junctions");
    assert!(map.path.as_deref().unwrap().ends_with("junctions.yaml"));
    assert!(map.initial_pose.is_some() && map.initial_covariance.is_some());
    let summary = log.run_summary().unwrap();
    assert_eq!((summary.scenario.as_str(), summary.seed), ("task_a", 1));
    assert!((summary.time_s - 20.0).abs() < 1e-9, "{summary:?}");
    // The intention carries no pixels in the log.
    assert!(log.as_recorded().iter().all(|e| match &e.message {
        LogMessage::Intention(i) => i.lpe.as_ref().is_none_or(|l| l.data.is_empty()),
        _ => true,
    }));

    // The replay: the same estimates, so the same error as the live run.
    let grid = map_core::load_ros_map(
        Path::new(map.path.as_deref().unwrap()),
        &map_core::ImportLimits::default(),
    )
    .unwrap()
    .grid;
    let config = robot_agent::replay::recorded_config(&log).unwrap();
    let replay = robot_agent::replay::replay(&log, &grid, &config).unwrap();
    let s = &replay.summary;
    println!("{}", robot_agent::replay::markdown(std::slice::from_ref(s)));
    println!("{}", amcl_accuracy::markdown(std::slice::from_ref(&live)));
    assert_eq!(s.map_matches, Some(true));
    assert_eq!(s.scans, 200);
    assert_eq!(s.max_live_difference_m, Some(0.0));
    let pos = s.position_error_m.unwrap();
    let heading = s.heading_error_deg.unwrap();
    assert_eq!(pos.count, 200);
    assert!((pos.mean - live.mean_position_error_m).abs() < 1e-12);
    assert!((pos.max - live.max_position_error_m).abs() < 1e-12);
    assert!((heading.mean - live.mean_heading_error_deg).abs() < 1e-9);
    assert!((heading.max - live.max_heading_error_deg).abs() < 1e-9);
    assert!(
        (s.distance_m - live.distance_m).abs() < 1e-6,
        "{s:?} {live:?}"
    );

    // `eval amcl-accuracy --log` reads the logs instead of driving: the same row.
    let from_log = amcl_accuracy::from_log(&file, None, None).unwrap();
    assert_eq!(from_log, live);
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_eval"))
        .args(["amcl-accuracy", "--log"])
        .arg(dir.path())
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(
        stdout.trim(),
        amcl_accuracy::markdown(std::slice::from_ref(&live)).trim()
    );
    // Not MCAP: the error names the file.
    let bad = dir.path().join("notes.mcap");
    std::fs::write(&bad, "just text").unwrap();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_eval"))
        .args(["amcl-accuracy", "--log"])
        .arg(&bad)
        .output()
        .unwrap();
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("notes.mcap") && stderr.contains("not an MCAP file"),
        "{stderr}"
    );
}

#[test]
fn interventions_are_in_the_log_and_the_replay_reinitialises_there() {
    let dir = tempfile::tempdir().unwrap();
    // A judge this impatient intervenes early and often.
    let live = drive(dir.path(), 15.0, 1.0);
    assert!(live.interventions >= 1, "{live:?}");
    let file = log_path(dir.path(), "task_a", ControllerKind::DynamicWindow, 1);
    let log = RunLog::open(&file).unwrap();
    let inits: Vec<&fleet_log::InitialPose> = log
        .as_recorded()
        .iter()
        .filter_map(|e| match &e.message {
            LogMessage::InitialPose(p) => Some(p),
            _ => None,
        })
        .collect();
    assert_eq!(inits.len(), live.interventions as usize);
    // Each comes after the scan of its cycle, with the same stamp.
    let scans = stamps(&log, Topic::Scan);
    for init in &inits {
        assert!(scans.contains(&init.header.stamp_ns), "{init:?}");
    }
    let grid = map_core::load_ros_map(
        Path::new(log.map().unwrap().path.as_deref().unwrap()),
        &map_core::ImportLimits::default(),
    )
    .unwrap()
    .grid;
    let config = robot_agent::replay::recorded_config(&log).unwrap();
    let replay = robot_agent::replay::replay(&log, &grid, &config).unwrap();
    assert_eq!(replay.summary.reinitialisations, inits.len());
    assert_eq!(replay.summary.max_live_difference_m, Some(0.0));
    assert!(
        (replay.summary.position_error_m.unwrap().mean - live.mean_position_error_m).abs() < 1e-12
    );
    assert_eq!(amcl_accuracy::from_log(&file, None, None).unwrap(), live);

    // Without the re-initialisations the filter would have to find the carried robot by itself:
    // the replay is no longer the live run.
    let mut stripped =
        fleet_log::LogWriter::create(&dir.path().join("stripped.mcap"), LogOptions::default())
            .unwrap();
    for e in log.as_recorded() {
        if !matches!(e.message, LogMessage::InitialPose(_)) {
            stripped.write(&e.message).unwrap();
        }
    }
    let stripped = RunLog::open(&stripped.finish().unwrap()).unwrap();
    let without = robot_agent::replay::replay(&stripped, &grid, &config).unwrap();
    assert_eq!(without.summary.reinitialisations, 0);
    assert!(without.summary.max_live_difference_m.unwrap() > 0.1);
}
