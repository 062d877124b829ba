//! Any bytes as a sequence's `rgb.txt`/`depth.txt` and as its `boxes.txt`: the parsers must
//! return `Ok` or `Err`, never panic; accepted timestamps are finite (and increase in an image
//! list), accepted boxes are ordered.
#![no_main]

use libfuzzer_sys::fuzz_target;
use scarp_datasets::sequence::{parse_boxes, parse_image_list};

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if let Ok(entries) = parse_image_list(text, std::path::Path::new("rgb.txt")) {
        assert!(entries.iter().all(|(t, path)| t.is_finite() && !path.is_empty()));
        assert!(entries.windows(2).all(|w| w[0].0 < w[1].0), "timestamps out of order");
    }
    if let Ok(boxes) = parse_boxes(text, std::path::Path::new("boxes.txt")) {
        for b in &boxes {
            assert!(b.timestamp_s.is_finite(), "a non-finite timestamp");
            let [x0, y0, x1, y1] = b.bbox_px;
            assert!(x0 <= x1 && y0 <= y1, "inverted box");
        }
    }
});
