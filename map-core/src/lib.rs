//! Floor plans as plain data: everything about a map that needs no database, no HTTP and no
//! network session, so the planner, the robot agent, the simulator and the evaluation can use
//! it without pulling in the map store's storage.
//!
//! - [`grid`]: the occupancy grid (ROS cell values, row 0 at the bottom), its geometry and
//!   transforms.
//! - [`distance`]: the exact Euclidean distance field and inflation by a robot radius.
//! - [`ros`]: import of ROS `map_server` YAML + image with Nav2's exact semantics.
//! - [`picture`]: import of plain floor-plan pictures given their scale.
//! - [`export`]: export back to ROS PGM + YAML as Nav2's `map_saver` writes it.
//! - [`fetch`] (feature `fetch`): the client that fetches a map from the map store over Zenoh.
//!
//! Storage (versions, the redb database, the queryable that serves maps) lives in `map-store`.

pub mod distance;
pub mod error;
pub mod export;
#[cfg(feature = "fetch")]
pub mod fetch;
pub mod grid;
pub mod picture;
pub mod ros;
pub mod search;

pub use distance::{DistanceField, Sources};
pub use error::MapError;
pub use export::{export_ros_map, ExportOptions};
#[cfg(feature = "fetch")]
pub use fetch::{fetch_map, fetch_meta};
pub use grid::{
    classify, CellClass, CellCounts, GridGeometry, OccupancyGrid, FREE, OCCUPIED, UNKNOWN,
};
pub use picture::{import_picture, PictureOptions};
pub use ros::{load_ros_map, ImportLimits, Interpretation, MapMode, RosMap};

/// The Nav2 reference maps for this crate's own unit tests (`shared/maps/nav2`, or
/// `$FLEET_SHARED_DIR/maps/nav2`).
#[cfg(test)]
pub(crate) fn nav2_maps_dir() -> std::path::PathBuf {
    std::env::var_os("FLEET_SHARED_DIR")
        .map_or_else(
            || std::path::PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../shared")),
            std::path::PathBuf::from,
        )
        .join("maps")
        .join("nav2")
}
