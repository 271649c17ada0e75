//! One entry point for importing a file into the store, whatever its kind: a ROS map YAML
//! (`.yaml`/`.yml`) or a floor-plan picture (anything else, which needs a scale).
//!
//! The file is read and validated completely before the store is touched, so a failed import
//! stores nothing.

use std::path::Path;

use protocol::ids::MAX_MAP_NAME_LEN;
use protocol::{MapMeta, MapName};

use crate::error::MapError;
use crate::grid::OccupancyGrid;
use crate::picture::{import_picture, PictureOptions};
use crate::ros::{load_ros_map, ImportLimits};
use crate::store::{MapSource, MapStore, SourceKind};

/// A file read into a grid, with a description of where it came from.
#[derive(Debug, Clone)]
pub struct Imported {
    pub grid: OccupancyGrid,
    pub source: MapSource,
}

/// Whether `path` names a ROS map description rather than a picture.
#[must_use]
pub fn is_ros_yaml(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("yaml") || e.eq_ignore_ascii_case("yml"))
}

/// Reads a ROS map YAML, or a picture with `picture` options (required for pictures).
///
/// # Errors
/// Every [`MapError`] of [`load_ros_map`] and [`import_picture`]; [`MapError::Invalid`] on
/// `resolution` when a picture comes without options.
pub fn import_file(
    path: &Path,
    picture: Option<&PictureOptions>,
    limits: &ImportLimits,
) -> Result<Imported, MapError> {
    if is_ros_yaml(path) {
        let map = load_ros_map(path, limits)?;
        let i = &map.interpretation;
        let note = format!(
            "ROS map, mode {}, negate {}, occupied_thresh {}, free_thresh {}, image {}",
            i.mode.as_str(),
            u8::from(i.negate),
            i.occupied_thresh,
            i.free_thresh,
            map.image_path.display()
        );
        return Ok(Imported {
            grid: map.grid,
            source: MapSource::new(SourceKind::RosMap, Some(path), note),
        });
    }
    let opts = picture.ok_or_else(|| {
        MapError::invalid(
            "resolution",
            "none",
            format!(
                "{} is a picture: give its scale in metres per pixel",
                path.display()
            ),
        )
    })?;
    let grid = import_picture(path, opts, limits)?;
    let note = format!(
        "picture, {} m/px, band {}, negate {}, occupied_thresh {}, free_thresh {}",
        opts.resolution_m,
        opts.band.as_str(),
        u8::from(opts.negate),
        opts.occupied_thresh,
        opts.free_thresh
    );
    Ok(Imported {
        grid,
        source: MapSource::new(SourceKind::Picture, Some(path), note),
    })
}

/// Imports `path` and stores it as the next version of `name`.
///
/// # Errors
/// As [`import_file`] and [`MapStore::put`]; on any error nothing is stored.
pub fn import_into(
    store: &MapStore,
    name: &MapName,
    path: &Path,
    picture: Option<&PictureOptions>,
    limits: &ImportLimits,
) -> Result<MapMeta, MapError> {
    let imported = import_file(path, picture, limits)?;
    store.put(name, &imported.grid, &imported.source)
}

/// A valid map name from a file name: the stem with every character outside
/// `[A-Za-z0-9_.-]` replaced by `_`, leading dots dropped, cut to the name length limit.
///
/// # Errors
/// [`MapError::Invalid`] on `name` if nothing usable is left (e.g. `.yaml`).
pub fn name_from_path(path: &Path) -> Result<MapName, MapError> {
    let stem = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let cleaned: String = stem
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || matches!(c, '_' | '.' | '-') {
                c
            } else {
                '_'
            }
        })
        .collect();
    let trimmed: String = cleaned
        .trim_start_matches('.')
        .chars()
        .take(MAX_MAP_NAME_LEN)
        .collect();
    MapName::new(trimmed).map_err(|e| {
        MapError::invalid(
            "name",
            path.display(),
            format!("cannot derive a map name: {e}; pass --name"),
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_from_paths() {
        let n = |p: &str| name_from_path(Path::new(p)).map(|n| n.to_string());
        assert_eq!(n("/x/depot.yaml").unwrap(), "depot");
        assert_eq!(n("Floor plan (3rd).png").unwrap(), "Floor_plan__3rd_");
        assert_eq!(n("..hidden.v2.png").unwrap(), "hidden.v2");
        assert_eq!(
            n(&format!("{}.png", "a".repeat(80))).unwrap().len(),
            MAX_MAP_NAME_LEN
        );
        assert_eq!(n("/maps/.yaml").unwrap(), "yaml");
        let e = n("/maps/..").unwrap_err().to_string();
        assert!(e.contains("name") && e.contains("/maps/.."), "{e}");
    }

    #[test]
    fn picture_without_scale_is_refused() {
        let e = import_file(Path::new("plan.png"), None, &ImportLimits::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("resolution") && e.contains("plan.png"), "{e}");
    }
}
