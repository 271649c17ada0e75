//! Per-robot replanning workers, the one replanning cycle, and the planning maps they share.
//!
//! Each robot gets one worker, started when it is first seen (never as a side effect of a
//! lookup). Poses reach it through a one-slot channel: a worker that is still planning skips
//! the poses that arrived meanwhile and plans from the newest, so a slow robot or a slow plan
//! never queues up, and workers of different robots run in parallel on the blocking pool. A
//! worker owns its robot's [`IntentionPlanner`]; the planning itself (goal advancement,
//! hybrid A*, DLM, LPE, path thinning) is the planning crate's, called through
//! [`IntentionPlanner::answer`]. A new search that the robot's kept plan left due goes, once the
//! answer is out, to the host's low-priority [`RefreshPool`]; the worker adopts its plan when
//! it comes back, answering from the kept plan meanwhile.
//!
//! The cycle is the same wherever it runs; what differs is behind [`CycleHost`]: the service
//! process itself (its task book under its lock, its own map store), or a worker process
//! (`planner-service worker`, [`super::remote`]) that asks the service's book over Zenoh and
//! reports back.

use std::collections::HashMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, Weak};
use std::time::{Duration, Instant};

use map_store::MapStore;
use planning::{
    stop_intention, Answer, GoalProgress, IntentionConfig, IntentionPlanner, LpeImage, MapKey,
    PlannerConfig, PlanningMap,
};
use protocol::{Header, Intention, MapName, PoseEstimate, RobotId, SiteId, TaskId};
use tokio::sync::{watch, Semaphore};
use zenoh::key_expr::OwnedKeyExpr;
use zenoh::Session;

use super::book::Decision;
use super::core::Cycle;
use super::error::FleetError;
use super::lock;
use super::refresh::{RefreshPool, RefreshReply};
use super::types::IntentionView;

/// A pose and when it reached the process that plans it (for the intention latency).
#[derive(Debug, Clone)]
pub(crate) struct Arrival {
    pub pose: PoseEstimate,
    pub received: Instant,
}

/// How one cycle ended, for the task book: the intention that went out (if it did) and what
/// the planning came to.
#[derive(Debug, Clone)]
pub(crate) enum Outcome {
    /// The robot has nothing to do (no task, another map, just completed): it was stopped.
    Stopped { sent: Option<IntentionView> },
    /// A path was found; `lpe` is the rendered image when the cycle asked for one.
    Planned {
        sent: Option<IntentionView>,
        lpe: Option<LpeImage>,
        reused: bool,
        /// How many other robots the path keeps clear of.
        avoided_robots: usize,
    },
    /// No path to goal `goal` of `task`: the robot was stopped.
    Failed {
        sent: Option<IntentionView>,
        task: TaskId,
        goal: usize,
        error: String,
    },
}

impl Outcome {
    pub fn sent(&self) -> Option<&IntentionView> {
        match self {
            Outcome::Stopped { sent }
            | Outcome::Planned { sent, .. }
            | Outcome::Failed { sent, .. } => sent.as_ref(),
        }
    }
}

/// What a cycle needs from the process it runs in (see the module docs).
pub(crate) trait CycleHost: Send + Sync + 'static {
    /// What the cycle for `pose` is to do; `None` when there is no answer (a worker that cannot
    /// reach the service): the cycle is skipped and the robot keeps its last intention.
    fn begin(&self, id: &RobotId, pose: &PoseEstimate) -> Option<Cycle>;
    /// The planning map of a stored map version.
    ///
    /// # Errors
    /// The map is unknown or cannot be built.
    fn planning_map(&self, name: &MapName, version: u32) -> Result<Arc<PlanningMap>, FleetError>;
    fn intention_config(&self) -> IntentionConfig;
    fn header(&self) -> Header;
    /// Publishes `intention` to robot `id`; the view to record (latency from `received`), if
    /// it went out.
    fn send_intention(
        &self,
        id: &RobotId,
        intention: &Intention,
        received: Instant,
    ) -> Option<IntentionView>;
    /// The cycle's end, for the task book.
    fn finish(&self, id: &RobotId, outcome: Outcome);
    /// At most this many plans at once (a worker process: its cores), with [`Self::begin`]
    /// asked outside them; `None`: no cap, the whole cycle in one go.
    fn planning_slots(&self) -> Option<&Arc<Semaphore>> {
        None
    }
    /// Where kept plans' due new searches run.
    fn refresh_pool(&self) -> &RefreshPool;
    /// A due new search came back (`ok`: it found a path).
    fn refreshed(&self, _ok: bool) {}
}

/// The running worker of one robot: its pose slot and its task.
#[derive(Debug)]
pub(crate) struct Worker {
    slot: Arc<PoseSlot>,
    task: tokio::task::JoinHandle<()>,
}

/// Where a worker takes its poses from. Shared, so that a caller can look it up under a lock
/// and hand the pose over after releasing it (waking the worker is a system call).
#[derive(Debug)]
pub(crate) struct PoseSlot {
    /// The newest pose, numbered from 1 in the order handed over.
    poses: watch::Sender<Option<(u64, Arrival)>>,
    /// Poses handed over so far.
    handed: AtomicU64,
    /// The number of the newest pose the loop took.
    taken: Arc<AtomicU64>,
}

impl PoseSlot {
    /// Hands the worker the newest pose, replacing one it has not taken yet; `true` when it
    /// did (that pose is never answered: the worker was still planning an older one).
    pub fn send(&self, arrival: Arrival) -> bool {
        let n = self.handed.fetch_add(1, Ordering::Relaxed) + 1;
        self.poses.send_replace(Some((n, arrival)));
        // The loop records what it takes while it holds the slot, so this read, after the
        // replacement, sees every take of the pose just replaced.
        n > 1 && self.taken.load(Ordering::Acquire) < n - 1
    }
}

impl Worker {
    /// Starts the worker of robot `id` on `runtime`; it ends with `shutdown`, when the host
    /// is gone, or when dropped.
    ///
    /// `pose_key` is the robot's pose key on `session`: the worker declares it while it runs,
    /// so Zenoh keeps a resource for that key and caches the route of the robot's poses. An
    /// undeclared key is matched again against every subscription the session knows, for
    /// every pose: O(robots) per pose, O(robots²) per cycle of the fleet.
    pub fn spawn<H: CycleHost>(
        runtime: &tokio::runtime::Handle,
        host: Weak<H>,
        id: RobotId,
        shutdown: watch::Receiver<bool>,
        (session, pose_key): (Session, OwnedKeyExpr),
    ) -> Self {
        let (poses, rx) = watch::channel(None);
        let taken = Arc::new(AtomicU64::new(0));
        let took = Arc::clone(&taken);
        let task = runtime.spawn(async move {
            let declared = match session.declare_keyexpr(pose_key).await {
                Ok(k) => Some(k),
                Err(e) => {
                    tracing::debug!(robot = %id, "pose key not declared: {e}");
                    None
                }
            };
            run(host, id, (rx, took), shutdown).await;
            if let Some(k) = declared {
                if let Err(e) = session.undeclare(k).await {
                    tracing::debug!("pose key not undeclared: {e}");
                }
            }
        });
        let slot = Arc::new(PoseSlot {
            poses,
            handed: AtomicU64::new(0),
            taken,
        });
        Self { slot, task }
    }

    /// As [`PoseSlot::send`].
    pub fn send(&self, arrival: Arrival) -> bool {
        self.slot.send(arrival)
    }

    /// The worker's pose slot, to hand poses over outside the lock that keeps the worker.
    pub fn slot(&self) -> Arc<PoseSlot> {
        Arc::clone(&self.slot)
    }

    pub fn abort(&self) {
        self.task.abort();
    }
}

impl Drop for Worker {
    fn drop(&mut self) {
        self.task.abort();
    }
}

/// Per-robot planning state, owned by the robot's worker.
#[derive(Default)]
struct Pipeline {
    /// The robot's intention pipeline, made on its first task.
    planner: Option<IntentionPlanner>,
}

impl Pipeline {
    /// The pipeline on the planning map of the pose's map version.
    fn on_map(
        &mut self,
        host: &impl CycleHost,
        pose: &PoseEstimate,
    ) -> Result<&mut IntentionPlanner, FleetError> {
        let map = host.planning_map(&pose.map.name, pose.map.version)?;
        let planning = |source| FleetError::Planning {
            map: pose.map.name.to_string(),
            source,
        };
        match &mut self.planner {
            Some(p) => {
                p.set_map(map).map_err(planning)?;
                Ok(p)
            }
            slot @ None => {
                let made = IntentionPlanner::new(map, host.intention_config()).map_err(planning)?;
                Ok(slot.insert(made))
            }
        }
    }
}

/// The worker loop: plans from the newest pose, skipping the ones that arrived meanwhile.
async fn run<H: CycleHost>(
    host: Weak<H>,
    id: RobotId,
    (mut poses, taken): (watch::Receiver<Option<(u64, Arrival)>>, Arc<AtomicU64>),
    mut shutdown: watch::Receiver<bool>,
) {
    let mut state = Some(Pipeline::default());
    // The kept plan's due new search, while the pool runs it.
    let mut refreshing: Option<RefreshReply> = None;
    loop {
        tokio::select! {
            changed = poses.changed() => if changed.is_err() { break },
            _ = shutdown.changed() => break,
            refreshed = async { refreshing.as_mut()?.await.ok() }, if refreshing.is_some() => {
                refreshing = None;
                let planner = state.as_mut().and_then(|st| st.planner.as_mut());
                // No result: the pool is gone, and so is the host (the loop ends next).
                if let (Some(r), Some(p)) = (refreshed, planner) {
                    let adopted = p.adopt(r);
                    if let Err(e) = &adopted {
                        tracing::debug!(robot = %id, "the due new search found no path: {e}");
                    }
                    if let Some(h) = host.upgrade() {
                        h.refreshed(adopted.is_ok());
                    }
                }
                continue;
            }
        }
        let arrival = {
            let slot = poses.borrow_and_update();
            let Some((n, arrival)) = &*slot else {
                continue;
            };
            taken.store(*n, Ordering::Release);
            arrival.clone()
        };
        let Some(h) = host.upgrade() else {
            break;
        };
        let Some(mut st) = state.take() else {
            break;
        };
        let robot = id.clone();
        let done = match h.planning_slots().cloned() {
            None => {
                tokio::task::spawn_blocking(move || {
                    if let Some(c) = h.begin(&robot, &arrival.pose) {
                        plan(h.as_ref(), &robot, &arrival, c, &mut st);
                    }
                    st
                })
                .await
            }
            Some(slots) => {
                // The question waits on the network, not on a core: asked outside the slots,
                // so that a hundred waiting cycles never crowd out the thread that receives
                // the answers.
                let (asker, asked, pose) = (Arc::clone(&h), robot.clone(), arrival.pose.clone());
                match tokio::task::spawn_blocking(move || asker.begin(&asked, &pose)).await {
                    Ok(Some(c)) => {
                        let Ok(slot) = slots.acquire_owned().await else {
                            break;
                        };
                        tokio::task::spawn_blocking(move || {
                            let _slot = slot;
                            plan(h.as_ref(), &robot, &arrival, c, &mut st);
                            st
                        })
                        .await
                    }
                    Ok(None) => Ok(st),
                    Err(e) => Err(e),
                }
            }
        };
        match done {
            Ok(mut st) => {
                // The answer is out: a new search it left due runs in the background.
                let job = st.planner.as_mut().and_then(IntentionPlanner::take_refresh);
                if let (Some(job), Some(h)) = (job, host.upgrade()) {
                    refreshing = Some(h.refresh_pool().submit(job));
                }
                state = Some(st);
            }
            Err(e) => {
                tracing::error!(robot = %id, "replanning worker failed: {e}");
                state = Some(Pipeline::default());
            }
        }
    }
}

/// The rest of one replanning cycle of one robot (blocking pool), once the host has brought
/// its task up to date for the pose (`cycle`): the plan made, the intention sent, the outcome
/// reported.
fn plan(host: &impl CycleHost, id: &RobotId, arrival: &Arrival, cycle: Cycle, st: &mut Pipeline) {
    let pose = &arrival.pose;
    let Decision::Plan { task, goals, next } = cycle.decision else {
        let stop = stop_intention(host.header(), pose, None, 0);
        let sent = host.send_intention(id, &stop, arrival.received);
        host.finish(id, Outcome::Stopped { sent });
        return;
    };
    let answer = st.on_map(host, pose).map(|p| {
        p.answer_among(
            pose,
            &GoalProgress::new(&goals, next),
            cycle.render_lpe,
            &cycle.neighbours,
        )
    });
    let planned = match answer {
        Ok(Answer::Heading { goal_index, plan }) => {
            plan.map(|p| (goal_index, p))
                .map_err(|source| FleetError::Planning {
                    map: pose.map.name.to_string(),
                    source,
                })
        }
        // The book already moved past every goal in reach of this pose.
        Ok(Answer::Done) => Err(FleetError::Conflict(format!(
            "task {task} has no goal left after goal {next}"
        ))),
        Err(e) => Err(e),
    };
    let outcome = match planned {
        Ok((goal_index, planned)) => {
            // The image travels only to a robot whose controller reads it; the dashboard's
            // preview stays with the book.
            let intention =
                planned.intention(host.header(), pose, Some(task), goal_index, cycle.send_lpe);
            Outcome::Planned {
                sent: host.send_intention(id, &intention, arrival.received),
                lpe: planned.lpe,
                reused: planned.reused,
                avoided_robots: planned.avoided_robots,
            }
        }
        Err(e) => {
            tracing::debug!(robot = %id, task = %task, "replan failed: {e}");
            let stop = stop_intention(host.header(), pose, Some(task.clone()), next);
            Outcome::Failed {
                sent: host.send_intention(id, &stop, arrival.received),
                task,
                goal: next,
                error: e.to_string(),
            }
        }
    };
    host.finish(id, outcome);
}

/// Where planning maps come from: the service's own store, or the site's map store over Zenoh
/// (a worker process).
pub(crate) enum MapSource {
    Store(Arc<MapStore>),
    Zenoh {
        session: Session,
        site: SiteId,
        timeout: Duration,
        runtime: tokio::runtime::Handle,
    },
}

impl MapSource {
    fn grid(&self, name: &MapName, version: u32) -> Result<map_store::OccupancyGrid, FleetError> {
        match self {
            MapSource::Store(store) => store
                .get(name, Some(version))
                .map(|stored| stored.grid)
                .map_err(|e| FleetError::from_map(e, || format!("{name} version {version}"))),
            MapSource::Zenoh {
                session,
                site,
                timeout,
                runtime,
            } => {
                // Called from the blocking pool, where waiting on the runtime is allowed.
                let map = runtime
                    .block_on(map_store::fetch::fetch_map(
                        session,
                        site,
                        name,
                        Some(version),
                        *timeout,
                    ))
                    .map_err(|e| FleetError::from_map(e, || format!("{name} version {version}")))?;
                let meta = map.meta;
                map_store::OccupancyGrid::new(
                    meta.width_cells,
                    meta.height_cells,
                    meta.resolution_m,
                    meta.origin,
                    map.cells,
                )
                .map_err(FleetError::Map)
            }
        }
    }
}

/// Planning maps of stored map versions, built once and shared by every robot's pipeline.
///
/// Its lock is a leaf: held only to look up or insert, never while building a map or taking
/// another lock.
pub(crate) struct PlanningMaps {
    source: MapSource,
    planner: PlannerConfig,
    built: Mutex<HashMap<(MapName, u32), Arc<PlanningMap>>>,
}

impl PlanningMaps {
    pub fn new(source: MapSource, planner: PlannerConfig) -> Self {
        Self {
            source,
            planner,
            built: Mutex::new(HashMap::new()),
        }
    }

    /// The planning map of map `name` version `version`.
    ///
    /// # Errors
    /// [`FleetError::NotFound`] for a map the store does not have, a map or planning error.
    pub fn get(&self, name: &MapName, version: u32) -> Result<Arc<PlanningMap>, FleetError> {
        let key = (name.clone(), version);
        if let Some(m) = lock(&self.built).get(&key) {
            return Ok(Arc::clone(m));
        }
        let grid = self.source.grid(name, version)?;
        // Built outside the lock: a big map takes a while and other maps stay usable.
        let built = PlanningMap::with_key(grid, MapKey(u64::from(version)), &self.planner)
            .map_err(|source| FleetError::Planning {
                map: name.to_string(),
                source,
            })?;
        Ok(Arc::clone(
            lock(&self.built).entry(key).or_insert(Arc::new(built)),
        ))
    }
}

#[cfg(test)]
mod tests {
    use std::sync::mpsc;

    use protocol::{keys, MapRef, Pose2D, RobotTopic};

    use super::*;

    /// A host whose cycles stop at `begin` until the test lets each one go, so the test
    /// decides when the worker is busy; it reports the pose sequence number of each cycle.
    struct GatedHost {
        begun: Mutex<mpsc::Sender<u64>>,
        gate: Mutex<mpsc::Receiver<()>>,
        pool: RefreshPool,
    }

    impl CycleHost for GatedHost {
        fn begin(&self, _id: &RobotId, pose: &PoseEstimate) -> Option<Cycle> {
            lock(&self.begun).send(pose.header.seq).ok()?;
            lock(&self.gate).recv().ok()?;
            // No answer: the cycle ends here, as for a worker that cannot reach the service.
            None
        }

        fn planning_map(&self, name: &MapName, _: u32) -> Result<Arc<PlanningMap>, FleetError> {
            Err(FleetError::NotFound {
                what: "map",
                id: name.to_string(),
            })
        }

        fn intention_config(&self) -> IntentionConfig {
            IntentionConfig::default()
        }

        fn header(&self) -> Header {
            Header::new(0, 0)
        }

        fn send_intention(&self, _: &RobotId, _: &Intention, _: Instant) -> Option<IntentionView> {
            None
        }

        fn finish(&self, _: &RobotId, _: Outcome) {}

        fn refresh_pool(&self) -> &RefreshPool {
            &self.pool
        }
    }

    fn arrival(seq: u64) -> Arrival {
        Arrival {
            pose: PoseEstimate {
                header: Header::new(seq, seq),
                pose: Pose2D::new(1.0, 2.0, 0.0),
                covariance: [0.01, 0.0, 0.0, 0.0, 0.01, 0.0, 0.0, 0.0, 0.003],
                sensor_stamp_ns: seq,
                map: MapRef {
                    name: MapName::new("junctions").unwrap(),
                    version: 1,
                },
                unmapped_obstacles_m: Vec::new(),
            },
            received: Instant::now(),
        }
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn a_pose_replaced_before_the_busy_worker_took_it_is_reported_and_never_planned() {
        let session = protocol::zenoh_io::SessionArgs::new(&["tcp/127.0.0.1:0".into()], &[])
            .open()
            .await
            .unwrap();
        let (begun_tx, begun) = mpsc::channel();
        let (release, gate) = mpsc::channel();
        let host = Arc::new(GatedHost {
            begun: Mutex::new(begun_tx),
            gate: Mutex::new(gate),
            pool: RefreshPool::start(1),
        });
        let id = RobotId::new("r1").unwrap();
        let (_stop, shutdown) = watch::channel(false);
        let site = SiteId::new("site").unwrap();
        let worker = Worker::spawn(
            &tokio::runtime::Handle::current(),
            Arc::downgrade(&host),
            id.clone(),
            shutdown,
            (session, keys::robot(&site, &id, RobotTopic::Pose)),
        );
        let next_begun = |rx: &mpsc::Receiver<u64>| rx.recv_timeout(Duration::from_secs(10));

        assert!(!worker.send(arrival(1)), "nothing was waiting");
        assert_eq!(next_begun(&begun), Ok(1));
        // The worker is busy with pose 1: pose 2 waits, pose 3 replaces it.
        assert!(!worker.send(arrival(2)), "pose 1 was taken");
        assert!(worker.send(arrival(3)), "pose 2 was never taken");
        release.send(()).unwrap();
        assert_eq!(next_begun(&begun), Ok(3), "the newest pose is planned next");
        // Taken poses are never counted, however late the next one comes.
        assert!(!worker.send(arrival(4)));
        release.send(()).unwrap();
        assert_eq!(next_begun(&begun), Ok(4));
        release.send(()).unwrap();
    }
}
