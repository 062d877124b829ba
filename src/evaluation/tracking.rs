//! Multi-target tracking scores against ground-truth boxes (CLEAR MOT, Bernardin & Stiefelhagen
//! 2008), plus the false-track figures of issue #6.
//!
//! Per frame, reported tracks are matched one-to-one to the true target boxes at IoU ≥
//! `match_iou`: a pair matched in the previous frame is kept while its IoU stays above the
//! threshold (CLEAR MOT's rule), the rest are matched greedily by decreasing IoU. Then:
//! - a true target box without a track is a miss (false negative);
//! - a track without a true target box is a false positive, unless it overlaps an ignored box
//!   at `match_iou` (see below);
//! - a true target whose matched track id differs from the id it last matched is an ID switch.
//!   The memory of the last id is cleared when the target leaves the scored area (no scored
//!   box in a frame): the tracker deregisters boxes that leave the image, by design (paper
//!   §II), so a target that comes back in a later pass gets a new id without a switch.
//!
//! `MOTA = 1 − (misses + false positives + ID switches) / true target boxes`.
//!
//! Ignored ("don't care") boxes: true target boxes closer than `border_margin_px` to the image
//! border (the tracker drops those by design), or narrower or shorter than `min_box_px`.
//! They count neither as misses nor, when a track covers them, as false positives.
//!
//! A false track is a track id that never matched a true target box in any frame. Its
//! lifetime is the time from its first to its last reported frame.

use std::collections::{BTreeMap, BTreeSet, HashMap};

use serde::{Deserialize, Serialize};

use crate::detection::BoundingBox;

/// Scoring parameters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TrackingEvalConfig {
    /// IoU for a track to match a true box. Default 0.5 (the usual CLEAR MOT threshold for
    /// boxes).
    pub match_iou: f64,
    /// True boxes closer than this to the image border are ignored, px. Default 5 (the
    /// tracker's deregistration margin).
    pub border_margin_px: f64,
    /// True boxes narrower or shorter than this are ignored, px. Default 8 (too small for any
    /// detector to be held to).
    pub min_box_px: f64,
}

impl Default for TrackingEvalConfig {
    fn default() -> Self {
        Self {
            match_iou: 0.5,
            border_margin_px: 5.0,
            min_box_px: 8.0,
        }
    }
}

/// A reported track box in one frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackObservation {
    /// Track id.
    pub id: u64,
    /// Box, px.
    pub bbox: BoundingBox,
}

/// A true box in one frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TruthBox {
    /// Object id (rock id).
    pub id: u32,
    /// Whether the object is a target (distractors are not to be tracked).
    pub is_target: bool,
    /// Box, px.
    pub bbox: BoundingBox,
}

/// One frame to score.
#[derive(Debug, Clone, PartialEq)]
pub struct EvalFrame {
    /// Frame time, s.
    pub timestamp_s: f64,
    /// Reported (confirmed) tracks.
    pub tracks: Vec<TrackObservation>,
    /// True boxes (targets and distractors).
    pub truth: Vec<TruthBox>,
}

/// Tracking scores over a sequence.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrackingScores {
    /// Frames scored.
    pub frames: usize,
    /// Distinct reported track ids.
    pub tracks: usize,
    /// True target boxes scored (ignored ones excluded).
    pub truth_boxes: usize,
    /// Track–truth matches.
    pub matches: usize,
    /// True target boxes without a track.
    pub misses: usize,
    /// Track boxes without a true target box (ignored boxes excluded).
    pub false_positives: usize,
    /// ID switches on targets.
    pub id_switches: usize,
    /// `1 − (misses + false positives + ID switches) / truth boxes`; 1 with no truth boxes and
    /// no errors.
    pub mota: f64,
    /// Mean IoU of matched track boxes with their true boxes; 0 with no matches.
    pub mean_iou: f64,
    /// Track ids that never matched a true target box.
    pub false_tracks: usize,
    /// Longest lifetime of a false track, s (0 without false tracks).
    pub false_track_max_lifetime_s: f64,
    /// Mean lifetime of the false tracks, s (0 without false tracks).
    pub false_track_mean_lifetime_s: f64,
    /// Distinct targets that were matched at least once.
    pub targets_tracked: usize,
    /// Distinct targets with at least one scored (not ignored) box.
    pub targets_seen: usize,
}

/// Whether a true box is ignored.
fn ignored(b: &BoundingBox, width: u32, height: u32, config: &TrackingEvalConfig) -> bool {
    !b.is_inside_image(width, height, config.border_margin_px)
        || b.width() < config.min_box_px
        || b.height() < config.min_box_px
}

/// Scores `frames` (in time order) of a `width × height` image sequence.
pub fn evaluate_tracking(
    frames: &[EvalFrame],
    width: u32,
    height: u32,
    config: &TrackingEvalConfig,
) -> TrackingScores {
    let mut last_match: HashMap<u32, u64> = HashMap::new();
    // Pairs matched in the previous frame: truth id → track id.
    let mut previous_pairs: HashMap<u32, u64> = HashMap::new();
    let mut matched_ids: BTreeSet<u64> = BTreeSet::new();
    let mut lifetimes: BTreeMap<u64, (f64, f64)> = BTreeMap::new();
    let (mut truth_boxes, mut matches, mut misses, mut false_positives, mut switches) =
        (0usize, 0usize, 0usize, 0usize, 0usize);
    let mut iou_sum = 0.0;
    let mut targets_seen: BTreeSet<u32> = BTreeSet::new();
    let mut targets_tracked: BTreeSet<u32> = BTreeSet::new();

    for frame in frames {
        // Forget the ids of targets that left the scored area.
        let present: BTreeSet<u32> = frame
            .truth
            .iter()
            .filter(|g| g.is_target && !ignored(&g.bbox, width, height, config))
            .map(|g| g.id)
            .collect();
        last_match.retain(|id, _| present.contains(id));
        for t in &frame.tracks {
            let e = lifetimes
                .entry(t.id)
                .or_insert((frame.timestamp_s, frame.timestamp_s));
            e.1 = frame.timestamp_s;
        }
        let (scored, dont_care): (Vec<&TruthBox>, Vec<&TruthBox>) = frame
            .truth
            .iter()
            .filter(|g| g.is_target)
            .partition(|g| !ignored(&g.bbox, width, height, config));
        truth_boxes += scored.len();
        targets_seen.extend(scored.iter().map(|g| g.id));

        let mut truth_used = vec![false; scored.len()];
        let mut track_used = vec![false; frame.tracks.len()];
        let mut pairs: Vec<(usize, usize, f64)> = Vec::new();
        // Keep last frame's pairs that still overlap.
        for (gi, g) in scored.iter().enumerate() {
            if let Some(&tid) = previous_pairs.get(&g.id)
                && let Some(ti) = frame.tracks.iter().position(|t| t.id == tid)
            {
                let iou = frame.tracks[ti].bbox.iou(&g.bbox);
                if iou >= config.match_iou && !track_used[ti] {
                    truth_used[gi] = true;
                    track_used[ti] = true;
                    pairs.push((gi, ti, iou));
                }
            }
        }
        // Greedy by IoU for the rest.
        let mut candidates: Vec<(f64, usize, usize)> = Vec::new();
        for (gi, g) in scored.iter().enumerate() {
            for (ti, t) in frame.tracks.iter().enumerate() {
                if truth_used[gi] || track_used[ti] {
                    continue;
                }
                let iou = t.bbox.iou(&g.bbox);
                if iou >= config.match_iou {
                    candidates.push((iou, gi, ti));
                }
            }
        }
        candidates.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)).then(a.2.cmp(&b.2)));
        for (iou, gi, ti) in candidates {
            if !truth_used[gi] && !track_used[ti] {
                truth_used[gi] = true;
                track_used[ti] = true;
                pairs.push((gi, ti, iou));
            }
        }

        previous_pairs.clear();
        for &(gi, ti, iou) in &pairs {
            let (gid, tid) = (scored[gi].id, frame.tracks[ti].id);
            if let Some(&prev) = last_match.get(&gid)
                && prev != tid
            {
                switches += 1;
            }
            last_match.insert(gid, tid);
            previous_pairs.insert(gid, tid);
            matched_ids.insert(tid);
            targets_tracked.insert(gid);
            iou_sum += iou;
        }
        matches += pairs.len();
        misses += scored.len() - pairs.len();
        for (ti, t) in frame.tracks.iter().enumerate() {
            if track_used[ti] {
                continue;
            }
            let on_ignored = dont_care
                .iter()
                .any(|g| t.bbox.iou(&g.bbox) >= config.match_iou);
            if on_ignored {
                // A track on a target that is leaving or too small is not false.
                matched_ids.insert(t.id);
            } else {
                false_positives += 1;
            }
        }
    }

    let false_lifetimes: Vec<f64> = lifetimes
        .iter()
        .filter(|(id, _)| !matched_ids.contains(id))
        .map(|(_, (first, last))| last - first)
        .collect();
    let errors = misses + false_positives + switches;
    TrackingScores {
        frames: frames.len(),
        tracks: lifetimes.len(),
        truth_boxes,
        matches,
        misses,
        false_positives,
        id_switches: switches,
        mota: if truth_boxes > 0 {
            1.0 - errors as f64 / truth_boxes as f64
        } else if errors == 0 {
            1.0
        } else {
            f64::NEG_INFINITY
        },
        mean_iou: if matches > 0 {
            iou_sum / matches as f64
        } else {
            0.0
        },
        false_tracks: false_lifetimes.len(),
        false_track_max_lifetime_s: false_lifetimes.iter().copied().fold(0.0, f64::max),
        false_track_mean_lifetime_s: if false_lifetimes.is_empty() {
            0.0
        } else {
            false_lifetimes.iter().sum::<f64>() / false_lifetimes.len() as f64
        },
        targets_tracked: targets_tracked.len(),
        targets_seen: targets_seen.len(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bx(x: f64, y: f64) -> BoundingBox {
        BoundingBox::new(x, y, x + 40.0, y + 40.0).unwrap()
    }

    fn frame(t: f64, tracks: &[(u64, f64, f64)], truth: &[(u32, bool, f64, f64)]) -> EvalFrame {
        EvalFrame {
            timestamp_s: t,
            tracks: tracks
                .iter()
                .map(|&(id, x, y)| TrackObservation { id, bbox: bx(x, y) })
                .collect(),
            truth: truth
                .iter()
                .map(|&(id, is_target, x, y)| TruthBox {
                    id,
                    is_target,
                    bbox: bx(x, y),
                })
                .collect(),
        }
    }

    #[test]
    fn perfect_tracking_scores_one() {
        let frames: Vec<_> = (0..5)
            .map(|k| {
                let x = 50.0 + 10.0 * f64::from(k);
                frame(0.05 * f64::from(k), &[(1, x, 60.0)], &[(3, true, x, 60.0)])
            })
            .collect();
        let s = evaluate_tracking(&frames, 320, 240, &TrackingEvalConfig::default());
        assert_eq!(
            (s.matches, s.misses, s.false_positives, s.id_switches),
            (5, 0, 0, 0)
        );
        assert_eq!(s.mota, 1.0);
        assert!((s.mean_iou - 1.0).abs() < 1e-12);
        assert_eq!((s.tracks, s.false_tracks, s.targets_tracked), (1, 0, 1));
    }

    #[test]
    fn counts_switches_misses_false_positives_and_false_tracks() {
        let frames = vec![
            // Target 3 tracked by 1; track 9 sits on a distractor.
            frame(
                0.0,
                &[(1, 50.0, 60.0), (9, 200.0, 100.0)],
                &[(3, true, 50.0, 60.0), (4, false, 200.0, 100.0)],
            ),
            // Target 3 missed; track 9 still there.
            frame(0.05, &[(9, 200.0, 100.0)], &[(3, true, 52.0, 60.0)]),
            // Target 3 picked up by track 2: an ID switch. Track 9 gone.
            frame(0.10, &[(2, 54.0, 60.0)], &[(3, true, 54.0, 60.0)]),
            // A track on a target at the border (ignored): neither miss nor false positive.
            frame(
                0.15,
                &[(2, 56.0, 60.0), (5, 1.0, 100.0)],
                &[(3, true, 56.0, 60.0), (7, true, 1.0, 100.0)],
            ),
            // Target 3 leaves the image, then comes back under a new id: no switch.
            frame(0.20, &[], &[]),
            frame(0.25, &[(6, 58.0, 60.0)], &[(3, true, 58.0, 60.0)]),
        ];
        let s = evaluate_tracking(&frames, 320, 240, &TrackingEvalConfig::default());
        assert_eq!(s.truth_boxes, 5);
        assert_eq!((s.matches, s.misses, s.id_switches), (4, 1, 1));
        assert_eq!(s.false_positives, 2);
        assert!((s.mota - (1.0 - 4.0 / 5.0)).abs() < 1e-12);
        assert_eq!(s.false_tracks, 1);
        assert!((s.false_track_max_lifetime_s - 0.05).abs() < 1e-12);
        assert_eq!(s.tracks, 5);
    }

    #[test]
    fn partial_overlap_gives_its_iou_and_low_overlap_is_no_match() {
        // Shifted by 10 px of 40: IoU = 30·40 / (2·1600 − 1200) = 0.6.
        let frames = vec![frame(0.0, &[(1, 60.0, 60.0)], &[(3, true, 50.0, 60.0)])];
        let s = evaluate_tracking(&frames, 320, 240, &TrackingEvalConfig::default());
        assert!((s.mean_iou - 0.6).abs() < 1e-12);
        let frames = vec![frame(0.0, &[(1, 75.0, 60.0)], &[(3, true, 50.0, 60.0)])];
        let s = evaluate_tracking(&frames, 320, 240, &TrackingEvalConfig::default());
        assert_eq!((s.matches, s.misses, s.false_positives), (0, 1, 1));
    }
}
