//! `eval`: thin entry point; everything lives in `eval::cli`.

use clap::Parser;

fn main() -> anyhow::Result<()> {
    protocol::telemetry::init_tracing("info")?;
    eval::cli::run(&eval::cli::Cli::parse())
}
