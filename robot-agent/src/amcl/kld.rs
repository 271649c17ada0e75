//! KLD-sampling (Fox 2001): how many particles are needed so that, with probability 1-δ, the
//! Kullback-Leibler distance between the sampled and the true posterior stays below ε, given
//! the number `k` of histogram bins the samples occupy so far.

use std::collections::HashSet;
use std::hash::{BuildHasherDefault, Hasher};

use protocol::Pose2D;

/// Histogram bin size in x and y (Nav2's `pf_kdtree` uses 0.5 m).
pub const BIN_SIZE_M: f64 = 0.5;
/// Histogram bin size in yaw (Nav2: 10 degrees).
pub const BIN_SIZE_RAD: f64 = 10.0 * std::f64::consts::PI / 180.0;

/// Required sample count for `k` occupied bins (Fox 2001, eq. 17 with the Wilson-Hilferty
/// approximation), clamped to `[min, max]`. `z` is the standard normal quantile, used as given.
#[must_use]
pub fn sample_bound(k: usize, err: f64, z: f64, min: usize, max: usize) -> usize {
    if k <= 1 {
        return max;
    }
    #[allow(clippy::cast_precision_loss)]
    let km1 = (k - 1) as f64;
    let b = 2.0 / (9.0 * km1);
    let x = 1.0 - b + b.sqrt() * z;
    let n = (km1 / (2.0 * err) * x * x * x).ceil();
    // n is positive and finite here; the float-to-int cast saturates for huge values.
    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
    let n = n as usize;
    n.clamp(min, max)
}

/// The histogram bin of a pose, packed into one integer key.
#[inline]
#[must_use]
pub fn bin_key(pose: &Pose2D) -> u64 {
    // Saturating float-to-int casts; 21 bits per axis hold ±500 km at 0.5 m.
    #[allow(clippy::cast_possible_truncation)]
    let ix = (pose.x_m / BIN_SIZE_M).floor() as i64;
    #[allow(clippy::cast_possible_truncation)]
    let iy = (pose.y_m / BIN_SIZE_M).floor() as i64;
    #[allow(clippy::cast_possible_truncation)]
    let ia = (pose.yaw_rad / BIN_SIZE_RAD).floor() as i64;
    let mask = (1u64 << 21) - 1;
    #[allow(clippy::cast_sign_loss)]
    let key = ((ix as u64 & mask) << 42) | ((iy as u64 & mask) << 21) | (ia as u64 & mask);
    key
}

/// A multiply-rotate hasher for already well-spread integer keys; SipHash would cost more than
/// the rest of the resampling loop.
#[derive(Debug, Default, Clone, Copy)]
pub struct BinHasher(u64);

impl Hasher for BinHasher {
    fn finish(&self) -> u64 {
        self.0
    }

    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_u64(u64::from(b));
        }
    }

    #[inline]
    fn write_u64(&mut self, i: u64) {
        self.0 = (self.0.rotate_left(5) ^ i).wrapping_mul(0x51_7c_c1_b7_27_22_0a_95);
    }
}

/// Set of occupied bins.
pub type BinSet = HashSet<u64, BuildHasherDefault<BinHasher>>;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bound_grows_with_bins_and_respects_limits() {
        assert_eq!(sample_bound(0, 0.05, 0.99, 500, 2000), 2000);
        assert_eq!(sample_bound(1, 0.05, 0.99, 500, 2000), 2000);
        // Fox's bound for k = 2: (1/(2ε)) * (1 - 2/9 + sqrt(2/9) z)^3.
        let x = 1.0 - 2.0 / 9.0 + (2.0f64 / 9.0).sqrt() * 0.99;
        let expected = (1.0 / 0.1 * x * x * x).ceil() as usize;
        assert_eq!(sample_bound(2, 0.05, 0.99, 1, 100_000), expected);
        let mut last = 0;
        for k in 2..200 {
            let n = sample_bound(k, 0.05, 0.99, 1, 100_000);
            assert!(n > last, "k {k}");
            last = n;
        }
        assert_eq!(sample_bound(10_000, 0.05, 0.99, 500, 2000), 2000);
        assert_eq!(sample_bound(3, 0.05, 0.99, 500, 2000), 500);
    }

    #[test]
    fn bins_separate_poses_half_a_metre_or_ten_degrees_apart() {
        let a = bin_key(&Pose2D::new(0.1, 0.1, 0.01));
        assert_eq!(a, bin_key(&Pose2D::new(0.4, 0.2, 0.1)));
        assert_ne!(a, bin_key(&Pose2D::new(0.6, 0.1, 0.01)));
        assert_ne!(a, bin_key(&Pose2D::new(0.1, -0.1, 0.01)));
        assert_ne!(a, bin_key(&Pose2D::new(0.1, 0.1, 0.2)));
        let mut set = BinSet::default();
        assert!(set.insert(a));
        assert!(!set.insert(a));
    }
}
