//! Odometry per 640×480 frame pair (budget ≤ 15 ms on 2 cores): two consecutive frames of the
//! default orbit (1°, about 7 cm apart), with the sensor's noise, initialised 2 cm / 0.5° off.

use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use scarp_datasets::paths::default_orbit;
use scarp_datasets::render::Renderer;
use scarp_datasets::sensor::SensorConfig;
use scarp_datasets::world::World;
use scarp_slam::PinholeCamera;
use scarp_slam::image::{ImagePyramid, gray_from_rgb};
use scarp_slam::mapping::ReacquisitionSearch;
use scarp_slam::odometry::{
    OdometryConfig, SourceFrame, TrackingReference, track, track_multi_start,
};

fn bench(c: &mut Criterion) {
    let world = World::builtin_default().expect("default world");
    let renderer = Renderer::new(&world);
    let camera = PinholeCamera::from_hfov(640, 480, 80.0).expect("camera");
    let orbit = default_orbit(&world, 360).expect("orbit");
    let sensor = SensorConfig::default();
    let frames: Vec<_> = [0usize, 1]
        .iter()
        .map(|&k| {
            let out = renderer
                .render(&camera, &orbit[k].world_from_camera)
                .expect("render");
            let depth = sensor.corrupt_depth(&out.depth_m, camera.fx, k as u64);
            let rgb = sensor.corrupt_rgb(&out.rgb, k as u64 + 100);
            (gray_from_rgb(&rgb), depth)
        })
        .collect();
    let truth = orbit[0].world_from_camera.inverse() * orbit[1].world_from_camera;
    let guess = Isometry3::from_parts(
        Translation3::new(0.015, -0.01, 0.01),
        UnitQuaternion::from_scaled_axis(Vector3::new(0.0, 0.5f64.to_radians(), 0.0)),
    ) * truth;
    let config = OdometryConfig::default();
    let pyramid =
        |k: usize| ImagePyramid::new(frames[k].0.clone(), frames[k].1.clone(), config.levels);
    let reference =
        TrackingReference::from_pyramid(&camera, &pyramid(0), &config).expect("reference");
    let source = SourceFrame::from_pyramid(&camera, &pyramid(1), &config).expect("source");
    let r = track(&reference, &source, &guess, &config).expect("track");
    let e = truth.inverse() * r.reference_from_current;
    eprintln!(
        "iterations {}, error {:.3} mm {:.4}°, failure {:?}",
        r.iterations,
        e.translation.vector.norm() * 1e3,
        e.rotation.angle().to_degrees(),
        r.failure
    );

    // The machine may be shared: report the process CPU time per call too (Linux), which does
    // not grow with other processes' load. Wall time on an idle 2-core machine is about
    // CPU time / 2 when both cores are busy.
    if let Some(start) = process_cpu_s() {
        let n = 40;
        for _ in 0..n {
            std::hint::black_box(track(&reference, &source, &guess, &config).expect("track"));
        }
        let gn = process_cpu_s().map(|t| (t - start) / f64::from(n) * 1e3);
        let start = process_cpu_s().unwrap_or(0.0);
        for _ in 0..n {
            let p = pyramid(1);
            let s = SourceFrame::from_pyramid(&camera, &p, &config).expect("source");
            std::hint::black_box(track(&reference, &s, &guess, &config).expect("track"));
        }
        let frame = process_cpu_s().map(|t| (t - start) / f64::from(n) * 1e3);
        eprintln!(
            "CPU ms per call: gauss-newton {gn:?}, pyramid + points + gauss-newton {frame:?}"
        );
    }

    let mut group = c.benchmark_group("odometry");
    group.sample_size(20);
    // What a sequence pays per frame: the new frame's pyramid, its points, tracking, and its
    // reference for the next frame.
    group.bench_function("per_frame_640x480", |b| {
        b.iter(|| {
            let p = pyramid(1);
            let source = SourceFrame::from_pyramid(&camera, &p, &config).expect("source");
            let result = track(&reference, &source, &guess, &config).expect("track");
            let next = TrackingReference::from_pyramid(&camera, &p, &config).expect("ref");
            (result, next)
        })
    });
    group.bench_function("gauss_newton_only_640x480", |b| {
        b.iter(|| track(&reference, &source, &guess, &config).expect("track"))
    });
    // A re-acquisition after 14 s out of view with the GPS walk's search (about 350 guesses),
    // the estimate having walked 1.1 m: a rare frame, not a per-frame cost.
    let search = ReacquisitionSearch::for_walk(0.5, 0.8, 30.0, 0.03);
    let walked = Translation3::new(0.9, -0.6, 0.35) * guess;
    let starts: Vec<_> = search
        .offsets_m(14.0)
        .iter()
        .map(|o| Translation3::from(*o) * walked)
        .collect();
    let multi = track_multi_start(&reference, &source, &starts, 4, &config).expect("track");
    let e = truth.inverse() * multi.result.reference_from_current;
    eprintln!(
        "re-acquisition over {} guesses: error {:.3} mm, failure {:?}",
        starts.len(),
        e.translation.vector.norm() * 1e3,
        multi.result.failure
    );
    group.bench_function("reacquisition_14s_gap_640x480", |b| {
        b.iter(|| track_multi_start(&reference, &source, &starts, 4, &config).expect("track"))
    });
    group.bench_function("pyramid_640x480", |b| b.iter(|| pyramid(1)));
    let p = pyramid(1);
    group.bench_function("reference_from_pyramid_640x480", |b| {
        b.iter(|| TrackingReference::from_pyramid(&camera, &p, &config).expect("ref"))
    });
    group.bench_function("source_from_pyramid_640x480", |b| {
        b.iter(|| SourceFrame::from_pyramid(&camera, &p, &config).expect("source"))
    });
    group.finish();
}

/// User + system CPU seconds of this process, from `/proc/self/stat` (100 ticks a second).
fn process_cpu_s() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // Fields after the parenthesised command name; utime and stime are fields 14 and 15.
    let rest = &stat[stat.rfind(')')? + 2..];
    let fields: Vec<&str> = rest.split_whitespace().collect();
    let utime: f64 = fields.get(11)?.parse().ok()?;
    let stime: f64 = fields.get(12)?.parse().ok()?;
    Some((utime + stime) / 100.0)
}

criterion_group!(benches, bench);
criterion_main!(benches);
