//! Per-robot replanning workers and the planning maps they share.
//!
//! Each robot the adapter registers gets one worker, started right then (never as a side
//! effect of a lookup). Poses reach it through a one-slot channel: a worker that is still
//! planning skips the poses that arrived meanwhile and plans from the newest, so a slow robot
//! or a slow plan never queues up, and workers of different robots run in parallel on the
//! blocking pool. A worker owns its robot's [`IntentionPlanner`]; the planning itself (goal
//! advancement, hybrid A*, DLM, LPE, path thinning) is the planning crate's, called through
//! [`IntentionPlanner::answer`].

use std::collections::HashMap;
use std::sync::{Arc, Mutex, Weak};
use std::time::Instant;

use map_store::MapStore;
use planning::{
    stop_intention, Answer, GoalProgress, IntentionPlanner, MapKey, PlannerConfig, PlanningMap,
};
use protocol::{MapName, PoseEstimate, RobotId};
use tokio::sync::watch;

use super::book::Decision;
use super::error::FleetError;
use super::{lock, Fleet, Now};

/// A pose and when it reached the service (for the intention latency).
#[derive(Debug, Clone)]
pub(super) struct Arrival {
    pub pose: PoseEstimate,
    pub received: Instant,
}

/// The running worker of one robot: its pose slot and its task.
#[derive(Debug)]
pub(super) struct Worker {
    poses: watch::Sender<Option<Arrival>>,
    task: tokio::task::JoinHandle<()>,
}

impl Worker {
    /// Starts the worker of robot `id` on `runtime`; it ends with `shutdown` or the fleet.
    pub fn spawn(
        runtime: &tokio::runtime::Handle,
        fleet: Weak<Fleet>,
        id: RobotId,
        shutdown: watch::Receiver<bool>,
    ) -> Self {
        let (poses, rx) = watch::channel(None);
        let task = runtime.spawn(run(fleet, id, rx, shutdown));
        Self { poses, task }
    }

    /// Hands the worker the newest pose (replacing one it has not taken yet).
    pub fn send(&self, arrival: Arrival) {
        self.poses.send_replace(Some(arrival));
    }

    pub fn abort(&self) {
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
        fleet: &Fleet,
        pose: &PoseEstimate,
    ) -> Result<&mut IntentionPlanner, FleetError> {
        let map = fleet.planning.get(&pose.map.name, pose.map.version)?;
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
                let made =
                    IntentionPlanner::new(map, fleet.config.intention()).map_err(planning)?;
                Ok(slot.insert(made))
            }
        }
    }
}

/// The worker loop: plans from the newest pose, skipping the ones that arrived meanwhile.
async fn run(
    fleet: Weak<Fleet>,
    id: RobotId,
    mut poses: watch::Receiver<Option<Arrival>>,
    mut shutdown: watch::Receiver<bool>,
) {
    let mut state = Some(Pipeline::default());
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
            cycle(&f, &robot, &arrival, &mut st);
            st
        })
        .await
        {
            Ok(st) => state = Some(st),
            Err(e) => {
                tracing::error!(robot = %id, "replanning worker failed: {e}");
                state = Some(Pipeline::default());
            }
        }
    }
}

/// One replanning cycle of one robot for the pose that just arrived (blocking pool): the task
/// brought up to date under the fleet's lock, the plan made outside it, the intention sent,
/// the outcome recorded.
fn cycle(fleet: &Fleet, id: &RobotId, arrival: &Arrival, st: &mut Pipeline) {
    let pose = &arrival.pose;
    let watched = fleet.watched();
    let cycle = fleet.with_core(|core| core.begin_cycle(id, pose, Now::read(), watched));
    let Decision::Plan { task, goals, next } = cycle.decision else {
        let stop = stop_intention(fleet.header(), pose, None, 0);
        if let Some(view) = fleet.send_intention(id, &stop, Some(arrival.received)) {
            fleet.with_core(|core| (core.intention_sent(id, view.clone()), Vec::new()));
            fleet.intention_event(id, view);
        }
        return;
    };
    let answer = st
        .on_map(fleet, pose)
        .map(|p| p.answer(pose, &GoalProgress::new(&goals, next), cycle.render_lpe));
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
    match planned {
        Ok((goal_index, planned)) => {
            fleet.metrics.record_replan(true);
            if planned.reused {
                fleet.metrics.record_reuse();
            }
            // The image travels only to a robot whose controller reads it; the dashboard's
            // preview stays here.
            let intention =
                planned.intention(fleet.header(), pose, Some(task), goal_index, cycle.send_lpe);
            let sent = fleet.send_intention(id, &intention, Some(arrival.received));
            let view = sent.clone();
            fleet.with_core(|core| (core.planned(id, view, planned.lpe, Now::read()), Vec::new()));
            if let Some(view) = sent {
                fleet.intention_event(id, view);
            }
        }
        Err(e) => {
            fleet.metrics.record_replan(false);
            tracing::debug!(robot = %id, task = %task, "replan failed: {e}");
            let stop = stop_intention(fleet.header(), pose, Some(task.clone()), next);
            let sent = fleet.send_intention(id, &stop, Some(arrival.received));
            let view = sent.clone();
            let error = e.to_string();
            fleet.with_core(|core| {
                let effects = core.plan_failed(id, view, &task, next, &error, Now::read());
                ((), effects)
            });
            if let Some(view) = sent {
                fleet.intention_event(id, view);
            }
        }
    }
}

/// Planning maps of stored map versions, built once and shared by every robot's pipeline.
///
/// Its lock is a leaf: held only to look up or insert, never while building a map or taking
/// another lock.
pub(super) struct PlanningMaps {
    maps: Arc<MapStore>,
    planner: PlannerConfig,
    built: Mutex<HashMap<(MapName, u32), Arc<PlanningMap>>>,
}

impl PlanningMaps {
    pub fn new(maps: Arc<MapStore>, planner: PlannerConfig) -> Self {
        Self {
            maps,
            planner,
            built: Mutex::new(HashMap::new()),
        }
    }

    pub fn store(&self) -> &Arc<MapStore> {
        &self.maps
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
        let stored = self
            .maps
            .get(name, Some(version))
            .map_err(|e| FleetError::from_map(e, || format!("{name} version {version}")))?;
        // Built outside the lock: a big map takes a while and other maps stay usable.
        let built = PlanningMap::with_key(stored.grid, MapKey(u64::from(version)), &self.planner)
            .map_err(|source| FleetError::Planning {
            map: name.to_string(),
            source,
        })?;
        Ok(Arc::clone(
            lock(&self.built).entry(key).or_insert(Arc::new(built)),
        ))
    }
}
