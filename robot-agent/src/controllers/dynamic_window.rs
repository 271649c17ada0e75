//! The dynamic window approach (Fox, Burgard & Thrun 1997) on the laser scan and the planned
//! path: the paper's baseline and the expert whose demonstrations train the intention-nets.
//!
//! Each cycle searches the velocities reachable within one cycle from the current ones (the
//! *dynamic window*) for the one that maximizes
//! `heading + progress + clearance + velocity` (weighted), where
//! - heading and progress look at where the arc puts the robot after `horizon_s` relative to a
//!   look-ahead point on the planned path (Fox's heading term, with a path instead of a goal),
//! - clearance is Fox's `dist(v, ω)`: how far the robot can travel along the arc's curvature
//!   before its disc (radius plus margin) touches a scan point, capped,
//! - velocity prefers driving fast.
//!
//! Arcs on which the robot could not brake before touching an obstacle (one cycle at (v, ω),
//! then full deceleration along the arc) are not admissible. If none is, it brakes as hard as the
//! window allows (from the lower of the measured and the last commanded speed), steering along
//! the freest arc. The robot never reverses.
//!
//! One addition to Fox: an obstacle lying on the path (the floor plan does not show it, so the
//! planner's path runs through it) hides the look-ahead point, and heading straight for it traps
//! plain Fox in front of the obstacle. A small navigation function on the scan around the robot
//! (after Brock & Khatib's global dynamic window, 1999) then supplies a detour point to head
//! for, with hysteresis so that the robot keeps to the side it chose. The same holds for a robot
//! standing inside the inflation beside a wall's end with its path round the end: the function
//! starts from the way out of the inflation, and the look-ahead point counts as hidden when the
//! line to it stays inside the inflation beyond the robot's own depth in it.
//!
//! A second: with the goal in straight sight within the look-ahead distance, the robot heads for
//! the goal itself, no faster than lets it turn into it, and clearance counts only as far as the
//! goal. The planner's path to a goal closer than its minimum turning radius allows loops round,
//! and following that loop at speed circled the goal just outside the tolerance.

use map_core::search::{MinCost, NEIGHBOURS_8};
use protocol::normalize_angle;

use super::path_tracker::{check_non_negative, check_positive};
use super::path_tracker::{checked_task, goal_speed_cap, to_robot_frame, window};
use super::{Control, ControlInput, Controller, ControllerError};
use crate::config::{ConfigError, ControllerKind};

const NAME: &str = "dynamic-window";

/// Dynamic window parameters (TOML table `[dynamic_window]`, see `controllers.example.toml`).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DynamicWindowConfig {
    /// Radius of the robot's disc footprint (a Pioneer 3-DX is about 0.25 m).
    pub robot_radius_m: f64,
    /// Extra distance kept from every scan point, for range noise and the cycle's latency.
    pub safety_margin_m: f64,
    /// Speeds sampled across the window (at least 2).
    pub v_samples: u32,
    /// Turn rates sampled across the window (at least 2).
    pub omega_samples: u32,
    /// Time over which an arc is followed to judge its heading and progress.
    pub horizon_s: f64,
    /// Arc length along which collisions are looked for; longer free arcs score no better.
    pub clearance_cap_m: f64,
    /// Spacing of the collision checks along an arc.
    pub arc_step_m: f64,
    /// Distance along the path, from the point nearest to the robot, to the point it heads for.
    pub lookahead_m: f64,
    /// The goal (last path pose) counts as reached within this distance: the command is then 0.
    pub goal_tolerance_m: f64,
    /// Cell size of the local navigation function around the robot (0 turns it off: plain Fox,
    /// heading straight for the look-ahead point).
    pub local_grid_resolution_m: f64,
    /// Weight of the heading towards the look-ahead point at the arc's end (Fox's α).
    pub heading_weight: f64,
    /// Weight of the distance gained towards the look-ahead point.
    pub progress_weight: f64,
    /// Weight of the free arc length (Fox's β).
    pub clearance_weight: f64,
    /// Weight of the forward speed (Fox's γ).
    pub velocity_weight: f64,
}

impl Default for DynamicWindowConfig {
    fn default() -> Self {
        Self {
            robot_radius_m: 0.25,
            safety_margin_m: 0.1,
            v_samples: 11,
            omega_samples: 21,
            horizon_s: 1.5,
            clearance_cap_m: 2.0,
            arc_step_m: 0.05,
            lookahead_m: 1.5,
            goal_tolerance_m: 0.2,
            local_grid_resolution_m: 0.1,
            heading_weight: 0.6,
            progress_weight: 0.5,
            clearance_weight: 1.0,
            velocity_weight: 0.3,
        }
    }
}

impl DynamicWindowConfig {
    /// Checks ranges that serde cannot express.
    ///
    /// # Errors
    /// [`ConfigError::Invalid`] naming the first bad field and its value.
    pub fn validate(&self) -> Result<(), ConfigError> {
        check_positive(&[
            ("dynamic_window.robot_radius_m", self.robot_radius_m),
            ("dynamic_window.horizon_s", self.horizon_s),
            ("dynamic_window.clearance_cap_m", self.clearance_cap_m),
            ("dynamic_window.arc_step_m", self.arc_step_m),
            ("dynamic_window.lookahead_m", self.lookahead_m),
            ("dynamic_window.goal_tolerance_m", self.goal_tolerance_m),
        ])?;
        check_non_negative(&[
            ("dynamic_window.safety_margin_m", self.safety_margin_m),
            (
                "dynamic_window.local_grid_resolution_m",
                self.local_grid_resolution_m,
            ),
            ("dynamic_window.heading_weight", self.heading_weight),
            ("dynamic_window.progress_weight", self.progress_weight),
            ("dynamic_window.clearance_weight", self.clearance_weight),
            ("dynamic_window.velocity_weight", self.velocity_weight),
        ])?;
        for (field, n) in [
            ("dynamic_window.v_samples", self.v_samples),
            ("dynamic_window.omega_samples", self.omega_samples),
        ] {
            if !(2..=201).contains(&n) {
                return Err(ConfigError::Invalid {
                    field,
                    value: n.to_string(),
                    reason: "must be between 2 and 201",
                });
            }
        }
        if self.local_grid_resolution_m > 0.0 && self.local_grid_resolution_m < 0.02 {
            return Err(ConfigError::Invalid {
                field: "dynamic_window.local_grid_resolution_m",
                value: self.local_grid_resolution_m.to_string(),
                reason: "must be 0 (off) or at least 0.02",
            });
        }
        if self.arc_step_m > self.clearance_cap_m {
            return Err(ConfigError::Invalid {
                field: "dynamic_window.arc_step_m",
                value: self.arc_step_m.to_string(),
                reason: "must not exceed dynamic_window.clearance_cap_m",
            });
        }
        Ok(())
    }
}

/// What the last cycle chose and why (for logs, tests and demonstrations).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Choice {
    pub v_mps: f64,
    pub omega_radps: f64,
    /// Total weighted score of the chosen arc (NaN when braking with no admissible arc).
    pub score: f64,
    /// Free arc length along the chosen arc's curvature (infinite: nothing within the cap).
    pub free_m: f64,
    /// Arcs evaluated, and how many of them the robot could brake on in time.
    pub candidates: usize,
    pub admissible: usize,
    /// The point headed for, in the robot frame: the look-ahead point on the path, or the
    /// detour point around an obstacle that hides it.
    pub target_m: (f64, f64),
}

/// Fox, Burgard & Thrun's dynamic window approach, following the planned path.
#[derive(Debug, Clone)]
pub struct DynamicWindow {
    config: DynamicWindowConfig,
    /// Scan points in the robot frame that any arc could reach (scratch, reused per cycle).
    points: Vec<[f64; 2]>,
    omegas: Vec<f64>,
    nav: NavGrid,
    /// Path points (robot frame) and their seed values (scratch).
    samples: Vec<((f64, f64), f64)>,
    /// Where the robot was heading around an obstacle last cycle (map frame).
    carrot: Option<(f64, f64)>,
    last: Option<Choice>,
}

impl DynamicWindow {
    /// A controller with a checked configuration.
    ///
    /// # Errors
    /// [`ConfigError::Invalid`] when a parameter is out of range.
    pub fn new(config: DynamicWindowConfig) -> Result<Self, ConfigError> {
        config.validate()?;
        Ok(Self {
            config,
            points: Vec::new(),
            omegas: Vec::new(),
            nav: NavGrid::default(),
            samples: Vec::new(),
            carrot: None,
            last: None,
        })
    }

    #[must_use]
    pub fn config(&self) -> &DynamicWindowConfig {
        &self.config
    }

    /// The arc chosen in the last cycle that drove (None after a stop or reset).
    #[must_use]
    pub fn last_choice(&self) -> Option<Choice> {
        self.last
    }

    /// Squared distance from (x, y) to the nearest kept scan point.
    fn nearest_sq(&self, x: f64, y: f64) -> f64 {
        self.points
            .iter()
            .map(|p| (p[0] - x) * (p[0] - x) + (p[1] - y) * (p[1] - y))
            .fold(f64::INFINITY, f64::min)
    }

    /// Whether no kept scan point lies within `radius_m` of the segment from the robot to `to`.
    fn line_clear(&self, to: (f64, f64), radius_m: f64) -> bool {
        let len_sq = to.0 * to.0 + to.1 * to.1;
        self.points.iter().all(|p| {
            let t = if len_sq < 1e-18 {
                0.0
            } else {
                ((p[0] * to.0 + p[1] * to.1) / len_sq).clamp(0.0, 1.0)
            };
            let (dx, dy) = (p[0] - t * to.0, p[1] - t * to.1);
            dx * dx + dy * dy >= radius_m * radius_m
        })
    }

    /// Fox's dist(v, ω): arc length along curvature `kappa`, starting at heading `heading_rad`,
    /// before the inflated disc touches a scan point; infinite when nothing does within the cap.
    fn free_distance(&self, kappa: f64, heading_rad: f64, inflated_m: f64, start_sq: f64) -> f64 {
        let c = &self.config;
        // Already inside the inflated disc (noise, a person stepping close): moves that do not get
        // any closer stay allowed, so the robot can drive out instead of freezing.
        let limit_sq = if start_sq < inflated_m * inflated_m {
            let d = (start_sq.sqrt() - 0.01).max(0.0);
            d * d
        } else {
            inflated_m * inflated_m
        };
        let (sh, ch) = heading_rad.sin_cos();
        let steps = (c.clearance_cap_m / c.arc_step_m).ceil() as usize;
        for k in 1..=steps {
            let s = (k as f64 * c.arc_step_m).min(c.clearance_cap_m);
            let (ax, ay, _) = arc_pose(kappa, s);
            let (x, y) = (ch * ax - sh * ay, sh * ax + ch * ay);
            if self.nearest_sq(x, y) < limit_sq {
                return ((k - 1) as f64 * c.arc_step_m).max(0.0);
            }
        }
        f64::INFINITY
    }
}

/// A robot-frame point of `pose` in the map frame.
fn to_map_frame(pose: &protocol::Pose2D, (x, y): (f64, f64)) -> (f64, f64) {
    let (s, c) = pose.yaw_rad.sin_cos();
    (pose.x_m + c * x - s * y, pose.y_m + s * x + c * y)
}

/// The pose after arc length `s_m` along a circle of curvature `kappa` from the origin, heading +x.
#[must_use]
pub fn arc_pose(kappa: f64, s_m: f64) -> (f64, f64, f64) {
    let th = kappa * s_m;
    if kappa.abs() < 1e-9 {
        (s_m, 0.0, 0.0)
    } else {
        (th.sin() / kappa, (1.0 - th.cos()) / kappa, th)
    }
}

/// `n` evenly spaced values over [lo, hi] (one when the interval is a point).
fn linspace(lo: f64, hi: f64, n: u32) -> impl Iterator<Item = f64> {
    let n = if hi - lo < 1e-12 { 1 } else { n.max(2) };
    (0..n).map(move |i| {
        if n == 1 {
            lo
        } else {
            lo + (hi - lo) * f64::from(i) / f64::from(n - 1)
        }
    })
}

/// A navigation function on a square grid centred on the robot (robot frame): the travel
/// distance, around the inflated scan points, to the planned path, where path points further
/// along start lower. Reused between cycles to avoid allocation.
#[derive(Debug, Clone, Default)]
struct NavGrid {
    n: usize,
    res_m: f64,
    half_m: f64,
    blocked: Vec<bool>,
    value: Vec<f64>,
    heap: std::collections::BinaryHeap<MinCost<f64, usize>>,
    /// How far from the robot blocked cells are its own way out of the inflation it stands in
    /// (how deep it stands, plus a cell's diagonal), not an obstacle in the way.
    leave_m: f64,
}

impl NavGrid {
    fn reset(&mut self, half_m: f64, res_m: f64, depth_m: f64) {
        self.n = (2.0 * half_m / res_m).ceil() as usize;
        self.res_m = res_m;
        self.half_m = half_m;
        self.leave_m = depth_m.max(0.0) + res_m * std::f64::consts::SQRT_2;
        self.blocked.clear();
        self.blocked.resize(self.n * self.n, false);
        self.value.clear();
        self.value.resize(self.n * self.n, f64::INFINITY);
        self.heap.clear();
    }

    /// Continuous cell coordinates of a robot-frame point.
    fn grid(&self, x: f64, y: f64) -> (f64, f64) {
        (
            (x + self.half_m) / self.res_m,
            (y + self.half_m) / self.res_m,
        )
    }

    fn cell(&self, x: f64, y: f64) -> Option<usize> {
        let (gx, gy) = self.grid(x, y);
        let n = self.n as f64;
        if gx < 0.0 || gy < 0.0 || gx >= n || gy >= n {
            return None;
        }
        Some(gy as usize * self.n + gx as usize)
    }

    fn centre(&self, i: usize) -> (f64, f64) {
        let (cx, cy) = (i % self.n, i / self.n);
        (
            (cx as f64 + 0.5) * self.res_m - self.half_m,
            (cy as f64 + 0.5) * self.res_m - self.half_m,
        )
    }

    fn block_disc(&mut self, x: f64, y: f64, radius_m: f64) {
        let (gx, gy) = self.grid(x, y);
        let r = radius_m / self.res_m;
        let n = self.n as f64;
        let (x0, x1) = ((gx - r).floor().max(0.0), (gx + r).ceil().min(n - 1.0));
        let (y0, y1) = ((gy - r).floor().max(0.0), (gy + r).ceil().min(n - 1.0));
        if x0 > x1 || y0 > y1 {
            return;
        }
        for cy in y0 as usize..=y1 as usize {
            for cx in x0 as usize..=x1 as usize {
                let (dx, dy) = (cx as f64 + 0.5 - gx, cy as f64 + 0.5 - gy);
                if dx * dx + dy * dy < r * r {
                    self.blocked[cy * self.n + cx] = true;
                }
            }
        }
    }

    /// Whether the cell under a robot-frame point is free; None off the grid.
    fn is_free(&self, x: f64, y: f64) -> Option<bool> {
        self.cell(x, y).map(|i| !self.blocked[i])
    }

    fn seed(&mut self, x: f64, y: f64, value: f64) {
        if let Some(i) = self.cell(x, y) {
            if !self.blocked[i] && value < self.value[i] {
                self.value[i] = value;
                self.heap.push(MinCost(value, i));
            }
        }
    }

    /// Dijkstra from the seeds over free cells, 8-connected.
    fn propagate(&mut self) {
        let n = self.n as i64;
        let diag = self.res_m * std::f64::consts::SQRT_2;
        while let Some(MinCost(v, i)) = self.heap.pop() {
            if v > self.value[i] {
                continue;
            }
            let (cx, cy) = ((i % self.n) as i64, (i / self.n) as i64);
            for (dx, dy) in NEIGHBOURS_8 {
                let (nx, ny) = (cx + dx, cy + dy);
                if nx < 0 || ny < 0 || nx >= n || ny >= n {
                    continue;
                }
                let j = (ny * n + nx) as usize;
                if self.blocked[j] {
                    continue;
                }
                let nv = v + if dx != 0 && dy != 0 { diag } else { self.res_m };
                if nv < self.value[j] {
                    self.value[j] = nv;
                    self.heap.push(MinCost(nv, j));
                }
            }
        }
    }

    /// Bilinear value at a robot-frame point; infinite off the grid, in the inflation, or where
    /// no path is reachable.
    fn value(&self, x: f64, y: f64) -> f64 {
        let (gx, gy) = self.grid(x, y);
        let (fx, fy) = (gx - 0.5, gy - 0.5);
        let (x0, y0) = (fx.floor(), fy.floor());
        let n = self.n as f64;
        if x0 < 0.0 || y0 < 0.0 || x0 + 1.0 >= n || y0 + 1.0 >= n {
            return self.cell(x, y).map_or(f64::INFINITY, |i| self.value[i]);
        }
        let (tx, ty) = (fx - x0, fy - y0);
        let i = y0 as usize * self.n + x0 as usize;
        let q = [
            self.value[i],
            self.value[i + 1],
            self.value[i + self.n],
            self.value[i + self.n + 1],
        ];
        if q.iter().all(|v| v.is_finite()) {
            (1.0 - ty) * ((1.0 - tx) * q[0] + tx * q[1]) + ty * ((1.0 - tx) * q[2] + tx * q[3])
        } else {
            self.cell(x, y).map_or(f64::INFINITY, |i| self.value[i])
        }
    }

    /// Whether the straight line from the robot to (x, y) crosses no blocked cell. Blocked cells
    /// at the start of the line, within `leave_m`, are skipped: the robot may stand in the
    /// inflation of a close point and must still see the way out. Not further: a line that
    /// leaves the robot along the obstacle, inside its inflation all the way, does not see past
    /// it (task E, 2026-11-29: the robot beside a thin wall's end saw the path round the end
    /// through it, and the window turned it into the end instead of round it).
    fn visible(&self, (x, y): (f64, f64)) -> bool {
        let len = x.hypot(y);
        let steps = (2.0 * len / self.res_m).ceil() as usize;
        let mut leaving = true;
        for k in 0..=steps {
            let f = if steps == 0 {
                1.0
            } else {
                k as f64 / steps as f64
            };
            let blocked = self.cell(f * x, f * y).is_some_and(|i| self.blocked[i]);
            if !blocked {
                leaving = false;
            } else if !leaving || f * len > self.leave_m {
                return false;
            }
        }
        true
    }

    /// Where the function's descent starts: the robot's cell where that has a value; where the
    /// robot stands inside the inflation of a close point (its cell blocked), the free cell
    /// within `leave_m` whose value plus the distance to it is least, the way out of the
    /// inflation. `None` where neither has a value.
    fn way_out(&self) -> Option<usize> {
        let escape_m = self.leave_m;
        let robot = self.cell(0.0, 0.0)?;
        if !self.blocked[robot] {
            return self.value[robot].is_finite().then_some(robot);
        }
        let k = (escape_m / self.res_m).ceil() as i64;
        let (cx, cy) = ((robot % self.n) as i64, (robot / self.n) as i64);
        let n = self.n as i64;
        let mut best: Option<(f64, usize)> = None;
        for dy in -k..=k {
            for dx in -k..=k {
                let (x, y) = (cx + dx, cy + dy);
                if x < 0 || y < 0 || x >= n || y >= n {
                    continue;
                }
                let j = (y * n + x) as usize;
                let d_m = (dx as f64).hypot(dy as f64) * self.res_m;
                if self.blocked[j] || !self.value[j].is_finite() || d_m > escape_m {
                    continue;
                }
                let cost = self.value[j] + d_m;
                if best.is_none_or(|(b, _)| cost < b) {
                    best = Some((cost, j));
                }
            }
        }
        best.map(|(_, j)| j)
    }

    /// Along the steepest descent from the robot (up to `distance_m` of travel; from inside the
    /// inflation, from its way out), the farthest point still in straight sight of the robot.
    fn visible_carrot(&self, distance_m: f64) -> Option<(f64, f64)> {
        let mut i = self.way_out()?;
        let n = self.n as i64;
        let mut travelled = 0.0;
        let mut best = Some(self.centre(i)).filter(|&p| self.visible(p));
        while travelled < distance_m {
            let (cx, cy) = ((i % self.n) as i64, (i / self.n) as i64);
            let mut next = i;
            for (dx, dy) in NEIGHBOURS_8 {
                let (nx, ny) = (cx + dx, cy + dy);
                if nx < 0 || ny < 0 || nx >= n || ny >= n {
                    continue;
                }
                let j = (ny * n + nx) as usize;
                if self.value[j] < self.value[next] {
                    next = j;
                }
            }
            if next == i {
                break;
            }
            let (a, b) = (self.centre(i), self.centre(next));
            travelled += (b.0 - a.0).hypot(b.1 - a.1);
            i = next;
            if self.visible(b) {
                best = Some(b);
            }
        }
        best
    }
}

impl Controller for DynamicWindow {
    fn kind(&self) -> ControllerKind {
        ControllerKind::DynamicWindow
    }

    fn control(&mut self, input: &ControlInput<'_>) -> Result<Control, ControllerError> {
        let c = self.config;
        let Some(task) = checked_task(NAME, input, c.goal_tolerance_m)? else {
            self.last = None;
            return Ok(Control::default());
        };
        let scan = input.scan.ok_or(ControllerError::MissingInput {
            controller: NAME,
            input: "laser scan",
        })?;
        let limits = input.limits;
        let inflated_m = c.robot_radius_m + c.safety_margin_m;

        // Only points that an arc of the cap's length could come near matter.
        let reach_m = c.clearance_cap_m + inflated_m + 0.1;
        self.points.clear();
        self.points
            .extend(super::scan_points(scan, reach_m).map(|(x, y)| [x, y]));
        let start_sq = self.nearest_sq(0.0, 0.0);

        // The dynamic window, within the limits; no reversing.
        let (v_lo, v_hi) = window(
            input.v_mps,
            limits.max_accel_mps2,
            input.dt_s,
            0.0,
            limits.max_speed_mps,
        );
        // Slow down for the goal: the fastest speed from which braking stops the robot there.
        let v_hi = v_hi
            .min(goal_speed_cap(
                task.goal_distance_m,
                c.goal_tolerance_m,
                limits,
            ))
            .max(v_lo);
        let (w_lo, w_hi) = window(
            input.omega_radps,
            limits.max_turn_accel_radps2,
            input.dt_s,
            -limits.max_turn_radps,
            limits.max_turn_radps,
        );
        self.omegas.clear();
        self.omegas.extend(linspace(w_lo, w_hi, c.omega_samples));
        // Driving exactly straight must be possible, or the robot weaves on a straight path.
        if w_lo < 0.0 && w_hi > 0.0 {
            self.omegas.push(0.0);
        }

        let lookahead = to_robot_frame(
            &input.pose,
            task.path.point_ahead(&task.projection, c.lookahead_m),
        );
        let goal = to_robot_frame(&input.pose, task.path.goal());
        let lookahead_is_goal = (goal.0 - lookahead.0).hypot(goal.1 - lookahead.1) < 1e-9;
        // Near the goal the planner's path can loop: a hybrid-A* search from a pose heading past
        // the goal comes round at its minimum turning radius, and a robot following that loop at
        // speed passes the goal just outside the tolerance, replans the same loop and circles.
        // With the goal in straight sight within the look-ahead, head for the goal itself.
        let goal_m = goal.0.hypot(goal.1);
        let goal_in_sight = goal_m < c.lookahead_m && self.line_clear(goal, c.robot_radius_m);
        // Fox's heading aims straight at the look-ahead point, which traps the robot in front of
        // an obstacle lying on the path. A navigation function on the scan around the robot
        // (Brock & Khatib's global dynamic window) knows the way around: when the look-ahead point
        // is out of sight behind an obstacle, the robot heads for the farthest point of the
        // function's descent that it can see. A robot standing inside the inflation of a close
        // point (a controller it relieves left it there) starts the descent from the way out of
        // it: plain Fox would aim it at the look-ahead point beyond the obstacle, where every
        // arc comes closer. Elsewhere (and where the function has no answer) plain Fox remains:
        // the function's 8-connected gradient is too coarse to steer by directly. Heading for
        // the goal in sight needs none.
        let use_nav = !goal_in_sight && c.local_grid_resolution_m > 0.0 && {
            let half_m = c.lookahead_m + c.clearance_cap_m.min(1.0);
            let res = c.local_grid_resolution_m;
            self.nav.reset(half_m, res, inflated_m - start_sq.sqrt());
            for p in &self.points {
                self.nav.block_disc(p[0], p[1], inflated_m);
            }
            // Seed only the path's last unobstructed stretch in the grid: a path point before an
            // obstruction would be a false minimum in front of it.
            let diag_m = 2.0 * half_m * std::f64::consts::SQRT_2;
            self.samples.clear();
            let mut s_m = 0.0;
            while s_m <= diag_m {
                let p = to_robot_frame(&input.pose, task.path.point_ahead(&task.projection, s_m));
                if let Some(free) = self.nav.is_free(p.0, p.1) {
                    if !free {
                        self.samples.clear();
                    } else {
                        self.samples.push((p, diag_m - s_m));
                    }
                }
                if (p.0 - goal.0).hypot(p.1 - goal.1) < 1e-9 {
                    break;
                }
                s_m += 0.5 * res;
            }
            for &(p, v) in &self.samples {
                self.nav.seed(p.0, p.1, v);
            }
            self.nav.propagate();
            self.nav.way_out().is_some()
        };
        let blocked_ahead = use_nav && !self.nav.visible(lookahead);
        let (target, target_is_goal) = if goal_in_sight {
            self.carrot = None;
            (goal, true)
        } else if blocked_ahead {
            let side = |p: (f64, f64)| (lookahead.0 * p.1 - lookahead.1 * p.0).signum();
            let kept = self
                .carrot
                .map(|m| to_robot_frame(&input.pose, m))
                .filter(|&p| {
                    p.0.hypot(p.1) > 3.0 * c.local_grid_resolution_m
                        && self.nav.value(p.0, p.1).is_finite()
                        && self.nav.visible(p)
                });
            let fresh = self
                .nav
                .visible_carrot(2.0 * c.lookahead_m)
                .filter(|p| p.0.hypot(p.1) > 2.0 * c.local_grid_resolution_m);
            // Around an obstacle centred on the path both sides are equally good, and range
            // noise would flip the choice every cycle: stay on the side chosen while it works.
            let chosen = match (kept, fresh) {
                (Some(k), Some(f)) if side(k) != side(f) => Some(k),
                (_, Some(f)) => Some(f),
                (k, None) => k,
            };
            self.carrot = chosen.map(|p| to_map_frame(&input.pose, p));
            match chosen {
                Some(p) => (p, false),
                None => (lookahead, lookahead_is_goal),
            }
        } else {
            self.carrot = None;
            (lookahead, lookahead_is_goal)
        };
        // Slow enough to turn into the goal: the arc tangent to the heading through the goal has
        // radius d² / 2|y|, and a goal behind is turned to on the spot.
        let v_hi = if goal_in_sight {
            let cap_mps = if goal.0 > 0.0 {
                limits.max_turn_radps * goal_m * goal_m / (2.0 * goal.1.abs()).max(1e-9)
            } else {
                0.0
            };
            v_hi.min(cap_mps).max(v_lo)
        } else {
            v_hi
        };
        let start_dist = target.0.hypot(target.1);
        let brake = limits.max_accel_mps2;
        // Room beyond a goal in sight does not matter: the robot stops there. Scored to the cap,
        // turning to a goal that lies before a wall lost to facing the open floor, and a robot
        // relieved just short of a goal behind it never turned round (task C, 2026-11-26).
        let clear_cap_m = if goal_in_sight {
            c.clearance_cap_m.min(goal_m.max(c.arc_step_m))
        } else {
            c.clearance_cap_m
        };
        let progress_scale = limits.max_speed_mps * c.horizon_s;

        let mut best: Option<Choice> = None;
        // Fallback when nothing is admissible: the hardest braking, along the freest arc.
        let mut freest: Option<(f64, f64)> = None;
        let mut candidates = 0;
        let mut admissible = 0;
        for v in linspace(v_lo, v_hi, c.v_samples) {
            for &w in &self.omegas {
                candidates += 1;
                let moving = v > 1e-6;
                let kappa = if moving { w / v } else { 0.0 };
                // Turning on the spot moves no part of a disc robot, so it is always admissible;
                // its clearance is that of driving straight on afterwards, or standing still
                // would look like the safest move and the robot would freeze before obstacles.
                let (free_m, clear_m) = if moving {
                    let f = self.free_distance(kappa, 0.0, inflated_m, start_sq);
                    (f, f)
                } else {
                    let ahead = self.free_distance(0.0, w * c.horizon_s, inflated_m, start_sq);
                    (f64::INFINITY, ahead)
                };
                if v == v_lo && freest.is_none_or(|(f, _)| free_m > f) {
                    freest = Some((free_m, w));
                }
                // Fox's admissibility: one cycle at (v, ω), then braking, must end before contact.
                if v * input.dt_s + v * v / (2.0 * brake) > free_m {
                    continue;
                }
                admissible += 1;
                // Where the arc leaves the robot after the horizon, never past an obstacle.
                let (ex, ey, eth) = if moving {
                    arc_pose(kappa, (v * c.horizon_s).min(free_m))
                } else {
                    (0.0, 0.0, w * c.horizon_s)
                };
                let (dx, dy) = (target.0 - ex, target.1 - ey);
                let end_dist = dx.hypot(dy);
                let heading = if target_is_goal && end_dist < c.goal_tolerance_m {
                    1.0
                } else {
                    1.0 - normalize_angle(dy.atan2(dx) - eth).abs() / std::f64::consts::PI
                };
                let progress = ((start_dist - end_dist) / progress_scale).clamp(-1.0, 1.0);
                let clearance = clear_m.min(clear_cap_m) / clear_cap_m;
                let velocity = v / limits.max_speed_mps;
                let score = c.heading_weight * heading
                    + c.progress_weight * progress
                    + c.clearance_weight * clearance
                    + c.velocity_weight * velocity;
                if best.is_none_or(|b| score > b.score) {
                    best = Some(Choice {
                        v_mps: v,
                        omega_radps: w,
                        score,
                        free_m,
                        candidates: 0,
                        admissible: 0,
                        target_m: target,
                    });
                }
            }
        }
        // Braking starts from the last command when that was slower than the odometry says: the
        // window is centred on the odometry's speed, which is noisy (±15 % per cycle on the
        // simulated base), and a lower edge computed from an overestimate kept the robot at full
        // speed into furniture.
        let brake_v = self.last.map_or(v_lo, |l| {
            v_lo.min((l.v_mps - limits.max_accel_mps2 * input.dt_s).max(0.0))
        });
        let mut choice = match (best, freest) {
            (Some(b), _) => b,
            (None, Some((free_m, w))) => Choice {
                v_mps: brake_v,
                omega_radps: w,
                score: f64::NAN,
                free_m,
                candidates: 0,
                admissible: 0,
                target_m: target,
            },
            // linspace always yields v_lo first, so `freest` is set whenever a sample exists.
            (None, None) => Choice {
                v_mps: brake_v,
                omega_radps: 0.0f64.clamp(w_lo, w_hi),
                score: f64::NAN,
                free_m: 0.0,
                candidates: 0,
                admissible: 0,
                target_m: target,
            },
        };
        choice.candidates = candidates;
        choice.admissible = admissible;
        tracing::trace!(
            v_mps = choice.v_mps,
            omega_radps = choice.omega_radps,
            score = choice.score,
            free_m = choice.free_m,
            admissible,
            target_x_m = target.0,
            target_y_m = target.1,
            blocked_ahead,
            goal_in_sight,
            "dynamic window"
        );
        self.last = Some(choice);
        Ok(Control::from_physical(
            choice.v_mps,
            choice.omega_radps,
            limits,
        ))
    }

    fn reset(&mut self) {
        self.last = None;
        self.carrot = None;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::Limits;
    use protocol::{Dlm, Header, Intention, LaserScan, Pose2D};
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn intention(path: Vec<Pose2D>) -> Intention {
        test_support::fixtures::intention(path, Dlm::GoForward)
    }

    fn straight_path(len_m: f64) -> Vec<Pose2D> {
        let n = (len_m / 0.1).round() as i32;
        (0..=n)
            .map(|i| Pose2D::new(0.1 * f64::from(i), 0.0, 0.0))
            .collect()
    }

    /// A 360-degree scan of `beams` beams from the robot (at the origin facing +x), each beam's
    /// range given by its angle.
    fn full_scan(beams: u32, range_at: impl Fn(f64) -> f32) -> LaserScan {
        let inc = std::f64::consts::TAU / f64::from(beams);
        LaserScan {
            header: Header::default(),
            angle_min_rad: -std::f32::consts::PI,
            angle_increment_rad: inc as f32,
            range_min_m: 0.05,
            range_max_m: 10.0,
            ranges_m: (0..beams)
                .map(|i| range_at(-std::f64::consts::PI + inc * f64::from(i)))
                .collect(),
        }
    }

    /// A 360-degree scan of a wall across the robot's way at `wall_x_m` (robot frame, robot at
    /// the origin facing +x), or of nothing.
    fn scan_with_wall(wall_x_m: Option<f64>) -> LaserScan {
        full_scan(360, |a| match wall_x_m {
            Some(x) if a.cos() > 1e-6 => {
                let r = x / a.cos();
                if r < 10.0 {
                    r as f32
                } else {
                    10.0
                }
            }
            _ => 10.0,
        })
    }

    fn input<'a>(
        v: f64,
        w: f64,
        scan: Option<&'a LaserScan>,
        intention: &'a Intention,
        limits: &'a Limits,
        dt_s: f64,
    ) -> ControlInput<'a> {
        ControlInput {
            pose: Pose2D::default(),
            v_mps: v,
            omega_radps: w,
            scan,
            camera: None,
            intention: Some(intention),
            limits,
            dt_s,
        }
    }

    #[test]
    fn never_leaves_the_limits_or_the_dynamic_window() {
        let limits = Limits::default();
        let mut dwa = DynamicWindow::new(DynamicWindowConfig::default()).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let scans = [
            scan_with_wall(None),
            scan_with_wall(Some(0.9)),
            scan_with_wall(Some(2.0)),
        ];
        for k in 0..300 {
            // Include velocities outside the limits (odometry noise, a shove).
            let v = rng.gen_range(-0.2..limits.max_speed_mps + 0.2);
            let w = rng.gen_range(-limits.max_turn_radps - 0.3..limits.max_turn_radps + 0.3);
            let dt = rng.gen_range(0.02..0.3);
            let bend: f64 = rng.gen_range(-3.0..3.0);
            let path: Vec<Pose2D> = (0..40)
                .map(|i| {
                    let s = 0.1 * f64::from(i);
                    Pose2D::new(s * bend.cos(), s * bend.sin(), bend)
                })
                .collect();
            let it = intention(path);
            let scan = &scans[k % scans.len()];
            let c = dwa
                .control(&input(v, w, Some(scan), &it, &limits, dt))
                .unwrap();
            assert!(c.v_norm.abs() <= 1.0 && c.omega_norm.abs() <= 1.0, "{c:?}");
            let (cv, cw) = c.to_physical(&limits);
            let (v_lo, v_hi) = window(v, limits.max_accel_mps2, dt, 0.0, limits.max_speed_mps);
            let (w_lo, w_hi) = window(
                w,
                limits.max_turn_accel_radps2,
                dt,
                -limits.max_turn_radps,
                limits.max_turn_radps,
            );
            // Within the window, or braking harder when no arc is admissible.
            let braking = dwa.last_choice().is_some_and(|ch| ch.admissible == 0);
            assert!(
                (braking && cv >= 0.0 && cv <= v_lo + 1e-9)
                    || (cv >= v_lo - 1e-9 && cv <= v_hi + 1e-9),
                "v {cv} not in [{v_lo}, {v_hi}] from {v}"
            );
            assert!(
                cw >= w_lo - 1e-9 && cw <= w_hi + 1e-9,
                "w {cw} not in [{w_lo}, {w_hi}] from {w}"
            );
            assert!(cv >= 0.0 && cv <= limits.max_speed_mps + 1e-12);
            assert!(cw.abs() <= limits.max_turn_radps + 1e-12);
        }
    }

    #[test]
    fn accelerates_straight_on_a_free_straight_path() {
        let limits = Limits::default();
        let mut dwa = DynamicWindow::new(DynamicWindowConfig::default()).unwrap();
        let it = intention(straight_path(5.0));
        let scan = scan_with_wall(None);
        let c = dwa
            .control(&input(0.3, 0.0, Some(&scan), &it, &limits, 0.1))
            .unwrap();
        let (v, w) = c.to_physical(&limits);
        assert!((v - 0.38).abs() < 1e-9, "{v}");
        assert_eq!(w, 0.0);
    }

    #[test]
    fn brakes_when_it_cannot_stop_before_a_wall() {
        let limits = Limits::default();
        let mut dwa = DynamicWindow::new(DynamicWindowConfig::default()).unwrap();
        let it = intention(straight_path(5.0));
        // Full speed, wall 0.6 m ahead: 0.25 m of free travel, 0.38 m needed to stop.
        let scan = scan_with_wall(Some(0.6));
        let c = dwa
            .control(&input(
                limits.max_speed_mps,
                0.0,
                Some(&scan),
                &it,
                &limits,
                0.1,
            ))
            .unwrap();
        let (v, _) = c.to_physical(&limits);
        assert!((v - (limits.max_speed_mps - 0.08)).abs() < 1e-9, "{v}");
        let choice = dwa.last_choice().unwrap();
        assert_eq!(choice.admissible, 0, "{choice:?}");
        // From a standstill, nothing forward is admissible close to the wall: it stays put.
        let scan = scan_with_wall(Some(0.36));
        let c = dwa
            .control(&input(0.0, 0.0, Some(&scan), &it, &limits, 0.1))
            .unwrap();
        assert_eq!(c.v_norm, 0.0, "{c:?}");
    }

    #[test]
    fn errors_without_scan_or_intention_and_stops_at_goal() {
        let limits = Limits::default();
        let mut dwa = DynamicWindow::new(DynamicWindowConfig::default()).unwrap();
        let it = intention(straight_path(5.0));
        let err = dwa
            .control(&input(0.0, 0.0, None, &it, &limits, 0.1))
            .unwrap_err();
        assert!(err.to_string().contains("laser scan"), "{err}");
        let mut no_intention = input(0.0, 0.0, None, &it, &limits, 0.1);
        no_intention.intention = None;
        assert!(matches!(
            dwa.control(&no_intention),
            Err(ControllerError::MissingInput {
                input: "intention",
                ..
            })
        ));
        let short = intention(straight_path(0.1));
        let scan = scan_with_wall(None);
        assert_eq!(
            dwa.control(&input(0.1, 0.0, Some(&scan), &short, &limits, 0.1))
                .unwrap(),
            Control::default()
        );
        let err = dwa
            .control(&input(0.1, 0.0, Some(&scan), &it, &limits, 0.0))
            .unwrap_err();
        assert!(err.to_string().contains("dt_s"), "{err}");
    }

    /// A 360-degree scan (robot at the origin facing +x) of a wall 0.6 m thick whose end is
    /// beside the robot: it fills x ≤ 0, 0.31 ≤ y ≤ 0.91, so the robot stands 0.31 m from its
    /// face, inside the window's 0.35 m inflation.
    fn scan_beside_a_walls_end() -> LaserScan {
        let inside = |x: f64, y: f64| (-3.0..=0.0).contains(&x) && (0.31..=0.91).contains(&y);
        full_scan(720, |a| {
            let mut r: f64 = 0.0;
            while r < 10.0 && !inside(r * a.cos(), r * a.sin()) {
                r += 0.005;
            }
            r.min(10.0) as f32
        })
    }

    #[test]
    fn finds_the_way_round_a_walls_end_from_inside_its_inflation() {
        let limits = Limits::default();
        let mut dwa = DynamicWindow::new(DynamicWindowConfig::default()).unwrap();
        // The planner's path round the end, 0.27-0.3 m from it (its radius is the robot's,
        // not the window's inflation), then on along the wall's far side.
        let corners: [(f64, f64); 7] = [
            (0.0, 0.0),
            (0.2, 0.3),
            (0.3, 0.6),
            (0.2, 1.0),
            (0.0, 1.2),
            (-0.5, 1.25),
            (-2.5, 1.25),
        ];
        let it = intention(test_support::fixtures::polyline(&corners, 0.05));
        let scan = scan_beside_a_walls_end();
        dwa.control(&input(0.0, 0.0, Some(&scan), &it, &limits, 0.1))
            .unwrap();
        // The look-ahead point, 1.5 m on, lies beyond the wall: the line to it runs inside the
        // inflation all the way from the robot, which is no way out of it. The window heads for
        // a point of the navigation function's descent instead, round the end: ahead of the
        // robot, not to its left through the wall.
        assert!(dwa.carrot.is_some(), "no detour from inside the inflation");
        let target = dwa.last_choice().unwrap().target_m;
        assert!(target.0 > 0.2, "target {target:?} is not round the end");
        assert!(
            target.1.atan2(target.0) < 0.8,
            "target {target:?} is through the wall"
        );
    }

    #[test]
    fn heads_for_a_goal_in_sight_and_not_through_a_wall() {
        let limits = Limits::default();
        let mut dwa = DynamicWindow::new(DynamicWindowConfig::default()).unwrap();
        // A path that loops out to the left and comes back to a goal 1 m ahead.
        let it = intention(test_support::fixtures::loop_path(1.0));
        let free = scan_with_wall(None);
        dwa.control(&input(0.5, 0.0, Some(&free), &it, &limits, 0.1))
            .unwrap();
        let at_goal = |t: (f64, f64)| (t.0 - 1.0).hypot(t.1) < 1e-9;
        assert!(at_goal(dwa.last_choice().unwrap().target_m));
        // A wall between the robot and the goal: the path's look-ahead point, not the goal.
        let wall = scan_with_wall(Some(0.6));
        dwa.control(&input(0.5, 0.0, Some(&wall), &it, &limits, 0.1))
            .unwrap();
        assert!(!at_goal(dwa.last_choice().unwrap().target_m));
    }

    #[test]
    fn arc_pose_is_on_the_circle() {
        let (x, y, th) = arc_pose(1.0, std::f64::consts::PI);
        assert!(
            x.abs() < 1e-12 && (y - 2.0).abs() < 1e-12 && (th - std::f64::consts::PI).abs() < 1e-12
        );
        assert_eq!(arc_pose(0.0, 1.5), (1.5, 0.0, 0.0));
        let (_, y, _) = arc_pose(-0.5, 1.0);
        assert!(y < 0.0);
    }

    /// Both controller tables, as `controllers.example.toml` holds them.
    #[derive(Debug, serde::Deserialize)]
    #[serde(deny_unknown_fields)]
    struct Example {
        path_tracker: crate::controllers::PathTrackerConfig,
        dynamic_window: DynamicWindowConfig,
    }

    #[test]
    fn example_file_parses_to_the_defaults() {
        let text = include_str!("../../controllers.example.toml");
        let e: Example = toml::from_str(text).unwrap();
        assert_eq!(e.dynamic_window, DynamicWindowConfig::default());
        assert_eq!(
            e.path_tracker,
            crate::controllers::PathTrackerConfig::default()
        );
        e.dynamic_window.validate().unwrap();
        e.path_tracker.validate().unwrap();
        let err = toml::from_str::<DynamicWindowConfig>("robot_radius = 0.3")
            .unwrap_err()
            .to_string();
        assert!(err.contains("robot_radius"), "{err}");
    }

    #[test]
    fn config_rejects_bad_values_by_name() {
        let bad = DynamicWindowConfig {
            v_samples: 1,
            ..DynamicWindowConfig::default()
        };
        let err = bad.validate().unwrap_err().to_string();
        assert!(err.contains("dynamic_window.v_samples = 1"), "{err}");
        let bad = DynamicWindowConfig {
            robot_radius_m: f64::NAN,
            ..DynamicWindowConfig::default()
        };
        assert!(DynamicWindow::new(bad).is_err());
    }
}
