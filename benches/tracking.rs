//! Tracker step per 640×480 frame with 8 targets (budget ≤ 3 ms on 2 cores). Measures
//! `Tracker::step` only (pyramid, corners and KLT prediction of every box, association,
//! update, life cycle), as `scarp track` reports it, on the fifth frame of a sequence whose
//! first four frames confirmed the 8 tracks.
//!
//! - `texture_*`: a broadband synthetic texture moving 3 px right and 1.5 px down per frame,
//!   eight 40–60 px boxes on it, each detected with a few pixels of error; with the default
//!   tracker config (25 px windows), 15 px windows, no forward–backward check, and one
//!   warped refinement pass.
//! - `rendered_lawnmower`: the first frames of the default world's lawn-mower survey (20 m
//!   altitude, 80° HFOV, 2000-frame sweep as `scarp render --path lawnmower`), rendered, with
//!   eight 36–50 px boxes spread over the frame, and the default tracker config (the `paper`
//!   preset; no refinement pass), then the same with one warped refinement pass re-tracked
//!   through the pyramid (`_refinement_pass`) or refined from the first pass on the
//!   full-resolution level (`_refine_from_previous_pass`).
//!
//! Each benchmark's setup runs only when it is selected, so a filtered run (for a profiler)
//! contains only that benchmark's work.

use criterion::{BatchSize, Criterion, criterion_group, criterion_main};
use scarp::detection::{BoundingBox, Detection};
use scarp::tracking::{Tracker, TrackerConfig};
use scarp_datasets::paths::lawnmower;
use scarp_datasets::render::Renderer;
use scarp_datasets::world::World;
use scarp_slam::PinholeCamera;
use scarp_slam::features::pattern::shifted_texture;
use scarp_slam::image::{GrayImage, gray_from_rgb};

/// Eight boxes of `40 + 3i` px on a 4×2 grid, shifted by `(dx, dy)`, with a few pixels of
/// deterministic detection error that changes with the frame `k`.
fn detections(k: u32, dx: f64, dy: f64, size0: f64, size_step: f64) -> Vec<Detection> {
    (0..8)
        .map(|i| {
            let (x, y) = (
                60.0 + 130.0 * f64::from(i % 4),
                80.0 + 180.0 * f64::from(i / 4),
            );
            let size = size0 + size_step * f64::from(i);
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

/// Runs the first four frames, checks that the 8 tracks are confirmed, and benchmarks the
/// step on the fifth.
fn bench_step(
    c: &mut Criterion,
    name: &str,
    config: &TrackerConfig,
    frames: &dyn Fn() -> Vec<(GrayImage, Vec<Detection>)>,
) {
    c.bench_function(&format!("tracker_step_8_targets_640x480_{name}"), |b| {
        let frames = frames();
        let mut warm = Tracker::new(config.clone()).expect("valid config");
        for (gray, dets) in frames.iter().take(4) {
            warm.step(gray, dets).expect("step");
        }
        assert_eq!(warm.tracks().iter().filter(|t| t.confirmed).count(), 8);
        let (next, dets) = &frames[4];
        b.iter_batched(
            || warm.clone(),
            |mut tracker| tracker.step(next, dets).expect("step"),
            BatchSize::LargeInput,
        )
    });
}

fn texture_frames() -> Vec<(GrayImage, Vec<Detection>)> {
    (0..5u32)
        .map(|k| {
            let (dx, dy) = (3.0 * k as f32, 1.5 * k as f32);
            (
                shifted_texture(640, 480, dx, dy),
                detections(k, f64::from(dx), f64::from(dy), 40.0, 3.0),
            )
        })
        .collect()
}

fn rendered_lawnmower_frames() -> Vec<(GrayImage, Vec<Detection>)> {
    let world = World::builtin_default().expect("default world");
    let camera = PinholeCamera::from_hfov(640, 480, 80.0).expect("camera");
    let poses = lawnmower(&world, 20.0, 80.0, 2000).expect("lawn-mower path");
    let renderer = Renderer::new(&world);
    poses
        .iter()
        .take(5)
        .zip(0u32..)
        .map(|(pose, k)| {
            let out = renderer
                .render(&camera, &pose.world_from_camera)
                .expect("render");
            // The terrain moves by a few pixels per frame; the detections stay put, which
            // the tracker associates at these sizes.
            (gray_from_rgb(&out.rgb), detections(k, 0.0, 0.0, 36.0, 2.0))
        })
        .collect()
}

fn bench(c: &mut Criterion) {
    let defaults = TrackerConfig::default();
    let window_15 = {
        let mut c = TrackerConfig::default();
        c.motion.klt.window_px = 15;
        c
    };
    let no_fb = {
        let mut c = TrackerConfig::default();
        c.motion.klt.max_forward_backward_px = None;
        c
    };
    let refined = {
        let mut c = TrackerConfig::default();
        c.motion.refinement_passes = 1;
        c
    };
    bench_step(c, "texture_default", &defaults, &texture_frames);
    bench_step(c, "texture_window_15", &window_15, &texture_frames);
    bench_step(c, "texture_no_forward_backward", &no_fb, &texture_frames);
    bench_step(c, "texture_refined", &refined, &texture_frames);
    bench_step(
        c,
        "rendered_lawnmower",
        &TrackerConfig::default(),
        &rendered_lawnmower_frames,
    );
    let mut refined = TrackerConfig::default();
    refined.motion.refinement_passes = 1;
    refined.motion.refine_from_previous_pass = false;
    bench_step(
        c,
        "rendered_lawnmower_refinement_pass",
        &refined,
        &rendered_lawnmower_frames,
    );
    let mut shortcut = refined;
    shortcut.motion.refine_from_previous_pass = true;
    bench_step(
        c,
        "rendered_lawnmower_refine_from_previous_pass",
        &shortcut,
        &rendered_lawnmower_frames,
    );
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(30);
    targets = bench
}
criterion_main!(benches);
