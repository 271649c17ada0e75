//! The `map-store` binary: parses arguments and hands over to [`map_store::cli::run`].

use std::process::ExitCode;

fn main() -> ExitCode {
    if let Err(e) = protocol::telemetry::init_tracing("warn") {
        eprintln!("error: {e}");
        return ExitCode::FAILURE;
    }
    let mut stdout = std::io::stdout();
    match map_store::cli::run(std::env::args_os(), &mut stdout) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => match e.downcast::<clap::Error>() {
            // clap formats help, version and usage errors itself, with its own exit codes.
            Ok(clap_err) => clap_err.exit(),
            Err(e) => {
                eprintln!("error: {e:#}");
                ExitCode::FAILURE
            }
        },
    }
}
