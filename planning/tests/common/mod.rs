//! Helpers of the planning crate's integration tests that drive a robot along answered paths.

#![allow(dead_code, clippy::unwrap_used)]

use protocol::{Header, MapName, MapRef, Pose2D, PoseEstimate};

/// A pose estimate on the depot map with no covariance, numbered `seq`.
pub fn estimate(pose: Pose2D, seq: u64) -> PoseEstimate {
    PoseEstimate {
        header: Header::new(seq, 1_000 + seq),
        pose,
        covariance: [0.0; 9],
        sensor_stamp_ns: 1_000 + seq,
        map: MapRef {
            name: MapName::new("depot").unwrap(),
            version: 1,
        },
        unmapped_obstacles_m: Vec::new(),
    }
}

/// The point `d_m` along `path`, facing along its segment.
pub fn along(path: &[Pose2D], d_m: f64) -> Pose2D {
    planning::path::point_along(path, d_m).unwrap()
}
