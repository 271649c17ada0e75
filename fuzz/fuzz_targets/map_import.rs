//! A ROS `map_server` upload: YAML text and the image it names, through the same loader the
//! service and the CLI use (files in a temporary folder, as the upload stages them).
//!
//! Input: a little-endian `u16` YAML length, the YAML, then the image bytes.
#![no_main]

use libfuzzer_sys::fuzz_target;
use map_core::{load_ros_map, ImportLimits};

const LIMITS: ImportLimits = ImportLimits {
    max_file_bytes: 1 << 20,
    max_side_px: 4096,
    max_pixels: 4 << 20,
};

fuzz_target!(|data: &[u8]| {
    let Some((len, rest)) = data.split_first_chunk::<2>() else {
        return;
    };
    let len = usize::from(u16::from_le_bytes(*len)).min(rest.len());
    let (yaml, image) = rest.split_at(len);
    let Ok(dir) = tempfile::tempdir() else {
        return;
    };
    let yaml_path = dir.path().join("map.yaml");
    // The image is always where a YAML that says `image: map.pgm` looks.
    if std::fs::write(&yaml_path, yaml).is_err()
        || std::fs::write(dir.path().join("map.pgm"), image).is_err()
    {
        return;
    }
    if let Ok(map) = load_ros_map(&yaml_path, &LIMITS) {
        let g = &map.grid;
        assert_eq!(
            g.cells().len() as u64,
            u64::from(g.width_cells()) * u64::from(g.height_cells())
        );
        assert!(g.resolution_m().is_finite() && g.resolution_m() > 0.0);
    }
});
