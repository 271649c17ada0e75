//! `planner-service bench-fleet` as a user runs it: the service in this process, the robots in
//! a `bench-robots` process over Zenoh TCP on loopback, path reuse measured beside full
//! replanning in the same run, and the JSON the issue names.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::process::Command;

#[test]
fn a_short_run_measures_path_reuse_beside_full_replanning() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("fleet.json");
    let map = test_support::nav2_maps_dir().join("depot.yaml");
    let output = Command::new(env!("CARGO_BIN_EXE_planner-service"))
        .args(["bench-fleet", "--robots", "4", "--rate-hz", "10"])
        .args(["--duration-s", "3", "--path-reuse", "--map"])
        .arg(&map)
        .arg("--out")
        .arg(&out)
        .env("RUST_LOG", "warn")
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(
        output.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&output.stderr)
    );
    assert!(
        stdout.contains("| path reuse |") && stdout.contains("| full |"),
        "{stdout}"
    );

    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    assert_eq!(report["robots"], 4);
    assert_eq!(report["rate_hz"], 10.0);
    assert_eq!(report["path_reuse"], true);
    for key in ["answered_fraction", "p50_ms", "p99_ms", "replans_per_s"] {
        assert!(report[key].as_f64().unwrap() > 0.0, "{key}: {report}");
    }
    let (measured, full) = (&report["measured"], &report["full_replanning"]);
    assert_eq!(measured["path_reuse"], true);
    assert_eq!(full["path_reuse"], false);
    for mode in [measured, full] {
        // 4 robots at 10 Hz for 3 s, each pose answered on an idle machine's loopback.
        let sent = mode["poses_sent"].as_u64().unwrap();
        assert!((100..=130).contains(&sent), "{mode}");
        assert!(mode["answered_fraction"].as_f64().unwrap() > 0.9, "{mode}");
        assert!(mode["tasks_created"].as_u64().unwrap() >= 4, "{mode}");
        assert!(mode["replans"].as_u64().unwrap() > 50, "{mode}");
    }
    // Robots that follow their paths are mostly answered from the kept plan; full replanning
    // never is.
    let kept = measured["kept_plan_answers"].as_u64().unwrap();
    assert!(
        kept * 2 > measured["replans"].as_u64().unwrap(),
        "{measured}"
    );
    assert_eq!(full["kept_plan_answers"], 0);
}

#[test]
fn bad_options_are_refused_by_name() {
    let output = Command::new(env!("CARGO_BIN_EXE_planner-service"))
        .args(["bench-fleet", "--robots", "0", "--duration-s", "1", "--map"])
        .arg(test_support::nav2_maps_dir().join("depot.yaml"))
        .output()
        .unwrap();
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(stderr.contains("robots = 0"), "{stderr}");
}
