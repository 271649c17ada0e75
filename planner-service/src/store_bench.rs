//! The task-store benchmark (`planner-service bench-store`): what `GET /api/v1/tasks?limit=1`,
//! a default page and the live-stream snapshot cost with 1k, 100k… stored tasks, read off the
//! task index, and (baseline, same run) the full scan that `list` and the snapshot did before
//! it. Each timing is the store read plus the JSON encoding of the answer, on one thread, in
//! a fresh database in a temporary folder: most tasks finished with a four-entry history, a
//! fixed number live.

use std::time::Instant;

use protocol::{MapName, RobotId, TaskId, TaskState};
use serde::Serialize;

use crate::bench::Summary;
use crate::fleet::{Goal, HistoryEntry, Task, TaskFilter, TaskStore};

/// What to run.
#[derive(Debug, Clone)]
pub struct StoreBenchOptions {
    /// Stored tasks, one database each.
    pub sizes: Vec<usize>,
    /// Of them, tasks that have not ended (queued or active).
    pub live: usize,
    /// Timed repetitions of each indexed read.
    pub reps: usize,
    /// Timed repetitions of each full-scan read (0: no baseline).
    pub baseline_reps: usize,
}

/// The results at one size.
#[derive(Debug, Clone, Serialize)]
pub struct StoreBenchRow {
    pub stored: usize,
    pub live: usize,
    pub db_bytes: u64,
    pub load_s: f64,
    /// `list(limit=1)`, indexed.
    pub list_limit1_ms: Summary,
    /// `list()` (default limit 100) after a cursor (at most 1000 tasks deep), indexed.
    pub page100_mid_ms: Summary,
    /// The snapshot's task list: the live tasks, indexed.
    pub snapshot_ms: Summary,
    /// `list(limit=1)` by full scan (before the index).
    pub baseline_list_limit1_ms: Option<Summary>,
    /// The snapshot before: the newest 100 tasks of any state, by full scan.
    pub baseline_snapshot_ms: Option<Summary>,
    /// One retention sweep pruning the oldest tenth of the finished tasks (export included).
    pub sweep_pruned: usize,
    pub sweep_ms: f64,
}

/// The results (JSON) of one run.
#[derive(Debug, Clone, Serialize)]
pub struct StoreBenchReport {
    pub reps: usize,
    pub baseline_reps: usize,
    pub rows: Vec<StoreBenchRow>,
}

const ROBOTS: usize = 10;
const BATCH: usize = 10_000;

fn synthetic(i: usize, live: bool) -> anyhow::Result<Task> {
    let id = TaskId::new(format!("t-{:06}", i + 1))?;
    let robot = RobotId::new(format!("robot_{}", i % ROBOTS))?;
    let map = MapName::new(if i.is_multiple_of(2) { "depot" } else { "yard" })?;
    let t0 = 1_700_000_000_000_000_000 + u64::try_from(i)? * 1_000_000_000;
    let states = if live {
        vec![TaskState::Queued]
    } else {
        vec![
            TaskState::Queued,
            TaskState::Assigned {
                robot_id: robot.clone(),
            },
            TaskState::Active {
                robot_id: robot.clone(),
                goal_index: 0,
            },
            TaskState::Completed,
        ]
    };
    let history: Vec<HistoryEntry> = states
        .iter()
        .enumerate()
        .map(|(k, s)| HistoryEntry {
            stamp_ns: t0 + u64::try_from(k).unwrap_or(0) * 1_000_000,
            state: s.clone(),
        })
        .collect();
    Ok(Task {
        id,
        map,
        map_version: 1,
        robot_id: (!live).then_some(robot),
        goals: vec![
            Goal {
                x_m: 3.0,
                y_m: 4.0,
                yaw_rad: None,
            },
            Goal {
                x_m: 13.0,
                y_m: 10.0,
                yaw_rad: Some(1.57),
            },
        ],
        state: states[states.len() - 1].clone(),
        created_ns: t0,
        updated_ns: history[history.len() - 1].stamp_ns,
        history,
    })
}

fn time(reps: usize, mut f: impl FnMut() -> anyhow::Result<usize>) -> anyhow::Result<Summary> {
    let mut ms = Vec::with_capacity(reps);
    let mut sink = 0;
    for _ in 0..reps {
        let start = Instant::now();
        sink += f()?;
        ms.push(start.elapsed().as_secs_f64() * 1e3);
    }
    std::hint::black_box(sink);
    Ok(Summary::of(&ms))
}

fn json_len(tasks: &[Task]) -> anyhow::Result<usize> {
    Ok(serde_json::to_vec(tasks)?.len())
}

/// Runs every size in turn.
///
/// # Errors
/// A storage or temporary-folder failure.
pub fn run_store_bench(
    opts: &StoreBenchOptions,
    progress: &mut dyn FnMut(&str),
) -> anyhow::Result<StoreBenchReport> {
    let mut rows = Vec::new();
    for &stored in &opts.sizes {
        let dir = tempfile::tempdir()?;
        let store = TaskStore::open(dir.path())?;
        let live = opts.live.min(stored);
        // Live tasks spread over the history: every (stored / live)-th task.
        let every = stored.checked_div(live).unwrap_or(usize::MAX).max(1);
        progress(&format!("loading {stored} tasks"));
        let start = Instant::now();
        let mut batch = Vec::with_capacity(BATCH);
        let mut made_live = 0;
        for i in 0..stored {
            let is_live = made_live < live && i % every == every - 1;
            made_live += usize::from(is_live);
            batch.push(synthetic(i, is_live)?);
            if batch.len() == BATCH {
                store.insert_many(&batch)?;
                batch.clear();
            }
        }
        store.insert_many(&batch)?;
        let load_s = start.elapsed().as_secs_f64();
        progress(&format!("timing {stored} tasks"));
        let one = TaskFilter {
            limit: Some(1),
            ..TaskFilter::default()
        };
        let middle = store
            .list_page(&TaskFilter {
                limit: Some((stored / 2).clamp(1, TaskFilter::MAX_LIMIT)),
                ..TaskFilter::default()
            })?
            .tasks
            .last()
            .map(crate::fleet::Cursor::after);
        let mid_page = TaskFilter {
            cursor: middle,
            ..TaskFilter::default()
        };
        let list_limit1_ms = time(opts.reps, || json_len(&store.list(&one)?))?;
        let page100_mid_ms = time(opts.reps, || json_len(&store.list(&mid_page)?))?;
        let snapshot_ms = time(opts.reps, || {
            json_len(&store.live(crate::http::events::SNAPSHOT_TASKS)?)
        })?;
        let (baseline_list_limit1_ms, baseline_snapshot_ms) = if opts.baseline_reps > 0 {
            (
                Some(time(opts.baseline_reps, || {
                    json_len(&store.list_by_scan(&one)?)
                })?),
                Some(time(opts.baseline_reps, || {
                    json_len(&store.list_by_scan(&TaskFilter::default())?)
                })?),
            )
        } else {
            (None, None)
        };
        let db_bytes = std::fs::metadata(store.path())?.len();
        let finished = stored - live;
        let start = Instant::now();
        let swept = store.sweep(
            &crate::fleet::Retention {
                max_age_ns: None,
                max_count: Some(finished - finished / 10),
            },
            0,
        )?;
        let sweep_ms = start.elapsed().as_secs_f64() * 1e3;
        rows.push(StoreBenchRow {
            stored,
            live,
            db_bytes,
            load_s,
            list_limit1_ms,
            page100_mid_ms,
            snapshot_ms,
            baseline_list_limit1_ms,
            baseline_snapshot_ms,
            sweep_pruned: swept.pruned,
            sweep_ms,
        });
    }
    Ok(StoreBenchReport {
        reps: opts.reps,
        baseline_reps: opts.baseline_reps,
        rows,
    })
}

/// The results as a markdown table (p50 and p99 per read, ms).
#[must_use]
pub fn markdown(r: &StoreBenchReport) -> String {
    let cell = |s: &Summary| format!("{:.3} / {:.3}", s.p50, s.p99);
    let opt = |s: &Option<Summary>| s.as_ref().map_or_else(|| "-".to_string(), cell);
    let mut out = String::from(
        "| stored tasks | live | db size | list limit=1 | page of 100 after a cursor | snapshot (live tasks) | before: list limit=1 (full scan) | before: snapshot (full scan) | sweep (oldest tenth) |\n\
         |---|---|---|---|---|---|---|---|---|\n",
    );
    for row in &r.rows {
        #[allow(clippy::cast_precision_loss)]
        let mib = row.db_bytes as f64 / (1024.0 * 1024.0);
        out.push_str(&format!(
            "| {} | {} | {mib:.1} MiB | {} | {} | {} | {} | {} | {} in {:.0} ms |\n",
            row.stored,
            row.live,
            cell(&row.list_limit1_ms),
            cell(&row.page100_mid_ms),
            cell(&row.snapshot_ms),
            opt(&row.baseline_list_limit1_ms),
            opt(&row.baseline_snapshot_ms),
            row.sweep_pruned,
            row.sweep_ms,
        ));
    }
    out.push_str(&format!(
        "\nms, p50 / p99 of {} runs ({} for the full scans), one thread, store read + JSON encoding.\n",
        r.reps, r.baseline_reps
    ));
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_small_run_reports_every_size() {
        let opts = StoreBenchOptions {
            sizes: vec![10, 50],
            live: 5,
            reps: 3,
            baseline_reps: 1,
        };
        let report = run_store_bench(&opts, &mut |_| {}).unwrap();
        assert_eq!(report.rows.len(), 2);
        assert_eq!(report.rows[1].live, 5);
        assert!(report.rows[1].baseline_snapshot_ms.is_some());
        assert!(markdown(&report).contains("| 50 | 5 |"));
        assert_eq!(report.rows[1].sweep_pruned, 4);
    }
}
