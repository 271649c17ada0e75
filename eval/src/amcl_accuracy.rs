//! How well AMCL localizes on the crude floor plan while the robot drives tasks A–E in the
//! simulator, whose world has furniture, people and glass that the plan lacks.
//!
//! Lock-step, no Zenoh and no wall clock: every control cycle steps the world by `dt_s`, feeds
//! the odometry and scan to AMCL, replans a hybrid-A* path from the AMCL pose to the current
//! goal (every `replan_every` cycles), and lets the controller (dynamic window or path tracker)
//! follow it from the AMCL pose. Only the comparison reads the ground truth: the estimate the
//! agent would publish (the filter's estimate carried forward by odometry) against the true
//! pose, every cycle. A goal counts as reached when the AMCL pose is within the DLM stop
//! distance of it, as the planner would decide; the truth never steers the robot.
//!
//! Human intervention (paper §4.1, DESIGN §9): a robot that collides, or whose true position
//! has not moved [`PROGRESS_M`] within `stuck_timeout_s`, is carried onto its planned path a
//! little ahead (the first free spot at least `intervention_ahead_m` further along) and the
//! intervention is counted. Its odometry does not see the carry. AMCL is then re-initialised
//! at the new true pose with the configured initial covariance, as the operator who carried
//! the robot would set its pose estimate: a metre-long kidnapping is not what this run
//! measures, and the recovery that would cope with one is off by default (as in Nav2). The
//! error keeps being counted every cycle, the settling after a re-initialisation included.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use planning::{
    stop_intention, Answer, Goal, GoalProgress, IntentionConfig, IntentionPlanner, PlanningMap,
};
use protocol::{normalize_angle, Header, Intention, MapName, MapRef, Pose2D, PoseEstimate, TaskId};
use robot_agent::amcl::{Amcl, LikelihoodField};
use robot_agent::controllers::{ControlInput, Controller, DynamicWindow, PathTracker};
use robot_agent::{AgentConfig, ControllerKind};
use serde::Serialize;
use sim::{Command, Scenario, SimConfig, World};

/// Thresholds of the accuracy requirement.
pub const MAX_MEAN_POSITION_ERROR_M: f64 = 0.10;
pub const MAX_MEAN_HEADING_ERROR_DEG: f64 = 3.0;
/// An error above this, even once, means the filter diverged.
pub const DIVERGED_POSITION_ERROR_M: f64 = 1.0;
/// The true position must move this far within `stuck_timeout_s` to count as progress.
pub const PROGRESS_M: f64 = 0.5;
/// Free space kept around the robot's disc where an intervention puts it down.
const PUT_DOWN_CLEARANCE_M: f64 = 0.15;

/// Why a run could not be made.
#[derive(Debug, thiserror::Error)]
pub enum AccuracyError {
    #[error("invalid {field} = {value}: {reason}")]
    Invalid {
        field: &'static str,
        value: String,
        reason: String,
    },
    #[error("scenario {path}: {reason}")]
    Scenario { path: String, reason: String },
    #[error("{what}: {reason}")]
    Setup { what: &'static str, reason: String },
}

/// One accuracy run's settings.
#[derive(Debug, Clone)]
pub struct AccuracyOptions {
    /// Mixed into the scenario's seed (sensor and odometry noise) and AMCL's seed; 0 keeps the
    /// scenario's own.
    pub seed: u64,
    /// `DynamicWindow` (default: avoids the furniture it sees) or `PathTracker`.
    pub controller: ControllerKind,
    /// Control cycle (10 Hz like the agent).
    pub dt_s: f64,
    /// Replan from the AMCL pose every this many cycles (1: every cycle, as the service does).
    pub replan_every: u32,
    /// Stop after this much simulated time (default: the scenario's time limit).
    pub max_sim_s: Option<f64>,
    /// Stop after this many goals (default: all of them).
    pub max_goals: Option<usize>,
    /// A goal not reached within this much simulated time is given up (the next one is tried).
    pub goal_timeout_s: f64,
    /// A robot whose true position moved less than [`PROGRESS_M`] in this long gets a human
    /// intervention (as does one that collides).
    pub stuck_timeout_s: f64,
    /// An intervention puts the robot down at least this far ahead along its planned path.
    pub intervention_ahead_m: f64,
    /// The agent configuration whose `[amcl]`, `[limits]`, `[path_tracker]` and
    /// `[dynamic_window]` tables are used.
    pub agent: AgentConfig,
}

impl Default for AccuracyOptions {
    fn default() -> Self {
        Self {
            seed: 0,
            controller: ControllerKind::DynamicWindow,
            dt_s: 0.1,
            replan_every: 1,
            max_sim_s: None,
            max_goals: None,
            goal_timeout_s: 120.0,
            stuck_timeout_s: 10.0,
            intervention_ahead_m: 1.0,
            agent: AgentConfig::default(),
        }
    }
}

/// The figures of one task.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TaskAccuracy {
    pub task: String,
    pub cycles: u64,
    pub sim_time_s: f64,
    pub mean_position_error_m: f64,
    pub max_position_error_m: f64,
    pub mean_heading_error_deg: f64,
    pub max_heading_error_deg: f64,
    pub diverged: bool,
    pub goals_reached: usize,
    pub goals_total: usize,
    pub distance_m: f64,
    pub collisions: u64,
    /// Human interventions: the robot collided or made no progress and was carried ahead.
    pub interventions: u64,
    /// Mean errors within [`MAX_MEAN_POSITION_ERROR_M`] and [`MAX_MEAN_HEADING_ERROR_DEG`]
    /// and no divergence.
    pub pass: bool,
}

/// `sim/scenarios/task_<letter>.yaml` for a task letter `a`..`e`.
///
/// # Errors
/// [`AccuracyError::Invalid`] for anything but one of `a`–`e`.
pub fn task_scenario(scenarios_dir: &Path, task: &str) -> Result<PathBuf, AccuracyError> {
    let t = task.trim().to_ascii_lowercase();
    if !matches!(t.as_str(), "a" | "b" | "c" | "d" | "e") {
        return Err(AccuracyError::Invalid {
            field: "tasks",
            value: task.to_string(),
            reason: "tasks are a, b, c, d, e".into(),
        });
    }
    Ok(scenarios_dir.join(format!("task_{t}.yaml")))
}

fn setup(what: &'static str) -> impl FnOnce(String) -> AccuracyError {
    move |reason| AccuracyError::Setup { what, reason }
}

/// Runs one task; `progress` gets (simulated seconds, simulated-time limit, goals reached)
/// every cycle.
///
/// # Errors
/// [`AccuracyError`] for an unreadable scenario or invalid options.
pub fn run_task(
    scenario_path: &Path,
    options: &AccuracyOptions,
    mut progress: impl FnMut(f64, f64, usize),
) -> Result<TaskAccuracy, AccuracyError> {
    if !(options.dt_s.is_finite() && options.dt_s > 0.0 && options.dt_s <= 1.0) {
        return Err(AccuracyError::Invalid {
            field: "dt_s",
            value: options.dt_s.to_string(),
            reason: "must lie in (0, 1]".into(),
        });
    }
    for (field, v) in [
        ("stuck_timeout_s", options.stuck_timeout_s),
        ("intervention_ahead_m", options.intervention_ahead_m),
        ("goal_timeout_s", options.goal_timeout_s),
    ] {
        if !(v.is_finite() && v > 0.0) {
            return Err(AccuracyError::Invalid {
                field,
                value: v.to_string(),
                reason: "must be a positive number".into(),
            });
        }
    }
    options
        .agent
        .validate()
        .map_err(|e| setup("agent config")(e.to_string()))?;
    let shown = scenario_path.display().to_string();
    let mut scenario = Scenario::load(scenario_path).map_err(|e| AccuracyError::Scenario {
        path: shown.clone(),
        reason: e.to_string(),
    })?;
    scenario.seed ^= options.seed;
    let plan_path = scenario.floor_plan_path(scenario_path);
    let plan = map_core::load_ros_map(&plan_path, &map_core::ImportLimits::default())
        .map_err(|e| AccuracyError::Scenario {
            path: plan_path.display().to_string(),
            reason: e.to_string(),
        })?
        .grid;
    let task = scenario.name.clone();
    let mut goals: Vec<Goal> = scenario
        .goals
        .iter()
        .map(|g| Goal::at(g.x_m, g.y_m))
        .collect();
    goals.truncate(options.max_goals.unwrap_or(goals.len()));
    let goals_total = goals.len();
    let max_sim_s = options.max_sim_s.unwrap_or(scenario.time_limit_s);
    let mut world = World::new(scenario, plan.clone(), SimConfig::default())
        .map_err(|e| setup("world")(e.to_string()))?;
    world
        .add_robots_at_start(1)
        .map_err(|e| setup("robot")(e.to_string()))?;
    let start = world
        .ground_truth_pose(0)
        .ok_or_else(|| setup("robot")("no robot".into()))?;

    let agent = &options.agent;
    let mut amcl_config = agent.amcl.clone();
    amcl_config.seed ^= options.seed;
    let field = LikelihoodField::new(&plan, amcl_config.laser_likelihood_max_dist_m)
        .map_err(|e| setup("likelihood field")(e.to_string()))?;
    let mut amcl =
        Amcl::new(amcl_config, Arc::new(field)).map_err(|e| setup("amcl")(e.to_string()))?;
    // The robot is placed where the scenario says, and told so (as an operator would).
    amcl.set_initial_pose(start, agent.localization.initial_covariance())
        .map_err(|e| setup("initial pose")(e.to_string()))?;
    // The service's own intention pipeline with its default configuration.
    let intention_config = IntentionConfig::default();
    let planning = Arc::new(
        PlanningMap::new(plan, &intention_config.planner)
            .map_err(|e| setup("planning map")(e.to_string()))?,
    );
    let mut pipeline = IntentionPlanner::new(planning, intention_config)
        .map_err(|e| setup("intention pipeline")(e.to_string()))?;
    let mut controller: Box<dyn Controller> = match options.controller {
        ControllerKind::PathTracker => Box::new(
            PathTracker::new(agent.path_tracker).map_err(|e| setup("controller")(e.to_string()))?,
        ),
        ControllerKind::DynamicWindow => Box::new(
            DynamicWindow::new(agent.dynamic_window)
                .map_err(|e| setup("controller")(e.to_string()))?,
        ),
        other => {
            return Err(AccuracyError::Invalid {
                field: "controller",
                value: other.to_string(),
                reason: "the accuracy run drives with path-tracker or dynamic-window".into(),
            })
        }
    };
    let map_ref = MapRef {
        name: MapName::new("plan").map_err(|e| setup("map name")(e.to_string()))?,
        version: 1,
    };
    let task_id = TaskId::new(task.clone()).ok();

    let mut cmd = Command::default();
    let mut intention: Option<Intention> = None;
    let (mut goal_index, mut goals_reached) = (0usize, 0usize);
    let mut goal_started_s = 0.0;
    let (mut sum_pos, mut max_pos, mut sum_yaw, mut max_yaw) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
    let (mut cycles, mut collisions, mut distance_m) = (0u64, 0u64, 0.0);
    let mut interventions = 0u64;
    let mut last_truth = start;
    // Where the robot last made progress, and when.
    let (mut progress_at, mut progress_s) = (start, 0.0);
    let mut t_s = 0.0;
    while t_s < max_sim_s && goal_index < goals_total {
        let obs = world.step(&[cmd], options.dt_s);
        t_s += options.dt_s;
        let o = &obs.robots[0];
        collisions += o.collisions.len() as u64;
        distance_m += o.ground_truth_pose.distance_m(&last_truth);
        last_truth = o.ground_truth_pose;
        amcl.update(&o.odom, Some(&o.scan))
            .map_err(|e| setup("amcl update")(e.to_string()))?;
        let Some(pose) = amcl.predict_pose(&o.odom) else {
            return Err(setup("amcl")("no estimate after initialization".into()));
        };
        // The comparison: the only place the truth is read.
        let pos_err = pose.distance_m(&o.ground_truth_pose);
        let yaw_err = normalize_angle(pose.yaw_rad - o.ground_truth_pose.yaw_rad)
            .abs()
            .to_degrees();
        sum_pos += pos_err;
        sum_yaw += yaw_err;
        max_pos = max_pos.max(pos_err);
        max_yaw = max_yaw.max(yaw_err);
        cycles += 1;
        tracing::trace!(
            t_s,
            pos_err,
            yaw_err,
            x = pose.x_m,
            y = pose.y_m,
            tx = o.ground_truth_pose.x_m,
            ty = o.ground_truth_pose.y_m,
            v = cmd.v_mps,
            w = cmd.omega_radps,
            "step"
        );
        if cycles % 50 == 0 {
            tracing::debug!(task = %task, t_s, goal_index, ?pose, truth = ?o.ground_truth_pose, ?cmd, collisions, "cycle");
        }

        // The human watching the robot: the truth is read here, never to steer.
        let truth = o.ground_truth_pose;
        if truth.distance_m(&progress_at) >= PROGRESS_M {
            (progress_at, progress_s) = (truth, t_s);
        }
        let collided = !o.collisions.is_empty();
        if collided || t_s - progress_s > options.stuck_timeout_s {
            let path = intention.as_ref().map_or(&[][..], |i| i.path.as_slice());
            match put_down_pose(&world, path, truth, options.intervention_ahead_m) {
                Some(put) => {
                    world
                        .carry_robot(0, put)
                        .map_err(|e| setup("intervention")(e.to_string()))?;
                    amcl.set_initial_pose(put, agent.localization.initial_covariance())
                        .map_err(|e| setup("intervention")(e.to_string()))?;
                    interventions += 1;
                    tracing::debug!(task = %task, t_s, ?truth, ?put, collided, "intervention");
                    last_truth = put;
                    (progress_at, progress_s) = (put, t_s);
                    intention = None;
                    pipeline.clear_trail();
                    cmd = Command::default();
                    controller.reset();
                    progress(t_s, max_sim_s, goals_reached);
                    continue;
                }
                None => {
                    tracing::debug!(task = %task, t_s, ?truth, "no free spot ahead on the path")
                }
            }
        }

        if t_s - goal_started_s > options.goal_timeout_s {
            tracing::warn!(task = %task, goal_index, "goal not reached in {} s; next goal", options.goal_timeout_s);
            goal_index += 1;
            goal_started_s = t_s;
            intention = None;
            cmd = Command::default();
            controller.reset();
            continue;
        }
        if intention.is_none() || cycles % u64::from(options.replan_every.max(1)) == 0 {
            // What the agent would publish, answered as the service answers it.
            let estimate = PoseEstimate {
                header: Header::new(cycles, obs.time_ns),
                pose,
                covariance: amcl.estimate().map_or([0.0; 9], |e| e.covariance),
                sensor_stamp_ns: obs.time_ns,
                map: map_ref.clone(),
            };
            let header = Header::new(cycles, obs.time_ns);
            match pipeline.answer(&estimate, &GoalProgress::new(&goals, goal_index), false) {
                Answer::Done => {
                    goals_reached += goals_total - goal_index;
                    goal_index = goals_total;
                    continue;
                }
                Answer::Heading {
                    goal_index: k,
                    plan,
                } => {
                    if k > goal_index {
                        goals_reached += k - goal_index;
                        goal_index = k;
                        goal_started_s = t_s;
                    }
                    intention = Some(match plan {
                        Ok(p) => p.intention(header, &estimate, task_id.clone(), k, false),
                        Err(e) => {
                            tracing::debug!(task = %task, "replan failed: {e}");
                            stop_intention(header, &estimate, task_id.clone(), k)
                        }
                    });
                }
            }
        }
        let Some(intention) = intention.as_ref() else {
            cmd = Command::default();
            progress(t_s, max_sim_s, goals_reached);
            continue;
        };
        let input = ControlInput {
            pose,
            v_mps: o.odom.v_mps,
            omega_radps: o.odom.omega_radps,
            scan: Some(&o.scan),
            camera: None,
            intention: Some(intention),
            limits: &agent.limits,
            dt_s: options.dt_s,
        };
        cmd = match controller.control(&input) {
            Ok(c) => {
                let (v, w) = c.to_physical(&agent.limits);
                Command {
                    v_mps: v,
                    omega_radps: w,
                }
            }
            Err(e) => {
                tracing::debug!(task = %task, "controller: {e}");
                Command::default()
            }
        };
        progress(t_s, max_sim_s, goals_reached);
    }
    #[allow(clippy::cast_precision_loss)]
    let n = cycles.max(1) as f64;
    let mean_position_error_m = sum_pos / n;
    let mean_heading_error_deg = sum_yaw / n;
    let diverged = max_pos > DIVERGED_POSITION_ERROR_M;
    Ok(TaskAccuracy {
        task,
        cycles,
        sim_time_s: t_s,
        mean_position_error_m,
        max_position_error_m: max_pos,
        mean_heading_error_deg,
        max_heading_error_deg: max_yaw,
        diverged,
        goals_reached,
        goals_total,
        distance_m,
        collisions,
        interventions,
        pass: !diverged
            && mean_position_error_m <= MAX_MEAN_POSITION_ERROR_M
            && mean_heading_error_deg <= MAX_MEAN_HEADING_ERROR_DEG,
    })
}

/// Where an intervention puts the robot down: the first pose on `path`, at least `ahead_m`
/// along it beyond the point nearest to the true position, where the robot's disc (plus a
/// margin) overlaps nothing, facing along the path; None when no such pose exists.
fn put_down_pose(world: &World, path: &[Pose2D], truth: Pose2D, ahead_m: f64) -> Option<Pose2D> {
    let nearest = path
        .iter()
        .enumerate()
        .min_by(|a, b| a.1.distance_m(&truth).total_cmp(&b.1.distance_m(&truth)))?
        .0;
    let radius_m = world.config.base.radius_m + PUT_DOWN_CLEARANCE_M;
    let mut along_m = 0.0;
    for k in nearest..path.len() {
        if k > nearest {
            along_m += path[k].distance_m(&path[k - 1]);
        }
        let p = path[k];
        if along_m >= ahead_m
            && world
                .disc_overlap(p.x_m, p.y_m, radius_m, Some(0), true)
                .is_none()
        {
            return Some(p);
        }
    }
    None
}

/// A markdown table of the results, one row per task.
#[must_use]
pub fn markdown(results: &[TaskAccuracy]) -> String {
    let mut out = String::from(
        "| task | mean pos. err (m) | max pos. err (m) | mean heading err (deg) | max heading err (deg) | diverged | goals reached | distance (m) | sim time (s) | collisions | interventions | verdict (mean <= 0.10 m, <= 3 deg) |\n|---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for r in results {
        out.push_str(&format!(
            "| {} | {:.3} | {:.3} | {:.2} | {:.2} | {} | {}/{} | {:.1} | {:.1} | {} | {} | {} |\n",
            r.task,
            r.mean_position_error_m,
            r.max_position_error_m,
            r.mean_heading_error_deg,
            r.max_heading_error_deg,
            if r.diverged { "yes" } else { "no" },
            r.goals_reached,
            r.goals_total,
            r.distance_m,
            r.sim_time_s,
            r.collisions,
            r.interventions,
            if r.pass { "pass" } else { "FAIL" },
        ));
    }
    out
}
