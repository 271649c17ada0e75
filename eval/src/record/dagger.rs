//! DAgger rounds (Ross, Gordon & Bagnell 2011): a trained network drives, mixed with the
//! expert by β, and the expert labels every state the mixture visits.
//!
//! [`Mixed`] is the controller the agent's supervisor runs in such an episode. Every cycle it
//! asks both: the expert (so its state follows the robot and its command becomes the label)
//! and the learner; it returns the expert's command with probability β and the learner's
//! otherwise, so the supervisor's safety rules and acceleration limits act on the mixture
//! exactly as they act on a deployed network. What the expert said is left in a [`LabelCell`]
//! for the recorder.

use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, PoisonError};

use protocol::ControllerKind;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use robot_agent::controllers::intention_net::{self, ModelKind};
use robot_agent::controllers::{Control, ControlInput, Controller, ControllerError};
use robot_agent::{make_controller, AgentConfig};

use crate::table::TableError;

/// The learner of a DAgger round.
#[derive(Debug, Clone, PartialEq)]
pub struct Policy {
    /// Its ONNX model (with card).
    pub model: PathBuf,
    /// Which network the card says it is.
    pub kind: ControllerKind,
    /// Probability that the expert's command is executed in a cycle (1: the expert drives).
    pub beta: f64,
}

impl Policy {
    /// Reads the model's card to learn its kind.
    ///
    /// # Errors
    /// [`TableError::Controller`] when the model cannot be read or its card is invalid;
    /// [`TableError::Setup`] for β outside [0, 1].
    pub fn load(model: &Path, beta: f64) -> Result<Self, TableError> {
        if !(0.0..=1.0).contains(&beta) {
            return Err(TableError::Setup {
                what: "beta",
                reason: format!("{beta} is not a probability in [0, 1]"),
            });
        }
        let card = intention_net::read_card(model).map_err(|e| TableError::Controller {
            method: ControllerKind::Dlm,
            reason: e.to_string(),
        })?;
        let kind = match card.kind {
            ModelKind::Dlm => ControllerKind::Dlm,
            ModelKind::Lpe => ControllerKind::Lpe,
            ModelKind::None => ControllerKind::None,
        };
        Ok(Self {
            model: model.to_path_buf(),
            kind,
            beta,
        })
    }

    /// The learner's controller, configured like the robot's agent otherwise.
    ///
    /// # Errors
    /// [`TableError::Controller`] when the model does not load or does not fit the limits.
    pub fn learner(&self, agent: &AgentConfig) -> Result<Box<dyn Controller>, TableError> {
        let mut config = agent.clone();
        config.controller = self.kind;
        config.model = Some(self.model.clone());
        // Episodes already run in parallel on all cores.
        config.intention_net.intra_threads = 1;
        make_controller(&config).map_err(|e| TableError::Controller {
            method: self.kind,
            reason: e.to_string(),
        })
    }
}

/// What the expert commanded in the last cycle, what it steered towards and whether the
/// learner's command was used.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Label {
    pub expert: Control,
    /// The expert's [`Controller::target`] (m/s, rad/s), when it has one.
    pub target: Option<(f64, f64)>,
    pub learner_drove: bool,
}

impl Label {
    /// Leaves in `cell` what `expert` said this cycle (its command `said`).
    fn leave(cell: &LabelCell, expert: &dyn Controller, said: Control, learner_drove: bool) {
        *cell.lock().unwrap_or_else(PoisonError::into_inner) = Some(Self {
            expert: said.clamped(),
            target: expert.target(),
            learner_drove,
        });
    }
}

/// Shared between [`Mixed`] (inside the supervisor) and the recorder.
pub type LabelCell = Arc<Mutex<Option<Label>>>;

/// The β-mixture of the expert and a learner.
pub struct Mixed {
    expert: Box<dyn Controller>,
    learner: Box<dyn Controller>,
    beta: f64,
    rng: ChaCha8Rng,
    label: LabelCell,
}

impl Mixed {
    /// Mixes `expert` and `learner` with β = `beta`, drawing with `seed`.
    #[must_use]
    pub fn new(
        expert: Box<dyn Controller>,
        learner: Box<dyn Controller>,
        beta: f64,
        seed: u64,
        label: LabelCell,
    ) -> Self {
        Self {
            expert,
            learner,
            beta,
            rng: ChaCha8Rng::seed_from_u64(seed),
            label,
        }
    }
}

impl Controller for Mixed {
    fn kind(&self) -> ControllerKind {
        self.expert.kind()
    }

    fn control(&mut self, input: &ControlInput<'_>) -> Result<Control, ControllerError> {
        let expert = self.expert.control(input)?;
        // Drawn every cycle, also when β is 0 or 1, so the draws do not depend on it.
        let expert_drives = self.rng.gen_bool(self.beta);
        let learner = self.learner.control(input);
        let (out, learner_drove) = match (expert_drives, learner) {
            (false, Ok(c)) => (c, true),
            // A learner that cannot run this cycle (no LPE image yet) leaves it to the expert.
            (_, _) => (expert, false),
        };
        Label::leave(&self.label, self.expert.as_ref(), expert, learner_drove);
        Ok(out)
    }

    fn target(&self) -> Option<(f64, f64)> {
        self.expert.target()
    }

    fn reset(&mut self) {
        self.expert.reset();
        self.learner.reset();
    }
}

/// The expert alone (no learner), leaving what it said in a [`LabelCell`] like [`Mixed`] does,
/// so that the recorder reads its target the same way in both kinds of episode.
pub struct Watched {
    expert: Box<dyn Controller>,
    label: LabelCell,
}

impl Watched {
    #[must_use]
    pub fn new(expert: Box<dyn Controller>, label: LabelCell) -> Self {
        Self { expert, label }
    }
}

impl Controller for Watched {
    fn kind(&self) -> ControllerKind {
        self.expert.kind()
    }

    fn control(&mut self, input: &ControlInput<'_>) -> Result<Control, ControllerError> {
        let expert = self.expert.control(input)?;
        Label::leave(&self.label, self.expert.as_ref(), expert, false);
        Ok(expert)
    }

    fn target(&self) -> Option<(f64, f64)> {
        self.expert.target()
    }

    fn reset(&mut self) {
        self.expert.reset();
    }
}
