//! The task book: every unfinished task and which robot works on which, with the task
//! lifecycle (DESIGN §8): create, cancel, dispatch, advance, pause, resume, fail, expire.
//!
//! `queued → assigned → active(goal k) → completed`, or `paused(reason)` while the robot is
//! silent (back to `active` on its next pose), `failed(reason)`, `cancelled`.
//!
//! Plain data in, effects out: a method gets the robots it needs as a [`RobotRegistry`] and
//! the time as [`Now`], writes the change to the [`TaskStore`] (stored first: a change that
//! cannot be stored does not happen) and returns what the rest of the service must do about
//! it as [`Effect`]s. Nothing here publishes, sleeps or reads a clock, so the lifecycle is
//! tested with a real database and no Zenoh.

use std::collections::{BTreeSet, HashMap};
use std::ops::Bound;
use std::sync::Arc;
use std::time::{Duration, Instant};

use planning::{Advance, Goal, GoalProgress};
use protocol::{MapName, PoseEstimate, RobotId, TaskId, TaskState};

use super::config::FleetConfig;
use super::error::FleetError;
use super::registry::RobotRegistry;
use super::store::{StoreError, TaskStore};
use super::types::{NewTask, RobotView, Task, TaskStateKind};
use super::Now;

/// What the service must do after a change.
#[derive(Debug, Clone, PartialEq)]
pub enum Effect {
    /// The task changed and is stored: count it and announce it (Zenoh, live stream).
    /// `before` is its previous state, `None` for a new task.
    Announce {
        task: Task,
        before: Option<TaskStateKind>,
    },
    /// The robot's task ended under it: tell it to stop now rather than at its next pose.
    Stop(RobotId),
    /// A robot changed in a way the dashboard shows.
    Robot(RobotView),
}

/// What a robot's pose means for its task.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Decision {
    /// Plan from the pose to goal `next` of `goals`.
    Plan {
        task: TaskId,
        goals: Vec<Goal>,
        next: usize,
    },
    /// The robot has no task (or its task could not be updated): it stops.
    Idle,
    /// The robot localizes on another map than its task's: the task waits, the robot stops.
    OtherMap,
    /// The pose reached the last goal: the task is completed and the robot free.
    Completed(TaskId),
}

/// A robot's current task.
#[derive(Debug, Clone, PartialEq)]
struct Assignment {
    task: TaskId,
    /// Since when the robot has been gone with this task (the pause timer).
    paused_since: Option<Instant>,
    /// Consecutive replans without a path.
    plan_failures: u32,
}

impl Assignment {
    fn new(task: TaskId) -> Self {
        Self {
            task,
            paused_since: None,
            plan_failures: 0,
        }
    }
}

/// The unfinished tasks and their robots (see the module docs).
#[derive(Debug)]
pub struct TaskBook {
    store: Arc<TaskStore>,
    /// Every unfinished task as stored: the replanning loop reads it here, not from the
    /// database, so "no change" (the common case) costs no transaction.
    live: HashMap<TaskId, Task>,
    /// The queued tasks of `live` per map, oldest first: dispatch walks only these, so its
    /// cost does not grow with a backlog on a map that has no free robot.
    queued: HashMap<MapName, BTreeSet<(u64, TaskId)>>,
    assignments: HashMap<RobotId, Assignment>,
    /// A goal within this distance of the pose is reached.
    goal_tolerance_m: f64,
    /// A task paused for longer fails.
    pause_timeout: Duration,
    /// Replans without a path in a row after which the task fails.
    max_plan_failures: u32,
}

impl TaskBook {
    /// Reads the unfinished tasks back: each robot that had one has it again (a paused one
    /// with its pause timer started `now`), and it resumes when the robot reports.
    ///
    /// # Errors
    /// A storage error.
    pub fn open(store: Arc<TaskStore>, config: &FleetConfig, now: Now) -> Result<Self, StoreError> {
        let mut book = Self {
            store,
            live: HashMap::new(),
            queued: HashMap::new(),
            assignments: HashMap::new(),
            goal_tolerance_m: config.goal_tolerance_m,
            pause_timeout: Duration::from_millis(config.pause_timeout_ms),
            max_plan_failures: config.max_plan_failures,
        };
        for task in book.store.unfinished()? {
            if let Some(robot) = task.state.robot_id() {
                let mut a = Assignment::new(task.id.clone());
                if matches!(task.state, TaskState::Paused { .. }) {
                    a.paused_since = Some(now.at);
                }
                tracing::info!(task = %task.id, robot = %robot, state = %task.kind(), "resuming stored task");
                book.assignments.insert(robot.clone(), a);
            }
            book.cache(task);
        }
        Ok(book)
    }

    /// Robots that have a task, in no particular order.
    pub fn robots(&self) -> impl Iterator<Item = &RobotId> {
        self.assignments.keys()
    }

    /// The task the robot works on.
    #[must_use]
    pub fn task_of(&self, robot: &RobotId) -> Option<&TaskId> {
        self.assignments.get(robot).map(|a| &a.task)
    }

    /// An unfinished task.
    #[must_use]
    pub fn task(&self, id: &TaskId) -> Option<&Task> {
        self.live.get(id)
    }

    /// Whether the robot has a task whose pause timer has not started (so its silence counts).
    #[must_use]
    pub fn awaits(&self, robot: &RobotId) -> bool {
        self.assignments
            .get(robot)
            .is_some_and(|a| a.paused_since.is_none())
    }

    /// Stores a new task: assigned to the requested robot, or queued and dispatched at once.
    /// The goals are checked against the map by the caller.
    ///
    /// # Errors
    /// [`FleetError::NotFound`] for an unknown robot, [`FleetError::Conflict`] for a busy one
    /// or one on another map, a storage error; nothing is stored then.
    pub fn create(
        &mut self,
        req: NewTask,
        map_version: u32,
        robots: &RobotRegistry,
        now: Now,
    ) -> Result<(Task, Vec<Effect>), FleetError> {
        let state = match &req.robot_id {
            Some(r) => {
                self.check_free(r, &req.map, robots)?;
                TaskState::Assigned {
                    robot_id: r.clone(),
                }
            }
            None => TaskState::Queued,
        };
        let task = self.store.create(
            &req.map,
            map_version,
            req.robot_id.clone(),
            req.goals,
            state,
            now.wall_ns,
        )?;
        tracing::info!(task = %task.id, map = %task.map, goals = task.goals.len(), state = %task.kind(), "task created");
        self.cache(task.clone());
        if let Some(r) = req.robot_id {
            self.assignments.insert(r, Assignment::new(task.id.clone()));
        }
        let mut effects = vec![Effect::Announce {
            task: task.clone(),
            before: None,
        }];
        if task.state != TaskState::Queued {
            return Ok((task, effects));
        }
        effects.extend(self.dispatch(robots, now));
        let task = self.live.get(&task.id).cloned().unwrap_or(task);
        Ok((task, effects))
    }

    fn check_free(
        &self,
        id: &RobotId,
        map: &MapName,
        robots: &RobotRegistry,
    ) -> Result<(), FleetError> {
        let robot = robots.get(id).ok_or_else(|| FleetError::NotFound {
            what: "robot",
            id: id.to_string(),
        })?;
        if let Some(t) = self.task_of(id) {
            return Err(FleetError::Conflict(format!(
                "robot {id} is busy with task {t}"
            )));
        }
        match &robot.pose {
            Some(p) if &p.map.name != map => Err(FleetError::Conflict(format!(
                "robot {id} localizes on map {}, not {map}",
                p.map.name
            ))),
            _ => Ok(()),
        }
    }

    /// Cancels a task that has not ended; its robot is told to stop and is free again.
    ///
    /// # Errors
    /// [`FleetError::NotFound`], [`FleetError::Conflict`] when the task already ended, a
    /// storage error.
    pub fn cancel(
        &mut self,
        id: &TaskId,
        robots: &RobotRegistry,
        now: Now,
    ) -> Result<(Task, Vec<Effect>), FleetError> {
        if !self.live.contains_key(id) {
            return Err(match self.store.get(id)? {
                Some(t) => FleetError::Conflict(format!("task {id} already ended ({})", t.kind())),
                None => not_found(id),
            });
        }
        let mut effects = Vec::new();
        self.change(id, TaskState::Cancelled, None, now, &mut effects)?;
        let task = match effects.last() {
            Some(Effect::Announce { task, .. }) => task.clone(),
            _ => return Err(not_found(id)),
        };
        let robot = self
            .assignments
            .iter()
            .find(|(_, a)| &a.task == id)
            .map(|(r, _)| r.clone());
        if let Some(robot) = robot {
            self.assignments.remove(&robot);
            effects.push(Effect::Stop(robot));
        }
        tracing::info!(task = %id, "task cancelled");
        effects.extend(self.dispatch(robots, now));
        Ok((task, effects))
    }

    /// Gives queued tasks, oldest first, to the nearest free robot on their map: online,
    /// localized, without a task (ties go to the smaller id).
    ///
    /// Costs O(maps × robots) plus O(log n) per task assigned, whatever the backlog: a map's
    /// queue is walked only while a robot on it is free.
    pub fn dispatch(&mut self, robots: &RobotRegistry, now: Now) -> Vec<Effect> {
        let mut effects = Vec::new();
        let mut maps: Vec<MapName> = self.queued.keys().cloned().collect();
        maps.sort();
        for map in maps {
            let mut after: Option<(u64, TaskId)> = None;
            loop {
                let next = self.queued.get(&map).and_then(|q| {
                    let lower = after.as_ref().map_or(Bound::Unbounded, Bound::Excluded);
                    q.range((lower, Bound::Unbounded)).next().cloned()
                });
                let Some(key) = next else {
                    break;
                };
                let id = key.1.clone();
                after = Some(key);
                let Some(first) = self.live.get(&id).and_then(|t| t.goals.first()) else {
                    continue;
                };
                let Some(robot) = robots
                    .iter()
                    .filter(|r| !self.assignments.contains_key(&r.id))
                    .filter_map(|r| Some((r.distance_on(&map, first)?, &r.id)))
                    .min_by(|a, b| a.0.total_cmp(&b.0).then_with(|| a.1.cmp(b.1)))
                    .map(|(_, r)| r.clone())
                else {
                    // No robot on this map is free: the rest of its queue waits too.
                    break;
                };
                let state = TaskState::Assigned {
                    robot_id: robot.clone(),
                };
                match self.change(&id, state, Some(&robot), now, &mut effects) {
                    Ok(_) => {
                        tracing::info!(task = %id, robot = %robot, "task assigned");
                        self.assignments.insert(robot, Assignment::new(id));
                    }
                    Err(e) => tracing::error!(task = %id, "cannot assign: {e}"),
                }
            }
        }
        effects
    }

    /// Brings the robot's task up to date with its pose: starts it, resumes it when paused,
    /// moves past reached goals (within `goal_tolerance_m`), completes it after the last one.
    pub fn advance(
        &mut self,
        robot: &RobotId,
        pose: &PoseEstimate,
        robots: &RobotRegistry,
        now: Now,
    ) -> (Decision, Vec<Effect>) {
        let Some(a) = self.assignments.get_mut(robot) else {
            return (Decision::Idle, Vec::new());
        };
        // The robot reports: whatever its task does next, it is not gone.
        a.paused_since = None;
        let id = a.task.clone();
        let Some(task) = self.live.get(&id) else {
            // An assignment always names a live task; a stale one just goes.
            self.assignments.remove(robot);
            return (Decision::Idle, Vec::new());
        };
        if pose.map.name != task.map {
            tracing::warn!(robot = %robot, task = %id, "robot localizes on {}, task is on {}", pose.map.name, task.map);
            return (Decision::OtherMap, Vec::new());
        }
        let progress = GoalProgress::new(&task.goals, task.goal_index().unwrap_or(0) as usize);
        let next = match progress.advance(pose.pose, self.goal_tolerance_m) {
            Advance::Done => {
                let effects = self.end(robot, &id, TaskState::Completed, robots, now);
                return (Decision::Completed(id), effects);
            }
            Advance::Heading { index, .. } => index,
        };
        let goals = task.goals.clone();
        let state = TaskState::Active {
            robot_id: robot.clone(),
            goal_index: u32::try_from(next).unwrap_or(u32::MAX),
        };
        let mut effects = Vec::new();
        match self.change(&id, state, None, now, &mut effects) {
            Ok(_) => (
                Decision::Plan {
                    task: id,
                    goals,
                    next,
                },
                effects,
            ),
            Err(e) => {
                tracing::error!(task = %id, "cannot update task: {e}");
                (Decision::Idle, effects)
            }
        }
    }

    /// The robot is gone (silent or left): its assigned or active task pauses with `reason`
    /// and its pause timer starts.
    pub fn pause(&mut self, robot: &RobotId, reason: &str, now: Now) -> Vec<Effect> {
        let Some(a) = self.assignments.get_mut(robot) else {
            return Vec::new();
        };
        a.paused_since.get_or_insert(now.at);
        let id = a.task.clone();
        let state = match self.live.get(&id).map(|t| &t.state) {
            Some(TaskState::Assigned { robot_id }) => TaskState::Paused {
                robot_id: robot_id.clone(),
                goal_index: 0,
                reason: reason.to_string(),
            },
            Some(TaskState::Active {
                robot_id,
                goal_index,
            }) => TaskState::Paused {
                robot_id: robot_id.clone(),
                goal_index: *goal_index,
                reason: reason.to_string(),
            },
            _ => return Vec::new(),
        };
        let mut effects = Vec::new();
        match self.change(&id, state, None, now, &mut effects) {
            Ok(true) => tracing::warn!(task = %id, robot = %robot, "task paused: {reason}"),
            Ok(false) => {}
            Err(e) => tracing::error!(task = %id, "cannot pause: {e}"),
        }
        effects
    }

    /// Fails the paused tasks whose robot stayed away longer than `pause_timeout_ms` and
    /// frees those robots.
    pub fn expire(&mut self, robots: &RobotRegistry, now: Now) -> Vec<Effect> {
        let pause_timeout = self.pause_timeout;
        let expired: Vec<(RobotId, TaskId)> = self
            .assignments
            .iter()
            .filter(|(_, a)| {
                a.paused_since
                    .is_some_and(|t| now.at.duration_since(t) > pause_timeout)
            })
            .map(|(r, a)| (r.clone(), a.task.clone()))
            .collect();
        if expired.is_empty() {
            return Vec::new();
        }
        let mut effects = Vec::new();
        for (robot, id) in expired {
            let secs = pause_timeout.as_secs();
            let reason = format!("robot {robot} did not come back within {secs} s");
            let paused = self
                .live
                .get(&id)
                .is_some_and(|t| matches!(t.state, TaskState::Paused { .. }));
            if paused {
                let failed = TaskState::Failed {
                    reason: reason.clone(),
                };
                match self.change(&id, failed, None, now, &mut effects) {
                    Ok(_) => tracing::warn!(task = %id, "task failed: {reason}"),
                    Err(e) => tracing::error!(task = %id, "cannot fail: {e}"),
                }
            }
            self.release(&robot, &id);
        }
        effects.extend(self.dispatch(robots, now));
        effects
    }

    /// A replan for the robot's task found a path: its failure count starts over.
    pub fn plan_succeeded(&mut self, robot: &RobotId) {
        if let Some(a) = self.assignments.get_mut(robot) {
            a.plan_failures = 0;
        }
    }

    /// A replan to goal `goal` of `task` found no path (`error`); after `max_plan_failures`
    /// in a row the task fails and the robot is free.
    pub fn plan_failed(
        &mut self,
        robot: &RobotId,
        task: &TaskId,
        goal: usize,
        error: &str,
        robots: &RobotRegistry,
        now: Now,
    ) -> Vec<Effect> {
        let max_failures = self.max_plan_failures;
        let Some(a) = self.assignments.get_mut(robot).filter(|a| &a.task == task) else {
            return Vec::new();
        };
        a.plan_failures += 1;
        if a.plan_failures < max_failures {
            return Vec::new();
        }
        let reason = format!("no path to goal {goal} after {max_failures} tries: {error}");
        self.fail(robot, task, reason, robots, now)
    }

    /// Fails the robot's task with `reason` and frees the robot.
    pub fn fail(
        &mut self,
        robot: &RobotId,
        task: &TaskId,
        reason: String,
        robots: &RobotRegistry,
        now: Now,
    ) -> Vec<Effect> {
        self.end(robot, task, TaskState::Failed { reason }, robots, now)
    }

    /// Ends a task (completed or failed), frees its robot and gives it the next queued task.
    fn end(
        &mut self,
        robot: &RobotId,
        id: &TaskId,
        state: TaskState,
        robots: &RobotRegistry,
        now: Now,
    ) -> Vec<Effect> {
        let mut effects = Vec::new();
        // A task that already ended (cancelled meanwhile) stays as it ended.
        if self.live.contains_key(id) {
            let kind = TaskStateKind::of(&state);
            match self.change(id, state, None, now, &mut effects) {
                Ok(_) => tracing::info!(task = %id, robot = %robot, state = %kind, "task ended"),
                Err(e) => tracing::error!(task = %id, "cannot end task: {e}"),
            }
        }
        self.release(robot, id);
        effects.extend(self.dispatch(robots, now));
        effects
    }

    fn release(&mut self, robot: &RobotId, id: &TaskId) {
        if self.assignments.get(robot).is_some_and(|a| &a.task == id) {
            self.assignments.remove(robot);
        }
    }

    /// Moves a live task to `state` (and to `robot`, when given): stored first, then cached
    /// and announced. `false`: it is in that state already (no transaction, no copy: the
    /// replanning loop's common case).
    fn change(
        &mut self,
        id: &TaskId,
        state: TaskState,
        robot: Option<&RobotId>,
        now: Now,
        effects: &mut Vec<Effect>,
    ) -> Result<bool, FleetError> {
        let current = self.live.get(id).ok_or_else(|| not_found(id))?;
        if current.state == state {
            return Ok(false);
        }
        let before = current.kind();
        let mut next = current.clone();
        if let Some(r) = robot {
            next.robot_id = Some(r.clone());
        }
        next.set_state(state, now.wall_ns);
        self.store.replace(&next).map_err(|e| match e {
            StoreError::NotFound(_) => not_found(id),
            other => FleetError::Store(other),
        })?;
        self.uncache(id);
        if !next.state.is_terminal() {
            self.cache(next.clone());
        }
        effects.push(Effect::Announce {
            task: next,
            before: Some(before),
        });
        Ok(true)
    }

    /// Keeps an unfinished task in `live` (and in its map's queue while it is queued).
    fn cache(&mut self, task: Task) {
        self.uncache(&task.id);
        if task.state == TaskState::Queued {
            self.queued
                .entry(task.map.clone())
                .or_default()
                .insert((task.created_ns, task.id.clone()));
        }
        self.live.insert(task.id.clone(), task);
    }

    /// Forgets a task that ended (or is about to be cached again).
    fn uncache(&mut self, id: &TaskId) {
        let Some(old) = self.live.remove(id) else {
            return;
        };
        if old.state == TaskState::Queued {
            if let Some(q) = self.queued.get_mut(&old.map) {
                q.remove(&(old.created_ns, old.id));
                if q.is_empty() {
                    self.queued.remove(&old.map);
                }
            }
        }
    }
}

fn not_found(id: &TaskId) -> FleetError {
    FleetError::NotFound {
        what: "task",
        id: id.to_string(),
    }
}
