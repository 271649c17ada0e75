//! The real-time Zenoh driver on loopback: cmd_vel in, scan/odom/camera out, the robot moves;
//! with a recorder (`sim run --record`), the first robot's sensors and truth go to a run log.

// Test code: a failed unwrap is a failed test.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::sync::{Arc, Mutex};
use std::time::Duration;

use protocol::keys::{self, RobotTopic};
use protocol::{CameraFrame, CmdVel, Header, LaserScan, Odometry, RobotId, SiteId};
use sim::driver::{self, DriverConfig};
use sim::{SimConfig, World};

#[derive(Default)]
struct Seen {
    scans: usize,
    cameras: usize,
    last_odom: Option<Odometry>,
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn driver_obeys_cmd_vel_and_publishes_sensors() {
    let (sim_session, client) = protocol::loopback_pair().await.unwrap();

    let site = SiteId::new("test_site").unwrap();
    let robot = RobotId::new("robot_1").unwrap();
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenarios/train_hall.yaml");
    let mut world = World::from_scenario_file(&path, SimConfig::default()).unwrap();
    world.add_robots_at_start(1).unwrap();
    let start = world.ground_truth_pose(0).unwrap();
    let log_dir = tempfile::tempdir().unwrap();
    let log_path = log_dir.path().join("sim.mcap");
    let mut recorder = fleet_log::Recorder::start(
        &log_path,
        fleet_log::LogOptions {
            camera: true,
            ..fleet_log::LogOptions::default()
        },
    )
    .unwrap();
    let plan_path = world.scenario.floor_plan_path(&path);
    recorder.record(fleet_log::LogMessage::Map(driver::log_map_info(
        &world,
        Some(&plan_path),
    )));

    let seen = Arc::new(Mutex::new(Seen::default()));
    let s1 = Arc::clone(&seen);
    let _scan_sub = client
        .declare_subscriber(keys::robot(&site, &robot, RobotTopic::Scan))
        .callback(move |sample| {
            let scan: LaserScan = protocol::decode_sample(&sample).unwrap();
            assert_eq!(scan.ranges_m.len(), 181);
            s1.lock().unwrap().scans += 1;
        })
        .await
        .unwrap();
    let s2 = Arc::clone(&seen);
    let _cam_sub = client
        .declare_subscriber(keys::robot(&site, &robot, RobotTopic::Camera))
        .callback(move |sample| {
            let frame: CameraFrame = protocol::decode_sample(&sample).unwrap();
            assert_eq!((frame.image.width_px, frame.image.height_px), (224, 224));
            s2.lock().unwrap().cameras += 1;
        })
        .await
        .unwrap();
    let s3 = Arc::clone(&seen);
    let _odom_sub = client
        .declare_subscriber(keys::robot(&site, &robot, RobotTopic::Odom))
        .callback(move |sample| {
            let odom: Odometry = protocol::decode_sample(&sample).unwrap();
            s3.lock().unwrap().last_odom = Some(odom);
        })
        .await
        .unwrap();

    let (stop_tx, stop_rx) = tokio::sync::oneshot::channel::<()>();
    let driver_site = site.clone();
    let driver_task = tokio::spawn(async move {
        let shutdown = async {
            let _ = stop_rx.await;
        };
        let config = DriverConfig {
            cmd_timeout_ms: 300,
            ..DriverConfig::default()
        };
        driver::run_recording(
            &sim_session,
            world,
            &driver_site,
            config,
            Some(recorder),
            shutdown,
        )
        .await
    });

    let cmd_key: zenoh::key_expr::KeyExpr<'static> =
        keys::robot(&site, &robot, RobotTopic::CmdVel).into();
    let mut moved = false;
    for seq in 0..60u64 {
        let cmd = CmdVel {
            header: Header::new(seq, seq * 100_000_000),
            v_mps: 0.5,
            omega_radps: 0.0,
        };
        protocol::zenoh_io::put(&client, &cmd_key, &cmd)
            .await
            .unwrap();
        tokio::time::sleep(Duration::from_millis(100)).await;
        let s = seen.lock().unwrap();
        if s.scans >= 3
            && s.cameras >= 3
            && s.last_odom
                .as_ref()
                .is_some_and(|o| o.pose.x_m.hypot(o.pose.y_m) > 0.2)
        {
            moved = true;
            break;
        }
    }
    assert!(moved, "robot did not move or sensors missing");

    // Stop sending: after the timeout the robot stops (odometry speed decays to ~0).
    tokio::time::sleep(Duration::from_millis(1500)).await;
    let v = seen
        .lock()
        .unwrap()
        .last_odom
        .as_ref()
        .map(|o| o.v_mps)
        .unwrap();
    assert!(v.abs() < 0.05, "stale cmd_vel must stop the robot, v = {v}");

    stop_tx.send(()).unwrap();
    driver_task.await.unwrap().unwrap();
    client.close().await.unwrap();

    // The run log: the driver finished it when it stopped.
    let log = fleet_log::RunLog::open(&log_path).unwrap();
    let counts = log.counts();
    let map = log.map().unwrap();
    assert_eq!(map.initial_pose, Some(start));
    assert_eq!(map.name, "hall");
    assert!(map.content_hash.is_some());
    let odom = counts[&fleet_log::Topic::Odom];
    // Odometry and truth every step (20 Hz), scans and camera every other one (10 Hz).
    assert!(odom > 20, "{counts:?}");
    assert_eq!(counts[&fleet_log::Topic::GroundTruth], odom);
    let scans = counts[&fleet_log::Topic::Scan];
    assert!(scans.abs_diff(odom / 2) <= 1, "{counts:?}");
    assert!(
        counts[&fleet_log::Topic::Camera].abs_diff(scans) <= 1,
        "{counts:?}"
    );
    let truth = log.ground_truth();
    assert!(truth
        .windows(2)
        .all(|w| w[0].header.stamp_ns < w[1].header.stamp_ns));
    assert!(truth.last().unwrap().pose.distance_m(&start) > 0.2);
}
