//! Test-only world for AMCL: the ground truth is a real Nav2 map plus unmapped obstacles
//! (furniture boxes, people discs) that the localizer's map lacks; a ray caster produces noisy
//! laser scans on the truth, and the four-alpha model produces drifting, noisy odometry.
//!
//! Shared by `tests/amcl.rs` and `benches/amcl.rs` (included by path); not part of the library.

#![allow(dead_code)]

use map_core::{CellClass, OccupancyGrid, OCCUPIED};
use protocol::{normalize_angle, Header, LaserScan, Odometry, Pose2D};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

pub use test_support::nav2_map as load_nav2;

/// Marks a rotated rectangle (centre, size, yaw) occupied.
pub fn add_box(grid: &mut OccupancyGrid, cx_m: f64, cy_m: f64, w_m: f64, h_m: f64, yaw_rad: f64) {
    let r = grid.resolution_m();
    let half_diag = 0.5 * w_m.hypot(h_m);
    let (s, c) = yaw_rad.sin_cos();
    let n = (half_diag / r).ceil() as i64 + 1;
    let (ccx, ccy) = grid.world_to_cell(cx_m, cy_m);
    for dy in -n..=n {
        for dx in -n..=n {
            let (x, y) = grid.cell_to_world(ccx + dx, ccy + dy);
            let (lx, ly) = (
                c * (x - cx_m) + s * (y - cy_m),
                -s * (x - cx_m) + c * (y - cy_m),
            );
            if lx.abs() <= 0.5 * w_m && ly.abs() <= 0.5 * h_m {
                grid.set(ccx + dx, ccy + dy, OCCUPIED);
            }
        }
    }
}

/// Marks a disc (a standing person seen at leg height is about 0.2-0.3 m across) occupied.
pub fn add_disc(grid: &mut OccupancyGrid, cx_m: f64, cy_m: f64, radius_m: f64) {
    let n = (radius_m / grid.resolution_m()).ceil() as i64 + 1;
    let (ccx, ccy) = grid.world_to_cell(cx_m, cy_m);
    for dy in -n..=n {
        for dx in -n..=n {
            let (x, y) = grid.cell_to_world(ccx + dx, ccy + dy);
            if (x - cx_m).hypot(y - cy_m) <= radius_m {
                grid.set(ccx + dx, ccy + dy, OCCUPIED);
            }
        }
    }
}

/// A planar laser: 181 beams over 270 degrees, 12 m, Gaussian range noise.
#[derive(Debug, Clone, Copy)]
pub struct Laser {
    pub beams: usize,
    pub angle_min_rad: f64,
    pub angle_increment_rad: f64,
    pub range_min_m: f64,
    pub range_max_m: f64,
    pub noise_std_m: f64,
}

impl Default for Laser {
    fn default() -> Self {
        let fov = 270f64.to_radians();
        Self {
            beams: 181,
            angle_min_rad: -0.5 * fov,
            angle_increment_rad: fov / 180.0,
            range_min_m: 0.05,
            range_max_m: 12.0,
            noise_std_m: 0.03,
        }
    }
}

/// Distance along a ray to the first occupied cell of `grid`, or `None` within `max_m`.
pub fn cast_ray(
    grid: &OccupancyGrid,
    x_m: f64,
    y_m: f64,
    angle_rad: f64,
    max_m: f64,
) -> Option<f64> {
    // Steps of a quarter cell: exact enough for a test, and simple to trust.
    let step = 0.25 * grid.resolution_m();
    let (s, c) = angle_rad.sin_cos();
    let mut t = 0.0;
    while t < max_m {
        let (cx, cy) = grid.world_to_cell(x_m + t * c, y_m + t * s);
        if !grid.contains(cx, cy) {
            return None;
        }
        if grid.class_at(cx, cy) == CellClass::Occupied {
            return Some(t);
        }
        t += step;
    }
    None
}

impl Laser {
    /// A scan from a laser at `pose` (map frame) on `grid`, with range noise.
    pub fn scan(
        &self,
        grid: &OccupancyGrid,
        pose: &Pose2D,
        seq: u64,
        rng: &mut ChaCha8Rng,
    ) -> LaserScan {
        let ranges_m = (0..self.beams)
            .map(|i| {
                let a = pose.yaw_rad + self.angle_min_rad + i as f64 * self.angle_increment_rad;
                match cast_ray(grid, pose.x_m, pose.y_m, a, self.range_max_m) {
                    Some(r) => {
                        let n: f64 = rng.sample(StandardNormal);
                        let noisy = (r + self.noise_std_m * n).max(self.range_min_m);
                        if noisy >= self.range_max_m {
                            self.range_max_m as f32
                        } else {
                            noisy as f32
                        }
                    }
                    None => self.range_max_m as f32,
                }
            })
            .collect();
        LaserScan {
            header: Header::new(seq, seq * 100_000_000),
            angle_min_rad: self.angle_min_rad as f32,
            angle_increment_rad: self.angle_increment_rad as f32,
            range_min_m: self.range_min_m as f32,
            range_max_m: self.range_max_m as f32,
            ranges_m,
        }
    }
}

/// True poses along a polyline: turn on the spot towards the next waypoint, then drive; 10 Hz at
/// `speed_mps` and `turn_radps`.
pub fn drive(
    waypoints: &[(f64, f64)],
    start_yaw_rad: f64,
    speed_mps: f64,
    turn_radps: f64,
) -> Vec<Pose2D> {
    let dt = 0.1;
    let mut pose = Pose2D::new(waypoints[0].0, waypoints[0].1, start_yaw_rad);
    let mut out = vec![pose];
    for &(gx, gy) in &waypoints[1..] {
        loop {
            let dx = gx - pose.x_m;
            let dy = gy - pose.y_m;
            let dist = dx.hypot(dy);
            if dist < 1e-6 {
                break;
            }
            let err = normalize_angle(dy.atan2(dx) - pose.yaw_rad);
            if err.abs() > 0.05 {
                pose.yaw_rad =
                    normalize_angle(pose.yaw_rad + err.clamp(-turn_radps * dt, turn_radps * dt));
            } else {
                pose.yaw_rad = dy.atan2(dx);
                let step = dist.min(speed_mps * dt);
                pose.x_m += step * pose.yaw_rad.cos();
                pose.y_m += step * pose.yaw_rad.sin();
            }
            out.push(pose);
        }
    }
    out
}

/// Wheel odometry that measures each true motion with four-alpha noise and integrates it in
/// its own frame (starting at the odom origin, not at the map pose), so it drifts.
pub struct OdometrySim {
    pub alphas: [f64; 4],
    pose: Pose2D,
    seq: u64,
}

impl OdometrySim {
    pub fn new(alphas: [f64; 4]) -> Self {
        Self {
            alphas,
            pose: Pose2D::new(0.0, 0.0, 0.0),
            seq: 0,
        }
    }

    /// Current reading.
    pub fn reading(&self) -> Odometry {
        Odometry {
            header: Header::new(self.seq, self.seq * 100_000_000),
            pose: self.pose,
            v_mps: 0.0,
            omega_radps: 0.0,
        }
    }

    /// Integrates a noisy measurement of the true motion `from` -> `to`.
    pub fn step(&mut self, from: &Pose2D, to: &Pose2D, rng: &mut ChaCha8Rng) -> Odometry {
        let dx = to.x_m - from.x_m;
        let dy = to.y_m - from.y_m;
        let trans = dx.hypot(dy);
        let rot1 = if trans < 1e-9 {
            0.0
        } else {
            normalize_angle(dy.atan2(dx) - from.yaw_rad)
        };
        let rot2 = normalize_angle(to.yaw_rad - from.yaw_rad - rot1);
        let [a1, a2, a3, a4] = self.alphas;
        let mut g = |var: f64| -> f64 {
            let n: f64 = rng.sample(StandardNormal);
            var.max(0.0).sqrt() * n
        };
        let r1 = rot1 + g(a1 * rot1 * rot1 + a2 * trans * trans);
        let t = trans + g(a3 * trans * trans + a4 * (rot1 * rot1 + rot2 * rot2));
        let r2 = rot2 + g(a1 * rot2 * rot2 + a2 * trans * trans);
        let heading = self.pose.yaw_rad + r1;
        self.pose.x_m += t * heading.cos();
        self.pose.y_m += t * heading.sin();
        self.pose.yaw_rad = normalize_angle(heading + r2);
        self.seq += 1;
        self.reading()
    }
}

/// The depot with unmapped furniture and people, and the map AMCL is given.
pub fn depot_world() -> (OccupancyGrid, OccupancyGrid) {
    let map = load_nav2("depot");
    let mut truth = map.clone();
    add_box(&mut truth, 3.5, 5.0, 0.8, 0.6, 0.3);
    add_box(&mut truth, 9.5, 11.0, 1.2, 0.5, 0.0);
    add_box(&mut truth, 13.5, 5.5, 0.6, 0.6, 0.7);
    add_disc(&mut truth, 8.0, 8.5, 0.15);
    add_disc(&mut truth, 10.0, 6.4, 0.15);
    add_disc(&mut truth, 3.9, 8.6, 0.15);
    add_disc(&mut truth, 13.2, 8.6, 0.15);
    (map, truth)
}

/// The Turtlebot3 sandbox with an unmapped box and people.
pub fn sandbox_world() -> (OccupancyGrid, OccupancyGrid) {
    let map = load_nav2("tb3_sandbox");
    let mut truth = map.clone();
    add_box(&mut truth, -2.3, -0.2, 0.4, 0.4, 0.4);
    add_disc(&mut truth, -0.5, 1.75, 0.15);
    add_disc(&mut truth, 1.9, -1.0, 0.15);
    (map, truth)
}
