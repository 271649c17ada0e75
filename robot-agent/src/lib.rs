//! Robot agent: localization, controllers and the safety loop that commands the base.
//!
//! Today it holds the agent's configuration ([`config`]); AMCL, the controllers and the
//! Zenoh loop come with the robot-agent issue.

pub mod config;

pub use config::{AgentConfig, ControllerKind, Limits, Safety};
