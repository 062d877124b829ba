//! `scarp eval`: the evaluation yardsticks, one subcommand per kind (`traj`; `mesh` joins it).

use std::path::PathBuf;

use anyhow::Context;
use clap::{Args, Subcommand};
use scarp_export::tum::read_tum_trajectory;

use crate::evaluation::trajectory::{Alignment, TrajectoryEvalConfig, evaluate_trajectory};

/// Evaluate results against ground truth.
#[derive(Debug, Args)]
pub struct EvalArgs {
    /// What to evaluate.
    #[command(subcommand)]
    pub command: EvalCommand,
}

/// The evaluation subcommands.
#[derive(Debug, Subcommand)]
pub enum EvalCommand {
    /// Trajectory error: ATE after alignment and RPE, as the TUM RGB-D benchmark defines them.
    Traj(TrajArgs),
}

/// `scarp eval traj`.
#[derive(Debug, Args)]
pub struct TrajArgs {
    /// Ground-truth TUM trajectory (`t tx ty tz qx qy qz qw`).
    #[arg(long)]
    pub gt: PathBuf,
    /// Estimated TUM trajectory.
    #[arg(long)]
    pub est: PathBuf,
    /// Alignment of the estimate before the ATE.
    #[arg(long, value_enum, default_value = "se3")]
    pub align: Alignment,
    /// Largest timestamp difference of an associated pair, seconds.
    #[arg(long, default_value_t = 0.02)]
    pub max_dt: f64,
    /// Print JSON on stdout.
    #[arg(long)]
    pub json: bool,
}

/// Runs `scarp eval`.
///
/// # Errors
/// Reading or evaluation errors, naming the file.
pub fn run(args: EvalArgs) -> anyhow::Result<()> {
    match args.command {
        EvalCommand::Traj(args) => run_traj(&args),
    }
}

fn run_traj(args: &TrajArgs) -> anyhow::Result<()> {
    let gt = read_tum_trajectory(&args.gt)
        .with_context(|| format!("reading ground truth {}", args.gt.display()))?;
    let est = read_tum_trajectory(&args.est)
        .with_context(|| format!("reading estimate {}", args.est.display()))?;
    let config = TrajectoryEvalConfig {
        max_dt_s: args.max_dt,
        alignment: args.align,
        ..TrajectoryEvalConfig::default()
    };
    let metrics = evaluate_trajectory(&gt, &est, &config).with_context(|| {
        format!(
            "evaluating {} against {}",
            args.est.display(),
            args.gt.display()
        )
    })?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&metrics)?);
    } else {
        let opt = |v: Option<f64>| v.map_or_else(|| "n/a".to_string(), |v| format!("{v:.6}"));
        println!("pairs                  {}", metrics.pairs);
        println!(
            "alignment              {:?} (scale {:.6})",
            metrics.alignment, metrics.scale
        );
        println!("ATE RMSE               {:.6} m", metrics.ate_rmse_m);
        println!("ATE mean               {:.6} m", metrics.ate_mean_m);
        println!("ATE median             {:.6} m", metrics.ate_median_m);
        println!("ATE max                {:.6} m", metrics.ate_max_m);
        println!(
            "RPE trans per frame    {:.6} m",
            metrics.rpe_trans_m_per_frame
        );
        println!("RPE trans per metre    {}", opt(metrics.rpe_trans_per_m));
        println!(
            "RPE trans per second   {} m/s",
            opt(metrics.rpe_trans_m_per_s)
        );
        println!(
            "RPE rot per frame      {:.6}°",
            metrics.rpe_rot_deg_per_frame
        );
    }
    Ok(())
}
