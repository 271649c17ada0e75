//! DLM (discretized local move): `TurnLeft | TurnRight | GoForward | Stop` from a path.
//!
//! Paper §3.1: the sign and size of the path's local signed curvature at the robot, against a
//! threshold; `Stop` when the remaining path is shorter than `stop_distance_m`. Three measures
//! of "how much the path turns ahead", all in the robot's frame, so "left" means left of where
//! the robot faces, even when the path starts with a turn in place:
//!
//! - [`DlmMeasure::Curvature`] (what DLM-Net r1 was trained on): the circle through the robot,
//!   tangent to its heading, through the path point `window_m` of arc length ahead of the path
//!   point closest to the robot, has curvature `2 y / (x^2 + y^2)` (x forward, y left), as pure
//!   pursuit does; a path point behind the robot is always a turn towards its side. The bearing
//!   of one point 1.5 m ahead moves by 0.2 m of lateral offset past the threshold, so a new
//!   hybrid-A* search that bends its first metre differently, or cuts a corner 10 cm
//!   tighter, flips it: half of its changes last 0.3 s or less (docs/benchmarks.md, "A DLM that
//!   holds").
//! - [`DlmMeasure::Heading`] (what DLM-Net h1–d1 were trained on): the direction of the
//!   path's chord from `heading_start_m` to
//!   `heading_start_m + heading_chord_m` ahead, against the robot's heading. A turn starts when
//!   that angle reaches `turn_threshold_rad` and holds while it stays at or past
//!   `turn_release_rad` on the same side (hysteresis, so the caller passes the previous DLM):
//!   the route's direction a metre or two ahead, not where one point of it lies, so wiggles and
//!   corner cuts of a few centimetres do not change it.
//! - [`DlmMeasure::Route`] (what DLM-Net r2–r4 were trained on): the heading
//!   measure's rule on the floor plan's route from the robot to the goal ([`super::route`])
//!   instead of on the searched path, so the DLM does not depend on how a search bent (a kept
//!   plan and a new search from one pose get the same DLM); `Stop` still comes from the path.
//! - [`DlmMeasure::FirstTurn`] (the default, what DLM-Net r5 and the shipped r49 were trained
//!   on): the first turn on the floor plan's route. The route's first
//!   `heading_start_m + heading_chord_m` are cut into pieces `heading_chord_m / 2` long, each
//!   measured against the robot's heading; the first piece whose angle reaches
//!   `turn_threshold_rad` decides the side, and a turn holds while the first piece at or past
//!   `turn_release_rad` is on its side. The route measure's one chord skips the first metre:
//!   round the end of a thin wall (a maze's hairpin) the route turns 180° within it, so the
//!   chord points along the way back, "go forward" to a robot still facing the wall's end, or
//!   ±π, left and right by a hair (task E, 2026-11-28: DLM-Net stood still there). The first
//!   piece that turns is the turn the robot has to make next. By default it measures the route's
//!   first metre (`heading_start_m` 0: two pieces); r5 was trained on 2 m and drives best told
//!   its turns that late, after the door or wall end it has to pass first.

use protocol::{Dlm, Pose2D};

use crate::intention::route::floor_plan_route;
use crate::map::{Disc, PlanningMap};
use crate::path::{length_of, point_along};
use serde::{Deserialize, Serialize};

/// How the DLM measures the turn of the path ahead (see the module docs).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DlmMeasure {
    /// The pure-pursuit circle through the path point `window_m` ahead (DLM-Net r1's).
    Curvature,
    /// The direction of the path `heading_start_m`..`+heading_chord_m` ahead, with hysteresis
    /// (DLM-Net h1–d1, docs/evaluation.md rounds 8–9).
    Heading,
    /// The heading measure on the floor plan's route to the goal, not on the searched path
    /// (DLM-Net r2–r4, docs/evaluation.md round 10).
    Route,
    /// The first turn on the floor plan's route, piece by piece (see the module docs; the
    /// default since DLM-Net r5, docs/evaluation.md round 21).
    #[default]
    FirstTurn,
}

impl DlmMeasure {
    /// Whether the measure turns on the floor plan's route ([`super::route`]) rather than on
    /// the searched path.
    #[must_use]
    pub fn uses_route(self) -> bool {
        matches!(self, Self::Route | Self::FirstTurn)
    }

    /// The name used in config files and model cards.
    #[must_use]
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Curvature => "curvature",
            Self::Heading => "heading",
            Self::Route => "route",
            Self::FirstTurn => "first_turn",
        }
    }
}

impl std::str::FromStr for DlmMeasure {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "curvature" => Ok(Self::Curvature),
            "heading" => Ok(Self::Heading),
            "route" => Ok(Self::Route),
            "first_turn" => Ok(Self::FirstTurn),
            other => Err(format!(
                "unknown DLM measure {other:?} (expected curvature, heading, route or first_turn)"
            )),
        }
    }
}

/// DLM parameters (the `[dlm]` table of the config file; recorded in recordings and DLM-Net
/// model cards, since a model is only valid for the DLM it was trained on).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DlmParams {
    /// Which measure of the path's turn decides (see the module docs).
    pub measure: DlmMeasure,
    /// `curvature`: arc length ahead of the robot at which the path point is taken.
    pub window_m: f64,
    /// `curvature`: |curvature| at or above which the move is a turn (1/m; 0.3 = a 3.3 m
    /// radius).
    pub curvature_threshold_per_m: f64,
    /// `heading`, `route`: arc length ahead of the robot where the measured chord of the path
    /// (the route) starts; `first_turn`: with `heading_chord_m`, how far the route is measured.
    pub heading_start_m: f64,
    /// `heading`, `route`: length of that chord.
    pub heading_chord_m: f64,
    /// `heading`, `route`: |angle| between the chord and the robot's heading at which a turn
    /// starts.
    pub turn_threshold_rad: f64,
    /// `heading`, `route`: a turn holds while the angle stays at or past this on its side.
    pub turn_release_rad: f64,
    /// `Stop` when the path left to drive is at most this long.
    pub stop_distance_m: f64,
    /// `Stop` too, but *arriving* ([`protocol::Intention::arriving`]: the robot drives on to
    /// the goal), when the path left is at most this long and longer than `stop_distance_m`,
    /// and the measure says `GoForward` (a turn still ahead stays a turn). 0: never, what
    /// DLM-Net r5 was trained on; 1.5: what DLM-Net r49 was trained and shipped on; 2.0 (the
    /// default): what the shipped DLM-Net r58 drives on (its card's `dlm_params`): where a goal
    /// without a heading is reached straight, not round a hook, the turn towards it told from
    /// 1.5 m comes too late for a network at full speed (round 54). The one-hot `go_forward`
    /// cannot tell a camera-driven network that its goal is near, so it either rolls past
    /// goals or stops short of those in front of a wall (docs/evaluation.md, round 45).
    pub arrive_distance_m: f64,
    /// Within `arrive_distance_m`: the arriving `Stop` only while the goal lies within this
    /// angle of the robot's heading; farther off, `TurnLeft`/`TurnRight` towards it (held down
    /// to half the angle). A `stop` one-hot does not say which way the goal lies, and a
    /// network told it drives the last metres straight (round 46). π: any bearing, as round
    /// 46's first fine-tune (a) was trained on; 0.2 (the default): DLM-Net r49's, r55's,
    /// r56's and r58's.
    pub arrive_bearing_rad: f64,
    /// Both turn angles (`turn_threshold_rad`, `turn_release_rad`) fall to `blocked_turn_rad`
    /// while the floor plan lets the robot drive less than this straight ahead
    /// ([`PlanningMap::free_ahead_m`]). A robot that faces a wall or a door's jamb cannot go
    /// forward, so a turn it still needs is told until it is nearly done; elsewhere the wide
    /// release stands, which a camera-driven network needs in a maze. 0: never, as before round
    /// 49; 1.2 (the default): DLM-Net r49's, r55's, r56's and r58's. Round 48 found DLM-Net
    /// leaving a room across a corridor, told `go_forward` with 0.4 rad still to turn, standing
    /// before the jamb opposite.
    pub blocked_ahead_m: f64,
    /// The turn angle while blocked (see `blocked_ahead_m`).
    pub blocked_turn_rad: f64,
    /// Where the searched path goes round an obstacle the robot's laser sees and the floor
    /// plan lacks (a cabinet, [`super::seen`]) that the floor plan's route runs into, and the
    /// measure says `GoForward`: the path point this far ahead (arc length) decides, as the
    /// paper's DLM does from the path's local curvature. `TurnLeft`/`TurnRight` towards it
    /// while its bearing from the heading is at least `sidestep_turn_rad`, held down to half
    /// that. The measures turn on the floor plan's route, which runs straight into the cabinet:
    /// told `go_forward`, DLM-Net r49 kept to the corridor's middle and clipped task C's
    /// cabinet in 9 runs of 10 (round 51).
    /// 0: never, as before round 51; 2.0 (the default): what DLM-Net r49 drove on since round
    /// 51, and the shipped r58 drives on (its card's `dlm_params`).
    pub sidestep_ahead_m: f64,
    /// The bearing that starts the turn (see `sidestep_ahead_m`).
    pub sidestep_turn_rad: f64,
    /// Where the measure tells a turn afresh (not only holds one), the floor plan's route leaves
    /// less than this off the heading (its first piece), and the path goes round a seen obstacle
    /// the route runs into (as for `sidestep_ahead_m`), the turn is measured on the path instead
    /// of the route. Beside such an obstacle the route turns into it: DLM-Net, told `turn_left`
    /// beside task D's cabinet by the room's door (8.6, 8.0) while the path still ran past it,
    /// turned into it (6 of 100 runs alone, round 54; none with the rule, round 55). A turn the
    /// measure only holds stays: it is the sidestep's own from the cycle before, and measured
    /// on the path it would flip to `GoForward` every other cycle. 0: never, as before round
    /// 55; π (the default): any turn, what the shipped DLM-Net r58 drives on.
    pub sidestep_over_turn_rad: f64,
    /// A turn round: where the route's first piece lies at least this far off the heading
    /// (`first_turn` only; the next leg starts behind the robot, as after a goal), the turn is
    /// told towards the side the floor plan closes in (a fan of rays up to [`ABOUT_TURN_RAY_M`]
    /// over the sweep of each side, nearer by [`ABOUT_TURN_MARGIN_M`] or more on average),
    /// whichever side the route lies on by a hair. A
    /// camera-driven network told the turn towards an open side drives into it as into a
    /// junction ahead; told it towards a wall, it turns on the spot, as it learned from wall
    /// starts. Round 53: of DLM-Net r49's 28 interventions alone (tasks A–E × 20), 16 were
    /// turns round after a goal, at three goals each with a passage open on the side it was
    /// told. 0: never, as before round 53; 2.6 (150°, the default): what DLM-Net r49 drove on
    /// since round 53, and the shipped r58 drives on (its card's `dlm_params`). At 2.2 a route
    /// leaving 125° to one side was turned the long way round, towards the wall on the other
    /// (task E's goal 3: 0.35 interventions per run alone became 0.70).
    pub about_turn_rad: f64,
}

impl Default for DlmParams {
    fn default() -> Self {
        Self {
            measure: DlmMeasure::FirstTurn,
            window_m: 1.5,
            curvature_threshold_per_m: 0.3,
            // first_turn measures the route's first metre: told a turn 2 m ahead, DLM-Net r5
            // turned before the door or wall end it had to pass first (docs/evaluation.md,
            // rounds 21-22: 1.38 interventions per run at 2 m, 0.73 at 1.5 m, 0.42 at 1.25 m,
            // 0.21 at 1 m).
            heading_start_m: 0.0,
            heading_chord_m: 1.0,
            turn_threshold_rad: 0.8,
            turn_release_rad: 0.6,
            stop_distance_m: 0.3,
            // The shipped DLM-Net r58's card (docs/evaluation.md, rounds 46-50, 54-58): the
            // planner must derive the DLM the shipped network drives on.
            arrive_distance_m: 2.0,
            arrive_bearing_rad: 0.2,
            blocked_ahead_m: 1.2,
            blocked_turn_rad: 0.2,
            // DLM-Net r49's card since round 51, and r55's, r56's and r58's.
            sidestep_ahead_m: 2.0,
            sidestep_turn_rad: 0.3,
            // DLM-Net r55's, r56's and r58's cards.
            sidestep_over_turn_rad: std::f64::consts::PI,
            // DLM-Net r49's card since round 53, and r55's, r56's and r58's.
            about_turn_rad: ABOUT_TURN_RAD,
        }
    }
}

/// A DLM parameter out of range (the `[dlm]` table).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("invalid dlm.{field} = {value}: {reason}")]
pub struct DlmParamsError {
    /// The field inside `[dlm]`, e.g. `window_m`.
    pub field: &'static str,
    pub value: f64,
    pub reason: &'static str,
}

impl DlmParams {
    /// The curvature measure with its defaults (the DLM before it had a measure, DLM-Net r1's).
    #[must_use]
    pub fn curvature() -> Self {
        Self {
            measure: DlmMeasure::Curvature,
            ..Self::as_before()
        }
    }

    /// The defaults with every key added since the first model cards at the value that leaves
    /// its rule off (`arrive_distance_m` 0, `arrive_bearing_rad` π, `blocked_ahead_m` 0,
    /// `sidestep_ahead_m` 0, `sidestep_over_turn_rad` 0, `about_turn_rad` 0): what a
    /// card or recording written before the key existed meant, and what DLM-Net r1-r5 were
    /// trained and driven on.
    #[must_use]
    pub fn as_before() -> Self {
        Self {
            arrive_distance_m: 0.0,
            arrive_bearing_rad: std::f64::consts::PI,
            blocked_ahead_m: 0.0,
            sidestep_ahead_m: 0.0,
            sidestep_over_turn_rad: 0.0,
            about_turn_rad: 0.0,
            ..Self::default()
        }
    }

    /// The heading measure with its defaults (its chord 1–2 m ahead, as DLM-Net h1–r4 had), as
    /// before the arriving `Stop` and the blocked rule ([`DlmParams::as_before`]).
    #[must_use]
    pub fn heading() -> Self {
        Self {
            measure: DlmMeasure::Heading,
            heading_start_m: 1.0,
            ..Self::as_before()
        }
    }

    /// Checks the fields, naming the first bad one.
    ///
    /// # Errors
    /// [`DlmParamsError`] naming the field and value.
    pub fn validate(&self) -> Result<(), DlmParamsError> {
        for (field, value) in [
            ("window_m", self.window_m),
            ("curvature_threshold_per_m", self.curvature_threshold_per_m),
            ("heading_start_m", self.heading_start_m),
            ("turn_threshold_rad", self.turn_threshold_rad),
            ("turn_release_rad", self.turn_release_rad),
            ("stop_distance_m", self.stop_distance_m),
            ("arrive_distance_m", self.arrive_distance_m),
            ("arrive_bearing_rad", self.arrive_bearing_rad),
            ("blocked_ahead_m", self.blocked_ahead_m),
            ("blocked_turn_rad", self.blocked_turn_rad),
            ("sidestep_ahead_m", self.sidestep_ahead_m),
            ("sidestep_turn_rad", self.sidestep_turn_rad),
            ("sidestep_over_turn_rad", self.sidestep_over_turn_rad),
            ("about_turn_rad", self.about_turn_rad),
        ] {
            if !value.is_finite() || value < 0.0 {
                return Err(DlmParamsError {
                    field,
                    value,
                    reason: "must be >= 0 and finite",
                });
            }
        }
        for (field, value) in [
            ("window_m", self.window_m),
            ("heading_chord_m", self.heading_chord_m),
        ] {
            if !(value.is_finite() && value > 0.0) {
                return Err(DlmParamsError {
                    field,
                    value,
                    reason: "must be positive",
                });
            }
        }
        if self.turn_release_rad > self.turn_threshold_rad {
            return Err(DlmParamsError {
                field: "turn_release_rad",
                value: self.turn_release_rad,
                reason: "must be at most turn_threshold_rad",
            });
        }
        // Only when on: a release below the default 0.2 must not need the key spelled out.
        if self.blocked_ahead_m > 0.0 && self.blocked_turn_rad > self.turn_release_rad {
            return Err(DlmParamsError {
                field: "blocked_turn_rad",
                value: self.blocked_turn_rad,
                reason: "must be at most turn_release_rad",
            });
        }
        if self.arrive_bearing_rad > std::f64::consts::PI {
            return Err(DlmParamsError {
                field: "arrive_bearing_rad",
                value: self.arrive_bearing_rad,
                reason: "must be at most pi",
            });
        }
        for (field, value) in [
            ("about_turn_rad", self.about_turn_rad),
            ("sidestep_over_turn_rad", self.sidestep_over_turn_rad),
        ] {
            if value > std::f64::consts::PI {
                return Err(DlmParamsError {
                    field,
                    value,
                    reason: "must be at most pi",
                });
            }
        }
        if self.turn_threshold_rad > std::f64::consts::PI {
            return Err(DlmParamsError {
                field: "turn_threshold_rad",
                value: self.turn_threshold_rad,
                reason: "must be at most pi",
            });
        }
        Ok(())
    }
}

/// Signed curvature (1/m, positive to the left) of the path ahead of `robot`, in the robot's
/// frame (infinite, with the side's sign, when the path point lies behind the robot), and the
/// remaining path length from the closest path point. `None` for an empty path.
#[must_use]
pub fn curvature_ahead(path: &[Pose2D], robot: Pose2D, window_m: f64) -> Option<(f64, f64)> {
    let rest = &path[crate::path::nearest_index(path, robot)?..];
    Some((curvature_of(rest, robot, window_m), length_of(rest)))
}

/// [`curvature_ahead`]'s curvature, for `rest`, the path from the point closest to the robot on
/// (not empty).
fn curvature_of(rest: &[Pose2D], robot: Pose2D, window_m: f64) -> f64 {
    let mut acc = 0.0;
    let mut target = rest[rest.len() - 1];
    for w in rest.windows(2) {
        acc += w[0].distance_m(&w[1]);
        if acc >= window_m {
            target = w[1];
            break;
        }
    }
    let (fwd, left) = in_robot_frame(robot, target);
    let d_sq = fwd * fwd + left * left;
    if d_sq < 1e-12 {
        return 0.0;
    }
    if fwd < 0.0 {
        // Behind the robot: a turn whatever the threshold, towards the point's side (left,
        // counter-clockwise, when straight behind).
        return if left >= -1e-9 {
            f64::INFINITY
        } else {
            f64::NEG_INFINITY
        };
    }
    2.0 * left / d_sq
}

/// The DLM for a robot at `robot` following `path` with no DLM before it (see the module
/// docs). An empty path means there is nothing left to do: `Stop`.
#[must_use]
pub fn dlm_from_path(path: &[Pose2D], robot: Pose2D, params: &DlmParams) -> Dlm {
    next_dlm(path, robot, params, None)
}

/// The DLM for a robot at `robot` following `path`, after `previous` (the DLM answered to the
/// robot's last pose, which the heading measure's hysteresis holds a turn on). The route
/// measure without a route measures the path, as the heading measure does.
#[must_use]
pub fn next_dlm(path: &[Pose2D], robot: Pose2D, params: &DlmParams, previous: Option<Dlm>) -> Dlm {
    next_dlm_along(path, None, robot, params, previous)
}

/// The DLM for a robot at `robot` sent along `path` towards `goal` on `map`, after
/// `previous`: the route measure turns on the floor plan's route from the robot
/// ([`floor_plan_route`], as far as the chord reaches), the others on the path; where the path
/// goes round one of the `seen` obstacles just ahead, the path's sidestep
/// ([`DlmParams::sidestep_ahead_m`]), or a fresh turn measured on the path
/// ([`DlmParams::sidestep_over_turn_rad`]). What the pipeline answers and `planner-service
/// plan` prints.
#[must_use]
pub fn dlm_on_map(
    map: &PlanningMap,
    path: &[Pose2D],
    robot: Pose2D,
    goal: Pose2D,
    params: &DlmParams,
    previous: Option<Dlm>,
    seen: &[Disc],
) -> Dlm {
    let route = params
        .measure
        .uses_route()
        .then(|| {
            floor_plan_route(
                map,
                robot,
                goal,
                params.heading_start_m + params.heading_chord_m,
            )
        })
        .flatten();
    let blocked = params.blocked_ahead_m > 0.0
        && map.free_ahead_m(
            robot,
            BAND_OF_RADIUS * map.robot_radius_m(),
            params.blocked_ahead_m,
        ) < params.blocked_ahead_m;
    let dlm = match decide(path, route.as_deref(), robot, params, previous, blocked) {
        turn @ (Dlm::TurnLeft | Dlm::TurnRight) => {
            about_turn_side(map, path, route.as_deref(), robot, params).unwrap_or(turn)
        }
        dlm => dlm,
    };
    if params.sidestep_ahead_m <= 0.0 {
        return dlm;
    }
    let Some(closest) = crate::path::nearest_index(path, robot) else {
        return dlm;
    };
    let rest = &path[closest..];
    let turn = matches!(dlm, Dlm::TurnLeft | Dlm::TurnRight);
    if !(dlm == Dlm::GoForward || (turn && params.sidestep_over_turn_rad > 0.0)) {
        return dlm;
    }
    let reach_m = params.sidestep_ahead_m + SIDESTEP_BEYOND_M;
    let berth_m = map.robot_radius_m() + SIDESTEP_BERTH_M;
    if !passes_near(rest, seen, reach_m, berth_m) {
        return dlm;
    }
    // A turn the measure only holds (from `previous`) is the sidestep's own, told the cycle
    // before: measured on the path, it would be `GoForward` every other cycle.
    if turn
        && !(first_piece_rad(route.as_deref(), rest, robot, params)
            .is_some_and(|first_rad| first_rad.abs() < params.sidestep_over_turn_rad)
            && decide(path, route.as_deref(), robot, params, None, blocked) == dlm)
    {
        return dlm;
    }
    // The turn is the obstacle's where the floor plan's route runs into it and the path goes
    // round it. Where the route passes it anyway (a box in a maze's corner, which the route
    // cuts past on the other side), the path's bend is the route's own turn, and told early it
    // cuts the corner of the wall the robot has to pass first (task E, round 51).
    let blocking = floor_plan_route(map, robot, goal, reach_m)
        .is_some_and(|route| passes_near(&route, seen, reach_m, berth_m));
    if !blocking {
        return dlm;
    }
    if dlm == Dlm::GoForward {
        sidestep_move(rest, robot, params, previous)
    } else {
        // The route turns towards what it runs into; the path's own first metre says where
        // the way round turns.
        decide(path, None, robot, params, previous, blocked)
    }
}

/// [`DlmParams::about_turn_rad`]'s default (rad).
pub const ABOUT_TURN_RAD: f64 = 2.6;
/// How far each ray of [`DlmParams::about_turn_rad`]'s fans looks for the floor plan's wall.
pub const ABOUT_TURN_RAY_M: f64 = 3.0;
/// How much nearer one side's wall must be than the other's for a turn round to be told
/// towards it; where the two are about as near (a hall), the measure's side stands.
pub const ABOUT_TURN_MARGIN_M: f64 = 0.5;

/// The side of a turn round ([`DlmParams::about_turn_rad`]): `None` where the rule is off,
/// the measure is not `first_turn`, the route's first piece lies less than `about_turn_rad`
/// off the heading, or neither side is nearer by the margin. Each side's free distance is the
/// mean of a fan of rays round the middle of the turn that side would sweep, taken from the
/// route's direction, not the heading: the robot turning on the spot keeps its answer (its
/// heading sweeps, the route's first piece stays), and one ray grazing a wall's corner does
/// not decide.
fn about_turn_side(
    map: &PlanningMap,
    path: &[Pose2D],
    route: Option<&[Pose2D]>,
    robot: Pose2D,
    params: &DlmParams,
) -> Option<Dlm> {
    if params.about_turn_rad <= 0.0 || params.measure != DlmMeasure::FirstTurn {
        return None;
    }
    let rest = &path[crate::path::nearest_index(path, robot)?..];
    let first_rad = first_piece_rad(route, rest, robot, params)?;
    if first_rad.abs() < params.about_turn_rad {
        return None;
    }
    let way_rad = robot.yaw_rad + first_rad;
    let half_width_m = BAND_OF_RADIUS * map.robot_radius_m();
    // Turning left (side +1) from facing away from the way sweeps through the way's right.
    let free_m = |side: f64| {
        let middle_rad = way_rad - side * std::f64::consts::FRAC_PI_2;
        let sum_m: f64 = ABOUT_TURN_FAN_RAD
            .iter()
            .map(|k| {
                let look = Pose2D::new(robot.x_m, robot.y_m, middle_rad + k);
                map.free_ahead_m(look, half_width_m, ABOUT_TURN_RAY_M)
            })
            .sum();
        sum_m / ABOUT_TURN_FAN_RAD.len() as f64
    };
    let (left_m, right_m) = (free_m(1.0), free_m(-1.0));
    if left_m + ABOUT_TURN_MARGIN_M <= right_m {
        Some(Dlm::TurnLeft)
    } else if right_m + ABOUT_TURN_MARGIN_M <= left_m {
        Some(Dlm::TurnRight)
    } else {
        None
    }
}

/// The angle (rad, left positive) between the robot's heading and the first piece of the
/// floor plan's `route`, or of `rest` (the path from the robot on) where there is none.
fn first_piece_rad(
    route: Option<&[Pose2D]>,
    rest: &[Pose2D],
    robot: Pose2D,
    params: &DlmParams,
) -> Option<f64> {
    piece_angles_rad(route.unwrap_or(rest), robot, params)
        .first()
        .copied()
}

/// The rays of [`about_turn_side`]'s fan, about the middle of a side's sweep (rad).
const ABOUT_TURN_FAN_RAD: [f64; 5] = [
    -std::f64::consts::FRAC_PI_4,
    -std::f64::consts::FRAC_PI_8,
    0.0,
    std::f64::consts::FRAC_PI_8,
    std::f64::consts::FRAC_PI_4,
];

/// How far past `sidestep_ahead_m` a seen obstacle the path goes round still counts: the
/// robot turns out before it comes level with the obstacle.
const SIDESTEP_BEYOND_M: f64 = 1.0;
/// A path point within this of a seen obstacle's disc, beyond the robot's radius, goes round
/// it (the search keeps the robot's radius from the disc, and a little more where it can).
const SIDESTEP_BERTH_M: f64 = 0.3;

/// Whether `poses` (a path or route from the robot on), in its first `reach_m`, comes within
/// `berth_m` of one of the `seen` discs' edges.
fn passes_near(poses: &[Pose2D], seen: &[Disc], reach_m: f64, berth_m: f64) -> bool {
    let mut along_m = 0.0;
    for w in poses.windows(2) {
        if along_m > reach_m {
            break;
        }
        let (a, b) = (w[0], w[1]);
        let (dx, dy) = (b.x_m - a.x_m, b.y_m - a.y_m);
        let len_sq = dx * dx + dy * dy;
        let len_m = len_sq.sqrt();
        // Only the segment's part within reach.
        let u_max = if len_m > 0.0 {
            ((reach_m - along_m) / len_m).min(1.0)
        } else {
            0.0
        };
        let near = seen.iter().any(|d| {
            let u = if len_sq > 0.0 {
                (((d.x_m - a.x_m) * dx + (d.y_m - a.y_m) * dy) / len_sq).clamp(0.0, u_max)
            } else {
                0.0
            };
            d.gap_m(a.x_m + u * dx, a.y_m + u * dy) <= berth_m
        });
        if near {
            return true;
        }
        along_m += len_m;
    }
    false
}

/// The sidestep's move: a turn towards the point of `rest` `sidestep_ahead_m` ahead while its
/// bearing is at least `sidestep_turn_rad` (held down to half that on the same side), else
/// `GoForward`.
fn sidestep_move(rest: &[Pose2D], robot: Pose2D, params: &DlmParams, previous: Option<Dlm>) -> Dlm {
    let Some(bearing_rad) = bearing_ahead_rad(rest, robot, params.sidestep_ahead_m) else {
        return Dlm::GoForward;
    };
    let release_rad = 0.5 * params.sidestep_turn_rad;
    match previous {
        Some(Dlm::TurnLeft) if bearing_rad >= release_rad => Dlm::TurnLeft,
        Some(Dlm::TurnRight) if bearing_rad <= -release_rad => Dlm::TurnRight,
        _ if bearing_rad >= params.sidestep_turn_rad => Dlm::TurnLeft,
        _ if bearing_rad <= -params.sidestep_turn_rad => Dlm::TurnRight,
        _ => Dlm::GoForward,
    }
}

/// `p` in the robot's frame: (ahead, to the left) in metres.
fn in_robot_frame(robot: Pose2D, p: Pose2D) -> (f64, f64) {
    let (s, c) = robot.yaw_rad.sin_cos();
    let (dx, dy) = (p.x_m - robot.x_m, p.y_m - robot.y_m);
    (c * dx + s * dy, -s * dx + c * dy)
}

/// The bearing (rad, left positive) from the robot's heading of the point of `poses` `ahead_m`
/// along it; `None` when that point is not ahead of the robot (a turn on the spot is the
/// rotation shim's business).
fn bearing_ahead_rad(poses: &[Pose2D], robot: Pose2D, ahead_m: f64) -> Option<f64> {
    let (fwd, left) = in_robot_frame(robot, point_along(poses, ahead_m)?);
    (fwd > 0.0).then(|| left.atan2(fwd))
}

/// The half width of the band [`DlmParams::blocked_ahead_m`] measures, as a share of the
/// robot's radius: narrower than the robot, so a wall it drives along does not count, and
/// wide enough for a jamb in front of its camera.
const BAND_OF_RADIUS: f64 = 0.6;

/// [`next_dlm`] with the floor plan's route from the robot (`route`, from
/// [`super::route::floor_plan_route`]), which the route measure turns on instead of the path.
#[must_use]
pub fn next_dlm_along(
    path: &[Pose2D],
    route: Option<&[Pose2D]>,
    robot: Pose2D,
    params: &DlmParams,
    previous: Option<Dlm>,
) -> Dlm {
    decide(path, route, robot, params, previous, false)
}

/// [`next_dlm_along`], with the turn angles of a robot `blocked` ahead
/// ([`DlmParams::blocked_ahead_m`]) when it is.
fn decide(
    path: &[Pose2D],
    route: Option<&[Pose2D]>,
    robot: Pose2D,
    params: &DlmParams,
    previous: Option<Dlm>,
    blocked: bool,
) -> Dlm {
    let Some(closest) = crate::path::nearest_index(path, robot) else {
        return Dlm::Stop;
    };
    let rest = &path[closest..];
    let left_m = left_of(rest, robot);
    if left_m <= params.stop_distance_m {
        return Dlm::Stop;
    }
    let measured = measured_move(rest, route, robot, params, previous, blocked);
    if measured == Dlm::GoForward && left_m <= params.arrive_distance_m {
        return arrive_move(path, robot, params, previous);
    }
    measured
}

/// The move inside the arrive distance where the measure says `GoForward`: the arriving
/// `Stop` while the goal (the path's end) lies within `arrive_bearing_rad` of the heading, else
/// a turn towards it, held while it stays at least half that angle off on its side.
fn arrive_move(path: &[Pose2D], robot: Pose2D, params: &DlmParams, previous: Option<Dlm>) -> Dlm {
    let Some(goal) = path.last() else {
        return Dlm::Stop;
    };
    let bearing_rad = protocol::normalize_angle(
        (goal.y_m - robot.y_m).atan2(goal.x_m - robot.x_m) - robot.yaw_rad,
    );
    let release_rad = 0.5 * params.arrive_bearing_rad;
    match previous {
        Some(Dlm::TurnLeft) if bearing_rad >= release_rad => Dlm::TurnLeft,
        Some(Dlm::TurnRight) if bearing_rad <= -release_rad => Dlm::TurnRight,
        _ if bearing_rad.abs() <= params.arrive_bearing_rad => Dlm::Stop,
        _ if bearing_rad > 0.0 => Dlm::TurnLeft,
        _ => Dlm::TurnRight,
    }
}

/// How much of `path` a robot at `robot` has left to drive: the path's length from the point
/// closest to the robot, or the straight distance to its end when that is longer; 0 for an
/// empty path.
#[must_use]
pub fn path_left_m(path: &[Pose2D], robot: Pose2D) -> f64 {
    crate::path::nearest_index(path, robot).map_or(0.0, |closest| left_of(&path[closest..], robot))
}

/// [`path_left_m`] for `rest`, the path from the point closest to the robot on.
fn left_of(rest: &[Pose2D], robot: Pose2D) -> f64 {
    let to_end = rest.last().map_or(0.0, |g| g.distance_m(&robot));
    length_of(rest).max(to_end)
}

/// Whether `dlm`, answered to a robot at `robot` on `path`, is an arriving `Stop` (see
/// [`DlmParams::arrive_distance_m`]) rather than one to rest on.
#[must_use]
pub fn is_arriving(dlm: Dlm, path: &[Pose2D], robot: Pose2D, params: &DlmParams) -> bool {
    dlm == Dlm::Stop
        && params.arrive_distance_m > params.stop_distance_m
        && path_left_m(path, robot) > params.stop_distance_m
}

/// The move the measure calls for on `rest` (the path from the point closest to the robot
/// on, not empty), before the goal's `Stop`.
fn measured_move(
    rest: &[Pose2D],
    route: Option<&[Pose2D]>,
    robot: Pose2D,
    params: &DlmParams,
    previous: Option<Dlm>,
    blocked: bool,
) -> Dlm {
    let (threshold_rad, release_rad) = if blocked {
        (params.blocked_turn_rad, params.blocked_turn_rad)
    } else {
        (params.turn_threshold_rad, params.turn_release_rad)
    };
    match params.measure {
        DlmMeasure::Curvature => {
            let kappa = curvature_of(rest, robot, params.window_m);
            if kappa.abs() < params.curvature_threshold_per_m {
                Dlm::GoForward
            } else if kappa > 0.0 {
                Dlm::TurnLeft
            } else {
                Dlm::TurnRight
            }
        }
        DlmMeasure::Heading | DlmMeasure::Route => {
            let measured = match (params.measure, route) {
                (DlmMeasure::Route, Some(route)) => route,
                _ => rest,
            };
            turn_by(
                &[heading_ahead_rad(measured, robot, params)],
                threshold_rad,
                release_rad,
                previous,
            )
        }
        DlmMeasure::FirstTurn => turn_by(
            &piece_angles_rad(route.unwrap_or(rest), robot, params),
            threshold_rad,
            release_rad,
            previous,
        ),
    }
}

/// The turn the measured `angles` (nearest first; one for the heading and route measures)
/// call for: a turn holds while the first angle at or past `release_rad` is on its side,
/// and starts on the side of the first angle at or past `threshold_rad`.
fn turn_by(angles: &[f64], threshold_rad: f64, release_rad: f64, previous: Option<Dlm>) -> Dlm {
    let first_past = |limit: f64| angles.iter().copied().find(|a| a.abs() >= limit);
    match (previous, first_past(release_rad)) {
        (Some(Dlm::TurnLeft), Some(a)) if a >= 0.0 => Dlm::TurnLeft,
        (Some(Dlm::TurnRight), Some(a)) if a <= 0.0 => Dlm::TurnRight,
        _ => match first_past(threshold_rad) {
            Some(a) if a >= 0.0 => Dlm::TurnLeft,
            Some(_) => Dlm::TurnRight,
            None => Dlm::GoForward,
        },
    }
}

/// The angles (rad, positive to the left, in (-pi, pi]) from the robot's heading to each
/// piece, `heading_chord_m / 2` long, of `route`'s first `heading_start_m + heading_chord_m`,
/// nearest first; a last piece shorter than 5 cm where the route ends is left out.
#[must_use]
pub fn piece_angles_rad(route: &[Pose2D], robot: Pose2D, params: &DlmParams) -> Vec<f64> {
    let piece_m = 0.5 * params.heading_chord_m;
    let reach_m = (params.heading_start_m + params.heading_chord_m).min(length_of(route));
    let mut angles = Vec::new();
    let mut from_m = 0.0;
    while from_m + 0.05 < reach_m {
        let to_m = (from_m + piece_m).min(reach_m);
        if let (Some(a), Some(b)) = (point_along(route, from_m), point_along(route, to_m)) {
            let direction = (b.y_m - a.y_m).atan2(b.x_m - a.x_m);
            angles.push(protocol::normalize_angle(direction - robot.yaw_rad));
        }
        from_m = to_m;
    }
    angles
}

/// The angle (rad, positive to the left, in (-pi, pi]) from the robot's heading to the chord
/// of `rest` (the path from the point closest to the robot on) between `heading_start_m` and
/// `heading_start_m + heading_chord_m`. Where the path ends before the chord is half long,
/// the direction from the closest point to the path's end; 0 when that is within 5 cm.
#[must_use]
pub fn heading_ahead_rad(rest: &[Pose2D], robot: Pose2D, params: &DlmParams) -> f64 {
    let (Some(first), Some(last)) = (rest.first(), rest.last()) else {
        return 0.0;
    };
    let (Some(start), Some(end)) = (
        point_along(rest, params.heading_start_m),
        point_along(rest, params.heading_start_m + params.heading_chord_m),
    ) else {
        return 0.0;
    };
    let (from, to) = if start.distance_m(&end) >= 0.5 * params.heading_chord_m {
        (start, end)
    } else if first.distance_m(last) >= 0.05 {
        (*first, *last)
    } else {
        return 0.0;
    };
    let direction = (to.y_m - from.y_m).atan2(to.x_m - from.x_m);
    protocol::normalize_angle(direction - robot.yaw_rad)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::{FRAC_PI_2, PI};

    #[test]
    fn bad_params_name_the_field_and_value() {
        DlmParams::default().validate().unwrap();
        assert_eq!(DlmParams::default().measure, DlmMeasure::FirstTurn);
        // The heading measure's own defaults but for the measure and the first metre, and the
        // shipped DLM-Net r58's arriving Stop, turn before a wall, sidestep and turn round.
        assert_eq!(
            DlmParams::default(),
            DlmParams {
                measure: DlmMeasure::FirstTurn,
                heading_start_m: 0.0,
                arrive_distance_m: 2.0,
                arrive_bearing_rad: 0.2,
                blocked_ahead_m: 1.2,
                sidestep_ahead_m: 2.0,
                sidestep_over_turn_rad: PI,
                about_turn_rad: 2.6,
                ..DlmParams::heading()
            }
        );
        assert_eq!(
            DlmParams::as_before(),
            DlmParams {
                arrive_distance_m: 0.0,
                arrive_bearing_rad: PI,
                blocked_ahead_m: 0.0,
                sidestep_ahead_m: 0.0,
                sidestep_over_turn_rad: 0.0,
                about_turn_rad: 0.0,
                ..DlmParams::default()
            }
        );
        let bad = DlmParams {
            sidestep_over_turn_rad: 3.2,
            ..DlmParams::default()
        };
        assert_eq!(
            bad.validate().unwrap_err().to_string(),
            "invalid dlm.sidestep_over_turn_rad = 3.2: must be at most pi"
        );
        let bad = DlmParams {
            window_m: 0.0,
            ..DlmParams::default()
        };
        let e = bad.validate().unwrap_err();
        assert_eq!(e.field, "window_m");
        assert_eq!(e.to_string(), "invalid dlm.window_m = 0: must be positive");
        let bad = DlmParams {
            stop_distance_m: f64::NAN,
            ..DlmParams::default()
        };
        let e = bad.validate().unwrap_err();
        assert_eq!(e.field, "stop_distance_m");
        assert!(e.to_string().contains("dlm.stop_distance_m = NaN"), "{e}");
        let bad = DlmParams {
            sidestep_ahead_m: -1.0,
            ..DlmParams::default()
        };
        let e = bad.validate().unwrap_err();
        assert_eq!(
            e.to_string(),
            "invalid dlm.sidestep_ahead_m = -1: must be >= 0 and finite"
        );
    }

    /// Poses along an arc (positive curvature = left) from `start`, `step` metres apart.
    fn arc(start: Pose2D, curvature: f64, length_m: f64, step: f64) -> Vec<Pose2D> {
        let n = (length_m / step).round() as usize;
        let mut out = vec![start];
        let mut p = start;
        for _ in 0..n {
            let yaw2 = p.yaw_rad + curvature * step;
            p = if curvature.abs() < 1e-12 {
                Pose2D::new(
                    p.x_m + step * p.yaw_rad.cos(),
                    p.y_m + step * p.yaw_rad.sin(),
                    p.yaw_rad,
                )
            } else {
                Pose2D::new(
                    p.x_m + (yaw2.sin() - p.yaw_rad.sin()) / curvature,
                    p.y_m - (yaw2.cos() - p.yaw_rad.cos()) / curvature,
                    yaw2,
                )
            };
            out.push(p);
        }
        out
    }

    /// The curvature measure, which the older tests here describe.
    fn params() -> DlmParams {
        DlmParams::curvature()
    }

    #[test]
    fn straight_is_go_forward() {
        let path = arc(Pose2D::new(1.0, 2.0, 0.7), 0.0, 10.0, 0.05);
        assert_eq!(dlm_from_path(&path, path[0], &params()), Dlm::GoForward);
        // A small lateral offset from the path does not make it a turn.
        let off = Pose2D::new(
            path[0].x_m + 0.05 * (0.7f64 + FRAC_PI_2).cos(),
            path[0].y_m + 0.05 * (0.7f64 + FRAC_PI_2).sin(),
            0.7,
        );
        assert_eq!(dlm_from_path(&path, off, &params()), Dlm::GoForward);
    }

    #[test]
    fn left_and_right_bends() {
        let left = arc(Pose2D::new(0.0, 0.0, -2.0), 1.0, 5.0, 0.05);
        assert_eq!(dlm_from_path(&left, left[0], &params()), Dlm::TurnLeft);
        let right = arc(Pose2D::new(0.0, 0.0, 2.0), -1.0, 5.0, 0.05);
        assert_eq!(dlm_from_path(&right, right[0], &params()), Dlm::TurnRight);
        // Gentle curves below the threshold are still forward.
        let gentle = arc(Pose2D::new(0.0, 0.0, 0.0), 0.1, 5.0, 0.05);
        assert_eq!(dlm_from_path(&gentle, gentle[0], &params()), Dlm::GoForward);
    }

    #[test]
    fn s_bend_turns_left_then_right() {
        let mut path = arc(Pose2D::new(0.0, 0.0, 0.0), 1.0, 2.0, 0.05);
        let mid = path[path.len() - 1];
        let second = arc(mid, -1.0, 2.0, 0.05);
        path.extend_from_slice(&second[1..]);
        path.extend_from_slice(&arc(path[path.len() - 1], 0.0, 3.0, 0.05)[1..]);
        assert_eq!(dlm_from_path(&path, path[0], &params()), Dlm::TurnLeft);
        assert_eq!(dlm_from_path(&path, mid, &params()), Dlm::TurnRight);
        let last = second[second.len() - 1];
        assert_eq!(dlm_from_path(&path, last, &params()), Dlm::GoForward);
    }

    #[test]
    fn first_turn_measure_takes_the_nearest_turn_and_holds_it_round_a_hairpin() {
        // 2 m ahead in four pieces, as DLM-Net r5 was trained on (the default drives 1 m).
        let params = DlmParams {
            measure: DlmMeasure::FirstTurn,
            heading_start_m: 1.0,
            ..DlmParams::default()
        };
        // A U-turn round a wall's end: 0.4 m north, 0.6 m east, then south.
        let mut route = vec![Pose2D::new(0.0, 0.0, FRAC_PI_2), Pose2D::new(0.0, 0.4, 0.0)];
        route.push(Pose2D::new(0.6, 0.4, -FRAC_PI_2));
        route.push(Pose2D::new(0.6, -3.0, -FRAC_PI_2));
        let robot = Pose2D::new(0.0, 0.0, FRAC_PI_2);
        let angles = piece_angles_rad(&route, robot, &params);
        assert_eq!(angles.len(), 4, "{angles:?}");
        assert!(angles[0].abs() < 0.5 && angles[1] < -0.8, "{angles:?}");
        let dlm = |robot, previous| next_dlm_along(&route, Some(&route), robot, &params, previous);
        assert_eq!(dlm(robot, None), Dlm::TurnRight);
        // The route measure's one chord (1-2 m) points straight back: a turn by a hair's side.
        let chord = heading_ahead_rad(&route, robot, &params);
        assert!((chord.abs() - PI).abs() < 1e-9, "{chord}");
        // Halfway round (facing east at the top), the way on is south: still right, and held.
        let top = Pose2D::new(0.3, 0.4, 0.0);
        let rest = &route[1..];
        let mut from_top = vec![top];
        from_top.extend_from_slice(&rest[1..]);
        assert_eq!(
            next_dlm_along(
                &from_top,
                Some(&from_top),
                top,
                &params,
                Some(Dlm::TurnRight)
            ),
            Dlm::TurnRight
        );
        // Facing down the way back: forward.
        let back = Pose2D::new(0.6, 0.0, -FRAC_PI_2);
        let along = [back, Pose2D::new(0.6, -3.0, -FRAC_PI_2)];
        assert_eq!(
            next_dlm_along(&along, Some(&along), back, &params, Some(Dlm::TurnRight)),
            Dlm::GoForward
        );
        assert_eq!(
            "first_turn".parse::<DlmMeasure>(),
            Ok(DlmMeasure::FirstTurn)
        );
        assert_eq!(DlmMeasure::FirstTurn.as_str(), "first_turn");
        assert!(DlmMeasure::FirstTurn.uses_route() && !DlmMeasure::Heading.uses_route());
    }

    #[test]
    fn measured_in_the_robot_frame() {
        // The path runs north; a robot facing east must turn left onto it, one facing west right.
        let path = arc(Pose2D::new(0.0, 0.0, FRAC_PI_2), 0.0, 5.0, 0.05);
        assert_eq!(
            dlm_from_path(&path, Pose2D::new(0.0, 0.0, 0.0), &params()),
            Dlm::TurnLeft
        );
        assert_eq!(
            dlm_from_path(&path, Pose2D::new(0.0, 0.0, PI), &params()),
            Dlm::TurnRight
        );
        // Straight behind: a turn, not forward.
        let behind = dlm_from_path(&path, Pose2D::new(0.0, 0.0, -FRAC_PI_2), &params());
        assert_eq!(behind, Dlm::TurnLeft);
    }

    #[test]
    fn heading_measure_turns_where_the_route_turns_and_not_for_a_wiggle() {
        let h = DlmParams::heading();
        let straight = arc(Pose2D::new(1.0, 2.0, 0.7), 0.0, 10.0, 0.05);
        assert_eq!(dlm_from_path(&straight, straight[0], &h), Dlm::GoForward);
        let left = arc(Pose2D::new(0.0, 0.0, -2.0), 1.0, 5.0, 0.05);
        assert_eq!(dlm_from_path(&left, left[0], &h), Dlm::TurnLeft);
        let right = arc(Pose2D::new(0.0, 0.0, 2.0), -1.0, 5.0, 0.05);
        assert_eq!(dlm_from_path(&right, right[0], &h), Dlm::TurnRight);
        // The curvature measure calls a 0.4/m curve a turn; over the chord 1-2 m ahead it
        // turns 0.6 rad, short of the 0.8 rad threshold.
        let gentle = arc(Pose2D::new(0.0, 0.0, 0.0), 0.4, 5.0, 0.05);
        assert_eq!(dlm_from_path(&gentle, gentle[0], &params()), Dlm::TurnLeft);
        assert_eq!(dlm_from_path(&gentle, gentle[0], &h), Dlm::GoForward);
        // A 20 cm S-wiggle in the first metre, then straight on: forward (the curvature
        // measure's point 1.5 m ahead lies 0.2 m aside).
        let mut wiggle = arc(Pose2D::new(0.0, 0.0, 0.0), 0.8, 0.5, 0.05);
        let mid = wiggle[wiggle.len() - 1];
        wiggle.extend_from_slice(&arc(mid, -0.8, 0.5, 0.05)[1..]);
        let end = wiggle[wiggle.len() - 1];
        wiggle.extend_from_slice(&arc(end, 0.0, 5.0, 0.05)[1..]);
        assert_eq!(dlm_from_path(&wiggle, wiggle[0], &h), Dlm::GoForward);
    }

    #[test]
    fn heading_measure_holds_a_turn_until_the_release_angle() {
        let h = DlmParams::heading();
        // The path runs east; the robot faces 0.7 rad left of it: between release (0.6) and
        // threshold (0.8).
        let path = arc(Pose2D::new(0.0, 0.0, 0.0), 0.0, 5.0, 0.05);
        let robot = Pose2D::new(0.0, 0.0, 0.7);
        assert_eq!(next_dlm(&path, robot, &h, None), Dlm::GoForward);
        assert_eq!(
            next_dlm(&path, robot, &h, Some(Dlm::GoForward)),
            Dlm::GoForward
        );
        assert_eq!(
            next_dlm(&path, robot, &h, Some(Dlm::TurnRight)),
            Dlm::TurnRight
        );
        // A turn to the other side is not held.
        assert_eq!(
            next_dlm(&path, robot, &h, Some(Dlm::TurnLeft)),
            Dlm::GoForward
        );
        // Past the release angle it ends.
        let nearly = Pose2D::new(0.0, 0.0, 0.5);
        assert_eq!(
            next_dlm(&path, nearly, &h, Some(Dlm::TurnRight)),
            Dlm::GoForward
        );
        // The curvature measure has no hysteresis.
        assert_eq!(
            next_dlm(&path, nearly, &params(), Some(Dlm::TurnRight)),
            dlm_from_path(&path, nearly, &params())
        );
    }

    #[test]
    fn heading_measure_in_the_robot_frame_and_at_the_goal() {
        let h = DlmParams::heading();
        let path = arc(Pose2D::new(0.0, 0.0, FRAC_PI_2), 0.0, 5.0, 0.05);
        assert_eq!(
            dlm_from_path(&path, Pose2D::new(0.0, 0.0, 0.0), &h),
            Dlm::TurnLeft
        );
        assert_eq!(
            dlm_from_path(&path, Pose2D::new(0.0, 0.0, PI), &h),
            Dlm::TurnRight
        );
        assert_eq!(
            dlm_from_path(&path, Pose2D::new(0.0, 0.0, -FRAC_PI_2), &h),
            Dlm::TurnLeft
        );
        // 1.2 m before the end the chord is cut short: the direction to the end decides.
        let near = path[path.len() - 25];
        assert_eq!(dlm_from_path(&path, near, &h), Dlm::GoForward);
        let beside = Pose2D::new(near.x_m, near.y_m, 0.0);
        assert_eq!(dlm_from_path(&path, beside, &h), Dlm::TurnLeft);
        assert_eq!(dlm_from_path(&path, path[path.len() - 4], &h), Dlm::Stop);
    }

    #[test]
    fn route_measure_turns_on_the_route_and_stops_on_the_path() {
        let r = DlmParams {
            measure: DlmMeasure::Route,
            ..DlmParams::heading()
        };
        // The searched path runs straight east; the floor plan's route bends north 1 m ahead.
        let path = arc(Pose2D::new(0.0, 0.0, 0.0), 0.0, 5.0, 0.05);
        let mut route = arc(Pose2D::new(0.0, 0.0, 0.0), 0.0, 1.0, 0.05);
        route.extend_from_slice(&arc(Pose2D::new(1.0, 0.0, FRAC_PI_2), 0.0, 4.0, 0.05)[1..]);
        let robot = path[0];
        assert_eq!(
            next_dlm_along(&path, Some(&route), robot, &r, None),
            Dlm::TurnLeft
        );
        // Without a route it measures the path, as the heading measure does.
        assert_eq!(next_dlm_along(&path, None, robot, &r, None), Dlm::GoForward);
        // The heading measure ignores a route.
        let h = DlmParams::heading();
        assert_eq!(
            next_dlm_along(&path, Some(&route), robot, &h, None),
            Dlm::GoForward
        );
        // Stop comes from the path: near its end, whatever the route says.
        let near_end = path[path.len() - 3];
        assert_eq!(
            next_dlm_along(&path, Some(&route), near_end, &r, None),
            Dlm::Stop
        );
        assert_eq!("route".parse::<DlmMeasure>().unwrap(), DlmMeasure::Route);
        assert_eq!(DlmMeasure::Route.as_str(), "route");
    }

    #[test]
    fn heading_params_are_checked() {
        DlmParams::heading().validate().unwrap();
        let e = DlmParams {
            turn_release_rad: 0.9,
            ..DlmParams::heading()
        }
        .validate()
        .unwrap_err();
        assert_eq!(e.field, "turn_release_rad");
        let e = DlmParams {
            heading_chord_m: 0.0,
            ..DlmParams::heading()
        }
        .validate()
        .unwrap_err();
        assert_eq!(e.field, "heading_chord_m");
        let parsed: DlmParams =
            toml::from_str("measure = \"heading\"\nturn_threshold_rad = 0.9").unwrap();
        assert_eq!(parsed.measure, DlmMeasure::Heading);
        assert!(toml::from_str::<DlmParams>("measure = \"bogus\"").is_err());
    }

    #[test]
    fn stop_near_the_goal() {
        let path = arc(Pose2D::new(0.0, 0.0, 0.0), 0.0, 3.0, 0.05);
        let near = path[path.len() - 4]; // 0.15 m before the end
        assert_eq!(dlm_from_path(&path, near, &params()), Dlm::Stop);
        let far = path[path.len() - 20]; // 0.95 m before the end
        assert_eq!(dlm_from_path(&path, far, &params()), Dlm::GoForward);
        assert_eq!(
            dlm_from_path(&[], Pose2D::new(0.0, 0.0, 0.0), &params()),
            Dlm::Stop
        );
        let tight = DlmParams {
            stop_distance_m: 1.0,
            ..params()
        };
        assert_eq!(dlm_from_path(&path, far, &tight), Dlm::Stop);
    }

    #[test]
    fn arriving_stop_before_the_goal_but_not_before_a_turn() {
        let arrive = DlmParams {
            arrive_distance_m: 1.5,
            ..DlmParams::as_before()
        };
        // 3 m straight, then 1.2 m of a left turn of 0.5 m radius (2.4 rad).
        let mut path = arc(Pose2D::new(0.0, 0.0, 0.0), 0.0, 3.0, 0.05);
        let end = *path.last().unwrap();
        path.extend(arc(end, 2.0, 1.2, 0.05).into_iter().skip(1));
        let straight = arc(Pose2D::new(0.0, 0.0, 0.0), 0.0, 3.0, 0.05);
        let at = |p: &[Pose2D], left: usize| p[p.len() - 1 - left];
        // 1.0 m before a straight path's end: arriving, not resting; 2.0 m: still going.
        let near = at(&straight, 20);
        let dlm = next_dlm_along(&straight, Some(&straight), near, &arrive, None);
        assert_eq!(dlm, Dlm::Stop);
        assert!(is_arriving(dlm, &straight, near, &arrive));
        assert_eq!(
            next_dlm_along(&straight, Some(&straight), at(&straight, 40), &arrive, None),
            Dlm::GoForward
        );
        // Within stop_distance_m the Stop is a rest.
        let there = at(&straight, 4);
        let dlm = next_dlm_along(&straight, Some(&straight), there, &arrive, None);
        assert_eq!(dlm, Dlm::Stop);
        assert!(!is_arriving(dlm, &straight, there, &arrive));
        // Where the last 1.2 m turn: the turn, not arriving.
        let before_turn = at(&path, 24);
        let route = &path[path.len() - 25..];
        assert_eq!(
            next_dlm_along(&path, Some(route), before_turn, &arrive, None),
            Dlm::TurnLeft
        );
        // Without an arrive distance (r5's DLM), 1.0 m before the end is no stop.
        assert_eq!(
            next_dlm_along(
                &straight,
                Some(&straight),
                near,
                &DlmParams::as_before(),
                None
            ),
            Dlm::GoForward
        );
        assert!(!is_arriving(
            Dlm::Stop,
            &straight,
            near,
            &DlmParams::as_before()
        ));
        // The defaults are the shipped DLM-Net r58's: arriving within 2 m, goal within 0.2 rad.
        let shipped = DlmParams::default();
        assert_eq!(
            (shipped.arrive_distance_m, shipped.arrive_bearing_rad),
            (2.0, 0.2)
        );
        assert_eq!(
            next_dlm_along(&straight, Some(&straight), near, &shipped, None),
            Dlm::Stop
        );
        // With a bearing limit: 1 m before the end, 0.3 m off to the right of the line and
        // facing along it, the goal lies 0.29 rad to the left: a turn, held down to 0.1 rad.
        let aimed = DlmParams {
            arrive_bearing_rad: 0.2,
            ..arrive
        };
        let off = Pose2D::new(near.x_m, near.y_m - 0.3, 0.0);
        assert_eq!(
            next_dlm_along(&straight, Some(&straight), off, &aimed, None),
            Dlm::TurnLeft
        );
        let turned = Pose2D::new(off.x_m, off.y_m, 0.15);
        assert_eq!(
            next_dlm_along(
                &straight,
                Some(&straight),
                turned,
                &aimed,
                Some(Dlm::TurnLeft)
            ),
            Dlm::TurnLeft
        );
        assert_eq!(
            next_dlm_along(&straight, Some(&straight), turned, &aimed, Some(Dlm::Stop)),
            Dlm::Stop
        );
        assert_eq!(
            next_dlm_along(&straight, Some(&straight), near, &aimed, None),
            Dlm::Stop
        );
    }

    #[test]
    fn a_robot_facing_a_wall_is_told_the_turn_it_still_needs() {
        use crate::config::PlannerConfig;
        use map_core::{OccupancyGrid, FREE, OCCUPIED};
        // An L: a corridor east along y 1..3 m, then north along x 8..10 m.
        let res = 0.05;
        let (w, h) = (220_u32, 260_u32);
        let mut cells = vec![OCCUPIED; (w * h) as usize];
        for y in 0..h {
            for x in 0..w {
                let (xm, ym) = (f64::from(x) * res, f64::from(y) * res);
                if ((0.5..10.0).contains(&xm) && (1.0..3.0).contains(&ym))
                    || ((8.0..10.0).contains(&xm) && (1.0..12.0).contains(&ym))
                {
                    cells[(y * w + x) as usize] = FREE;
                }
            }
        }
        let grid = OccupancyGrid::new(w, h, res, Pose2D::new(0.0, 0.0, 0.0), cells).unwrap();
        let map = PlanningMap::new(grid, &PlannerConfig::default()).unwrap();
        let goal = Pose2D::new(9.0, 11.0, FRAC_PI_2);
        // In the corner, 0.55 rad right of the way north, so facing the east wall close by.
        let at = Pose2D::new(9.7, 2.0, 0.0);
        let route = floor_plan_route(&map, at, goal, 1.0).unwrap();
        let way_rad = piece_angles_rad(&route, at, &DlmParams::default())[0];
        let robot = Pose2D::new(at.x_m, at.y_m, way_rad - 0.55);
        let ahead_m = map.free_ahead_m(robot, BAND_OF_RADIUS * map.robot_radius_m(), 2.0);
        assert!(ahead_m < 0.9, "{ahead_m}");
        let path = [robot, goal];
        let dlm = |params: &DlmParams, previous| {
            dlm_on_map(&map, &path, robot, goal, params, previous, &[])
        };
        // 0.55 rad is short of the release: forward, turning or not.
        let open = DlmParams::as_before();
        assert_eq!(dlm(&open, None), Dlm::GoForward);
        assert_eq!(dlm(&open, Some(Dlm::TurnLeft)), Dlm::GoForward);
        // Blocked within 0.9 m: the turn starts, and holds.
        let blocked = DlmParams {
            blocked_ahead_m: 0.9,
            ..DlmParams::as_before()
        };
        assert_eq!(dlm(&blocked, None), Dlm::TurnLeft);
        assert_eq!(dlm(&blocked, Some(Dlm::TurnLeft)), Dlm::TurnLeft);
        // Facing the way north (nothing ahead within 0.9 m): forward again.
        let turned = Pose2D::new(at.x_m, at.y_m, way_rad - 0.1);
        assert!(map.free_ahead_m(turned, 0.15, 0.9) >= 0.9);
        let path = [turned, goal];
        assert_eq!(
            dlm_on_map(
                &map,
                &path,
                turned,
                goal,
                &blocked,
                Some(Dlm::TurnLeft),
                &[]
            ),
            Dlm::GoForward
        );
        // Not wider than the release, while on.
        let bad = DlmParams {
            blocked_turn_rad: 0.7,
            ..blocked
        };
        assert_eq!(bad.validate().unwrap_err().field, "blocked_turn_rad");
        // Off, a release below blocked_turn_rad is no error.
        let narrow_release = DlmParams {
            turn_release_rad: 0.1,
            ..DlmParams::as_before()
        };
        narrow_release.validate().unwrap();
    }
}
