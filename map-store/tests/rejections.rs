//! Bad input: one test per rejection. Each error names the field (or file) and the value, and
//! nothing reaches the store.

// Helpers outside #[test] functions are test code too.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::{Path, PathBuf};

use map_store::import::import_into;
use map_store::{ImportLimits, MapError, MapStore};
use protocol::MapName;

fn nav2(file: &str) -> PathBuf {
    test_support::nav2_maps_dir().join(file)
}

/// A YAML next to a copy of testmap.pgm, with `body` as its contents.
struct Case {
    dir: tempfile::TempDir,
}

impl Case {
    fn new() -> Self {
        let dir = tempfile::tempdir().unwrap();
        std::fs::copy(nav2("testmap.pgm"), dir.path().join("testmap.pgm")).unwrap();
        Self { dir }
    }

    fn yaml(&self, body: &str) -> PathBuf {
        let p = self.dir.path().join("map.yaml");
        std::fs::write(&p, body).unwrap();
        p
    }

    /// Imports `path` into a fresh store and returns the error; checks nothing was stored.
    fn reject(&self, path: &Path, limits: &ImportLimits) -> MapError {
        let store = MapStore::open(&self.dir.path().join("db")).unwrap();
        let name = MapName::new("bad").unwrap();
        let e = import_into(&store, &name, path, None, limits).unwrap_err();
        assert!(
            store.list().unwrap().is_empty(),
            "a failed import stored something"
        );
        e
    }
}

const GOOD: &str = "image: testmap.pgm\nresolution: 0.1\norigin: [2.0, 3.0, 1.0]\n\
                    occupied_thresh: 0.65\nfree_thresh: 0.196\nnegate: 0\nmode: trinary\n";

fn with(key: &str, value: &str) -> String {
    GOOD.lines()
        .map(|l| {
            if l.starts_with(&format!("{key}:")) {
                format!("{key}: {value}")
            } else {
                l.to_string()
            }
        })
        .collect::<Vec<_>>()
        .join("\n")
}

fn assert_names(e: &MapError, parts: &[&str]) {
    let msg = e.to_string();
    for p in parts {
        assert!(msg.contains(p), "{msg:?} should mention {p:?}");
    }
}

#[test]
fn the_good_case_imports() {
    let c = Case::new();
    let store = MapStore::open(&c.dir.path().join("db")).unwrap();
    let path = c.yaml(GOOD);
    let meta = import_into(
        &store,
        &MapName::new("ok").unwrap(),
        &path,
        None,
        &ImportLimits::default(),
    )
    .unwrap();
    assert_eq!((meta.width_cells, meta.occupied_cells), (10, 29));
}

#[test]
fn missing_image() {
    let c = Case::new();
    let e = c.reject(
        &c.yaml(&with("image", "nowhere.pgm")),
        &ImportLimits::default(),
    );
    assert!(matches!(e, MapError::Io { .. }), "{e}");
    assert_names(&e, &["nowhere.pgm"]);
}

#[test]
fn missing_yaml() {
    let c = Case::new();
    let e = c.reject(&c.dir.path().join("absent.yaml"), &ImportLimits::default());
    assert_names(&e, &["absent.yaml"]);
}

#[test]
fn unreadable_image() {
    let c = Case::new();
    std::fs::write(
        c.dir.path().join("junk.png"),
        b"this is not an image at all",
    )
    .unwrap();
    let e = c.reject(
        &c.yaml(&with("image", "junk.png")),
        &ImportLimits::default(),
    );
    assert!(matches!(e, MapError::Image { .. }), "{e}");
    assert_names(&e, &["junk.png"]);
}

#[test]
fn unknown_mode() {
    let c = Case::new();
    let e = c.reject(&c.yaml(&with("mode", "fuzzy")), &ImportLimits::default());
    assert_names(&e, &["mode", "fuzzy"]);
}

#[test]
fn non_positive_resolution() {
    for bad in ["0", "-0.05"] {
        let c = Case::new();
        let e = c.reject(&c.yaml(&with("resolution", bad)), &ImportLimits::default());
        assert_names(&e, &["resolution", bad]);
    }
}

#[test]
fn non_finite_resolution() {
    for (bad, shown) in [(".nan", "NaN"), (".inf", "inf")] {
        let c = Case::new();
        let e = c.reject(&c.yaml(&with("resolution", bad)), &ImportLimits::default());
        assert_names(&e, &["resolution", shown]);
    }
}

#[test]
fn threshold_out_of_range() {
    let c = Case::new();
    let e = c.reject(
        &c.yaml(&with("occupied_thresh", "1.5")),
        &ImportLimits::default(),
    );
    assert_names(&e, &["occupied_thresh", "1.5"]);
    let e = c.reject(
        &c.yaml(&with("free_thresh", "-0.1")),
        &ImportLimits::default(),
    );
    assert_names(&e, &["free_thresh", "-0.1"]);
}

#[test]
fn thresholds_out_of_order() {
    let c = Case::new();
    let e = c.reject(
        &c.yaml(&with("free_thresh", "0.7")),
        &ImportLimits::default(),
    );
    assert_names(&e, &["free_thresh", "0.7", "occupied_thresh"]);
}

#[test]
fn wrong_length_origin() {
    let c = Case::new();
    let e = c.reject(
        &c.yaml(&with("origin", "[1.0, 2.0]")),
        &ImportLimits::default(),
    );
    assert_names(&e, &["origin", "3 elements", "got 2"]);
}

#[test]
fn image_file_over_size_limit() {
    let c = Case::new();
    let limits = ImportLimits {
        max_file_bytes: 50,
        ..ImportLimits::default()
    };
    let e = c.reject(&c.yaml(GOOD), &limits);
    assert!(
        matches!(
            e,
            MapError::TooLarge {
                field: "file_bytes",
                ..
            }
        ),
        "{e}"
    );
    assert_names(&e, &["file_bytes", "50"]);
}

#[test]
fn image_over_pixel_and_side_limits() {
    let c = Case::new();
    let limits = ImportLimits {
        max_pixels: 99,
        ..ImportLimits::default()
    };
    let e = c.reject(&c.yaml(GOOD), &limits);
    assert_names(&e, &["pixels", "100", "99"]);
    let limits = ImportLimits {
        max_side_px: 9,
        ..ImportLimits::default()
    };
    let e = c.reject(&c.yaml(GOOD), &limits);
    assert_names(&e, &["width_px", "10", "9"]);
}

fn crc32(bytes: &[u8]) -> u32 {
    let mut crc = 0xFFFF_FFFFu32;
    for &b in bytes {
        crc ^= u32::from(b);
        for _ in 0..8 {
            crc = if crc & 1 == 1 {
                (crc >> 1) ^ 0xEDB8_8320
            } else {
                crc >> 1
            };
        }
    }
    !crc
}

fn chunk(kind: &[u8; 4], data: &[u8]) -> Vec<u8> {
    let mut out = (data.len() as u32).to_be_bytes().to_vec();
    let mut body = kind.to_vec();
    body.extend_from_slice(data);
    out.extend_from_slice(&body);
    out.extend_from_slice(&crc32(&body).to_be_bytes());
    out
}

/// A valid PNG header claiming `w` x `h` 8-bit grey pixels, followed by a few bytes of a deflate
/// stream: what a decompression bomb looks like before it is inflated.
fn bomb_png(w: u32, h: u32) -> Vec<u8> {
    let mut png = b"\x89PNG\r\n\x1a\n".to_vec();
    let mut ihdr = w.to_be_bytes().to_vec();
    ihdr.extend_from_slice(&h.to_be_bytes());
    ihdr.extend_from_slice(&[8, 0, 0, 0, 0]);
    png.extend(chunk(b"IHDR", &ihdr));
    // zlib header + a stored-block start: never read, because the header is refused first.
    png.extend(chunk(b"IDAT", &[0x78, 0x9c, 0x63, 0x60, 0x00, 0x00]));
    png.extend(chunk(b"IEND", &[]));
    png
}

#[test]
fn decompression_bomb_is_refused_from_the_header() {
    let c = Case::new();
    let bomb = bomb_png(100_000, 100_000);
    assert!(
        bomb.len() < 100,
        "the bomb file itself is tiny: {} bytes",
        bomb.len()
    );
    std::fs::write(c.dir.path().join("bomb.png"), &bomb).unwrap();
    let yaml = c.yaml(&with("image", "bomb.png"));
    let e = c.reject(&yaml, &ImportLimits::default());
    assert!(
        matches!(
            e,
            MapError::TooLarge {
                field: "width_px",
                value: 100_000,
                ..
            }
        ),
        "{e}"
    );
    // With the side limit lifted, the pixel count (10^10) still refuses it before decoding.
    let limits = ImportLimits {
        max_side_px: u32::MAX,
        ..ImportLimits::default()
    };
    let e = c.reject(&yaml, &limits);
    assert!(
        matches!(
            e,
            MapError::TooLarge {
                field: "pixels",
                value: 10_000_000_000,
                ..
            }
        ),
        "{e}"
    );
    assert_names(&e, &["bomb.png", "10000000000"]);
}

#[test]
fn truncated_image() {
    let c = Case::new();
    let full = std::fs::read(nav2("depot.pgm")).unwrap();
    std::fs::write(c.dir.path().join("cut.pgm"), &full[..full.len() / 2]).unwrap();
    let e = c.reject(&c.yaml(&with("image", "cut.pgm")), &ImportLimits::default());
    assert!(matches!(e, MapError::Image { .. }), "{e}");
    assert_names(&e, &["cut.pgm"]);
}

#[test]
fn truncated_yaml() {
    let c = Case::new();
    // Cut after the origin line: the thresholds are missing.
    let cut: String = GOOD.lines().take(3).collect::<Vec<_>>().join("\n");
    let e = c.reject(&c.yaml(&cut), &ImportLimits::default());
    assert!(
        matches!(
            e,
            MapError::MissingField {
                field: "occupied_thresh",
                ..
            }
        ),
        "{e}"
    );
    assert_names(&e, &["occupied_thresh", "map.yaml"]);
}

#[test]
fn yaml_that_is_not_yaml() {
    let c = Case::new();
    let e = c.reject(&c.yaml("image: [unclosed\n"), &ImportLimits::default());
    assert!(matches!(e, MapError::Yaml { .. }), "{e}");
}
