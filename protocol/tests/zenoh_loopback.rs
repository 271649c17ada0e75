//! Publishes through a real Zenoh session and decodes the received samples.

// Fixture helpers outside #[test] fns are test code too; a panic is the right failure there.
#![allow(clippy::unwrap_used)]

use std::time::Duration;

use protocol::keys::{self, RobotTopic};
use protocol::zenoh_io::{decode_sample, encoding_for, put};
use protocol::{CameraFrame, CmdVel, Header, Image, ImageEncoding, RobotId, SiteId};
use zenoh::key_expr::KeyExpr;

async fn isolated_session() -> zenoh::Session {
    let mut config = zenoh::Config::default();
    // No discovery and no listeners: the test must not talk to anything else on the host.
    for (key, value) in [
        ("scouting/multicast/enabled", "false"),
        ("scouting/gossip/enabled", "false"),
        ("listen/endpoints", "[]"),
        ("connect/endpoints", "[]"),
    ] {
        config.insert_json5(key, value).unwrap();
    }
    zenoh::open(config).await.unwrap()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn put_and_decode_sample_over_zenoh() {
    let session = isolated_session().await;
    let site = SiteId::new("test_site").unwrap();
    let robot = RobotId::new("robot_1").unwrap();
    let subscriber = session
        .declare_subscriber(keys::all_robots(&site, RobotTopic::CmdVel))
        .await
        .unwrap();
    let cam_subscriber = session
        .declare_subscriber(keys::robot(&site, &robot, RobotTopic::Camera))
        .await
        .unwrap();

    let cmd = CmdVel {
        header: Header::new(7, 123),
        v_mps: 0.3,
        omega_radps: 0.1,
    };
    let key = KeyExpr::from(keys::robot(&site, &robot, RobotTopic::CmdVel));
    put(&session, &key, &cmd).await.unwrap();
    let sample = tokio::time::timeout(Duration::from_secs(5), subscriber.recv_async())
        .await
        .unwrap()
        .unwrap();
    assert_eq!(sample.encoding(), &encoding_for::<CmdVel>());
    assert_eq!(
        keys::parse_robot_key(sample.key_expr().as_str()),
        Some((site.clone(), robot.clone(), RobotTopic::CmdVel))
    );
    assert_eq!(decode_sample::<CmdVel>(&sample).unwrap(), cmd);

    let frame = CameraFrame {
        header: Header::new(8, 456),
        image: Image::new(64, 48, ImageEncoding::Rgb8, vec![17; 64 * 48 * 3]).unwrap(),
    };
    let key = KeyExpr::from(keys::robot(&site, &robot, RobotTopic::Camera));
    put(&session, &key, &frame).await.unwrap();
    let sample = tokio::time::timeout(Duration::from_secs(5), cam_subscriber.recv_async())
        .await
        .unwrap()
        .unwrap();
    assert_eq!(
        sample.encoding().to_string(),
        "application/octet-stream;intention-fleet/camera"
    );
    assert_eq!(decode_sample::<CameraFrame>(&sample).unwrap(), frame);
    assert!(decode_sample::<CmdVel>(&sample).is_err());

    session.close().await.unwrap();
}
