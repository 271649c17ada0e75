//! Keeping to the middle of passages: the smoothed path moved sideways to the middle of each
//! corridor and doorway it runs through.
//!
//! The shortest path hugs one side of a corridor after every turn, as close to the wall as the
//! robot's radius allows, because the shortcuts ([`crate::smoother`]) pull it straight from
//! corner to corner. What the floor plan does not have stands in exactly that lane: a cabinet
//! by the wall, the pane beside the opening of a glass door. Every controller that follows the
//! path is led past them with centimetres to spare, and the laser does not see glass
//! (docs/evaluation.md, round 12: all 23 glass contacts of the deployed LPE-Net and 39 of the
//! dynamic window's 43 in 100 task runs were at the panes beside the tasks' open glass doors). Nav2's
//! planners keep to the middle for the same reason: their costmaps charge for cells near
//! walls.
//!
//! Here, after smoothing: at each pose, the walls are found along the path's normal (taken over
//! half a metre of path, so that poses where two shortcuts meet do not cross when moved) on both
//! sides, by a sphere trace on the distance field; where they are at most
//! [`CentringParams::passage_max_m`] apart, the pose wants to move to the middle between them,
//! by at most [`CentringParams::max_shift_m`]; across a short opening in one side (a door off a
//! corridor) it keeps to the line between the middles on either side of it; elsewhere (a room,
//! an open hall) it stays. The wanted shifts are averaged along the path twice over
//! [`CentringParams::window_m`], so the path eases across instead of stepping, and grow from
//! zero (a smoothstep over [`CentringParams::taper_m`]) from the robot, to the goal and round
//! turns on the spot, which stay as they are. Where the moved path would bend tighter than
//! [`CentringParams::min_radius_m`] or not be free (a shift towards the inside of a bend, round
//! a corner), the shift round the spot is halved by a smooth factor, and where a spot still
//! breaks a rule it is taken away there. Headings follow the moved positions; poses that did
//! not move keep the search's exactly. A path that cannot be centred is kept as searched.
//!
//! Plain data in and out, in the grid frame, as the smoother.

use protocol::normalize_angle;
use serde::{Deserialize, Serialize};

use crate::map::{Disc, GridPose, PlanningMap};

/// The `[planner.centring]` table.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CentringParams {
    /// Off: the shortest smoothed path as it is.
    pub enabled: bool,
    /// A passage: walls on both sides of the path at most this far apart (wall to wall).
    pub passage_max_m: f64,
    /// Furthest a pose moves sideways.
    pub max_shift_m: f64,
    /// Length of the moving average the shifts are smoothed with (applied twice).
    pub window_m: f64,
    /// The tightest bend a shift may make (the robot turns on the spot, so the search's
    /// turning radius is a preference for smooth paths, not a limit of the base).
    pub min_radius_m: f64,
    /// A stretch at most this long where one side is open (a door in a corridor's wall, a side
    /// corridor) between two stretches of passage keeps to the line between their middles.
    pub bridge_m: f64,
    /// The shift grows from zero over this length from the start, to the goal and round turns
    /// on the spot (a smoothstep, so that the path keeps the headings there).
    pub taper_m: f64,
}

impl Default for CentringParams {
    fn default() -> Self {
        Self {
            enabled: true,
            passage_max_m: 3.0,
            max_shift_m: 0.6,
            window_m: 1.5,
            bridge_m: 2.5,
            min_radius_m: 0.3,
            taper_m: 2.0,
        }
    }
}

impl CentringParams {
    /// The first field out of range, with its value.
    #[must_use]
    pub fn invalid(&self) -> Option<(&'static str, f64)> {
        [
            ("centring.passage_max_m", self.passage_max_m),
            ("centring.max_shift_m", self.max_shift_m),
            ("centring.window_m", self.window_m),
            ("centring.bridge_m", self.bridge_m),
            ("centring.min_radius_m", self.min_radius_m),
            ("centring.taper_m", self.taper_m),
        ]
        .into_iter()
        .find(|(_, v)| !v.is_finite() || *v < 0.0)
    }
}

/// Distance from `(x, y)` along the unit direction `(dx, dy)` to the first obstacle (or unknown
/// cell, or disc), or `None` beyond `max_m`.
fn wall_along(
    map: &PlanningMap,
    discs: &[Disc],
    (x, y): (f64, f64),
    (dx, dy): (f64, f64),
    max_m: f64,
) -> Option<f64> {
    let res = map.grid().resolution_m();
    let mut d = 0.0;
    while d <= max_m {
        let c = map.clearance_among(discs, x + d * dx, y + d * dy);
        if c < res {
            return Some(d + c.max(0.0));
        }
        // The clearance is the distance to the nearest obstacle in any direction, so the ray
        // meets none before it.
        d += (c - 0.5 * res).max(0.5 * res);
    }
    None
}

/// The sideways shift (to the left of the path, metres) each pose wants: to the middle of the
/// passage it is in; across an opening no longer than [`CentringParams::bridge_m`] between two
/// passages, the line between their shifts; elsewhere none. `s_m` is each pose's arc length.
fn wanted_shifts(
    map: &PlanningMap,
    discs: &[Disc],
    poses: &[GridPose],
    normals: &[(f64, f64)],
    s_m: &[f64],
    p: &CentringParams,
) -> Vec<f64> {
    let middle = passage_middles(map, discs, poses, normals, p);
    let mut out: Vec<f64> = middle.iter().map(|m| m.unwrap_or(0.0)).collect();
    let mut i = 0;
    while i < middle.len() {
        if middle[i].is_some() {
            i += 1;
            continue;
        }
        let j = (i..middle.len())
            .find(|&k| middle[k].is_some())
            .unwrap_or(middle.len());
        if i > 0 && j < middle.len() && s_m[j] - s_m[i - 1] <= p.bridge_m {
            let (a, b) = (out[i - 1], out[j]);
            let span = s_m[j] - s_m[i - 1];
            for k in i..j {
                let f = if span > 0.0 {
                    (s_m[k] - s_m[i - 1]) / span
                } else {
                    0.0
                };
                out[k] = a + f * (b - a);
            }
        }
        i = j;
    }
    out
}

/// Each pose's shift to the middle of the passage it is in, `None` where a side is open.
fn passage_middles(
    map: &PlanningMap,
    discs: &[Disc],
    poses: &[GridPose],
    normals: &[(f64, f64)],
    p: &CentringParams,
) -> Vec<Option<f64>> {
    poses
        .iter()
        .zip(normals)
        .map(|(q, &(nx, ny))| {
            let left = wall_along(map, discs, (q.x_m, q.y_m), (nx, ny), p.passage_max_m);
            let right = wall_along(map, discs, (q.x_m, q.y_m), (-nx, -ny), p.passage_max_m);
            match (left, right) {
                (Some(l), Some(r)) if l + r <= p.passage_max_m => {
                    Some((0.5 * (l - r)).clamp(-p.max_shift_m, p.max_shift_m))
                }
                _ => None,
            }
        })
        .collect()
}

/// Moving average of `values` over `half` samples on each side (shorter at the ends).
fn moving_average(values: &[f64], half: usize) -> Vec<f64> {
    let n = values.len();
    let mut prefix = Vec::with_capacity(n + 1);
    prefix.push(0.0);
    for v in values {
        prefix.push(prefix[prefix.len() - 1] + v);
    }
    (0..n)
        .map(|i| {
            let (a, b) = (i.saturating_sub(half), (i + half + 1).min(n));
            #[allow(clippy::cast_precision_loss)]
            let count = (b - a) as f64;
            (prefix[b] - prefix[a]) / count
        })
        .collect()
}

/// The minimum of `values` over `half` samples on each side.
fn moving_minimum(values: &[f64], half: usize) -> Vec<f64> {
    let n = values.len();
    (0..n)
        .map(|i| {
            values[i.saturating_sub(half)..(i + half + 1).min(n)]
                .iter()
                .copied()
                .fold(f64::INFINITY, f64::min)
        })
        .collect()
}

/// The path moved to the middle of the passages it runs through (see the module docs); the
/// first and last poses are kept exactly. `discs` (grid frame) count as obstacles.
///
/// The result keeps what the search guarantees, with one exception: every pose free, poses at
/// most 1.5 × `spacing_m` apart, heading continuous; a moved stretch may bend down to
/// [`CentringParams::min_radius_m`] (the search keeps to `rho_m`; stretches that did not
/// move keep the search's poses exactly). Where the shifted path would break that (a shift
/// towards the inside of a tight bend, round a corner), the shift is halved round the spot,
/// and then taken away there; failing that, the original path is kept.
#[must_use]
pub fn centre(
    map: &PlanningMap,
    discs: &[Disc],
    poses: &[GridPose],
    p: &CentringParams,
    rho_m: f64,
    spacing_m: f64,
) -> Vec<GridPose> {
    let n = poses.len();
    if !p.enabled || n < 3 || p.max_shift_m <= 0.0 {
        return poses.to_vec();
    }
    let rho_m = rho_m.min(p.min_radius_m);
    if rho_m <= 0.0 {
        return poses.to_vec();
    }
    let s_m = GridPose::arc_lengths(poses);
    let length_m = s_m[n - 1];
    if length_m <= 0.0 {
        return poses.to_vec();
    }
    // Where the path must stay put: its ends (the robot, the goal) and turns on the spot, whose
    // poses share one position.
    let mut anchors_m = vec![0.0, length_m];
    for i in 1..n {
        if s_m[i] - s_m[i - 1] < 1e-6 {
            anchors_m.push(s_m[i]);
        }
    }
    let ramp: Vec<f64> = s_m
        .iter()
        .map(|&s| {
            let near_m = anchors_m
                .iter()
                .map(|a| (s - a).abs())
                .fold(f64::INFINITY, f64::min);
            if p.taper_m > 0.0 {
                // Smoothstep: no slope at the anchor either, so the path leaves the robot and
                // meets the goal in their own headings.
                let t = (near_m / p.taper_m).clamp(0.0, 1.0);
                t * t * (3.0 - 2.0 * t)
            } else if near_m > 0.0 {
                1.0
            } else {
                0.0
            }
        })
        .collect();
    #[allow(clippy::cast_precision_loss)]
    let step_m = length_m / (n - 1) as f64;
    let normals = normals(poses, &s_m, NORMAL_REACH_M);
    let wanted: Vec<f64> = wanted_shifts(map, discs, poses, &normals, &s_m, p)
        .iter()
        .zip(&ramp)
        .map(|(o, r)| o * r)
        .collect();
    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
    let half = ((0.5 * p.window_m / step_m).round() as usize).max(1);
    let shift: Vec<f64> = moving_average(&moving_average(&wanted, half), half)
        .iter()
        .zip(&ramp)
        .map(|(o, r)| o * r)
        .collect();
    // A shift towards the inside of a bend tightens it, and one round a corner may run into
    // it. Where the moved path bends tighter than the robot may turn or is not free, the shift
    // round the spot is halved, by a factor that is itself smooth (the halving's minimum over
    // a window, averaged over the same window), and the path moved again. The moved path's
    // bends are what count, not the search's: a bend that takes the shortest path across to a
    // wall disappears once the path keeps to the middle.
    let kappa_max = 1.0 / rho_m;
    let mut factor = vec![1.0; n];
    for _ in 0..HALVING_ROUNDS {
        let scaled: Vec<f64> = shift.iter().zip(&factor).map(|(o, f)| o * f).collect();
        let moved: Vec<(f64, f64)> = poses
            .iter()
            .zip(&normals)
            .zip(&scaled)
            .map(|((q, &(nx, ny)), &o)| (q.x_m + o * nx, q.y_m + o * ny))
            .collect();
        let free = |&(x, y): &(f64, f64)| map.clearance_among(discs, x, y) >= map.robot_radius_m();
        let need: Vec<f64> = bend_curvature(&moved, &s_m, CURVATURE_REACH_M)
            .iter()
            .zip(&scaled)
            .zip(&moved)
            .map(|((k, o), q)| {
                if o.abs() > 1e-9 && (*k > kappa_max || !free(q)) {
                    0.5
                } else {
                    1.0
                }
            })
            .collect();
        if need.iter().all(|&v| v >= 1.0) {
            break;
        }
        retreat(&mut factor, &need, half, half);
    }
    // The moved positions are averaged (over half the shifts' length) and checked; where a
    // spot still breaks a rule, the shift round it is taken away (by the same smooth factor)
    // and the rest tried again; after [`LOCAL_ROUNDS`] the original path is kept.
    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
    let half_pos = (half / 2).max(1);
    for _ in 0..LOCAL_ROUNDS {
        let scaled: Vec<f64> = shift.iter().zip(&factor).map(|(o, f)| o * f).collect();
        let (moved, verbatim) = reshaped(
            map, discs, poses, &normals, &scaled, &ramp, half_pos, spacing_m,
        );
        let bad = violations(map, discs, &moved, &verbatim, rho_m);
        if bad.is_empty() {
            return moved;
        }
        let mut need = vec![1.0; n];
        for b in bad {
            let (x, y) = (moved[b].x_m, moved[b].y_m);
            let k = (0..n)
                .min_by(|&i, &j| {
                    let di = (poses[i].x_m - x).hypot(poses[i].y_m - y);
                    let dj = (poses[j].x_m - x).hypot(poses[j].y_m - y);
                    di.total_cmp(&dj)
                })
                .unwrap_or(0);
            need[k] = 0.0;
        }
        retreat(&mut factor, &need, 2 * half, half);
    }
    poses.to_vec()
}

/// Scales `factor` down by what each pose `need`s, smoothly: the need's minimum over `erode`
/// poses on each side, averaged over `half` (so never more than any pose in reach needs).
fn retreat(factor: &mut [f64], need: &[f64], erode: usize, half: usize) {
    let step = moving_average(&moving_minimum(need, erode), half);
    for (f, s) in factor.iter_mut().zip(&step) {
        *f *= s;
    }
}

/// Rounds of [`centre`]'s local retreat before it keeps the original path.
const LOCAL_ROUNDS: usize = 5;

/// Rounds of halving the shift round bends that come out too tight, in [`centre`].
const HALVING_ROUNDS: usize = 8;

/// The indices of the first pose at most `reach_m` of arc length before pose `i` and the last
/// at most that far after it (`i` itself at the ends).
fn reach(s_m: &[f64], i: usize, reach_m: f64) -> (usize, usize) {
    let a = s_m.partition_point(|&s| s < s_m[i] - reach_m).min(i);
    let b = s_m
        .partition_point(|&s| s <= s_m[i] + reach_m)
        .clamp(i + 1, s_m.len())
        - 1;
    (a, b)
}

/// Unsigned curvature of the polyline `points` at each point: the turn between the chords to
/// the points `reach_m` of arc length (of the original path, `s_m`) before and after it, over
/// that length.
fn bend_curvature(points: &[(f64, f64)], s_m: &[f64], reach_m: f64) -> Vec<f64> {
    let n = points.len();
    (0..n)
        .map(|i| {
            let (a, b) = reach(s_m, i, reach_m);
            if a == i || b == i {
                return 0.0;
            }
            let (p, q, r) = (points[a], points[i], points[b]);
            let (l1, l2) = ((q.0 - p.0).hypot(q.1 - p.1), (r.0 - q.0).hypot(r.1 - q.1));
            if l1 < 1e-6 || l2 < 1e-6 {
                return 0.0;
            }
            let turn = normalize_angle((r.1 - q.1).atan2(r.0 - q.0) - (q.1 - p.1).atan2(q.0 - p.0));
            turn.abs() / (0.5 * (l1 + l2))
        })
        .collect()
}

/// The moved path's curvature at a pose is measured over this arc length either side.
const CURVATURE_REACH_M: f64 = 0.15;

/// The second average applies in full where the shift is at least this.
const SMOOTH_FULL_M: f64 = 0.05;

/// The path's direction at a pose is taken over this much arc length on either side: shifted
/// along their own headings, poses a few millimetres apart where two shortcuts meet would
/// cross each other.
const NORMAL_REACH_M: f64 = 0.25;

/// Each pose's left normal, from the direction between the points `reach_m` of arc length
/// before and after it (its own heading where the path does not move, turning on the spot).
fn normals(poses: &[GridPose], s_m: &[f64], reach_m: f64) -> Vec<(f64, f64)> {
    let n = poses.len();
    (0..n)
        .map(|i| {
            let (a, b) = reach(s_m, i, reach_m);
            let (dx, dy) = (poses[b].x_m - poses[a].x_m, poses[b].y_m - poses[a].y_m);
            let yaw = if dx.hypot(dy) > 1e-6 {
                dy.atan2(dx)
            } else {
                poses[i].yaw_rad
            };
            (-yaw.sin(), yaw.cos())
        })
        .collect()
}

/// `poses` each moved `shift` along its normal, pulled back towards the original until free
/// (the original is); the moved positions averaged once more over `half` poses on each side
/// where the shift is at least [`SMOOTH_FULL_M`] (less of it where it is less), where the
/// average is free; headings turned by as much as the moved neighbours turn the chord between
/// them; a moved pose not ahead of the one before it left out; and poses put in where moved
/// ones came too far apart. Poses whose neighbourhood did not move stay exactly as the search
/// put them (the ends and turns on the spot, where `ramp` is 0, rooms and halls), and are
/// flagged as such for [`violations`].
#[allow(clippy::too_many_arguments)]
fn reshaped(
    map: &PlanningMap,
    discs: &[Disc],
    poses: &[GridPose],
    normals: &[(f64, f64)],
    shift: &[f64],
    ramp: &[f64],
    half: usize,
    spacing_m: f64,
) -> (Vec<GridPose>, Vec<bool>) {
    let free = |x: f64, y: f64| map.clearance_among(discs, x, y) >= map.robot_radius_m();
    let moved: Vec<(f64, f64)> = poses
        .iter()
        .zip(normals)
        .zip(shift)
        .map(|((q, &(nx, ny)), &o)| {
            let mut o = o;
            for _ in 0..6 {
                let (x, y) = (q.x_m + o * nx, q.y_m + o * ny);
                if free(x, y) {
                    return (x, y);
                }
                o *= 0.5;
            }
            (q.x_m, q.y_m)
        })
        .collect();
    let xs = moving_average(&moved.iter().map(|m| m.0).collect::<Vec<_>>(), half);
    let ys = moving_average(&moved.iter().map(|m| m.1).collect::<Vec<_>>(), half);
    let points: Vec<(f64, f64)> = moved
        .iter()
        .enumerate()
        .map(|(i, &(x, y))| {
            // Only where the path was shifted: elsewhere the average would cut its bends.
            let w = ramp[i] * (shift[i].abs() / SMOOTH_FULL_M).min(1.0);
            let (sx, sy) = (x + w * (xs[i] - x), y + w * (ys[i] - y));
            if free(sx, sy) {
                (sx, sy)
            } else {
                (x, y)
            }
        })
        .collect();

    // Headings: the search's own, turned by as much as the moved neighbours turn the chord
    // between them, so that where nothing moved the pose stays exactly as the search put it
    // and an arc keeps its discretisation.
    let n = poses.len();
    let original: Vec<(f64, f64)> = poses.iter().map(|q| (q.x_m, q.y_m)).collect();
    let moved_at: Vec<bool> = points
        .iter()
        .zip(&original)
        .map(|(a, b)| (a.0 - b.0).hypot(a.1 - b.1) >= 1e-9)
        .collect();
    let mut out: Vec<GridPose> = Vec::with_capacity(n);
    let mut verbatim: Vec<bool> = Vec::with_capacity(n);
    for i in 0..n {
        if i == 0 || i == n - 1 || !moved_at[i - 1..=i + 1].contains(&true) {
            out.push(poses[i]);
            verbatim.push(true);
            continue;
        }
        let ((was, was_m), (is, is_m)) = (
            chord(original[i - 1], original[i + 1]),
            chord(points[i - 1], points[i + 1]),
        );
        let yaw_rad = if was_m > 1e-6 && is_m > 1e-6 {
            normalize_angle(poses[i].yaw_rad + normalize_angle(is - was))
        } else {
            poses[i].yaw_rad
        };
        let q = GridPose {
            x_m: points[i].0,
            y_m: points[i].1,
            yaw_rad,
        };
        // A moved pose must be ahead of the one before it (the heading turned right by a
        // quarter is the normal).
        if let Some(last) = out.last() {
            let (nx, ny) = normals[i];
            let ahead_m = (q.x_m - last.x_m) * ny - (q.y_m - last.y_m) * nx;
            if ahead_m <= 1e-4 && step(*last, q) > 1e-9 {
                continue;
            }
        }
        out.push(q);
        verbatim.push(false);
    }
    densify(&out, &verbatim, spacing_m)
}

/// Direction and length of the chord from `a` to `b`.
fn chord(a: (f64, f64), b: (f64, f64)) -> (f64, f64) {
    ((b.1 - a.1).atan2(b.0 - a.0), (b.0 - a.0).hypot(b.1 - a.1))
}

fn step(a: GridPose, b: GridPose) -> f64 {
    (b.x_m - a.x_m).hypot(b.y_m - a.y_m)
}

/// Poses put in between neighbours more than 1.5 × `spacing_m` apart (a bend moved outwards is
/// longer), on the straight line between them and turning evenly; they are not verbatim.
fn densify(poses: &[GridPose], verbatim: &[bool], spacing_m: f64) -> (Vec<GridPose>, Vec<bool>) {
    let mut out = Vec::with_capacity(poses.len());
    let mut flags = Vec::with_capacity(poses.len());
    for (k, w) in poses.windows(2).enumerate() {
        let (a, b) = (w[0], w[1]);
        out.push(a);
        flags.push(verbatim[k]);
        let d = step(a, b);
        if d > 1.5 * spacing_m {
            #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
            let pieces = (d / spacing_m).ceil() as usize;
            let dyaw = normalize_angle(b.yaw_rad - a.yaw_rad);
            for j in 1..pieces {
                #[allow(clippy::cast_precision_loss)]
                let t = j as f64 / pieces as f64;
                out.push(GridPose {
                    x_m: a.x_m + t * (b.x_m - a.x_m),
                    y_m: a.y_m + t * (b.y_m - a.y_m),
                    yaw_rad: normalize_angle(a.yaw_rad + t * dyaw),
                });
                flags.push(false);
            }
        }
    }
    if let (Some(last), Some(flag)) = (poses.last(), verbatim.last()) {
        out.push(*last);
        flags.push(*flag);
    }
    (out, flags)
}

/// Indices of poses where the path is not drivable: not free, or a step that turns tighter
/// than `rho_m` (turns on the spot, and steps between two poses as the search put them,
/// excepted).
fn violations(
    map: &PlanningMap,
    discs: &[Disc],
    poses: &[GridPose],
    verbatim: &[bool],
    rho_m: f64,
) -> Vec<usize> {
    let r = map.robot_radius_m();
    let mut bad = Vec::new();
    for (i, w) in poses.windows(2).enumerate() {
        let (a, b) = (w[0], w[1]);
        if verbatim[i] && verbatim[i + 1] {
            // As the search put them.
            continue;
        }
        if map.clearance_among(discs, b.x_m, b.y_m) < r {
            bad.push(i + 1);
            continue;
        }
        let d = (b.x_m - a.x_m).hypot(b.y_m - a.y_m);
        if d < 1e-9 {
            continue;
        }
        let dyaw = normalize_angle(b.yaw_rad - a.yaw_rad).abs();
        let chord = (b.y_m - a.y_m).atan2(b.x_m - a.x_m);
        let mid = a.yaw_rad + 0.5 * normalize_angle(b.yaw_rad - a.yaw_rad);
        if dyaw > 1.02 * d / rho_m || normalize_angle(chord - mid).abs() > d / rho_m + 1e-3 {
            bad.push(i);
        }
    }
    bad
}
