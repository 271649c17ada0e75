//! The privileged expert (method `expert`): the demonstrator whose commands the intention-nets
//! learn to imitate, in the spirit of CARLA's autopilot and "learning by cheating" (Chen et al.
//! 2019). Unlike every other method it reads the ground truth: the true pose of its robot, the
//! walls, furniture and glass, and every person and other robot with its velocity
//! ([`TruthView`], which the harness writes from the world every cycle). It ignores the AMCL
//! pose of [`ControlInput`].
//!
//! What it does each cycle, and why:
//! - **Reference path.** The planner's path (`intention.path`) is what the demonstrations must
//!   follow, so it is followed wherever the truth allows. The crude floor plan lacks furniture
//!   and glass, so the planner's path may run through them: the first [`ExpertConfig::block_scan_m`]
//!   metres ahead are checked against the true furniture and glass, and where they obstruct it
//!   the expert searches its own detour on the ground-truth grid (8-connected A* with a cost
//!   that keeps to the middle of free space) from its true position to the first point past
//!   the obstruction, then rejoins the planner's path. A detour is kept while it still leads
//!   there and searched at most every [`ExpertConfig::replan_period_s`], so the search (a few
//!   milliseconds) is rare. One much longer than the planner's way round, or none at all (a
//!   shut glass door closing the only way), is not taken: the expert then follows the
//!   planner's path, stops short of the obstruction without touching it and waits, as a
//!   person would at a locked door. Another robot that has stood still for
//!   [`ExpertConfig::standing_robot_s`] counts as an obstruction too, like furniture: it may be
//!   parked, waiting for a task or broken down, and following it at the follow gap (as a
//!   robot that is only slower is followed) would wait behind it for ever. Where the planner's
//!   path grazes walls or furniture (it
//!   only keeps the robot's radius from plan walls), the points just ahead are pushed along
//!   the clearance gradient towards [`ExpertConfig::comfort_clearance_m`].
//! - **Giving way.** Someone coming the other way along the reference gets the robot's side
//!   of the corridor: the reference is shifted away from their line as far as the walls allow,
//!   to the side away from where the robot sees them (left or right of its heading line, what
//!   the camera shows), the right where they come straight at it.
//!   Where a passage between them is too narrow to meet in (a door, a cabinet narrowing a
//!   corridor) and the robot cannot be through it well before they arrive, it waits beside
//!   the reference short of the passage, timing its approach to arrive a little before them
//!   (so that it keeps making way). This matters because a person who finds a robot in their
//!   way steps round it only where there is room, and otherwise waits for ever.
//! - **Nominal command.** Pure pursuit on that reference with a speed-scaled look-ahead, the
//!   speed capped by the curvature ahead (lateral acceleration), the distance to the goal, to
//!   an obstruction it has to stop short of and to where it waits, and by a person or robot
//!   ahead in its lane (follow at [`ExpertConfig::follow_gap_m`]); turns on the spot when the
//!   path lies behind. The last metre to the goal (or to where it waits) is driven straight
//!   at it: the planner's path there is bound by a turning radius and may loop, and pursuing
//!   a loop that tight circles the goal for ever.
//! - **Privileged safety filter.** Candidate targets (v, ω) around the nominal one are rolled
//!   out for [`ExpertConfig::horizon_s`] through the expert's own command filter while people
//!   and robots move on at their current velocities (constant-velocity prediction). A candidate
//!   is admissible when, held for [`ExpertConfig::commit_s`] and then braked at the base's
//!   limit, it keeps [`ExpertConfig::static_margin_m`] from walls, furniture and glass and, while
//!   the robot itself closes in, [`ExpertConfig::people_margin_m`] from people
//!   ([`ExpertConfig::robot_margin_m`] from robots). People in this simulator step aside from a
//!   robot in their way and never walk into one, so closing in is the robot's doing and a
//!   robot that stands still is never at fault. Among admissible candidates the cheapest wins:
//!   distance from the nominal command, change from the last choice, and soft costs for coming
//!   near people (within [`ExpertConfig::people_comfort_m`]) and static obstacles (within
//!   [`ExpertConfig::comfort_clearance_m`]).
//! - **Smoothness.** The command is never the target itself: a filter moves the command
//!   towards it with bounded acceleration and jerk (and the same for the turn rate), so the
//!   trajectory has little jerk (the paper's smoothness metric); only braking that safety
//!   needs uses the full limits. The rollouts run the very same filter, so what is checked is
//!   what is driven.
//!
//! Why not the dynamic window itself: it only sees the laser (not glass, not where people are
//! heading), and its arcs jump from cycle to cycle, which the smoothness metric punishes and a
//! network trained on it would learn. Why not plan everything on the truth: the demonstrations
//! must follow the intention the network is given, which comes from the crude plan.
//!
//! Everything is deterministic: no random draws, and the search and rollouts depend on the
//! inputs only. Its cost is about 0.3 ms per cycle (some 150 rollouts of 25 steps), plus an
//! occasional detour search of a few milliseconds.

use std::collections::BinaryHeap;
use std::sync::{Arc, Mutex, PoisonError};

use map_core::search::{MinCost, NEIGHBOURS_8};
use map_core::{DistanceField, GridGeometry, Sources};
use protocol::{normalize_angle, Pose2D};
use robot_agent::controllers::path_tracker::{pursuit_curvature, to_robot_frame};
use robot_agent::controllers::{Control, ControlInput, Controller, ControllerError};
use robot_agent::{ControllerKind, Limits};
use sim::geom::Obb;
use sim::World;

const NAME: &str = "expert";

/// What the expert may read besides the agent's inputs, written by the harness from the world
/// every cycle.
#[derive(Debug, Clone, Default)]
pub struct TruthView {
    /// The true pose of the expert's robot (map frame).
    pub pose: Pose2D,
    pub people: Vec<MovingDisc>,
    /// The other robots (not the expert's own).
    pub robots: Vec<MovingDisc>,
}

/// A disc moving at constant velocity (map frame): a person or a robot.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MovingDisc {
    pub x_m: f64,
    pub y_m: f64,
    pub vx_mps: f64,
    pub vy_mps: f64,
    pub radius_m: f64,
}

impl TruthView {
    /// The truth for robot `robot_index`: its true pose (the origin when there is no such
    /// robot), every person with the velocity its route gives, and every other robot with its
    /// true velocity.
    #[must_use]
    pub fn of(world: &World, robot_index: usize) -> Self {
        let pose = world.ground_truth_pose(robot_index).unwrap_or_default();
        let people = world
            .people
            .iter()
            .map(|p| {
                let (vx_mps, vy_mps) = p.velocity_mps();
                MovingDisc {
                    x_m: p.x_m,
                    y_m: p.y_m,
                    vx_mps,
                    vy_mps,
                    radius_m: p.radius_m,
                }
            })
            .collect();
        let radius_m = world.config.base.radius_m;
        let robots = (0..world.robot_count())
            .filter(|&j| j != robot_index)
            .filter_map(|j| {
                let p = world.ground_truth_pose(j)?;
                let (v, _) = world.ground_truth_velocity(j)?;
                let (s, c) = p.yaw_rad.sin_cos();
                Some(MovingDisc {
                    x_m: p.x_m,
                    y_m: p.y_m,
                    vx_mps: v * c,
                    vy_mps: v * s,
                    radius_m,
                })
            })
            .collect();
        Self {
            pose,
            people,
            robots,
        }
    }
}

/// The truth the harness shares with the expert (written before every control cycle).
pub type SharedTruth = Arc<Mutex<TruthView>>;

/// Why an expert could not be made.
#[derive(Debug, thiserror::Error)]
pub enum ExpertError {
    #[error("invalid expert.{field} = {value}: {reason}")]
    Invalid {
        field: &'static str,
        value: String,
        reason: &'static str,
    },
}

/// The expert's parameters (TOML/JSON table `expert`); every field has a default.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ExpertConfig {
    /// Free space always kept between the robot's disc and walls, furniture and glass.
    pub static_margin_m: f64,
    /// Free space kept between the robot's disc and a person while the robot closes in.
    pub people_margin_m: f64,
    /// Free space kept between the robot's disc and another robot while closing in.
    pub robot_margin_m: f64,
    /// Clearance beyond the hard margin the expert likes to keep from static obstacles: the
    /// reference is pushed out to it where there is room, and rollouts closer pay for it.
    pub comfort_clearance_m: f64,
    /// Gap to a person or robot below which rollouts pay for coming closer.
    pub people_comfort_m: f64,
    /// Gap kept behind a person or robot walking ahead in the robot's lane.
    pub follow_gap_m: f64,
    /// How long each candidate command is rolled out.
    pub horizon_s: f64,
    /// How long a candidate is held before braking in the admissibility check.
    pub commit_s: f64,
    /// Pure-pursuit look-ahead at standstill.
    pub lookahead_m: f64,
    /// Extra look-ahead per m/s of speed.
    pub lookahead_per_speed_s: f64,
    /// Largest look-ahead.
    pub max_lookahead_m: f64,
    /// Speed is capped so that v² κ stays below this on the curvature ahead.
    pub max_lateral_accel_mps2: f64,
    /// Acceleration and deceleration of the command in normal driving (braking for safety
    /// uses the robot's limit).
    pub accel_mps2: f64,
    /// Rate of change of that acceleration.
    pub jerk_mps3: f64,
    /// Angular acceleration of the command in normal driving.
    pub turn_accel_radps2: f64,
    /// Rate of change of that angular acceleration.
    pub turn_jerk_radps3: f64,
    /// Time constant with which the command approaches its target speed.
    pub speed_time_constant_s: f64,
    /// Time constant with which the command approaches its target turn rate.
    pub turn_time_constant_s: f64,
    /// Turn on the spot when the look-ahead point is further off the heading than this.
    pub rotate_in_place_rad: f64,
    /// The goal (last path pose) counts as reached within this distance.
    pub goal_tolerance_m: f64,
    /// How far ahead the planner's path is checked for furniture and glass.
    pub block_scan_m: f64,
    /// How far short of the first blocked point of its path (where its disc would come within
    /// `static_margin_m`) the expert stops before an obstruction it cannot go round. Far
    /// enough that the camera still sees what blocks the way when the robot stands: closer
    /// than about 0.6 m a shut glass door's frame is out of the 70° view and the pane alone
    /// looks like open corridor, so frames labelled "stop" there teach nothing a memoryless
    /// network can see, and its stop is late (2026-11-28: 0.2 m had the networks touch the
    /// door in 4 of 5 unseen buildings).
    pub obstruction_stop_m: f64,
    /// A detour is taken only when at most this many times as long as the planner's way
    /// (plus `detour_extra_m`); otherwise the expert stops short and waits.
    pub detour_max_ratio: f64,
    /// See `detour_max_ratio`.
    pub detour_extra_m: f64,
    /// Least time between two detour searches.
    pub replan_period_s: f64,
    /// Another robot that has stood still (below 2 cm/s) this long is an obstruction to go
    /// round, not a robot to follow.
    pub standing_robot_s: f64,
    /// The command filter restarts from the measured motion when the robot's speed differs
    /// from the last command by more than this (a carry, a safety stop, another controller).
    pub motion_resync_mps: f64,
    /// The same for the turn rate. The recorder raises it above its steering-noise peak: a
    /// push the expert did not command must not become its command, or the label would follow
    /// the push instead of correcting it.
    pub motion_resync_radps: f64,
}

impl Default for ExpertConfig {
    fn default() -> Self {
        Self {
            static_margin_m: 0.06,
            people_margin_m: 0.12,
            robot_margin_m: 0.15,
            comfort_clearance_m: 0.25,
            people_comfort_m: 0.6,
            follow_gap_m: 0.8,
            horizon_s: 2.5,
            commit_s: 0.3,
            lookahead_m: 0.6,
            lookahead_per_speed_s: 0.8,
            max_lookahead_m: 1.4,
            max_lateral_accel_mps2: 0.3,
            accel_mps2: 0.4,
            jerk_mps3: 1.5,
            turn_accel_radps2: 1.2,
            turn_jerk_radps3: 6.0,
            speed_time_constant_s: 0.5,
            turn_time_constant_s: 0.3,
            rotate_in_place_rad: 1.0,
            goal_tolerance_m: 0.2,
            block_scan_m: 6.0,
            obstruction_stop_m: 0.8,
            detour_max_ratio: 3.0,
            detour_extra_m: 6.0,
            replan_period_s: 1.0,
            standing_robot_s: 2.0,
            motion_resync_mps: 0.08,
            motion_resync_radps: 0.25,
        }
    }
}

impl ExpertConfig {
    /// Checks ranges that serde cannot express.
    ///
    /// # Errors
    /// [`ExpertError::Invalid`] naming the first bad field and its value.
    pub fn validate(&self) -> Result<(), ExpertError> {
        let positive = [
            ("people_comfort_m", self.people_comfort_m),
            ("horizon_s", self.horizon_s),
            ("commit_s", self.commit_s),
            ("lookahead_m", self.lookahead_m),
            ("max_lookahead_m", self.max_lookahead_m),
            ("max_lateral_accel_mps2", self.max_lateral_accel_mps2),
            ("accel_mps2", self.accel_mps2),
            ("jerk_mps3", self.jerk_mps3),
            ("turn_accel_radps2", self.turn_accel_radps2),
            ("turn_jerk_radps3", self.turn_jerk_radps3),
            ("speed_time_constant_s", self.speed_time_constant_s),
            ("turn_time_constant_s", self.turn_time_constant_s),
            ("rotate_in_place_rad", self.rotate_in_place_rad),
            ("goal_tolerance_m", self.goal_tolerance_m),
            ("block_scan_m", self.block_scan_m),
            ("obstruction_stop_m", self.obstruction_stop_m),
            ("detour_max_ratio", self.detour_max_ratio),
            ("replan_period_s", self.replan_period_s),
            ("standing_robot_s", self.standing_robot_s),
            ("motion_resync_mps", self.motion_resync_mps),
            ("motion_resync_radps", self.motion_resync_radps),
        ];
        for (field, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return Err(ExpertError::Invalid {
                    field,
                    value: v.to_string(),
                    reason: "must be a positive, finite number",
                });
            }
        }
        let non_negative = [
            ("static_margin_m", self.static_margin_m),
            ("people_margin_m", self.people_margin_m),
            ("robot_margin_m", self.robot_margin_m),
            ("comfort_clearance_m", self.comfort_clearance_m),
            ("follow_gap_m", self.follow_gap_m),
            ("lookahead_per_speed_s", self.lookahead_per_speed_s),
            ("detour_extra_m", self.detour_extra_m),
        ];
        for (field, v) in non_negative {
            if !(v.is_finite() && v >= 0.0) {
                return Err(ExpertError::Invalid {
                    field,
                    value: v.to_string(),
                    reason: "must be a finite number >= 0",
                });
            }
        }
        if self.max_lookahead_m < self.lookahead_m {
            return Err(ExpertError::Invalid {
                field: "max_lookahead_m",
                value: self.max_lookahead_m.to_string(),
                reason: "must be at least expert.lookahead_m",
            });
        }
        if self.commit_s > self.horizon_s {
            return Err(ExpertError::Invalid {
                field: "commit_s",
                value: self.commit_s.to_string(),
                reason: "must not exceed expert.horizon_s",
            });
        }
        if self.horizon_s > 10.0 {
            return Err(ExpertError::Invalid {
                field: "horizon_s",
                value: self.horizon_s.to_string(),
                reason: "must be at most 10 s (the rollouts' cost grows with it)",
            });
        }
        Ok(())
    }
}

/// Walls, furniture and glass as the expert knows them.
#[derive(Debug, Clone)]
struct StaticTruth {
    geometry: GridGeometry,
    /// Distance field of the floor plan's walls (occupied and unknown cells, as the simulator's
    /// collision test takes them).
    walls: DistanceField,
    /// Distance field of the ground-truth grid (walls, furniture and glass): the detour search.
    all: DistanceField,
    /// Furniture and glass, exact.
    boxes: Vec<Obb>,
    /// A cell-centre distance overstates the true distance to an obstacle cell's square by at
    /// most one cell diagonal (half from each end).
    slack_m: f64,
}

impl StaticTruth {
    fn new(world: &World) -> Self {
        let geometry = *world.plan.geometry();
        let walls = DistanceField::compute(&world.plan, Sources::OccupiedOrUnknown);
        let all = DistanceField::compute(&world.ground_truth_grid(), Sources::OccupiedOrUnknown);
        let boxes = world
            .furniture
            .iter()
            .map(|f| f.shape)
            .chain(world.glass.iter().map(|g| g.shape))
            .collect();
        let slack_m = geometry.resolution_m() * std::f64::consts::SQRT_2;
        Self {
            geometry,
            walls,
            all,
            boxes,
            slack_m,
        }
    }

    /// A lower bound on the distance from (x, y) to the nearest wall.
    fn wall_clearance_m(&self, x_m: f64, y_m: f64) -> f64 {
        let (cx, cy) = self.geometry.world_to_cell(x_m, y_m);
        f64::from(self.walls.at(cx, cy)) - self.slack_m
    }

    /// Exact distance from (x, y) to the nearest piece of furniture or glass.
    fn box_clearance_m(&self, x_m: f64, y_m: f64) -> f64 {
        self.boxes
            .iter()
            .map(|b| b.distance(x_m, y_m))
            .fold(f64::INFINITY, f64::min)
    }

    /// A lower bound on the distance from (x, y) to the nearest static obstacle.
    fn clearance_m(&self, x_m: f64, y_m: f64) -> f64 {
        self.wall_clearance_m(x_m, y_m)
            .min(self.box_clearance_m(x_m, y_m))
    }

    /// As [`Self::clearance_m`], with only the boxes in `near` (indices) considered.
    fn clearance_near_m(&self, x_m: f64, y_m: f64, near: &[usize]) -> f64 {
        near.iter()
            .map(|&i| self.boxes[i].distance(x_m, y_m))
            .fold(self.wall_clearance_m(x_m, y_m), f64::min)
    }

    /// As [`Self::clearance_m`], with the `standing` robots as obstacles too.
    fn clearance_with_m(&self, standing: &[StandingDisc], x_m: f64, y_m: f64) -> f64 {
        self.clearance_m(x_m, y_m)
            .min(standing_clearance_m(standing, x_m, y_m))
    }

    /// Unit direction in which [`Self::clearance_with_m`] grows fastest (zero where it is
    /// flat).
    fn clearance_gradient(&self, standing: &[StandingDisc], x_m: f64, y_m: f64) -> (f64, f64) {
        let h = self.geometry.resolution_m();
        let clear = |x: f64, y: f64| self.clearance_with_m(standing, x, y);
        let gx = clear(x_m + h, y_m) - clear(x_m - h, y_m);
        let gy = clear(x_m, y_m + h) - clear(x_m, y_m - h);
        let n = gx.hypot(gy);
        if n < 1e-9 {
            (0.0, 0.0)
        } else {
            (gx / n, gy / n)
        }
    }
}

/// Another robot that has stood still long enough to be gone round (see
/// [`ExpertConfig::standing_robot_s`]), as the obstruction check and the detour search see it:
/// its disc grown so that keeping the static margin from the grown disc keeps the robot
/// margin, and a little more, from the robot itself.
#[derive(Debug, Clone, Copy, PartialEq)]
struct StandingDisc {
    x_m: f64,
    y_m: f64,
    radius_m: f64,
}

/// Below this speed another robot counts as standing still.
const STILL_MPS: f64 = 0.02;
/// Room beyond the robot margin that a detour keeps from a standing robot, so that passing
/// it does not set off the rollouts' closing-in check.
const STANDING_EXTRA_M: f64 = 0.1;

/// Distance from (x, y) to the nearest standing robot's grown disc (infinite when none).
fn standing_clearance_m(standing: &[StandingDisc], x_m: f64, y_m: f64) -> f64 {
    standing
        .iter()
        .map(|d| (d.x_m - x_m).hypot(d.y_m - y_m) - d.radius_m)
        .fold(f64::INFINITY, f64::min)
}

/// Most cells one detour search may expand (a bound on its cost, about 10 ms).
const MAX_EXPANSIONS: u32 = 120_000;
/// How far the detour's goal may be moved off the planner's path to a cell with clearance.
const GOAL_SHIFT_M: f64 = 0.5;
/// The search window: the box around start and goal grown by this much.
const SEARCH_WINDOW_M: f64 = 5.0;
/// Extra cost per metre (relative) of running with no more than the hard margin to spare;
/// falls linearly to zero at [`PREFERRED_EXTRA_M`] more clearance.
const CLEARANCE_COST: f32 = 3.0;
const PREFERRED_EXTRA_M: f64 = 0.5;

/// Reusable buffers of the 8-connected A* on the ground-truth grid.
#[derive(Debug, Default)]
struct Search {
    generation: u32,
    seen: Vec<u32>,
    closed: Vec<u32>,
    g: Vec<f32>,
    parent: Vec<u32>,
    open: BinaryHeap<MinCost<f32, u32>>,
}

impl Search {
    /// The cheapest 8-connected way (map-frame cell centres) from `start` to `goal` through
    /// cells whose clearance (from the ground truth and the `standing` robots) is at least
    /// `min_clear_m`, preferring `PREFERRED_EXTRA_M` more; None when there is none within the
    /// window and the expansion budget. A start cell below the clearance may be left towards
    /// more clearance (the robot stands where it stands).
    fn plan(
        &mut self,
        truth: &StaticTruth,
        standing: &[StandingDisc],
        start: (f64, f64),
        goal: (f64, f64),
        min_clear_m: f64,
    ) -> Option<Vec<(f64, f64)>> {
        let geo = &truth.geometry;
        let (w, h) = (i64::from(geo.width_cells()), i64::from(geo.height_cells()));
        let n = truth.all.as_slice().len();
        if self.g.len() != n {
            self.seen = vec![0; n];
            self.closed = vec![0; n];
            self.g = vec![f32::INFINITY; n];
            self.parent = vec![0; n];
            self.generation = 0;
        }
        self.generation = self.generation.wrapping_add(1);
        if self.generation == 0 {
            self.seen.fill(0);
            self.closed.fill(0);
            self.generation = 1;
        }
        let gen = self.generation;
        let (sx, sy) = geo.world_to_cell(start.0, start.1);
        let (tx, ty) = geo.world_to_cell(goal.0, goal.1);
        let res = geo.resolution_m();
        let wu = usize::try_from(w).ok()?;
        let clear = |i: usize| {
            let c = f64::from(truth.all.as_slice()[i]) - truth.slack_m;
            if standing.is_empty() {
                return c;
            }
            #[allow(clippy::cast_possible_wrap)]
            let (x, y) = geo.cell_to_world((i % wu) as i64, (i / wu) as i64);
            c.min(standing_clearance_m(standing, x, y))
        };
        let si = geo.checked_index(sx, sy)?;
        // The planner's path may graze a wall where it rejoins: aim at the nearest cell
        // nearby that keeps the clearance instead.
        #[allow(clippy::cast_possible_truncation)]
        let reach = (GOAL_SHIFT_M / res).ceil() as i64;
        let (tx, ty) = (-reach..=reach)
            .flat_map(|dy| (-reach..=reach).map(move |dx| (dx, dy)))
            .filter(|&(dx, dy)| dx * dx + dy * dy <= reach * reach)
            .filter_map(|(dx, dy)| {
                let i = geo.checked_index(tx + dx, ty + dy)?;
                (clear(i) >= min_clear_m).then_some((dx * dx + dy * dy, tx + dx, ty + dy))
            })
            .min()
            .map(|(_, x, y)| (x, y))?;
        let ti = geo.checked_index(tx, ty)?;
        #[allow(clippy::cast_possible_truncation)]
        let window = (SEARCH_WINDOW_M / res).ceil() as i64;
        let (x0, x1) = (
            (sx.min(tx) - window).max(0),
            (sx.max(tx) + window).min(w - 1),
        );
        let (y0, y1) = (
            (sy.min(ty) - window).max(0),
            (sy.max(ty) + window).min(h - 1),
        );
        #[allow(clippy::cast_precision_loss, clippy::cast_possible_truncation)]
        let octile = |x: i64, y: i64| -> f32 {
            let (dx, dy) = ((x - tx).abs() as f32, (y - ty).abs() as f32);
            dx.max(dy) + (std::f32::consts::SQRT_2 - 1.0) * dx.min(dy)
        };
        #[allow(clippy::cast_possible_truncation)]
        let penalty = |c: f64| -> f32 {
            let short = ((min_clear_m + PREFERRED_EXTRA_M - c) / PREFERRED_EXTRA_M).clamp(0.0, 1.0);
            1.0 + CLEARANCE_COST * short as f32
        };
        self.open.clear();
        self.g[si] = 0.0;
        self.seen[si] = gen;
        #[allow(clippy::cast_possible_truncation)]
        self.open.push(MinCost(octile(sx, sy), si as u32));
        let mut expanded = 0u32;
        while let Some(MinCost(_, i)) = self.open.pop() {
            let i = i as usize;
            if self.closed[i] == gen {
                continue;
            }
            self.closed[i] = gen;
            if i == ti {
                let mut cells = vec![ti];
                let mut k = ti;
                while k != si {
                    k = self.parent[k] as usize;
                    cells.push(k);
                }
                cells.reverse();
                #[allow(clippy::cast_possible_wrap)]
                return Some(
                    cells
                        .into_iter()
                        .map(|c| geo.cell_to_world((c % wu) as i64, (c / wu) as i64))
                        .collect(),
                );
            }
            expanded += 1;
            if expanded > MAX_EXPANSIONS {
                return None;
            }
            #[allow(clippy::cast_possible_wrap)]
            let (x, y) = ((i % wu) as i64, (i / wu) as i64);
            let ci = clear(i);
            for (dx, dy) in NEIGHBOURS_8 {
                let (nx, ny) = (x + dx, y + dy);
                if nx < x0 || nx > x1 || ny < y0 || ny > y1 {
                    continue;
                }
                #[allow(clippy::cast_sign_loss, clippy::cast_possible_truncation)]
                let j = (ny as usize) * wu + nx as usize;
                if self.closed[j] == gen {
                    continue;
                }
                let cj = clear(j);
                // Below the clearance only to climb out of where the robot already stands.
                if cj < min_clear_m && !(ci < min_clear_m && cj >= ci) {
                    continue;
                }
                let step = if dx != 0 && dy != 0 {
                    std::f32::consts::SQRT_2
                } else {
                    1.0
                };
                let ng = self.g[i] + step * penalty(cj);
                if self.seen[j] != gen || ng < self.g[j] {
                    self.seen[j] = gen;
                    self.g[j] = ng;
                    #[allow(clippy::cast_possible_truncation)]
                    {
                        self.parent[j] = i as u32;
                        self.open.push(MinCost(ng + octile(nx, ny), j as u32));
                    }
                }
            }
        }
        None
    }
}

/// A detour around an obstruction on the planner's path, kept between cycles.
#[derive(Debug, Clone)]
struct Detour {
    points: Vec<(f64, f64)>,
    /// Where it meets the planner's path again.
    rejoin: (f64, f64),
}

/// The command and its rates of change: the state of the command filter.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct Motion {
    v_mps: f64,
    accel_mps2: f64,
    omega_radps: f64,
    turn_accel_radps2: f64,
}

/// How fast the command filter may change the command.
#[derive(Debug, Clone, Copy)]
struct FilterLimits {
    accel_mps2: f64,
    decel_mps2: f64,
    jerk_mps3: f64,
    turn_accel_radps2: f64,
    turn_jerk_radps3: f64,
    speed_tau_s: f64,
    turn_tau_s: f64,
    max_speed_mps: f64,
    max_turn_radps: f64,
}

/// One axis of the command filter: moves `x` (rate `r`) towards `target` with the rate
/// proportional to the error (time constant `tau`), bounded by `r_lo..r_hi`, changing at most
/// `jerk` per second, never overshooting.
#[allow(clippy::too_many_arguments)]
fn filter_axis(
    x: f64,
    r: f64,
    target: f64,
    tau: f64,
    r_lo: f64,
    r_hi: f64,
    jerk: f64,
    dt: f64,
) -> (f64, f64) {
    let wanted = ((target - x) / tau).clamp(r_lo, r_hi);
    let rate = r + (wanted - r).clamp(-jerk * dt, jerk * dt);
    let next = x + rate * dt;
    if (target - x) * (target - next) <= 0.0 {
        (target, 0.0)
    } else {
        (next, rate)
    }
}

impl FilterLimits {
    fn step(&self, m: Motion, v_target: f64, omega_target: f64, dt: f64) -> Motion {
        let (v, a) = filter_axis(
            m.v_mps,
            m.accel_mps2,
            v_target,
            self.speed_tau_s,
            -self.decel_mps2,
            self.accel_mps2,
            self.jerk_mps3,
            dt,
        );
        let (w, al) = filter_axis(
            m.omega_radps,
            m.turn_accel_radps2,
            omega_target,
            self.turn_tau_s,
            -self.turn_accel_radps2,
            self.turn_accel_radps2,
            self.turn_jerk_radps3,
            dt,
        );
        let vc = v.clamp(0.0, self.max_speed_mps);
        let wc = w.clamp(-self.max_turn_radps, self.max_turn_radps);
        Motion {
            v_mps: vc,
            accel_mps2: if vc == v { a } else { 0.0 },
            omega_radps: wc,
            turn_accel_radps2: if wc == w { al } else { 0.0 },
        }
    }
}

/// A person or robot as the rollouts see it.
#[derive(Debug, Clone, Copy)]
struct Mover {
    disc: MovingDisc,
    /// A robot that has stood still long enough to be gone round, not followed.
    standing: bool,
    /// Centre distance below which closing in is not admissible.
    hard_m: f64,
    /// Centre distance below which rollouts pay.
    soft_m: f64,
}

impl Mover {
    fn at(&self, t_s: f64) -> (f64, f64) {
        (
            self.disc.x_m + self.disc.vx_mps * t_s,
            self.disc.y_m + self.disc.vy_mps * t_s,
        )
    }
}

/// How the expert gives way to someone coming the other way.
#[derive(Debug, Clone, Copy)]
struct GiveWay {
    /// Where to wait before a narrow passage: distance along the reference and the spot.
    hold: Option<(f64, (f64, f64))>,
    /// The side it passes them on (+1 left, -1 right of the reference).
    side: f64,
    /// When they will be level with the spot.
    eta_s: Option<f64>,
}

/// A candidate's rollout.
#[derive(Debug, Clone, Copy)]
struct Rollout {
    /// Keeps the static margin while committed and braking.
    static_ok: bool,
    /// Keeps the people/robot margin while closing in, committed and braking.
    movers_ok: bool,
    /// Smallest centre distance minus hard distance to any mover over the whole horizon.
    mover_slack_m: f64,
    soft_cost: f64,
}

/// Weights of the candidate cost (dimensionless terms).
const W_SPEED: f64 = 1.0;
const W_TURN: f64 = 0.6;
const W_CHANGE: f64 = 0.3;
const W_PEOPLE: f64 = 3.0;
const W_STATIC: f64 = 1.0;
/// Extra cost of a candidate that brakes at the robot's limit rather than comfortably.
const W_HARD_BRAKE: f64 = 0.5;
/// Offsets of the candidate turn rates from the nominal one.
const TURN_OFFSETS_RADPS: [f64; 15] = [
    0.0, 0.1, -0.1, 0.25, -0.25, 0.45, -0.45, 0.7, -0.7, 1.0, -1.0, 1.4, -1.4, 2.0, -2.0,
];
/// Candidate speeds are these fractions of the top speed (those up to the nominal one).
const SPEED_LEVELS: usize = 8;
/// Projection onto the reference only looks this far along it (the reference starts at the
/// robot; a later stretch passing close by must not capture it).
const PROJECTION_WINDOW_M: f64 = 2.0;
/// The reference is kept this long (enough for look-ahead, curvature and obstruction checks).
const REFERENCE_M: f64 = 20.0;
/// Spacing of the obstruction check along the path.
const SCAN_STEP_M: f64 = 0.1;
/// The reference is pushed off obstacles over this first stretch.
const PUSH_M: f64 = 4.0;
/// Within this distance of the goal the expert heads straight for it (when nothing is in the
/// way) ...
const GOAL_APPROACH_M: f64 = 1.2;
/// ... and turns on the spot first when it is further off the heading than this.
const GOAL_ROTATE_RAD: f64 = 0.8;
/// How far along the reference people and robots coming the other way are looked for ...
const YIELD_LOOK_M: f64 = 10.0;
/// ... within this much more than the hard distance of it ...
const LANE_EXTRA_M: f64 = 0.3;
/// ... and coming at least this fast.
const ONCOMING_MPS: f64 = 0.05;
/// Extra width a passage needs to meet someone in.
const MEET_EXTRA_M: f64 = 0.1;
/// A narrow passage starting closer than this has been entered: go on through.
const NARROW_COMMITTED_M: f64 = 0.3;
/// Lateral room beyond the hard distance kept when passing someone coming the other way.
const PASS_EXTRA_M: f64 = 0.15;
/// The sideways shift for someone coming the other way builds up over this distance.
const SHIFT_RAMP_M: f64 = 1.5;
/// Speed at which the robot is assumed to get through a narrow passage (with its braking and
/// accelerating) when judging whether it can before someone coming the other way gets there.
const THROUGH_SPEED_MPS: f64 = 0.45;
/// ... and the time it must be through before they get there.
const THROUGH_MARGIN_S: f64 = 3.0;
/// Where to hold before a narrow passage: room for whoever comes out to get round.
const HOLD_BACK_M: f64 = 1.0;
/// The robot aims to reach the spot where it waits for someone coming through a narrow
/// passage this long before they get there ...
const HOLD_EARLY_S: f64 = 2.0;
/// ... and creeps there at least this fast.
const HOLD_CREEP_MPS: f64 = 0.1;
/// How far short of where it waits for someone coming through a passage the robot stops.
const HOLD_SHORT_M: f64 = 0.2;
/// The spot to wait at for someone coming through a narrow passage counts as reached this
/// close.
const HOLD_REACHED_M: f64 = 0.1;
/// A detour is kept while the robot stays this close to it.
const DETOUR_KEEP_M: f64 = 0.8;

/// The privileged expert controller (see the module docs).
pub struct Expert {
    config: ExpertConfig,
    truth: SharedTruth,
    statics: StaticTruth,
    radius_m: f64,
    search: Search,
    motion: Motion,
    last_target: (f64, f64),
    rotating: bool,
    /// Waiting before a narrow passage for someone coming the other way (last cycle).
    holding: bool,
    /// The side (+1 left, -1 right) on which someone coming the other way is passed.
    pass_side: Option<f64>,
    detour: Option<Detour>,
    last_search_s: Option<f64>,
    clock_s: f64,
    last_pose: Option<Pose2D>,
    view: TruthView,
    path: Vec<(f64, f64)>,
    reference: Vec<(f64, f64)>,
    movers: Vec<Mover>,
    near_boxes: Vec<usize>,
    /// Since when each other robot (by its index in the truth) has stood still.
    still_since_s: Vec<Option<f64>>,
    /// The other robots that have stood still for `standing_robot_s` (this cycle).
    standing: Vec<StandingDisc>,
}

impl std::fmt::Debug for Expert {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Expert")
            .field("config", &self.config)
            .field("radius_m", &self.radius_m)
            .field("motion", &self.motion)
            .field("detour", &self.detour.as_ref().map(|d| d.points.len()))
            .finish_non_exhaustive()
    }
}

/// Where a point projects onto a polyline: segment index, fraction, distance.
fn project(points: &[(f64, f64)], p: (f64, f64), window_m: f64) -> (usize, f64, f64) {
    let mut best = (0, 0.0, f64::INFINITY);
    let mut along = 0.0;
    for (i, w) in points.windows(2).enumerate() {
        if along > window_m {
            break;
        }
        let (a, b) = (w[0], w[1]);
        let (ex, ey) = (b.0 - a.0, b.1 - a.1);
        let len2 = ex * ex + ey * ey;
        let t = if len2 < 1e-18 {
            0.0
        } else {
            (((p.0 - a.0) * ex + (p.1 - a.1) * ey) / len2).clamp(0.0, 1.0)
        };
        let d = (a.0 + t * ex - p.0).hypot(a.1 + t * ey - p.1);
        if d < best.2 - 1e-12 {
            best = (i, t, d);
        }
        along += len2.sqrt();
    }
    if points.len() == 1 {
        best.2 = (points[0].0 - p.0).hypot(points[0].1 - p.1);
    }
    best
}

/// The point `distance_m` along a polyline from its start (its end when it is shorter).
fn point_along(points: &[(f64, f64)], distance_m: f64) -> (f64, f64) {
    let mut left = distance_m;
    for w in points.windows(2) {
        let len = (w[1].0 - w[0].0).hypot(w[1].1 - w[0].1);
        if len >= left && len > 0.0 {
            let u = left / len;
            return (
                w[0].0 + u * (w[1].0 - w[0].0),
                w[0].1 + u * (w[1].1 - w[0].1),
            );
        }
        left -= len;
    }
    points.last().copied().unwrap_or_default()
}

fn polyline_length(points: &[(f64, f64)]) -> f64 {
    points
        .windows(2)
        .map(|w| (w[1].0 - w[0].0).hypot(w[1].1 - w[0].1))
        .sum()
}

impl Expert {
    /// An expert for robot 0's kind of base in `world` (its radius), knowing the world's
    /// walls, furniture and glass; it reads the moving truth from `truth` every cycle.
    ///
    /// # Errors
    /// [`ExpertError::Invalid`] for a bad configuration.
    pub fn new(
        world: &World,
        config: ExpertConfig,
        truth: SharedTruth,
    ) -> Result<Self, ExpertError> {
        config.validate()?;
        let radius_m = world.config.base.radius_m;
        if !(radius_m.is_finite() && radius_m > 0.0) {
            return Err(ExpertError::Invalid {
                field: "robot radius (sim base.radius_m)",
                value: radius_m.to_string(),
                reason: "must be a positive, finite number",
            });
        }
        Ok(Self {
            config,
            truth,
            statics: StaticTruth::new(world),
            radius_m,
            search: Search::default(),
            motion: Motion::default(),
            last_target: (0.0, 0.0),
            rotating: false,
            holding: false,
            pass_side: None,
            detour: None,
            last_search_s: None,
            clock_s: 0.0,
            last_pose: None,
            view: TruthView::default(),
            path: Vec::new(),
            reference: Vec::new(),
            movers: Vec::new(),
            near_boxes: Vec::new(),
            still_since_s: Vec::new(),
            standing: Vec::new(),
        })
    }

    #[must_use]
    pub fn config(&self) -> &ExpertConfig {
        &self.config
    }

    /// Whether a detour around an obstruction on the planner's path is being followed.
    #[must_use]
    pub fn on_detour(&self) -> bool {
        self.detour.is_some()
    }

    /// The reference followed in the last cycle (map frame), for tests and plots.
    #[must_use]
    pub fn reference(&self) -> &[(f64, f64)] {
        &self.reference
    }

    fn filter_limits(&self, limits: &Limits) -> FilterLimits {
        let c = &self.config;
        FilterLimits {
            accel_mps2: c.accel_mps2.min(limits.max_accel_mps2),
            decel_mps2: c.accel_mps2.min(limits.max_accel_mps2),
            jerk_mps3: c.jerk_mps3,
            turn_accel_radps2: c.turn_accel_radps2.min(limits.max_turn_accel_radps2),
            turn_jerk_radps3: c.turn_jerk_radps3,
            speed_tau_s: c.speed_time_constant_s,
            turn_tau_s: c.turn_time_constant_s,
            max_speed_mps: limits.max_speed_mps,
            max_turn_radps: limits.max_turn_radps,
        }
    }

    /// Braking at the robot's limits (no jerk bound): for stops that safety needs.
    fn hard_limits(limits: &Limits, soft: &FilterLimits) -> FilterLimits {
        FilterLimits {
            decel_mps2: limits.max_accel_mps2,
            jerk_mps3: 1e3,
            turn_accel_radps2: limits.max_turn_accel_radps2,
            turn_jerk_radps3: 1e3,
            speed_tau_s: 1e-3,
            ..*soft
        }
    }

    /// Brings the filter state in line with what the robot really did in the last cycle
    /// (the supervisor may have stopped it, a collision or a carry may have).
    fn sync_motion(&mut self, input: &ControlInput<'_>) {
        let pose = self.view.pose;
        if let Some(last) = self.last_pose {
            let dt = input.dt_s;
            let (dx, dy) = (pose.x_m - last.x_m, pose.y_m - last.y_m);
            let (s, c) = last.yaw_rad.sin_cos();
            let v = (dx * c + dy * s) / dt;
            let w = normalize_angle(pose.yaw_rad - last.yaw_rad) / dt;
            let off_v = (v - self.motion.v_mps).abs() > self.config.motion_resync_mps;
            let off_w = (w - self.motion.omega_radps).abs() > self.config.motion_resync_radps;
            if off_v || off_w {
                // A jump (a carry, or cycles without this controller) shows in odometry as
                // well; trust the measured motion only when odometry roughly agrees.
                let (v, w) = if (v - input.v_mps).abs() < 0.3 {
                    (v, w)
                } else {
                    (input.v_mps, input.omega_radps)
                };
                self.motion = Motion {
                    v_mps: v.max(0.0),
                    accel_mps2: 0.0,
                    omega_radps: w,
                    turn_accel_radps2: 0.0,
                };
            }
        } else {
            self.motion = Motion {
                v_mps: input.v_mps.max(0.0),
                accel_mps2: 0.0,
                omega_radps: input.omega_radps,
                turn_accel_radps2: 0.0,
            };
        }
        self.last_pose = Some(pose);
    }

    /// One filter step towards (v, ω) = target; the command this cycle.
    fn drive(&mut self, limits: &Limits, f: &FilterLimits, target: (f64, f64), dt: f64) -> Control {
        self.motion = f.step(self.motion, target.0, target.1, dt);
        self.last_target = target;
        Control::from_physical(self.motion.v_mps, self.motion.omega_radps, limits)
    }

    /// Comes to a stop (goal reached, the planner says stop). Comfortably: the goal is
    /// approached slowly, and on a sudden stop the supervisor brakes at its own rate anyway.
    fn stop(&mut self, limits: &Limits, dt: f64) -> Control {
        let soft = self.filter_limits(limits);
        self.drive(limits, &soft, (0.0, 0.0), dt)
    }

    /// Notes which other robots stand still and since when, and lists those that have stood
    /// for `standing_robot_s` as obstructions.
    fn track_standing(&mut self) {
        self.still_since_s.resize(self.view.robots.len(), None);
        for (d, since) in self.view.robots.iter().zip(&mut self.still_since_s) {
            if d.vx_mps.hypot(d.vy_mps) >= STILL_MPS {
                *since = None;
            } else if since.is_none() {
                *since = Some(self.clock_s);
            }
        }
        let grow_m =
            (self.config.robot_margin_m - self.config.static_margin_m + STANDING_EXTRA_M).max(0.0);
        self.standing = (0..self.view.robots.len())
            .filter(|&i| self.has_stood(i))
            .map(|i| {
                let d = self.view.robots[i];
                StandingDisc {
                    x_m: d.x_m,
                    y_m: d.y_m,
                    radius_m: d.radius_m + grow_m,
                }
            })
            .collect();
    }

    /// Whether other robot `i` (its index in the truth) has stood still for
    /// `standing_robot_s`.
    fn has_stood(&self, i: usize) -> bool {
        self.still_since_s
            .get(i)
            .copied()
            .flatten()
            .is_some_and(|t| self.clock_s - t >= self.config.standing_robot_s)
    }

    /// Builds `self.reference` from the planner's path in `self.path`; returns the distance
    /// along it to an obstruction the robot must stop short of, if any.
    fn build_reference(&mut self, pose: Pose2D) -> Option<f64> {
        let here = (pose.x_m, pose.y_m);
        let (seg, t, _) = project(&self.path, here, PROJECTION_WINDOW_M);
        self.reference.clear();
        let mut ahead: Vec<(f64, f64)> = Vec::with_capacity(self.path.len() - seg + 1);
        if self.path.len() == 1 {
            ahead.push(self.path[0]);
        } else {
            let (a, b) = (self.path[seg], self.path[seg + 1]);
            ahead.push((a.0 + t * (b.0 - a.0), a.1 + t * (b.1 - a.1)));
            let mut along = 0.0;
            for &p in &self.path[seg + 1..] {
                let last = ahead[ahead.len() - 1];
                along += (p.0 - last.0).hypot(p.1 - last.1);
                ahead.push(p);
                if along > REFERENCE_M {
                    break;
                }
            }
        }
        let r = self.radius_m;
        let hard = self.config.static_margin_m;
        let obstruction_clearance_m = |x: f64, y: f64| {
            self.statics
                .box_clearance_m(x, y)
                .min(standing_clearance_m(&self.standing, x, y))
        };
        let blocked = |x: f64, y: f64| obstruction_clearance_m(x, y) - r < hard;
        // The first obstructed point within the scan, and where the path is clear again.
        let mut obstruction: Option<f64> = None;
        let mut rejoin: Option<(f64, usize)> = None;
        let mut clear_run_m = 0.0;
        let mut s = 0.0;
        'scan: for (i, w) in ahead.windows(2).enumerate() {
            let len = (w[1].0 - w[0].0).hypot(w[1].1 - w[0].1);
            let n = (len / SCAN_STEP_M).ceil().max(1.0);
            let mut k = 0.0;
            while k < n {
                k += 1.0;
                let u = k / n;
                let (x, y) = (
                    w[0].0 + u * (w[1].0 - w[0].0),
                    w[0].1 + u * (w[1].1 - w[0].1),
                );
                let sk = s + u * len;
                match obstruction {
                    None => {
                        if sk > self.config.block_scan_m {
                            break 'scan;
                        }
                        if blocked(x, y) {
                            obstruction = Some(sk);
                        }
                    }
                    Some(_) => {
                        // Clear again once it keeps the margin with room to spare for a while.
                        if obstruction_clearance_m(x, y) - r
                            >= hard + self.config.comfort_clearance_m
                        {
                            clear_run_m += len / n;
                            if clear_run_m >= 0.6 {
                                rejoin = Some((sk, i + 1));
                                break 'scan;
                            }
                        } else {
                            clear_run_m = 0.0;
                        }
                    }
                }
            }
            s += len;
        }
        if obstruction.is_some() && rejoin.is_none() {
            // Blocked to the end of the known path: the end itself may still be reachable.
            if let Some(&(x, y)) = ahead.last() {
                if !blocked(x, y) && ahead.len() > 1 {
                    rejoin = Some((s, ahead.len() - 1));
                }
            }
        }
        let Some(block_s) = obstruction else {
            self.detour = None;
            self.reference.extend_from_slice(&ahead);
            self.push_reference();
            return None;
        };
        // Keep the detour while it still leads to the path and the robot is on it.
        let keep = self.detour.as_ref().is_some_and(|d| {
            let near_path = project(&ahead, d.rejoin, f64::INFINITY).2 < 0.5;
            let on_it = project(&d.points, here, f64::INFINITY).2 < DETOUR_KEEP_M;
            near_path && on_it
        });
        if !keep {
            self.detour = None;
            let due = self
                .last_search_s
                .is_none_or(|t| self.clock_s - t >= self.config.replan_period_s);
            if let (true, Some((rejoin_s, idx))) = (due, rejoin) {
                self.last_search_s = Some(self.clock_s);
                let goal = ahead[idx];
                if let Some(points) =
                    self.search
                        .plan(&self.statics, &self.standing, here, goal, r + hard)
                {
                    let points = smooth_detour(&self.statics, &self.standing, points, r + hard);
                    let len = polyline_length(&points);
                    let limit =
                        self.config.detour_max_ratio * rejoin_s + self.config.detour_extra_m;
                    if len <= limit {
                        self.detour = Some(Detour {
                            points,
                            rejoin: goal,
                        });
                    } else {
                        tracing::debug!(len, limit, "detour too long; stopping short");
                    }
                } else {
                    tracing::debug!(?here, ?goal, "no detour; stopping short");
                }
            }
        }
        match &self.detour {
            Some(d) => {
                let (seg, t, _) = project(&d.points, here, f64::INFINITY);
                if d.points.len() > 1 {
                    let (a, b) = (d.points[seg], d.points[seg + 1]);
                    self.reference
                        .push((a.0 + t * (b.0 - a.0), a.1 + t * (b.1 - a.1)));
                    self.reference.extend_from_slice(&d.points[seg + 1..]);
                } else {
                    self.reference.extend_from_slice(&d.points);
                }
                // Back on the planner's path after the point nearest to the rejoin point.
                let (jseg, _, _) = project(&ahead, d.rejoin, f64::INFINITY);
                if jseg + 1 < ahead.len() {
                    self.reference.extend_from_slice(&ahead[jseg + 1..]);
                }
                self.push_reference();
                None
            }
            None => {
                self.reference.extend_from_slice(&ahead);
                self.push_reference();
                Some(block_s)
            }
        }
    }

    /// Moves the points of the reference's first stretch that run close to walls, furniture,
    /// glass or standing robots out along the clearance gradient, where that gains clearance.
    fn push_reference(&mut self) {
        let want = self.radius_m + self.config.static_margin_m + self.config.comfort_clearance_m;
        let mut along = 0.0;
        for i in 1..self.reference.len() {
            let prev = self.reference[i - 1];
            let mut p = self.reference[i];
            along += (p.0 - prev.0).hypot(p.1 - prev.1);
            if along > PUSH_M {
                break;
            }
            for _ in 0..3 {
                let c = self.statics.clearance_with_m(&self.standing, p.0, p.1);
                if c >= want {
                    break;
                }
                let (gx, gy) = self.statics.clearance_gradient(&self.standing, p.0, p.1);
                let step = (want - c).min(0.1);
                let q = (p.0 + gx * step, p.1 + gy * step);
                if self.statics.clearance_with_m(&self.standing, q.0, q.1) > c {
                    p = q;
                } else {
                    break;
                }
            }
            self.reference[i] = p;
        }
    }

    /// The pure-pursuit command on the reference with its speed caps.
    fn nominal(&mut self, pose: Pose2D, limits: &Limits, stop_at_m: Option<f64>) -> (f64, f64) {
        let c = &self.config;
        let here = (pose.x_m, pose.y_m);
        let (seg, t, _) = project(&self.reference, here, PROJECTION_WINDOW_M);
        // The reference from the robot's foot point on.
        let mut from: Vec<(f64, f64)> = Vec::with_capacity(self.reference.len() - seg + 1);
        if self.reference.len() > 1 {
            let (a, b) = (self.reference[seg], self.reference[seg + 1]);
            from.push((a.0 + t * (b.0 - a.0), a.1 + t * (b.1 - a.1)));
            from.extend_from_slice(&self.reference[seg + 1..]);
        } else {
            from.extend_from_slice(&self.reference);
        }
        let give_way = self.give_way(here, &mut from);
        let hold = give_way.and_then(|g| g.hold);
        self.holding = hold.is_some();
        self.pass_side = give_way.map(|g| g.side);
        let v_now = self.motion.v_mps;
        let lookahead_m = (c.lookahead_m + c.lookahead_per_speed_s * v_now).min(c.max_lookahead_m);
        let goal = from.last().copied().unwrap_or(here);
        let near = |p: (f64, f64)| {
            (p.0 - here.0).hypot(p.1 - here.1) < GOAL_APPROACH_M && self.segment_clear(here, p)
        };
        // Close to the goal, head straight for it: the planner's last metre, bound by its
        // turning radius, may loop round the goal, and pursuing a loop that tight orbits it.
        // The same for the spot where it waits for someone to come through a narrow passage.
        let aim = match hold {
            Some((_, q)) if near(q) => Some((q, HOLD_REACHED_M)),
            _ if near(goal) => Some((goal, c.goal_tolerance_m)),
            _ => None,
        };
        let target = aim.map_or_else(|| point_along(&from, lookahead_m), |a| a.0);
        let (tx, ty) = to_robot_frame(&pose, target);
        let alpha = ty.atan2(tx);
        let remaining_m = if aim.is_some() {
            tx.hypot(ty)
        } else {
            polyline_length(&from)
        };
        let arrived_m = aim.map_or(c.goal_tolerance_m, |a| a.1);
        if remaining_m <= arrived_m {
            // Waiting at the spot (the goal itself is handled before).
            return (0.0, 0.0);
        }
        let rotate_rad = if aim.is_some() {
            GOAL_ROTATE_RAD.min(c.rotate_in_place_rad)
        } else {
            c.rotate_in_place_rad
        };
        // Hysteresis, so that the robot does not alternate between turning and driving.
        if alpha.abs() > rotate_rad {
            self.rotating = true;
        } else if alpha.abs() < 0.35 * rotate_rad {
            self.rotating = false;
        }
        if self.rotating {
            let w = (1.5 * alpha).clamp(-limits.max_turn_radps, limits.max_turn_radps);
            return (0.0, w);
        }
        let kappa = pursuit_curvature(tx, ty);
        // The sharpest bend soon: slow before it arrives.
        let mut kappa_ahead = kappa.abs();
        let mut s = lookahead_m;
        while s < lookahead_m + 1.5 && s < remaining_m {
            s += 0.25;
            let p = point_along(&from, s);
            let (px, py) = to_robot_frame(&pose, p);
            kappa_ahead = kappa_ahead.max(pursuit_curvature(px, py).abs());
        }
        let brake = 0.8 * c.accel_mps2.min(limits.max_accel_mps2);
        let mut v = limits
            .max_speed_mps
            .min((c.max_lateral_accel_mps2 / kappa_ahead.max(1e-9)).sqrt())
            .min(limits.max_turn_radps / kappa.abs().max(1e-9))
            .min((2.0 * brake * (remaining_m - 0.5 * arrived_m).max(0.0)).sqrt());
        if let (Some((h, _)), Some(eta_s)) = (hold, give_way.and_then(|g| g.eta_s)) {
            // No hurry to wait: arrive a little before they do, so that the wait is short and
            // the robot keeps making way.
            let spare_s = (eta_s - HOLD_EARLY_S).max(0.5);
            v = v.min((h / spare_s).max(HOLD_CREEP_MPS));
        }
        let hold_m = if aim.is_some() {
            None
        } else {
            hold.map(|h| h.0)
        };
        let stops = [
            stop_at_m.map(|s| s - c.obstruction_stop_m),
            hold_m.map(|h| h - HOLD_SHORT_M),
        ];
        for stop_m in stops.into_iter().flatten() {
            v = v.min((2.0 * brake * stop_m.max(0.0)).sqrt());
        }
        // Follow whoever walks ahead in the robot's lane.
        let (sh, ch) = pose.yaw_rad.sin_cos();
        for m in self.movers.iter().filter(|m| !m.standing) {
            let d = m.disc;
            let (px, py) = to_robot_frame(&pose, (d.x_m, d.y_m));
            let radii = self.radius_m + d.radius_m;
            if px <= 0.0 || py.abs() > radii + c.people_margin_m + 0.1 {
                continue;
            }
            let gap = px.hypot(py) - radii;
            let along = d.vx_mps * ch + d.vy_mps * sh;
            let cap = along.max(0.0) + 0.5 * (gap - c.follow_gap_m);
            let stoppable =
                along.max(0.0) + (2.0 * brake * (gap - c.people_margin_m).max(0.0)).sqrt();
            v = v.min(cap.max(0.0)).min(stoppable);
        }
        let v = v.max(0.0);
        (
            v,
            (v * kappa).clamp(-limits.max_turn_radps, limits.max_turn_radps),
        )
    }

    /// Gives way to the nearest person or robot coming the other way along `from` (the
    /// reference from the robot on): shifts the reference to the side away from their line
    /// where there is room, so that they pass without having to step round the robot, and
    /// returns where to hold (distance along `from`, and the point) before a passage too
    /// narrow to meet in that lies between them. In there neither could get round the other, and a person
    /// waits for a robot in their way for ever.
    fn give_way(&self, here: (f64, f64), from: &mut [(f64, f64)]) -> Option<GiveWay> {
        let c = &self.config;
        let r = self.radius_m;
        // The arc length of every vertex, to place movers along the reference.
        let mut arc = Vec::with_capacity(from.len());
        let mut s = 0.0;
        for (i, p) in from.iter().enumerate() {
            if i > 0 {
                s += (p.0 - from[i - 1].0).hypot(p.1 - from[i - 1].1);
            }
            arc.push(s);
            if s > YIELD_LOOK_M {
                break;
            }
        }
        if arc.len() < 2 {
            return None;
        }
        let n_look = arc.len();
        // The nearest one coming: (distance along, signed offset to the left, radius,
        // speed towards the robot, offset to the left of the robot's heading line).
        let mut oncoming: Option<(f64, f64, f64, f64, f64)> = None;
        for d in self.view.people.iter().chain(self.view.robots.iter()) {
            let (seg, t, off) = project(&from[..n_look], (d.x_m, d.y_m), YIELD_LOOK_M);
            if off > r + d.radius_m + c.people_margin_m + LANE_EXTRA_M {
                continue;
            }
            let (a, b) = (from[seg], from[seg + 1]);
            let len = (b.0 - a.0).hypot(b.1 - a.1);
            if len < 1e-9 {
                continue;
            }
            let (ux, uy) = ((b.0 - a.0) / len, (b.1 - a.1) / len);
            if d.vx_mps * ux + d.vy_mps * uy > -ONCOMING_MPS {
                continue;
            }
            let s_m = arc[seg] + t * len;
            if s_m <= 0.0 {
                // Level with the robot or behind it: passing, nothing more to give way.
                continue;
            }
            let foot = (a.0 + t * (b.0 - a.0), a.1 + t * (b.1 - a.1));
            let left_m = ux * (d.y_m - foot.1) - uy * (d.x_m - foot.0);
            let speed = -(d.vx_mps * ux + d.vy_mps * uy);
            let (_, seen_left_m) = to_robot_frame(&self.view.pose, (d.x_m, d.y_m));
            if oncoming.is_none_or(|o| s_m < o.0) {
                oncoming = Some((s_m, left_m, d.radius_m, speed, seen_left_m));
            }
        }
        let (mover_s, mover_left, mover_r, mover_speed, seen_left_m) = oncoming?;
        // Room to meet: both discs, the gap between them and the margins to both sides.
        let need_m =
            2.0 * r + 2.0 * mover_r + c.people_margin_m + 2.0 * c.static_margin_m + MEET_EXTRA_M;
        let lateral_m = r + mover_r + c.people_margin_m + PASS_EXTRA_M;
        let keep_m = r + c.static_margin_m + 0.02;
        let side = pass_side(self.pass_side, seen_left_m, || {
            let (a, b) = (from[0], from[1]);
            let len = (b.0 - a.0).hypot(b.1 - a.1).max(1e-9);
            let n = (-(b.1 - a.1) / len, (b.0 - a.0) / len);
            let left = self.room_m(from[0], n, keep_m);
            let right = self.room_m(from[0], (-n.0, -n.1), keep_m);
            left > right + 0.2
        });
        let wanted = (lateral_m - side * (-mover_left)).max(0.0);
        // Where the robot is now across the reference, so that the shift starts from there.
        let (a, b) = (from[0], from[1]);
        let len0 = (b.0 - a.0).hypot(b.1 - a.1).max(1e-9);
        let robot_left = ((b.0 - a.0) * (here.1 - a.1) - (b.1 - a.1) * (here.0 - a.0)) / len0;
        let original: Vec<(f64, f64)> = from[..n_look].to_vec();
        let normal = |i: usize| -> Option<(f64, f64)> {
            let (a, b) = if i + 1 < n_look {
                (original[i], original[i + 1])
            } else {
                (original[i - 1], original[i])
            };
            let len = (b.0 - a.0).hypot(b.1 - a.1);
            (len > 1e-9).then(|| (-(b.1 - a.1) / len, (b.0 - a.0) / len))
        };
        // The first narrow stretch between the robot and them: (start, end) along `from`.
        let mut narrow: Option<(f64, f64)> = None;
        for i in 0..n_look {
            if arc[i] > mover_s && narrow.is_none() {
                break;
            }
            let Some(n) = normal(i) else { continue };
            let tight = self.width_m(original[i], n, need_m) < need_m;
            narrow = match narrow {
                None if tight => Some((arc[i], arc[i])),
                Some((a, _)) if tight => Some((a, arc[i])),
                Some(_) => break,
                None => None,
            };
        }
        let hold = narrow.and_then(|(start_m, end_m)| {
            // Inside it already: better to get through than to stop in it.
            if start_m <= NARROW_COMMITTED_M {
                return None;
            }
            // Through it, and clear of its end, before they get there: no need to wait.
            // Once waiting, it waits until they are through (no second-guessing on the way).
            let robot_s = (end_m + r + mover_r + c.people_margin_m) / THROUGH_SPEED_MPS;
            let mover_s_left = (mover_s - end_m - r - mover_r - c.people_margin_m) / mover_speed;
            (self.holding || robot_s + THROUGH_MARGIN_S >= mover_s_left)
                .then(|| (start_m - HOLD_BACK_M).max(0.0))
        });
        tracing::trace!(
            mover_s,
            mover_left,
            mover_speed,
            ?narrow,
            ?hold,
            side,
            wanted,
            "give way"
        );
        // The shift builds up by the hold point at the latest: it is where the robot waits.
        let ramp_m = hold.map_or(SHIFT_RAMP_M, |h| h.clamp(0.3, SHIFT_RAMP_M));
        for i in 0..n_look {
            if arc[i] > mover_s + 1.0 {
                break;
            }
            let Some(n) = normal(i) else { continue };
            let p = original[i];
            let room = self.room_m(p, (side * n.0, side * n.1), keep_m);
            let shift = side * wanted.min(room);
            let o = robot_left + (shift - robot_left) * (arc[i] / ramp_m).min(1.0);
            from[i] = (p.0 + n.0 * o, p.1 + n.1 * o);
        }
        // Where to wait: beside the reference by the full shift, whatever the ramp.
        let hold = hold.map(|h| {
            let mut along = 0.0;
            let mut spot = original[n_look - 1];
            for i in 0..n_look - 1 {
                let (a, b) = (original[i], original[i + 1]);
                let len = (b.0 - a.0).hypot(b.1 - a.1);
                if along + len >= h && len > 1e-9 {
                    let u = (h - along) / len;
                    let p = (a.0 + u * (b.0 - a.0), a.1 + u * (b.1 - a.1));
                    let n = (-(b.1 - a.1) / len, (b.0 - a.0) / len);
                    let room = self.room_m(p, (side * n.0, side * n.1), keep_m);
                    let o = side * wanted.min(room);
                    spot = (p.0 + n.0 * o, p.1 + n.1 * o);
                    break;
                }
                along += len;
            }
            (h, spot)
        });
        // When they will be level with the spot.
        let eta_s = hold.map(|(h, _)| (mover_s - h).max(0.0) / mover_speed);
        Some(GiveWay { hold, side, eta_s })
    }

    /// How far from `p` along the unit direction `d` the robot's centre can move and still
    /// keep `keep_m` from static obstacles (up to 1.5 m).
    fn room_m(&self, p: (f64, f64), d: (f64, f64), keep_m: f64) -> f64 {
        let mut o = 0.0;
        while o < 1.5 {
            let next = o + 0.05;
            if self.statics.clearance_m(p.0 + d.0 * next, p.1 + d.1 * next) < keep_m {
                break;
            }
            o = next;
        }
        o
    }

    /// Free width through `p` across the unit normal `n`, up to `cap_m`.
    fn width_m(&self, p: (f64, f64), n: (f64, f64), cap_m: f64) -> f64 {
        let mut total = 0.0;
        for sign in [1.0, -1.0] {
            // Sphere tracing: nothing is closer than the clearance.
            let mut d = 0.0;
            for _ in 0..32 {
                let c = self
                    .statics
                    .clearance_m(p.0 + sign * n.0 * d, p.1 + sign * n.1 * d);
                if c < 0.01 || total + d >= cap_m {
                    break;
                }
                d += c.max(0.01);
            }
            total += d;
        }
        total
    }

    /// Whether the straight segment from `a` to `b` keeps the hard margin from static obstacles.
    fn segment_clear(&self, a: (f64, f64), b: (f64, f64)) -> bool {
        let len = (b.0 - a.0).hypot(b.1 - a.1);
        let n = (len / SCAN_STEP_M).ceil().max(1.0);
        let floor = self.radius_m + self.config.static_margin_m;
        // From the first step on: where the robot stands is not the question.
        let mut k = 1.0;
        while k <= n {
            let u = k / n;
            if self
                .statics
                .clearance_m(a.0 + u * (b.0 - a.0), a.1 + u * (b.1 - a.1))
                < floor
            {
                return false;
            }
            k += 1.0;
        }
        true
    }

    /// Rolls out one candidate target through filter `f` and checks it (see the module docs).
    fn rollout(
        &self,
        pose: Pose2D,
        target: (f64, f64),
        f: &FilterLimits,
        limits: &Limits,
        dt: f64,
    ) -> Rollout {
        let r = self.radius_m;
        let c = &self.config;
        let steps = (c.horizon_s / dt).ceil().max(1.0) as usize;
        let commit = (c.commit_s / dt).round().max(1.0) as usize;
        let c0 = self
            .statics
            .clearance_near_m(pose.x_m, pose.y_m, &self.near_boxes)
            - r;
        // Already inside the margin (a put-down, a squeeze): moves that get no closer stay
        // allowed, so the robot can get out.
        let static_floor = c.static_margin_m.min(c0 - 0.005);
        let mut out = Rollout {
            static_ok: true,
            movers_ok: true,
            mover_slack_m: f64::INFINITY,
            soft_cost: 0.0,
        };
        let mut m = self.motion;
        let mut p = pose;
        for k in 1..=steps {
            m = f.step(m, target.0, target.1, dt);
            p = sim::integrate(p, m.v_mps, m.omega_radps, dt);
            #[allow(clippy::cast_precision_loss)]
            let t = k as f64 * dt;
            let clear = self
                .statics
                .clearance_near_m(p.x_m, p.y_m, &self.near_boxes)
                - r;
            if k <= commit && clear < static_floor {
                out.static_ok = false;
                return out;
            }
            if clear < c.comfort_clearance_m + c.static_margin_m {
                let short = (c.comfort_clearance_m + c.static_margin_m - clear)
                    / (c.comfort_clearance_m + c.static_margin_m);
                out.soft_cost += W_STATIC * short * short * dt;
            }
            for mv in &self.movers {
                let q = mv.at(t);
                let d = (q.0 - p.x_m).hypot(q.1 - p.y_m);
                out.mover_slack_m = out.mover_slack_m.min(d - mv.hard_m);
                if k <= commit && self.closing_in(p, m.v_mps, q, mv, pose) {
                    out.movers_ok = false;
                }
                if d < mv.soft_m {
                    let short = (mv.soft_m - d) / (mv.soft_m - mv.hard_m + 1e-9);
                    out.soft_cost += W_PEOPLE * short.min(2.0).powi(2) * dt;
                }
            }
            if k == commit {
                let (static_ok, movers_ok) = self.brake_check(p, m, t, limits, dt, static_floor);
                out.static_ok &= static_ok;
                out.movers_ok &= movers_ok;
                if !out.static_ok {
                    return out;
                }
            }
        }
        out
    }

    /// Whether the robot at `p` moving at `v` closes in on mover `mv` (now at `q`) within its
    /// hard distance; the threshold never exceeds the distance at the start, so that a robot
    /// already too close may move away.
    fn closing_in(&self, p: Pose2D, v: f64, q: (f64, f64), mv: &Mover, start: Pose2D) -> bool {
        let d = (q.0 - p.x_m).hypot(q.1 - p.y_m);
        let d0 = (mv.disc.x_m - start.x_m).hypot(mv.disc.y_m - start.y_m);
        let hard = mv.hard_m.min(d0 - 0.01);
        if d >= hard || v < 0.02 {
            return false;
        }
        let (s, c) = p.yaw_rad.sin_cos();
        (q.0 - p.x_m) * c + (q.1 - p.y_m) * s > 0.0
    }

    /// From state `m` at pose `p` (time `t0`), braking at the robot's limit along the current
    /// curvature: (static margin kept, movers' margin kept).
    fn brake_check(
        &self,
        mut p: Pose2D,
        m: Motion,
        t0: f64,
        limits: &Limits,
        dt: f64,
        static_floor: f64,
    ) -> (bool, bool) {
        let r = self.radius_m;
        let decel = limits.max_accel_mps2;
        let kappa = if m.v_mps > 0.05 {
            m.omega_radps / m.v_mps
        } else {
            0.0
        };
        let mut v = m.v_mps;
        let mut w = m.omega_radps;
        let mut t = t0;
        let mut movers_ok = true;
        while v > 0.0 {
            v = (v - decel * dt).max(0.0);
            w = if v > 0.05 {
                kappa * v
            } else {
                w.signum() * (w.abs() - limits.max_turn_accel_radps2 * dt).max(0.0)
            };
            p = sim::integrate(p, v, w, dt);
            t += dt;
            let clear = self
                .statics
                .clearance_near_m(p.x_m, p.y_m, &self.near_boxes)
                - r;
            if clear < static_floor {
                return (false, movers_ok);
            }
            for mv in &self.movers {
                let q = mv.at(t);
                let start = self.view.pose;
                if self.closing_in(p, v, q, mv, start) {
                    movers_ok = false;
                }
            }
        }
        (true, movers_ok)
    }

    /// The people and robots that a rollout could meet, and the boxes it could touch.
    fn gather_nearby(&mut self, pose: Pose2D, limits: &Limits) {
        let c = &self.config;
        let reach = limits.max_speed_mps * c.horizon_s + self.radius_m;
        self.movers.clear();
        let people = self
            .view
            .people
            .iter()
            .map(|d| (d, c.people_margin_m, false));
        let stood: Vec<bool> = (0..self.view.robots.len())
            .map(|i| self.has_stood(i))
            .collect();
        let robots = self
            .view
            .robots
            .iter()
            .zip(stood)
            .map(|(d, stood)| (d, c.robot_margin_m, stood));
        for (d, margin, standing) in people.chain(robots) {
            let dist = (d.x_m - pose.x_m).hypot(d.y_m - pose.y_m);
            let speed = d.vx_mps.hypot(d.vy_mps);
            if dist - d.radius_m > reach + speed * c.horizon_s + c.people_comfort_m {
                continue;
            }
            let radii = self.radius_m + d.radius_m;
            // Passing a standing robot close is what a detour round it does: no comfort
            // distance to pay for beyond the room the detour keeps.
            let comfort_m = if standing {
                margin + STANDING_EXTRA_M
            } else {
                margin.max(c.people_comfort_m)
            };
            self.movers.push(Mover {
                disc: *d,
                standing,
                hard_m: radii + margin,
                soft_m: radii + comfort_m,
            });
        }
        self.near_boxes.clear();
        for (i, b) in self.statics.boxes.iter().enumerate() {
            if b.distance(pose.x_m, pose.y_m) < reach + c.comfort_clearance_m + 0.5 {
                self.near_boxes.push(i);
            }
        }
    }

    /// Picks the target (v, ω) and whether it needs the hard (limit) filter.
    fn choose(
        &self,
        pose: Pose2D,
        nominal: (f64, f64),
        limits: &Limits,
        dt: f64,
    ) -> ((f64, f64), bool) {
        let soft = self.filter_limits(limits);
        let hard = Self::hard_limits(limits, &soft);
        let (v_nom, w_nom) = nominal;
        let vmax = limits.max_speed_mps;
        let wmax = limits.max_turn_radps;
        let mut speeds: Vec<f64> = Vec::with_capacity(SPEED_LEVELS + 1);
        speeds.push(v_nom);
        for i in 0..SPEED_LEVELS {
            #[allow(clippy::cast_precision_loss)]
            let v = vmax * i as f64 / (SPEED_LEVELS - 1) as f64;
            if v < v_nom - 1e-6 {
                speeds.push(v);
            }
        }
        let mut turns: Vec<f64> = Vec::with_capacity(TURN_OFFSETS_RADPS.len());
        for off in TURN_OFFSETS_RADPS {
            let w = (w_nom + off).clamp(-wmax, wmax);
            if turns.iter().all(|&o| (o - w).abs() > 0.02) {
                turns.push(w);
            }
        }
        let cost_of = |target: (f64, f64), roll: &Rollout, hard_brake: bool| {
            let dv = (target.0 - v_nom) / vmax;
            let dw = (target.1 - w_nom) / wmax;
            let cv = (target.0 - self.last_target.0) / vmax;
            let cw = (target.1 - self.last_target.1) / wmax;
            W_SPEED * dv * dv
                + W_TURN * dw * dw
                + W_CHANGE * (cv * cv + cw * cw)
                + roll.soft_cost
                + if hard_brake { W_HARD_BRAKE } else { 0.0 }
        };
        // Best fully admissible; best for movers among the statically admissible.
        let mut best: Option<(f64, (f64, f64), bool)> = None;
        let mut fallback: Option<(f64, f64, (f64, f64), bool)> = None;
        let mut consider = |target: (f64, f64), hard_brake: bool, roll: Rollout| {
            if !roll.static_ok {
                return;
            }
            let cost = cost_of(target, &roll, hard_brake);
            if roll.movers_ok {
                if best.is_none_or(|b| cost < b.0) {
                    best = Some((cost, target, hard_brake));
                }
            } else {
                // Keep the most room to whoever it would close in on; then the slowest.
                let key = roll.mover_slack_m;
                if fallback
                    .is_none_or(|f| key > f.0 + 1e-6 || ((key - f.0).abs() <= 1e-6 && cost < f.1))
                {
                    fallback = Some((key, cost, target, hard_brake));
                }
            }
        };
        for &v in &speeds {
            for &w in &turns {
                let roll = self.rollout(pose, (v, w), &soft, limits, dt);
                consider((v, w), false, roll);
            }
        }
        for w in [0.0, w_nom, self.motion.omega_radps] {
            let roll = self.rollout(pose, (0.0, w), &hard, limits, dt);
            consider((0.0, w), true, roll);
        }
        if let Some((_, target, hard_brake)) = best {
            return (target, hard_brake);
        }
        if let Some((_, _, target, hard_brake)) = fallback {
            return (target, hard_brake);
        }
        // Nothing keeps the margin: brake as hard as the robot can, turning no further.
        ((0.0, 0.0), true)
    }
}

/// Thins an 8-connected cell path and smooths it where that keeps `min_clear_m`.
fn smooth_detour(
    statics: &StaticTruth,
    standing: &[StandingDisc],
    cells: Vec<(f64, f64)>,
    min_clear_m: f64,
) -> Vec<(f64, f64)> {
    let Some(&last) = cells.last() else {
        return cells;
    };
    let mut pts: Vec<(f64, f64)> = cells.iter().step_by(3).copied().collect();
    if pts.last() != Some(&last) {
        pts.push(last);
    }
    for _ in 0..4 {
        for i in 1..pts.len().saturating_sub(1) {
            let (a, b, c) = (pts[i - 1], pts[i], pts[i + 1]);
            let q = (
                0.25 * a.0 + 0.5 * b.0 + 0.25 * c.0,
                0.25 * a.1 + 0.5 * b.1 + 0.25 * c.1,
            );
            let clear = |p: (f64, f64)| statics.clearance_with_m(standing, p.0, p.1);
            let cq = clear(q);
            if cq >= min_clear_m || cq >= clear(b) {
                pts[i] = q;
            }
        }
    }
    pts
}

impl Controller for Expert {
    fn kind(&self) -> ControllerKind {
        ControllerKind::Expert
    }

    fn control(&mut self, input: &ControlInput<'_>) -> Result<Control, ControllerError> {
        let intention = input.intention.ok_or(ControllerError::MissingInput {
            controller: NAME,
            input: "intention",
        })?;
        let dt = input.dt_s;
        if !(dt.is_finite() && dt > 0.0) {
            return Err(ControllerError::BadInput {
                controller: NAME,
                input: "dt_s",
                reason: format!("{dt} is not a positive, finite cycle length"),
            });
        }
        if !(input.v_mps.is_finite() && input.omega_radps.is_finite()) {
            return Err(ControllerError::BadInput {
                controller: NAME,
                input: "odometry speeds",
                reason: format!(
                    "not finite: {} m/s, {} rad/s",
                    input.v_mps, input.omega_radps
                ),
            });
        }
        let limits = input.limits;
        self.clock_s += dt;
        {
            let view = self.truth.lock().unwrap_or_else(PoisonError::into_inner);
            self.view.pose = view.pose;
            self.view.people.clone_from(&view.people);
            self.view.robots.clone_from(&view.robots);
        }
        self.track_standing();
        let pose = self.view.pose;
        if !(pose.x_m.is_finite() && pose.y_m.is_finite() && pose.yaw_rad.is_finite()) {
            return Err(ControllerError::BadInput {
                controller: NAME,
                input: "true pose",
                reason: format!("not finite: ({}, {}, {})", pose.x_m, pose.y_m, pose.yaw_rad),
            });
        }
        self.sync_motion(input);
        if intention.stops() {
            self.detour = None;
            return Ok(self.stop(limits, dt));
        }
        self.path.clear();
        for (i, p) in intention.path.iter().enumerate() {
            if !(p.x_m.is_finite() && p.y_m.is_finite()) {
                return Err(ControllerError::BadInput {
                    controller: NAME,
                    input: "intention.path",
                    reason: format!("pose {i} is not finite: ({}, {})", p.x_m, p.y_m),
                });
            }
            // Turns in place repeat a position; the reference is a polyline of positions.
            if self
                .path
                .last()
                .is_none_or(|q| (q.0 - p.x_m).hypot(q.1 - p.y_m) > 1e-6)
            {
                self.path.push((p.x_m, p.y_m));
            }
        }
        let Some(&goal) = self.path.last() else {
            return Err(ControllerError::BadInput {
                controller: NAME,
                input: "intention.path",
                reason: "the path is empty".into(),
            });
        };
        if (goal.0 - pose.x_m).hypot(goal.1 - pose.y_m) <= self.config.goal_tolerance_m {
            self.detour = None;
            return Ok(self.stop(limits, dt));
        }
        let stop_at_m = self.build_reference(pose);
        self.gather_nearby(pose, limits);
        let nominal = self.nominal(pose, limits, stop_at_m);
        let (target, hard_brake) = self.choose(pose, nominal, limits, dt);
        let soft = self.filter_limits(limits);
        let f = if hard_brake {
            Self::hard_limits(limits, &soft)
        } else {
            soft
        };
        let control = self.drive(limits, &f, target, dt);
        tracing::trace!(
            t_s = self.clock_s,
            x = pose.x_m,
            y = pose.y_m,
            yaw = pose.yaw_rad,
            ?goal,
            ?nominal,
            ?target,
            hard_brake,
            ?stop_at_m,
            detour = self.detour.is_some(),
            v = self.motion.v_mps,
            w = self.motion.omega_radps,
            // Evaluated only when tracing is on.
            person_gap_m = self
                .view
                .people
                .iter()
                .map(|d| (d.x_m - pose.x_m).hypot(d.y_m - pose.y_m) - d.radius_m - self.radius_m)
                .fold(f64::INFINITY, f64::min),
            "expert"
        );
        Ok(control)
    }

    fn target(&self) -> Option<(f64, f64)> {
        Some(self.last_target)
    }

    fn reset(&mut self) {
        self.motion = Motion::default();
        self.last_target = (0.0, 0.0);
        self.rotating = false;
        self.holding = false;
        self.pass_side = None;
        self.detour = None;
        self.last_search_s = None;
        self.last_pose = None;
        self.still_since_s.clear();
        self.standing.clear();
    }
}

/// The side (+1 left, -1 right) on which to pass someone coming the other way, seen
/// `seen_left_m` to the left of the robot's heading line: away from them as the robot sees
/// them, not as they stand to the reference. The camera shows the heading line, never the
/// reference, and a side chosen off the reference could label the same picture "pass left"
/// in one episode and "pass right" in another (round 59). Where they come straight at it, the left
/// only where `more_room_left` says it has clearly more room, else the right. A side once
/// chosen (`kept`) stays while they come, unless they are now on that side: turning back and
/// forth would block them.
fn pass_side(kept: Option<f64>, seen_left_m: f64, more_room_left: impl FnOnce() -> bool) -> f64 {
    const STRAIGHT_AT_M: f64 = 0.1;
    if let Some(side) = kept.filter(|s| s * seen_left_m < STRAIGHT_AT_M) {
        side
    } else if seen_left_m > STRAIGHT_AT_M {
        -1.0
    } else if seen_left_m < -STRAIGHT_AT_M || more_room_left() {
        1.0
    } else {
        -1.0
    }
}

#[cfg(test)]
mod tests {
    use super::pass_side;

    #[test]
    fn passes_on_the_side_away_from_where_the_robot_sees_them() {
        let unasked = || -> bool { panic!("room asked for where the picture decides") };
        assert!((pass_side(None, 0.3, unasked) - -1.0).abs() < 1e-12);
        assert!((pass_side(None, -0.3, unasked) - 1.0).abs() < 1e-12);
    }

    #[test]
    fn someone_straight_ahead_is_passed_on_the_right_unless_the_left_has_more_room() {
        assert!((pass_side(None, 0.05, || false) - -1.0).abs() < 1e-12);
        assert!((pass_side(None, -0.05, || true) - 1.0).abs() < 1e-12);
    }

    #[test]
    fn keeps_its_side_until_they_are_on_it() {
        // Chosen left; they drift a little left of the heading line: still left.
        assert!((pass_side(Some(1.0), 0.05, || false) - 1.0).abs() < 1e-12);
        // Now clearly on the left: the right.
        assert!((pass_side(Some(1.0), 0.4, || true) - -1.0).abs() < 1e-12);
    }
}
