//! The API's error responses: `{"error": "<code>", "reason": "<sentence>"}` with the status of
//! docs/api.md, built from every error the handlers meet.

use axum::extract::multipart::{MultipartError, MultipartRejection};
use axum::extract::rejection::{JsonRejection, QueryRejection};
use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};
use axum::Json;
use map_store::MapError;
use serde::Serialize;

use crate::fleet::{ErrorKind, FleetError};

/// An error answer: status, short code and a reason naming the field and value.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ApiError {
    pub status: StatusCode,
    pub reason: String,
    /// Sent as `Retry-After` (whole seconds) with a `503`.
    pub retry_after: Option<std::time::Duration>,
}

#[derive(Serialize)]
struct Body<'a> {
    error: &'a str,
    reason: &'a str,
}

impl ApiError {
    pub fn new(status: StatusCode, reason: impl Into<String>) -> Self {
        Self {
            status,
            reason: reason.into(),
            retry_after: None,
        }
    }

    /// `503`: the service is busy; the client may try again after `retry_after`.
    pub fn unavailable(reason: impl Into<String>, retry_after: std::time::Duration) -> Self {
        Self {
            retry_after: Some(retry_after),
            ..Self::new(StatusCode::SERVICE_UNAVAILABLE, reason)
        }
    }

    pub fn bad_request(reason: impl Into<String>) -> Self {
        Self::new(StatusCode::BAD_REQUEST, reason)
    }

    pub fn unauthorized(reason: impl Into<String>) -> Self {
        Self::new(StatusCode::UNAUTHORIZED, reason)
    }

    pub fn not_found(reason: impl Into<String>) -> Self {
        Self::new(StatusCode::NOT_FOUND, reason)
    }

    pub fn conflict(reason: impl Into<String>) -> Self {
        Self::new(StatusCode::CONFLICT, reason)
    }

    pub fn too_large(reason: impl Into<String>) -> Self {
        Self::new(StatusCode::PAYLOAD_TOO_LARGE, reason)
    }

    pub fn internal(reason: impl Into<String>) -> Self {
        Self::new(StatusCode::INTERNAL_SERVER_ERROR, reason)
    }

    /// The short code of the body's `error` field.
    #[must_use]
    pub fn code(&self) -> &'static str {
        code_of(self.status)
    }
}

/// The `error` code of a status, as docs/api.md lists them.
#[must_use]
pub fn code_of(status: StatusCode) -> &'static str {
    match status {
        StatusCode::BAD_REQUEST => "bad_request",
        StatusCode::UNAUTHORIZED => "unauthorized",
        StatusCode::NOT_FOUND => "not_found",
        StatusCode::METHOD_NOT_ALLOWED => "method_not_allowed",
        StatusCode::CONFLICT => "conflict",
        StatusCode::PAYLOAD_TOO_LARGE => "too_large",
        StatusCode::UNSUPPORTED_MEDIA_TYPE => "unsupported_media_type",
        StatusCode::SERVICE_UNAVAILABLE => "unavailable",
        s if s.is_client_error() => "bad_request",
        _ => "internal",
    }
}

impl std::fmt::Display for ApiError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} {}: {}",
            self.status.as_u16(),
            self.code(),
            self.reason
        )
    }
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        let reason = if self.status.is_server_error() {
            // The log keeps the whole reason; the client gets it without the host's paths.
            tracing::error!(status = %self.status, reason = %self.reason, "request failed");
            tidy_reason(&scrub_paths(&self.reason))
        } else {
            tidy_reason(&self.reason)
        };
        let body = Body {
            error: self.code(),
            reason: &reason,
        };
        let mut resp = (self.status, Json(body)).into_response();
        if let Some(after) = self.retry_after {
            let secs = after.as_secs_f64().ceil().max(1.0);
            if let Ok(v) = axum::http::HeaderValue::from_str(&format!("{secs:.0}")) {
                resp.headers_mut()
                    .insert(axum::http::header::RETRY_AFTER, v);
            }
        }
        resp
    }
}

/// Longest run of characters without a space that a reason repeats (ids, numbers, file names,
/// values the client sent); longer ones are cut and end in `…`.
pub const MAX_REASON_WORD_CHARS: usize = 64;

/// Longest reason sent, in characters; a longer one is cut and ends in `…`.
pub const MAX_REASON_CHARS: usize = 512;

/// A reason as the client gets it: every word of more than [`MAX_REASON_WORD_CHARS`]
/// characters cut to that many plus `…`, the whole cut to [`MAX_REASON_CHARS`] plus `…`.
/// A client that sends a 20 000-character id gets a reason of a few dozen characters back.
#[must_use]
pub fn tidy_reason(reason: &str) -> String {
    let mut out = String::with_capacity(reason.len().min(MAX_REASON_CHARS + 4));
    let mut total = 0_usize;
    let mut word = 0_usize;
    for c in reason.chars() {
        if total == MAX_REASON_CHARS {
            out.push('…');
            break;
        }
        if c.is_whitespace() {
            word = 0;
        } else {
            word += 1;
            if word == MAX_REASON_WORD_CHARS + 1 {
                out.push('…');
                total += 1;
                continue;
            }
            if word > MAX_REASON_WORD_CHARS {
                continue;
            }
        }
        out.push(c);
        total += 1;
    }
    out
}

/// Replaces absolute file-system paths (`/…/…`) in a server error's reason with
/// `<server path>`: they tell a client how the host is laid out and nothing it can act on.
#[must_use]
pub fn scrub_paths(reason: &str) -> String {
    let mut out = String::with_capacity(reason.len());
    for (i, piece) in reason.split(' ').enumerate() {
        if i > 0 {
            out.push(' ');
        }
        let start = piece
            .find(|c: char| !matches!(c, '(' | '"' | '\'' | '`' | '['))
            .unwrap_or(piece.len());
        let (lead, rest) = piece.split_at(start);
        let end = rest
            .rfind(|c: char| !matches!(c, ')' | '"' | '\'' | '`' | ']' | ':' | ',' | ';' | '.'))
            .map_or(0, |e| e + 1);
        let (path, trail) = rest.split_at(end);
        if path.starts_with('/') && path[1..].contains('/') {
            out.push_str(lead);
            out.push_str("<server path>");
            out.push_str(trail);
        } else {
            out.push_str(piece);
        }
    }
    out
}

impl From<MapError> for ApiError {
    fn from(e: MapError) -> Self {
        let status = match &e {
            MapError::NotFound { .. } => StatusCode::NOT_FOUND,
            MapError::TooLarge { .. } => StatusCode::PAYLOAD_TOO_LARGE,
            MapError::Invalid { .. }
            | MapError::MissingField { .. }
            | MapError::Yaml { .. }
            | MapError::Image { .. }
            | MapError::Id(_) => StatusCode::BAD_REQUEST,
            MapError::Io { .. }
            | MapError::Store { .. }
            | MapError::Remote { .. }
            | MapError::Zenoh { .. } => StatusCode::INTERNAL_SERVER_ERROR,
        };
        Self::new(status, e.to_string())
    }
}

impl From<FleetError> for ApiError {
    fn from(e: FleetError) -> Self {
        let status = match e.kind() {
            ErrorKind::BadRequest => StatusCode::BAD_REQUEST,
            ErrorKind::NotFound => StatusCode::NOT_FOUND,
            ErrorKind::Conflict => StatusCode::CONFLICT,
            ErrorKind::Internal => StatusCode::INTERNAL_SERVER_ERROR,
        };
        Self::new(status, e.to_string())
    }
}

impl From<protocol::IdError> for ApiError {
    fn from(e: protocol::IdError) -> Self {
        Self::bad_request(e.to_string())
    }
}

impl From<JsonRejection> for ApiError {
    fn from(e: JsonRejection) -> Self {
        // axum says 422 for a well-formed body with a bad field and 415 for a missing
        // content type; the API answers 400 for every bad body (docs/api.md).
        let status = if e.status() == StatusCode::PAYLOAD_TOO_LARGE {
            StatusCode::PAYLOAD_TOO_LARGE
        } else {
            StatusCode::BAD_REQUEST
        };
        Self::new(status, format!("invalid JSON body: {}", e.body_text()))
    }
}

impl From<QueryRejection> for ApiError {
    fn from(e: QueryRejection) -> Self {
        Self::bad_request(format!("invalid query string: {}", e.body_text()))
    }
}

impl From<MultipartRejection> for ApiError {
    fn from(e: MultipartRejection) -> Self {
        Self::new(
            e.status(),
            format!("expected a multipart/form-data body: {}", e.body_text()),
        )
    }
}

impl From<MultipartError> for ApiError {
    fn from(e: MultipartError) -> Self {
        if e.status() == StatusCode::PAYLOAD_TOO_LARGE {
            Self::too_large(format!("upload too large: {}", e.body_text()))
        } else {
            // axum says 500 when the body stream fails, but the only way it fails is the
            // client's: a body shorter than its Content-Length, a connection closed mid-upload.
            Self::bad_request(format!(
                "bad multipart body (truncated, or not multipart/form-data): {}",
                e.body_text()
            ))
        }
    }
}

impl From<tokio::task::JoinError> for ApiError {
    fn from(e: tokio::task::JoinError) -> Self {
        Self::internal(format!("worker task failed: {e}"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn long_words_and_reasons_are_cut() {
        let id = "a".repeat(20_000);
        let r = tidy_reason(&format!(
            "invalid robot_id {id:?}: is 20000 characters long"
        ));
        assert!(
            r.starts_with(&format!("invalid robot_id \"{}…", "a".repeat(63))),
            "{r}"
        );
        assert!(r.ends_with(" is 20000 characters long"), "{r}");
        assert!(r.chars().count() < 120, "{r}");
        let many = "word ".repeat(1000);
        let r = tidy_reason(&many);
        assert_eq!(r.chars().count(), MAX_REASON_CHARS + 1);
        assert!(r.ends_with('…'));
        assert_eq!(tidy_reason("short reason: ok"), "short reason: ok");
        // Multi-byte characters are cut on character boundaries.
        let r = tidy_reason(&"é".repeat(100));
        assert_eq!(r.chars().count(), MAX_REASON_WORD_CHARS + 1);
    }

    #[test]
    fn server_paths_are_scrubbed() {
        assert_eq!(
            scrub_paths("cannot access /tmp/x/uploads/21699-12/map.png: denied"),
            "cannot access <server path>: denied"
        );
        assert_eq!(
            scrub_paths("cannot stage (\"/var/lib/fleet/uploads/1-2\"), giving up"),
            "cannot stage (\"<server path>\"), giving up"
        );
        assert_eq!(scrub_paths("a/b and / stay"), "a/b and / stay");
    }
}
