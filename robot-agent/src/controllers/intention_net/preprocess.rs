//! Turning a wire image (`protocol::Image`: raw RGB8, PNG or JPEG) into the network's input:
//! f32, channels first (CHW), resized to the card's size, normalized with the card's
//! per-channel mean and std.
//!
//! The resize is an area average (every output pixel is the mean of the source area it covers,
//! fractional edges weighted): the recorder (`eval record`) stores the training images through
//! the same [`resize_area_rgb8`], so a network sees in deployment exactly the pixels it was
//! trained on.

use std::borrow::Cow;

use image::ImageFormat;
use protocol::{Image, ImageEncoding};

use super::card::Normalization;

/// An image that cannot be decoded or does not say what it holds.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{0}")]
pub struct PreprocessError(pub String);

/// The RGB8 pixels of `image` (row-major from the top-left) and their size. Raw RGB8 is
/// borrowed, PNG/JPEG are decoded; a decoded size that differs from the declared one is refused
/// because it means the sender mislabelled the frame.
///
/// # Errors
/// [`PreprocessError`] for undecodable data or a size mismatch.
pub fn decode_rgb8(image: &Image) -> Result<(Cow<'_, [u8]>, u32, u32), PreprocessError> {
    let format = match image.encoding {
        ImageEncoding::Rgb8 => {
            let expected = Image::rgb8_len(image.width_px, image.height_px);
            if expected != Some(image.data.len()) || image.data.is_empty() {
                return Err(PreprocessError(format!(
                    "rgb8 {}x{} px needs {} bytes, got {}",
                    image.width_px,
                    image.height_px,
                    expected.map_or_else(|| "too many".to_string(), |n| n.to_string()),
                    image.data.len()
                )));
            }
            return Ok((
                Cow::Borrowed(image.data.as_slice()),
                image.width_px,
                image.height_px,
            ));
        }
        ImageEncoding::Png => ImageFormat::Png,
        ImageEncoding::Jpeg => ImageFormat::Jpeg,
    };
    let decoded = image::load_from_memory_with_format(&image.data, format)
        .map_err(|e| PreprocessError(format!("cannot decode {}: {e}", image.encoding.mime())))?
        .into_rgb8();
    if decoded.dimensions() != (image.width_px, image.height_px) {
        return Err(PreprocessError(format!(
            "declared {}x{} px but the {} data is {}x{} px",
            image.width_px,
            image.height_px,
            image.encoding.mime(),
            decoded.width(),
            decoded.height()
        )));
    }
    let (w, h) = decoded.dimensions();
    Ok((Cow::Owned(decoded.into_raw()), w, h))
}

/// Writes `image` into `out` (length `3 * width_px * height_px`, CHW order), resizing with a
/// area average ([`resize_area_rgb8`]) when the sizes differ.
///
/// # Errors
/// [`PreprocessError`] for undecodable data or a wrong `out` length.
pub fn image_to_chw(
    image: &Image,
    width_px: u32,
    height_px: u32,
    norm: &Normalization,
    out: &mut [f32],
) -> Result<(), PreprocessError> {
    let (pixels, w, h) = decode_rgb8(image)?;
    let pixels: Cow<'_, [u8]> = if (w, h) == (width_px, height_px) {
        pixels
    } else {
        Cow::Owned(resize_area_rgb8(
            &pixels,
            w as usize,
            h as usize,
            width_px as usize,
            height_px as usize,
        ))
    };
    rgb8_to_chw(&pixels, norm, out)
}

/// For each output index, the source indices it covers and their weights (summing to 1).
fn taps(src: usize, dst: usize) -> Vec<Vec<(usize, f32)>> {
    #[allow(clippy::cast_precision_loss)]
    let scale = src as f64 / dst as f64;
    (0..dst)
        .map(|o| {
            #[allow(clippy::cast_precision_loss)]
            let (a, b) = (o as f64 * scale, (o + 1) as f64 * scale);
            #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
            let (first, last) = (a.floor() as usize, (b.ceil() as usize).min(src));
            (first..last)
                .filter_map(|i| {
                    #[allow(clippy::cast_precision_loss)]
                    let overlap = (b.min((i + 1) as f64) - a.max(i as f64)) / scale;
                    #[allow(clippy::cast_possible_truncation)]
                    (overlap > 1e-9).then_some((i, overlap as f32))
                })
                .collect()
        })
        .collect()
}

/// Downscales (or upscales) a row-major RGB8 image of `width`×`height` to `out_w`×`out_h`.
/// A buffer of the wrong length gives a black image rather than a panic.
#[must_use]
pub fn resize_area_rgb8(
    data: &[u8],
    width: usize,
    height: usize,
    out_w: usize,
    out_h: usize,
) -> Vec<u8> {
    if data.len() != width * height * 3 || width == 0 || height == 0 {
        return vec![0; out_w * out_h * 3];
    }
    if width == out_w && height == out_h {
        return data.to_vec();
    }
    let (tx, ty) = (taps(width, out_w), taps(height, out_h));
    // Rows first into f32, then columns.
    let mut rows = vec![0f32; height * out_w * 3];
    for y in 0..height {
        let src = &data[y * width * 3..(y + 1) * width * 3];
        for (ox, t) in tx.iter().enumerate() {
            let mut acc = [0f32; 3];
            for &(i, w) in t {
                for c in 0..3 {
                    acc[c] += w * f32::from(src[i * 3 + c]);
                }
            }
            rows[(y * out_w + ox) * 3..(y * out_w + ox) * 3 + 3].copy_from_slice(&acc);
        }
    }
    let mut out = vec![0u8; out_w * out_h * 3];
    for (oy, t) in ty.iter().enumerate() {
        for ox in 0..out_w {
            for c in 0..3 {
                let v: f32 = t
                    .iter()
                    .map(|&(i, w)| w * rows[(i * out_w + ox) * 3 + c])
                    .sum();
                #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
                {
                    out[(oy * out_w + ox) * 3 + c] = v.round().clamp(0.0, 255.0) as u8;
                }
            }
        }
    }
    out
}

/// Normalizes interleaved RGB8 `pixels` into planar `out`: `(p / 255 - mean[c]) / std[c]`.
///
/// # Errors
/// [`PreprocessError`] when the lengths do not agree.
pub fn rgb8_to_chw(
    pixels: &[u8],
    norm: &Normalization,
    out: &mut [f32],
) -> Result<(), PreprocessError> {
    let plane = pixels.len() / 3;
    if !pixels.len().is_multiple_of(3) || out.len() != pixels.len() {
        return Err(PreprocessError(format!(
            "{} RGB bytes do not fill a {}-value CHW tensor",
            pixels.len(),
            out.len()
        )));
    }
    let (r_out, rest) = out.split_at_mut(plane);
    let (g_out, b_out) = rest.split_at_mut(plane);
    // Same arithmetic as the Python side ((p/255 - mean) / std in f32), so fixtures match.
    let [mr, mg, mb] = norm.mean;
    let [sr, sg, sb] = norm.std;
    for (((px, r), g), b) in pixels
        .chunks_exact(3)
        .zip(r_out.iter_mut())
        .zip(g_out.iter_mut())
        .zip(b_out.iter_mut())
    {
        *r = (f32::from(px[0]) / 255.0 - mr) / sr;
        *g = (f32::from(px[1]) / 255.0 - mg) / sg;
        *b = (f32::from(px[2]) / 255.0 - mb) / sb;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::RgbImage;

    const IDENTITY: Normalization = Normalization {
        mean: [0.0; 3],
        std: [1.0; 3],
    };

    fn rgb(w: u32, h: u32, f: impl Fn(u32, u32) -> [u8; 3]) -> Image {
        let mut data = Vec::new();
        for y in 0..h {
            for x in 0..w {
                data.extend_from_slice(&f(x, y));
            }
        }
        Image::new(w, h, ImageEncoding::Rgb8, data).unwrap()
    }

    fn encode(img: &Image, format: ImageFormat, encoding: ImageEncoding) -> Image {
        let buf = RgbImage::from_raw(img.width_px, img.height_px, img.data.clone()).unwrap();
        let mut bytes = std::io::Cursor::new(Vec::new());
        buf.write_to(&mut bytes, format).unwrap();
        Image::new(img.width_px, img.height_px, encoding, bytes.into_inner()).unwrap()
    }

    #[test]
    fn planar_layout_and_normalization() {
        let img = rgb(
            2,
            1,
            |x, _| if x == 0 { [255, 0, 51] } else { [0, 255, 102] },
        );
        let norm = Normalization {
            mean: [0.5, 0.0, 0.0],
            std: [0.5, 1.0, 0.2],
        };
        let mut out = vec![0.0; 6];
        image_to_chw(&img, 2, 1, &norm, &mut out).unwrap();
        let want = [1.0, -1.0, 0.0, 1.0, 1.0, 2.0];
        for (o, w) in out.iter().zip(want) {
            assert!((o - w).abs() < 1e-6, "{out:?}");
        }
    }

    #[test]
    fn png_decodes_to_the_same_tensor_and_jpeg_close_to_it() {
        let img = rgb(32, 24, |x, y| [(x * 8) as u8, (y * 10) as u8, 90]);
        let mut raw = vec![0.0; 3 * 32 * 24];
        image_to_chw(&img, 32, 24, &IDENTITY, &mut raw).unwrap();
        let mut png = vec![0.0; raw.len()];
        let png_img = encode(&img, ImageFormat::Png, ImageEncoding::Png);
        image_to_chw(&png_img, 32, 24, &IDENTITY, &mut png).unwrap();
        assert_eq!(raw, png);
        let mut jpeg = vec![0.0; raw.len()];
        let jpeg_img = encode(&img, ImageFormat::Jpeg, ImageEncoding::Jpeg);
        image_to_chw(&jpeg_img, 32, 24, &IDENTITY, &mut jpeg).unwrap();
        let mean_abs = raw
            .iter()
            .zip(&jpeg)
            .map(|(a, b)| (a - b).abs())
            .sum::<f32>()
            / raw.len() as f32;
        assert!(mean_abs < 0.03, "jpeg differs by {mean_abs} on average");
        assert_ne!(
            raw, jpeg,
            "jpeg is lossy; equal tensors mean it was not decoded"
        );
    }

    #[test]
    fn resizes_to_the_requested_size() {
        let img = rgb(64, 48, |_, _| [10, 200, 30]);
        let mut out = vec![0.0; 3 * 16 * 12];
        image_to_chw(&img, 16, 12, &IDENTITY, &mut out).unwrap();
        assert!(out[..192].iter().all(|v| (v - 10.0 / 255.0).abs() < 1e-6));
        assert!(out[192..384]
            .iter()
            .all(|v| (v - 200.0 / 255.0).abs() < 1e-6));
    }

    #[test]
    fn refuses_lies_about_size_and_garbage() {
        let img = rgb(8, 8, |_, _| [1, 2, 3]);
        let mut png = encode(&img, ImageFormat::Png, ImageEncoding::Png);
        png.width_px = 9;
        let err = decode_rgb8(&png).unwrap_err();
        assert!(err.0.contains("declared 9x8"), "{err}");
        let broken = Image {
            width_px: 8,
            height_px: 8,
            encoding: ImageEncoding::Png,
            data: vec![0x89, b'P', b'N', b'G', b'\r', b'\n', 0x1a, b'\n', 0, 0],
        };
        assert!(decode_rgb8(&broken)
            .unwrap_err()
            .0
            .contains("cannot decode image/png"));
        let short = Image {
            data: vec![0; 5],
            ..img.clone()
        };
        assert!(decode_rgb8(&short)
            .unwrap_err()
            .0
            .contains("needs 192 bytes"));
        let mut out = vec![0.0; 5];
        assert!(image_to_chw(&img, 8, 8, &IDENTITY, &mut out).is_err());
    }

    #[test]
    fn averages_areas() {
        // 4×2 → 2×1: each output pixel averages a 2×2 block.
        let mut data = Vec::new();
        for v in [0u8, 100, 200, 200, 100, 100, 0, 0] {
            data.extend_from_slice(&[v, v, v]);
        }
        let out = resize_area_rgb8(&data, 4, 2, 2, 1);
        assert_eq!(out, vec![75, 75, 75, 100, 100, 100]);
        // A uniform image stays uniform at a fractional scale.
        let grey = vec![77u8; 224 * 224 * 3];
        assert!(resize_area_rgb8(&grey, 224, 224, 96, 96)
            .iter()
            .all(|&v| v == 77));
    }
}
