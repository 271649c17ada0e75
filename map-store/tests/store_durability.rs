//! Durability of the map store: restarts, and real crashes (SIGKILL, abort) in the middle of a
//! write. The crash tests re-run this test binary as a child process that writes big maps in a
//! loop; the parent kills it and checks that what was committed is intact and nothing partial
//! exists.

// Helpers outside #[test] functions are test code too.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::Duration;

use map_store::store::{content_hash, MapSource, MapStore, SourceKind};
use map_store::{load_ros_map, ImportLimits, OccupancyGrid, FREE, OCCUPIED, UNKNOWN};
use protocol::{MapName, Pose2D};
use rand::{Rng, SeedableRng};

const CHILD_DIR_ENV: &str = "MAP_STORE_CRASH_CHILD_DIR";
const CHILD_MODE_ENV: &str = "MAP_STORE_CRASH_CHILD_MODE";

fn name() -> MapName {
    MapName::new("big").unwrap()
}

fn source() -> MapSource {
    MapSource::new(SourceKind::Grid, None, "crash test")
}

/// A 2000 x 2000 map (4 MB of cells) so a write takes long enough to be hit by the kill.
fn big_grid(rng: &mut rand_chacha::ChaCha8Rng) -> OccupancyGrid {
    let cells: Vec<u8> = (0..2000 * 2000)
        .map(|_| match rng.gen_range(0..10) {
            0 => OCCUPIED,
            1 => UNKNOWN,
            _ => FREE,
        })
        .collect();
    OccupancyGrid::new(2000, 2000, 0.05, Pose2D::new(0.0, 0.0, 0.0), cells).unwrap()
}

/// Every version listed is complete: cells present, hash and id agree with the cells, versions
/// numbered 1..=n without gaps. Returns n.
fn check_consistent(store: &MapStore) -> u32 {
    let versions = store.versions(&name()).unwrap();
    assert_eq!(
        store.list().unwrap().len(),
        versions.len(),
        "a meta record without a version"
    );
    for (i, meta) in versions.iter().enumerate() {
        assert_eq!(
            meta.version as usize,
            i + 1,
            "versions have a gap: {versions:?}"
        );
        let stored = store.get_by_id(&meta.id).unwrap();
        let hash = content_hash(&stored.grid);
        assert_eq!(
            hash, meta.content_hash,
            "version {} has damaged cells",
            meta.version
        );
        assert!(meta.id.as_str().ends_with(&hash[..12]));
        let c = stored.grid.counts();
        assert_eq!(
            (c.free, c.occupied, c.unknown),
            (meta.free_cells, meta.occupied_cells, meta.unknown_cells)
        );
    }
    u32::try_from(versions.len()).unwrap()
}

/// The child side of the crash tests; does nothing unless started by them.
#[test]
#[ignore = "child process of the crash tests, started by them"]
fn crash_child() {
    let Some(dir) = std::env::var_os(CHILD_DIR_ENV) else {
        return;
    };
    let abort = std::env::var(CHILD_MODE_ENV).is_ok_and(|m| m == "abort");
    let store = MapStore::open(Path::new(&dir)).unwrap();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(std::process::id().into());
    let mut grid = big_grid(&mut rng);
    let mut puts = 0u32;
    loop {
        if abort && puts == 2 {
            // Abort from another thread while this one is inside the next put's transaction.
            let delay_ms = rng.gen_range(1..40);
            std::thread::spawn(move || {
                std::thread::sleep(Duration::from_millis(delay_ms));
                std::process::abort();
            });
        }
        // New content every round without regenerating 4 MB of random cells.
        let x = rng.gen_range(0..2000);
        let y = rng.gen_range(0..2000);
        let v = if grid.get(x, y) == Some(OCCUPIED) {
            FREE
        } else {
            OCCUPIED
        };
        grid.set(x, y, v);
        let meta = store.put(&name(), &grid, &source()).unwrap();
        puts += 1;
        println!("committed {}", meta.version);
    }
}

fn run_crash_round(dir: &Path, mode: &str, seed: u64) -> u32 {
    let before = {
        let store = MapStore::open(dir).unwrap();
        check_consistent(&store)
    };
    let mut child = Command::new(std::env::current_exe().unwrap())
        .args([
            "--exact",
            "crash_child",
            "--ignored",
            "--nocapture",
            "--test-threads=1",
        ])
        .env(CHILD_DIR_ENV, dir)
        .env(CHILD_MODE_ENV, mode)
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let stdout = BufReader::new(child.stdout.take().unwrap());
    let mut reported = before;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    for line in stdout.lines() {
        let line = line.unwrap();
        if let Some(v) = line.strip_prefix("committed ") {
            reported = v.trim().parse().unwrap();
            if mode == "kill" && reported >= before + 2 {
                // Land somewhere inside the next 4 MB write.
                std::thread::sleep(Duration::from_millis(rng.gen_range(0..30)));
                child.kill().unwrap();
                break;
            }
        }
    }
    let status = child.wait().unwrap();
    assert!(!status.success(), "the child must have died, got {status}");
    let store = MapStore::open(dir).unwrap();
    let after = check_consistent(&store);
    assert!(
        reported >= before + 2,
        "child committed only up to {reported}"
    );
    // The kill may land after a commit but before its "committed" line: at most one more.
    assert!(
        after == reported || after == reported + 1,
        "reported {reported}, stored {after}"
    );
    after
}

#[test]
fn sigkill_and_abort_mid_write_leave_committed_versions_intact() {
    let dir = tempfile::tempdir().unwrap();
    let mut stored = 0;
    for (round, mode) in ["kill", "abort", "kill"].into_iter().enumerate() {
        let n = run_crash_round(dir.path(), mode, round as u64);
        assert!(n >= stored + 2);
        stored = n;
    }
    // The store still takes writes after the crashes.
    let store = MapStore::open(dir.path()).unwrap();
    let small = OccupancyGrid::filled(3, 3, 0.1, Pose2D::new(0.0, 0.0, 0.0), FREE).unwrap();
    assert_eq!(
        store.put(&name(), &small, &source()).unwrap().version,
        stored + 1
    );
}

#[test]
fn everything_survives_a_restart() {
    let dir = tempfile::tempdir().unwrap();
    let yaml = test_support::nav2_maps_dir().join("depot.yaml");
    let grid = load_ros_map(&yaml, &ImportLimits::default()).unwrap().grid;
    let name = MapName::new("depot").unwrap();
    let src = MapSource::new(SourceKind::RosMap, Some(&yaml), "restart test");
    let (m1, m2) = {
        let store = MapStore::open(dir.path()).unwrap();
        let m1 = store.put(&name, &grid, &src).unwrap();
        let mut changed = grid.clone();
        changed.set(1, 1, OCCUPIED);
        let m2 = store.put(&name, &changed, &src).unwrap();
        (m1, m2)
    };
    let store = MapStore::open(dir.path()).unwrap();
    let back = store.get(&name, Some(1)).unwrap();
    assert_eq!(back.meta, m1);
    assert_eq!(back.grid, grid);
    assert_eq!(back.source, src);
    assert_eq!(store.get(&name, None).unwrap().meta, m2);
    assert_eq!(store.list().unwrap(), vec![m2, m1]);
}
