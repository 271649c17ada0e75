//! Replanning in worker processes (`planner-service worker`), on this host or others.
//!
//! The service keeps the task book; workers only plan. A worker joins the site with a
//! liveliness token (`fleet/<site>/worker/<id>/alive`) and watches the others' tokens; each
//! robot is replanned by one worker, chosen by [`super::rendezvous`] over the live tokens, so
//! the workers share the robots without talking to each other. For a pose of one of its robots
//! a worker runs the same cycle as the service ([`super::worker`]): it asks the service what
//! the cycle is to do (a query on `fleet/<site>/cycle/<robot>`, answered from the task book:
//! goals advanced, task completed, or nothing to do), plans on its own copy of the planning
//! map (fetched from the map store over Zenoh), publishes the intention straight to the robot
//! and reports the outcome (`fleet/<site>/cycle/<robot>/outcome`), which the service books
//! exactly as it books its own cycles.
//!
//! While no worker is alive the service plans every robot itself. A worker that dies takes
//! its token with it; everyone recomputes the owners at once, and the next pose of each of its
//! robots is planned by the new owner (the robot's kept plan, if any, starts afresh there).

use std::collections::{BTreeSet, HashMap};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, Weak};
use std::time::{Duration, Instant};

use image::RgbImage;
use planning::{IntentionConfig, LpeImage, PlanningMap};
use protocol::keys::{self, RobotTopic};
use protocol::{
    Header, Intention, MapName, PoseEstimate, RobotId, SiteId, TaskId, ValidationError,
    WireMessage, WorkerId,
};
use serde::{Deserialize, Serialize};
use tokio::sync::{watch, Semaphore};
use zenoh::liveliness::LivelinessToken;
use zenoh::pubsub::Subscriber;
use zenoh::sample::{Sample, SampleKind};
use zenoh::{Session, Wait};

use super::core::Cycle;
use super::error::{zenoh_err, FleetError};
use super::publishers::Publishers;
use super::refresh::RefreshPool;
use super::types::IntentionView;
use super::worker::{Arrival, CycleHost, MapSource, Outcome, PlanningMaps, Worker};
use super::{lock, now_ns, rendezvous};
use crate::config::ServiceConfig;

/// A worker's question for one cycle: the pose it is about to plan from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CycleRequest {
    pub header: Header,
    pub worker_id: WorkerId,
    pub pose: PoseEstimate,
}

impl WireMessage for CycleRequest {
    const KIND: &'static str = "cycle_request";

    fn validate(&self) -> Result<(), ValidationError> {
        self.pose.validate()
    }
}

/// The service's answer: [`Cycle`] as the task book decided it.
impl WireMessage for Cycle {
    const KIND: &'static str = "cycle_order";
}

/// How a worker's cycle ended.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", tag = "kind")]
pub enum CycleResult {
    Stopped,
    Planned {
        reused: bool,
        /// How many other robots the path keeps clear of.
        #[serde(default)]
        avoided_robots: usize,
    },
    Failed {
        task_id: TaskId,
        goal_index: usize,
        error: String,
    },
}

/// Size of the LPE preview carried as a [`CycleReport`]'s blob (RGB, 3 bytes a pixel).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PreviewSize {
    pub width_px: u32,
    pub height_px: u32,
}

/// A worker's report of one cycle (framed: the LPE preview, when rendered, is the blob).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CycleReport {
    pub header: Header,
    pub worker_id: WorkerId,
    pub result: CycleResult,
    /// The intention that went out to the robot, with its latency on the worker.
    pub sent: Option<IntentionView>,
    pub preview: Option<PreviewSize>,
    /// Poses the worker let a newer one replace before it took them, since its last report
    /// (any robot's: the service counts them all as `fleet_poses_superseded_total`).
    #[serde(default)]
    pub superseded: u32,
    #[serde(skip)]
    pub preview_rgb: Vec<u8>,
}

impl WireMessage for CycleReport {
    const KIND: &'static str = "cycle_report";
    const FRAMED: bool = true;

    fn blob(&self) -> Option<&[u8]> {
        Some(&self.preview_rgb)
    }

    fn put_blob(&mut self, blob: Vec<u8>) -> Result<(), ValidationError> {
        self.preview_rgb = blob;
        self.validate()
    }

    fn validate(&self) -> Result<(), ValidationError> {
        let expected = self
            .preview
            .map_or(0, |p| u64::from(p.width_px) * u64::from(p.height_px) * 3);
        if self.preview_rgb.len() as u64 == expected {
            Ok(())
        } else {
            Err(ValidationError::new(
                "preview",
                format!(
                    "{:?} needs {expected} RGB bytes, got {}",
                    self.preview,
                    self.preview_rgb.len()
                ),
            ))
        }
    }
}

impl CycleReport {
    fn of(header: Header, worker_id: WorkerId, outcome: Outcome) -> Self {
        let (result, sent, lpe) = match outcome {
            Outcome::Stopped { sent } => (CycleResult::Stopped, sent, None),
            Outcome::Planned {
                sent,
                lpe,
                reused,
                avoided_robots,
            } => (
                CycleResult::Planned {
                    reused,
                    avoided_robots,
                },
                sent,
                lpe,
            ),
            Outcome::Failed {
                sent,
                task,
                goal,
                error,
            } => (
                CycleResult::Failed {
                    task_id: task,
                    goal_index: goal,
                    error,
                },
                sent,
                None,
            ),
        };
        let preview = lpe.as_ref().map(|l| PreviewSize {
            width_px: l.image.width(),
            height_px: l.image.height(),
        });
        Self {
            header,
            worker_id,
            result,
            sent,
            preview,
            superseded: 0,
            preview_rgb: lpe.map(|l| l.image.into_raw()).unwrap_or_default(),
        }
    }

    /// The outcome to book (a preview that does not fit its size is dropped).
    #[must_use]
    pub(crate) fn into_outcome(self) -> Outcome {
        let lpe = self.preview.and_then(|p| {
            RgbImage::from_raw(p.width_px, p.height_px, self.preview_rgb)
                .map(|image| LpeImage { image })
        });
        match self.result {
            CycleResult::Stopped => Outcome::Stopped { sent: self.sent },
            CycleResult::Planned {
                reused,
                avoided_robots,
            } => Outcome::Planned {
                sent: self.sent,
                lpe,
                reused,
                avoided_robots,
            },
            CycleResult::Failed {
                task_id,
                goal_index,
                error,
            } => Outcome::Failed {
                sent: self.sent,
                task: task_id,
                goal: goal_index,
                error,
            },
        }
    }
}

/// A worker process's settings.
#[derive(Debug, Clone)]
pub struct WorkerOptions {
    pub id: WorkerId,
    pub site: SiteId,
    /// Its `[planner]`, `[dlm]`, `[lpe]`, `[path_reuse]` and `[fleet]` tables (the intention
    /// pipeline, as the service would run it).
    pub config: ServiceConfig,
    /// How long a cycle waits for the service's answer, and a map for the map store's.
    pub query_timeout: Duration,
}

/// What a worker keeps of its Zenoh side, released on shutdown.
#[derive(Default)]
struct WorkerIo {
    subscribers: Vec<Subscriber<()>>,
    token: Option<LivelinessToken>,
}

/// A replanning worker process's node (see the module docs); shared as `Arc<WorkerNode>`.
pub struct WorkerNode {
    me: Weak<WorkerNode>,
    options: WorkerOptions,
    session: Session,
    /// The intention and cycle-outcome publishers of the robots this process plans.
    publishers: Publishers,
    runtime: tokio::runtime::Handle,
    planning: PlanningMaps,
    /// The live workers, this one included.
    members: Mutex<BTreeSet<WorkerId>>,
    /// The workers of the robots this process plans now.
    robots: Mutex<HashMap<RobotId, Worker>>,
    shutdown: watch::Sender<bool>,
    io: Mutex<WorkerIo>,
    seq: AtomicU64,
    cycles: AtomicU64,
    /// One plan at a time per core this process may use (its affinity, e.g. `taskset`).
    planning_slots: Arc<Semaphore>,
    /// Kept plans' due new searches, below the answers' priority.
    refresh: RefreshPool,
    /// Poses superseded since the last report went out (see [`CycleReport::superseded`]).
    superseded: AtomicU64,
}

impl WorkerNode {
    /// Joins the site: watches the other workers, subscribes the robots' poses and declares
    /// its liveliness token last, so nobody counts on it before it listens.
    ///
    /// # Errors
    /// [`FleetError::Config`] for an invalid configuration, [`FleetError::Zenoh`].
    pub async fn start(
        session: Session,
        options: WorkerOptions,
    ) -> Result<Arc<WorkerNode>, FleetError> {
        options
            .config
            .planner
            .validate()
            .map_err(|e| FleetError::Config(e.to_string()))?;
        let (shutdown, _) = watch::channel(false);
        let site = options.site.clone();
        let node = Arc::new_cyclic(|me| WorkerNode {
            me: me.clone(),
            publishers: Publishers::new(session.clone()),
            planning: PlanningMaps::new(
                MapSource::Zenoh {
                    session: session.clone(),
                    site: site.clone(),
                    timeout: options.query_timeout,
                    runtime: tokio::runtime::Handle::current(),
                },
                options.config.planner.clone(),
            ),
            members: Mutex::new(BTreeSet::from([options.id.clone()])),
            options,
            session,
            runtime: tokio::runtime::Handle::current(),
            robots: Mutex::new(HashMap::new()),
            shutdown,
            io: Mutex::new(WorkerIo::default()),
            seq: AtomicU64::new(0),
            cycles: AtomicU64::new(0),
            planning_slots: Arc::new(Semaphore::new(super::cores())),
            refresh: RefreshPool::start(super::cores()),
            superseded: AtomicU64::new(0),
        });
        let me = Arc::downgrade(&node);
        let members = node
            .session
            .liveliness()
            .declare_subscriber(keys::workers_alive(&site))
            .history(true)
            .callback(move |s| {
                if let Some(n) = me.upgrade() {
                    n.on_worker(&s);
                }
            })
            .await
            .map_err(zenoh_err("watch the workers"))?;
        let me = Arc::downgrade(&node);
        let poses = node
            .session
            .declare_subscriber(keys::all_robots(&site, RobotTopic::Pose))
            .callback(move |s| {
                if let Some(n) = me.upgrade() {
                    n.on_pose(&s);
                }
            })
            .await
            .map_err(zenoh_err("subscribe poses"))?;
        let token = node
            .session
            .liveliness()
            .declare_token(keys::worker_alive(&site, &node.options.id))
            .await
            .map_err(zenoh_err("declare the worker's liveliness token"))?;
        {
            let mut io = lock(&node.io);
            io.subscribers = vec![members, poses];
            io.token = Some(token);
        }
        tracing::info!(worker = %node.options.id, site = %site, "worker joined");
        Ok(node)
    }

    #[must_use]
    pub fn id(&self) -> &WorkerId {
        &self.options.id
    }

    /// The live workers this one knows of, itself included.
    #[must_use]
    pub fn members(&self) -> Vec<WorkerId> {
        lock(&self.members).iter().cloned().collect()
    }

    /// Cycles this worker has run (each answered one pose).
    #[must_use]
    pub fn cycles(&self) -> u64 {
        self.cycles.load(Ordering::Relaxed)
    }

    /// Leaves the site: the token goes (the others take the robots over), the robots'
    /// workers stop.
    pub async fn shutdown(&self) {
        self.shutdown.send_replace(true);
        let io = std::mem::take(&mut *lock(&self.io));
        if let Some(token) = io.token {
            if let Err(e) = token.undeclare().await {
                tracing::warn!("cannot undeclare the worker's token: {e}");
            }
        }
        for s in io.subscribers {
            if let Err(e) = s.undeclare().await {
                tracing::warn!("cannot undeclare subscriber: {e}");
            }
        }
        lock(&self.robots).clear();
    }

    fn on_worker(&self, sample: &Sample) {
        let Some((site, worker)) = keys::parse_worker_alive_key(sample.key_expr().as_str()) else {
            return;
        };
        if site != self.options.site || worker == self.options.id {
            return;
        }
        let mut members = lock(&self.members);
        match sample.kind() {
            SampleKind::Put => {
                if members.insert(worker.clone()) {
                    tracing::info!(worker = %worker, "worker joined");
                }
            }
            SampleKind::Delete => {
                if members.remove(&worker) {
                    tracing::warn!(worker = %worker, "worker left: its robots move");
                }
            }
        }
    }

    fn on_pose(&self, sample: &Sample) {
        let Some((site, robot, topic)) = keys::parse_robot_key(sample.key_expr().as_str()) else {
            return;
        };
        if site != self.options.site || topic != RobotTopic::Pose {
            return;
        }
        let mine = {
            let members = lock(&self.members);
            rendezvous::owner(&robot, members.iter()) == Some(&self.options.id)
        };
        let mut robots = lock(&self.robots);
        if !mine {
            // Another worker has it now; a robot that comes back starts afresh.
            robots.remove(&robot);
            return;
        }
        let pose: PoseEstimate = match protocol::decode_sample(sample) {
            Ok(p) => p,
            Err(e) => {
                tracing::warn!(robot = %robot, "ignoring pose: {e}");
                return;
            }
        };
        let arrival = Arrival {
            pose,
            received: Instant::now(),
        };
        let superseded = robots
            .entry(robot.clone())
            .or_insert_with(|| {
                let pose_key = keys::robot(&self.options.site, &robot, RobotTopic::Pose);
                Worker::spawn(
                    &self.runtime,
                    self.me.clone(),
                    robot,
                    self.shutdown.subscribe(),
                    (self.session.clone(), pose_key),
                )
            })
            .send(arrival);
        if superseded {
            self.superseded.fetch_add(1, Ordering::Relaxed);
        }
    }

    /// Publishes `msg` on `key`; whether it went out (a failure is logged here).
    fn put<M: WireMessage>(&self, key: &zenoh::key_expr::OwnedKeyExpr, msg: &M) -> bool {
        match self.publishers.put(key, msg) {
            Ok(()) => true,
            Err(e) => {
                tracing::warn!(key = %key, "cannot publish: {e}");
                false
            }
        }
    }
}

impl CycleHost for WorkerNode {
    fn begin(&self, id: &RobotId, pose: &PoseEstimate) -> Option<Cycle> {
        let request = CycleRequest {
            header: self.header(),
            worker_id: self.options.id.clone(),
            pose: pose.clone(),
        };
        let bytes = match protocol::encode(&request) {
            Ok(b) => b,
            Err(e) => {
                tracing::warn!(robot = %id, "cannot encode the cycle request: {e}");
                return None;
            }
        };
        let key = keys::cycle(&self.options.site, id);
        let replies = match self
            .session
            .get(&key)
            .payload(bytes)
            .encoding(protocol::zenoh_io::encoding_for::<CycleRequest>())
            .timeout(self.options.query_timeout)
            .wait()
        {
            Ok(r) => r,
            Err(e) => {
                tracing::warn!(robot = %id, "cannot ask the service: {e}");
                return None;
            }
        };
        // Blocking pool: waiting here is what the cycle does anyway.
        let Ok(reply) = replies.recv() else {
            tracing::warn!(robot = %id, "the service did not answer the cycle query");
            return None;
        };
        match reply.result() {
            Ok(sample) => match protocol::decode_sample::<Cycle>(sample) {
                Ok(cycle) => Some(cycle),
                Err(e) => {
                    tracing::warn!(robot = %id, "bad cycle answer: {e}");
                    None
                }
            },
            Err(e) => {
                tracing::warn!(
                    robot = %id,
                    "the service refused the cycle: {}",
                    e.payload().try_to_string().unwrap_or_default()
                );
                None
            }
        }
    }

    fn planning_map(&self, name: &MapName, version: u32) -> Result<Arc<PlanningMap>, FleetError> {
        self.planning.get(name, version)
    }

    fn intention_config(&self) -> IntentionConfig {
        self.options.config.intention()
    }

    fn header(&self) -> Header {
        Header::new(self.seq.fetch_add(1, Ordering::Relaxed), now_ns())
    }

    fn send_intention(
        &self,
        id: &RobotId,
        intention: &Intention,
        received: Instant,
    ) -> Option<IntentionView> {
        let key = keys::robot(&self.options.site, id, RobotTopic::Intention);
        self.put(&key, intention).then(|| IntentionView {
            latency_ms: received.elapsed().as_secs_f64() * 1e3,
            ..IntentionView::of(intention)
        })
    }

    fn planning_slots(&self) -> Option<&Arc<Semaphore>> {
        Some(&self.planning_slots)
    }

    fn refresh_pool(&self) -> &RefreshPool {
        &self.refresh
    }

    fn finish(&self, id: &RobotId, outcome: Outcome) {
        self.cycles.fetch_add(1, Ordering::Relaxed);
        let mut report = CycleReport::of(self.header(), self.options.id.clone(), outcome);
        let superseded = self.superseded.swap(0, Ordering::Relaxed);
        report.superseded = u32::try_from(superseded).unwrap_or(u32::MAX);
        self.put(&keys::cycle_outcome(&self.options.site, id), &report);
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use protocol::{Dlm, MapRef, Pose2D};

    use super::*;

    fn view() -> IntentionView {
        IntentionView {
            task_id: Some(TaskId::new("t1").unwrap()),
            goal_index: 1,
            dlm: Dlm::TurnLeft,
            arriving: false,
            path: vec![Pose2D::new(1.0, 2.0, 0.5)],
            stamp_ns: 7,
            latency_ms: 3.5,
        }
    }

    #[test]
    fn a_report_with_a_preview_round_trips_through_the_wire() {
        let image = RgbImage::from_fn(4, 3, |x, y| image::Rgb([x as u8, y as u8, 9]));
        let outcome = Outcome::Planned {
            sent: Some(view()),
            lpe: Some(LpeImage {
                image: image.clone(),
            }),
            reused: true,
            avoided_robots: 2,
        };
        let mut report = CycleReport::of(Header::new(1, 2), WorkerId::new("w1").unwrap(), outcome);
        report.superseded = 3;
        let bytes = protocol::encode(&report).unwrap();
        let back: CycleReport = protocol::decode(&bytes).unwrap();
        assert_eq!(back, report);
        match back.into_outcome() {
            Outcome::Planned {
                sent,
                lpe,
                reused,
                avoided_robots,
            } => {
                assert_eq!(sent, Some(view()));
                assert_eq!(lpe.unwrap().image, image);
                assert!(reused);
                assert_eq!(avoided_robots, 2);
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn a_report_whose_preview_does_not_fit_is_rejected_naming_it() {
        let mut report = CycleReport::of(
            Header::new(1, 2),
            WorkerId::new("w1").unwrap(),
            Outcome::Stopped { sent: None },
        );
        report.preview = Some(PreviewSize {
            width_px: 2,
            height_px: 2,
        });
        let err = protocol::encode(&report).unwrap_err().to_string();
        assert!(err.contains("preview"), "{err}");
    }

    #[test]
    fn requests_and_orders_round_trip() {
        let request = CycleRequest {
            header: Header::new(3, 4),
            worker_id: WorkerId::new("w2").unwrap(),
            pose: PoseEstimate {
                header: Header::new(5, 6),
                pose: Pose2D::new(1.0, 1.0, 0.0),
                covariance: [0.0; 9],
                sensor_stamp_ns: 6,
                map: MapRef {
                    name: MapName::new("m").unwrap(),
                    version: 1,
                },
                unmapped_obstacles_m: Vec::new(),
            },
        };
        let back: CycleRequest = protocol::decode(&protocol::encode(&request).unwrap()).unwrap();
        assert_eq!(back, request);
        let order = Cycle {
            decision: super::super::book::Decision::Plan {
                task: TaskId::new("t1").unwrap(),
                goals: vec![planning::Goal::at(1.0, 2.0)],
                next: 0,
            },
            render_lpe: true,
            send_lpe: false,
            neighbours: vec![planning::Neighbour {
                pose: Pose2D::new(3.0, 1.0, 0.5),
                vx_mps: 0.4,
                vy_mps: -0.1,
            }],
        };
        let back: Cycle = protocol::decode(&protocol::encode(&order).unwrap()).unwrap();
        assert_eq!(back, order);
    }
}
