//! Test fixtures shared by the workspace's tests, benchmarks and examples (never by shipped
//! code): where the reference data lives, the Nav2 map loader, and the other pieces every
//! crate's tests would otherwise write again.
//!
//! Paths here are resolved from this crate's source location at build time; that is fine for
//! tests and forbidden in shipped binaries, which take their data locations from flags, the
//! environment or the user's data directory.

// Fixtures fail loudly: a test that cannot load its data has nothing else to do.
#![allow(
    clippy::expect_used,
    clippy::unwrap_used,
    clippy::cast_possible_truncation,
    clippy::cast_sign_loss,
    clippy::cast_precision_loss
)]

pub mod fixtures;
pub mod paths;

pub use paths::{
    models_dir, nav2_map, nav2_maps_dir, repo_root, scenario, scenarios_dir, shared_dir,
};
