//! TSDF budgets (DESIGN.md): integration of one 640×480 frame of the default-world orbit at
//! 1 cm voxels (≤ 10 ms on 2 cores), with and without the target's cylinder ROI, and marching
//! cubes of the target rock fused at 1 cm (≤ 100 ms for a 2 m rock).
//!
//! `cargo bench --bench tsdf`

use criterion::{Criterion, criterion_group, criterion_main};
use scarp_datasets::paths::default_orbit;
use scarp_datasets::render::Renderer;
use scarp_datasets::world::World;
use scarp_slam::meshing::{MeshingConfig, extract_mesh};
use scarp_slam::tsdf::{Roi, TsdfConfig, TsdfVolume};
use scarp_slam::{PinholeCamera, RgbdFrame};

fn bench(c: &mut Criterion) {
    let world = World::builtin_default().expect("default world");
    let camera = PinholeCamera::from_hfov(640, 480, 80.0).expect("valid camera");
    let poses: Vec<_> = default_orbit(&world, 24)
        .expect("orbit")
        .into_iter()
        .map(|p| p.world_from_camera)
        .collect();
    let renderer = Renderer::new(&world);
    let frames: Vec<RgbdFrame> = poses
        .iter()
        .map(|p| {
            let out = renderer.render(&camera, p).expect("render");
            RgbdFrame::new(0.0, out.rgb, out.depth_m, None).expect("frame")
        })
        .collect();
    let target = world.targets().next().expect("a target");
    let centre = target.centroid;
    let roi = Roi::Cylinder {
        center_xy: [centre.x, centre.y],
        z_min: centre.z - 1.6,
        z_max: centre.z + 1.2,
        radius_m: 1.2,
    };
    let mut group = c.benchmark_group("tsdf");
    group.sample_size(10);
    for (name, roi) in [("no roi", None), ("cylinder roi", Some(roi))] {
        let config = TsdfConfig {
            roi,
            ..TsdfConfig::default()
        };
        // Warm volume (all frames fused once), then time one more frame.
        let mut volume = TsdfVolume::new(config).expect("config");
        for (f, p) in frames.iter().zip(&poses) {
            volume.integrate(f, &camera, p).expect("integrate");
        }
        let mut k = 0;
        group.bench_function(format!("integrate 640x480 frame, 1 cm, {name}"), |b| {
            b.iter(|| {
                k = (k + 1) % frames.len();
                volume
                    .integrate(&frames[k], &camera, &poses[k])
                    .expect("integrate")
            })
        });
        if roi.is_some() {
            group.bench_function("marching cubes, target rock at 1 cm", |b| {
                b.iter(|| extract_mesh(&volume, &MeshingConfig::default()))
            });
        }
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
