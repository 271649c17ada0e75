//! The fleet core: delivery tasks, the robots that carry them out and the per-robot replanning
//! loop (DESIGN §2, §8), split by responsibility:
//!
//! - [`book`]: the task book — unfinished tasks, which robot has which, the task lifecycle
//!   (create, cancel, dispatch, advance, pause, resume, fail, expire), written through to the
//!   [`store`] and answered with effects.
//! - [`registry`]: the robot registry — online or not, last seen, pose, status, samples.
//! - [`core`](self::core): the two together — what a pose, a status, a departure, a watchdog
//!   round or a replan means. Plain data in, effects out, time passed in: tested without
//!   Zenoh and without sleeping.
//! - `adapter`: the thin Zenoh side — decodes samples, calls the core, publishes its effects.
//! - `worker`: one replanning worker per robot, calling the planning crate; the cycle it runs
//!   is the same in the service and in worker processes.
//! - `publishers`: declared publishers for what goes out every cycle (intentions, a worker's
//!   cycle outcomes), so Zenoh routes them from a cache instead of matching each key again.
//! - [`remote`]: worker processes (`planner-service worker`) that take the replanning off the
//!   service, each planning the robots [`rendezvous`] hashing gives it.
//! - [`config`], [`error`], [`types`], [`metrics`], [`store`]: the `[fleet]` table, errors,
//!   the API's JSON shapes, Prometheus metrics, the task database.
//!
//! [`Fleet`] wires them: one mutex guards the core and the workers' pose slots, so there is
//! no lock order to keep. Task changes are written to the database under it (stored before
//! anything can see them); planning, image encoding, camera decoding and every Zenoh put
//! happen outside it. The few other locks (the planning-map cache, the subscriber list) are
//! leaves: nothing is locked while holding them.

pub mod book;
pub mod config;
pub mod core;
pub mod error;
pub mod metrics;
pub mod registry;
pub mod remote;
pub mod rendezvous;
pub mod store;
pub mod types;

mod adapter;
mod publishers;
mod refresh;
mod worker;

use std::collections::{BTreeSet, HashMap};
use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, PoisonError, Weak};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use map_store::MapStore;
use planning::{stop_intention, Endpoint, IntentionConfig, PlanningMap};
use protocol::{
    Header, Image, ImageEncoding, Intention, MapName, Pose2D, PoseEstimate, RobotId, SiteId,
    TaskEvent, TaskId, WorkerId,
};
use publishers::Publishers;
use tokio::sync::{broadcast, mpsc, watch};
use zenoh::pubsub::Subscriber;
use zenoh::query::Queryable;
use zenoh::Session;

use self::adapter::Outgoing;
use self::book::Effect;
use self::core::{Core, Cycle};
use self::metrics::SERVICE_WORKER;
use self::worker::{CycleHost, MapSource, Outcome, PlanningMaps, Worker};
use crate::config::ServiceConfig;

pub use self::config::{FleetConfig, InvalidFleetConfig};
pub use self::error::{ErrorKind, FleetError};
pub use self::metrics::FleetMetrics;
pub use self::store::{Retention, StoreError, SweepReport, TaskStore};
pub use self::types::{
    Cursor, FleetEvent, Goal, HistoryEntry, IntentionView, NewTask, PoseView, RobotView,
    StatusView, Task, TaskFilter, TaskPage, TaskStateKind, WorkerView,
};

/// When something happens: the monotonic instant (timers) and the wall clock (stored stamps).
/// The I/O side reads it once and passes it in, so the core never reads a clock.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Now {
    pub at: Instant,
    pub wall_ns: u64,
}

impl Now {
    #[must_use]
    pub fn read() -> Self {
        Self {
            at: Instant::now(),
            wall_ns: now_ns(),
        }
    }

    /// `d` later.
    #[must_use]
    pub fn after(self, d: Duration) -> Self {
        Self {
            at: self.at + d,
            wall_ns: self
                .wall_ns
                .saturating_add(u64::try_from(d.as_nanos()).unwrap_or(u64::MAX)),
        }
    }
}

fn now_ns() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX))
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    // A panicking holder leaves plain data behind; it stays usable.
    m.lock().unwrap_or_else(PoisonError::into_inner)
}

/// What the fleet's one lock guards.
struct State {
    core: Core,
    /// Each registered robot's worker (started by the adapter when it registers the robot).
    workers: HashMap<RobotId, Worker>,
    /// Worker processes alive on the site (their liveliness tokens): while there is one, they
    /// plan every robot and the robots' workers here wait.
    remote: BTreeSet<WorkerId>,
    /// Who planned each robot's last cycle ([`SERVICE_WORKER`] or a worker process's id).
    served_by: HashMap<RobotId, String>,
}

/// The background side: Zenoh subscriptions and loops, ended by [`Fleet::shutdown`].
#[derive(Default)]
struct Io {
    subscribers: Vec<Subscriber<()>>,
    /// The cycle queryable that worker processes ask.
    queryable: Option<Queryable<()>>,
    tasks: Vec<tokio::task::JoinHandle<()>>,
}

/// The fleet core (see the module docs); shared as `Arc<Fleet>`.
pub struct Fleet {
    me: Weak<Fleet>,
    site: SiteId,
    session: Session,
    /// The robots' intention publishers.
    publishers: Publishers,
    config: ServiceConfig,
    runtime: tokio::runtime::Handle,
    store: Arc<TaskStore>,
    maps: Arc<MapStore>,
    planning: PlanningMaps,
    /// Kept plans' due new searches, below the answers' priority.
    refresh: refresh::RefreshPool,
    state: Mutex<State>,
    /// Announcements in the order the core made them, to the publisher task.
    outbox: mpsc::UnboundedSender<Outgoing>,
    events: broadcast::Sender<FleetEvent>,
    metrics: FleetMetrics,
    shutdown: watch::Sender<bool>,
    io: Mutex<Io>,
    seq: AtomicU64,
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
        config
            .fleet
            .validate()
            .map_err(|e| FleetError::Config(e.to_string()))?;
        config
            .planner
            .validate()
            .map_err(|e| FleetError::Config(e.to_string()))?;
        let store = Arc::new(TaskStore::open(data_dir)?);
        let metrics = FleetMetrics::default();
        for (state, count) in TaskStateKind::ALL.into_iter().zip(store.count_by_state()?) {
            metrics.tasks_added(state, count);
        }
        let (core, resumed) = Core::open(Arc::clone(&store), config.fleet.clone(), Now::read())?;
        let (events, _) = broadcast::channel(config.fleet.event_buffer);
        let (shutdown, _) = watch::channel(false);
        let (outbox, outgoing) = mpsc::unbounded_channel();
        let publisher = tokio::spawn(adapter::publisher(
            session.clone(),
            site.clone(),
            outgoing,
            events.clone(),
        ));
        let fleet = Arc::new_cyclic(|me| Fleet {
            me: me.clone(),
            site,
            publishers: Publishers::new(session.clone()),
            session,
            planning: PlanningMaps::new(
                MapSource::Store(Arc::clone(&maps)),
                config.planner.clone(),
            ),
            refresh: refresh::RefreshPool::start(cores()),
            maps,
            config,
            runtime: tokio::runtime::Handle::current(),
            store,
            state: Mutex::new(State {
                core,
                workers: HashMap::new(),
                remote: BTreeSet::new(),
                served_by: HashMap::new(),
            }),
            outbox,
            events,
            metrics,
            shutdown,
            io: Mutex::new(Io::default()),
            seq: AtomicU64::new(0),
        });
        lock(&fleet.io).tasks.push(publisher);
        // Robots of resumed tasks are registered (offline): they get their workers now.
        fleet.with_state(|state| {
            for id in &resumed {
                fleet.start_worker(state, id);
            }
            ((), Vec::new())
        });
        let subscribed = adapter::subscribe(&fleet.session, &fleet.site, &fleet.me).await;
        let (subscribers, queryable) = match subscribed {
            Ok(s) => s,
            Err(e) => {
                fleet.shutdown().await;
                return Err(e);
            }
        };
        let watchdog = tokio::spawn(adapter::watchdog(
            Arc::downgrade(&fleet),
            fleet.shutdown.subscribe(),
        ));
        let sweeper = tokio::spawn(retention_sweeper(
            Arc::downgrade(&fleet),
            fleet.shutdown.subscribe(),
        ));
        {
            let mut io = lock(&fleet.io);
            io.subscribers = subscribers;
            io.queryable = Some(queryable);
            io.tasks.push(watchdog);
            io.tasks.push(sweeper);
        }
        tracing::info!(site = %fleet.site, "fleet core running");
        Ok(fleet)
    }

    /// Stops the workers and the background loops and undeclares the subscriptions.
    pub async fn shutdown(&self) {
        self.shutdown.send_replace(true);
        let io = std::mem::take(&mut *lock(&self.io));
        for s in io.subscribers {
            if let Err(e) = s.undeclare().await {
                tracing::warn!("cannot undeclare subscriber: {e}");
            }
        }
        if let Some(q) = io.queryable {
            if let Err(e) = q.undeclare().await {
                tracing::warn!("cannot undeclare the cycle queryable: {e}");
            }
        }
        for t in io.tasks {
            t.abort();
        }
        self.with_state(|state| {
            for w in state.workers.values() {
                w.abort();
            }
            ((), Vec::new())
        });
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
        self.read(Core::views)
    }

    #[must_use]
    pub fn robot(&self, id: &RobotId) -> Option<RobotView> {
        self.read(|core| core.view(id))
    }

    /// The replanning workers: the service itself and every worker process alive, each with
    /// the online robots whose last cycle it planned and its counts; workers that left are
    /// listed (not alive) while they have counts.
    #[must_use]
    pub fn workers(&self) -> Vec<WorkerView> {
        let (remote, mut planned) = {
            let state = lock(&self.state);
            let mut planned: HashMap<String, Vec<RobotId>> = HashMap::new();
            for robot in state.core.registry.iter().filter(|r| r.online) {
                if let Some(worker) = state.served_by.get(&robot.id) {
                    planned
                        .entry(worker.clone())
                        .or_default()
                        .push(robot.id.clone());
                }
            }
            (state.remote.clone(), planned)
        };
        let mut names: BTreeSet<String> = self.metrics.worker_names().into_iter().collect();
        names.insert(SERVICE_WORKER.to_string());
        names.extend(remote.iter().map(ToString::to_string));
        names
            .into_iter()
            .map(|name| {
                let stats = self.metrics.worker(&name);
                let mut robots = planned.remove(&name).unwrap_or_default();
                robots.sort();
                WorkerView {
                    alive: name == SERVICE_WORKER
                        || WorkerId::new(name.as_str()).is_ok_and(|w| remote.contains(&w)),
                    id: name,
                    robots,
                    replans: stats.replans(),
                    failures: stats.failures(),
                    mean_latency_ms: stats.mean_latency_ms(),
                }
            })
            .collect()
    }

    /// PNG of the LPE image of the robot's latest intention that had one.
    #[must_use]
    pub fn robot_lpe_png(&self, id: &RobotId) -> Option<Vec<u8>> {
        let lpe = self.read(|core| core.registry.lpe(id))?;
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
        let frame = self.read(|core| core.registry.camera(id))?;
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
        self.store.get(id)?.ok_or_else(|| FleetError::NotFound {
            what: "task",
            id: id.to_string(),
        })
    }

    /// Tasks matching `filter`, newest first.
    ///
    /// # Errors
    /// A storage error.
    pub fn tasks(&self, filter: &TaskFilter) -> Result<Vec<Task>, FleetError> {
        Ok(self.store.list(filter)?)
    }

    /// One page of the tasks matching `filter`, newest first, and where the next starts.
    ///
    /// # Errors
    /// A storage error.
    pub fn task_page(&self, filter: &TaskFilter) -> Result<TaskPage, FleetError> {
        Ok(self.store.list_page(filter)?)
    }

    /// The newest `limit` tasks that have not ended, newest first.
    ///
    /// # Errors
    /// A storage error.
    pub fn live_tasks(&self, limit: usize) -> Result<Vec<Task>, FleetError> {
        Ok(self.store.live(limit)?)
    }

    /// Prunes the finished tasks past `[fleet]`'s retention (exported first) and takes them
    /// off the task gauges.
    ///
    /// # Errors
    /// A storage or export error; what was pruned before it stays pruned and counted.
    pub fn sweep_finished(&self) -> Result<SweepReport, FleetError> {
        let report = self.store.sweep(&self.config.fleet.retention(), now_ns())?;
        for (state, count) in TaskStateKind::ALL.into_iter().zip(report.pruned_by_state) {
            self.metrics.tasks_removed(state, count);
        }
        Ok(report)
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
        let meta = self
            .maps()
            .meta(&req.map, None)
            .map_err(|e| FleetError::from_map(e, || req.map.to_string()))?;
        // Checked before the lock: building a planning map takes a while.
        let planning = self.planning.get(&req.map, meta.version)?;
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
        self.try_with_core(|core| core.create(req, meta.version, Now::read()))
    }

    /// Cancels a task that has not ended; its robot gets a `Stop` intention at once.
    ///
    /// # Errors
    /// [`FleetError::NotFound`], or [`FleetError::Conflict`] when the task already ended.
    pub fn cancel_task(&self, id: &TaskId) -> Result<Task, FleetError> {
        self.try_with_core(|core| core.cancel(id, Now::read()))
    }

    // ----- the lock ------------------------------------------------------------------------

    /// Runs `f` under the fleet's lock and queues the effects it returns before releasing it
    /// (so they leave in the order they were made).
    fn with_state<R>(&self, f: impl FnOnce(&mut State) -> (R, Vec<Effect>)) -> R {
        let mut state = lock(&self.state);
        let (out, effects) = f(&mut state);
        self.route(&mut state.core, effects);
        out
    }

    fn with_core<R>(&self, f: impl FnOnce(&mut Core) -> (R, Vec<Effect>)) -> R {
        self.with_state(|state| f(&mut state.core))
    }

    fn try_with_core<T>(
        &self,
        f: impl FnOnce(&mut Core) -> Result<(T, Vec<Effect>), FleetError>,
    ) -> Result<T, FleetError> {
        self.with_core(|core| match f(core) {
            Ok((out, effects)) => (Ok(out), effects),
            Err(e) => (Err(e), Vec::new()),
        })
    }

    fn read<R>(&self, f: impl FnOnce(&Core) -> R) -> R {
        f(&lock(&self.state).core)
    }

    /// Counts the effects and queues them for the publisher; a stop is made into the
    /// intention for the robot's last pose (a robot that never sent one needs none).
    fn route(&self, core: &mut Core, effects: Vec<Effect>) {
        for effect in effects {
            let out = match effect {
                Effect::Announce { task, before } => {
                    self.metrics.task_moved(before, task.kind());
                    let event = TaskEvent {
                        header: self.header(),
                        task_id: task.id.clone(),
                        map: task.map.clone(),
                        state: task.state.clone(),
                        goal_count: u32::try_from(task.goals.len()).unwrap_or(u32::MAX),
                    };
                    Outgoing::Task(Box::new((event, task)))
                }
                Effect::Stop(robot) => {
                    let Some(pose) = core.registry.get(&robot).and_then(|r| r.pose.as_ref()) else {
                        continue;
                    };
                    let intention = stop_intention(self.header(), pose, None, 0);
                    let view = IntentionView::of(&intention);
                    core.registry.set_intention(&robot, view.clone());
                    Outgoing::Intention {
                        robot,
                        intention: Box::new(intention),
                        view,
                    }
                }
                Effect::Robot(view) => Outgoing::Event(Box::new(FleetEvent::Robot(view))),
            };
            // The publisher runs until shutdown; after it, nothing is published any more.
            let _ = self.outbox.send(out);
        }
    }

    /// Starts the worker of a robot just registered.
    fn start_worker(&self, state: &mut State, id: &RobotId) {
        let worker = Worker::spawn(
            &self.runtime,
            self.me.clone(),
            id.clone(),
            self.shutdown.subscribe(),
            (
                self.session.clone(),
                protocol::keys::robot(&self.site, id, protocol::keys::RobotTopic::Pose),
            ),
        );
        state.workers.insert(id.clone(), worker);
    }

    /// Whether anyone streams events (views and previews are made only then).
    fn watched(&self) -> bool {
        self.events.receiver_count() > 0
    }

    fn header(&self) -> Header {
        let seq = self.seq.fetch_add(1, Ordering::Relaxed);
        Header::new(seq, now_ns())
    }
}

impl Fleet {
    /// Books the end of a cycle that `worker` ran for robot `id` (the service's own cycles
    /// and the worker processes' reports alike).
    pub(crate) fn finish_cycle(&self, worker: &str, id: &RobotId, outcome: Outcome) {
        let ok = match &outcome {
            Outcome::Stopped { .. } => None,
            Outcome::Planned { .. } => Some(true),
            Outcome::Failed { .. } => Some(false),
        };
        if let Some(ok) = ok {
            self.metrics.record_replan(ok);
        }
        if matches!(outcome, Outcome::Planned { reused: true, .. }) {
            self.metrics.record_reuse();
        }
        if matches!(outcome, Outcome::Planned { avoided_robots, .. } if avoided_robots > 0) {
            self.metrics.record_round_robots();
        }
        let sent = outcome.sent().cloned();
        let latency = sent
            .as_ref()
            .map(|v| Duration::from_secs_f64(v.latency_ms.max(0.0) / 1e3));
        if let Some(l) = latency {
            self.metrics.record_intention(l);
        }
        self.metrics.record_worker(worker, latency, ok);
        self.with_state(|state| {
            if state.served_by.get(id).is_none_or(|w| w != worker) {
                state.served_by.insert(id.clone(), worker.to_string());
            }
            let core = &mut state.core;
            let now = Now::read();
            let effects = match outcome {
                Outcome::Stopped { sent } => {
                    if let Some(view) = sent {
                        core.intention_sent(id, view);
                    }
                    Vec::new()
                }
                Outcome::Planned { sent, lpe, .. } => {
                    core.planned(id, sent, lpe, now);
                    Vec::new()
                }
                Outcome::Failed {
                    sent,
                    task,
                    goal,
                    error,
                } => core.plan_failed(id, sent, &task, goal, &error, now),
            };
            ((), effects)
        });
        if let Some(view) = sent {
            self.intention_event(id, view);
        }
    }

    /// What the cycle of robot `id` for `pose` is to do, from the task book.
    pub(crate) fn begin_cycle(&self, id: &RobotId, pose: &PoseEstimate) -> Cycle {
        let watched = self.watched();
        self.with_core(|core| core.begin_cycle(id, pose, Now::read(), watched))
    }
}

/// The service's own cycles (while no worker process is alive).
impl CycleHost for Fleet {
    fn begin(&self, id: &RobotId, pose: &PoseEstimate) -> Option<Cycle> {
        Some(self.begin_cycle(id, pose))
    }

    fn planning_map(&self, name: &MapName, version: u32) -> Result<Arc<PlanningMap>, FleetError> {
        self.planning.get(name, version)
    }

    fn intention_config(&self) -> IntentionConfig {
        self.config.intention()
    }

    fn header(&self) -> Header {
        Fleet::header(self)
    }

    fn send_intention(
        &self,
        id: &RobotId,
        intention: &Intention,
        received: Instant,
    ) -> Option<IntentionView> {
        Fleet::send_intention(self, id, intention, received)
    }

    fn finish(&self, id: &RobotId, outcome: Outcome) {
        self.finish_cycle(SERVICE_WORKER, id, outcome);
    }

    fn refresh_pool(&self) -> &refresh::RefreshPool {
        &self.refresh
    }

    fn refreshed(&self, ok: bool) {
        self.metrics.record_refresh(ok);
    }
}

/// The cores this process may use (its affinity, e.g. `taskset`).
pub(crate) fn cores() -> usize {
    std::thread::available_parallelism().map_or(1, std::num::NonZero::get)
}

/// Sweeps finished tasks every `[fleet] retention_sweep_interval_s` until shutdown.
async fn retention_sweeper(fleet: Weak<Fleet>, mut shutdown: watch::Receiver<bool>) {
    loop {
        let Some(interval) = fleet
            .upgrade()
            .map(|f| Duration::from_secs(f.config.fleet.retention_sweep_interval_s))
        else {
            return;
        };
        tokio::select! {
            _ = shutdown.wait_for(|stop| *stop) => return,
            () = tokio::time::sleep(interval) => {}
        }
        let Some(f) = fleet.upgrade() else { return };
        match tokio::task::spawn_blocking(move || f.sweep_finished()).await {
            Ok(Ok(r)) if r.pruned > 0 => tracing::info!(pruned = r.pruned, "finished tasks pruned"),
            Ok(Ok(_)) => {}
            Ok(Err(e)) => tracing::warn!("cannot prune finished tasks: {e}"),
            Err(e) => tracing::warn!("task sweep stopped: {e}"),
        }
    }
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

#[cfg(test)]
mod tests;
