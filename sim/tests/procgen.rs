//! Procedural buildings (`sim::procgen`): deterministic to the byte, valid worlds whose goals are
//! reachable on the plan and in the ground truth, written files that load back to the same grid
//! and scenario, roles by seed range, and variety across seeds.

// Test code: a failed unwrap is a failed test.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::collections::{BTreeSet, VecDeque};
use std::path::{Path, PathBuf};

use map_core::{CellClass, DistanceField, ImportLimits, OccupancyGrid, Sources};
use sim::procgen::{
    self, building, building_name, role_of_seed, Building, Family, EVALUATION_SEED_BASE,
};
use sim::scenario::{Role, Scenario};
use sim::{SimConfig, World};

/// 20 training and 20 evaluation seeds.
fn training_seeds() -> std::ops::Range<u64> {
    0..20
}

fn evaluation_seeds() -> std::ops::Range<u64> {
    EVALUATION_SEED_BASE..EVALUATION_SEED_BASE + 20
}

/// 4-connected BFS over unblocked cells from `from`.
fn bfs(blocked: &[bool], w: usize, h: usize, from: (usize, usize)) -> Vec<bool> {
    let mut seen = vec![false; w * h];
    let start = from.1 * w + from.0;
    if blocked[start] {
        return seen;
    }
    seen[start] = true;
    let mut q = VecDeque::from([start]);
    while let Some(i) = q.pop_front() {
        let (x, y) = (i % w, i / w);
        let mut push = |j: usize| {
            if !blocked[j] && !seen[j] {
                seen[j] = true;
                q.push_back(j);
            }
        };
        if x > 0 {
            push(i - 1);
        }
        if x + 1 < w {
            push(i + 1);
        }
        if y > 0 {
            push(i - w);
        }
        if y + 1 < h {
            push(i + w);
        }
    }
    seen
}

fn cell(grid: &OccupancyGrid, x: f64, y: f64) -> (usize, usize) {
    let (cx, cy) = grid.world_to_cell(x, y);
    assert!(grid.contains(cx, cy), "({x}, {y}) off the grid");
    (usize::try_from(cx).unwrap(), usize::try_from(cy).unwrap())
}

/// Start, then the goals in order.
fn points(s: &Scenario) -> Vec<(f64, f64)> {
    std::iter::once((s.start.x_m, s.start.y_m))
        .chain(s.goals.iter().map(|g| (g.x_m, g.y_m)))
        .collect()
}

/// Every goal reachable from the previous point on `grid` inflated by `radius_m`.
fn check_legs(grid: &OccupancyGrid, s: &Scenario, radius_m: f64, what: &str) {
    let (w, h) = (grid.width_cells() as usize, grid.height_cells() as usize);
    let blocked = DistanceField::compute(grid, Sources::OccupiedOrUnknown).inflate(radius_m);
    for (i, leg) in points(s).windows(2).enumerate() {
        let reached = bfs(&blocked, w, h, cell(grid, leg[0].0, leg[0].1));
        let (gx, gy) = cell(grid, leg[1].0, leg[1].1);
        assert!(
            reached[gy * w + gx],
            "{}: goal {i} {:?} unreachable from {:?} on the {what} inflated by {radius_m} m",
            s.name,
            leg[1],
            leg[0]
        );
    }
}

fn schema_validator() -> jsonschema::Validator {
    let text =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("scenario.schema.json"))
            .unwrap();
    jsonschema::validator_for(&serde_json::from_str(&text).unwrap()).unwrap()
}

/// Everything one building must satisfy.
fn check_building(seed: u64, b: &Building, schema: &jsonschema::Validator) {
    let s = &b.scenario;
    assert_eq!(s.name, building_name(seed));
    assert_eq!(s.role, role_of_seed(seed));
    assert_eq!(s.floor_plan, format!("maps/{}.yaml", s.name));
    assert_eq!(b.plan.name, s.name);
    assert!(s.expect_goals_reached);
    assert!(
        (2..=4).contains(&s.goals.len()),
        "{}: {} goals",
        s.name,
        s.goals.len()
    );

    // Size and resolution.
    let plan = &b.grid;
    assert!((plan.resolution_m() - 0.05).abs() < 1e-12);
    let (w_m, h_m) = plan.extent_m();
    for side in [w_m, h_m] {
        assert!((19.9..=45.1).contains(&side), "{}: side {side} m", s.name);
    }

    // The grid is the plan, and all free floor is one 4-connected region.
    let (w, h) = (plan.width_cells() as usize, plan.height_cells() as usize);
    assert_eq!((w, h), (b.plan.width, b.plan.height));
    let walls: Vec<bool> = plan
        .cells()
        .iter()
        .map(|&v| map_core::classify(v) != CellClass::Free)
        .collect();
    assert_eq!(walls, b.plan.wall, "{}: grid and plan differ", s.name);
    let first_free = walls.iter().position(|&w| !w).unwrap();
    let region = bfs(&walls, w, h, (first_free % w, first_free / w));
    let free = walls.iter().filter(|&&w| !w).count();
    assert_eq!(
        region.iter().filter(|&&r| r).count(),
        free,
        "{}: free floor is not one connected region",
        s.name
    );

    // The world takes it, the robot can be put at the start (nothing there, people included).
    let mut world = World::new(s.clone(), plan.clone(), SimConfig::default())
        .unwrap_or_else(|e| panic!("{}: {e}", s.name));
    world
        .add_robots_at_start(1)
        .unwrap_or_else(|e| panic!("{}: start blocked: {e}", s.name));
    let truth = world.ground_truth_grid();

    // Start and goals free, clear of walls, furniture and glass, spaced out.
    let plan_df = DistanceField::compute(plan, Sources::OccupiedOrUnknown);
    let truth_df = DistanceField::compute(&truth, Sources::OccupiedOrUnknown);
    for (i, &(x, y)) in points(s).iter().enumerate() {
        let (cx, cy) = plan.world_to_cell(x, y);
        assert_eq!(
            plan.class_at(cx, cy),
            CellClass::Free,
            "{}: point {i}",
            s.name
        );
        assert_eq!(
            truth.class_at(cx, cy),
            CellClass::Free,
            "{}: point {i}",
            s.name
        );
        for (what, df) in [("plan", &plan_df), ("ground truth", &truth_df)] {
            assert!(
                df.at(cx, cy) >= 0.45,
                "{}: point {i} only {} m from an obstacle on the {what}",
                s.name,
                df.at(cx, cy)
            );
        }
    }
    for (i, leg) in points(s).windows(2).enumerate() {
        let d = (leg[1].0 - leg[0].0).hypot(leg[1].1 - leg[0].1);
        assert!(
            d >= 4.0,
            "{}: goal {i} only {d:.2} m from the previous point",
            s.name
        );
    }

    // Reachable for the 0.25 m robot (+5 cm) on the plan and in the ground truth, and through
    // passages of a metre in the ground truth (radius 0.45 m leaves 0.9 m of cell centres).
    let robot_m = SimConfig::default().base.radius_m;
    assert!((robot_m - 0.25).abs() < 1e-12);
    check_legs(plan, s, robot_m + 0.05, "plan");
    check_legs(&truth, s, robot_m + 0.05, "ground truth");
    check_legs(&truth, s, 0.45, "ground truth");

    // Furniture and glass stand on the floor, not in walls.
    for (i, f) in s.furniture.iter().enumerate() {
        let (cx, cy) = plan.world_to_cell(f.x_m, f.y_m);
        assert_eq!(
            plan.class_at(cx, cy),
            CellClass::Free,
            "{}: furniture[{i}]",
            s.name
        );
        assert!(f.size_x_m > 0.2 && f.size_y_m > 0.2 && f.height_m > 0.3);
    }
    for (i, g) in s.glass.iter().enumerate() {
        let (cx, cy) = plan.world_to_cell(0.5 * (g.x0_m + g.x1_m), 0.5 * (g.y0_m + g.y1_m));
        assert_eq!(
            plan.class_at(cx, cy),
            CellClass::Free,
            "{}: glass[{i}]",
            s.name
        );
    }

    // People walk clear of walls, furniture and glass.
    for (i, p) in s.people.iter().enumerate() {
        assert!(p.route.len() >= 2, "{}: people[{i}] stands still", s.name);
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

    // A generous time limit: at least a minute plus the straight-line legs at 0.6 m/s.
    let straight_m: f64 = points(s)
        .windows(2)
        .map(|l| (l[1].0 - l[0].0).hypot(l[1].1 - l[0].1))
        .sum();
    assert!(s.time_limit_s >= 60.0 + straight_m / 0.6, "{}", s.name);

    // The scenario file round-trips and passes the committed schema.
    let text = procgen::scenario_yaml(b).unwrap();
    let back = Scenario::from_yaml(&text, Path::new("gen.yaml")).unwrap();
    assert_eq!(&back, s);
    let doc: serde_json::Value = serde_yaml::from_str(&text).unwrap();
    let errors: Vec<String> = schema.iter_errors(&doc).map(|e| e.to_string()).collect();
    assert!(errors.is_empty(), "{}: {errors:?}", s.name);
}

/// Writes the map alone (PGM + YAML) and loads it back through map_core.
fn map_round_trip(b: &Building, dir: &Path) -> OccupancyGrid {
    let maps = dir.join("maps");
    std::fs::create_dir_all(&maps).unwrap();
    let yaml = maps.join(format!("{}.yaml", b.scenario.name));
    std::fs::write(maps.join(format!("{}.pgm", b.scenario.name)), b.plan.pgm()).unwrap();
    std::fs::write(&yaml, procgen::map_yaml(b)).unwrap();
    map_core::load_ros_map(&yaml, &ImportLimits::default())
        .unwrap()
        .grid
}

fn check_seeds(seeds: impl Iterator<Item = u64>) -> Vec<Building> {
    let schema = schema_validator();
    let dir = tempfile::tempdir().unwrap();
    seeds
        .map(|seed| {
            let b = building(seed).unwrap_or_else(|e| panic!("seed {seed}: {e}"));
            check_building(seed, &b, &schema);
            assert!(
                map_round_trip(&b, dir.path()) == b.grid,
                "{}: the written map loads back as another grid",
                b.scenario.name
            );
            b
        })
        .collect()
}

#[test]
fn training_buildings_are_valid_reachable_and_round_trip() {
    let buildings = check_seeds(training_seeds());
    assert!(buildings.iter().all(|b| b.scenario.role == Role::Training));
}

#[test]
fn evaluation_buildings_are_valid_reachable_and_round_trip() {
    let buildings = check_seeds(evaluation_seeds());
    assert!(buildings
        .iter()
        .all(|b| b.scenario.role == Role::Evaluation && b.scenario.name.starts_with("gen_eval_")));
}

/// The full checks on many more seeds: `cargo test -p sim --test procgen -- --ignored`
/// (`PROCGEN_SEEDS=N` sets how many of each role, default 250).
#[test]
#[ignore = "slow: hundreds of buildings"]
fn many_buildings_are_valid() {
    let n: u64 = std::env::var("PROCGEN_SEEDS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(250);
    check_seeds((0..n).chain(EVALUATION_SEED_BASE..EVALUATION_SEED_BASE + n));
}

#[test]
fn buildings_vary_across_seeds() {
    let buildings: Vec<Building> = training_seeds()
        .chain(evaluation_seeds())
        .map(|s| building(s).unwrap())
        .collect();
    let families: BTreeSet<Family> = buildings.iter().map(|b| b.family).collect();
    assert!(families.len() >= 3, "families {families:?}");
    let plans: BTreeSet<&Vec<bool>> = buildings.iter().map(|b| &b.plan.wall).collect();
    assert_eq!(plans.len(), buildings.len(), "two seeds gave the same plan");
    let fractions: BTreeSet<u64> = buildings
        .iter()
        .map(|b| (b.free_fraction() * 1000.0).round() as u64)
        .collect();
    assert!(fractions.len() >= 30, "free fractions {fractions:?}");
    let (lo, hi) = (
        fractions.first().copied().unwrap_or(0),
        fractions.last().copied().unwrap_or(0),
    );
    assert!(
        hi - lo >= 200,
        "free fractions only span {lo}..{hi} per mille"
    );
    let sizes: BTreeSet<(usize, usize)> = buildings
        .iter()
        .map(|b| (b.plan.width, b.plan.height))
        .collect();
    assert!(sizes.len() >= 30);
    let count = |f: fn(&Scenario) -> bool| buildings.iter().filter(|b| f(&b.scenario)).count();
    assert!(count(|s| !s.furniture.is_empty()) >= 35);
    assert!(count(|s| !s.glass.is_empty()) >= 10);
    assert!(count(|s| !s.people.is_empty()) >= 25);
    assert!(count(|s| !s.appearance.areas.is_empty()) >= 20);
    let looks: BTreeSet<String> = buildings
        .iter()
        .map(|b| format!("{:?}", b.scenario.appearance.default))
        .collect();
    assert_eq!(looks.len(), buildings.len());
    let goal_counts: BTreeSet<usize> = buildings.iter().map(|b| b.scenario.goals.len()).collect();
    assert_eq!(goal_counts, BTreeSet::from([2, 3, 4]));
}

/// Every file under `dir`, relative to it, sorted.
fn files_under(dir: &Path) -> Vec<PathBuf> {
    fn walk(base: &Path, dir: &Path, out: &mut Vec<PathBuf>) {
        for entry in std::fs::read_dir(dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                walk(base, &path, out);
            } else {
                out.push(path.strip_prefix(base).unwrap().to_path_buf());
            }
        }
    }
    let mut out = Vec::new();
    walk(dir, dir, &mut out);
    out.sort();
    out
}

#[test]
fn same_seed_same_building_and_files() {
    for seed in [7, EVALUATION_SEED_BASE + 3] {
        let a = building(seed).unwrap();
        assert_eq!(a, building(seed).unwrap(), "seed {seed}");
        let (d1, d2) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
        procgen::write_building(&a, d1.path()).unwrap();
        procgen::write_building(&building(seed).unwrap(), d2.path()).unwrap();
        let files = files_under(d1.path());
        let name = &a.scenario.name;
        assert_eq!(
            files,
            [
                PathBuf::from(format!("{name}.png")),
                PathBuf::from(format!("{name}.yaml")),
                PathBuf::from(format!("maps/{name}.pgm")),
                PathBuf::from(format!("maps/{name}.yaml")),
            ]
        );
        assert_eq!(files, files_under(d2.path()));
        for f in &files {
            assert!(
                std::fs::read(d1.path().join(f)).unwrap()
                    == std::fs::read(d2.path().join(f)).unwrap(),
                "{} differs between two runs",
                f.display()
            );
        }
        // What `eval table --scenario DIR/<name>.yaml` loads is the building.
        let world = World::from_scenario_file(
            &d1.path().join(format!("{name}.yaml")),
            SimConfig::default(),
        )
        .unwrap();
        assert!(world.plan == a.grid);
        assert_eq!(world.scenario, a.scenario);
        let png = image::open(d1.path().join(format!("{name}.png")))
            .unwrap()
            .to_rgb8();
        assert_eq!(
            png.dimensions(),
            (a.grid.width_cells(), a.grid.height_cells())
        );
    }
    assert_ne!(building(7).unwrap().scenario, building(8).unwrap().scenario);
}

#[test]
fn roles_follow_the_seed_range() {
    assert_eq!(role_of_seed(0), Role::Training);
    assert_eq!(role_of_seed(EVALUATION_SEED_BASE - 1), Role::Training);
    assert_eq!(role_of_seed(EVALUATION_SEED_BASE), Role::Evaluation);
    assert_eq!(role_of_seed(u64::MAX), Role::Evaluation);
    assert_eq!(building_name(123), "gen_000123");
    assert_eq!(building_name(EVALUATION_SEED_BASE + 4), "gen_eval_1000004");
    assert_eq!(EVALUATION_SEED_BASE, 1_000_000);
    // The scenario seed is derived, fits a JSON number exactly and differs per building.
    let seeds: BTreeSet<u64> = (0..100).map(procgen::scenario_seed).collect();
    assert_eq!(seeds.len(), 100);
    assert!(seeds.iter().all(|&s| s < 1 << 53));
}

#[test]
fn gen_building_command_writes_runnable_scenarios() {
    use clap::Parser;
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().to_str().unwrap();
    sim::cli::run(
        sim::cli::Cli::try_parse_from([
            "sim",
            "gen-building",
            "--seed",
            "41",
            "--count",
            "2",
            "--out",
            out,
        ])
        .unwrap(),
    )
    .unwrap();
    for name in ["gen_000041", "gen_000042"] {
        let path = dir.path().join(format!("{name}.yaml"));
        let mut world = World::from_scenario_file(&path, SimConfig::default()).unwrap();
        world.add_robots_at_start(1).unwrap();
        assert!(dir.path().join(format!("{name}.png")).is_file());
    }
    let err = sim::cli::run(
        sim::cli::Cli::try_parse_from([
            "sim",
            "gen-building",
            "--seed",
            &u64::MAX.to_string(),
            "--count",
            "2",
            "--out",
            out,
        ])
        .unwrap(),
    )
    .unwrap_err();
    assert!(err.to_string().contains("past the largest seed"), "{err}");
}
