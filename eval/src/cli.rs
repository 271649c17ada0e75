//! The `eval` command line.
//!
//! `eval amcl-accuracy [--tasks a,b,c,d,e] [--seed N] [--out results.json]`: AMCL against the
//! simulator's ground truth on tasks A–E (see [`crate::amcl_accuracy`]); prints a markdown
//! table and writes the figures as JSON.

use std::path::PathBuf;

use anyhow::Context;
use clap::{Parser, Subcommand};
use robot_agent::{AgentConfig, ControllerKind};

use crate::amcl_accuracy::{self, AccuracyOptions, TaskAccuracy};

/// Closed-loop evaluation of the intention fleet in the simulator.
#[derive(Debug, Parser)]
#[command(name = "eval", version, about)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Cmd,
}

#[derive(Debug, Subcommand)]
pub enum Cmd {
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
    },
}

/// Runs a command.
///
/// # Errors
/// Bad arguments (naming the flag and value), unreadable files, failed runs.
pub fn run(cli: &Cli) -> anyhow::Result<()> {
    match &cli.command {
        Cmd::AmclAccuracy {
            tasks,
            seed,
            out,
            controller,
            config,
            scenarios,
            max_sim_s,
        } => {
            let agent = match config {
                Some(path) => {
                    let text = std::fs::read_to_string(path)
                        .with_context(|| format!("cannot read {}", path.display()))?;
                    AgentConfig::from_toml(&text)
                        .with_context(|| format!("config {}", path.display()))?
                }
                None => AgentConfig::default(),
            };
            if let Some(s) = max_sim_s {
                if !(s.is_finite() && *s > 0.0) {
                    anyhow::bail!("invalid --max-sim-s {s}: must be a positive number");
                }
            }
            let scenarios = protocol::data_dirs::find_scenarios_dir(scenarios.as_deref())?;
            let paths = tasks
                .iter()
                .map(|t| amcl_accuracy::task_scenario(&scenarios, t))
                .collect::<Result<Vec<_>, _>>()?;
            let options = AccuracyOptions {
                seed: *seed,
                controller: *controller,
                max_sim_s: *max_sim_s,
                agent,
                ..AccuracyOptions::default()
            };
            let mut results: Vec<TaskAccuracy> = Vec::new();
            for path in &paths {
                let bar = indicatif::ProgressBar::new(1000);
                bar.set_style(
                    indicatif::ProgressStyle::with_template(
                        "{prefix:>8} [{bar:40}] {pos:>4}/{len} sim-s {msg}",
                    )
                    .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
                );
                bar.set_prefix(
                    path.file_stem()
                        .map(|s| s.to_string_lossy().into_owned())
                        .unwrap_or_default(),
                );
                let result = amcl_accuracy::run_task(path, &options, |t_s, limit_s, goals| {
                    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
                    {
                        bar.set_length(limit_s.ceil() as u64);
                        bar.set_position(t_s as u64);
                    }
                    bar.set_message(format!("goals reached {goals}"));
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
