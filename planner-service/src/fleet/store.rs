//! Durable task storage: one redb file (`<data-dir>/tasks.redb`), one JSON record per task with
//! its whole history. Every change is a single write transaction, so a crash leaves either the
//! old or the new state of a task, never a torn one, and a restart sees every acknowledged change.

use std::path::{Path, PathBuf};

use protocol::{MapName, RobotId, TaskId, TaskState};
use redb::{Database, ReadableTable, TableDefinition};

use super::types::{Goal, HistoryEntry, Task, TaskFilter};

const TASKS: TableDefinition<&str, &[u8]> = TableDefinition::new("tasks");
const COUNTERS: TableDefinition<&str, u64> = TableDefinition::new("counters");
const NEXT_TASK: &str = "next_task";
const DB_FILE: &str = "tasks.redb";

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
}

/// The task database.
#[derive(Debug)]
pub struct TaskStore {
    db: Database,
    path: PathBuf,
}

impl TaskStore {
    /// Opens (creating if needed) `tasks.redb` in `data_dir`.
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
            txn.open_table(TASKS).map_err(|e| db_err("open table", e))?;
            txn.open_table(COUNTERS)
                .map_err(|e| db_err("open table", e))?;
        }
        txn.commit().map_err(|e| db_err("commit", e))?;
        Ok(Self { db, path })
    }

    #[must_use]
    pub fn path(&self) -> &Path {
        &self.path
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
            tasks
                .insert(task.id.as_str(), encode(&task)?.as_slice())
                .map_err(|e| db_err("write", e))?;
            task
        };
        txn.commit().map_err(|e| db_err("commit", e))?;
        Ok(task)
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
        let mut out = self.scan(|t| filter.matches(t))?;
        out.sort_by(|a, b| b.created_ns.cmp(&a.created_ns).then(b.id.cmp(&a.id)));
        out.truncate(filter.limit());
        Ok(out)
    }

    /// Every task that has not ended, oldest first (what a restart resumes).
    ///
    /// # Errors
    /// [`StoreError::Db`] or [`StoreError::Corrupt`].
    pub fn unfinished(&self) -> Result<Vec<Task>, StoreError> {
        let mut out = self.scan(|t| !t.state.is_terminal())?;
        out.sort_by(|a, b| a.created_ns.cmp(&b.created_ns).then(a.id.cmp(&b.id)));
        Ok(out)
    }

    /// Every task (for counting at start).
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
            let mut task = match tasks.get(id.as_str()).map_err(|e| db_err("read", e))? {
                Some(v) => decode(id.as_str(), v.value())?,
                None => return Err(StoreError::NotFound(id.clone()).into()),
            };
            let changed = change(&mut task)?;
            if changed {
                tasks
                    .insert(id.as_str(), encode(&task)?.as_slice())
                    .map_err(|e| db_err("write", e))?;
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
    use crate::fleet::types::TaskStateKind;

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
}
