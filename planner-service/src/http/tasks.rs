//! Delivery-task routes: create, list (filtered, newest first, paged by cursor), get, cancel.
//! Validation and storage are the fleet's; this module maps HTTP onto it.

use axum::extract::rejection::{JsonRejection, QueryRejection};
use axum::extract::{Path as UrlPath, Query, State};
use axum::http::{HeaderMap, HeaderName, HeaderValue, StatusCode};
use axum::Json;
use protocol::{MapName, RobotId, TaskId};
use serde::Deserialize;

use super::error::ApiError;
use super::ranges;
use super::state::AppState;
use crate::fleet::{Cursor, NewTask, Task, TaskFilter, TaskStateKind};

/// The response header of `GET /api/v1/tasks` that carries the cursor of the next page
/// (absent on the last page). The body stays a plain array, as before cursors.
pub const NEXT_CURSOR: &str = "next-cursor";

/// `POST /api/v1/tasks` → `201 Task`; goals outside the physical ranges of [`ranges`] are
/// refused before the fleet sees them.
pub async fn create(
    State(state): State<AppState>,
    body: Result<Json<NewTask>, JsonRejection>,
) -> Result<(StatusCode, Json<Task>), ApiError> {
    let Json(req) = body?;
    ranges::goals(&req.goals)?;
    let fleet = state.fleet.clone();
    // Validation may build the map's planning grid (inflation, heuristic): not on the runtime.
    let task = tokio::task::spawn_blocking(move || fleet.create_task(req)).await??;
    Ok((StatusCode::CREATED, Json(task)))
}

/// The query of `GET /api/v1/tasks`, as text so each bad value is named.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ListQuery {
    state: Option<String>,
    robot_id: Option<String>,
    map: Option<String>,
    limit: Option<String>,
    /// Where the page starts: the `Next-Cursor` of the previous page.
    cursor: Option<String>,
    /// The token when reads are protected (checked by the auth layer).
    access_token: Option<String>,
}

impl ListQuery {
    fn filter(self) -> Result<TaskFilter, ApiError> {
        let _ = self.access_token;
        let limit = match self.limit {
            None => None,
            Some(s) => Some(
                s.parse::<usize>()
                    .ok()
                    .filter(|n| (1..=TaskFilter::MAX_LIMIT).contains(n))
                    .ok_or_else(|| {
                        ApiError::bad_request(format!(
                            "invalid limit = {s:?}: expected 1 to {}",
                            TaskFilter::MAX_LIMIT
                        ))
                    })?,
            ),
        };
        Ok(TaskFilter {
            state: self
                .state
                .map(|s| s.parse::<TaskStateKind>())
                .transpose()
                .map_err(|e| ApiError::bad_request(format!("invalid state: {e}")))?,
            robot_id: self.robot_id.map(RobotId::new).transpose()?,
            map: self.map.map(MapName::new).transpose()?,
            limit,
            cursor: self
                .cursor
                .map(|c| {
                    Cursor::decode(&c).ok_or_else(|| {
                        ApiError::bad_request(
                            "invalid cursor: expected the Next-Cursor of a previous page"
                                .to_string(),
                        )
                    })
                })
                .transpose()?,
        })
    }
}

/// `GET /api/v1/tasks` → `[Task]`, newest first; the `Next-Cursor` header, when there are
/// more, is the `cursor` of the next page.
pub async fn list(
    State(state): State<AppState>,
    query: Result<Query<ListQuery>, QueryRejection>,
) -> Result<(HeaderMap, Json<Vec<Task>>), ApiError> {
    let Query(q) = query?;
    let filter = q.filter()?;
    let fleet = state.fleet.clone();
    let page = tokio::task::spawn_blocking(move || fleet.task_page(&filter)).await??;
    let mut headers = HeaderMap::new();
    if let Some(next) = page.next_cursor {
        // Hex text: always a valid header value.
        if let Ok(v) = HeaderValue::from_str(&next.encode()) {
            headers.insert(HeaderName::from_static(NEXT_CURSOR), v);
        }
    }
    Ok((headers, Json(page.tasks)))
}

/// `GET /api/v1/tasks/{id}`.
pub async fn get(
    State(state): State<AppState>,
    UrlPath(id): UrlPath<String>,
) -> Result<Json<Task>, ApiError> {
    let id = TaskId::new(id)?;
    let fleet = state.fleet.clone();
    Ok(Json(
        tokio::task::spawn_blocking(move || fleet.task(&id)).await??,
    ))
}

/// `POST /api/v1/tasks/{id}/cancel` → `200 Task`, `409` when it already ended.
pub async fn cancel(
    State(state): State<AppState>,
    UrlPath(id): UrlPath<String>,
) -> Result<Json<Task>, ApiError> {
    let id = TaskId::new(id)?;
    let fleet = state.fleet.clone();
    Ok(Json(
        tokio::task::spawn_blocking(move || fleet.cancel_task(&id)).await??,
    ))
}
