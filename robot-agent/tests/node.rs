//! The agent node end to end over real Zenoh on loopback: the simulator publishes the robot's
//! sensors and obeys its commands, a map store serves the floor plan, a test-side planner
//! answers every pose with a real hybrid-A* intention, and the agent in between localizes,
//! drives and applies each safety rule.
//!
//! Tests run one at a time (a shared lock): each runs a real-time sim, planner and agent, and on
//! a 2-core machine two at once would starve each other's 10 Hz loops.

// Test helpers panic on broken setup: that is the failure report.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::Path;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use clap::Parser;
use map_store::{ImportLimits, MapServer, MapStore};
use planning::{
    stop_intention, Answer as Planned, Goal, GoalProgress, IntentionConfig, IntentionPlanner,
    PlanningMap,
};
use protocol::keys::{self, RobotTopic};
use protocol::{
    AgentState, AgentStatus, CmdVel, Header, MapName, Odometry, Pose2D, PoseEstimate, RobotId,
    SiteId, StopReason, TaskId,
};
use robot_agent::cli::Cli;
use robot_agent::node::{self, NodeOptions};
use robot_agent::{AgentConfig, ControllerKind};
use sim::driver::DriverConfig;
use sim::{Command, SimConfig, World};
use tokio::sync::watch;
use zenoh::Session;

/// Serializes the tests across their runtimes (an async lock: it is held across awaits).
static SERIAL: tokio::sync::Mutex<()> = tokio::sync::Mutex::const_new(());

use test_support::{repo_root as repo, scenario};

/// What the test-side planner does with each pose.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Answer {
    /// Plan to the goal and publish the intention (with an LPE image when `lpe`).
    Plan { lpe: bool },
    /// Publish nothing: the planner went silent.
    Silent,
}

/// Messages recorded from the wire with their local arrival time.
#[derive(Default)]
struct Recorder {
    statuses: Mutex<Vec<(Instant, AgentStatus)>>,
    cmds: Mutex<Vec<(Instant, CmdVel)>>,
    odoms: Mutex<Vec<(Instant, Odometry)>>,
    poses: Mutex<Vec<(Instant, PoseEstimate)>>,
}

impl Recorder {
    fn last_status(&self) -> Option<AgentStatus> {
        self.statuses.lock().unwrap().last().map(|(_, s)| s.clone())
    }
    fn speed_mps(&self) -> f64 {
        self.odoms
            .lock()
            .unwrap()
            .last()
            .map_or(0.0, |(_, o)| o.v_mps.abs())
    }
}

/// Sim, map store and planner on one "hub" Zenoh session; the agent gets its own session.
struct Harness {
    hub: Session,
    endpoints: Vec<String>,
    site: SiteId,
    robot: RobotId,
    map: MapName,
    rec: Arc<Recorder>,
    answer: watch::Sender<Answer>,
    stop: watch::Sender<bool>,
    /// Ground truth, when the test-side driver runs the world.
    truth: Option<Arc<Mutex<World>>>,
    tasks: Vec<tokio::task::JoinHandle<()>>,
    _map_server: MapServer,
    _store_dir: tempfile::TempDir,
}

/// Which base simulation publishes the sensors.
enum Base {
    /// `sim::driver::run`, the simulator's own real-time driver.
    SimDriver,
    /// The same loop run here, so the test can read the world's ground truth.
    TruthDriver,
}

async fn wait_stop(mut stop: watch::Receiver<bool>) {
    while !*stop.borrow() {
        if stop.changed().await.is_err() {
            return;
        }
    }
}

impl Harness {
    async fn start(task: &str, goal: (f64, f64), base: Base) -> Self {
        let site: SiteId = "test".parse().unwrap();
        let map: MapName = "plan".parse().unwrap();
        let hub = zenoh::open(protocol::peer_config(&["tcp/127.0.0.1:0".into()], &[]).unwrap())
            .await
            .unwrap();
        let endpoints = protocol::zenoh_io::locators(&hub).await;
        assert!(!endpoints.is_empty());

        let mut world = World::from_scenario_file(&scenario(task), SimConfig::default()).unwrap();
        world.add_robots_at_start(1).unwrap();
        let robot = world.robot_ids()[0].clone();
        let plan_path = world.scenario.floor_plan_path(&scenario(task));

        let store_dir = tempfile::tempdir().unwrap();
        let store = MapStore::open(store_dir.path()).unwrap();
        map_store::import_into(&store, &map, &plan_path, None, &ImportLimits::default()).unwrap();
        let map_server = MapServer::start(&hub, &site, Arc::new(store))
            .await
            .unwrap();

        let rec = Arc::new(Recorder::default());
        let (stop, stop_rx) = watch::channel(false);
        let (answer, answer_rx) = watch::channel(Answer::Plan { lpe: false });
        let mut tasks = Vec::new();
        let truth = match base {
            Base::SimDriver => {
                let (session, site, stop_rx) = (hub.clone(), site.clone(), stop_rx.clone());
                tasks.push(tokio::spawn(async move {
                    sim::driver::run(
                        &session,
                        world,
                        &site,
                        DriverConfig::default(),
                        wait_stop(stop_rx),
                    )
                    .await
                    .unwrap();
                }));
                None
            }
            Base::TruthDriver => {
                let world = Arc::new(Mutex::new(world));
                let (session, site, robot, w) =
                    (hub.clone(), site.clone(), robot.clone(), Arc::clone(&world));
                let stop_rx = stop_rx.clone();
                tasks.push(tokio::spawn(truth_driver(session, w, site, robot, stop_rx)));
                Some(world)
            }
        };

        // The planner: every pose in, one intention out.
        let grid = map_store::load_ros_map(&plan_path, &ImportLimits::default())
            .unwrap()
            .grid;
        let config = IntentionConfig::default();
        let planning = Arc::new(PlanningMap::new(grid, &config.planner).unwrap());
        let mut pipeline = IntentionPlanner::new(planning, config).unwrap();
        let goals = [Goal::at(goal.0, goal.1)];
        let poses = hub
            .declare_subscriber(keys::robot(&site, &robot, RobotTopic::Pose))
            .await
            .unwrap();
        let intention_pub = hub
            .declare_publisher(keys::robot(&site, &robot, RobotTopic::Intention))
            .await
            .unwrap();
        let rec2 = Arc::clone(&rec);
        let mut stop_rx2 = stop_rx.clone();
        tasks.push(tokio::spawn(async move {
            let mut seq = 0;
            let mut complained = false;
            let task_id = Some(TaskId::new("task_1").unwrap());
            loop {
                let sample = tokio::select! {
                    s = poses.recv_async() => match s { Ok(s) => s, Err(_) => break },
                    _ = stop_rx2.changed() => break,
                };
                let pose: PoseEstimate = protocol::decode_sample(&sample).unwrap();
                rec2.poses
                    .lock()
                    .unwrap()
                    .push((Instant::now(), pose.clone()));
                let Answer::Plan { lpe } = *answer_rx.borrow() else {
                    continue;
                };
                seq += 1;
                let header = Header::new(seq, pose.header.stamp_ns);
                let intention = match pipeline.answer(&pose, &GoalProgress::new(&goals, 0), lpe) {
                    Planned::Heading {
                        goal_index,
                        plan: Ok(p),
                    } => p.intention(header, &pose, task_id.clone(), goal_index, lpe),
                    Planned::Heading {
                        goal_index,
                        plan: Err(e),
                    } => {
                        if !complained {
                            eprintln!("planner: no path from {:?}: {e} (said once)", pose.pose);
                            complained = true;
                        }
                        stop_intention(header, &pose, task_id.clone(), goal_index)
                    }
                    Planned::Done => stop_intention(header, &pose, task_id.clone(), 0),
                };
                protocol::zenoh_io::publish(&intention_pub, &intention)
                    .await
                    .unwrap();
            }
        }));

        // Recorders of what the agent and the base say.
        for topic in [RobotTopic::Status, RobotTopic::CmdVel, RobotTopic::Odom] {
            let rec = Arc::clone(&rec);
            let sub = hub
                .declare_subscriber(keys::robot(&site, &robot, topic))
                .await
                .unwrap();
            let mut stop_rx = stop_rx.clone();
            tasks.push(tokio::spawn(async move {
                loop {
                    let sample = tokio::select! {
                        s = sub.recv_async() => match s { Ok(s) => s, Err(_) => break },
                        _ = stop_rx.changed() => break,
                    };
                    let now = Instant::now();
                    match topic {
                        RobotTopic::Status => {
                            let s: AgentStatus = protocol::decode_sample(&sample).unwrap();
                            s.validate().unwrap();
                            rec.statuses.lock().unwrap().push((now, s));
                        }
                        RobotTopic::CmdVel => {
                            let c: CmdVel = protocol::decode_sample(&sample).unwrap();
                            rec.cmds.lock().unwrap().push((now, c));
                        }
                        _ => {
                            let o: Odometry = protocol::decode_sample(&sample).unwrap();
                            rec.odoms.lock().unwrap().push((now, o));
                        }
                    }
                }
            }));
        }

        Self {
            hub,
            endpoints,
            site,
            robot,
            map,
            rec,
            answer,
            stop,
            truth,
            tasks,
            _map_server: map_server,
            _store_dir: store_dir,
        }
    }

    fn config(&self, controller: ControllerKind) -> AgentConfig {
        let mut config = AgentConfig {
            site: self.site.clone(),
            map: Some(self.map.clone()),
            controller,
            ..AgentConfig::default()
        };
        let start = sim::Scenario::load(&scenario("task_a")).unwrap().start;
        config.localization.initial_pose = Some(start.to_pose());
        config
    }

    /// Starts the agent node on its own session; returns its shutdown sender and task.
    fn spawn_agent(
        &self,
        config: AgentConfig,
    ) -> (
        tokio::sync::oneshot::Sender<()>,
        tokio::task::JoinHandle<Result<(), robot_agent::NodeError>>,
    ) {
        self.spawn_agent_recording(config, None)
    }

    /// [`Self::spawn_agent`] with `--record`.
    fn spawn_agent_recording(
        &self,
        config: AgentConfig,
        record: Option<node::RecordOptions>,
    ) -> (
        tokio::sync::oneshot::Sender<()>,
        tokio::task::JoinHandle<Result<(), robot_agent::NodeError>>,
    ) {
        let options = NodeOptions {
            robot_id: self.robot.clone(),
            config,
            zenoh: node::zenoh_config(&[], &self.endpoints, false).unwrap(),
            record,
        };
        let (tx, rx) = tokio::sync::oneshot::channel::<()>();
        let task = tokio::spawn(node::run(options, async move {
            let _ = rx.await;
        }));
        (tx, task)
    }

    /// Polls `cond` every 50 ms until it holds or `timeout` passes.
    async fn wait_for(&self, what: &str, timeout: Duration, cond: impl Fn(&Self) -> bool) {
        let t0 = Instant::now();
        while !cond(self) {
            if t0.elapsed() > timeout {
                panic!(
                    "timed out after {timeout:?} waiting for {what}; last status {:?}, speed {} m/s",
                    self.rec.last_status(),
                    self.rec.speed_mps()
                );
            }
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
    }

    fn state(&self) -> Option<AgentState> {
        self.rec.last_status().map(|s| s.state)
    }

    fn truth_pose(&self) -> Pose2D {
        let world = self.truth.as_ref().expect("truth driver");
        world.lock().unwrap().ground_truth_pose(0).unwrap()
    }

    async fn shutdown(self) {
        let _ = self.stop.send(true);
        for t in self.tasks {
            let _ = tokio::time::timeout(Duration::from_secs(5), t).await;
        }
        let _ = self.hub.close().await;
    }
}

/// `sim::driver::run`'s loop (odometry 20 Hz, scan and camera 10 Hz, a command older than
/// 500 ms means stop) with the world shared, so the test can read the ground truth.
async fn truth_driver(
    session: Session,
    world: Arc<Mutex<World>>,
    site: SiteId,
    robot: RobotId,
    stop: watch::Receiver<bool>,
) {
    let latest: Arc<Mutex<Option<(Command, Instant)>>> = Arc::default();
    let l2 = Arc::clone(&latest);
    let _sub = session
        .declare_subscriber(keys::robot(&site, &robot, RobotTopic::CmdVel))
        .callback(move |sample| {
            if let Ok(cmd) = protocol::decode_sample::<CmdVel>(&sample) {
                *l2.lock().unwrap() = Some((
                    Command {
                        v_mps: cmd.v_mps,
                        omega_radps: cmd.omega_radps,
                    },
                    Instant::now(),
                ));
            }
        })
        .await
        .unwrap();
    let odom_pub = session
        .declare_publisher(keys::robot(&site, &robot, RobotTopic::Odom))
        .await
        .unwrap();
    let scan_pub = session
        .declare_publisher(keys::robot(&site, &robot, RobotTopic::Scan))
        .await
        .unwrap();
    let camera_pub = session
        .declare_publisher(keys::robot(&site, &robot, RobotTopic::Camera))
        .await
        .unwrap();
    let dt = 0.05;
    let mut ticker = tokio::time::interval(Duration::from_secs_f64(dt));
    ticker.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let mut n = 0u64;
    let stopped = wait_stop(stop);
    tokio::pin!(stopped);
    loop {
        tokio::select! {
            () = &mut stopped => break,
            _ = ticker.tick() => {}
        }
        let cmd = match *latest.lock().unwrap() {
            Some((c, at)) if at.elapsed() <= Duration::from_millis(500) => c,
            _ => Command::default(),
        };
        let (obs, frame) = {
            let mut w = world.lock().unwrap();
            let obs = w.step(&[cmd], dt);
            let frame = n.is_multiple_of(2).then(|| w.camera_frame(0).unwrap());
            (obs, frame)
        };
        let o = &obs.robots[0];
        protocol::zenoh_io::publish(&odom_pub, &o.odom)
            .await
            .unwrap();
        if n.is_multiple_of(2) {
            protocol::zenoh_io::publish(&scan_pub, &o.scan)
                .await
                .unwrap();
        }
        if let Some(frame) = frame {
            protocol::zenoh_io::publish(&camera_pub, &frame)
                .await
                .unwrap();
        }
        n += 1;
    }
}

/// Drives to `goal`; with `record`, the agent records a run log there, which is checked and
/// replayed after the agent stopped.
async fn drive_to_goal(controller: ControllerKind, goal: (f64, f64), record: Option<&Path>) {
    let h = Harness::start("task_a", goal, Base::TruthDriver).await;
    let (stop_agent, agent) = h.spawn_agent_recording(
        h.config(controller),
        record.map(|path| node::RecordOptions {
            path: path.to_path_buf(),
            log: fleet_log::LogOptions {
                camera: true,
                ..fleet_log::LogOptions::default()
            },
        }),
    );
    h.wait_for("driving", Duration::from_secs(10), |h| {
        h.state() == Some(AgentState::Driving)
    })
    .await;
    // The planner says Stop (DLM) once the robot is within 0.3 m of the goal: the agent rests.
    h.wait_for("idle at the goal", Duration::from_secs(30), |h| {
        h.state() == Some(AgentState::Idle) && h.rec.speed_mps() < 0.01
    })
    .await;
    let truth = h.truth_pose();
    let miss = (truth.x_m - goal.0).hypot(truth.y_m - goal.1);
    println!("{controller}: stopped at {truth:?}, {miss:.3} m from the goal {goal:?}");
    // The DLM turns Stop 0.3 m before the end of the path; AMCL adds its error on top.
    assert!(miss < 0.5, "{controller} ended {miss} m from the goal");
    // The published pose tracks the truth.
    let last = h.rec.poses.lock().unwrap().last().unwrap().1.clone();
    assert!(
        last.pose.distance_m(&truth) < 0.2,
        "pose {:?} vs truth {truth:?}",
        last.pose
    );
    stop_agent.send(()).unwrap();
    agent.await.unwrap().unwrap();
    let published = h.rec.poses.lock().unwrap().len();
    h.shutdown().await;
    if let Some(path) = record {
        check_live_log(path, published);
    }
}

/// The log of a live agent: what it received and published, in processing order, and a replay
/// of its localization that reproduces every published pose exactly.
fn check_live_log(path: &Path, published: usize) {
    assert!(!fleet_log::partial_path(path).exists());
    let log = fleet_log::RunLog::open(path).unwrap();
    let counts = log.counts();
    println!("live log {}: {counts:?}", path.display());
    let map = log.map().unwrap();
    assert_eq!((map.name.as_str(), map.version), ("plan", 1));
    assert_eq!(map.source, "robot-agent");
    let grid = map_store::load_ros_map(
        &sim::Scenario::load(&scenario("task_a"))
            .unwrap()
            .floor_plan_path(&scenario("task_a")),
        &ImportLimits::default(),
    )
    .unwrap()
    .grid;
    // The map store's content hash, which the agent recorded from the map it was served.
    assert_eq!(
        map.content_hash.as_deref(),
        Some(map_store::store::content_hash(&grid).as_str())
    );
    assert!(map.initial_pose.is_some());
    for topic in [
        fleet_log::Topic::Odom,
        fleet_log::Topic::Scan,
        fleet_log::Topic::Camera,
        fleet_log::Topic::AmclPose,
        fleet_log::Topic::Intention,
        fleet_log::Topic::CmdVel,
    ] {
        assert!(
            counts.get(&topic).copied().unwrap_or(0) > 5,
            "{topic}: {counts:?}"
        );
    }
    // Each change of the status it published (it started, then drove).
    assert!(
        counts
            .get(&fleet_log::Topic::AgentStatus)
            .copied()
            .unwrap_or(0)
            >= 1,
        "{counts:?}"
    );
    // Every pose the test's planner got, the log has (the log may hold the last one or two
    // that the planner's subscriber had not taken when it stopped).
    let poses = counts[&fleet_log::Topic::AmclPose];
    assert!(
        poses >= published && poses <= published + 3,
        "{poses} vs {published}"
    );
    // Odometry at 20 Hz, scans at 10 Hz: stamps increase on each sensor topic.
    for topic in [fleet_log::Topic::Odom, fleet_log::Topic::Scan] {
        let stamps: Vec<u64> = log
            .as_recorded()
            .iter()
            .filter(|e| e.message.topic() == topic)
            .map(|e| e.log_time_ns)
            .collect();
        assert!(stamps.windows(2).all(|w| w[0] < w[1]), "{topic}");
    }
    let config = robot_agent::replay::recorded_config(&log).unwrap();
    let replay = robot_agent::replay::replay(&log, &grid, &config).unwrap();
    println!(
        "{}",
        robot_agent::replay::markdown(std::slice::from_ref(&replay.summary))
    );
    assert_eq!(replay.summary.map_matches, Some(true));
    assert_eq!(replay.poses.len(), poses);
    // Same filter, same seed, same inputs in the same order: the same estimates, bit for bit.
    assert_eq!(replay.summary.max_live_difference_m, Some(0.0));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 3)]
async fn path_tracker_drives_to_a_goal() {
    let _g = SERIAL.lock().await;
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("live.mcap");
    // Straight down the start corridor, 3.5 m.
    drive_to_goal(ControllerKind::PathTracker, (6.5, 4.0), Some(&log)).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 3)]
async fn dynamic_window_drives_round_a_corner() {
    let _g = SERIAL.lock().await;
    // A 90-degree left turn into the side corridor, then 4 m up it.
    drive_to_goal(ControllerKind::DynamicWindow, (3.0, 8.0), None).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 3)]
async fn stale_intention_stops_the_robot_and_driving_resumes() {
    let _g = SERIAL.lock().await;
    let h = Harness::start("task_a", (13.0, 4.0), Base::SimDriver).await;
    let (stop_agent, agent) = h.spawn_agent(h.config(ControllerKind::PathTracker));
    h.wait_for("driving at speed", Duration::from_secs(15), |h| {
        h.state() == Some(AgentState::Driving) && h.rec.speed_mps() > 0.3
    })
    .await;

    h.answer.send(Answer::Silent).unwrap();
    let silent_at = Instant::now();
    h.wait_for("a stale-intention stop", Duration::from_secs(2), |h| {
        matches!(
            h.rec.last_status().and_then(|s| s.stop_reason),
            Some(StopReason::StaleIntention { .. } | StopReason::NoIntention)
        )
    })
    .await;
    let noticed = silent_at.elapsed();
    h.wait_for("a zero command", Duration::from_secs(2), |h| {
        h.rec
            .cmds
            .lock()
            .unwrap()
            .last()
            .is_some_and(|(_, c)| c.v_mps == 0.0 && c.omega_radps == 0.0)
    })
    .await;
    let zero_at = silent_at.elapsed();
    println!("stale noticed after {noticed:?}, command zero after {zero_at:?}");
    // Deadline 300 ms plus a 0.7 m/s stop at 1 m/s^2 (0.7 s), plus a cycle or two of slack.
    assert!(noticed < Duration::from_millis(600), "{noticed:?}");
    assert!(zero_at < Duration::from_millis(1300), "{zero_at:?}");
    // While stopping, the commands only decrease.
    {
        let cmds = h.rec.cmds.lock().unwrap();
        let after: Vec<f64> = cmds
            .iter()
            .filter(|(t, _)| *t >= silent_at + Duration::from_millis(450))
            .map(|(_, c)| c.v_mps)
            .collect();
        assert!(after.windows(2).all(|w| w[1] <= w[0] + 1e-12), "{after:?}");
    }
    h.wait_for("the base at rest", Duration::from_secs(3), |h| {
        h.rec.speed_mps() < 0.01
    })
    .await;
    let status = h.rec.last_status().unwrap();
    assert_eq!(status.state, AgentState::Stopped, "{status:?}");
    assert!(status.localized);

    h.answer.send(Answer::Plan { lpe: false }).unwrap();
    h.wait_for("driving again", Duration::from_secs(5), |h| {
        h.state() == Some(AgentState::Driving) && h.rec.speed_mps() > 0.2
    })
    .await;
    stop_agent.send(()).unwrap();
    agent.await.unwrap().unwrap();
    h.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 3)]
async fn lost_localization_stops_the_robot() {
    let _g = SERIAL.lock().await;
    let h = Harness::start("task_a", (13.0, 4.0), Base::SimDriver).await;
    let mut config = h.config(ControllerKind::PathTracker);
    // Told "somewhere in the building, facing anywhere": the particles spread over several
    // corridors that look alike, and a robot at rest gathers no evidence to choose.
    config.localization.initial_position_std_m = 6.0;
    config.localization.initial_yaw_std_rad = 3.0;
    let (stop_agent, agent) = h.spawn_agent(config);
    h.wait_for("localization lost", Duration::from_secs(10), |h| {
        matches!(
            h.rec.last_status().and_then(|s| s.stop_reason),
            Some(StopReason::LocalizationLost { .. })
        )
    })
    .await;
    tokio::time::sleep(Duration::from_secs(2)).await;
    let status = h.rec.last_status().unwrap();
    println!("{status:?}");
    assert!(!status.localized);
    assert!(matches!(
        status.stop_reason,
        Some(StopReason::LocalizationLost { position_std_m }) if position_std_m > 0.5
    ));
    // Intentions arrive (the planner answers every pose), yet the robot never moved.
    let max_speed = h
        .rec
        .odoms
        .lock()
        .unwrap()
        .iter()
        .map(|(_, o)| o.v_mps.abs())
        .fold(0.0, f64::max);
    assert!(max_speed < 1e-9, "robot moved at {max_speed} m/s");
    assert!(h
        .rec
        .cmds
        .lock()
        .unwrap()
        .iter()
        .all(|(_, c)| c.v_mps == 0.0));
    stop_agent.send(()).unwrap();
    agent.await.unwrap().unwrap();
    h.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 3)]
async fn controller_error_stops_the_robot() {
    let _g = SERIAL.lock().await;
    let h = Harness::start("task_a", (13.0, 4.0), Base::SimDriver).await;
    let mut config = h.config(ControllerKind::Lpe);
    config.model = Some(repo().join("models/fixtures/lpe.onnx"));
    // The planner sends intentions without the LPE image the network needs.
    let (stop_agent, agent) = h.spawn_agent(config);
    h.wait_for("a controller error", Duration::from_secs(10), |h| {
        matches!(
            h.rec.last_status().and_then(|s| s.stop_reason),
            Some(StopReason::ControllerError { .. })
        )
    })
    .await;
    tokio::time::sleep(Duration::from_secs(1)).await;
    let status = h.rec.last_status().unwrap();
    assert_eq!(status.controller, ControllerKind::Lpe);
    assert_eq!(status.state, AgentState::Stopped);
    let Some(StopReason::ControllerError { message }) = &status.stop_reason else {
        panic!("{status:?}");
    };
    assert!(message.contains("intention.lpe"), "{message}");
    assert!(h.rec.speed_mps() < 1e-9);

    // With the image the same network drives (its untrained output is whatever it is, but the
    // agent no longer reports an error).
    h.answer.send(Answer::Plan { lpe: true }).unwrap();
    h.wait_for("the error to clear", Duration::from_secs(5), |h| {
        !matches!(
            h.rec.last_status().and_then(|s| s.stop_reason),
            Some(StopReason::ControllerError { .. })
        )
    })
    .await;
    stop_agent.send(()).unwrap();
    agent.await.unwrap().unwrap();
    h.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 3)]
async fn liveliness_status_and_pose_on_the_wire() {
    let _g = SERIAL.lock().await;
    let h = Harness::start("task_a", (6.5, 4.0), Base::SimDriver).await;
    let (stop_agent, agent) = h.spawn_agent(h.config(ControllerKind::DynamicWindow));
    h.wait_for("a pose", Duration::from_secs(10), |h| {
        h.rec.poses.lock().unwrap().len() >= 5
    })
    .await;
    let alive_key = keys::robot(&h.site, &h.robot, RobotTopic::Alive);
    let tokens = h
        .hub
        .liveliness()
        .get(keys::alive_all(&h.site))
        .await
        .unwrap();
    let mut seen = Vec::new();
    while let Ok(reply) = tokens.recv_async().await {
        if let Ok(sample) = reply.result() {
            seen.push(sample.key_expr().as_str().to_string());
        }
    }
    assert_eq!(seen, vec![alive_key.as_str().to_string()]);

    {
        let poses = h.rec.poses.lock().unwrap();
        let seqs: Vec<u64> = poses.iter().map(|(_, p)| p.header.seq).collect();
        assert!(seqs.windows(2).all(|w| w[1] == w[0] + 1), "{seqs:?}");
        for (_, p) in poses.iter() {
            p.validate().unwrap();
            assert_eq!(p.map.name, h.map);
            assert!(p.sensor_stamp_ns > 0);
            assert!(p.position_std_m() < 0.5, "{p:?}");
        }
        let statuses = h.rec.statuses.lock().unwrap();
        assert_eq!(statuses[0].1.state, AgentState::Starting);
        let last = &statuses.last().unwrap().1;
        assert_eq!(last.controller, ControllerKind::DynamicWindow);
        assert_eq!(last.map.as_ref().unwrap().name, h.map);
        assert!(last.localized);
    }

    // Shutdown: a zero command, then the token disappears.
    stop_agent.send(()).unwrap();
    agent.await.unwrap().unwrap();
    tokio::time::sleep(Duration::from_millis(300)).await;
    let last_cmd = h.rec.cmds.lock().unwrap().last().unwrap().1.clone();
    assert_eq!((last_cmd.v_mps, last_cmd.omega_radps), (0.0, 0.0));
    let last = h.rec.last_status().unwrap();
    assert_eq!(last.stop_reason, Some(StopReason::Commanded));
    let tokens = h
        .hub
        .liveliness()
        .get(keys::alive_all(&h.site))
        .await
        .unwrap();
    let mut after = 0;
    while let Ok(reply) = tokens.recv_async().await {
        after += usize::from(reply.result().is_ok());
    }
    assert_eq!(after, 0, "token still alive after shutdown");
    h.shutdown().await;
}

#[test]
fn bad_flags_are_named() {
    let err = Cli::try_parse_from([
        "robot-agent",
        "--robot-id",
        "r1",
        "--controller",
        "teleport",
    ])
    .unwrap_err()
    .to_string();
    assert!(
        err.contains("--controller") && err.contains("teleport"),
        "{err}"
    );
    let err = Cli::try_parse_from(["robot-agent", "--robot-id", "r1", "--initial-pose", "1,2"])
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("--initial-pose") && err.contains("1,2"),
        "{err}"
    );
    let err = Cli::try_parse_from(["robot-agent", "--robot-id", "bad/id"])
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("--robot-id") && err.contains("bad/id"),
        "{err}"
    );
    // Valid flags, but a network controller without a model.
    let cli = Cli::try_parse_from([
        "robot-agent",
        "--robot-id",
        "r1",
        "--map",
        "office",
        "--controller",
        "dlm",
    ])
    .unwrap();
    let err = robot_agent::cli::merged_config(&cli).unwrap_err();
    assert!(format!("{err:#}").contains("model"), "{err:#}");
    // Flags override the file.
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("agent.toml");
    std::fs::write(&file, "controller = \"path-tracker\"\nmap = \"office\"\n").unwrap();
    let cli = Cli::try_parse_from([
        "robot-agent",
        "--robot-id",
        "r1",
        "--config",
        file.to_str().unwrap(),
        "--controller",
        "dynamic-window",
        "--initial-pose",
        "1.5,-2,0.3",
    ])
    .unwrap();
    let config = robot_agent::cli::merged_config(&cli).unwrap();
    assert_eq!(config.controller, ControllerKind::DynamicWindow);
    assert_eq!(config.map.unwrap().as_str(), "office");
    assert_eq!(
        config.localization.initial_pose,
        Some(Pose2D::new(1.5, -2.0, 0.3))
    );
}

#[test]
fn the_binary_rejects_a_bad_flag_with_a_non_zero_exit() {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_robot-agent"))
        .args([
            "--robot-id",
            "r1",
            "--map",
            "office",
            "--controller",
            "warp",
        ])
        .output()
        .unwrap();
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("--controller") && stderr.contains("warp"),
        "{stderr}"
    );
    // A bad config value: named, non-zero, before any network activity.
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("agent.toml");
    std::fs::write(&file, "[safety]\nstop_decel_mps2 = 0.0\n").unwrap();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_robot-agent"))
        .args(["--robot-id", "r1", "--map", "office", "--config"])
        .arg(&file)
        .output()
        .unwrap();
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("safety.stop_decel_mps2 = 0"), "{stderr}");
}
