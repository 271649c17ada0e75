//! When to restart a child process that exited: exponential back-off, reset after a stable run.
//!
//! `planner-service demo` supervises its robot agents with it, the way systemd's
//! `Restart=always` with `RestartSec` and a rate limit, or a ROS 2 launch file's `respawn=True`
//! with `respawn_delay`, would: a crashing agent is started again after 1 s, then 2 s, 4 s, … up
//! to a ceiling, so a child that dies at once does not spin the machine, and a child that ran
//! for a while before it died gets the short delay again. Plain data and instants in, decisions
//! out: no processes and no sleeps, so the tests drive it with made-up clocks.

use std::time::{Duration, Instant};

use serde::{Deserialize, Serialize};

/// The back-off of one supervised child (`[demo.agent_restart]`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RestartPolicy {
    /// Delay before the first restart after a stable run.
    pub initial_backoff_ms: u64,
    /// The delay doubles with each quick death up to this.
    pub max_backoff_ms: u64,
    /// A child that ran at least this long before it exited counts as stable: its next restart
    /// waits `initial_backoff_ms` again.
    pub stable_after_ms: u64,
}

impl Default for RestartPolicy {
    fn default() -> Self {
        Self {
            initial_backoff_ms: 1_000,
            max_backoff_ms: 30_000,
            stable_after_ms: 60_000,
        }
    }
}

/// A restart policy that cannot work.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum RestartPolicyError {
    #[error("invalid initial_backoff_ms = {0}: must be at least 1")]
    InitialZero(u64),
    #[error("invalid max_backoff_ms = {max}: must be at least initial_backoff_ms = {initial}")]
    MaxBelowInitial { max: u64, initial: u64 },
}

impl RestartPolicy {
    /// # Errors
    /// A zero initial delay (a crash loop at full speed) or a ceiling below it.
    pub fn validate(&self) -> Result<(), RestartPolicyError> {
        if self.initial_backoff_ms == 0 {
            return Err(RestartPolicyError::InitialZero(self.initial_backoff_ms));
        }
        if self.max_backoff_ms < self.initial_backoff_ms {
            return Err(RestartPolicyError::MaxBelowInitial {
                max: self.max_backoff_ms,
                initial: self.initial_backoff_ms,
            });
        }
        Ok(())
    }
}

/// Where a supervised child is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ChildPhase {
    /// Running since then.
    Running { since: Instant },
    /// Exited; to be started again at `at`.
    Waiting { at: Instant },
}

/// The restart bookkeeping of one child.
#[derive(Debug, Clone)]
pub struct Restarts {
    policy: RestartPolicy,
    phase: ChildPhase,
    /// The delay the next quick death gets.
    next_backoff: Duration,
    restarts: u32,
}

impl Restarts {
    /// A child started at `now`.
    #[must_use]
    pub fn new(policy: RestartPolicy, now: Instant) -> Self {
        Self {
            policy,
            phase: ChildPhase::Running { since: now },
            next_backoff: Duration::from_millis(policy.initial_backoff_ms),
            restarts: 0,
        }
    }

    #[must_use]
    pub fn phase(&self) -> ChildPhase {
        self.phase
    }

    /// Restarts so far.
    #[must_use]
    pub fn restarts(&self) -> u32 {
        self.restarts
    }

    /// The child was seen to have exited (or failed to start) at `now`: returns how long to
    /// wait before starting it again. Seen twice, the first schedule stands.
    pub fn exited(&mut self, now: Instant) -> Duration {
        let since = match self.phase {
            ChildPhase::Running { since } => since,
            ChildPhase::Waiting { at } => return at.saturating_duration_since(now),
        };
        let initial = Duration::from_millis(self.policy.initial_backoff_ms);
        let max = Duration::from_millis(self.policy.max_backoff_ms);
        if now.saturating_duration_since(since)
            >= Duration::from_millis(self.policy.stable_after_ms)
        {
            self.next_backoff = initial;
        }
        let delay = self.next_backoff.min(max);
        self.next_backoff = (delay * 2).min(max);
        self.phase = ChildPhase::Waiting { at: now + delay };
        delay
    }

    /// Whether the child is waiting and its delay has passed.
    #[must_use]
    pub fn due(&self, now: Instant) -> bool {
        matches!(self.phase, ChildPhase::Waiting { at } if now >= at)
    }

    /// The child was started again at `now`.
    pub fn started(&mut self, now: Instant) {
        self.phase = ChildPhase::Running { since: now };
        self.restarts = self.restarts.saturating_add(1);
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    fn ms(v: u64) -> Duration {
        Duration::from_millis(v)
    }

    #[test]
    fn quick_deaths_double_the_delay_up_to_the_ceiling() {
        let policy = RestartPolicy {
            initial_backoff_ms: 1_000,
            max_backoff_ms: 5_000,
            stable_after_ms: 60_000,
        };
        let t0 = Instant::now();
        let mut r = Restarts::new(policy, t0);
        let mut now = t0 + ms(100);
        let mut delays = Vec::new();
        for _ in 0..5 {
            let d = r.exited(now);
            delays.push(d.as_millis());
            assert!(!r.due(now + d - ms(1)));
            now += d;
            assert!(r.due(now));
            r.started(now);
            now += ms(200);
        }
        assert_eq!(delays, [1_000, 2_000, 4_000, 5_000, 5_000]);
        assert_eq!(r.restarts(), 5);
    }

    #[test]
    fn a_stable_run_resets_the_delay() {
        let policy = RestartPolicy::default();
        let t0 = Instant::now();
        let mut r = Restarts::new(policy, t0);
        assert_eq!(r.exited(t0 + ms(10)), ms(1_000));
        r.started(t0 + ms(1_010));
        assert_eq!(r.exited(t0 + ms(1_020)), ms(2_000));
        r.started(t0 + ms(3_020));
        // Ran for the stable time: back to the initial delay.
        assert_eq!(r.exited(t0 + ms(3_020 + 60_000)), ms(1_000));
    }

    #[test]
    fn an_exit_seen_twice_keeps_its_schedule() {
        let t0 = Instant::now();
        let mut r = Restarts::new(RestartPolicy::default(), t0);
        assert_eq!(r.exited(t0), ms(1_000));
        assert_eq!(r.exited(t0 + ms(400)), ms(600));
        assert_eq!(r.phase(), ChildPhase::Waiting { at: t0 + ms(1_000) });
        assert!(!r.due(t0 + ms(999)));
        assert!(r.due(t0 + ms(1_000)));
        assert_eq!(r.restarts(), 0);
    }

    #[test]
    fn a_policy_without_delay_is_refused() {
        let zero = RestartPolicy {
            initial_backoff_ms: 0,
            ..RestartPolicy::default()
        };
        assert!(zero
            .validate()
            .unwrap_err()
            .to_string()
            .contains("initial_backoff_ms = 0"));
        let inverted = RestartPolicy {
            initial_backoff_ms: 5_000,
            max_backoff_ms: 1_000,
            ..RestartPolicy::default()
        };
        assert!(inverted
            .validate()
            .unwrap_err()
            .to_string()
            .contains("max_backoff_ms = 1000"));
        RestartPolicy::default().validate().unwrap();
    }
}
