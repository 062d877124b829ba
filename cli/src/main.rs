//! The `scarp` command-line tool: one module per subcommand, each with its own clap `Args`
//! struct and a `run` function over the `scarp` library. Run `scarp --help` for the subcommands.
//!
//! This crate alone pulls clap, indicatif, ctrlc and the tracing subscriber; the library crates
//! take no command-line types.
mod ba;
mod campaign;
mod config;
mod eval;
mod fragility;
mod localize;
mod map;
mod odometry;
mod plan;
mod process;
mod render;
mod simulate;
mod track;
mod world;

use clap::{Parser, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};

/// Find, localize and map precariously balanced rocks with a small drone.
#[derive(Debug, Parser)]
#[command(name = "scarp", version, about)]
pub struct Cli {
    /// Log verbosity (`error`, `warn`, `info`, `debug`, `trace`); `RUST_LOG` overrides it.
    #[arg(long, global = true, default_value = "info")]
    pub log: String,
    /// The subcommand.
    #[command(subcommand)]
    pub command: Command,
}

/// The subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Bundle-adjust a BAL problem (Levenberg–Marquardt, Schur complement) and report the cost
    /// of every iteration.
    Ba(ba::BaArgs),
    /// Fragility of a rock mesh: contact, mass properties, rocking angles α(θ), α_min and the
    /// toppling acceleration g·tan(α_min).
    Fragility(fragility::FragilityArgs),
    /// Run the simulated mission on a world (the main job).
    Simulate(simulate::SimulateArgs),
    /// Process a recorded flight offline (`scarp simulate --record`, or a real one): the same
    /// catalog, meshes and fragility as a live mission.
    Process(process::ProcessArgs),
    /// Run the mission over many worlds and seeds and tabulate every figure (`campaign.json`,
    /// `campaign.md`); resumable, shardable (`--shard I/N`), `merge` joins shards.
    Campaign(campaign::CampaignArgs),
    /// Evaluate outputs against the ground truth (`scarp eval mesh ...`, `scarp eval traj ...`).
    Eval(eval::EvalArgs),
    /// Track a sequence with RGBD odometry and write its trajectory.
    Odometry(odometry::OdometryArgs),
    /// Localize targets in a sequence with the bounding-box depth filter (detection → tracking
    /// → depth filter); writes each target's points, ellipsoid and status.
    Localize(localize::LocalizeArgs),
    /// Render a camera path through a world into a TUM RGB-D sequence.
    Render(render::RenderArgs),
    /// Write a world's ground-truth meshes and `world.json`.
    World(world::WorldArgs),
    /// Print every tunable with its default, as TOML.
    Config(config::ConfigArgs),
    /// Plan the mapping rings around a target, make a min-snap trajectory and fly it.
    Plan(plan::PlanArgs),
    /// Fuse an RGB-D sequence into a TSDF volume and mesh it (`mesh.ply`, `mesh.glb`,
    /// `map.json`).
    Map(map::MapArgs),
    /// Detect and track target boxes through a sequence (`tracks.txt`, `track.json`, and
    /// MOTA / ID switches / mean IoU / false tracks when `boxes.txt` exists).
    Track(track::TrackArgs),
}

/// Runs a parsed command line.
///
/// # Errors
/// Whatever the subcommand reports; the message names the file, line or key at fault.
pub fn run(cli: Cli) -> anyhow::Result<()> {
    init_logging(&cli.log);
    match cli.command {
        Command::Ba(args) => ba::run(args),
        Command::Fragility(args) => fragility::run(args),
        Command::Simulate(args) => simulate::run(args),
        Command::Process(args) => process::run(args),
        Command::Campaign(args) => campaign::run(args),
        Command::Eval(args) => eval::run(args),
        Command::Odometry(args) => odometry::run(args),
        Command::Localize(args) => localize::run(args),
        Command::Render(args) => render::run(args),
        Command::World(args) => world::run(args),
        Command::Config(args) => config::run(args),
        Command::Plan(args) => plan::run(args),
        Command::Map(args) => map::run(args),
        Command::Track(args) => track::run(args),
    }
}

/// Reads a TOML settings file into `T`; a missing field keeps its default and an unknown key is
/// an error, as the settings' serde attributes say.
///
/// # Errors
/// The file cannot be read, or it does not parse as `T` (the message names the file, and the
/// parser's names the key and line).
pub fn read_toml_config<T: serde::de::DeserializeOwned>(
    path: &std::path::Path,
) -> anyhow::Result<T> {
    use anyhow::Context;
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    toml::from_str(&text).with_context(|| format!("parsing {}", path.display()))
}

/// Opens a sequence with its own `camera.toml`, or with `camera_toml` in its place (the
/// `--camera` option).
pub fn open_sequence(
    dir: &std::path::Path,
    camera_toml: Option<&std::path::Path>,
) -> anyhow::Result<scarp_datasets::sequence::Sequence> {
    use anyhow::Context;
    let sequence = match camera_toml {
        Some(file) => scarp_datasets::sequence::Sequence::open_with_camera_file(dir, file),
        None => scarp_datasets::sequence::Sequence::open(dir),
    };
    sequence.with_context(|| format!("opening sequence {}", dir.display()))
}

/// A progress bar on a terminal; hidden when stderr is not one (CI, pipes).
pub fn progress_bar(length: u64, message: &'static str) -> ProgressBar {
    let bar = ProgressBar::new(length);
    if let Ok(style) = ProgressStyle::with_template("{msg} [{bar:40}] {pos}/{len} ({eta})") {
        bar.set_style(style.progress_chars("=> "));
    }
    bar.set_message(message);
    bar
}

fn init_logging(level: &str) {
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(level));
    // A second initialisation (tests calling `run` twice) is harmless and ignored.
    // Colour codes only on a terminal: a log file (a campaign's run.log) stays plain text.
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .with_writer(std::io::stderr)
        .try_init();
}

fn main() -> std::process::ExitCode {
    let cli = Cli::parse();
    match run(cli) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(error) => {
            eprintln!("error: {error:#}");
            std::process::ExitCode::FAILURE
        }
    }
}
