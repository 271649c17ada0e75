//! The `robot-agent` command line: flags over the TOML configuration, then [`node::run`] until
//! Ctrl-C.
//!
//! Flags override the file: `--site`, `--controller`, `--model`, `--map`, `--initial-pose`.
//! Without `--initial-pose` (and no `[localization] initial_pose` in the file) the agent
//! localizes globally.

use std::path::PathBuf;

use anyhow::Context;
use clap::Parser;
use protocol::{MapName, Pose2D, RobotId, SiteId};

use crate::config::{AgentConfig, ControllerKind};
use crate::node::{self, NodeOptions};

/// Robot agent: AMCL localization, the controller and the safety loop of one robot.
#[derive(Debug, Clone, Parser)]
#[command(name = "robot-agent", version, about)]
pub struct Cli {
    /// This robot's id (the `<robot_id>` key chunk).
    #[arg(long)]
    pub robot_id: RobotId,
    /// Site (the `<site>` key chunk); overrides `site` in the config.
    #[arg(long)]
    pub site: Option<SiteId>,
    /// dlm | lpe | none | path-tracker | dynamic-window; overrides `controller`.
    #[arg(long)]
    pub controller: Option<ControllerKind>,
    /// ONNX model of the dlm, lpe and none controllers; overrides `model`.
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Floor plan to localize on (map store name); overrides `map`.
    #[arg(long)]
    pub map: Option<MapName>,
    /// Initial pose `x,y,yaw` in the map frame (metres, radians); without it, global
    /// localization.
    #[arg(long, value_parser = parse_pose, allow_hyphen_values = true)]
    pub initial_pose: Option<Pose2D>,
    /// Agent configuration TOML (see robot-agent/agent.example.toml).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Zenoh endpoint to listen on, e.g. tcp/0.0.0.0:7447 (repeatable).
    #[arg(long)]
    pub listen: Vec<String>,
    /// Zenoh endpoint to connect to, e.g. tcp/192.168.1.10:7447 (repeatable).
    #[arg(long)]
    pub connect: Vec<String>,
    /// Turn off Zenoh multicast scouting (peers are then found only through the endpoints).
    #[arg(long)]
    pub no_multicast: bool,
}

/// Parses `x,y,yaw` (metres, metres, radians).
///
/// # Errors
/// A message naming the bad part.
pub fn parse_pose(text: &str) -> Result<Pose2D, String> {
    let parts: Vec<&str> = text.split(',').map(str::trim).collect();
    let [x, y, yaw] = parts.as_slice() else {
        return Err(format!(
            "`{text}` is not x,y,yaw (three comma-separated numbers)"
        ));
    };
    let num = |name: &str, s: &str| -> Result<f64, String> {
        s.parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| format!("{name} `{s}` is not a finite number"))
    };
    Ok(Pose2D::new(num("x", x)?, num("y", y)?, num("yaw", yaw)?))
}

/// The configuration file (or the defaults) with the flags applied, validated.
///
/// # Errors
/// An unreadable or invalid file, or a combination that fails validation (e.g. `--controller
/// dlm` without a model), naming the field.
pub fn merged_config(cli: &Cli) -> anyhow::Result<AgentConfig> {
    let mut config = match &cli.config {
        Some(path) => {
            let text = std::fs::read_to_string(path)
                .with_context(|| format!("cannot read config {}", path.display()))?;
            AgentConfig::from_toml(&text).with_context(|| format!("config {}", path.display()))?
        }
        None => AgentConfig::default(),
    };
    if let Some(site) = &cli.site {
        config.site = site.clone();
    }
    if let Some(kind) = cli.controller {
        config.controller = kind;
    }
    if let Some(model) = &cli.model {
        config.model = Some(model.clone());
    }
    if let Some(map) = &cli.map {
        config.map = Some(map.clone());
    }
    if let Some(pose) = cli.initial_pose {
        config.localization.initial_pose = Some(pose);
    }
    config.validate()?;
    if config.map.is_none() {
        anyhow::bail!("no map: give --map NAME or `map = \"NAME\"` in the config");
    }
    Ok(config)
}

/// Everything the node needs, from the command line.
///
/// # Errors
/// As [`merged_config`], or endpoints Zenoh refuses.
pub fn node_options(cli: &Cli) -> anyhow::Result<NodeOptions> {
    let config = merged_config(cli)?;
    let zenoh = node::zenoh_config(&cli.listen, &cli.connect, !cli.no_multicast)?;
    Ok(NodeOptions {
        robot_id: cli.robot_id.clone(),
        config,
        zenoh,
    })
}

/// Runs the agent until Ctrl-C.
///
/// # Errors
/// Bad arguments or configuration, a model that cannot be loaded, or Zenoh failures.
pub fn run(cli: &Cli) -> anyhow::Result<()> {
    let options = node_options(cli)?;
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .context("cannot start the tokio runtime")?;
    runtime.block_on(async move {
        let shutdown = async {
            if let Err(e) = tokio::signal::ctrl_c().await {
                tracing::error!("cannot listen for Ctrl-C ({e}); stopping");
            }
        };
        node::run(options, shutdown).await
    })?;
    Ok(())
}
