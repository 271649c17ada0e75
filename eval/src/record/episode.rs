//! One recorded episode: the [`CycleObserver`] that stores a sample per control cycle and
//! injects steering noise into what the robot executes (Codevilla et al. 2018).
//!
//! The label of a sample is the supervisor's decision with the expert driving (the expert's
//! command through the agent's safety rules and acceleration limits, exactly what the
//! network's output will go through when it drives); the perturbation is added only to the
//! executed command, after the decision, so a perturbed state carries the expert's
//! correction as its label.
//!
//! In a DAgger round ([`super::dagger`]) the supervisor runs the β-mixture of the expert and a
//! learner; the label is then what the expert said in that cycle (while the supervisor drives;
//! its own stops stay stop labels), whoever's command was executed.

use std::sync::PoisonError;

use protocol::{AgentState, Dlm, ImageEncoding};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use robot_agent::controllers::{Control, Controller};
use robot_agent::Limits;
use sim::Command;

use robot_agent::controllers::intention_net::preprocess::resize_area_rgb8;

use super::dagger::{LabelCell, Mixed, Watched};
use crate::table::run::{Cycle, CycleObserver, CycleOutcome};
use crate::table::TableError;

/// One stored control cycle.
#[derive(Debug, Clone, PartialEq)]
pub struct Sample {
    /// Camera image, `image_px`² RGB8.
    pub camera: Vec<u8>,
    /// LPE image at the same size (black when the pipeline had no plan).
    pub lpe: Vec<u8>,
    /// [`Dlm::index`] of the intention the robot follows.
    pub dlm: u8,
    /// The expert's command, normalised: (v, ω) / limits, in [-1, 1].
    pub label: [f32; 2],
    /// What the expert steered towards before its command filter
    /// ([`Controller::target`]), normalised the same way; `label` on cycles where the
    /// supervisor, not the expert, decided (its own stops).
    pub target: [f32; 2],
    /// What the robot executed, normalised the same way (≠ `label` under noise).
    pub executed: [f32; 2],
    /// True pose (x m, y m, yaw rad).
    pub pose_true: [f32; 3],
    /// Pose the agent published (AMCL), NaN on a cycle without one.
    pub pose_amcl: [f32; 3],
    /// Simulated seconds since the episode started.
    pub t_s: f32,
    /// The learner's command was executed (DAgger), not the expert's.
    pub learner_drove: bool,
}

/// Steering-noise schedule of a perturbed episode: a triangular pulse of turn-rate offset
/// over 2–4 s peaking at 0.5–1 × the largest peak with either sign, the next starting
/// 0.5–2.5 s after the last ends (about one every 4.5 s).
#[derive(Debug)]
struct Noise {
    rng: ChaCha8Rng,
    start_s: f64,
    duration_s: f64,
    peak_radps: f64,
    max_peak_radps: f64,
}

impl Noise {
    fn new(seed: u64, max_peak_radps: f64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let start_s = rng.gen_range(1.0..4.0);
        let mut n = Self {
            rng,
            start_s,
            duration_s: 0.0,
            peak_radps: 0.0,
            max_peak_radps,
        };
        n.draw_pulse();
        n
    }

    fn draw_pulse(&mut self) {
        self.duration_s = self.rng.gen_range(2.0..4.0);
        let sign = if self.rng.gen_bool(0.5) { 1.0 } else { -1.0 };
        self.peak_radps = sign * self.rng.gen_range(0.5..=1.0) * self.max_peak_radps;
    }

    /// The turn-rate offset at `t_s` (called with increasing times).
    fn offset_radps(&mut self, t_s: f64) -> f64 {
        if t_s >= self.start_s + self.duration_s {
            self.start_s += self.duration_s + self.rng.gen_range(0.5..2.5);
            self.draw_pulse();
        }
        if t_s < self.start_s {
            return 0.0;
        }
        let phase = (t_s - self.start_s) / self.duration_s;
        self.peak_radps * (1.0 - (2.0 * phase - 1.0).abs())
    }
}

/// Records one episode.
pub struct Recorder<'a> {
    image_px: usize,
    every: u64,
    max_samples: usize,
    limits: Limits,
    noise: Option<Noise>,
    cycle: u64,
    dlm: Option<Dlm>,
    lpe: Vec<u8>,
    pub samples: Vec<Sample>,
    progress: &'a (dyn Fn(u64) + Sync),
    dagger: Option<Dagger>,
    /// What the expert said in the last cycle (left by [`Mixed`] or [`Watched`]).
    label: LabelCell,
}

/// A DAgger episode's learner, until the run asks for the controller, and the mixture's draws.
struct Dagger {
    learner: Option<Box<dyn Controller>>,
    beta: f64,
    seed: u64,
}

impl<'a> Recorder<'a> {
    /// A recorder storing every `every`-th cycle, at most `max_samples`; `noise` = (seed,
    /// largest peak in rad/s) turns noise injection on.
    #[must_use]
    pub fn new(
        image_px: usize,
        every: u64,
        max_samples: usize,
        limits: Limits,
        noise: Option<(u64, f64)>,
        progress: &'a (dyn Fn(u64) + Sync),
    ) -> Self {
        Self {
            image_px,
            every: every.max(1),
            max_samples,
            limits,
            noise: noise.map(|(seed, peak_radps)| Noise::new(seed, peak_radps)),
            cycle: 0,
            dlm: None,
            lpe: vec![0; image_px * image_px * 3],
            samples: Vec::new(),
            progress,
            dagger: None,
            label: LabelCell::default(),
        }
    }

    /// Makes this a DAgger episode: `learner` drives with probability 1 − `beta` per cycle
    /// (drawn with `seed`) and the expert labels.
    #[must_use]
    pub fn with_learner(mut self, learner: Box<dyn Controller>, beta: f64, seed: u64) -> Self {
        self.dagger = Some(Dagger {
            learner: Some(learner),
            beta,
            seed,
        });
        self
    }

    fn shrink(&self, image: &protocol::Image, what: &'static str) -> Result<Vec<u8>, TableError> {
        if image.encoding != ImageEncoding::Rgb8 {
            return Err(TableError::Setup {
                what,
                reason: format!("expected raw RGB8, got {:?}", image.encoding),
            });
        }
        Ok(resize_area_rgb8(
            &image.data,
            image.width_px as usize,
            image.height_px as usize,
            self.image_px,
            self.image_px,
        ))
    }
}

#[allow(clippy::cast_possible_truncation)]
fn pose_f32(p: protocol::Pose2D) -> [f32; 3] {
    [p.x_m as f32, p.y_m as f32, p.yaw_rad as f32]
}

#[allow(clippy::cast_possible_truncation)]
fn control_f32(c: Control) -> [f32; 2] {
    [c.v_norm as f32, c.omega_norm as f32]
}

impl CycleObserver for Recorder<'_> {
    fn render_lpe(&self) -> bool {
        true
    }

    fn reads_camera(&self) -> bool {
        self.dagger.is_some()
    }

    fn controller(
        &mut self,
        expert: Box<dyn Controller>,
    ) -> Result<Box<dyn Controller>, TableError> {
        let Some(d) = self.dagger.as_mut() else {
            return Ok(Box::new(Watched::new(expert, self.label.clone())));
        };
        let learner = d.learner.take().ok_or(TableError::Setup {
            what: "learner",
            reason: "one recorder serves one run".into(),
        })?;
        Ok(Box::new(Mixed::new(
            expert,
            learner,
            d.beta,
            d.seed,
            self.label.clone(),
        )))
    }

    fn on_cycle(&mut self, cycle: Cycle<'_>) -> Result<CycleOutcome, TableError> {
        if let Some(intention) = cycle.intention {
            self.dlm = Some(intention.dlm);
            self.lpe = match &intention.lpe {
                Some(image) => self.shrink(image, "LPE image")?,
                None => vec![0; self.image_px * self.image_px * 3],
            };
        }
        let d = cycle.decision;
        let decided = Control::from_physical(d.cmd_v_mps, d.cmd_omega_radps, &self.limits);
        let said = if d.state == AgentState::Driving {
            *self.label.lock().unwrap_or_else(PoisonError::into_inner)
        } else {
            None
        };
        let (label, learner_drove) = match (&self.dagger, said) {
            (Some(_), Some(l)) => (l.expert, l.learner_drove),
            _ => (decided, false),
        };
        // `from_physical` clamps to the limits, as `label` is.
        let target = said
            .and_then(|l| l.target)
            .map_or(label, |(v, w)| Control::from_physical(v, w, &self.limits));
        let offset_radps = self
            .noise
            .as_mut()
            .map_or(0.0, |n| n.offset_radps(cycle.t_s));
        let cmd = Command {
            v_mps: d.cmd_v_mps,
            omega_radps: (d.cmd_omega_radps + offset_radps)
                .clamp(-self.limits.max_turn_radps, self.limits.max_turn_radps),
        };
        let store = self.cycle.is_multiple_of(self.every);
        self.cycle += 1;
        // No sample before the first intention: there is no DLM to store with it.
        if let (true, Some(dlm)) = (store, self.dlm) {
            let frame = cycle.world.camera_frame(0).map_err(|e| TableError::Setup {
                what: "camera",
                reason: e.to_string(),
            })?;
            let nan = [f32::NAN; 3];
            #[allow(clippy::cast_possible_truncation)]
            self.samples.push(Sample {
                camera: self.shrink(&frame.image, "camera image")?,
                lpe: self.lpe.clone(),
                // Dlm::index is 0..4.
                dlm: dlm.index() as u8,
                label: control_f32(label),
                target: control_f32(target),
                executed: control_f32(Control::from_physical(
                    cmd.v_mps,
                    cmd.omega_radps,
                    &self.limits,
                )),
                pose_true: pose_f32(cycle.truth_pose),
                pose_amcl: cycle.estimate_pose.map_or(nan, pose_f32),
                t_s: cycle.t_s as f32,
                learner_drove,
            });
            (self.progress)(1);
        }
        Ok(CycleOutcome {
            cmd,
            stop: self.samples.len() >= self.max_samples,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn noise_is_triangular_pulses() {
        let mut n = Noise::new(7, 1.0);
        let offsets: Vec<f64> = (0..600)
            .map(|i| n.offset_radps(f64::from(i) * 0.1))
            .collect();
        let peak = offsets.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        assert!(peak > 0.5 && peak <= 1.0);
        // Some quiet time between pulses and a pulse every few seconds.
        assert!(offsets.iter().filter(|v| **v == 0.0).count() > 50);
        let starts = offsets
            .windows(2)
            .filter(|w| w[0] == 0.0 && w[1] != 0.0)
            .count();
        assert!((8..=20).contains(&starts), "{starts} pulses in 60 s");
    }
}
