//! Shortcut smoothing: replace stretches of the lattice path by collision-checked Dubins curves.
//!
//! Lattice paths zig-zag between the discrete primitives. From each pose the smoother tries a
//! Dubins curve to a pose far down the path (the goal first, then halving the gap) and keeps
//! the first one that is collision-free and shorter than the stretch it replaces. Dubins curves
//! respect the turning radius and match the headings at both ends, so the result stays
//! drivable, continuous in heading and collision-free (each shortcut is checked against the
//! distance field exactly as the search checks primitives).

use protocol::normalize_angle;

use crate::dubins::DubinsPath;
use crate::map::{Disc, GridPose, PlanningMap};

/// Poses copied unchanged when no shortcut starts at a pose: a shortcut spanning fewer poses
/// than this would gain almost nothing.
const MIN_SPAN: usize = 8;

/// The shortcut-smoothed path (see the module docs), keeping out of `discs` (grid frame) as
/// well as the map's obstacles; endpoints are kept exactly.
#[must_use]
pub fn shortcut(
    map: &PlanningMap,
    discs: &[Disc],
    poses: &[GridPose],
    rho_m: f64,
    spacing_m: f64,
) -> Vec<GridPose> {
    let n = poses.len();
    if n < 3 {
        return poses.to_vec();
    }
    let cum = GridPose::arc_lengths(poses);
    let mut out = vec![poses[0]];
    let mut i = 0;
    while i < n - 1 {
        let mut gap = n - 1 - i;
        let mut found = None;
        while gap >= 2 {
            let j = i + gap;
            let (a, b) = (poses[i], poses[j]);
            if let Some(d) =
                DubinsPath::shortest((a.x_m, a.y_m, a.yaw_rad), (b.x_m, b.y_m, b.yaw_rad), rho_m)
            {
                // Chords understate the stretch's length by less than this, so a shortcut that
                // is not shorter by more is not worth it.
                if d.length_m() + 1e-3 < cum[j] - cum[i]
                    && map.curve_free_among(discs, d.length_m(), spacing_m, |t| {
                        let q = d.sample(t);
                        (q.0, q.1)
                    })
                {
                    found = Some((j, d));
                    break;
                }
            }
            gap /= 2;
        }
        if let Some((j, d)) = found {
            let len = d.length_m();
            let steps = (len / spacing_m).ceil().max(1.0);
            #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
            for k in 1..(steps as u32) {
                let q = d.sample(len * f64::from(k) / steps);
                out.push(GridPose {
                    x_m: q.0,
                    y_m: q.1,
                    yaw_rad: normalize_angle(q.2),
                });
            }
            out.push(poses[j]);
            i = j;
        } else {
            let next = (i + MIN_SPAN).min(n - 1);
            out.extend_from_slice(&poses[i + 1..=next]);
            i = next;
        }
    }
    out
}
