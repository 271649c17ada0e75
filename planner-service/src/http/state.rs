//! What every handler shares: the fleet and its map store, the HTTP settings, the token, the
//! counters and the shutdown signal that ends long-lived responses (event streams).

use std::path::PathBuf;
use std::sync::Arc;

use map_store::MapStore;
use tokio::sync::watch;

use super::metrics::HttpMetrics;
use crate::config::HttpConfig;
use crate::fleet::Fleet;

/// The router's state; cheap to clone.
#[derive(Clone)]
pub struct AppState {
    pub fleet: Arc<Fleet>,
    /// The fleet's map store.
    pub maps: Arc<MapStore>,
    pub http: Arc<HttpConfig>,
    pub token: Arc<str>,
    /// The service's data directory (uploads are staged under `uploads/` in it).
    pub data_dir: Arc<PathBuf>,
    pub metrics: Arc<HttpMetrics>,
    /// Memory shared by floor-plan decodes ([`super::images`]).
    pub decodes: super::images::DecodeBudget,
    /// Rendered map images by map id.
    pub map_images: Arc<super::images::ImageCache>,
    /// Turns `true` when the server shuts down.
    pub shutdown: watch::Receiver<bool>,
}
