//! Helpers of the planning crate's integration tests that drive a robot along answered paths.

#![allow(dead_code, clippy::unwrap_used)]

use protocol::{Pose2D, PoseEstimate};

/// A pose estimate on the depot map with no covariance, numbered `seq`.
pub fn estimate(pose: Pose2D, seq: u64) -> PoseEstimate {
    test_support::fixtures::pose_estimate("depot", pose, seq, Vec::new())
}

/// The point `d_m` along `path`, facing along its segment.
pub fn along(path: &[Pose2D], d_m: f64) -> Pose2D {
    planning::path::point_along(path, d_m).unwrap()
}
