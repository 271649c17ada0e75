//! Time per control step of the intention-net controllers on ONNX Runtime (the fixture models
//! of models/fixtures, 224x224 camera, and the shipped trained models of models/, which resize
//! the 224 px frame to their card's size), with 1 and 2 intra-op threads; preprocessing alone
//! (decode + normalize, no inference) is measured beside it so the inference share is visible.
//!
//! Needs the ONNX Runtime library from `bash scripts/setup.sh` (or ORT_DYLIB_PATH).
//! Run: `cargo bench -p robot-agent --bench intention_net`

#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::hint::black_box;
use std::io::Cursor;
use std::path::Path;
use std::time::Duration;

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use image::{ImageFormat, RgbImage};
use protocol::{CameraFrame, Dlm, Header, Image, ImageEncoding, Intention, Pose2D};
use robot_agent::controllers::intention_net::preprocess;
use robot_agent::controllers::{
    ControlInput, Controller, IntentionNet, IntentionNetOptions, ModelExpectation,
};
use robot_agent::{ControllerKind, Limits};
use test_support::fixtures;

const SIZE_PX: u32 = 224;

fn gradient() -> Image {
    let mut data = Vec::new();
    for y in 0..SIZE_PX {
        for x in 0..SIZE_PX {
            data.extend_from_slice(&[x as u8, y as u8, ((x + y) / 2) as u8]);
        }
    }
    Image::new(SIZE_PX, SIZE_PX, ImageEncoding::Rgb8, data).unwrap()
}

fn png(image: &Image) -> Image {
    let buf = RgbImage::from_raw(image.width_px, image.height_px, image.data.clone()).unwrap();
    let mut bytes = Cursor::new(Vec::new());
    buf.write_to(&mut bytes, ImageFormat::Png).unwrap();
    Image::new(SIZE_PX, SIZE_PX, ImageEncoding::Png, bytes.into_inner()).unwrap()
}

fn intention(lpe: Option<Image>) -> Intention {
    Intention {
        header: Header::new(1, 0),
        answers_pose_seq: 1,
        ..fixtures::intention_for_net(Dlm::GoForward, lpe)
    }
}

fn load(dir: &str, file: &str, kind: ControllerKind, threads: usize) -> IntentionNet {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../models")
        .join(dir)
        .join(file);
    let expect = ModelExpectation::new(kind, Limits::default()).unwrap();
    IntentionNet::load(
        &path,
        &expect,
        &IntentionNetOptions {
            intra_threads: threads,
        },
    )
    .unwrap_or_else(|e| panic!("{e}"))
}

fn bench(c: &mut Criterion) {
    let limits = Limits::default();
    let raw = CameraFrame {
        header: Header::new(1, 0),
        image: gradient(),
    };
    let encoded = CameraFrame {
        header: Header::new(1, 0),
        image: png(&raw.image),
    };
    let dlm_intention = intention(None);
    let lpe_intention = intention(Some(gradient()));
    let input = |camera, intention| ControlInput {
        pose: Pose2D::default(),
        v_mps: 0.0,
        omega_radps: 0.0,
        scan: None,
        camera: Some(camera),
        intention: Some(intention),
        limits: &limits,
        dt_s: 0.1,
    };

    let mut group = c.benchmark_group("intention-net step");
    group
        .sample_size(40)
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(3));
    for threads in [1, 2] {
        for (name, dir, file, kind, camera, intention) in [
            (
                "dlm rgb8",
                "fixtures",
                "dlm.onnx",
                ControllerKind::Dlm,
                &raw,
                &dlm_intention,
            ),
            (
                "dlm png",
                "fixtures",
                "dlm.onnx",
                ControllerKind::Dlm,
                &encoded,
                &dlm_intention,
            ),
            (
                "lpe rgb8",
                "fixtures",
                "lpe.onnx",
                ControllerKind::Lpe,
                &raw,
                &lpe_intention,
            ),
            (
                "shipped dlm rgb8",
                ".",
                "dlm.onnx",
                ControllerKind::Dlm,
                &raw,
                &dlm_intention,
            ),
            (
                "shipped lpe rgb8",
                ".",
                "lpe.onnx",
                ControllerKind::Lpe,
                &raw,
                &lpe_intention,
            ),
        ] {
            let mut net = load(dir, file, kind, threads);
            let step = input(camera, intention);
            group.bench_function(
                BenchmarkId::new(name, format!("{threads} thread(s)")),
                |b| {
                    b.iter(|| black_box(net.control(black_box(&step)).unwrap()));
                },
            );
        }
    }
    let card = load("fixtures", "dlm.onnx", ControllerKind::Dlm, 1)
        .card()
        .clone();
    let mut buf = vec![0.0_f32; 3 * (SIZE_PX * SIZE_PX) as usize];
    for (name, frame) in [("rgb8", &raw), ("png", &encoded)] {
        group.bench_function(BenchmarkId::new("preprocess only", name), |b| {
            b.iter(|| {
                preprocess::image_to_chw(
                    black_box(&frame.image),
                    card.image_width_px,
                    card.image_height_px,
                    &card.normalization,
                    &mut buf,
                )
                .unwrap();
                black_box(buf[0])
            });
        });
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
