//! Offline replay of the agent's localization over a run log (`robot-agent replay`,
//! `eval amcl-accuracy --log`): the agent's own [`Supervisor`] (so the same AMCL, the same
//! configuration and the same choice of the odometry that goes with a scan) is fed the log's
//! `/odom` and `/scan` in the order the agent processed them, as fast as it can, and
//! re-initialised wherever the log has an `/initialpose`.
//!
//! The filter starts at the log's initial pose (`/map`; global localization when it has none)
//! with the configuration the log recorded (`/agent_config`) unless another one is given. With
//! the recorded configuration the replay of an unmodified filter reproduces the live run's
//! estimates exactly: AMCL's only randomness is its seeded generator, and the replay makes the
//! same calls in the same order. Each estimate is compared with the ground truth at the scan's
//! stamp (when the log has `/ground_truth`) and with the pose the live agent published for that
//! scan (`/amcl_pose`).

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use fleet_log::{LogMessage, RunLog, StampedPose};
use map_core::OccupancyGrid;
use protocol::{normalize_angle, ControllerKind, MapName, MapRef, Pose2D};
use serde::Serialize;

use crate::config::AgentConfig;
use crate::controllers::{Control, ControlInput, Controller, ControllerError};
use crate::node::{NodeError, Supervisor};

/// Why a log could not be replayed.
#[derive(Debug, thiserror::Error)]
pub enum ReplayError {
    #[error(transparent)]
    Log(#[from] fleet_log::LogError),
    #[error("{}: {reason}", path.display())]
    Invalid { path: PathBuf, reason: String },
    #[error("{}: localization: {source}", path.display())]
    Agent {
        path: PathBuf,
        source: Box<NodeError>,
    },
    #[error("cannot write {}: {reason}", path.display())]
    Write { path: PathBuf, reason: String },
}

/// One estimate of the replayed filter.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ReplayedPose {
    /// The scan's stamp.
    pub stamp_ns: u64,
    pub x_m: f64,
    pub y_m: f64,
    pub yaw_rad: f64,
    /// Against the ground truth at the scan's stamp (`None`: the log has none there).
    pub position_error_m: Option<f64>,
    pub heading_error_deg: Option<f64>,
    /// Distance to the pose the live agent published for the same scan.
    pub live_difference_m: Option<f64>,
    /// Wall-clock time of this scan's update (AMCL and the estimate).
    pub update_ms: f64,
    /// Whether the filter ran on this scan (moved or turned enough since its last run); when
    /// not, the estimate is the last one carried forward by the odometry.
    pub filter_ran: bool,
}

/// Mean and maximum of a series.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct Stat {
    pub mean: f64,
    pub max: f64,
    pub count: usize,
}

impl Stat {
    fn of(values: impl Iterator<Item = f64>) -> Option<Self> {
        let (mut sum, mut max, mut count) = (0.0, 0.0f64, 0usize);
        for v in values {
            sum += v;
            max = max.max(v);
            count += 1;
        }
        #[allow(clippy::cast_precision_loss)]
        (count > 0).then(|| Stat {
            mean: sum / count as f64,
            max,
            count,
        })
    }
}

/// The figures of one replay.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ReplaySummary {
    pub log: String,
    pub scans: usize,
    pub reinitialisations: usize,
    /// The replayed filter against the ground truth (`None`: no ground truth in the log).
    pub position_error_m: Option<Stat>,
    pub heading_error_deg: Option<Stat>,
    /// What the live agent published (`/amcl_pose`) against the same ground truth.
    pub live_position_error_m: Option<Stat>,
    pub live_heading_error_deg: Option<Stat>,
    /// Largest distance between a replayed estimate and the live one for the same scan.
    pub max_live_difference_m: Option<f64>,
    pub update_ms: Stat,
    /// Stamps from the first to the last scan.
    pub log_duration_s: f64,
    /// Length of the true trajectory (carries left out).
    pub distance_m: f64,
    /// Whether the map given has the content hash the log recorded (`None`: none recorded).
    pub map_matches: Option<bool>,
}

/// A replay's estimates and summary.
#[derive(Debug, Clone)]
pub struct Replay {
    pub poses: Vec<ReplayedPose>,
    pub summary: ReplaySummary,
}

/// Stands in for the controller: a replay only localizes, it never asks for a command.
struct NoController(ControllerKind);

impl Controller for NoController {
    fn kind(&self) -> ControllerKind {
        self.0
    }

    fn control(&mut self, _input: &ControlInput<'_>) -> Result<Control, ControllerError> {
        Err(ControllerError::MissingInput {
            controller: "replay",
            input: "a controller (a replay only localizes)",
        })
    }
}

/// The agent configuration a log recorded (`/agent_config`); the defaults for a log without
/// one (the simulator's, whose agent ran elsewhere).
///
/// # Errors
/// [`ReplayError::Invalid`] naming the log when its configuration does not parse.
pub fn recorded_config(log: &RunLog) -> Result<AgentConfig, ReplayError> {
    let invalid = |reason: String| ReplayError::Invalid {
        path: log.path().to_path_buf(),
        reason,
    };
    let Some(value) = log.agent_config() else {
        tracing::warn!(log = %log.path().display(), "no /agent_config recorded: replaying with the default configuration");
        return Ok(AgentConfig::default());
    };
    let config: AgentConfig = serde_json::from_value(value.clone())
        .map_err(|e| invalid(format!("/agent_config does not parse ({e}); give --config")))?;
    config
        .validate()
        .map_err(|e| invalid(format!("/agent_config: {e}")))?;
    Ok(config)
}

/// Replays a log from files: on `map` (a ROS map YAML; `None`: the floor plan file the log
/// names) with `config` (`None`: the configuration the log recorded, which reproduces the live
/// run). A map whose content hash differs from the log's is used, with a warning.
///
/// # Errors
/// [`ReplayError::Invalid`] naming the log when no map is given or named or the map cannot be
/// loaded, and the errors of [`recorded_config`] and [`replay`].
pub fn replay_files(
    log: &RunLog,
    map: Option<&Path>,
    config: Option<AgentConfig>,
) -> Result<Replay, ReplayError> {
    let invalid = |reason: String| ReplayError::Invalid {
        path: log.path().to_path_buf(),
        reason,
    };
    let map_path: PathBuf = match map {
        Some(m) => m.to_path_buf(),
        None => log
            .map()
            .and_then(|m| m.path.clone())
            .map(PathBuf::from)
            .ok_or_else(|| invalid("the log names no floor plan file; give --map".into()))?,
    };
    let grid = map_core::load_ros_map(&map_path, &map_core::ImportLimits::default())
        .map_err(|e| invalid(format!("map {}: {e}", map_path.display())))?
        .grid;
    let config = match config {
        Some(c) => c,
        None => recorded_config(log)?,
    };
    let replay = replay(log, &grid, &config)?;
    if replay.summary.map_matches == Some(false) {
        tracing::warn!(
            log = %log.path().display(),
            map = %map_path.display(),
            "not the map the log was recorded on (content hash differs)"
        );
    }
    Ok(replay)
}

/// The true pose at `stamp_ns`: the sample with that stamp, else linear between the two around
/// it when they are at most 0.25 s apart.
fn truth_at(truth: &[StampedPose], stamp_ns: u64) -> Option<Pose2D> {
    let i = truth.partition_point(|t| t.header.stamp_ns < stamp_ns);
    let after = truth.get(i)?;
    if after.header.stamp_ns == stamp_ns {
        return Some(after.pose);
    }
    let before = truth.get(i.checked_sub(1)?)?;
    let span = after.header.stamp_ns - before.header.stamp_ns;
    if span > 250_000_000 {
        return None;
    }
    #[allow(clippy::cast_precision_loss)]
    let f = (stamp_ns - before.header.stamp_ns) as f64 / span as f64;
    let (a, b) = (before.pose, after.pose);
    Some(Pose2D::new(
        a.x_m + f * (b.x_m - a.x_m),
        a.y_m + f * (b.y_m - a.y_m),
        normalize_angle(a.yaw_rad + f * normalize_angle(b.yaw_rad - a.yaw_rad)),
    ))
}

fn heading_error_deg(a: Pose2D, b: Pose2D) -> f64 {
    normalize_angle(a.yaw_rad - b.yaw_rad).abs().to_degrees()
}

/// Replays the log's localization on `grid` with `config` (its `[amcl]` and `[localization]`
/// tables matter; the initial pose is the log's).
///
/// # Errors
/// [`ReplayError`] naming the log when it has no `/map` record, or the filter cannot be set up
/// on this map or refuses a recorded message.
pub fn replay(
    log: &RunLog,
    grid: &OccupancyGrid,
    config: &AgentConfig,
) -> Result<Replay, ReplayError> {
    let path = log.path().to_path_buf();
    let map = log.map().ok_or_else(|| ReplayError::Invalid {
        path: path.clone(),
        reason: "no /map record: not a run log of this fleet".into(),
    })?;
    let map_matches = map
        .content_hash
        .as_ref()
        .map(|recorded| *recorded == grid.content_hash());
    let mut config = config.clone();
    config.localization.initial_pose = map.initial_pose;
    let map_ref = MapRef {
        name: MapName::new(map.name.clone())
            .or_else(|_| MapName::new("replay"))
            .map_err(|e| ReplayError::Invalid {
                path: path.clone(),
                reason: e.to_string(),
            })?,
        version: map.version,
    };
    let kind = config.controller;
    let mut supervisor = Supervisor::new(config, map_ref, grid, Box::new(NoController(kind)))
        .map_err(|source| ReplayError::Agent {
            path: path.clone(),
            source: Box::new(source),
        })?;

    let truth = log.ground_truth();
    let live: HashMap<u64, Pose2D> = log
        .as_recorded()
        .iter()
        .filter_map(|e| match &e.message {
            LogMessage::AmclPose(p) => Some((p.sensor_stamp_ns, p.pose)),
            _ => None,
        })
        .collect();
    let epoch = Instant::now();
    let mut poses = Vec::new();
    let (mut scans, mut reinitialisations) = (0usize, 0usize);
    let mut update_ms = Vec::new();
    let (mut first_scan, mut last_scan) = (None, 0u64);
    for entry in log.as_recorded() {
        match &entry.message {
            LogMessage::Odom(odom) => supervisor.on_odometry(odom.clone()),
            LogMessage::InitialPose(init) => {
                supervisor
                    .set_pose(init.pose, init.covariance)
                    .map_err(|source| ReplayError::Agent {
                        path: path.clone(),
                        source: Box::new(source),
                    })?;
                reinitialisations += 1;
            }
            LogMessage::Scan(scan) => {
                scans += 1;
                let stamp_ns = scan.header.stamp_ns;
                first_scan.get_or_insert(stamp_ns);
                last_scan = stamp_ns;
                let now = epoch + Duration::from_nanos(stamp_ns);
                let started = Instant::now();
                let estimate = supervisor.on_scan(scan.clone(), now, stamp_ns);
                let ms = started.elapsed().as_secs_f64() * 1e3;
                let estimate = match estimate {
                    Ok(e) => e,
                    Err(e) => {
                        tracing::warn!(log = %path.display(), stamp_ns, "scan not used: {e}");
                        continue;
                    }
                };
                update_ms.push(ms);
                let Some(estimate) = estimate else { continue };
                let pose = estimate.pose;
                let at = truth_at(&truth, stamp_ns);
                poses.push(ReplayedPose {
                    stamp_ns,
                    x_m: pose.x_m,
                    y_m: pose.y_m,
                    yaw_rad: pose.yaw_rad,
                    position_error_m: at.map(|t| pose.distance_m(&t)),
                    heading_error_deg: at.map(|t| heading_error_deg(pose, t)),
                    live_difference_m: live.get(&stamp_ns).map(|l| pose.distance_m(l)),
                    update_ms: ms,
                    filter_ran: supervisor.last_amcl_update().is_some_and(|o| o.filter_ran),
                });
            }
            _ => {}
        }
    }
    let live_errors: Vec<(f64, f64)> = log
        .as_recorded()
        .iter()
        .filter_map(|e| match &e.message {
            LogMessage::AmclPose(p) => truth_at(&truth, p.sensor_stamp_ns)
                .map(|t| (p.pose.distance_m(&t), heading_error_deg(p.pose, t))),
            _ => None,
        })
        .collect();
    let summary = ReplaySummary {
        log: path.display().to_string(),
        scans,
        reinitialisations,
        position_error_m: Stat::of(poses.iter().filter_map(|p| p.position_error_m)),
        heading_error_deg: Stat::of(poses.iter().filter_map(|p| p.heading_error_deg)),
        live_position_error_m: Stat::of(live_errors.iter().map(|e| e.0)),
        live_heading_error_deg: Stat::of(live_errors.iter().map(|e| e.1)),
        max_live_difference_m: poses
            .iter()
            .filter_map(|p| p.live_difference_m)
            .reduce(f64::max),
        update_ms: Stat::of(update_ms.into_iter()).unwrap_or_default(),
        #[allow(clippy::cast_precision_loss)]
        log_duration_s: first_scan.map_or(0.0, |f| (last_scan - f) as f64 * 1e-9),
        distance_m: true_distance_m(&truth),
        map_matches,
    };
    Ok(Replay { poses, summary })
}

/// Length of the true trajectory. Two true poses with the same stamp are a carry (the robot
/// was picked up and put down in no time; the lock-step runner records both), not motion.
fn true_distance_m(truth: &[StampedPose]) -> f64 {
    truth
        .windows(2)
        .filter(|w| w[0].header.stamp_ns != w[1].header.stamp_ns)
        .map(|w| w[0].pose.distance_m(&w[1].pose))
        .sum()
}

/// Writes the estimates: CSV when `path` ends in `.csv`, JSON lines otherwise.
///
/// # Errors
/// [`ReplayError::Write`] naming the file.
pub fn write_poses(path: &Path, poses: &[ReplayedPose]) -> Result<(), ReplayError> {
    let write_err = |e: &dyn std::fmt::Display| ReplayError::Write {
        path: path.to_path_buf(),
        reason: e.to_string(),
    };
    let csv = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("csv"));
    let mut out = String::new();
    let opt = |v: Option<f64>| v.map_or_else(String::new, |v| format!("{v}"));
    if csv {
        out.push_str(
            "stamp_ns,x_m,y_m,yaw_rad,position_error_m,heading_error_deg,live_difference_m,update_ms,filter_ran\n",
        );
    }
    for p in poses {
        if csv {
            out.push_str(&format!(
                "{},{},{},{},{},{},{},{},{}\n",
                p.stamp_ns,
                p.x_m,
                p.y_m,
                p.yaw_rad,
                opt(p.position_error_m),
                opt(p.heading_error_deg),
                opt(p.live_difference_m),
                p.update_ms,
                p.filter_ran
            ));
        } else {
            out.push_str(&serde_json::to_string(p).map_err(|e| write_err(&e))?);
            out.push('\n');
        }
    }
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|e| write_err(&e))?;
    }
    std::fs::write(path, out).map_err(|e| write_err(&e))
}

/// A markdown table of replays, one row per log.
#[must_use]
pub fn markdown(summaries: &[ReplaySummary]) -> String {
    let mut out = String::from(
        "| log | scans | re-inits | mean pos. err (m) | max pos. err (m) | mean heading err (deg) | max heading err (deg) | live mean pos. err (m) | max diff. to live (m) | mean update (ms) | max update (ms) |\n|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    let f = |s: Option<Stat>, mean: bool, digits: usize| {
        s.map_or_else(
            || "-".to_string(),
            |s| format!("{:.digits$}", if mean { s.mean } else { s.max }),
        )
    };
    for s in summaries {
        let name = Path::new(&s.log)
            .file_name()
            .map_or_else(|| s.log.clone(), |n| n.to_string_lossy().into_owned());
        out.push_str(&format!(
            "| {name} | {} | {} | {} | {} | {} | {} | {} | {} | {:.3} | {:.3} |\n",
            s.scans,
            s.reinitialisations,
            f(s.position_error_m, true, 3),
            f(s.position_error_m, false, 3),
            f(s.heading_error_deg, true, 2),
            f(s.heading_error_deg, false, 2),
            f(s.live_position_error_m, true, 3),
            s.max_live_difference_m
                .map_or_else(|| "-".to_string(), |d| format!("{d:.2e}")),
            s.update_ms.mean,
            s.update_ms.max,
        ));
    }
    out
}
