//! [`LogWriter`]: writes a run log to `FILE.partial` and renames it to `FILE` when finished.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use protocol::{
    AgentStatus, CameraFrame, CmdVel, Header, Intention, LaserScan, Odometry, Pose2D, PoseEstimate,
};
use serde::Serialize;

use crate::camera::CompressedImage;
use crate::reader::LogMessage;
use crate::topics::{InitialPose, MapInfo, RunSummary, StampedPose, Topic};
use crate::{partial_path, LogError, MESSAGE_ENCODING, SCHEMA_ENCODING};

/// What goes into a log besides the always-recorded topics.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LogOptions {
    /// Record `/camera` (it dominates the log's size: a 224×224 JPEG is ~10 kB, 100 kB/s).
    pub camera: bool,
    /// Quality of the JPEG that RGB8 camera frames are compressed to (1–100).
    pub jpeg_quality: u8,
}

impl Default for LogOptions {
    fn default() -> Self {
        Self {
            camera: false,
            jpeg_quality: 85,
        }
    }
}

/// Writes one run log (see the crate docs for the topics). Channels are declared on their first
/// message, so a log has only the channels it uses.
pub struct LogWriter {
    path: PathBuf,
    partial: PathBuf,
    options: LogOptions,
    mcap: Option<mcap::Writer<BufWriter<File>>>,
    /// Channel id and next sequence number per topic.
    channels: BTreeMap<Topic, (u16, u32)>,
}

impl std::fmt::Debug for LogWriter {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LogWriter")
            .field("path", &self.path)
            .field("options", &self.options)
            .finish_non_exhaustive()
    }
}

impl LogWriter {
    /// Starts `path.partial` (creating `path`'s folder if needed); `path` appears on
    /// [`Self::finish`].
    ///
    /// # Errors
    /// [`LogError::Io`] when the file cannot be created, naming it.
    pub fn create(path: &Path, options: LogOptions) -> Result<Self, LogError> {
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(|e| LogError::io(dir, "create the folder", e))?;
        }
        let partial = partial_path(path);
        let file =
            File::create(&partial).map_err(|e| LogError::io(&partial, "create the file", e))?;
        let mcap = mcap::WriteOptions::new()
            .profile("")
            .library(concat!("fleet-log/", env!("CARGO_PKG_VERSION")))
            .compression(Some(mcap::Compression::Zstd))
            // One thread: lock-step runs already go in parallel on every core.
            .compression_threads(0)
            .create(BufWriter::new(file))
            .map_err(|e| LogError::mcap(&partial, e))?;
        Ok(Self {
            path: path.to_path_buf(),
            partial,
            options,
            mcap: Some(mcap),
            channels: BTreeMap::new(),
        })
    }

    /// The file the log ends up in.
    #[must_use]
    pub fn path(&self) -> &Path {
        &self.path
    }

    #[must_use]
    pub fn options(&self) -> LogOptions {
        self.options
    }

    fn write_json<T: Serialize>(
        &mut self,
        topic: Topic,
        stamp_ns: u64,
        message: &T,
    ) -> Result<(), LogError> {
        let data = serde_json::to_vec(message).map_err(|e| LogError::Encode {
            path: self.partial.clone(),
            topic: topic.name(),
            reason: e.to_string(),
        })?;
        let partial = &self.partial;
        let mcap = self.mcap.as_mut().ok_or_else(|| LogError::Io {
            path: partial.clone(),
            action: "write",
            reason: "the log is finished".into(),
        })?;
        let (channel_id, sequence) = match self.channels.entry(topic) {
            std::collections::btree_map::Entry::Occupied(e) => e.into_mut(),
            std::collections::btree_map::Entry::Vacant(e) => {
                let schema =
                    serde_json::to_vec(&topic.schema()).map_err(|err| LogError::Encode {
                        path: partial.clone(),
                        topic: topic.name(),
                        reason: err.to_string(),
                    })?;
                let schema_id = mcap
                    .add_schema(topic.schema_name(), SCHEMA_ENCODING, &schema)
                    .map_err(|err| LogError::mcap(partial, err))?;
                let id = mcap
                    .add_channel(schema_id, topic.name(), MESSAGE_ENCODING, &BTreeMap::new())
                    .map_err(|err| LogError::mcap(partial, err))?;
                e.insert((id, 0))
            }
        };
        *sequence = sequence.wrapping_add(1);
        mcap.write_to_known_channel(
            &mcap::records::MessageHeader {
                channel_id: *channel_id,
                sequence: *sequence,
                log_time: stamp_ns,
                publish_time: stamp_ns,
            },
            &data,
        )
        .map_err(|e| LogError::mcap(partial, e))
    }

    /// `/map`: call first.
    ///
    /// # Errors
    /// [`LogError`] naming the file when it cannot be written.
    pub fn map(&mut self, info: &MapInfo) -> Result<(), LogError> {
        self.write_json(Topic::Map, info.stamp_ns, info)
    }

    /// `/agent_config`: the agent's configuration as JSON.
    ///
    /// # Errors
    /// As [`Self::map`].
    pub fn agent_config(&mut self, stamp_ns: u64, config: &impl Serialize) -> Result<(), LogError> {
        self.write_json(Topic::AgentConfig, stamp_ns, config)
    }

    /// # Errors
    /// As [`Self::map`].
    pub fn scan(&mut self, scan: &LaserScan) -> Result<(), LogError> {
        self.write_json(Topic::Scan, scan.header.stamp_ns, scan)
    }

    /// # Errors
    /// As [`Self::map`].
    pub fn odom(&mut self, odom: &Odometry) -> Result<(), LogError> {
        self.write_json(Topic::Odom, odom.header.stamp_ns, odom)
    }

    /// `/camera`, only when [`LogOptions::camera`] is set (otherwise nothing is written).
    ///
    /// # Errors
    /// As [`Self::map`], or [`LogError::Encode`] when the frame cannot be compressed.
    pub fn camera(&mut self, frame: &CameraFrame) -> Result<(), LogError> {
        if !self.options.camera {
            return Ok(());
        }
        let image =
            CompressedImage::from_frame(frame, self.options.jpeg_quality).map_err(|reason| {
                LogError::Encode {
                    path: self.partial.clone(),
                    topic: Topic::Camera.name(),
                    reason,
                }
            })?;
        self.write_json(Topic::Camera, frame.header.stamp_ns, &image)
    }

    /// `/camera` from an already compressed image (e.g. copied from another log).
    ///
    /// # Errors
    /// As [`Self::map`].
    pub fn compressed_image(&mut self, image: &CompressedImage) -> Result<(), LogError> {
        self.write_json(Topic::Camera, image.timestamp.as_ns(), image)
    }

    /// # Errors
    /// As [`Self::map`].
    pub fn amcl_pose(&mut self, pose: &PoseEstimate) -> Result<(), LogError> {
        self.write_json(Topic::AmclPose, pose.header.stamp_ns, pose)
    }

    /// `/intention` (without the LPE image's bytes, see the crate docs).
    ///
    /// # Errors
    /// As [`Self::map`].
    pub fn intention(&mut self, intention: &Intention) -> Result<(), LogError> {
        self.write_json(Topic::Intention, intention.header.stamp_ns, intention)
    }

    /// # Errors
    /// As [`Self::map`].
    pub fn cmd_vel(&mut self, cmd: &CmdVel) -> Result<(), LogError> {
        self.write_json(Topic::CmdVel, cmd.header.stamp_ns, cmd)
    }

    /// `/agent_status`: the agent's state and who drives.
    ///
    /// # Errors
    /// As [`Self::map`].
    pub fn agent_status(&mut self, status: &AgentStatus) -> Result<(), LogError> {
        self.write_json(Topic::AgentStatus, status.header.stamp_ns, status)
    }

    /// `/initialpose`: the filter was re-initialised.
    ///
    /// # Errors
    /// As [`Self::map`].
    pub fn initial_pose(&mut self, pose: &InitialPose) -> Result<(), LogError> {
        self.write_json(Topic::InitialPose, pose.header.stamp_ns, pose)
    }

    /// `/ground_truth`.
    ///
    /// # Errors
    /// As [`Self::map`].
    pub fn ground_truth(&mut self, header: Header, pose: Pose2D) -> Result<(), LogError> {
        self.write_json(
            Topic::GroundTruth,
            header.stamp_ns,
            &StampedPose { header, pose },
        )
    }

    /// `/run_summary`.
    ///
    /// # Errors
    /// As [`Self::map`].
    pub fn run_summary(&mut self, summary: &RunSummary) -> Result<(), LogError> {
        self.write_json(Topic::RunSummary, summary.stamp_ns, summary)
    }

    /// Any message of the typed enum (what [`crate::RunLog`] reads back).
    ///
    /// # Errors
    /// As [`Self::map`].
    pub fn write(&mut self, message: &LogMessage) -> Result<(), LogError> {
        match message {
            LogMessage::Map(m) => self.map(m),
            LogMessage::AgentConfig { stamp_ns, config } => self.agent_config(*stamp_ns, config),
            LogMessage::Scan(m) => self.scan(m),
            LogMessage::Odom(m) => self.odom(m),
            LogMessage::Camera(m) => self.compressed_image(m),
            LogMessage::AmclPose(m) => self.amcl_pose(m),
            LogMessage::Intention(m) => self.intention(m),
            LogMessage::CmdVel(m) => self.cmd_vel(m),
            LogMessage::AgentStatus(m) => self.agent_status(m),
            LogMessage::InitialPose(m) => self.initial_pose(m),
            LogMessage::GroundTruth(m) => self.ground_truth(m.header, m.pose),
            LogMessage::RunSummary(m) => self.run_summary(m),
        }
    }

    /// Writes the MCAP summary and footer, flushes, syncs and renames `FILE.partial` to `FILE`.
    ///
    /// # Errors
    /// [`LogError`] naming the file; `FILE.partial` is left behind then.
    pub fn finish(mut self) -> Result<PathBuf, LogError> {
        let Some(mut mcap) = self.mcap.take() else {
            return Ok(self.path.clone());
        };
        mcap.finish()
            .map_err(|e| LogError::mcap(&self.partial, e))?;
        let file = mcap
            .into_inner()
            .into_inner()
            .map_err(|e| LogError::io(&self.partial, "flush", e.error()))?;
        file.sync_all()
            .map_err(|e| LogError::io(&self.partial, "sync", e))?;
        drop(file);
        std::fs::rename(&self.partial, &self.path)
            .map_err(|e| LogError::io(&self.path, "rename the finished log to", e))?;
        Ok(self.path.clone())
    }
}
