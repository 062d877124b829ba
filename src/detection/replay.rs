//! A detector that replays recorded boxes: a sequence's `boxes.txt`, or any other detector's
//! output saved with timestamps.

use scarp_slam::frame::RgbdFrame;

use super::{Detection, DetectionError, Detector};

/// Two timestamps closer than this are the same frame, seconds.
const SAME_FRAME_S: f64 = 1e-3;

/// Replays timestamped detections: each frame gets the detections recorded at its timestamp
/// (within a millisecond), in the order they were given.
#[derive(Debug, Clone, Default)]
pub struct ReplayDetector {
    detections: Vec<(f64, Detection)>,
}

impl ReplayDetector {
    /// Detections with the timestamps of the frames they belong to, seconds.
    pub fn new(detections: Vec<(f64, Detection)>) -> Self {
        Self { detections }
    }
}

impl Detector for ReplayDetector {
    /// Never fails: a frame with no recorded detection gets none.
    fn detect(&mut self, frame: &RgbdFrame) -> Result<Vec<Detection>, DetectionError> {
        Ok(self
            .detections
            .iter()
            .filter(|(t, _)| (t - frame.timestamp_s).abs() < SAME_FRAME_S)
            .map(|(_, d)| *d)
            .collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::detection::BoundingBox;
    use scarp_slam::image::Image;

    #[test]
    fn replays_the_boxes_of_each_frame() {
        let detection = |x: f64| Detection {
            bbox: BoundingBox::new(x, 0.0, x + 5.0, 5.0).unwrap(),
            score: 1.0,
            class_id: 0,
        };
        let mut replay = ReplayDetector::new(vec![
            (0.0, detection(1.0)),
            (0.1, detection(2.0)),
            (0.1, detection(3.0)),
        ]);
        let frame = |t: f64| {
            RgbdFrame::new(
                t,
                Image::filled(4, 3, [0u8; 3]),
                Image::filled(4, 3, 1.0f32),
                None,
            )
            .unwrap()
        };
        assert_eq!(replay.detect(&frame(0.0)).unwrap(), vec![detection(1.0)]);
        assert_eq!(
            replay.detect(&frame(0.1)).unwrap(),
            vec![detection(2.0), detection(3.0)]
        );
        assert!(replay.detect(&frame(0.5)).unwrap().is_empty());
    }
}
