//! Simulator: the ground-truth world, a differential-drive base and its sensors.
//!
//! The stand-in for robots and buildings (Stage in the Intention-Net paper, §4):
//! - [`scenario`]: the scenario file (floor plan + ground-truth extras + goals) and its schema;
//! - [`world`]: the lock-step simulation ([`World::step`]) with collisions, LIDAR and odometry;
//! - [`camera`]: the monocular camera renderer ([`World::render_camera`]);
//! - [`mapgen`]: the generated floor plans and shipped scenarios;
//! - [`procgen`]: procedural buildings from a seed (training and held-out evaluation buildings);
//! - [`driver`]: the real-time Zenoh driver; [`roster`]: the robot roster `sim run` prints (JSON),
//!   with its one parser; [`cli`]: the `sim` command line.

pub mod appearance;
pub mod camera;
pub mod cli;
pub mod config;
pub mod driver;
pub mod geom;
pub mod mapgen;
pub mod procgen;
pub mod raycast;
pub mod roster;
pub mod scenario;
pub mod view;
pub mod world;

pub use config::SimConfig;
pub use roster::{Roster, RosterError, RosterRobot};
pub use scenario::{Scenario, ScenarioError};
pub use world::{
    integrate, Collision, Command, Observations, Obstacle, RobotObservation, SimError, World,
};
