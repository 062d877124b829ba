//! Tracker step per 640×480 frame with 8 targets (budget ≤ 3 ms on 2 cores): a broadband
//! textured scene moving 3 px right and 1.5 px down per frame, eight 40–60 px boxes on it,
//! each detected with a few pixels of error. Measures `Tracker::step` only (KLT prediction of
//! every box, association, update, life cycle), as `scarp track` reports it.

use criterion::{BatchSize, Criterion, criterion_group, criterion_main};
use scarp::detection::{BoundingBox, Detection};
use scarp::tracking::{Tracker, TrackerConfig};
use scarp_slam::features::pattern::shifted_texture;
use scarp_slam::image::GrayImage;

fn frame(dx: f32, dy: f32) -> GrayImage {
    shifted_texture(640, 480, dx, dy)
}

fn detections(k: u32) -> Vec<Detection> {
    let (dx, dy) = (3.0 * f64::from(k), 1.5 * f64::from(k));
    (0..8)
        .map(|i| {
            let (x, y) = (
                60.0 + 130.0 * f64::from(i % 4),
                80.0 + 180.0 * f64::from(i / 4),
            );
            let size = 40.0 + 3.0 * f64::from(i);
            let e = f64::from((i * 7 + k * 3) % 5) - 2.0;
            Detection {
                bbox: BoundingBox::new(x + dx + e, y + dy - e, x + dx + size, y + dy + size + e)
                    .expect("valid box"),
                score: 0.9,
                class_id: 0,
            }
        })
        .collect()
}

fn bench(c: &mut Criterion) {
    let frames: Vec<GrayImage> = (0..5)
        .map(|k| frame(3.0 * k as f32, 1.5 * k as f32))
        .collect();
    let next = &frames[4];
    let dets = detections(4);
    let lawnmower: TrackerConfig = {
        let mut c = TrackerConfig::default();
        c.motion.klt.window_px = 15;
        c
    };
    let variants: Vec<(&str, TrackerConfig)> = vec![
        ("default", TrackerConfig::default()),
        ("window_15", lawnmower),
        ("no_forward_backward", {
            let mut c = TrackerConfig::default();
            c.motion.klt.max_forward_backward_px = None;
            c
        }),
        ("refined", {
            let mut c = TrackerConfig::default();
            c.motion.refinement_passes = 1;
            c
        }),
    ];
    for (name, config) in variants {
        let mut warm = Tracker::new(config).expect("valid config");
        for (k, f) in frames.iter().take(4).enumerate() {
            warm.step(f, &detections(k as u32)).expect("step");
        }
        assert_eq!(warm.tracks().iter().filter(|t| t.confirmed).count(), 8);
        c.bench_function(&format!("tracker_step_8_targets_640x480_{name}"), |b| {
            b.iter_batched(
                || warm.clone(),
                |mut tracker| tracker.step(next, &dets).expect("step"),
                BatchSize::LargeInput,
            )
        });
    }
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(30);
    targets = bench
}
criterion_main!(benches);
