//! Wire protocol: ids, messages, key expressions and the codec shared by every fleet process.
//!
//! Every process of the fleet (sim, robot agent, planner service, map store, eval) talks over
//! Zenoh through this crate only: ids are validated newtypes ([`ids`]), messages are plain serde
//! data with unit-suffixed fields ([`messages`]), key expressions are built and parsed in one
//! place ([`keys`]) and payloads go through one encode/decode pair with a wire version
//! ([`codec`], Zenoh glue in [`zenoh_io`]). [`data_dirs`] is where every binary finds its data
//! folders (scenarios, models, the shared reference maps) at run time.
//!
//! # Key expressions
//!
//! | key | message | producer → consumer |
//! |---|---|---|
//! | `fleet/<site>/robot/<robot_id>/scan` | [`LaserScan`] (JSON) | base / sim → agent |
//! | `fleet/<site>/robot/<robot_id>/odom` | [`Odometry`] (JSON) | base / sim → agent |
//! | `fleet/<site>/robot/<robot_id>/camera` | [`CameraFrame`] (framed) | base / sim → agent, dashboard |
//! | `fleet/<site>/robot/<robot_id>/cmd_vel` | [`CmdVel`] (JSON) | agent → base / sim |
//! | `fleet/<site>/robot/<robot_id>/pose` | [`PoseEstimate`] (JSON) | agent → planner |
//! | `fleet/<site>/robot/<robot_id>/intention` | [`Intention`] (framed) | planner → agent |
//! | `fleet/<site>/robot/<robot_id>/status` | [`AgentStatus`] (JSON) | agent → planner |
//! | `fleet/<site>/robot/<robot_id>/alive` | liveliness token | agent → planner |
//! | `fleet/<site>/map/<name>` | queryable: latest [`MapGrid`] / [`MapMeta`] | map store → agents |
//! | `fleet/<site>/map/<name>/<version>` | queryable: that version | map store → agents |
//! | `fleet/<site>/task/<task_id>` | [`TaskEvent`] (JSON) | planner → dashboard, eval |
//! | `fleet/<site>/worker/<worker_id>/alive` | liveliness token | worker → planner, workers |
//! | `fleet/<site>/cycle/<robot_id>` | queryable: what a replanning cycle is to do | worker → planner |
//! | `fleet/<site>/cycle/<robot_id>/outcome` | how that cycle ended | worker → planner |
//!
//! Wildcards: [`keys::all_robots`] (`fleet/<site>/robot/*/<topic>`), [`keys::alive_all`],
//! [`keys::map_queryable`] (`fleet/<site>/map/**`), [`keys::all_tasks`], [`keys::site_all`].
//! Ids are 1..=64 characters of `[A-Za-z0-9_.-]` not starting with `.` (map names at most 51), so
//! every id is exactly one key chunk and the builders cannot fail.
//!
//! # Wire format (version [`WIRE_VERSION`] = 1)
//!
//! * JSON kinds (`scan`, `odom`, `cmd_vel`, `pose`, `status`, `task_event`, `map_meta`):
//!   `{"wire_version":1,"kind":"pose","msg":{…}}`, Zenoh encoding `application/json`.
//! * Framed kinds (`camera`, `intention`, `map_grid`): `IFLT` magic, u16 LE wire version,
//!   u32 LE header length `H`, `H` bytes of JSON envelope
//!   `{"wire_version":1,"kind":…,"blob_len":N,"msg":{…}}` without the blob fields, then the `N`
//!   raw blob bytes (camera image data, LPE image data or nothing, map cells). Zenoh encoding
//!   `application/octet-stream;intention-fleet/<kind>`.
//!
//! A receiver rejects an unknown wire version with [`DecodeError::UnsupportedVersion`], which
//! names both versions; messages are validated on encode and on decode.
//!
//! # Example
//!
//! ```
//! use protocol::{decode, encode, keys, CmdVel, Header, RobotId, RobotTopic, SiteId};
//!
//! let site: SiteId = "hq".parse()?;
//! let robot: RobotId = "robot_1".parse()?;
//! assert_eq!(keys::robot(&site, &robot, RobotTopic::CmdVel).as_str(), "fleet/hq/robot/robot_1/cmd_vel");
//!
//! let cmd = CmdVel { header: Header::new(1, 1_000), v_mps: 0.5, omega_radps: -0.2 };
//! let bytes = encode(&cmd)?;
//! assert!(std::str::from_utf8(&bytes)?.starts_with(r#"{"wire_version":1,"kind":"cmd_vel","msg":{"#));
//! assert_eq!(decode::<CmdVel>(&bytes)?, cmd);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! # Security
//!
//! [`security`]: each process's certificate from the site's CA (mutual TLS) and Zenoh access
//! control binding each identity to the keys of the table above that it may publish or read.
//!
//! # Conventions
//!
//! SI units with the unit in the field name (`_m`, `_mps`, `_radps`, `_rad`, `_ns`, `_ms`, `_px`),
//! angles in radians, REP-103 frames (map frame, x forward, y left, yaw counter-clockwise), every
//! streamed message has a [`Header`] with a sequence number and a monotonic ns stamp.

pub mod codec;
pub mod data_dirs;
pub mod ids;
pub mod keys;
pub mod lpe;
pub mod messages;
pub mod security;
pub mod shutdown;
#[cfg(feature = "cli")]
pub mod telemetry;
pub mod zenoh_io;

pub use codec::{decode, encode, DecodeError, EncodeError, WireMessage, WIRE_VERSION};
pub use ids::{IdError, IdRejection, MapId, MapName, RobotId, SiteId, TaskId, WorkerId};
pub use keys::RobotTopic;
pub use lpe::{LpeParams, LpeParamsError};
pub use messages::{
    normalize_angle, position_std_m, AgentState, AgentStatus, CameraFrame, CmdVel, ControllerKind,
    Dlm, Header, Image, ImageEncoding, Intention, LaserScan, MapGrid, MapMeta, MapRef, Odometry,
    Pose2D, PoseEstimate, PoseParseError, StopReason, TaskEvent, TaskState, UnknownController,
    ValidationError, MAX_UNMAPPED_OBSTACLES, UNKNOWN_CELL,
};
pub use zenoh_io::{
    decode_sample, encoding_for, loopback_pair, peer_config, PublishError, SessionArgs,
    SessionError, SessionMode,
};
