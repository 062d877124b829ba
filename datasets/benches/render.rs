//! Rendering throughput: RGB, depth and instance ids at 640×480 of the default world from
//! lawn-mower altitude (budget: ≥ 100 frames/s on 2 cores, i.e. ≤ 10 ms a frame), and from the
//! close orbit around the first target.

use criterion::{Criterion, criterion_group, criterion_main};
use scarp_datasets::paths;
use scarp_datasets::render::Renderer;
use scarp_datasets::world::World;
use scarp_slam::PinholeCamera;

fn bench_render(c: &mut Criterion) {
    let world = World::builtin_default().expect("default world");
    let renderer = Renderer::new(&world);
    let camera = PinholeCamera::from_hfov(640, 480, 80.0).expect("camera");
    let lawnmower = paths::lawnmower(&world, 20.0, 80.0, 64).expect("path");
    let orbit = paths::default_orbit(&world, 64).expect("path");
    let mut group = c.benchmark_group("render_640x480");
    for (name, poses) in [("lawnmower_20m", &lawnmower), ("orbit_4m", &orbit)] {
        let mut k = 0;
        group.bench_function(name, |b| {
            b.iter(|| {
                k = (k + 1) % poses.len();
                renderer
                    .render(&camera, &poses[k].world_from_camera)
                    .expect("render")
            })
        });
    }
    group.finish();
}

criterion_group!(benches, bench_render);
criterion_main!(benches);
