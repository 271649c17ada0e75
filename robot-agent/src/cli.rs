//! The `robot-agent` command line: flags over the TOML configuration, then [`node::run`] until
//! Ctrl-C.
//!
//! Flags override the file: `--site`, `--controller`, `--model`, `--map`, `--initial-pose`.
//! Without `--initial-pose` (and no `[localization] initial_pose` in the file) the agent
//! localizes globally.
//!
//! Zenoh: the shared [`SessionArgs`] flags (`--zenoh-listen`/`--listen`,
//! `--zenoh-connect`/`--connect`, `--zenoh-multicast-scouting`); multicast scouting is off
//! unless asked for, so an agent meets only the peers it is pointed at.

use std::path::PathBuf;

use anyhow::Context;
use clap::Parser;
use protocol::{MapName, Pose2D, RobotId, SessionArgs, SiteId};

use crate::config::{AgentConfig, ControllerKind};
use crate::node::{self, NodeOptions};

/// Robot agent: AMCL localization, the controller and the safety loop of one robot.
#[derive(Debug, Clone, Parser)]
#[command(
    name = "robot-agent",
    version,
    about,
    mut_arg(SessionArgs::LISTEN_ID, |a| a.visible_alias("listen")),
    mut_arg(SessionArgs::CONNECT_ID, |a| a.visible_alias("connect"))
)]
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
    #[arg(long, allow_hyphen_values = true)]
    pub initial_pose: Option<Pose2D>,
    /// Agent configuration TOML (see robot-agent/agent.example.toml).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// The Zenoh session: `--zenoh-listen` (alias `--listen`), `--zenoh-connect` (alias
    /// `--connect`), `--zenoh-multicast-scouting`.
    #[command(flatten)]
    pub zenoh: SessionArgs,
    /// Multicast scouting is off unless `--zenoh-multicast-scouting` is given; this flag is
    /// still accepted (and changes nothing) for scripts written when it was on by default.
    #[arg(long, hide = true, conflicts_with = SessionArgs::MULTICAST_ID)]
    pub no_multicast: bool,
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
    let zenoh = cli.zenoh.config()?;
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

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory;

    fn parse(args: &[&str]) -> Result<Cli, clap::Error> {
        Cli::try_parse_from(["robot-agent", "--robot-id", "r1"].iter().chain(args))
    }

    #[test]
    fn zenoh_flags_are_the_shared_ones_with_the_old_names_kept() {
        Cli::command().debug_assert();
        let cli = parse(&[]).unwrap();
        assert_eq!(cli.zenoh, SessionArgs::default());
        assert!(!cli.zenoh.multicast_scouting, "multicast is off by default");
        let cli = parse(&[
            "--connect",
            "tcp/127.0.0.1:7447",
            "--zenoh-connect",
            "tcp/127.0.0.1:7448",
            "--listen",
            "tcp/0.0.0.0:7449",
            "--no-multicast",
        ])
        .unwrap();
        assert_eq!(
            cli.zenoh.connect,
            ["tcp/127.0.0.1:7447", "tcp/127.0.0.1:7448"]
        );
        assert_eq!(cli.zenoh.listen, ["tcp/0.0.0.0:7449"]);
        assert!(!cli.zenoh.multicast_scouting);
        assert!(
            parse(&["--zenoh-multicast-scouting"])
                .unwrap()
                .zenoh
                .multicast_scouting
        );
        assert!(parse(&["--zenoh-multicast-scouting", "--no-multicast"]).is_err());
    }

    #[test]
    fn a_bad_endpoint_is_named_when_the_options_are_built() {
        let cli = parse(&["--map", "office", "--connect", "nonsense"]).unwrap();
        let e = format!("{:#}", node_options(&cli).unwrap_err());
        assert!(e.contains("connect") && e.contains("nonsense"), "{e}");
    }

    #[test]
    fn the_initial_pose_is_parsed_by_pose2d() {
        let cli = parse(&["--initial-pose", "-1.5,2,0.3"]).unwrap();
        assert_eq!(cli.initial_pose, Some(Pose2D::new(-1.5, 2.0, 0.3)));
        let e = parse(&["--initial-pose", "1,x,0"]).unwrap_err().to_string();
        assert!(
            e.contains("--initial-pose") && e.contains("y = \"x\""),
            "{e}"
        );
    }
}
