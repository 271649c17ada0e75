//! Export of a grid back to ROS `map_server` format: a binary PGM (P5) and its YAML, written
//! the way Nav2's `map_saver` writes trinary maps.
//!
//! Pixels: unknown (and any value outside 0..=100) → 205; `cell <= rint(free_thresh * 100)` →
//! 254; `cell >= rint(occupied_thresh * 100)` → 0; anything in between → 205. Image row 0 is the
//! top of the map. The YAML holds `image` (the PGM's file name, relative to the YAML), `mode:
//! trinary`, `resolution`, `origin: [x, y, yaw]`, `negate: 0` and both thresholds.
//!
//! Thresholds: `map_saver` writes `free_thresh: 0.25` by default, but its own loader then reads
//! the unknown pixel 205 (occupancy `50/255 = 0.196`) as *free*, so unknown space would not
//! survive a round trip. The default here is therefore ROS 1 `map_saver`'s `free_thresh: 0.196`,
//! under which 205 stays unknown and import → export → import is exact for trinary maps;
//! [`ExportOptions::nav2_map_saver`] gives Nav2's 0.25 for byte-identical YAML.
//!
//! Both files are written atomically (temporary file in the same folder, fsync, rename), the
//! image first, so a reader never sees a YAML pointing at a half-written image.

use std::io::Write;
use std::path::{Path, PathBuf};

use crate::error::MapError;
use crate::grid::{OccupancyGrid, OCCUPIED};
use crate::ros::{Interpretation, MapMode};

/// Pixel value of an occupied cell.
pub const PIXEL_OCCUPIED: u8 = 0;
/// Pixel value of a free cell.
pub const PIXEL_FREE: u8 = 254;
/// Pixel value of an unknown cell.
pub const PIXEL_UNKNOWN: u8 = 205;

/// The thresholds written into the YAML and used to classify scale-valued cells.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExportOptions {
    pub occupied_thresh: f64,
    pub free_thresh: f64,
}

impl Default for ExportOptions {
    /// Thresholds under which the export re-imports exactly (see the module docs).
    fn default() -> Self {
        Self {
            occupied_thresh: 0.65,
            free_thresh: 0.196,
        }
    }
}

impl ExportOptions {
    /// Nav2 `map_saver`'s default thresholds (unknown cells re-import as free under them).
    #[must_use]
    pub fn nav2_map_saver() -> Self {
        Self {
            occupied_thresh: 0.65,
            free_thresh: 0.25,
        }
    }
}

/// The files an export wrote.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ExportedFiles {
    pub yaml: PathBuf,
    pub image: PathBuf,
}

/// The PGM pixel of each cell, top image row first.
#[must_use]
pub fn trinary_pixels(grid: &OccupancyGrid, opts: &ExportOptions) -> Vec<u8> {
    // rint() in map_saver rounds half to even.
    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
    let free_int = (opts.free_thresh * 100.0).round_ties_even() as u8;
    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
    let occ_int = (opts.occupied_thresh * 100.0).round_ties_even() as u8;
    let w = grid.width_cells() as usize;
    let h = grid.height_cells() as usize;
    let cells = grid.cells();
    let mut out = Vec::with_capacity(w * h);
    for row in (0..h).rev() {
        for &v in &cells[row * w..(row + 1) * w] {
            out.push(if v > OCCUPIED {
                PIXEL_UNKNOWN
            } else if v <= free_int {
                PIXEL_FREE
            } else if v >= occ_int {
                PIXEL_OCCUPIED
            } else {
                PIXEL_UNKNOWN
            });
        }
    }
    out
}

/// Writes `grid` as `<yaml_path>` plus a PGM beside it with the same stem.
///
/// # Errors
/// [`MapError::Invalid`] for bad thresholds or an output path without a file name,
/// [`MapError::Io`] naming the file that could not be written.
pub fn export_ros_map(
    grid: &OccupancyGrid,
    yaml_path: &Path,
    opts: &ExportOptions,
) -> Result<ExportedFiles, MapError> {
    Interpretation {
        mode: MapMode::Trinary,
        negate: false,
        occupied_thresh: opts.occupied_thresh,
        free_thresh: opts.free_thresh,
    }
    .validate()?;
    let stem = yaml_path
        .file_stem()
        .and_then(|s| s.to_str())
        .filter(|s| !s.is_empty())
        .ok_or_else(|| {
            MapError::invalid(
                "output",
                yaml_path.display(),
                "needs a file name such as map.yaml",
            )
        })?;
    let image_name = format!("{stem}.pgm");
    let image_path = yaml_path.with_file_name(&image_name);

    let mut pgm = format!("P5\n{} {}\n255\n", grid.width_cells(), grid.height_cells()).into_bytes();
    pgm.extend_from_slice(&trinary_pixels(grid, opts));
    write_atomic(&image_path, &pgm)?;

    let o = grid.origin();
    // `{:?}` prints the shortest text that parses back to the same f64.
    let yaml = format!(
        "image: {image}\nmode: trinary\nresolution: {res:?}\norigin: [{x:?}, {y:?}, {yaw:?}]\n\
         negate: 0\noccupied_thresh: {occ:?}\nfree_thresh: {free:?}\n",
        image = serde_json::to_string(&image_name).map_err(|e| MapError::invalid(
            "output",
            &image_name,
            e.to_string()
        ))?,
        res = grid.resolution_m(),
        x = o.x_m,
        y = o.y_m,
        yaw = o.yaw_rad,
        occ = opts.occupied_thresh,
        free = opts.free_thresh,
    );
    write_atomic(yaml_path, yaml.as_bytes())?;
    Ok(ExportedFiles {
        yaml: yaml_path.to_path_buf(),
        image: image_path,
    })
}

/// Writes `bytes` to a temporary file next to `path`, syncs it and renames it over `path`.
///
/// # Errors
/// [`MapError::Io`] naming the file.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), MapError> {
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let file_name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .ok_or_else(|| MapError::invalid("output", path.display(), "needs a file name"))?;
    let tmp = dir.join(format!(".{file_name}.tmp-{}", std::process::id()));
    let result = (|| {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        std::fs::rename(&tmp, path)
    })();
    result.map_err(|e| {
        // Best effort: a leftover temp file is harmless, the error below is what matters.
        let _ = std::fs::remove_file(&tmp);
        MapError::io(path, e)
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::{FREE, UNKNOWN};
    use crate::nav2_maps_dir;
    use crate::ros::{load_ros_map, ImportLimits};
    use protocol::Pose2D;

    fn round_trip(grid: &OccupancyGrid, opts: &ExportOptions) -> OccupancyGrid {
        let dir = tempfile::tempdir().unwrap();
        let yaml = dir.path().join("out.yaml");
        let files = export_ros_map(grid, &yaml, opts).unwrap();
        assert_eq!(files.image, dir.path().join("out.pgm"));
        load_ros_map(&yaml, &ImportLimits::default()).unwrap().grid
    }

    #[test]
    fn nav2_maps_round_trip_exactly() {
        for map in ["testmap", "depot", "tb3_sandbox", "warehouse"] {
            let yaml = nav2_maps_dir().join(format!("{map}.yaml"));
            let original = load_ros_map(&yaml, &ImportLimits::default()).unwrap().grid;
            let back = round_trip(&original, &ExportOptions::default());
            assert_eq!(back, original, "{map}");
        }
    }

    #[test]
    fn map_saver_pixels_and_yaml() {
        let o = Pose2D::new(-1.5, 2.25, 0.1);
        // Bottom row: free, occupied, unknown; top row: 25, 26, 65 (scale values).
        let g = OccupancyGrid::new(3, 2, 0.05, o, vec![FREE, 100, UNKNOWN, 25, 26, 65]).unwrap();
        let px = trinary_pixels(&g, &ExportOptions::nav2_map_saver());
        // Top image row first: 25 -> free, 26 -> in between, 65 -> occupied; then the bottom.
        assert_eq!(px, vec![254, 205, 0, 254, 0, 205]);
        let dir = tempfile::tempdir().unwrap();
        let yaml = dir.path().join("m.yaml");
        export_ros_map(&g, &yaml, &ExportOptions::nav2_map_saver()).unwrap();
        let text = std::fs::read_to_string(&yaml).unwrap();
        let doc: serde_yaml::Value = serde_yaml::from_str(&text).unwrap();
        assert_eq!(doc["image"].as_str(), Some("m.pgm"));
        assert_eq!(doc["mode"].as_str(), Some("trinary"));
        assert_eq!(doc["resolution"].as_f64(), Some(0.05));
        assert_eq!(doc["negate"].as_i64(), Some(0));
        assert_eq!(doc["occupied_thresh"].as_f64(), Some(0.65));
        assert_eq!(doc["free_thresh"].as_f64(), Some(0.25));
        let origin: Vec<f64> = doc["origin"]
            .as_sequence()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        assert_eq!(origin, vec![-1.5, 2.25, 0.1]);
        let pgm = std::fs::read(dir.path().join("m.pgm")).unwrap();
        assert!(pgm.starts_with(b"P5\n3 2\n255\n"));
        assert_eq!(&pgm[pgm.len() - 6..], px.as_slice());
        // No temporary files left behind.
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 2);
    }

    #[test]
    fn nav2_default_thresholds_lose_unknown_space() {
        // Why the default is 0.196: under map_saver's 0.25 the unknown pixel re-imports as free.
        let g = OccupancyGrid::new(2, 1, 0.1, Pose2D::default(), vec![UNKNOWN, 100]).unwrap();
        assert_eq!(round_trip(&g, &ExportOptions::default()), g);
        assert_eq!(
            round_trip(&g, &ExportOptions::nav2_map_saver()).cells(),
            &[FREE, 100]
        );
    }

    #[test]
    fn rejects_bad_thresholds_and_paths() {
        let g = OccupancyGrid::filled(2, 2, 0.1, Pose2D::default(), FREE).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let bad = ExportOptions {
            occupied_thresh: 0.2,
            free_thresh: 0.5,
        };
        let e = export_ros_map(&g, &dir.path().join("a.yaml"), &bad)
            .unwrap_err()
            .to_string();
        assert!(e.contains("free_thresh") && e.contains("0.5"), "{e}");
        let e = export_ros_map(
            &g,
            &dir.path().join("missing/a.yaml"),
            &ExportOptions::default(),
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("missing"), "{e}");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
    }
}
