//! The fleet core: robot registry, delivery tasks and the per-robot replanning loop (DESIGN §2,
//! §8).
//!
//! - Every pose a robot publishes goes to that robot's worker through a one-slot channel: a
//!   worker that is still planning skips the poses that arrived meanwhile and plans from the
//!   newest, so a slow robot or a slow plan never queues up, and workers of different robots run
//!   in parallel on the blocking pool.
//! - A worker replans from the pose to the robot's current goal (hybrid A*, obstacle heuristic
//!   cached per goal), derives the DLM (and the LPE image when the robot's controller needs it or
//!   the dashboard preview is due) and publishes the intention, stamped with the pose it answers.
//!   Goal reached → next goal; last goal → task completed and a `Stop` intention.
//! - Liveliness tokens and a pose watchdog decide who is online; a silent or departed robot's
//!   task is paused with the reason and fails after a grace period; it resumes when the robot
//!   reports again (also after a restart of the service: tasks live in [`store::TaskStore`]).
//! - Every task change is stored first, then published on the task's Zenoh key and on the event
//!   bus the HTTP layer streams to the dashboard.

pub mod metrics;
pub mod store;
pub mod types;

use std::collections::HashMap;
use std::path::Path;
use std::sync::{Arc, Mutex, MutexGuard, PoisonError, Weak};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use map_store::{MapError, MapStore};
use protocol::keys::{self, RobotTopic};
use protocol::{
    AgentStatus, CameraFrame, Header, Image, ImageEncoding, Intention, MapName, Pose2D,
    PoseEstimate, RobotId, SiteId, TaskEvent, TaskId, TaskState, WireMessage,
};
use serde::{Deserialize, Serialize};
use tokio::sync::{broadcast, watch};
use zenoh::pubsub::Subscriber;
use zenoh::sample::{Sample, SampleKind};
use zenoh::{Session, Wait};

use crate::config::ServiceConfig;
use planning::{
    stop_intention, Answer, Endpoint, GoalProgress, IntentionPlanner, LpeImage, MapKey, PlanError,
    PlanningMap,
};

pub use metrics::FleetMetrics;
pub use store::{StoreError, TaskStore};
pub use types::{
    FleetEvent, Goal, HistoryEntry, IntentionView, NewTask, PoseView, RobotView, StatusView, Task,
    TaskFilter, TaskStateKind,
};

/// The `[fleet]` table of the service configuration.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FleetConfig {
    /// A goal counts as reached when the pose estimate is this close to it.
    pub goal_tolerance_m: f64,
    /// A robot that sent no pose for this long is silent: its task pauses.
    pub robot_timeout_ms: u64,
    /// A paused task fails after this long without its robot.
    pub pause_timeout_ms: u64,
    /// Consecutive failed replans after which the task fails.
    pub max_plan_failures: u32,
    /// LPE images for the dashboard (robots whose controller does not use them) at most this often.
    pub lpe_preview_interval_ms: u64,
    /// Camera frames kept for the dashboard at most this often per robot.
    pub camera_sample_interval_ms: u64,
    /// Recent poses kept per robot (the travelled part of the LPE image).
    pub trail_poses: usize,
    /// Robot events on the live stream at most this often per robot.
    pub robot_event_interval_ms: u64,
    /// Events buffered for each live-stream subscriber; a slower one skips events.
    pub event_buffer: usize,
    /// Most goals one task may have.
    pub max_goals: usize,
    /// Spacing of the path sent in an intention (the planner's own is finer); turns in place
    /// are kept whatever the spacing.
    pub intention_path_spacing_m: f64,
}

impl Default for FleetConfig {
    fn default() -> Self {
        Self {
            goal_tolerance_m: 0.35,
            robot_timeout_ms: 2000,
            pause_timeout_ms: 120_000,
            max_plan_failures: 30,
            lpe_preview_interval_ms: 1000,
            camera_sample_interval_ms: 500,
            trail_poses: 60,
            robot_event_interval_ms: 100,
            event_buffer: 1024,
            max_goals: 64,
            intention_path_spacing_m: 0.2,
        }
    }
}

impl FleetConfig {
    /// Checks every value, naming the first bad one.
    ///
    /// # Errors
    /// A sentence naming the field and value.
    pub fn validate(&self) -> Result<(), String> {
        if !(self.intention_path_spacing_m.is_finite() && self.intention_path_spacing_m >= 0.0) {
            return Err(format!(
                "fleet.intention_path_spacing_m = {}: must be zero or positive",
                self.intention_path_spacing_m
            ));
        }
        if !(self.goal_tolerance_m.is_finite() && self.goal_tolerance_m > 0.0) {
            return Err(format!(
                "fleet.goal_tolerance_m = {}: must be positive",
                self.goal_tolerance_m
            ));
        }
        for (field, v) in [
            ("robot_timeout_ms", self.robot_timeout_ms),
            ("pause_timeout_ms", self.pause_timeout_ms),
            ("lpe_preview_interval_ms", self.lpe_preview_interval_ms),
            ("camera_sample_interval_ms", self.camera_sample_interval_ms),
        ] {
            if v == 0 {
                return Err(format!("fleet.{field} = 0: must be positive"));
            }
        }
        for (field, v) in [
            ("max_plan_failures", self.max_plan_failures as usize),
            ("event_buffer", self.event_buffer),
            ("max_goals", self.max_goals),
        ] {
            if v == 0 {
                return Err(format!("fleet.{field} = 0: must be positive"));
            }
        }
        Ok(())
    }
}

/// How the HTTP layer should answer a [`FleetError`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ErrorKind {
    BadRequest,
    NotFound,
    Conflict,
    Internal,
}

/// Why a fleet operation was refused or failed; nothing was changed.
#[derive(Debug, thiserror::Error)]
pub enum FleetError {
    #[error("invalid {field} = {value}: {reason}")]
    Invalid {
        field: String,
        value: String,
        reason: String,
    },
    #[error("no {what} {id}")]
    NotFound { what: &'static str, id: String },
    #[error("{0}")]
    Conflict(String),
    #[error(transparent)]
    Store(#[from] StoreError),
    #[error(transparent)]
    Map(#[from] MapError),
    #[error("planning map {map}: {source}")]
    Planning {
        map: String,
        #[source]
        source: PlanError,
    },
    #[error("invalid configuration: {0}")]
    Config(String),
    #[error("zenoh {action}: {reason}")]
    Zenoh {
        action: &'static str,
        reason: String,
    },
}

impl FleetError {
    #[must_use]
    pub fn kind(&self) -> ErrorKind {
        match self {
            FleetError::Invalid { .. } => ErrorKind::BadRequest,
            FleetError::NotFound { .. }
            | FleetError::Store(StoreError::NotFound(_))
            | FleetError::Map(MapError::NotFound { .. }) => ErrorKind::NotFound,
            FleetError::Conflict(_) => ErrorKind::Conflict,
            _ => ErrorKind::Internal,
        }
    }
}

/// A pose and when it reached the service (for the intention latency).
#[derive(Debug, Clone)]
struct Arrival {
    pose: PoseEstimate,
    received: Instant,
}

/// What the service knows about one robot.
struct Robot {
    id: RobotId,
    online: bool,
    last_seen: Instant,
    last_seen_ns: u64,
    pose: Option<PoseEstimate>,
    status: Option<AgentStatus>,
    task: Option<TaskId>,
    intention: Option<IntentionView>,
    lpe: Option<Arc<LpeImage>>,
    lpe_at: Option<Instant>,
    camera: Option<Arc<Image>>,
    camera_at: Option<Instant>,
    paused_since: Option<Instant>,
    last_event: Option<Instant>,
    poses: watch::Sender<Option<Arrival>>,
}

impl Robot {
    fn view(&self) -> RobotView {
        RobotView {
            id: self.id.clone(),
            online: self.online,
            last_seen_ns: self.last_seen_ns,
            map: self.pose.as_ref().map(|p| p.map.clone()),
            pose: self.pose.as_ref().map(PoseView::from),
            status: self.status.as_ref().map(StatusView::from),
            task_id: self.task.clone(),
            intention: self.intention.clone(),
        }
    }

    fn wants_lpe(&self) -> bool {
        self.status
            .as_ref()
            .is_some_and(|s| s.controller.reads_lpe())
    }
}

/// Per-robot planning state, owned by the robot's worker.
#[derive(Default)]
struct WorkerState {
    /// The robot's intention pipeline, made on its first task.
    pipeline: Option<IntentionPlanner>,
    failures: u32,
}

/// The fleet core (see the module docs); shared as `Arc<Fleet>`.
pub struct Fleet {
    me: Weak<Fleet>,
    site: SiteId,
    session: Session,
    maps: Arc<MapStore>,
    tasks: TaskStore,
    config: ServiceConfig,
    runtime: tokio::runtime::Handle,
    robots: Mutex<HashMap<RobotId, Robot>>,
    planning_maps: Mutex<HashMap<(MapName, u32), Arc<PlanningMap>>>,
    /// Serializes task transitions and robot assignment (always taken before `robots`).
    task_lock: Mutex<()>,
    /// Every unfinished task as stored: the replanning loop reads it here, not from the
    /// database, and a change is written through (under `task_lock`, the only writer).
    live_tasks: Mutex<HashMap<TaskId, Task>>,
    events: broadcast::Sender<FleetEvent>,
    metrics: FleetMetrics,
    shutdown: watch::Sender<bool>,
    subscribers: Mutex<Vec<Subscriber<()>>>,
    background: Mutex<Vec<tokio::task::JoinHandle<()>>>,
    seq: std::sync::atomic::AtomicU64,
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    // A panicking holder leaves plain data behind; the registry stays usable.
    m.lock().unwrap_or_else(PoisonError::into_inner)
}

fn now_ns() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX))
}

fn zenoh_err(action: &'static str) -> impl FnOnce(zenoh::Error) -> FleetError {
    move |e| FleetError::Zenoh {
        action,
        reason: e.to_string(),
    }
}

impl Fleet {
    /// Opens the task database in `data_dir`, subscribes the fleet's Zenoh keys and starts the
    /// replanning loop. Unfinished tasks are picked up again: they resume when their robot
    /// reports, or pause and fail if it does not.
    ///
    /// # Errors
    /// [`FleetError::Config`], [`FleetError::Store`], [`FleetError::Zenoh`].
    pub async fn start(
        session: Session,
        site: SiteId,
        maps: Arc<MapStore>,
        data_dir: &Path,
        config: ServiceConfig,
    ) -> Result<Arc<Fleet>, FleetError> {
        config.fleet.validate().map_err(FleetError::Config)?;
        config
            .planner
            .validate()
            .map_err(|e| FleetError::Config(e.to_string()))?;
        let tasks = TaskStore::open(data_dir)?;
        let (events, _) = broadcast::channel(config.fleet.event_buffer);
        let (shutdown, _) = watch::channel(false);
        let fleet = Arc::new_cyclic(|me| Fleet {
            me: me.clone(),
            site,
            session,
            maps,
            tasks,
            config,
            runtime: tokio::runtime::Handle::current(),
            robots: Mutex::new(HashMap::new()),
            planning_maps: Mutex::new(HashMap::new()),
            task_lock: Mutex::new(()),
            live_tasks: Mutex::new(HashMap::new()),
            events,
            metrics: FleetMetrics::default(),
            shutdown,
            subscribers: Mutex::new(Vec::new()),
            background: Mutex::new(Vec::new()),
            seq: std::sync::atomic::AtomicU64::new(0),
        });
        fleet.resume_stored_tasks()?;
        fleet.subscribe_zenoh().await?;
        let watchdog = tokio::spawn(watchdog(Arc::downgrade(&fleet), fleet.shutdown.subscribe()));
        lock(&fleet.background).push(watchdog);
        tracing::info!(site = %fleet.site, "fleet core running");
        Ok(fleet)
    }

    fn resume_stored_tasks(&self) -> Result<(), FleetError> {
        for task in self.tasks.all()? {
            self.metrics.task_moved(None, task.kind());
        }
        let now = Instant::now();
        let mut robots = lock(&self.robots);
        for task in self.tasks.unfinished()? {
            lock(&self.live_tasks).insert(task.id.clone(), task.clone());
            if let Some(robot_id) = task.state.robot_id() {
                let robot = self.robot_entry(&mut robots, robot_id);
                robot.task = Some(task.id.clone());
                robot.online = false;
                robot.last_seen = now;
                if matches!(task.state, TaskState::Paused { .. }) {
                    robot.paused_since = Some(now);
                }
                tracing::info!(task = %task.id, robot = %robot_id, state = %task.kind(), "resuming stored task");
            }
        }
        Ok(())
    }

    async fn subscribe_zenoh(&self) -> Result<(), FleetError> {
        let mut subs = Vec::new();
        let me = self.me.clone();
        subs.push(
            self.session
                .declare_subscriber(keys::all_robots(&self.site, RobotTopic::Pose))
                .callback(move |s| {
                    if let Some(f) = me.upgrade() {
                        f.on_pose(&s);
                    }
                })
                .await
                .map_err(zenoh_err("subscribe poses"))?,
        );
        let me = self.me.clone();
        subs.push(
            self.session
                .declare_subscriber(keys::all_robots(&self.site, RobotTopic::Status))
                .callback(move |s| {
                    if let Some(f) = me.upgrade() {
                        f.on_status(&s);
                    }
                })
                .await
                .map_err(zenoh_err("subscribe status"))?,
        );
        let me = self.me.clone();
        subs.push(
            self.session
                .declare_subscriber(keys::all_robots(&self.site, RobotTopic::Camera))
                .callback(move |s| {
                    if let Some(f) = me.upgrade() {
                        f.on_camera(&s);
                    }
                })
                .await
                .map_err(zenoh_err("subscribe cameras"))?,
        );
        let me = self.me.clone();
        subs.push(
            self.session
                .liveliness()
                .declare_subscriber(keys::alive_all(&self.site))
                .history(true)
                .callback(move |s| {
                    if let Some(f) = me.upgrade() {
                        f.on_liveliness(&s);
                    }
                })
                .await
                .map_err(zenoh_err("subscribe liveliness"))?,
        );
        lock(&self.subscribers).extend(subs);
        Ok(())
    }

    /// Stops the workers and the watchdog and undeclares the subscriptions.
    pub async fn shutdown(&self) {
        self.shutdown.send_replace(true);
        let subs = std::mem::take(&mut *lock(&self.subscribers));
        for s in subs {
            if let Err(e) = s.undeclare().await {
                tracing::warn!("cannot undeclare subscriber: {e}");
            }
        }
        let handles = std::mem::take(&mut *lock(&self.background));
        for h in handles {
            h.abort();
        }
    }

    #[must_use]
    pub fn site(&self) -> &SiteId {
        &self.site
    }

    #[must_use]
    pub fn maps(&self) -> &Arc<MapStore> {
        &self.maps
    }

    #[must_use]
    pub fn config(&self) -> &ServiceConfig {
        &self.config
    }

    #[must_use]
    pub fn metrics(&self) -> &FleetMetrics {
        &self.metrics
    }

    /// A receiver of every event from now on (the dashboard's live stream).
    #[must_use]
    pub fn subscribe(&self) -> broadcast::Receiver<FleetEvent> {
        self.events.subscribe()
    }

    // ----- queries -------------------------------------------------------------------------

    /// Every known robot, sorted by id.
    #[must_use]
    pub fn robots(&self) -> Vec<RobotView> {
        let robots = lock(&self.robots);
        let mut out: Vec<RobotView> = robots.values().map(Robot::view).collect();
        out.sort_by(|a, b| a.id.cmp(&b.id));
        out
    }

    #[must_use]
    pub fn robot(&self, id: &RobotId) -> Option<RobotView> {
        lock(&self.robots).get(id).map(Robot::view)
    }

    /// PNG of the LPE image of the robot's latest intention that had one.
    #[must_use]
    pub fn robot_lpe_png(&self, id: &RobotId) -> Option<Vec<u8>> {
        let lpe = lock(&self.robots).get(id).and_then(|r| r.lpe.clone())?;
        match lpe.to_png() {
            Ok(png) => Some(png),
            Err(e) => {
                tracing::warn!(robot = %id, "cannot encode LPE image: {e}");
                None
            }
        }
    }

    /// JPEG of the robot's latest sampled camera frame.
    #[must_use]
    pub fn robot_camera_jpeg(&self, id: &RobotId) -> Option<Vec<u8>> {
        let frame = lock(&self.robots).get(id).and_then(|r| r.camera.clone())?;
        match to_jpeg(&frame) {
            Ok(jpeg) => Some(jpeg),
            Err(e) => {
                tracing::warn!(robot = %id, "cannot encode camera frame: {e}");
                None
            }
        }
    }

    /// The task `id`.
    ///
    /// # Errors
    /// [`FleetError::NotFound`] or a storage error.
    pub fn task(&self, id: &TaskId) -> Result<Task, FleetError> {
        self.tasks.get(id)?.ok_or_else(|| FleetError::NotFound {
            what: "task",
            id: id.to_string(),
        })
    }

    /// Tasks matching `filter`, newest first.
    ///
    /// # Errors
    /// A storage error.
    pub fn tasks(&self, filter: &TaskFilter) -> Result<Vec<Task>, FleetError> {
        Ok(self.tasks.list(filter)?)
    }

    // ----- commands ------------------------------------------------------------------------

    /// Validates and stores a new task, then assigns it (to the requested robot, or the
    /// nearest idle robot on the map when one is free).
    ///
    /// # Errors
    /// [`FleetError::Invalid`] for an empty or too long goal list or a goal off the map or in
    /// an obstacle, [`FleetError::NotFound`] for an unknown map or robot,
    /// [`FleetError::Conflict`] for a busy robot or one on another map. Nothing is stored then.
    pub fn create_task(&self, req: NewTask) -> Result<Task, FleetError> {
        let max_goals = self.config.fleet.max_goals;
        if req.goals.is_empty() || req.goals.len() > max_goals {
            return Err(FleetError::Invalid {
                field: "goals".into(),
                value: format!("{} goals", req.goals.len()),
                reason: format!("a task needs 1 to {max_goals} goals"),
            });
        }
        let meta = self.maps.meta(&req.map, None).map_err(|e| match e {
            MapError::NotFound { .. } => FleetError::NotFound {
                what: "map",
                id: req.map.to_string(),
            },
            other => FleetError::Map(other),
        })?;
        let planning = self.planning_map(&req.map, meta.version)?;
        for (i, g) in req.goals.iter().enumerate() {
            let yaw = g.yaw_rad.unwrap_or(0.0);
            let value = match g.yaw_rad {
                Some(y) => format!("({}, {}, {y})", g.x_m, g.y_m),
                None => format!("({}, {})", g.x_m, g.y_m),
            };
            planning
                .check_endpoint(Endpoint::Goal, Pose2D::new(g.x_m, g.y_m, yaw))
                .map_err(|e| FleetError::Invalid {
                    field: format!("goals[{i}]"),
                    value,
                    reason: e.to_string(),
                })?;
        }
        let created = {
            let _guard = lock(&self.task_lock);
            let state = match &req.robot_id {
                Some(r) => {
                    self.check_robot_free(r, &req.map)?;
                    TaskState::Assigned {
                        robot_id: r.clone(),
                    }
                }
                None => TaskState::Queued,
            };
            let task = self.tasks.create(
                &req.map,
                meta.version,
                req.robot_id.clone(),
                req.goals,
                state,
                now_ns(),
            )?;
            lock(&self.live_tasks).insert(task.id.clone(), task.clone());
            if let Some(r) = &req.robot_id {
                if let Some(robot) = lock(&self.robots).get_mut(r) {
                    robot.task = Some(task.id.clone());
                }
            }
            self.metrics.task_moved(None, task.kind());
            self.announce(&task);
            task
        };
        tracing::info!(task = %created.id, map = %created.map, goals = created.goals.len(), state = %created.kind(), "task created");
        if created.kind() == TaskStateKind::Queued {
            self.dispatch();
            return self.task(&created.id);
        }
        Ok(created)
    }

    fn check_robot_free(&self, id: &RobotId, map: &MapName) -> Result<(), FleetError> {
        let robots = lock(&self.robots);
        let robot = robots.get(id).ok_or_else(|| FleetError::NotFound {
            what: "robot",
            id: id.to_string(),
        })?;
        if let Some(t) = &robot.task {
            return Err(FleetError::Conflict(format!(
                "robot {id} is busy with task {t}"
            )));
        }
        if let Some(p) = &robot.pose {
            if &p.map.name != map {
                return Err(FleetError::Conflict(format!(
                    "robot {id} localizes on map {}, not {map}",
                    p.map.name
                )));
            }
        }
        Ok(())
    }

    /// Cancels a task that has not ended; its robot gets a `Stop` intention at once.
    ///
    /// # Errors
    /// [`FleetError::NotFound`], or [`FleetError::Conflict`] when the task already ended.
    pub fn cancel_task(&self, id: &TaskId) -> Result<Task, FleetError> {
        let task = {
            let _guard = lock(&self.task_lock);
            let task = self.set_state(id, |t| {
                if t.state.is_terminal() {
                    Err(FleetError::Conflict(format!(
                        "task {id} already ended ({})",
                        t.kind()
                    )))
                } else {
                    Ok(Some(TaskState::Cancelled))
                }
            })?;
            let stop = {
                let mut robots = lock(&self.robots);
                robots
                    .values_mut()
                    .find(|r| r.task.as_ref() == Some(id))
                    .and_then(|r| {
                        r.task = None;
                        r.paused_since = None;
                        Some((r.id.clone(), r.pose.clone()?))
                    })
            };
            if let Some((robot_id, pose)) = stop {
                self.publish_intention_for(
                    &robot_id,
                    &stop_intention(self.header(), &pose, None, 0),
                    None,
                );
            }
            task
        };
        tracing::info!(task = %id, "task cancelled");
        self.dispatch();
        Ok(task)
    }

    /// Assigns queued tasks (oldest first) to the nearest idle online robot on their map.
    fn dispatch(&self) {
        let _guard = lock(&self.task_lock);
        if self.metrics.tasks_in(TaskStateKind::Queued) <= 0 {
            return;
        }
        // Listing the queue costs a scan of the task table: only worth it with a taker.
        let any_free = lock(&self.robots)
            .values()
            .any(|r| r.online && r.task.is_none() && r.pose.is_some());
        if !any_free {
            return;
        }
        let queued = match self.tasks.list(&TaskFilter {
            state: Some(TaskStateKind::Queued),
            limit: Some(TaskFilter::MAX_LIMIT),
            ..TaskFilter::default()
        }) {
            Ok(q) => q,
            Err(e) => {
                tracing::error!("cannot list queued tasks: {e}");
                return;
            }
        };
        for task in queued.into_iter().rev() {
            let Some(first) = task.goals.first() else {
                continue;
            };
            let chosen = {
                let robots = lock(&self.robots);
                robots
                    .values()
                    .filter(|r| r.online && r.task.is_none())
                    .filter(|r| r.status.as_ref().is_none_or(|s| s.localized))
                    .filter_map(|r| {
                        let p = r.pose.as_ref()?;
                        (p.map.name == task.map).then(|| {
                            let d = (p.pose.x_m - first.x_m).hypot(p.pose.y_m - first.y_m);
                            (d, r.id.clone())
                        })
                    })
                    .min_by(|a, b| a.0.total_cmp(&b.0).then_with(|| a.1.cmp(&b.1)))
                    .map(|(_, id)| id)
            };
            let Some(robot_id) = chosen else {
                continue;
            };
            let assigned = self.set_state(&task.id, |t| {
                t.robot_id = Some(robot_id.clone());
                Ok(Some(TaskState::Assigned {
                    robot_id: robot_id.clone(),
                }))
            });
            match assigned {
                Ok(_) => {
                    if let Some(r) = lock(&self.robots).get_mut(&robot_id) {
                        r.task = Some(task.id.clone());
                    }
                    tracing::info!(task = %task.id, robot = %robot_id, "task assigned");
                }
                Err(e) => tracing::error!(task = %task.id, "cannot assign: {e}"),
            }
        }
    }

    /// Changes a task's state in the store (the caller holds `task_lock`), then counts,
    /// publishes and streams the change. `decide` returns the new state, `None` for no change.
    /// An unfinished task is decided on its cached copy, so "no change" (the common case in
    /// the replanning loop) costs no database transaction.
    fn set_state(
        &self,
        id: &TaskId,
        decide: impl FnOnce(&mut Task) -> Result<Option<TaskState>, FleetError>,
    ) -> Result<Task, FleetError> {
        let cached = lock(&self.live_tasks).get(id).cloned();
        let (task, changed, before) = match cached {
            Some(current) => {
                let mut next = current.clone();
                match decide(&mut next)? {
                    Some(state) if state != next.state => {
                        next.set_state(state, now_ns());
                        let written = next.clone();
                        let (task, _) = self
                            .tasks
                            .update::<FleetError>(id, move |t| {
                                *t = written;
                                Ok(true)
                            })
                            .map_err(|e| not_found_task(e, id))?;
                        (task, true, Some(current.kind()))
                    }
                    _ => (current, false, None),
                }
            }
            None => {
                let mut before = None;
                let (task, changed) = self
                    .tasks
                    .update::<FleetError>(id, |t| {
                        before = Some(t.kind());
                        match decide(t)? {
                            Some(state) if state != t.state => {
                                t.set_state(state, now_ns());
                                Ok(true)
                            }
                            _ => Ok(false),
                        }
                    })
                    .map_err(|e| not_found_task(e, id))?;
                (task, changed, before)
            }
        };
        if changed {
            let mut live = lock(&self.live_tasks);
            if task.state.is_terminal() {
                live.remove(id);
            } else {
                live.insert(id.clone(), task.clone());
            }
            drop(live);
            self.metrics.task_moved(before, task.kind());
            self.announce(&task);
        }
        Ok(task)
    }

    /// Publishes a task change on its Zenoh key and the event bus.
    fn announce(&self, task: &Task) {
        let event = TaskEvent {
            header: self.header(),
            task_id: task.id.clone(),
            map: task.map.clone(),
            state: task.state.clone(),
            goal_count: u32::try_from(task.goals.len()).unwrap_or(u32::MAX),
        };
        if let Err(e) = put_sync(&self.session, &keys::task(&self.site, &task.id), &event) {
            tracing::warn!(task = %task.id, "cannot publish task event: {e}");
        }
        // No receiver is not an error: nobody watches the dashboard.
        let _ = self.events.send(FleetEvent::Task(task.clone()));
    }

    fn header(&self) -> Header {
        let seq = self.seq.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        Header::new(seq, now_ns())
    }

    // ----- Zenoh inputs --------------------------------------------------------------------

    fn robot_entry<'a>(
        &self,
        robots: &'a mut HashMap<RobotId, Robot>,
        id: &RobotId,
    ) -> &'a mut Robot {
        robots.entry(id.clone()).or_insert_with(|| {
            let (tx, rx) = watch::channel(None);
            let worker = self.runtime.spawn(robot_worker(
                self.me.clone(),
                id.clone(),
                rx,
                self.shutdown.subscribe(),
            ));
            lock(&self.background).push(worker);
            Robot {
                id: id.clone(),
                online: false,
                last_seen: Instant::now(),
                last_seen_ns: 0,
                pose: None,
                status: None,
                task: None,
                intention: None,
                lpe: None,
                lpe_at: None,
                camera: None,
                camera_at: None,
                paused_since: None,
                last_event: None,
                poses: tx,
            }
        })
    }

    fn robot_of(&self, sample: &Sample, topic: RobotTopic) -> Option<RobotId> {
        match keys::parse_robot_key(sample.key_expr().as_str()) {
            Some((site, id, t)) if site == self.site && t == topic => Some(id),
            _ => None,
        }
    }

    fn on_pose(&self, sample: &Sample) {
        let Some(id) = self.robot_of(sample, RobotTopic::Pose) else {
            return;
        };
        let pose: PoseEstimate = match protocol::decode_sample(sample) {
            Ok(p) => p,
            Err(e) => {
                tracing::warn!(robot = %id, "ignoring pose: {e}");
                return;
            }
        };
        let received = Instant::now();
        let came_back;
        let event = {
            let mut robots = lock(&self.robots);
            let robot = self.robot_entry(&mut robots, &id);
            came_back = !robot.online;
            robot.online = true;
            robot.last_seen = received;
            robot.last_seen_ns = now_ns();
            robot.pose = Some(pose.clone());
            robot.poses.send_replace(Some(Arrival { pose, received }));
            self.robot_event_due(robot, received)
        };
        if let Some(view) = event {
            let _ = self.events.send(FleetEvent::Robot(view));
        }
        if came_back {
            tracing::info!(robot = %id, "robot online");
            self.dispatch();
        }
    }

    fn robot_event_due(&self, robot: &mut Robot, now: Instant) -> Option<RobotView> {
        // A view clones the robot's path: not worth it when nobody watches.
        if self.events.receiver_count() == 0 {
            return None;
        }
        let interval = Duration::from_millis(self.config.fleet.robot_event_interval_ms);
        if robot
            .last_event
            .is_some_and(|t| now.duration_since(t) < interval)
        {
            return None;
        }
        robot.last_event = Some(now);
        Some(robot.view())
    }

    fn on_status(&self, sample: &Sample) {
        let Some(id) = self.robot_of(sample, RobotTopic::Status) else {
            return;
        };
        let status: AgentStatus = match protocol::decode_sample(sample) {
            Ok(s) => s,
            Err(e) => {
                tracing::warn!(robot = %id, "ignoring status: {e}");
                return;
            }
        };
        let view = {
            let mut robots = lock(&self.robots);
            let robot = self.robot_entry(&mut robots, &id);
            let changed =
                robot.status.as_ref().map(StatusView::from) != Some(StatusView::from(&status));
            robot.status = Some(status);
            changed.then(|| robot.view())
        };
        if let Some(view) = view {
            let _ = self.events.send(FleetEvent::Robot(view));
        }
    }

    fn on_camera(&self, sample: &Sample) {
        let Some(id) = self.robot_of(sample, RobotTopic::Camera) else {
            return;
        };
        let interval = Duration::from_millis(self.config.fleet.camera_sample_interval_ms);
        let now = Instant::now();
        {
            let robots = lock(&self.robots);
            let due = robots.get(&id).is_some_and(|r| {
                r.camera_at
                    .is_none_or(|t| now.duration_since(t) >= interval)
            });
            if !due {
                return;
            }
        }
        // Decode outside the lock: frames are the biggest messages on the bus.
        match protocol::decode_sample::<CameraFrame>(sample) {
            Ok(frame) => {
                if let Some(r) = lock(&self.robots).get_mut(&id) {
                    r.camera = Some(Arc::new(frame.image));
                    r.camera_at = Some(now);
                }
            }
            Err(e) => tracing::warn!(robot = %id, "ignoring camera frame: {e}"),
        }
    }

    fn on_liveliness(&self, sample: &Sample) {
        let Some(id) = self.robot_of(sample, RobotTopic::Alive) else {
            return;
        };
        match sample.kind() {
            SampleKind::Put => tracing::info!(robot = %id, "liveliness token appeared"),
            SampleKind::Delete => {
                tracing::warn!(robot = %id, "liveliness token gone");
                self.mark_offline(&id, "robot left (its liveliness token is gone)");
            }
        }
    }

    /// Marks a robot offline and pauses its task with `reason`.
    fn mark_offline(&self, id: &RobotId, reason: &str) {
        let _guard = lock(&self.task_lock);
        let task = {
            let mut robots = lock(&self.robots);
            let Some(robot) = robots.get_mut(id) else {
                return;
            };
            robot.online = false;
            if robot.paused_since.is_none() && robot.task.is_some() {
                robot.paused_since = Some(Instant::now());
            }
            let view = robot.view();
            let _ = self.events.send(FleetEvent::Robot(view));
            robot.task.clone()
        };
        if let Some(task_id) = task {
            let result = self.set_state(&task_id, |t| {
                Ok(match &t.state {
                    TaskState::Assigned { robot_id } => Some(TaskState::Paused {
                        robot_id: robot_id.clone(),
                        goal_index: 0,
                        reason: reason.to_string(),
                    }),
                    TaskState::Active {
                        robot_id,
                        goal_index,
                    } => Some(TaskState::Paused {
                        robot_id: robot_id.clone(),
                        goal_index: *goal_index,
                        reason: reason.to_string(),
                    }),
                    _ => None,
                })
            });
            match result {
                Ok(t) => tracing::warn!(task = %t.id, robot = %id, "task paused: {reason}"),
                Err(e) => tracing::error!(task = %task_id, "cannot pause: {e}"),
            }
        }
    }

    /// One watchdog round: silent robots go offline, long-paused tasks fail.
    fn watchdog_round(&self) {
        let timeout = Duration::from_millis(self.config.fleet.robot_timeout_ms);
        let pause_timeout = Duration::from_millis(self.config.fleet.pause_timeout_ms);
        let now = Instant::now();
        let (silent, expired, online, offline) = {
            let robots = lock(&self.robots);
            let silent: Vec<RobotId> = robots
                .values()
                .filter(|r| {
                    now.duration_since(r.last_seen) > timeout
                        && (r.online || (r.task.is_some() && r.paused_since.is_none()))
                })
                .map(|r| r.id.clone())
                .collect();
            let expired: Vec<(RobotId, TaskId)> = robots
                .values()
                .filter(|r| {
                    r.paused_since
                        .is_some_and(|t| now.duration_since(t) > pause_timeout)
                })
                .filter_map(|r| Some((r.id.clone(), r.task.clone()?)))
                .collect();
            let online = robots.values().filter(|r| r.online).count();
            (silent, expired, online, robots.len() - online)
        };
        self.metrics.set_robots(online, offline);
        for id in silent {
            let ms = timeout.as_millis();
            self.mark_offline(&id, &format!("robot {id} sent no pose for over {ms} ms"));
        }
        for (robot_id, task_id) in expired {
            let _guard = lock(&self.task_lock);
            let secs = pause_timeout.as_secs();
            let reason = format!("robot {robot_id} did not come back within {secs} s");
            match self.set_state(&task_id, |t| {
                Ok(
                    matches!(t.state, TaskState::Paused { .. }).then(|| TaskState::Failed {
                        reason: reason.clone(),
                    }),
                )
            }) {
                Ok(t) => tracing::warn!(task = %t.id, "task failed: {reason}"),
                Err(e) => tracing::error!(task = %task_id, "cannot fail: {e}"),
            }
            if let Some(r) = lock(&self.robots).get_mut(&robot_id) {
                r.task = None;
                r.paused_since = None;
            }
        }
    }

    // ----- planning ------------------------------------------------------------------------

    /// The planning map of a stored map version (built once, then shared).
    fn planning_map(&self, name: &MapName, version: u32) -> Result<Arc<PlanningMap>, FleetError> {
        let key = (name.clone(), version);
        if let Some(m) = lock(&self.planning_maps).get(&key) {
            return Ok(Arc::clone(m));
        }
        let stored = self.maps.get(name, Some(version)).map_err(|e| match e {
            MapError::NotFound { .. } => FleetError::NotFound {
                what: "map",
                id: format!("{name} version {version}"),
            },
            other => FleetError::Map(other),
        })?;
        // Built outside the lock: a big map takes a while and other maps stay usable.
        let built = Arc::new(
            PlanningMap::with_key(
                stored.grid,
                MapKey(u64::from(version)),
                &self.config.planner,
            )
            .map_err(|source| FleetError::Planning {
                map: name.to_string(),
                source,
            })?,
        );
        Ok(Arc::clone(
            lock(&self.planning_maps).entry(key).or_insert(built),
        ))
    }

    /// Publishes an intention to its robot and records it; `received` is when the answered
    /// pose arrived (None when the intention answers no new pose, e.g. a cancel).
    fn publish_intention_for(
        &self,
        robot_id: &RobotId,
        intention: &Intention,
        received: Option<Instant>,
    ) {
        let key = keys::robot(&self.site, robot_id, RobotTopic::Intention);
        if let Err(e) = put_sync(&self.session, &key, intention) {
            tracing::warn!(robot = %robot_id, "cannot publish intention: {e}");
            return;
        }
        let latency = received.map(|r| r.elapsed());
        if let Some(l) = latency {
            self.metrics.record_intention(l);
        }
        let view = IntentionView {
            task_id: intention.task_id.clone(),
            goal_index: intention.goal_index,
            dlm: intention.dlm,
            path: intention.path.clone(),
            stamp_ns: intention.header.stamp_ns,
            latency_ms: latency.map_or(0.0, |l| l.as_secs_f64() * 1e3),
        };
        if let Some(r) = lock(&self.robots).get_mut(robot_id) {
            r.intention = Some(view.clone());
        }
        let _ = self.events.send(FleetEvent::Intention {
            robot_id: robot_id.clone(),
            intention: view,
        });
    }

    /// One replanning cycle of one robot for the pose that just arrived (blocking pool).
    fn cycle(&self, id: &RobotId, arrival: &Arrival, st: &mut WorkerState) {
        let pose = &arrival.pose;
        let Some((task_id, goals, next)) = self.advance_task(id, pose) else {
            let stop = stop_intention(self.header(), pose, None, 0);
            self.publish_intention_for(id, &stop, Some(arrival.received));
            return;
        };
        let render_lpe = self.lpe_due(id);
        let answer = self
            .pipeline(pose, st)
            .map(|pipeline| pipeline.answer(pose, &GoalProgress::new(&goals, next), render_lpe));
        let planned = match answer {
            Ok(Answer::Heading { goal_index, plan }) => {
                plan.map(|p| (goal_index, p))
                    .map_err(|source| FleetError::Planning {
                        map: pose.map.name.to_string(),
                        source,
                    })
            }
            // `advance_task` already moved past every goal in reach of this pose.
            Ok(Answer::Done) => Err(FleetError::Conflict(format!(
                "task {task_id} has no goal left after goal {next}"
            ))),
            Err(e) => Err(e),
        };
        match planned {
            Ok((goal_index, planned)) => {
                st.failures = 0;
                self.metrics.record_replan(true);
                // The image travels only to a robot whose controller reads it; the dashboard's
                // preview stays here.
                let wants_lpe = lock(&self.robots).get(id).is_some_and(Robot::wants_lpe);
                let intention =
                    planned.intention(self.header(), pose, Some(task_id), goal_index, wants_lpe);
                if let Some(l) = planned.lpe {
                    if let Some(r) = lock(&self.robots).get_mut(id) {
                        r.lpe = Some(Arc::new(l));
                        r.lpe_at = Some(Instant::now());
                    }
                }
                self.publish_intention_for(id, &intention, Some(arrival.received));
            }
            Err(e) => {
                st.failures += 1;
                self.metrics.record_replan(false);
                tracing::debug!(robot = %id, task = %task_id, "replan failed ({}): {e}", st.failures);
                let stop = stop_intention(self.header(), pose, Some(task_id.clone()), next);
                self.publish_intention_for(id, &stop, Some(arrival.received));
                if st.failures >= self.config.fleet.max_plan_failures {
                    st.failures = 0;
                    let reason = format!(
                        "no path to goal {next} after {} tries: {e}",
                        self.config.fleet.max_plan_failures
                    );
                    self.finish_task(id, &task_id, TaskState::Failed { reason });
                }
            }
        }
    }

    /// Brings the robot's task up to date with its pose: starts or resumes it, advances past
    /// reached goals, completes it. Returns the task's goals and the index of the next one, if
    /// there is anything to plan for.
    fn advance_task(
        &self,
        id: &RobotId,
        pose: &PoseEstimate,
    ) -> Option<(TaskId, Vec<planning::Goal>, usize)> {
        let _guard = lock(&self.task_lock);
        let task_id = {
            let mut robots = lock(&self.robots);
            let robot = robots.get_mut(id)?;
            robot.paused_since = None;
            robot.task.clone()?
        };
        let cached = lock(&self.live_tasks).get(&task_id).cloned();
        let Some(task) = cached else {
            // Ended (cancelled, failed) since the robot took it.
            self.release_robot(id, &task_id);
            return None;
        };
        if pose.map.name != task.map {
            tracing::warn!(robot = %id, task = %task_id, "robot localizes on {}, task is on {}", pose.map.name, task.map);
            return None;
        }
        let progress = GoalProgress::new(&task.goals, task.goal_index().unwrap_or(0) as usize);
        let k = match progress.advance(pose.pose, self.config.fleet.goal_tolerance_m) {
            planning::Advance::Done => {
                self.finish_task_locked(id, &task_id, TaskState::Completed);
                return None;
            }
            planning::Advance::Heading { index, .. } => index,
        };
        let goal_index = u32::try_from(k).unwrap_or(u32::MAX);
        let robot_id = id.clone();
        if let Err(e) = self.set_state(&task_id, |_| {
            Ok(Some(TaskState::Active {
                robot_id,
                goal_index,
            }))
        }) {
            tracing::error!(task = %task_id, "cannot update task: {e}");
            return None;
        }
        Some((task_id, task.goals, k))
    }

    /// Ends a task (completed or failed) and frees its robot.
    fn finish_task(&self, id: &RobotId, task_id: &TaskId, state: TaskState) {
        let _guard = lock(&self.task_lock);
        self.finish_task_locked(id, task_id, state);
    }

    /// As [`Self::finish_task`] for a caller that holds `task_lock`.
    fn finish_task_locked(&self, id: &RobotId, task_id: &TaskId, state: TaskState) {
        let result = self.set_state(task_id, |t| Ok((!t.state.is_terminal()).then_some(state)));
        match result {
            Ok(t) => tracing::info!(task = %task_id, robot = %id, state = %t.kind(), "task ended"),
            Err(e) => tracing::error!(task = %task_id, "cannot end task: {e}"),
        }
        self.release_robot(id, task_id);
        // Dispatching takes the task lock: run it after this cycle, not inside.
        if let Some(me) = self.me.upgrade() {
            self.runtime.spawn_blocking(move || me.dispatch());
        }
    }

    fn release_robot(&self, id: &RobotId, task_id: &TaskId) {
        if let Some(r) = lock(&self.robots).get_mut(id) {
            if r.task.as_ref() == Some(task_id) {
                r.task = None;
                r.paused_since = None;
            }
        }
    }

    /// The robot's intention pipeline on the planning map of the pose's map version.
    fn pipeline<'a>(
        &self,
        pose: &PoseEstimate,
        st: &'a mut WorkerState,
    ) -> Result<&'a mut IntentionPlanner, FleetError> {
        let map = self.planning_map(&pose.map.name, pose.map.version)?;
        let planning = |source| FleetError::Planning {
            map: pose.map.name.to_string(),
            source,
        };
        if let Some(p) = &mut st.pipeline {
            p.set_map(Arc::clone(&map)).map_err(planning)?;
        } else {
            let made = IntentionPlanner::new(Arc::clone(&map), self.config.intention())
                .map_err(planning)?;
            st.pipeline = Some(made);
        }
        st.pipeline
            .as_mut()
            .ok_or_else(|| FleetError::Conflict("no pipeline".into()))
    }

    /// Whether this cycle renders the LPE image: always for a robot whose controller reads it,
    /// else at the preview interval while a dashboard watches.
    fn lpe_due(&self, id: &RobotId) -> bool {
        let interval = Duration::from_millis(self.config.fleet.lpe_preview_interval_ms);
        let robots = lock(&self.robots);
        robots.get(id).is_some_and(|r| {
            r.wants_lpe()
                || (self.events.receiver_count() > 0
                    && r.lpe_at.is_none_or(|t| t.elapsed() >= interval))
        })
    }
}

fn not_found_task(e: FleetError, id: &TaskId) -> FleetError {
    match e {
        FleetError::Store(StoreError::NotFound(_)) => FleetError::NotFound {
            what: "task",
            id: id.to_string(),
        },
        other => other,
    }
}

/// Each robot's worker: plans from the newest pose, skipping the ones that arrived meanwhile.
async fn robot_worker(
    fleet: Weak<Fleet>,
    id: RobotId,
    mut poses: watch::Receiver<Option<Arrival>>,
    mut shutdown: watch::Receiver<bool>,
) {
    let mut state = Some(WorkerState::default());
    loop {
        tokio::select! {
            changed = poses.changed() => if changed.is_err() { break },
            _ = shutdown.changed() => break,
        }
        let Some(arrival) = poses.borrow_and_update().clone() else {
            continue;
        };
        let Some(f) = fleet.upgrade() else {
            break;
        };
        let Some(mut st) = state.take() else {
            break;
        };
        let robot = id.clone();
        match tokio::task::spawn_blocking(move || {
            f.cycle(&robot, &arrival, &mut st);
            st
        })
        .await
        {
            Ok(st) => state = Some(st),
            Err(e) => {
                tracing::error!(robot = %id, "replanning worker failed: {e}");
                state = Some(WorkerState::default());
            }
        }
    }
}

async fn watchdog(fleet: Weak<Fleet>, mut shutdown: watch::Receiver<bool>) {
    let mut tick = tokio::time::interval(Duration::from_millis(200));
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    loop {
        tokio::select! {
            _ = tick.tick() => {}
            _ = shutdown.changed() => break,
        }
        let Some(f) = fleet.upgrade() else {
            break;
        };
        // The watchdog touches the task store: keep it off the async workers.
        if let Err(e) = tokio::task::spawn_blocking(move || {
            f.watchdog_round();
            f.dispatch();
        })
        .await
        {
            tracing::error!("watchdog round failed: {e}");
        }
    }
}

/// Encodes and puts a message from synchronous code (the blocking pool, HTTP handlers).
fn put_sync<M: WireMessage>(
    session: &Session,
    key: &zenoh::key_expr::OwnedKeyExpr,
    msg: &M,
) -> Result<(), FleetError> {
    let bytes = protocol::encode(msg).map_err(|e| FleetError::Zenoh {
        action: "encode",
        reason: e.to_string(),
    })?;
    session
        .put(key, bytes)
        .encoding(protocol::zenoh_io::encoding_for::<M>())
        .wait()
        .map_err(zenoh_err("put"))
}

fn to_jpeg(img: &Image) -> Result<Vec<u8>, String> {
    match img.encoding {
        ImageEncoding::Jpeg => Ok(img.data.clone()),
        ImageEncoding::Rgb8 | ImageEncoding::Png => {
            let rgb = match img.encoding {
                ImageEncoding::Png => image::load_from_memory(&img.data)
                    .map_err(|e| e.to_string())?
                    .to_rgb8(),
                _ => image::RgbImage::from_raw(img.width_px, img.height_px, img.data.clone())
                    .ok_or_else(|| "pixel buffer does not match the size".to_string())?,
            };
            let mut out = std::io::Cursor::new(Vec::new());
            image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, 80)
                .encode_image(&rgb)
                .map_err(|e| e.to_string())?;
            Ok(out.into_inner())
        }
    }
}
