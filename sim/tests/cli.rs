//! The `sim` command line on real files: render, view, schema, and bad input.

// Test code: a failed unwrap is a failed test.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use clap::Parser;
use sim::cli::{run, Cli};

fn scenario(name: &str) -> String {
    format!("{}/scenarios/{name}.yaml", env!("CARGO_MANIFEST_DIR"))
}

fn cli(args: &[&str]) -> anyhow::Result<()> {
    run(Cli::try_parse_from(
        std::iter::once("sim").chain(args.iter().copied()),
    )?)
}

#[test]
fn render_writes_a_camera_png_and_a_scan() {
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("camera.png");
    let scan = dir.path().join("scan.json");
    cli(&[
        "render",
        "--scenario",
        &scenario("task_c"),
        "--pose",
        "3,3,1.57",
        "--out",
        png.to_str().unwrap(),
        "--scan-out",
        scan.to_str().unwrap(),
    ])
    .unwrap();
    let img = image::open(&png).unwrap().to_rgb8();
    assert_eq!(img.dimensions(), (224, 224));
    let scan: protocol::LaserScan =
        serde_json::from_str(&std::fs::read_to_string(&scan).unwrap()).unwrap();
    assert_eq!(scan.ranges_m.len(), 181);
    scan.validate().unwrap();
}

#[test]
fn view_draws_the_plan_extras_start_and_goals() {
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("world.png");
    cli(&[
        "view",
        "--scenario",
        &scenario("task_a"),
        "--out",
        png.to_str().unwrap(),
    ])
    .unwrap();
    let img = image::open(&png).unwrap().to_rgb8();
    // junctions is 26 m x 20 m at 0.05 m per cell.
    assert_eq!(img.dimensions(), (520, 400));
    let has = |c: [u8; 3]| img.pixels().any(|p| p.0 == c);
    assert!(has([0, 200, 220]), "glass (cyan) missing");
    assert!(has([150, 95, 45]), "furniture missing");
    assert!(has([0, 170, 0]), "start missing");
}

#[test]
fn bad_input_is_refused_with_the_field_named() {
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("x.png");
    let e = cli(&[
        "render",
        "--scenario",
        &scenario("task_a"),
        "--pose",
        "3,abc,0",
        "--out",
        png.to_str().unwrap(),
    ])
    .unwrap_err()
    .to_string();
    assert!(e.contains("y") && e.contains("abc"), "{e}");
    // A pose inside a wall cannot hold a robot.
    let e = cli(&[
        "render",
        "--scenario",
        &scenario("task_a"),
        "--pose",
        "0.5,0.5,0",
        "--out",
        png.to_str().unwrap(),
    ])
    .unwrap_err()
    .to_string();
    assert!(e.contains("wall"), "{e}");
    assert!(!png.exists(), "nothing may be written on bad input");
    let e = cli(&[
        "view",
        "--scenario",
        "/nonexistent/s.yaml",
        "--out",
        png.to_str().unwrap(),
    ])
    .unwrap_err()
    .to_string();
    assert!(e.contains("/nonexistent/s.yaml"), "{e}");
}
