//! Robot agent: localization, controllers and the safety loop that commands the base.
//!
//! - [`amcl`]: AMCL localization on the floor plan's likelihood field.
//! - [`collision_monitor`]: the last check on every command, against the laser scan.
//! - [`give_way`]: waiting short of a narrow passage while someone comes through it.
//! - [`recovery`]: the dynamic window takes over while the monitor holds the controller.
//! - [`controllers`]: the controller trait and the controllers that implement it.
//! - [`config`]: the agent's configuration.
//! - [`node`]: the agent node on Zenoh (localization, control and safety loop); [`cli`]: the
//!   `robot-agent` command line around it.
//! - [`replay`]: the agent's localization replayed over a recorded run log (`fleet-log`).
//! - [`rotation_shim`]: a turn on the spot towards the path before the controller drives on.
//! - [`unmapped`]: the obstacle layer: what the laser sees where the floor plan is free, sent
//!   with each pose so the planner routes round it.

pub mod amcl;
pub mod camera_hold;
pub mod cli;
pub mod collision_monitor;
pub mod config;
pub mod controllers;
pub mod give_way;
pub mod movers;
pub mod node;
pub mod recovery;
pub mod replay;
pub mod rotation_shim;
pub mod unmapped;

pub use amcl::{Amcl, AmclConfig, Estimate, LikelihoodField, UpdateOutcome};
pub use camera_hold::{CameraHold, CameraHoldConfig};
pub use collision_monitor::{CollisionMonitorConfig, Verdict};
pub use config::{AgentConfig, ControllerKind, Limits, Localization, Safety};
pub use controllers::{Control, ControlInput, Controller, ControllerError};
pub use give_way::{GiveWay, GiveWayConfig};
pub use node::{make_controller, NodeError, NodeOptions, Supervisor};
pub use recovery::{Recovery, RecoveryConfig};
pub use rotation_shim::{RotationShim, RotationShimConfig};
pub use unmapped::{UnmappedConfig, UnmappedObstacles};
