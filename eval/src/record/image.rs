//! Area-average downscaling of RGB8 images: every output pixel is the mean of the source area
//! it covers (fractional edges weighted), so nothing aliases as nearest-neighbour would.

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
pub fn resize_rgb8(
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn averages_areas() {
        // 4×2 → 2×1: each output pixel averages a 2×2 block.
        let mut data = Vec::new();
        for v in [0u8, 100, 200, 200, 100, 100, 0, 0] {
            data.extend_from_slice(&[v, v, v]);
        }
        let out = resize_rgb8(&data, 4, 2, 2, 1);
        assert_eq!(out, vec![75, 75, 75, 100, 100, 100]);
        // A uniform image stays uniform at a fractional scale.
        let grey = vec![77u8; 224 * 224 * 3];
        assert!(resize_rgb8(&grey, 224, 224, 96, 96)
            .iter()
            .all(|&v| v == 77));
    }
}
