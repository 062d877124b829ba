//! Rendering throughput: RGB, depth and instance ids at 640×480 of the default world from
//! lawn-mower sweeps at the mission's search height (10 m) and at 20 m, and from the close orbit
//! around the first target, as the mapping views see it (budget: ≥ 100 frames/s on 2 cores,
//! i.e. ≤ 10 ms a frame); and the orbit's depth and instances alone, without shading.

use criterion::{Criterion, criterion_group, criterion_main};
use scarp_datasets::paths;
use scarp_datasets::render::Renderer;
use scarp_datasets::sensor::SensorConfig;
use scarp_datasets::world::World;
use scarp_slam::PinholeCamera;

fn bench_render(c: &mut Criterion) {
    let world = World::builtin_default().expect("default world");
    let renderer = Renderer::new(&world);
    let camera = PinholeCamera::from_hfov(640, 480, 80.0).expect("camera");
    let search = paths::lawnmower(&world, 10.0, 80.0, 64).expect("path");
    let lawnmower = paths::lawnmower(&world, 20.0, 80.0, 64).expect("path");
    let orbit = paths::default_orbit(&world, 64).expect("path");
    let mut group = c.benchmark_group("render_640x480");
    for (name, poses) in [
        ("lawnmower_10m", &search),
        ("lawnmower_20m", &lawnmower),
        ("orbit_4m", &orbit),
    ] {
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
    // Depth and instances only, as the evaluation's visibility test renders them.
    let mut k = 0;
    group.bench_function("orbit_4m_geometry_only", |b| {
        b.iter(|| {
            k = (k + 1) % orbit.len();
            renderer
                .render_geometry(&camera, &orbit[k].world_from_camera)
                .expect("render")
        })
    });
    group.finish();
}

/// The sensor model applied to every simulated frame: stereo depth noise with dropouts, and RGB
/// noise, on a rendered 640×480 view of the first target.
fn bench_sensor(c: &mut Criterion) {
    let world = World::builtin_default().expect("default world");
    let camera = PinholeCamera::from_hfov(640, 480, 80.0).expect("camera");
    let orbit = paths::default_orbit(&world, 8).expect("path");
    let frame = Renderer::new(&world)
        .render(&camera, &orbit[0].world_from_camera)
        .expect("render");
    let sensor = SensorConfig::default();
    let mut group = c.benchmark_group("sensor_640x480");
    let mut seed = 0;
    group.bench_function("corrupt_depth", |b| {
        b.iter(|| {
            seed += 1;
            sensor.corrupt_depth(&frame.depth_m, camera.fx, seed)
        })
    });
    group.bench_function("corrupt_rgb", |b| {
        b.iter(|| {
            seed += 1;
            sensor.corrupt_rgb(&frame.rgb, seed)
        })
    });
    group.finish();
}

criterion_group!(benches, bench_render, bench_sensor);
criterion_main!(benches);
