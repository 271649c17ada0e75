//! The intention-net controllers (paper §3.2, DESIGN §5): DLM-Net, LPE-Net and the
//! Non-Intention Net, run with ONNX Runtime through `ort`.
//!
//! [`IntentionNet::load`] finds and loads ONNX Runtime once per process ([`runtime`]), opens the
//! model, reads its [`ModelCard`] from the ONNX metadata, refuses a card that does not match the
//! configuration ([`ModelExpectation`]) and a graph that does not follow the ONNX contract, then
//! each control cycle turns the newest camera frame (and the intention's one-hot or LPE image)
//! into the network's inputs ([`preprocess`]) and returns the normalized control it outputs.

pub mod card;
pub mod preprocess;
pub mod runtime;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use ndarray::{Array2, Array4};
use ort::session::Session;
use ort::value::{TensorElementType, TensorRef};

use super::{Control, ControlInput, Controller, ControllerError};
use crate::config::{AgentConfig, ControllerKind};

pub use card::{
    CardError, CardMismatch, LpeRendering, ModelCard, ModelExpectation, ModelKind, Normalization,
};
pub use runtime::RuntimeError;

/// How a session runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct IntentionNetOptions {
    /// Threads ONNX Runtime may use inside one operator. One by default: the agent shares a
    /// small robot computer with localization and the safety loop.
    pub intra_threads: usize,
}

impl Default for IntentionNetOptions {
    fn default() -> Self {
        Self { intra_threads: 1 }
    }
}

/// Why a model could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum IntentionNetError {
    #[error(transparent)]
    Runtime(#[from] RuntimeError),
    #[error("controller {0:?} does not run an intention-net model")]
    NotANetwork(ControllerKind),
    #[error("controller {0:?} needs `model` (an ONNX file) in the configuration")]
    NoModelConfigured(ControllerKind),
    #[error("model {path}: cannot read the file: {reason}")]
    Read { path: String, reason: String },
    #[error("model {path}: ONNX Runtime cannot load it: {reason}")]
    Session { path: String, reason: String },
    #[error("model {path}: {source}")]
    Card { path: String, source: CardError },
    #[error("model {path}: {source}")]
    Mismatch { path: String, source: CardMismatch },
    #[error("model {path}: the graph does not follow the ONNX contract (DESIGN §5): {reason}")]
    Contract { path: String, reason: String },
}

impl From<IntentionNetError> for ControllerError {
    fn from(e: IntentionNetError) -> Self {
        let path = match &e {
            IntentionNetError::Read { path, .. }
            | IntentionNetError::Session { path, .. }
            | IntentionNetError::Card { path, .. }
            | IntentionNetError::Mismatch { path, .. }
            | IntentionNetError::Contract { path, .. } => path.clone(),
            IntentionNetError::Runtime(_)
            | IntentionNetError::NotANetwork(_)
            | IntentionNetError::NoModelConfigured(_) => "(none loaded)".to_string(),
        };
        ControllerError::Model {
            path,
            reason: e.to_string(),
        }
    }
}

/// A loaded intention-net model driving the robot.
pub struct IntentionNet {
    path: PathBuf,
    card: ModelCard,
    session: Session,
    camera: Array4<f32>,
    /// The `intention` one-hot (dlm) input.
    intention: Array2<f32>,
    /// The `lpe` image (lpe) input.
    lpe: Array4<f32>,
}

impl std::fmt::Debug for IntentionNet {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("IntentionNet")
            .field("path", &self.path)
            .field("card", &self.card)
            .finish_non_exhaustive()
    }
}

fn controller_name(kind: ModelKind) -> &'static str {
    match kind {
        ModelKind::Dlm => "intention-net dlm",
        ModelKind::Lpe => "intention-net lpe",
        ModelKind::None => "intention-net none",
    }
}

impl IntentionNet {
    /// Loads the model the agent configuration names, for its controller kind and limits.
    ///
    /// # Errors
    /// [`IntentionNetError`] if the controller has no network, no model is configured, or
    /// [`IntentionNet::load`] fails.
    pub fn from_config(
        config: &AgentConfig,
        options: &IntentionNetOptions,
    ) -> Result<Self, IntentionNetError> {
        let expect = ModelExpectation::new(config.controller, config.limits)
            .ok_or(IntentionNetError::NotANetwork(config.controller))?;
        let path = config
            .model
            .as_deref()
            .ok_or(IntentionNetError::NoModelConfigured(config.controller))?;
        Self::load(path, &expect, options)
    }

    /// Loads `path`, checks its card against `expect` and its graph against the ONNX contract.
    ///
    /// # Errors
    /// [`IntentionNetError`] naming what is wrong: no ONNX Runtime (with what to do), an
    /// unreadable file, a missing/invalid card key, a card value that differs from the
    /// configuration, or inputs/outputs that break the contract.
    pub fn load(
        path: &Path,
        expect: &ModelExpectation,
        options: &IntentionNetOptions,
    ) -> Result<Self, IntentionNetError> {
        let shown = path.display().to_string();
        let (session, card) = open(path, options)?;
        card.check(expect)
            .map_err(|source| IntentionNetError::Mismatch {
                path: shown.clone(),
                source,
            })?;
        check_contract(&session, &card).map_err(|reason| IntentionNetError::Contract {
            path: shown.clone(),
            reason,
        })?;
        let (w, h) = (card.image_width_px as usize, card.image_height_px as usize);
        let lpe_px = card.lpe_input_px() as usize;
        Ok(Self {
            path: path.to_path_buf(),
            camera: Array4::zeros((1, 3, h, w)),
            intention: Array2::zeros((1, 4)),
            lpe: Array4::zeros((1, 3, lpe_px, lpe_px)),
            card,
            session,
        })
    }

    /// The loaded model's card.
    #[must_use]
    pub fn card(&self) -> &ModelCard {
        &self.card
    }

    /// The model file.
    #[must_use]
    pub fn path(&self) -> &Path {
        &self.path
    }

    fn run(&mut self) -> Result<Control, ControllerError> {
        let fail = |e: ort::Error| ControllerError::Inference(e.to_string());
        let camera = TensorRef::from_array_view(self.camera.view()).map_err(fail)?;
        let outputs = match self.card.kind {
            ModelKind::Dlm => {
                let intention = TensorRef::from_array_view(self.intention.view()).map_err(fail)?;
                self.session
                    .run(ort::inputs!["camera" => camera, "intention" => intention])
            }
            ModelKind::Lpe => {
                let lpe = TensorRef::from_array_view(self.lpe.view()).map_err(fail)?;
                self.session
                    .run(ort::inputs!["camera" => camera, "lpe" => lpe])
            }
            ModelKind::None => self.session.run(ort::inputs!["camera" => camera]),
        }
        .map_err(fail)?;
        let control = outputs
            .get("control")
            .ok_or_else(|| ControllerError::Inference("no `control` output".into()))?;
        let (_, values) = control.try_extract_tensor::<f32>().map_err(fail)?;
        match values {
            [v, w, ..] => Ok(Control {
                v_norm: f64::from(*v),
                omega_norm: f64::from(*w),
            }),
            _ => Err(ControllerError::Inference(format!(
                "`control` has {} values, expected 2",
                values.len()
            ))),
        }
    }
}

impl Controller for IntentionNet {
    fn kind(&self) -> ControllerKind {
        self.card.kind.controller()
    }

    /// The raw network output; the agent clamps and scales it (a NaN output becomes a stop).
    fn control(&mut self, input: &ControlInput<'_>) -> Result<Control, ControllerError> {
        let controller = controller_name(self.card.kind);
        let frame = input.camera.ok_or(ControllerError::MissingInput {
            controller,
            input: "camera",
        })?;
        let card = &self.card;
        preprocess::image_to_chw(
            &frame.image,
            card.image_width_px,
            card.image_height_px,
            &card.normalization,
            self.camera.as_slice_mut().unwrap_or_default(),
        )
        .map_err(|e| ControllerError::BadInput {
            controller,
            input: "camera",
            reason: e.0,
        })?;
        match card.kind {
            ModelKind::Dlm => {
                let intention = input.intention.ok_or(ControllerError::MissingInput {
                    controller,
                    input: "intention",
                })?;
                for (slot, v) in self.intention.iter_mut().zip(intention.dlm.one_hot()) {
                    *slot = v;
                }
            }
            ModelKind::Lpe => {
                let lpe = input.intention.and_then(|i| i.lpe.as_ref()).ok_or(
                    ControllerError::MissingInput {
                        controller,
                        input: "intention.lpe",
                    },
                )?;
                let size = card.lpe_input_px();
                preprocess::image_to_chw(
                    lpe,
                    size,
                    size,
                    &card.normalization,
                    self.lpe.as_slice_mut().unwrap_or_default(),
                )
                .map_err(|e| ControllerError::BadInput {
                    controller,
                    input: "intention.lpe",
                    reason: e.0,
                })?;
            }
            ModelKind::None => {}
        }
        self.run()
    }
}

/// Opens `path` in ONNX Runtime and reads its card (not yet checked against anything).
fn open(
    path: &Path,
    options: &IntentionNetOptions,
) -> Result<(Session, ModelCard), IntentionNetError> {
    let shown = path.display().to_string();
    // Reading the file first gives a plain "no such file" rather than an ONNX Runtime error.
    let bytes = std::fs::read(path).map_err(|e| IntentionNetError::Read {
        path: shown.clone(),
        reason: e.to_string(),
    })?;
    let environment = runtime::environment()?;
    let session_err = |reason: String| IntentionNetError::Session {
        path: shown.clone(),
        reason,
    };
    let session = Session::builder(environment)
        .map_err(|e| session_err(e.to_string()))?
        .with_intra_threads(options.intra_threads.max(1))
        .map_err(|e| session_err(e.to_string()))?
        .commit_from_memory(&bytes)
        .map_err(|e| session_err(e.to_string()))?;
    let metadata = read_metadata(&session).map_err(session_err)?;
    let card = ModelCard::from_metadata(&metadata).map_err(|source| IntentionNetError::Card {
        path: shown.clone(),
        source,
    })?;
    Ok((session, card))
}

/// The card of the model at `path`, unchecked: what a tool needs to learn which kind of
/// network a file holds before it configures a controller for it.
///
/// # Errors
/// As [`IntentionNet::load`], short of the checks against a configuration and the contract.
pub fn read_card(path: &Path) -> Result<ModelCard, IntentionNetError> {
    open(path, &IntentionNetOptions::default()).map(|(_, card)| card)
}

fn read_metadata(session: &Session) -> Result<BTreeMap<String, String>, String> {
    let metadata = session
        .metadata()
        .map_err(|e| format!("cannot read metadata: {e}"))?;
    let keys = metadata
        .custom_keys()
        .map_err(|e| format!("cannot read metadata keys: {e}"))?;
    Ok(keys
        .into_iter()
        .filter_map(|k| metadata.custom(&k).map(|v| (k, v)))
        .collect())
}

/// Checks the graph's inputs and output against the contract and the card's sizes.
fn check_contract(session: &Session, card: &ModelCard) -> Result<(), String> {
    let want = card.kind.input_names();
    let mut have: Vec<&str> = session.inputs().iter().map(|i| i.name()).collect();
    have.sort_unstable();
    let mut sorted = want.to_vec();
    sorted.sort_unstable();
    if have != sorted {
        return Err(format!(
            "a {} model has inputs {want:?}, this graph has {have:?}",
            card.kind
        ));
    }
    let lpe_px = i64::from(card.lpe_input_px());
    let (h, w) = (
        i64::from(card.image_height_px),
        i64::from(card.image_width_px),
    );
    for input in session.inputs() {
        let expected: &[i64] = match input.name() {
            "camera" => &[-1, 3, h, w],
            "intention" => &[-1, 4],
            _ => &[-1, 3, lpe_px, lpe_px],
        };
        check_tensor(input.name(), input.dtype(), expected)?;
    }
    let control = session
        .outputs()
        .iter()
        .find(|o| o.name() == "control")
        .ok_or("no output named `control`")?;
    check_tensor("control", control.dtype(), &[-1, 2])
}

/// `expected` dims of -1 accept any size (the batch); a graph's dynamic dims accept anything.
fn check_tensor(name: &str, dtype: &ort::value::ValueType, expected: &[i64]) -> Result<(), String> {
    let (Some(ty), Some(shape)) = (dtype.tensor_type(), dtype.tensor_shape()) else {
        return Err(format!("`{name}` is not a tensor"));
    };
    if ty != TensorElementType::Float32 {
        return Err(format!("`{name}` is {ty}, the contract says f32"));
    }
    let dims: &[i64] = shape;
    let fits = dims.len() == expected.len()
        && dims
            .iter()
            .zip(expected)
            .all(|(&d, &e)| d < 0 || e < 0 || d == e);
    if !fits {
        return Err(format!(
            "`{name}` has shape {dims:?}, the card and contract say {expected:?} (-1 = any)"
        ));
    }
    Ok(())
}
