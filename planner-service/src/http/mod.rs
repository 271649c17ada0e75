//! The planner service's HTTP API (docs/api.md): floor plans, delivery tasks, robots, the live
//! event stream, health, metrics, the OpenAPI document and the embedded dashboard.
//!
//! - [`router`] builds the axum router; [`routes`] lists what it serves (the OpenAPI test
//!   compares the two).
//! - [`Server`] runs the whole service (map store, Zenoh map server, fleet, HTTP) and stops it
//!   cleanly; `planner-service serve` and the tests use it.
//! - [`conn`]: the accept loop (header-read and idle timeouts, connection limit); [`auth`]: the
//!   token; [`error`]: the `{"error","reason"}` answers; [`ranges`]: the physical ranges of
//!   numbers; [`maps`], [`tasks`], [`robots`], [`events`], [`health`], [`metrics`]: the routes;
//!   [`openapi`]: the OpenAPI document; [`assets`]: the dashboard files.

pub mod assets;
pub mod auth;
pub mod conn;
pub mod error;
pub mod events;
pub mod health;
pub mod images;
pub mod maps;
pub mod metrics;
pub mod openapi;
pub mod ranges;
pub mod robots;
pub mod server;
pub mod state;
pub mod tasks;

use std::collections::BTreeMap;

use axum::extract::DefaultBodyLimit;
use axum::http::{HeaderName, HeaderValue, Method, StatusCode};
use axum::middleware;
use axum::routing::{get, post, MethodRouter};
use axum::Router;
use tower_http::cors::{AllowOrigin, Any, CorsLayer};

pub use error::ApiError;
pub use server::{ServeError, ServeOptions, Server};
pub use state::AppState;

use crate::config::HttpConfig;

/// One route the router serves: method and path template (axum syntax, `{name}`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub struct RouteSpec {
    pub method: &'static str,
    pub path: &'static str,
}

/// Collects routes so the router and the route list come from the same calls.
struct Routes {
    by_path: BTreeMap<&'static str, MethodRouter<AppState>>,
    specs: Vec<RouteSpec>,
}

impl Routes {
    fn new() -> Self {
        Self {
            by_path: BTreeMap::new(),
            specs: Vec::new(),
        }
    }

    fn add(mut self, method: Method, path: &'static str, route: MethodRouter<AppState>) -> Self {
        let merged = match self.by_path.remove(path) {
            Some(existing) => existing.merge(route),
            None => route,
        };
        self.by_path.insert(path, merged);
        self.specs.push(RouteSpec {
            method: method_name(&method),
            path,
        });
        self
    }
}

fn method_name(m: &Method) -> &'static str {
    match *m {
        Method::POST => "post",
        Method::PUT => "put",
        Method::DELETE => "delete",
        Method::PATCH => "patch",
        _ => "get",
    }
}

fn build(http: &HttpConfig) -> Routes {
    let upload_limit = usize::try_from(http.max_upload_bytes).unwrap_or(usize::MAX);
    let declared_limit = http.max_upload_bytes;
    let upload = |r: MethodRouter<AppState>| {
        r.layer(DefaultBodyLimit::max(upload_limit))
            .layer(middleware::from_fn(move |req, next| {
                maps::refuse_oversized(declared_limit, req, next)
            }))
    };
    Routes::new()
        .add(Method::GET, "/", get(assets::index))
        .add(Method::GET, "/assets/app.js", get(assets::app_js))
        .add(Method::GET, "/assets/style.css", get(assets::style_css))
        .add(Method::GET, "/healthz", get(health::healthz))
        .add(Method::GET, "/metrics", get(metrics::metrics))
        .add(
            Method::GET,
            "/api/v1/openapi.json",
            get(openapi::openapi_json),
        )
        .add(Method::GET, "/api/v1/maps", get(maps::list))
        .add(Method::POST, "/api/v1/maps", upload(post(maps::upload)))
        .add(
            Method::POST,
            "/api/v1/maps/preview",
            upload(post(maps::preview)),
        )
        .add(Method::GET, "/api/v1/maps/{name}", get(maps::meta))
        .add(
            Method::GET,
            "/api/v1/maps/{name}/versions",
            get(maps::versions),
        )
        .add(Method::GET, "/api/v1/maps/{name}/image", get(maps::image))
        .add(Method::GET, "/api/v1/tasks", get(tasks::list))
        .add(Method::POST, "/api/v1/tasks", post(tasks::create))
        .add(Method::GET, "/api/v1/tasks/{id}", get(tasks::get))
        .add(
            Method::POST,
            "/api/v1/tasks/{id}/cancel",
            post(tasks::cancel),
        )
        .add(Method::GET, "/api/v1/robots", get(robots::list))
        .add(Method::GET, "/api/v1/robots/{id}", get(robots::get))
        .add(Method::GET, "/api/v1/workers", get(robots::workers))
        .add(
            Method::GET,
            "/api/v1/robots/{id}/lpe.png",
            get(robots::lpe_png),
        )
        .add(
            Method::GET,
            "/api/v1/robots/{id}/camera.jpg",
            get(robots::camera_jpg),
        )
        .add(Method::GET, "/api/v1/events", get(events::events))
}

/// Every route [`router`] serves.
#[must_use]
pub fn routes() -> Vec<RouteSpec> {
    let mut specs = build(&HttpConfig::default()).specs;
    specs.sort();
    specs
}

/// The API router with its layers: request counting, token check, body limits, CORS.
pub fn router(state: AppState) -> Router {
    let http = state.http.clone();
    let mut router = Router::new();
    for (path, route) in build(&http).by_path {
        router = router.route(path, route);
    }
    let json_limit = usize::try_from(http.max_json_bytes).unwrap_or(usize::MAX);
    let mut router = router
        .fallback(not_found)
        .method_not_allowed_fallback(method_not_allowed)
        .layer(DefaultBodyLimit::max(json_limit))
        .layer(middleware::from_fn_with_state(
            state.clone(),
            auth::check_token,
        ))
        .layer(middleware::from_fn_with_state(
            state.clone(),
            metrics::count_requests,
        ))
        .layer(tower_http::trace::TraceLayer::new_for_http())
        .with_state(state);
    if !http.cors.is_empty() {
        let origins = if http.cors.iter().any(|o| o == "*") {
            AllowOrigin::any()
        } else {
            AllowOrigin::list(
                http.cors
                    .iter()
                    .filter_map(|o| HeaderValue::from_str(o).ok()),
            )
        };
        router = router.layer(
            CorsLayer::new()
                .allow_origin(origins)
                .allow_methods([Method::GET, Method::POST, Method::PUT, Method::DELETE])
                .allow_headers(Any)
                .expose_headers([HeaderName::from_static(tasks::NEXT_CURSOR)]),
        );
    }
    router
}

async fn not_found(uri: axum::http::Uri) -> ApiError {
    ApiError::not_found(format!("no route {}", uri.path()))
}

async fn method_not_allowed(method: Method, uri: axum::http::Uri) -> ApiError {
    ApiError::new(
        StatusCode::METHOD_NOT_ALLOWED,
        format!("method {method} is not allowed on {}", uri.path()),
    )
}
