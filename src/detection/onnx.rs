//! [`OnnxDetector`]: a YOLO v5/v8 export in ONNX, run with `tract-onnx` (pure Rust, nothing
//! downloaded at run time). Built with the `onnx` cargo feature.
//!
//! Per frame: [letterbox](super::letterbox) the RGB image into the network input, run the
//! network, [decode](super::yolo) the candidates above the score threshold, apply
//! [class-aware NMS](super::nms) in network pixels, then map the kept boxes back to the image
//! and clip them to it (boxes that lie wholly in the padding vanish).

use std::path::{Path, PathBuf};

use scarp_slam::frame::RgbdFrame;
use tract_onnx::prelude::{
    DatumExt, Framework, InferenceModelExt, IntoRunnable, Tensor, TypedRunnableModel, tvec,
};

use super::letterbox::Letterbox;
use super::nms::non_max_suppression;
use super::yolo::{OnnxDetectorConfig, decode};
use super::{Detection, DetectionError, Detector};

/// A YOLO network loaded from an ONNX file.
#[derive(Debug)]
pub struct OnnxDetector {
    config: OnnxDetectorConfig,
    path: PathBuf,
    plan: std::sync::Arc<TypedRunnableModel>,
}

impl OnnxDetector {
    /// Loads and optimises the model at `path` for a `[1, 3, input_height_px, input_width_px]`
    /// f32 input.
    ///
    /// # Errors
    /// [`DetectionError::Config`] from [`OnnxDetectorConfig::validate`];
    /// [`DetectionError::Model`] naming `path` when the file cannot be read or parsed, or the
    /// network does not accept that input.
    pub fn load(path: &Path, config: OnnxDetectorConfig) -> Result<Self, DetectionError> {
        config.validate()?;
        let model_error = |what: &str, e: &dyn std::fmt::Display| DetectionError::Model {
            path: path.display().to_string(),
            reason: format!("{what}: {e:#}"),
        };
        let shape = [
            1,
            3,
            config.input_height_px as usize,
            config.input_width_px as usize,
        ];
        let plan = tract_onnx::onnx()
            .model_for_path(path)
            .map_err(|e| model_error("cannot load the ONNX file", &e))?
            .with_input_fact(0, f32::fact(shape).into())
            .map_err(|e| model_error("cannot set the input shape", &e))?
            .into_optimized()
            .map_err(|e| model_error(&format!("cannot build the network for input {shape:?}"), &e))?
            .into_runnable()
            .map_err(|e| model_error("cannot plan the network", &e))?;
        Ok(Self {
            config,
            path: path.to_path_buf(),
            plan,
        })
    }

    /// The configuration.
    pub fn config(&self) -> &OnnxDetectorConfig {
        &self.config
    }

    /// Detections in an RGB image, boxes in the image's continuous pixel coordinates, sorted by
    /// descending score.
    ///
    /// # Errors
    /// [`DetectionError::Model`] naming the model file when the network fails or its output is
    /// not a YOLO layout; [`DetectionError::Config`] for an empty image.
    pub fn detect_rgb(
        &self,
        rgb: &scarp_slam::image::RgbImage,
    ) -> Result<Vec<Detection>, DetectionError> {
        let c = &self.config;
        let model_error = |reason: String| DetectionError::Model {
            path: self.path.display().to_string(),
            reason,
        };
        let letterbox = Letterbox::new(
            rgb.width(),
            rgb.height(),
            c.input_width_px,
            c.input_height_px,
        )?;
        let input = letterbox.apply(rgb)?;
        let shape = [1, 3, c.input_height_px as usize, c.input_width_px as usize];
        let tensor = Tensor::from_shape(&shape, &input)
            .map_err(|e| model_error(format!("cannot make the input tensor: {e:#}")))?;
        let outputs = self
            .plan
            .run(tvec!(tensor.into()))
            .map_err(|e| model_error(format!("inference failed: {e:#}")))?;
        let output = outputs
            .first()
            .ok_or_else(|| model_error("the network has no output".into()))?;
        let values = output
            .to_plain_array_view::<f32>()
            .map_err(|e| model_error(format!("output is not f32: {e:#}")))?;
        let flat: Vec<f32> = values.iter().copied().collect();
        let candidates =
            decode(&flat, output.shape(), c.layout, c.score_threshold).map_err(|e| match e {
                DetectionError::Model { reason, .. } => model_error(reason),
                other => other,
            })?;
        let kept = non_max_suppression(&candidates, c.iou_threshold, c.max_detections);
        Ok(kept
            .into_iter()
            .filter_map(|d| {
                let bbox = letterbox
                    .to_image(&d.bbox)
                    .clipped(rgb.width(), rgb.height())?;
                Some(Detection { bbox, ..d })
            })
            .collect())
    }
}

impl Detector for OnnxDetector {
    /// # Errors
    /// As [`OnnxDetector::detect_rgb`].
    fn detect(&mut self, frame: &RgbdFrame) -> Result<Vec<Detection>, DetectionError> {
        self.detect_rgb(&frame.rgb)
    }
}
