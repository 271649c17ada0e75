//! The Zenoh side of the map store: a queryable that serves stored maps to robots, and the
//! client a robot uses to fetch one.
//!
//! | query | reply |
//! |---|---|
//! | `fleet/<site>/map/<name>` | the latest version as a framed [`MapGrid`] (cells as raw bytes) |
//! | `fleet/<site>/map/<name>/<version>` | that version as a framed [`MapGrid`] |
//! | either, with the selector parameter `meta` (`fleet/s/map/office?meta`) | only [`MapMeta`] (JSON) |
//! | an unknown map or version | an error reply naming it |
//! | anything else under `fleet/<site>/map/**` (wildcards) | an error reply naming the key |
//!
//! Payloads go through `protocol`'s codec; key expressions come from `protocol::keys`.

use std::sync::Arc;
use std::time::Duration;

use protocol::zenoh_io;
use protocol::{keys, MapGrid, MapMeta, MapName, SiteId};
use zenoh::query::{Query, Queryable};
use zenoh::Session;

use crate::error::MapError;
use crate::store::MapStore;

/// The selector parameter that asks for metadata only.
pub const META_PARAM: &str = "meta";

/// A running map queryable; dropping it undeclares the queryable.
pub struct MapServer {
    task: tokio::task::JoinHandle<()>,
}

impl MapServer {
    /// Declares the queryable on `fleet/<site>/map/**` and answers queries from `store` on a
    /// tokio task until dropped.
    ///
    /// # Errors
    /// [`MapError::Zenoh`] if the queryable cannot be declared.
    pub async fn start(
        session: &Session,
        site: &SiteId,
        store: Arc<MapStore>,
    ) -> Result<Self, MapError> {
        let key = keys::map_queryable(site);
        let queryable: Queryable<_> =
            session
                .declare_queryable(key)
                .await
                .map_err(|e| MapError::Zenoh {
                    action: "declare queryable",
                    reason: e.to_string(),
                })?;
        let site = site.clone();
        let task = tokio::spawn(async move {
            while let Ok(query) = queryable.recv_async().await {
                answer(&store, &site, &query).await;
            }
        });
        Ok(Self { task })
    }
}

impl Drop for MapServer {
    fn drop(&mut self) {
        self.task.abort();
    }
}

async fn answer(store: &MapStore, site: &SiteId, query: &Query) {
    let key = query.key_expr().clone();
    let result = match keys::parse_map_key(key.as_str()) {
        Some((query_site, name, version)) if &query_site == site => {
            let meta_only = query.parameters().contains_key(META_PARAM);
            // redb reads are short and synchronous; block_in_place keeps other tasks running.
            let found = tokio::task::block_in_place(|| {
                if meta_only {
                    store.meta(&name, version).map(Reply::Meta)
                } else {
                    store
                        .get(&name, version)
                        .map(|m| Reply::Grid(Box::new(m.to_map_grid())))
                }
            });
            match found {
                Ok(Reply::Meta(meta)) => zenoh_io::reply(query, &key, &meta).await,
                Ok(Reply::Grid(grid)) => zenoh_io::reply(query, &key, grid.as_ref()).await,
                Err(e) => {
                    reply_error(query, &e.to_string()).await;
                    return;
                }
            }
        }
        _ => {
            let msg =
                format!("{key} is not a map key: expected fleet/{site}/map/<name>[/<version>]");
            reply_error(query, &msg).await;
            return;
        }
    };
    if let Err(e) = result {
        tracing::warn!(%key, error = %e, "cannot reply to map query");
        reply_error(query, &e.to_string()).await;
    }
}

enum Reply {
    Meta(MapMeta),
    Grid(Box<MapGrid>),
}

async fn reply_error(query: &Query, msg: &str) {
    if let Err(e) = query.reply_err(msg.to_string()).await {
        tracing::warn!(key = %query.key_expr(), error = %e, "cannot send error reply");
    }
}

/// Fetches a map (latest when `version` is `None`) from a map store on the network.
///
/// # Errors
/// [`MapError::Remote`] when the store answers with an error (e.g. unknown map),
/// [`MapError::Zenoh`] when no store answers within `timeout` or the reply does not decode.
pub async fn fetch_map(
    session: &Session,
    site: &SiteId,
    name: &MapName,
    version: Option<u32>,
    timeout: Duration,
) -> Result<MapGrid, MapError> {
    let grid: MapGrid = query(session, site, name, version, false, timeout).await?;
    check_answer(&grid.meta, name, version)?;
    Ok(grid)
}

/// Fetches only the metadata of a map (latest when `version` is `None`).
///
/// # Errors
/// As [`fetch_map`].
pub async fn fetch_meta(
    session: &Session,
    site: &SiteId,
    name: &MapName,
    version: Option<u32>,
    timeout: Duration,
) -> Result<MapMeta, MapError> {
    let meta: MapMeta = query(session, site, name, version, true, timeout).await?;
    check_answer(&meta, name, version)?;
    Ok(meta)
}

fn check_answer(meta: &MapMeta, name: &MapName, version: Option<u32>) -> Result<(), MapError> {
    if &meta.name != name || version.is_some_and(|v| v != meta.version) {
        return Err(MapError::Zenoh {
            action: "fetch",
            reason: format!(
                "asked for {name} version {version:?}, got {} version {}",
                meta.name, meta.version
            ),
        });
    }
    Ok(())
}

async fn query<M: protocol::WireMessage>(
    session: &Session,
    site: &SiteId,
    name: &MapName,
    version: Option<u32>,
    meta_only: bool,
    timeout: Duration,
) -> Result<M, MapError> {
    let key = match version {
        Some(v) => keys::map_version(site, name, v),
        None => keys::map_latest(site, name),
    };
    let params = if meta_only { META_PARAM } else { "" };
    let replies = session
        .get((&key, params))
        .timeout(timeout)
        .await
        .map_err(|e| MapError::Zenoh {
            action: "query",
            reason: e.to_string(),
        })?;
    let reply = replies.recv_async().await.map_err(|_| MapError::Zenoh {
        action: "fetch",
        reason: format!(
            "no map store answered {key} (timeout {} ms)",
            timeout.as_millis()
        ),
    })?;
    match reply.into_result() {
        Ok(sample) => zenoh_io::decode_sample::<M>(&sample).map_err(|e| MapError::Zenoh {
            action: "decode",
            reason: format!("{key}: {e}"),
        }),
        Err(err) => Err(MapError::Remote {
            key: key.to_string(),
            reason: String::from_utf8_lossy(&err.payload().to_bytes()).into_owned(),
        }),
    }
}
