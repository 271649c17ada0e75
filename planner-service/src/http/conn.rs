//! The HTTP server's accept loop: every connection is served by hyper's HTTP/1 server with a
//! header-read timeout, watched for idleness, and counted against a connection limit.
//!
//! `axum::serve` has none of the three (its hyper connections get no timer, so hyper's own
//! header timeout never runs): a client that sends half a request head, or nothing at all,
//! held its connection and file descriptor for as long as it liked. Here:
//!
//! - **header-read timeout** (`http.header_read_timeout_ms`): hyper closes a connection whose
//!   request head is not complete that long after it started waiting for it, on a new
//!   connection and on a kept-alive one between requests alike;
//! - **idle timeout** (`http.idle_timeout_ms`): a connection on which no byte was read or
//!   written for that long is dropped, whatever state it is in (a stalled body, a client that
//!   does not read its answer);
//! - **connection limit** (`http.max_connections`): past it a new connection is answered
//!   `503` with `Retry-After` and closed, so it costs a file descriptor for at most
//!   [`REFUSAL_BUDGET`].
//!
//! Stopping: the loop stops accepting, asks every connection to finish its request in
//! flight and close (idle ones close at once), and returns when all have.

use std::io;
use std::pin::Pin;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::task::{Context, Poll};
use std::time::Duration;

use axum::Router;
use hyper_util::rt::{TokioIo, TokioTimer};
use hyper_util::service::TowerToHyperService;
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt, ReadBuf};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{watch, Semaphore};
use tokio::task::JoinSet;
use tokio::time::Instant;

use crate::config::HttpConfig;

/// The most time a refused connection may take (write the 503, read what the client sent).
pub const REFUSAL_BUDGET: Duration = Duration::from_secs(1);

/// Refusals in progress at once; beyond, an extra connection is closed without an answer.
const MAX_REFUSALS: usize = 64;

/// How long the loop pauses after an accept error that is not about one connection (e.g. out
/// of file descriptors), as `axum::serve` does, so it does not spin.
const ACCEPT_ERROR_PAUSE: Duration = Duration::from_secs(1);

/// The connection settings of `[http]`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ConnLimits {
    pub header_read_timeout: Duration,
    pub idle_timeout: Duration,
    pub max_connections: usize,
}

impl ConnLimits {
    #[must_use]
    pub fn of(http: &HttpConfig) -> Self {
        Self {
            header_read_timeout: Duration::from_millis(http.header_read_timeout_ms),
            idle_timeout: Duration::from_millis(http.idle_timeout_ms),
            max_connections: usize::try_from(http.max_connections).unwrap_or(usize::MAX),
        }
    }
}

/// Serves `app` on `listener` until `stop` turns true and every connection has closed.
///
/// # Errors
/// None so far: accept errors are logged and the loop goes on; the `Result` keeps the shape of
/// `axum::serve`.
pub async fn serve(
    listener: TcpListener,
    app: Router,
    limits: ConnLimits,
    mut stop: watch::Receiver<bool>,
) -> io::Result<()> {
    let permits = Arc::new(Semaphore::new(limits.max_connections));
    let refusals = Arc::new(Semaphore::new(MAX_REFUSALS));
    let mut http1 = hyper::server::conn::http1::Builder::new();
    http1
        .timer(TokioTimer::new())
        .header_read_timeout(limits.header_read_timeout)
        // A client that closes its sending side after a (possibly short) request still gets
        // the answer, e.g. the 400 of a truncated upload.
        .half_close(true)
        .keep_alive(true);
    let mut conns = JoinSet::new();
    loop {
        let (stream, peer) = tokio::select! {
            () = stopped(&mut stop) => break,
            // Reaps finished connections so the set does not grow.
            Some(_) = conns.join_next(), if !conns.is_empty() => continue,
            accepted = listener.accept() => match accepted {
                Ok(a) => a,
                Err(e) if is_connection_error(&e) => continue,
                Err(e) => {
                    tracing::error!(error = %e, "cannot accept an HTTP connection");
                    tokio::time::sleep(ACCEPT_ERROR_PAUSE).await;
                    continue;
                }
            },
        };
        let _ = stream.set_nodelay(true);
        match permits.clone().try_acquire_owned() {
            Ok(permit) => {
                let (http1, app, stop) = (http1.clone(), app.clone(), stop.clone());
                conns.spawn(async move {
                    serve_one(stream, http1, app, limits.idle_timeout, stop).await;
                    drop(permit);
                });
            }
            Err(_) => {
                tracing::warn!(%peer, limit = limits.max_connections, "HTTP connection limit reached: refusing a connection");
                if let Ok(slot) = refusals.clone().try_acquire_owned() {
                    let limit = limits.max_connections;
                    conns.spawn(async move {
                        let _ = tokio::time::timeout(REFUSAL_BUDGET, refuse(stream, limit)).await;
                        drop(slot);
                    });
                }
            }
        }
    }
    drop(listener);
    // Every connection saw `stop` too and is finishing; wait for the last.
    while conns.join_next().await.is_some() {}
    Ok(())
}

/// Resolves once the server stops (or its stop sender is gone).
async fn stopped(stop: &mut watch::Receiver<bool>) {
    let _ = stop.wait_for(|s| *s).await;
}

/// Errors that concern one connection only (the client gave up during the handshake).
fn is_connection_error(e: &io::Error) -> bool {
    matches!(
        e.kind(),
        io::ErrorKind::ConnectionRefused
            | io::ErrorKind::ConnectionAborted
            | io::ErrorKind::ConnectionReset
    )
}

/// Serves one connection until it ends, idles past `idle`, or the server stops.
async fn serve_one(
    stream: TcpStream,
    http1: hyper::server::conn::http1::Builder,
    app: Router,
    idle: Duration,
    mut stop: watch::Receiver<bool>,
) {
    let activity = Activity::new();
    let io = TokioIo::new(Watched {
        inner: stream,
        activity: activity.clone(),
    });
    let conn = http1.serve_connection(io, TowerToHyperService::new(app));
    tokio::pin!(conn);
    let mut stopping = false;
    loop {
        let idle_deadline = activity.last() + idle;
        tokio::select! {
            result = conn.as_mut() => {
                if let Err(e) = result {
                    if e.is_timeout() {
                        tracing::debug!("HTTP connection closed: no complete request head in time");
                    } else {
                        tracing::debug!(error = %e, "HTTP connection ended with an error");
                    }
                }
                return;
            }
            () = stopped(&mut stop), if !stopping => {
                stopping = true;
                conn.as_mut().graceful_shutdown();
            }
            () = tokio::time::sleep_until(idle_deadline) => {
                if activity.last() + idle <= Instant::now() {
                    tracing::debug!(idle_ms = idle.as_millis(), "HTTP connection closed: idle");
                    return;
                }
            }
        }
    }
}

/// Answers `503` with `Retry-After` to a connection over the limit and closes it. The request
/// head is read first (an HTTP client takes an answer before its request for a broken
/// connection), and what follows is read and dropped so that the close does not reset the
/// answer away.
async fn refuse(mut stream: TcpStream, limit: usize) {
    let mut head = Vec::with_capacity(1024);
    let mut chunk = [0_u8; 1024];
    while head.len() < 16 << 10 && !head.windows(4).any(|w| w == b"\r\n\r\n") {
        match stream.read(&mut chunk).await {
            Ok(0) | Err(_) => break,
            Ok(n) => head.extend_from_slice(&chunk[..n]),
        }
    }
    let body = format!(
        r#"{{"error":"unavailable","reason":"the server has its maximum of {limit} connections open (http.max_connections); retry later"}}"#
    );
    let answer = format!(
        "HTTP/1.1 503 Service Unavailable\r\ncontent-type: application/json\r\nretry-after: 1\r\nconnection: close\r\ncontent-length: {}\r\n\r\n{body}",
        body.len()
    );
    if stream.write_all(answer.as_bytes()).await.is_err() || stream.shutdown().await.is_err() {
        return;
    }
    let mut sink = [0_u8; 4096];
    let mut left: usize = 64 << 10;
    while left > 0 {
        match stream.read(&mut sink).await {
            Ok(0) | Err(_) => break,
            Ok(n) => left = left.saturating_sub(n),
        }
    }
}

/// When a connection last moved a byte, in milliseconds since it opened.
#[derive(Clone)]
struct Activity {
    opened: Instant,
    last_ms: Arc<AtomicU64>,
}

impl Activity {
    fn new() -> Self {
        Self {
            opened: Instant::now(),
            last_ms: Arc::new(AtomicU64::new(0)),
        }
    }

    fn touch(&self) {
        let ms = u64::try_from(self.opened.elapsed().as_millis()).unwrap_or(u64::MAX);
        self.last_ms.store(ms, Ordering::Relaxed);
    }

    fn last(&self) -> Instant {
        self.opened + Duration::from_millis(self.last_ms.load(Ordering::Relaxed))
    }
}

/// A stream that records when it last read or wrote a byte.
struct Watched {
    inner: TcpStream,
    activity: Activity,
}

impl AsyncRead for Watched {
    fn poll_read(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        let before = buf.filled().len();
        let polled = Pin::new(&mut self.inner).poll_read(cx, buf);
        if matches!(polled, Poll::Ready(Ok(()))) && buf.filled().len() > before {
            self.activity.touch();
        }
        polled
    }
}

impl AsyncWrite for Watched {
    fn poll_write(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<io::Result<usize>> {
        let polled = Pin::new(&mut self.inner).poll_write(cx, buf);
        if matches!(polled, Poll::Ready(Ok(n)) if n > 0) {
            self.activity.touch();
        }
        polled
    }

    fn poll_write_vectored(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        bufs: &[io::IoSlice<'_>],
    ) -> Poll<io::Result<usize>> {
        let polled = Pin::new(&mut self.inner).poll_write_vectored(cx, bufs);
        if matches!(polled, Poll::Ready(Ok(n)) if n > 0) {
            self.activity.touch();
        }
        polled
    }

    fn is_write_vectored(&self) -> bool {
        self.inner.is_write_vectored()
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.inner).poll_flush(cx)
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.inner).poll_shutdown(cx)
    }
}
