//! Hybrid A* (Dolgov, Thrun, Montemerlo, Diebel 2010) for a differential-drive robot.
//!
//! States are continuous (x, y, yaw) in the grid frame; the closed set is a lattice of
//! `xy_resolution_m` cells and `heading_bins` headings, and a lattice cell keeps the first
//! (cheapest) continuous state that reaches it. Motion primitives: forward arcs of curvature
//! 0, ±1/(2 R) and ±1/R (R = minimum turning radius), the same in reverse when enabled, and
//! turns in place when enabled, each with its cost in metres. The heuristic is
//! max(non-holonomic distance without obstacles, 2-D distance with obstacles); the latter is
//! the per-goal cached [`super::heuristic::ObstacleHeuristic`]. Analytic expansion tries a
//! collision-checked Dubins curve to the goal (for a goal whose heading is free, to another
//! heading where the one planned would loop) every `analytic_expansion_every` expansions and
//! on every expansion near the goal; within two turning radii of it, with turns in place
//! allowed, also a turn to face the goal and a straight line to it, taken where it costs less
//! than the curve (a goal beside or behind the robot, which a Dubins curve loops round). The
//! result is shortcut-smoothed ([`super::smoother`]).
//!
//! A [`Planner`] is one robot's reusable state (node, open and closed buffers keep their
//! capacity between plans); the [`PlanningMap`] it plans on is shared between robots and
//! threads.

use std::collections::{BinaryHeap, HashMap};
use std::f64::consts::{SQRT_2, TAU};
use std::hash::{BuildHasherDefault, Hasher};
use std::sync::{Arc, PoisonError};
use std::time::Instant;

use protocol::{normalize_angle, Pose2D};

use crate::config::PlannerConfig;
use crate::dubins::DubinsPath;
use crate::error::{Endpoint, PlanError};
use crate::heuristic::{MinKey, ObstacleHeuristic};
use crate::map::{Disc, GridPose, PlanningMap};
use crate::path::{Path, PathStats};
use crate::{centring, smoother};

/// Multiply-shift hasher for the lattice keys: SipHash would cost more than the search step.
#[derive(Default)]
struct LatticeHasher(u64);

impl Hasher for LatticeHasher {
    fn finish(&self) -> u64 {
        self.0 ^ (self.0 >> 29)
    }
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_u64(u64::from(b));
        }
    }
    fn write_u64(&mut self, i: u64) {
        self.0 = (self.0.rotate_left(5) ^ i).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    }
}

type LatticeMap = HashMap<u64, BinState, BuildHasherDefault<LatticeHasher>>;

#[derive(Debug, Clone, Copy)]
struct BinState {
    g: f64,
    closed: bool,
}

#[derive(Debug, Clone, Copy)]
struct Primitive {
    /// Signed curvature (1/m), positive to the left.
    curvature: f64,
    /// Signed arc length; negative drives backwards. Zero for a turn in place.
    length_m: f64,
    /// Heading change of a turn in place; zero otherwise.
    rotate_rad: f64,
    cost_m: f64,
    reverse: bool,
}

impl Primitive {
    #[inline]
    fn apply(&self, x: f64, y: f64, yaw: f64, t: f64) -> (f64, f64, f64) {
        if self.rotate_rad != 0.0 {
            return (x, y, yaw + self.rotate_rad * t);
        }
        let s = self.length_m * t;
        if self.curvature.abs() < 1e-12 {
            let (sn, cs) = yaw.sin_cos();
            (x + s * cs, y + s * sn, yaw)
        } else {
            let k = self.curvature;
            let yaw2 = yaw + k * s;
            (
                x + (yaw2.sin() - yaw.sin()) / k,
                y - (yaw2.cos() - yaw.cos()) / k,
                yaw2,
            )
        }
    }
}

#[derive(Debug, Clone, Copy)]
struct Node {
    x: f64,
    y: f64,
    yaw: f64,
    g: f64,
    h_obstacle: f64,
    parent: u32,
    prim: u16,
    reverse: bool,
}

const NO_PARENT: u32 = u32::MAX;
const NO_PRIM: u16 = u16::MAX;
/// Heading step between output poses of a turn in place.
const ROTATION_SAMPLE_RAD: f64 = 0.1;
/// A curve to a free goal's planned heading is given up for one to another heading when it is
/// longer by more than this many turning radii: it hooks round the goal (a U-turn beside it
/// costs about two).
const LOOP_SLACK: f64 = 1.0;
/// End headings tried for a free goal's curve when the one to its planned heading loops.
const FREE_END_HEADINGS: usize = 16;

enum Ending {
    /// The node is within tolerance (position and heading).
    Node(usize),
    /// The node is within position tolerance; turn in place to the goal heading.
    NodeThenRotate(usize),
    /// A collision-free Dubins curve from the node reaches the goal exactly.
    Analytic(usize, DubinsPath),
    /// From the node: a turn in place to face the goal, a straight line to it, and a turn in
    /// place to the goal heading where that is outside the tolerance.
    TurnStraight(usize, TurnStraight),
}

/// The turn–straight–turn connection of [`Ending::TurnStraight`].
#[derive(Debug, Clone, Copy)]
struct TurnStraight {
    /// Heading of the straight line (grid frame).
    bearing_rad: f64,
    length_m: f64,
    /// The final turn in place; zero within the goal heading tolerance.
    final_turn_rad: f64,
    /// In the search's metres: turns at `turn_in_place_cost_m_per_rad`, the line at 1.
    cost_m: f64,
}

/// One robot's planner (see the module docs).
#[derive(Debug)]
pub struct Planner {
    map: Arc<PlanningMap>,
    config: PlannerConfig,
    prims: Vec<Primitive>,
    nodes: Vec<Node>,
    open: BinaryHeap<MinKey>,
    lattice: LatticeMap,
    /// Obstacles on top of the map for the plan under way; set and cleared again by
    /// [`Self::plan_avoiding`], empty otherwise.
    avoid: Vec<Disc>,
    /// The time budget of the plan under way, when not the configured one.
    budget_ms: Option<u64>,
    /// The expansion budget of [`Self::plan_avoiding`], `None` otherwise.
    expansions: Option<u64>,
}

impl Planner {
    /// A planner for one robot on a shared planning map.
    ///
    /// # Errors
    /// [`PlanError::InvalidConfig`] for a bad configuration, [`PlanError::RadiusMismatch`]
    /// when the map was inflated for another robot radius.
    pub fn new(map: Arc<PlanningMap>, config: PlannerConfig) -> Result<Self, PlanError> {
        config.validate()?;
        if (map.robot_radius_m() - config.robot_radius_m).abs() > 1e-9 {
            return Err(PlanError::RadiusMismatch {
                map_m: map.robot_radius_m(),
                config_m: config.robot_radius_m,
            });
        }
        let prims = primitives(&config);
        Ok(Self {
            map,
            config,
            prims,
            nodes: Vec::new(),
            open: BinaryHeap::new(),
            lattice: LatticeMap::default(),
            avoid: Vec::new(),
            budget_ms: None,
            expansions: None,
        })
    }

    #[must_use]
    pub fn config(&self) -> &PlannerConfig {
        &self.config
    }

    #[must_use]
    pub fn map(&self) -> &Arc<PlanningMap> {
        &self.map
    }

    /// Replaces the map (a new map version); the search buffers are kept.
    ///
    /// # Errors
    /// [`PlanError::RadiusMismatch`] when the map was inflated for another robot radius.
    pub fn set_map(&mut self, map: Arc<PlanningMap>) -> Result<(), PlanError> {
        if (map.robot_radius_m() - self.config.robot_radius_m).abs() > 1e-9 {
            return Err(PlanError::RadiusMismatch {
                map_m: map.robot_radius_m(),
                config_m: self.config.robot_radius_m,
            });
        }
        self.map = map;
        Ok(())
    }

    fn lattice_key(&self, x: f64, y: f64, yaw: f64) -> u64 {
        let r = self.config.xy_resolution_m;
        let bins = f64::from(self.config.heading_bins);
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let (cx, cy) = (
            (x / r).floor().max(0.0) as u64,
            (y / r).floor().max(0.0) as u64,
        );
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let bin = ((yaw.rem_euclid(TAU) / TAU * bins).round() as u64)
            % u64::from(self.config.heading_bins);
        (cx << 40) | (cy << 16) | bin
    }

    fn obstacle_h(&self, heur: &mut ObstacleHeuristic, x: f64, y: f64) -> f64 {
        let coarse = self.map.coarse();
        let d = heur.distance_cells(coarse, self.map.coarse_cell(x, y));
        if d.is_infinite() {
            f64::INFINITY
        } else {
            // Both ends may lie anywhere in their coarse cells.
            ((f64::from(d) - SQRT_2) * coarse.cell_m).max(0.0)
        }
    }

    fn holonomic_h(&self, x: f64, y: f64, yaw: f64, goal: GridPose) -> f64 {
        if self.config.allow_turn_in_place || self.config.allow_reverse {
            // Turning in place (or Reeds-Shepp cusps) can beat Dubins; Euclidean is the
            // bound that stays admissible.
            (goal.x_m - x).hypot(goal.y_m - y)
        } else {
            DubinsPath::shortest(
                (x, y, yaw),
                (goal.x_m, goal.y_m, goal.yaw_rad),
                self.config.min_turning_radius_m,
            )
            .map_or(0.0, |d| d.length_m())
        }
    }

    /// Plans from `start` to `goal` (map frame) on the planner's map within the time budget.
    ///
    /// # Errors
    /// [`PlanError`] with the reason: an endpoint not finite, off the map or in an obstacle
    /// (with its clearance), the goal unreachable (with the states explored), or the budget
    /// exceeded.
    pub fn plan(&mut self, start: Pose2D, goal: Pose2D) -> Result<Path, PlanError> {
        self.plan_inner(start, goal)
    }

    /// [`Self::plan`] keeping out of `discs` (map frame, e.g. other robots) as well as the
    /// map's obstacles, within `budget_ms` and `max_expansions` instead of the configured
    /// budgets (the smaller of the two expansion budgets counts). The obstacle
    /// heuristic still comes from the map alone (the discs only add cost, so it stays
    /// admissible); a disc that closes the way makes the search fail, by exhausting the
    /// reachable states or the budget.
    ///
    /// # Errors
    /// As [`Self::plan`].
    pub fn plan_avoiding(
        &mut self,
        start: Pose2D,
        goal: Pose2D,
        discs: &[Disc],
        budget_ms: u64,
        max_expansions: u64,
    ) -> Result<Path, PlanError> {
        self.avoid = discs
            .iter()
            .map(|d| {
                let c = self.map.to_grid(Pose2D::new(d.x_m, d.y_m, 0.0));
                Disc {
                    x_m: c.x_m,
                    y_m: c.y_m,
                    radius_m: d.radius_m,
                }
            })
            .collect();
        self.budget_ms = Some(budget_ms);
        self.expansions = Some(max_expansions);
        let planned = self.plan_inner(start, goal);
        self.avoid.clear();
        self.budget_ms = None;
        self.expansions = None;
        planned
    }

    fn plan_inner(&mut self, start: Pose2D, goal: Pose2D) -> Result<Path, PlanError> {
        let t0 = Instant::now();
        let map = Arc::clone(&self.map);
        let s = map.check_endpoint(Endpoint::Start, start)?;
        let g = map.check_endpoint(Endpoint::Goal, goal)?;
        let (shared, cache_hit) =
            map.obstacle_heuristic(map.coarse_cell(g.x_m, g.y_m), map.coarse_cell(s.x_m, s.y_m));
        // Held for the whole plan: robots with the same goal take turns, and the search does
        // not pay a lock per heuristic query.
        let mut heur = shared.lock().unwrap_or_else(PoisonError::into_inner);

        let h0 = self.obstacle_h(&mut heur, s.x_m, s.y_m);
        if h0.is_infinite() {
            return Err(PlanError::Unreachable {
                states_expanded: heur.settled(),
                reason: "no 2-D route between start and goal in the inflated map",
            });
        }

        let (ending, expanded) = self.search(&mut heur, s, g, h0, t0)?;
        let settled = heur.settled();
        drop(heur);

        let analytic = matches!(ending, Ending::Analytic(..) | Ending::TurnStraight(..));
        let mut grid_poses = self.reconstruct(&ending, g);
        let raw_length_m = grid_length(&grid_poses);
        if self.config.smooth {
            grid_poses = smoother::shortcut(
                &map,
                &self.avoid,
                &grid_poses,
                self.config.min_turning_radius_m,
                self.config.path_spacing_m,
            );
        }
        grid_poses = centring::centre(
            &map,
            &self.avoid,
            &grid_poses,
            &self.config.centring,
            self.config.min_turning_radius_m,
            self.config.path_spacing_m,
        );
        let mut poses: Vec<Pose2D> = grid_poses.iter().map(|p| map.to_world(*p)).collect();
        if let Some(first) = poses.first_mut() {
            *first = Pose2D::new(start.x_m, start.y_m, normalize_angle(start.yaw_rad));
        }
        let exact_heading = match ending {
            Ending::Node(_) => false,
            Ending::NodeThenRotate(_) => true,
            // A free goal's curve may end in another heading than the one planned.
            Ending::Analytic(_, d) => {
                normalize_angle(d.sample(d.length_m()).2 - g.yaw_rad).abs() < 1e-6
            }
            // Within the heading tolerance it arrives along its line.
            Ending::TurnStraight(_, t) => t.final_turn_rad != 0.0,
        };
        if exact_heading {
            if let Some(last) = poses.last_mut() {
                if last.distance_m(&goal) < 1e-6 {
                    *last = Pose2D::new(goal.x_m, goal.y_m, normalize_angle(goal.yaw_rad));
                }
            }
        }
        let length_m = crate::path::length_of(&poses);
        #[allow(clippy::cast_possible_truncation)]
        let plan_time_us = t0.elapsed().as_micros() as u64;
        Ok(Path {
            poses,
            length_m,
            states_expanded: expanded,
            plan_time_us,
            stats: PathStats {
                heuristic_cache_hit: cache_hit,
                heuristic_cells_settled: settled,
                analytic_expansion: analytic,
                raw_length_m,
            },
        })
    }

    fn search(
        &mut self,
        heur: &mut ObstacleHeuristic,
        s: GridPose,
        goal: GridPose,
        h0: f64,
        t0: Instant,
    ) -> Result<(Ending, u64), PlanError> {
        self.nodes.clear();
        self.open.clear();
        self.lattice.clear();
        let w = self.config.heuristic_weight;
        let budget =
            std::time::Duration::from_millis(self.budget_ms.unwrap_or(self.config.time_budget_ms));
        let max_expansions = self.expansions.map_or(self.config.max_expansions, |e| {
            e.min(self.config.max_expansions)
        });
        let rho = self.config.min_turning_radius_m;
        let goal_q = (goal.x_m, goal.y_m, goal.yaw_rad);

        self.nodes.push(Node {
            x: s.x_m,
            y: s.y_m,
            yaw: s.yaw_rad,
            g: 0.0,
            h_obstacle: h0,
            parent: NO_PARENT,
            prim: NO_PRIM,
            reverse: false,
        });
        self.lattice.insert(
            self.lattice_key(s.x_m, s.y_m, s.yaw_rad),
            BinState {
                g: 0.0,
                closed: false,
            },
        );
        let h_start = h0.max(self.holonomic_h(s.x_m, s.y_m, s.yaw_rad, goal));
        #[allow(clippy::cast_possible_truncation)]
        self.open.push(MinKey::new((w * h_start) as f32, 0));

        let mut expanded = 0u64;
        while let Some(top) = self.open.pop() {
            let ni = top.idx() as usize;
            let n = self.nodes[ni];
            let key = self.lattice_key(n.x, n.y, n.yaw);
            match self.lattice.get_mut(&key) {
                Some(b) if !b.closed && n.g <= b.g + 1e-9 => b.closed = true,
                _ => continue,
            }
            expanded += 1;
            if expanded & 63 == 0 {
                let elapsed = t0.elapsed();
                if elapsed > budget {
                    return Err(budget_error(
                        format!("time budget {} ms", budget.as_millis()),
                        elapsed,
                        expanded,
                    ));
                }
            }
            if expanded > max_expansions {
                return Err(budget_error(
                    format!("max_expansions {max_expansions}"),
                    t0.elapsed(),
                    expanded,
                ));
            }

            // Goal test.
            if (n.x - goal.x_m).hypot(n.y - goal.y_m) <= self.config.goal_position_tolerance_m {
                if normalize_angle(n.yaw - goal.yaw_rad).abs() <= self.config.goal_yaw_tolerance_rad
                {
                    return Ok((Ending::Node(ni), expanded));
                }
                if self.config.allow_turn_in_place {
                    return Ok((Ending::NodeThenRotate(ni), expanded));
                }
            }

            // Analytic expansion.
            let near_goal = n.h_obstacle < self.config.analytic_near_goal_m;
            if expanded % u64::from(self.config.analytic_expansion_every) == 1 || near_goal {
                let dubins = self
                    .analytic_curves(&n, goal_q, rho)
                    .into_iter()
                    .flatten()
                    .find(|d| {
                        self.map.curve_free_among(
                            &self.avoid,
                            d.length_m(),
                            self.config.path_spacing_m,
                            |t| {
                                let q = d.sample(t);
                                (q.0, q.1)
                            },
                        )
                    });
                // Near the goal a differential drive can also turn to face it and drive
                // straight there: where that costs less than the Dubins curve (a goal beside
                // or behind the robot, closer than a turning circle), the curve would loop
                // round it (task B's last goal, passed 0.4 m to its side: a 4 m loop).
                let turn_straight = near_goal
                    .then(|| self.turn_straight(&n, goal))
                    .flatten()
                    .filter(|t| dubins.as_ref().is_none_or(|d| t.cost_m < d.length_m()));
                if let Some(t) = turn_straight {
                    return Ok((Ending::TurnStraight(ni, t), expanded));
                }
                if let Some(d) = dubins {
                    return Ok((Ending::Analytic(ni, d), expanded));
                }
            }

            // Successors.
            for pi in 0..self.prims.len() {
                let prim = self.prims[pi];
                let (x2, y2, yaw2) = prim.apply(n.x, n.y, n.yaw, 1.0);
                let (cx, cy) = self.map.cell_of(x2, y2);
                if !self.map.grid().contains(cx, cy) {
                    continue;
                }
                let key2 = self.lattice_key(x2, y2, yaw2);
                if key2 == key {
                    continue;
                }
                let mut cost = prim.cost_m;
                if ni != 0 && prim.reverse != n.reverse && prim.rotate_rad == 0.0 {
                    cost += self.config.direction_switch_cost_m;
                }
                let g2 = n.g + cost;
                if let Some(b) = self.lattice.get(&key2) {
                    if b.closed || b.g <= g2 {
                        continue;
                    }
                }
                if prim.rotate_rad == 0.0 {
                    let free = self.map.curve_free_among(
                        &self.avoid,
                        prim.length_m.abs(),
                        self.config.path_spacing_m,
                        |t| {
                            let q = prim.apply(n.x, n.y, n.yaw, t / prim.length_m.abs());
                            (q.0, q.1)
                        },
                    );
                    if !free {
                        continue;
                    }
                }
                let h_obstacle = if prim.rotate_rad == 0.0 {
                    self.obstacle_h(heur, x2, y2)
                } else {
                    n.h_obstacle
                };
                if h_obstacle.is_infinite() {
                    continue;
                }
                let h = h_obstacle.max(self.holonomic_h(x2, y2, yaw2, goal));
                self.lattice.insert(
                    key2,
                    BinState {
                        g: g2,
                        closed: false,
                    },
                );
                let reverse = if prim.rotate_rad == 0.0 {
                    prim.reverse
                } else {
                    n.reverse
                };
                #[allow(clippy::cast_possible_truncation)]
                let idx = self.nodes.len() as u32;
                self.nodes.push(Node {
                    x: x2,
                    y: y2,
                    yaw: normalize_angle(yaw2),
                    g: g2,
                    h_obstacle,
                    #[allow(clippy::cast_possible_truncation)]
                    parent: ni as u32,
                    #[allow(clippy::cast_possible_truncation)]
                    prim: pi as u16,
                    reverse,
                });
                #[allow(clippy::cast_possible_truncation)]
                self.open.push(MinKey::new((g2 + w * h) as f32, idx));
            }
        }
        Err(PlanError::Unreachable {
            states_expanded: expanded,
            reason: "hybrid A* search space exhausted",
        })
    }

    /// The Dubins curves the analytic expansion tries from node `n`, in order: the one to the
    /// goal's heading, unless the goal's heading is free (`goal_yaw_tolerance_rad` at least
    /// π: a task goal without a heading, planned with its leg's heading) and the shortest
    /// curve to any of [`FREE_END_HEADINGS`] headings is shorter than it by more than
    /// [`LOOP_SLACK`] turning radii: then that one comes first, the leg's heading second. A robot
    /// that came through a door beside the goal, not along the leg from the goal before, was
    /// otherwise planned round the goal to arrive in the leg's heading, and a camera-driven
    /// network told to turn round it circled it (task D's last goal, docs/evaluation.md
    /// round 54). Elsewhere the leg's heading stands, so that the next leg starts ahead.
    fn analytic_curves(
        &self,
        n: &Node,
        goal_q: (f64, f64, f64),
        rho: f64,
    ) -> [Option<DubinsPath>; 2] {
        let q0 = (n.x, n.y, n.yaw);
        let to_heading = DubinsPath::shortest(q0, goal_q, rho);
        if self.config.goal_yaw_tolerance_rad < std::f64::consts::PI {
            return [to_heading, None];
        }
        let slack_m = LOOP_SLACK * rho;
        let straight_m = (goal_q.0 - n.x).hypot(goal_q.1 - n.y);
        // The straight distance bounds every curve from below: a curve to the leg's heading
        // within the slack of it cannot lose by more to any other.
        if to_heading
            .as_ref()
            .is_some_and(|d| d.length_m() <= straight_m + slack_m)
        {
            return [to_heading, None];
        }
        let bearing_rad = (goal_q.1 - n.y).atan2(goal_q.0 - n.x);
        #[allow(clippy::cast_precision_loss)]
        let free = (0..FREE_END_HEADINGS)
            .map(|k| k as f64 * TAU / FREE_END_HEADINGS as f64)
            .chain(std::iter::once(bearing_rad))
            .filter_map(|yaw| DubinsPath::shortest(q0, (goal_q.0, goal_q.1, yaw), rho))
            .min_by(|a, b| a.length_m().total_cmp(&b.length_m()));
        match (to_heading, free) {
            (Some(d), Some(f)) if f.length_m() + slack_m < d.length_m() => [Some(f), Some(d)],
            (None, f) => [f, None],
            (d, _) => [d, None],
        }
    }

    /// The [`TurnStraight`] connection from node `n` to `goal` when turns in place and the
    /// connection are allowed (`analytic_turn_straight`), the goal is within two turning radii
    /// and the straight line is free.
    fn turn_straight(&self, n: &Node, goal: GridPose) -> Option<TurnStraight> {
        let c = &self.config;
        let length_m = (goal.x_m - n.x).hypot(goal.y_m - n.y);
        // Only within a turning circle's width of the goal, where a curve would loop: further
        // out a straight shot cuts past door frames and the planning map's unseen glass at
        // the robot's bare radius where the search's path keeps to the middle (the dynamic
        // window on task B: 12 glass contacts in 20 runs with shots from 4 m, 4 without).
        if !(c.allow_turn_in_place && c.analytic_turn_straight)
            || length_m < 1e-6
            || length_m > 2.0 * c.min_turning_radius_m
        {
            return None;
        }
        let bearing_rad = (goal.y_m - n.y).atan2(goal.x_m - n.x);
        let first_turn_rad = normalize_angle(bearing_rad - n.yaw);
        let final_turn_rad = normalize_angle(goal.yaw_rad - bearing_rad);
        let final_turn_rad = if final_turn_rad.abs() <= c.goal_yaw_tolerance_rad {
            0.0
        } else {
            final_turn_rad
        };
        let (cos, sin) = (bearing_rad.cos(), bearing_rad.sin());
        self.map
            .curve_free_among(&self.avoid, length_m, c.path_spacing_m, |t| {
                (n.x + t * cos, n.y + t * sin)
            })
            .then_some(TurnStraight {
                bearing_rad,
                length_m,
                final_turn_rad,
                cost_m: length_m
                    + c.turn_in_place_cost_m_per_rad
                        * (first_turn_rad.abs() + final_turn_rad.abs()),
            })
    }

    /// Grid-frame poses from the start to the end of the search, `path_spacing_m` apart.
    fn reconstruct(&self, ending: &Ending, goal: GridPose) -> Vec<GridPose> {
        let last = match ending {
            Ending::Node(i)
            | Ending::NodeThenRotate(i)
            | Ending::Analytic(i, _)
            | Ending::TurnStraight(i, _) => *i,
        };
        let mut chain = Vec::new();
        let mut i = last;
        loop {
            chain.push(i);
            let p = self.nodes[i].parent;
            if p == NO_PARENT {
                break;
            }
            i = p as usize;
        }
        chain.reverse();
        let spacing = self.config.path_spacing_m;
        let first = self.nodes[chain[0]];
        let mut out = vec![GridPose {
            x_m: first.x,
            y_m: first.y,
            yaw_rad: first.yaw,
        }];
        for pair in chain.windows(2) {
            let a = self.nodes[pair[0]];
            let b = self.nodes[pair[1]];
            let prim = self.prims[usize::from(b.prim)];
            let steps = if prim.rotate_rad == 0.0 {
                (prim.length_m.abs() / spacing).ceil().max(1.0)
            } else {
                (prim.rotate_rad.abs() / ROTATION_SAMPLE_RAD)
                    .ceil()
                    .max(1.0)
            };
            #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
            let n = steps as u32;
            for j in 1..=n {
                let q = prim.apply(a.x, a.y, a.yaw, f64::from(j) / steps);
                out.push(GridPose {
                    x_m: q.0,
                    y_m: q.1,
                    yaw_rad: normalize_angle(q.2),
                });
            }
        }
        match ending {
            Ending::Node(_) => {}
            Ending::NodeThenRotate(_) => turn_in_place(&mut out, goal, goal.yaw_rad),
            Ending::TurnStraight(_, t) => {
                turn_in_place(&mut out, goal, t.bearing_rad);
                let from = out.last().copied().unwrap_or(goal);
                let steps = (t.length_m / spacing).ceil().max(1.0);
                #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
                for j in 1..=(steps as u32) {
                    let s = t.length_m * f64::from(j) / steps;
                    out.push(GridPose {
                        x_m: from.x_m + s * t.bearing_rad.cos(),
                        y_m: from.y_m + s * t.bearing_rad.sin(),
                        yaw_rad: t.bearing_rad,
                    });
                }
                if t.final_turn_rad != 0.0 {
                    turn_in_place(&mut out, goal, goal.yaw_rad);
                }
            }
            Ending::Analytic(_, d) => {
                let len = d.length_m();
                let steps = (len / spacing).ceil().max(1.0);
                #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
                for j in 1..=(steps as u32) {
                    let q = d.sample(len * f64::from(j) / steps);
                    out.push(GridPose {
                        x_m: q.0,
                        y_m: q.1,
                        yaw_rad: normalize_angle(q.2),
                    });
                }
            }
        }
        out
    }
}

/// Appends a turn in place from the last pose of `out` (`fallback` when empty) to `yaw_rad`,
/// at most 0.9 [`ROTATION_SAMPLE_RAD`] apart: centring may later bend the heading of the pose
/// the turn starts from by a little (a straight line moved off a wall), and the turn's first
/// step must stay within the sample.
fn turn_in_place(out: &mut Vec<GridPose>, fallback: GridPose, yaw_rad: f64) {
    let from = out.last().copied().unwrap_or(fallback);
    let d = normalize_angle(yaw_rad - from.yaw_rad);
    if d == 0.0 {
        return;
    }
    let steps = (d.abs() / (0.9 * ROTATION_SAMPLE_RAD)).ceil().max(1.0);
    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
    for j in 1..=(steps as u32) {
        out.push(GridPose {
            x_m: from.x_m,
            y_m: from.y_m,
            yaw_rad: normalize_angle(from.yaw_rad + d * f64::from(j) / steps),
        });
    }
}

fn budget_error(limit: String, elapsed: std::time::Duration, expanded: u64) -> PlanError {
    #[allow(clippy::cast_possible_truncation)]
    let elapsed_ms = elapsed.as_millis() as u64;
    PlanError::BudgetExceeded {
        limit,
        elapsed_ms,
        states_expanded: expanded,
    }
}

fn grid_length(poses: &[GridPose]) -> f64 {
    poses
        .windows(2)
        .map(|w| (w[1].x_m - w[0].x_m).hypot(w[1].y_m - w[0].y_m))
        .sum()
}

fn primitives(c: &PlannerConfig) -> Vec<Primitive> {
    let k = 1.0 / c.min_turning_radius_m;
    let mut out = Vec::new();
    let mut directions = vec![false];
    if c.allow_reverse {
        directions.push(true);
    }
    for reverse in directions {
        for curvature in [0.0, k * 0.5, -k * 0.5, k, -k] {
            let mut cost = c.step_m;
            if curvature != 0.0 {
                cost *= c.turn_cost_factor;
            }
            if reverse {
                cost *= c.reverse_cost_factor;
            }
            out.push(Primitive {
                curvature,
                length_m: if reverse { -c.step_m } else { c.step_m },
                rotate_rad: 0.0,
                cost_m: cost,
                reverse,
            });
        }
    }
    if c.allow_turn_in_place {
        for rotate_rad in [c.turn_in_place_step_rad, -c.turn_in_place_step_rad] {
            out.push(Primitive {
                curvature: 0.0,
                length_m: 0.0,
                rotate_rad,
                cost_m: c.turn_in_place_cost_m_per_rad * c.turn_in_place_step_rad,
                reverse: false,
            });
        }
    }
    out
}
