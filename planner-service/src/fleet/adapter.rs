//! The fleet's Zenoh side: decodes what robots publish (pose, status, camera, liveliness),
//! hands it to the core, starts a robot's worker when the robot is first registered, and
//! publishes what the core decided. Also the two background loops: the watchdog and the
//! publisher of announcements.
//!
//! With worker processes on the site (`planner-service worker`, [`super::remote`]) it also
//! watches their liveliness tokens, answers their cycle queries from the task book and books
//! the outcomes they report.
//!
//! Announcements (task changes, a stop for a robot whose task was cancelled, robot events)
//! are queued while the core is locked, in the order the core made them, and one publisher
//! task puts them on Zenoh and the event bus: nothing is published under the lock, and a
//! subscriber never sees a task's states out of order.

use std::sync::Weak;
use std::time::{Duration, Instant};

use protocol::keys::{self, RobotTopic};
use protocol::{
    AgentStatus, CameraFrame, Intention, PoseEstimate, RobotId, SiteId, TaskEvent, WireMessage,
};
use tokio::sync::{broadcast, mpsc, watch};
use zenoh::pubsub::Subscriber;
use zenoh::query::{Query, Queryable};
use zenoh::sample::{Sample, SampleKind};
use zenoh::{Session, Wait};

use super::error::{zenoh_err, FleetError};
use super::remote::{CycleReport, CycleRequest};
use super::types::{FleetEvent, IntentionView, Task};
use super::{now_ns, Fleet, Now};
use crate::fleet::worker::{Arrival, Worker};

/// Something to publish, made under the core's lock and sent after it.
#[derive(Debug)]
pub(super) enum Outgoing {
    /// A task change: on the task's key and the event bus.
    Task(Box<(TaskEvent, Task)>),
    /// An intention that answers no pose (a stop after a cancel), with its view.
    Intention {
        robot: RobotId,
        intention: Box<Intention>,
        view: IntentionView,
    },
    /// A live-stream event only.
    Event(Box<FleetEvent>),
}

/// Subscribes the robots' pose, status and camera keys and their liveliness tokens, the
/// workers' tokens and cycle outcomes, and declares the cycle queryable.
///
/// # Errors
/// [`FleetError::Zenoh`].
pub(super) async fn subscribe(
    session: &Session,
    site: &SiteId,
    fleet: &Weak<Fleet>,
) -> Result<(Vec<Subscriber<()>>, Queryable<()>), FleetError> {
    let mut subs = Vec::new();
    let me = fleet.clone();
    let outcomes = session
        .declare_subscriber(keys::all_cycle_outcomes(site))
        .callback(move |s| {
            if let Some(f) = me.upgrade() {
                f.on_outcome(&s);
            }
        })
        .await
        .map_err(zenoh_err("subscribe cycle outcomes"))?;
    subs.push(outcomes);
    let me = fleet.clone();
    let cycles = session
        .declare_queryable(keys::cycle_queryable(site))
        .callback(move |q| {
            if let Some(f) = me.upgrade() {
                f.on_cycle_query(&q);
            }
        })
        .await
        .map_err(zenoh_err("declare the cycle queryable"))?;
    let me = fleet.clone();
    let workers = session
        .liveliness()
        .declare_subscriber(keys::workers_alive(site))
        .history(true)
        .callback(move |s| {
            if let Some(f) = me.upgrade() {
                f.on_worker(&s);
            }
        })
        .await
        .map_err(zenoh_err("watch the workers"))?;
    subs.push(workers);
    for (topic, action) in [
        (RobotTopic::Pose, "subscribe poses"),
        (RobotTopic::Status, "subscribe status"),
        (RobotTopic::Camera, "subscribe cameras"),
    ] {
        let me = fleet.clone();
        let sub = session
            .declare_subscriber(keys::all_robots(site, topic))
            .callback(move |s| {
                if let Some(f) = me.upgrade() {
                    match topic {
                        RobotTopic::Pose => f.on_pose(&s),
                        RobotTopic::Status => f.on_status(&s),
                        _ => f.on_camera(&s),
                    }
                }
            })
            .await
            .map_err(zenoh_err(action))?;
        subs.push(sub);
    }
    let me = fleet.clone();
    let alive = session
        .liveliness()
        .declare_subscriber(keys::alive_all(site))
        .history(true)
        .callback(move |s| {
            if let Some(f) = me.upgrade() {
                f.on_liveliness(&s);
            }
        })
        .await
        .map_err(zenoh_err("subscribe liveliness"))?;
    subs.push(alive);
    Ok((subs, cycles))
}

impl Fleet {
    fn robot_of(&self, sample: &Sample, topic: RobotTopic) -> Option<RobotId> {
        match keys::parse_robot_key(sample.key_expr().as_str()) {
            Some((site, id, t)) if site == self.site && t == topic => Some(id),
            _ => None,
        }
    }

    /// The robot a sample of `topic` is from and its decoded message; a sample of another
    /// site or topic is skipped, one that does not decode is logged and skipped.
    fn robot_message<M: protocol::WireMessage>(
        &self,
        sample: &Sample,
        topic: RobotTopic,
    ) -> Option<(RobotId, M)> {
        let id = self.robot_of(sample, topic)?;
        match protocol::decode_sample(sample) {
            Ok(m) => Some((id, m)),
            Err(e) => {
                tracing::warn!(robot = %id, "ignoring {topic:?}: {e}");
                None
            }
        }
    }

    fn on_pose(&self, sample: &Sample) {
        let Some((id, pose)) = self.robot_message::<PoseEstimate>(sample, RobotTopic::Pose) else {
            return;
        };
        let received = Instant::now();
        let now = Now {
            at: received,
            wall_ns: now_ns(),
        };
        let watched = self.watched();
        let slot = self.with_state(|state| {
            let (seen, effects) = state.core.pose_arrived(&id, pose.clone(), now, watched);
            if seen.new {
                self.start_worker(state, &id);
            }
            // While worker processes are alive they plan every robot.
            let slot = if state.remote.is_empty() {
                state.workers.get(&id).map(Worker::slot)
            } else {
                None
            };
            (slot, effects)
        });
        // Outside the lock: waking the worker is a system call, and every cycle takes the lock.
        if slot.is_some_and(|s| s.send(Arrival { pose, received })) {
            self.metrics.record_superseded(1);
        }
    }

    fn on_status(&self, sample: &Sample) {
        let Some((id, status)) = self.robot_message::<AgentStatus>(sample, RobotTopic::Status)
        else {
            return;
        };
        self.with_state(|state| {
            let (new, effects) = state.core.status_arrived(&id, status, Now::read());
            if new {
                self.start_worker(state, &id);
            }
            ((), effects)
        });
    }

    fn on_camera(&self, sample: &Sample) {
        let Some(id) = self.robot_of(sample, RobotTopic::Camera) else {
            return;
        };
        let now = Instant::now();
        if !self.with_core(|core| (core.registry.camera_due(&id, now), Vec::new())) {
            return;
        }
        // Decoded outside the lock: frames are the biggest messages on the bus.
        match protocol::decode_sample::<CameraFrame>(sample) {
            Ok(frame) => {
                self.with_core(|core| (core.registry.set_camera(&id, frame.image, now), Vec::new()))
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
                let reason = "robot left (its liveliness token is gone)";
                self.with_core(|core| ((), core.robot_left(&id, reason, Now::read())));
            }
        }
    }

    /// A worker process's liveliness token came or went.
    fn on_worker(&self, sample: &Sample) {
        let Some((site, worker)) = keys::parse_worker_alive_key(sample.key_expr().as_str()) else {
            return;
        };
        if site != self.site {
            return;
        }
        let joined = sample.kind() == SampleKind::Put;
        let alive = self.with_state(|state| {
            if joined {
                state.remote.insert(worker.clone());
            } else {
                state.remote.remove(&worker);
            }
            (state.remote.len(), Vec::new())
        });
        if joined {
            tracing::info!(worker = %worker, alive, "replanning worker joined");
        } else if alive == 0 {
            tracing::warn!(worker = %worker, "replanning worker left; the service plans again");
        } else {
            tracing::warn!(worker = %worker, alive, "replanning worker left; its robots move");
        }
    }

    /// A worker asks what a robot's cycle is to do: the task book answers, as for the
    /// service's own cycles.
    fn on_cycle_query(&self, query: &Query) {
        let refuse = |reason: String| {
            tracing::warn!(key = %query.key_expr(), "refusing cycle query: {reason}");
            if let Err(e) = query.reply_err(reason).wait() {
                tracing::warn!("cannot answer cycle query: {e}");
            }
        };
        let robot = match keys::parse_cycle_key(query.key_expr().as_str()) {
            Some((site, robot, false)) if site == self.site => robot,
            _ => return refuse("not a cycle key of this site".into()),
        };
        let request = match query
            .payload()
            .map(|p| protocol::decode::<CycleRequest>(&p.to_bytes()))
        {
            Some(Ok(r)) => r,
            Some(Err(e)) => return refuse(format!("bad cycle request: {e}")),
            None => return refuse("a cycle query carries the pose".into()),
        };
        let cycle = self.begin_cycle(&robot, &request.pose);
        let answer = encode(&cycle).and_then(|bytes| {
            query
                .reply(query.key_expr(), bytes)
                .encoding(protocol::zenoh_io::encoding_for::<super::core::Cycle>())
                .wait()
                .map_err(zenoh_err("reply"))
        });
        if let Err(e) = answer {
            tracing::warn!(robot = %robot, worker = %request.worker_id, "cannot answer cycle query: {e}");
        }
    }

    /// A worker reports how a cycle ended: booked like the service's own.
    fn on_outcome(&self, sample: &Sample) {
        let robot = match keys::parse_cycle_key(sample.key_expr().as_str()) {
            Some((site, robot, true)) if site == self.site => robot,
            _ => return,
        };
        match protocol::decode_sample::<CycleReport>(sample) {
            Ok(report) => {
                self.metrics.record_superseded(u64::from(report.superseded));
                let worker = report.worker_id.to_string();
                self.finish_cycle(&worker, &robot, report.into_outcome());
            }
            Err(e) => tracing::warn!(robot = %robot, "ignoring cycle outcome: {e}"),
        }
    }

    /// One watchdog round (see [`super::core::Core::watchdog`]).
    fn watchdog_round(&self) {
        let counts = self.with_core(|core| core.watchdog(Now::read()));
        self.metrics.set_robots(counts.online, counts.offline);
    }

    /// Publishes an intention to its robot from synchronous code (a worker); `received` is
    /// when the answered pose arrived. The view to record, if it went out.
    pub(super) fn send_intention(
        &self,
        robot: &RobotId,
        intention: &Intention,
        received: Instant,
    ) -> Option<IntentionView> {
        let key = keys::robot(&self.site, robot, RobotTopic::Intention);
        if let Err(e) = self.publishers.put(&key, intention) {
            tracing::warn!(robot = %robot, "cannot publish intention: {e}");
            return None;
        }
        Some(IntentionView {
            latency_ms: received.elapsed().as_secs_f64() * 1e3,
            ..IntentionView::of(intention)
        })
    }

    /// Streams an intention that went out.
    pub(super) fn intention_event(&self, robot: &RobotId, intention: IntentionView) {
        // No receiver is not an error: nobody watches the dashboard.
        let _ = self.events.send(FleetEvent::Intention {
            robot_id: robot.clone(),
            intention,
        });
    }
}

/// Puts the announcements in the order they were made (see the module docs), until the fleet
/// is gone or shut down.
pub(super) async fn publisher(
    session: Session,
    site: SiteId,
    mut outgoing: mpsc::UnboundedReceiver<Outgoing>,
    events: broadcast::Sender<FleetEvent>,
) {
    while let Some(out) = outgoing.recv().await {
        // No receiver on the event bus is not an error: nobody watches the dashboard.
        match out {
            Outgoing::Task(change) => {
                let (event, task) = *change;
                let key = keys::task(&site, &task.id);
                if let Err(e) = put(&session, &key, &event).await {
                    tracing::warn!(task = %task.id, "cannot publish task event: {e}");
                }
                let _ = events.send(FleetEvent::Task(task));
            }
            Outgoing::Intention {
                robot,
                intention,
                view,
            } => {
                let key = keys::robot(&site, &robot, RobotTopic::Intention);
                match put(&session, &key, intention.as_ref()).await {
                    Ok(()) => {
                        let _ = events.send(FleetEvent::Intention {
                            robot_id: robot,
                            intention: view,
                        });
                    }
                    Err(e) => tracing::warn!(robot = %robot, "cannot publish intention: {e}"),
                }
            }
            Outgoing::Event(event) => {
                let _ = events.send(*event);
            }
        }
    }
}

/// Every 200 ms: silent robots go offline, long-paused tasks fail, queued tasks are dispatched.
pub(super) async fn watchdog(fleet: Weak<Fleet>, mut shutdown: watch::Receiver<bool>) {
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
        // The watchdog writes to the task store: keep it off the async workers.
        if let Err(e) = tokio::task::spawn_blocking(move || f.watchdog_round()).await {
            tracing::error!("watchdog round failed: {e}");
        }
    }
}

pub(super) fn encode<M: WireMessage>(msg: &M) -> Result<Vec<u8>, FleetError> {
    protocol::encode(msg).map_err(|e| FleetError::Zenoh {
        action: "encode",
        reason: e.to_string(),
    })
}

async fn put<M: WireMessage>(
    session: &Session,
    key: &zenoh::key_expr::OwnedKeyExpr,
    msg: &M,
) -> Result<(), FleetError> {
    session
        .put(key, encode(msg)?)
        .encoding(protocol::zenoh_io::encoding_for::<M>())
        .await
        .map_err(zenoh_err("put"))
}
