//! The fleet benchmark (`planner-service bench-fleet`): how many replans per second the fleet
//! core sustains with N robots each sending a pose at a fixed rate, and the latency from a
//! pose leaving a robot to its intention arriving back.
//!
//! The service side is the fleet core as `serve` runs it (`Fleet`, its redb task store, its
//! per-robot replanning workers) on a Zenoh TCP listener on loopback. The robots run in a
//! separate process (`planner-service bench-robots`, started by the benchmark) that connects
//! to it, so the robots' publishing and decoding does not share the measured process, and
//! latency is measured where a robot sees it: pose put → the intention answering that pose
//! received, on the robots' clock.
//!
//! Simulated robots are kinematic: each follows the newest path it was sent at a fixed speed;
//! the benchmark gives a robot its next goal when its task has ended, so the load stays that of
//! a fleet at work. Robots are phase-shifted over the period like unsynchronized real robots.
//!
//! Two references in the same run: with `path_reuse` the same load is run a second time with
//! a new search every cycle (the paper's behaviour), and the planner alone (the same kind of
//! replans timed on one thread with no Zenoh, no store and no intention rendering) gives the
//! planning cost the service adds to.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use map_store::{import_into, load_ros_map, ImportLimits, MapStore};
use protocol::keys::{self, RobotTopic};
use protocol::{
    Header, Intention, MapName, MapRef, Pose2D, PoseEstimate, RobotId, SessionArgs, SiteId, TaskId,
};
use serde::{Deserialize, Serialize};

use crate::bench::Summary;
use crate::config::ServiceConfig;
use crate::fleet::{Fleet, Goal, NewTask, TaskStateKind};
use crate::launch::Process;
use planning::sample::{pose_along, sample_pairs};
use planning::{Planner, PlanningMap};

/// What to run.
#[derive(Debug, Clone)]
pub struct FleetBenchOptions {
    pub map_yaml: PathBuf,
    pub robots: usize,
    pub rate_hz: f64,
    pub duration_s: f64,
    /// Seconds of load before the measured `duration_s` (first tasks and their first plans).
    pub warmup_s: f64,
    pub speed_mps: f64,
    pub seed: u64,
    pub config: ServiceConfig,
    /// Measure with `[path_reuse]` on (and full replanning as the reference in the same run);
    /// off: the configuration's setting, measured alone.
    pub path_reuse: bool,
    /// Worker processes (`planner-service worker`) that do the replanning; 0: the service
    /// plans itself.
    pub workers: usize,
    /// Pin worker `k` to CPU core `k mod cores` (`taskset`).
    pub pin_workers: bool,
    /// The `planner-service` executable that runs `bench-robots` and the workers.
    pub robots_exe: PathBuf,
}

/// The figures of one measured run (one replanning mode).
#[derive(Debug, Clone, Serialize)]
pub struct ModeFigures {
    /// Whether a robot's kept plan could answer instead of a new search.
    pub path_reuse: bool,
    pub duration_s: f64,
    pub poses_sent: u64,
    /// Of those, the poses the robots' process sent more than half a period late.
    pub poses_late: u64,
    pub intentions_received: u64,
    /// Share of poses that got their own answer (the rest were superseded by a newer pose
    /// while the robot's worker was busy, by design).
    pub answered_fraction: f64,
    /// Intentions answering a pose per second (each is one replan, or a stop when idle).
    pub replans_per_s: f64,
    pub p50_ms: f64,
    pub p99_ms: f64,
    /// Pose sent by the robot to intention received by it, measured by the robots' process.
    pub latency_ms: Summary,
    /// Replans of robots with a task, and of those the answers from a kept plan (no search).
    pub replans: u64,
    pub kept_plan_answers: u64,
    /// Poses of the whole run (warm-up included) that a robot's worker (in the service or a
    /// worker process) never took: a newer pose of the same robot replaced each while its
    /// worker was still planning.
    pub poses_superseded: u64,
    /// Kept plans' due new searches run in the background over the whole run.
    pub refresh_searches: u64,
    pub tasks_created: u64,
    pub tasks_completed: u64,
    /// Who replanned: the service and each worker process, with their replans and latency.
    pub workers: Vec<crate::fleet::WorkerView>,
}

/// The results (JSON) of one benchmark.
#[derive(Debug, Clone, Serialize)]
pub struct FleetBenchReport {
    pub command: String,
    pub cpu_cores: usize,
    pub map: String,
    pub robots: usize,
    pub rate_hz: f64,
    /// Worker processes that replanned (0: the service itself).
    pub workers: usize,
    pub pin_workers: bool,
    /// Seconds of load before each measured run (not counted).
    pub warmup_s: f64,
    /// The measured mode's headline figures (as in `measured`).
    pub path_reuse: bool,
    pub answered_fraction: f64,
    pub p50_ms: f64,
    pub p99_ms: f64,
    pub replans_per_s: f64,
    pub measured: ModeFigures,
    /// The same load with a new search every cycle; `None` when that is what was measured.
    pub full_replanning: Option<ModeFigures>,
    /// The planner alone on one thread: mean replan time and the replans per second all cores
    /// could do at that cost.
    pub reference_replan_ms: Summary,
    pub reference_capacity_per_s: f64,
}

/// A benchmark that could not run.
#[derive(Debug, thiserror::Error)]
pub enum FleetBenchError {
    #[error("invalid {field} = {value}: {reason}")]
    Invalid {
        field: &'static str,
        value: String,
        reason: &'static str,
    },
    #[error("{0}")]
    Setup(String),
}

fn setup(e: impl std::fmt::Display) -> FleetBenchError {
    FleetBenchError::Setup(e.to_string())
}

/// One simulated robot: where it starts and the goals it is sent to in turn.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BenchRobot {
    pub id: RobotId,
    pub start: Pose2D,
    pub goals: Vec<Pose2D>,
}

/// What the robots' process is given (`bench-robots --plan FILE`, JSON).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobotsPlan {
    pub site: SiteId,
    pub map: MapRef,
    pub robots: Vec<BenchRobot>,
}

/// How the robots' process runs.
#[derive(Debug, Clone)]
pub struct RobotsOptions {
    /// The service's Zenoh endpoints.
    pub connect: Vec<String>,
    pub plan: RobotsPlan,
    pub rate_hz: f64,
    pub duration_s: f64,
    /// Seconds of load, not measured, before `duration_s`.
    pub warmup_s: f64,
    pub speed_mps: f64,
}

/// What the robots' process measured (its last stdout line, after [`RESULT_PREFIX`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobotsResult {
    pub duration_s: f64,
    pub poses_sent: u64,
    /// Poses sent more than half a period after they were due: the robots' process fell
    /// behind (a real robot's poses come evenly; these come bunched, and the older of two
    /// bunched poses is often superseded before the service takes it).
    pub poses_late: u64,
    pub answered: u64,
    pub latency_ms: Summary,
}

/// The robots' process prints this line once every robot has had an answer.
pub const READY_LINE: &str = "bench-robots: ready";
/// ... and its result after this prefix.
pub const RESULT_PREFIX: &str = "bench-robots: result ";

fn validate(
    robots: usize,
    rate_hz: f64,
    duration_s: f64,
    warmup_s: f64,
) -> Result<(), FleetBenchError> {
    if !(warmup_s >= 0.0 && warmup_s.is_finite()) {
        return Err(FleetBenchError::Invalid {
            field: "warmup_s",
            value: warmup_s.to_string(),
            reason: "must be zero or positive",
        });
    }
    if robots == 0 {
        return Err(FleetBenchError::Invalid {
            field: "robots",
            value: "0".into(),
            reason: "need at least one robot",
        });
    }
    if !(rate_hz > 0.0 && rate_hz <= 100.0) {
        return Err(FleetBenchError::Invalid {
            field: "rate_hz",
            value: rate_hz.to_string(),
            reason: "must lie in (0, 100]",
        });
    }
    if !(duration_s > 0.0 && duration_s.is_finite()) {
        return Err(FleetBenchError::Invalid {
            field: "duration_s",
            value: duration_s.to_string(),
            reason: "must be positive",
        });
    }
    Ok(())
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// Runs the benchmark (needs a multi-threaded tokio runtime).
///
/// # Errors
/// Bad options, a map that cannot be loaded, Zenoh or store failures, a robots' process that
/// does not start or report.
pub async fn run_fleet_bench(
    opts: &FleetBenchOptions,
    progress: &indicatif::ProgressBar,
) -> Result<FleetBenchReport, FleetBenchError> {
    validate(opts.robots, opts.rate_hz, opts.duration_s, opts.warmup_s)?;
    let data = tempfile::tempdir().map_err(setup)?;
    let store = MapStore::open(&data.path().join("maps")).map_err(setup)?;
    let name = MapName::new("bench").map_err(setup)?;
    let meta = import_into(
        &store,
        &name,
        &opts.map_yaml,
        None,
        &ImportLimits::default(),
    )
    .map_err(setup)?;
    let grid = load_ros_map(&opts.map_yaml, &ImportLimits::default())
        .map_err(setup)?
        .grid;
    let planning = Arc::new(PlanningMap::new(grid, &opts.config.planner).map_err(setup)?);
    // Starts, and goals: each robot gets 8 goals in a row, visited in turn.
    let pairs = sample_pairs(&planning, opts.robots * 9, opts.seed, 6.0, "bench").map_err(setup)?;
    let robots = (0..opts.robots)
        .map(|i| {
            Ok(BenchRobot {
                id: RobotId::new(format!("bench_{i:03}")).map_err(setup)?,
                start: pairs[i].0,
                goals: pairs[opts.robots + i * 8..opts.robots + i * 8 + 8]
                    .iter()
                    .map(|p| p.1)
                    .collect(),
            })
        })
        .collect::<Result<Vec<_>, FleetBenchError>>()?;
    let plan = RobotsPlan {
        site: SiteId::default(),
        map: MapRef {
            name,
            version: meta.version,
        },
        robots,
    };
    let reference = reference_replans(&planning, &opts.config, &plan.robots, opts.speed_mps)?;

    let store = Arc::new(store);
    let modes: Vec<bool> = if opts.path_reuse {
        vec![true, false]
    } else {
        vec![opts.config.path_reuse.enabled]
    };
    let run_ms = (opts.warmup_s + opts.duration_s) * 1e3;
    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
    progress.set_length((run_ms * modes.len() as f64) as u64);
    let mut figures = Vec::new();
    for (k, &reuse) in modes.iter().enumerate() {
        let dir = data.path().join(if reuse { "reuse" } else { "full" });
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let offset_ms = (run_ms * k as f64) as u64;
        figures.push(run_mode(opts, &store, &plan, reuse, &dir, progress, offset_ms).await?);
    }
    let mut figures = figures.into_iter();
    let measured = figures.next().ok_or_else(|| setup("no run"))?;
    let full_replanning = figures.next();
    let cores = std::thread::available_parallelism().map_or(1, std::num::NonZero::get);
    #[allow(clippy::cast_precision_loss)]
    Ok(FleetBenchReport {
        command: std::env::args().collect::<Vec<_>>().join(" "),
        cpu_cores: cores,
        map: opts.map_yaml.display().to_string(),
        robots: opts.robots,
        rate_hz: opts.rate_hz,
        workers: opts.workers,
        pin_workers: opts.pin_workers,
        warmup_s: opts.warmup_s,
        path_reuse: measured.path_reuse,
        answered_fraction: measured.answered_fraction,
        p50_ms: measured.p50_ms,
        p99_ms: measured.p99_ms,
        replans_per_s: measured.replans_per_s,
        measured,
        full_replanning,
        reference_capacity_per_s: if reference.mean > 0.0 {
            cores as f64 * 1e3 / reference.mean
        } else {
            0.0
        },
        reference_replan_ms: reference,
    })
}

/// One measured run: a fresh fleet core on a loopback listener, the robots' process against
/// it, goals fed as tasks end.
async fn run_mode(
    opts: &FleetBenchOptions,
    store: &Arc<MapStore>,
    plan: &RobotsPlan,
    reuse: bool,
    dir: &Path,
    progress: &indicatif::ProgressBar,
    progress_offset_ms: u64,
) -> Result<ModeFigures, FleetBenchError> {
    let mut config = opts.config.clone();
    config.path_reuse.enabled = reuse;
    std::fs::create_dir_all(dir).map_err(setup)?;
    let plan_file = dir.join("robots.json");
    std::fs::write(&plan_file, serde_json::to_vec(plan).map_err(setup)?).map_err(setup)?;
    let session = SessionArgs::new(&["tcp/127.0.0.1:0".to_string()], &[])
        .open()
        .await
        .map_err(setup)?;
    let endpoints = protocol::zenoh_io::locators(&session).await;
    if endpoints.is_empty() {
        return Err(setup(
            "the benchmark's Zenoh session listens on no endpoint",
        ));
    }
    let fleet = Fleet::start(
        session.clone(),
        plan.site.clone(),
        Arc::clone(store),
        dir,
        config.clone(),
    )
    .await
    .map_err(setup)?;
    // Workers fetch the map from the map store over Zenoh, as on a real site.
    let map_server = map_store::MapServer::start(&session, &plan.site, Arc::clone(store))
        .await
        .map_err(setup)?;
    let workers = match start_workers(opts, &config, dir, &endpoints, &fleet).await {
        Ok(w) => w,
        Err(e) => {
            fleet.shutdown().await;
            return Err(e);
        }
    };
    let result = drive(
        opts,
        &fleet,
        plan,
        &plan_file,
        &endpoints,
        progress,
        progress_offset_ms,
    )
    .await;
    let figures = match result {
        Ok((robots, tasks_created)) => {
            let completed = fleet
                .tasks(&crate::fleet::TaskFilter {
                    state: Some(TaskStateKind::Completed),
                    limit: Some(crate::fleet::TaskFilter::MAX_LIMIT),
                    ..Default::default()
                })
                .map_err(setup)?
                .len();
            let metrics = fleet.metrics();
            #[allow(clippy::cast_precision_loss)]
            Ok(ModeFigures {
                path_reuse: reuse,
                duration_s: robots.duration_s,
                poses_sent: robots.poses_sent,
                poses_late: robots.poses_late,
                intentions_received: robots.answered,
                answered_fraction: if robots.poses_sent == 0 {
                    0.0
                } else {
                    robots.answered as f64 / robots.poses_sent as f64
                },
                replans_per_s: robots.answered as f64 / robots.duration_s.max(1e-9),
                p50_ms: robots.latency_ms.p50,
                p99_ms: robots.latency_ms.p99,
                latency_ms: robots.latency_ms,
                replans: metrics.replans_total(),
                kept_plan_answers: metrics.replans_reused_total(),
                poses_superseded: metrics.poses_superseded_total(),
                refresh_searches: metrics.refresh_searches_total(),
                tasks_created,
                tasks_completed: completed as u64,
                workers: fleet.workers(),
            })
        }
        Err(e) => Err(e),
    };
    for mut w in workers {
        w.request_stop();
        w.wait_or_kill(Instant::now() + Duration::from_secs(5));
    }
    drop(map_server);
    fleet.shutdown().await;
    figures
}

/// Starts `opts.workers` worker processes on the benchmark's session and waits until the
/// service counts them all alive.
async fn start_workers(
    opts: &FleetBenchOptions,
    config: &ServiceConfig,
    dir: &Path,
    endpoints: &[String],
    fleet: &Arc<Fleet>,
) -> Result<Vec<Process>, FleetBenchError> {
    if opts.workers == 0 {
        return Ok(Vec::new());
    }
    let config_file = dir.join("worker.toml");
    std::fs::write(&config_file, toml::to_string(config).map_err(setup)?).map_err(setup)?;
    let cores = std::thread::available_parallelism().map_or(1, std::num::NonZero::get);
    let mut procs = Vec::new();
    for k in 0..opts.workers {
        let mut cmd = if opts.pin_workers {
            let mut c = Command::new("taskset");
            c.args(["-c", &(k % cores).to_string()])
                .arg(&opts.robots_exe);
            c
        } else {
            Command::new(&opts.robots_exe)
        };
        cmd.arg("worker")
            .args(["--worker-id", &format!("bench-w{k}")])
            .arg("--config")
            .arg(&config_file)
            .env("RUST_LOG", "warn");
        for e in endpoints {
            cmd.arg("--zenoh-connect").arg(e);
        }
        procs.push(Process::spawn("worker", cmd).map_err(setup)?);
    }
    let mut ready = Vec::new();
    for mut p in procs {
        let p = tokio::task::spawn_blocking(move || {
            p.wait_line(Duration::from_secs(30), |l| {
                l.starts_with(crate::cli::WORKER_READY_PREFIX).then_some(())
            })
            .map(|()| p)
        })
        .await
        .map_err(setup)?
        .map_err(setup)?;
        ready.push(p);
    }
    let deadline = Instant::now() + Duration::from_secs(10);
    loop {
        let alive = fleet
            .workers()
            .iter()
            .filter(|w| w.alive && w.id != crate::fleet::metrics::SERVICE_WORKER)
            .count();
        if alive == opts.workers {
            return Ok(ready);
        }
        if Instant::now() > deadline {
            return Err(setup(format!(
                "the service sees {alive} of {} workers after 10 s",
                opts.workers
            )));
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

/// Starts the robots' process, feeds tasks until it reports; what it measured and the tasks
/// created.
async fn drive(
    opts: &FleetBenchOptions,
    fleet: &Arc<Fleet>,
    plan: &RobotsPlan,
    plan_file: &Path,
    endpoints: &[String],
    progress: &indicatif::ProgressBar,
    progress_offset_ms: u64,
) -> Result<(RobotsResult, u64), FleetBenchError> {
    let mut cmd = Command::new(&opts.robots_exe);
    cmd.arg("bench-robots")
        .arg("--plan")
        .arg(plan_file)
        .arg("--rate-hz")
        .arg(opts.rate_hz.to_string())
        .arg("--duration-s")
        .arg(opts.duration_s.to_string())
        .arg("--warmup-s")
        .arg(opts.warmup_s.to_string())
        .arg("--speed-mps")
        .arg(opts.speed_mps.to_string())
        .env("RUST_LOG", "warn");
    for e in endpoints {
        cmd.arg("--connect").arg(e);
    }
    let mut robots_proc = Process::spawn("bench-robots", cmd).map_err(setup)?;
    let ready_timeout = Duration::from_secs(60);
    let mut robots_proc = tokio::task::spawn_blocking(move || {
        robots_proc
            .wait_line(ready_timeout, |l| (l.trim() == READY_LINE).then_some(()))
            .map(|()| robots_proc)
    })
    .await
    .map_err(setup)?
    .map_err(setup)?;
    let result_timeout = Duration::from_secs_f64(opts.warmup_s + opts.duration_s + 60.0);
    let waiting = tokio::task::spawn_blocking(move || {
        let result = robots_proc.wait_line(result_timeout, |l| {
            l.trim()
                .strip_prefix(RESULT_PREFIX)
                .map(serde_json::from_str::<RobotsResult>)
        });
        (robots_proc, result)
    });

    // Next goal index and current task of each robot.
    let mut feeding: Vec<(usize, Option<TaskId>)> = vec![(0, None); plan.robots.len()];
    let mut tasks_created = 0u64;
    let started = Instant::now();
    while !waiting.is_finished() {
        for (r, (next, current)) in plan.robots.iter().zip(feeding.iter_mut()) {
            let ended = current
                .as_ref()
                .is_none_or(|id| fleet.task(id).is_ok_and(|t| t.state.is_terminal()));
            if !ended || r.goals.is_empty() {
                continue;
            }
            let goal = r.goals[*next % r.goals.len()];
            let req = NewTask {
                map: plan.map.name.clone(),
                robot_id: Some(r.id.clone()),
                goals: vec![Goal {
                    x_m: goal.x_m,
                    y_m: goal.y_m,
                    yaw_rad: None,
                }],
            };
            // A robot the service has not seen yet, or still busy: try again next tick.
            if let Ok(task) = fleet.create_task(req) {
                *current = Some(task.id);
                *next += 1;
                tasks_created += 1;
            }
        }
        progress.set_position(
            progress_offset_ms + u64::try_from(started.elapsed().as_millis()).unwrap_or(0),
        );
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    let (mut robots_proc, result) = waiting.await.map_err(setup)?;
    robots_proc.wait_or_kill(Instant::now() + Duration::from_secs(5));
    let result = result
        .map_err(setup)?
        .map_err(|e| setup(format!("bench-robots reported a bad result: {e}")))?;
    Ok((result, tasks_created))
}

struct SimRobot {
    id: RobotId,
    pose: Pose2D,
    seq: u64,
    /// Declared like the agent's (robot-agent `node.rs`): the key is declared once, so the
    /// routers on the way cache its route instead of matching every pose's key again.
    publisher: zenoh::pubsub::Publisher<'static>,
}

#[derive(Default)]
struct Received {
    sent: HashMap<(usize, u64), Instant>,
    latencies_ms: Vec<f64>,
    paths: HashMap<usize, Vec<Pose2D>>,
    idle: HashMap<usize, bool>,
    count: u64,
}

/// The robots' side (`planner-service bench-robots`): connects to the service, waits until
/// every robot has had an answer (then `announce`s [`READY_LINE`]), then sends poses at the
/// rate for the duration, each robot following the newest path it was sent while it has a
/// task, and measures pose → intention latency.
///
/// # Errors
/// Bad options, Zenoh failures, robots the service never answers within 30 s.
pub async fn run_robots(
    opts: &RobotsOptions,
    announce: &mut dyn FnMut(&str),
) -> Result<RobotsResult, FleetBenchError> {
    validate(
        opts.plan.robots.len(),
        opts.rate_hz,
        opts.duration_s,
        opts.warmup_s,
    )?;
    let session = SessionArgs::new(&[], &opts.connect)
        .open()
        .await
        .map_err(setup)?;
    let site = &opts.plan.site;
    let map_ref = &opts.plan.map;
    let mut robots: Vec<SimRobot> = Vec::with_capacity(opts.plan.robots.len());
    for r in &opts.plan.robots {
        let publisher = session
            .declare_publisher(keys::robot(site, &r.id, RobotTopic::Pose))
            .await
            .map_err(setup)?;
        robots.push(SimRobot {
            id: r.id.clone(),
            pose: r.start,
            seq: 0,
            publisher,
        });
    }
    let n = robots.len();
    let received = Arc::new(Mutex::new(Received::default()));
    let mut subs = Vec::new();
    for (i, r) in robots.iter().enumerate() {
        let rx = Arc::clone(&received);
        let sub = session
            .declare_subscriber(keys::robot(site, &r.id, RobotTopic::Intention))
            .callback(move |s| {
                let Ok(intention) = protocol::decode_sample::<Intention>(&s) else {
                    return;
                };
                let now = Instant::now();
                let mut g = lock(&rx);
                if let Some(t) = g.sent.remove(&(i, intention.answers_pose_seq)) {
                    g.latencies_ms
                        .push(now.duration_since(t).as_secs_f64() * 1e3);
                    g.count += 1;
                }
                g.idle.insert(i, intention.task_id.is_none());
                g.paths.insert(i, intention.path);
            })
            .await
            .map_err(setup)?;
        subs.push(sub);
    }
    // Every robot reports until it has an answer (the first puts may leave before the
    // service's subscription has reached this session).
    let deadline = Instant::now() + Duration::from_secs(30);
    loop {
        let answered: Vec<bool> = {
            let g = lock(&received);
            (0..n).map(|i| g.idle.contains_key(&i)).collect()
        };
        if answered.iter().all(|a| *a) {
            break;
        }
        if Instant::now() > deadline {
            let missing = answered.iter().filter(|a| !**a).count();
            return Err(setup(format!(
                "{missing} of {n} robots got no answer from the service within 30 s"
            )));
        }
        for (i, r) in robots.iter_mut().enumerate() {
            if !answered[i] {
                publish_pose(r, map_ref, i, &received).await?;
            }
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    {
        let mut g = lock(&received);
        g.latencies_ms.clear();
        g.count = 0;
        g.sent.clear();
    }
    announce(READY_LINE);

    let period = Duration::from_secs_f64(1.0 / opts.rate_hz);
    let step_m = opts.speed_mps * period.as_secs_f64();
    let start = Instant::now();
    let warmup = Duration::from_secs_f64(opts.warmup_s.max(0.0));
    let mut t0 = start;
    let mut warming = !warmup.is_zero();
    let run_for = warmup + Duration::from_secs_f64(opts.duration_s);
    let mut poses_sent = 0u64;
    let mut poses_late = 0u64;
    let slot = period / u32::try_from(n).unwrap_or(u32::MAX);
    let mut next_due: Vec<Instant> = (0..n)
        .map(|i| t0 + slot * u32::try_from(i).unwrap_or(0))
        .collect();
    while start.elapsed() < run_for {
        let now = Instant::now();
        if warming && now >= start + warmup {
            // The measured part starts: answers to warm-up poses no longer count.
            warming = false;
            t0 = now;
            poses_sent = 0;
            poses_late = 0;
            let mut g = lock(&received);
            g.latencies_ms.clear();
            g.count = 0;
            g.sent.clear();
        }
        for (i, r) in robots.iter_mut().enumerate() {
            if now < next_due[i] {
                continue;
            }
            if now.duration_since(next_due[i]) > period / 2 {
                poses_late += 1;
            }
            next_due[i] += period;
            let (path, idle) = {
                let g = lock(&received);
                (
                    g.paths.get(&i).cloned(),
                    g.idle.get(&i).copied().unwrap_or(true),
                )
            };
            if !idle {
                if let Some(p) = path.and_then(|p| planning::path::point_along(&p, step_m)) {
                    r.pose = p;
                }
            }
            publish_pose(r, map_ref, i, &received).await?;
            poses_sent += 1;
        }
        let next = next_due.iter().min().copied().unwrap_or(now + period);
        tokio::time::sleep_until(tokio::time::Instant::from_std(next)).await;
    }
    let duration_s = t0.elapsed().as_secs_f64();
    // Answers in flight at the end still count.
    tokio::time::sleep(Duration::from_millis(200)).await;
    let (latencies, answered) = {
        let g = lock(&received);
        (g.latencies_ms.clone(), g.count)
    };
    drop(subs);
    if let Err(e) = session.close().await {
        tracing::warn!("closing the robots' session: {e}");
    }
    Ok(RobotsResult {
        duration_s,
        poses_sent,
        poses_late,
        answered,
        latency_ms: Summary::of(&latencies),
    })
}

async fn publish_pose(
    r: &mut SimRobot,
    map: &MapRef,
    index: usize,
    received: &Mutex<Received>,
) -> Result<(), FleetBenchError> {
    r.seq += 1;
    let msg = PoseEstimate {
        header: Header::new(r.seq, r.seq),
        pose: r.pose,
        covariance: [0.01, 0.0, 0.0, 0.0, 0.01, 0.0, 0.0, 0.0, 0.003],
        sensor_stamp_ns: r.seq,
        map: map.clone(),
        unmapped_obstacles_m: Vec::new(),
    };
    lock(received).sent.insert((index, r.seq), Instant::now());
    protocol::zenoh_io::publish(&r.publisher, &msg)
        .await
        .map_err(setup)
}

/// The planner alone: every robot replans 20 times from poses along its first path.
fn reference_replans(
    map: &Arc<PlanningMap>,
    config: &ServiceConfig,
    robots: &[BenchRobot],
    speed_mps: f64,
) -> Result<Summary, FleetBenchError> {
    let mut planner = Planner::new(Arc::clone(map), config.planner.clone()).map_err(setup)?;
    let mut times = Vec::new();
    for r in robots.iter().take(50) {
        let Some(goal) = r.goals.first().copied() else {
            continue;
        };
        let Ok(first) = planner.plan(r.start, goal) else {
            continue;
        };
        for k in 1..=20 {
            let Some(p) = pose_along(&first.poses, speed_mps * 0.1 * f64::from(k)) else {
                break;
            };
            let t = Instant::now();
            if planner.plan(p, goal).is_ok() {
                times.push(t.elapsed().as_secs_f64() * 1e3);
            }
        }
    }
    Ok(Summary::of(&times))
}

/// The report as a markdown table: one row per replanning mode.
#[must_use]
pub fn markdown(r: &FleetBenchReport) -> String {
    let mut out = String::from(
        "| robots | rate | workers | replanning | poses sent | sent late | answered | superseded | replans/s | kept-plan answers | latency mean | p50 | p99 | max | tasks done |\n\
         |---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for m in std::iter::once(&r.measured).chain(r.full_replanning.as_ref()) {
        #[allow(clippy::cast_precision_loss)]
        let kept = if m.replans == 0 {
            0.0
        } else {
            100.0 * m.kept_plan_answers as f64 / m.replans as f64
        };
        out.push_str(&format!(
            "| {} | {:.0} Hz | {} | {} | {} | {} | {:.1} % | {} | {:.0} | {kept:.1} % | {:.2} ms | {:.2} ms | {:.2} ms | {:.2} ms | {} |\n",
            r.robots,
            r.rate_hz,
            match (r.workers, r.pin_workers) {
                (0, _) => "service".to_string(),
                (w, true) => format!("{w} (pinned)"),
                (w, false) => w.to_string(),
            },
            if m.path_reuse { "path reuse" } else { "full" },
            m.poses_sent,
            m.poses_late,
            m.answered_fraction * 100.0,
            m.poses_superseded,
            m.replans_per_s,
            m.latency_ms.mean,
            m.latency_ms.p50,
            m.latency_ms.p99,
            m.latency_ms.max,
            m.tasks_completed,
        ));
    }
    out.push_str(&format!(
        "\nplanner alone (1 thread): {:.2} ms/replan, capacity {:.0}/s on {} cores\n",
        r.reference_replan_ms.mean, r.reference_capacity_per_s, r.cpu_cores
    ));
    out
}
