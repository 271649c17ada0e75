//! The `sim` command line: render one frame, draw a world top-down, run the Zenoh driver,
//! benchmark, (re)generate the shipped maps and scenarios, generate procedural buildings, print
//! the scenario schema.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use clap::{Parser, Subcommand};
use protocol::{Pose2D, SessionArgs, SiteId};
use serde::Serialize;

use crate::camera::{render, render_per_pixel};
use crate::config::SimConfig;
use crate::driver::{self, DriverConfig};
use crate::world::{Command, World};

/// Simulator for the intention fleet.
#[derive(Debug, Parser)]
#[command(name = "sim", version, about)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Cmd,
}

#[derive(Debug, Subcommand)]
pub enum Cmd {
    /// Render one camera frame (PNG) and optionally the LIDAR scan (JSON) at a pose.
    Render {
        #[arg(long)]
        scenario: PathBuf,
        /// x,y,yaw in the map frame (metres, radians).
        #[arg(long, allow_hyphen_values = true)]
        pose: Pose2D,
        #[arg(long)]
        out: PathBuf,
        #[arg(long)]
        scan_out: Option<PathBuf>,
        /// Sensor/base settings YAML (see sim/config.example.yaml).
        #[arg(long)]
        config: Option<PathBuf>,
    },
    /// Draw the floor plan, ground-truth extras, start and goals top-down (PNG).
    View {
        #[arg(long)]
        scenario: PathBuf,
        #[arg(long)]
        out: PathBuf,
        /// Pixels per plan cell.
        #[arg(long, default_value_t = 1)]
        scale: u32,
    },
    /// Run the real-time Zenoh driver until Ctrl-C.
    #[command(
        mut_arg(SessionArgs::LISTEN_ID, |a| a.visible_alias("listen")),
        mut_arg(SessionArgs::CONNECT_ID, |a| a.visible_alias("connect"))
    )]
    Run {
        #[arg(long)]
        scenario: PathBuf,
        #[arg(long, default_value_t = 1)]
        robots: usize,
        #[arg(long, default_value = "default")]
        site: String,
        /// The Zenoh session: `--zenoh-listen` (alias `--listen`), `--zenoh-connect` (alias
        /// `--connect`), `--zenoh-multicast-scouting` (off by default).
        #[command(flatten)]
        zenoh: SessionArgs,
        #[arg(long)]
        config: Option<PathBuf>,
        #[arg(long, default_value_t = 20.0)]
        odom_hz: f64,
        #[arg(long, default_value_t = 10.0)]
        scan_hz: f64,
        #[arg(long, default_value_t = 10.0)]
        camera_hz: f64,
        #[arg(long, default_value_t = 500)]
        cmd_timeout_ms: u64,
        /// Record the first robot's odometry, scans and ground truth as a run log (MCAP,
        /// written as FILE.partial until the driver stops; docs/logs.md).
        #[arg(long)]
        record: Option<PathBuf>,
        /// Also record the first robot's camera (JPEG) in the run log.
        #[arg(long, requires = "record")]
        record_camera: bool,
    },
    /// Measure camera frames/s and lock-step steps/s; writes JSON and prints a markdown table.
    Bench {
        /// Scenario (default: task_b.yaml in the scenarios folder: $FLEET_SCENARIOS_DIR,
        /// ./sim/scenarios, ./scenarios or the user data directory).
        #[arg(long)]
        scenario: Option<PathBuf>,
        #[arg(long)]
        out: Option<PathBuf>,
        /// Frames rendered by the column renderer (the reference renders a tenth).
        #[arg(long, default_value_t = 2000)]
        frames: usize,
    },
    /// Regenerate the shipped floor plans and scenarios into a folder.
    GenMaps {
        #[arg(long)]
        out: PathBuf,
    },
    /// Generate procedural buildings: for each seed S..S+N-1 the ROS map under `DIR/maps/`, the
    /// scenario `DIR/<name>.yaml` and a top-down picture `DIR/<name>.png`. Seeds from 1000000
    /// make evaluation buildings (`gen_eval_<seed>`), below it training ones (`gen_<seed>`).
    GenBuilding {
        #[arg(long)]
        seed: u64,
        #[arg(long, default_value_t = 1)]
        count: u64,
        #[arg(long)]
        out: PathBuf,
    },
    /// Print the scenario JSON Schema.
    Schema,
}

fn load_config(path: Option<&Path>) -> Result<SimConfig> {
    match path {
        Some(p) => Ok(SimConfig::load(p)?),
        None => Ok(SimConfig::default()),
    }
}

/// Runs a parsed command line.
///
/// # Errors
/// Any failure, with context naming the input at fault.
pub fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Cmd::Render {
            scenario,
            pose,
            out,
            scan_out,
            config,
        } => {
            let mut world = World::from_scenario_file(&scenario, load_config(config.as_deref())?)?;
            world.add_robot(protocol::RobotId::new("robot_1")?, pose)?;
            world.add_parked_robots()?;
            let image = world.render_camera(0)?;
            let img = image::RgbImage::from_raw(image.width_px, image.height_px, image.data)
                .context("camera image has the wrong size")?;
            img.save(&out)
                .with_context(|| format!("cannot write {}", out.display()))?;
            if let Some(scan_path) = scan_out {
                let obs = world.step(&[Command::default()], 0.0);
                let scan = obs
                    .robots
                    .first()
                    .map(|o| o.scan.clone())
                    .context("no robot in the world")?;
                let text = serde_json::to_string_pretty(&scan)?;
                std::fs::write(&scan_path, text)
                    .with_context(|| format!("cannot write {}", scan_path.display()))?;
            }
            println!("wrote {}", out.display());
            Ok(())
        }
        Cmd::View {
            scenario,
            out,
            scale,
        } => {
            let world = World::from_scenario_file(&scenario, SimConfig::default())?;
            crate::view::top_down(&world, scale)
                .save(&out)
                .with_context(|| format!("cannot write {}", out.display()))?;
            println!("wrote {}", out.display());
            Ok(())
        }
        Cmd::Run {
            scenario,
            robots,
            site,
            zenoh,
            config,
            odom_hz,
            scan_hz,
            camera_hz,
            cmd_timeout_ms,
            record,
            record_camera,
        } => {
            if robots == 0 {
                bail!("invalid --robots 0: need at least one robot");
            }
            let site = SiteId::new(site)?;
            let mut world = World::from_scenario_file(&scenario, load_config(config.as_deref())?)?;
            world.add_robots_at_start(robots)?;
            let driver_config = DriverConfig {
                odom_hz,
                scan_hz,
                camera_hz,
                cmd_timeout_ms,
            };
            driver_config.validate()?;
            // Where the robots stand, for whoever starts their agents: the roster, one JSON line
            // on stdout once the session is open (the launcher reads it with
            // `Roster::parse_line`); logs for people.
            let mut roster = crate::roster::Roster::of_world(&world);
            // After the roster: parked robots get no agent, and they stand still.
            world.add_parked_robots()?;
            for r in &roster.robots {
                tracing::info!(robot = %r.id, "starts at {:.3},{:.3},{:.4}", r.x_m, r.y_m, r.yaw_rad);
            }
            let recorder = match &record {
                Some(path) => {
                    let plan_path = world.scenario.floor_plan_path(&scenario);
                    let plan_path = std::path::absolute(&plan_path).unwrap_or(plan_path);
                    let mut r = fleet_log::Recorder::start(
                        path,
                        fleet_log::LogOptions {
                            camera: record_camera,
                            ..fleet_log::LogOptions::default()
                        },
                    )?;
                    r.record(fleet_log::LogMessage::Map(driver::log_map_info(
                        &world,
                        Some(&plan_path),
                    )));
                    Some(r)
                }
                None => None,
            };
            let rt = tokio::runtime::Runtime::new()?;
            rt.block_on(async move {
                // Multicast scouting only when asked for: two demos on one host must not drive
                // each other's robots.
                let session = zenoh.open().await?;
                roster.zenoh = protocol::zenoh_io::locators(&session).await;
                {
                    use std::io::Write as _;
                    let mut stdout = std::io::stdout().lock();
                    writeln!(stdout, "{}", roster.to_line()?)?;
                    stdout.flush()?;
                }
                driver::run_recording(
                    &session,
                    world,
                    &site,
                    driver_config,
                    recorder,
                    protocol::shutdown::stop_requested(),
                )
                .await?;
                session
                    .close()
                    .await
                    .map_err(|e| anyhow::anyhow!("closing zenoh: {e}"))?;
                Ok(())
            })
        }
        Cmd::Bench {
            scenario,
            out,
            frames,
        } => {
            let scenario = match scenario {
                Some(s) => s,
                None => protocol::data_dirs::find_scenarios_dir(None)?.join("task_b.yaml"),
            };
            let result = bench(&scenario, frames.max(10))?;
            println!("{}", result.markdown());
            if let Some(out) = out {
                std::fs::write(&out, serde_json::to_string_pretty(&result)?)
                    .with_context(|| format!("cannot write {}", out.display()))?;
            }
            Ok(())
        }
        Cmd::GenMaps { out } => {
            let files = crate::mapgen::generate(&out)?;
            println!("wrote {} files under {}", files.len(), out.display());
            Ok(())
        }
        Cmd::GenBuilding { seed, count, out } => {
            for written in crate::procgen::generate(&out, seed, count)? {
                println!("{}", written.summary);
            }
            println!("wrote {count} buildings under {}", out.display());
            Ok(())
        }
        Cmd::Schema => {
            print!("{}", crate::scenario::json_schema());
            Ok(())
        }
    }
}

/// Benchmark results.
#[derive(Debug, Clone, Serialize)]
pub struct BenchResult {
    pub scenario: String,
    pub width_px: u32,
    pub height_px: u32,
    pub column_frames: usize,
    pub column_frames_per_s: f64,
    pub per_pixel_frames: usize,
    pub per_pixel_frames_per_s: f64,
    pub speedup: f64,
    pub lockstep_steps: usize,
    /// Physics + LIDAR + odometry per step.
    pub lockstep_steps_per_s: f64,
    /// Physics + LIDAR + odometry + one camera frame per step.
    pub lockstep_with_camera_steps_per_s: f64,
    pub threads: usize,
}

impl BenchResult {
    pub fn markdown(&self) -> String {
        format!(
            "| measurement ({}x{} px, {}) | rate |\n|---|---|\n\
             | camera, column ray-caster (frames/s) | {:.0} |\n\
             | camera, per-pixel reference (frames/s) | {:.1} |\n\
             | speed-up of the column design | {:.0}x |\n\
             | lock-step steps/s (scan + odom, 1 robot) | {:.0} |\n\
             | lock-step steps/s (scan + odom + camera) | {:.0} |\n",
            self.width_px,
            self.height_px,
            self.scenario,
            self.column_frames_per_s,
            self.per_pixel_frames_per_s,
            self.speedup,
            self.lockstep_steps_per_s,
            self.lockstep_with_camera_steps_per_s
        )
    }
}

fn progress(n: usize, what: &str) -> indicatif::ProgressBar {
    let bar = indicatif::ProgressBar::new(n as u64);
    if let Ok(style) = indicatif::ProgressStyle::with_template("{msg:>28} {bar:40} {pos}/{len}") {
        bar.set_style(style);
    }
    bar.set_message(what.to_string());
    bar
}

/// Poses along a scripted drive from the scenario start (the driving itself is not timed).
fn bench_poses(world: &World, n: usize) -> Vec<Pose2D> {
    let mut w = world.clone();
    let mut poses = Vec::with_capacity(n);
    for k in 0..n {
        #[allow(clippy::cast_precision_loss)]
        let t = k as f64 * 0.1;
        let cmd = Command {
            v_mps: 0.8,
            omega_radps: 0.6 * (0.3 * t).sin(),
        };
        let obs = w.step(&[cmd], 0.1);
        poses.push(obs.robots[0].ground_truth_pose);
    }
    poses
}

/// Runs the benchmark on one core.
///
/// # Errors
/// Scenario loading or robot placement failures.
pub fn bench(scenario: &Path, frames: usize) -> Result<BenchResult> {
    let mut world = World::from_scenario_file(scenario, SimConfig::default())?;
    world.add_robot(
        protocol::RobotId::new("robot_1")?,
        world.scenario.start.to_pose(),
    )?;
    let poses = bench_poses(&world, 200);
    let model = world.camera_model().clone();
    let mut buf = Vec::new();

    let bar = progress(frames, "column renderer");
    let t0 = Instant::now();
    for k in 0..frames {
        render(&world, &model, poses[k % poses.len()], Some(0), &mut buf);
        if k % 64 == 0 {
            bar.set_position(k as u64);
        }
    }
    let column_s = t0.elapsed().as_secs_f64();
    bar.finish_and_clear();

    let ref_frames = (frames / 100).max(3);
    let bar = progress(ref_frames, "per-pixel reference");
    let t0 = Instant::now();
    for k in 0..ref_frames {
        render_per_pixel(&world, &model, poses[k % poses.len()], Some(0), &mut buf);
        bar.inc(1);
    }
    let ref_s = t0.elapsed().as_secs_f64();
    bar.finish_and_clear();

    let steps = frames;
    let mut w = world.clone();
    let cmd = [Command {
        v_mps: 0.5,
        omega_radps: 0.3,
    }];
    let t0 = Instant::now();
    for _ in 0..steps {
        let _ = w.step(&cmd, 0.05);
    }
    let step_s = t0.elapsed().as_secs_f64();
    let mut w = world.clone();
    let t0 = Instant::now();
    for _ in 0..steps {
        let _ = w.step(&cmd, 0.05);
        let _ = w.render_camera(0)?;
    }
    let step_cam_s = t0.elapsed().as_secs_f64();

    #[allow(clippy::cast_precision_loss)]
    let rate = |n: usize, s: f64| n as f64 / s.max(1e-12);
    let column = rate(frames, column_s);
    let per_pixel = rate(ref_frames, ref_s);
    Ok(BenchResult {
        scenario: world.scenario.name.clone(),
        width_px: world.config.camera.width_px,
        height_px: world.config.camera.height_px,
        column_frames: frames,
        column_frames_per_s: column,
        per_pixel_frames: ref_frames,
        per_pixel_frames_per_s: per_pixel,
        speedup: column / per_pixel.max(1e-12),
        lockstep_steps: steps,
        lockstep_steps_per_s: rate(steps, step_s),
        lockstep_with_camera_steps_per_s: rate(steps, step_cam_s),
        threads: 1,
    })
}

#[cfg(test)]
mod session_and_pose_flag_tests {
    use super::*;
    use clap::CommandFactory;

    #[test]
    fn run_takes_the_shared_zenoh_flags_and_render_a_pose2d() {
        Cli::command().debug_assert();
        let cli = Cli::try_parse_from([
            "sim",
            "run",
            "--scenario",
            "s.yaml",
            "--connect",
            "tcp/127.0.0.1:7447",
            "--zenoh-listen",
            "tcp/127.0.0.1:0",
        ])
        .unwrap();
        let Cmd::Run { zenoh, .. } = cli.command else {
            unreachable!("parsed a run command")
        };
        assert_eq!(zenoh.connect, ["tcp/127.0.0.1:7447"]);
        assert_eq!(zenoh.listen, ["tcp/127.0.0.1:0"]);
        assert!(!zenoh.multicast_scouting, "multicast is off by default");
        let cli = Cli::try_parse_from([
            "sim",
            "render",
            "--scenario",
            "s.yaml",
            "--pose",
            "-2.5,10,0",
            "--out",
            "x.png",
        ])
        .unwrap();
        let Cmd::Render { pose, .. } = cli.command else {
            unreachable!("parsed a render command")
        };
        assert_eq!(pose, Pose2D::new(-2.5, 10.0, 0.0));
    }
}
