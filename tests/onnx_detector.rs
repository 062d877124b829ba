//! `OnnxDetector` on the tiny YOLO fixtures made by `tests/fixtures/make_tiny_yolo.py`: known
//! inputs give known boxes after letterbox mapping, score threshold and class-aware NMS.
//!
//! The fixtures answer eight fixed candidates (in 64 × 64 input pixels) whose scores are
//! multiplied by the brightest input value; see the script for the table.
#![cfg(feature = "onnx")]

use std::path::PathBuf;

use scarp::detection::letterbox::PAD_VALUE;
use scarp::detection::{
    BoundingBox, Detection, DetectionError, Detector, OnnxDetector, OnnxDetectorConfig,
};
use scarp_slam::frame::RgbdFrame;
use scarp_slam::image::{DepthImage, RgbImage};

fn fixture(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(name)
}

fn config() -> OnnxDetectorConfig {
    OnnxDetectorConfig {
        input_width_px: 64,
        input_height_px: 64,
        ..OnnxDetectorConfig::default()
    }
}

fn boxes(dets: &[Detection]) -> Vec<([f64; 4], u32)> {
    dets.iter()
        .map(|d| {
            let b = d.bbox;
            ([b.x_min, b.y_min, b.x_max, b.y_max], d.class_id)
        })
        .collect()
}

/// The kept candidates A, C, E, F of the script mapped into a 128 × 64 image: scale 0.5,
/// 16 rows of padding above, so `x = x_in / 0.5 − 0.5` and `y = (y_in − 16) / 0.5 − 0.5`.
/// B is suppressed by A (IoU 0.88), D and H fall below 0.25, and G lies in the padding.
const EXPECTED_WIDE: [([f64; 4], u32); 4] = [
    ([23.5, 7.5, 55.5, 23.5], 0),  // A, 0.9
    ([25.5, 7.5, 57.5, 23.5], 1),  // C, 0.7: same place as B, other class
    ([87.5, -0.5, 103.5, 3.5], 0), // E, 0.6: clipped at the top
    ([39.5, 7.5, 71.5, 23.5], 0),  // F, 0.5: IoU 0.33 with A
];

#[test]
fn white_wide_image_gives_the_known_boxes_for_v8_and_v5() {
    let white = RgbImage::filled(128, 64, [255, 255, 255]);
    for name in ["tiny_yolov8.onnx", "tiny_yolov5.onnx"] {
        let det = OnnxDetector::load(&fixture(name), config()).unwrap();
        let got = det.detect_rgb(&white).unwrap();
        assert_eq!(boxes(&got), EXPECTED_WIDE.to_vec(), "{name}");
        let scores: Vec<f32> = got.iter().map(|d| d.score).collect();
        assert_eq!(scores, vec![0.9, 0.7, 0.6, 0.5], "{name}");
    }
}

#[test]
fn black_square_gives_nothing_and_grey_padding_scales_scores() {
    let det = OnnxDetector::load(&fixture("tiny_yolov8.onnx"), config()).unwrap();
    // No padding, brightest value 0: every score is 0.
    let black = RgbImage::filled(64, 64, [0, 0, 0]);
    assert!(det.detect_rgb(&black).unwrap().is_empty());
    // Padding makes the brightest value 114/255: scores 0.9, 0.7, 0.6 become 0.40, 0.31,
    // 0.27 (kept), F's 0.5 becomes 0.22 (< 0.25, dropped).
    let wide_black = RgbImage::filled(128, 64, [0, 0, 0]);
    let got = det.detect_rgb(&wide_black).unwrap();
    assert_eq!(boxes(&got), EXPECTED_WIDE[..3].to_vec());
    for (d, s) in got.iter().zip([0.9f32, 0.7, 0.6]) {
        assert!(
            (d.score - s * PAD_VALUE).abs() < 1e-6,
            "{} vs {}",
            d.score,
            s * PAD_VALUE
        );
    }
}

#[test]
fn detector_trait_and_nms_threshold() {
    let mut det = OnnxDetector::load(
        &fixture("tiny_yolov8.onnx"),
        OnnxDetectorConfig {
            // A stricter NMS: F (IoU 0.33 with A) is now suppressed.
            iou_threshold: 0.3,
            ..config()
        },
    )
    .unwrap();
    let frame = RgbdFrame::new(
        0.0,
        RgbImage::filled(128, 64, [255, 255, 255]),
        DepthImage::filled(128, 64, 0.0),
        None,
    )
    .unwrap();
    let got = det.detect(&frame).unwrap();
    assert_eq!(boxes(&got), EXPECTED_WIDE[..3].to_vec());
    // A square image maps boxes one to one (edges → centres: −0.5).
    let square = det
        .detect_rgb(&RgbImage::filled(64, 64, [255, 0, 0]))
        .unwrap();
    assert_eq!(
        square[0].bbox,
        BoundingBox::new(11.5, 19.5, 27.5, 27.5).unwrap()
    );
}

#[test]
fn bad_model_files_name_the_path() {
    let dir = tempfile::tempdir().unwrap();
    let garbage = dir.path().join("garbage.onnx");
    std::fs::write(&garbage, b"this is not a protobuf model").unwrap();
    let missing = dir.path().join("missing.onnx");
    for path in [garbage, missing] {
        match OnnxDetector::load(&path, config()) {
            Err(DetectionError::Model { path: p, .. }) => {
                assert_eq!(p, path.display().to_string());
            }
            other => panic!(
                "expected a model error for {}, got {other:?}",
                path.display()
            ),
        }
    }
    let bad = OnnxDetectorConfig {
        score_threshold: 1.5,
        ..config()
    };
    assert!(matches!(
        OnnxDetector::load(&fixture("tiny_yolov8.onnx"), bad),
        Err(DetectionError::Config {
            field: "score_threshold",
            ..
        })
    ));
}
