//! The bearer token: where it comes from (config, env, flag, or generated once and kept in
//! `<data-dir>/token`) and the middleware that checks it on mutating routes (and on reads when
//! `[http] protect_reads` is set).

use std::collections::HashMap;
use std::io::Write;
use std::path::{Path, PathBuf};

use axum::extract::{Query, Request, State};
use axum::http::{header, Method};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use rand::RngCore;

use super::error::ApiError;
use super::state::AppState;
use crate::config::validate_token;

/// File name of the generated token inside the data directory.
pub const TOKEN_FILE: &str = "token";

/// Where the service's token came from.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum TokenSource {
    /// The configuration, `FLEET_TOKEN` or `--token`.
    Configured,
    /// A token generated at an earlier start, read from this file.
    Stored(PathBuf),
    /// Generated now and written to this file.
    Generated(PathBuf),
}

/// Why no token could be set up.
#[derive(Debug, thiserror::Error)]
pub enum TokenError {
    #[error("cannot access token file {path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("invalid token in {path}: {reason} (delete the file to generate a new one)")]
    Invalid { path: PathBuf, reason: String },
}

/// The configured token, else the one stored in `<data_dir>/token`, else a new random one
/// (32 hex characters) written there atomically with mode 0600.
///
/// # Errors
/// [`TokenError`] when the file cannot be read or written, or holds an invalid token.
pub fn resolve_token(
    configured: Option<&str>,
    data_dir: &Path,
) -> Result<(String, TokenSource), TokenError> {
    if let Some(t) = configured {
        return Ok((t.to_string(), TokenSource::Configured));
    }
    let path = data_dir.join(TOKEN_FILE);
    let io = |source| TokenError::Io {
        path: path.clone(),
        source,
    };
    match std::fs::read_to_string(&path) {
        Ok(text) => {
            let token = text.trim().to_string();
            validate_token(&token).map_err(|reason| TokenError::Invalid {
                path: path.clone(),
                reason: reason.to_string(),
            })?;
            return Ok((token, TokenSource::Stored(path)));
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
        Err(e) => return Err(io(e)),
    }
    // A token must be unguessable, so this is the one random source seeded from the OS.
    let mut bytes = [0_u8; 16];
    rand::rngs::OsRng.fill_bytes(&mut bytes);
    let token = hex::encode(bytes);
    std::fs::create_dir_all(data_dir).map_err(|source| TokenError::Io {
        path: data_dir.to_path_buf(),
        source,
    })?;
    let tmp = data_dir.join(format!("{TOKEN_FILE}.tmp"));
    write_private(&tmp, token.as_bytes()).map_err(|source| TokenError::Io {
        path: tmp.clone(),
        source,
    })?;
    // The rename makes the file appear whole or not at all, even if the process dies here.
    std::fs::rename(&tmp, &path).map_err(io)?;
    Ok((token, TokenSource::Generated(path)))
}

fn write_private(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let mut opts = std::fs::OpenOptions::new();
    opts.write(true).create(true).truncate(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        opts.mode(0o600);
    }
    let mut f = opts.open(path)?;
    f.write_all(bytes)?;
    f.write_all(b"\n")?;
    f.sync_all()
}

/// Compares without an early exit, so the response time does not tell how much of a guess
/// was right.
fn same_token(given: &str, expected: &str) -> bool {
    let (a, b) = (given.as_bytes(), expected.as_bytes());
    let mut diff = u8::from(a.len() != b.len());
    for (i, &y) in b.iter().enumerate() {
        diff |= a.get(i).copied().unwrap_or(0) ^ y;
    }
    diff == 0
}

/// The token of an `Authorization: Bearer <token>` value. The scheme is case-insensitive and
/// followed by one or more spaces (RFC 7235 §2.1, RFC 6750 §2.1), so `bearer`, `BEARER` and
/// `Bearer` all work; `None` for another scheme or no token.
fn bearer_credentials(value: &str) -> Option<&str> {
    let value = value.trim();
    let (scheme, rest) = value.split_once([' ', '\t'])?;
    if !scheme.eq_ignore_ascii_case("bearer") {
        return None;
    }
    let token = rest.trim_start_matches([' ', '\t']);
    (!token.is_empty()).then_some(token)
}

/// Paths that stay open with `protect_reads`: the dashboard has to load before it can ask the
/// user for a token, and health probes carry none.
fn always_open(path: &str) -> bool {
    path == "/" || path == "/healthz" || path.starts_with("/assets/")
}

/// Checks the token of mutating requests, and of reads when `protect_reads` is set.
pub async fn check_token(State(state): State<AppState>, req: Request, next: Next) -> Response {
    let mutating = !matches!(*req.method(), Method::GET | Method::HEAD | Method::OPTIONS);
    let needed = mutating || (state.http.protect_reads && !always_open(req.uri().path()));
    if !needed {
        return next.run(req).await;
    }
    let header_token = match req.headers().get(header::AUTHORIZATION) {
        None => None,
        Some(v) => match v.to_str().ok().and_then(bearer_credentials) {
            Some(t) => Some(t.to_string()),
            None => {
                return ApiError::unauthorized("the Authorization header must be `Bearer <token>`")
                    .into_response()
            }
        },
    };
    // Only reads accept the query parameter: a browser EventSource cannot set headers, and a
    // token in a URL must not be enough to change anything.
    let given = header_token.or_else(|| {
        if mutating {
            return None;
        }
        Query::<HashMap<String, String>>::try_from_uri(req.uri())
            .ok()
            .and_then(|Query(q)| q.get("access_token").cloned())
    });
    match given {
        None => ApiError::unauthorized(if mutating {
            "this route needs `Authorization: Bearer <token>`"
        } else {
            "reads are protected: send `Authorization: Bearer <token>` or `access_token=<token>`"
        })
        .into_response(),
        Some(t) if !same_token(&t, &state.token) => {
            ApiError::unauthorized("wrong token").into_response()
        }
        Some(_) => next.run(req).await,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tokens_compare_exactly() {
        assert!(same_token("abcdef0123456789", "abcdef0123456789"));
        assert!(!same_token("abcdef0123456788", "abcdef0123456789"));
        assert!(!same_token("abcdef012345678", "abcdef0123456789"));
        assert!(!same_token("abcdef01234567890", "abcdef0123456789"));
        assert!(!same_token("", "abcdef0123456789"));
    }

    #[test]
    fn bearer_scheme_is_case_insensitive() {
        for v in [
            "Bearer abc",
            "bearer abc",
            "BEARER abc",
            "bEaReR   abc",
            " Bearer abc ",
        ] {
            assert_eq!(bearer_credentials(v), Some("abc"), "{v:?}");
        }
        for v in [
            "Basic abc",
            "Bearer",
            "Bearer ",
            "Bearerabc",
            "Token abc",
            "",
        ] {
            assert_eq!(bearer_credentials(v), None, "{v:?}");
        }
    }

    #[test]
    fn generated_token_is_stored_private_and_reused() {
        let dir = tempfile::tempdir().unwrap();
        let (t1, s1) = resolve_token(None, dir.path()).unwrap();
        assert_eq!(t1.len(), 32);
        assert!(t1.chars().all(|c| c.is_ascii_hexdigit()));
        let path = dir.path().join(TOKEN_FILE);
        assert_eq!(s1, TokenSource::Generated(path.clone()));
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            let mode = std::fs::metadata(&path).unwrap().permissions().mode();
            assert_eq!(mode & 0o777, 0o600);
        }
        let (t2, s2) = resolve_token(None, dir.path()).unwrap();
        assert_eq!((t2, s2), (t1.clone(), TokenSource::Stored(path.clone())));
        let (t3, s3) = resolve_token(Some("configured-token-123"), dir.path()).unwrap();
        assert_eq!(
            (t3.as_str(), s3),
            ("configured-token-123", TokenSource::Configured)
        );
        std::fs::write(&path, "short\n").unwrap();
        let e = resolve_token(None, dir.path()).unwrap_err().to_string();
        assert!(e.contains("token") && e.contains("length 5"), "{e}");
    }
}
