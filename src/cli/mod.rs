//! The `scarp` command line: one module per subcommand, each with its own clap `Args` struct and a
//! `run` function.

pub mod fragility;

use clap::{Parser, Subcommand};

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
    /// Fragility of a rock mesh: contact, mass properties, rocking angles α(θ), α_min and the
    /// toppling acceleration g·tan(α_min).
    Fragility(fragility::FragilityArgs),
}

/// Runs a parsed command line.
///
/// # Errors
/// Whatever the subcommand reports; the message names the file, line or key at fault.
pub fn run(cli: Cli) -> anyhow::Result<()> {
    init_logging(&cli.log);
    match cli.command {
        Command::Fragility(args) => fragility::run(args),
    }
}

fn init_logging(level: &str) {
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(level));
    // A second initialisation (tests calling `run` twice) is harmless and ignored.
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .try_init();
}
