//! Robot agent: localization, controllers and the safety loop that commands the base.
//!
//! - [`amcl`]: AMCL localization on the floor plan's likelihood field.
//! - [`controllers`]: the controller trait and the controllers that implement it.
//! - [`config`]: the agent's configuration.

pub mod amcl;
pub mod config;
pub mod controllers;

pub use amcl::{Amcl, AmclConfig, Estimate, LikelihoodField, UpdateOutcome};
pub use config::{AgentConfig, ControllerKind, Limits, Safety};
pub use controllers::{Control, ControlInput, Controller, ControllerError};
