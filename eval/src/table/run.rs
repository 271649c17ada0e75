//! One closed-loop run: a scenario, a method and a seed, in lock-step in one thread.
//!
//! Every control cycle the simulator steps by `dt_s`; the robot agent's own [`Supervisor`] takes
//! the odometry and the scan (AMCL on the crude floor plan), the camera frame when the method
//! reads it, and the intention that the planning crate's [`IntentionPlanner`] answers to the
//! pose the supervisor publishes, exactly as the fleet service answers it; the supervisor's
//! safety rules and the method's controller give the command for the next step. Time is the
//! simulation's: the supervisor's clock is a fixed instant plus the simulated time, so a run
//! depends on nothing but its seed.
//!
//! Only the [`judge`](super::judge) (the person watching) and the privileged expert read the
//! ground truth. With [`TableOptions::record`] a run also writes a run log
//! ([`log`](super::log)): sensors, the published poses, intentions, commands, the truth and
//! every re-initialisation after an intervention.

use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::{Duration, Instant};

use map_core::OccupancyGrid;
use planning::{stop_intention, Answer, Goal, GoalProgress, IntentionPlanner, PlanningMap};
use protocol::{
    normalize_angle, ControllerKind, Intention, MapName, MapRef, Pose2D, PoseEstimate, TaskId,
};
use robot_agent::controllers::Controller;
use robot_agent::node::Decision;
use robot_agent::{make_controller, AgentConfig, Supervisor};
use serde::{Deserialize, Serialize};
use sim::scenario::Role;
use sim::{Command, Scenario, SimConfig, World};

use super::judge::{self, Collisions, GoalDistance};
use super::log::{safe_chars, RunRecorder};
use super::{TableError, TableOptions};
use crate::expert::{Expert, SharedTruth, TruthView};
use crate::metrics::{self, TrajectorySample};

/// The true position must get this much closer to the goal (along the floor plan) within
/// `stuck_timeout_s` to count as progress.
pub const PROGRESS_M: f64 = 0.5;

/// A scenario loaded once and shared by all its runs.
#[derive(Debug)]
pub struct Prepared {
    pub path: PathBuf,
    pub scenario: Scenario,
    pub plan: OccupancyGrid,
    pub planning: Arc<PlanningMap>,
    /// Geodesic distance to each goal, for the judge.
    pub goal_distance: Vec<GoalDistance>,
}

impl Prepared {
    /// Loads a scenario file and its floor plan and builds what every run of it shares.
    ///
    /// # Errors
    /// [`TableError::Scenario`] naming the file for an unreadable or invalid scenario or plan.
    pub fn load(path: &Path, options: &TableOptions) -> Result<Self, TableError> {
        let scenario_err = |p: &Path, e: String| TableError::Scenario {
            path: p.display().to_string(),
            reason: e,
        };
        let scenario = Scenario::load(path).map_err(|e| scenario_err(path, e.to_string()))?;
        let plan_path = scenario.floor_plan_path(path);
        let plan = map_core::load_ros_map(&plan_path, &map_core::ImportLimits::default())
            .map_err(|e| scenario_err(&plan_path, e.to_string()))?
            .grid;
        Self::new(path, scenario, plan, options)
    }

    /// Builds what every run of a scenario shares from the scenario and its floor plan in
    /// memory (e.g. a generated building); `path` only names it.
    ///
    /// # Errors
    /// [`TableError::Scenario`] naming `path` when the plan cannot be planned on.
    pub fn new(
        path: &Path,
        scenario: Scenario,
        plan: OccupancyGrid,
        options: &TableOptions,
    ) -> Result<Self, TableError> {
        let planning = Arc::new(
            PlanningMap::new(plan.clone(), &options.intention.planner).map_err(|e| {
                TableError::Scenario {
                    path: path.display().to_string(),
                    reason: e.to_string(),
                }
            })?,
        );
        let goal_distance = scenario
            .goals
            .iter()
            .map(|g| GoalDistance::new(&plan, g.x_m, g.y_m))
            .collect();
        Ok(Self {
            path: path.to_path_buf(),
            scenario,
            plan,
            planning,
            goal_distance,
        })
    }

    /// Whether the scenario checks a behaviour (no interventions; judged by its expectation).
    #[must_use]
    pub fn is_behaviour(&self) -> bool {
        self.scenario.role == Role::Behaviour
    }
}

/// What one run measured (one object of `runs.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunResult {
    pub scenario: String,
    /// `training`, `evaluation` or `behaviour`.
    pub role: String,
    pub method: ControllerKind,
    pub seed: u64,
    /// Evaluation and training: every goal reached within the time limit and at most the
    /// intervention limit. Behaviour: no collision, and the goals reached exactly when the
    /// scenario expects them to be.
    pub success: bool,
    /// Why a run failed (`None` on success).
    pub failure: Option<String>,
    pub interventions: u32,
    /// When, where and why the human intervened.
    pub intervention_log: Vec<InterventionEvent>,
    /// Contacts by what was touched (a contact counts once however long it lasts).
    pub collisions: Collisions,
    /// Simulated seconds until the last goal was reached (or the run ended).
    pub time_s: f64,
    /// Mean |jerk| of the true trajectory in m/s³ (see `docs/evaluation.md`); `None` for a run
    /// too short to have one.
    pub smoothness: Option<f64>,
    /// Length of the true trajectory (interventions' carries excluded).
    pub path_length_m: f64,
    /// Smallest gap between the robot's disc and a person's (0: contact); `None` without people.
    pub min_person_distance_m: Option<f64>,
    /// Smallest gap between the robot's disc and a glass pane; `None` without glass.
    pub min_glass_distance_m: Option<f64>,
    pub goals_reached: usize,
    pub goals_total: usize,
    /// Mean distance between the pose the agent published (AMCL carried forward by odometry,
    /// every cycle) and the truth.
    pub mean_position_error_m: f64,
    pub max_position_error_m: f64,
    pub mean_heading_error_deg: f64,
    pub max_heading_error_deg: f64,
    /// Share of the cycles in which the collision monitor slowed or stopped the controller's
    /// command (`None`: the monitor was off).
    #[serde(default)]
    pub collision_monitor_share: Option<f64>,
    /// Share of the cycles in which the dynamic window drove in place of a controller the
    /// monitor held (`[safety.recovery]`; `None`: no recovery for this method).
    #[serde(default)]
    pub recovery_share: Option<f64>,
    /// How many times the dynamic window took over (`None` as for `recovery_share`).
    #[serde(default)]
    pub recoveries: Option<u32>,
    /// How many camera holds started (`[safety.camera_hold]`; `None`: off, or not for this
    /// method: only LPE-Net's brakes count by default).
    #[serde(default)]
    pub camera_holds: Option<u32>,
    /// The DLM told against the DLM the true pose would have given (`None`: not audited).
    #[serde(default)]
    pub intention_audit: Option<super::audit::IntentionAudit>,
    /// Wall-clock seconds the run took (not deterministic; everything else is).
    pub wall_s: f64,
}

/// One human intervention.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct InterventionEvent {
    pub t_s: f64,
    /// Where the robot was picked up (true position).
    pub x_m: f64,
    pub y_m: f64,
    /// `collision: <what>` or `no progress`.
    pub cause: String,
    /// For a contact with a person or another robot: where their centre was, seen from the
    /// robot's centre, against its heading (rad, left positive) ...
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub contact_bearing_rad: Option<f64>,
    /// ... and whether any of them was inside the camera's field of view: if not, a
    /// camera-driven controller could not see what it touched.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub contact_in_camera_view: Option<bool>,
    /// The gap between the robot's disc and the nearest glass pane then (absent without
    /// glass): a "no progress" a few decimetres from a pane is a robot standing before a shut
    /// glass door, as it should.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub glass_gap_m: Option<f64>,
}

/// The picture material of a run (kept in memory for the figures, not in `runs.json`).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RunTrace {
    /// True positions, one per cycle.
    pub points_m: Vec<(f64, f64)>,
    /// The planner's first path of every leg.
    pub planned_m: Vec<(f64, f64)>,
    /// Where interventions picked the robot up.
    pub interventions_m: Vec<(f64, f64)>,
    pub collisions_m: Vec<(f64, f64)>,
}

/// The task id a run's intentions carry: the scenario's name where it is a valid id, else the
/// name with every character an id may not hold replaced by `_`, cut to the id length limit.
/// An intention without a task means "nothing to do" to the agent, which would rest for the
/// whole run (a scenario named `my building` did).
fn task_id_of(name: &str) -> Option<TaskId> {
    let fallback = || {
        let cleaned: String = safe_chars(name).take(protocol::ids::MAX_ID_LEN).collect();
        let cleaned = cleaned.trim_start_matches('.');
        TaskId::new(if cleaned.is_empty() { "run" } else { cleaned })
    };
    TaskId::new(name).or_else(|_| fallback()).ok()
}

fn setup(what: &'static str) -> impl FnOnce(String) -> TableError {
    move |reason| TableError::Setup { what, reason }
}

/// The agent configuration of a method: the base one with this controller and, for the
/// networks, the model `<models_dir>/<method>.onnx`.
fn agent_config(
    options: &TableOptions,
    method: ControllerKind,
    start: Pose2D,
    seed: u64,
) -> AgentConfig {
    let mut agent = options.agent.clone();
    agent.controller = method;
    if method.needs_model() {
        agent.model = Some(options.model_path(method));
        // Runs go in parallel on all cores already.
        agent.intention_net.intra_threads = 1;
    }
    agent.amcl.seed ^= seed;
    // The operator places the robot where the scenario says and tells the agent so.
    agent.localization.initial_pose = Some(start);
    agent
}

/// What a [`CycleObserver`] sees at the end of one control cycle (after the supervisor decided).
pub struct Cycle<'a> {
    /// Simulated time.
    pub t_s: f64,
    /// The world, mutable so that the observer can render the camera.
    pub world: &'a mut World,
    pub truth_pose: Pose2D,
    /// The pose the agent published this cycle (`None`: no scan was processed).
    pub estimate_pose: Option<Pose2D>,
    /// The intention the supervisor got this cycle (`None`: none was answered).
    pub intention: Option<&'a Intention>,
    /// The supervisor's command (the method's controller through the safety rules).
    pub decision: &'a Decision,
    /// The goal the robot heads for.
    pub goal_index: usize,
}

/// What the loop does after a [`CycleObserver`] saw a cycle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CycleOutcome {
    /// The command the robot executes in the next step.
    pub cmd: Command,
    /// End the run now (it is then judged as if the time limit had come).
    pub stop: bool,
}

/// A hook into every control cycle of [`run_with`]: `eval record` stores samples with it and
/// perturbs the executed command (noise injection).
pub trait CycleObserver {
    /// Whether the pipeline renders the LPE image even for a method that does not read it.
    fn render_lpe(&self) -> bool {
        false
    }

    /// Whether the supervisor gets the camera even for a method that does not read it.
    fn reads_camera(&self) -> bool {
        false
    }

    /// The controller the supervisor runs, given the method's (DAgger wraps the expert with
    /// the learner that drives).
    ///
    /// # Errors
    /// Any [`TableError`]; the run is not set up.
    fn controller(
        &mut self,
        method_controller: Box<dyn Controller>,
    ) -> Result<Box<dyn Controller>, TableError> {
        Ok(method_controller)
    }

    /// Called once per cycle after the supervisor's decision (not on a cycle that ends in an
    /// intervention or with the last goal reached).
    ///
    /// # Errors
    /// Any [`TableError`]; it ends the run with that error.
    fn on_cycle(&mut self, cycle: Cycle<'_>) -> Result<CycleOutcome, TableError>;
}

/// Runs `method` on a prepared scenario with `seed` (mixed into the world's and AMCL's seeds;
/// 0 keeps the scenario's own). `progress` gets the simulated seconds of every cycle.
///
/// # Errors
/// [`TableError`] when the world, the controller (e.g. a missing model) or the pipeline
/// cannot be set up; what happens during the run is measured, not an error.
pub fn run_one(
    prepared: &Prepared,
    method: ControllerKind,
    seed: u64,
    options: &TableOptions,
    progress: impl FnMut(f64),
) -> Result<(RunResult, RunTrace), TableError> {
    run_with(prepared, method, seed, options, progress, None)
}

/// [`run_one`] with an optional [`CycleObserver`] that sees every cycle and chooses the
/// executed command.
///
/// # Errors
/// As [`run_one`], and whatever the observer returns.
#[allow(clippy::too_many_lines)]
pub fn run_with(
    prepared: &Prepared,
    method: ControllerKind,
    seed: u64,
    options: &TableOptions,
    mut progress: impl FnMut(f64),
    mut observer: Option<&mut dyn CycleObserver>,
) -> Result<(RunResult, RunTrace), TableError> {
    let render_lpe = method.reads_lpe() || observer.as_ref().is_some_and(|o| o.render_lpe());
    let reads_camera = method.reads_camera() || observer.as_ref().is_some_and(|o| o.reads_camera());
    let started = Instant::now();
    let mut scenario = prepared.scenario.clone();
    scenario.seed ^= seed;
    let name = scenario.name.clone();
    let role = serde_json::to_value(scenario.role)
        .ok()
        .and_then(|v| v.as_str().map(str::to_owned))
        .unwrap_or_default();
    let behaviour = prepared.is_behaviour();
    let expect_goals = scenario.expect_goals_reached;
    let time_limit_s = options.time_limit_s.unwrap_or(scenario.time_limit_s);
    let goals: Vec<Goal> = scenario
        .goals
        .iter()
        .map(|g| Goal::at(g.x_m, g.y_m))
        .collect();
    let goals_total = goals.len();
    let mut world = World::new(scenario, prepared.plan.clone(), SimConfig::default())
        .map_err(|e| setup("world")(e.to_string()))?;
    world
        .add_robots_at_start(1)
        .and_then(|()| world.add_parked_robots())
        .map_err(|e| setup("robot")(e.to_string()))?;
    let start = world
        .ground_truth_pose(0)
        .ok_or_else(|| setup("robot")("no robot".into()))?;

    let agent = agent_config(options, method, start, seed);
    let truth: SharedTruth = Arc::new(Mutex::new(TruthView::of(&world, 0)));
    let controller: Box<dyn Controller> = if method == ControllerKind::Expert {
        Box::new(
            Expert::new(&world, options.expert, Arc::clone(&truth))
                .map_err(|e| setup("expert")(e.to_string()))?,
        )
    } else {
        make_controller(&agent).map_err(|e| TableError::Controller {
            method,
            reason: e.to_string(),
        })?
    };
    let controller = match observer.as_deref_mut() {
        Some(o) => o.controller(controller)?,
        None => controller,
    };
    let map = MapRef {
        name: MapName::new("plan").map_err(|e| setup("map name")(e.to_string()))?,
        version: 1,
    };
    let initial_covariance = agent.localization.initial_covariance();
    let mut recorder = match &options.record {
        Some(settings) => Some(RunRecorder::start(
            settings,
            prepared,
            method,
            seed,
            &agent,
            start,
            initial_covariance,
        )?),
        None => None,
    };
    let record_camera = recorder.as_ref().is_some_and(RunRecorder::wants_camera);
    let monitor_on = agent.safety.collision_monitor.enabled;
    let mut supervisor = Supervisor::new(agent, map, &prepared.plan, controller)
        .map_err(|e| setup("agent")(e.to_string()))?;
    let mut pipeline =
        IntentionPlanner::new(Arc::clone(&prepared.planning), options.intention.clone())
            .map_err(|e| setup("intention pipeline")(e.to_string()))?;
    let task_id = task_id_of(&name);
    // The same pipeline fed the true pose: what the robot should have been told.
    let mut truth_pipeline = if options.audit_intentions {
        Some(
            IntentionPlanner::new(Arc::clone(&prepared.planning), options.intention.clone())
                .map_err(|e| setup("intention pipeline")(e.to_string()))?,
        )
    } else {
        None
    };
    let mut auditor = super::audit::Auditor::default();

    let dt_s = options.dt_s;
    // The supervisor's clock: a fixed origin plus simulated time.
    let epoch = Instant::now();
    let mut cmd = Command::default();
    let mut trace = RunTrace::default();
    let mut samples: Vec<Vec<TrajectorySample>> = vec![Vec::new()];
    let mut collisions = Collisions::default();
    let mut intervention_log = Vec::new();
    let mut in_contact = false;
    let (mut goal_index, mut interventions) = (0usize, 0u32);
    let mut last_path: Vec<Pose2D> = Vec::new();
    let mut planned_leg: Option<usize> = None;
    let mut min_person: Option<f64> = None;
    let mut min_glass: Option<f64> = None;
    let (mut sum_err, mut max_err, mut cycles) = (0.0f64, 0.0f64, 0u64);
    let mut monitor_limited = 0u64;
    let mut recovering_cycles = 0u64;
    let (mut sum_yaw_err, mut max_yaw_err) = (0.0f64, 0.0f64);
    let mut path_length_m = 0.0;
    let mut last_truth = start;
    // The judge's progress: the best remaining distance to the current goal and when.
    let mut best_remaining = prepared.goal_distance[0].at(start.x_m, start.y_m);
    let mut progress_s = 0.0;
    let mut t_s = 0.0;
    let mut time_ns = 0u64;
    let mut failure: Option<String> = None;
    let mut finished_s: Option<f64> = None;

    while t_s < time_limit_s {
        let obs = world.step(&[cmd], dt_s);
        t_s += dt_s;
        let now = epoch + Duration::from_nanos(obs.time_ns);
        let o = &obs.robots[0];
        let truth_pose = o.ground_truth_pose;
        time_ns = obs.time_ns;
        if let Some(r) = recorder.as_mut() {
            r.sensors(&o.odom, &o.scan, truth_pose)?;
        }
        path_length_m += truth_pose.distance_m(&last_truth);
        last_truth = truth_pose;
        trace.points_m.push((truth_pose.x_m, truth_pose.y_m));
        if let Some(last) = samples.last_mut() {
            last.push(TrajectorySample {
                t_s,
                x_m: truth_pose.x_m,
                y_m: truth_pose.y_m,
            });
        }
        // A contact counts once, however many steps the robot keeps pushing (only behaviour
        // runs, which have no interventions, go on pushing).
        if let Some(c) = o.collisions.first() {
            if !in_contact {
                collisions.count(&c.with);
                trace
                    .collisions_m
                    .push((c.stopped_at.x_m, c.stopped_at.y_m));
            }
        }
        in_contact = !o.collisions.is_empty();
        if let Some(g) = judge::person_gap_m(&world, 0) {
            min_person = Some(min_person.map_or(g, |m: f64| m.min(g)));
        }
        if let Some(g) = judge::glass_gap_m(&world, 0) {
            min_glass = Some(min_glass.map_or(g, |m: f64| m.min(g)));
        }
        progress(t_s);

        // The agent: odometry, then AMCL on the scan; the pose it publishes.
        supervisor.on_odometry(o.odom.clone());
        let estimate = supervisor
            .on_scan(o.scan.clone(), now, obs.time_ns)
            .map_err(|e| setup("agent scan")(e.to_string()))?;
        if let Some(e) = &estimate {
            if let Some(r) = recorder.as_mut() {
                r.pose(e)?;
            }
            let err = e.pose.distance_m(&truth_pose);
            let yaw_err = normalize_angle(e.pose.yaw_rad - truth_pose.yaw_rad)
                .abs()
                .to_degrees();
            sum_err += err;
            max_err = max_err.max(err);
            sum_yaw_err += yaw_err;
            max_yaw_err = max_yaw_err.max(yaw_err);
            cycles += 1;
        }

        // The person watching.
        let remaining = prepared.goal_distance[goal_index.min(goals_total - 1)]
            .at(truth_pose.x_m, truth_pose.y_m);
        if remaining <= best_remaining - PROGRESS_M {
            (best_remaining, progress_s) = (remaining, t_s);
        }
        let collided = o.collisions.first().map(|c| c.with.clone());
        if !behaviour && (collided.is_some() || t_s - progress_s > options.stuck_timeout_s) {
            if interventions >= options.max_interventions {
                failure = Some(format!(
                    "more than {} interventions",
                    options.max_interventions
                ));
                break;
            }
            // Before the robot is carried away from it.
            let glass_gap_m = judge::glass_gap_m(&world, 0);
            if let Some(put) = judge::put_down_pose(
                &world,
                0,
                &last_path,
                truth_pose,
                options.intervention_ahead_m,
            ) {
                world
                    .carry_robot(0, put)
                    .map_err(|e| setup("intervention")(e.to_string()))?;
                supervisor
                    .set_pose(put, initial_covariance)
                    .map_err(|e| setup("intervention")(e.to_string()))?;
                if let Some(r) = recorder.as_mut() {
                    // Where the live filter restarted, so that a replay restarts there too.
                    r.reinit(
                        protocol::Header::new(u64::from(interventions) + 1, obs.time_ns),
                        put,
                        initial_covariance,
                    )?;
                    r.cmd(obs.time_ns, 0.0, 0.0)?;
                }
                pipeline.clear_trail();
                if let Some(p) = truth_pipeline.as_mut() {
                    p.clear_trail();
                }
                auditor.on_intervention(t_s);
                interventions += 1;
                trace.interventions_m.push((truth_pose.x_m, truth_pose.y_m));
                let sight = collided
                    .as_ref()
                    .and_then(|w| judge::contact_sight(&world, 0, truth_pose, w));
                intervention_log.push(InterventionEvent {
                    t_s,
                    x_m: truth_pose.x_m,
                    y_m: truth_pose.y_m,
                    cause: collided.as_ref().map_or_else(
                        || "no progress".to_string(),
                        |w| format!("collision: {}", judge::obstacle_kind(w)),
                    ),
                    contact_bearing_rad: sight.map(|s| s.bearing_rad),
                    contact_in_camera_view: sight.map(|s| s.in_camera_view),
                    glass_gap_m,
                });
                tracing::debug!(scenario = %name, %method, seed, t_s, ?truth_pose, ?put, ?collided, "intervention");
                last_truth = put;
                in_contact = false;
                samples.push(Vec::new());
                best_remaining =
                    prepared.goal_distance[goal_index.min(goals_total - 1)].at(put.x_m, put.y_m);
                progress_s = t_s;
                cmd = Command::default();
                continue;
            }
            tracing::debug!(scenario = %name, %method, seed, t_s, "no free spot ahead on the path");
        }

        // The planner service's answer to the published pose.
        let estimate_pose = estimate.as_ref().map(|e| e.pose);
        // A copy for the observer only (the supervisor takes the intention).
        let mut answered: Option<Intention> = None;
        if let Some(estimate) = estimate {
            let header = estimate.header;
            let intention: Intention = match pipeline.answer(
                &estimate,
                &GoalProgress::new(&goals, goal_index),
                render_lpe,
            ) {
                Answer::Done => {
                    goal_index = goals_total;
                    finished_s = Some(t_s);
                    break;
                }
                Answer::Heading {
                    goal_index: k,
                    plan,
                } => {
                    if k > goal_index {
                        goal_index = k;
                        best_remaining =
                            prepared.goal_distance[k].at(truth_pose.x_m, truth_pose.y_m);
                        progress_s = t_s;
                    }
                    match plan {
                        Ok(p) => {
                            if let Some(tp) = truth_pipeline.as_mut() {
                                let true_estimate = PoseEstimate {
                                    pose: truth_pose,
                                    ..estimate.clone()
                                };
                                if let Answer::Heading {
                                    goal_index: tk,
                                    plan: Ok(tplan),
                                } = tp.answer(
                                    &true_estimate,
                                    &GoalProgress::new(&goals, goal_index),
                                    false,
                                ) {
                                    if tk == k {
                                        auditor.on_cycle(
                                            t_s,
                                            p.dlm,
                                            tplan.dlm,
                                            estimate.pose.distance_m(&truth_pose),
                                        );
                                    }
                                }
                            }
                            last_path.clone_from(&p.path);
                            if planned_leg != Some(k) {
                                planned_leg = Some(k);
                                trace
                                    .planned_m
                                    .extend(p.path.iter().map(|q| (q.x_m, q.y_m)));
                            }
                            p.intention(header, &estimate, task_id.clone(), k, render_lpe)
                        }
                        Err(e) => {
                            tracing::debug!(scenario = %name, %method, seed, "replan failed: {e}");
                            stop_intention(header, &estimate, task_id.clone(), k)
                        }
                    }
                }
            };
            if observer.is_some() {
                answered = Some(intention.clone());
            }
            if let Some(r) = recorder.as_mut() {
                r.intention(&intention)?;
            }
            if let Err(reason) = supervisor.on_intention(intention) {
                tracing::warn!(scenario = %name, "intention refused: {reason}");
            }
            // As the fleet's workers do once the intention is out.
            for p in std::iter::once(&mut pipeline).chain(truth_pipeline.as_mut()) {
                if let Err(e) = p.refresh() {
                    tracing::debug!(scenario = %name, "the due new search found no path: {e}");
                }
            }
        }
        if reads_camera || record_camera {
            // Rendering draws no random numbers: recording the camera changes nothing else.
            let frame = world
                .camera_frame(0)
                .map_err(|e| setup("camera")(e.to_string()))?;
            if let Some(r) = recorder.as_mut() {
                r.camera(&frame)?;
            }
            if reads_camera {
                supervisor.on_camera(frame);
            }
        }
        if method == ControllerKind::Expert {
            *truth.lock().unwrap_or_else(PoisonError::into_inner) = TruthView::of(&world, 0);
        }
        let decision = supervisor.control(now);
        monitor_limited += u64::from(decision.collision_monitor.is_some_and(|v| v.limited()));
        recovering_cycles += u64::from(decision.recovering);
        tracing::trace!(
            scenario = %name, %method, seed, t_s,
            x = truth_pose.x_m, y = truth_pose.y_m, yaw = truth_pose.yaw_rad,
            v = decision.cmd_v_mps, w = decision.cmd_omega_radps,
            state = ?decision.state, goal_index, remaining,
            monitor_scale = decision.collision_monitor.map(|m| m.scale),
            recovering = decision.recovering,
            backing_up = decision.backing_up,
            rotating = decision.rotating,
            giving_way = decision.giving_way,
            people = ?world.people.iter().map(|p| (p.x_m, p.y_m)).collect::<Vec<_>>(),
            "cycle"
        );
        cmd = Command {
            v_mps: decision.cmd_v_mps,
            omega_radps: decision.cmd_omega_radps,
        };
        if let Some(o) = observer.as_deref_mut() {
            let outcome = o.on_cycle(Cycle {
                t_s,
                world: &mut world,
                truth_pose,
                estimate_pose,
                intention: answered.as_ref(),
                decision: &decision,
                goal_index,
            })?;
            cmd = outcome.cmd;
            if outcome.stop {
                break;
            }
        }
        if let Some(r) = recorder.as_mut() {
            r.status(supervisor.status(0, obs.time_ns))?;
            r.cmd(obs.time_ns, cmd.v_mps, cmd.omega_radps)?;
        }
    }

    let goals_reached = goal_index.min(goals_total);
    let no_contact = collisions.total() == 0;
    let success = if behaviour {
        let reached_all = goals_reached == goals_total;
        let ok = no_contact && reached_all == expect_goals;
        if !ok {
            failure = Some(if !no_contact {
                format!("{} collision(s)", collisions.total())
            } else if expect_goals {
                "goal not reached".to_string()
            } else {
                "reached a goal it should not".to_string()
            });
        }
        ok
    } else {
        if failure.is_none() && goals_reached < goals_total {
            failure = Some(format!("time limit {time_limit_s} s"));
        }
        failure.is_none()
    };
    let jerk = segments_jerk(&samples);
    #[allow(clippy::cast_precision_loss)]
    let n = cycles.max(1) as f64;
    let result = RunResult {
        scenario: name,
        role,
        method,
        seed,
        success,
        failure,
        interventions,
        intervention_log,
        collisions,
        time_s: finished_s.unwrap_or(t_s),
        smoothness: jerk,
        path_length_m,
        min_person_distance_m: min_person,
        min_glass_distance_m: min_glass,
        goals_reached,
        goals_total,
        mean_position_error_m: sum_err / n,
        max_position_error_m: max_err,
        mean_heading_error_deg: sum_yaw_err / n,
        max_heading_error_deg: max_yaw_err,
        #[allow(clippy::cast_precision_loss)]
        collision_monitor_share: monitor_on.then(|| monitor_limited as f64 / n),
        #[allow(clippy::cast_precision_loss)]
        recovery_share: supervisor.recovers().then(|| recovering_cycles as f64 / n),
        recoveries: supervisor.recovers().then(|| supervisor.recoveries()),
        camera_holds: supervisor.camera_holds(),
        intention_audit: truth_pipeline.is_some().then(|| auditor.finish()),
        wall_s: started.elapsed().as_secs_f64(),
    };
    if let Some(r) = recorder {
        r.finish(time_ns, &result)?;
    }
    Ok((result, trace))
}

/// Mean |jerk| over the trajectory's pieces between interventions, weighted by their lengths
/// (a carry is not motion).
fn segments_jerk(segments: &[Vec<TrajectorySample>]) -> Option<f64> {
    let (mut sum, mut n) = (0.0, 0usize);
    for s in segments.iter().filter(|s| s.len() >= 4) {
        if let Ok(j) = metrics::mean_abs_jerk_mps3(s) {
            let k = s.len() - 3;
            #[allow(clippy::cast_precision_loss)]
            {
                sum += j * k as f64;
            }
            n += k;
        }
    }
    #[allow(clippy::cast_precision_loss)]
    (n > 0).then(|| sum / n as f64)
}

/// A run with plain figures, for the unit tests of what is made of runs (`report`, `compare`,
/// `places`): it succeeds below 30 interventions and touches glass once above 2.
#[cfg(test)]
pub(crate) fn test_run(
    scenario: &str,
    seed: u64,
    method: ControllerKind,
    interventions: u32,
) -> RunResult {
    RunResult {
        scenario: scenario.to_string(),
        role: "evaluation".to_string(),
        method,
        seed,
        success: interventions < 30,
        failure: None,
        interventions,
        intervention_log: Vec::new(),
        collisions: super::judge::Collisions {
            glass: u32::from(interventions > 2),
            ..super::judge::Collisions::default()
        },
        time_s: 100.0 + f64::from(interventions),
        smoothness: Some(1.5),
        path_length_m: 50.0,
        min_person_distance_m: None,
        min_glass_distance_m: None,
        goals_reached: 4,
        goals_total: 4,
        mean_position_error_m: 0.02,
        max_position_error_m: 0.1,
        mean_heading_error_deg: 1.0,
        max_heading_error_deg: 3.0,
        collision_monitor_share: None,
        recovery_share: None,
        recoveries: None,
        camera_holds: None,
        intention_audit: None,
        wall_s: 1.0,
    }
}

/// [`test_run`] with these pick-ups `(x_m, y_m, cause)`, 10 s apart, as its interventions.
#[cfg(test)]
pub(crate) fn test_run_with_log(
    scenario: &str,
    seed: u64,
    method: ControllerKind,
    picks: &[(f64, f64, &str)],
) -> RunResult {
    let mut run = test_run(
        scenario,
        seed,
        method,
        u32::try_from(picks.len()).unwrap_or(u32::MAX),
    );
    run.intervention_log = picks
        .iter()
        .zip(0u32..)
        .map(|(&(x_m, y_m, cause), i)| InterventionEvent {
            t_s: 10.0 * f64::from(i),
            x_m,
            y_m,
            cause: cause.to_string(),
            contact_bearing_rad: None,
            contact_in_camera_view: None,
            glass_gap_m: None,
        })
        .collect();
    run
}
