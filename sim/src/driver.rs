//! Real-time Zenoh driver: simulated robots on the wire exactly like real bases.
//!
//! Per robot it publishes `odom`, `scan` and `camera` on the keys of DESIGN §3 (built by
//! `protocol::keys`, encoded by `protocol`'s codec) and obeys `cmd_vel`. Physics steps at the
//! odometry rate in wall-clock time; scan and camera are published at their own rates. A command
//! older than `cmd_timeout_ms` counts as stop, so a dead agent cannot leave a robot driving.
//!
//! [`run_recording`] also records the first robot's odometry, scans, ground truth (and camera
//! when asked) as a run log (`fleet-log`; `sim run --record FILE`) on a background thread.

use std::future::Future;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use fleet_log::{LogMessage, Recorder, StampedPose};
use protocol::keys::{self, RobotTopic};
use protocol::{CmdVel, SiteId};
use serde::{Deserialize, Serialize};
use zenoh::Session;

use crate::world::{Command, World};

/// Rates and timeouts of the driver.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DriverConfig {
    pub odom_hz: f64,
    pub scan_hz: f64,
    pub camera_hz: f64,
    /// A cmd_vel older than this means stop.
    pub cmd_timeout_ms: u64,
}

impl Default for DriverConfig {
    fn default() -> Self {
        Self {
            odom_hz: 20.0,
            scan_hz: 10.0,
            camera_hz: 10.0,
            cmd_timeout_ms: 500,
        }
    }
}

/// Why the driver stopped with an error.
#[derive(Debug, thiserror::Error)]
pub enum DriverError {
    #[error("invalid driver setting {field} = {value}: {reason}")]
    Invalid {
        field: &'static str,
        value: String,
        reason: &'static str,
    },
    #[error("zenoh: {0}")]
    Zenoh(zenoh::Error),
    #[error(transparent)]
    Publish(#[from] protocol::PublishError),
    #[error(transparent)]
    Sim(#[from] crate::world::SimError),
    #[error("run log: {0}")]
    Log(#[from] fleet_log::LogError),
}

impl DriverConfig {
    /// # Errors
    /// [`DriverError::Invalid`] for a rate that is not positive and finite or above 1 kHz.
    pub fn validate(&self) -> Result<(), DriverError> {
        for (field, v) in [
            ("odom_hz", self.odom_hz),
            ("scan_hz", self.scan_hz),
            ("camera_hz", self.camera_hz),
        ] {
            if !(v.is_finite() && v > 0.0 && v <= 1000.0) {
                return Err(DriverError::Invalid {
                    field,
                    value: v.to_string(),
                    reason: "must lie in (0, 1000]",
                });
            }
        }
        Ok(())
    }
}

type Latest = Arc<Mutex<Vec<Option<(Command, Instant)>>>>;

/// Runs the driver for every robot of `world` until `shutdown` completes.
///
/// # Errors
/// Zenoh declaration or publication failures, invalid settings.
pub async fn run(
    session: &Session,
    world: World,
    site: &SiteId,
    config: DriverConfig,
    shutdown: impl Future<Output = ()>,
) -> Result<(), DriverError> {
    run_recording(session, world, site, config, None, shutdown).await
}

/// The `/map` record of a simulator log: the scenario's floor plan and the first robot's true
/// start (what an operator would give its agent as the initial pose).
#[must_use]
pub fn log_map_info(world: &World, plan_path: Option<&std::path::Path>) -> fleet_log::MapInfo {
    let plan = &world.plan;
    fleet_log::MapInfo {
        stamp_ns: world.time_ns(),
        name: plan_path.and_then(|p| p.file_stem()).map_or_else(
            || world.scenario.name.clone(),
            |s| s.to_string_lossy().into_owned(),
        ),
        version: 1,
        path: plan_path.map(|p| p.display().to_string()),
        content_hash: Some(plan.content_hash()),
        initial_pose: world.ground_truth_pose(0),
        initial_covariance: None,
        source: format!("sim: {}", world.scenario.name),
    }
}

/// [`run`], recording the first robot into `recorder` (which the caller has given its `/map`
/// record) and finishing the log when the driver stops.
///
/// # Errors
/// As [`run`], or the log's error when it cannot be finished.
pub async fn run_recording(
    session: &Session,
    mut world: World,
    site: &SiteId,
    config: DriverConfig,
    mut recorder: Option<Recorder>,
    shutdown: impl Future<Output = ()>,
) -> Result<(), DriverError> {
    config.validate()?;
    let ids = world.robot_ids();
    let latest: Latest = Arc::new(Mutex::new(vec![None; ids.len()]));
    let mut subscribers = Vec::new();
    let mut odom_pubs = Vec::new();
    let mut scan_pubs = Vec::new();
    let mut camera_pubs = Vec::new();
    for (i, id) in ids.iter().enumerate() {
        let latest = Arc::clone(&latest);
        let robot = id.clone();
        let sub = session
            .declare_subscriber(keys::robot(site, id, RobotTopic::CmdVel))
            .callback(
                move |sample| match protocol::decode_sample::<CmdVel>(&sample) {
                    Ok(cmd) => {
                        let command = Command {
                            v_mps: cmd.v_mps,
                            omega_radps: cmd.omega_radps,
                        };
                        if let Ok(mut slots) = latest.lock() {
                            if let Some(slot) = slots.get_mut(i) {
                                *slot = Some((command, Instant::now()));
                            }
                        }
                    }
                    Err(e) => tracing::warn!(robot = %robot, "ignoring cmd_vel: {e}"),
                },
            )
            .await
            .map_err(DriverError::Zenoh)?;
        subscribers.push(sub);
        odom_pubs.push(
            session
                .declare_publisher(keys::robot(site, id, RobotTopic::Odom))
                .await
                .map_err(DriverError::Zenoh)?,
        );
        scan_pubs.push(
            session
                .declare_publisher(keys::robot(site, id, RobotTopic::Scan))
                .await
                .map_err(DriverError::Zenoh)?,
        );
        camera_pubs.push(
            session
                .declare_publisher(keys::robot(site, id, RobotTopic::Camera))
                .await
                .map_err(DriverError::Zenoh)?,
        );
    }
    let dt = 1.0 / config.odom_hz;
    let timeout = Duration::from_millis(config.cmd_timeout_ms);
    let mut ticker = tokio::time::interval(Duration::from_secs_f64(dt));
    ticker.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let (mut scan_due, mut camera_due) = (0.0f64, 0.0f64);
    tokio::pin!(shutdown);
    tracing::info!(robots = ids.len(), site = %site, "sim driver running");
    loop {
        tokio::select! {
            () = &mut shutdown => break,
            _ = ticker.tick() => {}
        }
        let now = Instant::now();
        let commands: Vec<Command> = match latest.lock() {
            Ok(slots) => slots
                .iter()
                .map(|s| match s {
                    Some((c, at)) if now.duration_since(*at) <= timeout => *c,
                    _ => Command::default(),
                })
                .collect(),
            Err(_) => vec![Command::default(); ids.len()],
        };
        let obs = world.step(&commands, dt);
        scan_due -= dt;
        camera_due -= dt;
        let send_scan = scan_due <= 1e-9;
        let send_camera = camera_due <= 1e-9;
        if send_scan {
            scan_due += 1.0 / config.scan_hz;
        }
        if send_camera {
            camera_due += 1.0 / config.camera_hz;
        }
        for (i, o) in obs.robots.iter().enumerate() {
            for c in &o.collisions {
                tracing::warn!(robot = %o.robot_id, "collision with {}", c.with);
            }
            protocol::zenoh_io::publish(&odom_pubs[i], &o.odom).await?;
            if let Some(r) = recorder.as_mut().filter(|_| i == 0) {
                r.record(LogMessage::Odom(o.odom.clone()));
                r.record(LogMessage::GroundTruth(StampedPose {
                    header: o.odom.header,
                    pose: o.ground_truth_pose,
                }));
                if send_scan {
                    r.record(LogMessage::Scan(o.scan.clone()));
                }
            }
            if send_scan {
                protocol::zenoh_io::publish(&scan_pubs[i], &o.scan).await?;
            }
            if send_camera {
                let frame = world.camera_frame(i)?;
                protocol::zenoh_io::publish(&camera_pubs[i], &frame).await?;
                if let Some(r) = recorder.as_mut().filter(|_| i == 0) {
                    r.record_camera(&frame);
                }
            }
        }
    }
    drop(subscribers);
    if let Some(r) = recorder {
        let path = r.finish()?;
        tracing::info!(path = %path.display(), "run log written");
    }
    Ok(())
}
