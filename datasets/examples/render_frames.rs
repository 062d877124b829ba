//! Renders lawn-mower frames of the default world and prints the frame rate:
//! `cargo run --release -p scarp-datasets --example render_frames -- [FRAMES]`.

use scarp_datasets::paths;
use scarp_datasets::render::Renderer;
use scarp_datasets::world::World;
use scarp_slam::PinholeCamera;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let frames: usize = std::env::args()
        .nth(1)
        .map(|a| a.parse())
        .transpose()?
        .unwrap_or(100);
    let start = std::time::Instant::now();
    let world = World::builtin_default()?;
    let renderer = Renderer::new(&world);
    println!("world built in {:.2} s", start.elapsed().as_secs_f64());
    let camera = PinholeCamera::from_hfov(640, 480, 80.0)?;
    let poses = paths::lawnmower(&world, 20.0, 80.0, frames.max(2))?;
    let start = std::time::Instant::now();
    let mut covered = 0usize;
    for pose in &poses[..frames] {
        let out = renderer.render(&camera, &pose.world_from_camera)?;
        covered += out.depth_m.as_slice().iter().filter(|&&d| d > 0.0).count();
    }
    let seconds = start.elapsed().as_secs_f64();
    println!(
        "{frames} frames in {seconds:.2} s: {:.1} ms a frame, {:.0} frames/s ({} threads, {:.0}% pixels hit)",
        1e3 * seconds / frames as f64,
        frames as f64 / seconds,
        rayon::current_num_threads(),
        100.0 * covered as f64 / (frames * 640 * 480) as f64
    );
    Ok(())
}
