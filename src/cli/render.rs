//! `scarp render`: render a camera path through a world into a TUM RGB-D sequence.

use std::path::PathBuf;

use anyhow::Context;
use clap::{Args, ValueEnum};
use scarp_datasets::estimator::EstimatorConfig;
use scarp_datasets::paths;
use scarp_datasets::sensor::SensorConfig;
use scarp_datasets::sequence::{RenderSettings, SequenceSummary, write_sequence};
use scarp_datasets::world::World;
use scarp_slam::PinholeCamera;

/// Render a sequence (RGB, depth, instance masks, true and estimated poses, boxes).
#[derive(Debug, Args)]
pub struct RenderArgs {
    /// `default` for the built-in world, or a world TOML file.
    #[arg(long, default_value = "default")]
    pub world: String,
    /// `orbit` (4 m around the first target, 2 m above it), `lawnmower` (20 m altitude sweep),
    /// or a TUM trajectory file of `world_from_camera` poses.
    #[arg(long, default_value = "orbit")]
    pub path: String,
    /// Number of frames (ignored for a trajectory file, which sets its own).
    #[arg(long, default_value_t = 120)]
    pub frames: usize,
    /// Output sequence directory.
    #[arg(long)]
    pub out: PathBuf,
    /// Seed of the sensor and estimator noise.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Clean images, and an estimate equal to the ground truth.
    #[arg(long)]
    pub no_noise: bool,
    /// Depth PNG units per metre; default 5000 (TUM) for orbits and files, 1000 for lawn-mower
    /// sweeps, whose depths exceed 13 m.
    #[arg(long)]
    pub depth_scale: Option<f64>,
    /// Print a JSON summary on stdout.
    #[arg(long)]
    pub json: bool,
}

/// Which kind of path.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
enum PathKind {
    Orbit,
    Lawnmower,
    File,
}

/// The default camera: 640×480, 80° horizontal field of view.
pub fn default_camera() -> PinholeCamera {
    // Constant, valid intrinsics.
    PinholeCamera::from_hfov(640, 480, 80.0).expect("valid default camera")
}

/// Renders a sequence as the arguments say; shared by `render` and `simulate`.
///
/// # Errors
/// World, path and writing errors, naming the file or key.
pub fn render_sequence(args: &RenderArgs) -> anyhow::Result<SequenceSummary> {
    let world = World::from_name_or_path(&args.world)
        .with_context(|| format!("loading world `{}`", args.world))?;
    let camera = default_camera();
    let (kind, poses) = match args.path.as_str() {
        "orbit" => (PathKind::Orbit, paths::default_orbit(&world, args.frames)?),
        "lawnmower" => (
            PathKind::Lawnmower,
            paths::lawnmower(&world, 20.0, camera.hfov_deg(), args.frames)?,
        ),
        file => (
            PathKind::File,
            paths::from_tum_file(std::path::Path::new(file))?,
        ),
    };
    let depth_scale = args.depth_scale.unwrap_or(if kind == PathKind::Lawnmower {
        1000.0
    } else {
        5000.0
    });
    anyhow::ensure!(
        depth_scale > 0.0 && depth_scale.is_finite(),
        "--depth-scale must be positive"
    );
    let settings = RenderSettings {
        camera,
        noise: !args.no_noise,
        sensor: SensorConfig::default(),
        estimator: EstimatorConfig::default(),
        seed: args.seed,
        depth_scale,
    };
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let bar = super::progress_bar(poses.len() as u64, "rendering");
    let summary = write_sequence(&args.out, &world, &poses, &settings, &|| bar.inc(1))?;
    bar.finish_and_clear();
    Ok(summary)
}

/// Runs `scarp render`.
///
/// # Errors
/// As [`render_sequence`].
pub fn run(args: RenderArgs) -> anyhow::Result<()> {
    let summary = render_sequence(&args)?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
    } else {
        eprintln!(
            "wrote {} frames ({} boxes) to {} in {:.1} s ({:.0} frames/s)",
            summary.frames,
            summary.boxes,
            args.out.display(),
            summary.seconds,
            summary.frames as f64 / summary.seconds.max(1e-9)
        );
    }
    Ok(())
}
