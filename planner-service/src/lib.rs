//! Planner service: the fleet core that replans every robot's path through the `planning`
//! crate's intention pipeline, and the fleet HTTP API.
//!
//! - [`config`]: the service configuration file (`[planner]`, `[dlm]`, `[lpe]`, `[http]`,
//!   `[zenoh]`).
//! - [`fleet`]: robot registry, delivery tasks (redb) and the per-robot replanning loop over
//!   Zenoh.
//! - [`http`]: the HTTP API (docs/api.md) and the running service behind `serve`.
//! - [`demo`]: the fleet demo (service + simulator + agents as processes); [`launch`]: the
//!   launcher of the simulator and the agents that the demo and the end-to-end tests share;
//!   [`restart`]: the back-off with which the demo restarts an agent that exited;
//!   [`fleet_bench`]: the replanning-loop benchmark; [`store_bench`]: the task-store (list and
//!   snapshot) benchmark.
//! - [`cli`], [`bench`]: the `planner-service` command line and its planner benchmark.

pub mod bench;
pub mod cli;
pub mod config;
pub mod demo;
pub mod fleet;
pub mod fleet_bench;
pub mod http;
pub mod launch;
pub mod restart;
pub mod store_bench;
