//! Any bytes through the PLY readers: they must return `Ok` or `Err`, never panic, and an `Ok`
//! mesh must be valid (indices in range, finite positions and normals).
#![no_main]

use libfuzzer_sys::fuzz_target;
use scarp_export::ply::{read_mesh_from_reader, read_point_cloud_from_reader};

fuzz_target!(|data: &[u8]| {
    if let Ok(mesh) = read_mesh_from_reader(data, "fuzz.ply") {
        assert!(
            mesh.validate().is_ok(),
            "the reader returned an invalid mesh"
        );
        assert!(
            mesh.normals.iter().all(|n| n.iter().all(|c| c.is_finite())),
            "the reader returned a non-finite normal"
        );
    }
    if let Ok(cloud) = read_point_cloud_from_reader(data, "fuzz.ply") {
        assert!(
            cloud.validate().is_ok(),
            "the reader returned an invalid cloud"
        );
    }
});
