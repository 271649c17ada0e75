//! The `planner-service` command line: `plan` one path, `bench` the planner.
//!
//! `serve` and `demo` are added by the fleet service. [`run`] does the work so tests can call
//! it; `main` only parses arguments and reports errors.

use std::io::Write;
use std::path::{Path as FsPath, PathBuf};
use std::sync::Arc;

use anyhow::Context;
use clap::{Args, Parser, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};
use map_store::{load_ros_map, ImportLimits};
use protocol::Pose2D;

use crate::bench::{markdown_table, run_bench, BenchOptions};
use crate::config::ServiceConfig;
use crate::intention::{dlm_from_path, render_lpe};
use crate::picture::{render_picture, save_picture};
use crate::planning::{Planner, PlanningMap};

/// Fleet planner: hybrid A* paths and intentions on floor plans.
#[derive(Debug, Parser)]
#[command(name = "planner-service", version, about)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Plan one path on a ROS map and print it.
    Plan(PlanArgs),
    /// Benchmark hybrid A* against 2-D A* on random start/goal pairs.
    Bench(BenchArgs),
}

#[derive(Debug, Args)]
pub struct PlanArgs {
    /// ROS map_server YAML.
    #[arg(long)]
    pub map: PathBuf,
    /// Start pose `x,y,yaw` (metres, metres, radians) in the map frame.
    #[arg(long, value_parser = parse_pose, allow_hyphen_values = true)]
    pub start: Pose2D,
    /// Goal pose `x,y,yaw`.
    #[arg(long, value_parser = parse_pose, allow_hyphen_values = true)]
    pub goal: Pose2D,
    /// Configuration file (TOML with `[planner]`, `[dlm]`, `[lpe]`); defaults otherwise.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
    /// Write the LPE intention image at the start as PNG.
    #[arg(long)]
    pub lpe: Option<PathBuf>,
    /// Write a picture of the map and path as PNG.
    #[arg(long)]
    pub picture: Option<PathBuf>,
}

#[derive(Debug, Args)]
pub struct BenchArgs {
    /// Random start/goal pairs per map.
    #[arg(long, default_value_t = 1000)]
    pub pairs: usize,
    /// Map YAML files (default: the three Nav2 100by100 maps).
    #[arg(long, num_args = 1..)]
    pub maps: Vec<PathBuf>,
    /// Write the results as JSON here.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Seed of the pair sampler.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Configuration file (its `[planner]` table is used).
    #[arg(long)]
    pub config: Option<PathBuf>,
}

/// Parses `x,y,yaw` (three finite numbers).
///
/// # Errors
/// A message naming the bad part.
pub fn parse_pose(s: &str) -> Result<Pose2D, String> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    if parts.len() != 3 {
        return Err(format!(
            "expected x,y,yaw (metres, metres, radians), got {s:?}"
        ));
    }
    let mut v = [0.0; 3];
    for ((name, part), out) in ["x", "y", "yaw"].iter().zip(&parts).zip(&mut v) {
        *out = part
            .parse::<f64>()
            .ok()
            .filter(|x| x.is_finite())
            .ok_or_else(|| format!("{name} = {part:?} is not a finite number"))?;
    }
    Ok(Pose2D::new(v[0], v[1], v[2]))
}

fn load_config(path: Option<&FsPath>) -> anyhow::Result<ServiceConfig> {
    Ok(match path {
        Some(p) => ServiceConfig::load(p)?,
        None => ServiceConfig::default(),
    })
}

/// Runs a parsed command line, writing results to `out`.
///
/// # Errors
/// Any failure, with context; nothing is written to files named in the arguments unless the
/// plan succeeded.
pub fn run(cli: Cli, out: &mut dyn Write) -> anyhow::Result<()> {
    match cli.command {
        Command::Plan(args) => plan(&args, out),
        Command::Bench(args) => bench(&args, out),
    }
}

fn plan(args: &PlanArgs, out: &mut dyn Write) -> anyhow::Result<()> {
    let cfg = load_config(args.config.as_deref())?;
    let ros = load_ros_map(&args.map, &ImportLimits::default())?;
    let map = Arc::new(PlanningMap::new(ros.grid, &cfg.planner)?);
    let mut planner = Planner::new(Arc::clone(&map), cfg.planner.clone())?;
    let path = planner
        .plan(args.start, args.goal)
        .context("planning failed")?;
    let dlm = dlm_from_path(&path.poses, args.start, &cfg.dlm);

    if let Some(lpe_path) = &args.lpe {
        let img = render_lpe(map.grid(), args.start, &[], &path.poses, &cfg.lpe)?;
        img.save_png(lpe_path)?;
    }
    if let Some(pic) = &args.picture {
        save_picture(&render_picture(map.grid(), &path.poses), pic)?;
    }
    if args.json {
        let doc = serde_json::json!({
            "map": args.map.display().to_string(),
            "start": args.start,
            "goal": args.goal,
            "dlm": dlm.as_str(),
            "path": path,
        });
        writeln!(out, "{}", serde_json::to_string_pretty(&doc)?)?;
    } else {
        #[allow(clippy::cast_precision_loss)]
        let plan_ms = path.plan_time_us as f64 / 1e3;
        writeln!(out, "map: {}", args.map.display())?;
        writeln!(
            out,
            "length: {:.3} m, {} poses",
            path.length_m,
            path.poses.len()
        )?;
        writeln!(out, "planning time: {plan_ms:.3} ms")?;
        writeln!(out, "states expanded: {}", path.states_expanded)?;
        writeln!(
            out,
            "heuristic cache hit: {}",
            path.stats.heuristic_cache_hit
        )?;
        writeln!(out, "DLM at start: {dlm}")?;
        writeln!(out, "poses (x_m y_m yaw_rad):")?;
        for p in &path.poses {
            writeln!(out, "{:.3} {:.3} {:.4}", p.x_m, p.y_m, p.yaw_rad)?;
        }
    }
    Ok(())
}

fn bench(args: &BenchArgs, out: &mut dyn Write) -> anyhow::Result<()> {
    let cfg = load_config(args.config.as_deref())?;
    let mut opts = BenchOptions::nav2_default();
    if !args.maps.is_empty() {
        opts.maps.clone_from(&args.maps);
    }
    opts.pairs = args.pairs;
    opts.seed = args.seed;
    opts.config = cfg.planner;
    let total = (opts.pairs * opts.maps.len()) as u64;
    let bar = ProgressBar::new(total);
    if let Ok(style) =
        ProgressStyle::with_template("{bar:40} {pos}/{len} pairs {elapsed} eta {eta}")
    {
        bar.set_style(style);
    }
    let command: Vec<String> = std::env::args().collect();
    let report = run_bench(&opts, command.join(" "), &bar)?;
    bar.finish_and_clear();
    if let Some(path) = &args.out {
        std::fs::write(path, serde_json::to_string_pretty(&report)?)
            .with_context(|| format!("cannot write {}", path.display()))?;
    }
    write!(out, "{}", markdown_table(&report))?;
    for m in &report.maps {
        for f in &m.failures {
            writeln!(out, "failure on {}: {f}", m.map)?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn poses_parse_and_errors_name_the_part() {
        let p = parse_pose("1.5,-2,0.3").unwrap();
        assert_eq!(p, Pose2D::new(1.5, -2.0, 0.3));
        assert!(parse_pose("1,2").unwrap_err().contains("x,y,yaw"));
        assert!(parse_pose("1,nan,0").unwrap_err().contains("y"));
        assert!(parse_pose("1,2,abc").unwrap_err().contains("yaw"));
    }
}
