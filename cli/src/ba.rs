//! `scarp ba`: bundle-adjust a BAL problem and report the cost of every iteration.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;
use clap::{Args, ValueEnum};
use scarp_slam::ba::{LmConfig, RobustLoss, read_bal, solve_bal};

/// Robust loss choice on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum LossArg {
    /// Plain least squares.
    None,
    /// Huber with threshold `--loss-scale-px`.
    Huber,
    /// Cauchy with scale `--loss-scale-px`.
    Cauchy,
}

/// Bundle-adjust a BAL problem ("Bundle Adjustment in the Large" text format) with
/// Levenberg–Marquardt and the Schur complement.
#[derive(Debug, Args)]
pub struct BaArgs {
    /// The BAL problem file.
    pub file: PathBuf,
    /// Maximum number of LM iterations (accepted and rejected steps).
    #[arg(long, default_value_t = 50)]
    pub max_iterations: usize,
    /// Worker threads (default: all cores). Results do not depend on it.
    #[arg(long)]
    pub threads: Option<usize>,
    /// Robust loss on each observation.
    #[arg(long, value_enum, default_value_t = LossArg::None)]
    pub loss: LossArg,
    /// Scale of the robust loss, pixels.
    #[arg(long, default_value_t = 1.0)]
    pub loss_scale_px: f64,
    /// Print the result as JSON on stdout.
    #[arg(long)]
    pub json: bool,
}

/// Runs `scarp ba`.
///
/// # Errors
/// Reading errors (naming the file and line), invalid settings, or a problem that cannot be
/// evaluated at its start.
pub fn run(args: BaArgs) -> anyhow::Result<()> {
    let mut builder = rayon::ThreadPoolBuilder::new();
    if let Some(threads) = args.threads {
        anyhow::ensure!(threads > 0, "--threads must be at least 1");
        builder = builder.num_threads(threads);
    }
    let pool = builder.build().context("starting the worker threads")?;
    let config = LmConfig {
        max_iterations: args.max_iterations,
        loss: match args.loss {
            LossArg::None => RobustLoss::Trivial,
            LossArg::Huber => RobustLoss::Huber {
                delta_px: args.loss_scale_px,
            },
            LossArg::Cauchy => RobustLoss::Cauchy {
                scale_px: args.loss_scale_px,
            },
        },
        ..LmConfig::default()
    };
    let read_start = Instant::now();
    let mut problem = read_bal(&args.file)?;
    let read_seconds = read_start.elapsed().as_secs_f64();
    let solve_start = Instant::now();
    let summary = pool
        .install(|| solve_bal(&mut problem, &config))
        .with_context(|| format!("bundle-adjusting {}", args.file.display()))?;
    let seconds = solve_start.elapsed().as_secs_f64();
    if args.json {
        let json = serde_json::json!({
            "file": args.file.display().to_string(),
            "cameras": problem.cameras.len(),
            "points": problem.points.len(),
            "observations": problem.observations.len(),
            "initial_cost": summary.initial_cost,
            "final_cost": summary.final_cost,
            "iterations": summary.iterations,
            "seconds": seconds,
            "read_seconds": read_seconds,
            "threads": pool.current_num_threads(),
            "termination": summary.termination,
            "linear_solver": summary.linear_solver,
            "costs": summary.costs,
            "log": summary.log,
        });
        println!("{}", serde_json::to_string_pretty(&json)?);
    } else {
        for entry in &summary.log {
            eprintln!(
                "iter {:3}  cost {:.6e}  {}  radius {:.2e}  |g|∞ {:.2e}  |δ| {:.2e}",
                entry.iteration,
                entry.cost,
                if entry.accepted {
                    "accepted"
                } else {
                    "rejected"
                },
                entry.trust_region_radius,
                entry.gradient_max_norm,
                entry.step_norm,
            );
        }
        println!(
            "{}: {} cameras, {} points, {} observations; cost {:.6} -> {:.6} in {} iterations, {:.3} s ({:?})",
            args.file.display(),
            problem.cameras.len(),
            problem.points.len(),
            problem.observations.len(),
            summary.initial_cost,
            summary.final_cost,
            summary.iterations,
            seconds,
            summary.termination,
        );
    }
    Ok(())
}
