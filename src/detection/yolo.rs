//! Decoding the raw output of YOLO exports (Ultralytics v5 and v8 layouts) into candidate
//! detections in the network input's pixels (edge coordinates, see [`super::letterbox`]).
//!
//! - **v8** (and v9–v11): one output `[1, 4 + nc, N]`; for each of the `N` candidates the
//!   rows give `cx, cy, w, h` and then one score per class. The score is the class score.
//! - **v5** (and v7): one output `[1, N, 5 + nc]`; each candidate row is
//!   `cx, cy, w, h, objectness, class scores…`. The score is objectness × class score.
//!
//! Each candidate keeps only its best class, as the Ultralytics post-processing does.

use super::{BoundingBox, Detection, DetectionError};

/// Which output layout a model has.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum YoloLayout {
    /// Decided from the output shape `[1, a, b]`: v8 when `a < b` (there are far more
    /// candidates than classes in any real model), v5 otherwise.
    #[default]
    Auto,
    /// `[1, N, 5 + nc]` with objectness.
    V5,
    /// `[1, 4 + nc, N]` without objectness.
    V8,
}

impl YoloLayout {
    /// The concrete layout of an output of shape `shape`.
    ///
    /// # Errors
    /// [`DetectionError::Model`] (path `output`) when the shape is not `[1, a, b]` or too small
    /// for the layout (fewer than 1 class).
    pub fn resolve(self, shape: &[usize]) -> Result<Self, DetectionError> {
        let bad = |reason: String| DetectionError::Model {
            path: "output".into(),
            reason,
        };
        let [1, a, b] = *shape else {
            return Err(bad(format!(
                "expected a YOLO output of shape [1, a, b], got {shape:?}"
            )));
        };
        let layout = match self {
            Self::Auto if a < b => Self::V8,
            Self::Auto => Self::V5,
            other => other,
        };
        let (channels, needed) = match layout {
            Self::V8 => (a, 5),
            _ => (b, 6),
        };
        if channels < needed {
            return Err(bad(format!(
                "output {shape:?} read as {layout:?} has {channels} values per candidate, \
                 needs at least {needed} (box, {}one class)",
                if layout == Self::V8 {
                    ""
                } else {
                    "objectness, "
                }
            )));
        }
        Ok(layout)
    }
}

/// Candidates of a raw output `values` (row-major, of shape `shape`) scoring at least
/// `score_threshold`, boxes in network-input pixels. Candidates with a non-finite value or a
/// box without area are skipped. Order: candidate order of the output.
///
/// # Errors
/// As [`YoloLayout::resolve`], and [`DetectionError::Model`] when `values` does not hold
/// `shape`'s element count.
pub fn decode(
    values: &[f32],
    shape: &[usize],
    layout: YoloLayout,
    score_threshold: f32,
) -> Result<Vec<Detection>, DetectionError> {
    let layout = layout.resolve(shape)?;
    let (a, b) = (shape[1], shape[2]);
    if values.len() != a * b {
        return Err(DetectionError::Model {
            path: "output".into(),
            reason: format!(
                "output of shape {shape:?} holds {} values, expected {}",
                values.len(),
                a * b
            ),
        });
    }
    let (count, channels) = match layout {
        YoloLayout::V8 => (b, a),
        _ => (a, b),
    };
    // Value `k` of candidate `n`.
    let at = |n: usize, k: usize| match layout {
        YoloLayout::V8 => values[k * b + n],
        _ => values[n * b + k],
    };
    let first_class = if layout == YoloLayout::V8 { 4 } else { 5 };
    let mut out = Vec::new();
    for n in 0..count {
        let (class_id, class_score) = (first_class..channels)
            .map(|k| (k - first_class, at(n, k)))
            .fold(
                (0, f32::NEG_INFINITY),
                |best, c| {
                    if c.1 > best.1 { c } else { best }
                },
            );
        let score = if layout == YoloLayout::V8 {
            class_score
        } else {
            at(n, 4) * class_score
        };
        if !(score.is_finite() && score >= score_threshold) {
            continue;
        }
        let [cx, cy, w, h] = [0, 1, 2, 3].map(|k| f64::from(at(n, k)));
        let bbox = BoundingBox::from_center_size(cx, cy, w, h);
        if BoundingBox::new(bbox.x_min, bbox.y_min, bbox.x_max, bbox.y_max).is_err() {
            continue;
        }
        out.push(Detection {
            bbox,
            score,
            // A class index below the channel count: fits in u32 for any real model.
            class_id: u32::try_from(class_id).unwrap_or(u32::MAX),
        });
    }
    Ok(out)
}

/// Tunables of the ONNX YOLO detector (`OnnxDetector`, feature `onnx`): input size and
/// post-processing. The defaults are those of Ultralytics' `predict`.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct OnnxDetectorConfig {
    /// Network input width, px. Default 640 (the YOLO export default).
    pub input_width_px: u32,
    /// Network input height, px. Default 640.
    pub input_height_px: u32,
    /// Lowest score kept (class score for v8, objectness × class score for v5). Default 0.25.
    pub score_threshold: f32,
    /// Boxes of one class overlapping a higher-scoring one by more than this IoU are
    /// suppressed. Default 0.45.
    pub iou_threshold: f64,
    /// Most detections returned per frame. Default 300.
    pub max_detections: usize,
    /// Output layout. Default [`YoloLayout::Auto`] (from the output shape).
    pub layout: YoloLayout,
}

impl Default for OnnxDetectorConfig {
    fn default() -> Self {
        Self {
            input_width_px: 640,
            input_height_px: 640,
            score_threshold: 0.25,
            iou_threshold: 0.45,
            max_detections: 300,
            layout: YoloLayout::Auto,
        }
    }
}

impl OnnxDetectorConfig {
    /// Checks every field.
    ///
    /// # Errors
    /// [`DetectionError::Config`] naming the field: a zero input size, a threshold outside
    /// `[0, 1]`, or `max_detections` of 0.
    pub fn validate(&self) -> Result<(), DetectionError> {
        let bad =
            |field: &'static str, reason: String| Err(DetectionError::Config { field, reason });
        if self.input_width_px == 0 {
            return bad("input_width_px", "must be positive".into());
        }
        if self.input_height_px == 0 {
            return bad("input_height_px", "must be positive".into());
        }
        if !(0.0..=1.0).contains(&self.score_threshold) {
            return bad(
                "score_threshold",
                format!("must lie in [0, 1], got {}", self.score_threshold),
            );
        }
        if !(0.0..=1.0).contains(&self.iou_threshold) {
            return bad(
                "iou_threshold",
                format!("must lie in [0, 1], got {}", self.iou_threshold),
            );
        }
        if self.max_detections == 0 {
            return bad("max_detections", "must be positive".into());
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layouts_from_shapes() {
        assert_eq!(
            YoloLayout::Auto.resolve(&[1, 84, 8400]).unwrap(),
            YoloLayout::V8
        );
        assert_eq!(
            YoloLayout::Auto.resolve(&[1, 25200, 85]).unwrap(),
            YoloLayout::V5
        );
        assert!(YoloLayout::Auto.resolve(&[84, 8400]).is_err());
        assert!(YoloLayout::Auto.resolve(&[2, 84, 8400]).is_err());
        assert!(YoloLayout::V5.resolve(&[1, 10, 5]).is_err());
        assert!(YoloLayout::V8.resolve(&[1, 4, 10]).is_err());
    }

    #[test]
    fn decodes_v8_and_v5_alike() {
        // Two candidates, two classes. v8: rows cx, cy, w, h, s0, s1.
        let v8 = [
            10.0, 30.0, // cx
            20.0, 40.0, // cy
            4.0, 6.0, // w
            8.0, 2.0, // h
            0.2, 0.9, // class 0
            0.7, 0.1, // class 1
        ];
        let got = decode(&v8, &[1, 6, 2], YoloLayout::V8, 0.5).unwrap();
        assert_eq!(got.len(), 2);
        assert_eq!(got[0].class_id, 1);
        assert_eq!(got[0].score, 0.7);
        assert_eq!(
            got[0].bbox,
            BoundingBox::new(8.0, 16.0, 12.0, 24.0).unwrap()
        );
        assert_eq!((got[1].class_id, got[1].score), (0, 0.9));
        // v5: rows of cx, cy, w, h, objectness, s0, s1; score = objectness × class.
        let v5 = [
            10.0, 20.0, 4.0, 8.0, 0.5, 0.2, 1.0, //
            30.0, 40.0, 6.0, 2.0, 1.0, 0.9, 0.1,
        ];
        let got = decode(&v5, &[1, 2, 7], YoloLayout::V5, 0.5).unwrap();
        assert_eq!(got.len(), 2);
        assert_eq!((got[0].class_id, got[0].score), (1, 0.5));
        assert_eq!((got[1].class_id, got[1].score), (0, 0.9));
        // Threshold, non-finite values and empty boxes drop candidates.
        let mut v5b = v5;
        v5b[7] = f32::NAN;
        assert_eq!(
            decode(&v5b, &[1, 2, 7], YoloLayout::V5, 0.5).unwrap().len(),
            1
        );
        v5b[2] = 0.0;
        assert!(
            decode(&v5b, &[1, 2, 7], YoloLayout::V5, 0.5)
                .unwrap()
                .is_empty()
        );
        assert!(
            decode(&v5, &[1, 2, 7], YoloLayout::V5, 0.95)
                .unwrap()
                .is_empty()
        );
        assert!(decode(&v5[..10], &[1, 2, 7], YoloLayout::V5, 0.5).is_err());
    }
}
