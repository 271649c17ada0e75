//! Criterion benchmark: column ray-caster vs the per-pixel reference, and one lock-step step.

// Benchmark set-up: a failed unwrap aborts the benchmark, which is what we want.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use criterion::{criterion_group, criterion_main, Criterion};
use protocol::{Pose2D, RobotId};
use sim::camera::{render, render_per_pixel};
use sim::{Command, SimConfig, World};

fn world() -> World {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenarios/task_b.yaml");
    let mut w = World::from_scenario_file(&path, SimConfig::default()).unwrap();
    let start = w.scenario.start.to_pose();
    w.add_robot(RobotId::new("robot_1").unwrap(), start)
        .unwrap();
    w
}

fn bench(c: &mut Criterion) {
    let w = world();
    let model = w.camera_model().clone();
    let pose = Pose2D::new(2.5, 10.0, 0.0);
    let mut buf = Vec::new();
    c.bench_function("camera_224_column", |b| {
        b.iter(|| render(&w, &model, pose, Some(0), &mut buf))
    });
    let mut g = c.benchmark_group("reference");
    g.sample_size(10);
    g.bench_function("camera_224_per_pixel", |b| {
        b.iter(|| render_per_pixel(&w, &model, pose, Some(0), &mut buf))
    });
    g.finish();
    let mut ws = w.clone();
    let cmd = [Command {
        v_mps: 0.3,
        omega_radps: 0.2,
    }];
    c.bench_function("lockstep_step_scan_odom", |b| {
        b.iter(|| ws.step(&cmd, 0.01))
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
