//! The messages that travel between fleet processes, as plain serde data.
//!
//! Field names carry their units (`_m`, `_mps`, `_radps`, `_rad`, `_ns`, `_ms`, `_px`) because the
//! JSON form is read by other languages and by humans. Angles are radians; poses follow REP-103
//! (x forward, y left, yaw counter-clockwise). Byte blobs (camera images, LPE images, map cells)
//! are `#[serde(skip)]`: the codec carries them as raw bytes after the JSON header, never inside
//! JSON.
//!
//! Each message also has a `validate` method that the codec calls on both encode and decode, so an
//! inconsistent message (an RGB buffer of the wrong size, a NaN that JSON would turn into `null`)
//! is refused at the sender and never accepted at a receiver.

use std::f64::consts::{PI, TAU};
use std::fmt;

use serde::{Deserialize, Serialize};

use crate::ids::{MapId, MapName, RobotId, TaskId};

/// A message field that breaks an invariant, found by a `validate` method.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("invalid {field}: {reason}")]
pub struct ValidationError {
    /// Dotted path of the field, e.g. `"image.data"`.
    pub field: &'static str,
    pub reason: String,
}

impl ValidationError {
    pub fn new(field: &'static str, reason: impl Into<String>) -> Self {
        Self {
            field,
            reason: reason.into(),
        }
    }
}

/// JSON has no NaN or infinity (serde_json writes `null`), so such values must never be encoded.
fn check_finite(field: &'static str, value: f64) -> Result<(), ValidationError> {
    if value.is_finite() {
        Ok(())
    } else {
        Err(ValidationError::new(
            field,
            format!("{value} is not a finite number"),
        ))
    }
}

/// Sequence number and time stamp carried by every streamed message.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Header {
    /// Per-publisher counter, increasing by one per message; gaps mean loss.
    pub seq: u64,
    /// Monotonic time in ns (the sim clock in lock-step mode).
    pub stamp_ns: u64,
}

impl Header {
    pub fn new(seq: u64, stamp_ns: u64) -> Self {
        Self { seq, stamp_ns }
    }
}

/// Wraps an angle into (-pi, pi].
pub fn normalize_angle(rad: f64) -> f64 {
    // `%` keeps the sign of the dividend, so one correction step lands in (-pi, pi].
    let a = rad % TAU;
    if a <= -PI {
        a + TAU
    } else if a > PI {
        a - TAU
    } else {
        a
    }
}

/// A planar pose; which frame it is in is said by the field holding it.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Pose2D {
    pub x_m: f64,
    pub y_m: f64,
    /// Counter-clockwise from the frame's x axis.
    pub yaw_rad: f64,
}

impl Pose2D {
    pub fn new(x_m: f64, y_m: f64, yaw_rad: f64) -> Self {
        Self { x_m, y_m, yaw_rad }
    }

    /// Euclidean distance between the positions, ignoring yaw.
    pub fn distance_m(&self, other: &Pose2D) -> f64 {
        (self.x_m - other.x_m).hypot(self.y_m - other.y_m)
    }

    /// Squared distance between the positions: for finding the nearest pose of a path, which
    /// every replanning cycle does, without a square root per pose.
    pub fn distance_sq_m2(&self, other: &Pose2D) -> f64 {
        let (dx, dy) = (self.x_m - other.x_m, self.y_m - other.y_m);
        dx * dx + dy * dy
    }

    pub fn validate(&self, field: &'static str) -> Result<(), ValidationError> {
        for v in [self.x_m, self.y_m, self.yaw_rad] {
            check_finite(field, v)?;
        }
        Ok(())
    }
}

/// Text that is not a pose `x,y,yaw`; the message quotes the input.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum PoseParseError {
    #[error(
        "invalid pose {input:?}: expected x,y,yaw (metres, metres, radians; three \
         comma-separated numbers), got {parts} part(s)"
    )]
    Parts { input: String, parts: usize },
    #[error("invalid pose {input:?}: {component} = {value:?} is not a finite number")]
    NotFinite {
        input: String,
        /// `x`, `y` or `yaw`.
        component: &'static str,
        value: String,
    },
}

/// Parses `x,y,yaw` in metres, metres and radians, e.g. `"2.5,-1,1.57"`; spaces around the
/// numbers are allowed. Every command line that takes a pose (`--start`, `--goal`, `--pose`,
/// `--initial-pose`) parses it with this, through clap's `FromStr` support.
impl std::str::FromStr for Pose2D {
    type Err = PoseParseError;

    fn from_str(input: &str) -> Result<Self, Self::Err> {
        let parts: Vec<&str> = input.split(',').map(str::trim).collect();
        let [x, y, yaw] = parts.as_slice() else {
            return Err(PoseParseError::Parts {
                input: input.to_string(),
                parts: parts.len(),
            });
        };
        let number = |component: &'static str, value: &str| {
            value
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| PoseParseError::NotFinite {
                    input: input.to_string(),
                    component,
                    value: value.to_string(),
                })
        };
        Ok(Pose2D::new(
            number("x", x)?,
            number("y", y)?,
            number("yaw", yaw)?,
        ))
    }
}

/// One sweep of a planar LIDAR, in the robot frame.
///
/// Beam `i` points at `angle_min_rad + i * angle_increment_rad`. A range `>= range_max_m` means
/// "no return" (senders write exactly `range_max_m`; JSON cannot carry infinity). Ranges below
/// `range_min_m` are too close to measure and should be treated as unreliable.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LaserScan {
    pub header: Header,
    pub angle_min_rad: f32,
    pub angle_increment_rad: f32,
    pub range_min_m: f32,
    pub range_max_m: f32,
    pub ranges_m: Vec<f32>,
}

impl LaserScan {
    /// Angle of beam `i` in the robot frame.
    pub fn beam_angle_rad(&self, i: usize) -> f32 {
        self.angle_min_rad + i as f32 * self.angle_increment_rad
    }

    /// Whether beam `i` hit something within the sensor's range (false for out-of-bounds `i`).
    pub fn is_return(&self, i: usize) -> bool {
        self.ranges_m
            .get(i)
            .is_some_and(|&r| r >= self.range_min_m && r < self.range_max_m)
    }

    pub fn validate(&self) -> Result<(), ValidationError> {
        for (field, v) in [
            ("angle_min_rad", self.angle_min_rad),
            ("angle_increment_rad", self.angle_increment_rad),
            ("range_min_m", self.range_min_m),
            ("range_max_m", self.range_max_m),
        ] {
            check_finite(field, f64::from(v))?;
        }
        if !(self.range_min_m >= 0.0 && self.range_min_m < self.range_max_m) {
            return Err(ValidationError::new(
                "range_max_m",
                format!(
                    "need 0 <= range_min_m < range_max_m, got {} and {}",
                    self.range_min_m, self.range_max_m
                ),
            ));
        }
        if let Some((i, r)) = self
            .ranges_m
            .iter()
            .enumerate()
            .find(|(_, r)| !r.is_finite() || **r < 0.0)
        {
            return Err(ValidationError::new(
                "ranges_m",
                format!("beam {i} has range {r}; write range_max_m for no return"),
            ));
        }
        Ok(())
    }
}

/// Wheel odometry: pose in the `odom` frame (drifts) and the measured body velocity.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Odometry {
    pub header: Header,
    /// In the odom frame, not the map frame.
    pub pose: Pose2D,
    pub v_mps: f64,
    pub omega_radps: f64,
}

impl Odometry {
    pub fn validate(&self) -> Result<(), ValidationError> {
        self.pose.validate("pose")?;
        check_finite("v_mps", self.v_mps)?;
        check_finite("omega_radps", self.omega_radps)
    }
}

/// Velocity command for a differential-drive base (forward speed and CCW turn rate).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CmdVel {
    pub header: Header,
    pub v_mps: f64,
    pub omega_radps: f64,
}

impl CmdVel {
    pub fn validate(&self) -> Result<(), ValidationError> {
        check_finite("v_mps", self.v_mps)?;
        check_finite("omega_radps", self.omega_radps)
    }
}

/// Which version of which floor plan a pose or intention refers to.
#[derive(Debug, Clone, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MapRef {
    pub name: MapName,
    pub version: u32,
}

/// The agent's localization result (AMCL) in the map frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PoseEstimate {
    pub header: Header,
    /// In the map frame.
    pub pose: Pose2D,
    /// 3x3 row-major covariance over (x_m, y_m, yaw_rad).
    pub covariance: [f64; 9],
    /// Stamp of the scan/odometry the estimate was computed from (the planner measures latency
    /// against it).
    pub sensor_stamp_ns: u64,
    pub map: MapRef,
    /// Obstacles the robot's laser sees standing where the floor plan is free (a cabinet, a
    /// parked robot), as map-frame points `[x_m, y_m]`, seen from this pose: the planner routes
    /// round them as Nav2's global costmap routes round its obstacle layer. Empty when the agent
    /// reports none (or is older than the field).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub unmapped_obstacles_m: Vec<[f64; 2]>,
}

/// Position uncertainty of a 3x3 row-major covariance over (x_m, y_m, yaw_rad): the square root
/// of the largest eigenvalue of its xy block, the standard deviation along the worst direction.
#[must_use]
pub fn position_std_m(covariance: &[f64; 9]) -> f64 {
    let c = covariance;
    let (a, d) = (c[0], c[4]);
    // Symmetrize: a covariance should be symmetric, but do not trust rounding of the sender.
    let b = 0.5 * (c[1] + c[3]);
    let mean = 0.5 * (a + d);
    let half_diff = 0.5 * (a - d);
    let max_eig = mean + half_diff.hypot(b);
    max_eig.max(0.0).sqrt()
}

/// Most points one [`PoseEstimate`] may carry in `unmapped_obstacles_m`.
pub const MAX_UNMAPPED_OBSTACLES: usize = 256;

impl PoseEstimate {
    /// Position uncertainty: the square root of the largest eigenvalue of the xy covariance block,
    /// i.e. the standard deviation along the worst direction (conservative for "am I lost?").
    pub fn position_std_m(&self) -> f64 {
        position_std_m(&self.covariance)
    }

    /// Heading standard deviation: `sqrt(cov[yaw, yaw])`.
    pub fn yaw_std_rad(&self) -> f64 {
        self.covariance[8].max(0.0).sqrt()
    }

    pub fn validate(&self) -> Result<(), ValidationError> {
        self.pose.validate("pose")?;
        for v in self.covariance {
            check_finite("covariance", v)?;
        }
        if self.unmapped_obstacles_m.len() > MAX_UNMAPPED_OBSTACLES {
            return Err(ValidationError::new(
                "unmapped_obstacles_m",
                format!(
                    "{} points, at most {MAX_UNMAPPED_OBSTACLES}",
                    self.unmapped_obstacles_m.len()
                ),
            ));
        }
        for v in self.unmapped_obstacles_m.iter().flatten() {
            check_finite("unmapped_obstacles_m", *v)?;
        }
        Ok(())
    }
}

/// Discretized local move (paper §3.1): the DLM intention.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Dlm {
    TurnLeft,
    TurnRight,
    GoForward,
    Stop,
}

impl Dlm {
    /// All values in one-hot index order.
    pub const ALL: [Dlm; 4] = [Dlm::TurnLeft, Dlm::TurnRight, Dlm::GoForward, Dlm::Stop];

    /// Position in the network's one-hot input; fixed by the ONNX contract.
    pub fn index(self) -> usize {
        match self {
            Dlm::TurnLeft => 0,
            Dlm::TurnRight => 1,
            Dlm::GoForward => 2,
            Dlm::Stop => 3,
        }
    }

    pub fn from_index(index: usize) -> Option<Dlm> {
        Self::ALL.get(index).copied()
    }

    pub fn one_hot(self) -> [f32; 4] {
        let mut v = [0.0; 4];
        v[self.index()] = 1.0;
        v
    }

    pub fn as_str(self) -> &'static str {
        match self {
            Dlm::TurnLeft => "turn_left",
            Dlm::TurnRight => "turn_right",
            Dlm::GoForward => "go_forward",
            Dlm::Stop => "stop",
        }
    }
}

impl fmt::Display for Dlm {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// How an [`Image`]'s bytes are to be read.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ImageEncoding {
    /// Uncompressed, row-major from the top-left, 3 bytes (R, G, B) per pixel, no padding.
    Rgb8,
    Png,
    Jpeg,
}

impl ImageEncoding {
    /// MIME type; raw RGB8 has no registered one, so a vendor-style `image/x-rgb8` is used.
    pub fn mime(self) -> &'static str {
        match self {
            ImageEncoding::Rgb8 => "image/x-rgb8",
            ImageEncoding::Png => "image/png",
            ImageEncoding::Jpeg => "image/jpeg",
        }
    }
}

const PNG_SIGNATURE: [u8; 8] = [0x89, b'P', b'N', b'G', b'\r', b'\n', 0x1a, b'\n'];
const JPEG_SOI: [u8; 3] = [0xff, 0xd8, 0xff];

/// An image with its pixel size and encoding.
///
/// `data` is not part of the serde form: the codec sends it as a raw blob after the JSON header.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Image {
    pub width_px: u32,
    pub height_px: u32,
    pub encoding: ImageEncoding,
    #[serde(skip)]
    pub data: Vec<u8>,
}

impl Image {
    /// Builds and validates an image.
    pub fn new(
        width_px: u32,
        height_px: u32,
        encoding: ImageEncoding,
        data: Vec<u8>,
    ) -> Result<Self, ValidationError> {
        let image = Self {
            width_px,
            height_px,
            encoding,
            data,
        };
        image.validate()?;
        Ok(image)
    }

    /// Byte length of an RGB8 image of this size (None if it overflows usize).
    pub fn rgb8_len(width_px: u32, height_px: u32) -> Option<usize> {
        (width_px as usize)
            .checked_mul(height_px as usize)?
            .checked_mul(3)
    }

    /// Checks the size is non-zero and the bytes match the encoding (exact length for RGB8, the
    /// format signature for PNG/JPEG; compressed content is not decoded here).
    pub fn validate(&self) -> Result<(), ValidationError> {
        if self.width_px == 0 || self.height_px == 0 {
            return Err(ValidationError::new(
                "image.size",
                format!("{}x{} px has no pixels", self.width_px, self.height_px),
            ));
        }
        match self.encoding {
            ImageEncoding::Rgb8 => {
                let expected = Self::rgb8_len(self.width_px, self.height_px);
                if expected != Some(self.data.len()) {
                    return Err(ValidationError::new(
                        "image.data",
                        format!(
                            "rgb8 {}x{} px needs {} bytes, got {}",
                            self.width_px,
                            self.height_px,
                            expected.map_or_else(|| "too many".to_string(), |n| n.to_string()),
                            self.data.len()
                        ),
                    ));
                }
            }
            ImageEncoding::Png if !self.data.starts_with(&PNG_SIGNATURE) => {
                return Err(ValidationError::new(
                    "image.data",
                    format!("not PNG data ({} bytes, no PNG signature)", self.data.len()),
                ));
            }
            ImageEncoding::Jpeg if !self.data.starts_with(&JPEG_SOI) => {
                return Err(ValidationError::new(
                    "image.data",
                    format!(
                        "not JPEG data ({} bytes, no JPEG SOI marker)",
                        self.data.len()
                    ),
                ));
            }
            ImageEncoding::Png | ImageEncoding::Jpeg => {}
        }
        Ok(())
    }
}

/// One frame of the robot's monocular camera.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraFrame {
    pub header: Header,
    pub image: Image,
}

/// What the planner tells a robot to do next (paper §3.1), answering one pose estimate.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Intention {
    pub header: Header,
    /// None while the robot has no task (the intention is then `Stop`).
    pub task_id: Option<TaskId>,
    /// Index of the goal in the task's goal sequence that this path leads to.
    pub goal_index: u32,
    /// `header.seq` of the [`PoseEstimate`] this intention was planned from.
    pub answers_pose_seq: u64,
    /// `header.stamp_ns` of that pose estimate.
    pub answers_pose_stamp_ns: u64,
    pub map: MapRef,
    /// Planned path in the map frame, from the robot towards the goal.
    pub path: Vec<Pose2D>,
    pub dlm: Dlm,
    /// The goal is within the planner's `dlm.arrive_distance_m` and no turn is left before
    /// it: `dlm` is [`Dlm::Stop`], the network's "arriving" input, but the robot drives on to
    /// the goal (the planner moves to the next goal within its tolerance). A `Stop` that is
    /// not arriving means rest. Absent (false) from planners without an arrive distance.
    #[serde(default)]
    pub arriving: bool,
    /// Local path and environment image (224x224 RGB in DESIGN §4), when the planner renders one.
    pub lpe: Option<Image>,
}

impl Intention {
    /// Whether the robot is to rest: no task, or a `Stop` that is not [`Intention::arriving`].
    #[must_use]
    pub fn rests(&self) -> bool {
        self.task_id.is_none() || self.stops()
    }

    /// Whether the robot is to come to a stop where it is: a `Stop` that is not
    /// [`Intention::arriving`].
    #[must_use]
    pub fn stops(&self) -> bool {
        self.dlm == Dlm::Stop && !self.arriving
    }

    pub fn validate(&self) -> Result<(), ValidationError> {
        for pose in &self.path {
            pose.validate("path")?;
        }
        match &self.lpe {
            Some(image) => image.validate(),
            None => Ok(()),
        }
    }
}

/// The agent's driving state.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum AgentState {
    Starting,
    Idle,
    Driving,
    /// Slowing down to a stop; `stop_reason` says why.
    Stopping,
    Stopped,
    /// Localization is lost (`stop_reason` says so): turning in place, not driving, while the
    /// localizer searches the map for the robot.
    Relocalizing,
}

/// Why an agent is stopping or stopped.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum StopReason {
    NoIntention,
    StaleIntention { age_ms: u64 },
    LocalizationLost { position_std_m: f64 },
    ControllerError { message: String },
    GoalReached,
    Collision,
    Commanded,
}

impl fmt::Display for StopReason {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            StopReason::NoIntention => f.write_str("no intention received from the planner"),
            StopReason::StaleIntention { age_ms } => {
                write!(f, "newest intention is stale ({age_ms} ms old)")
            }
            StopReason::LocalizationLost { position_std_m } => write!(
                f,
                "localization lost (position uncertainty {position_std_m:.2} m)"
            ),
            StopReason::ControllerError { message } => write!(f, "controller error: {message}"),
            StopReason::GoalReached => f.write_str("goal reached"),
            StopReason::Collision => f.write_str("collision"),
            StopReason::Commanded => f.write_str("commanded to stop"),
        }
    }
}

/// Which controller turns observations and intentions into (v, ω).
///
/// The same names in the agent's configuration, on its command line and in its `AgentStatus`
/// (`dlm`, `lpe`, `none`, `path-tracker`, `dynamic-window`); statuses of agents from before
/// the kind was typed (`dlm_net`, `lpe_net`, …) still decode.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ControllerKind {
    /// Intention-net with the discretized-local-move intention (ONNX model).
    #[serde(alias = "dlm_net")]
    Dlm,
    /// Intention-net with the local-path-and-environment image (ONNX model).
    #[serde(alias = "lpe_net")]
    Lpe,
    /// Camera-only network, the paper's Non-Intention Net ablation (ONNX model).
    #[serde(alias = "non_intention_net")]
    None,
    /// Pure pursuit on the planned path, no camera.
    #[serde(alias = "path_tracker")]
    PathTracker,
    /// Dynamic window approach on the laser scan and the planned path.
    #[serde(alias = "dynamic_window")]
    DynamicWindow,
    /// The privileged demonstrator of the evaluation and recording harness (`eval`): it reads
    /// the simulator's ground truth (true pose, every obstacle, people's velocities), so no
    /// deployed agent can run it; an agent configuration naming it is refused.
    Expert,
}

impl ControllerKind {
    /// Every kind, in the order the command line lists them.
    pub const ALL: [ControllerKind; 6] = [
        Self::Dlm,
        Self::Lpe,
        Self::None,
        Self::PathTracker,
        Self::DynamicWindow,
        Self::Expert,
    ];

    /// The name used in the configuration file and on the command line.
    #[must_use]
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Dlm => "dlm",
            Self::Lpe => "lpe",
            Self::None => "none",
            Self::PathTracker => "path-tracker",
            Self::DynamicWindow => "dynamic-window",
            Self::Expert => "expert",
        }
    }

    /// Whether a robot agent can run this controller (every kind but the privileged expert,
    /// which needs the simulator's ground truth).
    #[must_use]
    pub fn deployable(self) -> bool {
        self != Self::Expert
    }

    /// Whether this controller reads the camera image.
    #[must_use]
    pub fn reads_camera(self) -> bool {
        self.needs_model()
    }

    /// Whether this controller reads LPE images, so the planner must send them.
    #[must_use]
    pub fn reads_lpe(self) -> bool {
        self == Self::Lpe
    }

    /// Whether this controller runs a neural network and so needs a model file.
    #[must_use]
    pub fn needs_model(self) -> bool {
        matches!(self, Self::Dlm | Self::Lpe | Self::None)
    }
}

impl std::fmt::Display for ControllerKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// A controller name that is none of [`ControllerKind::ALL`].
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown controller `{0}`: expected one of dlm, lpe, none, path-tracker, dynamic-window, expert")]
pub struct UnknownController(pub String);

impl std::str::FromStr for ControllerKind {
    type Err = UnknownController;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Self::ALL
            .into_iter()
            .find(|k| k.as_str() == s)
            .ok_or_else(|| UnknownController(s.to_string()))
    }
}

/// Periodic status of a robot agent.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AgentStatus {
    pub header: Header,
    pub state: AgentState,
    pub stop_reason: Option<StopReason>,
    /// The configured controller (what the intentions must carry for it).
    pub controller: ControllerKind,
    /// The map the agent localizes on, once it has one.
    pub map: Option<MapRef>,
    pub localized: bool,
    /// The agent's recovery drives in place of `controller` (`[safety.recovery]`): the dynamic
    /// window, or backing straight off from someone met face to face (`back_up_m`).
    #[serde(default)]
    pub recovering: bool,
    /// Of `recovering`: the recovery backs the robot straight off the way it came, from someone
    /// met face to face (`[safety.recovery] back_up_m`); no controller drives meanwhile.
    #[serde(default)]
    pub backing_up: bool,
    /// The rotation shim turns the robot on the spot towards its path, which lies behind it,
    /// before `controller` drives on (`[rotation_shim]`).
    #[serde(default)]
    pub rotating_in_place: bool,
    /// The give-way rule holds the robot short of a narrow passage, or beside the path before
    /// it, while someone comes through the passage the other way (`[give_way]`).
    #[serde(default)]
    pub giving_way: bool,
}

impl AgentStatus {
    pub fn validate(&self) -> Result<(), ValidationError> {
        if let Some(StopReason::LocalizationLost { position_std_m }) = &self.stop_reason {
            check_finite("stop_reason.position_std_m", *position_std_m)?;
        }
        Ok(())
    }
}

/// Lifecycle of a delivery task.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum TaskState {
    Queued,
    Assigned {
        robot_id: RobotId,
    },
    /// Driving towards goal `goal_index` of the task.
    Active {
        robot_id: RobotId,
        goal_index: u32,
    },
    /// Held at goal `goal_index` because its robot went silent or lost localization; resumes
    /// (back to `Active`) when the robot reports again, fails after the service's grace period.
    Paused {
        robot_id: RobotId,
        goal_index: u32,
        reason: String,
    },
    Completed,
    Failed {
        reason: String,
    },
    Cancelled,
}

impl TaskState {
    /// Whether the task can no longer change state.
    pub fn is_terminal(&self) -> bool {
        matches!(
            self,
            TaskState::Completed | TaskState::Failed { .. } | TaskState::Cancelled
        )
    }

    /// The robot working on the task, if any.
    pub fn robot_id(&self) -> Option<&RobotId> {
        match self {
            TaskState::Assigned { robot_id }
            | TaskState::Active { robot_id, .. }
            | TaskState::Paused { robot_id, .. } => Some(robot_id),
            _ => None,
        }
    }
}

/// A task changed state; published by the planner service.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TaskEvent {
    pub header: Header,
    pub task_id: TaskId,
    pub map: MapName,
    pub state: TaskState,
    pub goal_count: u32,
}

/// Cell value meaning "unknown" in a [`MapGrid`]; 0..=100 are occupancy percentages.
pub const UNKNOWN_CELL: u8 = 255;

/// Description of one stored map version.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MapMeta {
    pub id: MapId,
    pub name: MapName,
    pub version: u32,
    /// Hex sha256 of the map content.
    pub content_hash: String,
    pub width_cells: u32,
    pub height_cells: u32,
    /// Edge length of one square cell.
    pub resolution_m: f64,
    /// Map-frame pose of the bottom-left corner of cell (0, 0) (as ROS `map_server`).
    pub origin: Pose2D,
    pub free_cells: u64,
    pub occupied_cells: u64,
    pub unknown_cells: u64,
    /// Wall-clock creation time, ns since the Unix epoch.
    pub created_ns: u64,
}

impl MapMeta {
    pub fn map_ref(&self) -> MapRef {
        MapRef {
            name: self.name.clone(),
            version: self.version,
        }
    }

    /// Number of cells (None if it overflows usize).
    pub fn cell_count(&self) -> Option<usize> {
        (self.width_cells as usize).checked_mul(self.height_cells as usize)
    }

    pub fn validate(&self) -> Result<(), ValidationError> {
        if self.width_cells == 0 || self.height_cells == 0 {
            return Err(ValidationError::new(
                "meta.size",
                format!("{}x{} cells is empty", self.width_cells, self.height_cells),
            ));
        }
        if !(self.resolution_m.is_finite() && self.resolution_m > 0.0) {
            return Err(ValidationError::new(
                "meta.resolution_m",
                format!("{} is not a positive finite number", self.resolution_m),
            ));
        }
        self.origin.validate("meta.origin")
    }
}

/// A whole occupancy grid.
///
/// `cells` is row-major, row 0 is the bottom row (lowest y, as a ROS OccupancyGrid); values
/// 0..=100 are occupancy probability in percent and [`UNKNOWN_CELL`] (255) is unknown. `cells` is
/// not part of the serde form: the codec sends it as a raw blob.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MapGrid {
    pub meta: MapMeta,
    #[serde(skip)]
    pub cells: Vec<u8>,
}

impl MapGrid {
    /// Index into `cells` of column `x`, row `y` (row 0 at the bottom).
    pub fn index(&self, x: u32, y: u32) -> Option<usize> {
        if x < self.meta.width_cells && y < self.meta.height_cells {
            Some(y as usize * self.meta.width_cells as usize + x as usize)
        } else {
            None
        }
    }

    pub fn cell(&self, x: u32, y: u32) -> Option<u8> {
        self.index(x, y).and_then(|i| self.cells.get(i).copied())
    }

    pub fn validate(&self) -> Result<(), ValidationError> {
        self.meta.validate()?;
        let expected = self.meta.cell_count();
        if expected != Some(self.cells.len()) {
            return Err(ValidationError::new(
                "cells",
                format!(
                    "{}x{} grid needs {} cells, got {}",
                    self.meta.width_cells,
                    self.meta.height_cells,
                    expected.map_or_else(|| "too many".to_string(), |n| n.to_string()),
                    self.cells.len()
                ),
            ));
        }
        if let Some((i, v)) = self
            .cells
            .iter()
            .enumerate()
            .find(|(_, &v)| v > 100 && v != UNKNOWN_CELL)
        {
            return Err(ValidationError::new(
                "cells",
                format!("cell {i} has value {v}; allowed are 0..=100 and 255 (unknown)"),
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() < 1e-12
    }

    #[test]
    fn normalize_angle_range() {
        assert!(close(normalize_angle(0.0), 0.0));
        assert!(close(normalize_angle(PI), PI));
        assert!(close(normalize_angle(-PI), PI));
        assert!(close(normalize_angle(3.0 * PI), PI));
        assert!(close(normalize_angle(-0.5 * PI), -0.5 * PI));
        assert!(close(normalize_angle(TAU + 0.25), 0.25));
        assert!(close(normalize_angle(-TAU - 0.25), -0.25));
        for i in -1000..1000 {
            let a = normalize_angle(f64::from(i) * 0.0137);
            assert!(a > -PI && a <= PI, "{a}");
        }
    }

    #[test]
    fn dlm_indices() {
        for (i, d) in Dlm::ALL.iter().enumerate() {
            assert_eq!(d.index(), i);
            assert_eq!(Dlm::from_index(i), Some(*d));
            let oh = d.one_hot();
            assert_eq!(oh.iter().sum::<f32>(), 1.0);
            assert_eq!(oh[i], 1.0);
        }
        assert_eq!(Dlm::from_index(4), None);
        assert_eq!(
            serde_json::to_string(&Dlm::GoForward).unwrap(),
            "\"go_forward\""
        );
        assert_eq!(Dlm::TurnLeft.to_string(), "turn_left");
    }

    #[test]
    fn pose_std() {
        let mut cov = [0.0; 9];
        cov[0] = 0.04;
        cov[4] = 0.01;
        cov[8] = 0.09;
        let p = PoseEstimate {
            header: Header::new(1, 2),
            pose: Pose2D::new(1.0, 2.0, 0.5),
            covariance: cov,
            sensor_stamp_ns: 1,
            map: MapRef {
                name: MapName::new("m").unwrap(),
                version: 1,
            },
            unmapped_obstacles_m: Vec::new(),
        };
        assert!(close(p.position_std_m(), 0.2));
        assert!(close(p.yaw_std_rad(), 0.3));
        // Correlated xy: eigenvalues of [[1, 0.5], [0.5, 1]] are 1.5 and 0.5.
        let mut q = p.clone();
        q.covariance[0] = 1.0;
        q.covariance[4] = 1.0;
        q.covariance[1] = 0.5;
        q.covariance[3] = 0.5;
        assert!(close(q.position_std_m(), 1.5f64.sqrt()));
    }

    #[test]
    fn scan_beams() {
        let scan = LaserScan {
            header: Header::default(),
            angle_min_rad: -1.0,
            angle_increment_rad: 0.5,
            range_min_m: 0.1,
            range_max_m: 10.0,
            ranges_m: vec![1.0, 10.0, 0.05, 12.0],
        };
        assert_eq!(scan.beam_angle_rad(2), 0.0);
        assert!(scan.is_return(0));
        assert!(!scan.is_return(1));
        assert!(!scan.is_return(2));
        assert!(!scan.is_return(3));
        assert!(!scan.is_return(4));
        assert!(scan.validate().is_ok());
        let mut bad = scan.clone();
        bad.ranges_m[0] = f32::INFINITY;
        assert_eq!(bad.validate().unwrap_err().field, "ranges_m");
    }

    #[test]
    fn image_validation() {
        assert!(Image::new(2, 2, ImageEncoding::Rgb8, vec![0; 12]).is_ok());
        let e = Image::new(2, 2, ImageEncoding::Rgb8, vec![0; 11]).unwrap_err();
        assert_eq!(e.field, "image.data");
        assert!(e.reason.contains("12") && e.reason.contains("11"), "{e}");
        assert!(Image::new(0, 2, ImageEncoding::Rgb8, vec![]).is_err());
        assert!(Image::new(2, 2, ImageEncoding::Png, vec![1, 2, 3]).is_err());
        assert!(Image::new(2, 2, ImageEncoding::Jpeg, vec![0xff, 0xd8, 0xff, 0xe0]).is_ok());
        assert_eq!(ImageEncoding::Png.mime(), "image/png");
    }

    #[test]
    fn stop_reason_words_and_tags() {
        let r = StopReason::StaleIntention { age_ms: 600 };
        assert_eq!(r.to_string(), "newest intention is stale (600 ms old)");
        assert_eq!(
            serde_json::to_string(&r).unwrap(),
            r#"{"kind":"stale_intention","age_ms":600}"#
        );
        assert_eq!(
            serde_json::to_string(&StopReason::GoalReached).unwrap(),
            r#"{"kind":"goal_reached"}"#
        );
    }

    #[test]
    fn task_state_tags() {
        let s = TaskState::Active {
            robot_id: RobotId::new("r1").unwrap(),
            goal_index: 2,
        };
        assert_eq!(
            serde_json::to_string(&s).unwrap(),
            r#"{"kind":"active","robot_id":"r1","goal_index":2}"#
        );
        assert!(!s.is_terminal());
        assert_eq!(s.robot_id().map(RobotId::as_str), Some("r1"));
        assert!(TaskState::Failed { reason: "x".into() }.is_terminal());
    }

    #[test]
    fn grid_validation_and_indexing() {
        let meta = MapMeta {
            id: MapId::new("m-0123456789ab").unwrap(),
            name: MapName::new("m").unwrap(),
            version: 1,
            content_hash: "0123456789ab".into(),
            width_cells: 3,
            height_cells: 2,
            resolution_m: 0.05,
            origin: Pose2D::default(),
            free_cells: 6,
            occupied_cells: 0,
            unknown_cells: 0,
            created_ns: 0,
        };
        let grid = MapGrid {
            meta,
            cells: vec![0, 1, 2, 3, 100, 255],
        };
        assert!(grid.validate().is_ok());
        assert_eq!(grid.cell(1, 1), Some(100));
        assert_eq!(grid.cell(3, 0), None);
        let mut bad = grid.clone();
        bad.cells.pop();
        assert_eq!(bad.validate().unwrap_err().field, "cells");
        let mut bad = grid.clone();
        bad.cells[0] = 101;
        assert!(bad.validate().unwrap_err().reason.contains("101"));
    }

    #[test]
    fn poses_parse_from_text() {
        let p: Pose2D = "1.5,-2,0.3".parse().unwrap();
        assert_eq!(p, Pose2D::new(1.5, -2.0, 0.3));
        let p: Pose2D = " 3 , 4.25 ,-1.57 ".parse().unwrap();
        assert_eq!(p, Pose2D::new(3.0, 4.25, -1.57));
        assert_eq!("0,0,0".parse::<Pose2D>().unwrap(), Pose2D::default());
    }

    #[test]
    fn bad_pose_text_is_refused_naming_the_input() {
        // Two components are refused: a pose without a heading is a mistake, not yaw 0.
        let e = "1,2".parse::<Pose2D>().unwrap_err();
        assert_eq!(
            e,
            PoseParseError::Parts {
                input: "1,2".into(),
                parts: 2
            }
        );
        let text = e.to_string();
        assert!(
            text.contains("\"1,2\"") && text.contains("x,y,yaw"),
            "{text}"
        );
        assert!(matches!(
            "1,2,3,4".parse::<Pose2D>(),
            Err(PoseParseError::Parts { parts: 4, .. })
        ));
        assert!("".parse::<Pose2D>().is_err());
        let e = "3,abc,0".parse::<Pose2D>().unwrap_err();
        assert!(matches!(
            &e,
            PoseParseError::NotFinite { component: "y", value, .. } if value == "abc"
        ));
        let text = e.to_string();
        assert!(
            text.contains("3,abc,0") && text.contains("y = \"abc\""),
            "{text}"
        );
        for bad in ["1,nan,0", "inf,0,0", "1,2,", "1,2,abc"] {
            let e = bad.parse::<Pose2D>().unwrap_err().to_string();
            assert!(e.contains(bad), "{e}");
        }
    }
}
