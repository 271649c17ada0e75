//! A task's goals and how far a robot has come along them: which goal is next once a pose is
//! known (goals within the tolerance count as reached, possibly several at once), and which
//! heading to plan for at a goal that leaves it free.

use protocol::Pose2D;
use serde::{Deserialize, Serialize};

/// One goal of a delivery task; without `yaw_rad` any arrival heading is accepted.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Goal {
    pub x_m: f64,
    pub y_m: f64,
    #[serde(default)]
    pub yaw_rad: Option<f64>,
}

impl Goal {
    /// A goal that accepts any arrival heading.
    #[must_use]
    pub fn at(x_m: f64, y_m: f64) -> Self {
        Self {
            x_m,
            y_m,
            yaw_rad: None,
        }
    }

    /// The goal as a pose; a free heading becomes the direction of arrival from `from`.
    #[must_use]
    pub fn pose_from(&self, from: Pose2D) -> Pose2D {
        let yaw = self
            .yaw_rad
            .unwrap_or_else(|| (self.y_m - from.y_m).atan2(self.x_m - from.x_m));
        Pose2D::new(self.x_m, self.y_m, yaw)
    }

    /// Distance in the plane from `p` to the goal.
    #[must_use]
    pub fn distance_m(&self, p: Pose2D) -> f64 {
        (p.x_m - self.x_m).hypot(p.y_m - self.y_m)
    }
}

/// A task's goals and the index of the goal the robot is heading for (`next`; the goals
/// before it are reached).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GoalProgress<'a> {
    pub goals: &'a [Goal],
    pub next: usize,
}

/// Where a robot stands on its goals after one pose.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Advance {
    /// Heading for goal `index`, planned as the pose `target` (a free heading resolved).
    Heading { index: usize, target: Pose2D },
    /// Every goal is reached.
    Done,
}

impl<'a> GoalProgress<'a> {
    #[must_use]
    pub fn new(goals: &'a [Goal], next: usize) -> Self {
        Self { goals, next }
    }

    /// Moves past every goal within `tolerance_m` of `pose` in order, from `next` on. A goal
    /// with a free heading is planned with the heading of the straight line from the previous
    /// goal (from the robot itself for the first goal), so the robot arrives as the task's
    /// legs run rather than in whatever heading the search happens to end.
    #[must_use]
    pub fn advance(&self, pose: Pose2D, tolerance_m: f64) -> Advance {
        let mut k = self.next;
        while let Some(g) = self.goals.get(k) {
            if g.distance_m(pose) > tolerance_m {
                break;
            }
            k += 1;
        }
        let Some(goal) = self.goals.get(k) else {
            return Advance::Done;
        };
        let from = match k.checked_sub(1).and_then(|i| self.goals.get(i)) {
            Some(prev) => Pose2D::new(prev.x_m, prev.y_m, 0.0),
            None => pose,
        };
        Advance::Heading {
            index: k,
            target: goal.pose_from(from),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn advances_past_every_goal_in_reach_and_resolves_free_headings() {
        let goals = [Goal::at(1.0, 0.0), Goal::at(1.2, 0.0), Goal::at(1.2, 3.0)];
        let progress = GoalProgress::new(&goals, 0);
        // Far from all: the first goal, heading from the robot.
        let Advance::Heading { index, target } =
            progress.advance(Pose2D::new(-1.0, 0.0, 2.0), 0.35)
        else {
            panic!("not done yet")
        };
        assert_eq!(index, 0);
        assert!((target.yaw_rad - 0.0).abs() < 1e-12, "{target:?}");
        // At the first goal: the second is within reach too, so the third is next, with the
        // heading of the leg from the second goal.
        let Advance::Heading { index, target } = progress.advance(Pose2D::new(1.1, 0.0, 0.0), 0.35)
        else {
            panic!("not done yet")
        };
        assert_eq!(index, 2);
        assert!((target.yaw_rad - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
        assert_eq!(
            GoalProgress::new(&goals, 2).advance(Pose2D::new(1.2, 2.9, 0.0), 0.35),
            Advance::Done
        );
        // A fixed heading is kept; progress never goes back.
        let fixed = [Goal {
            x_m: 5.0,
            y_m: 5.0,
            yaw_rad: Some(-1.0),
        }];
        assert_eq!(
            GoalProgress::new(&fixed, 0).advance(Pose2D::new(0.0, 0.0, 0.0), 0.35),
            Advance::Heading {
                index: 0,
                target: Pose2D::new(5.0, 5.0, -1.0)
            }
        );
        assert_eq!(
            GoalProgress::new(&goals, 3).advance(Pose2D::new(1.0, 0.0, 0.0), 0.35),
            Advance::Done
        );
    }
}
