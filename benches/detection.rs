//! The simulated detector on one 640×480 frame of the default-world orbit (instance mask of
//! the target, distractors, pedestals and terrain), with the default model.
//!
//! `cargo bench --bench detection`

use criterion::{Criterion, criterion_group, criterion_main};
use scarp::detection::{Detector, SimulatedDetector, SimulatedDetectorConfig};
use scarp_datasets::paths::default_orbit;
use scarp_datasets::render::Renderer;
use scarp_datasets::world::World;
use scarp_slam::{PinholeCamera, RgbdFrame};

fn bench(c: &mut Criterion) {
    let world = World::builtin_default().expect("default world");
    let camera = PinholeCamera::from_hfov(640, 480, 80.0).expect("valid camera");
    let pose = default_orbit(&world, 8).expect("orbit")[0].world_from_camera;
    let out = Renderer::new(&world)
        .render(&camera, &pose)
        .expect("render");
    let frame = RgbdFrame::new(0.0, out.rgb, out.depth_m, Some(out.instance)).expect("frame");
    let mut detector = SimulatedDetector::for_world(SimulatedDetectorConfig::default(), &world)
        .expect("default config");
    let mut group = c.benchmark_group("detection");
    group.bench_function("simulated detector, 640x480 frame", |b| {
        b.iter(|| detector.detect(&frame).expect("mask present"))
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
