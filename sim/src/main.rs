//! `sim`: thin entry point; everything lives in `sim::cli`.

use clap::Parser;

fn main() -> anyhow::Result<()> {
    protocol::telemetry::init_tracing("info")?;
    sim::cli::run(sim::cli::Cli::parse())
}
