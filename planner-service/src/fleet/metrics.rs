//! Counters and the replan-latency histograms of the fleet (all of it, and per replanning
//! worker), rendered as Prometheus text.
//!
//! Lock-free atomics on the hot path; the per-worker table is behind a leaf lock taken only to
//! find a worker's entry.

use std::collections::BTreeMap;
use std::fmt::Write;
use std::sync::atomic::{AtomicI64, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use super::types::TaskStateKind;

/// Upper bounds (seconds) of the latency histogram buckets; the 20 ms target sits on one.
pub const LATENCY_BUCKETS_S: [f64; 12] = [
    0.001, 0.002, 0.005, 0.01, 0.015, 0.02, 0.03, 0.05, 0.1, 0.25, 0.5, 1.0,
];

/// Who planned a cycle in the per-worker metrics: the service process itself.
pub const SERVICE_WORKER: &str = "service";

/// A latency histogram on [`LATENCY_BUCKETS_S`], with its count and sum.
#[derive(Debug, Default)]
struct LatencyHistogram {
    buckets: [AtomicU64; LATENCY_BUCKETS_S.len()],
    count: AtomicU64,
    sum_ns: AtomicU64,
}

impl LatencyHistogram {
    fn observe(&self, latency: Duration) {
        let s = latency.as_secs_f64();
        for (bucket, le) in self.buckets.iter().zip(LATENCY_BUCKETS_S) {
            if s <= le {
                bucket.fetch_add(1, Ordering::Relaxed);
            }
        }
        self.count.fetch_add(1, Ordering::Relaxed);
        let ns = u64::try_from(latency.as_nanos()).unwrap_or(u64::MAX);
        self.sum_ns.fetch_add(ns, Ordering::Relaxed);
    }

    /// Mean of the observations in milliseconds (0 before the first).
    fn mean_ms(&self) -> f64 {
        let n = self.count.load(Ordering::Relaxed);
        #[allow(clippy::cast_precision_loss)]
        if n == 0 {
            0.0
        } else {
            self.sum_ns.load(Ordering::Relaxed) as f64 / n as f64 / 1e6
        }
    }

    /// Writes the bucket, sum and count lines of `name`; `labels` go before `le`.
    fn render(&self, out: &mut String, name: &str, labels: &str) {
        let sep = if labels.is_empty() { "" } else { "," };
        for (bucket, le) in self.buckets.iter().zip(LATENCY_BUCKETS_S) {
            let _ = writeln!(
                out,
                "{name}_bucket{{{labels}{sep}le=\"{le}\"}} {}",
                bucket.load(Ordering::Relaxed)
            );
        }
        let count = self.count.load(Ordering::Relaxed);
        #[allow(clippy::cast_precision_loss)]
        let sum_s = self.sum_ns.load(Ordering::Relaxed) as f64 / 1e9;
        let braces = if labels.is_empty() {
            String::new()
        } else {
            format!("{{{labels}}}")
        };
        let _ = writeln!(
            out,
            "{name}_bucket{{{labels}{sep}le=\"+Inf\"}} {count}\n\
             {name}_sum{braces} {sum_s}\n\
             {name}_count{braces} {count}"
        );
    }
}

/// One worker's replans and their latency.
#[derive(Debug, Default)]
pub struct WorkerStats {
    replans: AtomicU64,
    failures: AtomicU64,
    latency: LatencyHistogram,
}

impl WorkerStats {
    fn record(&self, latency: Option<Duration>, ok: Option<bool>) {
        if let Some(ok) = ok {
            self.replans.fetch_add(1, Ordering::Relaxed);
            if !ok {
                self.failures.fetch_add(1, Ordering::Relaxed);
            }
        }
        if let Some(l) = latency {
            self.latency.observe(l);
        }
    }

    #[must_use]
    pub fn replans(&self) -> u64 {
        self.replans.load(Ordering::Relaxed)
    }

    #[must_use]
    pub fn failures(&self) -> u64 {
        self.failures.load(Ordering::Relaxed)
    }

    /// Mean pose-to-intention latency of the worker's cycles (0 before the first).
    #[must_use]
    pub fn mean_latency_ms(&self) -> f64 {
        self.latency.mean_ms()
    }
}

/// The fleet's metrics.
#[derive(Debug, Default)]
pub struct FleetMetrics {
    /// Per replanning worker ([`SERVICE_WORKER`] for the service's own cycles).
    workers: Mutex<BTreeMap<String, Arc<WorkerStats>>>,
    replans_total: AtomicU64,
    replan_failures_total: AtomicU64,
    replans_reused_total: AtomicU64,
    replans_round_robots_total: AtomicU64,
    poses_superseded_total: AtomicU64,
    refresh_searches_total: AtomicU64,
    refresh_failures_total: AtomicU64,
    intentions_total: AtomicU64,
    latency: LatencyHistogram,
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

    /// One replan's path keeps clear of other robots (`[other_robots]`).
    pub fn record_round_robots(&self) {
        self.replans_round_robots_total
            .fetch_add(1, Ordering::Relaxed);
    }

    #[must_use]
    pub fn replans_reused_total(&self) -> u64 {
        self.replans_reused_total.load(Ordering::Relaxed)
    }

    /// `n` poses were replaced by a newer one before their robot's worker took them: they are
    /// never answered, because the worker was still planning an older pose.
    pub fn record_superseded(&self, n: u64) {
        self.poses_superseded_total.fetch_add(n, Ordering::Relaxed);
    }

    #[must_use]
    pub fn poses_superseded_total(&self) -> u64 {
        self.poses_superseded_total.load(Ordering::Relaxed)
    }

    /// A kept plan's due new search came back from the background (`ok`: it found a path).
    pub fn record_refresh(&self, ok: bool) {
        self.refresh_searches_total.fetch_add(1, Ordering::Relaxed);
        if !ok {
            self.refresh_failures_total.fetch_add(1, Ordering::Relaxed);
        }
    }

    #[must_use]
    pub fn refresh_searches_total(&self) -> u64 {
        self.refresh_searches_total.load(Ordering::Relaxed)
    }

    /// One intention left the service `latency` after the pose it answers arrived.
    pub fn record_intention(&self, latency: Duration) {
        self.intentions_total.fetch_add(1, Ordering::Relaxed);
        self.latency.observe(latency);
    }

    /// A cycle planned by `worker`: its intention's latency (if one went out) and whether a
    /// path was found (`None`: the robot had nothing to do).
    pub fn record_worker(&self, worker: &str, latency: Option<Duration>, ok: Option<bool>) {
        self.worker(worker).record(latency, ok);
    }

    /// The workers that have stats, sorted.
    #[must_use]
    pub fn worker_names(&self) -> Vec<String> {
        self.workers
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .keys()
            .cloned()
            .collect()
    }

    /// The stats of `worker` (made on first use).
    #[must_use]
    pub fn worker(&self, worker: &str) -> Arc<WorkerStats> {
        let mut workers = self
            .workers
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        // Every cycle comes here: allocate the name only for a worker not seen before.
        if let Some(stats) = workers.get(worker) {
            return Arc::clone(stats);
        }
        Arc::clone(workers.entry(worker.to_string()).or_default())
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
        self.latency.render(out, "fleet_replan_latency_seconds", "");
        self.render_workers(out);
        let _ = writeln!(
            out,
            "# HELP fleet_replans_total Replans run.\n# TYPE fleet_replans_total counter\n\
             fleet_replans_total {}\n\
             # HELP fleet_replan_failures_total Replans that found no path.\n\
             # TYPE fleet_replan_failures_total counter\nfleet_replan_failures_total {}\n\
             # HELP fleet_replans_reused_total Replans answered from the kept plan, no search.\n\
             # TYPE fleet_replans_reused_total counter\nfleet_replans_reused_total {}\n\
             # HELP fleet_replans_round_robots_total Replans whose path keeps clear of other \
             robots.\n\
             # TYPE fleet_replans_round_robots_total counter\nfleet_replans_round_robots_total {}\n\
             # HELP fleet_poses_superseded_total Poses replaced by a newer one before a worker \
             took them (never answered).\n\
             # TYPE fleet_poses_superseded_total counter\nfleet_poses_superseded_total {}\n\
             # HELP fleet_refresh_searches_total Kept plans' due new searches run in the \
             background.\n\
             # TYPE fleet_refresh_searches_total counter\nfleet_refresh_searches_total {}\n\
             # HELP fleet_refresh_failures_total Of those, the ones that found no path.\n\
             # TYPE fleet_refresh_failures_total counter\nfleet_refresh_failures_total {}\n\
             # HELP fleet_intentions_total Intentions published.\n\
             # TYPE fleet_intentions_total counter\nfleet_intentions_total {}",
            load(&self.replans_total),
            load(&self.replan_failures_total),
            load(&self.replans_reused_total),
            load(&self.replans_round_robots_total),
            load(&self.poses_superseded_total),
            load(&self.refresh_searches_total),
            load(&self.refresh_failures_total),
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

impl FleetMetrics {
    fn render_workers(&self, out: &mut String) {
        let workers: Vec<(String, Arc<WorkerStats>)> = self
            .workers
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .iter()
            .map(|(k, v)| (k.clone(), Arc::clone(v)))
            .collect();
        let _ = writeln!(
            out,
            "# HELP fleet_worker_replan_latency_seconds Pose received to intention published, \
             by the worker that planned it (service: the service process itself).\n\
             # TYPE fleet_worker_replan_latency_seconds histogram"
        );
        for (name, w) in &workers {
            w.latency.render(
                out,
                "fleet_worker_replan_latency_seconds",
                &format!("worker=\"{name}\""),
            );
        }
        let _ = writeln!(
            out,
            "# HELP fleet_worker_replans_total Replans run, by worker.\n\
             # TYPE fleet_worker_replans_total counter"
        );
        for (name, w) in &workers {
            let _ = writeln!(
                out,
                "fleet_worker_replans_total{{worker=\"{name}\"}} {}",
                w.replans()
            );
        }
        let _ = writeln!(
            out,
            "# HELP fleet_worker_replan_failures_total Replans that found no path, by worker.\n\
             # TYPE fleet_worker_replan_failures_total counter"
        );
        for (name, w) in &workers {
            let _ = writeln!(
                out,
                "fleet_worker_replan_failures_total{{worker=\"{name}\"}} {}",
                w.failures()
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
        m.record_superseded(1);
        m.record_refresh(true);
        m.record_refresh(false);
        let mut text = String::new();
        m.render_prometheus(&mut text);
        assert!(text.contains("fleet_poses_superseded_total 1\n"));
        assert!(text.contains("fleet_refresh_searches_total 2\n"));
        assert!(text.contains("fleet_refresh_failures_total 1\n"));
        assert!(text.contains("fleet_replan_latency_seconds_bucket{le=\"0.001\"} 0"));
        assert!(text.contains("fleet_replan_latency_seconds_bucket{le=\"0.002\"} 1"));
        assert!(text.contains("fleet_replan_latency_seconds_bucket{le=\"0.05\"} 2"));
        assert!(text.contains("fleet_replan_latency_seconds_count 2"));
        assert!(text.contains("fleet_tasks{state=\"queued\"} 0"));
        assert!(text.contains("fleet_tasks{state=\"active\"} 1"));
    }

    #[test]
    fn each_worker_has_its_own_histogram() {
        let m = FleetMetrics::default();
        m.record_worker("w1", Some(Duration::from_millis(3)), Some(true));
        m.record_worker("w1", Some(Duration::from_millis(40)), Some(false));
        m.record_worker(SERVICE_WORKER, Some(Duration::from_micros(500)), None);
        let mut text = String::new();
        m.render_prometheus(&mut text);
        assert!(text
            .contains("fleet_worker_replan_latency_seconds_bucket{worker=\"w1\",le=\"0.005\"} 1"));
        assert!(text
            .contains("fleet_worker_replan_latency_seconds_bucket{worker=\"w1\",le=\"0.05\"} 2"));
        assert!(text.contains("fleet_worker_replan_latency_seconds_count{worker=\"w1\"} 2"));
        assert!(text.contains("fleet_worker_replans_total{worker=\"w1\"} 2"));
        assert!(text.contains("fleet_worker_replan_failures_total{worker=\"w1\"} 1"));
        assert!(text.contains("fleet_worker_replans_total{worker=\"service\"} 0"));
        assert!(text.contains(
            "fleet_worker_replan_latency_seconds_bucket{worker=\"service\",le=\"0.001\"} 1"
        ));
        assert!((m.worker("w1").mean_latency_ms() - 21.5).abs() < 1e-9);
    }
}
