//! AMCL accuracy over the whole of task B (all four goals), lock-step against the simulator's
//! ground truth, with the default agent configuration: the requirement is a mean position
//! error of at most 0.10 m and a mean heading error of at most 3 degrees, without divergence.
//! The privileged expert drives, so that what is measured is the localization and not the
//! dynamic window's collisions with glass it cannot see (docs/evaluation.md).

#![allow(clippy::unwrap_used)]

use std::path::Path;

use eval::amcl_accuracy::{self, AccuracyOptions};
use eval::table::{self, TableOptions};
use protocol::ControllerKind;

#[test]
fn task_b_meets_the_accuracy_requirement_with_the_defaults() {
    let scenarios = Path::new(env!("CARGO_MANIFEST_DIR")).join("../sim/scenarios");
    let path = table::task_scenario(&scenarios, "b").unwrap();
    let options = AccuracyOptions {
        controller: ControllerKind::Expert,
        ..AccuracyOptions::default()
    };
    let r = amcl_accuracy::run_task(&path, &options, |_| {}).unwrap();
    println!("{}", amcl_accuracy::markdown(std::slice::from_ref(&r)));
    assert_eq!(r.goals_total, 4, "{r:?}");
    assert_eq!(r.goals_reached, 4, "{r:?}");
    assert!(r.distance_m > 50.0, "{r:?}");
    // Interventions are counted, not free. With paths kept to the middle of passages
    // (planning::centring) the expert, on its way back west to goal 3, meets a walking person
    // head-on in the middle of the 1.2 m opening of the glass door at x = 20 m and both stand
    // (its give-way rule finds narrow passages on the floor plan, which has no glass); the
    // judge carries it on once (docs/evaluation.md, round 12). Localization is what is measured.
    assert!(r.interventions <= 1, "{r:?}");
    assert_eq!(r.collisions, 0, "{r:?}");
    assert!(!r.diverged, "{r:?}");
    assert!(
        r.mean_position_error_m <= amcl_accuracy::MAX_MEAN_POSITION_ERROR_M,
        "{r:?}"
    );
    assert!(
        r.mean_heading_error_deg <= amcl_accuracy::MAX_MEAN_HEADING_ERROR_DEG,
        "{r:?}"
    );
    assert!(r.pass);
}

#[test]
fn bad_task_and_options_are_refused() {
    let scenarios = Path::new(env!("CARGO_MANIFEST_DIR")).join("../sim/scenarios");
    let err = table::task_scenario(&scenarios, "z").unwrap_err();
    assert!(err.to_string().contains("tasks = z"), "{err}");
    let path = table::task_scenario(&scenarios, "a").unwrap();
    let options = AccuracyOptions {
        run: TableOptions {
            stuck_timeout_s: 0.0,
            ..TableOptions::default()
        },
        ..AccuracyOptions::default()
    };
    let err = amcl_accuracy::run_task(&path, &options, |_| {}).unwrap_err();
    assert!(err.to_string().contains("stuck_timeout_s = 0"), "{err}");
}
