//! The agent's obstacle layer: what the laser sees standing where the floor plan is free.
//!
//! The floor plan has walls, not furniture, so the planner's path runs through a cabinet that
//! stands out from a corridor wall, and the robot, led into it, is held short by its collision
//! monitor (docs/evaluation.md, tasks C and D). Nav2 marks what its sensors see on the global
//! costmap for this; here the agent marks it and sends it with its pose
//! ([`protocol::PoseEstimate::unmapped_obstacles_m`]), and the planner routes round it
//! (`planning::SeenObstacleParams`).
//!
//! A laser return counts when it lies at least `min_map_gap_m` from the floor plan's walls (the
//! likelihood field AMCL already has says how far). It is marked in a cell of `cell_m`; a cell
//! hit in scan after scan (no gap over `gap_s`) for `static_s` is *confirmed*: something stands
//! there. People walking, robots driving, move their returns to other cells within a fraction of
//! that time and are never confirmed; a person or robot standing still is, as it should be.
//! A confirmed cell stays while the robot looks elsewhere (the planner must not lead the robot
//! back into the cabinet it just turned away from), until a beam passes through it (Nav2's
//! ray-trace clearing: whatever stood there has gone) or nothing hits it for `forget_s`.
//!
//! Plain data: a scan, the pose it was taken from and the floor plan's distance function in;
//! map-frame points out. Time is the scan's stamp, so a replay or a lock-step run gives the
//! same points.

use std::collections::HashMap;

use protocol::{LaserScan, Pose2D, MAX_UNMAPPED_OBSTACLES};

use crate::config::ConfigError;
use crate::controllers::path_tracker::check_positive;

/// The `[unmapped_obstacles]` table.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct UnmappedConfig {
    /// Off: the agent reports nothing and plans see the floor plan only (the paper's setting).
    pub enabled: bool,
    /// A return at least this far from the floor plan's walls is something the plan lacks
    /// (AMCL's pose error and the field's quantization stay well below it).
    pub min_map_gap_m: f64,
    /// Returns farther than this are not marked (the beams spread and the heading error grows
    /// with range).
    pub max_range_m: f64,
    /// Nothing is marked while AMCL's position standard deviation is above this: a return
    /// placed from a doubtful pose would put a wall where the floor plan has one already.
    pub max_position_std_m: f64,
    /// Side of a marking cell.
    pub cell_m: f64,
    /// A cell hit this long without a break is confirmed.
    pub static_s: f64,
    /// A cell not hit for longer than this starts again (before it is confirmed).
    pub gap_s: f64,
    /// A confirmed cell nothing hit for this long is forgotten.
    pub forget_s: f64,
    /// A beam that passes this far beyond a cell's centre clears it.
    pub clear_margin_m: f64,
    /// Confirmed cells within this distance of the robot are reported, nearest first.
    pub report_range_m: f64,
    /// At most this many points are reported per pose.
    pub max_points: usize,
}

impl Default for UnmappedConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            min_map_gap_m: 0.3,
            max_range_m: 4.0,
            max_position_std_m: 0.15,
            cell_m: 0.1,
            static_s: 1.0,
            gap_s: 0.5,
            forget_s: 30.0,
            clear_margin_m: 0.2,
            report_range_m: 6.0,
            max_points: 96,
        }
    }
}

impl UnmappedConfig {
    /// # Errors
    /// [`ConfigError::Invalid`] naming the field and value.
    pub fn validate(&self) -> Result<(), ConfigError> {
        check_positive(&[
            ("unmapped_obstacles.min_map_gap_m", self.min_map_gap_m),
            ("unmapped_obstacles.max_range_m", self.max_range_m),
            (
                "unmapped_obstacles.max_position_std_m",
                self.max_position_std_m,
            ),
            ("unmapped_obstacles.cell_m", self.cell_m),
            ("unmapped_obstacles.static_s", self.static_s),
            ("unmapped_obstacles.gap_s", self.gap_s),
            ("unmapped_obstacles.forget_s", self.forget_s),
            ("unmapped_obstacles.clear_margin_m", self.clear_margin_m),
            ("unmapped_obstacles.report_range_m", self.report_range_m),
        ])?;
        if self.max_points == 0 || self.max_points > MAX_UNMAPPED_OBSTACLES {
            return Err(ConfigError::Invalid {
                field: "unmapped_obstacles.max_points",
                value: self.max_points.to_string(),
                reason: "must lie between 1 and 256 (what a pose message may carry)",
            });
        }
        Ok(())
    }
}

#[derive(Debug, Clone, Copy)]
struct Cell {
    first_ns: u64,
    last_ns: u64,
    confirmed: bool,
}

/// The marked cells of one robot (see the module docs).
#[derive(Debug, Clone)]
pub struct UnmappedObstacles {
    config: UnmappedConfig,
    cells: HashMap<(i64, i64), Cell>,
}

/// The map-frame centre of cell (`ix`, `iy`) of side `cell_m`.
fn centre((ix, iy): (i64, i64), cell_m: f64) -> (f64, f64) {
    ((ix as f64 + 0.5) * cell_m, (iy as f64 + 0.5) * cell_m)
}

fn ns(s: f64) -> u64 {
    // Config values are validated positive and finite; the cast saturates beyond u64.
    (s * 1e9) as u64
}

impl UnmappedObstacles {
    #[must_use]
    pub fn new(config: UnmappedConfig) -> Self {
        Self {
            config,
            cells: HashMap::new(),
        }
    }

    /// Takes one scan taken at `map_from_laser` (the robot's pose composed with the laser's
    /// mount); `map_gap_m(x, y)` is the distance from a map-frame point to the floor plan's
    /// nearest wall.
    pub fn on_scan(
        &mut self,
        scan: &LaserScan,
        map_from_laser: Pose2D,
        map_gap_m: impl Fn(f64, f64) -> f64,
    ) {
        let t_ns = scan.header.stamp_ns;
        let (sin, cos) = map_from_laser.yaw_rad.sin_cos();
        self.clear(scan, map_from_laser);
        let c = self.config.cell_m;
        let static_ns = ns(self.config.static_s);
        let gap_ns = ns(self.config.gap_s);
        for (i, &r) in scan.ranges_m.iter().enumerate() {
            if !scan.is_return(i) || f64::from(r) > self.config.max_range_m {
                continue;
            }
            let (bs, bc) = f64::from(scan.beam_angle_rad(i)).sin_cos();
            let (lx, ly) = (f64::from(r) * bc, f64::from(r) * bs);
            let x_m = map_from_laser.x_m + cos * lx - sin * ly;
            let y_m = map_from_laser.y_m + sin * lx + cos * ly;
            if map_gap_m(x_m, y_m) < self.config.min_map_gap_m {
                continue;
            }
            let key = ((x_m / c).floor() as i64, (y_m / c).floor() as i64);
            let cell = self.cells.entry(key).or_insert(Cell {
                first_ns: t_ns,
                last_ns: t_ns,
                confirmed: false,
            });
            if !cell.confirmed && t_ns.saturating_sub(cell.last_ns) > gap_ns {
                cell.first_ns = t_ns;
            }
            cell.last_ns = t_ns;
            cell.confirmed |= t_ns.saturating_sub(cell.first_ns) >= static_ns;
        }
        let forget_ns = ns(self.config.forget_s);
        self.cells.retain(|_, cell| {
            let idle_ns = t_ns.saturating_sub(cell.last_ns);
            if cell.confirmed {
                idle_ns <= forget_ns
            } else {
                idle_ns <= gap_ns
            }
        });
    }

    /// Drops every cell a beam of `scan` passed through: it has been seen free.
    fn clear(&mut self, scan: &LaserScan, map_from_laser: Pose2D) {
        let n = scan.ranges_m.len();
        if n == 0 || scan.angle_increment_rad <= 0.0 {
            return;
        }
        let (sin, cos) = map_from_laser.yaw_rad.sin_cos();
        let margin_m = self.config.clear_margin_m;
        let first_rad = f64::from(scan.angle_min_rad);
        let step_rad = f64::from(scan.angle_increment_rad);
        let range_max_m = f64::from(scan.range_max_m);
        let cell_m = self.config.cell_m;
        self.cells.retain(|&key, _| {
            let (x_m, y_m) = centre(key, cell_m);
            let (dx, dy) = (x_m - map_from_laser.x_m, y_m - map_from_laser.y_m);
            let (lx, ly) = (cos * dx + sin * dy, -sin * dx + cos * dy);
            let range_m = lx.hypot(ly);
            let beam = ((ly.atan2(lx) - first_rad) / step_rad).round();
            if beam < 0.0 || beam >= n as f64 || range_m + margin_m >= range_max_m {
                return true;
            }
            let i = beam as usize;
            let beam_m = f64::from(scan.ranges_m[i]);
            let through = !scan.is_return(i) || beam_m > range_m + margin_m;
            !(through && beam_m >= f64::from(scan.range_min_m))
        });
    }

    /// The confirmed cells' centres (map frame) within `report_range_m` of `robot`, nearest
    /// first, at most `max_points`.
    #[must_use]
    pub fn points_m(&self, robot: Pose2D) -> Vec<[f64; 2]> {
        let mut near: Vec<(f64, [f64; 2])> = self
            .cells
            .iter()
            .filter(|(_, cell)| cell.confirmed)
            .map(|(&k, _)| {
                let (x_m, y_m) = centre(k, self.config.cell_m);
                ((x_m - robot.x_m).hypot(y_m - robot.y_m), [x_m, y_m])
            })
            .filter(|(d, _)| *d <= self.config.report_range_m)
            .collect();
        // Cells are kept in a hash map: a full order makes the nearest `max_points` the same
        // whatever its iteration order.
        near.sort_by(|a, b| {
            a.0.total_cmp(&b.0)
                .then(a.1[0].total_cmp(&b.1[0]))
                .then(a.1[1].total_cmp(&b.1[1]))
        });
        near.truncate(self.config.max_points);
        near.into_iter().map(|(_, p)| p).collect()
    }

    /// How many cells are marked (confirmed or not).
    #[must_use]
    pub fn marked(&self) -> usize {
        self.cells.len()
    }
}

#[cfg(test)]
mod tests {
    use protocol::Header;

    use super::*;

    /// A 181-beam half-circle scan (as the simulator's) at time `t_s` whose beams end at the
    /// first of `discs` (x, y, radius in the laser frame) they meet, or at 8 m.
    fn scan(t_s: f64, discs: &[(f64, f64, f64)]) -> LaserScan {
        let n = 181;
        let step = std::f32::consts::PI / 180.0;
        let ranges_m = (0..n)
            .map(|i| {
                let a = -std::f64::consts::FRAC_PI_2 + f64::from(i as u16) * f64::from(step);
                let (s, c) = a.sin_cos();
                discs
                    .iter()
                    .filter_map(|&(x, y, r)| {
                        let along = x * c + y * s;
                        let off2 = (x * x + y * y) - along * along;
                        (along > 0.0 && off2 <= r * r).then(|| along - (r * r - off2).sqrt())
                    })
                    .fold(8.0f64, f64::min) as f32
            })
            .collect();
        LaserScan {
            header: Header::new(0, ns(t_s)),
            angle_min_rad: -std::f32::consts::FRAC_PI_2,
            angle_increment_rad: step,
            range_min_m: 0.05,
            range_max_m: 8.0,
            ranges_m,
        }
    }

    fn no_walls(_: f64, _: f64) -> f64 {
        2.0
    }

    #[test]
    fn something_standing_is_confirmed_after_static_s_and_cleared_when_seen_gone() {
        let mut layer = UnmappedObstacles::new(UnmappedConfig::default());
        let at = Pose2D::new(0.0, 0.0, 0.0);
        let cabinet = [(2.0, 0.3, 0.3)];
        for k in 0..10 {
            layer.on_scan(&scan(0.1 * f64::from(k), &cabinet), at, no_walls);
            assert!(layer.points_m(at).is_empty(), "confirmed too early at {k}");
        }
        layer.on_scan(&scan(1.0, &cabinet), at, no_walls);
        let points = layer.points_m(at);
        assert!(!points.is_empty());
        for [x, y] in &points {
            let gap = (x - 2.0).hypot(y - 0.3) - 0.3;
            assert!(gap.abs() < 0.12, "({x}, {y}) is not on the cabinet's face");
        }
        // Looking away (a scan of nothing, but the cabinet now behind the laser) keeps it.
        let turned = Pose2D::new(0.0, 0.0, std::f64::consts::PI);
        layer.on_scan(&scan(1.5, &[]), turned, no_walls);
        assert_eq!(layer.points_m(at).len(), points.len());
        // Looking at the spot and seeing through it clears it.
        layer.on_scan(&scan(2.0, &[]), at, no_walls);
        assert!(layer.points_m(at).is_empty());
        assert_eq!(layer.marked(), 0);
    }

    #[test]
    fn a_person_walking_across_is_never_confirmed() {
        let mut layer = UnmappedObstacles::new(UnmappedConfig::default());
        let at = Pose2D::new(0.0, 0.0, 0.0);
        // 1 m/s across the robot's way, 2 m ahead, for 4 s: a 0.2 m radius body.
        for k in 0..40 {
            let t = 0.1 * f64::from(k);
            let person = [(2.0, -2.0 + t, 0.2)];
            layer.on_scan(&scan(t, &person), at, no_walls);
            assert!(layer.points_m(at).is_empty(), "confirmed at {t} s");
        }
        // A slow one (0.3 m/s) walking away is not either.
        for k in 0..40 {
            let t = 10.0 + 0.1 * f64::from(k);
            let person = [(1.5 + 0.3 * (t - 10.0), 0.0, 0.2)];
            layer.on_scan(&scan(t, &person), at, no_walls);
            assert!(layer.points_m(at).is_empty(), "confirmed at {t} s");
        }
    }

    #[test]
    fn walls_of_the_floor_plan_and_far_returns_are_not_marked() {
        let mut layer = UnmappedObstacles::new(UnmappedConfig::default());
        let at = Pose2D::new(0.0, 0.0, 0.0);
        let wall_at_x2 = |x: f64, _: f64| (x - 2.0).abs();
        let far = [(5.0, 0.0, 0.5), (2.0, 0.0, 0.1)];
        for k in 0..20 {
            layer.on_scan(&scan(0.1 * f64::from(k), &far), at, wall_at_x2);
        }
        assert_eq!(layer.marked(), 0);
    }

    #[test]
    fn reports_the_nearest_first_within_range_and_at_most_max_points() {
        let config = UnmappedConfig {
            max_points: 3,
            ..UnmappedConfig::default()
        };
        let mut layer = UnmappedObstacles::new(config);
        let at = Pose2D::new(0.0, 0.0, 0.0);
        let things = [(1.5, 0.0, 0.3), (3.0, 1.5, 0.3)];
        for k in 0..12 {
            layer.on_scan(&scan(0.1 * f64::from(k), &things), at, no_walls);
        }
        let points = layer.points_m(at);
        assert_eq!(points.len(), 3);
        let d: Vec<f64> = points.iter().map(|p| p[0].hypot(p[1])).collect();
        assert!(d.windows(2).all(|w| w[0] <= w[1]), "{d:?}");
        assert!(d[2] < 1.5, "{d:?}");
        // From 10 m away nothing is within report_range_m.
        assert!(layer.points_m(Pose2D::new(-10.0, 0.0, 0.0)).is_empty());
    }

    #[test]
    fn validation_names_the_field() {
        let bad = UnmappedConfig {
            static_s: 0.0,
            ..UnmappedConfig::default()
        };
        assert!(bad
            .validate()
            .unwrap_err()
            .to_string()
            .contains("unmapped_obstacles.static_s"));
        let bad = UnmappedConfig {
            max_points: 300,
            ..UnmappedConfig::default()
        };
        assert!(bad
            .validate()
            .unwrap_err()
            .to_string()
            .contains("max_points"));
    }
}
