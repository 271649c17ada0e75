//! The Zenoh side of the map store: a queryable that serves stored maps to robots (the client
//! a robot uses to fetch one is `map_core::fetch`).
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

use protocol::zenoh_io;
use protocol::{keys, MapGrid, MapMeta, SiteId};
use zenoh::query::{Query, Queryable};
use zenoh::Session;

use crate::store::MapStore;
use map_core::fetch::META_PARAM;
use map_core::MapError;

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
