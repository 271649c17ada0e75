//! Import of a plain floor-plan picture (PNG, JPEG, BMP, PGM: a scanned or exported visitor
//! plan) given its scale in metres per pixel.
//!
//! The picture is read like a ROS map image (same limits, same Nav2 pixel rules, see
//! [`crate::ros`]): occupancy is `1 - brightness` (or `brightness` with `negate`), a pixel is
//! occupied above `occupied_thresh` and free below `free_thresh`.
//!
//! The band between the thresholds is treated as **trinary by default: unknown**. Anti-aliased
//! wall edges, hatching and text on a plan are lighter than walls, so with thresholds that put
//! them below `free_thresh` they become free, and whatever grey is left in the band is at most
//! unknown, never a wall: a planner keeps clear of it (unknown counts as an obstacle for
//! planning) while AMCL's laser model, which only uses occupied cells, does not expect a wall
//! there. [`MapMode::Scale`] keeps in-band values as occupancy percentages instead.
//!
//! The defaults (`occupied_thresh` 0.65, `free_thresh` 0.25) follow Nav2's `map_saver`: pixels
//! darker than 89/255 are walls, lighter than 191/255 free. A plan with darker hatching or text
//! needs a higher `free_thresh` so the marks fall below it.

use std::path::Path;

use protocol::Pose2D;

use crate::error::MapError;
use crate::grid::OccupancyGrid;
use crate::ros::{occupancy_from_image, read_image, ImportLimits, Interpretation, MapMode};

/// How to read a floor-plan picture.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PictureOptions {
    /// Metres per pixel (the plan's scale).
    pub resolution_m: f64,
    pub occupied_thresh: f64,
    pub free_thresh: f64,
    /// Light walls on a dark background.
    pub negate: bool,
    /// Map-frame pose of the picture's lower-left pixel.
    pub origin: Pose2D,
    /// How the band between the thresholds is read: [`MapMode::Trinary`] (unknown, default) or
    /// [`MapMode::Scale`] (occupancy percentages); [`MapMode::Raw`] is refused for pictures.
    pub band: MapMode,
}

impl PictureOptions {
    /// Defaults for a picture at `resolution_m` metres per pixel.
    #[must_use]
    pub fn new(resolution_m: f64) -> Self {
        Self {
            resolution_m,
            occupied_thresh: 0.65,
            free_thresh: 0.25,
            negate: false,
            origin: Pose2D::new(0.0, 0.0, 0.0),
            band: MapMode::Trinary,
        }
    }

    fn interpretation(&self) -> Interpretation {
        Interpretation {
            mode: self.band,
            negate: self.negate,
            occupied_thresh: self.occupied_thresh,
            free_thresh: self.free_thresh,
        }
    }

    /// Checks resolution, thresholds, origin and band mode.
    ///
    /// # Errors
    /// [`MapError::Invalid`] naming the field and value.
    pub fn validate(&self) -> Result<(), MapError> {
        if !self.resolution_m.is_finite() || self.resolution_m <= 0.0 {
            return Err(MapError::invalid(
                "resolution",
                self.resolution_m,
                "must be a positive, finite number of metres per pixel",
            ));
        }
        if self.band == MapMode::Raw {
            return Err(MapError::invalid(
                "mode",
                "raw",
                "a picture has no raw occupancy values; use trinary or scale",
            ));
        }
        for (field, v) in [
            ("origin.x", self.origin.x_m),
            ("origin.y", self.origin.y_m),
            ("origin.yaw", self.origin.yaw_rad),
        ] {
            if !v.is_finite() {
                return Err(MapError::invalid(field, v, "must be finite"));
            }
        }
        self.interpretation().validate()
    }
}

/// Reads a floor-plan picture into a grid, one cell per pixel.
///
/// # Errors
/// [`MapError::Invalid`] for bad options (checked before the file is touched), then
/// [`MapError::Io`], [`MapError::TooLarge`] (refused from the header) or [`MapError::Image`].
pub fn import_picture(
    path: &Path,
    opts: &PictureOptions,
    limits: &ImportLimits,
) -> Result<OccupancyGrid, MapError> {
    opts.validate()?;
    let img = read_image(path, limits)?;
    let cells = occupancy_from_image(&img, &opts.interpretation());
    OccupancyGrid::new(
        img.width(),
        img.height(),
        opts.resolution_m,
        opts.origin,
        cells,
    )
}
