//! Any bytes through the GLB reader: it must return `Ok` or `Err`, never panic, and every
//! mesh it returns must be valid.
#![no_main]

use libfuzzer_sys::fuzz_target;
use scarp_export::glb::read_glb_from_slice;

fuzz_target!(|data: &[u8]| {
    if let Ok(contents) = read_glb_from_slice(data, "fuzz.glb") {
        for node in &contents.nodes {
            assert!(
                node.mesh.validate().is_ok(),
                "the reader returned an invalid mesh"
            );
        }
    }
});
