//! Message fixtures: an intention along a path, or a pose estimate, the way controller and
//! planner tests and benchmarks feed one, without writing every field of the wire message again.

use protocol::{Dlm, Header, Image, Intention, MapName, MapRef, Pose2D, PoseEstimate};

/// Version 1 of the map `name`.
#[must_use]
pub fn map_ref(name: &str) -> MapRef {
    MapRef {
        name: MapName::new(name).expect("a valid map name"),
        version: 1,
    }
}

/// A pose estimate numbered `seq` (stamped 1000 + `seq` ns) on version 1 of map `map`, with no
/// covariance and the agent reporting `unmapped_obstacles_m` (map frame).
#[must_use]
pub fn pose_estimate(
    map: &str,
    pose: Pose2D,
    seq: u64,
    unmapped_obstacles_m: Vec<[f64; 2]>,
) -> PoseEstimate {
    PoseEstimate {
        header: Header::new(seq, 1_000 + seq),
        pose,
        covariance: [0.0; 9],
        sensor_stamp_ns: 1_000 + seq,
        map: map_ref(map),
        unmapped_obstacles_m,
    }
}

/// An intention to follow `path` with `dlm` on map `test` (no task, no LPE image, header and
/// answered pose zero); override fields with struct update syntax where a test cares.
#[must_use]
pub fn intention(path: Vec<Pose2D>, dlm: Dlm) -> Intention {
    Intention {
        header: Header::default(),
        task_id: None,
        goal_index: 0,
        answers_pose_seq: 0,
        answers_pose_stamp_ns: 0,
        map: map_ref("test"),
        path,
        dlm,
        arriving: false,
        lpe: None,
    }
}

/// An intention that carries only a DLM and maybe an LPE image (what a network reads).
#[must_use]
pub fn intention_for_net(dlm: Dlm, lpe: Option<Image>) -> Intention {
    Intention {
        lpe,
        ..intention(Vec::new(), dlm)
    }
}

/// A straight path from `(x0, y0)` along `yaw_rad`, one pose every `step_m` for `len_m`.
#[must_use]
pub fn straight_path(x0: f64, y0: f64, yaw_rad: f64, len_m: f64, step_m: f64) -> Vec<Pose2D> {
    let n = (len_m / step_m).round().max(0.0) as usize;
    let (s, c) = yaw_rad.sin_cos();
    (0..=n)
        .map(|i| {
            let d = i as f64 * step_m;
            Pose2D::new(x0 + c * d, y0 + s * d, yaw_rad)
        })
        .collect()
}

/// A path through `points` in straight pieces, a pose every `step_m` at most along each (its
/// yaw the piece's direction) and one on the last point, facing along the last piece.
#[must_use]
pub fn polyline(points: &[(f64, f64)], step_m: f64) -> Vec<Pose2D> {
    let mut out = Vec::new();
    for w in points.windows(2) {
        let ((ax, ay), (bx, by)) = (w[0], w[1]);
        let yaw = (by - ay).atan2(bx - ax);
        let n = ((bx - ax).hypot(by - ay) / step_m).ceil().max(1.0) as usize;
        for i in 0..n {
            let f = i as f64 / n as f64;
            out.push(Pose2D::new(ax + f * (bx - ax), ay + f * (by - ay), yaw));
        }
    }
    if let Some(&(x, y)) = points.last() {
        let yaw = out.last().map_or(0.0, |p| p.yaw_rad);
        out.push(Pose2D::new(x, y, yaw));
    }
    out
}

/// A path from the origin (heading +x) that swings out to the left, `reach_m` at most, and comes
/// back to a goal 1 m straight ahead: the shape of a planner's loop round a goal too close to
/// turn into.
#[must_use]
pub fn loop_path(reach_m: f64) -> Vec<Pose2D> {
    (0..=30)
        .map(|i| {
            let a = std::f64::consts::PI * f64::from(i) / 30.0;
            Pose2D::new(0.5 - 0.5 * a.cos(), reach_m * a.sin(), a)
        })
        .collect()
}
