//! One RGBD camera frame.

use crate::SlamError;
use crate::image::{DepthImage, MaskImage, RgbImage};

/// A colour image, a depth image and optionally an instance mask taken at one instant by one
/// camera. All images share the camera's size.
#[derive(Debug, Clone, PartialEq)]
pub struct RgbdFrame {
    /// Capture time in seconds (the sequence's clock, e.g. UNIX time for TUM sequences).
    pub timestamp_s: f64,
    /// Colour image, 8-bit sRGB.
    pub rgb: RgbImage,
    /// z-depth in metres along the camera z axis; 0.0 means no measurement.
    pub depth_m: DepthImage,
    /// Per-pixel instance id, when the source knows it (synthetic sequences).
    pub instance_mask: Option<MaskImage>,
}

impl RgbdFrame {
    /// Builds a frame, checking that the images share one size and the timestamp is finite.
    ///
    /// # Errors
    /// [`SlamError::ImageSizeMismatch`] when depth or mask differ in size from the colour image;
    /// [`SlamError::NotFinite`] for a NaN or infinite timestamp.
    pub fn new(
        timestamp_s: f64,
        rgb: RgbImage,
        depth_m: DepthImage,
        instance_mask: Option<MaskImage>,
    ) -> Result<Self, SlamError> {
        if !timestamp_s.is_finite() {
            return Err(SlamError::NotFinite {
                what: "frame timestamp".into(),
            });
        }
        depth_m.check_size("depth image", rgb.width(), rgb.height())?;
        if let Some(mask) = &instance_mask {
            mask.check_size("instance mask", rgb.width(), rgb.height())?;
        }
        Ok(Self {
            timestamp_s,
            rgb,
            depth_m,
            instance_mask,
        })
    }

    /// Width in pixels.
    pub fn width(&self) -> u32 {
        self.rgb.width()
    }

    /// Height in pixels.
    pub fn height(&self) -> u32 {
        self.rgb.height()
    }

    /// Number of pixels with a depth measurement.
    pub fn valid_depth_count(&self) -> usize {
        self.depth_m.as_slice().iter().filter(|&&d| d > 0.0).count()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rejects_mismatched_sizes() {
        let rgb = RgbImage::filled(4, 3, [0, 0, 0]);
        let err =
            RgbdFrame::new(0.0, rgb.clone(), DepthImage::filled(3, 3, 1.0), None).unwrap_err();
        assert!(err.to_string().contains("depth image"));
        let err = RgbdFrame::new(
            0.0,
            rgb.clone(),
            DepthImage::filled(4, 3, 1.0),
            Some(MaskImage::filled(4, 4, 0)),
        )
        .unwrap_err();
        assert!(err.to_string().contains("instance mask"));
        assert!(
            RgbdFrame::new(f64::NAN, rgb.clone(), DepthImage::filled(4, 3, 1.0), None).is_err()
        );
        let f = RgbdFrame::new(1.5, rgb, DepthImage::filled(4, 3, 1.0), None).unwrap();
        assert_eq!(f.valid_depth_count(), 12);
    }
}
