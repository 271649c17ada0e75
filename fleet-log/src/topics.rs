//! The topics of a run log, the log-only message types and the JSON schema of every channel.
//!
//! The schemas describe the serde form of the messages (the same JSON the wire codec carries in
//! its `msg` field); a test validates real messages against them, so a field added to a message
//! without its schema fails there.

use protocol::{Header, Pose2D};
use serde::{Deserialize, Serialize};
use serde_json::{json, Value};

/// MCAP message encoding of every channel.
pub const MESSAGE_ENCODING: &str = "json";
/// MCAP schema encoding of every channel.
pub const SCHEMA_ENCODING: &str = "jsonschema";

/// One channel of a run log.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Topic {
    Map,
    AgentConfig,
    Scan,
    Odom,
    Camera,
    AmclPose,
    Intention,
    CmdVel,
    AgentStatus,
    InitialPose,
    GroundTruth,
    RunSummary,
}

impl Topic {
    pub const ALL: [Topic; 12] = [
        Topic::Map,
        Topic::AgentConfig,
        Topic::Scan,
        Topic::Odom,
        Topic::Camera,
        Topic::AmclPose,
        Topic::Intention,
        Topic::CmdVel,
        Topic::AgentStatus,
        Topic::InitialPose,
        Topic::GroundTruth,
        Topic::RunSummary,
    ];

    /// The MCAP topic name.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Topic::Map => "/map",
            Topic::AgentConfig => "/agent_config",
            Topic::Scan => "/scan",
            Topic::Odom => "/odom",
            Topic::Camera => "/camera",
            Topic::AmclPose => "/amcl_pose",
            Topic::Intention => "/intention",
            Topic::CmdVel => "/cmd_vel",
            Topic::AgentStatus => "/agent_status",
            Topic::InitialPose => "/initialpose",
            Topic::GroundTruth => "/ground_truth",
            Topic::RunSummary => "/run_summary",
        }
    }

    /// The topic of an MCAP topic name.
    #[must_use]
    pub fn from_name(name: &str) -> Option<Topic> {
        Topic::ALL.into_iter().find(|t| t.name() == name)
    }

    /// The schema's name (the message type Foxglove shows).
    #[must_use]
    pub fn schema_name(self) -> &'static str {
        match self {
            Topic::Map => "fleet.MapInfo",
            Topic::AgentConfig => "fleet.AgentConfig",
            Topic::Scan => "fleet.LaserScan",
            Topic::Odom => "fleet.Odometry",
            Topic::Camera => "foxglove.CompressedImage",
            Topic::AmclPose => "fleet.PoseEstimate",
            Topic::Intention => "fleet.Intention",
            Topic::CmdVel => "fleet.CmdVel",
            Topic::AgentStatus => "fleet.AgentStatus",
            Topic::InitialPose => "fleet.InitialPose",
            Topic::GroundTruth => "fleet.StampedPose",
            Topic::RunSummary => "fleet.RunSummary",
        }
    }

    /// The JSON schema of the channel's messages.
    #[must_use]
    #[allow(clippy::too_many_lines)]
    pub fn schema(self) -> Value {
        let header = json!({
            "type": "object",
            "properties": {
                "seq": {"type": "integer", "minimum": 0},
                "stamp_ns": {"type": "integer", "minimum": 0, "description": "ns; the simulated clock in lock-step runs"}
            },
            "required": ["seq", "stamp_ns"]
        });
        let pose = json!({
            "type": "object",
            "properties": {
                "x_m": {"type": "number"},
                "y_m": {"type": "number"},
                "yaw_rad": {"type": "number"}
            },
            "required": ["x_m", "y_m", "yaw_rad"]
        });
        let covariance = json!({
            "type": "array", "items": {"type": "number"}, "minItems": 9, "maxItems": 9,
            "description": "3x3 row-major over x_m, y_m, yaw_rad"
        });
        let map_ref = json!({
            "type": "object",
            "properties": {"name": {"type": "string"}, "version": {"type": "integer", "minimum": 0}},
            "required": ["name", "version"]
        });
        let body = match self {
            Topic::Map => json!({
                "type": "object",
                "description": "The floor plan the run localized on and where the filter started",
                "properties": {
                    "stamp_ns": {"type": "integer", "minimum": 0},
                    "name": {"type": "string"},
                    "version": {"type": "integer", "minimum": 0},
                    "path": {"type": ["string", "null"]},
                    "content_hash": {"type": ["string", "null"], "description": "hex sha256 as the map store computes it"},
                    "initial_pose": {"oneOf": [pose, {"type": "null"}], "description": "null: global localization"},
                    "initial_covariance": {"oneOf": [covariance, {"type": "null"}]},
                    "source": {"type": "string"}
                },
                "required": ["stamp_ns", "name", "version", "source"]
            }),
            Topic::AgentConfig => json!({
                "type": "object",
                "description": "The robot agent's configuration (robot-agent/agent.example.toml) as JSON"
            }),
            Topic::Scan => json!({
                "type": "object",
                "properties": {
                    "header": header,
                    "angle_min_rad": {"type": "number"},
                    "angle_increment_rad": {"type": "number"},
                    "range_min_m": {"type": "number"},
                    "range_max_m": {"type": "number"},
                    "ranges_m": {"type": "array", "items": {"type": "number"}, "description": "range_max_m: no return"}
                },
                "required": ["header", "angle_min_rad", "angle_increment_rad", "range_min_m", "range_max_m", "ranges_m"]
            }),
            Topic::Odom => json!({
                "type": "object",
                "properties": {
                    "header": header,
                    "pose": pose,
                    "v_mps": {"type": "number"},
                    "omega_radps": {"type": "number"}
                },
                "required": ["header", "pose", "v_mps", "omega_radps"]
            }),
            Topic::Camera => json!({
                "type": "object",
                "description": "foxglove.CompressedImage",
                "properties": {
                    "timestamp": {
                        "type": "object",
                        "properties": {"sec": {"type": "integer", "minimum": 0}, "nsec": {"type": "integer", "minimum": 0}},
                        "required": ["sec", "nsec"]
                    },
                    "frame_id": {"type": "string"},
                    "data": {"type": "string", "contentEncoding": "base64"},
                    "format": {"type": "string", "enum": ["jpeg", "png"]}
                },
                "required": ["timestamp", "frame_id", "data", "format"]
            }),
            Topic::AmclPose => json!({
                "type": "object",
                "properties": {
                    "header": header,
                    "pose": pose,
                    "covariance": covariance,
                    "sensor_stamp_ns": {"type": "integer", "minimum": 0},
                    "map": map_ref
                },
                "required": ["header", "pose", "covariance", "sensor_stamp_ns", "map"]
            }),
            Topic::Intention => json!({
                "type": "object",
                "description": "The planner's answer to one pose; lpe carries no pixels in a log",
                "properties": {
                    "header": header,
                    "task_id": {"type": ["string", "null"]},
                    "goal_index": {"type": "integer", "minimum": 0},
                    "answers_pose_seq": {"type": "integer", "minimum": 0},
                    "answers_pose_stamp_ns": {"type": "integer", "minimum": 0},
                    "map": map_ref,
                    "path": {"type": "array", "items": pose},
                    "dlm": {"type": "string", "enum": ["turn_left", "turn_right", "go_forward", "stop"]},
                    "lpe": {"oneOf": [{"type": "null"}, {
                        "type": "object",
                        "properties": {
                            "width_px": {"type": "integer", "minimum": 0},
                            "height_px": {"type": "integer", "minimum": 0},
                            "encoding": {"type": "string", "enum": ["rgb8", "png", "jpeg"]}
                        },
                        "required": ["width_px", "height_px", "encoding"]
                    }]}
                },
                "required": ["header", "goal_index", "answers_pose_seq", "answers_pose_stamp_ns", "map", "path", "dlm"]
            }),
            Topic::CmdVel => json!({
                "type": "object",
                "properties": {
                    "header": header,
                    "v_mps": {"type": "number"},
                    "omega_radps": {"type": "number"}
                },
                "required": ["header", "v_mps", "omega_radps"]
            }),
            Topic::AgentStatus => json!({
                "type": "object",
                "description": "The agent's state, and who drives: the configured controller, or the dynamic window recovering, the rotation shim or the give-way rule in its place",
                "properties": {
                    "header": header,
                    "state": {"type": "string", "enum": ["starting", "idle", "driving", "stopping", "stopped", "relocalizing"]},
                    "stop_reason": {"oneOf": [{"type": "null"}, {
                        "type": "object",
                        "properties": {"kind": {"type": "string", "enum": [
                            "no_intention", "stale_intention", "localization_lost", "controller_error",
                            "goal_reached", "collision", "commanded"
                        ]}},
                        "required": ["kind"]
                    }]},
                    "controller": {"type": "string", "enum": ["dlm", "lpe", "none", "path-tracker", "dynamic-window", "expert"]},
                    "map": {"oneOf": [{"type": "null"}, map_ref]},
                    "localized": {"type": "boolean"},
                    "recovering": {"type": "boolean", "description": "the agent's recovery drives in the controller's place: the dynamic window, or backing straight off from someone met face to face"},
                    "backing_up": {"type": "boolean", "description": "of recovering: backing straight off from someone met face to face"},
                    "rotating_in_place": {"type": "boolean"},
                    "giving_way": {"type": "boolean"}
                },
                "required": ["header", "state", "stop_reason", "controller", "map", "localized"]
            }),
            Topic::InitialPose => json!({
                "type": "object",
                "description": "The filter was re-initialised here (e.g. after the robot was carried)",
                "properties": {"header": header, "pose": pose, "covariance": covariance},
                "required": ["header", "pose", "covariance"]
            }),
            Topic::GroundTruth => json!({
                "type": "object",
                "description": "The true map-frame pose (simulator only)",
                "properties": {"header": header, "pose": pose},
                "required": ["header", "pose"]
            }),
            Topic::RunSummary => json!({
                "type": "object",
                "properties": {
                    "stamp_ns": {"type": "integer", "minimum": 0},
                    "scenario": {"type": "string"},
                    "method": {"type": "string"},
                    "seed": {"type": "integer", "minimum": 0},
                    "success": {"type": "boolean"},
                    "goals_reached": {"type": "integer", "minimum": 0},
                    "goals_total": {"type": "integer", "minimum": 0},
                    "collisions": {"type": "integer", "minimum": 0},
                    "interventions": {"type": "integer", "minimum": 0},
                    "time_s": {"type": "number"}
                },
                "required": ["stamp_ns", "scenario", "method", "seed", "success", "goals_reached", "goals_total", "collisions", "interventions", "time_s"]
            }),
        };
        let mut schema = body;
        if let Some(object) = schema.as_object_mut() {
            object.insert(
                "$schema".into(),
                json!("https://json-schema.org/draft/2020-12/schema"),
            );
            object.insert("title".into(), json!(self.schema_name()));
        }
        schema
    }
}

impl std::fmt::Display for Topic {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// The floor plan a run localized on and where its filter started (`/map`, first in a log).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MapInfo {
    /// When the run started (the first stamp of the log).
    pub stamp_ns: u64,
    /// The map's name (the map store's name, or the floor plan file's stem).
    pub name: String,
    pub version: u32,
    /// The floor plan file (ROS map YAML) when the recorder loaded one.
    pub path: Option<String>,
    /// Hex sha256 of the grid (`map_core::OccupancyGrid::content_hash`), as the map store names versions.
    pub content_hash: Option<String>,
    /// The pose the filter was initialised at; `None`: global localization.
    pub initial_pose: Option<Pose2D>,
    /// Its covariance (3x3 row-major over x, y, yaw), when known.
    pub initial_covariance: Option<[f64; 9]>,
    /// Who wrote the log: `robot-agent`, `eval` or `sim`.
    pub source: String,
}

/// A pose with its stamp (`/ground_truth`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StampedPose {
    pub header: Header,
    pub pose: Pose2D,
}

/// A re-initialisation of the localizer (`/initialpose`): after it the filter starts afresh
/// at `pose` with `covariance`, as RViz's "2D pose estimate" or the operator who carried the
/// robot sets it. The first initialisation of a run is [`MapInfo::initial_pose`], not this.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct InitialPose {
    pub header: Header,
    pub pose: Pose2D,
    /// 3x3 row-major over x, y, yaw.
    pub covariance: [f64; 9],
}

/// How a lock-step run ended (`/run_summary`, last in an `eval` log).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunSummary {
    pub stamp_ns: u64,
    pub scenario: String,
    pub method: String,
    pub seed: u64,
    pub success: bool,
    pub goals_reached: usize,
    pub goals_total: usize,
    pub collisions: u32,
    pub interventions: u32,
    /// Simulated seconds until the last goal was reached (or the run ended).
    pub time_s: f64,
}
