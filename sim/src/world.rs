//! The ground-truth world and its lock-step simulation: walls, furniture, glass, people, robots.
//!
//! [`World::step`] advances everything by `dt` and returns what each robot's sensors report
//! (scan, noisy odometry, collisions) plus the true pose, which only the evaluation harness may
//! read. The camera is rendered separately ([`World::render_camera`]) because controllers need it
//! at 10 Hz while physics runs faster. Every random draw comes from per-robot ChaCha streams
//! seeded by the scenario, and the camera draws none, so a run is bitwise reproducible whatever
//! is rendered when.

use std::path::Path;

use map_core::{ImportLimits, OccupancyGrid};
use protocol::{Header, LaserScan, Odometry, Pose2D, RobotId};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

use crate::appearance::Appearance;
use crate::config::SimConfig;
use crate::geom::{ray_disc, Obb};
use crate::raycast::WallGrid;
use crate::scenario::{Rgb, RouteMode, Scenario, ScenarioError};

/// Why a world could not be built or a robot placed.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    #[error(transparent)]
    Scenario(#[from] ScenarioError),
    #[error("robot {robot_id} cannot be placed at ({x_m:.2}, {y_m:.2}): it would overlap {with}")]
    Blocked {
        robot_id: String,
        x_m: f64,
        y_m: f64,
        with: Obstacle,
    },
    #[error("robot {robot_id} already exists")]
    DuplicateRobot { robot_id: String },
    #[error("no robot with index {index} (the world has {count})")]
    NoSuchRobot { index: usize, count: usize },
}

/// What a robot ran into.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
#[serde(tag = "kind", content = "index", rename_all = "snake_case")]
pub enum Obstacle {
    Wall,
    /// Index into the scenario's `furniture`.
    Furniture(usize),
    /// Index into the scenario's `glass`.
    Glass(usize),
    /// Index into the scenario's `people`.
    Person(usize),
    /// Another robot, by index in the world.
    Robot(usize),
}

impl std::fmt::Display for Obstacle {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Obstacle::Wall => f.write_str("a wall"),
            Obstacle::Furniture(i) => write!(f, "furniture[{i}]"),
            Obstacle::Glass(i) => write!(f, "glass[{i}]"),
            Obstacle::Person(i) => write!(f, "people[{i}]"),
            Obstacle::Robot(i) => write!(f, "robot #{i}"),
        }
    }
}

/// A collision event: the step was cut short and the robot stopped at `stopped_at`.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Collision {
    pub with: Obstacle,
    /// Last free true pose, where the robot now stands.
    pub stopped_at: Pose2D,
}

/// A velocity command for one robot.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Command {
    pub v_mps: f64,
    pub omega_radps: f64,
}

/// Furniture as the world holds it.
#[derive(Debug, Clone)]
pub struct Furniture {
    pub shape: Obb,
    pub height_m: f64,
    pub color: Rgb,
}

/// A glass pane as the world holds it.
#[derive(Debug, Clone)]
pub struct Glass {
    pub shape: Obb,
    pub frame_color: Rgb,
    pub tint: Rgb,
}

/// A walking person.
#[derive(Debug, Clone)]
pub struct Person {
    pub x_m: f64,
    pub y_m: f64,
    pub radius_m: f64,
    pub shirt_color: Rgb,
    pub pants_color: Rgb,
    /// Distance walked in total (drives the leg swing in the camera).
    pub walked_m: f64,
    route: Vec<(f64, f64)>,
    speed_mps: f64,
    mode: RouteMode,
    /// Index of the route point being walked to.
    target: usize,
    forward: bool,
    /// The sense (+1 anticlockwise, -1 clockwise) in which the person is walking round a robot
    /// in the way, kept until the route is free again (choosing afresh each step would undo
    /// the last one).
    rounding: Option<f64>,
}

impl Person {
    /// The walking velocity (vx, vy) in m/s the route gives now: the walking speed towards the
    /// route point being walked to (past it, towards the next one). A person who steps aside
    /// from a robot or waits for one deviates from it for that step; a route of one point
    /// gives zero.
    pub fn velocity_mps(&self) -> (f64, f64) {
        // A short look ahead along the route also covers standing exactly on a route point.
        const PROBE_M: f64 = 0.01;
        let (x, y, _, _) = self.advanced(PROBE_M);
        let (dx, dy) = (x - self.x_m, y - self.y_m);
        let d = dx.hypot(dy);
        if d < 1e-12 {
            return (0.0, 0.0);
        }
        (dx / d * self.speed_mps, dy / d * self.speed_mps)
    }

    /// Where the person would be after walking `dist` (route following, no blocking).
    fn advanced(&self, mut dist: f64) -> (f64, f64, usize, bool) {
        let (mut x, mut y, mut target, mut forward) =
            (self.x_m, self.y_m, self.target, self.forward);
        let n = self.route.len();
        if n < 2 {
            return (x, y, target, forward);
        }
        // Bounded: each iteration reaches a route point or ends the walk.
        for _ in 0..4 * n + 4 {
            let (tx, ty) = self.route[target];
            let d = (tx - x).hypot(ty - y);
            if d > dist {
                x += (tx - x) * dist / d;
                y += (ty - y) * dist / d;
                break;
            }
            dist -= d;
            x = tx;
            y = ty;
            (target, forward) = self.after(target, forward);
        }
        (x, y, target, forward)
    }

    /// The route point walked to after route point `target` (walking `forward`), for a route
    /// of at least two points.
    fn after(&self, target: usize, forward: bool) -> (usize, bool) {
        let n = self.route.len();
        match self.mode {
            RouteMode::Loop => ((target + 1) % n, forward),
            RouteMode::PingPong => {
                let forward = if forward && target + 1 == n {
                    false
                } else if !forward && target == 0 {
                    true
                } else {
                    forward
                };
                (if forward { target + 1 } else { target - 1 }, forward)
            }
        }
    }
}

/// A robot slower than this stands, for the people walking round it or turning short of it.
const STANDING_MPS: f64 = 0.05;

/// One simulated robot's state.
#[derive(Debug, Clone)]
pub struct Robot {
    pub id: RobotId,
    /// True pose in the map frame: evaluation only.
    pub(crate) pose: Pose2D,
    pub(crate) v_mps: f64,
    pub(crate) omega_radps: f64,
    odom_pose: Pose2D,
    odom_v_mps: f64,
    odom_omega_radps: f64,
    rng: ChaCha8Rng,
    seq: u64,
    camera_seq: u64,
}

impl Robot {
    pub fn id(&self) -> &RobotId {
        &self.id
    }
}

/// What one robot's sensors report after a step.
#[derive(Debug, Clone)]
pub struct RobotObservation {
    pub robot_id: RobotId,
    pub scan: LaserScan,
    pub odom: Odometry,
    /// Collisions during this step (at most one: the robot stops at the first).
    pub collisions: Vec<Collision>,
    /// The TRUE map-frame pose. For the evaluation harness only: a controller or localizer that
    /// reads it cheats.
    pub ground_truth_pose: Pose2D,
}

/// Everything [`World::step`] returns.
#[derive(Debug, Clone)]
pub struct Observations {
    /// Simulation clock after the step.
    pub time_ns: u64,
    pub robots: Vec<RobotObservation>,
}

/// The ground-truth world.
#[derive(Debug, Clone)]
pub struct World {
    pub scenario: Scenario,
    pub config: SimConfig,
    /// The crude floor plan the planner gets (no furniture, glass or people).
    pub plan: OccupancyGrid,
    pub(crate) walls: WallGrid,
    pub(crate) appearance: Appearance,
    pub furniture: Vec<Furniture>,
    pub glass: Vec<Glass>,
    pub people: Vec<Person>,
    pub(crate) robots: Vec<Robot>,
    pub(crate) camera_model: crate::camera::CameraModel,
    time_ns: u64,
}

/// Integrates a unicycle exactly over `dt` (arc when turning): the simulator's motion model,
/// also what a privileged controller predicts with.
#[must_use]
pub fn integrate(p: Pose2D, v: f64, w: f64, dt: f64) -> Pose2D {
    let yaw = p.yaw_rad;
    if w.abs() < 1e-9 {
        Pose2D::new(p.x_m + v * dt * yaw.cos(), p.y_m + v * dt * yaw.sin(), yaw)
    } else {
        let yaw2 = yaw + w * dt;
        let r = v / w;
        Pose2D::new(
            p.x_m + r * (yaw2.sin() - yaw.sin()),
            p.y_m - r * (yaw2.cos() - yaw.cos()),
            protocol::normalize_angle(yaw2),
        )
    }
}

fn approach(current: f64, target: f64, max_delta: f64) -> f64 {
    current + (target - current).clamp(-max_delta, max_delta)
}

impl World {
    /// Loads a scenario file and its floor plan and builds the world (no robots yet).
    ///
    /// # Errors
    /// Scenario, floor-plan and placement errors.
    pub fn from_scenario_file(path: &Path, config: SimConfig) -> Result<Self, SimError> {
        let scenario = Scenario::load(path)?;
        let plan_path = scenario.floor_plan_path(path);
        let plan = map_core::load_ros_map(&plan_path, &ImportLimits::default())
            .map_err(|source| ScenarioError::Map {
                path: plan_path.clone(),
                source,
            })?
            .grid;
        Self::new(scenario, plan, config)
    }

    /// Builds the world from a validated scenario and its floor plan.
    ///
    /// # Errors
    /// [`SimError::Scenario`] when the config is invalid or the start or a goal is off the plan.
    pub fn new(
        scenario: Scenario,
        plan: OccupancyGrid,
        config: SimConfig,
    ) -> Result<Self, SimError> {
        scenario.validate()?;
        config.validate()?;
        let walls = WallGrid::from_grid(&plan);
        for (i, g) in scenario.goals.iter().enumerate() {
            let (cx, cy) = walls.cell_of(g.x_m, g.y_m);
            if walls.is_wall(cx, cy) {
                return Err(ScenarioError::invalid(
                    format!("goals[{i}]"),
                    format!("({}, {})", g.x_m, g.y_m),
                    "lies in a wall or off the floor plan",
                )
                .into());
            }
        }
        let appearance = Appearance::build(
            &scenario.appearance,
            &walls,
            config.camera.wall_height_m,
            scenario.seed,
        );
        let furniture = scenario
            .furniture
            .iter()
            .map(|b| Furniture {
                shape: b.shape(),
                height_m: b.height_m,
                color: b.color,
            })
            .collect();
        let glass = scenario
            .glass
            .iter()
            .map(|g| Glass {
                shape: g.shape(),
                frame_color: g.frame_color,
                tint: g.tint,
            })
            .collect();
        let people = scenario
            .people
            .iter()
            .map(|p| {
                let route: Vec<(f64, f64)> = p.route.iter().map(|q| (q.x_m, q.y_m)).collect();
                let (x_m, y_m) = route[0];
                Person {
                    x_m,
                    y_m,
                    radius_m: p.radius_m,
                    shirt_color: p.shirt_color,
                    pants_color: p.pants_color,
                    walked_m: 0.0,
                    target: usize::from(route.len() > 1),
                    route,
                    speed_mps: p.speed_mps,
                    mode: p.mode,
                    forward: true,
                    rounding: None,
                }
            })
            .collect();
        Ok(Self {
            scenario,
            config,
            plan,
            walls,
            appearance,
            furniture,
            glass,
            people,
            robots: Vec::new(),
            camera_model: crate::camera::CameraModel::new(&config.camera),
            time_ns: 0,
        })
    }

    /// Simulation clock.
    pub fn time_ns(&self) -> u64 {
        self.time_ns
    }

    pub fn robot_count(&self) -> usize {
        self.robots.len()
    }

    pub fn robot_ids(&self) -> Vec<RobotId> {
        self.robots.iter().map(|r| r.id.clone()).collect()
    }

    /// The TRUE pose of robot `index`: for the evaluation harness and tools only.
    pub fn ground_truth_pose(&self, index: usize) -> Option<Pose2D> {
        self.robots.get(index).map(|r| r.pose)
    }

    /// The TRUE speed and turn rate (v, ω) of robot `index` after the last step: for the
    /// evaluation harness and its privileged expert only.
    pub fn ground_truth_velocity(&self, index: usize) -> Option<(f64, f64)> {
        self.robots.get(index).map(|r| (r.v_mps, r.omega_radps))
    }

    /// What a disc at (x, y) of radius `r` overlaps, ignoring robot `skip_robot` and people
    /// when `with_people` is false.
    pub fn disc_overlap(
        &self,
        x: f64,
        y: f64,
        r: f64,
        skip_robot: Option<usize>,
        with_people: bool,
    ) -> Option<Obstacle> {
        if self.walls.disc_hits_wall(x, y, r) {
            return Some(Obstacle::Wall);
        }
        if let Some(i) = self
            .furniture
            .iter()
            .position(|f| f.shape.distance(x, y) < r)
        {
            return Some(Obstacle::Furniture(i));
        }
        if let Some(i) = self.glass.iter().position(|g| g.shape.distance(x, y) < r) {
            return Some(Obstacle::Glass(i));
        }
        if with_people {
            if let Some(i) = self
                .people
                .iter()
                .position(|p| (p.x_m - x).hypot(p.y_m - y) < r + p.radius_m)
            {
                return Some(Obstacle::Person(i));
            }
        }
        let rr = self.config.base.radius_m;
        self.robots
            .iter()
            .enumerate()
            .find(|(i, o)| {
                Some(*i) != skip_robot && (o.pose.x_m - x).hypot(o.pose.y_m - y) < r + rr
            })
            .map(|(i, _)| Obstacle::Robot(i))
    }

    /// Adds a robot at a true pose; its odometry frame starts at the identity.
    ///
    /// # Errors
    /// [`SimError::DuplicateRobot`], or [`SimError::Blocked`] when the pose overlaps something.
    pub fn add_robot(&mut self, id: RobotId, pose: Pose2D) -> Result<usize, SimError> {
        if self.robots.iter().any(|r| r.id == id) {
            return Err(SimError::DuplicateRobot {
                robot_id: id.to_string(),
            });
        }
        if let Some(with) =
            self.disc_overlap(pose.x_m, pose.y_m, self.config.base.radius_m, None, true)
        {
            return Err(SimError::Blocked {
                robot_id: id.to_string(),
                x_m: pose.x_m,
                y_m: pose.y_m,
                with,
            });
        }
        let index = self.robots.len();
        let seed = self.scenario.seed ^ (0x5EED_0000 + index as u64).wrapping_mul(0x9E37_79B9);
        self.robots.push(Robot {
            id,
            pose,
            v_mps: 0.0,
            omega_radps: 0.0,
            odom_pose: Pose2D::default(),
            odom_v_mps: 0.0,
            odom_omega_radps: 0.0,
            rng: ChaCha8Rng::seed_from_u64(seed),
            seq: 0,
            camera_seq: 0,
        });
        Ok(index)
    }

    /// Adds the scenario's parked robots, `parked_1..n`, after the robots already placed (so
    /// the driven robots keep their indices). Nobody commands them: they stand still.
    ///
    /// # Errors
    /// [`SimError::Blocked`] when a parked robot overlaps something, a driven robot included.
    pub fn add_parked_robots(&mut self) -> Result<(), SimError> {
        let poses: Vec<Pose2D> = self
            .scenario
            .parked_robots
            .iter()
            .map(|p| p.to_pose())
            .collect();
        for (k, pose) in poses.into_iter().enumerate() {
            let id = RobotId::new(format!("parked_{}", k + 1)).map_err(|e| {
                ScenarioError::invalid("parked_robots", k, format!("not a valid robot id: {e}"))
            })?;
            self.add_robot(id, pose)?;
        }
        Ok(())
    }

    /// A person carries robot `index` to the true pose `pose` (the evaluation harness's human
    /// intervention): the robot stands still there and its odometry does not see the move, as
    /// the wheels did not turn.
    ///
    /// # Errors
    /// [`SimError::NoSuchRobot`], or [`SimError::Blocked`] (nothing moved) when the pose overlaps
    /// something other than the robot itself.
    pub fn carry_robot(&mut self, index: usize, pose: Pose2D) -> Result<(), SimError> {
        let count = self.robots.len();
        let robot_id = match self.robots.get(index) {
            Some(r) => r.id.to_string(),
            None => return Err(SimError::NoSuchRobot { index, count }),
        };
        if let Some(with) = self.disc_overlap(
            pose.x_m,
            pose.y_m,
            self.config.base.radius_m,
            Some(index),
            true,
        ) {
            return Err(SimError::Blocked {
                robot_id,
                x_m: pose.x_m,
                y_m: pose.y_m,
                with,
            });
        }
        let robot = &mut self.robots[index];
        robot.pose = pose;
        robot.v_mps = 0.0;
        robot.omega_radps = 0.0;
        Ok(())
    }

    /// Places `n` robots named `robot_1..n`: the first at the scenario start, the others at free
    /// poses found on rings around it (deterministic).
    ///
    /// # Errors
    /// [`SimError::Blocked`] when the start is blocked or no free pose is found.
    pub fn add_robots_at_start(&mut self, n: usize) -> Result<(), SimError> {
        let start = self.scenario.start.to_pose();
        for k in 1..=n {
            let id = RobotId::new(format!("robot_{k}")).map_err(|e| {
                ScenarioError::invalid("robots", k, format!("not a valid robot id: {e}"))
            })?;
            if k == 1 {
                self.add_robot(id, start)?;
                continue;
            }
            let r = self.config.base.radius_m;
            let mut placed = None;
            'search: for ring in 1..40 {
                let dist = f64::from(ring) * 2.4 * r;
                for j in 0..16 {
                    let a = start.yaw_rad
                        + std::f64::consts::PI
                        + f64::from(j) * std::f64::consts::TAU / 16.0;
                    let (x, y) = (start.x_m + dist * a.cos(), start.y_m + dist * a.sin());
                    if self.disc_overlap(x, y, r + 0.1, None, true).is_none() {
                        placed = Some(Pose2D::new(x, y, start.yaw_rad));
                        break 'search;
                    }
                }
            }
            let pose = placed.ok_or_else(|| SimError::Blocked {
                robot_id: id.to_string(),
                x_m: start.x_m,
                y_m: start.y_m,
                with: Obstacle::Wall,
            })?;
            self.add_robot(id, pose)?;
        }
        Ok(())
    }

    fn step_people(&mut self, dt: f64) {
        let rr = self.config.base.radius_m;
        for i in 0..self.people.len() {
            let p = &self.people[i];
            let step_m = p.speed_mps * dt;
            let (x, y, target, forward) = p.advanced(step_m);
            // People do not walk into a robot: the robot's collisions are its own doing.
            // How close, centre to centre, a person comes to a robot.
            let keep_m = p.radius_m + rr + 0.05;
            let near_robot = |x: f64, y: f64| {
                self.robots
                    .iter()
                    .map(|r| (r.pose.x_m, r.pose.y_m, r.v_mps.abs() < STANDING_MPS))
                    .find(|r| (r.0 - x).hypot(r.1 - y) < keep_m)
            };
            let (x, y, target, forward, rounding) = match near_robot(x, y) {
                None => (x, y, target, forward, None),
                // A route point a robot stands on is taken as reached: the person turns to the
                // next one (walking round the robot to it would never end; task D's first
                // person turns at (25.5, 13.0), where the robot passes).
                Some(r)
                    if r.2
                        && p.route.len() > 1
                        && (p.route[p.target].0 - r.0).hypot(p.route[p.target].1 - r.1)
                            < keep_m =>
                {
                    let (target, forward) = p.after(p.target, p.forward);
                    (p.x_m, p.y_m, target, forward, None)
                }
                // A robot in the way: step aside, away from it, where nothing else is, or walk
                // round it, and walk on from there (the route leads back to its next point).
                // Merely waiting would deadlock against a robot that waits for the person to
                // pass.
                Some(r) => {
                    let (dx, dy) = (x - p.x_m, y - p.y_m);
                    let len = dx.hypot(dy);
                    if len < 1e-9 {
                        continue;
                    }
                    let (ux, uy) = (dx / len, dy / len);
                    // The normal of the walking direction on the side away from the robot.
                    let away = if ux * (r.1 - p.y_m) - uy * (r.0 - p.x_m) > 0.0 {
                        -1.0
                    } else {
                        1.0
                    };
                    let (nx, ny) = (-uy * away, ux * away);
                    let free = |x: f64, y: f64| {
                        near_robot(x, y).is_none()
                            && self.disc_overlap(x, y, p.radius_m, None, false).is_none()
                    };
                    // Sideways, or diagonally forward and aside.
                    let h = std::f64::consts::FRAC_1_SQRT_2;
                    let sideways = [
                        (
                            p.x_m + (ux + nx) * h * step_m,
                            p.y_m + (uy + ny) * h * step_m,
                        ),
                        (p.x_m + nx * step_m, p.y_m + ny * step_m),
                    ];
                    // Where a wall stops the side-step (met in a corridor, the robot on the
                    // person's open side), walk round a standing robot along its circle, the
                    // way that leads on first. Standing instead deadlocked 5 of task B's 20
                    // runs: the person pressed to the wall just ahead of the robot's flank,
                    // the robot's monitor refusing every motion that brings it closer. A
                    // robot driving at someone is not dodged: avoiding people is its job
                    // (the behaviour scenarios' oncoming person).
                    let (rx, ry) = (p.x_m - r.0, p.y_m - r.1);
                    // At least as far out as a person keeps from a robot (one that drove up
                    // closer is stepped back from), and a hair more, so that rounding never
                    // takes a step for one closer in.
                    let d = rx.hypot(ry).max(keep_m) + 1e-3;
                    let angle = ry.atan2(rx);
                    let round = |sense: f64| {
                        let a = angle + sense * step_m / d;
                        (r.0 + d * a.cos(), r.1 + d * a.sin(), Some(sense))
                    };
                    let on = |q: &(f64, f64, Option<f64>)| (q.0 - p.x_m) * ux + (q.1 - p.y_m) * uy;
                    let sideways = sideways.map(|(x, y)| (x, y, None));
                    // Once on the way round, on round (a side-step back would undo each step
                    // of it), turned back only where that way is blocked.
                    let (first, last) = match (r.2, p.rounding) {
                        (false, _) => (None, [None, None]),
                        (true, Some(sense)) => (Some(round(sense)), [Some(round(-sense)), None]),
                        (true, None) => {
                            let (a, b) = (round(1.0), round(-1.0));
                            let (a, b) = if on(&b) > on(&a) { (b, a) } else { (a, b) };
                            (None, [Some(a), Some(b)])
                        }
                    };
                    // The route point being walked to stays the same: it was not reached.
                    match first
                        .into_iter()
                        .chain(sideways)
                        .chain(last.into_iter().flatten())
                        .find(|&(x, y, _)| free(x, y))
                    {
                        Some((x, y, sense)) => (x, y, p.target, p.forward, sense.or(p.rounding)),
                        None => continue,
                    }
                }
            };
            let p = &mut self.people[i];
            p.walked_m += (x - p.x_m).hypot(y - p.y_m);
            p.x_m = x;
            p.y_m = y;
            p.target = target;
            p.forward = forward;
            p.rounding = rounding;
        }
    }

    /// Moves robot `i` under command `cmd`, stopping it at the last free pose on contact.
    fn step_robot(&mut self, i: usize, cmd: Command, dt: f64) -> Vec<Collision> {
        let b = self.config.base;
        let target_v = if cmd.v_mps.is_finite() {
            cmd.v_mps.clamp(-b.max_reverse_mps, b.max_speed_mps)
        } else {
            0.0
        };
        let target_w = if cmd.omega_radps.is_finite() {
            cmd.omega_radps.clamp(-b.max_turn_radps, b.max_turn_radps)
        } else {
            0.0
        };
        let robot = &mut self.robots[i];
        robot.v_mps = approach(robot.v_mps, target_v, b.max_accel_mps2 * dt);
        robot.omega_radps = approach(robot.omega_radps, target_w, b.max_turn_accel_radps2 * dt);
        let (v, w, start) = (robot.v_mps, robot.omega_radps, robot.pose);
        // Sub-steps of at most 2 cm / 0.05 rad so no thin obstacle is jumped over.
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let n = ((v.abs() * dt / 0.02).max(w.abs() * dt / 0.05).ceil() as usize).clamp(1, 1000);
        #[allow(clippy::cast_precision_loss)]
        let h = dt / n as f64;
        let mut pose = start;
        for _ in 0..n {
            let next = integrate(pose, v, w, h);
            if let Some(with) = self.disc_overlap(next.x_m, next.y_m, b.radius_m, Some(i), true) {
                let robot = &mut self.robots[i];
                robot.pose = pose;
                robot.v_mps = 0.0;
                robot.omega_radps = 0.0;
                return vec![Collision {
                    with,
                    stopped_at: pose,
                }];
            }
            pose = next;
        }
        self.robots[i].pose = pose;
        Vec::new()
    }

    /// Thrun's `sample_motion_model_odometry` applied to the true motion of robot `i`.
    fn step_odometry(&mut self, i: usize, before: Pose2D, dt: f64) {
        let a = self.config.odometry;
        let robot = &mut self.robots[i];
        let after = robot.pose;
        let (dx, dy) = (after.x_m - before.x_m, after.y_m - before.y_m);
        let trans = dx.hypot(dy);
        // For a (near) pure rotation the heading of the translation is meaningless (AMCL skips it
        // below 1 cm; here the truth is exact, so only numerical noise needs guarding).
        let mut rot1 = if trans < 1e-4 {
            0.0
        } else {
            protocol::normalize_angle(dy.atan2(dx) - before.yaw_rad)
        };
        let mut backwards = false;
        if rot1.abs() > std::f64::consts::FRAC_PI_2 {
            // Driving backwards: measure the rotation to the reversed heading.
            rot1 = protocol::normalize_angle(rot1 + std::f64::consts::PI);
            backwards = true;
        }
        let rot2 = protocol::normalize_angle(after.yaw_rad - before.yaw_rad - rot1);
        let mut sample = |var: f64| -> f64 {
            let std = var.max(0.0).sqrt();
            Normal::new(0.0, std).map_or(0.0, |n| n.sample(&mut robot.rng))
        };
        let r1 = rot1 - sample(a.alpha1 * rot1 * rot1 + a.alpha2 * trans * trans);
        let tr = trans - sample(a.alpha3 * trans * trans + a.alpha4 * (rot1 * rot1 + rot2 * rot2));
        let r2 = rot2 - sample(a.alpha1 * rot2 * rot2 + a.alpha2 * trans * trans);
        let signed = if backwards { -tr } else { tr };
        let o = robot.odom_pose;
        let heading = o.yaw_rad + r1;
        robot.odom_pose = Pose2D::new(
            o.x_m + signed * heading.cos(),
            o.y_m + signed * heading.sin(),
            protocol::normalize_angle(heading + r2),
        );
        if dt > 0.0 {
            robot.odom_v_mps = signed / dt;
            robot.odom_omega_radps = (r1 + r2) / dt;
        }
    }

    /// Advances the world by `dt_s`; `commands[i]` drives robot `i` (missing ones stop).
    pub fn step(&mut self, commands: &[Command], dt_s: f64) -> Observations {
        let dt = if dt_s.is_finite() { dt_s.max(0.0) } else { 0.0 };
        self.step_people(dt);
        let mut collisions = Vec::with_capacity(self.robots.len());
        for i in 0..self.robots.len() {
            let before = self.robots[i].pose;
            let cmd = commands.get(i).copied().unwrap_or_default();
            collisions.push(self.step_robot(i, cmd, dt));
            self.step_odometry(i, before, dt);
        }
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let dt_ns = (dt * 1e9).round() as u64;
        self.time_ns += dt_ns;
        let robots = collisions
            .into_iter()
            .enumerate()
            .map(|(i, collisions)| {
                let scan = self.scan(i);
                let robot = &mut self.robots[i];
                let header = Header::new(robot.seq, self.time_ns);
                robot.seq += 1;
                RobotObservation {
                    robot_id: robot.id.clone(),
                    scan: LaserScan { header, ..scan },
                    odom: Odometry {
                        header,
                        pose: robot.odom_pose,
                        v_mps: robot.odom_v_mps,
                        omega_radps: robot.odom_omega_radps,
                    },
                    collisions,
                    ground_truth_pose: robot.pose,
                }
            })
            .collect();
        Observations {
            time_ns: self.time_ns,
            robots,
        }
    }

    /// The distance along a ray to the first thing the LIDAR sees, up to `max_m`.
    pub(crate) fn lidar_ray(
        &self,
        ox: f64,
        oy: f64,
        dx: f64,
        dy: f64,
        max_m: f64,
        skip_robot: usize,
    ) -> Option<f64> {
        let mut best = self
            .walls
            .cast(ox, oy, dx, dy, max_m)
            .map_or(f64::INFINITY, |h| h.dist_m);
        for f in &self.furniture {
            if let Some(s) = f.shape.ray(ox, oy, dx, dy) {
                best = best.min(s.t_in);
            }
        }
        if self.config.lidar.sees_glass {
            for g in &self.glass {
                if let Some(s) = g.shape.ray(ox, oy, dx, dy) {
                    best = best.min(s.t_in);
                }
            }
        }
        for p in &self.people {
            if let Some((t, _)) = ray_disc(ox, oy, dx, dy, p.x_m, p.y_m, p.radius_m) {
                best = best.min(t);
            }
        }
        let rr = self.config.base.radius_m;
        for (j, r) in self.robots.iter().enumerate() {
            if j != skip_robot {
                if let Some((t, _)) = ray_disc(ox, oy, dx, dy, r.pose.x_m, r.pose.y_m, rr) {
                    best = best.min(t);
                }
            }
        }
        (best <= max_m).then_some(best)
    }

    /// One LIDAR sweep of robot `i` with Gaussian range noise (header left default).
    fn scan(&mut self, i: usize) -> LaserScan {
        let l = self.config.lidar;
        let pose = self.robots[i].pose;
        let beams = l.beams as usize;
        let inc = l.fov_rad / f64::from(l.beams - 1);
        let angle_min = -0.5 * l.fov_rad;
        let mut ranges = Vec::with_capacity(beams);
        for k in 0..beams {
            #[allow(clippy::cast_precision_loss)]
            let a = pose.yaw_rad + angle_min + k as f64 * inc;
            let (s, c) = a.sin_cos();
            ranges.push(self.lidar_ray(pose.x_m, pose.y_m, c, s, l.range_max_m, i));
        }
        let noise = Normal::new(0.0, l.noise_std_m.max(0.0)).ok();
        let rng = &mut self.robots[i].rng;
        let ranges_m = ranges
            .into_iter()
            .map(|r| match r {
                // Every beam draws noise, hit or not, so the stream stays aligned across runs.
                Some(d) => {
                    let n = noise.as_ref().map_or(0.0, |n| n.sample(rng));
                    (d + n).clamp(0.0, l.range_max_m - 1e-3)
                }
                None => {
                    let _ = noise.as_ref().map(|n| n.sample(rng));
                    l.range_max_m
                }
            })
            .map(|r| {
                #[allow(clippy::cast_possible_truncation)]
                let r32 = r as f32;
                r32
            })
            .collect();
        #[allow(clippy::cast_possible_truncation)]
        LaserScan {
            header: Header::default(),
            angle_min_rad: angle_min as f32,
            angle_increment_rad: inc as f32,
            range_min_m: l.range_min_m as f32,
            range_max_m: l.range_max_m as f32,
            ranges_m,
        }
    }

    /// The static ground truth as a grid: the plan's walls plus furniture and glass rasterized
    /// (people and robots excluded). For tests and the evaluation harness.
    pub fn ground_truth_grid(&self) -> OccupancyGrid {
        let shapes = self
            .furniture
            .iter()
            .map(|f| f.shape)
            .chain(self.glass.iter().map(|g| g.shape));
        rasterize_shapes(&self.plan, shapes)
    }

    /// Advances the camera sequence number of robot `index` and returns the header to use.
    pub(crate) fn next_camera_header(&mut self, index: usize) -> Header {
        let time = self.time_ns;
        self.robots
            .get_mut(index)
            .map_or_else(Header::default, |r| {
                let h = Header::new(r.camera_seq, time);
                r.camera_seq += 1;
                h
            })
    }
}

/// `plan` with `shapes` rasterized as occupied: every cell any part of which touches a shape (what
/// [`World::ground_truth_grid`] draws for furniture and glass).
pub fn rasterize_shapes(
    plan: &OccupancyGrid,
    shapes: impl IntoIterator<Item = Obb>,
) -> OccupancyGrid {
    let mut grid = plan.clone();
    let res = grid.resolution_m();
    for s in shapes {
        let r = s.bounding_radius() + res;
        let (c0x, c0y) = grid.world_to_cell(s.cx - r, s.cy - r);
        let (c1x, c1y) = grid.world_to_cell(s.cx + r, s.cy + r);
        for cy in c0y.min(c1y)..=c0y.max(c1y) {
            for cx in c0x.min(c1x)..=c0x.max(c1x) {
                let (x, y) = grid.cell_to_world(cx, cy);
                // A cell is blocked when any part of it touches the shape.
                if s.distance(x, y) <= 0.5 * res * std::f64::consts::SQRT_2 {
                    grid.set(cx, cy, map_core::OCCUPIED);
                }
            }
        }
    }
    grid
}
