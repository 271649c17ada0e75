//! Path planning on occupancy grids (DESIGN.md §6, paper §3.3).
//!
//! [`PlanningMap`] is built once per map version (distance field, coarse free grid, cache of
//! obstacle heuristics per goal) and shared as `Arc<PlanningMap>` between all robots;
//! [`Planner`] is one robot's reusable search state; [`Planner::plan`] runs hybrid A*
//! (Dolgov et al. 2010) from a start pose to a goal pose within a time budget.
//! [`grid_astar`] is the plain 8-connected 2-D A* used as a benchmark reference.

pub mod config;
pub mod dubins;
pub mod error;
pub mod grid_astar;
pub mod heuristic;
pub mod hybrid_astar;
pub mod map;
pub mod path;
pub mod smoother;

pub use config::PlannerConfig;
pub use error::PlanError;
pub use hybrid_astar::Planner;
pub use map::{MapKey, PlanningMap};
pub use path::{Path, PathStats};
