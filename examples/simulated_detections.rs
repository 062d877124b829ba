//! Runs the simulated detector (default model) over a rendered sequence and compares its boxes
//! with the ground truth of `boxes.txt`: target recall, mean IoU of matched target boxes, and
//! false positives per frame.
//!
//! ```sh
//! scarp render --path lawnmower --frames 300 --out /tmp/survey
//! cargo run --example simulated_detections -- /tmp/survey
//! ```

use std::collections::BTreeMap;
use std::path::PathBuf;

use anyhow::Context;
use scarp::detection::simulated::roles_from_boxes;
use scarp::detection::{BoundingBox, Detector, SimulatedDetector, SimulatedDetectorConfig};
use scarp_datasets::sequence::Sequence;
use scarp_datasets::world::RockRole;

fn main() -> anyhow::Result<()> {
    let dir: PathBuf = std::env::args_os()
        .nth(1)
        .context("usage: simulated_detections SEQUENCE_DIR")?
        .into();
    let seq = Sequence::open(&dir)?;
    let mut detector = SimulatedDetector::new(
        SimulatedDetectorConfig::default(),
        roles_from_boxes(&seq.boxes),
    )?;
    // Truth boxes by frame timestamp (bit pattern, as written and read back).
    let mut truth: BTreeMap<u64, Vec<(RockRole, BoundingBox)>> = BTreeMap::new();
    for b in &seq.boxes {
        truth
            .entry(b.timestamp_s.to_bits())
            .or_default()
            .push((b.role, BoundingBox::from_inclusive_pixels(b.bbox_px)));
    }
    let (mut target_boxes, mut matched, mut iou_sum, mut false_positives) = (0, 0, 0.0, 0);
    for i in 0..seq.len() {
        let frame = seq.load_frame(i)?;
        let dets = detector.detect(&frame)?;
        let frame_truth = truth
            .get(&frame.timestamp_s.to_bits())
            .cloned()
            .unwrap_or_default();
        let targets: Vec<BoundingBox> = frame_truth
            .iter()
            .filter(|(r, _)| *r == RockRole::Target)
            .map(|(_, b)| *b)
            .collect();
        target_boxes += targets.len();
        for d in &dets {
            let best = targets.iter().map(|t| t.iou(&d.bbox)).fold(0.0, f64::max);
            if best >= 0.3 {
                matched += 1;
                iou_sum += best;
            } else {
                false_positives += 1;
            }
        }
    }
    println!(
        "{} frames, {} visible target boxes, {} matched (recall {:.3}), mean IoU {:.3}, \
         {} false positives ({:.3} per frame)",
        seq.len(),
        target_boxes,
        matched,
        matched as f64 / target_boxes.max(1) as f64,
        iou_sum / matched.max(1) as f64,
        false_positives,
        false_positives as f64 / seq.len().max(1) as f64
    );
    Ok(())
}
