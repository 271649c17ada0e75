//! The robot registry: what the service knows about each robot it has heard of: online or not,
//! when it was last heard, its pose estimate and status, the last intention it was sent and the
//! samples the dashboard shows (camera frame, LPE image).
//!
//! Plain data: every method takes the time it needs, nothing here blocks, publishes or spawns.
//! Which robot has which task is the task book's business ([`super::book`]); a view of a robot
//! is given its task by the caller.

use std::collections::HashMap;
use std::sync::Arc;
use std::time::{Duration, Instant};

use planning::{Goal, LpeImage};
use protocol::{AgentStatus, Image, MapName, PoseEstimate, RobotId, TaskId};

use super::config::FleetConfig;
use super::types::{IntentionView, PoseView, RobotView, StatusView};
use super::Now;

/// Two poses further apart than this (by their stamps) give no velocity.
pub const VELOCITY_MAX_GAP_NS: u64 = 1_000_000_000;

/// The smoothed velocity after `pose`, from the one before (`last`) and the velocity so far:
/// half the new step's, half the old; 0 after a gap, a jump to another map or a first pose.
fn velocity_after(last: Option<&PoseEstimate>, pose: &PoseEstimate, old: (f64, f64)) -> (f64, f64) {
    let Some(last) = last.filter(|l| l.map == pose.map) else {
        return (0.0, 0.0);
    };
    let dt_ns = match pose.header.stamp_ns.saturating_sub(last.header.stamp_ns) {
        // The same stamp again (or an older one): nothing new to measure.
        0 => return old,
        gap if gap > VELOCITY_MAX_GAP_NS => return (0.0, 0.0),
        dt => dt,
    };
    #[allow(clippy::cast_precision_loss)]
    let dt_s = dt_ns as f64 * 1e-9;
    let step = (
        (pose.pose.x_m - last.pose.x_m) / dt_s,
        (pose.pose.y_m - last.pose.y_m) / dt_s,
    );
    (0.5 * (old.0 + step.0), 0.5 * (old.1 + step.1))
}

/// One robot as the service knows it.
#[derive(Debug, Clone)]
pub struct Robot {
    pub id: RobotId,
    pub online: bool,
    /// When the robot last sent a pose (or was first heard of).
    pub last_seen: Instant,
    pub last_seen_ns: u64,
    pub pose: Option<PoseEstimate>,
    /// Velocity in the map frame (m/s) from its last poses, smoothed; 0 until two poses on
    /// one map came less than [`VELOCITY_MAX_GAP_NS`] apart.
    pub velocity_mps: (f64, f64),
    pub status: Option<AgentStatus>,
    /// The last intention it was sent, without its image.
    pub intention: Option<IntentionView>,
    lpe: Option<Arc<LpeImage>>,
    lpe_at: Option<Instant>,
    camera: Option<Arc<Image>>,
    camera_at: Option<Instant>,
    /// When a robot event last went to the live stream.
    last_event: Option<Instant>,
}

impl Robot {
    fn new(id: RobotId, now: Instant) -> Self {
        Self {
            id,
            online: false,
            last_seen: now,
            last_seen_ns: 0,
            pose: None,
            velocity_mps: (0.0, 0.0),
            status: None,
            intention: None,
            lpe: None,
            lpe_at: None,
            camera: None,
            camera_at: None,
            last_event: None,
        }
    }

    /// The robot as the API shows it, with the task the book gives it.
    #[must_use]
    pub fn view(&self, task: Option<&TaskId>) -> RobotView {
        RobotView {
            id: self.id.clone(),
            online: self.online,
            last_seen_ns: self.last_seen_ns,
            map: self.pose.as_ref().map(|p| p.map.clone()),
            pose: self.pose.as_ref().map(PoseView::from),
            status: self.status.as_ref().map(StatusView::from),
            task_id: task.cloned(),
            intention: self.intention.clone(),
        }
    }

    /// Whether the robot's controller reads LPE images (so every intention carries one).
    #[must_use]
    pub fn wants_lpe(&self) -> bool {
        self.status
            .as_ref()
            .is_some_and(|s| s.controller.reads_lpe())
    }

    /// How far the robot is from `goal` if it could start a task on `map` now: online,
    /// localized (or not saying) and with a pose on that map.
    #[must_use]
    pub fn distance_on(&self, map: &MapName, goal: &Goal) -> Option<f64> {
        if !self.online || self.status.as_ref().is_some_and(|s| !s.localized) {
            return None;
        }
        let p = self.pose.as_ref().filter(|p| &p.map.name == map)?;
        Some(goal.distance_m(p.pose))
    }
}

/// What a pose changed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PoseSeen {
    /// The robot was not known before: the caller starts its worker.
    pub new: bool,
    /// It was offline (or new) and is online now.
    pub came_back: bool,
    /// A robot event is due on the live stream.
    pub event_due: bool,
}

/// Every robot the service has heard of.
#[derive(Debug, Clone)]
pub struct RobotRegistry {
    robots: HashMap<RobotId, Robot>,
    event_interval: Duration,
    camera_interval: Duration,
    lpe_interval: Duration,
}

impl RobotRegistry {
    #[must_use]
    pub fn new(config: &FleetConfig) -> Self {
        Self {
            robots: HashMap::new(),
            event_interval: Duration::from_millis(config.robot_event_interval_ms),
            camera_interval: Duration::from_millis(config.camera_sample_interval_ms),
            lpe_interval: Duration::from_millis(config.lpe_preview_interval_ms),
        }
    }

    #[must_use]
    pub fn get(&self, id: &RobotId) -> Option<&Robot> {
        self.robots.get(id)
    }

    /// Every robot, in no particular order.
    pub fn iter(&self) -> impl Iterator<Item = &Robot> {
        self.robots.values()
    }

    /// Adds a robot not heard from yet (a stored task names it), offline; `true` if it is new.
    pub fn register(&mut self, id: &RobotId, now: Now) -> bool {
        if self.robots.contains_key(id) {
            return false;
        }
        self.robots
            .insert(id.clone(), Robot::new(id.clone(), now.at));
        true
    }

    /// A pose arrived: the robot is online and seen now. `watched`: someone streams events
    /// (a view clones the robot's path, so none is made for nobody).
    pub fn saw_pose(
        &mut self,
        id: &RobotId,
        pose: PoseEstimate,
        now: Now,
        watched: bool,
    ) -> PoseSeen {
        let new = self.register(id, now);
        let interval = self.event_interval;
        let Some(robot) = self.robots.get_mut(id) else {
            return PoseSeen {
                new,
                came_back: false,
                event_due: false,
            };
        };
        let came_back = !robot.online;
        robot.online = true;
        robot.last_seen = now.at;
        robot.last_seen_ns = now.wall_ns;
        robot.velocity_mps = velocity_after(robot.pose.as_ref(), &pose, robot.velocity_mps);
        robot.pose = Some(pose);
        let event_due = watched
            && robot
                .last_event
                .is_none_or(|t| now.at.duration_since(t) >= interval);
        if event_due {
            robot.last_event = Some(now.at);
        }
        PoseSeen {
            new,
            came_back,
            event_due,
        }
    }

    /// A status arrived; returns (the robot is new, what the dashboard shows changed).
    pub fn saw_status(&mut self, id: &RobotId, status: AgentStatus, now: Now) -> (bool, bool) {
        let new = self.register(id, now);
        let Some(robot) = self.robots.get_mut(id) else {
            return (new, false);
        };
        let changed =
            robot.status.as_ref().map(StatusView::from) != Some(StatusView::from(&status));
        robot.status = Some(status);
        (new, changed)
    }

    /// Marks a known robot offline; `None` for an unknown one. Its last status goes too: a
    /// robot nobody hears from is not `driving`, whatever it said last (the agent's next
    /// status, sent periodically, brings it back).
    pub fn set_offline(&mut self, id: &RobotId) -> Option<&Robot> {
        let robot = self.robots.get_mut(id)?;
        robot.online = false;
        robot.status = None;
        Some(robot)
    }

    /// Robots that sent no pose for longer than `timeout`.
    pub fn silent(&self, now: Instant, timeout: Duration) -> impl Iterator<Item = &Robot> {
        self.robots
            .values()
            .filter(move |r| now.duration_since(r.last_seen) > timeout)
    }

    /// (online, offline) robots.
    #[must_use]
    pub fn counts(&self) -> (usize, usize) {
        let online = self.robots.values().filter(|r| r.online).count();
        (online, self.robots.len() - online)
    }

    /// Whether a camera frame of this known robot is due for the dashboard.
    #[must_use]
    pub fn camera_due(&self, id: &RobotId, now: Instant) -> bool {
        self.robots.get(id).is_some_and(|r| {
            r.camera_at
                .is_none_or(|t| now.duration_since(t) >= self.camera_interval)
        })
    }

    pub fn set_camera(&mut self, id: &RobotId, image: Image, now: Instant) {
        if let Some(r) = self.robots.get_mut(id) {
            r.camera = Some(Arc::new(image));
            r.camera_at = Some(now);
        }
    }

    /// The latest sampled camera frame.
    #[must_use]
    pub fn camera(&self, id: &RobotId) -> Option<Arc<Image>> {
        self.robots.get(id).and_then(|r| r.camera.clone())
    }

    /// Whether this cycle renders the LPE image: always for a robot whose controller reads
    /// it, else at the preview interval while a dashboard watches.
    #[must_use]
    pub fn lpe_due(&self, id: &RobotId, now: Instant, watched: bool) -> bool {
        self.robots.get(id).is_some_and(|r| {
            r.wants_lpe()
                || (watched
                    && r.lpe_at
                        .is_none_or(|t| now.duration_since(t) >= self.lpe_interval))
        })
    }

    pub fn set_lpe(&mut self, id: &RobotId, lpe: LpeImage, now: Instant) {
        if let Some(r) = self.robots.get_mut(id) {
            r.lpe = Some(Arc::new(lpe));
            r.lpe_at = Some(now);
        }
    }

    /// The LPE image of the latest intention that had one.
    #[must_use]
    pub fn lpe(&self, id: &RobotId) -> Option<Arc<LpeImage>> {
        self.robots.get(id).and_then(|r| r.lpe.clone())
    }

    pub fn set_intention(&mut self, id: &RobotId, view: IntentionView) {
        if let Some(r) = self.robots.get_mut(id) {
            r.intention = Some(view);
        }
    }
}
