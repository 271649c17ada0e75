//! The `eval table` smoke test CI runs: one task × two methods × one seed through the real
//! binary, checking what it writes.

#![allow(clippy::unwrap_used)]
use std::path::Path;
use std::process::Command;

fn read_json(path: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

#[test]
fn one_task_two_methods_writes_runs_table_and_figures() {
    let out = tempfile::tempdir().unwrap();
    let status = Command::new(env!("CARGO_BIN_EXE_eval"))
        .args([
            "table",
            "--tasks",
            "a",
            "--methods",
            "dynamic-window,expert",
        ])
        .args(["--seeds", "1", "--jobs", "2", "--out"])
        .arg(out.path())
        .arg("--scenarios")
        .arg(test_support::scenarios_dir())
        .status()
        .unwrap();
    assert!(status.success(), "eval table failed: {status}");

    let runs = read_json(&out.path().join("runs.json"));
    let runs = runs.as_array().expect("runs.json is a list");
    assert_eq!(runs.len(), 2);
    for run in runs {
        for key in [
            "scenario",
            "method",
            "seed",
            "success",
            "interventions",
            "collisions",
            "time_s",
            "smoothness",
            "goals_reached",
            "goals_total",
            "min_person_distance_m",
        ] {
            assert!(run.get(key).is_some(), "run lacks {key}: {run}");
        }
        assert_eq!(run["scenario"], "task_a");
        assert_eq!(run["seed"], 0);
        assert_eq!(run["goals_total"], 4);
        // Task A has a person walking the main corridor.
        assert!(run["min_person_distance_m"].as_f64().is_some(), "{run}");
        let smoothness = run["smoothness"].as_f64().expect("a smoothness");
        assert!(smoothness > 0.0 && smoothness.is_finite(), "{run}");
    }
    let expert = runs.iter().find(|r| r["method"] == "expert").unwrap();
    // The teacher gets there without help and without touching anything.
    assert_eq!(expert["success"], true, "{expert}");
    assert_eq!(expert["interventions"], 0, "{expert}");
    assert_eq!(expert["goals_reached"], 4, "{expert}");
    let c = &expert["collisions"];
    for kind in ["wall", "furniture", "glass", "person", "robot"] {
        assert_eq!(c[kind], 0, "expert collided with a {kind}: {expert}");
    }
    let time_s = expert["time_s"].as_f64().unwrap();
    assert!(time_s > 60.0 && time_s < 480.0, "{expert}");
    // The intention audit planned from the true pose too, nearly every cycle, and AMCL's pose
    // gave the true DLM in almost all of them.
    let audit = &expert["intention_audit"];
    let cycles = audit["cycles"].as_f64().unwrap();
    assert!(cycles > 0.8 * time_s / 0.1, "{audit}");
    assert!(
        audit["dlm_differs"].as_f64().unwrap() < 0.1 * cycles,
        "{audit}"
    );

    let table = read_json(&out.path().join("table.json"));
    let rows = table["rows"].as_array().unwrap();
    assert_eq!(rows.len(), 2);
    assert!(rows
        .iter()
        .all(|r| r["runs"] == 1 && r["scenario"] == "task_a"));
    // Places where interventions gathered: none for the expert, and for the window only places
    // of at least two of its own interventions.
    for row in rows {
        let places = row["intervention_places"].as_array().expect("a list");
        let listed: u64 = places
            .iter()
            .map(|p| p["interventions"].as_u64().unwrap())
            .inspect(|&n| assert!(n >= 2, "{row}"))
            .sum();
        let total = runs
            .iter()
            .filter(|r| r["method"] == row["method"])
            .map(|r| r["interventions"].as_u64().unwrap())
            .sum::<u64>();
        assert!(listed <= total, "{row}");
        if row["method"] == "expert" {
            assert!(places.is_empty(), "{row}");
        }
    }
    assert!(table["wall_s"].as_f64().unwrap() > 0.0);
    assert!(table["simulated_s"].as_f64().unwrap() > 60.0);

    let md = std::fs::read_to_string(out.path().join("table.md")).unwrap();
    assert!(md.contains("| task_a | expert | 1/1 |"), "{md}");
    assert!(md.contains("| task_a | dynamic-window |"), "{md}");
    assert!(md.contains("real-time factor"), "{md}");
    assert!(md.contains("Wrong intentions from the pose"), "{md}");

    for picture in ["figures/task_a.png", "figures/grid.png"] {
        let img = image::open(out.path().join(picture))
            .unwrap_or_else(|e| panic!("{picture}: {e}"))
            .to_rgb8();
        assert!(img.width() > 100 && img.height() > 100, "{picture}");
    }
}

#[test]
fn a_missing_model_is_an_error_naming_the_file() {
    let out = tempfile::tempdir().unwrap();
    let models = tempfile::tempdir().unwrap();
    let output = Command::new(env!("CARGO_BIN_EXE_eval"))
        .args(["table", "--tasks", "a", "--methods", "dlm", "--seeds", "1"])
        .arg("--models")
        .arg(models.path())
        .arg("--out")
        .arg(out.path())
        .arg("--scenarios")
        .arg(test_support::scenarios_dir())
        .output()
        .unwrap();
    assert!(!output.status.success());
    let err = String::from_utf8_lossy(&output.stderr);
    let expected = models.path().join("dlm.onnx");
    assert!(
        err.contains(&expected.display().to_string()),
        "error should name {}: {err}",
        expected.display()
    );
    assert!(!out.path().join("runs.json").exists());
}

#[test]
fn bad_arguments_are_refused_by_name() {
    let out = tempfile::tempdir().unwrap();
    for (args, needle) in [
        (vec!["--tasks", "z"], "tasks"),
        (vec!["--seeds", "0"], "--seeds"),
        (vec!["--methods", "teleport"], "teleport"),
        (vec!["--encounter", "sofa"], "sofa"),
    ] {
        let output = Command::new(env!("CARGO_BIN_EXE_eval"))
            .arg("table")
            .args(&args)
            .arg("--out")
            .arg(out.path())
            .arg("--scenarios")
            .arg(test_support::scenarios_dir())
            .output()
            .unwrap();
        assert!(!output.status.success(), "{args:?}");
        let err = String::from_utf8_lossy(&output.stderr);
        assert!(err.contains(needle), "{args:?}: {err}");
    }
}

fn prepared(name: &str) -> (eval::table::Prepared, eval::table::TableOptions) {
    let options = eval::table::TableOptions::default();
    let path = test_support::scenarios_dir().join(format!("{name}.yaml"));
    (
        eval::table::Prepared::load(&path, &options).unwrap(),
        options,
    )
}

#[test]
fn a_run_depends_on_its_seed_only() {
    use protocol::ControllerKind;
    let (p, options) = prepared("behaviour_person_oncoming");
    let run = |seed| {
        let (mut r, trace) =
            eval::table::run_one(&p, ControllerKind::DynamicWindow, seed, &options, |_| {})
                .unwrap();
        r.wall_s = 0.0;
        (r, trace)
    };
    let (a, ta) = run(3);
    let (b, tb) = run(3);
    assert_eq!(a, b);
    assert_eq!(ta, tb);
    let (c, _) = run(4);
    assert_ne!(a.mean_position_error_m, c.mean_position_error_m);
}

#[test]
fn a_scripted_encounter_goes_on_the_first_leg_of_each_scenario_it_fits() {
    use eval::record::encounter::Encounter;
    use protocol::ControllerKind;
    let options = eval::table::TableOptions {
        time_limit_s: Some(60.0),
        ..eval::table::TableOptions::default()
    };
    let names = ["task_a", "task_b", "task_c", "task_d", "task_e"];
    let tasks = || -> Vec<_> { names.iter().map(|t| prepared(t).0).collect() };
    let furniture_before: Vec<usize> = tasks().iter().map(|p| p.scenario.furniture.len()).collect();
    let (fitted, left_out) =
        eval::table::with_encounter(tasks(), Encounter::Furniture, &options).unwrap();
    assert_eq!(fitted.len() + left_out.len(), 5, "{left_out:?}");
    assert!(
        fitted.len() >= 2,
        "fits on {} of 5 tasks: {left_out:?}",
        fitted.len()
    );
    // The same placement every time: every method and seed meets the same one.
    let (again, _) = eval::table::with_encounter(tasks(), Encounter::Furniture, &options).unwrap();
    for (p, q) in fitted.iter().zip(&again) {
        assert_eq!(p.scenario, q.scenario);
        let task = p
            .scenario
            .name
            .strip_suffix("-furniture")
            .expect("named by its kind");
        let k = names.iter().position(|t| *t == task).unwrap();
        assert_eq!(p.scenario.furniture.len(), furniture_before[k] + 1);
    }
    // The expert, which sees it, goes round it; the path tracker, which follows the floor
    // plan's path through it, is held short by the collision monitor and relieved.
    let p = &fitted[0];
    let piece = p.scenario.furniture.last().unwrap().shape();
    for method in [ControllerKind::Expert, ControllerKind::PathTracker] {
        let (r, trace) = eval::table::run_one(p, method, 0, &options, |_| {}).unwrap();
        // (Task C's glass, which the path tracker's laser does not see, is not this test's.)
        assert_eq!(r.collisions.furniture, 0, "{method:?}: {r:?}");
        if method == ControllerKind::Expert {
            assert_eq!(r.collisions.total(), 0, "{r:?}");
        }
        let near = trace
            .points_m
            .iter()
            .any(|&(x, y)| piece.distance(x, y) < 1.0);
        assert!(near, "{method:?} never came near the furniture: {r:?}");
        assert!(
            r.goals_reached >= 1,
            "{method:?} did not get past it: {r:?}"
        );
    }
}

/// A scenario's name need not be a valid task id (spaces, `+`, 70 characters): the run still
/// drives (its intentions carry a cleaned-up id; without one the agent rests).
#[test]
fn a_scenario_named_anyhow_still_drives() {
    use protocol::ControllerKind;
    let (p, mut options) = prepared("behaviour_person_oncoming");
    options.time_limit_s = Some(8.0);
    let mut scenario = p.scenario.clone();
    scenario.name = format!("my building + a person {}", "x".repeat(50));
    let renamed = eval::table::Prepared::new(&p.path, scenario, p.plan.clone(), &options).unwrap();
    let (r, _) =
        eval::table::run_one(&renamed, ControllerKind::DynamicWindow, 0, &options, |_| {}).unwrap();
    assert!(r.path_length_m > 2.0, "{r:?}");
}

#[test]
fn the_glass_door_is_judged_by_contact_and_by_not_reaching_the_goal() {
    use protocol::ControllerKind;
    let (p, options) = prepared("behaviour_glass_door");
    assert!(p.is_behaviour());
    // The dynamic window's laser sees through glass: it drives into the door.
    let (dw, _) =
        eval::table::run_one(&p, ControllerKind::DynamicWindow, 0, &options, |_| {}).unwrap();
    assert!(!dw.success, "{dw:?}");
    assert!(dw.collisions.glass >= 1, "{dw:?}");
    // Behaviour runs have no interventions, and a contact counts once however long it lasts.
    assert_eq!(dw.interventions, 0);
    assert_eq!(dw.collisions.total(), 1, "{dw:?}");
    assert_eq!(dw.goals_reached, 0);
    // The expert knows the glass is there: it stops short and waits, which is right.
    let (expert, _) =
        eval::table::run_one(&p, ControllerKind::Expert, 0, &options, |_| {}).unwrap();
    assert!(expert.success, "{expert:?}");
    assert_eq!(expert.collisions.total(), 0, "{expert:?}");
    assert_eq!(expert.goals_reached, 0);
    let gap = expert.min_glass_distance_m.unwrap();
    assert!(gap > 0.05 && gap < 1.5, "{expert:?}");
}

#[test]
fn a_parked_robot_is_passed_by_the_window_and_by_the_path_tracker_only_with_recovery() {
    use protocol::ControllerKind;
    let (p, mut options) = prepared("behaviour_robot_parked");
    assert!(p.is_behaviour());
    // The dynamic window sees the parked robot with its laser and drives round it.
    let (dw, _) =
        eval::table::run_one(&p, ControllerKind::DynamicWindow, 0, &options, |_| {}).unwrap();
    assert!(dw.success, "{dw:?}");
    assert_eq!(dw.collisions.total(), 0, "{dw:?}");
    assert_eq!(dw.goals_reached, 1);
    assert_eq!(dw.recoveries, None, "the window is not relieved by itself");
    // The agent reports the parked robot (its laser sees it standing where the floor plan is
    // free) and the planner routes round it: the path tracker, which has no obstacle sensing
    // of its own and follows the plan, goes round it without help.
    let (seen, _) =
        eval::table::run_one(&p, ControllerKind::PathTracker, 0, &options, |_| {}).unwrap();
    assert!(seen.success, "{seen:?}");
    assert_eq!(seen.collisions.total(), 0, "{seen:?}");
    assert_eq!(seen.recoveries, Some(0), "{seen:?}");
    // On the floor plan alone it follows the plan through it. The collision monitor holds it
    // short; the recovery then hands over to the dynamic window, which goes round, and back.
    options.agent.unmapped_obstacles.enabled = false;
    options.intention.seen.enabled = false;
    let (pt, _) =
        eval::table::run_one(&p, ControllerKind::PathTracker, 0, &options, |_| {}).unwrap();
    assert!(pt.success, "{pt:?}");
    assert_eq!(pt.collisions.total(), 0, "{pt:?}");
    assert_eq!(pt.interventions, 0, "{pt:?}");
    assert!(pt.recoveries.unwrap() >= 1, "{pt:?}");
    let share = pt.recovery_share.unwrap();
    assert!(share > 0.0 && share < 0.5, "{pt:?}");
    // Without the recovery the monitor keeps it there, without contact ...
    options.agent.safety.recovery.enabled = false;
    let (held, _) =
        eval::table::run_one(&p, ControllerKind::PathTracker, 0, &options, |_| {}).unwrap();
    assert!(!held.success, "{held:?}");
    assert_eq!(held.collisions.total(), 0, "{held:?}");
    assert!(held.collision_monitor_share.unwrap() > 0.5, "{held:?}");
    assert_eq!(held.recoveries, None);
    // ... and without the monitor it runs into the robot, and the judge says so.
    options.agent.safety.collision_monitor.enabled = false;
    let (blind, _) =
        eval::table::run_one(&p, ControllerKind::PathTracker, 0, &options, |_| {}).unwrap();
    assert!(!blind.success, "{blind:?}");
    assert!(blind.collisions.robot >= 1, "{blind:?}");
    assert_eq!(blind.collision_monitor_share, None);
}
