//! Any bytes as a `camera.toml`: the parser must return `Ok` or `Err`, never panic, and an `Ok`
//! file must give usable cameras (finite intrinsics, positive sizes, a finite colour pose).
#![no_main]

use libfuzzer_sys::fuzz_target;
use scarp_datasets::sequence::CameraFile;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if let Ok(file) = CameraFile::parse(text, std::path::Path::new("camera.toml")) {
        assert!(file.camera().is_ok(), "accepted unusable intrinsics");
        assert!(file.depth_scale > 0.0 && file.depth_scale.is_finite());
        assert!(file.color_camera().is_ok(), "accepted an unusable colour camera");
        if let Some(color) = file.color {
            let pose = color.color_from_depth();
            assert!(pose.translation.vector.iter().all(|v| v.is_finite()));
            assert!(pose.rotation.coords.iter().all(|v| v.is_finite()));
        }
    }
});
