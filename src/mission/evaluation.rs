//! Ground-truth bookkeeping of a mission: which true rock each target is, how far off its
//! localization was, which true targets were missed and whether a distractor was mapped.
//! Per-target mesh and fragility scores are computed when the target is finished
//! ([`super::mapping::finish_target`]); this module only matches and counts.

use std::collections::HashMap;

use nalgebra::{Isometry3, Point3, Vector3};
use scarp_datasets::world::{Rock, RockRole, World};

use super::catalog::{Catalog, TargetStatus};
use super::report::{CENTER_FROM_SCAN, MissionReport};

/// A target farther than this from every true rock's centroid matches none, metres.
pub const MATCH_RADIUS_M: f64 = 3.0;

/// The true rock whose centroid is nearest `center`, if within [`MATCH_RADIUS_M`], with the
/// distance.
pub fn nearest_rock<'w>(world: &'w World, center: &Point3<f64>) -> Option<(&'w Rock, f64)> {
    world
        .rocks
        .iter()
        .map(|r| (r, (r.centroid - center).norm()))
        .filter(|(_, d)| *d <= MATCH_RADIUS_M)
        .min_by(|a, b| a.1.total_cmp(&b.1))
}

/// The state estimator's position error (estimate − truth, metres, world ENU) summed over the
/// frames that updated each target's localization: what moves the truth into the frame the
/// vehicle flies in.
#[derive(Debug, Clone, Default)]
pub struct EstimatorErrorByTarget {
    sums: HashMap<u32, (Vector3<f64>, usize)>,
}

impl EstimatorErrorByTarget {
    /// Records one frame that updated the targets `updated`, seen at the estimated and the true
    /// camera poses. Only targets still being localized count (not yet in `targets`, or with a
    /// status that [`TargetStatus::follows_filter`]): from mapping on, the reported centre is
    /// frozen, and a later update (the rock seen again from the search) did not localize it.
    pub fn record(
        &mut self,
        updated: &[u32],
        targets: &Catalog,
        world_from_camera_estimate: &Isometry3<f64>,
        world_from_camera_truth: &Isometry3<f64>,
    ) {
        let error = world_from_camera_estimate.translation.vector
            - world_from_camera_truth.translation.vector;
        let localizing = updated
            .iter()
            .filter(|id| targets.get(id).is_none_or(|m| m.status.follows_filter()));
        for id in localizing {
            let slot = self.sums.entry(*id).or_insert((Vector3::zeros(), 0));
            slot.0 += error;
            slot.1 += 1;
        }
    }

    /// Forgets target `id`'s frames (its filter started afresh).
    pub fn forget(&mut self, id: u32) {
        self.sums.remove(&id);
    }

    /// The mean error over the frames that updated target `id`; `None` if none did.
    pub fn mean_m(&self, id: u32) -> Option<Vector3<f64>> {
        // Entries exist only for targets updated at least once: the count is never zero.
        self.sums.get(&id).map(|(sum, n)| sum / *n as f64)
    }
}

/// The localization error in the frame the vehicle flies in: the distance from the localized
/// centre to the true centroid moved by the estimator's mean position error (estimate − truth)
/// over the frames that localized the target, metres.
pub fn estimate_frame_error_m(
    center: &Point3<f64>,
    true_centroid: &Point3<f64>,
    estimator_error_m: &Vector3<f64>,
) -> f64 {
    estimate_frame_offset_m(center, true_centroid, estimator_error_m).norm()
}

/// The localized centre less the true centroid moved by the estimator's mean position error
/// (estimate − truth), ENU metres: [`estimate_frame_error_m`] as a vector, so that its
/// vertical (z, + above the rock's centroid) can be told from its horizontal.
pub fn estimate_frame_offset_m(
    center: &Point3<f64>,
    true_centroid: &Point3<f64>,
    estimator_error_m: &Vector3<f64>,
) -> Vector3<f64> {
    center - (true_centroid + estimator_error_m)
}

/// Fills each target's `gt_rock_id` and `gt_role` (the true rock nearest its `center`), the
/// errors of its localized centre (`localization_error_m`, and where the estimator's error at
/// its localization is known `localization_error_estimate_frame_m`) and of its `center`
/// (`center_error_m`, `center_error_estimate_frame_m`), and the report's `distractors_mapped`
/// and `targets_missed`.
pub fn ground_truth_summary(world: &World, targets: &mut Catalog, report: &mut MissionReport) {
    for m in targets.values_mut() {
        let r = &mut m.report;
        let center = Point3::from(r.center);
        let localized = Point3::from(r.localized_center);
        match nearest_rock(world, &center) {
            Some((rock, distance)) => {
                r.gt_rock_id = Some(rock.id);
                r.gt_role = Some(rock.role.as_str().into());
                r.center_error_m = Some(distance);
                r.localization_error_m = Some((localized - rock.centroid).norm());
                let in_estimate_frame = |at: &Point3<f64>, error: Option<[f64; 3]>| {
                    error.map(|e| estimate_frame_offset_m(at, &rock.centroid, &Vector3::from(e)))
                };
                let localization_offset =
                    in_estimate_frame(&localized, r.estimator_error_at_localization_m);
                r.localization_offset_estimate_frame_m = localization_offset.map(Into::into);
                r.localization_error_estimate_frame_m = localization_offset.map(|v| v.norm());
                r.center_error_estimate_frame_m = if r.center_source == CENTER_FROM_SCAN {
                    in_estimate_frame(&center, r.estimator_error_over_keyframes_m).map(|v| v.norm())
                } else {
                    r.localization_error_estimate_frame_m
                };
            }
            None => {
                r.gt_rock_id = None;
                r.gt_role = None;
                r.center_error_m = None;
                r.localization_error_m = None;
                r.localization_error_estimate_frame_m = None;
                r.localization_offset_estimate_frame_m = None;
                r.center_error_estimate_frame_m = None;
            }
        }
    }
    let mapped: Vec<&crate::mission::catalog::MissionTarget> = targets
        .values()
        .filter(|m| m.status == TargetStatus::Mapped)
        .collect();
    report.distractors_mapped = mapped
        .iter()
        .filter(|m| m.report.gt_role.as_deref() != Some(RockRole::Target.as_str()))
        .count();
    report.targets_missed = world
        .targets()
        .map(|r| r.id)
        .filter(|id| !mapped.iter().any(|m| m.report.gt_rock_id == Some(*id)))
        .collect();
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mission::catalog::MissionTarget;

    fn target(center: Point3<f64>, status: TargetStatus) -> MissionTarget {
        let mut m = MissionTarget::new(0, &center, 0.0);
        m.set_status(status);
        m
    }

    #[test]
    fn the_estimator_error_counts_only_frames_that_localized_the_target() {
        let at = |x: f64| Isometry3::translation(x, 0.0, 0.0);
        let mut targets = Catalog::new();
        let mut errors = EstimatorErrorByTarget::default();
        let set = |targets: &mut Catalog, status| targets.get_mut(&1).unwrap().set_status(status);
        // Target 1 before the mission registers it, then while it is localized.
        errors.record(&[1], &targets, &at(1.0), &at(0.0));
        targets.insert(1, target(Point3::origin(), TargetStatus::Localizing));
        errors.record(&[1], &targets, &at(3.0), &at(0.0));
        set(&mut targets, TargetStatus::FineLocalizing);
        errors.record(&[1], &targets, &at(2.0), &at(0.0));
        // Mapped: its centre is frozen, so seeing it again later changes nothing.
        for status in [TargetStatus::Mapping, TargetStatus::Mapped] {
            set(&mut targets, status);
            errors.record(&[1], &targets, &at(50.0), &at(0.0));
        }
        assert_eq!(errors.mean_m(1), Some(Vector3::new(2.0, 0.0, 0.0)));
        // A filter started afresh forgets its earlier frames.
        errors.forget(1);
        assert_eq!(errors.mean_m(1), None);
        assert_eq!(errors.mean_m(2), None);
    }

    #[test]
    fn matches_counts_and_misses() {
        let world = World::builtin_default().unwrap();
        let rocks: Vec<&Rock> = world.targets().collect();
        let distractor = world
            .rocks
            .iter()
            .find(|r| r.role == RockRole::Distractor)
            .unwrap();
        let mut targets = Catalog::new();
        let off = Vector3::new(0.3, -0.4, 0.0);
        let mut biased = target(rocks[0].centroid + off, TargetStatus::Mapped);
        // The estimator was off by 0.2 m east and 0.1 m up while localizing it: in its frame
        // the centre is 0.1 m east, 0.4 m south and 0.1 m low of where the rock appeared.
        biased.report.estimator_error_at_localization_m = Some([0.2, 0.0, 0.1]);
        // Its scan then placed it 5 cm east and 2 cm up, in a map frame the estimator held
        // 4 cm east and 2 cm up over the keyframes: 1 cm off in that frame.
        biased
            .report
            .set_scan_center(&(rocks[0].centroid + Vector3::new(0.05, 0.0, 0.02)));
        biased.report.estimator_error_over_keyframes_m = Some([0.04, 0.0, 0.02]);
        targets.insert(1, biased);
        targets.insert(2, target(distractor.centroid, TargetStatus::Mapped));
        targets.insert(3, target(rocks[1].centroid, TargetStatus::Unconverged));
        targets.insert(
            4,
            target(Point3::new(1e4, 1e4, 0.0), TargetStatus::Localizing),
        );
        let mut report = MissionReport::default();
        ground_truth_summary(&world, &mut targets, &mut report);
        assert_eq!(targets[&1].report.gt_rock_id, Some(rocks[0].id));
        assert!((targets[&1].report.localization_error_m.unwrap() - 0.5).abs() < 1e-9);
        let in_estimate_frame = targets[&1]
            .report
            .localization_error_estimate_frame_m
            .unwrap();
        assert!(
            (in_estimate_frame - 0.18f64.sqrt()).abs() < 1e-9,
            "{in_estimate_frame}"
        );
        // The same error as a vector, its vertical signed: 0.1 m below the rock's centroid.
        let offset = targets[&1]
            .report
            .localization_offset_estimate_frame_m
            .unwrap();
        for (got, want) in offset.iter().zip([0.1, -0.4, -0.1]) {
            assert!((got - want).abs() < 1e-9, "{offset:?}");
        }
        let scanned = &targets[&1].report;
        assert!((scanned.center_error_m.unwrap() - 0.0029f64.sqrt()).abs() < 1e-9);
        assert!((scanned.center_error_estimate_frame_m.unwrap() - 0.01).abs() < 1e-9);
        // A centre C_e alone: both errors are the localization's.
        let unscanned = &targets[&2].report;
        assert_eq!(unscanned.center_error_m, unscanned.localization_error_m);
        assert_eq!(targets[&3].report.localization_error_estimate_frame_m, None);
        assert_eq!(
            targets[&3].report.localization_offset_estimate_frame_m,
            None
        );
        assert_eq!(targets[&2].report.gt_role.as_deref(), Some("distractor"));
        assert_eq!(targets[&4].report.gt_rock_id, None);
        assert_eq!(report.distractors_mapped, 1);
        let expected_missed: Vec<u32> = rocks[1..].iter().map(|r| r.id).collect();
        assert_eq!(report.targets_missed, expected_missed);
    }
}
