//! Planner service: hybrid A* replanning, intentions (DLM, LPE), and the fleet HTTP API.
//!
//! - [`planning`]: hybrid A* on an inflated occupancy grid with a cached obstacle heuristic,
//!   Dubins analytic expansion, a shortcut smoother and a plain 2-D A* reference.
//! - [`intention`]: the paper's two intentions derived from a planned path (DLM, LPE image).
//! - [`config`]: the service configuration file (`[planner]`, `[dlm]`, `[lpe]`, `[http]`,
//!   `[zenoh]`).
//! - [`fleet`]: robot registry, delivery tasks (redb) and the per-robot replanning loop over
//!   Zenoh.
//! - [`http`]: the HTTP API (docs/api.md) and the running service behind `serve`.
//! - [`demo`]: the fleet demo (service + simulator + agents as processes); [`fleet_bench`]:
//!   the replanning-loop benchmark.
//! - [`cli`], [`bench`], [`picture`]: the `planner-service` command line, its benchmark and
//!   map + path pictures.

pub mod bench;
pub mod cli;
pub mod config;
pub mod demo;
pub mod fleet;
pub mod fleet_bench;
pub mod http;
pub mod intention;
pub mod picture;
pub mod planning;
