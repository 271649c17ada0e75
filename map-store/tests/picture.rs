//! Importing a generated floor-plan picture: black walls with anti-aliased grey edges, light
//! hatching and grey text inside rooms. Only the walls may become occupied.

// Helpers outside #[test] functions are test code too.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::Path;

use image::{GrayImage, Luma};
use map_store::{import_picture, CellClass, ImportLimits, MapMode, OccupancyGrid, PictureOptions};

const W: u32 = 300;
const H: u32 = 200;

#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum Ink {
    Paper,
    Wall,
    /// Anti-aliasing ring right next to a wall: mid grey, in the band between the thresholds.
    EdgeMid,
    /// Outer anti-aliasing ring: light grey, below free_thresh.
    EdgeLight,
    Hatch,
    Text,
}

fn ink_value(ink: Ink) -> u8 {
    match ink {
        Ink::Paper => 255,
        Ink::Wall => 0,
        Ink::EdgeMid => 150,
        Ink::EdgeLight => 210,
        Ink::Hatch => 225,
        Ink::Text => 200,
    }
}

/// A two-room plan: outer walls, one inner wall with a door, hatching in the left room and a
/// blocky "LAB" label in the right one.
fn plan() -> Vec<Ink> {
    let mut ink = vec![Ink::Paper; (W * H) as usize];
    let is_wall = |x: u32, y: u32| {
        let outer = x < 6 || y < 6 || x >= W - 6 || y >= H - 6;
        let inner = (147..153).contains(&x) && !(80..120).contains(&y);
        outer || inner
    };
    for y in 0..H {
        for x in 0..W {
            let i = (y * W + x) as usize;
            if is_wall(x, y) {
                ink[i] = Ink::Wall;
                continue;
            }
            // Chebyshev distance to a wall pixel, up to 2.
            let near = |r: i64| {
                (-r..=r).any(|dy| {
                    (-r..=r).any(|dx| {
                        let (nx, ny) = (i64::from(x) + dx, i64::from(y) + dy);
                        nx >= 0
                            && ny >= 0
                            && nx < i64::from(W)
                            && ny < i64::from(H)
                            && is_wall(nx as u32, ny as u32)
                    })
                })
            };
            if near(1) {
                ink[i] = Ink::EdgeMid;
            } else if near(2) {
                ink[i] = Ink::EdgeLight;
            } else if x > 20 && x < 130 && y > 20 && y < 180 && (x + y) % 9 == 0 {
                ink[i] = Ink::Hatch;
            } else if (180..260).contains(&x) && (90..110).contains(&y) {
                // L, A, B as filled blocks with gaps: 3 px strokes.
                let gx = (x - 180) % 28;
                let stroke = gx < 3 || (90..93).contains(&y) || (107..110).contains(&y);
                if stroke && gx < 22 {
                    ink[i] = Ink::Text;
                }
            }
        }
    }
    ink
}

fn write_plan(dir: &Path, ext: &str) -> std::path::PathBuf {
    let ink = plan();
    let img = GrayImage::from_fn(W, H, |x, y| Luma([ink_value(ink[(y * W + x) as usize])]));
    let path = dir.join(format!("plan.{ext}"));
    if ext == "jpg" {
        let rgb = image::DynamicImage::ImageLuma8(img).to_rgb8();
        let mut f = std::fs::File::create(&path).unwrap();
        image::codecs::jpeg::JpegEncoder::new_with_quality(&mut f, 95)
            .encode_image(&rgb)
            .unwrap();
    } else {
        img.save(&path).unwrap();
    }
    path
}

/// Ink at grid cell (cx, cy): image row 0 is the top, grid row 0 the bottom.
fn ink_at(ink: &[Ink], cx: u32, cy: u32) -> Ink {
    ink[((H - 1 - cy) * W + cx) as usize]
}

fn classes(g: &OccupancyGrid) -> impl Iterator<Item = (u32, u32, CellClass)> + '_ {
    (0..H).flat_map(move |cy| (0..W).map(move |cx| (cx, cy, g.class_at(cx.into(), cy.into()))))
}

#[test]
fn png_plan_only_walls_are_occupied() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_plan(dir.path(), "png");
    let mut opts = PictureOptions::new(0.02);
    opts.origin = protocol::Pose2D::new(1.0, -2.0, 0.0);
    let g = import_picture(&path, &opts, &ImportLimits::default()).unwrap();
    assert_eq!((g.width_cells(), g.height_cells()), (W, H));
    assert_eq!(g.origin(), opts.origin);
    let ink = plan();
    let mut seen_hatch_or_text = 0;
    for (cx, cy, class) in classes(&g) {
        let expected = match ink_at(&ink, cx, cy) {
            Ink::Wall => CellClass::Occupied,
            // The band between the thresholds is unknown for pictures (trinary), never a wall.
            Ink::EdgeMid => CellClass::Unknown,
            Ink::Hatch | Ink::Text => {
                seen_hatch_or_text += 1;
                CellClass::Free
            }
            Ink::Paper | Ink::EdgeLight => CellClass::Free,
        };
        assert_eq!(
            class,
            expected,
            "cell ({cx}, {cy}) ink {:?}",
            ink_at(&ink, cx, cy)
        );
    }
    assert!(
        seen_hatch_or_text > 500,
        "the plan must contain hatching and text"
    );
}

#[test]
fn scale_band_keeps_grey_as_percentages() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_plan(dir.path(), "png");
    let mut opts = PictureOptions::new(0.02);
    opts.band = MapMode::Scale;
    let g = import_picture(&path, &opts, &ImportLimits::default()).unwrap();
    let ink = plan();
    let (cx, cy) = (0..H)
        .flat_map(|cy| (0..W).map(move |cx| (cx, cy)))
        .find(|&(cx, cy)| ink_at(&ink, cx, cy) == Ink::EdgeMid)
        .unwrap();
    // occ = 1 - 150/255 = 0.412; (0.412 - 0.25) / (0.65 - 0.25) = 40.4 % -> 40.
    assert_eq!(g.get(cx.into(), cy.into()), Some(40));
    assert_eq!(g.class_at(cx.into(), cy.into()), CellClass::Free);
}

#[test]
fn jpeg_plan_walls_survive_compression_and_marks_stay_free() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_plan(dir.path(), "jpg");
    let g = import_picture(&path, &PictureOptions::new(0.02), &ImportLimits::default()).unwrap();
    let ink = plan();
    for (cx, cy, class) in classes(&g) {
        match ink_at(&ink, cx, cy) {
            // JPEG ringing may only shift classes within the anti-aliased edge.
            Ink::Wall => assert_eq!(class, CellClass::Occupied, "({cx}, {cy})"),
            Ink::EdgeMid | Ink::EdgeLight => assert_ne!(class, CellClass::Occupied, "({cx}, {cy})"),
            Ink::Hatch | Ink::Text | Ink::Paper => {
                assert_eq!(class, CellClass::Free, "({cx}, {cy})");
            }
        }
    }
}

#[test]
fn picture_options_are_checked_before_reading() {
    let limits = ImportLimits::default();
    let missing = Path::new("/nonexistent/plan.png");
    for (field, res) in [
        ("resolution", 0.0),
        ("resolution", -0.5),
        ("resolution", f64::NAN),
    ] {
        let e = import_picture(missing, &PictureOptions::new(res), &limits).unwrap_err();
        assert!(e.to_string().contains(field), "{e}");
    }
    let mut o = PictureOptions::new(0.05);
    o.free_thresh = 0.8;
    let e = import_picture(missing, &o, &limits)
        .unwrap_err()
        .to_string();
    assert!(e.contains("free_thresh") && e.contains("0.8"), "{e}");
    let mut o = PictureOptions::new(0.05);
    o.band = MapMode::Raw;
    assert!(import_picture(missing, &o, &limits)
        .unwrap_err()
        .to_string()
        .contains("mode"));
    let e = import_picture(missing, &PictureOptions::new(0.05), &limits)
        .unwrap_err()
        .to_string();
    assert!(e.contains("/nonexistent/plan.png"), "{e}");
}
