//! The map store: versioned, durable floor plans and the Zenoh queryable that serves them.
//!
//! The map code itself (grid, distance field, ROS and picture import, export) is `map-core`,
//! re-exported here so the store's users see one crate.
//!
//! - [`import`]: one entry point for any input file, validated before anything is stored.
//! - [`store`]: durable, versioned, content-addressed storage in an embedded redb database.
//! - [`serve`]: the Zenoh queryable serving maps to robots (the client is `map_core::fetch`).
//! - [`config`], [`cli`], [`bench`]: the `map-store` binary's configuration, commands and
//!   benchmark.

pub mod bench;
pub mod cli;
pub mod config;
pub mod import;
pub mod serve;
pub mod store;

pub use map_core::{
    classify, export_ros_map, fetch_map, fetch_meta, import_picture, load_ros_map, CellClass,
    CellCounts, DistanceField, ExportOptions, GridGeometry, ImportLimits, Interpretation, MapError,
    MapMode, OccupancyGrid, PictureOptions, RosMap, Sources, FREE, OCCUPIED, UNKNOWN,
};
pub use map_core::{distance, error, export, fetch, grid, picture, ros};

pub use config::MapStoreConfig;
pub use import::{import_file, import_into};
pub use serve::MapServer;
pub use store::{MapSource, MapStore, SourceKind, StoredMap};
