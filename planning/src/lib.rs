//! Planning on a floor plan (DESIGN.md §4, §6; paper §3.1, §3.3): from a robot's pose estimate
//! and its task's goals to the intention it should follow.
//!
//! [`IntentionPlanner::answer`] is the one entry point the fleet service, the evaluation and the
//! tests call: goal advancement ([`goals`]), hybrid A* ([`Planner`]) on a [`PlanningMap`] built
//! once per map version and shared between robots, then the DLM, the LPE image and the thinned
//! path ([`intention`]).
//!
//! - [`hybrid_astar`], [`dubins`], [`smoother`], [`heuristic`], [`map`], [`path`], [`config`],
//!   [`error`]: the search (Dolgov et al. 2010) with its cached obstacle heuristic;
//!   [`centring`] moves its smoothed path to the middle of corridors and doorways.
//! - [`grid_astar`]: the plain 8-connected 2-D A* used as a benchmark reference.
//! - [`sample`]: seeded random start/goal pairs; [`picture`]: map + path pictures.
//!
//! This crate depends on `protocol` and `map-core` only: no storage, no HTTP, no session.

pub mod centring;
pub mod config;
pub mod dubins;
pub mod error;
pub mod goals;
pub mod grid_astar;
pub mod heuristic;
pub mod hybrid_astar;
pub mod intention;
pub mod map;
pub mod path;
pub mod picture;
pub mod sample;
pub mod smoother;

pub use centring::CentringParams;
pub use config::PlannerConfig;
pub use error::{Endpoint, PlanError};
pub use goals::{Advance, Goal, GoalProgress};
pub use hybrid_astar::Planner;
pub use intention::{
    stop_intention, Answer, AvoidParams, DlmMeasure, DlmParams, IntentionConfig, IntentionPlanner,
    LpeImage, LpeParams, Neighbour, Planned, RefreshJob, Refreshed, ReuseParams,
    SeenObstacleParams,
};
pub use map::{Disc, MapKey, PlanningMap};
pub use path::{Path, PathStats};
