//! LPE images: pixel-exact golden images (regenerate with `UPDATE_GOLDEN=1`) plus properties
//! that would catch a wrong image even if a golden file were regenerated from a broken renderer.

// Integration tests: helpers outside #[test] functions panic on failure by design.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::PathBuf;

use map_core::{OccupancyGrid, FREE, OCCUPIED, UNKNOWN};
use planning::intention::{render_lpe, LpeImage, LpeParams};
use protocol::Pose2D;

const RED: [u8; 3] = [255, 0, 0];
const BLUE: [u8; 3] = [0, 0, 255];

fn golden_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests")
        .join("golden")
}

/// Compares with the committed golden PNG pixel by pixel, or rewrites it with UPDATE_GOLDEN=1.
fn assert_golden(name: &str, img: &LpeImage) {
    let path = golden_dir().join(name);
    if std::env::var_os("UPDATE_GOLDEN").is_some_and(|v| v == "1") {
        std::fs::create_dir_all(golden_dir()).unwrap();
        img.save_png(&path).unwrap();
        return;
    }
    let golden = image::open(&path)
        .unwrap_or_else(|e| {
            panic!(
                "{}: {e} (run with UPDATE_GOLDEN=1 to create it)",
                path.display()
            )
        })
        .to_rgb8();
    assert_eq!(golden.dimensions(), img.image.dimensions());
    let diff = golden
        .pixels()
        .zip(img.image.pixels())
        .filter(|(a, b)| a != b)
        .count();
    assert_eq!(
        diff, 0,
        "{name}: {diff} pixels differ from the golden image"
    );
}

/// Straight segment of poses from `a` to `b`, 0.05 m apart.
fn line(a: (f64, f64), b: (f64, f64)) -> Vec<Pose2D> {
    let len = (b.0 - a.0).hypot(b.1 - a.1);
    let yaw = (b.1 - a.1).atan2(b.0 - a.0);
    let n = (len / 0.05).round() as usize;
    (0..=n)
        .map(|i| {
            let t = i as f64 / n as f64;
            Pose2D::new(a.0 + (b.0 - a.0) * t, a.1 + (b.1 - a.1) * t, yaw)
        })
        .collect()
}

/// A 20 m x 10 m free room with a wall along y = 6 m, unknown beyond y = 8 m.
fn corridor() -> OccupancyGrid {
    let mut g = OccupancyGrid::filled(200, 100, 0.1, Pose2D::new(0.0, 0.0, 0.0), FREE).unwrap();
    for x in 0..200 {
        for y in 60..62 {
            g.set(x, y, OCCUPIED);
        }
        for y in 80..100 {
            g.set(x, y, UNKNOWN);
        }
    }
    g
}

fn px(img: &LpeImage, u: u32, v: u32) -> [u8; 3] {
    img.image.get_pixel(u, v).0
}

#[test]
fn heading_up_path_colours_and_wall_side() {
    let params = LpeParams::default();
    let g = corridor();
    // Robot at (10, 4) facing +x; the wall at y = 6 is 2 m to its left.
    let robot = Pose2D::new(10.0, 4.0, 0.0);
    let travelled = line((6.0, 4.0), (10.0, 4.0));
    let ahead = line((10.0, 4.0), (16.0, 4.0));
    let img = render_lpe(&g, robot, &travelled, &ahead, &params).unwrap();
    assert_eq!(img.image.dimensions(), (224, 224));
    let [ru, rv] = params.robot_px;
    // Ahead is up (smaller rows) in blue, travelled is down in red, both in the robot's column.
    assert_eq!(px(&img, ru, rv - 20), BLUE);
    assert_eq!(px(&img, ru, rv + 20), RED);
    // The robot pixel is where they meet: the path ahead is drawn last.
    assert_eq!(px(&img, ru, rv), BLUE);
    let blue_above = (0..rv).filter(|&v| px(&img, ru, v) == BLUE).count();
    let blue_below = (rv + 2..224).filter(|&v| px(&img, ru, v) == BLUE).count();
    assert!(
        blue_above > 100 && blue_below == 0,
        "{blue_above} {blue_below}"
    );
    // The wall 2 m to the left is 40 px left of the robot column; unknown beyond it.
    assert_eq!(px(&img, ru - 41, rv), params.occupied_rgb);
    assert_eq!(px(&img, ru - 30, rv), params.free_rgb);
    assert_eq!(px(&img, ru - 90, rv), params.unknown_rgb);
    // Nothing occupied on the right half.
    let right_occupied = (ru + 2..224)
        .flat_map(|u| (0..224).map(move |v| (u, v)))
        .filter(|&(u, v)| px(&img, u, v) == params.occupied_rgb)
        .count();
    assert_eq!(right_occupied, 0);
    assert_golden("lpe_corridor.png", &img);
}

#[test]
fn rotating_the_robot_rotates_the_image() {
    let params = LpeParams::default();
    let g = corridor();
    // Facing -x the wall (y = 6) is on the robot's right.
    let robot = Pose2D::new(10.0, 4.0, std::f64::consts::PI);
    let img = render_lpe(&g, robot, &[], &line((10.0, 4.0), (5.0, 4.0)), &params).unwrap();
    let [ru, rv] = params.robot_px;
    assert_eq!(px(&img, ru + 41, rv), params.occupied_rgb);
    assert_eq!(px(&img, ru - 41, rv), params.free_rgb);
    assert_eq!(px(&img, ru, rv - 20), BLUE);
    // A path turning left ahead of the robot bends to the image's left.
    let robot = Pose2D::new(10.0, 2.0, 0.0);
    let mut ahead = line((10.0, 2.0), (12.0, 2.0));
    ahead.extend(line((12.0, 2.0), (12.0, 5.0)));
    let img = render_lpe(&g, robot, &[], &ahead, &params).unwrap();
    // 2 m ahead, 2 m left: (ru - 40, rv - 40) is blue; mirrored right is not.
    assert_eq!(px(&img, ru - 40, rv - 40), BLUE);
    assert_ne!(px(&img, ru + 40, rv - 40), BLUE);
    assert_golden("lpe_left_turn.png", &img);
}

#[test]
fn real_map_golden_image() {
    let grid = test_support::nav2_map("tb3_sandbox");
    let robot = Pose2D::new(-0.5, 0.5, 0.3);
    let travelled = line((-1.5, 0.2), (-0.5, 0.5));
    let ahead = line((-0.5, 0.5), (1.0, 1.0));
    let img = render_lpe(&grid, robot, &travelled, &ahead, &LpeParams::default()).unwrap();
    let png = img.to_png().unwrap();
    assert_eq!(&png[1..4], b"PNG");
    assert_golden("lpe_tb3_sandbox.png", &img);
}
