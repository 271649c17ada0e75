//! Where the reference data lives: the Nav2 maps in `shared/maps` beside the repository.
//!
//! Tests, benchmarks and the demo find them here so every crate agrees on one location.
//! `FLEET_SHARED_DIR` overrides the default, `<repository>/../shared` (how CI lays it out).

use std::path::PathBuf;

/// The `shared/` folder: `$FLEET_SHARED_DIR`, else `../shared` next to the repository.
#[must_use]
pub fn shared_dir() -> PathBuf {
    std::env::var_os("FLEET_SHARED_DIR").map_or_else(
        || PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../shared")),
        PathBuf::from,
    )
}

/// The folder of the Nav2 reference maps (`shared/maps/nav2`).
#[must_use]
pub fn nav2_maps_dir() -> PathBuf {
    shared_dir().join("maps").join("nav2")
}
