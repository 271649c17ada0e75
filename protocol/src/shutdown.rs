//! How the fleet's processes learn that they should stop: Ctrl-C, or SIGTERM on Unix (what
//! `kill`, systemd, container runtimes and the fleet demo send). Every binary stops the same
//! way, so each gets to finish what it must not lose (a run log, the task store).

/// A stop request listened for from [`StopSignal::install`] on, so a signal that arrives
/// before anyone waits is neither lost nor fatal (SIGTERM's default action kills at once).
#[derive(Debug)]
pub struct StopSignal {
    #[cfg(unix)]
    term: tokio::signal::unix::Signal,
}

impl StopSignal {
    /// Starts listening for SIGTERM (Ctrl-C is listened for once [`Self::wait`] runs). Needs a
    /// tokio runtime.
    ///
    /// # Errors
    /// The signal handler cannot be installed.
    pub fn install() -> std::io::Result<Self> {
        Ok(Self {
            #[cfg(unix)]
            term: tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate())?,
        })
    }

    /// Completes on Ctrl-C or SIGTERM.
    ///
    /// # Errors
    /// Ctrl-C cannot be listened for.
    pub async fn wait(self) -> std::io::Result<()> {
        #[cfg(unix)]
        {
            let mut term = self.term;
            tokio::select! {
                r = tokio::signal::ctrl_c() => r?,
                _ = term.recv() => {}
            }
        }
        #[cfg(not(unix))]
        tokio::signal::ctrl_c().await?;
        Ok(())
    }
}

/// Completes on Ctrl-C or SIGTERM; a handler that cannot be installed is logged and the
/// other one still waited for (a process that cannot be asked to stop should still run).
pub async fn stop_requested() {
    match StopSignal::install() {
        Ok(signal) => {
            if let Err(e) = signal.wait().await {
                tracing::error!("cannot listen for Ctrl-C ({e}); waiting for SIGTERM only");
                std::future::pending::<()>().await;
            }
        }
        Err(e) => {
            tracing::error!("cannot listen for SIGTERM ({e}); waiting for Ctrl-C only");
            if let Err(e) = tokio::signal::ctrl_c().await {
                tracing::error!("cannot listen for Ctrl-C either ({e})");
                std::future::pending::<()>().await;
            }
        }
    }
}

#[cfg(all(test, unix))]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    /// SIGTERM sent to this process after `install` ends `wait` instead of the process.
    #[tokio::test]
    async fn sigterm_ends_the_wait() {
        let signal = StopSignal::install().unwrap();
        let status = std::process::Command::new("kill")
            .args(["-TERM", &std::process::id().to_string()])
            .status()
            .unwrap();
        assert!(status.success());
        tokio::time::timeout(std::time::Duration::from_secs(10), signal.wait())
            .await
            .expect("SIGTERM did not end the wait")
            .unwrap();
    }
}
