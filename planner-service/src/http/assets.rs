//! The dashboard (`web/index.html`, `web/assets/app.js`, `web/assets/style.css`), embedded in
//! the binary so the service needs no files beside it.

use axum::http::header;
use axum::response::{IntoResponse, Response};

const INDEX_HTML: &str = include_str!("../../../web/index.html");
const APP_JS: &str = include_str!("../../../web/assets/app.js");
const STYLE_CSS: &str = include_str!("../../../web/assets/style.css");

fn asset(content_type: &'static str, body: &'static str) -> Response {
    // `no-cache` makes browsers revalidate, so a new binary's dashboard shows at once.
    (
        [
            (header::CONTENT_TYPE, content_type),
            (header::CACHE_CONTROL, "no-cache"),
        ],
        body,
    )
        .into_response()
}

/// `GET /`.
pub async fn index() -> Response {
    asset("text/html; charset=utf-8", INDEX_HTML)
}

/// `GET /assets/app.js`.
pub async fn app_js() -> Response {
    asset("text/javascript; charset=utf-8", APP_JS)
}

/// `GET /assets/style.css`.
pub async fn style_css() -> Response {
    asset("text/css; charset=utf-8", STYLE_CSS)
}
