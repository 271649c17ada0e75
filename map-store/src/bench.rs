//! The `map-store bench` measurements: import and exact distance field of the Nav2 2000 × 2000
//! benchmark maps against a reference 8-connected chamfer distance transform in the same run,
//! and redb put/get of one such map.

use std::path::Path;
use std::time::Instant;

use serde::{Deserialize, Serialize};

use crate::distance::{DistanceField, Sources};
use crate::error::MapError;
use crate::grid::{classify, CellClass, OccupancyGrid};
use crate::ros::{load_ros_map, ImportLimits};
use crate::store::{MapSource, MapStore, SourceKind};

/// The Nav2 planner benchmark maps.
pub const BENCH_MAPS: [&str; 3] = ["100by100_10", "100by100_15", "100by100_20"];

/// Timings of one map (each the best of `repeats` runs, in milliseconds).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct MapTimings {
    pub map: String,
    pub width_cells: u32,
    pub height_cells: u32,
    pub import_ms: f64,
    pub exact_edt_ms: f64,
    pub chamfer_ms: f64,
    /// Largest |chamfer − exact| over all cells, in metres: what the cheap reference gets wrong.
    pub chamfer_max_error_m: f64,
}

/// The whole report written by `map-store bench`.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct BenchReport {
    pub repeats: u32,
    pub maps: Vec<MapTimings>,
    /// redb put of the first map (fresh database, one transaction with fsync).
    pub store_put_ms: f64,
    /// redb get of the same map by name (cells copied out, grid validated).
    pub store_get_ms: f64,
}

/// Reference: two-pass 8-connected chamfer transform (weights 1 and √2 cells, Borgefors 1986),
/// the brushfire distance a simple planner would use. Occupied cells are the sources.
#[must_use]
pub fn chamfer_distance_m(grid: &OccupancyGrid) -> Vec<f32> {
    let w = grid.width_cells() as usize;
    let h = grid.height_cells() as usize;
    let inf = f32::INFINITY;
    let mut d: Vec<f32> = grid
        .cells()
        .iter()
        .map(|&v| {
            if classify(v) == CellClass::Occupied {
                0.0
            } else {
                inf
            }
        })
        .collect();
    let diag = std::f32::consts::SQRT_2;
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let mut best = d[i];
            if x > 0 {
                best = best.min(d[i - 1] + 1.0);
            }
            if y > 0 {
                best = best.min(d[i - w] + 1.0);
                if x > 0 {
                    best = best.min(d[i - w - 1] + diag);
                }
                if x + 1 < w {
                    best = best.min(d[i - w + 1] + diag);
                }
            }
            d[i] = best;
        }
    }
    for y in (0..h).rev() {
        for x in (0..w).rev() {
            let i = y * w + x;
            let mut best = d[i];
            if x + 1 < w {
                best = best.min(d[i + 1] + 1.0);
            }
            if y + 1 < h {
                best = best.min(d[i + w] + 1.0);
                if x + 1 < w {
                    best = best.min(d[i + w + 1] + diag);
                }
                if x > 0 {
                    best = best.min(d[i + w - 1] + diag);
                }
            }
            d[i] = best;
        }
    }
    #[allow(clippy::cast_possible_truncation)]
    let res = grid.resolution_m() as f32;
    d.iter_mut().for_each(|v| *v *= res);
    d
}

fn best_ms<T>(
    repeats: u32,
    mut f: impl FnMut() -> Result<T, MapError>,
) -> Result<(f64, T), MapError> {
    let mut best = f64::INFINITY;
    let mut last = None;
    for _ in 0..repeats.max(1) {
        let t = Instant::now();
        let out = f()?;
        best = best.min(t.elapsed().as_secs_f64() * 1e3);
        last = Some(out);
    }
    match last {
        Some(out) => Ok((best, out)),
        None => Err(MapError::invalid("repeats", repeats, "must be at least 1")),
    }
}

/// Runs the benchmark on the maps in `maps_dir`; `tick` is called after each step (progress).
///
/// # Errors
/// Any import or store error.
pub fn run_bench(
    maps_dir: &Path,
    repeats: u32,
    mut tick: impl FnMut(&str),
) -> Result<BenchReport, MapError> {
    let limits = ImportLimits::default();
    let mut maps = Vec::new();
    let mut first = None;
    for name in BENCH_MAPS {
        let yaml = maps_dir.join(format!("{name}.yaml"));
        let (import_ms, map) = best_ms(repeats, || load_ros_map(&yaml, &limits))?;
        let grid = map.grid;
        let (exact_edt_ms, exact) = best_ms(repeats, || {
            Ok(DistanceField::compute(&grid, Sources::Occupied))
        })?;
        let (chamfer_ms, chamfer) = best_ms(repeats, || Ok(chamfer_distance_m(&grid)))?;
        let chamfer_max_error_m = exact
            .as_slice()
            .iter()
            .zip(&chamfer)
            .filter(|(a, b)| a.is_finite() && b.is_finite())
            .map(|(a, b)| f64::from((a - b).abs()))
            .fold(0.0, f64::max);
        maps.push(MapTimings {
            map: name.to_string(),
            width_cells: grid.width_cells(),
            height_cells: grid.height_cells(),
            import_ms,
            exact_edt_ms,
            chamfer_ms,
            chamfer_max_error_m,
        });
        tick(name);
        if first.is_none() {
            first = Some(grid);
        }
    }
    let grid = first.ok_or_else(|| MapError::invalid("maps", "none", "no benchmark map"))?;
    let dir = fresh_bench_dir()?;
    let store = MapStore::open(&dir)?;
    let name = protocol::MapName::new("bench")?;
    let source = MapSource::new(SourceKind::Grid, None, "bench");
    let mut put_ms = f64::INFINITY;
    let mut g = grid.clone();
    for i in 0..repeats.max(1) {
        // Distinct content each round so every put really writes.
        g.set(
            i64::from(i),
            0,
            if g.get(i64::from(i), 0) == Some(100) {
                0
            } else {
                100
            },
        );
        let t = Instant::now();
        store.put(&name, &g, &source)?;
        put_ms = put_ms.min(t.elapsed().as_secs_f64() * 1e3);
    }
    let (store_get_ms, _) = best_ms(repeats, || store.get(&name, Some(1)))?;
    tick("store");
    drop(store);
    // Best effort: the folder lives in the system temp dir anyway.
    let _ = std::fs::remove_dir_all(&dir);
    Ok(BenchReport {
        repeats,
        maps,
        store_put_ms: put_ms,
        store_get_ms,
    })
}

fn fresh_bench_dir() -> Result<std::path::PathBuf, MapError> {
    let dir = std::env::temp_dir().join(format!("map-store-bench-{}", std::process::id()));
    // A leftover from a crashed run with the same pid would skew put timings.
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).map_err(|e| MapError::io(&dir, e))?;
    Ok(dir)
}

/// The report as a markdown table.
#[must_use]
pub fn markdown(report: &BenchReport) -> String {
    let mut s = String::from(
        "| map | cells | import (ms) | exact EDT (ms) | chamfer ref. (ms) | EDT / chamfer | chamfer max error (m) |\n\
         |---|---|---|---|---|---|---|\n",
    );
    for m in &report.maps {
        s.push_str(&format!(
            "| {} | {}×{} | {:.1} | {:.1} | {:.1} | {:.2}× | {:.3} |\n",
            m.map,
            m.width_cells,
            m.height_cells,
            m.import_ms,
            m.exact_edt_ms,
            m.chamfer_ms,
            m.exact_edt_ms / m.chamfer_ms,
            m.chamfer_max_error_m
        ));
    }
    s.push_str(&format!(
        "\nredb, one 2000×2000 map: put {:.1} ms, get {:.1} ms (best of {}).\n",
        report.store_put_ms, report.store_get_ms, report.repeats
    ));
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::{FREE, OCCUPIED};
    use protocol::Pose2D;

    #[test]
    fn chamfer_is_exact_on_axes_and_diagonals_and_bounded_elsewhere() {
        let mut g = OccupancyGrid::filled(41, 41, 0.1, Pose2D::default(), FREE).unwrap();
        g.set(20, 20, OCCUPIED);
        let c = chamfer_distance_m(&g);
        let e = DistanceField::compute(&g, Sources::Occupied);
        assert!((c[g.index(20, 30)] - 1.0).abs() < 1e-5);
        assert!((c[g.index(30, 30)] - e.at(30, 30)).abs() < 1e-5);
        // Off the 8 directions the chamfer over-estimates, by at most ~8 %.
        let (ce, ee) = (c[g.index(40, 30)], e.at(40, 30));
        assert!(ce > ee && ce < ee * 1.09, "{ce} vs {ee}");
    }
}
