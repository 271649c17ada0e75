//! People, and anything else that walks, in the laser scan: which returns move, grouped into
//! bodies that are tracked from cycle to cycle with a velocity.
//!
//! - **Candidates:** the supervisor passes the returns that lie neither on the floor plan's
//!   walls nor on the obstacle layer's confirmed cells (map frame).
//! - **Moving:** of those, the ones in no cell (or next to one) that candidates of
//!   [`STILL_FROM`] to [`HISTORY`] cycles ago were in. Something standing there then is still
//!   there; someone walking has moved on by more than a cell.
//! - **Bodies:** the nearest moving return and those within [`GROUP_M`] of it are one body,
//!   then the nearest of the rest, and so on. A body is matched to the track whose predicted
//!   position is nearest (within [`ASSOCIATE_M`]); its velocity is a running average of the
//!   centroid's motion. A track not seen this cycle is dropped.
//!
//! Two rules read the tracks: the give-way rule ([`crate::give_way`]) waits for the one coming
//! along the path, and the collision monitor ([`crate::collision_monitor`]) moves each body
//! on by its velocity when it looks ahead. Plain data in, tracks out.

use std::collections::{HashSet, VecDeque};

/// Cycles of candidate returns remembered ...
pub const HISTORY: usize = 20;
/// ... of which those at least this many cycles old say what stands still.
pub const STILL_FROM: usize = 10;
/// Side of the cells the history is kept in.
const HISTORY_CELL_M: f64 = 0.1;
/// Returns within this of a body's nearest one belong to the same body.
pub const GROUP_M: f64 = 0.5;
/// A body this close to where a track was expected is the same mover.
const ASSOCIATE_M: f64 = 0.4;
/// Weight of the newest velocity measurement in the tracked velocity.
const VELOCITY_GAIN: f64 = 0.3;
/// ... and while the track is young, so that its first estimate comes quickly.
const YOUNG_VELOCITY_GAIN: f64 = 0.6;
/// A track younger than this has no velocity to judge by.
pub const MIN_TRACK_S: f64 = 0.5;
/// Slower than this, a settled track is taken to stand (its velocity is mostly noise): the
/// collision monitor's bodies crossing the heading, the recovery's people walking near.
pub const MIN_WALKING_MPS: f64 = 0.2;
/// Scans further apart than this start the tracking afresh (what was seen is too old to say
/// what stands still, and a body has moved too far to match).
const MAX_GAP_S: f64 = 0.5;
/// A mover's returns lie at least this far from the obstacle layer's confirmed cells.
const MOVER_SEEN_GAP_M: f64 = 0.2;

/// Whether a laser return could be a mover: `map_gap_m` from the floor plan's nearest wall
/// (at least `min_map_gap_m`) and `seen_gap_m` from the obstacle layer's nearest confirmed
/// cell. Returns on a cabinet's faces that the layer has not confirmed yet (seen edge-on, a
/// beam now and then) lie next to ones it has; someone walking by keeps their body's width off
/// anything.
#[must_use]
pub fn off_the_plan(min_map_gap_m: f64, map_gap_m: f64, seen_gap_m: f64) -> bool {
    map_gap_m >= min_map_gap_m && seen_gap_m >= MOVER_SEEN_GAP_M
}

/// A body followed from cycle to cycle (map frame).
#[derive(Debug, Clone, PartialEq)]
pub struct Track {
    /// Centroid of this cycle's returns.
    pub x_m: f64,
    pub y_m: f64,
    pub vx_mps: f64,
    pub vy_mps: f64,
    /// How long it has been followed.
    pub age_s: f64,
    /// This cycle's returns.
    pub points_m: Vec<[f64; 2]>,
}

impl Track {
    /// Whether it has been followed long enough for its velocity to mean something.
    #[must_use]
    pub fn settled(&self) -> bool {
        self.age_s >= MIN_TRACK_S
    }

    /// The largest distance from the centroid to one of its returns.
    #[must_use]
    pub fn extent_m(&self) -> f64 {
        self.points_m
            .iter()
            .map(|&[x, y]| (x - self.x_m).hypot(y - self.y_m))
            .fold(0.0, f64::max)
    }
}

/// The tracker's state: the candidates' history and the tracks.
#[derive(Debug, Clone, Default)]
pub struct MoverTracker {
    history: VecDeque<HashSet<(i64, i64)>>,
    tracks: Vec<Track>,
}

impl MoverTracker {
    /// This cycle's tracks.
    #[must_use]
    pub fn tracks(&self) -> &[Track] {
        &self.tracks
    }

    /// Forgets everything (a stop, an intervention, a lost localisation).
    pub fn reset(&mut self) {
        self.history.clear();
        self.tracks.clear();
    }

    /// One cycle of `dt_s` with this cycle's candidate returns (map frame) seen from `from_m`
    /// (the robot): the bodies among them are matched to the tracks.
    pub fn update(&mut self, dt_s: f64, from_m: [f64; 2], candidates_m: &[[f64; 2]]) {
        if dt_s > MAX_GAP_S {
            self.reset();
        }
        let moving = self.moving(candidates_m);
        let bodies = group(from_m, moving);
        let mut previous = std::mem::take(&mut self.tracks);
        for points_m in bodies {
            #[allow(clippy::cast_precision_loss)]
            let n = points_m.len() as f64;
            let (cx, cy) = points_m
                .iter()
                .fold((0.0, 0.0), |(sx, sy), &[x, y]| (sx + x / n, sy + y / n));
            // The nearest predicted track; bodies come nearest the robot first, so the body
            // that matters most is matched first.
            let matched = (dt_s > 0.0)
                .then(|| {
                    previous
                        .iter()
                        .enumerate()
                        .map(|(i, t)| {
                            let (px, py) = (t.x_m + t.vx_mps * dt_s, t.y_m + t.vy_mps * dt_s);
                            (i, (cx - px).hypot(cy - py))
                        })
                        .filter(|&(_, d)| d <= ASSOCIATE_M)
                        .min_by(|a, b| a.1.total_cmp(&b.1))
                })
                .flatten()
                .map(|(i, _)| previous.swap_remove(i));
            let track = match matched {
                Some(t) => {
                    let (mx, my) = ((cx - t.x_m) / dt_s, (cy - t.y_m) / dt_s);
                    let g = if t.settled() {
                        VELOCITY_GAIN
                    } else {
                        YOUNG_VELOCITY_GAIN
                    };
                    Track {
                        x_m: cx,
                        y_m: cy,
                        vx_mps: t.vx_mps + g * (mx - t.vx_mps),
                        vy_mps: t.vy_mps + g * (my - t.vy_mps),
                        age_s: t.age_s + dt_s,
                        points_m,
                    }
                }
                None => Track {
                    x_m: cx,
                    y_m: cy,
                    vx_mps: 0.0,
                    vy_mps: 0.0,
                    age_s: 0.0,
                    points_m,
                },
            };
            self.tracks.push(track);
        }
    }

    /// The candidates that are moving: those in no cell (or next to one) that the candidates
    /// of [`STILL_FROM`] to [`HISTORY`] cycles ago were in. The faces of a cabinet the obstacle
    /// layer has not confirmed yet (seen edge-on, hit now and then) are standing things too.
    fn moving(&mut self, candidates_m: &[[f64; 2]]) -> Vec<[f64; 2]> {
        let cell = |x: f64, y: f64| {
            #[allow(clippy::cast_possible_truncation)]
            (
                (x / HISTORY_CELL_M).floor() as i64,
                (y / HISTORY_CELL_M).floor() as i64,
            )
        };
        let earlier: HashSet<(i64, i64)> = self
            .history
            .iter()
            .take(self.history.len().saturating_sub(STILL_FROM))
            .flatten()
            .copied()
            .collect();
        let moving = candidates_m
            .iter()
            .filter(|&&[x, y]| {
                let (ix, iy) = cell(x, y);
                !(-1..=1).any(|dx| (-1..=1).any(|dy| earlier.contains(&(ix + dx, iy + dy))))
            })
            .copied()
            .collect();
        if self.history.len() == HISTORY {
            self.history.pop_front();
        }
        self.history
            .push_back(candidates_m.iter().map(|&[x, y]| cell(x, y)).collect());
        moving
    }
}

/// The moving returns as bodies, nearest to `from_m` first: the nearest return and those
/// within [`GROUP_M`] of it, then the nearest of the rest, and so on.
fn group(from_m: [f64; 2], mut points_m: Vec<[f64; 2]>) -> Vec<Vec<[f64; 2]>> {
    let dist = |p: &[f64; 2]| (p[0] - from_m[0]).hypot(p[1] - from_m[1]);
    points_m.sort_by(|a, b| dist(a).total_cmp(&dist(b)));
    let mut bodies = Vec::new();
    while let Some(&seed) = points_m.first() {
        let (body, rest): (Vec<_>, Vec<_>) = points_m
            .into_iter()
            .partition(|p| (p[0] - seed[0]).hypot(p[1] - seed[1]) <= GROUP_M);
        bodies.push(body);
        points_m = rest;
    }
    bodies
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The returns of a person's near side: a half circle of radius 0.2 facing `from`.
    fn person(x: f64, y: f64, from: [f64; 2]) -> Vec<[f64; 2]> {
        let facing = (from[1] - y).atan2(from[0] - x);
        (-4..=4)
            .map(|k| {
                let a = facing + f64::from(k) * 0.35;
                [x + 0.2 * a.cos(), y + 0.2 * a.sin()]
            })
            .collect()
    }

    #[test]
    fn two_people_walking_are_two_tracks_with_their_velocities() {
        // One walks towards the robot along x at 1 m/s, one crosses along y at 0.8 m/s; a
        // pillar returns from the same place every cycle.
        let mut tracker = MoverTracker::default();
        let robot = [0.0, 0.0];
        let dt = 0.1;
        for k in 0..25 {
            let t = f64::from(k) * dt;
            let mut seen = person(4.0 - t, 0.0, robot);
            seen.extend(person(0.8, -2.5 + 0.8 * t, robot));
            seen.extend(person(1.5, 2.0, robot));
            tracker.update(dt, robot, &seen);
        }
        let tracks = tracker.tracks();
        assert_eq!(tracks.len(), 2, "{tracks:?}");
        let oncoming = tracks.iter().find(|t| t.x_m > 1.2).unwrap();
        let crossing = tracks.iter().find(|t| t.x_m < 1.2).unwrap();
        assert!(oncoming.settled() && crossing.settled());
        assert!((oncoming.vx_mps + 1.0).abs() < 0.1, "{oncoming:?}");
        assert!(oncoming.vy_mps.abs() < 0.1, "{oncoming:?}");
        assert!((crossing.vy_mps - 0.8).abs() < 0.1, "{crossing:?}");
        assert!(crossing.vx_mps.abs() < 0.1, "{crossing:?}");
        assert!(oncoming.extent_m() < 0.25);
    }

    #[test]
    fn someone_standing_is_no_mover_once_seen_a_second() {
        let mut tracker = MoverTracker::default();
        let robot = [0.0, 0.0];
        for _ in 0..STILL_FROM + 2 {
            tracker.update(0.1, robot, &person(2.0, 0.5, robot));
        }
        assert!(tracker.tracks().is_empty(), "{:?}", tracker.tracks());
        tracker.reset();
        tracker.update(0.1, robot, &person(2.0, 0.5, robot));
        assert_eq!(tracker.tracks().len(), 1);
    }
}
