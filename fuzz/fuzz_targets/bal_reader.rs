//! Any bytes through the BAL reader: it must return `Ok` or `Err`, never panic, and an `Ok`
//! problem must be consistent (indices in range, every value finite).
#![no_main]

use libfuzzer_sys::fuzz_target;
use scarp_slam::ba::parse_bal;

fuzz_target!(|data: &[u8]| {
    if let Ok(problem) = parse_bal(data, "fuzz.txt") {
        for o in &problem.observations {
            assert!(
                o.camera < problem.cameras.len() && o.point < problem.points.len(),
                "the reader returned an out-of-range index"
            );
            assert!(
                o.pixel.iter().all(|v| v.is_finite()),
                "the reader returned a non-finite observation"
            );
        }
        assert!(
            problem
                .cameras
                .iter()
                .all(|c| c.bal_parameters().iter().all(|v| v.is_finite())),
            "the reader returned a non-finite camera"
        );
        assert!(
            problem
                .points
                .iter()
                .all(|p| p.iter().all(|v| v.is_finite())),
            "the reader returned a non-finite point"
        );
    }
});
