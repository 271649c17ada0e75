//! The robot roster: which robots `sim run` drives and where each one starts.
//!
//! `sim run` prints the roster as one JSON line on stdout once its Zenoh session is open and
//! before it starts driving, and that line is its only stdout output (logs go to stderr):
//!
//! ```text
//! {"robots":[{"id":"robot_1","x_m":3.0,"y_m":4.0,"yaw_rad":0.0},{"id":"robot_2",…}],"zenoh":["tcp/127.0.0.1:41235"]}
//! ```
//!
//! Poses are the robots' ground-truth start poses in the map frame (metres, radians), written
//! with full `f64` precision. Whoever starts the robots' agents (the launcher of the fleet demo
//! and of the end-to-end tests) reads it with [`Roster::parse_line`], the one parser of this
//! format.

use protocol::{Pose2D, RobotId};
use serde::{Deserialize, Serialize};

use crate::world::World;

/// One robot of the roster and its start pose.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RosterRobot {
    pub id: RobotId,
    pub x_m: f64,
    pub y_m: f64,
    pub yaw_rad: f64,
}

impl RosterRobot {
    /// The start pose (map frame).
    #[must_use]
    pub fn pose(&self) -> Pose2D {
        Pose2D::new(self.x_m, self.y_m, self.yaw_rad)
    }
}

/// The robots of a simulator run, in the simulator's order.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Roster {
    pub robots: Vec<RosterRobot>,
    /// The simulator's own Zenoh endpoints (where it listens): the agents connect to them
    /// directly, so that Zenoh reconnects a lost link between a robot's base and its agent
    /// (it does so only for configured endpoints, not for peers met by gossip).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub zenoh: Vec<String>,
}

/// A line that is not a valid roster.
#[derive(Debug, thiserror::Error)]
pub enum RosterError {
    #[error("not a roster line (expected {{\"robots\":[…]}}): {0}")]
    Json(#[from] serde_json::Error),
    #[error("roster: robot {id} has a non-finite pose")]
    NonFinitePose { id: RobotId },
    #[error("roster: robot {0} is listed twice")]
    DuplicateId(RobotId),
}

impl Roster {
    /// The robots of `world` at their current ground-truth poses.
    #[must_use]
    pub fn of_world(world: &World) -> Self {
        let robots = world
            .robot_ids()
            .iter()
            .enumerate()
            .filter_map(|(i, id)| {
                world.ground_truth_pose(i).map(|p| RosterRobot {
                    id: id.clone(),
                    x_m: p.x_m,
                    y_m: p.y_m,
                    yaw_rad: p.yaw_rad,
                })
            })
            .collect();
        Self {
            robots,
            zenoh: Vec::new(),
        }
    }

    /// The roster as one JSON line (no newline).
    ///
    /// # Errors
    /// When serialization fails (a non-finite pose cannot be written as JSON).
    pub fn to_line(&self) -> Result<String, RosterError> {
        self.validate()?;
        Ok(serde_json::to_string(self)?)
    }

    /// Parses one line of `sim run`'s stdout (surrounding whitespace is ignored).
    ///
    /// # Errors
    /// [`RosterError`] for anything but a valid roster: another line, bad JSON, an invalid
    /// robot id, a non-finite pose, a robot listed twice.
    pub fn parse_line(line: &str) -> Result<Self, RosterError> {
        let roster: Self = serde_json::from_str(line.trim())?;
        roster.validate()?;
        Ok(roster)
    }

    fn validate(&self) -> Result<(), RosterError> {
        for (i, r) in self.robots.iter().enumerate() {
            if ![r.x_m, r.y_m, r.yaw_rad].iter().all(|v| v.is_finite()) {
                return Err(RosterError::NonFinitePose { id: r.id.clone() });
            }
            if self.robots[..i].iter().any(|other| other.id == r.id) {
                return Err(RosterError::DuplicateId(r.id.clone()));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    #[test]
    fn a_roster_line_parses_with_exact_poses() {
        let line = r#" {"robots":[{"id":"robot_1","x_m":3.0,"y_m":4.0,"yaw_rad":0.0},{"id":"robot_2","x_m":1.5,"y_m":-2.25,"yaw_rad":1.25}]} "#;
        let roster = Roster::parse_line(line).unwrap();
        assert_eq!(roster.robots.len(), 2);
        assert_eq!(roster.robots[1].id.as_str(), "robot_2");
        assert_eq!(roster.robots[1].pose(), Pose2D::new(1.5, -2.25, 1.25));
    }

    #[test]
    fn written_lines_read_back_bit_for_bit() {
        let roster = Roster {
            robots: vec![RosterRobot {
                id: RobotId::new("robot_7").unwrap(),
                x_m: 0.1 + 0.2,
                y_m: -1.0 / 3.0,
                yaw_rad: std::f64::consts::PI,
            }],
            zenoh: vec!["tls/127.0.0.1:40123".into()],
        };
        let line = roster.to_line().unwrap();
        assert!(!line.contains('\n'));
        assert_eq!(Roster::parse_line(&line).unwrap(), roster);
    }

    #[test]
    fn other_lines_are_not_rosters() {
        for line in [
            "",
            "robot robot_2 at 1.500,-2.250,1.2500",
            "2024-01-01T00:00:00Z INFO sim driver running",
            r#"{"robots":[{"id":"robot_1","x_m":1,"y_m":2}]}"#,
            r#"{"robots":[{"id":"robot 1","x_m":1,"y_m":2,"yaw_rad":0}]}"#,
            r#"{"robots":[],"extra":1}"#,
        ] {
            assert!(Roster::parse_line(line).is_err(), "{line:?} parsed");
        }
        let twice = r#"{"robots":[{"id":"r","x_m":1,"y_m":2,"yaw_rad":0},{"id":"r","x_m":3,"y_m":2,"yaw_rad":0}]}"#;
        assert!(matches!(
            Roster::parse_line(twice),
            Err(RosterError::DuplicateId(_))
        ));
    }

    #[test]
    fn the_roster_of_a_world_lists_its_robots_at_their_start() {
        let path = test_support::scenario("task_a");
        let mut world = World::from_scenario_file(&path, crate::SimConfig::default()).unwrap();
        world.add_robots_at_start(2).unwrap();
        let roster = Roster::of_world(&world);
        let ids: Vec<&str> = roster.robots.iter().map(|r| r.id.as_str()).collect();
        assert_eq!(ids, ["robot_1", "robot_2"]);
        for (i, r) in roster.robots.iter().enumerate() {
            assert_eq!(Some(r.pose()), world.ground_truth_pose(i));
        }
        let back = Roster::parse_line(&roster.to_line().unwrap()).unwrap();
        assert_eq!(back, roster);
    }
}
