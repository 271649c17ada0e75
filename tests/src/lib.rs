//! Multi-process end-to-end tests over real Zenoh sessions live in `tests/` of this crate.
//!
//! They start the real binaries (map store, simulator, agents, planner service) as separate
//! processes on loopback and drive them over HTTP and Zenoh; they arrive with the planner
//! service, which is the first piece that needs all the others.
