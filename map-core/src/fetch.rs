//! The client side of the map store's Zenoh queryable: how a robot (or anyone) fetches a floor
//! plan or its metadata from the map store on the network. The server is `map-store`'s `serve`.

use std::time::Duration;

use protocol::zenoh_io;
use protocol::{keys, MapGrid, MapMeta, MapName, SiteId};
use zenoh::Session;

use crate::error::MapError;

/// The selector parameter that asks for metadata only.
pub const META_PARAM: &str = "meta";

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
