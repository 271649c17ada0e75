//! The intention-net controllers on the real ONNX Runtime, with the fixture models that
//! training/make_fixture_model.py generates (models/fixtures/).
//!
//! These tests need the ONNX Runtime library that `bash scripts/setup.sh` installs; without it
//! they fail with the message that says so, they never skip.

// Test helpers panic on broken fixtures: that is the failure report.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::io::Cursor;
use std::path::{Path, PathBuf};

use image::{ImageFormat, RgbImage};
use protocol::{CameraFrame, Dlm, Header, Image, ImageEncoding, Intention, Pose2D};
use robot_agent::controllers::intention_net::runtime::{self, RuntimeError};
use robot_agent::controllers::intention_net::{IntentionNetError, LpeRendering};
use robot_agent::controllers::{
    Control, ControlInput, Controller, ControllerError, IntentionNet, IntentionNetOptions,
    ModelExpectation, ModelKind,
};
use robot_agent::{AgentConfig, ControllerKind, Limits};
use serde_json::Value;
use test_support::fixtures;

const SIZE_PX: u32 = 224;

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/fixtures")
}

fn expect(kind: ControllerKind) -> ModelExpectation {
    ModelExpectation::new(kind, Limits::default()).unwrap()
}

fn load(file: &str, kind: ControllerKind) -> IntentionNet {
    IntentionNet::load(
        &fixtures().join(file),
        &expect(kind),
        &IntentionNetOptions::default(),
    )
    .unwrap_or_else(|e| panic!("loading {file}: {e}"))
}

/// The pixels of a pattern spec of expected.json, exactly as the Python script builds them.
fn pattern(spec: &Value, size_px: u32) -> Image {
    let rgb = |x: u32, y: u32| -> [u8; 3] {
        match spec["pattern"].as_str().unwrap() {
            "constant" => {
                let c = spec["rgb"].as_array().unwrap();
                [0, 1, 2].map(|i| c[i].as_u64().unwrap() as u8)
            }
            "gradient" => {
                let (w, h) = (size_px - 1, size_px - 1);
                [x * 255 / w, y * 255 / h, (x + y) * 255 / (w + h)].map(|v| v as u8)
            }
            other => panic!("unknown pattern {other}"),
        }
    };
    let mut data = Vec::with_capacity((size_px * size_px * 3) as usize);
    for y in 0..size_px {
        for x in 0..size_px {
            data.extend_from_slice(&rgb(x, y));
        }
    }
    Image::new(size_px, size_px, ImageEncoding::Rgb8, data).unwrap()
}

fn encoded(image: &Image, format: ImageFormat, encoding: ImageEncoding) -> Image {
    let buf = RgbImage::from_raw(image.width_px, image.height_px, image.data.clone()).unwrap();
    let mut bytes = Cursor::new(Vec::new());
    buf.write_to(&mut bytes, format).unwrap();
    Image::new(
        image.width_px,
        image.height_px,
        encoding,
        bytes.into_inner(),
    )
    .unwrap()
}

fn frame(image: Image) -> CameraFrame {
    CameraFrame {
        header: Header::new(1, 1_000),
        image,
    }
}

fn intention(dlm: Dlm, lpe: Option<Image>) -> Intention {
    Intention {
        header: Header::new(1, 1_000),
        answers_pose_seq: 1,
        answers_pose_stamp_ns: 1_000,
        ..fixtures::intention_for_net(dlm, lpe)
    }
}

fn run(
    net: &mut IntentionNet,
    camera: Option<&CameraFrame>,
    intention: Option<&Intention>,
) -> Result<Control, ControllerError> {
    let limits = Limits::default();
    net.control(&ControlInput {
        pose: Pose2D::default(),
        v_mps: 0.0,
        omega_radps: 0.0,
        scan: None,
        camera,
        intention,
        limits: &limits,
        dt_s: 0.1,
    })
}

fn dlm_named(name: &str) -> Dlm {
    *Dlm::ALL.iter().find(|d| d.as_str() == name).unwrap()
}

fn close(got: Control, want: [f64; 2], tol: f64) -> bool {
    (got.v_norm - want[0]).abs() <= tol && (got.omega_norm - want[1]).abs() <= tol
}

#[test]
fn outputs_match_the_onnxruntime_python_reference() {
    let text = std::fs::read_to_string(fixtures().join("expected.json")).unwrap();
    let expected: Value = serde_json::from_str(&text).unwrap();
    let tol = expected["tolerance"].as_f64().unwrap();
    assert!(tol <= 1e-4);
    let mut dlm = load("dlm.onnx", ControllerKind::Dlm);
    let mut lpe = load("lpe.onnx", ControllerKind::Lpe);
    let mut none = load("none.onnx", ControllerKind::None);
    let cases = expected["cases"].as_array().unwrap();
    assert_eq!(cases.len(), 3 * (4 + 2 + 1));
    for case in cases {
        let camera = frame(pattern(&case["camera"], SIZE_PX));
        let want = [0, 1].map(|i| case["control"][i].as_f64().unwrap());
        let got = match case["model"].as_str().unwrap() {
            "dlm.onnx" => {
                let i = intention(dlm_named(case["dlm"].as_str().unwrap()), None);
                run(&mut dlm, Some(&camera), Some(&i))
            }
            "lpe.onnx" => {
                let i = intention(Dlm::GoForward, Some(pattern(&case["lpe"], SIZE_PX)));
                run(&mut lpe, Some(&camera), Some(&i))
            }
            "none.onnx" => run(&mut none, Some(&camera), None),
            other => panic!("unknown model {other}"),
        }
        .unwrap();
        assert!(close(got, want, tol), "{case}: got {got:?}");
    }
}

#[test]
fn dlm_selects_a_different_control_for_each_intention() {
    let mut net = load("dlm.onnx", ControllerKind::Dlm);
    assert_eq!(net.kind(), ControllerKind::Dlm);
    let camera = frame(pattern(
        &serde_json::json!({"pattern": "gradient"}),
        SIZE_PX,
    ));
    let controls: Vec<Control> = Dlm::ALL
        .iter()
        .map(|&d| run(&mut net, Some(&camera), Some(&intention(d, None))).unwrap())
        .collect();
    for (i, a) in controls.iter().enumerate() {
        assert!(a.v_norm.abs() <= 1.0 && a.omega_norm.abs() <= 1.0, "{a:?}");
        for b in &controls[i + 1..] {
            assert!(!close(*a, [b.v_norm, b.omega_norm], 1e-3), "{controls:?}");
        }
    }
    // The same inputs again give the same output: no hidden state between cycles.
    let again = run(&mut net, Some(&camera), Some(&intention(Dlm::ALL[0], None))).unwrap();
    assert_eq!(again, controls[0]);
}

#[test]
fn png_jpeg_and_other_sizes_are_decoded_and_resized() {
    let mut net = load("none.onnx", ControllerKind::None);
    let gradient = pattern(&serde_json::json!({"pattern": "gradient"}), SIZE_PX);
    let raw = run(&mut net, Some(&frame(gradient.clone())), None).unwrap();
    let png = encoded(&gradient, ImageFormat::Png, ImageEncoding::Png);
    let from_png = run(&mut net, Some(&frame(png)), None).unwrap();
    assert!(
        close(from_png, [raw.v_norm, raw.omega_norm], 1e-6),
        "{from_png:?} vs {raw:?}"
    );
    let jpeg = encoded(&gradient, ImageFormat::Jpeg, ImageEncoding::Jpeg);
    let from_jpeg = run(&mut net, Some(&frame(jpeg)), None).unwrap();
    // Lossy but smooth: the output moves a little, not a lot.
    assert!(
        close(from_jpeg, [raw.v_norm, raw.omega_norm], 0.05),
        "{from_jpeg:?} vs {raw:?}"
    );

    let grey = serde_json::json!({"pattern": "constant", "rgb": [200, 30, 60]});
    let small = run(&mut net, Some(&frame(pattern(&grey, SIZE_PX))), None).unwrap();
    let big = run(&mut net, Some(&frame(pattern(&grey, 2 * SIZE_PX))), None).unwrap();
    assert!(
        close(big, [small.v_norm, small.omega_norm], 1e-5),
        "{big:?} vs {small:?}"
    );

    let mut lied = encoded(&gradient, ImageFormat::Png, ImageEncoding::Png);
    lied.width_px = 100;
    let err = run(&mut net, Some(&frame(lied)), None).unwrap_err();
    assert!(
        matches!(&err, ControllerError::BadInput { input: "camera", reason, .. } if reason.contains("declared 100x224")),
        "{err}"
    );
}

#[test]
fn missing_inputs_are_named() {
    let mut none = load("none.onnx", ControllerKind::None);
    let err = run(&mut none, None, None).unwrap_err();
    assert!(
        matches!(
            err,
            ControllerError::MissingInput {
                input: "camera",
                ..
            }
        ),
        "{err}"
    );
    let camera = frame(pattern(
        &serde_json::json!({"pattern": "gradient"}),
        SIZE_PX,
    ));
    let mut dlm = load("dlm.onnx", ControllerKind::Dlm);
    let err = run(&mut dlm, Some(&camera), None).unwrap_err();
    assert!(
        matches!(
            err,
            ControllerError::MissingInput {
                input: "intention",
                ..
            }
        ),
        "{err}"
    );
    let mut lpe = load("lpe.onnx", ControllerKind::Lpe);
    let err = run(
        &mut lpe,
        Some(&camera),
        Some(&intention(Dlm::GoForward, None)),
    )
    .unwrap_err();
    assert!(
        matches!(
            err,
            ControllerError::MissingInput {
                input: "intention.lpe",
                ..
            }
        ),
        "{err}"
    );
    assert!(err.to_string().contains("intention.lpe"), "{err}");
}

fn load_err(file: &str, expectation: &ModelExpectation) -> IntentionNetError {
    IntentionNet::load(
        &fixtures().join(file),
        expectation,
        &IntentionNetOptions::default(),
    )
    .unwrap_err()
}

#[test]
fn card_and_configuration_mismatches_are_refused_by_field() {
    let err = load_err("dlm.onnx", &expect(ControllerKind::Lpe));
    assert!(
        matches!(&err, IntentionNetError::Mismatch { source, .. } if source.field == "controller"),
        "{err}"
    );
    let msg = err.to_string();
    assert!(
        msg.contains("dlm.onnx") && msg.contains("kind = dlm") && msg.contains("lpe"),
        "{msg}"
    );

    let small = ModelExpectation {
        image_size_px: Some([112, 112]),
        ..expect(ControllerKind::Dlm)
    };
    let msg = load_err("dlm.onnx", &small).to_string();
    assert!(
        msg.contains("image size") && msg.contains("224x224") && msg.contains("112x112"),
        "{msg}"
    );

    let faster = ModelExpectation {
        limits: Limits {
            max_speed_mps: 1.0,
            ..Limits::default()
        },
        ..expect(ControllerKind::None)
    };
    let msg = load_err("none.onnx", &faster).to_string();
    assert!(
        msg.contains("limits.max_speed_mps") && msg.contains("0.7"),
        "{msg}"
    );

    let mut other_rendering: LpeRendering = load("lpe.onnx", ControllerKind::Lpe)
        .card()
        .lpe_rendering
        .clone()
        .unwrap();
    other_rendering.metres_per_px = 0.1;
    let msg = load_err(
        "lpe.onnx",
        &ModelExpectation {
            lpe_rendering: Some(other_rendering),
            ..expect(ControllerKind::Lpe)
        },
    )
    .to_string();
    assert!(
        msg.contains("lpe rendering") && msg.contains("0.1"),
        "{msg}"
    );

    // The card of dlm_bad_card.onnx claims 112x112 but its graph takes 224x224.
    let err = load_err("dlm_bad_card.onnx", &expect(ControllerKind::Dlm));
    assert!(matches!(err, IntentionNetError::Contract { .. }), "{err}");
    assert!(err.to_string().contains("`camera` has shape"), "{err}");

    let err = load_err("no_such_model.onnx", &expect(ControllerKind::Dlm));
    assert!(
        matches!(&err, IntentionNetError::Read { path, .. } if path.ends_with("no_such_model.onnx")),
        "{err}"
    );
    let as_controller_error = ControllerError::from(err);
    assert!(matches!(as_controller_error, ControllerError::Model { .. }));
}

#[test]
fn loads_from_the_agent_configuration() {
    let model = fixtures().join("lpe.onnx");
    let text = format!(
        "controller = \"lpe\"\nmodel = {:?}\n",
        model.display().to_string()
    );
    let config = AgentConfig::from_toml(&text).unwrap();
    let net =
        IntentionNet::from_config(&config, &IntentionNetOptions { intra_threads: 2 }).unwrap();
    assert_eq!(net.kind(), ControllerKind::Lpe);
    assert_eq!(net.card().kind, ModelKind::Lpe);
    assert_eq!(net.card().dataset_id, "fixture-untrained");
    assert_eq!(
        net.card().lpe_rendering.as_ref().map(|r| r.size_px),
        Some(224)
    );

    let dwa = AgentConfig::default();
    let err = IntentionNet::from_config(&dwa, &IntentionNetOptions::default()).unwrap_err();
    assert!(
        matches!(
            err,
            IntentionNetError::NotANetwork(ControllerKind::DynamicWindow)
        ),
        "{err}"
    );
}

#[test]
fn library_discovery_says_what_to_do() {
    let empty = tempfile::tempdir().unwrap();
    let err = runtime::find_library(None, &[empty.path().to_path_buf()]).unwrap_err();
    assert!(matches!(err, RuntimeError::NotFound { .. }));
    let msg = err.to_string();
    assert!(
        msg.contains("bash scripts/setup.sh") && msg.contains("ORT_DYLIB_PATH"),
        "{msg}"
    );
    assert!(msg.contains(&empty.path().display().to_string()), "{msg}");
    // An empty ORT_DYLIB_PATH counts as unset.
    let err = runtime::find_library(Some("".into()), &[empty.path().to_path_buf()]).unwrap_err();
    assert!(matches!(err, RuntimeError::NotFound { .. }));

    let missing = empty.path().join("libonnxruntime.so");
    let err = runtime::find_library(Some(missing.clone().into()), &[]).unwrap_err();
    assert!(matches!(err, RuntimeError::EnvPathMissing { .. }), "{err}");
    assert!(
        err.to_string().contains(&missing.display().to_string()),
        "{err}"
    );

    // The setup script's layout is found, and an explicit path wins over it.
    let capi = empty
        .path()
        .join(".venv/lib/python3.11/site-packages/onnxruntime/capi");
    std::fs::create_dir_all(&capi).unwrap();
    std::fs::write(capi.join("libonnxruntime_providers_shared.so"), b"").unwrap();
    std::fs::write(capi.join("libonnxruntime.so.1.31.1"), b"").unwrap();
    let found = runtime::find_library(
        None,
        &[empty.path().join("nothing"), empty.path().to_path_buf()],
    )
    .unwrap();
    assert_eq!(found, capi.join("libonnxruntime.so.1.31.1"));
    let explicit = empty.path().join("custom.so");
    std::fs::write(&explicit, b"").unwrap();
    let found = runtime::find_library(Some(explicit.clone().into()), &[empty.path().to_path_buf()])
        .unwrap();
    assert_eq!(found, explicit);
}

#[test]
fn the_process_loaded_the_setup_library() {
    let _net = load("none.onnx", ControllerKind::None);
    let path = runtime::loaded_library().unwrap();
    let name = path.file_name().unwrap().to_string_lossy().to_string();
    assert!(
        name.starts_with("libonnxruntime.so") || name.contains("onnxruntime"),
        "{name}"
    );
}
