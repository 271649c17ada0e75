//! Shipped scenarios, maps, schema and fixtures: generated files up to date, schema valid,
//! goals free and reachable on the plan and in the ground truth (or, where a scenario expects
//! them unreached, closed off in it), task maps kept apart, behaviour checks meaning what they
//! say.

// Test code: a failed unwrap is a failed test.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::path::{Path, PathBuf};

use map_core::{CellClass, DistanceField, OccupancyGrid, Sources};
use sim::scenario::{json_schema, Role, Scenario};
use sim::{Command, Obstacle, SimConfig, World};

fn sim_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn shipped() -> Vec<(PathBuf, Scenario)> {
    let dir = sim_dir().join("scenarios");
    let mut out = Vec::new();
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        let name = path.file_name().unwrap().to_string_lossy().to_string();
        if path.extension().is_some_and(|e| e == "yaml") && name != "example.yaml" {
            let s = Scenario::load(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
            out.push((path, s));
        }
    }
    out.sort_by(|a, b| a.1.name.cmp(&b.1.name));
    out
}

fn validator() -> jsonschema::Validator {
    let text = std::fs::read_to_string(sim_dir().join("scenario.schema.json")).unwrap();
    let schema: serde_json::Value = serde_json::from_str(&text).unwrap();
    jsonschema::validator_for(&schema).unwrap()
}

fn yaml_as_json(path: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(path).unwrap();
    serde_yaml::from_str(&text).unwrap()
}

fn files(dir: &str) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(sim_dir().join("tests/fixtures").join(dir))
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    v.sort();
    assert!(!v.is_empty());
    v
}

#[test]
fn committed_schema_is_the_generated_one() {
    let committed = std::fs::read_to_string(sim_dir().join("scenario.schema.json")).unwrap();
    assert_eq!(
        committed,
        json_schema(),
        "regenerate with `cargo run -p sim -- schema > sim/scenario.schema.json`"
    );
}

#[test]
fn committed_maps_and_scenarios_are_the_generated_ones() {
    let tmp = tempfile::tempdir().unwrap();
    let written = sim::mapgen::generate(tmp.path()).unwrap();
    for path in written {
        let rel = path.strip_prefix(tmp.path()).unwrap();
        let committed = std::fs::read(sim_dir().join("scenarios").join(rel))
            .unwrap_or_else(|e| panic!("{}: {e}", rel.display()));
        assert!(
            committed == std::fs::read(&path).unwrap(),
            "{} differs from the generator; run `cargo run -p sim -- gen-maps --out sim/scenarios`",
            rel.display()
        );
    }
}

#[test]
fn shipped_scenarios_and_valid_fixtures_pass_schema_and_loader() {
    let v = validator();
    let mut paths: Vec<PathBuf> = shipped().into_iter().map(|(p, _)| p).collect();
    paths.push(sim_dir().join("scenarios/example.yaml"));
    paths.extend(files("valid"));
    for path in paths {
        let doc = yaml_as_json(&path);
        let errors: Vec<String> = v.iter_errors(&doc).map(|e| e.to_string()).collect();
        assert!(errors.is_empty(), "{}: {errors:?}", path.display());
        World::from_scenario_file(&path, SimConfig::default())
            .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    }
}

#[test]
fn invalid_fixtures_fail_schema_and_loader_with_clear_messages() {
    let v = validator();
    let expected: BTreeMap<&str, &str> = [
        ("unknown_field.yaml", "speed_limit"),
        ("no_goals.yaml", "goals"),
        ("negative_time.yaml", "time_limit_s"),
        ("bad_texture.yaml", "marble"),
        ("person_too_fast.yaml", "people[0].speed_mps"),
        ("negative_box.yaml", "furniture[0].size_x_m"),
        ("bad_color.yaml", "300"),
    ]
    .into_iter()
    .collect();
    for path in files("invalid") {
        let name = path.file_name().unwrap().to_str().unwrap().to_string();
        let doc = yaml_as_json(&path);
        assert!(!v.is_valid(&doc), "{name} passes the schema");
        let err = Scenario::load(&path).expect_err(&name).to_string();
        let needle = expected
            .get(name.as_str())
            .unwrap_or_else(|| panic!("no expectation for {name}"));
        assert!(
            err.contains(needle),
            "{name}: error {err:?} does not name {needle:?}"
        );
    }
}

/// 4-connected BFS over free cells from `from`; returns the reached set as a bitmap.
fn bfs(blocked: &[bool], w: usize, h: usize, from: (usize, usize)) -> Vec<bool> {
    let mut seen = vec![false; w * h];
    let start = from.1 * w + from.0;
    if blocked[start] {
        return seen;
    }
    seen[start] = true;
    let mut q = VecDeque::from([from]);
    while let Some((x, y)) = q.pop_front() {
        let mut push = |nx: usize, ny: usize| {
            let i = ny * w + nx;
            if !blocked[i] && !seen[i] {
                seen[i] = true;
                q.push_back((nx, ny));
            }
        };
        if x > 0 {
            push(x - 1, y);
        }
        if x + 1 < w {
            push(x + 1, y);
        }
        if y > 0 {
            push(x, y - 1);
        }
        if y + 1 < h {
            push(x, y + 1);
        }
    }
    seen
}

fn cell(grid: &OccupancyGrid, x: f64, y: f64) -> (usize, usize) {
    let (cx, cy) = grid.world_to_cell(x, y);
    assert!(grid.contains(cx, cy), "({x}, {y}) off the grid");
    (usize::try_from(cx).unwrap(), usize::try_from(cy).unwrap())
}

/// Which goals BFS reaches from the start on `grid` inflated by 0.3 m.
fn goals_reached(grid: &OccupancyGrid, s: &Scenario) -> Vec<bool> {
    let w = grid.width_cells() as usize;
    let h = grid.height_cells() as usize;
    let blocked = DistanceField::compute(grid, Sources::OccupiedOrUnknown).inflate(0.3);
    let reached = bfs(&blocked, w, h, cell(grid, s.start.x_m, s.start.y_m));
    s.goals
        .iter()
        .map(|g| {
            let (cx, cy) = cell(grid, g.x_m, g.y_m);
            reached[cy * w + cx]
        })
        .collect()
}

fn check_reachable(grid: &OccupancyGrid, s: &Scenario, what: &str) {
    for (i, (g, ok)) in s.goals.iter().zip(goals_reached(grid, s)).enumerate() {
        assert!(
            ok,
            "{}: goal {i} ({}, {}) unreachable on the {what}",
            s.name, g.x_m, g.y_m
        );
    }
}

/// `expect_goals_reached: false` means the ground truth closes the way to every goal.
fn check_blocked(grid: &OccupancyGrid, s: &Scenario) {
    for (i, (g, ok)) in s.goals.iter().zip(goals_reached(grid, s)).enumerate() {
        assert!(
            !ok,
            "{}: goal {i} ({}, {}) reachable on the ground truth, yet expect_goals_reached is false",
            s.name, g.x_m, g.y_m
        );
    }
}

#[test]
fn goals_free_clear_and_reachable_on_plan_and_ground_truth() {
    for (path, s) in shipped() {
        let world = World::from_scenario_file(&path, SimConfig::default()).unwrap();
        let plan = &world.plan;
        assert!((plan.resolution_m() - 0.05).abs() < 1e-12);
        let df = DistanceField::compute(plan, Sources::OccupiedOrUnknown);
        for (i, g) in s.goals.iter().enumerate() {
            let (cx, cy) = plan.world_to_cell(g.x_m, g.y_m);
            assert_eq!(
                plan.class_at(cx, cy),
                CellClass::Free,
                "{}: goal {i}",
                s.name
            );
            assert!(
                df.at(cx, cy) >= 0.4,
                "{}: goal {i} only {} m from a wall",
                s.name,
                df.at(cx, cy)
            );
        }
        // A behaviour check is one situation on the way to one goal; tasks are goal sequences.
        if s.role != Role::Behaviour {
            assert!(s.goals.len() >= 3, "{}: needs several goals", s.name);
        }
        check_reachable(plan, &s, "floor plan");
        if s.expect_goals_reached {
            check_reachable(
                &world.ground_truth_grid(),
                &s,
                "ground truth (furniture and glass)",
            );
        } else {
            check_blocked(&world.ground_truth_grid(), &s);
        }
    }
}

#[test]
fn task_set_matches_the_paper() {
    let all = shipped();
    let map_of = |name: &str| -> String {
        all.iter()
            .find(|(_, s)| s.name == name)
            .map(|(_, s)| s.floor_plan.clone())
            .unwrap()
    };
    let training: Vec<&Scenario> = all
        .iter()
        .map(|(_, s)| s)
        .filter(|s| s.role == Role::Training)
        .collect();
    let training_maps: BTreeSet<String> = training.iter().map(|s| s.floor_plan.clone()).collect();
    assert!(
        training.len() >= 6,
        "need six training environments, have {}",
        training.len()
    );
    assert!(
        training_maps.len() >= 6,
        "training maps must differ: {training_maps:?}"
    );
    for task in ["task_a", "task_b", "task_c"] {
        let map = map_of(task);
        assert!(
            training_maps.contains(&map),
            "{task} must be in a training environment"
        );
        let task_goals = &all.iter().find(|(_, s)| s.name == task).unwrap().1.goals;
        for t in training.iter().filter(|t| t.floor_plan == map) {
            assert_ne!(&t.goals, task_goals, "{task} needs new goals");
        }
    }
    for task in ["task_d", "task_e"] {
        let map = map_of(task);
        assert!(
            !training_maps.contains(&map),
            "{task}'s map {map} is used for training"
        );
    }
    assert_ne!(map_of("task_d"), map_of("task_e"));
    let evaluation: Vec<&Scenario> = all
        .iter()
        .map(|(_, s)| s)
        .filter(|s| s.role == Role::Evaluation)
        .collect();
    assert_eq!(evaluation.len(), 5);
    assert!(evaluation.iter().any(|s| !s.glass.is_empty()));
    assert!(evaluation
        .iter()
        .all(|s| !s.furniture.is_empty() && !s.people.is_empty()));
    let looks: BTreeSet<String> = training
        .iter()
        .map(|s| format!("{:?}", s.appearance.default))
        .collect();
    assert!(
        looks.len() >= 6,
        "training environments must differ in appearance"
    );
}

#[test]
fn routes_use_passages_at_least_1_4_m_wide() {
    // Cells whose centre is >= 0.7 m from any wall are the middles of passages >= 1.4 m wide
    // (1.5 m minus the half-cell of centre-to-centre distances); every goal must be reachable
    // through them, so no route depends on a passage too narrow for the design rule.
    for (path, s) in shipped() {
        let world = World::from_scenario_file(&path, SimConfig::default()).unwrap();
        let plan = &world.plan;
        let (w, h) = (plan.width_cells() as usize, plan.height_cells() as usize);
        let blocked = DistanceField::compute(plan, Sources::OccupiedOrUnknown).inflate(0.7);
        let reached = bfs(&blocked, w, h, cell(plan, s.start.x_m, s.start.y_m));
        for (i, g) in s.goals.iter().enumerate() {
            let (cx, cy) = cell(plan, g.x_m, g.y_m);
            let near = (cy.saturating_sub(12)..(cy + 13).min(h))
                .any(|y| (cx.saturating_sub(12)..(cx + 13).min(w)).any(|x| reached[y * w + x]));
            assert!(
                near,
                "{}: goal {i} not reachable through wide passages",
                s.name
            );
        }
    }
}

#[test]
fn people_routes_stay_clear_of_walls_furniture_and_glass() {
    for (path, s) in shipped() {
        let world = World::from_scenario_file(&path, SimConfig::default()).unwrap();
        for (i, p) in s.people.iter().enumerate() {
            for pair in p.route.windows(2) {
                let (a, b) = (pair[0], pair[1]);
                let n = ((b.x_m - a.x_m).hypot(b.y_m - a.y_m) / 0.05)
                    .ceil()
                    .max(1.0) as usize;
                for k in 0..=n {
                    let t = k as f64 / n as f64;
                    let (x, y) = (a.x_m + t * (b.x_m - a.x_m), a.y_m + t * (b.y_m - a.y_m));
                    let hit = world.disc_overlap(x, y, p.radius_m, None, false);
                    assert!(
                        hit.is_none(),
                        "{}: people[{i}] walks into {hit:?} at ({x:.2}, {y:.2})",
                        s.name
                    );
                }
            }
        }
    }
}

/// The robot agent's top speed (`robot_agent::config::Limits::default().max_speed_mps`; sim does
/// not depend on the agent).
const AGENT_MAX_SPEED_MPS: f64 = 0.7;

/// Drives robot 0 straight ahead at the agent's top speed, blind, until it hits something or the
/// time limit passes; returns what it hit and when.
fn blind_run(path: &Path) -> Option<(Obstacle, f64)> {
    let mut world = World::from_scenario_file(path, SimConfig::default()).unwrap();
    world.add_robots_at_start(1).unwrap();
    world.add_parked_robots().unwrap();
    let dt_s = 0.05;
    let cmd = [Command {
        v_mps: AGENT_MAX_SPEED_MPS,
        omega_radps: 0.0,
    }];
    let steps = (world.scenario.time_limit_s / dt_s) as usize;
    for k in 0..steps {
        let obs = world.step(&cmd, dt_s);
        if let Some(c) = obs.robots[0].collisions.first() {
            return Some((c.with.clone(), k as f64 * dt_s));
        }
    }
    None
}

#[test]
fn behaviour_scenarios_mean_what_they_say() {
    let all = shipped();
    let behaviour: BTreeMap<&str, &(PathBuf, Scenario)> = all
        .iter()
        .filter(|(_, s)| s.role == Role::Behaviour)
        .map(|e| (e.1.name.as_str(), e))
        .collect();
    assert_eq!(
        behaviour.keys().copied().collect::<Vec<_>>(),
        [
            "behaviour_glass_door",
            "behaviour_person_ahead",
            "behaviour_person_oncoming",
            "behaviour_robot_parked"
        ]
    );
    // Only the glass door is there to be stopped at.
    for (name, (_, s)) in &behaviour {
        assert_eq!(
            s.expect_goals_reached,
            *name != "behaviour_glass_door",
            "{name}"
        );
    }

    // The glass door: a blind robot drives into the glass long before the time limit.
    let (path, s) = behaviour["behaviour_glass_door"];
    assert!(s.people.is_empty() && s.furniture.is_empty() && s.glass.len() >= 2);
    let (hit, t) = blind_run(path).expect("a blind robot must hit the glass door");
    assert!(matches!(hit, Obstacle::Glass(_)), "hit {hit:?}");
    assert!(t < 0.5 * s.time_limit_s, "hit the door only at {t} s");

    // The oncoming person: starts far ahead and walks towards the start, faster than a stroll.
    let (path, s) = behaviour["behaviour_person_oncoming"];
    assert_eq!(s.people.len(), 1);
    let p = &s.people[0];
    let (first, second) = (p.route[0], p.route[1]);
    let start_dist = |q: sim::scenario::PointSpec| (q.x_m - s.start.x_m).hypot(q.y_m - s.start.y_m);
    assert!(start_dist(first) > 15.0 && start_dist(second) < start_dist(first));
    assert!(p.speed_mps >= 0.5);
    let (hit, _) = blind_run(path).expect("a blind robot must walk into the oncoming person");
    assert_eq!(hit, Obstacle::Person(0));

    // The person ahead: walks away from the robot, slower than it, starting close.
    let (path, s) = behaviour["behaviour_person_ahead"];
    assert_eq!(s.people.len(), 1);
    let p = &s.people[0];
    let (first, second) = (p.route[0], p.route[1]);
    let heading = (s.start.yaw_rad.cos(), s.start.yaw_rad.sin());
    let along = |q: sim::scenario::PointSpec| {
        (q.x_m - s.start.x_m) * heading.0 + (q.y_m - s.start.y_m) * heading.1
    };
    assert!(
        along(first) > 1.0 && along(first) < 4.0,
        "starts {} m ahead",
        along(first)
    );
    assert!(along(second) > along(first) + 10.0, "walks the robot's way");
    assert!(p.speed_mps > 0.0 && p.speed_mps < 0.5 * AGENT_MAX_SPEED_MPS);
    let goal = s.goals[0];
    assert!(
        along(goal) > along(second),
        "the goal lies beyond where the person turns off"
    );
    let (hit, _) = blind_run(path).expect("a blind robot must catch up with the person ahead");
    assert_eq!(hit, Obstacle::Person(0));

    // The parked robot: stands on the centre line ahead, with room to pass on either side.
    let (path, s) = behaviour["behaviour_robot_parked"];
    assert_eq!(s.parked_robots.len(), 1);
    assert!(s.people.is_empty() && s.furniture.is_empty() && s.glass.is_empty());
    let parked = s.parked_robots[0];
    assert!((parked.y_m - s.start.y_m).abs() < 1e-9 && parked.x_m > s.start.x_m + 5.0);
    let (hit, _) = blind_run(path).expect("a blind robot must run into the parked robot");
    // Robot 0 is the driven one; the parked robot comes after it.
    assert_eq!(hit, Obstacle::Robot(1));
}
