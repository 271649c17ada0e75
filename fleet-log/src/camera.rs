//! Camera frames in a log: Foxglove's `foxglove.CompressedImage` in JSON (base64 data), made
//! from a [`CameraFrame`] (RGB8 is compressed to JPEG; PNG and JPEG are kept as they are).

use base64::Engine;
use image::codecs::jpeg::JpegEncoder;
use image::ExtendedColorType;
use protocol::{CameraFrame, ImageEncoding};
use serde::{Deserialize, Serialize};

/// Seconds and nanoseconds (Foxglove's `Time`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Timestamp {
    pub sec: u64,
    pub nsec: u32,
}

impl Timestamp {
    #[must_use]
    pub fn from_ns(stamp_ns: u64) -> Self {
        Self {
            sec: stamp_ns / 1_000_000_000,
            #[allow(clippy::cast_possible_truncation)]
            nsec: (stamp_ns % 1_000_000_000) as u32,
        }
    }

    #[must_use]
    pub fn as_ns(self) -> u64 {
        self.sec
            .saturating_mul(1_000_000_000)
            .saturating_add(u64::from(self.nsec))
    }
}

/// One camera frame as `foxglove.CompressedImage` (`/camera`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CompressedImage {
    pub timestamp: Timestamp,
    pub frame_id: String,
    /// Base64 of the JPEG or PNG bytes.
    pub data: String,
    /// `jpeg` or `png`.
    pub format: String,
}

impl CompressedImage {
    /// The frame compressed for the log: RGB8 as JPEG of `jpeg_quality` (1–100), PNG and JPEG
    /// unchanged.
    ///
    /// # Errors
    /// The JPEG encoder's reason (e.g. RGB8 data of the wrong length).
    pub fn from_frame(frame: &CameraFrame, jpeg_quality: u8) -> Result<Self, String> {
        let image = &frame.image;
        let (bytes, format) = match image.encoding {
            ImageEncoding::Rgb8 => {
                let mut out = Vec::new();
                JpegEncoder::new_with_quality(&mut out, jpeg_quality.clamp(1, 100))
                    .encode(
                        &image.data,
                        image.width_px,
                        image.height_px,
                        ExtendedColorType::Rgb8,
                    )
                    .map_err(|e| e.to_string())?;
                (out, "jpeg")
            }
            ImageEncoding::Jpeg => (image.data.clone(), "jpeg"),
            ImageEncoding::Png => (image.data.clone(), "png"),
        };
        Ok(Self {
            timestamp: Timestamp::from_ns(frame.header.stamp_ns),
            frame_id: "camera".into(),
            data: base64::engine::general_purpose::STANDARD.encode(bytes),
            format: format.into(),
        })
    }

    /// The image bytes.
    ///
    /// # Errors
    /// The base64 decoder's reason.
    pub fn bytes(&self) -> Result<Vec<u8>, String> {
        base64::engine::general_purpose::STANDARD
            .decode(&self.data)
            .map_err(|e| e.to_string())
    }
}
