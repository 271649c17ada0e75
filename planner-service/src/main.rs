//! `planner-service` binary: parses the command line and hands it to [`planner_service::cli::run`].

use std::process::ExitCode;

use clap::Parser;

fn main() -> ExitCode {
    // Errors only unless RUST_LOG says otherwise (what `EnvFilter::from_default_env` gave).
    if let Err(e) = protocol::telemetry::init_tracing("error") {
        eprintln!("error: {e}");
        return ExitCode::FAILURE;
    }
    let cli = planner_service::cli::Cli::parse();
    match planner_service::cli::run(cli, &mut std::io::stdout().lock()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
