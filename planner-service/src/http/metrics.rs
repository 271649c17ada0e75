//! `GET /metrics`: Prometheus text with the HTTP request counters kept here and the fleet's
//! own metrics.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::sync::Mutex;

use axum::extract::{MatchedPath, Request, State};
use axum::http::header;
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};

use super::state::AppState;

/// Requests served, by route template and status.
#[derive(Debug, Default)]
pub struct HttpMetrics {
    requests: Mutex<BTreeMap<(String, u16), u64>>,
}

impl HttpMetrics {
    pub fn record(&self, route: &str, status: u16) {
        // A poisoned lock only means another request panicked mid-increment; counting on is
        // better than losing every later count.
        let mut map = self
            .requests
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        *map.entry((route.to_string(), status)).or_insert(0) += 1;
    }

    /// How many requests to `route` got `status` so far.
    #[must_use]
    pub fn count(&self, route: &str, status: u16) -> u64 {
        let map = self
            .requests
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        map.get(&(route.to_string(), status)).copied().unwrap_or(0)
    }

    /// Appends `fleet_http_requests_total{route,status}` in Prometheus text format.
    pub fn render_prometheus(&self, out: &mut String) {
        let map = self
            .requests
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        out.push_str(
            "# HELP fleet_http_requests_total HTTP requests served, by route and status.\n",
        );
        out.push_str("# TYPE fleet_http_requests_total counter\n");
        for ((route, status), n) in map.iter() {
            // Route templates hold no quotes or backslashes; escape anyway to stay valid.
            let route = route.replace('\\', "\\\\").replace('"', "\\\"");
            let _ = writeln!(
                out,
                "fleet_http_requests_total{{route=\"{route}\",status=\"{status}\"}} {n}"
            );
        }
    }
}

/// Middleware counting every response by matched route (`unmatched` for unknown paths).
pub async fn count_requests(State(state): State<AppState>, req: Request, next: Next) -> Response {
    let route = req
        .extensions()
        .get::<MatchedPath>()
        .map_or_else(|| "unmatched".to_string(), |p| p.as_str().to_string());
    let resp = next.run(req).await;
    state.metrics.record(&route, resp.status().as_u16());
    resp
}

/// `GET /metrics`.
pub async fn metrics(State(state): State<AppState>) -> Response {
    let mut out = String::new();
    state.fleet.metrics().render_prometheus(&mut out);
    state.metrics.render_prometheus(&mut out);
    state.map_images.render_prometheus(&mut out);
    state.decodes.render_prometheus(&mut out);
    (
        [(
            header::CONTENT_TYPE,
            "text/plain; version=0.0.4; charset=utf-8",
        )],
        out,
    )
        .into_response()
}
