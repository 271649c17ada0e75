//! The `eval` command line.
//!
//! `eval amcl-accuracy [--tasks a,b,c,d,e] [--seed N] [--out results.json] [--record-dir DIR]`:
//! AMCL against the simulator's ground truth on tasks A–E (see [`crate::amcl_accuracy`]);
//! prints a markdown table and writes the figures as JSON. `--record-dir` writes one run log
//! per task (docs/logs.md); `--log FILE|DIR` (repeatable) replays logs instead of driving.
//!
//! `eval kidnap [--map depot.yaml] [--trials 10] [--distance-m 5] [--out F.json]`: kidnap
//! trials on the depot map (see [`crate::kidnap`]).
//!
//! `eval table [--tasks a,b,c,d,e] [--scenario FILE]... [--behaviour] [--methods LIST]
//! [--seeds N] [--models DIR] [--jobs N] [--record-dir DIR] --out DIR`: the paper's Table 1 and
//! Figure 5 in closed loop (see [`crate::table`]).
//!
//! `eval compare BASE OTHER [--base-method M] [--other-method M] [--names A,B] [--json F]`: two
//! tables (their folders or `runs.json` files) run for run, paired by scenario and seed (see
//! [`crate::table::compare`]); prints markdown.
//!
//! `eval record [--scenario FILE]... [--samples N] [--noise P] [--noise-peak-radps W] [--policy MODEL --beta B]
//! [--seed S] [--jobs N] [--image-px PX] [--every K] [--episode-s S] [--record-dir DIR] --out DIR`: the expert's
//! demonstrations on the training scenarios as an imitation-learning dataset (see
//! [`crate::record`]); `--record-dir` also writes each episode's run log.

use std::path::PathBuf;

use anyhow::Context;
use clap::{Parser, Subcommand};
use planning::DlmMeasure;
use robot_agent::{AgentConfig, ControllerKind};

use crate::amcl_accuracy::{self, AccuracyOptions, TaskAccuracy};
use crate::kidnap;
use crate::record::encounter::Encounter;
use crate::table::{self, TableOptions};

/// Closed-loop evaluation of the intention fleet in the simulator.
#[derive(Debug, Parser)]
#[command(name = "eval", version, about)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Cmd,
}

#[derive(Debug, Subcommand)]
pub enum Cmd {
    /// The paper's Table 1 and Figure 5: every scenario × method × seed in lock-step closed loop.
    Table(TableArgs),
    /// Demonstrations of the privileged expert on the training scenarios, for imitation.
    Record(RecordArgs),
    /// Two tables of the same scenarios and seeds, run for run: interventions per run of each,
    /// per scenario, and the paired difference with its standard error.
    Compare(CompareArgs),
    /// Kidnap trials on the depot map: the robot is carried away unseen; does the agent report
    /// lost localization and re-converge (lock-step)?
    Kidnap {
        /// The depot floor plan (ROS map YAML).
        #[arg(long, default_value = "../shared/maps/nav2/depot.yaml")]
        map: PathBuf,
        #[arg(long, default_value_t = 10)]
        trials: u64,
        /// Trial k runs with seed first_seed + k.
        #[arg(long, default_value_t = 1)]
        first_seed: u64,
        /// How far the robot is carried (m).
        #[arg(long, default_value_t = 5.0)]
        distance_m: f64,
        /// Simulated time of the kidnap (s).
        #[arg(long, default_value_t = 15.0)]
        kidnap_at_s: f64,
        /// Each trial ends this long after the kidnap (s).
        #[arg(long, default_value_t = 30.0)]
        after_s: f64,
        /// Agent configuration TOML whose [amcl], [limits] and controller tables are used.
        #[arg(long)]
        config: Option<PathBuf>,
        /// Write the trials as JSON here.
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// AMCL accuracy against the simulator's ground truth on tasks A–E (lock-step).
    AmclAccuracy {
        /// Comma-separated task letters.
        #[arg(long, default_value = "a,b,c,d,e", value_delimiter = ',')]
        tasks: Vec<String>,
        /// Mixed into the scenario's and AMCL's seeds (0: the scenarios' own).
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Write the figures as JSON here.
        #[arg(long)]
        out: Option<PathBuf>,
        /// dynamic-window or path-tracker.
        #[arg(long, default_value = "dynamic-window")]
        controller: ControllerKind,
        /// Agent configuration TOML whose [amcl], [limits] and controller tables are used.
        #[arg(long)]
        config: Option<PathBuf>,
        /// Directory of the task_<x>.yaml scenarios (default: $FLEET_SCENARIOS_DIR,
        /// ./sim/scenarios, ./scenarios or the user data directory).
        #[arg(long)]
        scenarios: Option<PathBuf>,
        /// Stop each task after this much simulated time (default: the scenario's limit).
        #[arg(long)]
        max_sim_s: Option<f64>,
        /// Record each run as a run log `<task>-<controller>-seed<N>.mcap` in this folder.
        #[arg(long)]
        record_dir: Option<PathBuf>,
        /// Also record the camera (JPEG) in the run logs.
        #[arg(long, requires = "record_dir")]
        record_camera: bool,
        /// Replay these run logs (files, or folders of *.mcap; repeatable) instead of driving:
        /// the agent's AMCL (with --config's tables, else the recorded configuration) against
        /// the logs' ground truth.
        #[arg(long, conflicts_with_all = ["record_dir", "max_sim_s", "scenarios"])]
        log: Vec<PathBuf>,
        /// With --log: the floor plan (ROS map YAML) instead of the file the log names.
        #[arg(long, requires = "log")]
        map: Option<PathBuf>,
    },
}

fn record_settings(
    dir: Option<&std::path::Path>,
    camera: bool,
) -> Option<table::log::RecordSettings> {
    dir.map(|dir| table::log::RecordSettings {
        dir: dir.to_path_buf(),
        log: fleet_log::LogOptions {
            camera,
            ..fleet_log::LogOptions::default()
        },
    })
}

/// The methods `eval table` runs when `--methods` is not given: the ones without a model, and
/// each network whose model file is in the models folder.
fn default_methods(models_dir: &std::path::Path) -> (Vec<ControllerKind>, Vec<String>) {
    let mut methods = Vec::new();
    let mut skipped = Vec::new();
    for kind in ControllerKind::ALL {
        let model = models_dir.join(format!("{kind}.onnx"));
        if kind.needs_model() && !model.is_file() {
            skipped.push(format!("{kind} (no {})", model.display()));
        } else {
            methods.push(kind);
        }
    }
    (methods, skipped)
}

/// Arguments of `eval table`.
#[derive(Debug, clap::Args)]
pub struct TableArgs {
    /// Comma-separated task letters (default: a,b,c,d,e unless --scenario is given).
    #[arg(long, value_delimiter = ',')]
    tasks: Option<Vec<String>>,
    /// Any scenario file, in addition to the tasks (repeatable).
    #[arg(long)]
    scenario: Vec<PathBuf>,
    /// Add every behaviour scenario (`behaviour_*.yaml` of the scenarios folder).
    #[arg(long)]
    behaviour: bool,
    /// Add this many generated buildings (`sim gen-building`), seeds --generated-first-seed and
    /// on: by default evaluation buildings, which no recording may use.
    #[arg(long, default_value_t = 0)]
    generated: u64,
    /// First seed of the generated buildings (default: the start of the evaluation range).
    #[arg(long, default_value_t = sim::procgen::EVALUATION_SEED_BASE)]
    generated_first_seed: u64,
    /// Comma-separated methods: dlm, lpe, none, path-tracker, dynamic-window, expert (default:
    /// every method whose model, if it needs one, is in the models folder).
    #[arg(long, value_delimiter = ',')]
    methods: Option<Vec<ControllerKind>>,
    /// Seeds 0..N per scenario × method (seed 0: the scenario's own noise).
    #[arg(long, default_value_t = 5)]
    seeds: u64,
    /// Folder of dlm.onnx, lpe.onnx, none.onnx (default: $FLEET_MODELS_DIR, ./models or the
    /// user data directory).
    #[arg(long)]
    models: Option<PathBuf>,
    /// Runs in parallel (default: the number of cores).
    #[arg(long)]
    jobs: Option<usize>,
    /// Output folder: runs.json, table.json, table.md, figures/.
    #[arg(long)]
    out: PathBuf,
    /// Agent configuration TOML (its [amcl], [limits], [safety] and controller tables).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Folder of the task and behaviour scenarios (default: $FLEET_SCENARIOS_DIR,
    /// ./sim/scenarios, ./scenarios or the user data directory).
    #[arg(long)]
    scenarios: Option<PathBuf>,
    /// Seconds without progress before the human intervenes.
    #[arg(long, default_value_t = 10.0)]
    stuck_timeout_s: f64,
    /// A run with more interventions than this fails.
    #[arg(long, default_value_t = 30)]
    max_interventions: u32,
    /// Record each run as a run log `<scenario>-<method>-seed<N>.mcap` in this folder
    /// (docs/logs.md).
    #[arg(long)]
    record_dir: Option<PathBuf>,
    /// Also record the camera (JPEG) in the run logs.
    #[arg(long, requires = "record_dir")]
    record_camera: bool,
    /// A new hybrid-A* search every cycle (`[path_reuse]` off): the paper's replanning, and
    /// the reference path reuse is measured against. Default: the service's default, a robot's
    /// path kept while it holds.
    #[arg(long, conflicts_with = "path_reuse")]
    full_replanning: bool,
    /// Kept paths while they hold (`[path_reuse]` on), the default since 2026-11-27; the flag
    /// stays for the commands written when it was not.
    #[arg(long)]
    path_reuse: bool,
    /// Plans the shortest smoothed path, without moving it to the middle of corridors and
    /// doorways (`[planner.centring]` off): the paths of every table before 2026-11-27's
    /// fourteenth session, and of the recordings the shipped networks learned from.
    #[arg(long)]
    no_centring: bool,
    /// Hands each controller's command to the base unchecked, without the agent's collision
    /// monitor (`[safety.collision_monitor]`): the learned controllers alone, as in the paper.
    #[arg(long)]
    no_collision_monitor: bool,
    /// Never lets the dynamic window relieve a controller the collision monitor holds
    /// (`[safety.recovery]`), nor the agent's rotation shim turn the robot or its give-way rule
    /// make it wait (`[rotation_shim]`, `[give_way]`), and the monitor takes every return to
    /// stand still (as `--no-mover-tracking`): the controller alone, as the tables that measure
    /// a network by itself have always run it.
    #[arg(long)]
    no_recovery: bool,
    /// Lets the recovering dynamic window drive across where LPE-Net braked for something the
    /// laser does not see, without the agent's camera hold (`[safety.camera_hold]`), as in
    /// every table before 2026-12-04 (`--no-recovery` implies it).
    #[arg(long)]
    no_camera_hold: bool,
    /// Lets the controller turn the robot round itself when its path starts behind it, without
    /// the agent's rotation shim (`[rotation_shim]`), as in every table before 2026-11-27's
    /// sixteenth session (`--no-recovery` implies it).
    #[arg(long)]
    no_rotation_shim: bool,
    /// Lets the robot drive into a narrow passage whoever comes through it the other way,
    /// without the agent's give-way rule (`[give_way]`), as in every table before 2026-11-27's
    /// sixteenth session (`--no-recovery` implies it).
    #[arg(long)]
    no_give_way: bool,
    /// The collision monitor takes every laser return to stand still, without moving walking
    /// bodies on by their tracked velocity (`[safety.collision_monitor] track_movers` off), as
    /// in every table before 2026-11-27's seventeenth session (`--no-recovery` implies it).
    #[arg(long)]
    no_mover_tracking: bool,
    /// Plans on the floor plan alone: the agent reports no obstacles its laser sees where the
    /// plan is free (`[unmapped_obstacles]` off) and the planner routes round none
    /// (`[seen_obstacles]` off), as in every table before 2026-11-27's fifteenth session.
    #[arg(long)]
    no_seen_obstacles: bool,
    /// Puts this scripted encounter (`person_ahead`, `person_oncoming`, `glass_door`,
    /// `robot_parked`, `furniture`, `open_glass_door`, `person_head_on`,
    /// `person_head_on_near`, `person_through_door`; as `eval record
    /// --encounters` draws them) on the path from
    /// each scenario's start to its first goal, named `<scenario>-<kind>`; scenarios where it
    /// does not fit are left out. With `--generated N`: the situation on N buildings.
    #[arg(long)]
    encounter: Option<Encounter>,
    /// How the planner derives the DLM (`heading`, `route` or `curvature`, planning `DlmMeasure`);
    /// default: what the DLM-Net's card says it was trained on (`dlm_params`, every DLM
    /// parameter, else `dlm_measure` with the planner's defaults; a card without either:
    /// curvature, DLM-Net r1's), and the planner's default for a table without DLM-Net. A
    /// value that contradicts the card is refused, unless `--dlm-measure-over-card`.
    #[arg(long)]
    dlm_measure: Option<DlmMeasure>,
    /// Lets `--dlm-measure` contradict the DLM-Net's card: the network is fed intentions of a
    /// measure it was not trained on (to see how it copes, before training on the new one).
    #[arg(long, requires = "dlm_measure")]
    dlm_measure_over_card: bool,
    /// The planner's `dlm.arrive_distance_m` (m; 0: no arriving `Stop`), over what the
    /// DLM-Net's card says (a warning when they differ).
    #[arg(long)]
    dlm_arrive_m: Option<f64>,
    /// The planner's `dlm.arrive_bearing_rad` (the arriving `Stop` only while the goal lies
    /// within this angle of the heading), over what the DLM-Net's card says.
    #[arg(long)]
    dlm_arrive_bearing_rad: Option<f64>,
    /// The planner's `dlm.blocked_ahead_m` (m; 0: never): while the floor plan lets the robot
    /// drive less than this straight ahead, a turn it still needs is told down to
    /// `dlm.blocked_turn_rad`; over what the DLM-Net's card says.
    #[arg(long)]
    dlm_blocked_ahead_m: Option<f64>,
    /// The planner's `dlm.sidestep_ahead_m` (m; 0: never): where the path goes round what the
    /// laser sees and the floor plan lacks, the path point this far ahead tells the turn; over
    /// what the DLM-Net's card says.
    #[arg(long)]
    dlm_sidestep_m: Option<f64>,
    /// The planner's `dlm.about_turn_rad` (rad; 0: never): where the route leaves at least this
    /// far off the heading, the turn round is told towards the side the walls close in; over
    /// what the DLM-Net's card says.
    #[arg(long)]
    dlm_about_turn_rad: Option<f64>,
}

impl TableArgs {
    /// Whether the table's intention pipeline keeps paths while they hold (`[path_reuse]`):
    /// the service's default unless `--full-replanning` (the two flags conflict, so
    /// `--path-reuse` only says the default).
    fn keeps_paths(&self) -> bool {
        self.path_reuse || !self.full_replanning
    }
}

/// Arguments of `eval record`.
#[derive(Debug, clap::Args)]
pub struct RecordArgs {
    /// Training scenario files (repeatable; default: every train_*.yaml of the scenarios
    /// folder). Evaluation and behaviour scenarios are refused.
    #[arg(long)]
    scenario: Vec<PathBuf>,
    /// Also record on this many generated training buildings (`sim gen-building`), seeds
    /// --generated-first-seed and on.
    #[arg(long, default_value_t = 0)]
    generated: u64,
    /// First seed of the generated buildings; must stay below the evaluation range (1000000).
    #[arg(long, default_value_t = 0)]
    generated_first_seed: u64,
    /// Samples to record in all.
    #[arg(long, default_value_t = 100_000)]
    samples: usize,
    /// Wall-clock budget in minutes: no new batch of episodes starts after it, and the
    /// recording is written with the whole episodes it has (then exactly the recording of
    /// `--samples K`, K what it got, with that dataset id).
    #[arg(long)]
    max_minutes: Option<f64>,
    /// Probability that an episode carries steering noise (labels stay the expert's).
    #[arg(long, default_value_t = 0.2)]
    noise: f64,
    /// Probability that an episode gets a scripted encounter on its first leg: a person
    /// ahead, a person coming towards the robot or a shut glass door (paper §4.2), a parked
    /// robot, furniture in the way, an open glass door off the drawn path ...
    #[arg(long, default_value_t = 0.0)]
    encounters: f64,
    /// ... of these kinds (comma-separated; default the six above: `person_head_on`, a person
    /// coming along the robot's own line, `person_head_on_near`, the same setting off
    /// 3–6 m ahead, and `person_through_door`, a person coming head-on through an open glass
    /// door's opening 3.5–10 m ahead, only when named), tried in a random order, the
    /// first that fits: `--encounter-kinds furniture` records only furniture in the way.
    #[arg(long, value_delimiter = ',', requires = "encounters")]
    encounter_kinds: Vec<Encounter>,
    /// Store only the episodes that got an encounter (the rest are skipped before they run):
    /// for a kind that fits on few routes, such as `person_head_on`.
    #[arg(long, requires = "encounters")]
    encounters_only: bool,
    /// Probability that an episode starts facing a wall 0.5–1.1 m away (its first goal then
    /// to the side or behind): the turn on the spot at a goal by a corridor's end wall.
    #[arg(long, default_value_t = 0.0)]
    wall_starts: f64,
    /// Probability that an episode (not a wall start) starts 0.6–1.5 m from its first goal,
    /// with the goal to the side or behind: the way back to a goal driven past just outside
    /// the tolerance.
    #[arg(long, default_value_t = 0.0)]
    goal_starts: f64,
    /// Probability that an episode (neither of the above) starts 1–3 m from its first goal
    /// with a wall between, the way round the wall's end short, facing along it: the hairpin
    /// round the end of a thin maze wall.
    #[arg(long, default_value_t = 0.0)]
    hairpin_starts: f64,
    /// Largest turn-rate offset of a noise pulse in rad/s (the expert's command filter ignores
    /// pushes up to this size, so its labels correct them).
    #[arg(long, default_value_t = 0.4)]
    noise_peak_radps: f64,
    /// Seed of the episodes (starts, goals, worlds, noise).
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Episodes in parallel (default: the number of cores); the files do not depend on it.
    #[arg(long)]
    jobs: Option<usize>,
    /// Side of the stored camera and LPE images in pixels (area-average downscale).
    #[arg(long, default_value_t = 96)]
    image_px: usize,
    /// Store every K-th control cycle (1: every cycle, 10 Hz).
    #[arg(long, default_value_t = 1)]
    every: u64,
    /// Simulated seconds an episode lasts at most.
    #[arg(long, default_value_t = 120.0)]
    episode_s: f64,
    /// Samples per shard at most.
    #[arg(long, default_value_t = 5000)]
    shard_samples: usize,
    /// A DAgger round: this trained model (ONNX with card) drives, mixed with the expert by
    /// --beta, and the expert labels every state visited.
    #[arg(long)]
    policy: Option<PathBuf>,
    /// Probability that the expert's command is executed in a cycle of a DAgger round.
    #[arg(long, requires = "policy", default_value_t = 0.5)]
    beta: f64,
    /// Agent configuration TOML (its [amcl], [limits] and [safety] tables).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Folder of the train_*.yaml scenarios (default: $FLEET_SCENARIOS_DIR, ./sim/scenarios,
    /// ./scenarios or the user data directory).
    #[arg(long)]
    scenarios: Option<PathBuf>,
    /// Also write one run log per episode here (MCAP, docs/logs.md):
    /// `episode<NNNNN>-<scenario>-expert-seed<seed>.mcap`, NNNNN the samples' `episode`.
    #[arg(long)]
    record_dir: Option<PathBuf>,
    /// Also record the camera (JPEG) in the run logs.
    #[arg(long, requires = "record_dir")]
    record_camera: bool,
    /// How the planner derives the DLM labels (`heading`, `route`, or `curvature`, what DLM-Net
    /// r1 was trained on; planning `DlmMeasure`); default: the DLM parameters a DLM-Net
    /// `--policy` was trained on (its card), else the planner's default. index.json records the `[dlm]`
    /// parameters as `dlm_params`. A measure that contradicts the policy's card is refused,
    /// unless `--dlm-measure-over-card`.
    #[arg(long)]
    dlm_measure: Option<DlmMeasure>,
    /// Lets `--dlm-measure` contradict the `--policy` DLM-Net's card: the first DAgger round
    /// of a new measure, driven by a network trained on another one, labelled in the new one.
    #[arg(long, requires = "dlm_measure")]
    dlm_measure_over_card: bool,
    /// The planner's `dlm.arrive_distance_m` (m; 0: no arriving `Stop`), over what the
    /// `--policy` DLM-Net's card says (a warning when they differ): a DAgger round that
    /// introduces the arriving `Stop` to a network trained without it. Recorded in
    /// index.json's `dlm_params`.
    #[arg(long)]
    dlm_arrive_m: Option<f64>,
    /// The planner's `dlm.arrive_bearing_rad` (the arriving `Stop` only while the goal lies
    /// within this angle of the heading), over what the `--policy` DLM-Net's card says.
    #[arg(long)]
    dlm_arrive_bearing_rad: Option<f64>,
    /// The planner's `dlm.blocked_ahead_m` (m; 0: never), over what the `--policy` DLM-Net's
    /// card says; recorded in index.json's `dlm_params`.
    #[arg(long)]
    dlm_blocked_ahead_m: Option<f64>,
    /// The planner's `dlm.sidestep_ahead_m` (m; 0: never): where the path goes round what the
    /// laser sees and the floor plan lacks, the path point this far ahead tells the turn; over
    /// what the DLM-Net's card says.
    #[arg(long)]
    dlm_sidestep_m: Option<f64>,
    /// The planner's `dlm.about_turn_rad` (rad; 0: never), over what the `--policy` DLM-Net's
    /// card says.
    #[arg(long)]
    dlm_about_turn_rad: Option<f64>,
    /// Output folder: index.json and shard_NNNNN/*.npy (training/DATASET.md).
    #[arg(long)]
    out: PathBuf,
}

/// The DLM parameters to plan with: those the DLM-Net `dlm_model` (when one drives) was
/// trained on, read from its ONNX card (`dlm_params`; a card without them: the planner's
/// defaults for its `dlm_measure`, absent meaning curvature, DLM-Net r1's), else the planner's
/// defaults for the measure asked for. A measure asked for that contradicts the card is refused
/// unless `over_card`: the network would be fed intentions it never saw.
fn dlm_params_for(
    asked: Option<DlmMeasure>,
    dlm_model: Option<&std::path::Path>,
    over_card: bool,
) -> anyhow::Result<planning::DlmParams> {
    // A card that names only its measure (or nothing) predates every key added since.
    let with_measure = |measure: DlmMeasure| planning::DlmParams {
        measure,
        ..planning::DlmParams::as_before()
    };
    let Some(model) = dlm_model else {
        return Ok(planning::DlmParams {
            measure: asked.unwrap_or_default(),
            ..planning::DlmParams::default()
        });
    };
    let card = robot_agent::controllers::intention_net::read_card(model)
        .with_context(|| format!("reading the card of {}", model.display()))?;
    let trained_on = match (card.dlm_params.as_deref(), card.dlm_measure.as_deref()) {
        (Some(raw), measure) => card_dlm_params(raw, measure).map_err(|e| {
            anyhow::anyhow!("{}: card key dlm_params = {raw}: {e}", model.display())
        })?,
        (None, Some(name)) => with_measure(
            name.parse::<DlmMeasure>()
                .map_err(|e| anyhow::anyhow!("{}: card key dlm_measure: {e}", model.display()))?,
        ),
        (None, None) => with_measure(DlmMeasure::Curvature),
    };
    match asked {
        Some(a) if a != trained_on.measure && over_card => {
            tracing::warn!(
                model = %model.display(),
                trained_on = trained_on.measure.as_str(),
                planned_with = a.as_str(),
                "the DLM-Net is fed a DLM measure it was not trained on (--dlm-measure-over-card)"
            );
            Ok(with_measure(a))
        }
        Some(a) if a != trained_on.measure => anyhow::bail!(
            "--dlm-measure {} but the card of {} says it was trained on the {} DLM \
             (--dlm-measure-over-card to drive it on another measure anyway)",
            a.as_str(),
            model.display(),
            trained_on.measure.as_str()
        ),
        _ => Ok(trained_on),
    }
}

/// `params` with `arrive_m`, `bearing_rad`, `blocked_m`, `sidestep_m` and `about_rad` (when
/// given) as its `arrive_distance_m`, `arrive_bearing_rad`, `blocked_ahead_m`,
/// `sidestep_ahead_m` and `about_turn_rad`, warning when that changes what a card said; the
/// intention pipeline's validation checks the values.
fn with_overrides(
    params: planning::DlmParams,
    arrive_m: Option<f64>,
    bearing_rad: Option<f64>,
    blocked_m: Option<f64>,
    sidestep_m: Option<f64>,
    about_rad: Option<f64>,
) -> planning::DlmParams {
    let mut out = params;
    for (given, field, name) in [
        (arrive_m, &mut out.arrive_distance_m, "--dlm-arrive-m"),
        (
            bearing_rad,
            &mut out.arrive_bearing_rad,
            "--dlm-arrive-bearing-rad",
        ),
        (blocked_m, &mut out.blocked_ahead_m, "--dlm-blocked-ahead-m"),
        (sidestep_m, &mut out.sidestep_ahead_m, "--dlm-sidestep-m"),
        (about_rad, &mut out.about_turn_rad, "--dlm-about-turn-rad"),
    ] {
        if let Some(value) = given {
            if value.to_bits() != field.to_bits() {
                tracing::warn!(
                    was = *field,
                    now = value,
                    "{name} changes the DLM's parameters"
                );
            }
            *field = value;
        }
    }
    out
}

/// A card's `dlm_params`: valid planner DLM parameters whose measure is the card's
/// `dlm_measure` (when it has one). A key the card lacks was added to the planner after the
/// card was written and takes the value that meant "as before"
/// ([`planning::DlmParams::as_before`]), not the planner's default of today (DLM-Net r5's card
/// has no `arrive_distance_m`, and was trained without the arriving `Stop`).
fn card_dlm_params(raw: &str, measure: Option<&str>) -> Result<planning::DlmParams, String> {
    let mut value: serde_json::Value =
        serde_json::from_str(raw).map_err(|e| format!("bad JSON: {e}"))?;
    let serde_json::Value::Object(given) = &mut value else {
        return Err("not a JSON object".into());
    };
    let serde_json::Value::Object(before) = serde_json::to_value(planning::DlmParams::as_before())
        .map_err(|e| format!("the planner's parameters as JSON: {e}"))?
    else {
        return Err("the planner's parameters are not a JSON object".into());
    };
    for (key, v) in before {
        given.entry(key).or_insert(v);
    }
    let params: planning::DlmParams =
        serde_json::from_value(value).map_err(|e| format!("bad JSON: {e}"))?;
    params.validate().map_err(|e| e.to_string())?;
    match measure {
        Some(m) if m.trim() != params.measure.as_str() => {
            Err(format!("its measure is not the card's dlm_measure = {m}"))
        }
        _ => Ok(params),
    }
}

fn run_record(args: &RecordArgs) -> anyhow::Result<()> {
    let scenarios = if args.scenario.is_empty() {
        let dir = protocol::data_dirs::find_scenarios_dir(args.scenarios.as_deref())?;
        crate::record::training_scenarios(&dir)?
    } else {
        args.scenario.clone()
    };
    let policy = args
        .policy
        .as_deref()
        .map(|model| crate::record::Policy::load(model, args.beta))
        .transpose()?;
    // A DLM-Net that drives is fed the DLM it was trained on.
    let dlm_policy = policy
        .as_ref()
        .filter(|p| p.kind == ControllerKind::Dlm)
        .map(|p| p.model.clone());
    let options = crate::record::RecordOptions {
        scenarios,
        generated: seed_range(args.generated_first_seed, args.generated)?,
        samples: args.samples,
        noise: args.noise,
        encounters: args.encounters,
        encounters_only: args.encounters_only,
        encounter_kinds: if args.encounter_kinds.is_empty() {
            Encounter::DEFAULT.to_vec()
        } else {
            args.encounter_kinds.clone()
        },
        wall_starts: args.wall_starts,
        goal_starts: args.goal_starts,
        hairpin_starts: args.hairpin_starts,
        noise_peak_radps: args.noise_peak_radps,
        seed: args.seed,
        jobs: args.jobs.unwrap_or_else(|| {
            std::thread::available_parallelism().map_or(1, std::num::NonZeroUsize::get)
        }),
        image_px: args.image_px,
        every: args.every,
        episode_s: args.episode_s,
        shard_samples: args.shard_samples,
        policy,
        max_wall_s: args.max_minutes.map(|m| m * 60.0),
        run: {
            let mut run = TableOptions {
                agent: read_agent_config(args.config.as_deref())?,
                record: record_settings(args.record_dir.as_deref(), args.record_camera),
                ..crate::record::recording_run_options()
            };
            run.intention.dlm = with_overrides(
                dlm_params_for(
                    args.dlm_measure,
                    dlm_policy.as_deref(),
                    args.dlm_measure_over_card,
                )?,
                args.dlm_arrive_m,
                args.dlm_arrive_bearing_rad,
                args.dlm_blocked_ahead_m,
                args.dlm_sidestep_m,
                args.dlm_about_turn_rad,
            );
            run
        },
        command: std::env::args().collect::<Vec<_>>().join(" "),
    };
    options.validate()?;
    let bar = indicatif::ProgressBar::new(args.samples as u64);
    bar.set_style(
        indicatif::ProgressStyle::with_template(
            "[{elapsed_precise}] [{bar:40}] {pos}/{len} samples ({per_sec}, eta {eta})",
        )
        .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    let summary = crate::record::record(&options, &args.out, &|n| bar.inc(n))?;
    bar.finish_and_clear();
    #[allow(clippy::cast_precision_loss)]
    let rate = summary.samples as f64 / summary.wall_s.max(1e-3);
    println!(
        "dataset {}: {} samples from {} episodes ({} with noise) in {} shards under {}; \
         {rate:.1} samples/s, {:.0} simulated s in {:.0} s",
        summary.dataset_id,
        summary.samples,
        summary.episodes,
        summary.noisy_episodes,
        summary.shards,
        args.out.display(),
        summary.simulated_s,
        summary.wall_s
    );
    for (kind, episodes) in &summary.encounters {
        println!("  {} episodes with a scripted {kind}", episodes.len());
    }
    for (episodes, how) in [
        (&summary.wall_starts, "facing a wall"),
        (&summary.goal_starts, "next to their first goal"),
        (&summary.hairpin_starts, "in a hairpin round a wall's end"),
    ] {
        if !episodes.is_empty() {
            println!("  {} episodes started {how}", episodes.len());
        }
    }
    Ok(())
}

fn read_agent_config(config: Option<&std::path::Path>) -> anyhow::Result<AgentConfig> {
    match config {
        Some(path) => {
            let text = std::fs::read_to_string(path)
                .with_context(|| format!("cannot read {}", path.display()))?;
            AgentConfig::from_toml(&text).with_context(|| format!("config {}", path.display()))
        }
        None => Ok(AgentConfig::default()),
    }
}

/// `count` seeds from `first`.
fn seed_range(first: u64, count: u64) -> anyhow::Result<Vec<u64>> {
    let end = first.checked_add(count).ok_or_else(|| {
        anyhow::anyhow!(
            "invalid --generated-first-seed {first} with --generated {count}: overflows"
        )
    })?;
    Ok((first..end).collect())
}

fn run_table(args: &TableArgs) -> anyhow::Result<()> {
    if args.seeds == 0 {
        anyhow::bail!("invalid --seeds 0: need at least one seed");
    }
    if args.jobs == Some(0) {
        anyhow::bail!("invalid --jobs 0: need at least one job");
    }
    let mut agent = read_agent_config(args.config.as_deref())?;
    if args.no_collision_monitor {
        agent.safety.collision_monitor.enabled = false;
    }
    if args.no_recovery {
        agent.safety.recovery.enabled = false;
    }
    if args.no_camera_hold || args.no_recovery {
        agent.safety.camera_hold.enabled = false;
    }
    if args.no_rotation_shim || args.no_recovery {
        agent.rotation_shim.enabled = false;
    }
    if args.no_give_way || args.no_recovery {
        agent.give_way.enabled = false;
    }
    if args.no_mover_tracking || args.no_recovery {
        agent.safety.collision_monitor.track_movers = false;
    }
    if args.no_seen_obstacles {
        agent.unmapped_obstacles.enabled = false;
    }
    let models_dir = match &args.models {
        Some(dir) => dir.clone(),
        None => {
            protocol::data_dirs::find_models_dir(None).unwrap_or_else(|_| PathBuf::from("models"))
        }
    };
    let methods = match &args.methods {
        Some(m) if m.is_empty() => anyhow::bail!("invalid --methods: empty list"),
        Some(m) => m.clone(),
        None => {
            let (methods, skipped) = default_methods(&models_dir);
            if !skipped.is_empty() {
                eprintln!("not running {}", skipped.join(", "));
            }
            methods
        }
    };
    let mut paths: Vec<PathBuf> = Vec::new();
    let tasks: Vec<String> = match &args.tasks {
        Some(t) => t.clone(),
        None if args.scenario.is_empty() && args.generated == 0 => {
            ["a", "b", "c", "d", "e"].map(String::from).to_vec()
        }
        None => Vec::new(),
    };
    if !tasks.is_empty() || args.behaviour {
        let dir = protocol::data_dirs::find_scenarios_dir(args.scenarios.as_deref())?;
        for t in &tasks {
            paths.push(table::task_scenario(&dir, t)?);
        }
        if args.behaviour {
            let mut found: Vec<PathBuf> = std::fs::read_dir(&dir)
                .with_context(|| format!("cannot list {}", dir.display()))?
                .filter_map(Result::ok)
                .map(|e| e.path())
                .filter(|p| {
                    p.file_name()
                        .and_then(|n| n.to_str())
                        .is_some_and(|n| n.starts_with("behaviour_") && n.ends_with(".yaml"))
                })
                .collect();
            found.sort();
            if found.is_empty() {
                anyhow::bail!("--behaviour: no behaviour_*.yaml in {}", dir.display());
            }
            paths.extend(found);
        }
    }
    paths.extend(args.scenario.iter().cloned());
    let options = TableOptions {
        stuck_timeout_s: args.stuck_timeout_s,
        max_interventions: args.max_interventions,
        agent,
        models_dir,
        record: record_settings(args.record_dir.as_deref(), args.record_camera),
        ..TableOptions::default()
    };
    let dlm_model = options.model_path(ControllerKind::Dlm);
    let options = TableOptions {
        intention: {
            let mut intention = options.intention;
            intention.reuse.enabled = args.keeps_paths();
            if args.no_centring {
                intention.planner.centring.enabled = false;
            }
            intention.seen.enabled = !args.no_seen_obstacles;
            intention.dlm = with_overrides(
                dlm_params_for(
                    args.dlm_measure,
                    methods
                        .contains(&ControllerKind::Dlm)
                        .then_some(dlm_model.as_path()),
                    args.dlm_measure_over_card,
                )?,
                args.dlm_arrive_m,
                args.dlm_arrive_bearing_rad,
                args.dlm_blocked_ahead_m,
                args.dlm_sidestep_m,
                args.dlm_about_turn_rad,
            );
            intention
        },
        ..options
    };
    options.validate(&methods)?;
    let seeds: Vec<u64> = (0..args.seeds).collect();
    let jobs = args.jobs.unwrap_or_else(|| {
        std::thread::available_parallelism().map_or(1, std::num::NonZeroUsize::get)
    });
    let mut prepared = table::prepare(&paths, &options)?;
    for seed in seed_range(args.generated_first_seed, args.generated)? {
        prepared.push(table::prepare_generated(seed, &options)?);
    }
    if let Some(kind) = args.encounter {
        let (fitted, left_out) = table::with_encounter(prepared, kind, &options)?;
        if !left_out.is_empty() {
            eprintln!(
                "no room for a {} encounter on the first leg of {} scenario(s), left out: {}",
                kind.as_str(),
                left_out.len(),
                left_out.join(", ")
            );
        }
        if fitted.is_empty() {
            anyhow::bail!("--encounter {}: it fits on no scenario", kind.as_str());
        }
        prepared = fitted;
    }
    let runs = table::plan_runs(prepared.len(), &methods, &seeds);
    eprintln!(
        "{} scenarios × {} methods × {} seeds = {} runs on {jobs} jobs",
        prepared.len(),
        methods.len(),
        seeds.len(),
        runs.len()
    );
    let bar = indicatif::ProgressBar::new(runs.len() as u64);
    bar.set_style(
        indicatif::ProgressStyle::with_template(
            "[{elapsed_precise}] [{bar:40}] {pos}/{len} runs {msg}",
        )
        .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    let started = std::time::Instant::now();
    let simulated = std::sync::Mutex::new(0.0f64);
    let ticks = std::sync::atomic::AtomicU64::new(0);
    let outcome = table::run_all(&prepared, &runs, &options, jobs, &|p| match p {
        table::Progress::Simulated(s) => {
            let mut total = simulated
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner);
            *total += s;
            // A message every 200 cycles is plenty for the eye.
            if ticks
                .fetch_add(1, std::sync::atomic::Ordering::Relaxed)
                .is_multiple_of(200)
            {
                let wall = started.elapsed().as_secs_f64().max(1e-3);
                bar.set_message(format!(
                    "{:.0} sim-s, real-time factor {:.1}",
                    *total,
                    *total / wall
                ));
            }
        }
        table::Progress::Finished(r) => {
            bar.inc(1);
            bar.println(format!(
                "{} {} seed {}: {} ({} interventions, {} collisions, {:.0} s, {:.1} s wall)",
                r.scenario,
                r.method,
                r.seed,
                if r.success {
                    "success"
                } else {
                    r.failure.as_deref().unwrap_or("failed")
                },
                r.interventions,
                r.collisions.total(),
                r.time_s,
                r.wall_s
            ));
        }
    })?;
    bar.finish_and_clear();
    let wall_s = started.elapsed().as_secs_f64();
    let simulated_s = *simulated
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    let results: Vec<table::RunResult> = outcome.iter().map(|(r, _)| r.clone()).collect();
    let summary = table::report::Table {
        seeds,
        methods,
        rows: table::report::rows(&results),
        simulated_s,
        wall_s,
        jobs,
        path_reuse: options.intention.reuse.enabled,
    };
    table::report::write_tables(&args.out, &results, &summary)?;
    table::report::write_figures(&args.out, &prepared, &summary.methods, &outcome)?;
    println!("{}", table::report::markdown(&summary));
    println!(
        "wrote {}/{{runs.json,table.json,table.md,figures/}}; real-time factor {:.1} ({simulated_s:.0} simulated s in {wall_s:.0} s)",
        args.out.display(),
        summary.real_time_factor()
    );
    Ok(())
}

/// `eval compare`'s arguments.
#[derive(Debug, clap::Args)]
pub struct CompareArgs {
    /// The base table: the folder `eval table --out` wrote, or its `runs.json`.
    pub base: PathBuf,
    /// The table compared against it.
    pub other: PathBuf,
    /// The base table's method, where it holds several.
    #[arg(long)]
    pub base_method: Option<ControllerKind>,
    /// The other table's method, where it holds several.
    #[arg(long)]
    pub other_method: Option<ControllerKind>,
    /// What to call the two tables, `BASE,OTHER` (default: their folders' names).
    #[arg(long, value_delimiter = ',')]
    pub names: Vec<String>,
    /// Also write the comparison as JSON here.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

/// The runs of a table folder or `runs.json` file.
fn read_runs(path: &std::path::Path) -> anyhow::Result<Vec<table::RunResult>> {
    let file = if path.is_dir() {
        path.join("runs.json")
    } else {
        path.to_path_buf()
    };
    let text =
        std::fs::read_to_string(&file).with_context(|| format!("reading {}", file.display()))?;
    serde_json::from_str(&text)
        .with_context(|| format!("{}: not a table's runs.json", file.display()))
}

fn table_name(path: &std::path::Path) -> String {
    let dir = if path.is_dir() {
        Some(path)
    } else {
        path.parent()
    };
    dir.and_then(|d| d.file_name()).map_or_else(
        || path.display().to_string(),
        |n| n.to_string_lossy().into_owned(),
    )
}

fn run_compare(args: &CompareArgs) -> anyhow::Result<()> {
    let base = read_runs(&args.base)?;
    let other = read_runs(&args.other)?;
    let c = table::compare::compare(&base, args.base_method, &other, args.other_method)?;
    let (bn, on) = match args.names.as_slice() {
        [b, o] => (b.clone(), o.clone()),
        [] => (table_name(&args.base), table_name(&args.other)),
        names => anyhow::bail!(
            "--names {}: two names are needed, BASE,OTHER",
            names.join(",")
        ),
    };
    print!("{}", table::compare::markdown(&c, &bn, &on));
    if let Some(path) = &args.json {
        let text = serde_json::to_string_pretty(&c)?;
        let tmp = path.with_extension("json.tmp");
        std::fs::write(&tmp, text).with_context(|| format!("writing {}", tmp.display()))?;
        std::fs::rename(&tmp, path).with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}

/// Runs a command.
///
/// # Errors
/// Bad arguments (naming the flag and value), unreadable files, failed runs.
pub fn run(cli: &Cli) -> anyhow::Result<()> {
    match &cli.command {
        Cmd::Table(args) => run_table(args),
        Cmd::Record(args) => run_record(args),
        Cmd::Compare(args) => run_compare(args),
        Cmd::Kidnap {
            map,
            trials,
            first_seed,
            distance_m,
            kidnap_at_s,
            after_s,
            config,
            out,
        } => {
            let defaults = kidnap::KidnapOptions::default();
            let options = kidnap::KidnapOptions {
                trials: *trials,
                first_seed: *first_seed,
                distance_m: *distance_m,
                kidnap_at_s: *kidnap_at_s,
                after_s: *after_s,
                run: TableOptions {
                    agent: read_agent_config(config.as_deref())?,
                    ..defaults.run.clone()
                },
                ..defaults
            };
            let bar = indicatif::ProgressBar::new(*trials);
            bar.set_style(
                indicatif::ProgressStyle::with_template("kidnap {bar:30} {pos}/{len} trials {msg}")
                    .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
            );
            let report = kidnap::run(map, &options, |t| {
                bar.inc(1);
                bar.set_message(format!(
                    "seed {}: {}",
                    t.seed,
                    if t.recovered {
                        "recovered"
                    } else {
                        "not recovered"
                    }
                ));
            })?;
            bar.finish_and_clear();
            println!("{}", kidnap::markdown(&report));
            if let Some(out) = out {
                let json = serde_json::to_string_pretty(&report)?;
                std::fs::write(out, json)
                    .with_context(|| format!("cannot write {}", out.display()))?;
            }
            Ok(())
        }
        Cmd::AmclAccuracy {
            tasks,
            seed,
            out,
            controller,
            config,
            scenarios,
            max_sim_s,
            record_dir,
            record_camera,
            log,
            map,
        } => {
            if !log.is_empty() {
                let agent = config
                    .as_deref()
                    .map(|c| read_agent_config(Some(c)))
                    .transpose()?;
                let mut results = Vec::new();
                for file in amcl_accuracy::log_files(log)? {
                    results.push(amcl_accuracy::from_log(
                        &file,
                        map.as_deref(),
                        agent.as_ref(),
                    )?);
                }
                println!("{}", amcl_accuracy::markdown(&results));
                if let Some(out) = out {
                    let json = serde_json::to_string_pretty(&results)?;
                    std::fs::write(out, json)
                        .with_context(|| format!("cannot write {}", out.display()))?;
                }
                return Ok(());
            }
            let agent = read_agent_config(config.as_deref())?;
            let scenarios = protocol::data_dirs::find_scenarios_dir(scenarios.as_deref())?;
            let paths = tasks
                .iter()
                .map(|t| table::task_scenario(&scenarios, t))
                .collect::<Result<Vec<_>, _>>()?;
            let options = AccuracyOptions {
                seed: *seed,
                controller: *controller,
                run: TableOptions {
                    time_limit_s: *max_sim_s,
                    agent,
                    record: record_settings(record_dir.as_deref(), *record_camera),
                    ..TableOptions::default()
                },
            };
            let mut results: Vec<TaskAccuracy> = Vec::new();
            for path in &paths {
                let bar = indicatif::ProgressBar::new(1000);
                bar.set_style(
                    indicatif::ProgressStyle::with_template("{prefix:>8} {pos:>4} sim-s {msg}")
                        .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
                );
                bar.set_prefix(
                    path.file_stem()
                        .map(|s| s.to_string_lossy().into_owned())
                        .unwrap_or_default(),
                );
                let result = amcl_accuracy::run_task(path, &options, |t_s| {
                    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
                    bar.set_position(t_s as u64);
                })?;
                bar.finish_and_clear();
                results.push(result);
            }
            println!("{}", amcl_accuracy::markdown(&results));
            if let Some(out) = out {
                let json = serde_json::to_string_pretty(&results)?;
                std::fs::write(out, json)
                    .with_context(|| format!("cannot write {}", out.display()))?;
            }
            Ok(())
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_dlm_is_planned_with_the_parameters_its_dlm_net_was_trained_on() {
        let shipped = test_support::models_dir().join("dlm.onnx");
        let fixture = test_support::models_dir().join("fixtures").join("dlm.onnx");
        let measure = |asked, model: Option<&std::path::Path>, over_card| {
            dlm_params_for(asked, model, over_card).map(|p| p.measure)
        };
        // The shipped DLM-Net states every parameter (the first_turn DLM); a card without them
        // (the fixture, DLM-Net r1) means the defaults of the curvature DLM.
        let card = robot_agent::controllers::intention_net::read_card(&shipped).unwrap();
        assert_eq!(
            dlm_params_for(None, Some(&shipped), false).unwrap(),
            card_dlm_params(&card.dlm_params.unwrap(), card.dlm_measure.as_deref()).unwrap()
        );
        assert_eq!(
            measure(None, Some(&shipped), false).unwrap(),
            DlmMeasure::FirstTurn
        );
        assert_eq!(
            dlm_params_for(None, Some(&fixture), false).unwrap(),
            planning::DlmParams::curvature()
        );
        assert_eq!(
            measure(Some(DlmMeasure::FirstTurn), Some(&shipped), false).unwrap(),
            DlmMeasure::FirstTurn
        );
        let err = measure(Some(DlmMeasure::Curvature), Some(&shipped), false).unwrap_err();
        assert!(
            err.to_string().contains("--dlm-measure curvature")
                && err.to_string().contains("the first_turn DLM"),
            "{err}"
        );
        // Unless told to drive it on another measure anyway.
        assert_eq!(
            measure(Some(DlmMeasure::Curvature), Some(&shipped), true).unwrap(),
            DlmMeasure::Curvature
        );
        // Without a DLM-Net, what is asked for, else the default.
        assert_eq!(
            measure(Some(DlmMeasure::Curvature), None, false).unwrap(),
            DlmMeasure::Curvature
        );
        assert_eq!(
            dlm_params_for(None, None, false).unwrap(),
            planning::DlmParams::default()
        );
        let missing = test_support::models_dir().join("no-such-model.onnx");
        assert!(dlm_params_for(None, Some(&missing), false).is_err());
    }

    #[test]
    fn a_key_a_card_lacks_means_what_it_meant_before_it_was_added() {
        // DLM-Net r5's card, written before the arriving Stop and the blocked rule.
        let r5 = r#"{"curvature_threshold_per_m":0.3,"heading_chord_m":1.0,"heading_start_m":0.0,"measure":"first_turn","stop_distance_m":0.3,"turn_release_rad":0.6,"turn_threshold_rad":0.8,"window_m":1.5}"#;
        let params = card_dlm_params(r5, Some("first_turn")).unwrap();
        assert_eq!(
            params,
            planning::DlmParams {
                measure: DlmMeasure::FirstTurn,
                ..planning::DlmParams::as_before()
            }
        );
        assert_ne!(params, planning::DlmParams::default());
        // A key the card states is kept.
        let b2 = r#"{"measure":"first_turn","arrive_distance_m":1.5,"arrive_bearing_rad":0.2}"#;
        let params = card_dlm_params(b2, None).unwrap();
        assert_eq!(
            (
                params.arrive_distance_m,
                params.arrive_bearing_rad,
                params.blocked_ahead_m
            ),
            (1.5, 0.2, 0.0)
        );
        assert!(card_dlm_params("[1, 2]", None)
            .unwrap_err()
            .contains("not a JSON object"));
    }

    #[test]
    fn a_cards_dlm_params_are_checked_and_named_when_wrong() {
        let raw = r#"{"measure":"route","window_m":1.5,"curvature_threshold_per_m":0.3,"heading_start_m":1.0,"heading_chord_m":1.0,"turn_threshold_rad":0.8,"turn_release_rad":0.4,"stop_distance_m":0.3}"#;
        let params = card_dlm_params(raw, Some("route")).unwrap();
        assert_eq!(params.measure, DlmMeasure::Route);
        assert!((params.turn_release_rad - 0.4).abs() < 1e-12);
        assert_eq!(card_dlm_params(raw, None).unwrap(), params);
        for (bad, measure, says) in [
            (raw.replace("0.4", "0.9"), Some("route"), "turn_release_rad"),
            (raw.to_string(), Some("heading"), "dlm_measure = heading"),
            (raw.replace("window_m", "window"), Some("route"), "bad JSON"),
        ] {
            let err = card_dlm_params(&bad, measure).unwrap_err();
            assert!(err.contains(says), "{bad}: {err}");
        }
    }

    #[test]
    fn tables_keep_paths_unless_told_to_search_every_cycle() {
        let table = |flags: &[&str]| {
            let mut argv = vec!["eval", "table", "--out", "t"];
            argv.extend_from_slice(flags);
            match Cli::try_parse_from(argv).map(|c| c.command) {
                Ok(Cmd::Table(args)) => Ok(args.keeps_paths()),
                Ok(other) => panic!("{other:?}"),
                Err(e) => Err(e.kind()),
            }
        };
        assert_eq!(table(&[]), Ok(true));
        assert_eq!(table(&["--path-reuse"]), Ok(true));
        assert_eq!(table(&["--full-replanning"]), Ok(false));
        assert_eq!(
            table(&["--full-replanning", "--path-reuse"]),
            Err(clap::error::ErrorKind::ArgumentConflict)
        );
    }

    #[test]
    fn record_and_log_flags() {
        let cli = Cli::try_parse_from([
            "eval",
            "amcl-accuracy",
            "--tasks",
            "a",
            "--seed",
            "1",
            "--record-dir",
            "logs",
            "--record-camera",
        ])
        .unwrap();
        let Cmd::AmclAccuracy {
            record_dir,
            record_camera,
            log,
            ..
        } = &cli.command
        else {
            panic!("{cli:?}")
        };
        assert_eq!(record_dir.as_deref(), Some(std::path::Path::new("logs")));
        assert!(*record_camera && log.is_empty());
        let settings = record_settings(record_dir.as_deref(), *record_camera).unwrap();
        assert!(settings.log.camera);

        let cli = Cli::try_parse_from([
            "eval",
            "amcl-accuracy",
            "--log",
            "a.mcap",
            "--log",
            "logs/",
            "--map",
            "m.yaml",
        ])
        .unwrap();
        let Cmd::AmclAccuracy { log, map, .. } = &cli.command else {
            panic!("{cli:?}")
        };
        assert_eq!(log.len(), 2);
        assert!(map.is_some());
        // Replaying and recording at once, or a camera without a recording, make no sense.
        for bad in [
            &[
                "eval",
                "amcl-accuracy",
                "--log",
                "a.mcap",
                "--record-dir",
                "d",
            ][..],
            &["eval", "amcl-accuracy", "--record-camera"][..],
            &["eval", "amcl-accuracy", "--map", "m.yaml"][..],
            &["eval", "table", "--out", "o", "--record-camera"][..],
        ] {
            assert!(Cli::try_parse_from(bad).is_err(), "{bad:?}");
        }
        let cli =
            Cli::try_parse_from(["eval", "table", "--out", "o", "--record-dir", "d"]).unwrap();
        let Cmd::Table(args) = &cli.command else {
            panic!("{cli:?}")
        };
        assert_eq!(args.record_dir.as_deref(), Some(std::path::Path::new("d")));
    }
}
