//! The first frame after a gap in view, when the state estimate walked by a metre meanwhile:
//! one guess cannot reach the truth (the odometry corrects a guess by at most half a metre), a
//! search over the estimate's walk does. And the first frame after a short run of dropped
//! frames, over which the estimate's motion is off by half a metre: searched for too.

mod common;

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use scarp_datasets::render::Renderer;
use scarp_slam::mapping::{
    EstimateRotationGate, ModelTracker, ModelTrackingConfig, ReacquisitionSearch,
};
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

/// Frames dropped in a row before the frame after the short run.
const DROPPED: usize = 17;
/// The short run, seconds: 18 frame periods at the mission's 20 Hz.
const RUN_S: f64 = 0.9;

/// Orbit frames 0..[`BEFORE`], then [`DROPPED`] frames the tracker drops (their estimate turned
/// 10° from the truth, beyond the rotation gate), then the orbit's next frame, [`RUN_S`] after
/// the last one kept, with the estimate's motion over the run off by `walk_m`. Returns each
/// kept-or-not frame's position error (metres), whether it was kept, and the search's starts.
fn run_after_drops(after_dropped_frames: bool, walk_m: Vector3<f64>) -> Vec<(f64, bool, usize)> {
    let scene = common::orbit_scene();
    let renderer = Renderer::new(&scene.world);
    let config = ModelTrackingConfig {
        tsdf: TsdfConfig {
            voxel_size_m: 0.02,
            roi: Some(scene.roi),
            ..TsdfConfig::default()
        },
        estimate_rotation_gate: Some(EstimateRotationGate {
            min_deg: 0.5,
            deg_per_sqrt_s: 1.0,
        }),
        max_dropped_frames: DROPPED + 5,
        reacquisition: Some(ReacquisitionSearch {
            after_dropped_frames,
            ..gps_search()
        }),
        ..ModelTrackingConfig::default()
    };
    let mut tracker = ModelTracker::new(scene.camera, config).unwrap();
    let render = |k: usize, timestamp_s: f64| {
        let out = renderer.render(&scene.camera, &scene.poses[k].1).unwrap();
        RgbdFrame::new(timestamp_s, out.rgb, out.depth_m, None).unwrap()
    };
    let period_s = RUN_S / (DROPPED + 1) as f64;
    let turned = UnitQuaternion::from_scaled_axis(Vector3::new(0.0, 10f64.to_radians(), 0.0));
    let mut out = Vec::new();
    let mut track = |frame: &RgbdFrame, truth: &Isometry3<f64>, estimate: &Isometry3<f64>| {
        let tracked = tracker.process(frame, estimate).unwrap();
        let error_m =
            (tracked.world_from_camera.translation.vector - truth.translation.vector).norm();
        out.push((
            error_m,
            !tracked.dropped && !tracked.fell_back,
            tracked.reacquisition.map_or(0, |r| r.starts),
        ));
    };
    for k in 0..BEFORE {
        let truth = scene.poses[k].1;
        track(&render(k, k as f64 * period_s), &truth, &truth);
    }
    let last_kept_s = (BEFORE - 1) as f64 * period_s;
    for d in 1..=DROPPED {
        let truth = scene.poses[BEFORE - 1].1;
        let estimate = Isometry3::from_parts(truth.translation, turned * truth.rotation);
        track(
            &render(BEFORE - 1, last_kept_s + d as f64 * period_s),
            &truth,
            &estimate,
        );
    }
    let truth = scene.poses[BEFORE].1;
    let estimate = Translation3::from(walk_m) * truth;
    track(&render(BEFORE, last_kept_s + RUN_S), &truth, &estimate);
    out
}

#[test]
fn the_frame_after_a_run_of_dropped_frames_is_searched_for() {
    // The estimate's motion over the run off by 0.6 m, mostly vertically (the simulated GPS's
    // vertical walk and white noise, 2 σ over 0.9 s: 0.37 m on the default world's seed 62),
    // beyond the odometry's 0.5 m reach.
    let walk_m = Vector3::new(0.12, -0.08, 0.58);
    let searched = run_after_drops(true, walk_m);
    assert!(
        searched[..BEFORE]
            .iter()
            .all(|&(e, kept, _)| kept && e < 0.01)
    );
    assert!(
        searched[BEFORE..BEFORE + DROPPED]
            .iter()
            .all(|&(_, kept, _)| !kept)
    );
    let (error_m, kept, starts) = searched[BEFORE + DROPPED];
    assert!(starts >= 3, "{starts} guesses");
    assert!(
        kept && error_m < 0.03,
        "kept {kept}, {error_m:.3} m from the truth"
    );

    // Without the rule: the one guess, 0.6 m out.
    let single = run_after_drops(false, walk_m);
    let (error_m, kept, starts) = single[BEFORE + DROPPED];
    assert_eq!(starts, 0);
    assert!(
        !kept || error_m > 0.03,
        "one guess: kept {kept}, {error_m:.3} m"
    );
}
