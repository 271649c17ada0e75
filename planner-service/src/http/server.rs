//! The running service behind `planner-service serve`: opens the map store in
//! `<data-dir>/maps`, serves maps to robots over Zenoh, starts the fleet, serves HTTP, and
//! stops it all cleanly.
//!
//! [`Server::start`] binds (port 0 works) and returns at once with the bound address, so tests
//! and the demo start it in-process; [`Server::stop`] shuts HTTP down gracefully (event
//! streams end), then the fleet, the map server and the Zenoh session. HTTP connections are
//! served by [`super::conn`] with the header-read and idle timeouts and the connection limit of
//! `[http]`.

use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

use map_store::{MapServer, MapStore};
use tokio::sync::watch;
use tokio::task::JoinHandle;

use super::auth::{resolve_token, TokenError, TokenSource};
use super::conn::ConnLimits;
use super::metrics::HttpMetrics;
use super::state::AppState;
use crate::config::ServiceConfig;
use crate::fleet::{Fleet, FleetError};

/// What the service needs to start.
#[derive(Debug, Clone)]
pub struct ServeOptions {
    /// The whole configuration, with environment and flags already applied.
    pub config: ServiceConfig,
    /// Maps (`maps/`), tasks, the generated token and upload staging live here.
    pub data_dir: PathBuf,
}

/// Why the service could not start or stop cleanly.
#[derive(Debug, thiserror::Error)]
pub enum ServeError {
    #[error("invalid configuration: {0}")]
    Config(String),
    #[error(transparent)]
    Token(#[from] TokenError),
    #[error("cannot open the map store: {0}")]
    Maps(#[from] map_store::MapError),
    #[error("cannot open the zenoh session: {0}")]
    Zenoh(String),
    #[error("cannot start the fleet: {0}")]
    Fleet(#[from] FleetError),
    #[error("cannot listen on http.listen = {addr}: {source}")]
    Bind {
        addr: SocketAddr,
        #[source]
        source: std::io::Error,
    },
    #[error("HTTP server failed: {0}")]
    Http(std::io::Error),
    #[error("HTTP server did not stop within {0:?}")]
    StopTimeout(Duration),
}

/// How long stopping waits for open requests to finish before giving up on them.
const STOP_GRACE: Duration = Duration::from_secs(5);

/// The running service.
pub struct Server {
    addr: SocketAddr,
    token: String,
    token_source: TokenSource,
    session: zenoh::Session,
    maps: Arc<MapStore>,
    map_server: MapServer,
    fleet: Arc<Fleet>,
    shutdown: watch::Sender<bool>,
    http_task: JoinHandle<std::io::Result<()>>,
}

impl Server {
    /// Starts everything and returns once the HTTP listener is bound.
    ///
    /// # Errors
    /// [`ServeError`] naming what failed; whatever had started is stopped again.
    pub async fn start(opts: ServeOptions) -> Result<Self, ServeError> {
        let cfg = &opts.config;
        cfg.validate()
            .map_err(|e| ServeError::Config(e.to_string()))?;
        let (token, token_source) = resolve_token(cfg.http.token.as_deref(), &opts.data_dir)?;
        let maps_dir = opts.data_dir.join("maps");
        let maps = Arc::new(
            tokio::task::spawn_blocking(move || MapStore::open(&maps_dir))
                .await
                .map_err(|e| ServeError::Config(format!("map store task failed: {e}")))??,
        );
        let zenoh_cfg = cfg
            .zenoh
            .session_config()
            .map_err(|e| ServeError::Config(e.to_string()))?;
        let session = zenoh::open(zenoh_cfg)
            .await
            .map_err(|e| ServeError::Zenoh(e.to_string()))?;
        let map_server = match MapServer::start(&session, &cfg.zenoh.site, maps.clone()).await {
            Ok(s) => s,
            Err(e) => {
                let _ = session.close().await;
                return Err(e.into());
            }
        };
        let fleet = match Fleet::start(
            session.clone(),
            cfg.zenoh.site.clone(),
            maps.clone(),
            &opts.data_dir,
            cfg.clone(),
        )
        .await
        {
            Ok(f) => f,
            Err(e) => {
                drop(map_server);
                let _ = session.close().await;
                return Err(e.into());
            }
        };
        let listener = match tokio::net::TcpListener::bind(cfg.http.listen).await {
            Ok(l) => l,
            Err(source) => {
                fleet.shutdown().await;
                drop(map_server);
                let _ = session.close().await;
                return Err(ServeError::Bind {
                    addr: cfg.http.listen,
                    source,
                });
            }
        };
        let addr = listener.local_addr().map_err(ServeError::Http)?;
        let (shutdown, shutdown_rx) = watch::channel(false);
        let state = AppState {
            fleet: fleet.clone(),
            maps: maps.clone(),
            http: Arc::new(cfg.http.clone()),
            token: Arc::from(token.as_str()),
            data_dir: Arc::new(opts.data_dir.clone()),
            metrics: Arc::new(HttpMetrics::default()),
            decodes: super::images::DecodeBudget::new(
                cfg.http.decode_budget_bytes,
                std::time::Duration::from_millis(cfg.http.decode_wait_ms),
            ),
            map_images: Arc::new(super::images::ImageCache::new(cfg.http.image_cache_bytes)),
            shutdown: shutdown_rx.clone(),
        };
        let app = super::router(state);
        let limits = ConnLimits::of(&cfg.http);
        let http_task = tokio::spawn(super::conn::serve(listener, app, limits, shutdown_rx));
        tracing::info!(%addr, site = %cfg.zenoh.site, "planner service started");
        Ok(Self {
            addr,
            token,
            token_source,
            session,
            maps,
            map_server,
            fleet,
            shutdown,
            http_task,
        })
    }

    /// The bound HTTP address.
    #[must_use]
    pub fn local_addr(&self) -> SocketAddr {
        self.addr
    }

    /// `http://<addr>`.
    #[must_use]
    pub fn url(&self) -> String {
        format!("http://{}", self.addr)
    }

    /// The bearer token of mutating routes.
    #[must_use]
    pub fn token(&self) -> &str {
        &self.token
    }

    /// Where the token came from.
    #[must_use]
    pub fn token_source(&self) -> &TokenSource {
        &self.token_source
    }

    /// The service's Zenoh session (robots and tests connect to its locators).
    #[must_use]
    pub fn session(&self) -> &zenoh::Session {
        &self.session
    }

    /// The Zenoh endpoints the service listens on, e.g. `tcp/127.0.0.1:40123`.
    pub async fn zenoh_locators(&self) -> Vec<String> {
        protocol::zenoh_io::locators(&self.session).await
    }

    /// The map store.
    #[must_use]
    pub fn maps(&self) -> &Arc<MapStore> {
        &self.maps
    }

    /// The fleet core.
    #[must_use]
    pub fn fleet(&self) -> &Arc<Fleet> {
        &self.fleet
    }

    /// Stops HTTP (open event streams end, requests in flight finish within a grace period),
    /// then the map server and the Zenoh session; the data directory can be opened again
    /// when this returns.
    ///
    /// # Errors
    /// [`ServeError::StopTimeout`] when requests did not finish in time, [`ServeError::Http`].
    pub async fn stop(self) -> Result<(), ServeError> {
        let Self {
            session,
            maps,
            map_server,
            fleet,
            shutdown,
            mut http_task,
            ..
        } = self;
        let _ = shutdown.send(true);
        let http_result = match tokio::time::timeout(STOP_GRACE, &mut http_task).await {
            Ok(Ok(r)) => r.map_err(ServeError::Http),
            Ok(Err(e)) => Err(ServeError::Http(std::io::Error::other(e))),
            Err(_) => {
                http_task.abort();
                Err(ServeError::StopTimeout(STOP_GRACE))
            }
        };
        fleet.shutdown().await;
        drop(map_server);
        if let Err(e) = session.close().await {
            tracing::warn!(error = %e, "cannot close zenoh session");
        }
        // The database may only be reopened once every handle is gone; aborted tasks drop
        // theirs when the runtime next polls them.
        // The fleet holds the map store, so it goes first.
        wait_sole_owner(&fleet).await;
        drop(fleet);
        wait_sole_owner(&maps).await;
        drop(maps);
        http_result
    }
}

async fn wait_sole_owner<T>(arc: &Arc<T>) {
    let deadline = tokio::time::Instant::now() + STOP_GRACE;
    while Arc::strong_count(arc) > 1 && tokio::time::Instant::now() < deadline {
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
    if Arc::strong_count(arc) > 1 {
        tracing::warn!("a task still holds the store after stop");
    }
}
