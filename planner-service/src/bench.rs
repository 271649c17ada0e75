//! The planner benchmark: hybrid A* against a plain 2-D A* on the same random queries.
//!
//! For each map: seeded random start/goal pairs (uniform over inflated free cells, random
//! headings, at least `min_separation_m` apart). Per pair, in one run: the 8-connected 2-D A*
//! reference (which also decides "reachable"), a first hybrid A* plan (new goal, so the
//! obstacle heuristic is built for it), and a replan from the pose `replan_offset_m` along the
//! first path (cached heuristic). Results are JSON-serializable and render as a markdown table.

use std::path::{Path as FsPath, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use indicatif::ProgressBar;
use map_store::{load_ros_map, ImportLimits};
use serde::Serialize;

use planning::grid_astar::GridAstar;
use planning::sample::{pose_along, sample_pairs, NoPairs};
use planning::{PlanError, Planner, PlannerConfig, PlanningMap};

/// What to benchmark.
#[derive(Debug, Clone)]
pub struct BenchOptions {
    pub maps: Vec<PathBuf>,
    pub pairs: usize,
    pub seed: u64,
    pub min_separation_m: f64,
    pub replan_offset_m: f64,
    pub config: PlannerConfig,
}

/// The benchmark maps: Nav2's three 100 m x 100 m maps (in `shared/maps/nav2`).
pub const NAV2_BENCH_MAPS: [&str; 3] = ["100by100_10.yaml", "100by100_15.yaml", "100by100_20.yaml"];

impl BenchOptions {
    /// The benchmark on `maps`: 1000 pairs each, seed 1.
    #[must_use]
    pub fn with_maps(maps: Vec<PathBuf>) -> Self {
        Self {
            maps,
            pairs: 1000,
            seed: 1,
            min_separation_m: 3.0,
            replan_offset_m: 0.5,
            config: PlannerConfig::default(),
        }
    }

    /// The benchmark: [`NAV2_BENCH_MAPS`] in `nav2_maps_dir`, 1000 pairs each.
    #[must_use]
    pub fn nav2_default(nav2_maps_dir: &FsPath) -> Self {
        Self::with_maps(
            NAV2_BENCH_MAPS
                .iter()
                .map(|m| nav2_maps_dir.join(m))
                .collect(),
        )
    }
}

/// Summary statistics of a sample.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, serde::Deserialize)]
pub struct Summary {
    pub n: usize,
    pub mean: f64,
    pub p50: f64,
    pub p99: f64,
    pub max: f64,
}

impl Summary {
    #[must_use]
    pub fn of(values: &[f64]) -> Self {
        if values.is_empty() {
            return Self::default();
        }
        let mut v = values.to_vec();
        v.sort_by(f64::total_cmp);
        #[allow(clippy::cast_precision_loss)]
        let mean = v.iter().sum::<f64>() / v.len() as f64;
        let pick = |q: f64| {
            #[allow(
                clippy::cast_possible_truncation,
                clippy::cast_sign_loss,
                clippy::cast_precision_loss
            )]
            let i = ((q * v.len() as f64).ceil() as usize).clamp(1, v.len()) - 1;
            v[i]
        };
        Self {
            n: v.len(),
            mean,
            p50: pick(0.5),
            p99: pick(0.99),
            max: v[v.len() - 1],
        }
    }
}

/// Results on one map.
#[derive(Debug, Clone, Serialize)]
pub struct MapResult {
    pub map: String,
    pub width_cells: u32,
    pub height_cells: u32,
    pub prepare_ms: f64,
    pub pairs: usize,
    /// Pairs the 2-D A* connects.
    pub reachable: usize,
    /// Reachable pairs hybrid A* solved.
    pub hybrid_solved: usize,
    pub success_rate: f64,
    /// Unreachable pairs that hybrid A* correctly reported as unreachable.
    pub unreachable_reported: usize,
    pub first_plan_ms: Summary,
    pub replan_ms: Summary,
    pub replan_cache_hits: usize,
    pub states_expanded: Summary,
    pub replan_states_expanded: Summary,
    /// Hybrid A* length over the 8-connected 2-D A* length, per solved pair.
    pub length_ratio: Summary,
    pub astar_ms: Summary,
    pub astar_expanded: Summary,
    /// The first few failures on reachable pairs, with their reasons.
    pub failures: Vec<String>,
}

/// The whole benchmark run.
#[derive(Debug, Clone, Serialize)]
pub struct BenchReport {
    pub command: String,
    pub cpu_cores: usize,
    pub seed: u64,
    pub config: PlannerConfig,
    pub maps: Vec<MapResult>,
}

/// A benchmark that could not run.
#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    #[error("cannot load map {path}: {source}")]
    Map {
        path: String,
        #[source]
        source: map_store::MapError,
    },
    #[error(transparent)]
    Plan(#[from] PlanError),
    #[error(transparent)]
    NoPairs(#[from] NoPairs),
}

fn ms(since: Instant) -> f64 {
    since.elapsed().as_secs_f64() * 1e3
}

/// Benchmarks one map.
///
/// # Errors
/// [`BenchError`] if the map cannot be loaded or prepared.
pub fn bench_map(
    path: &FsPath,
    opts: &BenchOptions,
    seed: u64,
    progress: &ProgressBar,
) -> Result<MapResult, BenchError> {
    let name = path.display().to_string();
    let ros = load_ros_map(path, &ImportLimits::default()).map_err(|source| BenchError::Map {
        path: name.clone(),
        source,
    })?;
    let t = Instant::now();
    let map = Arc::new(PlanningMap::new(ros.grid, &opts.config)?);
    let prepare_ms = ms(t);
    let pairs = sample_pairs(&map, opts.pairs, seed, opts.min_separation_m, &name)?;
    let mut planner = Planner::new(Arc::clone(&map), opts.config.clone())?;
    let mut astar = GridAstar::new();

    let (mut first, mut replan, mut states, mut replan_states, mut ratio) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let (mut astar_ms, mut astar_expanded) = (Vec::new(), Vec::new());
    let (mut reachable, mut solved, mut unreachable_reported, mut hits) = (0, 0, 0, 0);
    let mut failures = Vec::new();
    #[allow(clippy::cast_precision_loss)]
    for (s, g) in &pairs {
        let t = Instant::now();
        let reference = astar.plan(&map, *s, *g);
        astar_ms.push(ms(t));
        let t = Instant::now();
        let result = planner.plan(*s, *g);
        let first_ms = ms(t);
        match (reference, result) {
            (Some(r), Ok(p)) => {
                reachable += 1;
                solved += 1;
                astar_expanded.push(r.expanded as f64);
                first.push(first_ms);
                states.push(p.states_expanded as f64);
                ratio.push(p.length_m / r.length_m.max(1e-9));
                if let Some(moved) = pose_along(&p.poses, opts.replan_offset_m) {
                    let t = Instant::now();
                    let again = planner.plan(moved, *g);
                    let replan_ms = ms(t);
                    match again {
                        Ok(p2) => {
                            replan.push(replan_ms);
                            replan_states.push(p2.states_expanded as f64);
                            hits += usize::from(p2.stats.heuristic_cache_hit);
                        }
                        Err(e) => {
                            if failures.len() < 10 {
                                failures.push(format!("replan {moved:?} -> {g:?}: {e}"));
                            }
                        }
                    }
                }
            }
            (Some(r), Err(e)) => {
                reachable += 1;
                astar_expanded.push(r.expanded as f64);
                if failures.len() < 10 {
                    failures.push(format!("{s:?} -> {g:?}: {e}"));
                }
            }
            (None, Err(PlanError::Unreachable { .. })) => unreachable_reported += 1,
            (None, _) => {}
        }
        progress.inc(1);
    }
    #[allow(clippy::cast_precision_loss)]
    let success_rate = if reachable == 0 {
        1.0
    } else {
        solved as f64 / reachable as f64
    };
    let grid = map.grid();
    Ok(MapResult {
        map: name,
        width_cells: grid.width_cells(),
        height_cells: grid.height_cells(),
        prepare_ms,
        pairs: pairs.len(),
        reachable,
        hybrid_solved: solved,
        success_rate,
        unreachable_reported,
        first_plan_ms: Summary::of(&first),
        replan_ms: Summary::of(&replan),
        replan_cache_hits: hits,
        states_expanded: Summary::of(&states),
        replan_states_expanded: Summary::of(&replan_states),
        length_ratio: Summary::of(&ratio),
        astar_ms: Summary::of(&astar_ms),
        astar_expanded: Summary::of(&astar_expanded),
        failures,
    })
}

/// Runs the whole benchmark; `progress` counts pairs over all maps.
///
/// # Errors
/// [`BenchError`] from any map.
pub fn run_bench(
    opts: &BenchOptions,
    command: String,
    progress: &ProgressBar,
) -> Result<BenchReport, BenchError> {
    let mut maps = Vec::new();
    for (i, path) in opts.maps.iter().enumerate() {
        maps.push(bench_map(
            path,
            opts,
            opts.seed.wrapping_add(i as u64),
            progress,
        )?);
    }
    Ok(BenchReport {
        command,
        cpu_cores: std::thread::available_parallelism().map_or(1, std::num::NonZeroUsize::get),
        seed: opts.seed,
        config: opts.config.clone(),
        maps,
    })
}

/// The report as a markdown table (one row per map).
#[must_use]
pub fn markdown_table(report: &BenchReport) -> String {
    let mut s = String::from(
        "| map | pairs | reachable | success | first plan mean / p50 / p99 (ms) | replan p50 / p99 (ms) | states mean / p99 | length / 2-D A* mean / p99 | 2-D A* mean / p99 (ms) |\n\
         |---|---|---|---|---|---|---|---|---|\n",
    );
    for m in &report.maps {
        let name = FsPath::new(&m.map)
            .file_name()
            .map_or(m.map.clone(), |n| n.to_string_lossy().into_owned());
        s.push_str(&format!(
            "| {name} | {} | {} | {:.1} % | {:.2} / {:.2} / {:.2} | {:.2} / {:.2} | {:.0} / {:.0} | {:.3} / {:.3} | {:.2} / {:.2} |\n",
            m.pairs,
            m.reachable,
            m.success_rate * 100.0,
            m.first_plan_ms.mean,
            m.first_plan_ms.p50,
            m.first_plan_ms.p99,
            m.replan_ms.p50,
            m.replan_ms.p99,
            m.states_expanded.mean,
            m.states_expanded.p99,
            m.length_ratio.mean,
            m.length_ratio.p99,
            m.astar_ms.mean,
            m.astar_ms.p99,
        ));
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn summary_percentiles() {
        let v: Vec<f64> = (1..=100).map(f64::from).collect();
        let s = Summary::of(&v);
        assert_eq!((s.n, s.p50, s.p99, s.max), (100, 50.0, 99.0, 100.0));
        assert!((s.mean - 50.5).abs() < 1e-12);
        assert_eq!(Summary::of(&[]).n, 0);
    }
}
