//! The collision monitor: the last check between any controller and the base, on the laser
//! scan (Nav2's `collision_monitor` in its "approach" model).
//!
//! A learned controller sees the world through a camera and can misjudge a chair it has never
//! seen; the dynamic window sees it with the laser. The monitor follows the commanded (v, ω) arc
//! forward in time and, when the robot's disc (plus a margin) would reach a scan point sooner
//! than `time_before_collision_s`, scales the speed down so that it reaches it no sooner than
//! that. Repeated every cycle, the robot slows smoothly and comes to rest short of the obstacle.
//! The turn rate is left as commanded: turning does not move a disc's footprint, so the
//! controller can still steer away or round the obstacle, and the tighter arc this gives at the
//! lower speed is checked in turn. The monitor never adds speed.
//!
//! A point already inside the margin (range noise, a person stepping close) does not freeze the
//! robot: only motion that brings the disc closer to it than it is now counts as a collision.
//! In the inner half of the margin that holds point by point, so that range noise cannot
//! ratchet the robot in, scan by scan.
//!
//! People walk. The returns of a tracked body walking across the robot's heading
//! ([`crate::movers`]) are moved on by that motion as the monitor looks ahead, so that someone
//! crossing the robot's way is braked for where they will be, not where they are
//! (`track_movers`; traced: a robot at 0.7 m/s braked a cycle too late for a person walking
//! diagonally across its path). Motion along the heading is left out ([`moving_bodies`]).
//! Glass is invisible to a laser, so the monitor cannot help there; the camera must.
//!
//! Plain data in, a verdict out; the [`Supervisor`](crate::Supervisor) applies it.

use protocol::{LaserScan, Pose2D};

use crate::config::ConfigError;
use crate::controllers::dynamic_window::arc_pose;
use crate::controllers::path_tracker::{check_non_negative, check_positive};
use crate::controllers::scan_points;
use crate::movers::{Track, MIN_WALKING_MPS};

/// How much closer than now the disc may come to a point already inside the margin: floating
/// point rounding, no more.
const ROUNDING_M: f64 = 1e-3;

/// The `[safety.collision_monitor]` table.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CollisionMonitorConfig {
    /// Off: the controller's command goes to the base unchecked (as the paper's robot drove).
    pub enabled: bool,
    /// Radius of the robot's disc footprint.
    pub robot_radius_m: f64,
    /// Gap to keep between the disc and any scan point.
    pub margin_m: f64,
    /// The command is slowed so that a collision is never nearer than this in time.
    pub time_before_collision_s: f64,
    /// Time step of the forward simulation along the commanded arc.
    pub simulation_step_s: f64,
    /// Moves the returns of each body walking across the robot's heading on by that motion
    /// (tracked) in the forward simulation; off, every return stands still.
    pub track_movers: bool,
}

impl Default for CollisionMonitorConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            robot_radius_m: 0.25,
            margin_m: 0.05,
            time_before_collision_s: 1.2,
            simulation_step_s: 0.05,
            track_movers: true,
        }
    }
}

impl CollisionMonitorConfig {
    /// Checks ranges that serde cannot express.
    ///
    /// # Errors
    /// [`ConfigError::Invalid`] naming the first bad field and its value.
    pub fn validate(&self) -> Result<(), ConfigError> {
        check_positive(&[
            (
                "safety.collision_monitor.robot_radius_m",
                self.robot_radius_m,
            ),
            (
                "safety.collision_monitor.time_before_collision_s",
                self.time_before_collision_s,
            ),
            (
                "safety.collision_monitor.simulation_step_s",
                self.simulation_step_s,
            ),
        ])?;
        check_non_negative(&[("safety.collision_monitor.margin_m", self.margin_m)])?;
        if self.simulation_step_s > self.time_before_collision_s {
            return Err(ConfigError::Invalid {
                field: "safety.collision_monitor.simulation_step_s",
                value: self.simulation_step_s.to_string(),
                reason: "must not exceed time_before_collision_s",
            });
        }
        Ok(())
    }
}

/// What the monitor did to one command.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Verdict {
    pub v_mps: f64,
    pub omega_radps: f64,
    /// The factor the speed was multiplied by (1: passed unchanged, 0: turning in place).
    pub scale: f64,
    /// When the commanded arc would first bring the disc too close, if within the horizon.
    pub time_to_collision_s: Option<f64>,
}

impl Verdict {
    /// Whether the command was changed.
    #[must_use]
    pub fn limited(&self) -> bool {
        self.scale < 1.0
    }
}

/// A walking body in the scan's frame: the returns within `reach_m` of (`x_m`, `y_m`) move
/// with (`vx_mps`, `vy_mps`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MovingBody {
    pub x_m: f64,
    pub y_m: f64,
    pub reach_m: f64,
    pub vx_mps: f64,
    pub vy_mps: f64,
}

/// A body's returns reach this much beyond the farthest one tracked this cycle.
const BODY_SLACK_M: f64 = 0.1;

/// The settled `tracks` (map frame) that walk across the robot's heading, in the frame of a
/// scan taken at `map_from_scan`, with their motion across it only.
///
/// Motion along the heading is left out. Someone coming head-on is met as before: the
/// controller steers round what the scan shows and the person steps aside. Braking for where
/// they would be stopped the robot early, before them, at a spot where neither could pass
/// (traced, task B seed 2: held for 9 s). Someone walking ahead is followed as before, without
/// counting on them walking on.
#[must_use]
pub fn moving_bodies(tracks: &[Track], map_from_scan: Pose2D) -> Vec<MovingBody> {
    let (s, c) = map_from_scan.yaw_rad.sin_cos();
    tracks
        .iter()
        .filter(|t| t.settled())
        .filter_map(|t| {
            let (dx, dy) = (t.x_m - map_from_scan.x_m, t.y_m - map_from_scan.y_m);
            let across_mps = -s * t.vx_mps + c * t.vy_mps;
            (across_mps.abs() >= MIN_WALKING_MPS).then(|| MovingBody {
                x_m: c * dx + s * dy,
                y_m: -s * dx + c * dy,
                reach_m: t.extent_m() + BODY_SLACK_M,
                vx_mps: 0.0,
                vy_mps: across_mps,
            })
        })
        .collect()
}

/// Checks the command (v, ω) against `scan` (robot frame, the laser at the robot's centre).
/// Only the speed is scaled: a disc turning sweeps nothing, and the tighter arc that the full
/// turn rate gives at the lower speed is checked again, so that the robot keeps turning the way
/// its controller steers, away from the obstacle or round it. The returns of `movers` move on
/// with them (when `track_movers` is on).
#[must_use]
pub fn check(
    config: &CollisionMonitorConfig,
    scan: &LaserScan,
    movers: &[MovingBody],
    v_mps: f64,
    omega_radps: f64,
) -> Verdict {
    let movers = if config.track_movers { movers } else { &[] };
    let (mut v, mut time_to_collision_s) = (v_mps, None);
    let mut safe = false;
    for _ in 0..5 {
        let arc = check_arc(config, scan, movers, v, omega_radps);
        time_to_collision_s = time_to_collision_s.or(arc.time_to_collision_s);
        if !arc.limited() {
            safe = true;
            break;
        }
        v = arc.v_mps;
    }
    if !safe {
        // Still closing in on something: turn in place, which cannot.
        v = 0.0;
    }
    Verdict {
        v_mps: v,
        omega_radps,
        scale: if v_mps.abs() < 1e-12 { 1.0 } else { v / v_mps },
        time_to_collision_s,
    }
}

fn check_arc(
    config: &CollisionMonitorConfig,
    scan: &LaserScan,
    movers: &[MovingBody],
    v_mps: f64,
    omega_radps: f64,
) -> Verdict {
    let pass = Verdict {
        v_mps,
        omega_radps,
        scale: 1.0,
        time_to_collision_s: None,
    };
    // A disc turning in place sweeps nothing; only forward (or backward) motion can collide.
    if v_mps.abs() < 1e-6 {
        return pass;
    }
    let keep_m = config.robot_radius_m + config.margin_m;
    let horizon_s = config.time_before_collision_s;
    // Points the disc could reach within the horizon at the commanded speed, or that walk
    // into its reach.
    let walk_m = movers
        .iter()
        .map(|m| m.vx_mps.hypot(m.vy_mps) * horizon_s)
        .fold(0.0, f64::max);
    let reach_m = v_mps.abs() * horizon_s + keep_m;
    let velocity = |px: f64, py: f64| {
        movers
            .iter()
            .find(|m| (px - m.x_m).hypot(py - m.y_m) <= m.reach_m)
            .map_or((0.0, 0.0), |m| (m.vx_mps, m.vy_mps))
    };
    let points: Vec<(f64, f64, f64, f64)> = scan_points(scan, reach_m + walk_m)
        .map(|(px, py)| {
            let (vx, vy) = velocity(px, py);
            (px, py, vx, vy)
        })
        .filter(|&(px, py, vx, vy)| px.hypot(py) <= reach_m + vx.hypot(vy) * horizon_s)
        .collect();
    if points.is_empty() {
        return pass;
    }
    let nearest_sq = |x: f64, y: f64, t_s: f64| {
        points
            .iter()
            .map(|&(px, py, vx, vy)| {
                let (px, py) = (px + vx * t_s, py + vy * t_s);
                (px - x) * (px - x) + (py - y) * (py - y)
            })
            .fold(f64::INFINITY, f64::min)
    };
    // Already inside the margin: moving must not get any closer than now (1 mm for rounding;
    // any more would let the robot creep in over many cycles).
    let start = nearest_sq(0.0, 0.0, 0.0).sqrt();
    let limit_m = if start < keep_m {
        (start - ROUNDING_M).max(0.0)
    } else {
        keep_m
    };
    let limit_sq = limit_m * limit_m;
    // "No closer than the nearest point now" alone is a ratchet under range noise: the nearest
    // return of a body jitters by centimetres from scan to scan, and each scan that reads it
    // farther lets the robot on by the difference, never back (traced: a robot crept into a
    // person standing beside it, millimetres per cycle for 4 s). Within the inner half of the
    // margin each point counts on its own: no motion may bring the disc closer to any of them,
    // whatever the nearest one reads.
    let inner_m = config.robot_radius_m + config.margin_m / 2.0;
    let inner: Vec<(f64, f64, f64, f64, f64)> = points
        .iter()
        .map(|&(px, py, vx, vy)| (px, py, vx, vy, px.hypot(py)))
        .filter(|&(.., d)| d < inner_m)
        .map(|(px, py, vx, vy, d)| {
            let l = (d - ROUNDING_M).max(0.0);
            (px, py, vx, vy, l * l)
        })
        .collect();
    let closes_in = |x: f64, y: f64, t_s: f64| {
        inner.iter().any(|&(px, py, vx, vy, l_sq)| {
            let (px, py) = (px + vx * t_s, py + vy * t_s);
            (px - x) * (px - x) + (py - y) * (py - y) < l_sq
        })
    };
    let kappa = omega_radps / v_mps;
    let steps = (horizon_s / config.simulation_step_s).ceil() as u32;
    for k in 1..=steps {
        let t_s = (f64::from(k) * config.simulation_step_s).min(horizon_s);
        let (x, y, _) = arc_pose(kappa, v_mps * t_s);
        if nearest_sq(x, y, t_s) < limit_sq || closes_in(x, y, t_s) {
            // Collides at t_s: scaled down, the robot would reach that spot at the horizon. The
            // step before it is the last free one, so a collision in the first step stops.
            let free_s = t_s - config.simulation_step_s;
            let scale = (free_s / horizon_s).clamp(0.0, 1.0);
            return Verdict {
                v_mps: v_mps * scale,
                omega_radps: omega_radps * scale,
                scale,
                time_to_collision_s: Some(t_s),
            };
        }
    }
    pass
}

#[cfg(test)]
mod tests {
    use super::*;
    use protocol::Header;

    /// A 180-degree, 181-beam scan (as the simulator's LIDAR) of a wall across the way at
    /// `wall_x_m` ahead, nothing else within range.
    fn wall_ahead(wall_x_m: f64) -> LaserScan {
        let n = 181_u16;
        let inc = std::f32::consts::PI / f32::from(n - 1);
        let ranges_m = (0..n)
            .map(|i| {
                let a = -std::f64::consts::FRAC_PI_2 + f64::from(i) * f64::from(inc);
                let c = a.cos();
                if c > 1e-6 {
                    ((wall_x_m / c) as f32).min(8.0)
                } else {
                    8.0
                }
            })
            .collect();
        LaserScan {
            header: Header::default(),
            angle_min_rad: -std::f32::consts::FRAC_PI_2,
            angle_increment_rad: inc,
            range_min_m: 0.05,
            range_max_m: 8.0,
            ranges_m,
        }
    }

    #[test]
    fn a_free_arc_passes_unchanged_and_turning_in_place_always_does() {
        let c = CollisionMonitorConfig::default();
        let far = check(&c, &wall_ahead(3.0), &[], 0.7, 0.2);
        assert_eq!((far.v_mps, far.omega_radps, far.scale), (0.7, 0.2, 1.0));
        assert!(!far.limited());
        let spin = check(&c, &wall_ahead(0.26), &[], 0.0, 1.0);
        assert_eq!((spin.v_mps, spin.omega_radps), (0.0, 1.0));
    }

    #[test]
    fn driving_at_a_wall_slows_so_that_contact_stays_the_horizon_away() {
        let c = CollisionMonitorConfig::default();
        // 0.7 m/s at a wall 0.8 m ahead: the disc plus margin (0.3 m) reaches it after 0.5 m,
        // 0.71 s, sooner than 1.2 s.
        let v = check(&c, &wall_ahead(0.8), &[], 0.7, 0.3);
        assert!(v.limited());
        let ttc = v.time_to_collision_s.unwrap();
        assert!((0.69..0.76).contains(&ttc), "{ttc}");
        assert!(v.v_mps > 0.2 && v.v_mps < 0.45, "{}", v.v_mps);
        // The turn rate is kept: the robot turns as its controller steers.
        assert_eq!(v.omega_radps, 0.3);
    }

    #[test]
    fn a_robot_driven_at_a_wall_through_the_monitor_stops_short_of_it() {
        let c = CollisionMonitorConfig::default();
        let (mut x_m, dt) = (0.0, 0.1);
        for _ in 0..200 {
            let v = check(&c, &wall_ahead(2.0 - x_m), &[], 0.7, 0.0);
            x_m += v.v_mps * dt;
        }
        let gap_m = 2.0 - x_m - c.robot_radius_m;
        assert!(gap_m > 0.0 && gap_m < c.margin_m + 0.05, "gap {gap_m}");
    }

    /// The scan of a wall along x = `wall_x_m` (map frame) from a robot at (x, y, yaw).
    fn wall_from(x_m: f64, yaw_rad: f64, wall_x_m: f64) -> LaserScan {
        let mut scan = wall_ahead(1.0);
        for (i, r) in scan.ranges_m.iter_mut().enumerate() {
            let a = yaw_rad
                + f64::from(scan.angle_min_rad)
                + f64::from(scan.angle_increment_rad) * i as f64;
            let c = a.cos();
            *r = if c > 1e-6 {
                (((wall_x_m - x_m) / c) as f32).min(8.0)
            } else {
                8.0
            };
        }
        scan
    }

    #[test]
    fn a_robot_steered_along_a_wall_keeps_turning_and_never_touches_it() {
        // A controller that steers on a 1.4 m circle, which crosses a wall 1 m ahead: the
        // monitor slows the robot at the wall while it turns away, then lets it go on.
        let c = CollisionMonitorConfig::default();
        let (mut x, mut y, mut yaw, dt) = (0.0_f64, 0.0_f64, 0.0_f64, 0.1);
        let (mut min_gap_m, mut travelled_m, mut slowed) = (f64::INFINITY, 0.0, 0);
        for _ in 0..300 {
            let v = check(&c, &wall_from(x, yaw, 1.0), &[], 0.7, 0.5);
            assert_eq!(v.omega_radps, 0.5);
            slowed += usize::from(v.limited());
            yaw += v.omega_radps * dt;
            x += v.v_mps * dt * yaw.cos();
            y += v.v_mps * dt * yaw.sin();
            travelled_m += v.v_mps * dt;
            min_gap_m = min_gap_m.min(1.0 - x - c.robot_radius_m);
        }
        assert!(min_gap_m > 0.0, "touched the wall: gap {min_gap_m}");
        assert!(slowed > 0, "never slowed");
        assert!(
            travelled_m > 5.0,
            "stalled after {travelled_m} m at ({x}, {y})"
        );
    }

    #[test]
    fn inside_the_margin_it_may_back_off_or_turn_but_not_close_in() {
        let c = CollisionMonitorConfig::default();
        let scan = wall_ahead(0.27);
        assert_eq!(check(&c, &scan, &[], 0.3, 0.0).v_mps, 0.0);
        let away = check(&c, &scan, &[], -0.1, 0.0);
        assert_eq!(away.v_mps, -0.1);
    }

    /// A 181-beam scan, with Gaussian range noise of `noise_m` (the simulator's is 1 cm), from a
    /// robot at (x, y, yaw) of a person: a disc of `radius_m` at (`cx`, `cy`).
    fn person_from(
        pose: (f64, f64, f64),
        person: (f64, f64, f64),
        noise_m: f64,
        rng: &mut impl rand::Rng,
    ) -> LaserScan {
        use rand_distr::Distribution;
        let noise = rand_distr::Normal::new(0.0, noise_m).unwrap();
        let mut scan = wall_ahead(1.0);
        let (x, y, yaw) = pose;
        let (cx, cy, radius_m) = person;
        for (i, r) in scan.ranges_m.iter_mut().enumerate() {
            let a = yaw
                + f64::from(scan.angle_min_rad)
                + f64::from(scan.angle_increment_rad) * i as f64;
            let (dx, dy) = (a.cos(), a.sin());
            let (ox, oy) = (cx - x, cy - y);
            let along = ox * dx + oy * dy;
            let off_sq = ox * ox + oy * oy - along * along;
            let hit = (along > 0.0 && off_sq < radius_m * radius_m)
                .then(|| along - (radius_m * radius_m - off_sq).sqrt());
            *r = hit.map_or(8.0, |h| (h + noise.sample(rng)).clamp(0.06, 7.99) as f32);
        }
        scan
    }

    #[test]
    fn range_noise_does_not_let_a_robot_creep_into_someone_standing_close() {
        use rand::SeedableRng;
        // Someone standing ahead and a little to the left, already inside the margin; the
        // controller keeps pushing forward and turning towards them (as a dynamic window whose
        // path leads past them does). Each scan reads their body anew, with the simulator's
        // 1 cm of noise, for 60 s.
        let c = CollisionMonitorConfig::default();
        let person = (0.46, 0.05, 0.2);
        for seed in 0..5 {
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
            let (mut x, mut y, mut yaw, dt) = (0.0_f64, 0.0_f64, 0.0_f64, 0.1);
            let mut min_gap_m = f64::INFINITY;
            for _ in 0..600 {
                let scan = person_from((x, y, yaw), person, 0.01, &mut rng);
                let v = check(&c, &scan, &[], 0.3, 0.1);
                yaw += v.omega_radps * dt;
                x += v.v_mps * dt * yaw.cos();
                y += v.v_mps * dt * yaw.sin();
                let gap_m = (person.0 - x).hypot(person.1 - y) - person.2 - c.robot_radius_m;
                min_gap_m = min_gap_m.min(gap_m);
            }
            assert!(
                min_gap_m > 0.01,
                "seed {seed}: crept to {min_gap_m} m from the person"
            );
        }
    }

    #[test]
    fn someone_crossing_is_braked_for_where_they_will_be() {
        use rand::SeedableRng;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let c = CollisionMonitorConfig::default();
        // Someone 1.1 m ahead and 1 m to the right walks across at 1 m/s; at 0.7 m/s the robot
        // would meet them in a second. Where they stand now is clear of the robot's way.
        let person = (1.1, -1.0, 0.2);
        let scan = person_from((0.0, 0.0, 0.0), person, 0.0, &mut rng);
        let walking = MovingBody {
            x_m: person.0,
            y_m: person.1,
            reach_m: 0.3,
            vx_mps: 0.0,
            vy_mps: 1.0,
        };
        assert!(!check(&c, &scan, &[], 0.7, 0.0).limited());
        assert!(check(&c, &scan, &[walking], 0.7, 0.0).limited());
        let off = CollisionMonitorConfig {
            track_movers: false,
            ..c
        };
        assert!(!check(&off, &scan, &[walking], 0.7, 0.0).limited());

        // In closed loop, on a course that meets them, the robot never touches them.
        let (mut x, dt) = (0.0_f64, 0.1);
        let mut min_gap_m = f64::INFINITY;
        for k in 0..60 {
            let py = -2.3 + 1.0 * f64::from(k) * dt;
            let at = (2.0, py, 0.2);
            let scan = person_from((x, 0.0, 0.0), at, 0.01, &mut rng);
            let body = MovingBody {
                x_m: at.0 - x,
                y_m: at.1,
                reach_m: 0.3,
                vx_mps: 0.0,
                vy_mps: 1.0,
            };
            let v = check(&c, &scan, &[body], 0.7, 0.0);
            x += v.v_mps * dt;
            min_gap_m = min_gap_m.min((at.0 - x).hypot(at.1) - at.2 - c.robot_radius_m);
        }
        assert!(min_gap_m > 0.0, "touched them: {min_gap_m}");
        assert!(x > 2.5, "never went on after they passed: {x}");
    }

    #[test]
    fn inside_the_inner_margin_it_still_slides_away_along_a_wall() {
        // 1 cm from a wall on its right, turned 0.3 rad away from it: driving on takes it off.
        let c = CollisionMonitorConfig::default();
        let mut scan = wall_ahead(1.0);
        let (yaw, wall_y) = (0.3_f64, -0.26_f64);
        for (i, r) in scan.ranges_m.iter_mut().enumerate() {
            let a = yaw
                + f64::from(scan.angle_min_rad)
                + f64::from(scan.angle_increment_rad) * i as f64;
            let s = a.sin();
            *r = if s < -1e-6 {
                ((wall_y / s) as f32).min(8.0)
            } else {
                8.0
            };
        }
        let v = check(&c, &scan, &[], 0.3, 0.0);
        assert!(!v.limited(), "{v:?}");
    }

    #[test]
    fn a_bad_value_is_named() {
        let c = CollisionMonitorConfig {
            time_before_collision_s: 0.0,
            ..CollisionMonitorConfig::default()
        };
        let e = c.validate().unwrap_err().to_string();
        assert!(
            e.contains("safety.collision_monitor.time_before_collision_s"),
            "{e}"
        );
        assert!(CollisionMonitorConfig::default().validate().is_ok());
    }
}
