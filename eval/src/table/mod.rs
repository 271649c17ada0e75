//! `eval table`: the paper's Table 1 and Figure 5 in closed loop (DESIGN §9).
//!
//! Every scenario × method × seed is one deterministic lock-step run ([`run`]): simulator,
//! the robot agent's own supervisor (AMCL, safety rules, the method's controller) and the
//! planning crate's intention pipeline, with a [`judge`] that intervenes like the paper's
//! human. Runs spread over threads; [`report`] aggregates them into `runs.json`, `table.json`,
//! `table.md` and the pictures.

pub mod audit;
pub mod compare;
pub mod judge;
pub mod log;
pub mod places;
pub mod report;
pub mod run;

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Mutex, PoisonError};

use planning::IntentionConfig;
use protocol::ControllerKind;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use robot_agent::AgentConfig;

use crate::expert::ExpertConfig;
use crate::record::encounter::Encounter;
pub use run::{run_one, Prepared, RunResult, RunTrace};

/// Why a table could not be made.
#[derive(Debug, thiserror::Error)]
pub enum TableError {
    #[error("invalid {field} = {value}: {reason}")]
    Invalid {
        field: &'static str,
        value: String,
        reason: String,
    },
    #[error("scenario {path}: {reason}")]
    Scenario { path: String, reason: String },
    #[error("method {method} needs the model {}: {reason}", path.display())]
    MissingModel {
        method: ControllerKind,
        path: PathBuf,
        reason: String,
    },
    #[error("method {method}: {reason}")]
    Controller {
        method: ControllerKind,
        reason: String,
    },
    #[error("{what}: {reason}")]
    Setup { what: &'static str, reason: String },
    #[error("cannot write {}: {reason}", path.display())]
    Write { path: PathBuf, reason: String },
    /// A run log (`--record-dir`, `--log`) that cannot be written or read; names the file.
    #[error("run log: {0}")]
    Log(#[from] fleet_log::LogError),
}

/// Settings shared by every run of a table.
#[derive(Debug, Clone)]
pub struct TableOptions {
    /// Control cycle of the agent and step of the simulator (10 Hz as deployed).
    pub dt_s: f64,
    /// A robot that got no [`run::PROGRESS_M`] closer to its goal (along the floor plan) in
    /// this long gets a human intervention, as does one that collides.
    pub stuck_timeout_s: f64,
    /// An intervention puts the robot down at least this far ahead along its planned path.
    pub intervention_ahead_m: f64,
    /// A run with more interventions than this fails.
    pub max_interventions: u32,
    /// Also plans from the true pose every cycle and compares the DLMs ([`audit`]): how often
    /// AMCL's error made the intention wrong. Costs a second plan per cycle.
    pub audit_intentions: bool,
    /// Ends every run after this much simulated time instead of the scenario's time limit.
    pub time_limit_s: Option<f64>,
    /// The agent configuration (its controller and model are set per method).
    pub agent: AgentConfig,
    /// The service's intention pipeline configuration.
    pub intention: IntentionConfig,
    pub expert: ExpertConfig,
    /// Folder of `<method>.onnx` for `dlm`, `lpe` and `none`.
    pub models_dir: PathBuf,
    /// Record every run as a run log in this folder ([`log`], docs/logs.md).
    pub record: Option<log::RecordSettings>,
}

impl Default for TableOptions {
    fn default() -> Self {
        Self {
            dt_s: 0.1,
            stuck_timeout_s: 10.0,
            intervention_ahead_m: 1.0,
            max_interventions: 30,
            audit_intentions: true,
            time_limit_s: None,
            agent: AgentConfig::default(),
            intention: deterministic_intention_config(),
            expert: ExpertConfig::default(),
            models_dir: PathBuf::from("models"),
            record: None,
        }
    }
}

/// The service's default intention pipeline, with the planner's wall-clock budgets lifted (the
/// expansion budgets still bound every plan): a plan that ran out of time on a loaded machine
/// would make a run depend on more than its seed.
#[must_use]
pub fn deterministic_intention_config() -> IntentionConfig {
    let mut config = IntentionConfig::default();
    config.planner.time_budget_ms = 60_000;
    config.seen.budget_ms = 60_000;
    config
}

impl TableOptions {
    /// The model a network method loads.
    #[must_use]
    pub fn model_path(&self, method: ControllerKind) -> PathBuf {
        self.models_dir.join(format!("{method}.onnx"))
    }

    /// Checks the numbers and that every network method's model file exists.
    ///
    /// # Errors
    /// [`TableError::Invalid`] naming the field, [`TableError::MissingModel`] naming the file.
    pub fn validate(&self, methods: &[ControllerKind]) -> Result<(), TableError> {
        for (field, v) in [
            ("dt_s", self.dt_s),
            ("stuck_timeout_s", self.stuck_timeout_s),
            ("intervention_ahead_m", self.intervention_ahead_m),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(TableError::Invalid {
                    field,
                    value: v.to_string(),
                    reason: "must be a positive number".into(),
                });
            }
        }
        if let Some(t) = self.time_limit_s {
            if !(t.is_finite() && t > 0.0) {
                return Err(TableError::Invalid {
                    field: "time_limit_s",
                    value: t.to_string(),
                    reason: "must be a positive number".into(),
                });
            }
        }
        if self.dt_s > 1.0 {
            return Err(TableError::Invalid {
                field: "dt_s",
                value: self.dt_s.to_string(),
                reason: "must be at most 1 s".into(),
            });
        }
        self.agent.validate().map_err(|e| TableError::Setup {
            what: "agent configuration",
            reason: e.to_string(),
        })?;
        self.expert.validate().map_err(|e| TableError::Setup {
            what: "expert configuration",
            reason: e.to_string(),
        })?;
        for &method in methods.iter().filter(|m| m.needs_model()) {
            let path = self.model_path(method);
            if !path.is_file() {
                return Err(TableError::MissingModel {
                    method,
                    path,
                    reason: "no such file (train one, see docs/evaluation.md, or give --models)"
                        .into(),
                });
            }
        }
        Ok(())
    }
}

/// One run to make.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RunSpec {
    /// Index into the prepared scenarios.
    pub scenario: usize,
    pub method: ControllerKind,
    pub seed: u64,
}

/// Every scenario × method × seed, scenario-major.
#[must_use]
pub fn plan_runs(scenarios: usize, methods: &[ControllerKind], seeds: &[u64]) -> Vec<RunSpec> {
    let mut runs = Vec::with_capacity(scenarios * methods.len() * seeds.len());
    for scenario in 0..scenarios {
        for &method in methods {
            for &seed in seeds {
                runs.push(RunSpec {
                    scenario,
                    method,
                    seed,
                });
            }
        }
    }
    runs
}

/// Loads each scenario once.
///
/// # Errors
/// [`TableError::Scenario`] naming the first bad file.
pub fn prepare(paths: &[PathBuf], options: &TableOptions) -> Result<Vec<Prepared>, TableError> {
    paths.iter().map(|p| Prepared::load(p, options)).collect()
}

/// The generated building of `seed` (`sim::procgen`: a random office, corridor network, hall
/// or mixture with furniture, glass, people and looks), prepared like a scenario file and
/// named `generated/<name>`. Seeds from [`sim::procgen::EVALUATION_SEED_BASE`] on are
/// evaluation buildings, the ones below training buildings.
///
/// # Errors
/// [`TableError::Scenario`] naming the seed when no building can be made of it.
pub fn prepare_generated(seed: u64, options: &TableOptions) -> Result<Prepared, TableError> {
    let building = sim::procgen::building(seed).map_err(|e| TableError::Scenario {
        path: format!("generated building {seed}"),
        reason: e.to_string(),
    })?;
    let label = PathBuf::from("generated").join(&building.scenario.name);
    Prepared::new(&label, building.scenario, building.grid, options)
}

/// Rounds of placement draws [`with_encounter`] tries per scenario.
const ENCOUNTER_TRIES: usize = 5;

/// Each of `prepared` with a scripted `kind` encounter on the path from its start to its first
/// goal (the recorder's, [`crate::record::encounter`]), named `<scenario>-<kind>`: the
/// situation put on every route of a table instead of waiting for the buildings to have it.
/// The placement is drawn from the scenario's name, so every method and seed meets the same
/// one. Scenarios where it does not fit (a short or narrow first leg) are left out; their
/// names come back second.
///
/// # Errors
/// [`TableError::Setup`] when the simulator refuses a scenario.
pub fn with_encounter(
    prepared: Vec<Prepared>,
    kind: Encounter,
    options: &TableOptions,
) -> Result<(Vec<Prepared>, Vec<String>), TableError> {
    let (mut fitted, mut left_out) = (Vec::new(), Vec::new());
    for p in prepared {
        let mut scenario = p.scenario.clone();
        let Some(goal) = scenario.goals.first() else {
            left_out.push(scenario.name);
            continue;
        };
        let goal = (goal.x_m, goal.y_m);
        let start = protocol::Pose2D::new(
            scenario.start.x_m,
            scenario.start.y_m,
            scenario.start.yaw_rad,
        );
        let world = sim::World::new(scenario.clone(), p.plan.clone(), sim::SimConfig::default())
            .map_err(|e| TableError::Setup {
                what: "simulator",
                reason: format!("{}: {e}", scenario.name),
            })?;
        let seed = scenario.name.bytes().fold(0xE7C0_u64, |h, b| {
            h.wrapping_mul(31).wrapping_add(u64::from(b))
        });
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        // More draws than a recording's episode gets: a table has few scenarios to spare.
        let added = (0..ENCOUNTER_TRIES).any(|_| {
            crate::record::encounter::add_first_fitting(
                &mut scenario,
                &p.planning,
                &options.intention.planner,
                &world,
                start,
                goal,
                &[kind],
                &mut rng,
            ) == Some(kind)
        });
        if added {
            scenario.name = format!("{}-{}", scenario.name, kind.as_str());
            fitted.push(Prepared::new(&p.path, scenario, p.plan, options)?);
        } else {
            left_out.push(scenario.name);
        }
    }
    Ok((fitted, left_out))
}

/// What the workers report while a table runs.
#[derive(Debug, Clone, Copy)]
pub enum Progress<'a> {
    /// This many more seconds were simulated.
    Simulated(f64),
    /// A run ended.
    Finished(&'a RunResult),
}

/// Makes `runs` on `jobs` threads, reporting to `progress` from the workers. Results come back
/// in the order of `runs`. The first setup error stops the remaining runs.
///
/// # Errors
/// The first [`TableError`] of any run.
pub fn run_all(
    prepared: &[Prepared],
    runs: &[RunSpec],
    options: &TableOptions,
    jobs: usize,
    progress: &(dyn Fn(Progress<'_>) + Sync),
) -> Result<Vec<(RunResult, RunTrace)>, TableError> {
    let next = AtomicUsize::new(0);
    let results: Mutex<Vec<Option<(RunResult, RunTrace)>>> = Mutex::new(vec![None; runs.len()]);
    let first_error: Mutex<Option<TableError>> = Mutex::new(None);
    let failed = AtomicBool::new(false);
    std::thread::scope(|s| {
        for _ in 0..jobs.clamp(1, runs.len().max(1)) {
            s.spawn(|| loop {
                if failed.load(Ordering::Relaxed) {
                    return;
                }
                let i = next.fetch_add(1, Ordering::Relaxed);
                let Some(spec) = runs.get(i) else { return };
                let mut last_s = 0.0;
                let outcome = run_one(
                    &prepared[spec.scenario],
                    spec.method,
                    spec.seed,
                    options,
                    |t_s| {
                        progress(Progress::Simulated(t_s - last_s));
                        last_s = t_s;
                    },
                );
                match outcome {
                    Ok(r) => {
                        progress(Progress::Finished(&r.0));
                        results.lock().unwrap_or_else(PoisonError::into_inner)[i] = Some(r);
                    }
                    Err(e) => {
                        failed.store(true, Ordering::Relaxed);
                        first_error
                            .lock()
                            .unwrap_or_else(PoisonError::into_inner)
                            .get_or_insert(e);
                        return;
                    }
                }
            });
        }
    });
    if let Some(e) = first_error
        .into_inner()
        .unwrap_or_else(PoisonError::into_inner)
    {
        return Err(e);
    }
    Ok(results
        .into_inner()
        .unwrap_or_else(PoisonError::into_inner)
        .into_iter()
        .flatten()
        .collect())
}

/// `sim/scenarios/task_<letter>.yaml` for a task letter `a`..`e`.
///
/// # Errors
/// [`TableError::Invalid`] for anything but one of `a`–`e`.
pub fn task_scenario(scenarios_dir: &Path, task: &str) -> Result<PathBuf, TableError> {
    let t = task.trim().to_ascii_lowercase();
    if !matches!(t.as_str(), "a" | "b" | "c" | "d" | "e") {
        return Err(TableError::Invalid {
            field: "tasks",
            value: task.to_string(),
            reason: "tasks are a, b, c, d, e".into(),
        });
    }
    Ok(scenarios_dir.join(format!("task_{t}.yaml")))
}
