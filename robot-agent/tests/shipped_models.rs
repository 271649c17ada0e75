//! The trained models shipped in `models/` (`dlm.onnx`, `lpe.onnx`, `none.onnx`): each loads in
//! the agent with the agent's default configuration (its card matches the robot's limits and
//! the contract), is at most 20 MB, carries the card its `models/<kind>.card.json` records, and
//! computes on recorded frames what onnxruntime computed for them in Python
//! (`training/check_frames.py` → `models/checks/expected.json`), through the agent's own
//! preprocessing. On those frames the networks turn the way the expert turned.
//!
//! Needs the ONNX Runtime library that `bash scripts/setup.sh` installs; fails, never skips.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::{Path, PathBuf};

use protocol::{CameraFrame, Dlm, Header, Image, ImageEncoding, Intention};
use robot_agent::controllers::{Control, ControlInput, Controller, IntentionNet};
use robot_agent::controllers::{IntentionNetOptions, ModelExpectation};
use robot_agent::{AgentConfig, ControllerKind, Limits};
use serde_json::Value;
use test_support::fixtures;

const KINDS: [(&str, ControllerKind); 3] = [
    ("dlm", ControllerKind::Dlm),
    ("lpe", ControllerKind::Lpe),
    ("none", ControllerKind::None),
];

fn models() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../models")
}

fn load(kind: ControllerKind, file: &str) -> IntentionNet {
    let config = AgentConfig {
        controller: kind,
        model: Some(models().join(file)),
        ..AgentConfig::default()
    };
    IntentionNet::from_config(&config, &IntentionNetOptions::default())
        .unwrap_or_else(|e| panic!("the agent refuses models/{file}: {e}"))
}

fn png(path: &Path) -> Image {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let size = image::load_from_memory(&bytes).unwrap();
    Image::new(size.width(), size.height(), ImageEncoding::Png, bytes).unwrap()
}

fn control(net: &mut IntentionNet, camera: &Image, dlm: Dlm, lpe: Option<Image>) -> Control {
    let frame = CameraFrame {
        header: Header::new(1, 1_000),
        image: camera.clone(),
    };
    let intention = Intention {
        header: Header::new(1, 1_000),
        answers_pose_seq: 1,
        answers_pose_stamp_ns: 1_000,
        ..fixtures::intention_for_net(dlm, lpe)
    };
    net.control(&ControlInput {
        pose: protocol::Pose2D::default(),
        v_mps: 0.0,
        omega_radps: 0.0,
        scan: None,
        camera: Some(&frame),
        intention: Some(&intention),
        limits: &Limits::default(),
        dt_s: 0.1,
    })
    .unwrap()
}

#[test]
fn shipped_models_load_in_the_agent_and_carry_their_cards() {
    for (name, kind) in KINDS {
        let file = format!("{name}.onnx");
        let bytes = std::fs::metadata(models().join(&file))
            .unwrap_or_else(|e| panic!("models/{file}: {e}"))
            .len();
        assert!(bytes <= 20_000_000, "models/{file} is {bytes} bytes");
        let net = load(kind, &file);
        let card = net.card();
        assert_eq!(card.kind.as_str(), name);
        // The card the repository documents is the one inside the model.
        let json: Value = serde_json::from_str(
            &std::fs::read_to_string(models().join(format!("{name}.card.json"))).unwrap(),
        )
        .unwrap();
        for (key, value) in card.to_metadata() {
            let recorded = json[&key]
                .as_str()
                .unwrap_or_else(|| panic!("{name}.card.json lacks {key}"));
            if let (Ok(a), Ok(b)) = (recorded.parse::<f64>(), value.parse::<f64>()) {
                assert!((a - b).abs() <= 1e-9 * a.abs().max(1.0), "{name}: {key}");
            } else if key == "lpe_rendering" {
                let (a, b): (Value, Value) = (
                    serde_json::from_str(recorded).unwrap(),
                    serde_json::from_str(&value).unwrap(),
                );
                assert_eq!(a, b, "{name}: {key}");
            } else if key != "norm_mean" && key != "norm_std" {
                assert_eq!(recorded, value, "{name}: {key}");
            }
        }
        // The card states what it was trained on and how it did in closed loop.
        for key in ["recipe", "deviations", "closed_loop"] {
            assert!(
                json[key].as_str().is_some_and(|s| !s.is_empty()),
                "{name}: {key}"
            );
        }
        // A network for another controller kind is refused by its card.
        let other = if kind == ControllerKind::Dlm {
            ControllerKind::Lpe
        } else {
            ControllerKind::Dlm
        };
        let err = IntentionNet::load(
            &models().join(&file),
            &ModelExpectation::new(other, Limits::default()).unwrap(),
            &IntentionNetOptions::default(),
        )
        .unwrap_err();
        assert!(err.to_string().contains("kind"), "{err}");
    }
}

#[test]
fn shipped_models_compute_what_python_computed_and_turn_like_the_expert() {
    let checks = models().join("checks");
    let expected: Value =
        serde_json::from_str(&std::fs::read_to_string(checks.join("expected.json")).unwrap())
            .unwrap();
    let frames = expected["frames"].as_array().unwrap();
    assert!(frames.len() >= 12);
    for (name, kind) in KINDS {
        let mut net = load(kind, &format!("{name}.onnx"));
        // (expert ω, network ω) on the frames where the expert turned.
        let mut turns: Vec<(f64, f64)> = Vec::new();
        for f in frames {
            let camera = png(&checks.join(f["files"]["camera"].as_str().unwrap()));
            let lpe = png(&checks.join(f["files"]["lpe"].as_str().unwrap()));
            let dlm = Dlm::ALL[usize::try_from(f["dlm"].as_u64().unwrap()).unwrap()];
            let got = control(&mut net, &camera, dlm, Some(lpe));
            let want = &f["outputs"][name];
            for (i, g) in [got.v_norm, got.omega_norm].into_iter().enumerate() {
                let w = want[i].as_f64().unwrap();
                assert!((g - w).abs() <= 1e-4, "{name}: {g} vs Python {w}");
            }
            let label_w = f["label"][1].as_f64().unwrap();
            if label_w.abs() > 0.4 {
                turns.push((label_w, got.omega_norm));
            }
        }
        if kind == ControllerKind::None {
            continue; // Without an intention it cannot know which way a junction goes.
        }
        let agree = turns
            .iter()
            .filter(|(e, n)| e.signum() == n.signum())
            .count();
        assert!(
            agree * 3 >= turns.len() * 2,
            "{name} turns the expert's way on {agree} of {} turning frames: {turns:?}",
            turns.len()
        );
    }
}

#[test]
fn the_dlm_network_reads_its_intention() {
    let checks = models().join("checks");
    let expected: Value =
        serde_json::from_str(&std::fs::read_to_string(checks.join("expected.json")).unwrap())
            .unwrap();
    let mut net = load(ControllerKind::Dlm, "dlm.onnx");
    // On every frame, asking for a left turn turns further left than asking for a right one.
    let mut left_of_right = 0;
    let frames = expected["frames"].as_array().unwrap();
    for f in frames {
        let camera = png(&checks.join(f["files"]["camera"].as_str().unwrap()));
        let left = control(&mut net, &camera, Dlm::TurnLeft, None).omega_norm;
        let right = control(&mut net, &camera, Dlm::TurnRight, None).omega_norm;
        if left > right {
            left_of_right += 1;
        }
    }
    assert!(
        left_of_right * 4 >= frames.len() * 3,
        "turn_left > turn_right on only {left_of_right} of {} frames",
        frames.len()
    );
}
