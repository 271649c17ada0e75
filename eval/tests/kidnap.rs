//! Kidnap trials in the simulator (`eval kidnap`): the agent notices that it was carried away,
//! reports lost localization, turns in place and finds itself again; without relocalization it
//! only reports.

// Test helpers outside #[test] functions: a failed setup should fail the test loudly.
#![allow(clippy::unwrap_used)]

use eval::kidnap::{self, KidnapOptions};

fn depot() -> std::path::PathBuf {
    test_support::paths::nav2_maps_dir().join("depot.yaml")
}

fn options(first_seed: u64) -> KidnapOptions {
    KidnapOptions {
        trials: 1,
        first_seed,
        after_s: 15.0,
        ..KidnapOptions::default()
    }
}

#[test]
fn a_kidnapped_agent_reports_lost_and_relocalizes() {
    // Seed 2 carries the robot from the aisle at (12.3, 7.8) to (7.5, 6.4).
    let report = kidnap::run(&depot(), &options(2), |_| {}).unwrap();
    let t = &report.trials[0];
    let (from, to) = (t.from.unwrap(), t.to.unwrap());
    assert!((from.distance_m(&to) - 5.0).abs() < 1e-9, "{t:?}");
    let lost = t.lost_reported_after_s.expect("never reported lost");
    assert!(lost <= 3.0, "{t:?}");
    let found = t.reconverged_after_s.expect("never re-converged");
    assert!(found > 0.0 && found <= 10.0, "{t:?}");
    assert!(t.final_position_error_m <= 0.1, "{t:?}");
    assert!(t.recovered && report.recovered == 1, "{t:?}");
    let table = kidnap::markdown(&report);
    assert!(table.contains("1/1 trials re-converged"), "{table}");
}

#[test]
fn without_relocalization_the_agent_only_reports_lost() {
    let mut o = options(2);
    o.run.agent.amcl.relocalization_particles = 0;
    let report = kidnap::run(&depot(), &o, |_| {}).unwrap();
    let t = &report.trials[0];
    assert!(t.lost_reported_after_s.is_some(), "{t:?}");
    assert!(t.reconverged_after_s.is_none(), "{t:?}");
    assert!(!t.recovered, "{t:?}");
}

#[test]
fn bad_options_are_refused_by_name() {
    let mut o = options(1);
    o.distance_m = -1.0;
    let err = kidnap::run(&depot(), &o, |_| {}).unwrap_err().to_string();
    assert!(err.contains("distance_m") && err.contains("-1"), "{err}");
    let err = kidnap::run(
        std::path::Path::new("/nonexistent/depot.yaml"),
        &options(1),
        |_| {},
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("/nonexistent/depot.yaml"), "{err}");
}
