//! `GET /api/v1/events`: the live event stream (Server-Sent Events) of the dashboard.
//!
//! The subscription to the fleet's event bus is taken before the snapshot is read, so no
//! change falls between the two (a change may show in both, which is harmless: events carry
//! whole objects). A subscriber that falls behind the bus's buffer skips what it missed and
//! gets a fresh `snapshot` instead, so a task change is never lost to a slow client; the
//! stream ends when the server shuts down.

use std::convert::Infallible;
use std::time::Duration;

use axum::extract::State;
use axum::response::sse::{Event, KeepAlive, Sse};
use futures::stream::{self, Stream, StreamExt};
use serde::Serialize;
use tokio::sync::broadcast::error::RecvError;

use super::error::ApiError;
use super::state::AppState;
use crate::fleet::{RobotView, Task, TaskFilter};

/// Most tasks in a snapshot: the newest that have not ended.
pub const SNAPSHOT_TASKS: usize = TaskFilter::MAX_LIMIT;

/// Longest interval of the `: keep-alive` comment lines.
pub const KEEP_ALIVE: Duration = Duration::from_secs(15);

/// The interval of the `: keep-alive` lines: [`KEEP_ALIVE`], or half of `http.idle_timeout_ms`
/// when that is shorter, so a quiet stream is never closed as idle.
#[must_use]
pub fn keep_alive_interval(idle_timeout_ms: u64) -> Duration {
    KEEP_ALIVE.min(Duration::from_millis(idle_timeout_ms / 2).max(Duration::from_millis(1)))
}

#[derive(Serialize)]
struct Snapshot {
    robots: Vec<RobotView>,
    tasks: Vec<Task>,
}

fn json_event(name: &str, data: &impl Serialize) -> Event {
    Event::default()
        .event(name)
        .json_data(data)
        .unwrap_or_else(|e| {
            // Only a non-string map key can fail here, and the fleet's types have none.
            tracing::error!(event = name, "cannot serialize event: {e}");
            Event::default().comment("unserializable event dropped")
        })
}

/// The robots and the live tasks (not ended; the newest [`SNAPSHOT_TASKS`]), read off the async
/// workers (the task list is a database read, off the state index: its cost does not grow with
/// the finished tasks stored).
async fn snapshot(fleet: std::sync::Arc<crate::fleet::Fleet>) -> Result<Snapshot, ApiError> {
    tokio::task::spawn_blocking(move || {
        Ok::<_, ApiError>(Snapshot {
            robots: fleet.robots(),
            tasks: fleet.live_tasks(SNAPSHOT_TASKS)?,
        })
    })
    .await?
}

/// `GET /api/v1/events`.
pub async fn events(
    State(state): State<AppState>,
) -> Result<Sse<impl Stream<Item = Result<Event, Infallible>>>, ApiError> {
    let rx = state.fleet.subscribe();
    let first_snapshot = snapshot(state.fleet.clone()).await?;
    let first = stream::once(async move { json_event("snapshot", &first_snapshot) });
    let shutdown = state.shutdown.clone();
    let fleet = state.fleet.clone();
    let live = stream::unfold(rx, move |mut rx| {
        let mut shutdown = shutdown.clone();
        let fleet = fleet.clone();
        async move {
            loop {
                // Decided first, handled after: the shutdown wait must not live across the
                // snapshot's await.
                let received = tokio::select! {
                    _ = shutdown.wait_for(|stop| *stop) => return None,
                    r = rx.recv() => r,
                };
                match received {
                    Ok(ev) => return Some((json_event(ev.event_name(), &ev), rx)),
                    Err(RecvError::Lagged(n)) => {
                        tracing::debug!(skipped = n, "slow event-stream client resynced");
                        match snapshot(fleet.clone()).await {
                            Ok(s) => return Some((json_event("snapshot", &s), rx)),
                            Err(e) => tracing::warn!("cannot resync an event stream: {e:?}"),
                        }
                    }
                    Err(RecvError::Closed) => return None,
                }
            }
        }
    });
    Ok(Sse::new(first.chain(live).map(Ok)).keep_alive(
        KeepAlive::new()
            .interval(keep_alive_interval(state.http.idle_timeout_ms))
            .text("keep-alive"),
    ))
}
