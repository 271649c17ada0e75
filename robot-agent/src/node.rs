//! The agent node: one robot's localization, controller and safety loop on Zenoh (DESIGN §2).
//!
//! [`run`] opens a Zenoh session, declares the robot's liveliness token, fetches its floor plan
//! from the map store, and then, until the shutdown future completes:
//!
//! - runs AMCL on every laser scan (with the odometry of that instant) and publishes the
//!   [`PoseEstimate`] on `pose`;
//! - at `control_rate_hz` builds a [`ControlInput`] from the pose advanced by odometry, the
//!   newest scan, camera frame and fresh intention, asks the controller, scales μ by the limits,
//!   applies acceleration limits and publishes [`CmdVel`];
//! - applies the safety rules: no intention, a stale one, lost localization or a controller
//!   error decelerate the robot to a stop with the reason in its [`AgentStatus`]; driving
//!   resumes by itself when the cause goes away;
//! - checks every command against the laser scan ([`crate::collision_monitor`]) and, when the
//!   monitor keeps holding the controller back, lets the dynamic window drive round the
//!   obstacle for a while ([`crate::recovery`]);
//! - publishes [`AgentStatus`] at `status_rate_hz` and on every change of state, and whenever
//!   the dynamic window, the rotation shim or the give-way rule takes over or hands back;
//! - with [`NodeOptions::record`], records what it receives (odometry, scans, intentions, the
//!   camera when asked) and publishes (poses, commands) as a run log (`fleet-log`, MCAP) on a
//!   background thread, in the order it processed them.
//!
//! The decision part ([`Supervisor`]) is plain data in, command out, so it is tested without
//! Zenoh; [`run`] is the I/O shell around it.

use std::collections::VecDeque;
use std::future::Future;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use fleet_log::{LogMessage, Recorder};
use map_core::OccupancyGrid;
use protocol::keys::{self, RobotTopic};
use protocol::{
    AgentState, AgentStatus, CameraFrame, CmdVel, Header, Intention, LaserScan, MapGrid, MapRef,
    Odometry, Pose2D, PoseEstimate, RobotId, StopReason,
};
use zenoh::handlers::RingChannel;
use zenoh::Session;

use crate::amcl::{Amcl, AmclError, Estimate, LikelihoodField, UpdateOutcome};
use crate::camera_hold::{CameraHold, Observation as HoldObservation};
use crate::collision_monitor::{self, MovingBody, Verdict};
use crate::config::{AgentConfig, ConfigError, ControllerKind, Limits};
use crate::controllers::{
    Control, ControlInput, Controller, DynamicWindow, IntentionNet, IntentionNetError,
    IntentionNetOptions, PathTracker,
};
use crate::give_way::GiveWay;
use crate::movers::{self, MoverTracker};
use crate::recovery::{Mode, Recovery};
use crate::rotation_shim::RotationShim;
use crate::unmapped::UnmappedObstacles;

/// Why the node could not start or had to stop.
#[derive(Debug, thiserror::Error)]
pub enum NodeError {
    #[error(transparent)]
    Config(#[from] ConfigError),
    #[error(transparent)]
    Model(#[from] IntentionNetError),
    #[error("zenoh: cannot {action}: {reason}")]
    Zenoh {
        action: &'static str,
        reason: String,
    },
    #[error(transparent)]
    Publish(#[from] protocol::PublishError),
    #[error("map {name}: {reason}")]
    Map { name: String, reason: String },
    #[error("localization: {0}")]
    Amcl(#[from] AmclError),
    #[error("run log: {0}")]
    Log(#[from] fleet_log::LogError),
}

fn zenoh_err(action: &'static str) -> impl FnOnce(zenoh::Error) -> NodeError {
    move |e| NodeError::Zenoh {
        action,
        reason: e.to_string(),
    }
}

/// The Zenoh configuration of an agent: a peer with the given endpoints, multicast scouting
/// on only when asked for (see [`protocol::SessionArgs`], which builds it).
///
/// # Errors
/// [`NodeError::Zenoh`] naming the endpoint or setting Zenoh refused.
pub fn zenoh_config(
    listen: &[String],
    connect: &[String],
    multicast_scouting: bool,
) -> Result<zenoh::Config, NodeError> {
    protocol::SessionArgs {
        listen: listen.to_vec(),
        connect: connect.to_vec(),
        multicast_scouting,
        ..protocol::SessionArgs::default()
    }
    .config()
    .map_err(|e| NodeError::Zenoh {
        action: "configure the session",
        reason: e.to_string(),
    })
}

/// The controller a configuration asks for; network controllers load and check their model
/// (and ONNX Runtime) here, so a missing library or mismatched card fails at start-up.
///
/// # Errors
/// [`NodeError::Config`] for bad controller parameters, [`NodeError::Model`] when the model or
/// ONNX Runtime cannot be loaded or the model card does not match the configuration.
pub fn make_controller(config: &AgentConfig) -> Result<Box<dyn Controller>, NodeError> {
    Ok(match config.controller {
        ControllerKind::PathTracker => Box::new(PathTracker::new(config.path_tracker)?),
        ControllerKind::DynamicWindow => Box::new(DynamicWindow::new(config.dynamic_window)?),
        ControllerKind::Dlm | ControllerKind::Lpe | ControllerKind::None => {
            let options = IntentionNetOptions {
                intra_threads: config.intention_net.intra_threads,
            };
            Box::new(IntentionNet::from_config(config, &options)?)
        }
        ControllerKind::Expert => {
            return Err(NodeError::Config(ConfigError::Invalid {
                field: "controller",
                value: "expert".into(),
                reason: "the privileged expert reads the simulator's ground truth; only `eval` \
                         runs it",
            }))
        }
    })
}

/// Everything [`run`] needs besides the shutdown signal.
#[derive(Debug, Clone)]
pub struct NodeOptions {
    pub robot_id: RobotId,
    /// The merged configuration (file + command line); `map` must be set.
    pub config: AgentConfig,
    pub zenoh: zenoh::Config,
    /// Record a run log (`--record FILE`).
    pub record: Option<RecordOptions>,
}

/// Where `--record` writes the run log and what it keeps.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordOptions {
    /// The MCAP file (written as `FILE.partial` until the agent stops).
    pub path: PathBuf,
    pub log: fleet_log::LogOptions,
}

/// Queues a message for the run log, if one is recorded (the message is built only then).
fn record(recorder: &mut Option<Recorder>, message: impl FnOnce() -> LogMessage) {
    if let Some(r) = recorder {
        r.record(message());
    }
}

/// Nanosecond stamps that never go backwards: the wall clock at start plus monotonic time.
#[derive(Debug, Clone, Copy)]
struct Clock {
    start: Instant,
    start_ns: u64,
}

impl Clock {
    fn new() -> Self {
        let start_ns = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .map_or(0, |d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX));
        Self {
            start: Instant::now(),
            start_ns,
        }
    }

    fn stamp_ns(&self, at: Instant) -> u64 {
        let since = u64::try_from(at.duration_since(self.start).as_nanos()).unwrap_or(u64::MAX);
        self.start_ns.saturating_add(since)
    }
}

/// How many published poses are remembered to age the intentions that answer them (100 s of
/// scans at 10 Hz: an intention answering an older pose is stale under any sane deadline).
const POSE_HISTORY: usize = 1000;
/// Odometry readings kept to find the one taken with a scan.
const ODOM_HISTORY: usize = 64;

/// What the supervisor decided for one control cycle.
#[derive(Debug, Clone, PartialEq)]
pub struct Decision {
    pub cmd_v_mps: f64,
    pub cmd_omega_radps: f64,
    pub state: AgentState,
    pub stop_reason: Option<StopReason>,
    /// What the collision monitor did to the command (`None` when the command was to stand or
    /// turn in place, or the monitor is off).
    pub collision_monitor: Option<Verdict>,
    /// The recovery drove this cycle in place of the configured controller
    /// ([`crate::recovery`]): the dynamic window, or backing straight off.
    pub recovering: bool,
    /// Of `recovering`: the robot backs straight off from someone met face to face
    /// (`[safety.recovery] back_up_m`; the status's `backing_up`).
    pub backing_up: bool,
    /// The rotation shim turned the robot towards its path this cycle
    /// ([`crate::rotation_shim`]; the status's `rotating_in_place`).
    pub rotating: bool,
    /// The robot waits short of a narrow passage for someone coming through it
    /// ([`crate::give_way`]; the status's `giving_way`).
    pub giving_way: bool,
}

/// The agent's brain without I/O: localization, the newest inputs, the controller and the
/// safety rules. [`run`] feeds it messages and clock ticks and publishes what it returns.
pub struct Supervisor {
    config: AgentConfig,
    map: MapRef,
    amcl: Amcl,
    /// What AMCL did with the last scan (diagnostics, replay timing).
    last_amcl: Option<UpdateOutcome>,
    controller: Box<dyn Controller>,
    /// The dynamic window that relieves `controller` when it is stuck (none when recovery is
    /// off or the controller is the dynamic window itself).
    fallback: Option<Box<dyn Controller>>,
    recovery: Recovery,
    /// Turns the robot towards its path before the controller drives on (none when off or the
    /// controller is the dynamic window or the expert, which turn round by themselves).
    shim: Option<RotationShim>,
    /// Waits short of a narrow passage while someone comes through (none when off, or for the
    /// expert, which gives way by its own rule).
    give_way: Option<GiveWay>,
    /// The walking bodies in the scan, for the give-way rule and the collision monitor.
    movers: MoverTracker,
    /// This cycle's walking bodies in the scan's frame, for the collision monitor.
    moving: Vec<MovingBody>,
    /// The held scan is newer than the tracker's last: the tracker takes each scan once (a
    /// control cycle may come without a new one) ...
    scan_untracked: bool,
    /// ... over the time since the last.
    movers_since_s: f64,
    /// What the laser sees where the floor plan is free (`None` when reporting is off).
    unmapped: Option<UnmappedObstacles>,
    /// What it reported with the last pose (map frame).
    unmapped_seen: Vec<[f64; 2]>,
    /// What the collision monitor did to the last command.
    last_verdict: Option<Verdict>,
    /// Keeps the recovery behind where the camera-driven controller braked for what the laser
    /// does not see (none when off or not for this controller, [`CameraHold`]).
    camera_hold: Option<CameraHold>,
    /// What the hold looks at this cycle (set while the controller drives).
    hold_obs: Option<HoldObservation>,
    /// Whether the fallback drove the last cycle, or the recovery backed the robot off.
    recovering: bool,
    odometry: VecDeque<Odometry>,
    scan: Option<LaserScan>,
    /// What the collision monitor did in this cycle.
    monitor: Option<Verdict>,
    camera: Option<CameraFrame>,
    intention: Option<Intention>,
    /// (seq, local time) of every published pose still remembered.
    poses: VecDeque<(u64, Instant)>,
    pose_seq: u64,
    cmd_v_mps: f64,
    cmd_omega_radps: f64,
    last_control: Option<Instant>,
    state: AgentState,
    stop_reason: Option<StopReason>,
}

impl std::fmt::Debug for Supervisor {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Supervisor")
            .field("map", &self.map)
            .field("controller", &self.config.controller)
            .field("state", &self.state)
            .field("stop_reason", &self.stop_reason)
            .finish_non_exhaustive()
    }
}

fn approach(current: f64, target: f64, max_delta: f64) -> f64 {
    current + (target - current).clamp(-max_delta, max_delta)
}

impl Supervisor {
    /// Builds the localizer on `grid` (initial pose from the configuration, or global
    /// localization) around an already made controller.
    ///
    /// # Errors
    /// [`NodeError::Amcl`] when the filter cannot be set up on this map.
    pub fn new(
        config: AgentConfig,
        map: MapRef,
        grid: &OccupancyGrid,
        controller: Box<dyn Controller>,
    ) -> Result<Self, NodeError> {
        let field = Arc::new(LikelihoodField::new(
            grid,
            config.amcl.laser_likelihood_max_dist_m,
        )?);
        let mut amcl = Amcl::new(config.amcl.clone(), field)?;
        match config.localization.initial_pose {
            Some(pose) => amcl.set_initial_pose(pose, config.localization.initial_covariance())?,
            None => amcl.global_localization()?,
        }
        // The expert reads the ground truth and goes round things itself.
        let relieved = !matches!(
            controller.kind(),
            ControllerKind::DynamicWindow | ControllerKind::Expert
        );
        let fallback: Option<Box<dyn Controller>> = if config.safety.recovery.enabled && relieved {
            Some(Box::new(DynamicWindow::new(config.dynamic_window)?))
        } else {
            None
        };
        let recovery = Recovery::new(config.safety.recovery);
        let camera_hold = config
            .safety
            .camera_hold
            .applies_to(controller.kind())
            .then(|| CameraHold::new(config.safety.camera_hold));
        let shim = (config.rotation_shim.enabled && relieved)
            .then(|| RotationShim::new(config.rotation_shim));
        let give_way = (config.give_way.enabled && controller.kind() != ControllerKind::Expert)
            .then(|| GiveWay::new(config.give_way));
        let unmapped = config
            .unmapped_obstacles
            .enabled
            .then(|| UnmappedObstacles::new(config.unmapped_obstacles));
        Ok(Self {
            config,
            map,
            amcl,
            last_amcl: None,
            controller,
            fallback,
            recovery,
            shim,
            give_way,
            movers: MoverTracker::default(),
            moving: Vec::new(),
            scan_untracked: false,
            movers_since_s: 0.0,
            unmapped,
            unmapped_seen: Vec::new(),
            last_verdict: None,
            camera_hold,
            hold_obs: None,
            recovering: false,
            odometry: VecDeque::with_capacity(ODOM_HISTORY),
            scan: None,
            monitor: None,
            camera: None,
            intention: None,
            poses: VecDeque::with_capacity(POSE_HISTORY),
            pose_seq: 0,
            cmd_v_mps: 0.0,
            cmd_omega_radps: 0.0,
            last_control: None,
            state: AgentState::Starting,
            stop_reason: None,
        })
    }

    /// What AMCL did with the last scan given to [`Self::on_scan`] (`None` before one).
    #[must_use]
    pub fn last_amcl_update(&self) -> Option<UpdateOutcome> {
        self.last_amcl
    }

    #[must_use]
    pub fn state(&self) -> AgentState {
        self.state
    }

    #[must_use]
    pub fn stop_reason(&self) -> Option<&StopReason> {
        self.stop_reason.as_ref()
    }

    #[must_use]
    pub fn map(&self) -> &MapRef {
        &self.map
    }

    /// The localizer, for diagnostics.
    #[must_use]
    pub fn amcl(&self) -> &Amcl {
        &self.amcl
    }

    /// Position standard deviation of the current belief (infinite before the first estimate).
    #[must_use]
    pub fn position_std_m(&self) -> f64 {
        self.amcl
            .estimate()
            .map_or(f64::INFINITY, |e| protocol::position_std_m(&e.covariance))
    }

    #[must_use]
    pub fn localized(&self) -> bool {
        self.position_std_m() <= self.config.safety.max_position_std_m && !self.amcl.is_lost()
    }

    /// Re-initialises localization at `pose` with a row-major 3×3 covariance (x, y, yaw), as an
    /// operator who carried the robot (or RViz's "2D pose estimate") sets it. The held intention
    /// answered a pose elsewhere and is dropped, and the controller starts afresh.
    ///
    /// # Errors
    /// [`NodeError::Amcl`] for a non-finite pose or covariance; nothing is changed then.
    pub fn set_pose(&mut self, pose: Pose2D, covariance: [f64; 9]) -> Result<(), NodeError> {
        self.amcl.set_initial_pose(pose, covariance)?;
        self.intention = None;
        self.reset_controllers();
        self.recovery.idle(0.0);
        if let Some(hold) = &mut self.camera_hold {
            hold.reset();
        }
        Ok(())
    }

    /// Remembers an odometry reading.
    pub fn on_odometry(&mut self, odom: Odometry) {
        if self.odometry.len() == ODOM_HISTORY {
            self.odometry.pop_front();
        }
        self.odometry.push_back(odom);
    }

    pub fn on_camera(&mut self, frame: CameraFrame) {
        self.camera = Some(frame);
    }

    /// The odometry reading taken with a sensor stamp: the newest at or before it (the base
    /// publishes odometry at least as often as scans), else the oldest one known.
    fn odometry_at(&self, stamp_ns: u64) -> Option<&Odometry> {
        self.odometry
            .iter()
            .rev()
            .find(|o| o.header.stamp_ns <= stamp_ns)
            .or_else(|| self.odometry.front())
    }

    /// Runs AMCL on a scan and returns the pose estimate to publish, stamped `now`; `None` when
    /// no odometry has arrived yet (the filter needs the motion that goes with the scan).
    ///
    /// # Errors
    /// [`NodeError::Amcl`] for a malformed scan or odometry; the filter is left unchanged.
    pub fn on_scan(
        &mut self,
        scan: LaserScan,
        now: Instant,
        stamp_ns: u64,
    ) -> Result<Option<PoseEstimate>, NodeError> {
        let Some(odom) = self.odometry_at(scan.header.stamp_ns).cloned() else {
            self.scan = Some(scan);
            self.scan_untracked = true;
            return Ok(None);
        };
        self.last_amcl = Some(self.amcl.update(&odom, Some(&scan))?);
        let sensor_stamp_ns = scan.header.stamp_ns;
        let (Some(estimate), Some(pose)) = (self.amcl.estimate(), self.amcl.predict_pose(&odom))
        else {
            self.scan = Some(scan);
            self.scan_untracked = true;
            return Ok(None);
        };
        self.unmapped_seen = self.mark_unmapped(&scan, &estimate, pose);
        self.scan = Some(scan);
        self.scan_untracked = true;
        self.pose_seq += 1;
        if self.poses.len() == POSE_HISTORY {
            self.poses.pop_front();
        }
        self.poses.push_back((self.pose_seq, now));
        Ok(Some(PoseEstimate {
            header: Header::new(self.pose_seq, stamp_ns),
            pose,
            covariance: estimate.covariance,
            sensor_stamp_ns,
            map: self.map.clone(),
            unmapped_obstacles_m: self.unmapped_seen.clone(),
        }))
    }

    /// Marks `scan`, taken at `estimate`, on the obstacle layer and returns what it reports
    /// round `pose` (nothing when the layer is off; no marking while the estimate is too
    /// doubtful to place a return).
    fn mark_unmapped(
        &mut self,
        scan: &LaserScan,
        estimate: &Estimate,
        pose: Pose2D,
    ) -> Vec<[f64; 2]> {
        let Some(layer) = self.unmapped.as_mut() else {
            return Vec::new();
        };
        let std_m = protocol::position_std_m(&estimate.covariance);
        if std_m <= self.config.unmapped_obstacles.max_position_std_m {
            let map_from_laser = pose_compose(estimate.pose, self.config.amcl.robot_from_laser);
            let field = self.amcl.field();
            layer.on_scan(scan, map_from_laser, |x, y| field.distance_m(x, y));
        }
        layer.points_m(pose)
    }

    /// Takes an intention if it answers a pose this agent published on this map and is newer
    /// than the one held; returns why it was refused otherwise.
    ///
    /// # Errors
    /// A reason to log: another map, a pose this agent never published, or an older answer.
    pub fn on_intention(&mut self, intention: Intention) -> Result<(), String> {
        if intention.map.name != self.map.name {
            return Err(format!(
                "intention for map {} v{}, the agent localizes on {} v{}",
                intention.map.name, intention.map.version, self.map.name, self.map.version
            ));
        }
        if intention.answers_pose_seq > self.pose_seq || intention.answers_pose_seq == 0 {
            return Err(format!(
                "intention answers pose {}, which this agent has not published (latest {})",
                intention.answers_pose_seq, self.pose_seq
            ));
        }
        if let Some(held) = &self.intention {
            if held.answers_pose_seq > intention.answers_pose_seq {
                return Err(format!(
                    "intention answers pose {}, older than the held one ({})",
                    intention.answers_pose_seq, held.answers_pose_seq
                ));
            }
        }
        self.intention = Some(intention);
        Ok(())
    }

    /// Age of the held intention: now minus when the pose it answers was published. Poses that
    /// fell out of the history give the age of the oldest remembered one, a lower bound.
    fn intention_age(&self, intention: &Intention, now: Instant) -> Duration {
        let seq = intention.answers_pose_seq;
        let published = self
            .poses
            .iter()
            .rev()
            .find(|(s, _)| *s <= seq)
            .or_else(|| self.poses.front())
            .map_or(now, |(_, at)| *at);
        now.saturating_duration_since(published)
    }

    /// One control cycle at local time `now`.
    pub fn control(&mut self, now: Instant) -> Decision {
        let nominal_dt = 1.0 / self.config.control_rate_hz;
        let dt = self.last_control.map_or(nominal_dt, |t| {
            now.saturating_duration_since(t)
                .as_secs_f64()
                .clamp(1e-3, 2.0 * nominal_dt)
        });
        self.last_control = Some(now);
        let limits = self.config.limits;
        self.monitor = None;
        self.moving.clear();
        self.movers_since_s += dt;
        self.hold_obs = None;
        let (target, state, reason) = self.target(now, dt, &limits);
        let obs = self.hold_obs.take();
        let target = match (target, self.camera_hold.as_mut(), obs) {
            (Some((v, w)), Some(hold), Some(obs)) if state == AgentState::Driving => {
                Some((hold.cycle(dt, &obs, v, limits.max_accel_mps2), w))
            }
            (target, ..) => target,
        };
        let (mut v, mut w) = match target {
            // Driving: the controller's command within the acceleration limits.
            Some((v, w)) => (
                approach(self.cmd_v_mps, v, limits.max_accel_mps2 * dt),
                approach(self.cmd_omega_radps, w, limits.max_turn_accel_radps2 * dt),
            ),
            None => (
                approach(self.cmd_v_mps, 0.0, self.config.safety.stop_decel_mps2 * dt),
                approach(self.cmd_omega_radps, 0.0, limits.max_turn_accel_radps2 * dt),
            ),
        };
        // The collision monitor comes last, after the acceleration limits, as it sits right
        // before the base: braking for an obstacle may be harder than the controller's own.
        // Its scan is never old while driving: poses are published on scans, so without new
        // ones the intention goes stale within its deadline and the robot stops anyway.
        let monitor = &self.config.safety.collision_monitor;
        if let Some(scan) = self.scan.as_ref().filter(|_| monitor.enabled) {
            if v != 0.0 {
                let verdict = collision_monitor::check(monitor, scan, &self.moving, v, w);
                (v, w) = (verdict.v_mps, verdict.omega_radps);
                self.monitor = Some(verdict);
            }
        }
        self.last_verdict = self.monitor;
        let state = match state {
            AgentState::Stopping | AgentState::Stopped => {
                if v == 0.0 && w == 0.0 {
                    AgentState::Stopped
                } else {
                    AgentState::Stopping
                }
            }
            other => other,
        };
        if state != AgentState::Driving {
            self.recovery.idle(dt);
            if self.state == AgentState::Driving {
                // A stop ends the controller's episode; it starts afresh when driving resumes.
                self.reset_controllers();
            }
        }
        let recovering = self.recovering && state == AgentState::Driving;
        let backing_up = recovering && self.backing_up();
        self.cmd_v_mps = v;
        self.cmd_omega_radps = w;
        self.state = state;
        let rotating = self.rotating();
        let giving_way = self.giving_way();
        self.stop_reason.clone_from(&reason);
        Decision {
            cmd_v_mps: v,
            cmd_omega_radps: w,
            state,
            stop_reason: reason,
            collision_monitor: self.monitor,
            recovering,
            backing_up,
            rotating,
            giving_way,
        }
    }

    fn reset_controllers(&mut self) {
        self.controller.reset();
        if let Some(f) = &mut self.fallback {
            f.reset();
        }
        if let Some(shim) = &mut self.shim {
            shim.reset();
        }
        if let Some(g) = &mut self.give_way {
            g.reset();
        }
        self.movers.reset();
        self.recovering = false;
    }

    /// Whether a stuck controller is relieved by the dynamic window (`[safety.recovery]` on
    /// and the controller is neither the dynamic window nor the expert).
    #[must_use]
    pub fn recovers(&self) -> bool {
        self.fallback.is_some()
    }

    /// How many camera holds have started (`None`: the hold is off or not for this
    /// controller).
    #[must_use]
    pub fn camera_holds(&self) -> Option<u32> {
        self.camera_hold.as_ref().map(CameraHold::holds)
    }

    /// How many times the dynamic window has taken over from the configured controller.
    #[must_use]
    pub fn recoveries(&self) -> u32 {
        self.recovery.recoveries()
    }

    /// Whether the rotation shim turns the robot on the spot now ([`Decision::rotating`]; only
    /// while driving: a stop ends the turn).
    #[must_use]
    pub fn rotating(&self) -> bool {
        self.state == AgentState::Driving && self.shim.as_ref().is_some_and(RotationShim::turning)
    }

    /// Whether the give-way rule holds the robot now ([`Decision::giving_way`]; only while
    /// driving: a stop ends the wait).
    #[must_use]
    pub fn giving_way(&self) -> bool {
        self.state == AgentState::Driving && self.give_way.as_ref().is_some_and(GiveWay::waiting)
    }

    /// Whether the recovery backs the robot straight off now (the status's `backing_up`).
    fn backing_up(&self) -> bool {
        self.recovering && self.recovery.mode() == Mode::BackUp
    }

    /// The controller that drives now: the configured one, or the dynamic window recovering
    /// (backing off, no controller drives: the configured one takes the robot on after).
    #[must_use]
    pub fn active_controller(&self) -> ControllerKind {
        if self.recovering && !self.backing_up() {
            ControllerKind::DynamicWindow
        } else {
            self.config.controller
        }
    }

    /// The target command (`None`: come to a stop), the state and the stop reason.
    fn target(
        &mut self,
        now: Instant,
        dt: f64,
        limits: &Limits,
    ) -> (Option<(f64, f64)>, AgentState, Option<StopReason>) {
        let stop = |reason| (None, AgentState::Stopping, Some(reason));
        let position_std_m = self.position_std_m();
        if position_std_m > self.config.safety.max_position_std_m || self.amcl.is_lost() {
            // Not finite only before the first estimate; the status needs a number.
            let shown = if position_std_m.is_finite() {
                position_std_m
            } else {
                f64::MAX
            };
            let reason = StopReason::LocalizationLost {
                position_std_m: shown,
            };
            let spin = self.config.safety.relocalize_spin_radps;
            if self.amcl.is_relocalizing() && spin > 0.0 {
                // Turning in place sweeps the laser over the surroundings and lets the
                // filter update (it only runs on motion); it cannot run into anything.
                return (Some((0.0, spin)), AgentState::Relocalizing, Some(reason));
            }
            return stop(reason);
        }
        let Some(intention) = self.intention.as_ref() else {
            return stop(StopReason::NoIntention);
        };
        let age = self.intention_age(intention, now);
        if age > Duration::from_millis(self.config.safety.intention_deadline_ms) {
            return stop(StopReason::StaleIntention {
                age_ms: u64::try_from(age.as_millis()).unwrap_or(u64::MAX),
            });
        }
        if intention.rests() {
            // Nothing to do, or the goal is reached: rest, which is not a fault.
            return (None, AgentState::Idle, None);
        }
        let latest = self.odometry.back();
        let pose = latest
            .and_then(|o| self.amcl.predict_pose(o))
            .or_else(|| self.amcl.estimate().map(|e| e.pose))
            .unwrap_or_else(|| Pose2D::new(0.0, 0.0, 0.0));
        let input = ControlInput {
            pose,
            v_mps: latest.map_or(0.0, |o| o.v_mps),
            omega_radps: latest.map_or(0.0, |o| o.omega_radps),
            scan: self.scan.as_ref(),
            camera: self.camera.as_ref(),
            intention: Some(intention),
            limits,
            dt_s: dt,
        };
        let goal = intention.path.last().copied();
        self.hold_obs = self.camera_hold.is_some().then(|| HoldObservation {
            pose,
            last_command_mps: self.cmd_v_mps,
            commanded_mps: None,
            ahead_m: self
                .scan
                .as_ref()
                .map_or(f64::INFINITY, crate::recovery::ahead_m),
            goal,
            path_bend_rad: crate::camera_hold::path_bend_rad(
                pose,
                &intention.path,
                self.config.safety.camera_hold.path_ahead_m,
            ),
            mover_m: f64::INFINITY,
            recovering: false,
        });
        let monitor = &self.config.safety.collision_monitor;
        let tracking = self.give_way.is_some() || (monitor.enabled && monitor.track_movers);
        let held = match self.scan.as_ref().filter(|_| tracking) {
            Some(scan) => {
                let seen = SeenInputs {
                    field: self.amcl.field(),
                    seen_m: &self.unmapped_seen,
                    cell_m: self.config.unmapped_obstacles.cell_m,
                };
                let laser = self.config.amcl.robot_from_laser;
                let map_from_laser = pose_compose(pose, laser);
                if std::mem::take(&mut self.scan_untracked) {
                    let since_s = std::mem::take(&mut self.movers_since_s);
                    let candidates = mover_candidates(
                        &seen,
                        scan,
                        map_from_laser,
                        self.config.give_way.min_map_gap_m,
                    );
                    self.movers
                        .update(since_s, [pose.x_m, pose.y_m], &candidates);
                }
                self.moving =
                    collision_monitor::moving_bodies(self.movers.tracks(), map_from_laser);
                self.give_way.as_mut().and_then(|give_way| {
                    give_way.cycle(dt, pose, &intention.path, self.movers.tracks(), |x, y| {
                        seen.free_m(x, y)
                    })
                })
            }
            None => None,
        };
        if let Some(obs) = self.hold_obs.as_mut() {
            // The tracks are this cycle's where the scan was tracked, else the last scan's.
            obs.mover_m = self
                .movers
                .tracks()
                .iter()
                .map(|t| (t.x_m - pose.x_m).hypot(t.y_m - pose.y_m))
                .fold(f64::INFINITY, f64::min);
        }
        if let Some(spot) = held.and_then(|h| h.wait_at_m) {
            self.recovery.idle(dt);
            if let Some(shim) = &mut self.shim {
                shim.reset();
            }
            let command = to_wait_spot(pose, spot, limits);
            return (Some(command), AgentState::Driving, None);
        }
        let hold = held.map(|h| h.max_speed_mps);
        let mode = if hold.is_some() {
            // Waiting for someone on purpose is not being stuck.
            self.recovery.idle(dt);
            Mode::Primary
        } else if self.fallback.is_some() {
            let unmapped_m = crate::recovery::beside_m(&self.unmapped_seen, pose);
            let ahead_m = self
                .scan
                .as_ref()
                .map_or(f64::INFINITY, crate::recovery::ahead_m);
            // The tracks are this cycle's, the verdict the last command's: someone walking
            // near now was near then.
            let monitored = self.last_verdict.map(|verdict| crate::recovery::Monitored {
                verdict,
                walker_m: crate::recovery::walker_m(self.movers.tracks(), pose),
            });
            self.recovery
                .oncoming(crate::recovery::oncoming_m(self.movers.tracks(), pose));
            self.recovery
                .drive(dt, pose, goal, monitored, unmapped_m, ahead_m)
        } else {
            Mode::Primary
        };
        if mode == Mode::BackUp {
            // Straight back the way the robot came; the controller takes it on afresh after.
            self.recovering = true;
            if let Some(shim) = &mut self.shim {
                shim.reset();
            }
            let back_mps = self.config.safety.recovery.back_up_speed_mps;
            return (Some((-back_mps, 0.0)), AgentState::Driving, None);
        }
        let recovering = mode == Mode::Fallback;
        let controller = match (&mut self.fallback, recovering) {
            (Some(fallback), true) => fallback,
            _ => &mut self.controller,
        };
        if recovering != self.recovering {
            // Each takes the robot over where the other left it.
            controller.reset();
            self.recovering = recovering;
        }
        if let Some(shim) = self.shim.as_mut() {
            let was_turning = shim.turning();
            let turn = if recovering {
                shim.reset();
                None
            } else {
                shim.command(pose, input.v_mps, &intention.path, limits.max_turn_radps)
            };
            if turn.is_some() {
                return (turn.map(|c| capped(c, hold)), AgentState::Driving, None);
            }
            if was_turning {
                // The controller takes the robot on from where the turn left it.
                controller.reset();
            }
        }
        match controller.control(&input) {
            Ok(control) => {
                let command = Control::clamped(control).to_physical(limits);
                if let Some(obs) = self.hold_obs.as_mut() {
                    obs.recovering = recovering;
                    if !recovering && hold.is_none() {
                        // The controller's own wish, before anyone changed it.
                        obs.commanded_mps = Some(command.0);
                    }
                }
                (Some(capped(command, hold)), AgentState::Driving, None)
            }
            Err(e) => stop(StopReason::ControllerError {
                message: e.to_string(),
            }),
        }
    }

    /// The status to publish now.
    #[must_use]
    pub fn status(&self, seq: u64, stamp_ns: u64) -> AgentStatus {
        AgentStatus {
            header: Header::new(seq, stamp_ns),
            state: self.state,
            stop_reason: self.stop_reason.clone(),
            // The configured one even while recovering: the planner renders the intention
            // for it (the LPE image), and it takes over again.
            controller: self.config.controller,
            map: Some(self.map.clone()),
            localized: self.localized(),
            recovering: self.recovering,
            backing_up: self.backing_up(),
            rotating_in_place: self.rotating(),
            giving_way: self.giving_way(),
        }
    }
}

/// What the laser's returns are measured against: the floor plan and the obstacle layer.
struct SeenInputs<'a> {
    field: &'a LikelihoodField,
    /// The obstacle layer's confirmed cells (map frame).
    seen_m: &'a [[f64; 2]],
    cell_m: f64,
}

impl SeenInputs<'_> {
    /// Distance from (x, y) to the nearest confirmed cell's edge.
    fn seen_gap_m(&self, x: f64, y: f64) -> f64 {
        self.seen_m
            .iter()
            .map(|&[sx, sy]| (sx - x).hypot(sy - y) - 0.5 * self.cell_m)
            .fold(f64::INFINITY, f64::min)
    }

    /// Distance from (x, y) to the nearest wall or confirmed cell.
    fn free_m(&self, x: f64, y: f64) -> f64 {
        self.field.distance_m(x, y).min(self.seen_gap_m(x, y))
    }
}

/// `a` then `b`: the pose `b` (in `a`'s frame) in `a`'s parent frame.
fn pose_compose(a: Pose2D, b: Pose2D) -> Pose2D {
    let (s, c) = a.yaw_rad.sin_cos();
    Pose2D::new(
        a.x_m + c * b.x_m - s * b.y_m,
        a.y_m + s * b.x_m + c * b.y_m,
        a.yaw_rad + b.yaw_rad,
    )
}

/// The laser's returns (taken at `map_from_laser`) that could be movers, in the map frame:
/// off the floor plan's walls and off the obstacle layer's confirmed cells.
fn mover_candidates(
    seen: &SeenInputs<'_>,
    scan: &LaserScan,
    map_from_laser: Pose2D,
    min_map_gap_m: f64,
) -> Vec<[f64; 2]> {
    let (ls, lc) = map_from_laser.yaw_rad.sin_cos();
    (0..scan.ranges_m.len())
        .filter(|&i| scan.is_return(i))
        .filter_map(|i| {
            let r = f64::from(scan.ranges_m[i]);
            let (bs, bc) = f64::from(scan.beam_angle_rad(i)).sin_cos();
            let (lx, ly) = (r * bc, r * bs);
            let (x, y) = (
                map_from_laser.x_m + lc * lx - ls * ly,
                map_from_laser.y_m + ls * lx + lc * ly,
            );
            movers::off_the_plan(
                min_map_gap_m,
                seen.field.distance_m(x, y),
                seen.seen_gap_m(x, y),
            )
            .then_some([x, y])
        })
        .collect()
}

/// Arrived within this of the waiting spot beside the path.
const WAIT_SPOT_REACHED_M: f64 = 0.1;
/// Top speed on the way to the waiting spot.
const WAIT_SPOT_SPEED_MPS: f64 = 0.3;

/// The command (v, ω) that takes the robot from `pose` to the waiting spot `spot` beside its
/// path, turning on the spot first where it faces well away from it, and stands there.
fn to_wait_spot(pose: Pose2D, spot: (f64, f64), limits: &Limits) -> (f64, f64) {
    let (dx, dy) = (spot.0 - pose.x_m, spot.1 - pose.y_m);
    let d = dx.hypot(dy);
    if d <= WAIT_SPOT_REACHED_M {
        return (0.0, 0.0);
    }
    let error = protocol::normalize_angle(dy.atan2(dx) - pose.yaw_rad);
    let w = (1.5 * error).clamp(-limits.max_turn_radps, limits.max_turn_radps);
    if error.abs() > 0.6 {
        return (0.0, w);
    }
    let v = (0.8 * d).min(WAIT_SPOT_SPEED_MPS).min(limits.max_speed_mps);
    (v, w)
}

/// `command` (v, ω) with its forward speed capped at `max_speed_mps`, on the same arc.
fn capped((v, w): (f64, f64), max_speed_mps: Option<f64>) -> (f64, f64) {
    match max_speed_mps {
        Some(cap) if v > cap => (cap, if v > 0.0 { w * cap / v } else { w }),
        _ => (v, w),
    }
}

/// Whether two statuses differ in what a listener cares about (the state or the kind of stop
/// reason; a stale intention's growing age is not a change).
fn same_condition(
    a: (AgentState, Option<&StopReason>),
    b: (AgentState, Option<&StopReason>),
) -> bool {
    a.0 == b.0 && a.1.map(std::mem::discriminant) == b.1.map(std::mem::discriminant)
}

fn grid_of(map: MapGrid) -> Result<(MapRef, OccupancyGrid), NodeError> {
    let meta = map.meta;
    let map_ref = meta.map_ref();
    let grid = OccupancyGrid::new(
        meta.width_cells,
        meta.height_cells,
        meta.resolution_m,
        meta.origin,
        map.cells,
    )
    .map_err(|e| NodeError::Map {
        name: meta.name.to_string(),
        reason: e.to_string(),
    })?;
    Ok((map_ref, grid))
}

/// Runs the agent until `shutdown` completes, then commands a stop and leaves the session.
///
/// # Errors
/// [`NodeError`] for an invalid configuration, a model that cannot be loaded, or Zenoh failures
/// at start-up; messages that fail to decode at run time are logged and skipped.
pub async fn run(
    options: NodeOptions,
    shutdown: impl Future<Output = ()>,
) -> Result<(), NodeError> {
    let NodeOptions {
        robot_id,
        config,
        zenoh,
        record,
    } = options;
    config.validate()?;
    let map_name = config.map.clone().ok_or(ConfigError::Invalid {
        field: "map",
        value: "(none)".into(),
        reason: "give --map or `map` in the configuration",
    })?;
    // Before the session: a missing ONNX Runtime or a wrong model is a start-up error.
    let controller = make_controller(&config)?;
    // Before the session too: a log that cannot be created is a start-up error.
    let mut recorder = record
        .map(|r| Recorder::start(&r.path, r.log))
        .transpose()?;
    let session = zenoh::open(zenoh)
        .await
        .map_err(zenoh_err("open the session"))?;
    let result = run_in_session(
        &session,
        &robot_id,
        &map_name,
        config,
        controller,
        &mut recorder,
        shutdown,
    )
    .await;
    if let Err(e) = session.close().await {
        tracing::warn!("closing the zenoh session: {e}");
    }
    if let Some(r) = recorder {
        match r.finish() {
            Ok(path) => tracing::info!(path = %path.display(), "run log written"),
            // The run's own error is the one to report.
            Err(e) if result.is_err() => tracing::warn!("{e}"),
            Err(e) => return Err(e.into()),
        }
    }
    result
}

async fn run_in_session(
    session: &Session,
    robot_id: &RobotId,
    map_name: &protocol::MapName,
    config: AgentConfig,
    controller: Box<dyn Controller>,
    recorder: &mut Option<Recorder>,
    shutdown: impl Future<Output = ()>,
) -> Result<(), NodeError> {
    let site = config.site.clone();
    let key = |topic| keys::robot(&site, robot_id, topic);
    let clock = Clock::new();
    let token = session
        .liveliness()
        .declare_token(key(RobotTopic::Alive))
        .await
        .map_err(zenoh_err("declare the liveliness token"))?;
    let pose_pub = session
        .declare_publisher(key(RobotTopic::Pose))
        .await
        .map_err(zenoh_err("declare the pose publisher"))?;
    let status_pub = session
        .declare_publisher(key(RobotTopic::Status))
        .await
        .map_err(zenoh_err("declare the status publisher"))?;
    let cmd_pub = session
        .declare_publisher(key(RobotTopic::CmdVel))
        .await
        .map_err(zenoh_err("declare the cmd_vel publisher"))?;
    // Ring channels keep the newest samples: a slow cycle skips old data instead of queueing it.
    let odom_sub = session
        .declare_subscriber(key(RobotTopic::Odom))
        .with(RingChannel::new(ODOM_HISTORY))
        .await
        .map_err(zenoh_err("subscribe odom"))?;
    let scan_sub = session
        .declare_subscriber(key(RobotTopic::Scan))
        .with(RingChannel::new(4))
        .await
        .map_err(zenoh_err("subscribe scan"))?;
    let camera_sub = session
        .declare_subscriber(key(RobotTopic::Camera))
        .with(RingChannel::new(1))
        .await
        .map_err(zenoh_err("subscribe camera"))?;
    let intention_sub = session
        .declare_subscriber(key(RobotTopic::Intention))
        .with(RingChannel::new(4))
        .await
        .map_err(zenoh_err("subscribe intention"))?;

    let mut status_seq = 0u64;
    let starting = AgentStatus {
        header: Header::new(status_seq, clock.stamp_ns(Instant::now())),
        state: AgentState::Starting,
        stop_reason: None,
        controller: config.controller,
        map: None,
        localized: false,
        recovering: false,
        backing_up: false,
        rotating_in_place: false,
        giving_way: false,
    };
    protocol::zenoh_io::publish(&status_pub, &starting).await?;
    tracing::info!(robot = %robot_id, site = %site, map = %map_name, controller = %config.controller, "agent starting");

    tokio::pin!(shutdown);
    let fetch_timeout = Duration::from_millis(config.map_fetch_timeout_ms);
    let mut backoff = Duration::from_millis(100);
    let map = loop {
        let fetch =
            map_core::fetch_map(session, &site, map_name, config.map_version, fetch_timeout);
        tokio::select! {
            () = &mut shutdown => {
                tracing::info!("shutdown before the map arrived");
                token.undeclare().await.map_err(zenoh_err("undeclare the liveliness token"))?;
                return Ok(());
            }
            answer = fetch => match answer {
                Ok(map) => break map,
                Err(e) => {
                    tracing::warn!(map = %map_name, "map store did not deliver the map ({e}); retrying in {backoff:?}");
                }
            }
        }
        tokio::select! {
            () = &mut shutdown => {
                token.undeclare().await.map_err(zenoh_err("undeclare the liveliness token"))?;
                return Ok(());
            }
            () = tokio::time::sleep(backoff) => {}
        }
        backoff = (backoff * 2).min(Duration::from_secs(5));
    };
    let content_hash = map.meta.content_hash.clone();
    let (map_ref, grid) = grid_of(map)?;
    tracing::info!(map = %map_ref.name, version = map_ref.version, "map received");
    record(recorder, || {
        LogMessage::Map(fleet_log::MapInfo {
            stamp_ns: clock.stamp_ns(Instant::now()),
            name: map_ref.name.to_string(),
            version: map_ref.version,
            path: None,
            content_hash: Some(content_hash),
            initial_pose: config.localization.initial_pose,
            initial_covariance: config
                .localization
                .initial_pose
                .map(|_| config.localization.initial_covariance()),
            source: "robot-agent".into(),
        })
    });
    if let Some(r) = recorder.as_mut() {
        match serde_json::to_value(&config) {
            Ok(value) => r.record(LogMessage::AgentConfig {
                stamp_ns: clock.stamp_ns(Instant::now()),
                config: value,
            }),
            Err(e) => tracing::warn!("the configuration is not recorded: {e}"),
        }
    }
    let mut agent = Supervisor::new(config.clone(), map_ref, &grid, controller)?;
    drop(grid);

    let mut control_tick =
        tokio::time::interval(Duration::from_secs_f64(1.0 / config.control_rate_hz));
    control_tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let mut status_tick =
        tokio::time::interval(Duration::from_secs_f64(1.0 / config.status_rate_hz));
    status_tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let mut cmd_seq = 0u64;
    let mut published: (AgentState, Option<StopReason>) = (AgentState::Starting, None);
    let mut published_recovering = false;
    // What the last published status said of backing off, the rotation shim and the give-way
    // rule.
    let mut published_takeover = (false, false, false);

    loop {
        tokio::select! {
            () = &mut shutdown => break,
            sample = odom_sub.recv_async() => {
                let sample = sample.map_err(zenoh_err("receive odom"))?;
                match protocol::decode_sample::<Odometry>(&sample) {
                    Ok(odom) => {
                        record(recorder, || LogMessage::Odom(odom.clone()));
                        agent.on_odometry(odom);
                    }
                    Err(e) => tracing::warn!("ignoring odom: {e}"),
                }
            }
            sample = scan_sub.recv_async() => {
                let sample = sample.map_err(zenoh_err("receive scan"))?;
                let scan = match protocol::decode_sample::<LaserScan>(&sample) {
                    Ok(scan) => scan,
                    Err(e) => {
                        tracing::warn!("ignoring scan: {e}");
                        continue;
                    }
                };
                record(recorder, || LogMessage::Scan(scan.clone()));
                let now = Instant::now();
                match agent.on_scan(scan, now, clock.stamp_ns(now)) {
                    Ok(Some(pose)) => {
                        protocol::zenoh_io::publish(&pose_pub, &pose).await?;
                        record(recorder, || LogMessage::AmclPose(pose));
                    }
                    Ok(None) => tracing::debug!("scan before any odometry: no pose yet"),
                    Err(e) => tracing::warn!("scan not used for localization: {e}"),
                }
            }
            sample = camera_sub.recv_async() => {
                let sample = sample.map_err(zenoh_err("receive camera"))?;
                match protocol::decode_sample::<CameraFrame>(&sample) {
                    Ok(frame) => {
                        if let Some(r) = recorder.as_mut() {
                            r.record_camera(&frame);
                        }
                        agent.on_camera(frame);
                    }
                    Err(e) => tracing::warn!("ignoring camera frame: {e}"),
                }
            }
            sample = intention_sub.recv_async() => {
                let sample = sample.map_err(zenoh_err("receive intention"))?;
                match protocol::decode_sample::<Intention>(&sample) {
                    Ok(intention) => {
                        record(recorder, || {
                            LogMessage::Intention(fleet_log::intention_without_pixels(&intention))
                        });
                        if let Err(why) = agent.on_intention(intention) {
                            tracing::debug!("intention ignored: {why}");
                        }
                    }
                    Err(e) => tracing::warn!("ignoring intention: {e}"),
                }
            }
            _ = control_tick.tick() => {
                let now = Instant::now();
                let decision = agent.control(now);
                cmd_seq += 1;
                let cmd = CmdVel {
                    header: Header::new(cmd_seq, clock.stamp_ns(now)),
                    v_mps: decision.cmd_v_mps,
                    omega_radps: decision.cmd_omega_radps,
                };
                protocol::zenoh_io::publish(&cmd_pub, &cmd).await?;
                record(recorder, || LogMessage::CmdVel(cmd));
                let condition_changed = !same_condition(
                    (published.0, published.1.as_ref()),
                    (decision.state, decision.stop_reason.as_ref()),
                );
                if condition_changed {
                    match &decision.stop_reason {
                        Some(reason) => tracing::info!(state = ?decision.state, "{reason}"),
                        None => tracing::info!(state = ?decision.state, "state changed"),
                    }
                }
                if decision.recovering != published_recovering {
                    if decision.backing_up {
                        tracing::info!(
                            recoveries = agent.recoveries(),
                            "met face to face: backing straight off"
                        );
                    } else if decision.recovering {
                        tracing::info!(
                            recoveries = agent.recoveries(),
                            "stuck: the dynamic window takes over"
                        );
                    } else {
                        tracing::info!(controller = %agent.active_controller(), "recovered: handed back");
                    }
                }
                let takeover = (decision.backing_up, decision.rotating, decision.giving_way);
                // The status says whether it is recovering, turning in place or giving way, so
                // each hand-over is news too (the operator sees why the robot stands or turns).
                if condition_changed
                    || decision.recovering != published_recovering
                    || takeover != published_takeover
                {
                    status_seq += 1;
                    let status = agent.status(status_seq, clock.stamp_ns(now));
                    protocol::zenoh_io::publish(&status_pub, &status).await?;
                    record(recorder, || LogMessage::AgentStatus(status));
                    published = (decision.state, decision.stop_reason);
                    published_recovering = decision.recovering;
                    published_takeover = takeover;
                }
            }
            _ = status_tick.tick() => {
                status_seq += 1;
                let status = agent.status(status_seq, clock.stamp_ns(Instant::now()));
                protocol::zenoh_io::publish(&status_pub, &status).await?;
            }
        }
    }

    // Leave the base standing still rather than waiting for its command timeout.
    let now = Instant::now();
    let stop = CmdVel {
        header: Header::new(cmd_seq + 1, clock.stamp_ns(now)),
        v_mps: 0.0,
        omega_radps: 0.0,
    };
    protocol::zenoh_io::publish(&cmd_pub, &stop).await?;
    record(recorder, || LogMessage::CmdVel(stop));
    let mut last = agent.status(status_seq + 1, clock.stamp_ns(now));
    last.state = AgentState::Stopped;
    last.stop_reason = Some(StopReason::Commanded);
    protocol::zenoh_io::publish(&status_pub, &last).await?;
    token
        .undeclare()
        .await
        .map_err(zenoh_err("undeclare the liveliness token"))?;
    tracing::info!(robot = %robot_id, "agent stopped");
    Ok(())
}
