//! Robot routes: the registry as the fleet sees it, each robot's latest LPE image and camera
//! frame, and the replanning workers that plan the robots.

use axum::extract::{Path as UrlPath, State};
use axum::http::header;
use axum::response::{IntoResponse, Response};
use axum::Json;
use protocol::RobotId;

use super::error::ApiError;
use super::state::AppState;
use crate::fleet::{RobotView, WorkerView};

/// `GET /api/v1/robots`, sorted by id.
pub async fn list(State(state): State<AppState>) -> Json<Vec<RobotView>> {
    Json(state.fleet.robots())
}

/// `GET /api/v1/workers`, sorted by id.
pub async fn workers(State(state): State<AppState>) -> Json<Vec<WorkerView>> {
    Json(state.fleet.workers())
}

/// `GET /api/v1/robots/{id}`.
pub async fn get(
    State(state): State<AppState>,
    UrlPath(id): UrlPath<String>,
) -> Result<Json<RobotView>, ApiError> {
    let id = RobotId::new(id)?;
    state
        .fleet
        .robot(&id)
        .map(Json)
        .ok_or_else(|| ApiError::not_found(format!("no robot {id}")))
}

fn image(content_type: &'static str, bytes: Vec<u8>) -> Response {
    (
        [
            (header::CONTENT_TYPE, content_type),
            // A live picture: never serve a stale copy.
            (header::CACHE_CONTROL, "no-store"),
        ],
        bytes,
    )
        .into_response()
}

/// Encodes one of a robot's live pictures off the async workers and answers it, or 404
/// naming `what` when the robot has none yet.
async fn picture(
    state: AppState,
    id: String,
    content_type: &'static str,
    what: &'static str,
    encode: fn(&crate::fleet::Fleet, &RobotId) -> Option<Vec<u8>>,
) -> Result<Response, ApiError> {
    let id = RobotId::new(id)?;
    let fleet = state.fleet.clone();
    let lookup = id.clone();
    let bytes = tokio::task::spawn_blocking(move || encode(&fleet, &lookup)).await?;
    bytes
        .map(|b| image(content_type, b))
        .ok_or_else(|| ApiError::not_found(format!("no {what} of robot {id}")))
}

/// `GET /api/v1/robots/{id}/lpe.png`.
pub async fn lpe_png(
    State(state): State<AppState>,
    UrlPath(id): UrlPath<String>,
) -> Result<Response, ApiError> {
    picture(
        state,
        id,
        "image/png",
        "LPE image",
        crate::fleet::Fleet::robot_lpe_png,
    )
    .await
}

/// `GET /api/v1/robots/{id}/camera.jpg`.
pub async fn camera_jpg(
    State(state): State<AppState>,
    UrlPath(id): UrlPath<String>,
) -> Result<Response, ApiError> {
    picture(
        state,
        id,
        "image/jpeg",
        "camera frame",
        crate::fleet::Fleet::robot_camera_jpeg,
    )
    .await
}
