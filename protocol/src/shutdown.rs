//! How the fleet's processes learn that they should stop: Ctrl-C, or SIGTERM on Unix (what
//! `kill`, systemd, container runtimes and the fleet demo send), or, for a process started by a
//! supervisor that asks for it ([`STOP_ON_STDIN_EOF_ENV`]), the end of its standard input.
//! Every binary stops the same way, so each gets to finish what it must not lose (a run log,
//! the task store).
//!
//! The last one is for the demo's children: a supervisor killed outright (SIGKILL, the OOM
//! killer, a crash) sends no SIGTERM, and its simulator and agents used to run on, retrying
//! its Zenoh endpoint forever, ready to join whatever listens there next with a second
//! `robot_1`. The kernel closes a dead process's pipes, so a child reading its stdin sees
//! the end of it whatever way the supervisor died.

/// The environment variable (value `1`) that makes a process stop when its standard input
/// ends: [`crate`]'s users' supervisors set it and keep a pipe to the child's stdin open for
/// as long as they want it to run.
pub const STOP_ON_STDIN_EOF_ENV: &str = "FLEET_STOP_ON_STDIN_EOF";

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

    /// Completes on Ctrl-C or SIGTERM, or at the end of stdin when [`STOP_ON_STDIN_EOF_ENV`]
    /// asks for it.
    ///
    /// # Errors
    /// Ctrl-C cannot be listened for.
    pub async fn wait(self) -> std::io::Result<()> {
        let parent_gone = async {
            if stop_on_stdin_eof() {
                stdin_closed().await;
                tracing::warn!("standard input closed: the supervising process is gone, stopping");
            } else {
                std::future::pending::<()>().await;
            }
        };
        #[cfg(unix)]
        {
            let mut term = self.term;
            tokio::select! {
                r = tokio::signal::ctrl_c() => r?,
                _ = term.recv() => {}
                () = parent_gone => {}
            }
        }
        #[cfg(not(unix))]
        tokio::select! {
            r = tokio::signal::ctrl_c() => r?,
            () = parent_gone => {}
        }
        Ok(())
    }
}

/// Whether [`STOP_ON_STDIN_EOF_ENV`] is set to `1`.
fn stop_on_stdin_eof() -> bool {
    std::env::var_os(STOP_ON_STDIN_EOF_ENV).is_some_and(|v| v == "1")
}

/// Completes when stdin ends (or cannot be read). Reads on a thread of its own: a blocking
/// read would hold a runtime worker, and whatever arrives is discarded.
async fn stdin_closed() {
    let (tx, rx) = tokio::sync::oneshot::channel();
    let spawned = std::thread::Builder::new()
        .name("stdin-watch".into())
        .spawn(move || {
            use std::io::Read as _;
            let mut stdin = std::io::stdin().lock();
            let mut buf = [0u8; 256];
            loop {
                match stdin.read(&mut buf) {
                    Ok(0) => break,
                    Ok(_) => {}
                    Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                    Err(_) => break,
                }
            }
            let _ = tx.send(());
        });
    match spawned {
        Ok(_) => {
            let _ = rx.await;
        }
        Err(e) => {
            tracing::error!("cannot watch stdin ({e}); only signals stop this process");
            std::future::pending::<()>().await;
        }
    }
}

/// Completes on Ctrl-C or SIGTERM (or the end of stdin, see [`StopSignal::wait`]); a handler that
/// cannot be installed is logged and the other one still waited for (a process that cannot be asked
/// to stop should still run).
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
