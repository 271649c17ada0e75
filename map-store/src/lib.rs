//! Floor plans in, occupancy grids out.
//!
//! - [`grid`]: the occupancy grid (ROS cell values, row 0 at the bottom) and its transforms.
//! - [`distance`]: the exact Euclidean distance field and inflation by a robot radius.
//! - [`ros`]: import of ROS `map_server` YAML + image with Nav2's exact semantics.
//! - [`picture`]: import of plain floor-plan pictures given their scale.
//! - [`import`]: one entry point for any input file, validated before anything is stored.
//! - [`store`]: durable, versioned, content-addressed storage in an embedded redb database.
//! - [`export`]: export back to ROS PGM + YAML as Nav2's `map_saver` writes it.
//! - [`serve`]: the Zenoh queryable serving maps to robots, and the robots' [`fetch_map`].
//! - [`config`], [`cli`], [`bench`]: the `map-store` binary's configuration, commands and
//!   benchmark.

pub mod bench;
pub mod cli;
pub mod config;
pub mod distance;
pub mod error;
pub mod export;
pub mod grid;
pub mod import;
pub mod paths;
pub mod picture;
pub mod ros;
pub mod serve;
pub mod store;

pub use config::MapStoreConfig;
pub use distance::{DistanceField, Sources};
pub use error::MapError;
pub use export::{export_ros_map, ExportOptions};
pub use grid::{
    classify, CellClass, CellCounts, GridGeometry, OccupancyGrid, FREE, OCCUPIED, UNKNOWN,
};
pub use import::{import_file, import_into};
pub use picture::{import_picture, PictureOptions};
pub use ros::{load_ros_map, ImportLimits, Interpretation, MapMode, RosMap};
pub use serve::{fetch_map, fetch_meta, MapServer};
pub use store::{MapSource, MapStore, SourceKind, StoredMap};
