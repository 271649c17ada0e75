//! The physical ranges of every number the API accepts, checked before anything is stored.
//!
//! Out of range is a client fault (`400`, the field and value named). The OpenAPI document
//! publishes the same bounds as `minimum`/`maximum` ([`super::openapi`] reads these
//! constants), so a client generated from it never sends what the server refuses.
//!
//! | what | range |
//! |---|---|
//! | map-frame coordinates (goals, map origin, every corner of a map) | `|x|, |y| ≤ 100 km` |
//! | angles (goal `yaw_rad`, map origin yaw) | `[-2π, 2π]` rad |
//! | map resolution | `[0.001, 10]` m per cell |

use std::f64::consts::TAU;

use map_store::OccupancyGrid;
use planning::Goal;

use super::error::ApiError;

/// Largest `|x|` or `|y|` of a map-frame point, in metres (100 km: a campus, not a planet).
pub const MAX_COORDINATE_M: f64 = 100_000.0;

/// Largest `|yaw|` accepted, in radians (one turn either way; not normalised, refused beyond).
pub const MAX_ABS_YAW_RAD: f64 = TAU;

/// Finest map resolution accepted, in metres per cell.
pub const MIN_RESOLUTION_M: f64 = 0.001;

/// Coarsest map resolution accepted, in metres per cell.
pub const MAX_RESOLUTION_M: f64 = 10.0;

/// A number as a reason shows it: plain when short, in exponent form when huge or tiny (Rust
/// prints `1e300` with 301 digits otherwise).
#[must_use]
pub fn show(value: f64) -> String {
    let a = value.abs();
    if a != 0.0 && a.is_finite() && !(1e-4..1e9).contains(&a) {
        format!("{value:e}")
    } else {
        format!("{value}")
    }
}

/// Checks that `value` is finite and within `[min, max]`.
///
/// # Errors
/// `400` naming `field`, the value and the range with its `unit`.
pub fn within(field: &str, value: f64, min: f64, max: f64, unit: &str) -> Result<f64, ApiError> {
    if value.is_finite() && (min..=max).contains(&value) {
        Ok(value)
    } else {
        Err(ApiError::bad_request(format!(
            "invalid {field} = {}: must be a finite number within [{}, {}] {unit}",
            show(value),
            show(min),
            show(max)
        )))
    }
}

/// A map-frame coordinate in metres.
///
/// # Errors
/// As [`within`].
pub fn coordinate(field: &str, value: f64) -> Result<f64, ApiError> {
    within(field, value, -MAX_COORDINATE_M, MAX_COORDINATE_M, "m")
}

/// An angle in radians.
///
/// # Errors
/// As [`within`].
pub fn yaw(field: &str, value: f64) -> Result<f64, ApiError> {
    within(field, value, -MAX_ABS_YAW_RAD, MAX_ABS_YAW_RAD, "rad")
}

/// A map resolution in metres per cell.
///
/// # Errors
/// As [`within`].
pub fn resolution(field: &str, value: f64) -> Result<f64, ApiError> {
    within(
        field,
        value,
        MIN_RESOLUTION_M,
        MAX_RESOLUTION_M,
        "m per cell",
    )
}

/// Every goal of a new task: coordinates and (when given) heading.
///
/// # Errors
/// `400` naming the first bad field, e.g. `goals[2].yaw_rad`.
pub fn goals(goals: &[Goal]) -> Result<(), ApiError> {
    for (i, g) in goals.iter().enumerate() {
        coordinate(&format!("goals[{i}].x_m"), g.x_m)?;
        coordinate(&format!("goals[{i}].y_m"), g.y_m)?;
        if let Some(y) = g.yaw_rad {
            yaw(&format!("goals[{i}].yaw_rad"), y)?;
        }
    }
    Ok(())
}

/// An imported map's placement: resolution, origin, and every corner of the grid inside the
/// coordinate range (so every point on the map is a valid goal).
///
/// # Errors
/// `400` naming the field (`resolution`, `origin.x_m`, …, `extent`).
pub fn map_geometry(grid: &OccupancyGrid) -> Result<(), ApiError> {
    resolution("resolution", grid.resolution_m())?;
    let origin = grid.origin();
    coordinate("origin.x_m", origin.x_m)?;
    coordinate("origin.y_m", origin.y_m)?;
    yaw("origin.yaw_rad", origin.yaw_rad)?;
    let (w, h) = (
        f64::from(grid.width_cells()),
        f64::from(grid.height_cells()),
    );
    for (gx, gy) in [(w, 0.0), (0.0, h), (w, h)] {
        let (x, y) = grid.geometry().grid_to_world(gx, gy);
        if !(x.abs() <= MAX_COORDINATE_M && y.abs() <= MAX_COORDINATE_M) {
            return Err(ApiError::bad_request(format!(
                "invalid extent: the map ({} x {} cells of {} m from origin ({}, {})) reaches ({}, {}), outside ±{} m",
                grid.width_cells(),
                grid.height_cells(),
                show(grid.resolution_m()),
                show(origin.x_m),
                show(origin.y_m),
                show(x),
                show(y),
                show(MAX_COORDINATE_M)
            )));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use protocol::Pose2D;

    #[test]
    fn numbers_show_short() {
        assert_eq!(show(1e300), "1e300");
        assert_eq!(show(-2.5e301), "-2.5e301");
        assert_eq!(show(1e-300), "1e-300");
        assert_eq!(show(0.05), "0.05");
        assert_eq!(show(0.0), "0");
        assert_eq!(show(100_000.0), "100000");
        assert_eq!(show(f64::NAN), "NaN");
    }

    #[test]
    fn ranges_name_field_and_value() {
        assert!(yaw("goals[0].yaw_rad", 3.0).is_ok());
        let e = yaw("goals[0].yaw_rad", 1e300).unwrap_err();
        assert_eq!(e.status, axum::http::StatusCode::BAD_REQUEST);
        assert!(
            e.reason.contains("goals[0].yaw_rad = 1e300"),
            "{}",
            e.reason
        );
        assert!(coordinate("x_m", f64::INFINITY).is_err());
        assert!(coordinate("x_m", -100_000.0).is_ok());
        assert!(resolution("resolution", 1e-300).is_err());
        assert!(resolution("resolution", 0.05).is_ok());
        let g = [Goal::at(1.0, 2.0), Goal::at(2.5e301, 0.0)];
        let e = goals(&g).unwrap_err();
        assert!(e.reason.contains("goals[1].x_m = 2.5e301"), "{}", e.reason);
    }

    #[test]
    fn map_corners_must_stay_in_range() {
        let grid = |res: f64, origin: Pose2D| {
            OccupancyGrid::new(10, 10, res, origin, vec![0; 100]).unwrap_or_else(|e| panic!("{e}"))
        };
        assert!(map_geometry(&grid(0.05, Pose2D::new(-3.0, 2.0, 0.5))).is_ok());
        let e = map_geometry(&grid(0.05, Pose2D::new(1e308, 0.0, 0.0))).unwrap_err();
        assert!(e.reason.contains("origin.x_m = 1e308"), "{}", e.reason);
        let e = map_geometry(&grid(10.0, Pose2D::new(99_990.0, 0.0, 0.0))).unwrap_err();
        assert!(e.reason.contains("extent"), "{}", e.reason);
        let e = map_geometry(&grid(0.05, Pose2D::new(0.0, 0.0, 7.0))).unwrap_err();
        assert!(e.reason.contains("origin.yaw_rad = 7"), "{}", e.reason);
    }
}
