//! The paper's Table 1 metrics computed from a driven trajectory.
//!
//! Smoothness is "the average jerk, i.e. the change in acceleration, of the path that the robot
//! traverses" (§4.1): here the mean magnitude of the third time-derivative of the position,
//! estimated with central finite differences on a uniformly sampled trajectory. Lower is smoother.

/// One sample of the true trajectory (map frame), as the harness records it.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TrajectorySample {
    pub t_s: f64,
    pub x_m: f64,
    pub y_m: f64,
}

/// Why a metric cannot be computed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MetricError {
    #[error("need at least {needed} samples for {metric}, got {got}")]
    TooFewSamples {
        metric: &'static str,
        needed: usize,
        got: usize,
    },
    #[error("samples must be uniformly spaced in time: sample {index} has dt = {dt_s} s, expected {expected_s} s")]
    NonUniform {
        index: usize,
        dt_s: f64,
        expected_s: f64,
    },
}

/// Length of the driven path in metres.
#[must_use]
pub fn path_length_m(samples: &[TrajectorySample]) -> f64 {
    samples
        .windows(2)
        .map(|w| (w[1].x_m - w[0].x_m).hypot(w[1].y_m - w[0].y_m))
        .sum()
}

/// Mean |jerk| in m/s³ over a uniformly sampled trajectory.
///
/// # Errors
/// Fewer than four samples, or samples not uniformly spaced in time (to 1 %).
pub fn mean_abs_jerk_mps3(samples: &[TrajectorySample]) -> Result<f64, MetricError> {
    if samples.len() < 4 {
        return Err(MetricError::TooFewSamples {
            metric: "jerk",
            needed: 4,
            got: samples.len(),
        });
    }
    let dt = samples[1].t_s - samples[0].t_s;
    for (i, w) in samples.windows(2).enumerate() {
        let d = w[1].t_s - w[0].t_s;
        if d.is_nan() || d <= 0.0 || (d - dt).abs() > 0.01 * dt {
            return Err(MetricError::NonUniform {
                index: i + 1,
                dt_s: d,
                expected_s: dt,
            });
        }
    }
    // Third difference over four consecutive samples: (p3 - 3 p2 + 3 p1 - p0) / dt³.
    let dt3 = dt * dt * dt;
    let jerks: Vec<f64> = samples
        .windows(4)
        .map(|w| {
            let jx = w[3].x_m - 3.0 * w[2].x_m + 3.0 * w[1].x_m - w[0].x_m;
            let jy = w[3].y_m - 3.0 * w[2].y_m + 3.0 * w[1].y_m - w[0].y_m;
            jx.hypot(jy) / dt3
        })
        .collect();
    #[allow(clippy::cast_precision_loss)]
    Ok(jerks.iter().sum::<f64>() / jerks.len() as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sampled(f: impl Fn(f64) -> (f64, f64), n: usize, dt: f64) -> Vec<TrajectorySample> {
        (0..n)
            .map(|i| {
                let t = i as f64 * dt;
                let (x_m, y_m) = f(t);
                TrajectorySample { t_s: t, x_m, y_m }
            })
            .collect()
    }

    #[test]
    fn straight_line_and_constant_acceleration_have_no_jerk() {
        let line = sampled(|t| (0.5 * t, 0.2 * t), 50, 0.1);
        assert!(mean_abs_jerk_mps3(&line).unwrap() < 1e-9);
        let accel = sampled(|t| (0.3 * t * t, 0.0), 50, 0.1);
        assert!(mean_abs_jerk_mps3(&accel).unwrap() < 1e-6);
        assert!((path_length_m(&line) - 49.0 * 0.1 * 0.5f64.hypot(0.2)).abs() < 1e-9);
    }

    #[test]
    fn cubic_motion_has_its_analytic_jerk() {
        // x = t³ has jerk 6 m/s³ everywhere.
        let cubic = sampled(|t| (t * t * t, 0.0), 40, 0.05);
        assert!((mean_abs_jerk_mps3(&cubic).unwrap() - 6.0).abs() < 1e-6);
    }

    #[test]
    fn rejects_short_or_irregular_trajectories() {
        let short = sampled(|t| (t, 0.0), 3, 0.1);
        assert!(matches!(
            mean_abs_jerk_mps3(&short),
            Err(MetricError::TooFewSamples { .. })
        ));
        let mut irregular = sampled(|t| (t, 0.0), 10, 0.1);
        irregular[5].t_s += 0.05;
        assert!(matches!(
            mean_abs_jerk_mps3(&irregular),
            Err(MetricError::NonUniform { index: 5, .. })
        ));
    }
}
