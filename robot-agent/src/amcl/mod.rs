//! Adaptive Monte Carlo localization (Fox 2001; Thrun et al., Probabilistic Robotics ch. 8) on
//! the floor plan: where is the robot in the map frame, given wheel odometry and a 2-D laser?
//!
//! - [`config`]: [`AmclConfig`], Nav2's parameters and defaults.
//! - [`field`]: [`LikelihoodField`], the clamped, quantized distance field of a map.
//! - [`sensor`]: the likelihood-field laser model, [`ScanModel`].
//! - [`beam`]: the ray-cast beam model, [`BeamScanModel`].
//! - [`motion`]: the four-alpha odometry motion model.
//! - [`kld`]: the KLD-sampling bound and its pose histogram.
//!
//! One filter cycle ([`Amcl::update`]), once the odometry has moved `update_min_d_m` or turned
//! `update_min_a_rad` since the last cycle: move every particle by a noisy sample of the odometry
//! change; weigh it by the scan; track the short- and long-term average likelihood (Augmented
//! MCL); every `resample_interval` cycles draw a new particle set by low-variance resampling,
//! replacing each draw with a uniformly random free-space pose with probability
//! `max(0, 1 - w_fast / w_slow)`, until the KLD bound for the bins occupied so far is met.
//! All randomness comes from one `ChaCha8Rng` seeded from the configuration.

pub mod beam;
pub mod config;
pub mod field;
pub mod kld;
pub mod motion;
pub mod sensor;

use std::f64::consts::PI;
use std::sync::Arc;

use protocol::{normalize_angle, LaserScan, Odometry, Pose2D};
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

pub use beam::{BeamScanModel, RayCache};
pub use config::{AmclConfig, BeamCombination, LaserModel};
pub use field::LikelihoodField;
pub use motion::{MotionNoise, OdometryDelta};
pub use sensor::ScanModel;

/// Why the localizer refused a configuration or an input.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum AmclError {
    #[error("invalid AMCL config: {field} = {value}: {reason}")]
    Config {
        field: &'static str,
        value: String,
        reason: String,
    },
    #[error("invalid AMCL config file: {0}")]
    Toml(String),
    #[error("invalid {field}: {reason}")]
    Input { field: &'static str, reason: String },
}

/// One hypothesis of the robot's pose in the map frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Particle {
    pub pose: Pose2D,
    /// Normalized: the weights of all particles sum to one.
    pub weight: f64,
}

/// The filter's belief summarized as a Gaussian, ready for a `protocol::PoseEstimate`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Estimate {
    /// Weighted mean position and circular mean heading.
    pub pose: Pose2D,
    /// 3x3 row-major covariance over (x_m, y_m, yaw_rad), yaw deviations taken around the
    /// circular mean.
    pub covariance: [f64; 9],
    pub particle_count: usize,
}

/// What one call of [`Amcl::update`] did.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct UpdateOutcome {
    /// The filter moved and/or weighed its particles (false: skipped, see the other fields).
    pub filter_ran: bool,
    /// No initial pose or global localization yet; nothing happened.
    pub not_initialized: bool,
    /// The laser scan weighed the particles.
    pub laser_applied: bool,
    /// A new particle set was drawn.
    pub resampled: bool,
    /// Beams left out by beam skipping in this update.
    pub beams_skipped: usize,
    /// Random free-space particles drawn for recovery in this resampling.
    pub random_particles: usize,
    pub particle_count: usize,
    /// Localization is lost (see [`Amcl::is_lost`]) after this update.
    pub lost: bool,
}

/// The adaptive Monte Carlo localizer of one robot on one map.
#[derive(Debug, Clone)]
pub struct Amcl {
    config: AmclConfig,
    noise: MotionNoise,
    field: Arc<LikelihoodField>,
    rng: ChaCha8Rng,
    particles: Vec<Particle>,
    scratch: Vec<Particle>,
    draws: Vec<u32>,
    /// Per particle and beam field levels, for beam skipping.
    levels: Vec<u8>,
    /// Per particle pose in grid coordinates and weight factor, for the beam model.
    grid_poses: Vec<[f64; 3]>,
    factors: Vec<f64>,
    /// Rays cast by the beam model on this filter's field, reused across updates.
    rays: beam::RayCache,
    beams_skipped: usize,
    bins: kld::BinSet,
    /// Odometry pose at the last filter cycle; `None` until the first odometry after
    /// (re)initialization.
    odom_at_update: Option<Pose2D>,
    /// Weigh the next scan even without motion (after (re)initialization, like Nav2).
    force_update: bool,
    updates_since_resample: u32,
    w_slow: f64,
    w_fast: f64,
    /// Summary of the weighted set before the last resampling (as Nav2 estimates): recovery
    /// particles drawn at resampling have not been weighed yet and must not move the estimate.
    weighted_estimate: Option<Estimate>,
    /// Consecutive updates whose scan did not fit / did fit.
    misfits_in_row: u32,
    fits_in_row: u32,
    /// Lost: too many misfits in a row, and not found again since.
    lost: bool,
    /// Particles were spread to relocalize, and the filter has not found itself since.
    relocalizing: bool,
    /// Odometry rotation since relocalization started.
    relocalization_turned_rad: f64,
    /// Odometry distance since relocalization started.
    relocalization_travelled_m: f64,
}

impl Amcl {
    /// A localizer with no particles yet: call [`Self::set_initial_pose`] or
    /// [`Self::global_localization`] before it can localize.
    ///
    /// # Errors
    /// [`AmclError::Config`] for an invalid configuration, or a field clamped at another
    /// distance than `laser_likelihood_max_dist_m`.
    pub fn new(config: AmclConfig, field: Arc<LikelihoodField>) -> Result<Self, AmclError> {
        config.validate()?;
        if (field.max_dist_m() - config.laser_likelihood_max_dist_m).abs() > 1e-9 {
            return Err(AmclError::Config {
                field: "laser_likelihood_max_dist_m",
                value: config.laser_likelihood_max_dist_m.to_string(),
                reason: format!(
                    "the likelihood field was built with {} m",
                    field.max_dist_m()
                ),
            });
        }
        let noise = MotionNoise {
            alpha1: config.alpha1,
            alpha2: config.alpha2,
            alpha3: config.alpha3,
            alpha4: config.alpha4,
        };
        Ok(Self {
            rng: ChaCha8Rng::seed_from_u64(config.seed),
            noise,
            field,
            particles: Vec::with_capacity(config.max_particles),
            scratch: Vec::with_capacity(config.max_particles),
            draws: Vec::with_capacity(config.max_particles),
            levels: Vec::new(),
            grid_poses: Vec::new(),
            factors: Vec::new(),
            rays: beam::RayCache::default(),
            beams_skipped: 0,
            bins: kld::BinSet::default(),
            odom_at_update: None,
            force_update: false,
            updates_since_resample: 0,
            w_slow: 0.0,
            w_fast: 0.0,
            weighted_estimate: None,
            misfits_in_row: 0,
            fits_in_row: 0,
            lost: false,
            relocalizing: false,
            relocalization_turned_rad: 0.0,
            relocalization_travelled_m: 0.0,
            config,
        })
    }

    #[must_use]
    pub fn config(&self) -> &AmclConfig {
        &self.config
    }

    #[must_use]
    pub fn field(&self) -> &Arc<LikelihoodField> {
        &self.field
    }

    /// The current particles (for plotting and diagnostics).
    #[must_use]
    pub fn particles(&self) -> &[Particle] {
        &self.particles
    }

    /// Whether an initial pose or global localization has been given.
    #[must_use]
    pub fn is_initialized(&self) -> bool {
        !self.particles.is_empty()
    }

    /// Short- and long-term average scan likelihood (Augmented MCL), for diagnostics.
    #[must_use]
    pub fn recovery_averages(&self) -> (f64, f64) {
        (self.w_slow, self.w_fast)
    }

    /// Replaces the belief by `max_particles` samples of a Gaussian around `pose`.
    ///
    /// # Errors
    /// [`AmclError::Input`] if the pose is not finite or the covariance (3x3 row-major over
    /// x, y, yaw) is not finite, symmetric and positive semi-definite.
    pub fn set_initial_pose(
        &mut self,
        pose: Pose2D,
        covariance: [f64; 9],
    ) -> Result<(), AmclError> {
        pose.validate("initial_pose")
            .map_err(|e| AmclError::Input {
                field: "initial_pose",
                reason: e.reason,
            })?;
        let l = cholesky3(&covariance)?;
        self.particles.clear();
        #[allow(clippy::cast_precision_loss)]
        let w = 1.0 / self.config.max_particles as f64;
        for _ in 0..self.config.max_particles {
            let n: [f64; 3] = [
                self.rng.sample(StandardNormal),
                self.rng.sample(StandardNormal),
                self.rng.sample(StandardNormal),
            ];
            let p = Pose2D::new(
                pose.x_m + l[0] * n[0],
                pose.y_m + l[3] * n[0] + l[4] * n[1],
                normalize_angle(pose.yaw_rad + l[6] * n[0] + l[7] * n[1] + l[8] * n[2]),
            );
            self.particles.push(Particle { pose: p, weight: w });
        }
        self.reset_after_init();
        Ok(())
    }

    /// Replaces the belief by `max_particles` poses drawn uniformly over the map's free space
    /// (the robot does not know where it is).
    ///
    /// # Errors
    /// [`AmclError::Input`] if the map has no free cell.
    pub fn global_localization(&mut self) -> Result<(), AmclError> {
        if self.field.free_cell_count() == 0 {
            return Err(AmclError::Input {
                field: "map",
                reason: "has no free cell to place particles in".into(),
            });
        }
        self.particles.clear();
        #[allow(clippy::cast_precision_loss)]
        let w = 1.0 / self.config.max_particles as f64;
        for _ in 0..self.config.max_particles {
            if let Some(pose) = random_free_pose(&self.field, &mut self.rng) {
                self.particles.push(Particle { pose, weight: w });
            }
        }
        self.reset_after_init();
        // Not knowing where it is, the filter searches as after losing itself.
        self.start_relocalizing();
        Ok(())
    }

    /// Whether localization is lost: the last `lost_after_updates` scans did not fit the map
    /// from the estimate, and since then the filter has not concentrated on a pose where they
    /// fit (an operator's initial pose or global localization also ends it).
    #[must_use]
    pub fn is_lost(&self) -> bool {
        self.lost
    }

    /// Whether particles are spread over the map to find the robot again.
    #[must_use]
    pub fn is_relocalizing(&self) -> bool {
        self.relocalizing
    }

    fn reset_after_init(&mut self) {
        self.misfits_in_row = 0;
        self.fits_in_row = 0;
        self.lost = false;
        self.relocalizing = false;
        // The new belief is about "now": motion accumulated before it must not be applied.
        self.odom_at_update = None;
        self.force_update = true;
        self.updates_since_resample = 0;
        self.w_slow = 0.0;
        self.w_fast = 0.0;
        self.weighted_estimate = None;
    }

    /// Feeds one odometry reading and, if one arrived with it, a laser scan.
    ///
    /// The filter runs when the odometry moved or turned enough since the last run (or after
    /// (re)initialization); otherwise the call only returns why it did not.
    ///
    /// # Errors
    /// [`AmclError::Input`] if the odometry pose or the scan is malformed (NaN, inconsistent
    /// ranges); the filter is left unchanged.
    pub fn update(
        &mut self,
        odometry: &Odometry,
        scan: Option<&LaserScan>,
    ) -> Result<UpdateOutcome, AmclError> {
        odometry
            .pose
            .validate("odometry.pose")
            .map_err(|e| AmclError::Input {
                field: "odometry.pose",
                reason: e.reason,
            })?;
        if let Some(scan) = scan {
            scan.validate().map_err(|e| AmclError::Input {
                field: "scan",
                reason: e.to_string(),
            })?;
        }
        let mut outcome = UpdateOutcome {
            particle_count: self.particles.len(),
            ..UpdateOutcome::default()
        };
        if self.particles.is_empty() {
            outcome.not_initialized = true;
            return Ok(outcome);
        }
        let now = odometry.pose;
        match self.odom_at_update {
            None => {
                self.odom_at_update = Some(now);
            }
            Some(before) => {
                let moved = (now.x_m - before.x_m).hypot(now.y_m - before.y_m)
                    >= self.config.update_min_d_m
                    || normalize_angle(now.yaw_rad - before.yaw_rad).abs()
                        >= self.config.update_min_a_rad;
                let forced = self.force_update && scan.is_some();
                if !(moved || forced) {
                    return Ok(outcome);
                }
                if self.relocalizing {
                    self.relocalization_turned_rad +=
                        normalize_angle(now.yaw_rad - before.yaw_rad).abs();
                    self.relocalization_travelled_m +=
                        (now.x_m - before.x_m).hypot(now.y_m - before.y_m);
                }
                let delta = OdometryDelta::between(&before, &now, &self.noise);
                for p in &mut self.particles {
                    delta.sample(&mut p.pose, &mut self.rng);
                }
                self.odom_at_update = Some(now);
                self.weighted_estimate = None;
                outcome.filter_ran = true;
            }
        }
        let Some(scan) = scan else {
            return Ok(outcome);
        };
        self.weigh(scan);
        self.weighted_estimate = summarize(&self.particles);
        self.force_update = false;
        let relocalize = self.check_fit(scan);
        outcome.filter_ran = true;
        outcome.laser_applied = true;
        outcome.beams_skipped = self.beams_skipped;
        self.updates_since_resample += 1;
        if self.updates_since_resample >= self.config.resample_interval {
            self.updates_since_resample = 0;
            outcome.random_particles = self.resample();
            outcome.resampled = true;
        }
        if relocalize {
            self.spread_for_relocalization();
        }
        outcome.particle_count = self.particles.len();
        outcome.lost = self.lost;
        Ok(outcome)
    }

    /// Scores the scan against the map from the new estimate and updates the lost state;
    /// returns whether particles should be spread to relocalize now.
    fn check_fit(&mut self, scan: &LaserScan) -> bool {
        let Some(estimate) = self.weighted_estimate else {
            return false;
        };
        let field = Arc::clone(&self.field);
        let model = BeamScanModel::for_agreement(&field, &self.config, scan, &mut self.rays);
        let Some(fit) = model.agreement(&estimate.pose, self.config.lost_fit_distance_m) else {
            // Nothing within range: the scan says nothing either way.
            return false;
        };
        if fit < self.config.lost_fit_fraction {
            self.misfits_in_row += 1;
            self.fits_in_row = 0;
        } else {
            self.fits_in_row += 1;
            self.misfits_in_row = 0;
        }
        let n = self.config.lost_after_updates;
        if !self.lost && self.misfits_in_row >= n {
            self.lost = true;
            return self.config.relocalization_particles > 0;
        }
        // Found again once the scans fit from one concentrated hypothesis, and (when
        // relocalizing) the laser has swept all round: repetitive buildings have look-alike
        // places that only a view in some direction tells apart.
        let concentrated = (estimate.covariance[0] + estimate.covariance[4]).sqrt()
            <= self.config.relocalized_position_std_m;
        let swept = !self.relocalizing
            || self.relocalization_turned_rad >= self.config.relocalization_sweep_rad
            || self.relocalization_travelled_m >= self.config.relocalization_travel_m;
        if self.lost && self.fits_in_row >= n && concentrated && swept {
            self.lost = false;
            self.relocalizing = false;
        }
        false
    }

    /// Adds `relocalization_particles` poses drawn uniformly over the free space to the
    /// current ones, all weighted alike: if the belief was right after all, its particles
    /// win the next weighing; if not, the spread ones hold the true pose somewhere.
    fn spread_for_relocalization(&mut self) {
        for _ in 0..self.config.relocalization_particles {
            if let Some(pose) = random_free_pose(&self.field, &mut self.rng) {
                self.particles.push(Particle { pose, weight: 0.0 });
            }
        }
        #[allow(clippy::cast_precision_loss)]
        let w = 1.0 / self.particles.len() as f64;
        for p in &mut self.particles {
            p.weight = w;
        }
        self.start_relocalizing();
    }

    /// Lost and searching: a flatter model, random particles at every resampling and a raised
    /// particle cap until the filter has concentrated again after a sweep or some travel.
    fn start_relocalizing(&mut self) {
        self.lost = true;
        self.relocalizing = true;
        self.relocalization_turned_rad = 0.0;
        self.relocalization_travelled_m = 0.0;
        self.fits_in_row = 0;
    }

    /// Multiplies every weight by the scan likelihood, normalizes, and updates the averages.
    fn weigh(&mut self, scan: &LaserScan) {
        let field = Arc::clone(&self.field);
        self.beams_skipped = 0;
        let origin_yaw = field.origin().yaw_rad;
        let total = match self.config.laser_model {
            LaserModel::LikelihoodField => {
                let model = ScanModel::new(&field, &self.config, scan);
                if model.beam_count() == 0 {
                    // No return at all (open space beyond range): the scan says nothing.
                    return;
                }
                if self.config.do_beamskip {
                    self.weigh_with_beam_skipping(&model)
                } else {
                    self.weigh_each(|gx, gy, c, s| model.likelihood_in_grid(gx, gy, c, s))
                }
            }
            LaserModel::Beam => {
                let temperature = if self.relocalizing {
                    self.config.relocalization_temperature
                } else {
                    1.0
                };
                let mut model = BeamScanModel::new(&field, &self.config, scan, &mut self.rays)
                    .with_temperature(temperature);
                if model.beam_count() == 0 {
                    return;
                }
                self.grid_poses.clear();
                self.grid_poses.extend(self.particles.iter().map(|p| {
                    let (gx, gy) = field.world_to_grid(p.pose.x_m, p.pose.y_m);
                    [gx, gy, p.pose.yaw_rad - origin_yaw]
                }));
                self.factors.resize(self.particles.len(), 0.0);
                model.likelihoods_in_grid(&self.grid_poses, &mut self.factors);
                let mut total = 0.0;
                for (p, f) in self.particles.iter_mut().zip(&self.factors) {
                    p.weight *= f;
                    total += p.weight;
                }
                total
            }
        };
        if !(total.is_finite() && total > 0.0) {
            // Every hypothesis is impossible (or the product underflowed): forget the weights
            // rather than divide by zero; recovery, if enabled, gets its chance at resampling.
            #[allow(clippy::cast_precision_loss)]
            let w = 1.0 / self.particles.len() as f64;
            for p in &mut self.particles {
                p.weight = w;
            }
            return;
        }
        // Weights were normalized before, so `total` is the average likelihood of the scan
        // under the predicted belief, independent of the particle count.
        if self.w_slow == 0.0 {
            self.w_slow = total;
        } else {
            self.w_slow += self.config.recovery_alpha_slow * (total - self.w_slow);
        }
        if self.w_fast == 0.0 {
            self.w_fast = total;
        } else {
            self.w_fast += self.config.recovery_alpha_fast * (total - self.w_fast);
        }
        for p in &mut self.particles {
            p.weight /= total;
        }
    }

    /// Multiplies every weight by `likelihood(gx, gy, cos, sin)` of its pose in grid
    /// coordinates; returns the weight sum.
    fn weigh_each(&mut self, likelihood: impl Fn(f64, f64, f64, f64) -> f64) -> f64 {
        let origin_yaw = self.field.origin().yaw_rad;
        let mut total = 0.0;
        for p in &mut self.particles {
            let (gx, gy) = self.field.world_to_grid(p.pose.x_m, p.pose.y_m);
            let (s, c) = (p.pose.yaw_rad - origin_yaw).sin_cos();
            p.weight *= likelihood(gx, gy, c, s);
            total += p.weight;
        }
        total
    }

    /// Beam skipping (Nav2's `likelihood_field_prob`): a first pass records every particle's
    /// field level per beam, a beam is kept if enough particles see it near a mapped obstacle,
    /// and a second pass weighs the particles by the kept beams. Returns the weight sum.
    fn weigh_with_beam_skipping(&mut self, model: &ScanModel<'_>) -> f64 {
        let beams = model.beam_count();
        let origin_yaw = self.field.origin().yaw_rad;
        self.levels.clear();
        self.levels.resize(beams * self.particles.len(), 0);
        for (p, levels) in self
            .particles
            .iter()
            .zip(self.levels.chunks_exact_mut(beams))
        {
            let (gx, gy) = self.field.world_to_grid(p.pose.x_m, p.pose.y_m);
            let (s, c) = (p.pose.yaw_rad - origin_yaw).sin_cos();
            model.levels_in_grid(gx, gy, c, s, levels);
        }
        let near_level = (self.config.beam_skip_distance_m / self.field.level_m()).floor();
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let near_level = near_level.min(f64::from(u8::MAX)) as u8;
        let mut near = vec![0usize; beams];
        for levels in self.levels.chunks_exact(beams) {
            for (n, &level) in near.iter_mut().zip(levels) {
                *n += usize::from(level <= near_level);
            }
        }
        #[allow(clippy::cast_precision_loss)]
        let needed = self.config.beam_skip_threshold * self.particles.len() as f64;
        #[allow(clippy::cast_precision_loss)]
        let mut keep: Vec<bool> = near.iter().map(|&n| n as f64 >= needed).collect();
        let skipped = keep.iter().filter(|&&k| !k).count();
        #[allow(clippy::cast_precision_loss)]
        if skipped as f64 > self.config.beam_skip_error_threshold * beams as f64 {
            keep.fill(true);
        }
        self.beams_skipped = keep.iter().filter(|&&k| !k).count();
        let mut total = 0.0;
        for (p, levels) in self
            .particles
            .iter_mut()
            .zip(self.levels.chunks_exact(beams))
        {
            p.weight *= model.likelihood_of_levels(levels, &keep);
            total += p.weight;
        }
        total
    }

    /// Low-variance resampling with KLD-adaptive size and random recovery particles. Returns
    /// the number of random particles drawn.
    fn resample(&mut self) -> usize {
        let max = if self.relocalizing {
            self.config
                .relocalization_particles
                .max(self.config.max_particles)
        } else {
            self.config.max_particles
        };
        let recovery_on =
            self.config.recovery_alpha_slow > 0.0 && self.config.recovery_alpha_fast > 0.0;
        let mut w_diff = if recovery_on && self.w_slow > 0.0 {
            (1.0 - self.w_fast / self.w_slow).max(0.0)
        } else {
            0.0
        };
        if self.relocalizing {
            // Keep seeding the whole map while relocalizing: one unlucky scan (a person next
            // to the true pose) must not wipe out the true hypothesis for good.
            w_diff = w_diff.max(self.config.relocalization_random_fraction);
        }

        // A low-variance (systematic) draw of `max` candidates: one random offset, then a comb
        // with spacing 1/max over the cumulative weights.
        self.draws.clear();
        #[allow(clippy::cast_precision_loss)]
        let step = 1.0 / max as f64;
        let mut target = self.rng.gen::<f64>() * step;
        let mut cumulative = 0.0;
        let last = self.particles.len().saturating_sub(1);
        let mut i = 0usize;
        for _ in 0..max {
            while i < last && cumulative + self.particles[i].weight < target {
                cumulative += self.particles[i].weight;
                i += 1;
            }
            #[allow(clippy::cast_possible_truncation)]
            self.draws.push(i as u32);
            target += step;
        }
        // KLD stops early, and the comb is ordered by particle; taking it in random order makes
        // every prefix a fair sample of the posterior, as KLD's bin count assumes.
        self.draws.shuffle(&mut self.rng);

        self.scratch.clear();
        self.bins.clear();
        let mut random_count = 0;
        for &d in &self.draws {
            let pose = if w_diff > 0.0 && self.rng.gen::<f64>() < w_diff {
                match random_free_pose(&self.field, &mut self.rng) {
                    Some(p) => {
                        random_count += 1;
                        p
                    }
                    None => self.particles[d as usize].pose,
                }
            } else {
                self.particles[d as usize].pose
            };
            self.scratch.push(Particle { pose, weight: 1.0 });
            self.bins.insert(kld::bin_key(&pose));
            // While relocalizing the count stays at the cap: KLD would shrink the set to the
            // few poses the first scans favour, and with them the chance that random draws
            // near the true pose survive.
            let min = if self.relocalizing {
                max
            } else {
                self.config.min_particles
            };
            let limit = kld::sample_bound(
                self.bins.len(),
                self.config.pf_err,
                self.config.pf_z,
                min,
                max,
            );
            if self.scratch.len() >= limit {
                break;
            }
        }
        #[allow(clippy::cast_precision_loss)]
        let w = 1.0 / self.scratch.len() as f64;
        for p in &mut self.scratch {
            p.weight = w;
        }
        std::mem::swap(&mut self.particles, &mut self.scratch);
        // Unlike Nav2, the averages are not reset after an injection: Thrun's Augmented MCL keeps
        // injecting while the short-term likelihood stays below the long-term one, which is
        // what lets a kidnapped robot on a large map find itself again.
        random_count
    }

    /// Weighted mean pose (circular mean for yaw) and covariance of the particles, taken
    /// before the last resampling, with the current particle count; `None` before
    /// initialization.
    #[must_use]
    pub fn estimate(&self) -> Option<Estimate> {
        let mut estimate = self
            .weighted_estimate
            .or_else(|| summarize(&self.particles))?;
        estimate.particle_count = self.particles.len();
        Some(estimate)
    }

    /// The estimate carried forward by the odometry since the last filter cycle: the pose to
    /// publish between cycles (the filter itself only moves every `update_min_d_m`).
    #[must_use]
    pub fn predict_pose(&self, odometry: &Odometry) -> Option<Pose2D> {
        let estimate = self.estimate()?;
        let Some(before) = self.odom_at_update else {
            return Some(estimate.pose);
        };
        // The odometry change expressed in the robot frame at the last cycle...
        let (s, c) = before.yaw_rad.sin_cos();
        let dx = odometry.pose.x_m - before.x_m;
        let dy = odometry.pose.y_m - before.y_m;
        let (lx, ly) = (c * dx + s * dy, -s * dx + c * dy);
        let dyaw = normalize_angle(odometry.pose.yaw_rad - before.yaw_rad);
        // ...applied to the estimate.
        let (s, c) = estimate.pose.yaw_rad.sin_cos();
        Some(Pose2D::new(
            estimate.pose.x_m + c * lx - s * ly,
            estimate.pose.y_m + s * lx + c * ly,
            normalize_angle(estimate.pose.yaw_rad + dyaw),
        ))
    }
}

/// Weighted mean (circular for yaw) and covariance of a particle set.
fn summarize(particles: &[Particle]) -> Option<Estimate> {
    if particles.is_empty() {
        return None;
    }
    let (mut wsum, mut sx, mut sy, mut ss, mut sc) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for p in particles {
        wsum += p.weight;
        sx += p.weight * p.pose.x_m;
        sy += p.weight * p.pose.y_m;
        let (s, c) = p.pose.yaw_rad.sin_cos();
        ss += p.weight * s;
        sc += p.weight * c;
    }
    if wsum.is_nan() || wsum <= 0.0 {
        return None;
    }
    let mean = Pose2D::new(sx / wsum, sy / wsum, ss.atan2(sc));
    let mut cov = [0.0; 9];
    for p in particles {
        let d = [
            p.pose.x_m - mean.x_m,
            p.pose.y_m - mean.y_m,
            normalize_angle(p.pose.yaw_rad - mean.yaw_rad),
        ];
        for r in 0..3 {
            for c in 0..3 {
                cov[r * 3 + c] += p.weight * d[r] * d[c];
            }
        }
    }
    for v in &mut cov {
        *v /= wsum;
    }
    Some(Estimate {
        pose: mean,
        covariance: cov,
        particle_count: particles.len(),
    })
}

/// A pose uniform over the free cells (uniform within the cell) and uniform in heading.
fn random_free_pose(field: &LikelihoodField, rng: &mut ChaCha8Rng) -> Option<Pose2D> {
    let n = field.free_cell_count();
    if n == 0 {
        return None;
    }
    let (cx, cy) = field.free_cell(rng.gen_range(0..n))?;
    let gx = f64::from(cx) + rng.gen::<f64>();
    let gy = f64::from(cy) + rng.gen::<f64>();
    let (x, y) = field.grid_to_world(gx, gy);
    Some(Pose2D::new(x, y, rng.gen_range(-PI..PI)))
}

/// Lower-triangular `L` with `L Lᵀ = cov` for a symmetric positive semi-definite 3x3 matrix
/// (row-major); zero-variance directions give zero columns.
fn cholesky3(cov: &[f64; 9]) -> Result<[f64; 9], AmclError> {
    let bad = |reason: String| AmclError::Input {
        field: "initial_covariance",
        reason,
    };
    if let Some(v) = cov.iter().find(|v| !v.is_finite()) {
        return Err(bad(format!("{v} is not finite")));
    }
    let scale = cov[0].abs().max(cov[4].abs()).max(cov[8].abs()).max(1e-300);
    for (a, b) in [(1, 3), (2, 6), (5, 7)] {
        if (cov[a] - cov[b]).abs() > 1e-9 * scale {
            return Err(bad(format!("not symmetric: {} vs {}", cov[a], cov[b])));
        }
    }
    let tol = 1e-12 * scale;
    let mut l = [0.0; 9];
    for j in 0..3 {
        let mut d = cov[j * 3 + j];
        for k in 0..j {
            d -= l[j * 3 + k] * l[j * 3 + k];
        }
        if d < -tol {
            return Err(bad(format!(
                "not positive semi-definite (pivot {j} is {d})"
            )));
        }
        let djj = d.max(0.0).sqrt();
        l[j * 3 + j] = djj;
        for i in (j + 1)..3 {
            let mut v = cov[i * 3 + j];
            for k in 0..j {
                v -= l[i * 3 + k] * l[j * 3 + k];
            }
            l[i * 3 + j] = if djj > 0.0 { v / djj } else { 0.0 };
        }
    }
    Ok(l)
}

#[cfg(test)]
mod tests {
    use super::*;
    use map_core::{OccupancyGrid, FREE, OCCUPIED};
    use protocol::Header;

    /// A 10 m x 6 m room with walls and an off-centre pillar, at 0.05 m.
    fn room() -> Arc<LikelihoodField> {
        let (w, h) = (200u32, 120u32);
        let mut g = OccupancyGrid::filled(w, h, 0.05, Pose2D::new(0.0, 0.0, 0.0), FREE).unwrap();
        for x in 0..i64::from(w) {
            g.set(x, 0, OCCUPIED);
            g.set(x, i64::from(h) - 1, OCCUPIED);
        }
        for y in 0..i64::from(h) {
            g.set(0, y, OCCUPIED);
            g.set(i64::from(w) - 1, y, OCCUPIED);
        }
        for x in 140..150 {
            for y in 30..50 {
                g.set(x, y, OCCUPIED);
            }
        }
        Arc::new(LikelihoodField::new(&g, 2.0).unwrap())
    }

    fn odom(x: f64, y: f64, yaw: f64) -> Odometry {
        Odometry {
            header: Header::default(),
            pose: Pose2D::new(x, y, yaw),
            v_mps: 0.0,
            omega_radps: 0.0,
        }
    }

    #[test]
    fn initial_pose_samples_match_the_given_covariance() {
        let mut a = Amcl::new(AmclConfig::default(), room()).unwrap();
        assert!(a.estimate().is_none());
        let cov = [0.04, 0.01, 0.0, 0.01, 0.09, 0.0, 0.0, 0.0, 0.01];
        a.set_initial_pose(Pose2D::new(3.0, 2.0, 3.1), cov).unwrap();
        let e = a.estimate().unwrap();
        assert_eq!(e.particle_count, 2000);
        assert!((e.pose.x_m - 3.0).abs() < 0.03 && (e.pose.y_m - 2.0).abs() < 0.03);
        // Circular mean near +-pi: a naive mean of yaw would land near 0.
        assert!(
            normalize_angle(e.pose.yaw_rad - 3.1).abs() < 0.02,
            "{}",
            e.pose.yaw_rad
        );
        for (i, want) in cov.iter().enumerate() {
            assert!(
                (e.covariance[i] - want).abs() < 0.012,
                "cov[{i}] {}",
                e.covariance[i]
            );
        }
        let not_psd = [1.0, 2.0, 0.0, 2.0, 1.0, 0.0, 0.0, 0.0, 1.0];
        assert!(a
            .set_initial_pose(Pose2D::new(0.0, 0.0, 0.0), not_psd)
            .is_err());
        assert!(a
            .set_initial_pose(Pose2D::new(0.0, 0.0, 0.0), [0.0; 9])
            .is_ok());
    }

    #[test]
    fn config_and_field_must_agree_and_inputs_are_checked() {
        let c = AmclConfig {
            laser_likelihood_max_dist_m: 1.0,
            ..AmclConfig::default()
        };
        let e = Amcl::new(c, room()).unwrap_err();
        assert!(e.to_string().contains("laser_likelihood_max_dist_m"), "{e}");
        let mut a = Amcl::new(AmclConfig::default(), room()).unwrap();
        let out = a.update(&odom(0.0, 0.0, 0.0), None).unwrap();
        assert!(out.not_initialized && !out.filter_ran);
        a.set_initial_pose(
            Pose2D::new(5.0, 3.0, 0.0),
            [0.01, 0.0, 0.0, 0.0, 0.01, 0.0, 0.0, 0.0, 0.01],
        )
        .unwrap();
        assert!(a.update(&odom(f64::NAN, 0.0, 0.0), None).is_err());
    }

    #[test]
    fn gating_runs_the_filter_only_after_enough_motion() {
        // Nav2's thresholds, coarser than the defaults, so that the steps below stay under them.
        let config = AmclConfig {
            update_min_d_m: 0.25,
            update_min_a_rad: 0.2,
            ..AmclConfig::default()
        };
        let mut a = Amcl::new(config, room()).unwrap();
        a.set_initial_pose(Pose2D::new(5.0, 3.0, 0.0), [0.0; 9])
            .unwrap();
        assert!(!a.update(&odom(0.0, 0.0, 0.0), None).unwrap().filter_ran);
        assert!(!a.update(&odom(0.1, 0.0, 0.0), None).unwrap().filter_ran);
        assert!(!a.update(&odom(0.1, 0.0, 0.15), None).unwrap().filter_ran);
        let out = a.update(&odom(0.3, 0.0, 0.0), None).unwrap();
        assert!(out.filter_ran && !out.laser_applied && !out.resampled);
        // Noisy motion of 0.3 m along +x from an exact start.
        let e = a.estimate().unwrap();
        assert!((e.pose.x_m - 5.3).abs() < 0.05, "{:?}", e.pose);
        let p = a.predict_pose(&odom(0.5, 0.0, 0.0)).unwrap();
        // The odometry moved 0.2 m straight ahead: so does the prediction, along the estimate.
        assert!((p.distance_m(&e.pose) - 0.2).abs() < 1e-9);
        assert!((p.yaw_rad - e.pose.yaw_rad).abs() < 1e-12);
    }

    #[test]
    fn resampling_shrinks_a_concentrated_set_and_is_deterministic() {
        let scan = LaserScan {
            header: Header::default(),
            angle_min_rad: -3.0,
            angle_increment_rad: 0.1,
            range_min_m: 0.05,
            range_max_m: 12.0,
            ranges_m: vec![12.0; 61],
        };
        let run = || {
            let mut a = Amcl::new(
                AmclConfig {
                    seed: 9,
                    ..AmclConfig::default()
                },
                room(),
            )
            .unwrap();
            a.set_initial_pose(
                Pose2D::new(5.0, 3.0, 0.0),
                [0.0001, 0.0, 0.0, 0.0, 0.0001, 0.0, 0.0, 0.0, 0.0001],
            )
            .unwrap();
            let mut s = scan.clone();
            // Only one wall return: the scan still weighs the particles.
            s.ranges_m[30] = 5.0 - 0.025;
            let out = a.update(&odom(0.0, 0.0, 0.0), Some(&s)).unwrap();
            assert!(out.laser_applied && out.resampled);
            a.particles().to_vec()
        };
        let first = run();
        // All particles in one or two KLD bins: the bound drops to min_particles.
        assert_eq!(first.len(), 500);
        assert_eq!(first, run());
    }
}
