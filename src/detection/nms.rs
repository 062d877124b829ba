//! Class-aware non-maximum suppression.

use std::cmp::Ordering;

use super::Detection;

/// Greedy class-aware non-maximum suppression: visiting detections by descending score (ties
/// keep their input order), keep one unless a kept detection of the **same class** overlaps it
/// with IoU above `iou_threshold`. At most `max_detections` are kept.
///
/// The result is sorted by descending score, and no two kept detections of one class have
/// IoU > `iou_threshold`. Detections with a NaN score are dropped.
pub fn non_max_suppression(
    detections: &[Detection],
    iou_threshold: f64,
    max_detections: usize,
) -> Vec<Detection> {
    let mut order: Vec<usize> = (0..detections.len())
        .filter(|&i| !detections[i].score.is_nan())
        .collect();
    order.sort_by(|&a, &b| by_descending_score(&detections[a], &detections[b]).then(a.cmp(&b)));
    let mut kept: Vec<Detection> = Vec::new();
    for i in order {
        if kept.len() >= max_detections {
            break;
        }
        let d = detections[i];
        let suppressed = kept
            .iter()
            .any(|k| k.class_id == d.class_id && k.bbox.iou(&d.bbox) > iou_threshold);
        if !suppressed {
            kept.push(d);
        }
    }
    kept
}

/// Orders detections by descending score.
pub fn by_descending_score(a: &Detection, b: &Detection) -> Ordering {
    b.score.total_cmp(&a.score)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::detection::BoundingBox;
    use proptest::prelude::*;

    fn det(x0: f64, y0: f64, x1: f64, y1: f64, score: f32, class_id: u32) -> Detection {
        Detection {
            bbox: BoundingBox::new(x0, y0, x1, y1).unwrap(),
            score,
            class_id,
        }
    }

    #[test]
    fn hand_computed_cases() {
        let a = det(0.0, 0.0, 10.0, 10.0, 0.9, 0);
        // IoU(a, b) = 90 / 110 = 0.818: suppressed at 0.5.
        let b = det(1.0, 0.0, 11.0, 10.0, 0.8, 0);
        // IoU(a, c) = 50 / 150 = 0.333: kept at 0.5, suppressed at 0.3.
        let c = det(5.0, 0.0, 15.0, 10.0, 0.7, 0);
        // Same box as b, other class: kept.
        let d = det(1.0, 0.0, 11.0, 10.0, 0.6, 1);
        let all = [c, b, d, a];
        assert_eq!(non_max_suppression(&all, 0.5, 100), vec![a, c, d]);
        assert_eq!(non_max_suppression(&all, 0.3, 100), vec![a, d]);
        // Threshold 0.9: nothing overlaps that much.
        assert_eq!(non_max_suppression(&all, 0.9, 100), vec![a, b, c, d]);
        assert_eq!(non_max_suppression(&all, 0.5, 2), vec![a, c]);
        assert!(non_max_suppression(&[], 0.5, 10).is_empty());
        // A NaN score never survives; ties keep input order.
        let nan = det(50.0, 50.0, 60.0, 60.0, f32::NAN, 0);
        let tie = det(20.0, 20.0, 30.0, 30.0, 0.9, 0);
        assert_eq!(non_max_suppression(&[nan, tie, a], 0.5, 10), vec![tie, a]);
    }

    fn arb_detection() -> impl Strategy<Value = Detection> {
        (
            0.0..100.0f64,
            0.0..100.0f64,
            1.0..40.0f64,
            1.0..40.0f64,
            0.0..1.0f32,
            0..3u32,
        )
            .prop_map(|(x, y, w, h, score, class_id)| det(x, y, x + w, y + h, score, class_id))
    }

    proptest! {
        #[test]
        fn kept_boxes_of_one_class_never_overlap_above_threshold(
            dets in proptest::collection::vec(arb_detection(), 0..60),
            iou in 0.05..0.95f64,
        ) {
            let kept = non_max_suppression(&dets, iou, usize::MAX);
            for (i, a) in kept.iter().enumerate() {
                for b in &kept[i + 1..] {
                    if a.class_id == b.class_id {
                        prop_assert!(a.bbox.iou(&b.bbox) <= iou);
                    }
                }
            }
            prop_assert!(kept.windows(2).all(|p| p[0].score >= p[1].score));
            // Every dropped detection is covered by a kept one of its class scoring at least
            // as high.
            for d in &dets {
                if !kept.contains(d) {
                    prop_assert!(kept.iter().any(|k| k.class_id == d.class_id
                        && k.score >= d.score
                        && k.bbox.iou(&d.bbox) > iou));
                }
            }
            // The top-scoring detection always survives.
            if let Some(best) = dets.iter().max_by(|a, b| a.score.total_cmp(&b.score)) {
                prop_assert!(kept.iter().any(|k| k.score == best.score));
            }
        }
    }
}
