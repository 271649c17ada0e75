//! A floor-plan image as uploaded (PGM, PNG, BMP or JPEG bytes): the header cost estimate, the
//! decode under import limits, and the conversion to ROS cells in every mode.
#![no_main]

use std::path::Path;

use libfuzzer_sys::fuzz_target;
use map_core::ros::{decode_cost_bytes, decode_image, occupancy_from_image};
use map_core::{ImportLimits, Interpretation, MapMode};

/// Small enough that a valid image bomb stays far below libFuzzer's 2 GB memory limit.
const LIMITS: ImportLimits = ImportLimits {
    max_file_bytes: 1 << 20,
    max_side_px: 4096,
    max_pixels: 4 << 20,
};

fuzz_target!(|data: &[u8]| {
    let path = Path::new("fuzz.img");
    let cost = decode_cost_bytes(data, path);
    let Ok(img) = decode_image(data, path, &LIMITS) else {
        return;
    };
    // What decoded had a readable header, and the estimate covers its pixels.
    let pixels = u64::from(img.width()) * u64::from(img.height());
    let cost = cost.expect("a decodable image has a readable header");
    assert!(cost >= pixels, "cost {cost} below {pixels} pixels");
    for mode in [MapMode::Trinary, MapMode::Scale, MapMode::Raw] {
        for negate in [false, true] {
            let how = Interpretation {
                mode,
                negate,
                occupied_thresh: 0.65,
                free_thresh: 0.25,
            };
            let cells = occupancy_from_image(&img, &how);
            assert_eq!(cells.len() as u64, pixels);
            assert!(cells.iter().all(|&c| c <= 100 || c == 255));
        }
    }
});
