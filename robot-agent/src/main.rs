//! `robot-agent`: thin entry point; everything lives in `robot_agent::cli`.

use clap::Parser;

fn main() -> anyhow::Result<()> {
    protocol::telemetry::init_tracing("info")?;
    robot_agent::cli::run(&robot_agent::cli::Cli::parse())
}
