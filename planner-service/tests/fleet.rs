//! The fleet core over real Zenoh sessions on loopback, a real task database and a real floor
//! plan (the sim's `junctions` plan): a test-side robot publishes poses and follows the
//! intentions it gets, the way an agent does.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use map_store::{import_into, ImportLimits, MapStore};
use planner_service::config::ServiceConfig;
use planner_service::fleet::{ErrorKind, Fleet, Goal, NewTask, TaskFilter, TaskStateKind};
use protocol::keys::{self, RobotTopic};
use protocol::{
    Dlm, Header, Intention, MapName, MapRef, Pose2D, PoseEstimate, RobotId, SiteId, TaskState,
};
use zenoh::Session;

fn plan_path() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../sim/scenarios/maps/junctions.yaml")
}

fn store_with_map(dir: &Path) -> (Arc<MapStore>, MapRef) {
    let store = MapStore::open(&dir.join("maps")).unwrap();
    let name = MapName::new("junctions").unwrap();
    let meta = import_into(&store, &name, &plan_path(), None, &ImportLimits::default()).unwrap();
    (
        Arc::new(store),
        MapRef {
            name,
            version: meta.version,
        },
    )
}

fn config() -> ServiceConfig {
    let mut c = ServiceConfig::default();
    c.fleet.robot_timeout_ms = 600;
    c.fleet.pause_timeout_ms = 1500;
    c
}

/// A robot on the test side: publishes poses, keeps the newest intention.
struct TestRobot {
    session: Session,
    site: SiteId,
    id: RobotId,
    map: MapRef,
    seq: u64,
    latest: Arc<Mutex<Option<Intention>>>,
    _sub: zenoh::pubsub::Subscriber<()>,
}

impl TestRobot {
    async fn new(session: Session, site: &SiteId, id: &str, map: MapRef) -> Self {
        let id = RobotId::new(id).unwrap();
        let latest = Arc::new(Mutex::new(None));
        let slot = Arc::clone(&latest);
        let sub = session
            .declare_subscriber(keys::robot(site, &id, RobotTopic::Intention))
            .callback(move |s| {
                if let Ok(i) = protocol::decode_sample::<Intention>(&s) {
                    *slot.lock().unwrap() = Some(i);
                }
            })
            .await
            .unwrap();
        Self {
            session,
            site: site.clone(),
            id,
            map,
            seq: 0,
            latest,
            _sub: sub,
        }
    }

    async fn publish_pose(&mut self, pose: Pose2D) -> u64 {
        self.seq += 1;
        let msg = PoseEstimate {
            header: Header::new(self.seq, self.seq * 1_000_000),
            pose,
            covariance: [0.01, 0.0, 0.0, 0.0, 0.01, 0.0, 0.0, 0.0, 0.005],
            sensor_stamp_ns: self.seq * 1_000_000,
            map: self.map.clone(),
            unmapped_obstacles_m: Vec::new(),
        };
        protocol::zenoh_io::put(
            &self.session,
            &keys::robot(&self.site, &self.id, RobotTopic::Pose).into(),
            &msg,
        )
        .await
        .unwrap();
        self.seq
    }

    /// Publishes `pose` until an intention answering it arrives.
    async fn answer(&mut self, pose: Pose2D) -> Intention {
        for _ in 0..50 {
            let seq = self.publish_pose(pose).await;
            for _ in 0..20 {
                tokio::time::sleep(Duration::from_millis(10)).await;
                if let Some(i) = self.latest.lock().unwrap().clone() {
                    if i.answers_pose_seq == seq {
                        return i;
                    }
                }
            }
        }
        panic!("no intention answered the pose {pose:?}");
    }
}

async fn wait_state(fleet: &Fleet, task: &protocol::TaskId, kind: TaskStateKind, max: Duration) {
    let t0 = std::time::Instant::now();
    loop {
        let t = fleet.task(task).unwrap();
        if t.kind() == kind {
            return;
        }
        assert!(
            t0.elapsed() < max,
            "task {task} is {:?}, wanted {kind}",
            t.state
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

fn goal(x: f64, y: f64) -> Goal {
    Goal {
        x_m: x,
        y_m: y,
        yaw_rad: None,
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_robot_following_intentions_completes_a_two_goal_task() {
    let dir = tempfile::tempdir().unwrap();
    let (maps, map) = store_with_map(dir.path());
    let (server, robot_session) = protocol::zenoh_io::loopback_pair().await.unwrap();
    let site = SiteId::default();
    let fleet = Fleet::start(server, site.clone(), maps, dir.path(), config())
        .await
        .unwrap();
    let mut robot = TestRobot::new(robot_session, &site, "robot_1", map.clone()).await;

    // No task: the robot is told to stop, answering its own pose.
    let mut pose = Pose2D::new(3.0, 4.0, 0.0);
    let idle = robot.answer(pose).await;
    assert_eq!(idle.dlm, Dlm::Stop);
    assert_eq!(idle.task_id, None);

    let task = fleet
        .create_task(NewTask {
            map: map.name.clone(),
            robot_id: None,
            goals: vec![goal(8.0, 4.0), goal(13.0, 10.0)],
        })
        .unwrap();
    // Queued, then at once assigned to the only idle robot on the map.
    assert_eq!(
        task.state,
        TaskState::Assigned {
            robot_id: robot.id.clone()
        }
    );

    // Drive: jump 0.5 m along every answered path, as a robot would over a few cycles.
    let mut goals_seen = Vec::new();
    for _ in 0..200 {
        let i = robot.answer(pose).await;
        if i.task_id.is_none() {
            break;
        }
        assert_eq!(i.task_id.as_ref(), Some(&task.id));
        assert!(!i.path.is_empty(), "an active task gets a path");
        let first = i.path.first().unwrap();
        assert!(first.distance_m(&pose) < 0.3, "the path starts at the pose");
        if goals_seen.last() != Some(&i.goal_index) {
            goals_seen.push(i.goal_index);
        }
        let next = i
            .path
            .iter()
            .find(|p| p.distance_m(&pose) >= 0.5)
            .copied()
            .unwrap_or(*i.path.last().unwrap());
        pose = next;
    }
    assert_eq!(goals_seen, vec![0, 1]);
    let done = fleet.task(&task.id).unwrap();
    assert_eq!(done.state, TaskState::Completed);
    let kinds: Vec<TaskStateKind> = done
        .history
        .iter()
        .map(|h| TaskStateKind::of(&h.state))
        .collect();
    assert_eq!(
        kinds,
        vec![
            TaskStateKind::Queued,
            TaskStateKind::Assigned,
            TaskStateKind::Active,
            TaskStateKind::Active,
            TaskStateKind::Completed
        ]
    );
    let view = fleet.robot(&robot.id).unwrap();
    assert!(view.online);
    assert_eq!(view.task_id, None);
    let mut metrics = String::new();
    fleet.metrics().render_prometheus(&mut metrics);
    assert!(
        metrics.contains("fleet_tasks{state=\"completed\"} 1"),
        "{metrics}"
    );
    fleet.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_tasks_are_refused_and_nothing_is_stored() {
    let dir = tempfile::tempdir().unwrap();
    let (maps, map) = store_with_map(dir.path());
    let (server, _other) = protocol::zenoh_io::loopback_pair().await.unwrap();
    let fleet = Fleet::start(server, SiteId::default(), maps, dir.path(), config())
        .await
        .unwrap();
    let cases = [
        (map.name.clone(), vec![], ErrorKind::BadRequest, "goals"),
        (
            map.name.clone(),
            vec![goal(8.0, 4.0), goal(-50.0, 4.0)],
            ErrorKind::BadRequest,
            "goals[1]",
        ),
        // The outer wall of the junctions plan.
        (
            map.name.clone(),
            vec![goal(0.0, 0.0)],
            ErrorKind::BadRequest,
            "goals[0]",
        ),
        (
            MapName::new("nowhere").unwrap(),
            vec![goal(1.0, 1.0)],
            ErrorKind::NotFound,
            "nowhere",
        ),
    ];
    for (map_name, goals, kind, named) in cases {
        let err = fleet
            .create_task(NewTask {
                map: map_name,
                robot_id: None,
                goals,
            })
            .unwrap_err();
        assert_eq!(err.kind(), kind, "{err}");
        assert!(err.to_string().contains(named), "{err}");
    }
    let err = fleet
        .create_task(NewTask {
            map: map.name.clone(),
            robot_id: Some(RobotId::new("ghost").unwrap()),
            goals: vec![goal(8.0, 4.0)],
        })
        .unwrap_err();
    assert_eq!(err.kind(), ErrorKind::NotFound, "{err}");
    assert!(fleet.tasks(&TaskFilter::default()).unwrap().is_empty());
    fleet.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn cancel_stops_the_robot_and_a_second_cancel_conflicts() {
    let dir = tempfile::tempdir().unwrap();
    let (maps, map) = store_with_map(dir.path());
    let (server, robot_session) = protocol::zenoh_io::loopback_pair().await.unwrap();
    let site = SiteId::default();
    let fleet = Fleet::start(server, site.clone(), maps, dir.path(), config())
        .await
        .unwrap();
    let mut robot = TestRobot::new(robot_session, &site, "robot_1", map.clone()).await;
    let pose = Pose2D::new(3.0, 4.0, 0.0);
    robot.answer(pose).await;
    let task = fleet
        .create_task(NewTask {
            map: map.name.clone(),
            robot_id: Some(robot.id.clone()),
            goals: vec![goal(13.0, 10.0)],
        })
        .unwrap();
    let driving = robot.answer(pose).await;
    assert_ne!(driving.dlm, Dlm::Stop);
    let cancelled = fleet.cancel_task(&task.id).unwrap();
    assert_eq!(cancelled.state, TaskState::Cancelled);
    let stop = robot.answer(pose).await;
    assert_eq!((stop.dlm, stop.task_id), (Dlm::Stop, None));
    let again = fleet.cancel_task(&task.id).unwrap_err();
    assert_eq!(again.kind(), ErrorKind::Conflict, "{again}");
    fleet.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_silent_robot_pauses_its_task_then_fails_it_and_a_restart_resumes() {
    let dir = tempfile::tempdir().unwrap();
    let (maps, map) = store_with_map(dir.path());
    let site = SiteId::default();
    let task_id;
    {
        let (server, robot_session) = protocol::zenoh_io::loopback_pair().await.unwrap();
        let fleet = Fleet::start(
            server,
            site.clone(),
            Arc::clone(&maps),
            dir.path(),
            config(),
        )
        .await
        .unwrap();
        let mut robot = TestRobot::new(robot_session, &site, "robot_1", map.clone()).await;
        let pose = Pose2D::new(3.0, 4.0, 0.0);
        robot.answer(pose).await;
        let task = fleet
            .create_task(NewTask {
                map: map.name.clone(),
                robot_id: None,
                goals: vec![goal(13.0, 10.0)],
            })
            .unwrap();
        task_id = task.id.clone();
        robot.answer(pose).await;
        wait_state(
            &fleet,
            &task_id,
            TaskStateKind::Active,
            Duration::from_secs(5),
        )
        .await;
        // Silence: the task pauses with the reason.
        wait_state(
            &fleet,
            &task_id,
            TaskStateKind::Paused,
            Duration::from_secs(5),
        )
        .await;
        match fleet.task(&task_id).unwrap().state {
            TaskState::Paused { reason, .. } => assert!(reason.contains("no pose"), "{reason}"),
            other => panic!("{other:?}"),
        }
        // Reporting again resumes it.
        robot.answer(pose).await;
        wait_state(
            &fleet,
            &task_id,
            TaskStateKind::Active,
            Duration::from_secs(5),
        )
        .await;
        fleet.shutdown().await;
    }
    // A new service on the same data dir: the task is still active and resumes on a pose.
    let (server, robot_session) = protocol::zenoh_io::loopback_pair().await.unwrap();
    let fleet = Fleet::start(
        server,
        site.clone(),
        Arc::clone(&maps),
        dir.path(),
        config(),
    )
    .await
    .unwrap();
    assert_eq!(fleet.task(&task_id).unwrap().kind(), TaskStateKind::Active);
    let mut robot = TestRobot::new(robot_session, &site, "robot_1", map.clone()).await;
    let resumed = robot.answer(Pose2D::new(3.0, 4.0, 0.0)).await;
    assert_eq!(resumed.task_id.as_ref(), Some(&task_id));
    assert!(!resumed.path.is_empty());
    // Then silence past the grace period: paused, then failed with the reason.
    wait_state(
        &fleet,
        &task_id,
        TaskStateKind::Failed,
        Duration::from_secs(10),
    )
    .await;
    match fleet.task(&task_id).unwrap().state {
        TaskState::Failed { reason } => assert!(reason.contains("did not come back"), "{reason}"),
        other => panic!("{other:?}"),
    }
    fleet.shutdown().await;
}
