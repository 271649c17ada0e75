//! Robot run logs as MCAP: what a robot agent received and published, what the simulator knew
//! (ground truth), and how the run was set up, so that a localization run can be replayed
//! offline (`robot-agent replay`, `eval amcl-accuracy --log`) and looked at in Foxglove.
//!
//! A log is an [MCAP](https://mcap.dev) file with zstd-compressed chunks. Every channel has
//! message encoding `json` and a JSON schema (schema encoding `jsonschema`), so Foxglove and
//! the `mcap` CLI open it without any plugin. One channel per topic ([`Topic`]):
//!
//! | topic | message | who writes it |
//! |---|---|---|
//! | `/map` | [`MapInfo`]: map name, version, path and content hash, initial pose | once, first |
//! | `/agent_config` | the agent's whole configuration (`AgentConfig` as JSON) | once |
//! | `/scan` | [`protocol::LaserScan`] | sensor data the agent used |
//! | `/odom` | [`protocol::Odometry`] | sensor data the agent used |
//! | `/camera` | [`CompressedImage`] (`foxglove.CompressedImage`, base64 JPEG/PNG) | only when asked |
//! | `/amcl_pose` | [`protocol::PoseEstimate`] the agent published | agent |
//! | `/intention` | [`protocol::Intention`] without the LPE image bytes | planner → agent |
//! | `/cmd_vel` | [`protocol::CmdVel`] the agent commanded | agent |
//! | `/agent_status` | [`protocol::AgentStatus`]: its state, and whether the recovery (the dynamic window, or backing off), the rotation shim or the give-way rule drives in the controller's place; each change | agent |
//! | `/initialpose` | [`InitialPose`]: a re-initialisation of the filter (not the first one) | operator / judge |
//! | `/ground_truth` | [`StampedPose`]: the true pose (simulator only) | simulator |
//! | `/run_summary` | [`RunSummary`]: how a lock-step run ended | `eval` |
//!
//! Every message's MCAP `log_time` (and `publish_time`) is the message's own stamp in ns
//! (`header.stamp_ns`; the simulated clock in lock-step runs). Messages are written in the
//! order the agent processed them; [`RunLog::messages`] gives them in time order (stable, so
//! equal stamps keep the recorded order), [`RunLog::as_recorded`] in file order.
//!
//! Writing is crash-safe in the sense that matters here: [`LogWriter`] writes
//! `FILE.partial` and renames it to `FILE` only in [`LogWriter::finish`], so a `FILE` that
//! exists is complete; a crashed recorder leaves `FILE.partial` behind (`mcap recover` salvages
//! its finished chunks). [`Recorder`] runs a writer on its own thread for the real-time nodes.
//!
//! The intention's LPE image is not stored: [`protocol::Image`]'s bytes are not part of its
//! serde form (the wire codec sends them as a raw blob), so `/intention` keeps the image's size
//! and encoding and reads back with empty `lpe.data`. The camera is where pixels go.

mod camera;
mod reader;
mod recorder;
mod topics;
mod writer;

pub use camera::{CompressedImage, Timestamp};
pub use reader::{LogEntry, LogMessage, RunLog};
pub use recorder::Recorder;
pub use topics::{
    InitialPose, MapInfo, RunSummary, StampedPose, Topic, MESSAGE_ENCODING, SCHEMA_ENCODING,
};
pub use writer::{LogOptions, LogWriter};

use std::path::{Path, PathBuf};

/// Why a log could not be written or read; every variant names the file.
#[derive(Debug, thiserror::Error)]
pub enum LogError {
    #[error("{}: not an MCAP file ({reason})", path.display())]
    NotMcap { path: PathBuf, reason: String },
    #[error("{}: cannot {action}: {reason}", path.display())]
    Io {
        path: PathBuf,
        action: &'static str,
        reason: String,
    },
    #[error("{}: broken MCAP: {reason}", path.display())]
    Mcap { path: PathBuf, reason: String },
    #[error("{}: message {sequence} on {topic}: {reason}", path.display())]
    Message {
        path: PathBuf,
        topic: String,
        sequence: u32,
        reason: String,
    },
    #[error("{}: cannot encode a {topic} message: {reason}", path.display())]
    Encode {
        path: PathBuf,
        topic: &'static str,
        reason: String,
    },
    #[error("{}: the recorder thread stopped: {reason}", path.display())]
    Recorder { path: PathBuf, reason: String },
}

impl LogError {
    pub(crate) fn io(path: &Path, action: &'static str, e: impl std::fmt::Display) -> Self {
        Self::Io {
            path: path.to_path_buf(),
            action,
            reason: e.to_string(),
        }
    }

    pub(crate) fn mcap(path: &Path, e: impl std::fmt::Display) -> Self {
        Self::Mcap {
            path: path.to_path_buf(),
            reason: e.to_string(),
        }
    }
}

/// `FILE.partial`: where [`LogWriter`] writes until it finishes.
#[must_use]
pub fn partial_path(path: &Path) -> PathBuf {
    let mut name = path.as_os_str().to_owned();
    name.push(".partial");
    PathBuf::from(name)
}

/// A copy of an intention for `/intention`: everything but the LPE image's pixels (which the
/// log would drop anyway, see the crate docs), so a recorder does not copy 150 kB per cycle.
#[must_use]
pub fn intention_without_pixels(intention: &protocol::Intention) -> protocol::Intention {
    protocol::Intention {
        header: intention.header,
        task_id: intention.task_id.clone(),
        goal_index: intention.goal_index,
        answers_pose_seq: intention.answers_pose_seq,
        answers_pose_stamp_ns: intention.answers_pose_stamp_ns,
        map: intention.map.clone(),
        path: intention.path.clone(),
        dlm: intention.dlm,
        arriving: intention.arriving,
        lpe: intention.lpe.as_ref().map(|image| protocol::Image {
            width_px: image.width_px,
            height_px: image.height_px,
            encoding: image.encoding,
            data: Vec::new(),
        }),
    }
}
