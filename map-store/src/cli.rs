//! The `map-store` command line; `main` only calls [`run`].
//!
//! ```text
//! map-store [--data-dir DIR] [--config FILE] <command>
//!
//!   import <map.yaml | picture> [--resolution M] [--name NAME] [--json]
//!          [--occupied-thresh P] [--free-thresh P] [--negate] [--scale-band]
//!       Import a ROS map_server YAML (+ image) or a floor-plan picture (PNG/JPEG/BMP/PGM; needs
//!       --resolution in metres per pixel) as the next version of NAME (default: the file stem,
//!       sanitized). Prints id, name, version, size, resolution, origin and the counts of free,
//!       occupied and unknown cells (--json: the MapMeta as JSON).
//!   export <id-or-name> <out.yaml> [--nav2-thresholds]
//!       Write a stored map (by id, else latest version of a name) as PGM + YAML the way Nav2's
//!       map_saver writes trinary maps.
//!   list [--json]
//!       Every stored version, by name, newest first.
//!   serve [--site S] [--zenoh-listen ENDPOINT]... [--zenoh-connect ENDPOINT]...
//!         [--zenoh-multicast-scouting]
//!       Serve maps on fleet/<site>/map/<name>[/<version>] over Zenoh until Ctrl-C
//!       (`--listen`/`--connect` are aliases; multicast scouting is off unless asked for).
//!   bench [--out results.json] [--markdown table.md] [--repeats N]
//!       Time import + exact distance field of the Nav2 2000x2000 maps (<shared>/maps/nav2, the
//!       shared folder found by `protocol::data_dirs`: $FLEET_SHARED_DIR, ./shared, ../shared or
//!       the user data directory) against a chamfer reference, and redb put/get; writes JSON and
//!       prints a markdown table.
//! ```
//!
//! The data directory defaults to the user's data directory
//! (`directories::ProjectDirs` for `org.intention-fleet.map-store`, e.g.
//! `~/.local/share/map-store` on Linux); `--data-dir` wins over the config's `data_dir`.
//! Every error is printed once with the field and value it concerns, and the exit status is
//! non-zero; a failed import stores nothing.

use std::ffi::OsString;
use std::io::Write;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

use anyhow::{anyhow, Context as _};
use clap::{Parser, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};
use protocol::{MapMeta, MapName, SessionArgs, SiteId};

use crate::bench::{markdown, run_bench, BENCH_MAPS};
use crate::config::MapStoreConfig;
use crate::export::{export_ros_map, ExportOptions};
use crate::import::{import_into, is_ros_yaml, name_from_path};
use crate::picture::PictureOptions;
use crate::ros::MapMode;
use crate::serve::MapServer;
use crate::store::MapStore;

#[derive(Debug, Parser)]
#[command(
    name = "map-store",
    version,
    about = "Floor-plan import, versioned storage and serving"
)]
pub struct Cli {
    /// Folder of the map database (default: the user's data directory).
    #[arg(long, global = true, env = "MAP_STORE_DATA_DIR")]
    pub data_dir: Option<PathBuf>,
    /// TOML configuration (see map-store.example.toml).
    #[arg(long, global = true)]
    pub config: Option<PathBuf>,
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Import a ROS map YAML or a floor-plan picture.
    Import {
        path: PathBuf,
        /// Metres per pixel of a picture (required for pictures).
        #[arg(long)]
        resolution: Option<f64>,
        /// Map name (default: the file stem, sanitized).
        #[arg(long)]
        name: Option<String>,
        /// Print the stored MapMeta as JSON.
        #[arg(long)]
        json: bool,
        /// Picture: occupancy above which a pixel is a wall.
        #[arg(long, default_value_t = 0.65)]
        occupied_thresh: f64,
        /// Picture: occupancy below which a pixel is free.
        #[arg(long, default_value_t = 0.25)]
        free_thresh: f64,
        /// Picture: light walls on a dark background.
        #[arg(long)]
        negate: bool,
        /// Picture: keep in-between greys as occupancy percentages instead of unknown.
        #[arg(long)]
        scale_band: bool,
    },
    /// Export a stored map as ROS PGM + YAML.
    Export {
        id_or_name: String,
        out: PathBuf,
        /// Write Nav2 map_saver's free_thresh 0.25 (unknown re-imports as free) instead of 0.196.
        #[arg(long)]
        nav2_thresholds: bool,
    },
    /// List stored maps.
    List {
        #[arg(long)]
        json: bool,
    },
    /// Serve maps over Zenoh until Ctrl-C.
    #[command(
        mut_arg(SessionArgs::LISTEN_ID, |a| a.visible_alias("listen")),
        mut_arg(SessionArgs::CONNECT_ID, |a| a.visible_alias("connect"))
    )]
    Serve {
        #[arg(long)]
        site: Option<String>,
        /// The Zenoh session: `--zenoh-listen` (alias `--listen`) and `--zenoh-connect` (alias
        /// `--connect`) replace the config's lists, `--zenoh-multicast-scouting` turns
        /// scouting on.
        #[command(flatten)]
        zenoh: SessionArgs,
    },
    /// Benchmark import, distance fields and storage.
    Bench {
        /// JSON results file.
        #[arg(long)]
        out: Option<PathBuf>,
        /// Markdown table file (also printed).
        #[arg(long)]
        markdown: Option<PathBuf>,
        #[arg(long, default_value_t = 3)]
        repeats: u32,
    },
}

/// Parses `args` (including the program name) and runs the command, printing to `out`.
///
/// # Errors
/// Every failure, with context naming the file, field and value.
pub fn run<I, T>(args: I, out: &mut dyn Write) -> anyhow::Result<()>
where
    I: IntoIterator<Item = T>,
    T: Into<OsString> + Clone,
{
    let cli = Cli::try_parse_from(args)?;
    let mut config = match &cli.config {
        Some(path) => MapStoreConfig::load(path)?,
        None => MapStoreConfig::default(),
    };
    if let Some(dir) = &cli.data_dir {
        config.data_dir = Some(dir.clone());
    }
    match cli.command {
        Command::Import {
            path,
            resolution,
            name,
            json,
            occupied_thresh,
            free_thresh,
            negate,
            scale_band,
        } => {
            let name = match name {
                Some(n) => MapName::new(n)?,
                None => name_from_path(&path)?,
            };
            let picture = if is_ros_yaml(&path) {
                None
            } else {
                let resolution_m = resolution.ok_or_else(|| {
                    anyhow!(
                        "invalid resolution = none: {} is a picture, pass --resolution <metres per pixel>",
                        path.display()
                    )
                })?;
                let mut p = PictureOptions::new(resolution_m);
                p.occupied_thresh = occupied_thresh;
                p.free_thresh = free_thresh;
                p.negate = negate;
                p.band = if scale_band {
                    MapMode::Scale
                } else {
                    MapMode::Trinary
                };
                p.validate()?;
                Some(p)
            };
            let store = open_store(&config)?;
            let spinner = spinner(&format!("importing {}", path.display()));
            let meta = import_into(&store, &name, &path, picture.as_ref(), &config.limits);
            spinner.finish_and_clear();
            let meta = meta?;
            if json {
                writeln!(out, "{}", serde_json::to_string_pretty(&meta)?)?;
            } else {
                print_meta(out, &meta)?;
            }
        }
        Command::Export {
            id_or_name,
            out: yaml,
            nav2_thresholds,
        } => {
            let store = open_store(&config)?;
            let map = store.find(&id_or_name)?;
            let opts = if nav2_thresholds {
                ExportOptions::nav2_map_saver()
            } else {
                ExportOptions::default()
            };
            let files = export_ros_map(&map.grid, &yaml, &opts)?;
            writeln!(
                out,
                "exported {} (version {}) to {} and {}",
                map.meta.id,
                map.meta.version,
                files.yaml.display(),
                files.image.display()
            )?;
        }
        Command::List { json } => {
            let store = open_store(&config)?;
            let maps = store.list()?;
            if json {
                writeln!(out, "{}", serde_json::to_string_pretty(&maps)?)?;
            } else if maps.is_empty() {
                writeln!(out, "no maps stored in {}", store.path().display())?;
            } else {
                writeln!(
                    out,
                    "{:<30} {:>7} {:>11} {:>8}  id",
                    "name", "version", "cells", "res (m)"
                )?;
                for m in &maps {
                    writeln!(
                        out,
                        "{:<30} {:>7} {:>11} {:>8}  {}",
                        m.name,
                        m.version,
                        format!("{}x{}", m.width_cells, m.height_cells),
                        m.resolution_m,
                        m.id
                    )?;
                }
            }
        }
        Command::Serve { site, zenoh } => {
            if let Some(site) = site {
                config.site = SiteId::new(site)?;
            }
            config.zenoh.override_with(&zenoh);
            let store = Arc::new(open_store(&config)?);
            let runtime = tokio::runtime::Builder::new_multi_thread()
                .enable_all()
                .build()
                .context("cannot start the async runtime")?;
            runtime.block_on(serve(&config, store, out))?;
        }
        Command::Bench {
            out: json_path,
            markdown: md_path,
            repeats,
        } => {
            let maps_dir = protocol::data_dirs::find_nav2_maps_dir(None)?;
            let bar = ProgressBar::new(BENCH_MAPS.len() as u64 + 1);
            bar.set_style(
                ProgressStyle::with_template("{bar:30} {pos}/{len} {msg}")
                    .unwrap_or_else(|_| ProgressStyle::default_bar()),
            );
            let report = run_bench(&maps_dir, repeats, |step| {
                bar.set_message(step.to_string());
                bar.inc(1);
            });
            bar.finish_and_clear();
            let report = report?;
            let table = markdown(&report);
            if let Some(p) = json_path {
                crate::export::write_atomic(&p, serde_json::to_string_pretty(&report)?.as_bytes())?;
            }
            if let Some(p) = md_path {
                crate::export::write_atomic(&p, table.as_bytes())?;
            }
            write!(out, "{table}")?;
        }
    }
    Ok(())
}

async fn serve(
    config: &MapStoreConfig,
    store: Arc<MapStore>,
    out: &mut dyn Write,
) -> anyhow::Result<()> {
    let session = config.zenoh.open().await?;
    let server = MapServer::start(&session, &config.site, store.clone()).await?;
    let names: Vec<String> = store
        .list()?
        .iter()
        .map(|m| format!("{}/{}", m.name, m.version))
        .collect();
    writeln!(
        out,
        "serving {} map versions on {} (listen {:?}, connect {:?}); Ctrl-C stops",
        names.len(),
        protocol::keys::map_queryable(&config.site),
        config.zenoh.listen,
        config.zenoh.connect
    )?;
    out.flush()?;
    tokio::signal::ctrl_c()
        .await
        .context("cannot wait for Ctrl-C")?;
    drop(server);
    session
        .close()
        .await
        .map_err(|e| anyhow!("cannot close the zenoh session: {e}"))?;
    Ok(())
}

fn open_store(config: &MapStoreConfig) -> anyhow::Result<MapStore> {
    let dir = match &config.data_dir {
        Some(d) => d.clone(),
        None => default_data_dir()?,
    };
    Ok(MapStore::open(&dir)?)
}

/// The per-user data directory of the map store.
///
/// # Errors
/// When the platform reports no home directory.
pub fn default_data_dir() -> anyhow::Result<PathBuf> {
    directories::ProjectDirs::from("org", "intention-fleet", "map-store")
        .map(|d| d.data_dir().to_path_buf())
        .ok_or_else(|| anyhow!("no home directory to put the map database in; pass --data-dir"))
}

fn spinner(msg: &str) -> ProgressBar {
    let s = ProgressBar::new_spinner();
    s.set_message(msg.to_string());
    s.enable_steady_tick(Duration::from_millis(100));
    s
}

fn print_meta(out: &mut dyn Write, m: &MapMeta) -> std::io::Result<()> {
    writeln!(out, "id:         {}", m.id)?;
    writeln!(out, "name:       {}", m.name)?;
    writeln!(out, "version:    {}", m.version)?;
    writeln!(out, "width:      {} cells", m.width_cells)?;
    writeln!(out, "height:     {} cells", m.height_cells)?;
    writeln!(out, "resolution: {} m/cell", m.resolution_m)?;
    writeln!(
        out,
        "origin:     x {} m, y {} m, yaw {} rad",
        m.origin.x_m, m.origin.y_m, m.origin.yaw_rad
    )?;
    writeln!(out, "free:       {}", m.free_cells)?;
    writeln!(out, "occupied:   {}", m.occupied_cells)?;
    writeln!(out, "unknown:    {}", m.unknown_cells)?;
    Ok(())
}

#[cfg(test)]
mod session_flag_tests {
    use super::*;
    use clap::CommandFactory;

    #[test]
    fn serve_takes_the_shared_zenoh_flags_with_the_old_names_kept() {
        Cli::command().debug_assert();
        let cli = Cli::try_parse_from([
            "map-store",
            "serve",
            "--listen",
            "tcp/0.0.0.0:7448",
            "--zenoh-connect",
            "tcp/10.0.0.2:7447",
        ])
        .unwrap();
        let Command::Serve { zenoh, .. } = cli.command else {
            unreachable!("parsed a serve command")
        };
        assert_eq!(zenoh.listen, ["tcp/0.0.0.0:7448"]);
        assert_eq!(zenoh.connect, ["tcp/10.0.0.2:7447"]);
        assert!(!zenoh.multicast_scouting, "multicast is off by default");
        let cli =
            Cli::try_parse_from(["map-store", "serve", "--zenoh-multicast-scouting"]).unwrap();
        let Command::Serve { zenoh, .. } = cli.command else {
            unreachable!("parsed a serve command")
        };
        assert!(zenoh.multicast_scouting);
    }
}
