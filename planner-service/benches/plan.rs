//! Criterion benchmark of a small subset of the planner benchmark: first plans (heuristic
//! cache cleared) and replans (cached) on `100by100_10`, with the 2-D A* reference.
//! The full benchmark is `planner-service bench`.

// A benchmark harness has no caller to hand errors to: failing loudly is the intent.
#![allow(clippy::expect_used)]

use std::sync::Arc;

use criterion::{criterion_group, criterion_main, Criterion};
use map_store::{load_ros_map, ImportLimits};
use planning::grid_astar::GridAstar;
use planning::sample::{pose_along, sample_pairs};
use planning::{Planner, PlannerConfig, PlanningMap};

fn plan(c: &mut Criterion) {
    let path = test_support::nav2_maps_dir().join("100by100_10.yaml");
    let ros = load_ros_map(&path, &ImportLimits::default()).expect("map loads");
    let cfg = PlannerConfig::default();
    let map = Arc::new(PlanningMap::new(ros.grid, &cfg).expect("map prepares"));
    let pairs = sample_pairs(&map, 20, 7, 3.0, "100by100_10").expect("pairs");
    let mut planner = Planner::new(Arc::clone(&map), cfg).expect("planner");
    let mut astar = GridAstar::new();
    let solvable: Vec<_> = pairs
        .into_iter()
        .filter(|(s, g)| planner.plan(*s, *g).is_ok())
        .collect();
    let replans: Vec<_> = solvable
        .iter()
        .filter_map(|(s, g)| {
            let p = planner.plan(*s, *g).ok()?;
            Some((pose_along(&p.poses, 0.5)?, *g))
        })
        .collect();

    let mut group = c.benchmark_group("100by100_10");
    group.sample_size(10);
    group.bench_function("hybrid_first_plan_x20", |b| {
        b.iter(|| {
            for (s, g) in &solvable {
                map.clear_heuristic_cache();
                let _ = planner.plan(*s, *g);
            }
        });
    });
    group.bench_function("hybrid_replan_x20", |b| {
        b.iter(|| {
            for (s, g) in &replans {
                let _ = planner.plan(*s, *g);
            }
        });
    });
    group.bench_function("grid_astar_x20", |b| {
        b.iter(|| {
            for (s, g) in &solvable {
                let _ = astar.plan(&map, *s, *g);
            }
        });
    });
    group.finish();
}

criterion_group!(benches, plan);
criterion_main!(benches);
