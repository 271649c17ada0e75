//! [`RunLog`]: reads a run log back into typed messages.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use protocol::{AgentStatus, CmdVel, Intention, LaserScan, Odometry, PoseEstimate};
use serde::de::DeserializeOwned;
use serde_json::Value;

use crate::camera::CompressedImage;
use crate::topics::{InitialPose, MapInfo, RunSummary, StampedPose, Topic};
use crate::LogError;

/// One message of a run log, typed by its topic.
#[derive(Debug, Clone, PartialEq)]
pub enum LogMessage {
    Map(MapInfo),
    /// The agent's configuration, as JSON (robot-agent reads it back as its `AgentConfig`).
    AgentConfig {
        stamp_ns: u64,
        config: Value,
    },
    Scan(LaserScan),
    Odom(Odometry),
    Camera(CompressedImage),
    AmclPose(PoseEstimate),
    /// Read back with an empty `lpe.data` (logs keep no LPE pixels).
    Intention(Intention),
    CmdVel(CmdVel),
    AgentStatus(AgentStatus),
    InitialPose(InitialPose),
    GroundTruth(StampedPose),
    RunSummary(RunSummary),
}

impl LogMessage {
    #[must_use]
    pub fn topic(&self) -> Topic {
        match self {
            LogMessage::Map(_) => Topic::Map,
            LogMessage::AgentConfig { .. } => Topic::AgentConfig,
            LogMessage::Scan(_) => Topic::Scan,
            LogMessage::Odom(_) => Topic::Odom,
            LogMessage::Camera(_) => Topic::Camera,
            LogMessage::AmclPose(_) => Topic::AmclPose,
            LogMessage::Intention(_) => Topic::Intention,
            LogMessage::CmdVel(_) => Topic::CmdVel,
            LogMessage::AgentStatus(_) => Topic::AgentStatus,
            LogMessage::InitialPose(_) => Topic::InitialPose,
            LogMessage::GroundTruth(_) => Topic::GroundTruth,
            LogMessage::RunSummary(_) => Topic::RunSummary,
        }
    }

    /// The message's own stamp (what the writer uses as `log_time`).
    #[must_use]
    pub fn stamp_ns(&self) -> u64 {
        match self {
            LogMessage::Map(m) => m.stamp_ns,
            LogMessage::AgentConfig { stamp_ns, .. } => *stamp_ns,
            LogMessage::Scan(m) => m.header.stamp_ns,
            LogMessage::Odom(m) => m.header.stamp_ns,
            LogMessage::Camera(m) => m.timestamp.as_ns(),
            LogMessage::AmclPose(m) => m.header.stamp_ns,
            LogMessage::Intention(m) => m.header.stamp_ns,
            LogMessage::CmdVel(m) => m.header.stamp_ns,
            LogMessage::AgentStatus(m) => m.header.stamp_ns,
            LogMessage::InitialPose(m) => m.header.stamp_ns,
            LogMessage::GroundTruth(m) => m.header.stamp_ns,
            LogMessage::RunSummary(m) => m.stamp_ns,
        }
    }
}

/// A message with its MCAP `log_time`.
#[derive(Debug, Clone, PartialEq)]
pub struct LogEntry {
    pub log_time_ns: u64,
    pub message: LogMessage,
}

/// A whole run log in memory.
#[derive(Debug, Clone)]
pub struct RunLog {
    path: PathBuf,
    /// In file order.
    entries: Vec<LogEntry>,
    /// Messages on topics this crate does not know, by topic (skipped).
    unknown: BTreeMap<String, usize>,
}

fn decode<T: DeserializeOwned>(
    path: &Path,
    topic: Topic,
    sequence: u32,
    data: &[u8],
) -> Result<T, LogError> {
    serde_json::from_slice(data).map_err(|e| LogError::Message {
        path: path.to_path_buf(),
        topic: topic.name().into(),
        sequence,
        reason: e.to_string(),
    })
}

impl RunLog {
    /// Reads and decodes a whole log.
    ///
    /// # Errors
    /// [`LogError::NotMcap`] naming the file when it is not MCAP at all (e.g. a CSV or a
    /// `.partial` left by a crash that never wrote a byte), [`LogError::Mcap`] for a truncated
    /// or corrupt one, [`LogError::Message`] for a message that does not decode as its topic's
    /// type.
    pub fn open(path: &Path) -> Result<Self, LogError> {
        let bytes = std::fs::read(path).map_err(|e| LogError::io(path, "read", e))?;
        Self::from_bytes(path, &bytes)
    }

    /// Decodes a log held in memory; `path` names it in errors.
    ///
    /// # Errors
    /// As [`Self::open`].
    pub fn from_bytes(path: &Path, bytes: &[u8]) -> Result<Self, LogError> {
        if !bytes.starts_with(mcap::MAGIC) {
            let reason = if bytes.is_empty() {
                "the file is empty".to_string()
            } else {
                format!(
                    "{} bytes that do not start with the MCAP magic bytes \\x89MCAP0\\r\\n",
                    bytes.len()
                )
            };
            return Err(LogError::NotMcap {
                path: path.to_path_buf(),
                reason,
            });
        }
        let stream = mcap::MessageStream::new(bytes).map_err(|e| LogError::mcap(path, e))?;
        let mut entries = Vec::new();
        let mut unknown: BTreeMap<String, usize> = BTreeMap::new();
        for message in stream {
            let message = message.map_err(|e| LogError::mcap(path, e))?;
            let Some(topic) = Topic::from_name(&message.channel.topic) else {
                *unknown.entry(message.channel.topic.clone()).or_default() += 1;
                continue;
            };
            if message.channel.message_encoding != crate::MESSAGE_ENCODING {
                return Err(LogError::Message {
                    path: path.to_path_buf(),
                    topic: topic.name().into(),
                    sequence: message.sequence,
                    reason: format!(
                        "message encoding {:?}, expected {:?}",
                        message.channel.message_encoding,
                        crate::MESSAGE_ENCODING
                    ),
                });
            }
            let (seq, data) = (message.sequence, &message.data[..]);
            let typed = match topic {
                Topic::Map => LogMessage::Map(decode(path, topic, seq, data)?),
                Topic::AgentConfig => LogMessage::AgentConfig {
                    stamp_ns: message.log_time,
                    config: decode(path, topic, seq, data)?,
                },
                Topic::Scan => LogMessage::Scan(decode(path, topic, seq, data)?),
                Topic::Odom => LogMessage::Odom(decode(path, topic, seq, data)?),
                Topic::Camera => LogMessage::Camera(decode(path, topic, seq, data)?),
                Topic::AmclPose => LogMessage::AmclPose(decode(path, topic, seq, data)?),
                Topic::Intention => LogMessage::Intention(decode(path, topic, seq, data)?),
                Topic::CmdVel => LogMessage::CmdVel(decode(path, topic, seq, data)?),
                Topic::AgentStatus => LogMessage::AgentStatus(decode(path, topic, seq, data)?),
                Topic::InitialPose => LogMessage::InitialPose(decode(path, topic, seq, data)?),
                Topic::GroundTruth => LogMessage::GroundTruth(decode(path, topic, seq, data)?),
                Topic::RunSummary => LogMessage::RunSummary(decode(path, topic, seq, data)?),
            };
            entries.push(LogEntry {
                log_time_ns: message.log_time,
                message: typed,
            });
        }
        Ok(Self {
            path: path.to_path_buf(),
            entries,
            unknown,
        })
    }

    /// The file it was read from.
    #[must_use]
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Every message in time order (by `log_time`; equal stamps keep the recorded order).
    #[must_use]
    pub fn messages(&self) -> Vec<&LogEntry> {
        let mut sorted: Vec<&LogEntry> = self.entries.iter().collect();
        sorted.sort_by_key(|e| e.log_time_ns);
        sorted
    }

    /// Every message in the order it was written: the order the agent processed them, which is
    /// what a replay must follow to reproduce the agent exactly.
    #[must_use]
    pub fn as_recorded(&self) -> &[LogEntry] {
        &self.entries
    }

    /// How many messages each topic has.
    #[must_use]
    pub fn counts(&self) -> BTreeMap<Topic, usize> {
        let mut counts = BTreeMap::new();
        for e in &self.entries {
            *counts.entry(e.message.topic()).or_default() += 1;
        }
        counts
    }

    /// Messages on topics this crate does not know (skipped when reading), by topic.
    #[must_use]
    pub fn unknown_topics(&self) -> &BTreeMap<String, usize> {
        &self.unknown
    }

    /// The `/map` record (the first, if a log had several).
    #[must_use]
    pub fn map(&self) -> Option<&MapInfo> {
        self.entries.iter().find_map(|e| match &e.message {
            LogMessage::Map(m) => Some(m),
            _ => None,
        })
    }

    /// The `/agent_config` record.
    #[must_use]
    pub fn agent_config(&self) -> Option<&Value> {
        self.entries.iter().find_map(|e| match &e.message {
            LogMessage::AgentConfig { config, .. } => Some(config),
            _ => None,
        })
    }

    /// The `/run_summary` record.
    #[must_use]
    pub fn run_summary(&self) -> Option<&RunSummary> {
        self.entries.iter().find_map(|e| match &e.message {
            LogMessage::RunSummary(m) => Some(m),
            _ => None,
        })
    }

    /// The `/agent_status` records in the order written (each a change of who drives, or of
    /// the agent's state).
    #[must_use]
    pub fn agent_statuses(&self) -> Vec<&AgentStatus> {
        self.entries
            .iter()
            .filter_map(|e| match &e.message {
                LogMessage::AgentStatus(s) => Some(s),
                _ => None,
            })
            .collect()
    }

    /// The ground truth in time order.
    #[must_use]
    pub fn ground_truth(&self) -> Vec<StampedPose> {
        let mut truth: Vec<StampedPose> = self
            .entries
            .iter()
            .filter_map(|e| match &e.message {
                LogMessage::GroundTruth(t) => Some(*t),
                _ => None,
            })
            .collect();
        truth.sort_by_key(|t| t.header.stamp_ns);
        truth
    }
}
