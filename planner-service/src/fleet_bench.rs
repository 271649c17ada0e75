//! The fleet benchmark (`planner-service bench-fleet`): how many replans per second the fleet
//! core sustains with N robots each sending a pose at a fixed rate, and the latency from a
//! pose leaving a robot to its intention arriving back, over real Zenoh sessions on loopback.
//!
//! Simulated robots are kinematic: each follows the newest path it was sent at a fixed speed
//! and gets a new goal when its task completes, so the load stays that of a fleet at work.
//! Robots are phase-shifted over the period like unsynchronized real robots. The reference,
//! in the same run, is the planner alone: the same kind of replans timed on one thread with no
//! Zenoh, no store and no intention rendering, giving the planning cost the service adds to.

use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use map_store::{import_into, load_ros_map, ImportLimits, MapStore};
use protocol::keys::{self, RobotTopic};
use protocol::{Header, Intention, MapName, MapRef, Pose2D, PoseEstimate, RobotId, SiteId};
use serde::Serialize;

use crate::bench::Summary;
use crate::config::ServiceConfig;
use crate::fleet::{Fleet, Goal, NewTask};
use planning::sample::{pose_along, sample_pairs};
use planning::{Planner, PlanningMap};

/// What to run.
#[derive(Debug, Clone)]
pub struct FleetBenchOptions {
    pub map_yaml: PathBuf,
    pub robots: usize,
    pub rate_hz: f64,
    pub duration_s: f64,
    pub speed_mps: f64,
    pub seed: u64,
    pub config: ServiceConfig,
}

/// The results (JSON) of one run.
#[derive(Debug, Clone, Serialize)]
pub struct FleetBenchReport {
    pub command: String,
    pub cpu_cores: usize,
    pub map: String,
    pub robots: usize,
    pub rate_hz: f64,
    pub duration_s: f64,
    pub poses_sent: u64,
    pub intentions_received: u64,
    /// Intentions answering a pose per second (each is one replan, or a stop when idle).
    pub replans_per_s: f64,
    /// Share of poses that got their own answer (the rest were superseded by a newer pose
    /// while the robot's worker was busy, by design).
    pub answered_fraction: f64,
    /// Pose sent by the robot to intention received by it.
    pub latency_ms: Summary,
    pub tasks_created: u64,
    pub tasks_completed: u64,
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

struct SimRobot {
    id: RobotId,
    pose: Pose2D,
    seq: u64,
    goals: Vec<Pose2D>,
    next_goal: usize,
}

#[derive(Default)]
struct Received {
    sent: HashMap<(usize, u64), Instant>,
    latencies_ms: Vec<f64>,
    paths: HashMap<usize, Vec<Pose2D>>,
    idle: HashMap<usize, bool>,
    count: u64,
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// Runs the benchmark (needs a multi-threaded tokio runtime).
///
/// # Errors
/// Bad options, a map that cannot be loaded, Zenoh or store failures.
pub async fn run_fleet_bench(
    opts: &FleetBenchOptions,
    progress: &indicatif::ProgressBar,
) -> Result<FleetBenchReport, FleetBenchError> {
    if opts.robots == 0 {
        return Err(FleetBenchError::Invalid {
            field: "robots",
            value: "0".into(),
            reason: "need at least one robot",
        });
    }
    if !(opts.rate_hz > 0.0 && opts.rate_hz <= 100.0) {
        return Err(FleetBenchError::Invalid {
            field: "rate_hz",
            value: opts.rate_hz.to_string(),
            reason: "must lie in (0, 100]",
        });
    }
    if !(opts.duration_s > 0.0 && opts.duration_s.is_finite()) {
        return Err(FleetBenchError::Invalid {
            field: "duration_s",
            value: opts.duration_s.to_string(),
            reason: "must be positive",
        });
    }
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
    let map_ref = MapRef {
        name: name.clone(),
        version: meta.version,
    };
    let grid = load_ros_map(&opts.map_yaml, &ImportLimits::default())
        .map_err(setup)?
        .grid;
    let planning = Arc::new(PlanningMap::new(grid, &opts.config.planner).map_err(setup)?);
    // Starts, and goals: each robot gets 8 goals in a row, visited in turn.
    let pairs = sample_pairs(&planning, opts.robots * 9, opts.seed, 6.0, "bench").map_err(setup)?;
    let mut robots: Vec<SimRobot> = (0..opts.robots)
        .map(|i| {
            let id = RobotId::new(format!("bench_{i:03}")).map_err(setup)?;
            let goals = pairs[opts.robots + i * 8..opts.robots + i * 8 + 8]
                .iter()
                .map(|p| p.1)
                .collect();
            Ok(SimRobot {
                id,
                pose: pairs[i].0,
                seq: 0,
                goals,
                next_goal: 0,
            })
        })
        .collect::<Result<_, FleetBenchError>>()?;

    let reference = reference_replans(&planning, &opts.config, &robots, opts.speed_mps)?;
    let (server, client) = protocol::zenoh_io::loopback_pair().await.map_err(setup)?;
    let site = SiteId::default();
    let fleet = Fleet::start(
        server,
        site.clone(),
        Arc::new(store),
        data.path(),
        opts.config.clone(),
    )
    .await
    .map_err(setup)?;

    let received = Arc::new(Mutex::new(Received::default()));
    let mut subs = Vec::new();
    for (i, r) in robots.iter().enumerate() {
        let rx = Arc::clone(&received);
        let sub = client
            .declare_subscriber(keys::robot(&site, &r.id, RobotTopic::Intention))
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
    // Every robot reports until the service knows it (the first puts may leave before the
    // service's subscription has reached this session).
    let deadline = Instant::now() + Duration::from_secs(30);
    loop {
        let known: std::collections::HashSet<RobotId> =
            fleet.robots().into_iter().map(|r| r.id).collect();
        if known.len() >= opts.robots {
            break;
        }
        if Instant::now() > deadline {
            return Err(setup("the service did not see every robot within 30 s"));
        }
        for (i, r) in robots.iter_mut().enumerate() {
            if !known.contains(&r.id) {
                publish_pose(&client, &site, r, &map_ref, i, &received).await?;
            }
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    lock(&received).latencies_ms.clear();
    lock(&received).count = 0;

    let period = Duration::from_secs_f64(1.0 / opts.rate_hz);
    let dt_s = period.as_secs_f64();
    let mut tasks_created = 0u64;
    let t0 = Instant::now();
    let run_for = Duration::from_secs_f64(opts.duration_s);
    let mut poses_sent = 0u64;
    let slot = period / u32::try_from(opts.robots).unwrap_or(u32::MAX);
    let mut next_due: Vec<Instant> = (0..opts.robots)
        .map(|i| t0 + slot * u32::try_from(i).unwrap_or(0))
        .collect();
    progress.set_length(u64::try_from(run_for.as_millis()).unwrap_or(u64::MAX));
    while t0.elapsed() < run_for {
        let now = Instant::now();
        for (i, r) in robots.iter_mut().enumerate() {
            if now < next_due[i] {
                continue;
            }
            next_due[i] += period;
            let (path, idle) = {
                let g = lock(&received);
                (
                    g.paths.get(&i).cloned(),
                    g.idle.get(&i).copied().unwrap_or(true),
                )
            };
            if idle {
                if let Some(goal) = r.goals.get(r.next_goal % r.goals.len()).copied() {
                    let req = NewTask {
                        map: name.clone(),
                        robot_id: Some(r.id.clone()),
                        goals: vec![Goal {
                            x_m: goal.x_m,
                            y_m: goal.y_m,
                            yaw_rad: None,
                        }],
                    };
                    // A busy robot (its last answer was idle but a task just started) is fine.
                    if fleet.create_task(req).is_ok() {
                        tasks_created += 1;
                        lock(&received).idle.insert(i, false);
                    }
                    r.next_goal += 1;
                }
            } else if let Some(p) = path.and_then(|p| advance(&p, opts.speed_mps * dt_s)) {
                r.pose = p;
            }
            publish_pose(&client, &site, r, &map_ref, i, &received).await?;
            poses_sent += 1;
        }
        progress.set_position(u64::try_from(t0.elapsed().as_millis()).unwrap_or(0));
        let next = next_due.iter().min().copied().unwrap_or(now + period);
        tokio::time::sleep_until(tokio::time::Instant::from_std(next)).await;
    }
    let elapsed_s = t0.elapsed().as_secs_f64();
    // Answers in flight at the end still count.
    tokio::time::sleep(Duration::from_millis(200)).await;
    let (latencies, count) = {
        let g = lock(&received);
        (g.latencies_ms.clone(), g.count)
    };
    let completed = fleet
        .tasks(&crate::fleet::TaskFilter {
            state: Some(crate::fleet::TaskStateKind::Completed),
            limit: Some(crate::fleet::TaskFilter::MAX_LIMIT),
            ..Default::default()
        })
        .map_err(setup)?
        .len();
    drop(subs);
    fleet.shutdown().await;
    let cores = std::thread::available_parallelism().map_or(1, std::num::NonZero::get);
    #[allow(clippy::cast_precision_loss)]
    let report = FleetBenchReport {
        command: std::env::args().collect::<Vec<_>>().join(" "),
        cpu_cores: cores,
        map: opts.map_yaml.display().to_string(),
        robots: opts.robots,
        rate_hz: opts.rate_hz,
        duration_s: elapsed_s,
        poses_sent,
        intentions_received: count,
        replans_per_s: count as f64 / elapsed_s,
        answered_fraction: if poses_sent == 0 {
            0.0
        } else {
            count as f64 / poses_sent as f64
        },
        latency_ms: Summary::of(&latencies),
        tasks_created,
        tasks_completed: completed as u64,
        reference_capacity_per_s: if reference.mean > 0.0 {
            cores as f64 * 1e3 / reference.mean
        } else {
            0.0
        },
        reference_replan_ms: reference,
    };
    Ok(report)
}

async fn publish_pose(
    session: &zenoh::Session,
    site: &SiteId,
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
    };
    lock(received).sent.insert((index, r.seq), Instant::now());
    protocol::zenoh_io::put(
        session,
        &keys::robot(site, &r.id, RobotTopic::Pose).into(),
        &msg,
    )
    .await
    .map_err(setup)
}

/// The pose exactly `step_m` along `path` (interpolated: intentions carry a thinned path).
fn advance(path: &[Pose2D], step_m: f64) -> Option<Pose2D> {
    let mut left = step_m;
    for w in path.windows(2) {
        let d = w[0].distance_m(&w[1]);
        if d >= left && d > 0.0 {
            let t = left / d;
            return Some(Pose2D::new(
                w[0].x_m + t * (w[1].x_m - w[0].x_m),
                w[0].y_m + t * (w[1].y_m - w[0].y_m),
                (w[1].y_m - w[0].y_m).atan2(w[1].x_m - w[0].x_m),
            ));
        }
        left -= d;
    }
    path.last().copied()
}

/// The planner alone: every robot replans 20 times from poses along its first path.
fn reference_replans(
    map: &Arc<PlanningMap>,
    config: &ServiceConfig,
    robots: &[SimRobot],
    speed_mps: f64,
) -> Result<Summary, FleetBenchError> {
    let mut planner = Planner::new(Arc::clone(map), config.planner.clone()).map_err(setup)?;
    let mut times = Vec::new();
    for r in robots.iter().take(50) {
        let Some(goal) = r.goals.first().copied() else {
            continue;
        };
        let Ok(first) = planner.plan(r.pose, goal) else {
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

/// The report as a markdown table.
#[must_use]
pub fn markdown(r: &FleetBenchReport) -> String {
    format!(
        "| robots | rate | poses sent | answered | replans/s | latency mean | p50 | p99 | max | tasks done | planner alone (1 thread) | planner capacity ({} cores) |\n\
         |---|---|---|---|---|---|---|---|---|---|---|---|\n\
         | {} | {:.0} Hz | {} | {:.1} % | {:.0} | {:.2} ms | {:.2} ms | {:.2} ms | {:.2} ms | {} | {:.2} ms/replan | {:.0}/s |\n",
        r.cpu_cores,
        r.robots,
        r.rate_hz,
        r.poses_sent,
        r.answered_fraction * 100.0,
        r.replans_per_s,
        r.latency_ms.mean,
        r.latency_ms.p50,
        r.latency_ms.p99,
        r.latency_ms.max,
        r.tasks_completed,
        r.reference_replan_ms.mean,
        r.reference_capacity_per_s,
    )
}
