//! Counters and the replan-latency histogram of the fleet, rendered as Prometheus text.
//!
//! Lock-free atomics: the replanning workers record into them on the hot path.

use std::fmt::Write;
use std::sync::atomic::{AtomicI64, AtomicU64, Ordering};
use std::time::Duration;

use super::types::TaskStateKind;

/// Upper bounds (seconds) of the latency histogram buckets; the 20 ms target sits on one.
pub const LATENCY_BUCKETS_S: [f64; 12] = [
    0.001, 0.002, 0.005, 0.01, 0.015, 0.02, 0.03, 0.05, 0.1, 0.25, 0.5, 1.0,
];

/// The fleet's metrics.
#[derive(Debug, Default)]
pub struct FleetMetrics {
    replans_total: AtomicU64,
    replan_failures_total: AtomicU64,
    replans_reused_total: AtomicU64,
    intentions_total: AtomicU64,
    latency_buckets: [AtomicU64; LATENCY_BUCKETS_S.len()],
    latency_count: AtomicU64,
    latency_sum_ns: AtomicU64,
    robots_online: AtomicI64,
    robots_offline: AtomicI64,
    tasks: [AtomicI64; TaskStateKind::ALL.len()],
}

impl FleetMetrics {
    /// One replan finished (`ok` = a path was found).
    pub fn record_replan(&self, ok: bool) {
        self.replans_total.fetch_add(1, Ordering::Relaxed);
        if !ok {
            self.replan_failures_total.fetch_add(1, Ordering::Relaxed);
        }
    }

    /// One replan was answered from the robot's kept plan, without a search.
    pub fn record_reuse(&self) {
        self.replans_reused_total.fetch_add(1, Ordering::Relaxed);
    }

    #[must_use]
    pub fn replans_reused_total(&self) -> u64 {
        self.replans_reused_total.load(Ordering::Relaxed)
    }

    /// One intention left the service `latency` after the pose it answers arrived.
    pub fn record_intention(&self, latency: Duration) {
        self.intentions_total.fetch_add(1, Ordering::Relaxed);
        let s = latency.as_secs_f64();
        for (bucket, le) in self.latency_buckets.iter().zip(LATENCY_BUCKETS_S) {
            if s <= le {
                bucket.fetch_add(1, Ordering::Relaxed);
            }
        }
        self.latency_count.fetch_add(1, Ordering::Relaxed);
        let ns = u64::try_from(latency.as_nanos()).unwrap_or(u64::MAX);
        self.latency_sum_ns.fetch_add(ns, Ordering::Relaxed);
    }

    /// A task moved from `from` (None: new) to `to`.
    pub fn task_moved(&self, from: Option<TaskStateKind>, to: TaskStateKind) {
        if let Some(f) = from {
            self.tasks[f as usize].fetch_sub(1, Ordering::Relaxed);
        }
        self.tasks[to as usize].fetch_add(1, Ordering::Relaxed);
    }

    /// Counts `n` tasks in `state` that were already stored (at start).
    pub fn tasks_added(&self, state: TaskStateKind, n: usize) {
        self.tasks[state as usize]
            .fetch_add(i64::try_from(n).unwrap_or(i64::MAX), Ordering::Relaxed);
    }

    /// Takes `n` pruned tasks in `state` off the gauge.
    pub fn tasks_removed(&self, state: TaskStateKind, n: usize) {
        self.tasks[state as usize]
            .fetch_sub(i64::try_from(n).unwrap_or(i64::MAX), Ordering::Relaxed);
    }

    /// Sets the online/offline robot gauges.
    pub fn set_robots(&self, online: usize, offline: usize) {
        self.robots_online
            .store(i64::try_from(online).unwrap_or(i64::MAX), Ordering::Relaxed);
        self.robots_offline.store(
            i64::try_from(offline).unwrap_or(i64::MAX),
            Ordering::Relaxed,
        );
    }

    #[must_use]
    pub fn robots_online(&self) -> i64 {
        self.robots_online.load(Ordering::Relaxed)
    }

    #[must_use]
    pub fn tasks_in(&self, kind: TaskStateKind) -> i64 {
        self.tasks[kind as usize].load(Ordering::Relaxed)
    }

    #[must_use]
    pub fn replans_total(&self) -> u64 {
        self.replans_total.load(Ordering::Relaxed)
    }

    #[must_use]
    pub fn intentions_total(&self) -> u64 {
        self.intentions_total.load(Ordering::Relaxed)
    }

    /// Appends the metrics in the Prometheus text exposition format.
    pub fn render_prometheus(&self, out: &mut String) {
        let load = |a: &AtomicU64| a.load(Ordering::Relaxed);
        // Writing to a String cannot fail.
        let _ = writeln!(
            out,
            "# HELP fleet_replan_latency_seconds Pose received to intention published.\n\
             # TYPE fleet_replan_latency_seconds histogram"
        );
        for (bucket, le) in self.latency_buckets.iter().zip(LATENCY_BUCKETS_S) {
            let _ = writeln!(
                out,
                "fleet_replan_latency_seconds_bucket{{le=\"{le}\"}} {}",
                load(bucket)
            );
        }
        let count = load(&self.latency_count);
        #[allow(clippy::cast_precision_loss)]
        let sum_s = load(&self.latency_sum_ns) as f64 / 1e9;
        let _ = writeln!(
            out,
            "fleet_replan_latency_seconds_bucket{{le=\"+Inf\"}} {count}\n\
             fleet_replan_latency_seconds_sum {sum_s}\n\
             fleet_replan_latency_seconds_count {count}"
        );
        let _ = writeln!(
            out,
            "# HELP fleet_replans_total Replans run.\n# TYPE fleet_replans_total counter\n\
             fleet_replans_total {}\n\
             # HELP fleet_replan_failures_total Replans that found no path.\n\
             # TYPE fleet_replan_failures_total counter\nfleet_replan_failures_total {}\n\
             # HELP fleet_replans_reused_total Replans answered from the kept plan, no search.\n\
             # TYPE fleet_replans_reused_total counter\nfleet_replans_reused_total {}\n\
             # HELP fleet_intentions_total Intentions published.\n\
             # TYPE fleet_intentions_total counter\nfleet_intentions_total {}",
            load(&self.replans_total),
            load(&self.replan_failures_total),
            load(&self.replans_reused_total),
            load(&self.intentions_total)
        );
        let _ = writeln!(
            out,
            "# HELP fleet_robots Robots known to the service.\n# TYPE fleet_robots gauge\n\
             fleet_robots{{state=\"online\"}} {}\nfleet_robots{{state=\"offline\"}} {}",
            self.robots_online.load(Ordering::Relaxed),
            self.robots_offline.load(Ordering::Relaxed)
        );
        let _ = writeln!(
            out,
            "# HELP fleet_tasks Tasks by state.\n# TYPE fleet_tasks gauge"
        );
        for kind in TaskStateKind::ALL {
            let _ = writeln!(
                out,
                "fleet_tasks{{state=\"{kind}\"}} {}",
                self.tasks_in(kind)
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn histogram_is_cumulative_and_gauges_follow_moves() {
        let m = FleetMetrics::default();
        m.record_intention(Duration::from_micros(1500));
        m.record_intention(Duration::from_millis(40));
        m.task_moved(None, TaskStateKind::Queued);
        m.task_moved(Some(TaskStateKind::Queued), TaskStateKind::Active);
        let mut text = String::new();
        m.render_prometheus(&mut text);
        assert!(text.contains("fleet_replan_latency_seconds_bucket{le=\"0.001\"} 0"));
        assert!(text.contains("fleet_replan_latency_seconds_bucket{le=\"0.002\"} 1"));
        assert!(text.contains("fleet_replan_latency_seconds_bucket{le=\"0.05\"} 2"));
        assert!(text.contains("fleet_replan_latency_seconds_count 2"));
        assert!(text.contains("fleet_tasks{state=\"queued\"} 0"));
        assert!(text.contains("fleet_tasks{state=\"active\"} 1"));
    }
}
