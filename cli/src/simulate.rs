//! `scarp simulate`: the main job, a closed-loop mission on a world (see [`scarp::mission`]).

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use anyhow::Context;
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use scarp_datasets::world::World;

use super::world::write_world;
use scarp::mission::config::MissionConfig;
use scarp::mission::simulation::{Mission, MissionInputs};

/// Run the simulated mission on a world: search, localize, map and measure every target.
#[derive(Debug, Args)]
pub struct SimulateArgs {
    /// A built-in world (`default`, `library-a`, `library-b`) or a world TOML file.
    #[arg(long, default_value = "default")]
    pub world: String,
    /// Output directory.
    #[arg(long, default_value = "out/simulate")]
    pub out: PathBuf,
    /// Seed of every random draw.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Mission configuration (TOML; `scarp config` prints every key with its default).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Print `mission.json` on stdout.
    #[arg(long)]
    pub json: bool,
    /// Fly on through collisions instead of ending the flight (`safety.allow_collisions`), for
    /// debugging a plan.
    #[arg(long)]
    pub allow_collisions: bool,
    /// Also record the flight as the drone sensed it into this folder: the TUM RGB-D layout
    /// with `estimate.txt`, `camera.toml` and `flight.txt` (mount pitch and mode per frame);
    /// the true poses are kept apart in `groundtruth/`. `scarp process` reads it. Several GB
    /// for a default mission.
    #[arg(long)]
    pub record: Option<PathBuf>,
}

/// The mission configuration in `path`, or the defaults.
///
/// # Errors
/// An unreadable file, or an unknown key or bad value (named).
pub(crate) fn load_config(path: Option<&PathBuf>) -> anyhow::Result<MissionConfig> {
    let Some(path) = path else {
        return Ok(MissionConfig::default());
    };
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    Ok(MissionConfig::from_toml_str(
        &text,
        &path.display().to_string(),
    )?)
}

/// Runs `scarp simulate`.
///
/// # Errors
/// World, configuration, planning and writing errors. Ctrl-C is not an error: the run stops,
/// writes its outputs with `interrupted: true` and returns.
pub fn run(args: SimulateArgs) -> anyhow::Result<()> {
    let started = std::time::Instant::now();
    let mut config = load_config(args.config.as_ref())?;
    config.safety.allow_collisions |= args.allow_collisions;
    let world = World::from_name_or_path(&args.world)
        .with_context(|| format!("loading world `{}`", args.world))?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    write_world(&world, &args.out.join("world_gt"))?;

    let stop = Arc::new(AtomicBool::new(false));
    {
        let stop = Arc::clone(&stop);
        // A second handler (tests running the CLI twice in one process) is refused; the first
        // one still sets its own flag, so only a library caller loses Ctrl-C handling.
        let _ = ctrlc::set_handler(move || stop.store(true, Ordering::Relaxed));
    }
    let mission = Mission::new(MissionInputs {
        world: &world,
        world_name: args.world.clone(),
        config,
        seed: args.seed,
        out: args.out.clone(),
        stop: &stop,
        started,
        record: args.record.clone(),
    })?;
    let bar = ProgressBar::new_spinner();
    if let Ok(style) = ProgressStyle::with_template("{spinner} {elapsed} {msg}") {
        bar.set_style(style);
    }
    let mut last_update = 0.0;
    let report = mission.run(&mut |p| {
        if p.sim_time_s - last_update >= 1.0 {
            last_update = p.sim_time_s;
            bar.set_message(format!(
                "sim {:>6.0} s · {:<13} · targets found {} mapped {}",
                p.sim_time_s,
                p.mode.as_str(),
                p.targets_found,
                p.targets_mapped
            ));
            bar.tick();
        }
    })?;
    bar.finish_and_clear();
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    }
    eprintln!(
        "{}: {} targets mapped of {} found, {} distractors mapped, missed {:?}, {} collisions; \
         {:.0} s simulated in {:.0} s (×{:.1}) → {}",
        report.end_reason,
        report.targets_mapped,
        report.targets_found,
        report.distractors_mapped,
        report.targets_missed,
        report.collisions,
        report.sim_time_s,
        report.wall_time_s,
        report.real_time_factor,
        args.out.display()
    );
    Ok(())
}
