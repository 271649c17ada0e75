//! The model card of an intention-net ONNX model (DESIGN §5) and its check against the agent's
//! configuration.
//!
//! The card lives in the ONNX model's `metadata_props` (string key → string value), so it travels
//! inside the `.onnx` file and cannot drift from the weights. Keys (all required unless noted):
//!
//! | key | value |
//! |---|---|
//! | `card_version` | `1` |
//! | `kind` | `dlm`, `lpe` or `none` |
//! | `backbone` | free text, e.g. `resnet50` or `small-cnn` |
//! | `image_width_px`, `image_height_px` | the `camera` input size the network was trained on |
//! | `norm_mean`, `norm_std` | three comma-separated numbers, R,G,B: `x = (pixel/255 - mean) / std` |
//! | `max_speed_mps`, `max_turn_radps` | the limits that map the normalized output μ ∈ [-1,1]² to physical units |
//! | `dataset_id` | which demonstrations it was trained on |
//! | `validation_loss` | final validation loss, finite and ≥ 0 |
//! | `lpe_rendering` | `lpe` models only: JSON of the planner's LPE rendering parameters |
//! | `dlm_measure`, `dlm_params` | `dlm` models only, optional: how the planner derived the DLM the network was trained on (planning `DlmParams`; absent = `curvature`); the planner's `[dlm]` table must say the same, and `eval table` and `eval record --policy` plan with it |
//! | `lpe_image_px` | `lpe` models only, optional: the `lpe` input size (square) when the network takes the rendering scaled down (area average); absent = the rendering's `size_px` |
//!
//! Unknown keys are ignored on purpose: exporters (PyTorch, onnx tools) add their own.

use std::collections::BTreeMap;
use std::fmt;

use crate::config::{ControllerKind, Limits};

/// The card format this agent reads.
pub const CARD_VERSION: &str = "1";

/// Which of the paper's three networks a model is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ModelKind {
    /// DLM-Net: camera + one-hot discretized local move.
    Dlm,
    /// LPE-Net: camera + local path and environment image through a siamese CNN.
    Lpe,
    /// Non-Intention Net: camera only.
    None,
}

impl ModelKind {
    /// The card's spelling (`dlm`, `lpe`, `none`), the same as the agent config's.
    #[must_use]
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Dlm => "dlm",
            Self::Lpe => "lpe",
            Self::None => "none",
        }
    }

    /// The model kind a controller needs; `None` for controllers without a network.
    #[must_use]
    pub fn for_controller(kind: ControllerKind) -> Option<Self> {
        match kind {
            ControllerKind::Dlm => Some(Self::Dlm),
            ControllerKind::Lpe => Some(Self::Lpe),
            ControllerKind::None => Some(Self::None),
            ControllerKind::PathTracker
            | ControllerKind::DynamicWindow
            | ControllerKind::Expert => None,
        }
    }

    /// The controller that runs a model of this kind.
    #[must_use]
    pub fn controller(self) -> ControllerKind {
        match self {
            Self::Dlm => ControllerKind::Dlm,
            Self::Lpe => ControllerKind::Lpe,
            Self::None => ControllerKind::None,
        }
    }

    /// The graph's input names in the ONNX contract, camera first.
    #[must_use]
    pub fn input_names(self) -> &'static [&'static str] {
        match self {
            Self::Dlm => &["camera", "intention"],
            Self::Lpe => &["camera", "lpe"],
            Self::None => &["camera"],
        }
    }
}

impl fmt::Display for ModelKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// How the planner rendered the LPE images a model was trained on (the planner's `[lpe]`
/// parameters, DESIGN §4): a model is only valid for that rendering. The one definition lives in
/// `protocol`, shared with the planner that draws the images.
pub type LpeRendering = protocol::LpeParams;

/// Per-channel (R, G, B) normalization: `x = (pixel / 255 - mean) / std`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Normalization {
    pub mean: [f32; 3],
    pub std: [f32; 3],
}

/// Everything the model's metadata says about it.
#[derive(Debug, Clone, PartialEq)]
pub struct ModelCard {
    pub kind: ModelKind,
    pub backbone: String,
    pub image_width_px: u32,
    pub image_height_px: u32,
    pub normalization: Normalization,
    pub max_speed_mps: f64,
    pub max_turn_radps: f64,
    pub dataset_id: String,
    pub validation_loss: f64,
    /// Present exactly for `lpe` models.
    pub lpe_rendering: Option<LpeRendering>,
    /// `lpe` models only: the LPE input size when it differs from the rendering's.
    pub lpe_image_px: Option<u32>,
    /// `dlm` models only: the planner's DLM measure the network was trained on (planning
    /// `DlmMeasure` by name; `None`: a card from before it was recorded, the curvature DLM).
    /// The agent does not derive DLMs, so it only carries this for whoever plans them.
    pub dlm_measure: Option<String>,
    /// `dlm` models only: every planner DLM parameter the network was trained on, as JSON
    /// (planning `DlmParams`, the recording's `[dlm]` table; `None`: a card from before they
    /// were recorded, the planner's defaults for `dlm_measure`). Carried, like
    /// `dlm_measure`, for whoever plans DLMs, which parses and checks it.
    pub dlm_params: Option<String>,
}

/// A card that is missing a key or has a value that makes no sense.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CardError {
    #[error("model card: metadata key `{key}` is missing ({what})")]
    Missing {
        key: &'static str,
        what: &'static str,
    },
    #[error("model card: invalid {key} = {value:?}: {reason}")]
    Invalid {
        key: &'static str,
        value: String,
        reason: String,
    },
}

/// What the agent's configuration expects of the model it loads.
#[derive(Debug, Clone, PartialEq)]
pub struct ModelExpectation {
    pub kind: ModelKind,
    /// The robot's limits: the card's limits must be the same, or every command would be
    /// scaled differently from the demonstrations the network learned.
    pub limits: Limits,
    /// `[width, height]` of the network input, when the deployment fixes it; `None` accepts the
    /// card's size (camera frames are resized to it).
    pub image_size_px: Option<[u32; 2]>,
    /// The planner's LPE rendering, when known; `None` accepts the card's.
    pub lpe_rendering: Option<LpeRendering>,
}

impl ModelExpectation {
    /// The expectation of a controller kind with the given limits, accepting the card's image
    /// size and LPE rendering. `None` for controllers without a network.
    #[must_use]
    pub fn new(kind: ControllerKind, limits: Limits) -> Option<Self> {
        Some(Self {
            kind: ModelKind::for_controller(kind)?,
            limits,
            image_size_px: None,
            lpe_rendering: None,
        })
    }
}

/// A card value that differs from the configuration; `field` is the configuration's name.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("model card does not match the configuration: {field} is {configured} in the configuration but {card} in the model card")]
pub struct CardMismatch {
    pub field: &'static str,
    pub card: String,
    pub configured: String,
}

fn required<'m>(
    meta: &'m BTreeMap<String, String>,
    key: &'static str,
    what: &'static str,
) -> Result<&'m str, CardError> {
    meta.get(key)
        .map(|v| v.trim())
        .ok_or(CardError::Missing { key, what })
}

fn invalid(key: &'static str, value: &str, reason: impl Into<String>) -> CardError {
    CardError::Invalid {
        key,
        value: value.to_string(),
        reason: reason.into(),
    }
}

fn positive_u32(
    meta: &BTreeMap<String, String>,
    key: &'static str,
    what: &'static str,
) -> Result<u32, CardError> {
    let raw = required(meta, key, what)?;
    match raw.parse::<u32>() {
        Ok(v) if (1..=8192).contains(&v) => Ok(v),
        Ok(_) => Err(invalid(key, raw, "must be in 1..=8192")),
        Err(e) => Err(invalid(key, raw, format!("not an integer: {e}"))),
    }
}

fn finite_f64(
    meta: &BTreeMap<String, String>,
    key: &'static str,
    what: &'static str,
) -> Result<f64, CardError> {
    let raw = required(meta, key, what)?;
    match raw.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        Ok(_) => Err(invalid(key, raw, "must be finite")),
        Err(e) => Err(invalid(key, raw, format!("not a number: {e}"))),
    }
}

fn positive_f64(
    meta: &BTreeMap<String, String>,
    key: &'static str,
    what: &'static str,
) -> Result<f64, CardError> {
    let v = finite_f64(meta, key, what)?;
    if v <= 0.0 {
        return Err(invalid(key, &v.to_string(), "must be positive"));
    }
    Ok(v)
}

fn rgb_triple(
    meta: &BTreeMap<String, String>,
    key: &'static str,
    what: &'static str,
    positive: bool,
) -> Result<[f32; 3], CardError> {
    let raw = required(meta, key, what)?;
    let parts: Vec<&str> = raw.split(',').map(str::trim).collect();
    if parts.len() != 3 {
        return Err(invalid(
            key,
            raw,
            format!(
                "needs 3 comma-separated numbers (R,G,B), got {}",
                parts.len()
            ),
        ));
    }
    let mut out = [0.0_f32; 3];
    for (slot, part) in out.iter_mut().zip(&parts) {
        let v: f32 = part
            .parse()
            .map_err(|e| invalid(key, raw, format!("{part:?} is not a number: {e}")))?;
        if !v.is_finite() || (positive && v <= 0.0) {
            let need = if positive {
                "positive and finite"
            } else {
                "finite"
            };
            return Err(invalid(key, raw, format!("{part} must be {need}")));
        }
        *slot = v;
    }
    Ok(out)
}

fn non_empty(
    meta: &BTreeMap<String, String>,
    key: &'static str,
    what: &'static str,
) -> Result<String, CardError> {
    let raw = required(meta, key, what)?;
    if raw.is_empty() {
        return Err(invalid(key, raw, "must not be empty"));
    }
    Ok(raw.to_string())
}

impl ModelCard {
    /// Parses the card from a model's metadata, naming the first missing or invalid key.
    ///
    /// # Errors
    /// [`CardError`] naming the key and, for invalid ones, the value.
    pub fn from_metadata(meta: &BTreeMap<String, String>) -> Result<Self, CardError> {
        let version = required(meta, "card_version", "the card format version")?;
        if version != CARD_VERSION {
            return Err(invalid(
                "card_version",
                version,
                format!("this agent reads card version {CARD_VERSION}"),
            ));
        }
        let kind_raw = required(meta, "kind", "dlm, lpe or none")?;
        let kind = match kind_raw {
            "dlm" => ModelKind::Dlm,
            "lpe" => ModelKind::Lpe,
            "none" => ModelKind::None,
            _ => return Err(invalid("kind", kind_raw, "must be dlm, lpe or none")),
        };
        let lpe_rendering = match (kind, meta.get("lpe_rendering")) {
            (ModelKind::Lpe, Some(raw)) => {
                let r: LpeRendering = serde_json::from_str(raw)
                    .map_err(|e| invalid("lpe_rendering", raw, format!("bad JSON: {e}")))?;
                // The shared struct fills absent keys with defaults (handy in a config file);
                // a card must state every one, or a model would silently claim a rendering.
                let present: serde_json::Map<String, serde_json::Value> = serde_json::from_str(raw)
                    .map_err(|e| invalid("lpe_rendering", raw, format!("bad JSON: {e}")))?;
                if let Ok(serde_json::Value::Object(all)) =
                    serde_json::to_value(LpeRendering::default())
                {
                    if let Some(missing) = all.keys().find(|k| !present.contains_key(*k)) {
                        return Err(invalid(
                            "lpe_rendering",
                            raw,
                            format!("missing key {missing}"),
                        ));
                    }
                }
                r.validate()
                    .map_err(|e| invalid("lpe_rendering", raw, e.to_string()))?;
                Some(r)
            }
            (ModelKind::Lpe, None) => {
                return Err(CardError::Missing {
                    key: "lpe_rendering",
                    what: "an lpe model must record the LPE rendering it was trained on",
                })
            }
            (_, Some(raw)) => {
                return Err(invalid(
                    "lpe_rendering",
                    raw,
                    format!("only lpe models have one, this card says kind = {kind}"),
                ))
            }
            (_, None) => None,
        };
        let lpe_image_px = match (kind, meta.get("lpe_image_px")) {
            (ModelKind::Lpe, Some(_)) => {
                Some(positive_u32(meta, "lpe_image_px", "LPE input size")?)
            }
            (_, Some(raw)) => {
                return Err(invalid(
                    "lpe_image_px",
                    raw,
                    format!("only lpe models have one, this card says kind = {kind}"),
                ))
            }
            (_, None) => None,
        };
        let validation_loss = finite_f64(meta, "validation_loss", "the final validation loss")?;
        if validation_loss < 0.0 {
            return Err(invalid(
                "validation_loss",
                &validation_loss.to_string(),
                "a loss cannot be negative",
            ));
        }
        Ok(Self {
            kind,
            backbone: non_empty(meta, "backbone", "which CNN backbone, e.g. resnet50")?,
            image_width_px: positive_u32(meta, "image_width_px", "camera input width")?,
            image_height_px: positive_u32(meta, "image_height_px", "camera input height")?,
            normalization: Normalization {
                mean: rgb_triple(meta, "norm_mean", "per-channel mean R,G,B", false)?,
                std: rgb_triple(meta, "norm_std", "per-channel std R,G,B", true)?,
            },
            max_speed_mps: positive_f64(meta, "max_speed_mps", "speed for v = 1")?,
            max_turn_radps: positive_f64(meta, "max_turn_radps", "turn rate for ω = 1")?,
            dataset_id: non_empty(meta, "dataset_id", "the training dataset")?,
            validation_loss,
            lpe_rendering,
            lpe_image_px,
            dlm_measure: match kind {
                ModelKind::Dlm => meta.get("dlm_measure").cloned(),
                ModelKind::Lpe | ModelKind::None => None,
            },
            dlm_params: match (kind, meta.get("dlm_params")) {
                (ModelKind::Dlm, Some(raw)) => Some(raw.clone()),
                _ => None,
            },
        })
    }

    /// The side of the square `lpe` input: `lpe_image_px`, else the rendering's size; 0 for a
    /// model without an LPE input.
    #[must_use]
    pub fn lpe_input_px(&self) -> u32 {
        self.lpe_image_px
            .or_else(|| self.lpe_rendering.as_ref().map(|r| r.size_px))
            .unwrap_or(0)
    }

    /// The metadata that [`ModelCard::from_metadata`] reads back; what an exporter writes.
    #[must_use]
    pub fn to_metadata(&self) -> BTreeMap<String, String> {
        let triple = |v: [f32; 3]| format!("{},{},{}", v[0], v[1], v[2]);
        let mut m = BTreeMap::new();
        m.insert("card_version".into(), CARD_VERSION.into());
        m.insert("kind".into(), self.kind.as_str().into());
        m.insert("backbone".into(), self.backbone.clone());
        m.insert("image_width_px".into(), self.image_width_px.to_string());
        m.insert("image_height_px".into(), self.image_height_px.to_string());
        m.insert("norm_mean".into(), triple(self.normalization.mean));
        m.insert("norm_std".into(), triple(self.normalization.std));
        m.insert("max_speed_mps".into(), self.max_speed_mps.to_string());
        m.insert("max_turn_radps".into(), self.max_turn_radps.to_string());
        m.insert("dataset_id".into(), self.dataset_id.clone());
        m.insert("validation_loss".into(), self.validation_loss.to_string());
        if let Some(r) = &self.lpe_rendering {
            // Serializing plain numbers and arrays cannot fail.
            if let Ok(json) = serde_json::to_string(r) {
                m.insert("lpe_rendering".into(), json);
            }
        }
        if let Some(px) = self.lpe_image_px {
            m.insert("lpe_image_px".into(), px.to_string());
        }
        if let Some(measure) = &self.dlm_measure {
            m.insert("dlm_measure".into(), measure.clone());
        }
        if let Some(params) = &self.dlm_params {
            m.insert("dlm_params".into(), params.clone());
        }
        m
    }

    /// Checks the card against what the configuration expects, naming the first field that
    /// differs.
    ///
    /// # Errors
    /// [`CardMismatch`] with the configuration's field name and both values.
    pub fn check(&self, expect: &ModelExpectation) -> Result<(), CardMismatch> {
        if self.kind != expect.kind {
            return Err(CardMismatch {
                field: "controller",
                card: format!("kind = {}", self.kind),
                configured: expect.kind.to_string(),
            });
        }
        if let Some([w, h]) = expect.image_size_px {
            if [w, h] != [self.image_width_px, self.image_height_px] {
                return Err(CardMismatch {
                    field: "image size (image_width_px x image_height_px)",
                    card: format!("{}x{} px", self.image_width_px, self.image_height_px),
                    configured: format!("{w}x{h} px"),
                });
            }
        }
        for (field, card, configured) in [
            (
                "limits.max_speed_mps",
                self.max_speed_mps,
                expect.limits.max_speed_mps,
            ),
            (
                "limits.max_turn_radps",
                self.max_turn_radps,
                expect.limits.max_turn_radps,
            ),
        ] {
            // Relative tolerance: the card stores decimal text, the config may be computed.
            if (card - configured).abs() > 1e-9 * card.abs().max(configured.abs()) {
                return Err(CardMismatch {
                    field,
                    card: card.to_string(),
                    configured: configured.to_string(),
                });
            }
        }
        if let (Some(want), Some(have)) = (&expect.lpe_rendering, &self.lpe_rendering) {
            if want != have {
                return Err(CardMismatch {
                    field: "lpe rendering",
                    card: format!("{have:?}"),
                    configured: format!("{want:?}"),
                });
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dlm_meta() -> BTreeMap<String, String> {
        [
            ("card_version", "1"),
            ("kind", "dlm"),
            ("backbone", "small-cnn"),
            ("image_width_px", "224"),
            ("image_height_px", "224"),
            ("norm_mean", "0.485,0.456,0.406"),
            ("norm_std", "0.229, 0.224, 0.225"),
            ("max_speed_mps", "0.7"),
            ("max_turn_radps", "1.2"),
            ("dataset_id", "ds-1"),
            ("validation_loss", "0.031"),
            ("onnx.producer_extra", "ignored"),
        ]
        .into_iter()
        .map(|(k, v)| (k.to_string(), v.to_string()))
        .collect()
    }

    #[test]
    fn parses_a_full_card_and_round_trips() {
        let card = ModelCard::from_metadata(&dlm_meta()).unwrap();
        assert_eq!(card.kind, ModelKind::Dlm);
        assert_eq!((card.image_width_px, card.image_height_px), (224, 224));
        assert_eq!(card.normalization.std, [0.229, 0.224, 0.225]);
        assert!((card.validation_loss - 0.031).abs() < 1e-12);
        assert_eq!(card.lpe_rendering, None);
        assert_eq!(ModelCard::from_metadata(&card.to_metadata()).unwrap(), card);
    }

    #[test]
    fn every_required_key_is_named_when_missing() {
        for key in [
            "card_version",
            "kind",
            "backbone",
            "image_width_px",
            "image_height_px",
            "norm_mean",
            "norm_std",
            "max_speed_mps",
            "max_turn_radps",
            "dataset_id",
            "validation_loss",
        ] {
            let mut meta = dlm_meta();
            meta.remove(key);
            let err = ModelCard::from_metadata(&meta).unwrap_err();
            assert!(
                matches!(err, CardError::Missing { key: k, .. } if k == key),
                "{key}: {err}"
            );
            assert!(err.to_string().contains(key), "{err}");
        }
    }

    #[test]
    fn invalid_values_are_named_with_their_value() {
        for (key, value) in [
            ("kind", "dwa"),
            ("card_version", "2"),
            ("image_width_px", "0"),
            ("image_height_px", "wide"),
            ("norm_mean", "0.5,0.5"),
            ("norm_std", "0.2,0,0.2"),
            ("max_speed_mps", "-0.7"),
            ("max_turn_radps", "NaN"),
            ("validation_loss", "-1"),
            ("dataset_id", "  "),
        ] {
            let mut meta = dlm_meta();
            meta.insert(key.to_string(), value.to_string());
            let err = ModelCard::from_metadata(&meta).unwrap_err();
            assert!(
                matches!(&err, CardError::Invalid { key: k, .. } if *k == key),
                "{key}={value}: {err}"
            );
        }
    }

    #[test]
    fn dlm_models_carry_their_dlm_measure_and_parameters() {
        let mut meta = dlm_meta();
        meta.insert("dlm_measure".into(), "route".into());
        meta.insert("dlm_params".into(), r#"{"measure":"route"}"#.into());
        let card = ModelCard::from_metadata(&meta).unwrap();
        assert_eq!(card.dlm_measure.as_deref(), Some("route"));
        assert_eq!(card.dlm_params.as_deref(), Some(r#"{"measure":"route"}"#));
        assert_eq!(ModelCard::from_metadata(&card.to_metadata()).unwrap(), card);
        // Only DLM-Nets have them.
        meta.insert("kind".into(), "none".into());
        let card = ModelCard::from_metadata(&meta).unwrap();
        assert_eq!((card.dlm_measure, card.dlm_params), (None, None));
    }

    #[test]
    fn lpe_rendering_is_required_for_lpe_and_refused_elsewhere() {
        let mut meta = dlm_meta();
        meta.insert("kind".into(), "lpe".into());
        let err = ModelCard::from_metadata(&meta).unwrap_err();
        assert!(err.to_string().contains("lpe_rendering"), "{err}");
        let rendering = r#"{"size_px":224,"metres_per_px":0.05,"robot_px":[112,168],"travelled_width_px":3.0,"ahead_width_px":3.0,"free_rgb":[255,255,255],"occupied_rgb":[0,0,0],"unknown_rgb":[128,128,128],"travelled_rgb":[255,0,0],"ahead_rgb":[0,0,255]}"#;
        meta.insert("lpe_rendering".into(), rendering.into());
        let card = ModelCard::from_metadata(&meta).unwrap();
        assert_eq!(
            card.lpe_rendering.as_ref().map(|r| r.robot_px),
            Some([112, 168])
        );
        meta.insert("lpe_rendering".into(), rendering.replace("168", "400"));
        assert!(ModelCard::from_metadata(&meta).is_err());
        assert_eq!(
            card.lpe_input_px(),
            224,
            "absent lpe_image_px: the rendering's size"
        );
        meta.insert("lpe_rendering".into(), rendering.into());
        meta.insert("lpe_image_px".into(), "96".into());
        let card = ModelCard::from_metadata(&meta).unwrap();
        assert_eq!(card.lpe_input_px(), 96);
        assert_eq!(ModelCard::from_metadata(&card.to_metadata()).unwrap(), card);
        meta.insert("lpe_image_px".into(), "0".into());
        let err = ModelCard::from_metadata(&meta).unwrap_err();
        assert!(err.to_string().contains("lpe_image_px"), "{err}");
        let mut meta = dlm_meta();
        meta.insert("lpe_rendering".into(), rendering.into());
        let err = ModelCard::from_metadata(&meta).unwrap_err();
        assert!(err.to_string().contains("kind = dlm"), "{err}");
        let mut meta = dlm_meta();
        meta.insert("lpe_image_px".into(), "96".into());
        let err = ModelCard::from_metadata(&meta).unwrap_err();
        assert!(err.to_string().contains("kind = dlm"), "{err}");
    }

    #[test]
    fn check_names_the_mismatching_field() {
        let card = ModelCard::from_metadata(&dlm_meta()).unwrap();
        let ok = ModelExpectation::new(ControllerKind::Dlm, Limits::default()).unwrap();
        card.check(&ok).unwrap();
        assert!(ModelExpectation::new(ControllerKind::DynamicWindow, Limits::default()).is_none());

        let as_lpe = ModelExpectation {
            kind: ModelKind::Lpe,
            ..ok.clone()
        };
        let err = card.check(&as_lpe).unwrap_err();
        assert_eq!(err.field, "controller");
        assert!(err.to_string().contains("kind = dlm"), "{err}");

        let small = ModelExpectation {
            image_size_px: Some([112, 112]),
            ..ok.clone()
        };
        let err = card.check(&small).unwrap_err();
        assert!(err.to_string().contains("112x112"), "{err}");

        let limits = Limits {
            max_turn_radps: 2.0,
            ..Limits::default()
        };
        let err = card
            .check(&ModelExpectation {
                limits,
                ..ok.clone()
            })
            .unwrap_err();
        assert_eq!(err.field, "limits.max_turn_radps");
        assert!(err.to_string().contains("1.2"), "{err}");
    }
}
