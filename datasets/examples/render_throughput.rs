//! Renders N frames of the default world along the bench's two paths (lawn-mower at 20 m, orbit
//! at 4 m) with the sensor model, and prints wall and CPU time per frame for each stage, and a
//! digest of every clean image, so that a rewrite of the renderer can be checked bit for bit.
//! Used to profile the renderer without criterion's harness:
//!
//! ```text
//! cargo run --release -p scarp-datasets --example render_throughput -- 200
//! valgrind --tool=callgrind target/release/examples/render_throughput 20
//! ```

use std::time::Instant;

use scarp_datasets::paths;
use scarp_datasets::render::Renderer;
use scarp_datasets::sensor::SensorConfig;
use scarp_datasets::world::World;
use scarp_slam::PinholeCamera;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let frames: usize = match std::env::args().nth(1) {
        Some(n) => n.parse()?,
        None => 100,
    };
    let world = World::builtin_default()?;
    let renderer = Renderer::new(&world);
    let camera = PinholeCamera::from_hfov(640, 480, 80.0)?;
    let sensor = SensorConfig::default();
    let lawnmower = paths::lawnmower(&world, 20.0, 80.0, 64)?;
    let orbit = paths::default_orbit(&world, 64)?;
    for (name, poses) in [("lawnmower_20m", &lawnmower), ("orbit_4m", &orbit)] {
        let (mut render_s, mut sensor_s) = (0.0, 0.0);
        let mut digest = Fnv1a::default();
        for k in 0..frames {
            let clock = Instant::now();
            let out = renderer.render(&camera, &poses[k % poses.len()].world_from_camera)?;
            render_s += clock.elapsed().as_secs_f64();
            out.depth_m
                .as_slice()
                .iter()
                .for_each(|d| digest.add(&d.to_bits().to_le_bytes()));
            out.instance
                .as_slice()
                .iter()
                .for_each(|i| digest.add(&i.to_le_bytes()));
            out.rgb.as_slice().iter().for_each(|p| digest.add(p));
            let clock = Instant::now();
            let depth = sensor.corrupt_depth(&out.depth_m, camera.fx, k as u64);
            let rgb = sensor.corrupt_rgb(&out.rgb, k as u64);
            sensor_s += clock.elapsed().as_secs_f64();
            std::hint::black_box((depth, rgb));
        }
        let per_frame_ms = |s: f64| 1e3 * s / frames.max(1) as f64;
        println!(
            "{name}: render {:.2} ms/frame ({:.0} frames/s), sensor {:.2} ms/frame, \
             images' digest {:016x}",
            per_frame_ms(render_s),
            frames as f64 / render_s.max(1e-12),
            per_frame_ms(sensor_s),
            digest.0
        );
    }
    Ok(())
}

/// 64-bit FNV-1a over bytes: a digest, not a cryptographic hash.
struct Fnv1a(u64);

impl Default for Fnv1a {
    fn default() -> Self {
        Self(0xcbf2_9ce4_8422_2325)
    }
}

impl Fnv1a {
    fn add(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 = (self.0 ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3);
        }
    }
}
