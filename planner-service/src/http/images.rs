//! What floor-plan pictures may cost the service: a memory budget shared by every decode
//! (uploads and previews), and the rendered map images kept per map version.
//!
//! A 110 KB PNG can hold 100 M pixels; decoding it and building its grid takes one to nine bytes
//! a pixel. [`DecodeBudget`] admits a decode only when its cost, read from the image header
//! ([`map_core::ros::decode_cost_bytes`]), fits in what the decodes running now leave of
//! `[http] decode_budget_bytes`: others wait up to `decode_wait_ms` in arrival order, then get
//! `503` with `Retry-After`; one that could never fit gets `413` at once.
//!
//! [`ImageCache`] keeps the PNG of `GET /maps/{name}/image` by map id (content addressed, so an
//! entry never goes stale) up to `[http] image_cache_bytes`, least recently used out first:
//! rendering a large plan takes hundreds of milliseconds, serving it again takes a copy.

use std::collections::HashMap;
use std::fmt::Write as _;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Duration;

use axum::http::{header, HeaderValue};
use axum::response::{IntoResponse, Response};
use tokio::sync::{OwnedSemaphorePermit, Semaphore};

use super::error::ApiError;

/// The budget's unit: permits are KiB so a `u32` count covers 4 TiB.
const UNIT_BYTES: u64 = 1024;

/// Decodes admitted against a shared memory budget.
#[derive(Debug, Clone)]
pub struct DecodeBudget {
    permits: Arc<Semaphore>,
    total_units: u32,
    wait: Duration,
}

/// Why a decode was not admitted.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum BudgetError {
    #[error("decoding this picture takes about {need_mb} MB, more than the {budget_mb} MB all decodes may use together ([http] decode_budget_bytes)")]
    TooLarge { need_mb: u64, budget_mb: u64 },
    #[error("other floor plans are being decoded and this one ({need_mb} MB) did not fit within {waited_ms} ms; try again")]
    Busy { need_mb: u64, waited_ms: u64 },
}

impl From<BudgetError> for ApiError {
    fn from(e: BudgetError) -> Self {
        match e {
            BudgetError::TooLarge { .. } => ApiError::too_large(e.to_string()),
            BudgetError::Busy { .. } => {
                ApiError::unavailable(e.to_string(), Duration::from_secs(1))
            }
        }
    }
}

fn mb(bytes: u64) -> u64 {
    bytes.div_ceil(1 << 20)
}

impl DecodeBudget {
    /// `budget_bytes` for all decodes together; a decode waits at most `wait` for room.
    #[must_use]
    pub fn new(budget_bytes: u64, wait: Duration) -> Self {
        let units = u32::try_from(budget_bytes / UNIT_BYTES)
            .unwrap_or(u32::MAX)
            .min(u32::try_from(Semaphore::MAX_PERMITS).unwrap_or(u32::MAX))
            .max(1);
        Self {
            permits: Arc::new(Semaphore::new(units as usize)),
            total_units: units,
            wait,
        }
    }

    /// Room for a decode of `cost_bytes`, held until the permit drops.
    ///
    /// # Errors
    /// [`BudgetError::TooLarge`] at once when the cost exceeds the whole budget,
    /// [`BudgetError::Busy`] when it did not fit within the wait.
    pub async fn admit(&self, cost_bytes: u64) -> Result<OwnedSemaphorePermit, BudgetError> {
        let units = cost_bytes.div_ceil(UNIT_BYTES).max(1);
        let need_mb = mb(cost_bytes);
        let Ok(units) = u32::try_from(units) else {
            return Err(self.too_large(need_mb));
        };
        if units > self.total_units {
            return Err(self.too_large(need_mb));
        }
        // Tokio's semaphore is fair: a large decode waiting is not overtaken by small ones.
        match tokio::time::timeout(self.wait, self.permits.clone().acquire_many_owned(units)).await
        {
            Ok(Ok(permit)) => Ok(permit),
            // Closed never happens (nobody closes it); timed out is the common case.
            Ok(Err(_)) | Err(_) => Err(BudgetError::Busy {
                need_mb,
                waited_ms: u64::try_from(self.wait.as_millis()).unwrap_or(u64::MAX),
            }),
        }
    }

    fn too_large(&self, need_mb: u64) -> BudgetError {
        BudgetError::TooLarge {
            need_mb,
            budget_mb: mb(u64::from(self.total_units) * UNIT_BYTES),
        }
    }

    /// Bytes of the budget free now.
    #[must_use]
    pub fn available_bytes(&self) -> u64 {
        self.permits.available_permits() as u64 * UNIT_BYTES
    }

    /// Appends the budget's free bytes in Prometheus text format.
    pub fn render_prometheus(&self, out: &mut String) {
        let _ = writeln!(
            out,
            "# HELP fleet_http_decode_budget_available_bytes Memory left for floor-plan decodes.\n\
             # TYPE fleet_http_decode_budget_available_bytes gauge\n\
             fleet_http_decode_budget_available_bytes {}",
            self.available_bytes()
        );
    }
}

/// Rendered PNGs by map id, least recently used out first.
#[derive(Debug)]
pub struct ImageCache {
    capacity_bytes: u64,
    inner: Mutex<CacheInner>,
    hits: AtomicU64,
    misses: AtomicU64,
}

#[derive(Debug, Default)]
struct CacheInner {
    entries: HashMap<String, (Arc<[u8]>, u64)>,
    /// Bumped on every use; an entry's stamp is its last use.
    clock: u64,
    bytes: u64,
}

impl ImageCache {
    #[must_use]
    pub fn new(capacity_bytes: u64) -> Self {
        Self {
            capacity_bytes,
            inner: Mutex::new(CacheInner::default()),
            hits: AtomicU64::new(0),
            misses: AtomicU64::new(0),
        }
    }

    /// The PNG of map `id`, if kept.
    pub fn get(&self, id: &str) -> Option<Arc<[u8]>> {
        let mut inner = self.inner.lock().unwrap_or_else(PoisonError::into_inner);
        inner.clock += 1;
        let now = inner.clock;
        let Some((png, stamp)) = inner.entries.get_mut(id) else {
            self.misses.fetch_add(1, Ordering::Relaxed);
            return None;
        };
        *stamp = now;
        self.hits.fetch_add(1, Ordering::Relaxed);
        Some(Arc::clone(png))
    }

    /// (hits, misses) of [`Self::get`] so far.
    #[must_use]
    pub fn lookups(&self) -> (u64, u64) {
        (
            self.hits.load(Ordering::Relaxed),
            self.misses.load(Ordering::Relaxed),
        )
    }

    /// Appends the cache's counters and size in Prometheus text format.
    pub fn render_prometheus(&self, out: &mut String) {
        let (hits, misses) = self.lookups();
        let (entries, bytes) = self.usage();
        let _ = writeln!(
            out,
            "# HELP fleet_http_map_image_lookups_total Map image requests served from the cache (hit) or rendered (miss).\n\
             # TYPE fleet_http_map_image_lookups_total counter\n\
             fleet_http_map_image_lookups_total{{result=\"hit\"}} {hits}\n\
             fleet_http_map_image_lookups_total{{result=\"miss\"}} {misses}\n\
             # HELP fleet_http_map_image_cache_bytes Rendered map images kept.\n\
             # TYPE fleet_http_map_image_cache_bytes gauge\n\
             fleet_http_map_image_cache_bytes {bytes}\n\
             # HELP fleet_http_map_image_cache_entries Map versions whose image is kept.\n\
             # TYPE fleet_http_map_image_cache_entries gauge\n\
             fleet_http_map_image_cache_entries {entries}"
        );
    }

    /// Keeps `png` for `id`, dropping the least recently used entries to make room; a PNG
    /// larger than the whole cache is not kept.
    pub fn insert(&self, id: &str, png: Arc<[u8]>) {
        let size = png.len() as u64;
        if size > self.capacity_bytes {
            return;
        }
        let mut inner = self.inner.lock().unwrap_or_else(PoisonError::into_inner);
        inner.clock += 1;
        let now = inner.clock;
        if let Some((old, _)) = inner.entries.insert(id.to_string(), (png, now)) {
            inner.bytes -= old.len() as u64;
        }
        inner.bytes += size;
        while inner.bytes > self.capacity_bytes {
            let Some(oldest) = inner
                .entries
                .iter()
                .min_by_key(|(_, (_, stamp))| *stamp)
                .map(|(k, _)| k.clone())
            else {
                break;
            };
            if let Some((gone, _)) = inner.entries.remove(&oldest) {
                inner.bytes -= gone.len() as u64;
            }
        }
    }

    /// (entries, bytes) kept now.
    #[must_use]
    pub fn usage(&self) -> (usize, u64) {
        let inner = self.inner.lock().unwrap_or_else(PoisonError::into_inner);
        (inner.entries.len(), inner.bytes)
    }
}

/// `304 Not Modified` when the request's `If-None-Match` names `etag` (or `*`).
#[must_use]
pub fn not_modified(if_none_match: Option<&HeaderValue>, etag: &HeaderValue) -> Option<Response> {
    let given = if_none_match?.to_str().ok()?;
    let hit = given
        .split(',')
        .map(str::trim)
        .any(|t| t == "*" || t.trim_start_matches("W/") == etag.to_str().unwrap_or_default());
    hit.then(|| {
        (
            axum::http::StatusCode::NOT_MODIFIED,
            [(header::ETAG, etag.clone())],
        )
            .into_response()
    })
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    #[tokio::test]
    async fn decodes_share_the_budget_and_wait_for_room() {
        let budget = DecodeBudget::new(10 << 20, Duration::from_millis(0));
        let big = budget.admit(6 << 20).await.unwrap();
        assert_eq!(budget.available_bytes(), 4 << 20);
        // No room and no wait: busy, with the size in the reason.
        let busy = budget.admit(6 << 20).await.unwrap_err();
        assert_eq!(
            busy,
            BudgetError::Busy {
                need_mb: 6,
                waited_ms: 0
            }
        );
        let small = budget.admit(3 << 20).await.unwrap();
        drop(big);
        let again = budget.admit(6 << 20).await.unwrap();
        drop((small, again));
        assert_eq!(budget.available_bytes(), 10 << 20);
        // More than the whole budget never fits: 413 at once.
        let err = budget.admit(11 << 20).await.unwrap_err();
        assert_eq!(
            err,
            BudgetError::TooLarge {
                need_mb: 11,
                budget_mb: 10
            }
        );
        assert_eq!(ApiError::from(err).status.as_u16(), 413);
        assert_eq!(ApiError::from(busy).status.as_u16(), 503);
    }

    #[tokio::test]
    async fn a_waiting_decode_gets_in_when_room_frees_up() {
        let budget = DecodeBudget::new(10 << 20, Duration::from_secs(30));
        let first = budget.admit(8 << 20).await.unwrap();
        let b = budget.clone();
        let waiting = tokio::spawn(async move { b.admit(8 << 20).await.map(drop) });
        tokio::task::yield_now().await;
        assert!(!waiting.is_finished());
        drop(first);
        waiting.await.unwrap().unwrap();
    }

    #[test]
    fn the_cache_drops_the_least_recently_used_first() {
        let cache = ImageCache::new(100);
        let png = |n: usize| -> Arc<[u8]> { vec![7u8; n].into() };
        cache.insert("a", png(40));
        cache.insert("b", png(40));
        assert!(cache.get("a").is_some()); // a is now newer than b
        cache.insert("c", png(40));
        assert!(cache.get("b").is_none(), "b was the least recently used");
        assert!(cache.get("a").is_some() && cache.get("c").is_some());
        assert_eq!(cache.usage(), (2, 80));
        // Replacing an entry counts its new size only.
        cache.insert("a", png(10));
        assert_eq!(cache.usage(), (2, 50));
        // Larger than the cache: not kept, nothing evicted.
        cache.insert("huge", png(101));
        assert!(cache.get("huge").is_none());
        assert_eq!(cache.usage(), (2, 50));
    }

    #[test]
    fn if_none_match_answers_304_for_the_same_tag_only() {
        let etag = HeaderValue::from_static("\"office-0123456789ab\"");
        let same = HeaderValue::from_static("\"other\", W/\"office-0123456789ab\"");
        assert_eq!(
            not_modified(Some(&same), &etag).unwrap().status().as_u16(),
            304
        );
        let other = HeaderValue::from_static("\"office-ffffffffffff\"");
        assert!(not_modified(Some(&other), &etag).is_none());
        assert!(not_modified(None, &etag).is_none());
        let any = HeaderValue::from_static("*");
        assert!(not_modified(Some(&any), &etag).is_some());
    }
}
