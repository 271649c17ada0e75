//! `GET /healthz`: liveness plus two numbers an operator checks first.

use axum::extract::State;
use axum::Json;
use serde::Serialize;

use super::state::AppState;
use crate::fleet::TaskStateKind;

#[derive(Debug, Serialize)]
pub struct Health {
    status: &'static str,
    version: &'static str,
    robots_online: usize,
    /// Tasks in state `active` (a robot is driving them).
    tasks_active: i64,
}

/// `GET /healthz`.
pub async fn healthz(State(state): State<AppState>) -> Json<Health> {
    let robots_online = state.fleet.robots().iter().filter(|r| r.online).count();
    Json(Health {
        status: "ok",
        version: env!("CARGO_PKG_VERSION"),
        robots_online,
        tasks_active: state.fleet.metrics().tasks_in(TaskStateKind::Active),
    })
}
