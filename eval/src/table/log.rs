//! Run logs of lock-step runs (`--record-dir`): one MCAP file per run with what the agent got
//! and published, the ground truth and every re-initialisation after an intervention, so that
//! `robot-agent replay` and `eval amcl-accuracy --log` re-run its localization offline
//! (docs/logs.md).

use std::path::{Path, PathBuf};

use fleet_log::{InitialPose, LogOptions, LogWriter, MapInfo, RunSummary};
use protocol::{
    AgentStatus, CameraFrame, CmdVel, ControllerKind, Header, Intention, LaserScan, Odometry,
    Pose2D, PoseEstimate,
};
use robot_agent::AgentConfig;

use super::run::{Prepared, RunResult};
use super::TableError;

/// Where and what `--record-dir` records.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordSettings {
    /// One file per run: `<scenario>-<method>-seed<seed>.mcap`.
    pub dir: PathBuf,
    pub log: LogOptions,
}

/// The log file of one run in `dir`.
#[must_use]
pub fn log_path(dir: &Path, scenario: &str, method: ControllerKind, seed: u64) -> PathBuf {
    let safe: String = safe_chars(scenario).collect();
    dir.join(format!("{safe}-{method}-seed{seed}.mcap"))
}

/// A scenario's name with every character but ASCII letters, digits, `_`, `-` and `.` turned
/// into `_`: what both a file name and a task id may hold.
pub(crate) fn safe_chars(name: &str) -> impl Iterator<Item = char> + '_ {
    name.chars().map(|c| {
        if c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.') {
            c
        } else {
            '_'
        }
    })
}

/// The writer of one run's log.
pub(crate) struct RunRecorder {
    writer: LogWriter,
    cmd_seq: u64,
    /// The last `/agent_status` written, so only changes are.
    status: Option<AgentStatus>,
}

impl RunRecorder {
    /// Starts the log with `/map` (the floor plan, its hash, the start and the initial
    /// covariance) and `/agent_config` (the configuration the supervisor runs with, seed
    /// included).
    pub(crate) fn start(
        settings: &RecordSettings,
        prepared: &Prepared,
        method: ControllerKind,
        seed: u64,
        agent: &AgentConfig,
        start: Pose2D,
        initial_covariance: [f64; 9],
    ) -> Result<Self, TableError> {
        let name = &prepared.scenario.name;
        let path = log_path(&settings.dir, name, method, seed);
        let mut writer = LogWriter::create(&path, settings.log)?;
        let plan_path = prepared.scenario.floor_plan_path(&prepared.path);
        let plan = &prepared.plan;
        writer.map(&MapInfo {
            stamp_ns: 0,
            name: plan_path
                .file_stem()
                .map_or_else(|| name.clone(), |s| s.to_string_lossy().into_owned()),
            version: 1,
            path: plan_path
                .is_file()
                .then(|| std::path::absolute(&plan_path).unwrap_or(plan_path.clone()))
                .map(|p| p.display().to_string()),
            content_hash: Some(plan.content_hash()),
            initial_pose: Some(start),
            initial_covariance: Some(initial_covariance),
            source: format!("eval: {name} {method} seed {seed}"),
        })?;
        writer.agent_config(0, agent)?;
        // Where the robot stands before the first step (the trajectory starts here).
        writer.ground_truth(Header::new(0, 0), start)?;
        Ok(Self {
            writer,
            cmd_seq: 0,
            status: None,
        })
    }

    /// What the agent got this cycle, and the truth at the same instant.
    pub(crate) fn sensors(
        &mut self,
        odom: &Odometry,
        scan: &LaserScan,
        truth: Pose2D,
    ) -> Result<(), TableError> {
        self.writer.odom(odom)?;
        self.writer.scan(scan)?;
        Ok(self.writer.ground_truth(odom.header, truth)?)
    }

    pub(crate) fn pose(&mut self, pose: &PoseEstimate) -> Result<(), TableError> {
        Ok(self.writer.amcl_pose(pose)?)
    }

    /// The judge carried the robot to `pose` and re-initialised the filter there: the true
    /// pose after the carry (same stamp as the one before it) and the `/initialpose`.
    pub(crate) fn reinit(
        &mut self,
        header: Header,
        pose: Pose2D,
        covariance: [f64; 9],
    ) -> Result<(), TableError> {
        self.writer.ground_truth(header, pose)?;
        Ok(self.writer.initial_pose(&InitialPose {
            header,
            pose,
            covariance,
        })?)
    }

    pub(crate) fn intention(&mut self, intention: &Intention) -> Result<(), TableError> {
        Ok(self
            .writer
            .intention(&fleet_log::intention_without_pixels(intention))?)
    }

    pub(crate) fn wants_camera(&self) -> bool {
        self.writer.options().camera
    }

    pub(crate) fn camera(&mut self, frame: &CameraFrame) -> Result<(), TableError> {
        Ok(self.writer.camera(frame)?)
    }

    /// The command the robot executes next.
    pub(crate) fn cmd(
        &mut self,
        stamp_ns: u64,
        v_mps: f64,
        omega_radps: f64,
    ) -> Result<(), TableError> {
        self.cmd_seq += 1;
        Ok(self.writer.cmd_vel(&CmdVel {
            header: Header::new(self.cmd_seq, stamp_ns),
            v_mps,
            omega_radps,
        })?)
    }

    /// `/agent_status` when it differs from the last one written (header aside): who drives
    /// (the controller, or the recovering dynamic window, the rotation shim, the give-way rule)
    /// and the agent's state.
    pub(crate) fn status(&mut self, status: AgentStatus) -> Result<(), TableError> {
        let unchanged = self.status.as_ref().is_some_and(|last| {
            AgentStatus {
                header: status.header,
                ..last.clone()
            } == status
        });
        if unchanged {
            return Ok(());
        }
        let status = AgentStatus {
            header: Header::new(
                self.status.as_ref().map_or(1, |last| last.header.seq + 1),
                status.header.stamp_ns,
            ),
            ..status
        };
        self.writer.agent_status(&status)?;
        self.status = Some(status);
        Ok(())
    }

    /// Ends the log with `/run_summary` and renames it into place.
    pub(crate) fn finish(mut self, stamp_ns: u64, result: &RunResult) -> Result<(), TableError> {
        self.writer.run_summary(&RunSummary {
            stamp_ns,
            scenario: result.scenario.clone(),
            method: result.method.to_string(),
            seed: result.seed,
            success: result.success,
            goals_reached: result.goals_reached,
            goals_total: result.goals_total,
            collisions: result.collisions.total(),
            interventions: result.interventions,
            time_s: result.time_s,
        })?;
        self.writer.finish()?;
        Ok(())
    }
}
