//! Any bytes as a TUM trajectory: the parser must return `Ok` or `Err`, never panic, and an
//! `Ok` trajectory must have finite, strictly increasing timestamps and finite rigid poses with
//! unit quaternions.
#![no_main]

use libfuzzer_sys::fuzz_target;
use scarp_export::tum::parse_tum_trajectory;
use scarp_slam::geometry::check_finite_isometry;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if let Ok(poses) = parse_tum_trajectory(text) {
        for pair in poses.windows(2) {
            assert!(pair[0].timestamp_s < pair[1].timestamp_s, "timestamps out of order");
        }
        for pose in &poses {
            assert!(pose.timestamp_s.is_finite(), "a non-finite timestamp");
            assert!(check_finite_isometry(&pose.world_from_camera, "pose").is_ok());
            let norm = pose.world_from_camera.rotation.quaternion().norm();
            assert!((norm - 1.0).abs() < 1e-9, "a quaternion of norm {norm}");
        }
    }
});
