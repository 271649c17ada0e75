//! Where the reference data lives: the Nav2 maps in `shared/maps` beside the repository, the
//! simulator's scenarios and the shipped models in the repository.
//!
//! `FLEET_SHARED_DIR` overrides the default `shared/` location, `<repository>/../shared` (how CI
//! lays it out).

use std::path::{Path, PathBuf};

use map_core::{load_ros_map, ImportLimits, OccupancyGrid};

/// The repository root.
#[must_use]
pub fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .map_or_else(|| PathBuf::from(".."), Path::to_path_buf)
}

/// The `shared/` folder: `$FLEET_SHARED_DIR`, else `../shared` next to the repository.
#[must_use]
pub fn shared_dir() -> PathBuf {
    std::env::var_os("FLEET_SHARED_DIR")
        .map_or_else(|| repo_root().join("..").join("shared"), PathBuf::from)
}

/// The folder of the Nav2 reference maps (`shared/maps/nav2`).
#[must_use]
pub fn nav2_maps_dir() -> PathBuf {
    shared_dir().join("maps").join("nav2")
}

/// Loads `<name>.yaml` from the Nav2 reference maps; panics with the path when it cannot.
#[must_use]
pub fn nav2_map(name: &str) -> OccupancyGrid {
    let path = nav2_maps_dir().join(format!("{name}.yaml"));
    load_ros_map(&path, &ImportLimits::default())
        .unwrap_or_else(|e| panic!("loading {}: {e}", path.display()))
        .grid
}

/// The simulator's scenarios (`sim/scenarios`).
#[must_use]
pub fn scenarios_dir() -> PathBuf {
    repo_root().join("sim").join("scenarios")
}

/// `sim/scenarios/<name>.yaml`.
#[must_use]
pub fn scenario(name: &str) -> PathBuf {
    scenarios_dir().join(format!("{name}.yaml"))
}

/// The shipped models and fixtures (`models/`).
#[must_use]
pub fn models_dir() -> PathBuf {
    repo_root().join("models")
}
