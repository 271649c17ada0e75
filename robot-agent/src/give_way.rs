//! Giving way: the robot waits before a passage too narrow to meet in while someone comes
//! through it the other way.
//!
//! A cabinet narrows task C's corridor to 1.1 m, and a person walks that corridor. Met inside
//! the gap, neither can step aside: the person stands, the collision monitor holds the robot,
//! the obstacle layer confirms the standing person and no way is left (15 of LPE-Net's 39
//! interventions in 20 runs of tasks A–E, 2026-11-27). People give way at such a place: the one
//! who arrives second waits short of it. The privileged expert does so reading the simulator's
//! truth (`eval::expert`); this is the same rule on what the robot itself sees.
//!
//! - **Someone coming:** the laser returns that lie neither on the floor plan's walls nor on the
//!   obstacle layer's confirmed cells ([`crate::unmapped`]) and move are tracked as bodies
//!   ([`crate::movers`]). Of those with a return within `lane_m` of the path ahead (up to
//!   `look_m`), the one nearest along the path is the mover; its velocity along the path says
//!   whether it comes towards the robot (faster than `oncoming_mps`).
//! - **A narrow passage between:** the width across the path (to walls and confirmed cells,
//!   both sides) below `narrow_width_m` somewhere between the robot and them.
//! - **Wait short of it:** the speed is capped so that the robot stops `hold_back_m` before the
//!   passage (far enough for them to come out of it and step round the robot), unless the
//!   robot is within `committed_m` of it or in it already (better to go on through). It waits
//!   while they keep coming, and `release_s` after.
//!
//! Plain data in (pose, path, tracks, a free-space function), a speed cap out; the
//! [`Supervisor`](crate::Supervisor) caps whichever controller drives.

use protocol::Pose2D;

use crate::config::ConfigError;
use crate::controllers::path_tracker::{check_non_negative, check_positive};
use crate::movers::Track;
use crate::rotation_shim::nearest_index;

/// The `[give_way]` table.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct GiveWayConfig {
    /// Off: the robot drives into a narrow passage whoever comes the other way.
    pub enabled: bool,
    /// How far along the path movers and narrow passages are looked for.
    pub look_m: f64,
    /// A mover this close to the path (centre line to return) is in the robot's lane.
    pub lane_m: f64,
    /// A mover coming towards the robot along the path faster than this is coming through.
    pub oncoming_mps: f64,
    /// A passage narrower than this (across the path, wall to wall) is too narrow to meet in.
    pub narrow_width_m: f64,
    /// The robot waits this far before the passage ...
    pub hold_back_m: f64,
    /// ... and this far to the side of the path, room allowing (0: on the path, where the
    /// person coming out stepped round the robot towards the wall and stood there, round 14).
    /// 0.4 (the default since round 55): at 0.8, a DLM-Net that waited south-east of task C's
    /// cabinet, in its shadow, then nosed into its corner on the way back to the gap (9 of 20
    /// runs deployed; 1 at 0.4, LPE-Net 2 against 1, docs/evaluation.md round 55).
    pub step_aside_m: f64,
    /// The robot's radius, and the room it keeps to walls when it steps aside.
    pub robot_radius_m: f64,
    pub wall_margin_m: f64,
    /// A passage that starts closer than this has been entered: go on through.
    pub committed_m: f64,
    /// Deceleration to the waiting point.
    pub brake_mps2: f64,
    /// The robot waits this long after the last sight of someone coming.
    pub release_s: f64,
    /// A laser return at least this far from the floor plan's walls is not a wall (read by
    /// the mover tracking for the collision monitor too, also when the rule is off).
    pub min_map_gap_m: f64,
}

impl Default for GiveWayConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            look_m: 4.0,
            lane_m: 0.6,
            oncoming_mps: 0.15,
            narrow_width_m: 1.3,
            hold_back_m: 1.0,
            step_aside_m: 0.4,
            robot_radius_m: 0.25,
            wall_margin_m: 0.15,
            committed_m: 0.3,
            brake_mps2: 0.5,
            release_s: 1.0,
            min_map_gap_m: 0.3,
        }
    }
}

impl GiveWayConfig {
    /// Checks ranges that serde cannot express.
    ///
    /// # Errors
    /// [`ConfigError::Invalid`] naming the first bad field and its value.
    pub fn validate(&self) -> Result<(), ConfigError> {
        check_positive(&[
            ("give_way.look_m", self.look_m),
            ("give_way.lane_m", self.lane_m),
            ("give_way.oncoming_mps", self.oncoming_mps),
            ("give_way.narrow_width_m", self.narrow_width_m),
            ("give_way.hold_back_m", self.hold_back_m),
            ("give_way.robot_radius_m", self.robot_radius_m),
            ("give_way.committed_m", self.committed_m),
            ("give_way.brake_mps2", self.brake_mps2),
            ("give_way.release_s", self.release_s),
            ("give_way.min_map_gap_m", self.min_map_gap_m),
        ])?;
        check_non_negative(&[
            ("give_way.step_aside_m", self.step_aside_m),
            ("give_way.wall_margin_m", self.wall_margin_m),
        ])
    }
}

/// Spacing of the width checks along the path, and of the steps across it.
const STEP_M: f64 = 0.05;
/// The returns are a mover's near side; its body reaches this much further.
const BODY_M: f64 = 0.5;
/// Free space across the path is measured this far from an obstacle's edge.
const FREE_M: f64 = 0.05;
/// A mover further than this from the path's centre line comes along one side of it.
const SIDE_M: f64 = 0.15;
/// A step aside shorter than this is not worth making.
const MIN_STEP_ASIDE_M: f64 = 0.2;

/// Why the robot waits, and where.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hold {
    /// The speed cap this cycle.
    pub max_speed_mps: f64,
    /// Where to wait (map frame): beside the path short of the passage, off the mover's line,
    /// so that they can come by without having to step round the robot; `None` where there is
    /// no room beside the path (the robot then waits on it). Once they are by, the planner's
    /// next path starts from where the robot stands.
    pub wait_at_m: Option<(f64, f64)>,
    /// Where the narrow passage starts, along the path from the robot.
    pub narrow_from_m: f64,
    /// How far along the path the mover is.
    pub mover_m: f64,
}

/// The give-way state: the wait.
#[derive(Debug, Clone, Default)]
pub struct GiveWay {
    config: GiveWayConfig,
    clock_s: f64,
    /// The last cycle the robot was held, while it counts as waiting.
    waiting: Option<f64>,
    /// The last cycle someone was seen coming through while waiting.
    last_seen_s: f64,
    /// Where this wait takes place (chosen when it starts).
    wait_at_m: Option<(f64, f64)>,
    waits: u32,
}

impl GiveWay {
    #[must_use]
    pub fn new(config: GiveWayConfig) -> Self {
        Self {
            config,
            ..Self::default()
        }
    }

    /// How many times the robot waited for someone.
    #[must_use]
    pub fn waits(&self) -> u32 {
        self.waits
    }

    /// Whether the robot waits now.
    #[must_use]
    pub fn waiting(&self) -> bool {
        self.waiting.is_some()
    }

    /// Forgets the wait (a stop, an intervention).
    pub fn reset(&mut self) {
        self.waiting = None;
        self.wait_at_m = None;
    }

    /// One cycle of `dt_s`: the speed cap while the robot must wait, `None` when it may drive.
    /// `tracks` are this cycle's moving bodies ([`crate::movers`], map frame); `free_m(x, y)`
    /// is the distance from a map point to the nearest wall or confirmed cell.
    pub fn cycle(
        &mut self,
        dt_s: f64,
        pose: Pose2D,
        path: &[Pose2D],
        tracks: &[Track],
        free_m: impl Fn(f64, f64) -> f64,
    ) -> Option<Hold> {
        self.clock_s += dt_s;
        let c = self.config;
        if !c.enabled {
            return None;
        }
        let Some(ahead) = Ahead::new(pose, path, c.look_m) else {
            self.reset();
            return None;
        };
        let mover = self.mover(&ahead, tracks);
        let coming = mover.filter(|m| m.toward_mps > c.oncoming_mps);
        if coming.is_some() {
            self.last_seen_s = self.clock_s;
        }
        let narrow_from_m = coming
            .or(mover.filter(|_| self.waiting.is_some()))
            .and_then(|m| ahead.narrow_from(m.along_m + BODY_M, c.narrow_width_m, &free_m));
        let recently = self.waiting.is_some() && self.clock_s - self.last_seen_s <= c.release_s;
        let hold = match (narrow_from_m, mover) {
            (Some(from_m), Some(m)) if (coming.is_some() || recently) && from_m > c.committed_m => {
                if self.waiting.is_none() || self.wait_at_m.is_none() {
                    self.wait_at_m = self.wait_spot(&ahead, from_m, m.left_m, &free_m);
                }
                Some(Hold {
                    max_speed_mps: (2.0 * c.brake_mps2 * (from_m - c.hold_back_m).max(0.0)).sqrt(),
                    wait_at_m: self.wait_at_m,
                    narrow_from_m: from_m,
                    mover_m: m.along_m,
                })
            }
            _ => None,
        };
        match (hold, self.waiting) {
            (Some(h), None) => {
                self.waits += 1;
                self.waiting = Some(self.clock_s);
                tracing::debug!(
                    narrow_from_m = h.narrow_from_m,
                    mover_m = h.mover_m,
                    toward_mps = mover.map(|m| m.toward_mps),
                    ?pose,
                    "giving way to someone coming through a narrow passage"
                );
            }
            (Some(_), Some(_)) => self.waiting = Some(self.clock_s),
            // A mover lost for a cycle or two at the edge of the view is not a new wait.
            (None, Some(last_s)) if self.clock_s - last_s > c.release_s => {
                self.waiting = None;
                self.wait_at_m = None;
            }
            _ => {}
        }
        hold
    }

    /// The spot beside the path, `hold_back_m` short of the passage starting `from_m` along,
    /// on the side away from the mover's line (`mover_left_m` to the left of the path), or on
    /// the roomier side when it comes along the middle.
    fn wait_spot(
        &self,
        ahead: &Ahead,
        from_m: f64,
        mover_left_m: f64,
        free_m: impl Fn(f64, f64) -> f64,
    ) -> Option<(f64, f64)> {
        let c = self.config;
        let (p, (tx, ty)) = ahead.at((from_m - c.hold_back_m).max(0.0));
        let left = (-ty, tx);
        let keep_m = c.robot_radius_m + c.wall_margin_m;
        let room = |sign: f64| {
            let mut t = 0.0;
            while t < c.step_aside_m + keep_m
                && free_m(p.0 + sign * t * left.0, p.1 + sign * t * left.1) > FREE_M
            {
                t += STEP_M;
            }
            (t - keep_m).min(c.step_aside_m)
        };
        let (room_left, room_right) = (room(1.0), room(-1.0));
        // Away from their line; along the middle, the roomier side.
        let left_side =
            mover_left_m < -SIDE_M || (mover_left_m.abs() <= SIDE_M && room_left > room_right);
        let sign = if left_side { 1.0 } else { -1.0 };
        let shift_m = if sign > 0.0 { room_left } else { room_right };
        (shift_m >= MIN_STEP_ASIDE_M)
            .then_some((p.0 + sign * shift_m * left.0, p.1 + sign * shift_m * left.1))
    }

    /// The body nearest along the path ahead with a return within `lane_m` of it, as seen
    /// along the path.
    fn mover(&self, ahead: &Ahead, tracks: &[Track]) -> Option<Mover> {
        let lane = self.config.lane_m;
        let (_, track) = tracks
            .iter()
            .filter_map(|t| {
                let s = t
                    .points_m
                    .iter()
                    .filter_map(|&[x, y]| {
                        let (s, off) = ahead.project(x, y)?;
                        (off.abs() <= lane && s > 0.0).then_some(s)
                    })
                    .min_by(f64::total_cmp)?;
                Some((s, t))
            })
            .min_by(|a, b| a.0.total_cmp(&b.0))?;
        let (along_m, left_m) = ahead.project(track.x_m, track.y_m)?;
        let (tx, ty) = ahead.tangent(along_m);
        let toward_mps = if track.settled() {
            -(track.vx_mps * tx + track.vy_mps * ty)
        } else {
            0.0
        };
        Some(Mover {
            along_m,
            left_m,
            toward_mps,
        })
    }
}

/// The tracked mover as seen along the path.
#[derive(Debug, Clone, Copy)]
struct Mover {
    along_m: f64,
    left_m: f64,
    /// Its speed towards the robot along the path (0 while the track is young).
    toward_mps: f64,
}

/// The path ahead of the robot: from its nearest point, `look_m` long, with arc lengths.
struct Ahead {
    points: Vec<(f64, f64)>,
    arc_m: Vec<f64>,
}

impl Ahead {
    fn new(pose: Pose2D, path: &[Pose2D], look_m: f64) -> Option<Self> {
        let mut points = vec![(pose.x_m, pose.y_m)];
        let mut arc_m = vec![0.0];
        for p in &path[nearest_index(pose, path).min(path.len())..] {
            let last = points[points.len() - 1];
            let step = (p.x_m - last.0).hypot(p.y_m - last.1);
            if step < 1e-6 {
                continue;
            }
            let s = arc_m[arc_m.len() - 1] + step;
            points.push((p.x_m, p.y_m));
            arc_m.push(s);
            if s >= look_m {
                break;
            }
        }
        (points.len() >= 2).then_some(Self { points, arc_m })
    }

    /// (distance along, signed offset to the left) of the nearest point of the path to (x, y).
    fn project(&self, x: f64, y: f64) -> Option<(f64, f64)> {
        let mut best: Option<(f64, f64, f64)> = None;
        for i in 0..self.points.len() - 1 {
            let (a, b) = (self.points[i], self.points[i + 1]);
            let (dx, dy) = (b.0 - a.0, b.1 - a.1);
            let len = dx.hypot(dy);
            let t = (((x - a.0) * dx + (y - a.1) * dy) / (len * len)).clamp(0.0, 1.0);
            let (fx, fy) = (a.0 + t * dx, a.1 + t * dy);
            let d = (x - fx).hypot(y - fy);
            if best.is_none_or(|(bd, _, _)| d < bd) {
                let left = (dx * (y - a.1) - dy * (x - a.0)) / len;
                best = Some((d, self.arc_m[i] + t * len, left));
            }
        }
        best.map(|(_, s, left)| (s, left))
    }

    /// The point and unit tangent at distance `s_m` along.
    fn at(&self, s_m: f64) -> ((f64, f64), (f64, f64)) {
        let i = self
            .arc_m
            .windows(2)
            .position(|w| s_m <= w[1])
            .unwrap_or(self.arc_m.len() - 2);
        let (a, b) = (self.points[i], self.points[i + 1]);
        let len = (self.arc_m[i + 1] - self.arc_m[i]).max(1e-9);
        let t = ((s_m - self.arc_m[i]) / len).clamp(0.0, 1.0);
        (
            (a.0 + t * (b.0 - a.0), a.1 + t * (b.1 - a.1)),
            ((b.0 - a.0) / len, (b.1 - a.1) / len),
        )
    }

    fn tangent(&self, s_m: f64) -> (f64, f64) {
        self.at(s_m).1
    }

    /// Where the first stretch narrower than `width_m` starts, up to `until_m` along.
    fn narrow_from(
        &self,
        until_m: f64,
        width_m: f64,
        free_m: impl Fn(f64, f64) -> f64,
    ) -> Option<f64> {
        let end_m = until_m.min(self.arc_m[self.arc_m.len() - 1]);
        let side = |p: (f64, f64), n: (f64, f64)| {
            let mut t = 0.0;
            while t < width_m && free_m(p.0 + t * n.0, p.1 + t * n.1) > FREE_M {
                t += STEP_M;
            }
            t
        };
        let mut s = 0.0;
        while s <= end_m {
            let (p, (tx, ty)) = self.at(s);
            let left = side(p, (-ty, tx));
            if left < width_m && left + side(p, (ty, -tx)) < width_m {
                return Some(s);
            }
            s += STEP_M;
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::movers::MoverTracker;

    /// Task C's corridor (y 12–14) with its cabinet (x 25.6–26.4, y 12.1–12.9): the distance to
    /// the nearest wall or cabinet face.
    fn corridor(x: f64, y: f64) -> f64 {
        let walls = (y - 12.0).min(14.0 - y);
        let dx = (25.6 - x).max(x - 26.4).max(0.0);
        let dy = (12.1 - y).max(y - 12.9).max(0.0);
        walls.min(dx.hypot(dy))
    }

    /// The path west along the corridor, through the gap beside the cabinet.
    fn path_west(from_x: f64) -> Vec<Pose2D> {
        (0..80)
            .map(|i| {
                let x = from_x - 0.2 * f64::from(i);
                let y = if (24.8..=27.2).contains(&x) {
                    13.45
                } else {
                    13.2
                };
                Pose2D::new(x, y, std::f64::consts::PI)
            })
            .collect()
    }

    /// A person's front: returns on the east half of a 0.25 m disc at (x, y).
    fn person(x: f64, y: f64) -> Vec<[f64; 2]> {
        (-4..=4)
            .map(|k| {
                let a = f64::from(k) * 0.3;
                [x + 0.25 * a.cos(), y + 0.25 * a.sin()]
            })
            .collect()
    }

    #[test]
    fn waits_short_of_the_gap_while_someone_comes_through_it() {
        let mut gw = GiveWay::new(GiveWayConfig::default());
        let mut tracker = MoverTracker::default();
        let (mut robot_x, mut person_x, mut person_y): (f64, f64, f64) = (29.5, 23.0, 13.3);
        let in_gap = |x: f64| (25.35..=26.65).contains(&x);
        let mut closest_wait_x = f64::INFINITY;
        for k in 0..300 {
            let pose = Pose2D::new(robot_x, 13.2, std::f64::consts::PI);
            tracker.update(0.1, [robot_x, 13.2], &person(person_x, person_y));
            let hold = gw.cycle(0.1, pose, &path_west(robot_x), tracker.tracks(), corridor);
            let mut v = hold.map_or(0.7, |h| h.max_speed_mps.min(0.7));
            if hold.is_some() {
                closest_wait_x = closest_wait_x.min(robot_x);
            }
            // The collision monitor: never closer than 0.6 m to the person.
            if (robot_x - 0.1 * v - person_x).hypot(13.2 - person_y) < 0.6 {
                v = 0.0;
            }
            robot_x -= 0.1 * v;
            // The person walks east on their line and, out of the gap with the robot in the
            // way, steps aside.
            if (robot_x - person_x - 0.06).hypot(13.2 - person_y) >= 0.6 {
                person_x += 0.06;
            } else if person_x > 26.7 {
                person_y = 12.5;
            }
            assert!(
                !(in_gap(robot_x) && in_gap(person_x)),
                "met in the gap at step {k}: robot {robot_x}, person {person_x}"
            );
        }
        assert_eq!(gw.waits(), 1);
        assert!(
            closest_wait_x > 26.4 + 0.8,
            "waits about a metre short of the gap: {closest_wait_x}"
        );
        assert!(
            robot_x < 24.0,
            "through once the person came out: {robot_x}"
        );
    }

    /// Runs `cycles` cycles of 0.1 s with the robot at `robot_at(t)` on the path west and the
    /// person's front at `person_x(t)` on y = 13.3; the first time it was made to wait.
    fn first_wait(
        cycles: u16,
        robot_at: impl Fn(f64) -> Pose2D,
        person_x: impl Fn(f64) -> f64,
        free_m: impl Fn(f64, f64) -> f64 + Copy,
    ) -> Option<f64> {
        let mut gw = GiveWay::new(GiveWayConfig::default());
        let mut tracker = MoverTracker::default();
        (0..cycles).map(|k| 0.1 * f64::from(k)).find(|&t| {
            let pose = robot_at(t);
            tracker.update(0.1, [pose.x_m, pose.y_m], &person(person_x(t), 13.3));
            gw.cycle(0.1, pose, &path_west(pose.x_m), tracker.tracks(), free_m)
                .is_some()
        })
    }

    #[test]
    fn drives_on_for_someone_walking_ahead_or_a_wide_corridor() {
        let west = |x0: f64, y: f64, v: f64| {
            move |t: f64| Pose2D::new(x0 - v * t, y, std::f64::consts::PI)
        };
        // Someone walking away from the robot through the gap: follow, no waiting.
        let t = first_wait(30, west(29.0, 13.2, 0.4), |t| 27.0 - 0.6 * t, corridor);
        assert_eq!(t, None, "waited for someone walking away");
        // Someone coming the other way in a wide corridor (no cabinet): pass.
        let wide = |_: f64, y: f64| (y - 12.0).min(14.0 - y);
        let t = first_wait(30, west(29.0, 13.2, 0.4), |t| 24.0 + 0.6 * t, wide);
        assert_eq!(t, None, "waited in a 2 m corridor");
        // The same person in the gap's corridor: the robot waits.
        let t = first_wait(30, west(29.0, 13.2, 0.4), |t| 24.0 + 0.6 * t, corridor);
        assert!(t.is_some(), "no wait for someone coming through the gap");
    }

    #[test]
    fn goes_on_through_a_passage_it_has_entered() {
        // In the gap already, the person coming towards its far end.
        let t = first_wait(
            10,
            |t| Pose2D::new(26.2 - 0.3 * t, 13.45, std::f64::consts::PI),
            |t| 23.0 + 0.6 * t,
            corridor,
        );
        assert_eq!(t, None, "stopped inside the gap");
    }

    #[test]
    fn bad_values_are_named() {
        let bad = GiveWayConfig {
            hold_back_m: -1.0,
            ..GiveWayConfig::default()
        };
        match bad.validate() {
            Err(ConfigError::Invalid { field, .. }) => assert_eq!(field, "give_way.hold_back_m"),
            other => panic!("{other:?}"),
        }
        GiveWayConfig::default().validate().expect("defaults");
    }
}
