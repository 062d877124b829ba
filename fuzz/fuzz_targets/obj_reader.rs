//! Any bytes as an OBJ file: the parser must return `Ok` or `Err`, never panic, and an `Ok`
//! mesh must be valid (faces, indices in range, finite positions, one colour per vertex or none).
#![no_main]

use libfuzzer_sys::fuzz_target;
use scarp_export::obj::parse_obj;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if let Ok(mesh) = parse_obj(text) {
        assert!(!mesh.faces.is_empty(), "a mesh without faces");
        assert!(mesh.validate().is_ok(), "the reader returned an invalid mesh");
    }
});
