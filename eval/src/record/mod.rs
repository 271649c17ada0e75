//! `eval record`: demonstrations of the privileged expert on the training scenarios, stored
//! as a dataset for imitation learning (`training/DATASET.md` describes the files).
//!
//! Each episode is one closed-loop run ([`crate::table::run::run_with`]) with the expert
//! driving through the agent's supervisor and the planning crate's intention pipeline, exactly
//! as `eval table` runs it, on one training scenario (episode `e` uses scenario
//! `e mod n`) with its own seed, mixed into the world's (people, sensor noise) and AMCL's: a
//! random start and a random sequence of 2–4 goals on the floor plan, each reachable from the
//! last and clear of the scenario's furniture and glass. A fraction `noise` of the episodes
//! carries steering perturbations ([`episode`]) whose labels stay the expert's.
//!
//! Episodes run `jobs` at a time and are stored in episode order, and an episode depends on
//! nothing but the seed and its number, so a recording is the same file for file for any
//! number of jobs. Samples go to shards of at most `shard_samples` ([`writer`]).

pub mod dagger;
pub mod encounter;
pub mod episode;
pub mod npy;
pub mod writer;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use protocol::{normalize_angle, ControllerKind, Pose2D};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use sha2::{Digest, Sha256};
use sim::raycast::WallGrid;
use sim::scenario::{PointSpec, PoseSpec, Role};
use sim::{Scenario, SimConfig, World};

use crate::table::judge::GoalDistance;
use crate::table::run::{run_with, Prepared};
use crate::table::{prepare_generated, TableError, TableOptions};
pub use dagger::Policy;
use episode::{Recorder, Sample};
use writer::ShardWriter;

/// Version of the dataset layout in `index.json`.
pub const FORMAT_VERSION: u32 = 1;

/// Why a recording could not be made.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    #[error("invalid {field} = {value}: {reason}")]
    Invalid {
        field: &'static str,
        value: String,
        reason: String,
    },
    #[error("scenario {path} has role {role}: only training scenarios may be recorded (evaluation and behaviour scenarios must stay unseen)")]
    NotTraining { path: String, role: String },
    #[error("scenario {path}: {reason}")]
    Scenario { path: String, reason: String },
    #[error(transparent)]
    Run(#[from] TableError),
    #[error("cannot write {}: {reason}", path.display())]
    Write { path: PathBuf, reason: String },
}

/// What to record.
#[derive(Debug, Clone)]
pub struct RecordOptions {
    /// Training scenario files.
    pub scenarios: Vec<PathBuf>,
    /// Seeds of generated training buildings (`sim::procgen`; below its evaluation range).
    pub generated: Vec<u64>,
    /// Samples to store in all.
    pub samples: usize,
    /// Probability that an episode carries steering noise.
    pub noise: f64,
    /// Probability that an episode gets a scripted encounter on its first leg ([`encounter`]:
    /// a person ahead or coming towards the robot, a shut glass door, a parked robot,
    /// furniture in the way) ...
    pub encounters: f64,
    /// ... of one of these kinds, tried in a random order per episode, the first that fits.
    pub encounter_kinds: Vec<encounter::Encounter>,
    /// Store only episodes that got an encounter: the others are skipped before they run, so
    /// a recording of a kind that fits on few routes (a head-on person needs a long, wide
    /// enough first leg) spends its time on that kind. Needs `encounters` above 0.
    pub encounters_only: bool,
    /// Probability that an episode starts facing a wall up close ([`WALL_START_M`] from the
    /// robot's centre), so that its first goal lies to the side or behind: the states where a
    /// robot that has just reached a goal at a corridor's end must turn round on the spot.
    pub wall_starts: f64,
    /// Probability that an episode (not already a wall start) starts near its first goal
    /// ([`GOAL_START_M`] away, with the goal to the side or behind): the states where a robot
    /// that drove past a goal just outside the tolerance must turn back to it instead of
    /// circling round it.
    pub goal_starts: f64,
    /// Probability that an episode (neither a wall nor a goal start) starts in a hairpin
    /// ([`HAIRPIN_START_M`] from its first goal with a wall between, the way round that
    /// wall's end short), facing along the way: the turn round the end of a thin wall where
    /// DLM-Net, told only `turn_left`, stalled or touched the end (task E's mazes).
    pub hairpin_starts: f64,
    /// Largest turn-rate offset of a noise pulse. In a noisy episode the expert's
    /// resynchronisation threshold (`ExpertConfig::motion_resync_radps`: it adopts the
    /// measured motion as its own command state when the two differ by more) is raised above
    /// this peak, so the push never becomes the expert's command and its label corrects it.
    pub noise_peak_radps: f64,
    pub seed: u64,
    /// Episodes run in parallel.
    pub jobs: usize,
    /// Side of the stored square images in pixels.
    pub image_px: usize,
    /// Store every `every`-th control cycle (1: all, 10 Hz).
    pub every: u64,
    /// Simulated length limit of one episode.
    pub episode_s: f64,
    /// Samples per shard at most.
    pub shard_samples: usize,
    /// A DAgger round: the learner that drives (mixed with the expert by its β); `None`: the
    /// expert drives.
    pub policy: Option<Policy>,
    /// Wall-clock budget: no new batch of episodes starts after it. A recording that stops on
    /// it holds whole episodes, K samples, and is exactly the recording of `samples = K` (same
    /// files, same dataset id), so it is as reproducible as one that ran to its count.
    pub max_wall_s: Option<f64>,
    /// Shared run settings (the expert's and the agent's configuration, the cycle). With
    /// `run.record` every episode also writes a run log, named after its episode number;
    /// the episodes of the last batch that the sample budget cuts off keep theirs too.
    pub run: TableOptions,
    /// The command line, for `index.json` (not part of the dataset id).
    pub command: String,
}

/// The closed-loop options a recording runs with: the table's, but labelled from a new search
/// every cycle (`[path_reuse]` off), as the paper's planner does and as every recording was
/// made before path reuse became the service's default, so their dataset ids still describe
/// what the same command records. A recording with reuse on hashes it into its id.
#[must_use]
pub fn recording_run_options() -> TableOptions {
    let mut run = TableOptions::default();
    run.intention.reuse.enabled = false;
    run
}

impl Default for RecordOptions {
    fn default() -> Self {
        Self {
            scenarios: Vec::new(),
            generated: Vec::new(),
            samples: 100_000,
            noise: 0.2,
            encounters: 0.0,
            encounter_kinds: encounter::Encounter::DEFAULT.to_vec(),
            encounters_only: false,
            wall_starts: 0.0,
            goal_starts: 0.0,
            hairpin_starts: 0.0,
            noise_peak_radps: 0.4,
            seed: 0,
            jobs: 1,
            image_px: 96,
            every: 1,
            episode_s: 120.0,
            shard_samples: 5000,
            policy: None,
            max_wall_s: None,
            run: recording_run_options(),
            command: String::new(),
        }
    }
}

/// What a recording did.
#[derive(Debug, Clone, PartialEq)]
pub struct Summary {
    pub dataset_id: String,
    pub samples: usize,
    /// Episodes that contributed samples.
    pub episodes: usize,
    pub noisy_episodes: usize,
    /// The stored episodes that got each scripted encounter, by kind.
    pub encounters: BTreeMap<&'static str, Vec<u32>>,
    /// The stored episodes that started facing a wall.
    pub wall_starts: Vec<u32>,
    /// The stored episodes that started near their first goal.
    pub goal_starts: Vec<u32>,
    /// The stored episodes that started in a hairpin.
    pub hairpin_starts: Vec<u32>,
    pub shards: usize,
    /// Simulated seconds of all episodes run (including samples cut off at the end).
    pub simulated_s: f64,
    pub wall_s: f64,
}

/// The training scenarios of a scenarios folder: `train_*.yaml`, sorted.
///
/// # Errors
/// [`RecordError::Scenario`] when the folder cannot be listed or has none.
pub fn training_scenarios(dir: &Path) -> Result<Vec<PathBuf>, RecordError> {
    let err = |reason: String| RecordError::Scenario {
        path: dir.display().to_string(),
        reason,
    };
    let mut found: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(|e| err(e.to_string()))?
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|p| {
            p.file_name()
                .and_then(|n| n.to_str())
                .is_some_and(|n| n.starts_with("train_") && n.ends_with(".yaml"))
        })
        .collect();
    found.sort();
    if found.is_empty() {
        return Err(err("no train_*.yaml".into()));
    }
    Ok(found)
}

impl RecordOptions {
    /// Checks the numbers and that every scenario is a training one.
    ///
    /// # Errors
    /// [`RecordError::Invalid`] naming the field, [`RecordError::NotTraining`] naming the file
    /// and its role, [`RecordError::Scenario`] for an unreadable file.
    pub fn validate(&self) -> Result<(), RecordError> {
        let invalid = |field, value: String, reason: &str| RecordError::Invalid {
            field,
            value,
            reason: reason.into(),
        };
        if self.scenarios.is_empty() && self.generated.is_empty() {
            return Err(invalid(
                "scenarios",
                "[]".into(),
                "need at least one scenario file or generated building",
            ));
        }
        if let Some(&seed) = self
            .generated
            .iter()
            .find(|&&s| sim::procgen::role_of_seed(s) != Role::Training)
        {
            return Err(RecordError::NotTraining {
                path: format!("generated building {seed}"),
                role: "evaluation".into(),
            });
        }
        if self.samples == 0 {
            return Err(invalid("samples", "0".into(), "need at least one"));
        }
        for (field, p) in [
            ("noise", self.noise),
            ("encounters", self.encounters),
            ("wall_starts", self.wall_starts),
            ("goal_starts", self.goal_starts),
            ("hairpin_starts", self.hairpin_starts),
        ] {
            if !(0.0..=1.0).contains(&p) {
                return Err(invalid(field, p.to_string(), "must be in [0, 1]"));
            }
        }
        if self.encounters_only && self.encounters <= 0.0 {
            return Err(invalid(
                "encounters_only",
                "true".into(),
                "needs encounters above 0: no episode would be stored",
            ));
        }
        let kinds = encounter::Encounter::names(&self.encounter_kinds);
        let distinct: std::collections::BTreeSet<_> = kinds.iter().collect();
        if kinds.is_empty() || distinct.len() < kinds.len() {
            return Err(invalid(
                "encounter_kinds",
                kinds.join(","),
                "must name at least one kind, each once",
            ));
        }
        if !(self.noise_peak_radps.is_finite()
            && self.noise_peak_radps > 0.0
            && self.noise_peak_radps <= self.run.agent.limits.max_turn_radps)
        {
            return Err(invalid(
                "noise_peak_radps",
                self.noise_peak_radps.to_string(),
                "must be in (0, the turn-rate limit]",
            ));
        }
        if self.jobs == 0 {
            return Err(invalid("jobs", "0".into(), "need at least one"));
        }
        if !(8..=1024).contains(&self.image_px) {
            return Err(invalid(
                "image_px",
                self.image_px.to_string(),
                "must be in 8..=1024",
            ));
        }
        if self.every == 0 {
            return Err(invalid("every", "0".into(), "must be at least 1"));
        }
        if !(self.episode_s.is_finite() && self.episode_s >= 1.0) {
            return Err(invalid(
                "episode_s",
                self.episode_s.to_string(),
                "must be at least 1 s",
            ));
        }
        if let Some(w) = self.max_wall_s {
            if !(w.is_finite() && w > 0.0) {
                return Err(invalid(
                    "max_wall_s",
                    w.to_string(),
                    "need a positive number of seconds",
                ));
            }
        }
        if self.shard_samples == 0 {
            return Err(invalid("shard_samples", "0".into(), "need at least one"));
        }
        self.run.validate(&[ControllerKind::Expert])?;
        for path in &self.scenarios {
            let scenario = Scenario::load(path).map_err(|e| RecordError::Scenario {
                path: path.display().to_string(),
                reason: e.to_string(),
            })?;
            if scenario.role != Role::Training {
                return Err(RecordError::NotTraining {
                    path: path.display().to_string(),
                    role: format!("{:?}", scenario.role).to_lowercase(),
                });
            }
        }
        Ok(())
    }

    /// A hash of everything that determines the samples (settings and scenario files).
    ///
    /// # Errors
    /// [`RecordError::Scenario`] for an unreadable scenario file.
    pub fn dataset_id(&self) -> Result<String, RecordError> {
        let generated = self
            .generated
            .iter()
            .map(|&seed| prepare_generated(seed, &self.run))
            .collect::<Result<Vec<_>, _>>()?;
        self.dataset_id_with(generated.iter())
    }

    /// [`RecordOptions::dataset_id`] with the generated buildings already made: their
    /// scenarios and plans are hashed, so a change of the generator is a new dataset.
    fn dataset_id_with<'a>(
        &self,
        generated: impl Iterator<Item = &'a Prepared>,
    ) -> Result<String, RecordError> {
        let mut h = Sha256::new();
        h.update(
            format!(
                "intention-fleet demonstrations v{FORMAT_VERSION}; seed {}; samples {}; noise {:?} peak {:?}; \
                 image_px {}; every {}; episode_s {:?}; shard_samples {}; dt_s {:?}; expert {:?}\n",
                self.seed,
                self.samples,
                self.noise,
                self.noise_peak_radps,
                self.image_px,
                self.every,
                self.episode_s,
                self.shard_samples,
                self.run.dt_s,
                self.run.expert,
            )
            .as_bytes(),
        );
        for path in &self.scenarios {
            let bytes = std::fs::read(path).map_err(|e| RecordError::Scenario {
                path: path.display().to_string(),
                reason: e.to_string(),
            })?;
            h.update(Sha256::digest(&bytes));
        }
        for g in generated {
            h.update(format!("generated {:?}\n", g.scenario).as_bytes());
            h.update(Sha256::digest(g.plan.cells()));
        }
        if self.run.intention.dlm != planning::DlmParams::curvature() {
            // Other DLM labels on the same states are another dataset (hashed only when they
            // are not the curvature DLM's, so the ids of recordings made before the DLM had a
            // measure stay as they were).
            h.update(format!("dlm {:?}\n", self.run.intention.dlm).as_bytes());
        }
        if self.run.intention.reuse.enabled {
            h.update(format!("path_reuse {:?}\n", self.run.intention.reuse).as_bytes());
        }
        if self.encounters > 0.0 {
            // The kinds too: a recording with a kind added is other data at the same P.
            let kinds = encounter::Encounter::names(&self.encounter_kinds);
            h.update(format!("encounters {:?} {kinds:?}\n", self.encounters).as_bytes());
        }
        if self.encounters_only {
            // Hashed only when on, so the ids of recordings made before it stay as they were.
            h.update(b"encounters_only\n");
        }
        if self.wall_starts > 0.0 {
            // Hashed only when on, so the ids of recordings made before it stay as they were.
            h.update(format!("wall_starts {:?}\n", self.wall_starts).as_bytes());
        }
        if self.goal_starts > 0.0 {
            h.update(format!("goal_starts {:?}\n", self.goal_starts).as_bytes());
        }
        if self.hairpin_starts > 0.0 {
            h.update(format!("hairpin_starts {:?}\n", self.hairpin_starts).as_bytes());
        }
        if let Some(p) = &self.policy {
            let bytes = std::fs::read(&p.model).map_err(|e| {
                RecordError::Run(TableError::Setup {
                    what: "policy",
                    reason: format!("{}: {e}", p.model.display()),
                })
            })?;
            h.update(format!("policy {:?} beta {:?}\n", p.kind, p.beta).as_bytes());
            h.update(Sha256::digest(&bytes));
        }
        Ok(hex::encode(&h.finalize()[..8]))
    }
}

/// SplitMix64: decorrelates the seeds of neighbouring episodes.
fn mix(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// The seed of episode `episode` of a recording seeded `seed`.
#[must_use]
pub fn episode_seed(seed: u64, episode: u64) -> u64 {
    mix(seed ^ mix(episode))
}

/// A scenario loaded for recording, with a world to check candidate poses against.
struct Loaded {
    prepared: Prepared,
    world: World,
    /// The floor plan's walls, for the rays of a wall start.
    walls: WallGrid,
}

impl Loaded {
    fn new(prepared: Prepared) -> Result<Self, RecordError> {
        let world = World::new(
            prepared.scenario.clone(),
            prepared.plan.clone(),
            SimConfig::default(),
        )
        .map_err(|e| RecordError::Scenario {
            path: prepared.path.display().to_string(),
            reason: e.to_string(),
        })?;
        let walls = WallGrid::from_grid(&prepared.plan);
        Ok(Self {
            prepared,
            world,
            walls,
        })
    }
}

/// Clearance around the robot's disc that a start (people included) and a goal (furniture
/// and glass) keep.
const START_CLEARANCE_M: f64 = 0.15;
const GOAL_CLEARANCE_M: f64 = 0.3;
/// Start→goal and goal→goal straight-line distance at least.
const MIN_LEG_M: f64 = 4.0;
/// A wall start: the nearest wall face lies this far from the robot's centre, straight ahead
/// up to [`WALL_START_YAW_RAD`]. Past task A's second goal the robot stands 0.7–0.8 m from
/// the corridor's end wall.
const WALL_START_M: std::ops::RangeInclusive<f64> = 0.5..=1.1;
const WALL_START_YAW_RAD: f64 = 0.3;
/// Rays cast round a candidate start to find its nearest wall.
const WALL_START_RAYS: u32 = 72;
/// A goal start: the first goal lies this far from the robot's centre (DLM-Net r5 alone
/// passed task D's goals 0.5–0.9 m off and circled round them), at least
/// [`GOAL_START_OFF_RAD`] off its heading, and the way there along the floor plan is at most
/// [`GOAL_START_DETOUR`] times the straight line (no wall between).
const GOAL_START_M: std::ops::RangeInclusive<f64> = 0.6..=1.5;
const GOAL_START_OFF_RAD: std::ops::RangeInclusive<f64> = 0.9..=std::f64::consts::PI;
const GOAL_START_DETOUR: f64 = 1.3;
/// Candidate places tried round the first goal for a goal start.
const GOAL_START_TRIES: usize = 64;
/// A hairpin start: this far from a goal in a straight line, with a wall between, and the
/// way round along the floor plan at least [`HAIRPIN_MIN_DETOUR`] times the straight line but
/// at most [`HAIRPIN_MAX_EXTRA_M`] longer than it, so the way turns round a wall's end close
/// by (task E's maze: walls 0.6 m thick between 2 m passages) rather than the long way round.
const HAIRPIN_START_M: std::ops::RangeInclusive<f64> = 1.0..=3.0;
const HAIRPIN_MIN_DETOUR: f64 = 2.0;
const HAIRPIN_MAX_EXTRA_M: f64 = 7.0;
/// How far ahead the way's direction is read from the goal's distance field, and over how
/// many bearings.
const HAIRPIN_LOOK_M: f64 = 0.4;
const HAIRPIN_BEARINGS: u32 = 32;
/// The start faces the way's direction up to this much off.
const HAIRPIN_YAW_RAD: f64 = 0.3;
/// Candidate places tried round each goal for a hairpin start.
const HAIRPIN_TRIES: usize = 256;

/// How an episode starts.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum StartKind {
    /// At a random free place, facing a random way.
    Open,
    /// Facing a wall up close (`RecordOptions::wall_starts`).
    Wall,
    /// Near the first goal, which lies to the side or behind (`RecordOptions::goal_starts`).
    NearGoal,
    /// Behind a wall from the first goal, facing along the way round the wall's end
    /// (`RecordOptions::hairpin_starts`).
    Hairpin,
}

/// Where an episode starts and the goals it visits, with their distance fields for the judge.
struct EpisodePlan {
    start: Pose2D,
    goal_distance: Vec<GoalDistance>,
    goals: Vec<(f64, f64)>,
}

/// The direction (map-frame yaw) and distance of the nearest wall face seen from (x, y), over
/// [`WALL_START_RAYS`] rays up to `max_m`.
fn nearest_wall(walls: &WallGrid, x_m: f64, y_m: f64, max_m: f64) -> Option<(f64, f64)> {
    (0..WALL_START_RAYS)
        .filter_map(|i| {
            let yaw = std::f64::consts::TAU * f64::from(i) / f64::from(WALL_START_RAYS);
            walls
                .cast(x_m, y_m, yaw.cos(), yaw.sin(), max_m)
                .map(|hit| (yaw, hit.dist_m))
        })
        .min_by(|a, b| a.1.total_cmp(&b.1))
}

/// Start and goals of one episode: random points in the plan's inflated free space, clear of
/// the world's furniture and glass, each goal reachable along the plan from the point before.
/// With `wall_start`, the start is the first candidate whose nearest wall is within
/// [`WALL_START_M`], turned to face it (up to [`WALL_START_YAW_RAD`] off), so the robot must
/// turn on the spot before it can drive. With a goal start, the start is then moved next to
/// the first goal ([`GOAL_START_M`], the goal off its heading by [`GOAL_START_OFF_RAD`]).
/// A hairpin start is put behind a wall from the first goal that has one close by
/// ([`hairpin_start`]); the goals before that one are dropped. `None` when the scenario has
/// no room for them (an episode without a hairpin anywhere is skipped).
fn plan_episode(loaded: &Loaded, seed: u64, kind: StartKind) -> Option<EpisodePlan> {
    let prepared = &loaded.prepared;
    let radius_m = SimConfig::default().base.radius_m;
    let pairs = planning::sample::sample_pairs(
        &prepared.planning,
        24,
        seed,
        MIN_LEG_M,
        &prepared.scenario.name,
    )
    .ok()?;
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x5EED);
    let wanted = rng.gen_range(2..=4usize);
    let clear = |p: &Pose2D, r: f64, people: bool| {
        loaded
            .world
            .disc_overlap(p.x_m, p.y_m, radius_m + r, None, people)
            .is_none()
    };
    let start = if kind == StartKind::Wall {
        let mut turn = ChaCha8Rng::seed_from_u64(seed ^ 0x0A11_57A7);
        pairs
            .iter()
            .flat_map(|(s, g)| [*s, *g])
            .filter(|s| clear(s, START_CLEARANCE_M, true))
            .find_map(|s| {
                let (yaw, d) = nearest_wall(&loaded.walls, s.x_m, s.y_m, *WALL_START_M.end())?;
                WALL_START_M.contains(&d).then(|| {
                    let off = turn.gen_range(-WALL_START_YAW_RAD..=WALL_START_YAW_RAD);
                    Pose2D::new(s.x_m, s.y_m, normalize_angle(yaw + off))
                })
            })?
    } else {
        pairs
            .iter()
            .map(|(s, _)| *s)
            .find(|s| clear(s, START_CLEARANCE_M, true))?
    };
    let mut goals: Vec<(f64, f64)> = Vec::new();
    let mut distances = Vec::new();
    let mut last = start;
    for candidate in pairs.iter().flat_map(|(s, g)| [*g, *s]) {
        if goals.len() == wanted {
            break;
        }
        if candidate.distance_m(&last) < MIN_LEG_M || !clear(&candidate, GOAL_CLEARANCE_M, false) {
            continue;
        }
        let d = GoalDistance::new(&prepared.plan, candidate.x_m, candidate.y_m);
        if !d.at(last.x_m, last.y_m).is_finite() {
            continue;
        }
        goals.push((candidate.x_m, candidate.y_m));
        distances.push(d);
        last = candidate;
    }
    if goals.len() < 2 {
        return None;
    }
    let start =
        match kind {
            StartKind::NearGoal => near_goal_start(loaded, seed, goals[0], &distances[0], &clear)?,
            StartKind::Hairpin => {
                // The first goal with a hairpin round it; the goals before it are dropped.
                let (first, start) = goals.iter().zip(&distances).enumerate().find_map(
                    |(i, (&goal, distance))| {
                        hairpin_start(loaded, seed ^ i as u64, goal, distance, &clear)
                            .map(|s| (i, s))
                    },
                )?;
                goals.drain(..first);
                distances.drain(..first);
                start
            }
            StartKind::Open | StartKind::Wall => start,
        };
    Some(EpisodePlan {
        start,
        goal_distance: distances,
        goals,
    })
}

/// A point `d` in `range` from `goal` at a random bearing `around` (drawn in that order):
/// `(d, around, x_m, y_m)`.
fn round_goal(
    rng: &mut ChaCha8Rng,
    goal: (f64, f64),
    range: std::ops::RangeInclusive<f64>,
) -> (f64, f64, f64, f64) {
    let d = rng.gen_range(range);
    let around = rng.gen_range(-std::f64::consts::PI..std::f64::consts::PI);
    (
        d,
        around,
        goal.0 + d * around.cos(),
        goal.1 + d * around.sin(),
    )
}

/// Whether `p` is free of the world's things and a start the planner takes.
fn fits_as_start(loaded: &Loaded, clear: &dyn Fn(&Pose2D, f64, bool) -> bool, p: &Pose2D) -> bool {
    clear(p, START_CLEARANCE_M, true)
        && loaded
            .prepared
            .planning
            .check_endpoint(planning::Endpoint::Start, *p)
            .is_ok()
}

/// A start [`HAIRPIN_START_M`] from `goal` with a wall between them and the way round it
/// short (see [`HAIRPIN_MIN_DETOUR`]), facing where the goal's distance field falls fastest
/// [`HAIRPIN_LOOK_M`] ahead, up to [`HAIRPIN_YAW_RAD`] off; `None` when no try fits.
fn hairpin_start(
    loaded: &Loaded,
    seed: u64,
    goal: (f64, f64),
    distance: &GoalDistance,
    clear: &dyn Fn(&Pose2D, f64, bool) -> bool,
) -> Option<Pose2D> {
    let mut rng = ChaCha8Rng::seed_from_u64(mix(seed ^ 0x4A19_9147));
    (0..HAIRPIN_TRIES).find_map(|_| {
        let (d, around, x_m, y_m) = round_goal(&mut rng, goal, HAIRPIN_START_M);
        let off = rng.gen_range(-HAIRPIN_YAW_RAD..=HAIRPIN_YAW_RAD);
        let way_m = distance.at(x_m, y_m);
        if !(way_m.is_finite()
            && way_m >= HAIRPIN_MIN_DETOUR * d
            && way_m <= d + HAIRPIN_MAX_EXTRA_M)
        {
            return None;
        }
        // A wall between: the ray from the start towards the goal hits one before the goal.
        let towards = around + std::f64::consts::PI;
        loaded
            .walls
            .cast(x_m, y_m, towards.cos(), towards.sin(), d)?;
        let way_yaw = (0..HAIRPIN_BEARINGS)
            .map(|i| std::f64::consts::TAU * f64::from(i) / f64::from(HAIRPIN_BEARINGS))
            .map(|yaw| {
                let ahead = distance.at(
                    x_m + HAIRPIN_LOOK_M * yaw.cos(),
                    y_m + HAIRPIN_LOOK_M * yaw.sin(),
                );
                (yaw, ahead)
            })
            .filter(|(_, ahead)| ahead.is_finite())
            .min_by(|a, b| a.1.total_cmp(&b.1))?
            .0;
        let p = Pose2D::new(x_m, y_m, normalize_angle(way_yaw + off));
        fits_as_start(loaded, clear, &p).then_some(p)
    })
}

/// A start [`GOAL_START_M`] from `goal` with a free way to it, facing
/// [`GOAL_START_OFF_RAD`] away from it to either side; `None` when no try fits.
fn near_goal_start(
    loaded: &Loaded,
    seed: u64,
    goal: (f64, f64),
    distance: &GoalDistance,
    clear: &dyn Fn(&Pose2D, f64, bool) -> bool,
) -> Option<Pose2D> {
    let mut rng = ChaCha8Rng::seed_from_u64(mix(seed ^ 0x060A_1557));
    (0..GOAL_START_TRIES).find_map(|_| {
        let (d, around, x_m, y_m) = round_goal(&mut rng, goal, GOAL_START_M);
        let off = rng.gen_range(GOAL_START_OFF_RAD) * if rng.gen_bool(0.5) { 1.0 } else { -1.0 };
        // Facing the goal is `around + π`; turned `off` from that.
        let p = Pose2D::new(
            x_m,
            y_m,
            normalize_angle(around + std::f64::consts::PI + off),
        );
        let way_m = distance.at(x_m, y_m);
        (fits_as_start(loaded, clear, &p) && way_m.is_finite() && way_m <= GOAL_START_DETOUR * d)
            .then_some(p)
    })
}

/// What one episode gave.
struct Episode {
    scenario: usize,
    noisy: bool,
    start: StartKind,
    encounter: Option<encounter::Encounter>,
    samples: Vec<Sample>,
    simulated_s: f64,
}

/// Runs episode number `episode` (on `loaded`, the `scenario`-th scenario); its seed, and
/// with it everything random in it, follows from the recording's seed and the number.
fn run_episode(
    loaded: &Loaded,
    scenario: usize,
    episode: u64,
    max_samples: usize,
    options: &RecordOptions,
    progress: &(dyn Fn(u64) + Sync),
) -> Result<Episode, RecordError> {
    let seed = episode_seed(options.seed, episode);
    let noisy = ChaCha8Rng::seed_from_u64(seed).gen_bool(options.noise);
    let wall_start =
        ChaCha8Rng::seed_from_u64(mix(seed ^ 0x0A11_0000)).gen_bool(options.wall_starts);
    // Its own draw, so that recordings without goal starts stay as they were.
    let goal_start =
        ChaCha8Rng::seed_from_u64(mix(seed ^ 0x060A_0000)).gen_bool(options.goal_starts);
    let hairpin_start =
        ChaCha8Rng::seed_from_u64(mix(seed ^ 0x4A19_0000)).gen_bool(options.hairpin_starts);
    let start_kind = match (wall_start, goal_start, hairpin_start) {
        (true, _, _) => StartKind::Wall,
        (false, true, _) => StartKind::NearGoal,
        (false, false, true) => StartKind::Hairpin,
        (false, false, false) => StartKind::Open,
    };
    let empty = Episode {
        scenario,
        noisy,
        start: start_kind,
        encounter: None,
        samples: Vec::new(),
        simulated_s: 0.0,
    };
    let Some(EpisodePlan {
        start,
        goal_distance,
        goals,
    }) = plan_episode(loaded, seed, start_kind)
    else {
        tracing::warn!(scenario = %loaded.prepared.scenario.name, seed, "no room for an episode");
        return Ok(empty);
    };
    let base = &loaded.prepared;
    let mut scenario_spec = base.scenario.clone();
    if options.run.record.is_some() {
        // Names the episode's run log after the dataset's episode number (the `episode`
        // field of its samples): `episode00012-<scenario>-expert-seed<seed>.mcap`.
        scenario_spec.name = format!("episode{episode:05}-{}", scenario_spec.name);
    }
    scenario_spec.start = PoseSpec {
        x_m: start.x_m,
        y_m: start.y_m,
        yaw_rad: start.yaw_rad,
    };
    scenario_spec.goals = goals
        .iter()
        .map(|&(x_m, y_m)| PointSpec { x_m, y_m })
        .collect();
    let encounter =
        if ChaCha8Rng::seed_from_u64(mix(seed ^ 0x00E7_C0DE)).gen_bool(options.encounters) {
            encounter::add(
                &mut scenario_spec,
                &base.planning,
                &options.run.intention.planner,
                &loaded.world,
                start,
                goals[0],
                &options.encounter_kinds,
                &mut ChaCha8Rng::seed_from_u64(mix(seed ^ 0x0E7C_0DE5)),
            )
        } else {
            None
        };
    if options.encounters_only && encounter.is_none() {
        return Ok(empty);
    }
    let prepared = Prepared {
        path: base.path.clone(),
        scenario: scenario_spec,
        plan: base.plan.clone(),
        planning: Arc::clone(&base.planning),
        goal_distance,
    };
    let mut run = options.run.clone();
    run.time_limit_s = Some(options.episode_s);
    // Labels do not need it; it would cost a second plan per cycle.
    run.audit_intentions = false;
    if noisy {
        run.expert.motion_resync_radps += options.noise_peak_radps;
    }
    let mut recorder = Recorder::new(
        options.image_px,
        options.every,
        max_samples,
        run.agent.limits,
        noisy.then(|| (mix(seed ^ 0x0015_E000), options.noise_peak_radps)),
        progress,
    );
    if let Some(policy) = &options.policy {
        let learner = policy.learner(&options.run.agent)?;
        recorder = recorder.with_learner(learner, policy.beta, mix(seed ^ 0x00DA_66E5));
    }
    let mut simulated_s = 0.0;
    match run_with(
        &prepared,
        ControllerKind::Expert,
        seed,
        &run,
        |t_s| simulated_s = t_s,
        Some(&mut recorder),
    ) {
        Ok(_) => {}
        // A person standing on the start: the episode is skipped (still deterministic).
        Err(TableError::Setup {
            what: "robot",
            reason,
        }) => {
            tracing::warn!(scenario = %base.scenario.name, seed, "episode skipped: {reason}");
            return Ok(empty);
        }
        Err(e) => return Err(e.into()),
    }
    Ok(Episode {
        scenario,
        noisy,
        start: start_kind,
        encounter,
        samples: recorder.samples,
        simulated_s,
    })
}

/// Records `options.samples` samples into `out` (created if needed): the shards and
/// `index.json`, every file written atomically, `index.json` last. `progress` gets the number
/// of samples each time some are taken (from the worker threads; the total may run past
/// `options.samples` in the last episodes, whose surplus is dropped).
///
/// # Errors
/// [`RecordError`] for invalid options, a scenario that is not a training one or cannot be
/// loaded, a run that cannot be set up, or a file that cannot be written.
pub fn record(
    options: &RecordOptions,
    out: &Path,
    progress: &(dyn Fn(u64) + Sync),
) -> Result<Summary, RecordError> {
    let started = Instant::now();
    options.validate()?;
    let generated = options
        .generated
        .iter()
        .map(|&seed| prepare_generated(seed, &options.run))
        .collect::<Result<Vec<_>, _>>()?;
    let mut dataset_id = options.dataset_id_with(generated.iter())?;
    let files = options
        .scenarios
        .iter()
        .map(|path| Prepared::load(path, &options.run))
        .collect::<Result<Vec<_>, _>>()?;
    let loaded: Vec<Loaded> = files
        .into_iter()
        .chain(generated)
        .map(Loaded::new)
        .collect::<Result<_, RecordError>>()?;
    std::fs::create_dir_all(out).map_err(|e| RecordError::Write {
        path: out.to_path_buf(),
        reason: e.to_string(),
    })?;
    let mut writer = ShardWriter::new(out, options.image_px, options.shard_samples);
    let (mut episodes, mut noisy_episodes, mut simulated_s) = (0usize, 0usize, 0.0f64);
    let mut encounters: BTreeMap<&'static str, Vec<u32>> = BTreeMap::new();
    let mut wall_starts: Vec<u32> = Vec::new();
    let mut goal_starts: Vec<u32> = Vec::new();
    let mut hairpin_starts: Vec<u32> = Vec::new();
    let mut next_episode = 0u64;
    // Episodes that give nothing (no room, blocked start) must not loop for ever.
    let mut empty_in_a_row = 0usize;
    let mut out_of_time = false;
    while writer.samples() < options.samples {
        if options
            .max_wall_s
            .is_some_and(|budget| started.elapsed().as_secs_f64() >= budget)
            && writer.samples() > 0
        {
            out_of_time = true;
            break;
        }
        let remaining = options.samples - writer.samples();
        let batch: Vec<u64> = (next_episode..next_episode + options.jobs as u64).collect();
        next_episode += options.jobs as u64;
        let results: Vec<Result<Episode, RecordError>> = std::thread::scope(|s| {
            let handles: Vec<_> = batch
                .iter()
                .map(|&e| {
                    let loaded = &loaded;
                    s.spawn(move || {
                        #[allow(clippy::cast_possible_truncation)]
                        let scenario = (e % loaded.len() as u64) as usize;
                        run_episode(&loaded[scenario], scenario, e, remaining, options, progress)
                    })
                })
                .collect();
            handles
                .into_iter()
                .map(|h| {
                    h.join().unwrap_or_else(|_| {
                        Err(RecordError::Run(TableError::Setup {
                            what: "episode",
                            reason: "worker thread panicked".into(),
                        }))
                    })
                })
                .collect()
        });
        for (e, result) in batch.iter().zip(results) {
            let episode = result?;
            simulated_s += episode.simulated_s;
            if writer.samples() >= options.samples {
                continue;
            }
            if episode.samples.is_empty() {
                empty_in_a_row += 1;
                // Skipped episodes cost no simulation; a kind that fits on one route in
                // twenty still stores some long before this many.
                let limit = if options.encounters_only { 1000 } else { 50 };
                if empty_in_a_row > limit {
                    return Err(RecordError::Scenario {
                        path: loaded[episode.scenario].prepared.path.display().to_string(),
                        reason: format!("{limit} episodes in a row gave no samples"),
                    });
                }
                continue;
            }
            empty_in_a_row = 0;
            episodes += 1;
            noisy_episodes += usize::from(episode.noisy);
            #[allow(clippy::cast_possible_truncation)]
            let (scenario, id) = (episode.scenario as u32, *e as u32);
            if let Some(kind) = episode.encounter {
                encounters.entry(kind.as_str()).or_default().push(id);
            }
            match episode.start {
                StartKind::Wall => wall_starts.push(id),
                StartKind::NearGoal => goal_starts.push(id),
                StartKind::Hairpin => hairpin_starts.push(id),
                StartKind::Open => {}
            }
            for sample in episode.samples {
                if writer.samples() >= options.samples {
                    break;
                }
                writer.push(&sample, scenario, id, episode.noisy)?;
            }
        }
    }
    // Stopped by the budget at an episode boundary: the files are those of `samples = K`;
    // the id and the index say so, so the same data always has the same id.
    let cut;
    let options = if out_of_time {
        cut = RecordOptions {
            samples: writer.samples(),
            ..options.clone()
        };
        dataset_id = cut.dataset_id_with(
            loaded[options.scenarios.len()..]
                .iter()
                .map(|l| &l.prepared),
        )?;
        &cut
    } else {
        options
    };
    let mut header = index_header(options, &dataset_id, &loaded);
    if out_of_time {
        header["stopped_by_max_wall_s"] = serde_json::json!(options.max_wall_s);
    }
    header["encounters"] = serde_json::json!({
        "probability": options.encounters,
        "only": options.encounters_only,
        "kinds": encounter::Encounter::names(&options.encounter_kinds),
        "episodes": encounters,
    });
    for (key, p, listed) in [
        ("wall_starts", options.wall_starts, &wall_starts),
        ("goal_starts", options.goal_starts, &goal_starts),
        ("hairpin_starts", options.hairpin_starts, &hairpin_starts),
    ] {
        if p > 0.0 {
            header[key] = serde_json::json!({ "probability": p, "episodes": listed });
        }
    }
    let shards = writer.finish(&header)?;
    Ok(Summary {
        dataset_id,
        samples: writer.samples(),
        episodes,
        noisy_episodes,
        encounters,
        wall_starts,
        goal_starts,
        hairpin_starts,
        shards,
        simulated_s,
        wall_s: started.elapsed().as_secs_f64(),
    })
}

/// The part of `index.json` that does not depend on the shards.
fn index_header(options: &RecordOptions, dataset_id: &str, loaded: &[Loaded]) -> serde_json::Value {
    serde_json::json!({
        "format": "intention-fleet-demonstrations",
        "version": FORMAT_VERSION,
        "dataset_id": dataset_id,
        "command": options.command,
        "seed": options.seed,
        "noise": options.noise,
        "noise_peak_radps": options.noise_peak_radps,
        "image_px": options.image_px,
        "every_cycles": options.every,
        "dt_s": options.run.dt_s,
        "episode_s": options.episode_s,
        "max_speed_mps": options.run.agent.limits.max_speed_mps,
        "max_turn_radps": options.run.agent.limits.max_turn_radps,
        // The rendering the LPE images were drawn with: a model trained on them records it.
        "lpe_rendering": options.run.intention.lpe,
        // How the DLM labels were derived: a DLM-Net trained on them records it in its card.
        "dlm_params": options.run.intention.dlm,
        "policy": options.policy.as_ref().map(|p| serde_json::json!({
            "model": p.model.display().to_string(),
            "kind": p.kind,
            "beta": p.beta,
        })),
        "dlm": ["turn_left", "turn_right", "go_forward", "stop"],
        "scenarios": loaded.iter().enumerate().map(|(i, l)| serde_json::json!({
            "index": i,
            "name": l.prepared.scenario.name,
            "path": l.prepared.path.display().to_string(),
        })).collect::<Vec<_>>(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn office() -> Loaded {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../sim/scenarios/train_office.yaml");
        Loaded::new(Prepared::load(&path, &recording_run_options()).unwrap()).unwrap()
    }

    /// A goal start keeps the episode's goals and only moves the start next to the first,
    /// with a free, direct way to it and the goal off the robot's heading.
    #[test]
    fn a_goal_start_puts_the_first_goal_beside_or_behind_the_robot() {
        let loaded = office();
        let mut fitted = 0;
        for seed in 0..24 {
            let (Some(open), Some(near)) = (
                plan_episode(&loaded, seed, StartKind::Open),
                plan_episode(&loaded, seed, StartKind::NearGoal),
            ) else {
                continue;
            };
            fitted += 1;
            assert_eq!(open.goals, near.goals, "seed {seed}");
            let (gx, gy) = near.goals[0];
            let s = near.start;
            let d = (gx - s.x_m).hypot(gy - s.y_m);
            assert!(GOAL_START_M.contains(&d), "seed {seed}: {d} m");
            let off = normalize_angle((gy - s.y_m).atan2(gx - s.x_m) - s.yaw_rad).abs();
            assert!(
                off >= 0.9 - 1e-9,
                "seed {seed}: goal {off} rad off the heading"
            );
            let way = near.goal_distance[0].at(s.x_m, s.y_m);
            assert!(
                way <= GOAL_START_DETOUR * d + 1e-9,
                "seed {seed}: way {way} m for {d} m"
            );
            assert!(loaded
                .prepared
                .planning
                .check_endpoint(planning::Endpoint::Start, s)
                .is_ok());
            assert!(loaded
                .world
                .disc_overlap(s.x_m, s.y_m, SimConfig::default().base.radius_m, None, true)
                .is_none());
        }
        assert!(fitted >= 20, "{fitted} of 24 seeds fitted");
    }

    /// A hairpin start lies behind a wall from its first goal, the way round the wall's end
    /// short, and faces along that way: a step ahead is nearer the goal along the plan.
    #[test]
    fn a_hairpin_start_faces_the_way_round_a_wall_between_it_and_its_goal() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../sim/scenarios/train_maze_a.yaml");
        let loaded = Loaded::new(Prepared::load(&path, &recording_run_options()).unwrap()).unwrap();
        let mut fitted = 0;
        for seed in 0..24 {
            let Some(plan) = plan_episode(&loaded, seed, StartKind::Hairpin) else {
                continue;
            };
            fitted += 1;
            let (gx, gy) = plan.goals[0];
            let s = plan.start;
            let d = (gx - s.x_m).hypot(gy - s.y_m);
            assert!(HAIRPIN_START_M.contains(&d), "seed {seed}: {d} m");
            let towards = (gy - s.y_m).atan2(gx - s.x_m);
            assert!(
                loaded
                    .walls
                    .cast(s.x_m, s.y_m, towards.cos(), towards.sin(), d)
                    .is_some(),
                "seed {seed}: no wall between"
            );
            let distance = &plan.goal_distance[0];
            let way = distance.at(s.x_m, s.y_m);
            assert!(
                way >= HAIRPIN_MIN_DETOUR * d && way <= d + HAIRPIN_MAX_EXTRA_M,
                "seed {seed}: way {way} m for {d} m"
            );
            let ahead = distance.at(
                s.x_m + HAIRPIN_LOOK_M * s.yaw_rad.cos(),
                s.y_m + HAIRPIN_LOOK_M * s.yaw_rad.sin(),
            );
            assert!(ahead < way, "seed {seed}: {ahead} m ahead, {way} m here");
            assert!(loaded
                .prepared
                .planning
                .check_endpoint(planning::Endpoint::Start, s)
                .is_ok());
        }
        // The rest have no wall end near any of their goals and are skipped (15 of 24 fit).
        assert!(fitted >= 12, "{fitted} of 24 seeds fitted");
    }
}
