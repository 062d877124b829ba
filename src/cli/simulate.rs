//! `scarp simulate`: the main job. Until the closed-loop mission exists, it writes the default
//! world's ground truth and renders its demo sequences (a lawn-mower survey and an orbit of the
//! first target) and says so.

use std::path::PathBuf;

use clap::Args;

use super::render::{RenderArgs, render_sequence};
use super::world::write_world;

/// Run the simulated mission on a world.
#[derive(Debug, Args)]
pub struct SimulateArgs {
    /// `default` for the built-in world, or a world TOML file.
    #[arg(long, default_value = "default")]
    pub world: String,
    /// Output directory.
    #[arg(long, default_value = "out/simulate")]
    pub out: PathBuf,
    /// Seed of every random draw.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Print a JSON summary on stdout.
    #[arg(long)]
    pub json: bool,
}

/// Runs `scarp simulate`.
///
/// # Errors
/// World, rendering and writing errors.
pub fn run(args: SimulateArgs) -> anyhow::Result<()> {
    eprintln!(
        "scarp simulate: the closed-loop mission is not built yet; rendering the demo sequences of world `{}` instead",
        args.world
    );
    let world = scarp_datasets::world::World::from_name_or_path(&args.world)?;
    write_world(&world, &args.out.join("world_gt"))?;
    let mut summaries = serde_json::Map::new();
    for (path, frames) in [("lawnmower", 200), ("orbit", 120)] {
        let render = RenderArgs {
            world: args.world.clone(),
            path: path.into(),
            frames,
            target: None,
            altitude: 20.0,
            area_m: 30.0,
            out: args.out.join(path),
            seed: args.seed,
            no_noise: false,
            depth_scale: None,
            json: false,
        };
        let summary = render_sequence(&render)?;
        eprintln!(
            "{path}: {} frames in {:.1} s → {}",
            summary.frames,
            summary.seconds,
            render.out.display()
        );
        summaries.insert(path.into(), serde_json::to_value(&summary)?);
    }
    if args.json {
        println!("{}", serde_json::to_string_pretty(&summaries)?);
    }
    Ok(())
}
