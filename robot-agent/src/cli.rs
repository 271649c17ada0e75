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
//!
//! `--record FILE` records a run log (MCAP, docs/logs.md); `--record-camera` adds the camera.
//!
//! `robot-agent replay --log FILE --map MAP [--config F] [--out POSES]` runs the agent's AMCL
//! over a run log as fast as it can (see [`crate::replay`]) and prints a markdown summary.

use std::path::PathBuf;

use anyhow::Context;
use clap::{Parser, Subcommand};
use protocol::{MapName, Pose2D, RobotId, SessionArgs, SiteId};

use crate::config::{AgentConfig, ControllerKind};
use crate::node::{self, NodeOptions, RecordOptions};

/// Robot agent: AMCL localization, the controller and the safety loop of one robot.
#[derive(Debug, Clone, Parser)]
#[command(
    name = "robot-agent",
    version,
    about,
    subcommand_negates_reqs = true,
    args_conflicts_with_subcommands = true,
    mut_arg(SessionArgs::LISTEN_ID, |a| a.visible_alias("listen")),
    mut_arg(SessionArgs::CONNECT_ID, |a| a.visible_alias("connect"))
)]
pub struct Cli {
    /// Offline tools; without one, the agent runs.
    #[command(subcommand)]
    pub command: Option<Command>,
    /// This robot's id (the `<robot_id>` key chunk).
    #[arg(long, required = true)]
    pub robot_id: Option<RobotId>,
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
    /// Record what the agent receives and publishes to this MCAP run log (written as
    /// FILE.partial until the agent stops; docs/logs.md).
    #[arg(long)]
    pub record: Option<PathBuf>,
    /// Also record the camera (JPEG) in the run log.
    #[arg(long, requires = "record")]
    pub record_camera: bool,
}

/// The subcommands.
#[derive(Debug, Clone, Subcommand)]
pub enum Command {
    /// Replay the agent's localization over a run log as fast as it can.
    Replay(ReplayArgs),
}

/// Arguments of `robot-agent replay`.
#[derive(Debug, Clone, clap::Args)]
pub struct ReplayArgs {
    /// The run log (MCAP from `robot-agent --record`, `eval ... --record-dir` or `sim run
    /// --record`).
    #[arg(long)]
    pub log: PathBuf,
    /// The floor plan (ROS map YAML) to localize on; its content hash is checked against the
    /// log's.
    #[arg(long)]
    pub map: PathBuf,
    /// Agent configuration TOML whose [amcl] and [localization] tables replace the recorded
    /// ones (default: the configuration the log recorded, which reproduces the live run).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Write the estimates here: CSV when it ends in .csv, JSON lines otherwise.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Write the summary as JSON here.
    #[arg(long)]
    pub summary: Option<PathBuf>,
    /// Pin the particle count (min = max = N) of whichever configuration is used, e.g. to
    /// time the filter at a fixed size.
    #[arg(long)]
    pub particles: Option<usize>,
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
    let robot_id = cli
        .robot_id
        .clone()
        .context("--robot-id is required to run the agent")?;
    let config = merged_config(cli)?;
    let zenoh = cli.zenoh.config()?;
    Ok(NodeOptions {
        robot_id,
        config,
        zenoh,
        record: cli.record.as_ref().map(|path| RecordOptions {
            path: path.clone(),
            log: fleet_log::LogOptions {
                camera: cli.record_camera,
                ..fleet_log::LogOptions::default()
            },
        }),
    })
}

/// `robot-agent replay`: prints the markdown summary, writes the estimates.
///
/// # Errors
/// An unreadable log, map or configuration, or a log the filter cannot replay.
pub fn run_replay(args: &ReplayArgs) -> anyhow::Result<()> {
    let log = fleet_log::RunLog::open(&args.log)?;
    let mut config = match &args.config {
        Some(path) => {
            let text = std::fs::read_to_string(path)
                .with_context(|| format!("cannot read config {}", path.display()))?;
            AgentConfig::from_toml(&text).with_context(|| format!("config {}", path.display()))?
        }
        None => crate::replay::recorded_config(&log)?,
    };
    if let Some(n) = args.particles {
        config.amcl.min_particles = n;
        config.amcl.max_particles = n;
        config
            .validate()
            .with_context(|| format!("--particles {n}"))?;
    }
    let replay = crate::replay::replay_files(&log, Some(&args.map), Some(config))?;
    if let Some(out) = &args.out {
        crate::replay::write_poses(out, &replay.poses)?;
    }
    if let Some(path) = &args.summary {
        let json = serde_json::to_string_pretty(&replay.summary)?;
        std::fs::write(path, json).with_context(|| format!("cannot write {}", path.display()))?;
    }
    println!(
        "{}",
        crate::replay::markdown(std::slice::from_ref(&replay.summary))
    );
    Ok(())
}

/// Runs the agent until Ctrl-C, or the subcommand.
///
/// # Errors
/// Bad arguments or configuration, a model that cannot be loaded, or Zenoh failures.
pub fn run(cli: &Cli) -> anyhow::Result<()> {
    if let Some(Command::Replay(args)) = &cli.command {
        return run_replay(args);
    }
    let options = node_options(cli)?;
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .context("cannot start the tokio runtime")?;
    runtime.block_on(async move {
        // Ctrl-C or SIGTERM (the demo, systemd, a container runtime): the agent stops the
        // base and finishes its run log.
        node::run(options, protocol::shutdown::stop_requested()).await
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
    fn record_and_replay_flags() {
        let cli = parse(&["--map", "office", "--record", "run.mcap", "--record-camera"]).unwrap();
        let record = node_options(&cli).unwrap().record.unwrap();
        assert_eq!(record.path, PathBuf::from("run.mcap"));
        assert!(record.log.camera);
        let cli = parse(&["--map", "office"]).unwrap();
        assert!(node_options(&cli).unwrap().record.is_none());
        let e = parse(&["--record-camera"]).unwrap_err().to_string();
        assert!(e.contains("--record"), "{e}");

        // `replay` needs no robot id, and takes none.
        let cli = Cli::try_parse_from([
            "robot-agent",
            "replay",
            "--log",
            "a.mcap",
            "--map",
            "m.yaml",
            "--out",
            "p.csv",
        ])
        .unwrap();
        assert!(cli.robot_id.is_none());
        let Some(Command::Replay(args)) = &cli.command else {
            panic!("{cli:?}")
        };
        assert_eq!(args.log, PathBuf::from("a.mcap"));
        assert_eq!(args.map, PathBuf::from("m.yaml"));
        assert_eq!(args.out, Some(PathBuf::from("p.csv")));
        assert!(args.config.is_none());
        let e = Cli::try_parse_from(["robot-agent", "replay", "--log", "a.mcap"])
            .unwrap_err()
            .to_string();
        assert!(e.contains("--map"), "{e}");
        assert!(Cli::try_parse_from([
            "robot-agent",
            "--robot-id",
            "r1",
            "replay",
            "--log",
            "a",
            "--map",
            "m"
        ])
        .is_err());
        // The agent itself still needs its id.
        let e = Cli::try_parse_from(["robot-agent", "--map", "office"])
            .unwrap_err()
            .to_string();
        assert!(e.contains("--robot-id"), "{e}");
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
