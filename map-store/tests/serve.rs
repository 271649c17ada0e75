//! Serving maps over real Zenoh sessions on loopback: a store session and a robot session.

// Helpers outside #[test] functions are test code too.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::sync::Arc;
use std::time::Duration;

use map_store::store::{MapSource, MapStore, SourceKind};
use map_store::{fetch_map, fetch_meta, load_ros_map, ImportLimits, MapError, MapServer, OCCUPIED};
use protocol::{keys, MapName, SiteId};

const TIMEOUT: Duration = Duration::from_secs(5);

async fn session_pair() -> (zenoh::Session, zenoh::Session) {
    protocol::loopback_pair().await.unwrap()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn robot_fetches_latest_and_versions_meta_and_gets_named_errors() {
    let dir = tempfile::tempdir().unwrap();
    let store = Arc::new(MapStore::open(dir.path()).unwrap());
    let yaml = test_support::nav2_maps_dir().join("depot.yaml");
    let grid = load_ros_map(&yaml, &ImportLimits::default()).unwrap().grid;
    let name = MapName::new("depot").unwrap();
    let src = MapSource::new(SourceKind::RosMap, Some(&yaml), "serve test");
    let v1 = store.put(&name, &grid, &src).unwrap();
    let mut changed = grid.clone();
    changed.set(3, 3, OCCUPIED);
    let v2 = store.put(&name, &changed, &src).unwrap();

    let site = SiteId::new("hq").unwrap();
    let (server_session, robot) = session_pair().await;
    let _server = MapServer::start(&server_session, &site, store.clone())
        .await
        .unwrap();

    // The queryable's declaration reaches the robot's session asynchronously; until then a
    // query finds no store. Robots retry the same way.
    let deadline = std::time::Instant::now() + TIMEOUT;
    while fetch_meta(&robot, &site, &name, None, TIMEOUT)
        .await
        .is_err()
    {
        assert!(
            std::time::Instant::now() < deadline,
            "the map store never became reachable"
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }

    let latest = fetch_map(&robot, &site, &name, None, TIMEOUT)
        .await
        .unwrap();
    assert_eq!(latest.meta, v2);
    assert_eq!(latest.cells, changed.cells());
    let first = fetch_map(&robot, &site, &name, Some(1), TIMEOUT)
        .await
        .unwrap();
    assert_eq!(first.meta, v1);
    assert_eq!(first.cells, grid.cells());

    let meta = fetch_meta(&robot, &site, &name, None, TIMEOUT)
        .await
        .unwrap();
    assert_eq!(meta, v2);
    // The meta reply is JSON (not the framed grid), straight from the documented selector.
    let replies = robot
        .get(format!("{}?meta", keys::map_version(&site, &name, 1)))
        .await
        .unwrap();
    let sample = replies.recv_async().await.unwrap().into_result().unwrap();
    let bytes = sample.payload().to_bytes();
    let json: serde_json::Value = serde_json::from_slice(&bytes).unwrap();
    assert_eq!(json["kind"], "map_meta");
    assert_eq!(json["msg"]["version"], 1);

    let missing = MapName::new("attic").unwrap();
    match fetch_map(&robot, &site, &missing, None, TIMEOUT).await {
        Err(MapError::Remote { key, reason }) => {
            assert!(key.ends_with("/map/attic"), "{key}");
            assert!(reason.contains("attic"), "{reason}");
        }
        other => panic!("expected a remote error, got {other:?}"),
    }
    let e = fetch_map(&robot, &site, &name, Some(9), TIMEOUT)
        .await
        .unwrap_err()
        .to_string();
    assert!(e.contains("depot") && e.contains('9'), "{e}");

    // Another site's keys are not served by this store: no answer within the timeout.
    let other = SiteId::new("elsewhere").unwrap();
    let e = fetch_map(&robot, &other, &name, None, Duration::from_millis(300))
        .await
        .unwrap_err();
    assert!(matches!(e, MapError::Zenoh { .. }), "{e}");
}
