//! The first frame after a gap in view, when the state estimate walked by a metre meanwhile:
//! one guess cannot reach the truth (the odometry corrects a guess by at most half a metre), a
//! search over the estimate's walk does.

mod common;

use nalgebra::{Isometry3, Translation3, Vector3};
use scarp_datasets::render::Renderer;
use scarp_slam::mapping::{ModelTracker, ModelTrackingConfig, ReacquisitionSearch};
use scarp_slam::tsdf::{Roi, TsdfConfig};
use scarp_slam::{PinholeCamera, RgbdFrame};

/// Orbit frames (1° apart) seen before the gap.
const BEFORE: usize = 6;
/// The orbit frame seen first after the gap.
const AFTER: usize = 20;
/// The gap, seconds.
const GAP_S: f64 = 12.0;

/// How far the state estimate walked during the gap, world ENU metres.
fn walk_m() -> Vector3<f64> {
    Vector3::new(0.9, -0.6, 0.35)
}

/// Frames 0..[`BEFORE`] and [`AFTER`], [`AFTER`] + 1 of a 1°-a-frame orbit of the default
/// world's first target, with their true poses; the frames after the gap are stamped
/// [`GAP_S`] later.
fn frames() -> (PinholeCamera, Vec<(RgbdFrame, Isometry3<f64>)>, Roi) {
    let scene = common::orbit_scene();
    let renderer = Renderer::new(&scene.world);
    let orbit = &scene.poses;
    let last_before_s = orbit[BEFORE - 1].0;
    let frames = (0..BEFORE)
        .chain([AFTER, AFTER + 1])
        .map(|k| {
            let (stamp_s, truth) = orbit[k];
            let out = renderer.render(&scene.camera, &truth).unwrap();
            let timestamp_s = if k < BEFORE {
                stamp_s
            } else {
                last_before_s + GAP_S + (stamp_s - orbit[AFTER].0)
            };
            let frame = RgbdFrame::new(timestamp_s, out.rgb, out.depth_m, None).unwrap();
            (frame, truth)
        })
        .collect();
    (scene.camera, frames, scene.roi)
}

fn gps_search() -> ReacquisitionSearch {
    ReacquisitionSearch::for_walk(0.5, 0.8, 30.0, 0.02)
}

/// Tracks the frames with the estimate equal to the truth before the gap and walked by
/// [`walk_m`] after it; returns each frame's position error (metres) and whether it was kept.
fn run(search: Option<ReacquisitionSearch>) -> Vec<(f64, bool, Option<usize>)> {
    let (camera, frames, roi) = frames();
    let config = ModelTrackingConfig {
        tsdf: TsdfConfig {
            voxel_size_m: 0.02,
            roi: Some(roi),
            ..TsdfConfig::default()
        },
        reacquisition: search,
        ..ModelTrackingConfig::default()
    };
    let mut tracker = ModelTracker::new(camera, config).unwrap();
    frames
        .iter()
        .enumerate()
        .map(|(k, (frame, truth))| {
            let estimate = if k < BEFORE {
                *truth
            } else {
                Translation3::from(walk_m()) * truth
            };
            let tracked = tracker.process(frame, &estimate).unwrap();
            let error_m =
                (tracked.world_from_camera.translation.vector - truth.translation.vector).norm();
            (
                error_m,
                !tracked.dropped && !tracked.fell_back,
                tracked.reacquisition.map(|r| r.starts),
            )
        })
        .collect()
}

#[test]
fn a_frame_after_a_gap_is_found_across_the_estimates_walk() {
    let searched = run(Some(gps_search()));
    for (k, &(error_m, kept, _)) in searched.iter().enumerate().take(BEFORE) {
        assert!(kept && error_m < 0.01, "frame {k}: {error_m} m");
    }
    let (error_m, kept, starts) = searched[BEFORE];
    assert!(kept, "the first frame after the gap is re-acquired");
    assert!(error_m < 0.03, "re-acquired {error_m:.3} m from the truth");
    assert!(starts.is_some_and(|n| n > 50), "{starts:?} guesses");
    // The next frame is not after a gap: one guess, from the re-acquired pose.
    let (error_m, kept, starts) = searched[BEFORE + 1];
    assert!(
        kept && error_m < 0.03 && starts.is_none(),
        "{error_m} {starts:?}"
    );

    // One guess, a metre out, cannot be right: the frame is dropped or kept in the wrong place.
    let single = run(None);
    let (error_m, kept, starts) = single[BEFORE];
    assert!(starts.is_none());
    assert!(
        !kept || error_m > 0.3,
        "one guess: kept {kept}, {error_m:.3} m"
    );
}
