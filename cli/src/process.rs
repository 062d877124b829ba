//! `scarp process`: the rock catalog from a recorded flight (see [`scarp::mission::offline`]).

use std::path::PathBuf;

use anyhow::Context;
use clap::Args;
use scarp_datasets::world::World;

use super::simulate::load_config;
use scarp::mission::offline::{ProcessInputs, process_flight};

/// Process a recorded flight offline: detection, tracking, localization, mapping of every
/// localized target, BA, meshing, fragility and export, as a live mission does.
#[derive(Debug, Args)]
pub struct ProcessArgs {
    /// The flight folder: TUM RGB-D layout with `estimate.txt` and `camera.toml` (as
    /// `scarp simulate --record` writes it; `flight.txt` and `origin.toml` are used when
    /// present).
    pub flight: PathBuf,
    /// Output folder: `mission.json`, `targets/<id>/`, `targets.csv`, `targets.geojson`,
    /// `report.html`.
    #[arg(long)]
    pub out: PathBuf,
    /// Mission configuration (TOML; `scarp config` prints every key with its default): the
    /// detector, tracker, filter, cylinder, mapping and fragility settings are used.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// The world the flight was simulated in (`default`, `library-a`, `library-b` or a TOML
    /// file): adds the ground-truth columns. Without it, nothing is compared with a truth.
    #[arg(long)]
    pub world: Option<String>,
    /// Seed of the simulated detector and the depth filter (the live run's `--seed`
    /// reproduces its perception).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Print `mission.json` on stdout.
    #[arg(long)]
    pub json: bool,
}

/// Runs `scarp process`.
///
/// # Errors
/// An unreadable flight, configuration or world; a write failure.
pub fn run(args: ProcessArgs) -> anyhow::Result<()> {
    let config = load_config(args.config.as_ref())?;
    let world = args
        .world
        .as_deref()
        .map(|name| {
            World::from_name_or_path(name).with_context(|| format!("loading world `{name}`"))
        })
        .transpose()?;
    let report = process_flight(&ProcessInputs {
        flight: args.flight.clone(),
        out: args.out.clone(),
        config,
        world: world.as_ref(),
        seed: args.seed,
    })?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    }
    eprintln!(
        "processed {}: {} targets mapped of {} found in {:.0} s → {}",
        args.flight.display(),
        report.targets_mapped,
        report.targets_found,
        report.wall_time_s,
        args.out.display()
    );
    Ok(())
}
