//! Keeping the previous plan while it still holds (issue 16: cheaper replanning).
//!
//! The paper replans every cycle. Most cycles the robot is still on the path it was sent, the
//! map version and the goal are the same, and a new hybrid-A* search returns the same route
//! from a point a few centimetres further along. [`KeptPlan`] keeps the last searched path and
//! answers such a cycle with the rest of it instead; it asks for a new search when the map or
//! the goal changed, when the robot left a corridor around the path (position and heading), or
//! at the path's end. After `max_cycles` reused answers in a row a new search is *due*, so a
//! better route that only shows from further along is still found within a bounded time: the
//! caller runs it after sending the answer ([`crate::IntentionPlanner::refresh`]), off the
//! pose-to-intention path, or the next answer runs it first.

use serde::{Deserialize, Serialize};

use crate::error::{Endpoint, PlanError};
use crate::map::{MapKey, PlanningMap};
use crate::path::nearest_index;
use protocol::Pose2D;

/// When a kept plan may answer instead of a new search.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ReuseParams {
    /// On by default (since 2026-11-27: no worse in closed loop for any method, the same DLM as
    /// a new search as often as a new search agrees with itself, and the fleet's 100- and
    /// 250-robot targets; docs/benchmarks.md, "Path reuse"). Off: a new search every cycle
    /// (the paper's behaviour, the reference reuse is measured against, and what `eval
    /// record` labels with).
    pub enabled: bool,
    /// The robot must be within this distance of the kept path.
    pub corridor_m: f64,
    /// ... and its heading within this angle of the path's there.
    pub corridor_yaw_rad: f64,
    /// A new search is due after this many reused answers in a row.
    pub max_cycles: u32,
    /// The answered path goes from the robot straight to the kept path's pose this far along
    /// it past the robot's nearest: a shallow merge like a new search's, not a sideways kink at
    /// the robot (the LPE image draws it, and LPE-Net was trained on new searches' pictures).
    pub rejoin_m: f64,
}

impl Default for ReuseParams {
    fn default() -> Self {
        Self {
            enabled: true,
            corridor_m: 0.25,
            corridor_yaw_rad: 0.5,
            max_cycles: 20,
            rejoin_m: 0.5,
        }
    }
}

impl ReuseParams {
    /// # Errors
    /// [`PlanError::InvalidConfig`] naming the field and value.
    pub fn validate(&self) -> Result<(), PlanError> {
        if !(self.corridor_m.is_finite() && self.corridor_m > 0.0) {
            return Err(PlanError::invalid_config(
                "reuse.corridor_m",
                self.corridor_m,
                "must be positive",
            ));
        }
        if !(self.corridor_yaw_rad.is_finite()
            && self.corridor_yaw_rad > 0.0
            && self.corridor_yaw_rad <= std::f64::consts::PI)
        {
            return Err(PlanError::invalid_config(
                "reuse.corridor_yaw_rad",
                self.corridor_yaw_rad,
                "must be in (0, pi]",
            ));
        }
        if !(self.rejoin_m.is_finite() && self.rejoin_m >= 0.0) {
            return Err(PlanError::invalid_config(
                "reuse.rejoin_m",
                self.rejoin_m,
                "must be zero or positive",
            ));
        }
        if self.max_cycles == 0 {
            return Err(PlanError::invalid_config(
                "reuse.max_cycles",
                self.max_cycles,
                "must be at least 1",
            ));
        }
        Ok(())
    }
}

/// What a kept plan answers: the rest of its path from the robot, and the rest's length.
#[derive(Debug, Clone, PartialEq)]
pub struct KeptRest {
    /// The robot's pose, then the kept path from where it rejoins it.
    pub poses: Vec<Pose2D>,
    pub length_m: f64,
}

/// The last searched path of one robot, and how far along it the robot has come.
#[derive(Debug, Clone)]
pub struct KeptPlan {
    map: MapKey,
    goal: Pose2D,
    free_heading: bool,
    poses: Vec<Pose2D>,
    /// Path length from the first pose to each pose, so an answer's length costs no walk
    /// along the path.
    along_m: Vec<f64>,
    /// Index of the path pose nearest the robot at the last answer (the search for the nearest
    /// pose starts here, so a path that passes near itself is never followed backwards).
    along: usize,
    reused: u32,
}

impl KeptPlan {
    /// Keeps `poses`, just searched on `map` to `goal`.
    #[must_use]
    pub fn new(map: MapKey, goal: Pose2D, free_heading: bool, poses: Vec<Pose2D>) -> Self {
        let mut along_m = Vec::with_capacity(poses.len());
        let mut acc = 0.0;
        for (i, p) in poses.iter().enumerate() {
            if i > 0 {
                acc += poses[i - 1].distance_m(p);
            }
            along_m.push(acc);
        }
        Self {
            map,
            goal,
            free_heading,
            poses,
            along_m,
            along: 0,
            reused: 0,
        }
    }

    /// Whether a new search is due: `max_cycles` answers in a row came from this plan.
    #[must_use]
    pub fn refresh_due(&self, params: &ReuseParams) -> bool {
        self.reused >= params.max_cycles
    }

    /// Puts the due search off by another `max_cycles` answers (the search failed while the
    /// plan still holds).
    pub fn postpone_refresh(&mut self) {
        self.reused = 0;
    }

    /// The goal the plan leads to, and whether its heading is free.
    #[must_use]
    pub fn goal(&self) -> (Pose2D, bool) {
        (self.goal, self.free_heading)
    }

    /// The rest of the kept path from `robot` (the robot's pose first), or `None` when the
    /// plan no longer holds there and a new search must answer (see the module docs).
    pub fn follow(
        &mut self,
        map: &PlanningMap,
        robot: Pose2D,
        goal: Pose2D,
        free_heading: bool,
        params: &ReuseParams,
    ) -> Option<KeptRest> {
        // A free-heading goal's heading is resolved from the robot's pose each cycle, so only
        // its position identifies it.
        let same_goal = free_heading == self.free_heading
            && goal.x_m == self.goal.x_m
            && goal.y_m == self.goal.y_m
            && (free_heading || goal.yaw_rad == self.goal.yaw_rad);
        if !params.enabled || map.key() != self.map || !same_goal {
            return None;
        }
        let index = self.along + nearest_index(self.poses.get(self.along..)?, robot)?;
        let nearest = &self.poses[index];
        let turned = protocol::normalize_angle(robot.yaw_rad - nearest.yaw_rad).abs();
        if robot.distance_m(nearest) > params.corridor_m
            || turned > params.corridor_yaw_rad
            || index + 1 >= self.poses.len()
            || map.check_endpoint(Endpoint::Start, robot).is_err()
        {
            return None;
        }
        self.along = index;
        self.reused += 1;
        let mut rejoin = index + 1;
        while self.along_m[rejoin] - self.along_m[index] < params.rejoin_m
            && rejoin + 1 < self.poses.len()
        {
            rejoin += 1;
        }
        let mut poses = Vec::with_capacity(self.poses.len() - rejoin + 1);
        poses.push(robot);
        poses.extend_from_slice(&self.poses[rejoin..]);
        let end_m = self.along_m[self.along_m.len() - 1];
        Some(KeptRest {
            poses,
            length_m: robot.distance_m(&self.poses[rejoin]) + end_m - self.along_m[rejoin],
        })
    }
}
