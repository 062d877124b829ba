//! Any bytes as an ESRI ASCII grid: the parser must return `Ok` or `Err`, never panic, and an
//! `Ok` grid must be a valid heightfield whose terrain mesh is valid (finite f32 vertices).
#![no_main]

use libfuzzer_sys::fuzz_target;
use scarp_datasets::terrain::{parse_esri_ascii, terrain_mesh};

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if let Ok(heightfield) = parse_esri_ascii(text) {
        assert!(heightfield.validate().is_ok(), "an invalid heightfield");
        // Meshing allocates two triangles a cell: keep the fuzzer's memory bounded.
        if heightfield.nx * heightfield.ny <= 1 << 16 {
            assert!(terrain_mesh(&heightfield).validate().is_ok(), "an invalid terrain mesh");
        }
    }
});
