//! Import of ROS `map_server` maps (YAML + PGM/PNG/BMP/JPEG) with Nav2's exact semantics.
//!
//! Nav2 (`nav2_map_server/src/map_io.cpp`) reads a pixel as follows: `shade` is the mean of the
//! R, G, B channels scaled to [0, 1] (in trinary mode an alpha channel joins the mean as
//! `1 - alpha`); `occ = negate ? shade : 1 - shade`. Trinary: occupied (100) when
//! `occ > occupied_thresh`, free (0) when `occ < free_thresh`, unknown otherwise. Scale: unknown
//! when the pixel is not opaque, then as trinary but in-between values become
//! `rint((occ - free) / (occupied - free) * 100)`. Raw: `round(shade * 255)` when it lies in
//! 0..=100, unknown otherwise. Image row 0 is the top of the map and `origin` is the pose of the
//! lower-left pixel. The comparisons are strict as in Nav2's code (the shared maps README writes
//! `>=`/`<=`; the two differ only when a threshold times the pixel range is an integer).

use std::path::{Path, PathBuf};

use image::{DynamicImage, GenericImageView};
use protocol::Pose2D;
use serde_yaml::Value;

use crate::error::MapError;
use crate::grid::{OccupancyGrid, FREE, OCCUPIED, UNKNOWN};

/// How pixel brightness maps to occupancy (ROS `mode`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MapMode {
    Trinary,
    Scale,
    Raw,
}

impl MapMode {
    #[must_use]
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Trinary => "trinary",
            Self::Scale => "scale",
            Self::Raw => "raw",
        }
    }
}

impl std::str::FromStr for MapMode {
    type Err = MapError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        // Nav2 lower-cases the mode before matching.
        match s.to_ascii_lowercase().as_str() {
            "trinary" => Ok(Self::Trinary),
            "scale" => Ok(Self::Scale),
            "raw" => Ok(Self::Raw),
            _ => Err(MapError::invalid(
                "mode",
                s,
                "expected trinary, scale or raw",
            )),
        }
    }
}

/// The pixel interpretation of a map image: everything of the YAML but the geometry.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Interpretation {
    pub mode: MapMode,
    pub negate: bool,
    pub occupied_thresh: f64,
    pub free_thresh: f64,
}

impl Interpretation {
    /// Checks the thresholds: both in [0, 1] and `free_thresh < occupied_thresh`.
    ///
    /// # Errors
    /// [`MapError::Invalid`] naming the threshold and its value.
    pub fn validate(&self) -> Result<(), MapError> {
        for (field, v) in [
            ("occupied_thresh", self.occupied_thresh),
            ("free_thresh", self.free_thresh),
        ] {
            if !v.is_finite() || !(0.0..=1.0).contains(&v) {
                return Err(MapError::invalid(field, v, "must lie in [0, 1]"));
            }
        }
        if self.free_thresh >= self.occupied_thresh {
            return Err(MapError::invalid(
                "free_thresh",
                self.free_thresh,
                format!("must be below occupied_thresh = {}", self.occupied_thresh),
            ));
        }
        Ok(())
    }
}

/// Limits checked on the image header before any pixel is decoded (decompression bombs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ImportLimits {
    /// Largest image file accepted, in bytes.
    pub max_file_bytes: u64,
    /// Largest width or height, in pixels.
    pub max_side_px: u32,
    /// Largest width × height, in pixels.
    pub max_pixels: u64,
}

impl Default for ImportLimits {
    fn default() -> Self {
        // Room for a 100 m × 100 m floor at 1 cm, far above any building plan we expect.
        Self {
            max_file_bytes: 256 << 20,
            max_side_px: 20_000,
            max_pixels: 100_000_000,
        }
    }
}

/// A ROS map as read from disk: the grid plus what the YAML said.
#[derive(Debug, Clone)]
pub struct RosMap {
    pub grid: OccupancyGrid,
    pub interpretation: Interpretation,
    /// The image path, resolved against the YAML's folder.
    pub image_path: PathBuf,
}

/// Loads a ROS `map_server` YAML and its image.
///
/// # Errors
/// A [`MapError`] naming the field or file and value for every malformed input.
pub fn load_ros_map(yaml_path: &Path, limits: &ImportLimits) -> Result<RosMap, MapError> {
    let text = std::fs::read_to_string(yaml_path).map_err(|e| MapError::io(yaml_path, e))?;
    let doc: Value = serde_yaml::from_str(&text).map_err(|e| MapError::Yaml {
        path: yaml_path.to_path_buf(),
        reason: e.to_string(),
    })?;
    let map = doc.as_mapping().ok_or_else(|| MapError::Yaml {
        path: yaml_path.to_path_buf(),
        reason: "top level is not a mapping".into(),
    })?;
    let get = |field: &'static str| -> Result<&Value, MapError> {
        map.get(field).ok_or_else(|| MapError::MissingField {
            field,
            path: yaml_path.to_path_buf(),
        })
    };
    let number = |field: &'static str| -> Result<f64, MapError> {
        let v = get(field)?;
        v.as_f64()
            .ok_or_else(|| MapError::invalid(field, show(v), "expected a number"))
    };

    let image = get("image")?;
    let image = image
        .as_str()
        .filter(|s| !s.is_empty())
        .ok_or_else(|| MapError::invalid("image", show(image), "expected a file name"))?;
    let image_path = yaml_path
        .parent()
        .unwrap_or_else(|| Path::new("."))
        .join(image);

    let resolution_m = number("resolution")?;
    if !resolution_m.is_finite() || resolution_m <= 0.0 {
        return Err(MapError::invalid(
            "resolution",
            resolution_m,
            "must be a positive, finite number of metres per pixel",
        ));
    }
    let origin_value = get("origin")?;
    let origin: Vec<f64> = origin_value
        .as_sequence()
        .ok_or_else(|| MapError::invalid("origin", show(origin_value), "expected [x, y, yaw]"))?
        .iter()
        .map(|v| {
            v.as_f64()
                .ok_or_else(|| MapError::invalid("origin", show(v), "expected numbers"))
        })
        .collect::<Result<_, _>>()?;
    if origin.len() != 3 {
        return Err(MapError::invalid(
            "origin",
            show(origin_value),
            format!("expected 3 elements [x, y, yaw], got {}", origin.len()),
        ));
    }
    if let Some(bad) = origin.iter().find(|v| !v.is_finite()) {
        return Err(MapError::invalid("origin", bad, "elements must be finite"));
    }

    let mode = match map.get("mode") {
        None => MapMode::Trinary,
        Some(v) => v
            .as_str()
            .ok_or_else(|| MapError::invalid("mode", show(v), "expected trinary, scale or raw"))?
            .parse()?,
    };
    // Nav2 accepts negate as an integer or a boolean; absent means 0.
    let negate = match map.get("negate") {
        None => false,
        Some(Value::Bool(b)) => *b,
        Some(v) => match v.as_i64() {
            Some(0) => false,
            Some(1) => true,
            _ => {
                return Err(MapError::invalid(
                    "negate",
                    show(v),
                    "expected 0, 1, true or false",
                ))
            }
        },
    };
    let interpretation = Interpretation {
        mode,
        negate,
        occupied_thresh: number("occupied_thresh")?,
        free_thresh: number("free_thresh")?,
    };
    interpretation.validate()?;

    let img = read_image(&image_path, limits)?;
    let cells = occupancy_from_image(&img, &interpretation);
    let origin = Pose2D::new(origin[0], origin[1], origin[2]);
    let grid = OccupancyGrid::new(img.width(), img.height(), resolution_m, origin, cells)?;
    Ok(RosMap {
        grid,
        interpretation,
        image_path,
    })
}

/// Reads an image after checking its size, its header dimensions and the decoder's memory
/// against `limits`, so an oversized or bomb image is refused before its pixels are decoded.
///
/// # Errors
/// [`MapError::Io`], [`MapError::TooLarge`] or [`MapError::Image`].
pub fn read_image(path: &Path, limits: &ImportLimits) -> Result<DynamicImage, MapError> {
    let meta = std::fs::metadata(path).map_err(|e| MapError::io(path, e))?;
    if meta.len() > limits.max_file_bytes {
        return Err(MapError::TooLarge {
            path: path.to_path_buf(),
            field: "file_bytes",
            value: meta.len(),
            limit: limits.max_file_bytes,
        });
    }
    let bytes = std::fs::read(path).map_err(|e| MapError::io(path, e))?;
    decode_image(&bytes, path, limits)
}

/// Decodes image bytes under `limits`; `path` only labels errors.
///
/// # Errors
/// [`MapError::TooLarge`] or [`MapError::Image`].
pub fn decode_image(
    bytes: &[u8],
    path: &Path,
    limits: &ImportLimits,
) -> Result<DynamicImage, MapError> {
    let image_err = |e: &dyn std::fmt::Display| MapError::Image {
        path: path.to_path_buf(),
        reason: e.to_string(),
    };
    let too_large = |field, value, limit| MapError::TooLarge {
        path: path.to_path_buf(),
        field,
        value,
        limit,
    };
    if bytes.len() as u64 > limits.max_file_bytes {
        return Err(too_large(
            "file_bytes",
            bytes.len() as u64,
            limits.max_file_bytes,
        ));
    }
    let reader = || {
        image::ImageReader::new(std::io::Cursor::new(bytes))
            .with_guessed_format()
            .map_err(|e| image_err(&e))
    };
    let probe = reader()?;
    if probe.format().is_none() {
        return Err(image_err(
            &"unrecognized image format (expected PGM, PNG, BMP or JPEG)",
        ));
    }
    let (w, h) = probe.into_dimensions().map_err(|e| image_err(&e))?;
    for (field, v) in [("width_px", w), ("height_px", h)] {
        if v > limits.max_side_px {
            return Err(too_large(
                field,
                u64::from(v),
                u64::from(limits.max_side_px),
            ));
        }
    }
    let pixels = u64::from(w) * u64::from(h);
    if pixels > limits.max_pixels {
        return Err(too_large("pixels", pixels, limits.max_pixels));
    }
    let mut decoder_limits = image::Limits::default();
    decoder_limits.max_image_width = Some(w);
    decoder_limits.max_image_height = Some(h);
    // Eight bytes per pixel covers 16-bit RGBA, the widest layout we accept.
    decoder_limits.max_alloc = Some(pixels.saturating_mul(8).max(1 << 20));
    let mut r = reader()?;
    r.limits(decoder_limits);
    r.decode().map_err(|e| image_err(&e))
}

/// Converts an image to ROS cell values (row 0 at the bottom) per Nav2's rules.
///
/// Pixels are read in place, widened to 16 bits one at a time: a whole-image 16-bit RGBA copy
/// costs 8 bytes a pixel (800 MB for a 100-megapixel plan) where the grid needs one.
#[must_use]
pub fn occupancy_from_image(img: &DynamicImage, how: &Interpretation) -> Vec<u8> {
    let (w, h) = img.dimensions();
    let has_alpha = img.color().has_alpha();
    let mut cells = vec![UNKNOWN; w as usize * h as usize];
    for_each_rgba16(img, |x, y, px| {
        // Image row 0 is the top; grid row 0 is the bottom.
        cells[(h - 1 - y) as usize * w as usize + x as usize] = cell_value(px, has_alpha, how);
    });
    cells
}

/// Calls `f(x, y, [r, g, b, a])` for every pixel, widened to 16 bits as `image`'s own
/// conversions do (an 8-bit `v` becomes `v * 257`, grey is copied to r, g and b, no alpha is
/// opaque).
fn for_each_rgba16(img: &DynamicImage, mut f: impl FnMut(u32, u32, [u16; 4])) {
    const OPAQUE: u16 = u16::MAX;
    let wide = |v: u8| u16::from(v) * 257;
    match img {
        DynamicImage::ImageLuma8(b) => b.enumerate_pixels().for_each(|(x, y, p)| {
            let v = wide(p.0[0]);
            f(x, y, [v, v, v, OPAQUE]);
        }),
        DynamicImage::ImageLumaA8(b) => b.enumerate_pixels().for_each(|(x, y, p)| {
            let v = wide(p.0[0]);
            f(x, y, [v, v, v, wide(p.0[1])]);
        }),
        DynamicImage::ImageRgb8(b) => b.enumerate_pixels().for_each(|(x, y, p)| {
            let [r, g, bl] = p.0;
            f(x, y, [wide(r), wide(g), wide(bl), OPAQUE]);
        }),
        DynamicImage::ImageRgba8(b) => b.enumerate_pixels().for_each(|(x, y, p)| {
            let [r, g, bl, a] = p.0;
            f(x, y, [wide(r), wide(g), wide(bl), wide(a)]);
        }),
        DynamicImage::ImageLuma16(b) => b.enumerate_pixels().for_each(|(x, y, p)| {
            let v = p.0[0];
            f(x, y, [v, v, v, OPAQUE]);
        }),
        DynamicImage::ImageLumaA16(b) => b.enumerate_pixels().for_each(|(x, y, p)| {
            let [v, a] = p.0;
            f(x, y, [v, v, v, a]);
        }),
        DynamicImage::ImageRgb16(b) => b.enumerate_pixels().for_each(|(x, y, p)| {
            let [r, g, bl] = p.0;
            f(x, y, [r, g, bl, OPAQUE]);
        }),
        DynamicImage::ImageRgba16(b) => b.enumerate_pixels().for_each(|(x, y, p)| f(x, y, p.0)),
        // Float images come from no decoder we enable (PGM, PNG, BMP, JPEG); convert a row at
        // a time rather than the whole picture.
        other => {
            for y in 0..other.height() {
                let row = other.crop_imm(0, y, other.width(), 1).to_rgba16();
                for (x, _, p) in row.enumerate_pixels() {
                    f(x, y, p.0);
                }
            }
        }
    }
}

/// One pixel's ROS cell value under `how`.
fn cell_value([r, g, b, a]: [u16; 4], has_alpha: bool, how: &Interpretation) -> u8 {
    let max = f64::from(u16::MAX);
    let mut sum = f64::from(r) + f64::from(g) + f64::from(b);
    let mut n = 3.0;
    if how.mode == MapMode::Trinary && has_alpha {
        sum += max - f64::from(a);
        n += 1.0;
    }
    let shade = sum / n / max;
    let occ = if how.negate { shade } else { 1.0 - shade };
    match how.mode {
        MapMode::Trinary => {
            if how.occupied_thresh < occ {
                OCCUPIED
            } else if occ < how.free_thresh {
                FREE
            } else {
                UNKNOWN
            }
        }
        MapMode::Scale => {
            if has_alpha && a != u16::MAX {
                UNKNOWN
            } else if how.occupied_thresh < occ {
                OCCUPIED
            } else if occ < how.free_thresh {
                FREE
            } else {
                let ratio = (occ - how.free_thresh) / (how.occupied_thresh - how.free_thresh);
                // In [0, 100] by the branch conditions.
                #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
                let v = (ratio * 100.0).round_ties_even() as u8;
                v
            }
        }
        MapMode::Raw => {
            let pct = (shade * 255.0).round();
            if (0.0..=100.0).contains(&pct) {
                #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
                let v = pct as u8;
                v
            } else {
                UNKNOWN
            }
        }
    }
}

/// Bytes that decoding an image and turning it into a grid take at the peak: the decoded
/// pixels (their colour type's size) plus one byte a cell for the grid, from the header only,
/// so a caller can budget memory before anything is decoded.
///
/// # Errors
/// [`MapError::Image`] when the header cannot be read.
pub fn decode_cost_bytes(bytes: &[u8], path: &Path) -> Result<u64, MapError> {
    use image::ImageDecoder;
    let image_err = |e: &dyn std::fmt::Display| MapError::Image {
        path: path.to_path_buf(),
        reason: e.to_string(),
    };
    let decoder = image::ImageReader::new(std::io::Cursor::new(bytes))
        .with_guessed_format()
        .map_err(|e| image_err(&e))?
        .into_decoder()
        .map_err(|e| image_err(&e))?;
    let (w, h) = decoder.dimensions();
    let per_pixel = u64::from(decoder.color_type().bytes_per_pixel()) + 1;
    Ok((u64::from(w) * u64::from(h)).saturating_mul(per_pixel))
}

fn show(v: &Value) -> String {
    serde_yaml::to_string(v).map_or_else(|_| format!("{v:?}"), |s| s.trim().to_string())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::nav2_maps_dir;

    /// Nav2's `test_constants.cpp`: the expected grid, lower-left pixel first.
    const NAV2_TESTMAP: [i8; 100] = [
        0, 0, 0, 0, 0, 0, 0, 0, 0, 0, //
        100, 100, 100, 100, 0, 0, 100, 100, 100, 0, //
        100, 100, 100, 100, 0, 0, 100, 100, 100, 0, //
        100, 0, 0, 0, 0, 0, 0, 0, 0, 0, //
        100, 0, 0, 0, 0, 0, 0, 0, 0, 0, //
        100, 0, 0, 0, 0, 0, 100, 100, 0, 0, //
        100, 0, 0, 0, 0, 0, 100, 100, 0, 0, //
        100, 0, 0, 0, 0, 0, 100, 100, 0, 0, //
        100, 0, 0, 0, 0, 0, 100, 100, 0, 0, //
        100, 0, 0, 0, 0, 0, 0, 0, 0, 0, //
    ];

    fn shared_maps() -> PathBuf {
        nav2_maps_dir()
    }

    /// The pixel walk reads every colour type as `image`'s whole-image 16-bit conversion does.
    #[test]
    fn pixels_are_read_in_place_as_the_16_bit_conversion_reads_them() {
        let (w, h) = (7u32, 5u32);
        // A fixed pseudo-random picture (LCG) so every channel takes varied values.
        let mut state = 0x2545_f491_u32;
        let mut next = || {
            state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            u16::try_from(state >> 16).unwrap()
        };
        let src =
            image::ImageBuffer::from_fn(w, h, |_, _| image::Rgba([next(), next(), next(), next()]));
        let base = DynamicImage::ImageRgba16(src);
        let variants = [
            DynamicImage::ImageLuma8(base.to_luma8()),
            DynamicImage::ImageLumaA8(base.to_luma_alpha8()),
            DynamicImage::ImageRgb8(base.to_rgb8()),
            DynamicImage::ImageRgba8(base.to_rgba8()),
            DynamicImage::ImageLuma16(base.to_luma16()),
            DynamicImage::ImageLumaA16(base.to_luma_alpha16()),
            DynamicImage::ImageRgb16(base.to_rgb16()),
            base.clone(),
            DynamicImage::ImageRgb32F(base.to_rgb32f()),
        ];
        for img in &variants {
            let mut seen = Vec::new();
            for_each_rgba16(img, |x, y, px| seen.push((x, y, px)));
            let want: Vec<(u32, u32, [u16; 4])> = img
                .to_rgba16()
                .enumerate_pixels()
                .map(|(x, y, p)| (x, y, p.0))
                .collect();
            assert_eq!(seen, want, "{:?}", img.color());
        }
    }

    #[test]
    fn decode_cost_counts_decoded_pixels_and_the_grid() {
        let img = DynamicImage::ImageLuma8(image::GrayImage::new(300, 200));
        let mut png = Vec::new();
        img.write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
            .unwrap();
        assert_eq!(
            decode_cost_bytes(&png, Path::new("m.png")).unwrap(),
            300 * 200 * 2
        );
        let err = decode_cost_bytes(b"not an image", Path::new("m.png")).unwrap_err();
        assert!(err.to_string().contains("m.png"), "{err}");
    }

    #[test]
    fn nav2_testmap_loads_exactly_in_every_format() {
        let dir = tempfile::tempdir().unwrap();
        for image in ["testmap.pgm", "testmap.png", "testmap.bmp"] {
            let yaml = dir.path().join(format!("{image}.yaml"));
            std::fs::write(
                &yaml,
                format!(
                    "image: {}\nresolution: 0.1\norigin: [2.0, 3.0, 1.0]\n\
                     occupied_thresh: 0.65\nfree_thresh: 0.196\nnegate: 0\nmode: trinary\n",
                    shared_maps().join(image).display()
                ),
            )
            .unwrap();
            let map = load_ros_map(&yaml, &ImportLimits::default()).unwrap();
            let g = &map.grid;
            assert_eq!((g.width_cells(), g.height_cells()), (10, 10), "{image}");
            assert!((g.resolution_m() - 0.1).abs() < 1e-12);
            assert_eq!(g.origin(), Pose2D::new(2.0, 3.0, 1.0));
            let expected: Vec<u8> = NAV2_TESTMAP.iter().map(|&v| v as u8).collect();
            assert_eq!(g.cells(), expected.as_slice(), "{image}");
        }
    }

    #[test]
    fn shipped_testmap_yaml_resolves_image_relative_to_yaml() {
        let map = load_ros_map(
            &shared_maps().join("testmap.yaml"),
            &ImportLimits::default(),
        )
        .unwrap();
        assert!(map.image_path.ends_with("testmap.png"));
        assert_eq!(map.grid.counts().occupied, 29);
    }
}
