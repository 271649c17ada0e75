//! AMCL parameters, named and defaulted like Nav2's `amcl` node so that a Nav2 tuning carries
//! over, with units in the names and validation that names the offending field.

use protocol::Pose2D;
use serde::{Deserialize, Serialize};

use super::AmclError;

/// How the per-beam likelihoods of one scan combine into a particle's weight factor.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum BeamCombination {
    /// Nav2's `likelihood_field` model: `1 + Σ p³`. Beams are not independent (one unmapped
    /// person shadows several), and the sum keeps one bad beam from vetoing a good particle.
    SumOfCubes,
    /// The textbook product `Π p` (Thrun et al., Table 6.3): sharper, but overconfident with
    /// correlated beams and prone to collapsing onto a wrong pose when the map is crude.
    Product,
}

/// Which laser model weighs the particles.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LaserModel {
    /// Endpoint distance to the nearest wall, one lookup per beam ([`super::ScanModel`]).
    LikelihoodField,
    /// Measured against ray-cast range, free space and no-returns count
    /// ([`super::BeamScanModel`]; Nav2's `beam`).
    Beam,
}

/// Configuration of the adaptive Monte Carlo localizer. Every field has Nav2's default except
/// - the laser model: Nav2 defaults to `likelihood_field` (sum of cubes); here the default is
///   the ray-cast `beam` model with the product of the beams' likelihoods. Over tasks A–E at
///   seeds 1–5 it tracks to 0.016 m mean error against 0.088 m for the likelihood field with
///   the product (Nav2's `likelihood_field_prob`), which itself tracked 5x more precisely than
///   the sum of cubes (docs/benchmarks.md). Beam skipping (likelihood field only) is off as in
///   Nav2: with it, one seed of task C collapsed onto a wrong pose 11 m off;
/// - the motion noise alphas, set to the Pioneer-class base's odometry (rotation from rotation
///   0.05, the rest 0.02) instead of Nav2's 0.2, which assumes a slipping base: too much
///   noise spreads the particles along corridors, where only door jambs pin the position;
/// - the update thresholds, 0.05 m / 0.05 rad instead of 0.25 m / 0.2 rad: at 0.7 m/s the
///   estimate between updates is dead reckoning, and errors of a quarter metre built up.
///
/// - lost-localization detection and global relocalization, which Nav2 leaves to the
///   operator.
///
/// See `amcl.example.toml` beside this file for a commented example.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct AmclConfig {
    /// Seed of the filter's random source: the same seed and inputs give the same particles.
    pub seed: u64,
    /// Lower bound of the KLD-adaptive particle count.
    pub min_particles: usize,
    /// Upper bound of the KLD-adaptive particle count; also the count after an initial pose or
    /// global localization.
    pub max_particles: usize,
    /// KLD-sampling: maximum error between the true and the estimated distribution.
    pub pf_err: f64,
    /// KLD-sampling: the upper standard normal quantile `z` used in the bound, as Nav2 uses it
    /// (Nav2 passes 0.99 straight into the formula as `z`, not as a probability).
    pub pf_z: f64,
    /// Rotation noise from rotation (Thrun's α1).
    pub alpha1: f64,
    /// Rotation noise from translation (α2).
    pub alpha2: f64,
    /// Translation noise from translation (α3).
    pub alpha3: f64,
    /// Translation noise from rotation (α4).
    pub alpha4: f64,
    /// Decay rate of the slow average likelihood (Augmented MCL); 0 disables recovery.
    pub recovery_alpha_slow: f64,
    /// Decay rate of the fast average likelihood; 0 disables recovery.
    pub recovery_alpha_fast: f64,
    /// The laser model; see [`LaserModel`].
    pub laser_model: LaserModel,
    /// Distances to the nearest obstacle are clamped here in the likelihood field.
    pub laser_likelihood_max_dist_m: f64,
    /// Beams used per scan, spread evenly over the scan.
    pub max_beams: usize,
    /// Mixture weight of the Gaussian hit component.
    pub z_hit: f64,
    /// Mixture weight of the uniform random-measurement component.
    pub z_rand: f64,
    /// Standard deviation of the hit component.
    pub sigma_hit_m: f64,
    /// Beam model only: weight of the short-reading component (unmapped things in front of
    /// the wall the map predicts).
    pub z_short: f64,
    /// Beam model only: weight of the no-return component.
    pub z_max: f64,
    /// Beam model only: decay rate of the short-reading component.
    pub lambda_short_per_m: f64,
    /// How beams combine; see [`BeamCombination`].
    pub beam_combination: BeamCombination,
    /// Skip beams that most particles cannot explain (Nav2's `do_beamskip`): a beam whose
    /// endpoint lies within `beam_skip_distance_m` of a mapped obstacle for fewer than
    /// `beam_skip_threshold` of the particles most likely hit something the map lacks.
    pub do_beamskip: bool,
    pub beam_skip_distance_m: f64,
    pub beam_skip_threshold: f64,
    /// If more than this fraction of the beams would be skipped, the filter is probably lost
    /// rather than the world cluttered: use all beams.
    pub beam_skip_error_threshold: f64,
    /// The filter runs only after the odometry moved this far since the last run...
    pub update_min_d_m: f64,
    /// ...or turned this much.
    pub update_min_a_rad: f64,
    /// Resample after every n-th filter update.
    pub resample_interval: u32,
    /// Pose of the laser in the robot frame (default: at the centre, looking forward).
    pub robot_from_laser: Pose2D,
    /// Lost-localization check: a beam matches the map when its reading lies within this of
    /// the range ray-cast from the estimate, and contradicts it when it is longer (through a
    /// mapped wall, or no return where a wall is in range).
    pub lost_fit_distance_m: f64,
    /// A scan fits when at least this fraction of its matching and contradicting beams match
    /// (shorter readings, from furniture and people in front of walls, are left out).
    pub lost_fit_fraction: f64,
    /// Localization counts as lost after this many filter updates in a row whose scan does not
    /// fit, and as found again after as many that do (with the belief concentrated again).
    pub lost_after_updates: u32,
    /// When lost, this many particles are spread uniformly over the free space, beside the
    /// current ones, and the particle cap is raised to it until the filter is found again
    /// (global relocalization). 0: only report that localization is lost.
    pub relocalization_particles: usize,
    /// While relocalizing, this fraction of every resampling is drawn uniformly over the free
    /// space (as Augmented MCL's recovery does), so that the true pose keeps a chance.
    pub relocalization_random_fraction: f64,
    /// Relocalization ends only after the odometry turned this much since it started (a full
    /// turn sweeps the laser all round; the agent turns in place meanwhile)...
    pub relocalization_sweep_rad: f64,
    /// ...or travelled this far (a robot moved by other means, e.g. pushed or teleoperated).
    pub relocalization_travel_m: f64,
    /// ...and once the weighted particles' position standard deviation (√(σx² + σy²)) is
    /// within this.
    pub relocalized_position_std_m: f64,
    /// While relocalizing, the beam model's log-likelihood is divided by this: a flatter
    /// model, so that the true pose's neighbourhood survives among particles spread thin.
    pub relocalization_temperature: f64,
}

impl Default for AmclConfig {
    fn default() -> Self {
        Self {
            seed: 0,
            min_particles: 500,
            max_particles: 2000,
            pf_err: 0.05,
            pf_z: 0.99,
            alpha1: 0.05,
            alpha2: 0.02,
            alpha3: 0.02,
            alpha4: 0.02,
            recovery_alpha_slow: 0.0,
            recovery_alpha_fast: 0.0,
            laser_model: LaserModel::Beam,
            laser_likelihood_max_dist_m: 2.0,
            max_beams: 60,
            z_hit: 0.5,
            z_rand: 0.5,
            sigma_hit_m: 0.2,
            z_short: 0.05,
            z_max: 0.05,
            lambda_short_per_m: 0.1,
            beam_combination: BeamCombination::Product,
            do_beamskip: false,
            beam_skip_distance_m: 0.5,
            beam_skip_threshold: 0.3,
            beam_skip_error_threshold: 0.9,
            update_min_d_m: 0.05,
            update_min_a_rad: 0.05,
            resample_interval: 1,
            robot_from_laser: Pose2D::new(0.0, 0.0, 0.0),
            lost_fit_distance_m: 0.3,
            lost_fit_fraction: 0.85,
            lost_after_updates: 5,
            relocalization_particles: 30_000,
            relocalization_random_fraction: 0.05,
            relocalization_sweep_rad: std::f64::consts::TAU,
            relocalization_travel_m: 5.0,
            relocalized_position_std_m: 0.25,
            relocalization_temperature: 10.0,
        }
    }
}

/// Particle counts above this would not fit a 10 Hz cycle on a robot's CPU.
pub const MAX_PARTICLES_LIMIT: usize = 1_000_000;

fn bad(field: &'static str, value: impl ToString, reason: &str) -> AmclError {
    AmclError::Config {
        field,
        value: value.to_string(),
        reason: reason.to_string(),
    }
}

impl AmclConfig {
    /// Parses a TOML document and validates it.
    ///
    /// # Errors
    /// [`AmclError::Toml`] for syntax or unknown keys, [`AmclError::Config`] for bad values.
    pub fn from_toml(text: &str) -> Result<Self, AmclError> {
        let config: Self = toml::from_str(text).map_err(|e| AmclError::Toml(e.to_string()))?;
        config.validate()?;
        Ok(config)
    }

    /// Checks every value; the error names the field and the value.
    ///
    /// # Errors
    /// [`AmclError::Config`] for the first bad field.
    pub fn validate(&self) -> Result<(), AmclError> {
        if self.min_particles == 0 {
            return Err(bad(
                "min_particles",
                self.min_particles,
                "must be at least 1",
            ));
        }
        if self.max_particles < self.min_particles || self.max_particles > MAX_PARTICLES_LIMIT {
            return Err(bad(
                "max_particles",
                self.max_particles,
                "must lie between min_particles and 1000000",
            ));
        }
        if !(self.pf_err > 0.0 && self.pf_err < 1.0) {
            return Err(bad("pf_err", self.pf_err, "must lie in (0, 1)"));
        }
        if !(self.pf_z.is_finite() && self.pf_z > 0.0) {
            return Err(bad("pf_z", self.pf_z, "must be a positive finite number"));
        }
        for (field, v) in [
            ("alpha1", self.alpha1),
            ("alpha2", self.alpha2),
            ("alpha3", self.alpha3),
            ("alpha4", self.alpha4),
            ("z_hit", self.z_hit),
            ("z_rand", self.z_rand),
            ("z_short", self.z_short),
            ("z_max", self.z_max),
            ("lambda_short_per_m", self.lambda_short_per_m),
            ("update_min_d_m", self.update_min_d_m),
            ("update_min_a_rad", self.update_min_a_rad),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(bad(field, v, "must be a finite number >= 0"));
            }
        }
        for (field, v) in [
            ("recovery_alpha_slow", self.recovery_alpha_slow),
            ("recovery_alpha_fast", self.recovery_alpha_fast),
        ] {
            if !(0.0..=1.0).contains(&v) {
                return Err(bad(field, v, "must lie in [0, 1]"));
            }
        }
        if self.recovery_alpha_slow > 0.0 && self.recovery_alpha_fast <= self.recovery_alpha_slow {
            return Err(bad(
                "recovery_alpha_fast",
                self.recovery_alpha_fast,
                "must exceed recovery_alpha_slow when recovery is enabled",
            ));
        }
        if self.z_hit + self.z_rand <= 0.0 {
            return Err(bad("z_hit", self.z_hit, "z_hit + z_rand must be positive"));
        }
        for (field, v) in [
            (
                "laser_likelihood_max_dist_m",
                self.laser_likelihood_max_dist_m,
            ),
            ("sigma_hit_m", self.sigma_hit_m),
            ("beam_skip_distance_m", self.beam_skip_distance_m),
            ("lost_fit_distance_m", self.lost_fit_distance_m),
            (
                "relocalized_position_std_m",
                self.relocalized_position_std_m,
            ),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(bad(field, v, "must be a positive finite number"));
            }
        }
        for (field, v) in [
            ("beam_skip_threshold", self.beam_skip_threshold),
            ("beam_skip_error_threshold", self.beam_skip_error_threshold),
            ("lost_fit_fraction", self.lost_fit_fraction),
            (
                "relocalization_random_fraction",
                self.relocalization_random_fraction,
            ),
        ] {
            if !(0.0..=1.0).contains(&v) {
                return Err(bad(field, v, "must lie in [0, 1]"));
            }
        }
        if self.do_beamskip && self.laser_model == LaserModel::Beam {
            return Err(bad(
                "do_beamskip",
                self.do_beamskip,
                "beam skipping applies to laser_model = \"likelihood_field\" only",
            ));
        }
        if self.max_beams < 2 {
            return Err(bad("max_beams", self.max_beams, "must be at least 2"));
        }
        if !(self.relocalization_temperature.is_finite() && self.relocalization_temperature >= 1.0)
        {
            return Err(bad(
                "relocalization_temperature",
                self.relocalization_temperature,
                "must be a finite number >= 1",
            ));
        }
        for (field, v) in [
            ("relocalization_sweep_rad", self.relocalization_sweep_rad),
            ("relocalization_travel_m", self.relocalization_travel_m),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(bad(field, v, "must be a finite number >= 0"));
            }
        }
        if self.lost_after_updates == 0 {
            return Err(bad(
                "lost_after_updates",
                self.lost_after_updates,
                "must be at least 1",
            ));
        }
        if self.relocalization_particles > MAX_PARTICLES_LIMIT {
            return Err(bad(
                "relocalization_particles",
                self.relocalization_particles,
                "must be at most 1000000",
            ));
        }
        if self.resample_interval == 0 {
            return Err(bad(
                "resample_interval",
                self.resample_interval,
                "must be at least 1",
            ));
        }
        let p = self.robot_from_laser;
        for (field, v) in [
            ("robot_from_laser.x_m", p.x_m),
            ("robot_from_laser.y_m", p.y_m),
            ("robot_from_laser.yaw_rad", p.yaw_rad),
        ] {
            if !v.is_finite() {
                return Err(bad(field, v, "must be finite"));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn example_file_parses_and_equals_defaults() {
        let text = include_str!("amcl.example.toml");
        let parsed = AmclConfig::from_toml(text).unwrap();
        assert_eq!(parsed, AmclConfig::default());
    }

    #[test]
    fn empty_document_gives_nav2_defaults() {
        let c = AmclConfig::from_toml("").unwrap();
        assert_eq!(c.min_particles, 500);
        assert_eq!(c.max_particles, 2000);
        assert_eq!(c.max_beams, 60);
        assert_eq!(c.recovery_alpha_slow, 0.0);
    }

    #[test]
    fn errors_name_field_and_value() {
        let e = AmclConfig::from_toml("max_particles = 10")
            .unwrap_err()
            .to_string();
        assert!(e.contains("max_particles") && e.contains("10"), "{e}");
        let e = AmclConfig::from_toml("sigma_hit_m = -0.1")
            .unwrap_err()
            .to_string();
        assert!(e.contains("sigma_hit_m") && e.contains("-0.1"), "{e}");
        let e = AmclConfig::from_toml("recovery_alpha_slow = 0.1\nrecovery_alpha_fast = 0.01")
            .unwrap_err()
            .to_string();
        assert!(e.contains("recovery_alpha_fast"), "{e}");
        let e = AmclConfig::from_toml("relocalization_temperature = 0.5")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("relocalization_temperature") && e.contains("0.5"),
            "{e}"
        );
        let e = AmclConfig::from_toml("sigma_hit = 0.2")
            .unwrap_err()
            .to_string();
        assert!(e.contains("sigma_hit"), "{e}");
        let e = AmclConfig::from_toml("[robot_from_laser]\nx_m = 0.1\ny_m = 0.0\nyaw_rad = nan")
            .unwrap_err()
            .to_string();
        assert!(e.contains("robot_from_laser.yaw_rad"), "{e}");
    }
}
