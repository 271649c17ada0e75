//! Dubins curves: the shortest forward path between two poses with a bounded turning radius.
//!
//! The six words (LSL, RSR, LSR, RSL, RLR, LRL) in the normalized closed form of Shkel &
//! Lumelsky (2001), as popularized by A. Walker's `dubins.c`. Hybrid A* uses them for the
//! analytic expansion to the goal, as the obstacle-free non-holonomic heuristic, and the
//! smoother uses them for shortcuts.

use std::f64::consts::TAU;

/// One segment type: turn left, straight, turn right.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Seg {
    L,
    S,
    R,
}

/// A Dubins path from a start pose (x, y, yaw) with turning radius `rho_m`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DubinsPath {
    start: (f64, f64, f64),
    rho_m: f64,
    /// Normalized segment lengths (multiples of `rho_m`).
    params: [f64; 3],
    word: [Seg; 3],
}

fn mod2pi(a: f64) -> f64 {
    a.rem_euclid(TAU)
}

impl DubinsPath {
    /// The shortest Dubins path from `q0` to `q1` (each `(x_m, y_m, yaw_rad)`), or `None` when
    /// the radius is not positive or an input is not finite.
    #[must_use]
    pub fn shortest(q0: (f64, f64, f64), q1: (f64, f64, f64), rho_m: f64) -> Option<Self> {
        if !rho_m.is_finite()
            || rho_m <= 0.0
            || ![q0.0, q0.1, q0.2, q1.0, q1.1, q1.2]
                .iter()
                .all(|v| v.is_finite())
        {
            return None;
        }
        let dx = q1.0 - q0.0;
        let dy = q1.1 - q0.1;
        let d = dx.hypot(dy) / rho_m;
        let theta = if d > 0.0 { mod2pi(dy.atan2(dx)) } else { 0.0 };
        let alpha = mod2pi(q0.2 - theta);
        let beta = mod2pi(q1.2 - theta);
        let (sa, ca) = alpha.sin_cos();
        let (sb, cb) = beta.sin_cos();
        let c_ab = (alpha - beta).cos();
        let d_sq = d * d;

        let mut best: Option<([f64; 3], [Seg; 3])> = None;
        let mut consider = |p: [f64; 3], w: [Seg; 3]| {
            let len = p[0] + p[1] + p[2];
            if best.is_none_or(|(b, _)| len < b[0] + b[1] + b[2]) {
                best = Some((p, w));
            }
        };

        // LSL
        let p_sq = 2.0 + d_sq - 2.0 * c_ab + 2.0 * d * (sa - sb);
        if p_sq >= 0.0 {
            let tmp1 = (cb - ca).atan2(d + sa - sb);
            consider(
                [mod2pi(tmp1 - alpha), p_sq.sqrt(), mod2pi(beta - tmp1)],
                [Seg::L, Seg::S, Seg::L],
            );
        }
        // RSR
        let p_sq = 2.0 + d_sq - 2.0 * c_ab + 2.0 * d * (sb - sa);
        if p_sq >= 0.0 {
            let tmp1 = (ca - cb).atan2(d - sa + sb);
            consider(
                [mod2pi(alpha - tmp1), p_sq.sqrt(), mod2pi(tmp1 - beta)],
                [Seg::R, Seg::S, Seg::R],
            );
        }
        // LSR
        let p_sq = -2.0 + d_sq + 2.0 * c_ab + 2.0 * d * (sa + sb);
        if p_sq >= 0.0 {
            let p = p_sq.sqrt();
            let tmp0 = (-ca - cb).atan2(d + sa + sb) - (-2.0_f64).atan2(p);
            consider(
                [mod2pi(tmp0 - alpha), p, mod2pi(tmp0 - beta)],
                [Seg::L, Seg::S, Seg::R],
            );
        }
        // RSL
        let p_sq = -2.0 + d_sq + 2.0 * c_ab - 2.0 * d * (sa + sb);
        if p_sq >= 0.0 {
            let p = p_sq.sqrt();
            let tmp0 = (ca + cb).atan2(d - sa - sb) - 2.0_f64.atan2(p);
            consider(
                [mod2pi(alpha - tmp0), p, mod2pi(beta - tmp0)],
                [Seg::R, Seg::S, Seg::L],
            );
        }
        // RLR
        let tmp0 = (6.0 - d_sq + 2.0 * c_ab + 2.0 * d * (sa - sb)) / 8.0;
        if tmp0.abs() <= 1.0 {
            let phi = (ca - cb).atan2(d - sa + sb);
            let p = mod2pi(TAU - tmp0.acos());
            let t = mod2pi(alpha - phi + mod2pi(p / 2.0));
            consider(
                [t, p, mod2pi(alpha - beta - t + mod2pi(p))],
                [Seg::R, Seg::L, Seg::R],
            );
        }
        // LRL
        let tmp0 = (6.0 - d_sq + 2.0 * c_ab + 2.0 * d * (sb - sa)) / 8.0;
        if tmp0.abs() <= 1.0 {
            let phi = (ca - cb).atan2(d + sa - sb);
            let p = mod2pi(TAU - tmp0.acos());
            let t = mod2pi(-alpha - phi + p / 2.0);
            consider(
                [t, p, mod2pi(mod2pi(beta) - alpha - t + mod2pi(p))],
                [Seg::L, Seg::R, Seg::L],
            );
        }

        best.map(|(params, word)| Self {
            start: q0,
            rho_m,
            params,
            word,
        })
    }

    /// Total length in metres.
    #[must_use]
    pub fn length_m(&self) -> f64 {
        (self.params[0] + self.params[1] + self.params[2]) * self.rho_m
    }

    /// The pose after `s_m` metres along the path (clamped to the path).
    #[must_use]
    pub fn sample(&self, s_m: f64) -> (f64, f64, f64) {
        let t = (s_m / self.rho_m).clamp(0.0, self.params.iter().sum());
        // Walk in the normalized frame (unit radius, start at the origin with the start yaw).
        let mut q = (0.0, 0.0, self.start.2);
        let mut remaining = t;
        for (len, seg) in self.params.iter().zip(self.word) {
            let step = remaining.min(*len);
            q = segment(step, q, seg);
            remaining -= step;
            if remaining <= 0.0 {
                break;
            }
        }
        (
            self.start.0 + q.0 * self.rho_m,
            self.start.1 + q.1 * self.rho_m,
            q.2,
        )
    }
}

fn segment(t: f64, q: (f64, f64, f64), seg: Seg) -> (f64, f64, f64) {
    let (x, y, th) = q;
    match seg {
        Seg::L => (
            x + (th + t).sin() - th.sin(),
            y - (th + t).cos() + th.cos(),
            th + t,
        ),
        Seg::R => (
            x - (th - t).sin() + th.sin(),
            y + (th - t).cos() - th.cos(),
            th - t,
        ),
        Seg::S => (x + th.cos() * t, y + th.sin() * t, th),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use protocol::normalize_angle;
    use rand::{Rng, SeedableRng};

    #[test]
    fn ends_at_the_goal_and_is_at_least_the_straight_distance() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        for _ in 0..500 {
            let q0 = (
                rng.gen_range(-5.0..5.0),
                rng.gen_range(-5.0..5.0),
                rng.gen_range(-4.0..4.0),
            );
            let q1 = (
                rng.gen_range(-5.0..5.0),
                rng.gen_range(-5.0..5.0),
                rng.gen_range(-4.0..4.0),
            );
            let rho = rng.gen_range(0.2..2.0);
            let p = DubinsPath::shortest(q0, q1, rho).unwrap();
            let end = p.sample(p.length_m());
            assert!(
                (end.0 - q1.0).abs() < 1e-6 && (end.1 - q1.1).abs() < 1e-6,
                "{q0:?} {q1:?}"
            );
            assert!(normalize_angle(end.2 - q1.2).abs() < 1e-6);
            let straight = (q1.0 - q0.0).hypot(q1.1 - q0.1);
            assert!(p.length_m() >= straight - 1e-9);
            // Consecutive samples are never further apart than the arc length between them.
            let mut prev = p.sample(0.0);
            let n = 50;
            for i in 1..=n {
                let s = p.length_m() * f64::from(i) / f64::from(n);
                let q = p.sample(s);
                assert!((q.0 - prev.0).hypot(q.1 - prev.1) <= p.length_m() / f64::from(n) + 1e-9);
                // Motion follows the heading: the chord points along the headings, up to the
                // turning the step allows.
                let step = p.length_m() / f64::from(n);
                if step > 1e-6 && step / rho < 0.5 {
                    let chord = (q.1 - prev.1).atan2(q.0 - prev.0);
                    let mid = prev.2 + normalize_angle(q.2 - prev.2) / 2.0;
                    assert!(
                        normalize_angle(chord - mid).abs() <= step / rho + 1e-6,
                        "{q0:?} {q1:?} at {s}"
                    );
                }
                prev = q;
            }
        }
    }

    #[test]
    fn straight_ahead_is_a_line_and_behind_needs_a_turn() {
        let p = DubinsPath::shortest((0.0, 0.0, 0.0), (3.0, 0.0, 0.0), 1.0).unwrap();
        assert!((p.length_m() - 3.0).abs() < 1e-9);
        let p =
            DubinsPath::shortest((0.0, 0.0, 0.0), (-3.0, 0.0, std::f64::consts::PI), 1.0).unwrap();
        // Half circle plus straight: pi * 1 + ... at least 3 + pi - 2 (turn around radius 1).
        assert!(p.length_m() > 3.0 + 1.0);
        assert!(DubinsPath::shortest((0.0, 0.0, 0.0), (1.0, 0.0, 0.0), 0.0).is_none());
    }
}
