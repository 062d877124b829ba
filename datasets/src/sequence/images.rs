//! PNG reading and writing for colour, depth and mask images.

use std::path::Path;

use image::codecs::png::{CompressionType, FilterType, PngEncoder};
use image::{DynamicImage, ExtendedColorType, ImageEncoder};
use scarp_slam::image::{DepthImage, MaskImage, RgbImage};

use crate::DatasetError;

fn image_error(path: &Path, message: impl Into<String>) -> DatasetError {
    DatasetError::Image {
        path: path.to_path_buf(),
        message: message.into(),
    }
}

fn decode(path: &Path) -> Result<DynamicImage, DatasetError> {
    let bytes = std::fs::read(path).map_err(|e| DatasetError::io(path, e))?;
    image::load_from_memory(&bytes)
        .map_err(|e| image_error(path, format!("cannot decode image: {e}")))
}

fn encode_png(
    path: &Path,
    bytes: &[u8],
    width: u32,
    height: u32,
    color: ExtendedColorType,
) -> Result<(), DatasetError> {
    scarp_export::atomic::write_atomically(path, |writer| {
        PngEncoder::new_with_quality(writer, CompressionType::Fast, FilterType::Sub)
            .write_image(bytes, width, height, color)
            .map_err(std::io::Error::other)
    })?;
    Ok(())
}

/// Reads a colour image (8-bit RGB, RGBA or grey, converted to RGB).
///
/// # Errors
/// [`DatasetError::Io`] for a missing file, [`DatasetError::Image`] for a corrupt one.
pub fn read_rgb_png(path: &Path) -> Result<RgbImage, DatasetError> {
    let rgb = decode(path)?.to_rgb8();
    let (w, h) = rgb.dimensions();
    let pixels = rgb
        .into_raw()
        .chunks_exact(3)
        .map(|c| [c[0], c[1], c[2]])
        .collect();
    RgbImage::from_vec(w, h, pixels).map_err(|e| image_error(path, e.to_string()))
}

fn read_u16(path: &Path, what: &str) -> Result<(u32, u32, Vec<u16>), DatasetError> {
    match decode(path)? {
        DynamicImage::ImageLuma16(img) => {
            let (w, h) = img.dimensions();
            Ok((w, h, img.into_raw()))
        }
        other => Err(image_error(
            path,
            format!(
                "{what} must be a 16-bit greyscale PNG, found {:?}",
                other.color()
            ),
        )),
    }
}

/// Reads a 16-bit depth PNG and divides by `depth_scale` (units per metre); 0 stays "no
/// measurement".
///
/// # Errors
/// [`DatasetError::Io`], or [`DatasetError::Image`] for a corrupt file or one that is not
/// 16-bit greyscale.
pub fn read_depth_png(path: &Path, depth_scale: f64) -> Result<DepthImage, DatasetError> {
    let (w, h, raw) = read_u16(path, "a depth image")?;
    let inv = 1.0 / depth_scale;
    DepthImage::from_vec(
        w,
        h,
        raw.into_iter()
            .map(|d| (f64::from(d) * inv) as f32)
            .collect(),
    )
    .map_err(|e| image_error(path, e.to_string()))
}

/// Reads a 16-bit instance-mask PNG.
///
/// # Errors
/// As [`read_depth_png`].
pub fn read_mask_png(path: &Path) -> Result<MaskImage, DatasetError> {
    let (w, h, raw) = read_u16(path, "a mask")?;
    MaskImage::from_vec(w, h, raw).map_err(|e| image_error(path, e.to_string()))
}

/// Writes an 8-bit RGB PNG atomically.
///
/// # Errors
/// [`DatasetError::Write`] naming the file.
pub fn write_rgb_png(path: &Path, rgb: &RgbImage) -> Result<(), DatasetError> {
    let bytes: Vec<u8> = rgb.as_slice().iter().flatten().copied().collect();
    encode_png(
        path,
        &bytes,
        rgb.width(),
        rgb.height(),
        ExtendedColorType::Rgb8,
    )
}

/// Writes depth as a 16-bit PNG at `depth_scale` units per metre, rounding to the nearest unit.
/// Depths that do not fit in 16 bits (beyond 65535 / `depth_scale` metres) become 0 (no
/// measurement) rather than a wrong value.
///
/// # Errors
/// [`DatasetError::Write`] naming the file.
pub fn write_depth_png(
    path: &Path,
    depth_m: &DepthImage,
    depth_scale: f64,
) -> Result<(), DatasetError> {
    let bytes: Vec<u8> = depth_m
        .as_slice()
        .iter()
        .flat_map(|&d| {
            let units = (f64::from(d) * depth_scale).round();
            let value = if units > 0.0 && units <= f64::from(u16::MAX) {
                units as u16
            } else {
                0
            };
            value.to_ne_bytes()
        })
        .collect();
    encode_png(
        path,
        &bytes,
        depth_m.width(),
        depth_m.height(),
        ExtendedColorType::L16,
    )
}

/// Writes an instance mask as a 16-bit PNG.
///
/// # Errors
/// [`DatasetError::Write`] naming the file.
pub fn write_mask_png(path: &Path, mask: &MaskImage) -> Result<(), DatasetError> {
    let bytes: Vec<u8> = mask
        .as_slice()
        .iter()
        .flat_map(|v| v.to_ne_bytes())
        .collect();
    encode_png(
        path,
        &bytes,
        mask.width(),
        mask.height(),
        ExtendedColorType::L16,
    )
}
