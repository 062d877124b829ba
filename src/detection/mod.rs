//! Target detection: an image goes in, scored and classed boxes come out.
//!
//! The [`Detector`] trait is what the tracker and the mission call. Implementations model a
//! trained network on synthetic sequences (from ground-truth instance masks) or run a real YOLO
//! export in ONNX.
//!
//! Boxes are in continuous pixel coordinates of the input image: pixel centres sit at integers,
//! so a box covering pixels `0..=9` horizontally spans `x_min = -0.5` to `x_max = 9.5`.

pub mod letterbox;
pub mod nms;
#[cfg(feature = "onnx")]
pub mod onnx;
pub mod replay;
pub mod simulated;
pub mod yolo;

pub use nms::non_max_suppression;
#[cfg(feature = "onnx")]
pub use onnx::OnnxDetector;
pub use replay::ReplayDetector;
pub use simulated::{SimulatedDetector, SimulatedDetectorConfig};
pub use yolo::{OnnxDetectorConfig, YoloLayout};

use scarp_slam::frame::RgbdFrame;

/// The YOLO ONNX detector of the model file `model`, boxed for the tracker and the mission.
///
/// # Errors
/// [`DetectionError::Model`] naming the file when it cannot be loaded, or when this build lacks
/// the `onnx` cargo feature (the message says how to rebuild); [`DetectionError::Config`] for
/// invalid settings.
pub fn load_onnx_detector(
    model: &std::path::Path,
    config: OnnxDetectorConfig,
) -> Result<Box<dyn Detector>, DetectionError> {
    #[cfg(feature = "onnx")]
    {
        Ok(Box::new(OnnxDetector::load(model, config)?))
    }
    #[cfg(not(feature = "onnx"))]
    {
        let _ = config;
        Err(DetectionError::Model {
            path: model.display().to_string(),
            reason: "this scarp was built without the `onnx` cargo feature (rebuild with \
                     `--features onnx`)"
                .into(),
        })
    }
}

/// An axis-aligned image box, pixels (column `x`, row `y`), continuous coordinates.
///
/// Invariant for a valid box: all four values are finite and `x_min < x_max`, `y_min < y_max`.
/// [`BoundingBox::new`] checks it; the fields stay public so that maths stays plain.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct BoundingBox {
    /// Left edge, px.
    pub x_min: f64,
    /// Top edge, px.
    pub y_min: f64,
    /// Right edge, px.
    pub x_max: f64,
    /// Bottom edge, px.
    pub y_max: f64,
}

impl BoundingBox {
    /// A box from its edges.
    ///
    /// # Errors
    /// [`DetectionError::InvalidBox`] when an edge is not finite or the box has no area.
    pub fn new(x_min: f64, y_min: f64, x_max: f64, y_max: f64) -> Result<Self, DetectionError> {
        let b = Self {
            x_min,
            y_min,
            x_max,
            y_max,
        };
        let finite = [x_min, y_min, x_max, y_max].iter().all(|v| v.is_finite());
        if !finite || x_min >= x_max || y_min >= y_max {
            return Err(DetectionError::InvalidBox { bbox: b });
        }
        Ok(b)
    }

    /// The box that covers whole pixels with inclusive integer bounds `[x0, y0, x1, y1]`
    /// (the `boxes.txt` convention).
    pub fn from_inclusive_pixels(bounds: [u32; 4]) -> Self {
        let [x0, y0, x1, y1] = bounds.map(f64::from);
        Self {
            x_min: x0 - 0.5,
            y_min: y0 - 0.5,
            x_max: x1 + 0.5,
            y_max: y1 + 0.5,
        }
    }

    /// A box from its centre `(cx, cy)` and size `(w, h)`, px.
    pub fn from_center_size(cx: f64, cy: f64, w: f64, h: f64) -> Self {
        Self {
            x_min: cx - 0.5 * w,
            y_min: cy - 0.5 * h,
            x_max: cx + 0.5 * w,
            y_max: cy + 0.5 * h,
        }
    }

    /// Width, px (negative for an inverted box).
    pub fn width(&self) -> f64 {
        self.x_max - self.x_min
    }

    /// Height, px (negative for an inverted box).
    pub fn height(&self) -> f64 {
        self.y_max - self.y_min
    }

    /// Centre `(x, y)`, px.
    pub fn center(&self) -> (f64, f64) {
        (
            0.5 * (self.x_min + self.x_max),
            0.5 * (self.y_min + self.y_max),
        )
    }

    /// Area, px²; zero for an empty or inverted box.
    pub fn area(&self) -> f64 {
        self.width().max(0.0) * self.height().max(0.0)
    }

    /// The overlap of two boxes, `None` when they do not overlap.
    pub fn intersection(&self, other: &Self) -> Option<Self> {
        let b = Self {
            x_min: self.x_min.max(other.x_min),
            y_min: self.y_min.max(other.y_min),
            x_max: self.x_max.min(other.x_max),
            y_max: self.y_max.min(other.y_max),
        };
        (b.x_min < b.x_max && b.y_min < b.y_max).then_some(b)
    }

    /// Intersection over union in `[0, 1]`; 0 when either box is empty.
    pub fn iou(&self, other: &Self) -> f64 {
        let inter = self.intersection(other).map_or(0.0, |b| b.area());
        let union = self.area() + other.area() - inter;
        if union > 0.0 { inter / union } else { 0.0 }
    }

    /// The box grown by `margin_px` on every side (shrunk for a negative margin).
    pub fn enlarged(&self, margin_px: f64) -> Self {
        Self {
            x_min: self.x_min - margin_px,
            y_min: self.y_min - margin_px,
            x_max: self.x_max + margin_px,
            y_max: self.y_max + margin_px,
        }
    }

    /// The box clipped to a `width × height` image (`-0.5 ..= size - 0.5` on each axis),
    /// `None` when no area is left.
    pub fn clipped(&self, width: u32, height: u32) -> Option<Self> {
        let (w, h) = (f64::from(width) - 0.5, f64::from(height) - 0.5);
        Self::new(
            self.x_min.clamp(-0.5, w),
            self.y_min.clamp(-0.5, h),
            self.x_max.clamp(-0.5, w),
            self.y_max.clamp(-0.5, h),
        )
        .ok()
    }

    /// Whether the box lies inside a `width × height` image with at least `margin_px` to spare
    /// on every side (the image spans `-0.5 ..= width - 0.5`).
    pub fn is_inside_image(&self, width: u32, height: u32, margin_px: f64) -> bool {
        self.x_min >= -0.5 + margin_px
            && self.y_min >= -0.5 + margin_px
            && self.x_max <= f64::from(width) - 0.5 - margin_px
            && self.y_max <= f64::from(height) - 0.5 - margin_px
    }
}

/// One detection: a box, its confidence and its class.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Detection {
    /// The box in the detector's input image, px.
    pub bbox: BoundingBox,
    /// Confidence in `[0, 1]`.
    pub score: f32,
    /// Class index of the detector's model (0 = precariously balanced rock for ours).
    pub class_id: u32,
}

/// Finds targets in camera frames.
///
/// Implementations may keep state (a seeded random generator, a loaded network), hence
/// `&mut self`. Detections come back sorted by descending score.
pub trait Detector {
    /// Detects targets in one frame.
    ///
    /// # Errors
    /// [`DetectionError`] when the frame lacks what the detector needs (an instance mask for
    /// the simulated detector) or the model fails to run.
    fn detect(&mut self, frame: &RgbdFrame) -> Result<Vec<Detection>, DetectionError>;
}

/// Detection errors; each names what is wrong.
#[derive(Debug, thiserror::Error)]
pub enum DetectionError {
    /// A box with a non-finite edge or no area.
    #[error(
        "invalid bounding box {bbox:?}: edges must be finite with x_min < x_max, y_min < y_max"
    )]
    InvalidBox {
        /// The offending box.
        bbox: BoundingBox,
    },
    /// The frame lacks an input the detector needs.
    #[error("detector input: {0}")]
    MissingInput(String),
    /// A configuration value is out of range.
    #[error("detector config `{field}`: {reason}")]
    Config {
        /// The config field at fault.
        field: &'static str,
        /// Why it is wrong.
        reason: String,
    },
    /// The model file could not be loaded or run.
    #[error("detector model {path}: {reason}")]
    Model {
        /// The model file.
        path: String,
        /// What failed.
        reason: String,
    },
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn iou_of_known_boxes() {
        let a = BoundingBox::new(0.0, 0.0, 10.0, 10.0).unwrap();
        let b = BoundingBox::new(5.0, 0.0, 15.0, 10.0).unwrap();
        assert!((a.iou(&b) - 50.0 / 150.0).abs() < 1e-12);
        assert_eq!(a.iou(&a), 1.0);
        let far = BoundingBox::new(20.0, 20.0, 30.0, 30.0).unwrap();
        assert_eq!(a.iou(&far), 0.0);
    }

    #[test]
    fn rejects_degenerate_boxes() {
        assert!(BoundingBox::new(0.0, 0.0, 0.0, 10.0).is_err());
        assert!(BoundingBox::new(f64::NAN, 0.0, 1.0, 10.0).is_err());
        assert!(BoundingBox::new(5.0, 0.0, 1.0, 10.0).is_err());
    }

    #[test]
    fn inclusive_pixels_cover_whole_pixels() {
        let b = BoundingBox::from_inclusive_pixels([0, 0, 9, 4]);
        assert_eq!((b.width(), b.height()), (10.0, 5.0));
        assert!(b.is_inside_image(10, 5, 0.0));
        assert!(!b.is_inside_image(10, 5, 1.0));
    }

    #[test]
    fn clipping_to_the_image() {
        let b = BoundingBox::new(-10.0, 2.0, 5.0, 30.0).unwrap();
        assert_eq!(
            b.clipped(10, 20),
            Some(BoundingBox::new(-0.5, 2.0, 5.0, 19.5).unwrap())
        );
        assert_eq!(
            BoundingBox::new(20.0, 0.0, 30.0, 5.0)
                .unwrap()
                .clipped(10, 20),
            None
        );
    }
}
