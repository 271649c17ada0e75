//! Durable task storage: one redb file (`<data-dir>/tasks.redb`), one JSON record per task with
//! its whole history. Every change is a single write transaction, so a crash leaves either the
//! old or the new state of a task, never a torn one, and a restart sees every acknowledged change.
//!
//! Listing cost does not grow with history: an index table, written in the same transaction as
//! the task, orders tasks newest first within each scope (all tasks, one state, one robot, one
//! map), so a page of `limit` tasks is about `limit` lookups. Index keys are bytes:
//! `scope ‖ created_ns (big-endian) ‖ task id`, with `scope` = `a` (all), `s<state>`,
//! `r<len><robot>` or `m<len><map>`. A database written before the index existed gets it
//! built once when opened.
//!
//! Finished tasks are pruned by [`TaskStore::sweep`] under a [`Retention`] policy, appended
//! first (and synced) to `<data-dir>/tasks-export.jsonl`, one task with its history a line.

use std::io::Write;
use std::path::{Path, PathBuf};

use protocol::{MapName, RobotId, TaskId, TaskState};
use redb::{Database, ReadableTable, ReadableTableMetadata, Table, TableDefinition};

use super::types::{Cursor, Goal, HistoryEntry, Task, TaskFilter, TaskPage, TaskStateKind};

const TASKS: TableDefinition<&str, &[u8]> = TableDefinition::new("tasks");
const COUNTERS: TableDefinition<&str, u64> = TableDefinition::new("counters");
const INDEX: TableDefinition<&[u8], ()> = TableDefinition::new("task_index");
const NEXT_TASK: &str = "next_task";
/// The counter that says which index layout the database has (absent: none yet).
const INDEX_VERSION: &str = "index_version";
const INDEX_LAYOUT: u64 = 1;
const DB_FILE: &str = "tasks.redb";
/// Where pruned tasks go (JSON lines) before they are deleted.
pub const EXPORT_FILE: &str = "tasks-export.jsonl";
/// Tasks pruned per write transaction (and per export sync).
const SWEEP_BATCH: usize = 5000;
const LIVE: [TaskStateKind; 4] = [
    TaskStateKind::Queued,
    TaskStateKind::Assigned,
    TaskStateKind::Active,
    TaskStateKind::Paused,
];
const FINISHED: [TaskStateKind; 3] = [
    TaskStateKind::Completed,
    TaskStateKind::Failed,
    TaskStateKind::Cancelled,
];

/// A storage failure; the change it was part of did not happen.
#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    #[error("task database {action}: {reason}")]
    Db {
        action: &'static str,
        reason: String,
    },
    #[error("task record {id} is corrupt: {reason}")]
    Corrupt { id: String, reason: String },
    #[error("no task {0}")]
    NotFound(TaskId),
    #[error("task export {path}: {reason}")]
    Export { path: String, reason: String },
}

/// How long finished (completed, failed, cancelled) tasks are kept. `None` is no bound.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Retention {
    /// Finished tasks that ended longer ago than this are pruned.
    pub max_age_ns: Option<u64>,
    /// At most this many finished tasks are kept (the newest by creation).
    pub max_count: Option<usize>,
}

/// What a sweep pruned.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct SweepReport {
    /// Tasks exported and deleted.
    pub pruned: usize,
    /// Of them, per state ([`TaskStateKind`] as index).
    pub pruned_by_state: [usize; 7],
}

/// The task database.
#[derive(Debug)]
pub struct TaskStore {
    db: Database,
    path: PathBuf,
}

type IndexTable<'t> = Table<'t, &'static [u8], ()>;
type TaskTable<'t> = Table<'t, &'static str, &'static [u8]>;

impl TaskStore {
    /// Opens (creating if needed) `tasks.redb` in `data_dir`; builds the task index if the
    /// database has none yet.
    ///
    /// # Errors
    /// [`StoreError::Db`] if the folder or database cannot be created or opened.
    pub fn open(data_dir: &Path) -> Result<Self, StoreError> {
        std::fs::create_dir_all(data_dir).map_err(|e| StoreError::Db {
            action: "create folder",
            reason: format!("{}: {e}", data_dir.display()),
        })?;
        let path = data_dir.join(DB_FILE);
        let db = Database::create(&path).map_err(|e| StoreError::Db {
            action: "open",
            reason: format!("{}: {e}", path.display()),
        })?;
        let txn = db.begin_write().map_err(|e| db_err("begin", e))?;
        {
            let tasks = txn.open_table(TASKS).map_err(|e| db_err("open table", e))?;
            let mut counters = txn
                .open_table(COUNTERS)
                .map_err(|e| db_err("open table", e))?;
            let layout = counters
                .get(INDEX_VERSION)
                .map_err(|e| db_err("read", e))?
                .map(|v| v.value());
            if layout != Some(INDEX_LAYOUT) {
                txn.delete_table(INDEX)
                    .map_err(|e| db_err("delete table", e))?;
                let mut index = txn.open_table(INDEX).map_err(|e| db_err("open table", e))?;
                let mut count = 0_u64;
                for entry in tasks.iter().map_err(|e| db_err("iterate", e))? {
                    let (k, v) = entry.map_err(|e| db_err("iterate", e))?;
                    let task = decode(k.value(), v.value())?;
                    for key in index_keys(&task) {
                        index
                            .insert(key.as_slice(), ())
                            .map_err(|e| db_err("write", e))?;
                    }
                    count += 1;
                }
                counters
                    .insert(INDEX_VERSION, INDEX_LAYOUT)
                    .map_err(|e| db_err("write", e))?;
                if count > 0 {
                    tracing::info!(tasks = count, "task index built");
                }
            } else {
                txn.open_table(INDEX).map_err(|e| db_err("open table", e))?;
            }
        }
        txn.commit().map_err(|e| db_err("commit", e))?;
        Ok(Self { db, path })
    }

    #[must_use]
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The JSON-lines file pruned tasks are appended to, next to the database.
    #[must_use]
    pub fn export_path(&self) -> PathBuf {
        self.path.with_file_name(EXPORT_FILE)
    }

    /// Stores a new task in `state` and returns it with its new id (`t-000001`, …).
    ///
    /// # Errors
    /// [`StoreError::Db`]; then nothing was stored.
    pub fn create(
        &self,
        map: &MapName,
        map_version: u32,
        robot_id: Option<RobotId>,
        goals: Vec<Goal>,
        state: TaskState,
        now_ns: u64,
    ) -> Result<Task, StoreError> {
        let txn = self.db.begin_write().map_err(|e| db_err("begin", e))?;
        let task = {
            let mut counters = txn
                .open_table(COUNTERS)
                .map_err(|e| db_err("open table", e))?;
            let seq = counters
                .get(NEXT_TASK)
                .map_err(|e| db_err("read", e))?
                .map_or(1, |v| v.value());
            counters
                .insert(NEXT_TASK, seq + 1)
                .map_err(|e| db_err("write", e))?;
            let id = TaskId::new(format!("t-{seq:06}")).map_err(|e| StoreError::Corrupt {
                id: seq.to_string(),
                reason: e.to_string(),
            })?;
            let task = Task {
                id,
                map: map.clone(),
                map_version,
                robot_id,
                goals,
                state: state.clone(),
                created_ns: now_ns,
                updated_ns: now_ns,
                history: vec![HistoryEntry {
                    stamp_ns: now_ns,
                    state,
                }],
            };
            let mut tasks = txn.open_table(TASKS).map_err(|e| db_err("open table", e))?;
            let mut index = txn.open_table(INDEX).map_err(|e| db_err("open table", e))?;
            write_task(&mut tasks, &mut index, None, &task)?;
            task
        };
        txn.commit().map_err(|e| db_err("commit", e))?;
        Ok(task)
    }

    /// Stores whole tasks as they are, in one transaction (bulk loads: benchmarks, imports).
    /// A task with the id of a stored one replaces it. The id counter is not moved.
    ///
    /// # Errors
    /// [`StoreError::Db`]; then nothing was stored.
    pub fn insert_many(&self, batch: &[Task]) -> Result<(), StoreError> {
        let txn = self.db.begin_write().map_err(|e| db_err("begin", e))?;
        {
            let mut tasks = txn.open_table(TASKS).map_err(|e| db_err("open table", e))?;
            let mut index = txn.open_table(INDEX).map_err(|e| db_err("open table", e))?;
            for task in batch {
                let old = match tasks.get(task.id.as_str()).map_err(|e| db_err("read", e))? {
                    Some(v) => Some(decode(task.id.as_str(), v.value())?),
                    None => None,
                };
                write_task(&mut tasks, &mut index, old.as_ref(), task)?;
            }
        }
        txn.commit().map_err(|e| db_err("commit", e))
    }

    /// The task `id`, if stored.
    ///
    /// # Errors
    /// [`StoreError::Db`] or [`StoreError::Corrupt`].
    pub fn get(&self, id: &TaskId) -> Result<Option<Task>, StoreError> {
        let txn = self.db.begin_read().map_err(|e| db_err("begin", e))?;
        let tasks = txn.open_table(TASKS).map_err(|e| db_err("open table", e))?;
        let found = tasks.get(id.as_str()).map_err(|e| db_err("read", e))?;
        found.map(|v| decode(id.as_str(), v.value())).transpose()
    }

    /// Tasks matching `filter`, newest first, at most `filter.limit()`.
    ///
    /// # Errors
    /// [`StoreError::Db`] or [`StoreError::Corrupt`].
    pub fn list(&self, filter: &TaskFilter) -> Result<Vec<Task>, StoreError> {
        Ok(self.list_page(filter)?.tasks)
    }

    /// One page of the tasks matching `filter`, newest first, after `filter.cursor`.
    ///
    /// Walks one index scope (the robot's when the filter names one, else the map's, else the
    /// state's, else all tasks) newest first and checks the rest of the filter on each task, so
    /// a page costs about `limit` lookups when the scope's tasks match.
    ///
    /// # Errors
    /// [`StoreError::Db`] or [`StoreError::Corrupt`].
    pub fn list_page(&self, filter: &TaskFilter) -> Result<TaskPage, StoreError> {
        let scope = if let Some(r) = &filter.robot_id {
            Scope::Robot(r.as_str())
        } else if let Some(m) = &filter.map {
            Scope::Map(m.as_str())
        } else if let Some(s) = filter.state {
            Scope::State(s)
        } else {
            Scope::All
        };
        let prefix = scope.prefix();
        let upper = match &filter.cursor {
            Some(c) => index_key(&prefix, c.created_ns, c.id.as_str()),
            None => scope_end(&prefix),
        };
        let limit = filter.limit();
        let txn = self.db.begin_read().map_err(|e| db_err("begin", e))?;
        let tasks = txn.open_table(TASKS).map_err(|e| db_err("open table", e))?;
        let index = txn.open_table(INDEX).map_err(|e| db_err("open table", e))?;
        let mut out = Vec::new();
        let mut more = false;
        let range = index
            .range::<&[u8]>(prefix.as_slice()..upper.as_slice())
            .map_err(|e| db_err("iterate", e))?;
        for entry in range.rev() {
            let (k, _) = entry.map_err(|e| db_err("iterate", e))?;
            let (_, id) = split_key(k.value(), prefix.len())?;
            let Some(v) = tasks.get(id).map_err(|e| db_err("read", e))? else {
                continue;
            };
            let task = decode(id, v.value())?;
            if !filter.matches(&task) {
                continue;
            }
            if out.len() == limit {
                more = true;
                break;
            }
            out.push(task);
        }
        let next_cursor = if more {
            out.last().map(Cursor::after)
        } else {
            None
        };
        Ok(TaskPage {
            tasks: out,
            next_cursor,
        })
    }

    /// The same answer as [`TaskStore::list`] by decoding every stored task, as `list` did
    /// before the index: the baseline of `planner-service bench-store`.
    ///
    /// # Errors
    /// [`StoreError::Db`] or [`StoreError::Corrupt`].
    #[doc(hidden)]
    pub fn list_by_scan(&self, filter: &TaskFilter) -> Result<Vec<Task>, StoreError> {
        let mut out = self.scan(|t| filter.matches(t))?;
        out.sort_by(|a, b| b.created_ns.cmp(&a.created_ns).then(b.id.cmp(&a.id)));
        out.truncate(filter.limit());
        Ok(out)
    }

    /// The newest `limit` tasks that have not ended, newest first (the live stream's
    /// snapshot): read off the state index, whatever the number of finished tasks.
    ///
    /// # Errors
    /// [`StoreError::Db`] or [`StoreError::Corrupt`].
    pub fn live(&self, limit: usize) -> Result<Vec<Task>, StoreError> {
        let txn = self.db.begin_read().map_err(|e| db_err("begin", e))?;
        let index = txn.open_table(INDEX).map_err(|e| db_err("open table", e))?;
        let mut keys = Vec::new();
        for state in LIVE {
            let prefix = Scope::State(state).prefix();
            let range = index
                .range::<&[u8]>(prefix.as_slice()..scope_end(&prefix).as_slice())
                .map_err(|e| db_err("iterate", e))?;
            for entry in range.rev().take(limit) {
                let (k, _) = entry.map_err(|e| db_err("iterate", e))?;
                let (ns, id) = split_key(k.value(), prefix.len())?;
                keys.push((ns, id.to_string()));
            }
        }
        keys.sort_unstable_by(|a, b| b.cmp(a));
        keys.truncate(limit);
        let tasks = txn.open_table(TASKS).map_err(|e| db_err("open table", e))?;
        fetch(&tasks, keys.iter().map(|(_, id)| id.as_str()))
    }

    /// Every task that has not ended, oldest first (what a restart resumes).
    ///
    /// # Errors
    /// [`StoreError::Db`] or [`StoreError::Corrupt`].
    pub fn unfinished(&self) -> Result<Vec<Task>, StoreError> {
        let mut out = self.live(usize::MAX)?;
        out.reverse();
        Ok(out)
    }

    /// How many tasks are stored in each state ([`TaskStateKind`] as index), read off the index
    /// without decoding a task.
    ///
    /// # Errors
    /// [`StoreError::Db`].
    pub fn count_by_state(&self) -> Result<[usize; 7], StoreError> {
        let txn = self.db.begin_read().map_err(|e| db_err("begin", e))?;
        let index = txn.open_table(INDEX).map_err(|e| db_err("open table", e))?;
        let mut counts = [0; 7];
        for state in TaskStateKind::ALL {
            let prefix = Scope::State(state).prefix();
            let range = index
                .range::<&[u8]>(prefix.as_slice()..scope_end(&prefix).as_slice())
                .map_err(|e| db_err("iterate", e))?;
            counts[state as usize] = range.count();
        }
        Ok(counts)
    }

    /// How many tasks are stored.
    ///
    /// # Errors
    /// [`StoreError::Db`].
    pub fn count(&self) -> Result<u64, StoreError> {
        let txn = self.db.begin_read().map_err(|e| db_err("begin", e))?;
        let tasks = txn.open_table(TASKS).map_err(|e| db_err("open table", e))?;
        tasks.len().map_err(|e| db_err("read", e))
    }

    /// Every task (tests, tools: this decodes the whole database).
    ///
    /// # Errors
    /// [`StoreError::Db`] or [`StoreError::Corrupt`].
    pub fn all(&self) -> Result<Vec<Task>, StoreError> {
        self.scan(|_| true)
    }

    fn scan(&self, keep: impl Fn(&Task) -> bool) -> Result<Vec<Task>, StoreError> {
        let txn = self.db.begin_read().map_err(|e| db_err("begin", e))?;
        let tasks = txn.open_table(TASKS).map_err(|e| db_err("open table", e))?;
        let mut out = Vec::new();
        for entry in tasks.iter().map_err(|e| db_err("iterate", e))? {
            let (k, v) = entry.map_err(|e| db_err("iterate", e))?;
            let task = decode(k.value(), v.value())?;
            if keep(&task) {
                out.push(task);
            }
        }
        Ok(out)
    }

    /// Reads task `id`, lets `change` modify it, and writes it back in one transaction.
    /// `change` returning `Err` aborts with nothing written; `Ok(false)` means "no change".
    ///
    /// # Errors
    /// [`StoreError::NotFound`], [`StoreError::Db`], or the error of `change`.
    pub fn update<E: From<StoreError>>(
        &self,
        id: &TaskId,
        change: impl FnOnce(&mut Task) -> Result<bool, E>,
    ) -> Result<(Task, bool), E> {
        let txn = self.db.begin_write().map_err(|e| db_err("begin", e))?;
        let (task, changed) = {
            let mut tasks = txn.open_table(TASKS).map_err(|e| db_err("open table", e))?;
            let old = match tasks.get(id.as_str()).map_err(|e| db_err("read", e))? {
                Some(v) => decode(id.as_str(), v.value())?,
                None => return Err(StoreError::NotFound(id.clone()).into()),
            };
            let mut task = old.clone();
            let changed = change(&mut task)?;
            if changed {
                let mut index = txn.open_table(INDEX).map_err(|e| db_err("open table", e))?;
                write_task(&mut tasks, &mut index, Some(&old), &task)?;
            }
            (task, changed)
        };
        if changed {
            txn.commit().map_err(|e| db_err("commit", e))?;
        } else {
            txn.abort().map_err(|e| db_err("abort", e))?;
        }
        Ok((task, changed))
    }

    /// Writes `task` over its stored record in one transaction.
    ///
    /// # Errors
    /// [`StoreError::NotFound`] when no task has its id (nothing is written then),
    /// [`StoreError::Db`].
    pub fn replace(&self, task: &Task) -> Result<(), StoreError> {
        self.update::<StoreError>(&task.id, |stored| {
            stored.clone_from(task);
            Ok(true)
        })
        .map(|_| ())
    }

    /// Prunes the finished tasks that `retention` no longer keeps: the oldest (by creation)
    /// beyond `max_count`, and those that ended more than `max_age_ns` before `now_ns`. Each
    /// batch is appended to [`TaskStore::export_path`] and synced before it is deleted (task
    /// and index entries, one transaction), so a crash in between exports a task twice, never
    /// loses one. Tasks that have not ended are never touched.
    ///
    /// # Errors
    /// [`StoreError::Export`] (then nothing more was deleted), [`StoreError::Db`],
    /// [`StoreError::Corrupt`].
    pub fn sweep(&self, retention: &Retention, now_ns: u64) -> Result<SweepReport, StoreError> {
        let mut report = SweepReport::default();
        if retention.max_age_ns.is_none() && retention.max_count.is_none() {
            return Ok(report);
        }
        // The finished tasks, oldest first, from the index alone.
        let mut finished: Vec<(u64, String)> = Vec::new();
        {
            let txn = self.db.begin_read().map_err(|e| db_err("begin", e))?;
            let index = txn.open_table(INDEX).map_err(|e| db_err("open table", e))?;
            for state in FINISHED {
                let prefix = Scope::State(state).prefix();
                let range = index
                    .range::<&[u8]>(prefix.as_slice()..scope_end(&prefix).as_slice())
                    .map_err(|e| db_err("iterate", e))?;
                for entry in range {
                    let (k, _) = entry.map_err(|e| db_err("iterate", e))?;
                    let (ns, id) = split_key(k.value(), prefix.len())?;
                    finished.push((ns, id.to_string()));
                }
            }
        }
        finished.sort_unstable();
        let excess = retention
            .max_count
            .map_or(0, |max| finished.len().saturating_sub(max));
        let cutoff = retention.max_age_ns.map(|age| now_ns.saturating_sub(age));
        // Oldest first, both bounds reach a prefix: the count one by position, the age one by
        // creation (a task created after the cutoff cannot have ended before it).
        let mut candidates = finished
            .into_iter()
            .enumerate()
            .take_while(|(i, (created_ns, _))| {
                *i < excess || cutoff.is_some_and(|c| *created_ns < c)
            })
            .map(|(i, (_, id))| (i < excess, id));
        loop {
            let mut batch = Vec::new();
            {
                let txn = self.db.begin_read().map_err(|e| db_err("begin", e))?;
                let tasks = txn.open_table(TASKS).map_err(|e| db_err("open table", e))?;
                while batch.len() < SWEEP_BATCH {
                    let Some((over_count, id)) = candidates.next() else {
                        break;
                    };
                    let Some(v) = tasks.get(id.as_str()).map_err(|e| db_err("read", e))? else {
                        continue;
                    };
                    let task = decode(&id, v.value())?;
                    let too_old = cutoff.is_some_and(|c| task.updated_ns < c);
                    if task.state.is_terminal() && (over_count || too_old) {
                        batch.push(task);
                    }
                }
            }
            if batch.is_empty() {
                return Ok(report);
            }
            self.export(&batch)?;
            let txn = self.db.begin_write().map_err(|e| db_err("begin", e))?;
            {
                let mut tasks = txn.open_table(TASKS).map_err(|e| db_err("open table", e))?;
                let mut index = txn.open_table(INDEX).map_err(|e| db_err("open table", e))?;
                for task in &batch {
                    tasks
                        .remove(task.id.as_str())
                        .map_err(|e| db_err("delete", e))?;
                    for key in index_keys(task) {
                        index
                            .remove(key.as_slice())
                            .map_err(|e| db_err("delete", e))?;
                    }
                    report.pruned += 1;
                    report.pruned_by_state[task.kind() as usize] += 1;
                }
            }
            txn.commit().map_err(|e| db_err("commit", e))?;
        }
    }

    /// Appends `batch` to the export file, one JSON task a line, and syncs it.
    fn export(&self, batch: &[Task]) -> Result<(), StoreError> {
        let path = self.export_path();
        let fail = |e: &dyn std::fmt::Display| StoreError::Export {
            path: path.display().to_string(),
            reason: e.to_string(),
        };
        let mut text = Vec::new();
        for task in batch {
            serde_json::to_writer(&mut text, task).map_err(|e| fail(&e))?;
            text.push(b'\n');
        }
        let mut file = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(&path)
            .map_err(|e| fail(&e))?;
        file.write_all(&text).map_err(|e| fail(&e))?;
        file.sync_all().map_err(|e| fail(&e))
    }
}

/// One ordered range of the index.
#[derive(Debug, Clone, Copy)]
enum Scope<'a> {
    All,
    State(TaskStateKind),
    Robot(&'a str),
    Map(&'a str),
}

impl Scope<'_> {
    fn prefix(self) -> Vec<u8> {
        let named = |tag: u8, name: &str| {
            // Ids are at most 64 bytes (protocol::ids), so the length fits a byte.
            let len = u8::try_from(name.len()).unwrap_or(u8::MAX);
            let mut p = vec![tag, len];
            p.extend_from_slice(name.as_bytes());
            p
        };
        match self {
            Scope::All => vec![b'a'],
            Scope::State(s) => vec![b's', s as u8],
            Scope::Robot(r) => named(b'r', r),
            Scope::Map(m) => named(b'm', m),
        }
    }
}

/// Past every key of the scope `prefix`: ids are ASCII, so no id starts with `0xff`.
fn scope_end(prefix: &[u8]) -> Vec<u8> {
    let mut end = prefix.to_vec();
    end.extend_from_slice(&[0xff; 9]);
    end
}

fn index_key(prefix: &[u8], created_ns: u64, id: &str) -> Vec<u8> {
    let mut key = Vec::with_capacity(prefix.len() + 8 + id.len());
    key.extend_from_slice(prefix);
    key.extend_from_slice(&created_ns.to_be_bytes());
    key.extend_from_slice(id.as_bytes());
    key
}

/// The creation time and id in an index key of a scope whose prefix is `prefix_len` long.
fn split_key(key: &[u8], prefix_len: usize) -> Result<(u64, &str), StoreError> {
    let corrupt = || StoreError::Corrupt {
        id: hex::encode(key),
        reason: "bad index key".into(),
    };
    let rest = key.get(prefix_len..).ok_or_else(corrupt)?;
    let (time, id) = rest.split_at_checked(8).ok_or_else(corrupt)?;
    let ns = u64::from_be_bytes(time.try_into().map_err(|_| corrupt())?);
    Ok((ns, std::str::from_utf8(id).map_err(|_| corrupt())?))
}

/// The index keys of `task`: all tasks, its state, its map and its robot (if any).
fn index_keys(task: &Task) -> Vec<Vec<u8>> {
    let id = task.id.as_str();
    let mut keys = vec![
        index_key(&Scope::All.prefix(), task.created_ns, id),
        index_key(&Scope::State(task.kind()).prefix(), task.created_ns, id),
        index_key(&Scope::Map(task.map.as_str()).prefix(), task.created_ns, id),
    ];
    if let Some(r) = &task.robot_id {
        keys.push(index_key(
            &Scope::Robot(r.as_str()).prefix(),
            task.created_ns,
            id,
        ));
    }
    keys
}

/// Writes `task` (over `old`, when it was stored) and moves its index entries.
fn write_task(
    tasks: &mut TaskTable<'_>,
    index: &mut IndexTable<'_>,
    old: Option<&Task>,
    task: &Task,
) -> Result<(), StoreError> {
    tasks
        .insert(task.id.as_str(), encode(task)?.as_slice())
        .map_err(|e| db_err("write", e))?;
    let new_keys = index_keys(task);
    if let Some(old) = old {
        for key in index_keys(old) {
            if !new_keys.contains(&key) {
                index
                    .remove(key.as_slice())
                    .map_err(|e| db_err("write", e))?;
            }
        }
    }
    for key in &new_keys {
        index
            .insert(key.as_slice(), ())
            .map_err(|e| db_err("write", e))?;
    }
    Ok(())
}

/// The tasks `ids`, in that order (an id no longer stored is skipped).
fn fetch<'a>(
    tasks: &impl ReadableTable<&'static str, &'static [u8]>,
    ids: impl Iterator<Item = &'a str>,
) -> Result<Vec<Task>, StoreError> {
    let mut out = Vec::new();
    for id in ids {
        if let Some(v) = tasks.get(id).map_err(|e| db_err("read", e))? {
            out.push(decode(id, v.value())?);
        }
    }
    Ok(out)
}

fn db_err(action: &'static str, e: impl Into<redb::Error>) -> StoreError {
    StoreError::Db {
        action,
        reason: e.into().to_string(),
    }
}

fn encode(task: &Task) -> Result<Vec<u8>, StoreError> {
    serde_json::to_vec(task).map_err(|e| StoreError::Corrupt {
        id: task.id.to_string(),
        reason: e.to_string(),
    })
}

fn decode(id: &str, bytes: &[u8]) -> Result<Task, StoreError> {
    serde_json::from_slice(bytes).map_err(|e| StoreError::Corrupt {
        id: id.to_string(),
        reason: e.to_string(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn goal(x: f64) -> Goal {
        Goal {
            x_m: x,
            y_m: 1.0,
            yaw_rad: None,
        }
    }

    #[test]
    fn tasks_survive_reopen_with_history_and_ids_keep_counting() {
        let dir = tempfile::tempdir().unwrap();
        let map = MapName::new("depot").unwrap();
        let robot = RobotId::new("robot_1").unwrap();
        let first = {
            let store = TaskStore::open(dir.path()).unwrap();
            let t = store
                .create(&map, 1, None, vec![goal(1.0)], TaskState::Queued, 10)
                .unwrap();
            assert_eq!(t.id.as_str(), "t-000001");
            let (t, changed) = store
                .update::<StoreError>(&t.id, |t| {
                    t.set_state(
                        TaskState::Active {
                            robot_id: robot.clone(),
                            goal_index: 0,
                        },
                        20,
                    );
                    Ok(true)
                })
                .unwrap();
            assert!(changed);
            t
        };
        let store = TaskStore::open(dir.path()).unwrap();
        let again = store.get(&first.id).unwrap().unwrap();
        assert_eq!(again, first);
        assert_eq!(again.history.len(), 2);
        let second = store
            .create(&map, 1, None, vec![goal(2.0)], TaskState::Queued, 30)
            .unwrap();
        assert_eq!(second.id.as_str(), "t-000002");
        assert_eq!(store.unfinished().unwrap().len(), 2);
        let active = store
            .list(&TaskFilter {
                state: Some(TaskStateKind::Active),
                ..TaskFilter::default()
            })
            .unwrap();
        assert_eq!(active, vec![first]);
        let newest_first = store.list(&TaskFilter::default()).unwrap();
        assert_eq!(newest_first[0].id, second.id);
    }

    #[test]
    fn a_refused_change_writes_nothing() {
        let dir = tempfile::tempdir().unwrap();
        let store = TaskStore::open(dir.path()).unwrap();
        let map = MapName::new("depot").unwrap();
        let t = store
            .create(&map, 1, None, vec![goal(1.0)], TaskState::Queued, 10)
            .unwrap();
        let refused = store.update::<StoreError>(&t.id, |t| {
            t.set_state(TaskState::Cancelled, 11);
            Err(StoreError::NotFound(t.id.clone()))
        });
        assert!(refused.is_err());
        assert_eq!(store.get(&t.id).unwrap().unwrap(), t);
        let missing = TaskId::new("t-999999").unwrap();
        assert!(matches!(
            store.update::<StoreError>(&missing, |_| Ok(true)),
            Err(StoreError::NotFound(_))
        ));
    }
    fn finished(store: &TaskStore, id: &TaskId, state: TaskState, at: u64) -> Task {
        store
            .update::<StoreError>(id, |t| {
                t.set_state(state, at);
                Ok(true)
            })
            .unwrap()
            .0
    }

    /// 300 tasks on two maps and three robots (some without), in every state, some with equal
    /// creation times (the id breaks the tie).
    fn many(store: &TaskStore) -> Vec<Task> {
        let maps = [
            MapName::new("depot").unwrap(),
            MapName::new("yard").unwrap(),
        ];
        let robots = [
            RobotId::new("robot_1").unwrap(),
            RobotId::new("robot_2").unwrap(),
            RobotId::new("robot_10").unwrap(),
        ];
        let mut out = Vec::new();
        for i in 0..300_u64 {
            let robot = (i % 4 != 3).then(|| robots[(i % 3) as usize].clone());
            let t = store
                .create(
                    &maps[(i % 2) as usize],
                    1,
                    robot.clone(),
                    vec![goal(1.0)],
                    TaskState::Queued,
                    1000 + i / 2,
                )
                .unwrap();
            let t = match (i % 5, robot) {
                (1, _) => finished(store, &t.id, TaskState::Completed, 5000 + i),
                (2, _) => finished(store, &t.id, TaskState::Cancelled, 5000 + i),
                (3, Some(r)) => finished(
                    store,
                    &t.id,
                    TaskState::Active {
                        robot_id: r,
                        goal_index: 0,
                    },
                    5000 + i,
                ),
                _ => t,
            };
            out.push(t);
        }
        out
    }

    fn newest_first(mut tasks: Vec<Task>) -> Vec<Task> {
        tasks.sort_by(|a, b| b.created_ns.cmp(&a.created_ns).then(b.id.cmp(&a.id)));
        tasks
    }

    #[test]
    fn pages_return_every_matching_task_once_newest_first() {
        let dir = tempfile::tempdir().unwrap();
        let store = TaskStore::open(dir.path()).unwrap();
        let all = many(&store);
        let filters = [
            TaskFilter::default(),
            TaskFilter {
                state: Some(TaskStateKind::Completed),
                ..TaskFilter::default()
            },
            TaskFilter {
                robot_id: Some(RobotId::new("robot_1").unwrap()),
                ..TaskFilter::default()
            },
            TaskFilter {
                map: Some(MapName::new("yard").unwrap()),
                state: Some(TaskStateKind::Queued),
                ..TaskFilter::default()
            },
            TaskFilter {
                robot_id: Some(RobotId::new("robot_10").unwrap()),
                map: Some(MapName::new("depot").unwrap()),
                ..TaskFilter::default()
            },
            TaskFilter {
                robot_id: Some(RobotId::new("nobody").unwrap()),
                ..TaskFilter::default()
            },
        ];
        for filter in filters {
            let expected =
                newest_first(all.iter().filter(|t| filter.matches(t)).cloned().collect());
            assert_eq!(
                store.list_by_scan(&filter).unwrap(),
                expected[..expected.len().min(100)]
            );
            for limit in [1, 7, 1000] {
                let mut got = Vec::new();
                let mut filter = TaskFilter {
                    limit: Some(limit),
                    ..filter.clone()
                };
                loop {
                    let page = store.list_page(&filter).unwrap();
                    assert!(page.tasks.len() <= limit);
                    got.extend(page.tasks);
                    match page.next_cursor {
                        Some(c) => {
                            assert_eq!(Cursor::decode(&c.encode()), Some(c.clone()));
                            filter.cursor = Some(c);
                        }
                        None => break,
                    }
                }
                assert_eq!(got, expected, "{filter:?}");
            }
        }
        // The snapshot's live tasks and a restart's unfinished ones come off the index too.
        let live = newest_first(
            all.iter()
                .filter(|t| !t.state.is_terminal())
                .cloned()
                .collect(),
        );
        assert_eq!(store.live(1000).unwrap(), live);
        assert_eq!(store.live(5).unwrap(), live[..5]);
        let mut oldest_first = live.clone();
        oldest_first.reverse();
        assert_eq!(store.unfinished().unwrap(), oldest_first);
        let counts = store.count_by_state().unwrap();
        for k in TaskStateKind::ALL {
            assert_eq!(
                counts[k as usize],
                all.iter().filter(|t| t.kind() == k).count(),
                "{k}"
            );
        }
    }

    #[test]
    fn an_old_database_gets_its_index_built_on_open() {
        let dir = tempfile::tempdir().unwrap();
        let written = {
            let store = TaskStore::open(dir.path()).unwrap();
            many(&store)
        };
        // Make it a database from before the index: no index table, no layout counter.
        {
            let db = Database::create(dir.path().join(DB_FILE)).unwrap();
            let txn = db.begin_write().unwrap();
            assert!(txn.delete_table(INDEX).unwrap());
            txn.open_table(COUNTERS)
                .unwrap()
                .remove(INDEX_VERSION)
                .unwrap();
            txn.commit().unwrap();
        }
        let store = TaskStore::open(dir.path()).unwrap();
        assert_eq!(
            store
                .list(&TaskFilter {
                    limit: Some(1000),
                    ..TaskFilter::default()
                })
                .unwrap(),
            newest_first(written.clone())
        );
        let robot = TaskFilter {
            robot_id: Some(RobotId::new("robot_2").unwrap()),
            limit: Some(1000),
            ..TaskFilter::default()
        };
        assert_eq!(
            store.list(&robot).unwrap(),
            store.list_by_scan(&robot).unwrap()
        );
        assert_eq!(store.count().unwrap(), 300);
    }

    #[test]
    fn retention_exports_then_prunes_only_finished_tasks_past_the_bounds() {
        let dir = tempfile::tempdir().unwrap();
        let store = TaskStore::open(dir.path()).unwrap();
        let all = many(&store);
        let finished_ids = |store: &TaskStore| -> Vec<TaskId> {
            let mut ids: Vec<_> = store
                .all()
                .unwrap()
                .into_iter()
                .filter(|t| t.state.is_terminal())
                .map(|t| t.id)
                .collect();
            ids.sort();
            ids
        };
        let live_before = store.unfinished().unwrap();
        assert_eq!(finished_ids(&store).len(), 120);
        // No bound: nothing happens.
        assert_eq!(
            store.sweep(&Retention::default(), u64::MAX).unwrap(),
            SweepReport::default()
        );
        assert!(!store.export_path().exists());

        // At most 100 finished: the 20 oldest by creation go, exported first.
        let report = store
            .sweep(
                &Retention {
                    max_age_ns: None,
                    max_count: Some(100),
                },
                0,
            )
            .unwrap();
        assert_eq!(report.pruned, 20);
        assert_eq!(
            report.pruned_by_state[TaskStateKind::Completed as usize]
                + report.pruned_by_state[TaskStateKind::Cancelled as usize],
            20
        );
        let mut finished_all: Vec<_> = all
            .iter()
            .filter(|t| {
                matches!(
                    t.kind(),
                    TaskStateKind::Completed | TaskStateKind::Cancelled
                )
            })
            .cloned()
            .collect();
        finished_all.sort_by_key(|t| (t.created_ns, t.id.clone()));
        let export = std::fs::read_to_string(store.export_path()).unwrap();
        let exported: Vec<Task> = export
            .lines()
            .map(|l| serde_json::from_str(l).unwrap())
            .collect();
        let mut expected_gone = finished_all[..20].to_vec();
        let mut sorted_export = exported.clone();
        sorted_export.sort_by_key(|t| (t.created_ns, t.id.clone()));
        expected_gone.sort_by_key(|t| (t.created_ns, t.id.clone()));
        // Exported with their whole history.
        assert_eq!(sorted_export, expected_gone);
        for t in &exported {
            assert_eq!(store.get(&t.id).unwrap(), None);
            assert_eq!(t.history.len(), 2);
        }
        assert_eq!(finished_ids(&store).len(), 100);
        assert_eq!(store.unfinished().unwrap(), live_before);
        assert!(store
            .list(&TaskFilter {
                limit: Some(1000),
                ..TaskFilter::default()
            })
            .unwrap()
            .iter()
            .all(|t| !exported.contains(t)));

        // By age: tasks that ended before 5000 + 200 go (ended at 5000 + i), live ones stay
        // however old.
        let report = store
            .sweep(
                &Retention {
                    max_age_ns: Some(100),
                    max_count: Some(100),
                },
                5300,
            )
            .unwrap();
        let left = store.all().unwrap();
        assert!(left
            .iter()
            .filter(|t| t.state.is_terminal())
            .all(|t| t.updated_ns >= 5200));
        assert_eq!(report.pruned, 100 - finished_ids(&store).len());
        assert_eq!(store.unfinished().unwrap(), live_before);
        let lines = std::fs::read_to_string(store.export_path())
            .unwrap()
            .lines()
            .count();
        assert_eq!(lines, 20 + report.pruned);
        // Index entries went with them.
        let finished_filter = TaskFilter {
            state: Some(TaskStateKind::Completed),
            limit: Some(1000),
            ..TaskFilter::default()
        };
        assert_eq!(
            store.list(&finished_filter).unwrap(),
            store.list_by_scan(&finished_filter).unwrap()
        );
        assert_eq!(
            store.count_by_state().unwrap().iter().sum::<usize>(),
            left.len()
        );
    }
}
