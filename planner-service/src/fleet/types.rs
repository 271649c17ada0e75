//! The fleet's JSON shapes (docs/api.md): delivery tasks, robots as the service sees them,
//! intentions, and the live events the dashboard streams.

use std::fmt;
use std::str::FromStr;

use protocol::{
    AgentState, AgentStatus, ControllerKind, Dlm, Intention, MapName, MapRef, Pose2D, PoseEstimate,
    RobotId, StopReason, TaskId, TaskState,
};
use serde::{Deserialize, Serialize};

pub use planning::Goal;

/// A task as submitted over HTTP.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NewTask {
    pub map: MapName,
    #[serde(default)]
    pub robot_id: Option<RobotId>,
    pub goals: Vec<Goal>,
}

/// One state a task went through, with when.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HistoryEntry {
    pub stamp_ns: u64,
    pub state: TaskState,
}

/// A stored delivery task.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Task {
    pub id: TaskId,
    pub map: MapName,
    /// Latest version of the map when the task was created.
    pub map_version: u32,
    /// The robot the task was given to (requested or assigned), if any yet.
    pub robot_id: Option<RobotId>,
    pub goals: Vec<Goal>,
    pub state: TaskState,
    pub created_ns: u64,
    pub updated_ns: u64,
    pub history: Vec<HistoryEntry>,
}

impl Task {
    #[must_use]
    pub fn kind(&self) -> TaskStateKind {
        TaskStateKind::of(&self.state)
    }

    /// The goal the robot is heading to (active or paused), if any.
    #[must_use]
    pub fn goal_index(&self) -> Option<u32> {
        match &self.state {
            TaskState::Active { goal_index, .. } | TaskState::Paused { goal_index, .. } => {
                Some(*goal_index)
            }
            _ => None,
        }
    }

    /// Records a new state (and when) in the task and its history.
    pub fn set_state(&mut self, state: TaskState, stamp_ns: u64) {
        self.state = state.clone();
        self.updated_ns = stamp_ns;
        self.history.push(HistoryEntry { stamp_ns, state });
    }
}

/// The name of a task state, for filters and metrics.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TaskStateKind {
    Queued,
    Assigned,
    Active,
    Paused,
    Completed,
    Failed,
    Cancelled,
}

impl TaskStateKind {
    pub const ALL: [TaskStateKind; 7] = [
        TaskStateKind::Queued,
        TaskStateKind::Assigned,
        TaskStateKind::Active,
        TaskStateKind::Paused,
        TaskStateKind::Completed,
        TaskStateKind::Failed,
        TaskStateKind::Cancelled,
    ];

    #[must_use]
    pub fn of(state: &TaskState) -> Self {
        match state {
            TaskState::Queued => Self::Queued,
            TaskState::Assigned { .. } => Self::Assigned,
            TaskState::Active { .. } => Self::Active,
            TaskState::Paused { .. } => Self::Paused,
            TaskState::Completed => Self::Completed,
            TaskState::Failed { .. } => Self::Failed,
            TaskState::Cancelled => Self::Cancelled,
        }
    }

    #[must_use]
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Queued => "queued",
            Self::Assigned => "assigned",
            Self::Active => "active",
            Self::Paused => "paused",
            Self::Completed => "completed",
            Self::Failed => "failed",
            Self::Cancelled => "cancelled",
        }
    }
}

impl fmt::Display for TaskStateKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// A state name that is not one of [`TaskStateKind::ALL`].
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown task state {0:?}: expected one of queued, assigned, active, paused, completed, failed, cancelled")]
pub struct UnknownTaskState(pub String);

impl FromStr for TaskStateKind {
    type Err = UnknownTaskState;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Self::ALL
            .into_iter()
            .find(|k| k.as_str() == s)
            .ok_or_else(|| UnknownTaskState(s.to_string()))
    }
}

/// Which tasks to list; `limit` defaults to [`TaskFilter::DEFAULT_LIMIT`]; `cursor` (from the
/// previous page) starts the listing after that task.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TaskFilter {
    pub state: Option<TaskStateKind>,
    pub robot_id: Option<RobotId>,
    pub map: Option<MapName>,
    pub limit: Option<usize>,
    pub cursor: Option<Cursor>,
}

/// A position in the newest-first task order: the (creation time, id) of the last task of a
/// page. Its text form is opaque to clients (hex).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Cursor {
    pub created_ns: u64,
    pub id: TaskId,
}

impl Cursor {
    /// Longest text form: 8 bytes of time and the longest id, in hex.
    pub const MAX_TEXT_LEN: usize = 2 * (8 + TaskId::MAX_LEN);

    /// The cursor just past `task`.
    #[must_use]
    pub fn after(task: &Task) -> Self {
        Self {
            created_ns: task.created_ns,
            id: task.id.clone(),
        }
    }

    /// The opaque text form handed to clients.
    #[must_use]
    pub fn encode(&self) -> String {
        let mut bytes = self.created_ns.to_be_bytes().to_vec();
        bytes.extend_from_slice(self.id.as_str().as_bytes());
        hex::encode(bytes)
    }

    /// [`Cursor::encode`]'s form as a regular expression (the OpenAPI document states it, so a
    /// generated cursor that matches it is one the server takes): 16 lower-case hex digits of
    /// time, then the id's bytes in lower-case hex (A-Z a-z 0-9 _ . -, not starting with '.').
    pub const PATTERN: &'static str = concat!(
        "^[0-9a-f]{16}",
        "(?:2d|3[0-9]|4[1-9a-f]|5[0-9af]|6[1-9a-f]|7[0-9a])",
        "(?:2[de]|3[0-9]|4[1-9a-f]|5[0-9af]|6[1-9a-f]|7[0-9a]){0,63}$"
    );

    /// Parses [`Cursor::encode`]'s form (lower-case hex only, as [`Cursor::PATTERN`] says);
    /// `None` for anything else.
    #[must_use]
    pub fn decode(text: &str) -> Option<Self> {
        if text.len() > Self::MAX_TEXT_LEN
            || !text
                .bytes()
                .all(|b| b.is_ascii_digit() || (b'a'..=b'f').contains(&b))
        {
            return None;
        }
        let bytes = hex::decode(text).ok()?;
        let (time, id) = bytes.split_at_checked(8)?;
        let created_ns = u64::from_be_bytes(time.try_into().ok()?);
        let id = TaskId::new(String::from_utf8(id.to_vec()).ok()?).ok()?;
        Some(Self { created_ns, id })
    }
}

/// One page of a task listing: the tasks, and where the next page starts (`None` at the end).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TaskPage {
    pub tasks: Vec<Task>,
    pub next_cursor: Option<Cursor>,
}

impl TaskFilter {
    pub const DEFAULT_LIMIT: usize = 100;
    pub const MAX_LIMIT: usize = 1000;

    #[must_use]
    pub fn matches(&self, task: &Task) -> bool {
        self.state.is_none_or(|s| s == task.kind())
            && self
                .robot_id
                .as_ref()
                .is_none_or(|r| task.robot_id.as_ref() == Some(r))
            && self.map.as_ref().is_none_or(|m| &task.map == m)
    }

    #[must_use]
    pub fn limit(&self) -> usize {
        self.limit
            .unwrap_or(Self::DEFAULT_LIMIT)
            .min(Self::MAX_LIMIT)
    }
}

/// A robot's pose estimate as the dashboard shows it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PoseView {
    pub x_m: f64,
    pub y_m: f64,
    pub yaw_rad: f64,
    /// 3x3 row-major covariance over (x_m, y_m, yaw_rad).
    pub covariance: [f64; 9],
    pub stamp_ns: u64,
    /// What the robot's laser sees standing where the floor plan is free (map frame), which its
    /// plan keeps clear of.
    #[serde(default)]
    pub unmapped_obstacles_m: Vec<[f64; 2]>,
}

impl From<&PoseEstimate> for PoseView {
    fn from(p: &PoseEstimate) -> Self {
        Self {
            x_m: p.pose.x_m,
            y_m: p.pose.y_m,
            yaw_rad: p.pose.yaw_rad,
            covariance: p.covariance,
            stamp_ns: p.header.stamp_ns,
            unmapped_obstacles_m: p.unmapped_obstacles_m.clone(),
        }
    }
}

/// A robot's last reported status.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StatusView {
    pub state: AgentState,
    pub stop_reason: Option<StopReason>,
    pub controller: ControllerKind,
    pub localized: bool,
    /// The agent's recovery drives in place of `controller`: the dynamic window, or backing
    /// straight off.
    #[serde(default)]
    pub recovering: bool,
    /// Of `recovering`: backing straight off from someone met face to face.
    #[serde(default)]
    pub backing_up: bool,
    /// The agent's rotation shim turns the robot on the spot towards its path.
    #[serde(default)]
    pub rotating_in_place: bool,
    /// The agent's give-way rule holds the robot short of a narrow passage while someone comes
    /// through it.
    #[serde(default)]
    pub giving_way: bool,
}

impl From<&AgentStatus> for StatusView {
    fn from(s: &AgentStatus) -> Self {
        Self {
            state: s.state,
            stop_reason: s.stop_reason.clone(),
            controller: s.controller,
            localized: s.localized,
            recovering: s.recovering,
            backing_up: s.backing_up,
            rotating_in_place: s.rotating_in_place,
            giving_way: s.giving_way,
        }
    }
}

/// The last intention sent to a robot, without its image.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct IntentionView {
    pub task_id: Option<TaskId>,
    pub goal_index: u32,
    pub dlm: Dlm,
    /// `dlm` is an arriving `Stop`: the robot drives on to its goal ([`Intention::arriving`]).
    #[serde(default)]
    pub arriving: bool,
    pub path: Vec<Pose2D>,
    pub stamp_ns: u64,
    /// From the pose arriving at the service to the intention leaving it.
    pub latency_ms: f64,
}

impl IntentionView {
    /// The view of an intention, its latency not measured (0).
    #[must_use]
    pub fn of(intention: &Intention) -> Self {
        Self {
            task_id: intention.task_id.clone(),
            goal_index: intention.goal_index,
            dlm: intention.dlm,
            arriving: intention.arriving,
            path: intention.path.clone(),
            stamp_ns: intention.header.stamp_ns,
            latency_ms: 0.0,
        }
    }
}

/// A replanning worker as the service knows it (`GET /api/v1/workers`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WorkerView {
    /// `service` (the service process itself) or a worker process's id.
    pub id: String,
    /// Its liveliness token is up (the service is always alive).
    pub alive: bool,
    /// Online robots whose last replanning cycle it ran.
    pub robots: Vec<RobotId>,
    pub replans: u64,
    pub failures: u64,
    /// Mean pose-to-intention latency of its cycles, measured where it planned.
    pub mean_latency_ms: f64,
}

/// A robot as the service knows it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RobotView {
    pub id: RobotId,
    pub online: bool,
    pub last_seen_ns: u64,
    pub map: Option<MapRef>,
    pub pose: Option<PoseView>,
    pub status: Option<StatusView>,
    pub task_id: Option<TaskId>,
    pub intention: Option<IntentionView>,
}

/// One event of the live stream (`event:` name from [`FleetEvent::event_name`]).
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(untagged)]
pub enum FleetEvent {
    Robot(RobotView),
    Intention {
        robot_id: RobotId,
        intention: IntentionView,
    },
    Task(Task),
}

impl FleetEvent {
    #[must_use]
    pub fn event_name(&self) -> &'static str {
        match self {
            FleetEvent::Robot(_) => "robot",
            FleetEvent::Intention { .. } => "intention",
            FleetEvent::Task(_) => "task",
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn state_names_round_trip_and_unknown_is_named() {
        for k in TaskStateKind::ALL {
            assert_eq!(k.as_str().parse::<TaskStateKind>().unwrap(), k);
        }
        let err = "running".parse::<TaskStateKind>().unwrap_err();
        assert!(err.to_string().contains("\"running\""));
    }

    #[test]
    fn new_task_rejects_unknown_fields_and_bad_ids() {
        let ok: NewTask =
            serde_json::from_str(r#"{"map":"depot","goals":[{"x_m":1,"y_m":2}]}"#).unwrap();
        assert_eq!(ok.goals[0].yaw_rad, None);
        assert!(
            serde_json::from_str::<NewTask>(r#"{"map":"depot","goals":[],"priority":3}"#).is_err()
        );
        assert!(serde_json::from_str::<NewTask>(r#"{"map":"a/b","goals":[]}"#).is_err());
    }

    #[test]
    fn free_heading_points_from_the_previous_pose() {
        let g = Goal {
            x_m: 1.0,
            y_m: 1.0,
            yaw_rad: None,
        };
        let p = g.pose_from(Pose2D::new(0.0, 0.0, 3.0));
        assert!((p.yaw_rad - std::f64::consts::FRAC_PI_4).abs() < 1e-12);
    }
}
