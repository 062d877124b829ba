//! The tracker's check of the odometry against a state estimate: a frame whose tracked rotation
//! strays from the estimate's by more than the estimator could have drifted is dropped, rather
//! than fused and kept as the reference of the frames after it.

mod common;

use nalgebra::{Isometry3, UnitQuaternion, Vector3};
use scarp_datasets::render::Renderer;
use scarp_slam::mapping::{EstimateRotationGate, ModelTracker, ModelTrackingConfig};
use scarp_slam::tsdf::{Roi, TsdfConfig};
use scarp_slam::{PinholeCamera, RgbdFrame};

/// Degrees the odd frame's view is turned away from where the estimate (the truth) says it is.
const TURN_DEG: f64 = 4.0;
/// The orbit's frame whose image is taken from the turned pose.
const ODD: usize = 3;

/// Frames 0..6 of a 1°-a-frame orbit of the default world's first target, and their true
/// poses; frame [`ODD`] is rendered from its pose turned by [`TURN_DEG`] about the camera's
/// vertical axis: an image the odometry tracks to a pose the estimate says is wrong, as a local
/// minimum of the odometry would.
fn frames() -> (PinholeCamera, Vec<(RgbdFrame, Isometry3<f64>)>, Roi) {
    let scene = common::orbit_scene();
    let renderer = Renderer::new(&scene.world);
    let turn = UnitQuaternion::from_scaled_axis(Vector3::y() * TURN_DEG.to_radians());
    let frames = scene.poses[..6]
        .iter()
        .enumerate()
        .map(|(k, &(timestamp_s, truth))| {
            let seen_from = if k == ODD {
                truth * Isometry3::from_parts(Default::default(), turn)
            } else {
                truth
            };
            let out = renderer.render(&scene.camera, &seen_from).unwrap();
            let frame = RgbdFrame::new(timestamp_s, out.rgb, out.depth_m, None).unwrap();
            (frame, truth)
        })
        .collect();
    (scene.camera, frames, scene.roi)
}

fn tracker(
    camera: PinholeCamera,
    roi: Roi,
    gate: Option<EstimateRotationGate>,
    max_dropped_frames: usize,
) -> ModelTracker {
    let config = ModelTrackingConfig {
        tsdf: TsdfConfig {
            voxel_size_m: 0.02,
            roi: Some(roi),
            ..TsdfConfig::default()
        },
        estimate_rotation_gate: gate,
        max_dropped_frames,
        ..ModelTrackingConfig::default()
    };
    ModelTracker::new(camera, config).unwrap()
}

const GATE: EstimateRotationGate = EstimateRotationGate {
    min_deg: 0.5,
    deg_per_sqrt_s: 3.8,
};

fn angle_deg(a: &Isometry3<f64>, b: &Isometry3<f64>) -> f64 {
    (a.inverse() * b).rotation.angle().to_degrees()
}

#[test]
fn a_frame_that_strays_from_the_estimate_is_dropped_and_tracking_goes_on() {
    let (camera, frames, roi) = frames();
    let mut gated = tracker(camera, roi, Some(GATE), 10);
    for (k, (frame, truth)) in frames.iter().enumerate() {
        let blocks = gated.volume().stats().blocks;
        let tracked = gated.process(frame, truth).unwrap();
        if k == ODD {
            let d = tracked.disagreement.expect("the odd frame disagrees");
            assert!(tracked.dropped && !tracked.fused && tracked.keyframe.is_none());
            assert!((d.rotation_deg - TURN_DEG).abs() < 0.5, "{d:?}");
            assert!(d.tolerance_deg < 2.0, "{d:?}");
            let reason = tracked.distrust_reason().unwrap();
            assert!(reason.contains("strays"), "{reason}");
            assert_eq!(gated.volume().stats().blocks, blocks);
        } else {
            assert!(!tracked.dropped && tracked.fused, "frame {k}: {tracked:?}");
            // The frame after the dropped one tracks from the last frame kept.
            assert!(
                angle_deg(&tracked.world_from_camera, truth) < 0.1,
                "frame {k}: {:.3}°",
                angle_deg(&tracked.world_from_camera, truth)
            );
        }
    }

    // Without the gate the odd frame is fused where its image puts it, 4° off the estimate.
    let mut ungated = tracker(camera, roi, None, 10);
    for (k, (frame, truth)) in frames.iter().enumerate().take(ODD + 1) {
        let tracked = ungated.process(frame, truth).unwrap();
        if k == ODD {
            assert!(tracked.fused && !tracked.dropped);
            assert!(angle_deg(&tracked.world_from_camera, truth) > TURN_DEG - 0.5);
        }
    }
}

#[test]
fn frames_beyond_the_drop_limit_are_placed_by_the_estimate() {
    let (camera, frames, roi) = frames();
    let mut placed = tracker(camera, roi, Some(GATE), 0);
    for (k, (frame, truth)) in frames.iter().enumerate().take(ODD + 1) {
        let tracked = placed.process(frame, truth).unwrap();
        if k == ODD {
            assert!(tracked.disagreement.is_some());
            assert!(tracked.fell_back && tracked.fused && !tracked.dropped);
            // Placed by the estimate's motion, which is the truth here.
            assert!(angle_deg(&tracked.world_from_camera, truth) < 0.1);
        }
    }
}

#[test]
fn the_gate_widens_with_the_time_between_frames() {
    assert_eq!(GATE.tolerance_deg(0.0), 0.5);
    assert!((GATE.tolerance_deg(0.25) - (0.5 + 3.8 * 0.5)).abs() < 1e-12);
    assert_eq!(GATE.tolerance_deg(-1.0), 0.5);
    assert_eq!(GATE.tolerance_deg(f64::NAN), 0.5);
}
