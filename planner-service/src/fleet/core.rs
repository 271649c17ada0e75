//! The fleet's decisions over the task book and the robot registry together: what a pose, a
//! status, a departure, a watchdog round or a replan means for robots and tasks.
//!
//! [`Core`] is the one thing the fleet locks (see [`super::Fleet`]): the book and the registry
//! change together under it, so no second lock has an order to get wrong. Like its parts it
//! is plain data in, [`Effect`]s out, with the time passed in, so every rule here is tested
//! without Zenoh and without sleeping.

use std::sync::Arc;
use std::time::Duration;

use planning::{LpeImage, Neighbour};
use protocol::{AgentStatus, PoseEstimate, RobotId, TaskId};

use super::book::{Decision, Effect, TaskBook};
use super::config::FleetConfig;
use super::error::FleetError;
use super::registry::{PoseSeen, RobotRegistry};
use super::store::{StoreError, TaskStore};
use super::types::{IntentionView, NewTask, RobotView, Task};
use super::Now;

/// What one replanning cycle is to do for a pose (sent to a worker process as is).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Cycle {
    pub decision: Decision,
    /// Render the LPE image (the controller reads it, or the dashboard preview is due).
    pub render_lpe: bool,
    /// Send the image to the robot (its controller reads it).
    pub send_lpe: bool,
    /// The other online robots on the robot's map within `[fleet] neighbour_radius_m`, which
    /// its plan keeps clear of.
    #[serde(default)]
    pub neighbours: Vec<Neighbour>,
}

/// Robots online and offline at a watchdog round (before it marked the silent ones).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RobotCounts {
    pub online: usize,
    pub offline: usize,
}

/// The task book and the robot registry (see the module docs).
#[derive(Debug)]
pub struct Core {
    pub book: TaskBook,
    pub registry: RobotRegistry,
    config: FleetConfig,
}

impl Core {
    /// Opens the book on `store`; robots named by unfinished tasks are registered offline
    /// (returned, so the caller starts their workers).
    ///
    /// # Errors
    /// A storage error.
    pub fn open(
        store: Arc<TaskStore>,
        config: FleetConfig,
        now: Now,
    ) -> Result<(Self, Vec<RobotId>), StoreError> {
        let book = TaskBook::open(store, &config, now)?;
        let mut registry = RobotRegistry::new(&config);
        let robots: Vec<RobotId> = book.robots().cloned().collect();
        for r in &robots {
            registry.register(r, now);
        }
        let core = Self {
            book,
            registry,
            config,
        };
        Ok((core, robots))
    }

    #[must_use]
    pub fn config(&self) -> &FleetConfig {
        &self.config
    }

    /// The robot as the API shows it.
    #[must_use]
    pub fn view(&self, id: &RobotId) -> Option<RobotView> {
        let robot = self.registry.get(id)?;
        Some(robot.view(self.book.task_of(id)))
    }

    /// Every robot, sorted by id.
    #[must_use]
    pub fn views(&self) -> Vec<RobotView> {
        let mut out: Vec<RobotView> = self
            .registry
            .iter()
            .map(|r| r.view(self.book.task_of(&r.id)))
            .collect();
        out.sort_by(|a, b| a.id.cmp(&b.id));
        out
    }

    /// A pose arrived: the robot is online; one that came back may take a queued task.
    /// `watched`: someone streams events.
    pub fn pose_arrived(
        &mut self,
        id: &RobotId,
        pose: PoseEstimate,
        now: Now,
        watched: bool,
    ) -> (PoseSeen, Vec<Effect>) {
        let seen = self.registry.saw_pose(id, pose, now, watched);
        let mut effects = Vec::new();
        if seen.event_due {
            effects.extend(self.view(id).map(Effect::Robot));
        }
        if seen.came_back {
            tracing::info!(robot = %id, "robot online");
            effects.extend(self.book.dispatch(&self.registry, now));
        }
        (seen, effects)
    }

    /// A status arrived; `true` when the robot is new (the caller starts its worker).
    pub fn status_arrived(
        &mut self,
        id: &RobotId,
        status: AgentStatus,
        now: Now,
    ) -> (bool, Vec<Effect>) {
        let (new, changed) = self.registry.saw_status(id, status, now);
        let effects = if changed {
            self.view(id).map(Effect::Robot).into_iter().collect()
        } else {
            Vec::new()
        };
        (new, effects)
    }

    /// The robot is gone (`reason`): offline, and its task paused.
    pub fn robot_left(&mut self, id: &RobotId, reason: &str, now: Now) -> Vec<Effect> {
        let Some(robot) = self.registry.set_offline(id) else {
            return Vec::new();
        };
        let mut effects = vec![Effect::Robot(robot.view(self.book.task_of(id)))];
        effects.extend(self.book.pause(id, reason, now));
        effects
    }

    /// One watchdog round: robots silent for `robot_timeout_ms` go offline (pausing their
    /// task), tasks paused for `pause_timeout_ms` fail, queued tasks go to free robots.
    pub fn watchdog(&mut self, now: Now) -> (RobotCounts, Vec<Effect>) {
        let timeout = Duration::from_millis(self.config.robot_timeout_ms);
        // A robot that is offline already only counts when it still has a task that has not
        // been paused (after a restart, say): its silence must pause that task.
        let silent: Vec<RobotId> = self
            .registry
            .silent(now.at, timeout)
            .filter(|r| r.online || self.book.awaits(&r.id))
            .map(|r| r.id.clone())
            .collect();
        let (online, offline) = self.registry.counts();
        let mut effects = Vec::new();
        for id in silent {
            let ms = timeout.as_millis();
            let reason = format!("robot {id} sent no pose for over {ms} ms");
            effects.extend(self.robot_left(&id, &reason, now));
        }
        effects.extend(self.book.expire(&self.registry, now));
        // Robots also become free by localizing (a status), which triggers nothing else.
        effects.extend(self.book.dispatch(&self.registry, now));
        (RobotCounts { online, offline }, effects)
    }

    /// Creates a task whose goals the caller checked on the map.
    ///
    /// # Errors
    /// As [`TaskBook::create`].
    pub fn create(
        &mut self,
        req: NewTask,
        map_version: u32,
        now: Now,
    ) -> Result<(Task, Vec<Effect>), FleetError> {
        self.book.create(req, map_version, &self.registry, now)
    }

    /// Cancels a task.
    ///
    /// # Errors
    /// As [`TaskBook::cancel`].
    pub fn cancel(&mut self, id: &TaskId, now: Now) -> Result<(Task, Vec<Effect>), FleetError> {
        self.book.cancel(id, &self.registry, now)
    }

    /// The start of a replanning cycle for a pose of a known robot: its task brought up to
    /// date, and what to render.
    pub fn begin_cycle(
        &mut self,
        id: &RobotId,
        pose: &PoseEstimate,
        now: Now,
        watched: bool,
    ) -> (Cycle, Vec<Effect>) {
        let Some(robot) = self.registry.get(id) else {
            let idle = Cycle {
                decision: Decision::Idle,
                render_lpe: false,
                send_lpe: false,
                neighbours: Vec::new(),
            };
            return (idle, Vec::new());
        };
        let send_lpe = robot.wants_lpe();
        let render_lpe = self.registry.lpe_due(id, now.at, watched);
        let (decision, effects) = self.book.advance(id, pose, &self.registry, now);
        let neighbours = if matches!(decision, Decision::Plan { .. }) {
            self.neighbours(id, pose)
        } else {
            Vec::new()
        };
        let cycle = Cycle {
            decision,
            render_lpe,
            send_lpe,
            neighbours,
        };
        (cycle, effects)
    }

    /// The other online robots on `pose`'s map within `[fleet] neighbour_radius_m` of it.
    fn neighbours(&self, id: &RobotId, pose: &PoseEstimate) -> Vec<Neighbour> {
        let radius_m = self.config.neighbour_radius_m;
        if radius_m <= 0.0 {
            return Vec::new();
        }
        self.registry
            .iter()
            .filter(|r| r.online && &r.id != id)
            .filter_map(|r| {
                let p = r.pose.as_ref()?;
                (p.map.name == pose.map.name && p.pose.distance_m(&pose.pose) <= radius_m)
                    .then_some(Neighbour {
                        pose: p.pose,
                        vx_mps: r.velocity_mps.0,
                        vy_mps: r.velocity_mps.1,
                    })
            })
            .collect()
    }

    /// The end of a cycle that found a path: the intention that went out (if it did) and the
    /// LPE image it rendered.
    pub fn planned(
        &mut self,
        id: &RobotId,
        sent: Option<IntentionView>,
        lpe: Option<LpeImage>,
        now: Now,
    ) {
        self.book.plan_succeeded(id);
        if let Some(l) = lpe {
            self.registry.set_lpe(id, l, now.at);
        }
        if let Some(view) = sent {
            self.registry.set_intention(id, view);
        }
    }

    /// The end of a cycle that found no path to goal `goal` of `task` (the robot was sent a
    /// stop); after `max_plan_failures` in a row the task fails.
    pub fn plan_failed(
        &mut self,
        id: &RobotId,
        sent: Option<IntentionView>,
        task: &TaskId,
        goal: usize,
        error: &str,
        now: Now,
    ) -> Vec<Effect> {
        if let Some(view) = sent {
            self.registry.set_intention(id, view);
        }
        self.book
            .plan_failed(id, task, goal, error, &self.registry, now)
    }

    /// An intention that answers no plan went out (a stop).
    pub fn intention_sent(&mut self, id: &RobotId, view: IntentionView) {
        self.registry.set_intention(id, view);
    }
}
