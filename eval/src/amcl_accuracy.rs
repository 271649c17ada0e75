//! How well AMCL localizes on the crude floor plan while the robot drives tasks A–E in the
//! simulator, whose world has furniture, people and glass that the plan lacks.
//!
//! Each task is one closed-loop run of [`crate::table`] (lock-step, no Zenoh and no wall clock:
//! the robot agent's own supervisor runs AMCL and the controller, the planning crate's
//! intention pipeline replans from the published pose every cycle, the judge intervenes like
//! the paper's human). Only the comparison reads the ground truth: the pose the agent publishes
//! (the filter's estimate carried forward by odometry) against the true pose, every cycle. After
//! an intervention AMCL is re-initialised at the new true pose with the configured initial
//! covariance, as the operator who carried the robot would set its pose estimate; the settling
//! after it counts too.
//!
//! [`from_log`] makes the same row from a run log (`--record-dir`, `robot-agent --record`)
//! instead of driving: the agent's AMCL replayed over the log's sensors
//! ([`robot_agent::replay`]), against the log's ground truth.

use std::path::{Path, PathBuf};

use robot_agent::{AgentConfig, ControllerKind};
use serde::Serialize;

use crate::table::{self, Prepared, RunResult, TableError, TableOptions};

/// Thresholds of the accuracy requirement.
pub const MAX_MEAN_POSITION_ERROR_M: f64 = 0.10;
pub const MAX_MEAN_HEADING_ERROR_DEG: f64 = 3.0;
/// An error above this, even once, means the filter diverged.
pub const DIVERGED_POSITION_ERROR_M: f64 = 1.0;

/// One accuracy run's settings.
#[derive(Debug, Clone)]
pub struct AccuracyOptions {
    /// Mixed into the scenario's seed (sensor and odometry noise) and AMCL's seed; 0 keeps the
    /// scenario's own.
    pub seed: u64,
    /// The method that drives (default: the dynamic window).
    pub controller: ControllerKind,
    /// The closed loop's settings (agent configuration, interventions, time limit).
    pub run: TableOptions,
}

impl Default for AccuracyOptions {
    fn default() -> Self {
        Self {
            seed: 0,
            controller: ControllerKind::DynamicWindow,
            run: TableOptions::default(),
        }
    }
}

/// The figures of one task.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TaskAccuracy {
    pub task: String,
    pub sim_time_s: f64,
    pub mean_position_error_m: f64,
    pub max_position_error_m: f64,
    pub mean_heading_error_deg: f64,
    pub max_heading_error_deg: f64,
    pub diverged: bool,
    pub goals_reached: usize,
    pub goals_total: usize,
    pub distance_m: f64,
    pub collisions: u32,
    /// Human interventions: the robot collided or made no progress and was carried ahead.
    pub interventions: u32,
    /// Mean errors within [`MAX_MEAN_POSITION_ERROR_M`] and [`MAX_MEAN_HEADING_ERROR_DEG`]
    /// and no divergence.
    pub pass: bool,
}

impl From<&RunResult> for TaskAccuracy {
    fn from(r: &RunResult) -> Self {
        let diverged = r.max_position_error_m > DIVERGED_POSITION_ERROR_M;
        Self {
            task: r.scenario.clone(),
            sim_time_s: r.time_s,
            mean_position_error_m: r.mean_position_error_m,
            max_position_error_m: r.max_position_error_m,
            mean_heading_error_deg: r.mean_heading_error_deg,
            max_heading_error_deg: r.max_heading_error_deg,
            diverged,
            goals_reached: r.goals_reached,
            goals_total: r.goals_total,
            distance_m: r.path_length_m,
            collisions: r.collisions.total(),
            interventions: r.interventions,
            pass: !diverged
                && r.mean_position_error_m <= MAX_MEAN_POSITION_ERROR_M
                && r.mean_heading_error_deg <= MAX_MEAN_HEADING_ERROR_DEG,
        }
    }
}

/// Runs one task; `progress` gets the simulated seconds of every cycle.
///
/// # Errors
/// [`TableError`] for an unreadable scenario or invalid options.
pub fn run_task(
    scenario_path: &Path,
    options: &AccuracyOptions,
    progress: impl FnMut(f64),
) -> Result<TaskAccuracy, TableError> {
    options.run.validate(&[options.controller])?;
    let prepared = Prepared::load(scenario_path, &options.run)?;
    let (result, _) = table::run_one(
        &prepared,
        options.controller,
        options.seed,
        &options.run,
        progress,
    )?;
    Ok(TaskAccuracy::from(&result))
}

/// One task's figures from a run log: the agent's AMCL replayed over it with `config` (`None`:
/// the configuration the log recorded) on `map` (`None`: the floor plan file the log names).
///
/// Goals, collisions and the run's time come from the log's `/run_summary` (an `eval` log);
/// a log without one (a live agent's) shows 0 goals, and its re-initialisations as
/// interventions.
///
/// # Errors
/// [`TableError::Log`] for a file that is not a readable run log, [`TableError::Setup`] when
/// the map cannot be found or loaded or the replay fails, naming the file.
pub fn from_log(
    log_path: &Path,
    map: Option<&Path>,
    config: Option<&AgentConfig>,
) -> Result<TaskAccuracy, TableError> {
    let log = fleet_log::RunLog::open(log_path)?;
    let setup = |reason: String| TableError::Setup {
        what: "replay",
        reason: format!("{}: {reason}", log_path.display()),
    };
    let replay = robot_agent::replay::replay_files(&log, map, config.cloned())
        .map_err(|e| setup(e.to_string()))?;
    let s = &replay.summary;
    let position = s.position_error_m.ok_or_else(|| {
        setup("no ground truth in the log (record it with eval or sim run --record)".into())
    })?;
    let heading = s.heading_error_deg.unwrap_or_default();
    let run = log.run_summary();
    let diverged = position.max > DIVERGED_POSITION_ERROR_M;
    Ok(TaskAccuracy {
        task: run.map_or_else(
            || {
                log_path
                    .file_stem()
                    .map(|n| n.to_string_lossy().into_owned())
                    .unwrap_or_default()
            },
            |r| r.scenario.clone(),
        ),
        sim_time_s: run.map_or(s.log_duration_s, |r| r.time_s),
        mean_position_error_m: position.mean,
        max_position_error_m: position.max,
        mean_heading_error_deg: heading.mean,
        max_heading_error_deg: heading.max,
        diverged,
        goals_reached: run.map_or(0, |r| r.goals_reached),
        goals_total: run.map_or(0, |r| r.goals_total),
        distance_m: s.distance_m,
        collisions: run.map_or(0, |r| r.collisions),
        interventions: run.map_or_else(
            || u32::try_from(s.reinitialisations).unwrap_or(u32::MAX),
            |r| r.interventions,
        ),
        pass: !diverged
            && position.mean <= MAX_MEAN_POSITION_ERROR_M
            && heading.mean <= MAX_MEAN_HEADING_ERROR_DEG,
    })
}

/// The run logs named: files as given, folders as their `*.mcap` files in name order.
///
/// # Errors
/// [`TableError::Invalid`] for a path that does not exist or a folder without logs.
pub fn log_files(paths: &[PathBuf]) -> Result<Vec<PathBuf>, TableError> {
    let mut files = Vec::new();
    for p in paths {
        if p.is_dir() {
            let mut found: Vec<PathBuf> = std::fs::read_dir(p)
                .map_err(|e| TableError::Invalid {
                    field: "log",
                    value: p.display().to_string(),
                    reason: e.to_string(),
                })?
                .filter_map(Result::ok)
                .map(|e| e.path())
                .filter(|f| f.extension().is_some_and(|x| x == "mcap"))
                .collect();
            found.sort();
            if found.is_empty() {
                return Err(TableError::Invalid {
                    field: "log",
                    value: p.display().to_string(),
                    reason: "the folder has no .mcap file".into(),
                });
            }
            files.extend(found);
        } else if p.exists() {
            files.push(p.clone());
        } else {
            return Err(TableError::Invalid {
                field: "log",
                value: p.display().to_string(),
                reason: "no such file or folder".into(),
            });
        }
    }
    Ok(files)
}

/// A markdown table of the results, one row per task.
#[must_use]
pub fn markdown(results: &[TaskAccuracy]) -> String {
    let mut out = String::from(
        "| task | mean pos. err (m) | max pos. err (m) | mean heading err (deg) | max heading err (deg) | diverged | goals reached | distance (m) | sim time (s) | collisions | interventions | verdict (mean <= 0.10 m, <= 3 deg) |\n|---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for r in results {
        out.push_str(&format!(
            "| {} | {:.3} | {:.3} | {:.2} | {:.2} | {} | {}/{} | {:.1} | {:.1} | {} | {} | {} |\n",
            r.task,
            r.mean_position_error_m,
            r.max_position_error_m,
            r.mean_heading_error_deg,
            r.max_heading_error_deg,
            if r.diverged { "yes" } else { "no" },
            r.goals_reached,
            r.goals_total,
            r.distance_m,
            r.sim_time_s,
            r.collisions,
            r.interventions,
            if r.pass { "pass" } else { "FAIL" },
        ));
    }
    out
}
