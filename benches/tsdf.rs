//! TSDF budgets (DESIGN.md): integration of one 640×480 frame of the default-world orbit at
//! 1 cm voxels (block allocation and voxel update, as Open3D's
//! `compute_unique_block_coordinates` + `integrate` in `slam/benches/compare_open3d.py`), with
//! the target's cylinder ROI and on the full frame to 8 m, each on clean depth and on depth with
//! the default stereo noise; and marching cubes of the fused volumes (the target rock in its
//! cylinder, ≤ 100 ms for a 2 m rock, and the noisy full frame). Integration uses `scarp map`'s
//! settings for a rendered sequence: the sensor's depth noise known (σ at 1 m from the stereo
//! model, 0 for clean depth), with a block support of 4 for noisy pixels. Meshing takes the
//! voxels seen by 3 frames or more (`scarp map --min-observations 3`). The noisy cylinder is
//! integrated a second time with the nearest pixel's depth (`scarp map --depth-sample nearest`,
//! Open3D's sampling rule).
//!
//! `cargo bench --bench tsdf`

use criterion::{Criterion, criterion_group, criterion_main};
use scarp_datasets::paths::default_orbit;
use scarp_datasets::render::Renderer;
use scarp_datasets::sensor::SensorConfig;
use scarp_datasets::world::World;
use scarp_slam::meshing::{MeshingConfig, extract_mesh, remove_small_components};
use scarp_slam::tsdf::{DepthSample, Roi, TsdfConfig, TsdfVolume};
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
    let sensor = SensorConfig::default();
    let mut clean = Vec::new();
    let mut noisy = Vec::new();
    for (i, p) in poses.iter().enumerate() {
        let out = renderer.render(&camera, p).expect("render");
        // Fixed seeds: every run fuses the same noisy frames.
        let depth = sensor.corrupt_depth(&out.depth_m, camera.fx, 3 + i as u64);
        let rgb = sensor.corrupt_rgb(&out.rgb, 3 + i as u64);
        noisy.push(RgbdFrame::new(0.0, rgb, depth, None).expect("frame"));
        clean.push(RgbdFrame::new(0.0, out.rgb, out.depth_m, None).expect("frame"));
    }
    let target = world.targets().next().expect("a target");
    let centre = target.centroid;
    let roi = Roi::Cylinder {
        center_xy: [centre.x, centre.y],
        z_min: centre.z - 1.6,
        z_max: centre.z + 1.2,
        radius_m: 1.2,
    };
    let meshing = MeshingConfig {
        min_observations: 3,
        ..MeshingConfig::default()
    };
    let mut group = c.benchmark_group("tsdf");
    group.sample_size(10);
    for (region, roi, max_depth_m) in [
        ("cylinder roi", Some(roi), 10.0),
        ("full frame 8 m", None, 8.0),
    ] {
        for (noise, frames) in [("clean", &clean), ("noisy", &noisy)] {
            let depth_sigma_at_1m_m = if noise == "noisy" {
                sensor.depth_sigma_m(1.0, camera.fx) as f32
            } else {
                0.0
            };
            let config = TsdfConfig {
                roi,
                max_depth_m,
                depth_sigma_at_1m_m: Some(depth_sigma_at_1m_m),
                min_block_support: 4,
                ..TsdfConfig::default()
            };
            // Warm volume (all frames fused once), then time one more frame.
            let warm = |config: TsdfConfig| {
                let mut volume = TsdfVolume::new(config).expect("config");
                for (f, p) in frames.iter().zip(&poses) {
                    volume.integrate(f, &camera, p).expect("integrate");
                }
                volume
            };
            let mut volume = warm(config);
            let mut k = 0;
            group.bench_function(
                format!("integrate 640x480 frame, 1 cm, {region}, {noise}"),
                |b| {
                    b.iter(|| {
                        k = (k + 1) % frames.len();
                        volume
                            .integrate(&frames[k], &camera, &poses[k])
                            .expect("integrate")
                    })
                },
            );
            if roi.is_some() && noise == "noisy" {
                let mut nearest = warm(TsdfConfig {
                    depth_sample: DepthSample::Nearest,
                    ..volume.config().clone()
                });
                group.bench_function(
                    format!("integrate 640x480 frame, 1 cm, {region}, {noise}, nearest pixel"),
                    |b| {
                        b.iter(|| {
                            k = (k + 1) % frames.len();
                            nearest
                                .integrate(&frames[k], &camera, &poses[k])
                                .expect("integrate")
                        })
                    },
                );
            }
            let mesh = (roi.is_some() && noise == "clean") || (roi.is_none() && noise == "noisy");
            if mesh {
                group.bench_function(format!("marching cubes, 1 cm, {region}, {noise}"), |b| {
                    b.iter(|| extract_mesh(&volume, &meshing))
                });
                // `scarp map`'s filter of floating noise, after marching cubes.
                let raw = extract_mesh(&volume, &meshing);
                group.bench_function(
                    format!("small components under 200 triangles, {region}, {noise}"),
                    |b| b.iter(|| remove_small_components(&raw, 200)),
                );
            }
        }
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
