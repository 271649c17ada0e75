//! The one logging set-up of the fleet binaries (feature `cli`): `tracing` to stderr, filtered
//! by `RUST_LOG` when it is set and valid, else by the binary's default filter.

use tracing_subscriber::EnvFilter;

/// Why logging could not be set up.
#[derive(Debug, thiserror::Error)]
pub enum TracingInitError {
    #[error("invalid default log filter {filter:?}: {reason}")]
    DefaultFilter { filter: String, reason: String },
    #[error("cannot install the log subscriber: {0}")]
    Install(String),
}

/// Installs the global subscriber: formatted events on stderr, filtered by `RUST_LOG`
/// (e.g. `info,zenoh=warn`), or by `default_filter` when `RUST_LOG` is unset or empty. An
/// invalid `RUST_LOG` falls back to `default_filter` and says so in a warning.
///
/// # Errors
/// [`TracingInitError::DefaultFilter`] for an unparsable `default_filter`,
/// [`TracingInitError::Install`] when a global subscriber is already installed.
pub fn init_tracing(default_filter: &str) -> Result<(), TracingInitError> {
    let default = || {
        EnvFilter::try_new(default_filter).map_err(|e| TracingInitError::DefaultFilter {
            filter: default_filter.to_string(),
            reason: e.to_string(),
        })
    };
    let (filter, ignored) = match std::env::var(EnvFilter::DEFAULT_ENV) {
        Ok(value) if !value.trim().is_empty() => match EnvFilter::try_new(&value) {
            Ok(filter) => (filter, None),
            Err(e) => (default()?, Some((value, e.to_string()))),
        },
        Ok(_) => (default()?, None),
        Err(std::env::VarError::NotPresent) => (default()?, None),
        Err(e @ std::env::VarError::NotUnicode(_)) => (
            default()?,
            Some(("(not unicode)".to_string(), e.to_string())),
        ),
    };
    tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        // A write to a stderr that is gone (the pipe of a supervisor that died) is dropped.
        // The subscriber's default reports it with `eprintln!` to that same stderr, which
        // panics; the next log line in the unwinding panics again and aborts the process,
        // before it can finish its run log (tests/tests/demo.rs, the demo killed outright).
        .log_internal_errors(false)
        .try_init()
        .map_err(|e| TracingInitError::Install(e.to_string()))?;
    if let Some((value, reason)) = ignored {
        tracing::warn!("ignoring RUST_LOG={value:?} ({reason}); logging with {default_filter:?}");
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    // Test code: a failed unwrap is a failed test.
    #![allow(clippy::unwrap_used)]

    use super::*;

    #[test]
    fn a_bad_default_filter_is_named_and_a_second_install_refused() {
        let e = init_tracing("info,[[[").unwrap_err().to_string();
        assert!(e.contains("info,[[["), "{e}");
        // The first install may succeed or find the test harness's; the second must refuse.
        let _ = init_tracing("warn");
        assert!(matches!(
            init_tracing("warn"),
            Err(TracingInitError::Install(_))
        ));
    }
}
