//! Odometry motion model (Thrun et al., Probabilistic Robotics, Table 5.6
//! `sample_motion_model_odometry`, with Nav2's handling of driving backwards).
//!
//! The relative motion between two odometry poses is decomposed into a rotation towards the
//! direction of travel, a translation and a final rotation; each particle moves by that motion
//! with Gaussian noise whose variance grows with the motion (the four alphas).

use protocol::{normalize_angle, Pose2D};
use rand::Rng;
use rand_distr::StandardNormal;

/// Below this translation the direction of travel is meaningless, so all rotation goes to rot2.
const MIN_TRANS_FOR_ROT1_M: f64 = 0.01;

/// The four noise parameters, named as in Thrun et al. and Nav2.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MotionNoise {
    pub alpha1: f64,
    pub alpha2: f64,
    pub alpha3: f64,
    pub alpha4: f64,
}

/// A relative motion decomposed as (rot1, trans, rot2) plus the noise standard deviations that
/// the four-alpha model assigns to it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OdometryDelta {
    pub rot1_rad: f64,
    pub trans_m: f64,
    pub rot2_rad: f64,
    rot1_std_rad: f64,
    trans_std_m: f64,
    rot2_std_rad: f64,
}

impl OdometryDelta {
    /// Decomposes the motion from `from` to `to` (both in the odom frame).
    #[must_use]
    pub fn between(from: &Pose2D, to: &Pose2D, noise: &MotionNoise) -> Self {
        let dx = to.x_m - from.x_m;
        let dy = to.y_m - from.y_m;
        let trans_m = dx.hypot(dy);
        let rot1_rad = if trans_m < MIN_TRANS_FOR_ROT1_M {
            0.0
        } else {
            normalize_angle(dy.atan2(dx) - from.yaw_rad)
        };
        let rot2_rad = normalize_angle(to.yaw_rad - from.yaw_rad - rot1_rad);
        // Driving backwards is a rotation of about pi plus a translation; only the deviation
        // from straight forward or straight backward should count as rotation noise (Nav2).
        let rot1_noise = rot1_rad
            .abs()
            .min(normalize_angle(rot1_rad - std::f64::consts::PI).abs());
        let rot2_noise = rot2_rad
            .abs()
            .min(normalize_angle(rot2_rad - std::f64::consts::PI).abs());
        let t2 = trans_m * trans_m;
        Self {
            rot1_rad,
            trans_m,
            rot2_rad,
            rot1_std_rad: (noise.alpha1 * rot1_noise * rot1_noise + noise.alpha2 * t2).sqrt(),
            trans_std_m: (noise.alpha3 * t2
                + noise.alpha4 * (rot1_noise * rot1_noise + rot2_noise * rot2_noise))
                .sqrt(),
            rot2_std_rad: (noise.alpha1 * rot2_noise * rot2_noise + noise.alpha2 * t2).sqrt(),
        }
    }

    /// Moves `pose` by one noisy sample of this motion.
    #[inline]
    pub fn sample<R: Rng>(&self, pose: &mut Pose2D, rng: &mut R) {
        let n1: f64 = rng.sample(StandardNormal);
        let n2: f64 = rng.sample(StandardNormal);
        let n3: f64 = rng.sample(StandardNormal);
        let rot1 = self.rot1_rad - self.rot1_std_rad * n1;
        let trans = self.trans_m - self.trans_std_m * n2;
        let rot2 = self.rot2_rad - self.rot2_std_rad * n3;
        let heading = pose.yaw_rad + rot1;
        pose.x_m += trans * heading.cos();
        pose.y_m += trans * heading.sin();
        pose.yaw_rad = normalize_angle(heading + rot2);
    }

    /// Moves `pose` by the motion without noise.
    pub fn apply_exact(&self, pose: &mut Pose2D) {
        let heading = pose.yaw_rad + self.rot1_rad;
        pose.x_m += self.trans_m * heading.cos();
        pose.y_m += self.trans_m * heading.sin();
        pose.yaw_rad = normalize_angle(heading + self.rot2_rad);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    const NOISE: MotionNoise = MotionNoise {
        alpha1: 0.2,
        alpha2: 0.2,
        alpha3: 0.2,
        alpha4: 0.2,
    };

    #[test]
    fn exact_motion_reproduces_the_odometry_pose_change() {
        let from = Pose2D::new(1.0, 2.0, 0.3);
        for to in [
            Pose2D::new(1.5, 2.4, -0.2),
            Pose2D::new(0.2, 1.9, 3.0),
            Pose2D::new(1.0, 2.0, 1.0),
        ] {
            let d = OdometryDelta::between(&from, &to, &NOISE);
            // Applied to a particle rotated and shifted elsewhere, the motion is the same in the
            // particle's own frame; applied to `from` itself it must give `to`.
            let mut p = from;
            d.apply_exact(&mut p);
            assert!((p.x_m - to.x_m).abs() < 1e-12 && (p.y_m - to.y_m).abs() < 1e-12);
            assert!(normalize_angle(p.yaw_rad - to.yaw_rad).abs() < 1e-12);
        }
    }

    #[test]
    fn noisy_samples_scatter_around_the_motion_with_the_model_spread() {
        let from = Pose2D::new(0.0, 0.0, 0.0);
        let to = Pose2D::new(1.0, 0.0, 0.0);
        let d = OdometryDelta::between(&from, &to, &NOISE);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let n = 20_000;
        let (mut sx, mut sxx) = (0.0, 0.0);
        for _ in 0..n {
            let mut p = from;
            d.sample(&mut p, &mut rng);
            sx += p.x_m;
            sxx += p.x_m * p.x_m;
        }
        let mean = sx / f64::from(n);
        let std = (sxx / f64::from(n) - mean * mean).sqrt();
        // trans std = sqrt(alpha3) * 1 m = 0.447 m; rot noise shortens x a little on average.
        assert!((mean - 0.9).abs() < 0.1, "mean {mean}");
        assert!((std - 0.447).abs() < 0.05, "std {std}");
    }

    #[test]
    fn backward_motion_is_not_treated_as_a_half_turn() {
        let from = Pose2D::new(0.0, 0.0, 0.0);
        let to = Pose2D::new(-0.5, 0.0, 0.0);
        let d = OdometryDelta::between(&from, &to, &NOISE);
        // rot1 is pi, yet its noise counts as zero rotation: only translation noise remains.
        assert!(d.rot1_std_rad < 0.5 * 0.45 + 1e-9);
        assert!((d.rot1_rad.abs() - std::f64::consts::PI).abs() < 1e-12);
    }
}
