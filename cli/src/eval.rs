//! `scarp eval`: yardsticks. `scarp eval mesh` scores a reconstructed mesh against the ground
//! truth; `scarp eval traj` scores a trajectory (ATE and RPE, as the TUM benchmark does).

use std::path::PathBuf;

use anyhow::Context;
use clap::{Args, Subcommand};
use scarp_datasets::sequence::Sequence;
use scarp_datasets::world::World;
use scarp_export::ply::read_mesh;
use scarp_export::tum::read_tum_trajectory;

use scarp::evaluation::mesh::{MeshEvalConfig, Visibility, evaluate_mesh};
use scarp::evaluation::trajectory::{Alignment, TrajectoryEvalConfig, evaluate_trajectory};

/// Evaluate outputs against the ground truth.
#[derive(Debug, Args)]
pub struct EvalArgs {
    /// What to evaluate.
    #[command(subcommand)]
    pub command: EvalCommand,
}

/// The evaluations.
#[derive(Debug, Subcommand)]
pub enum EvalCommand {
    /// Accuracy, completeness, precision, recall and F-score at τ of a mesh.
    Mesh(EvalMeshArgs),
    /// Trajectory error: ATE after alignment and RPE, as the TUM RGB-D benchmark defines them.
    Traj(TrajArgs),
}

/// `scarp eval mesh`.
#[derive(Debug, Args)]
pub struct EvalMeshArgs {
    /// Ground-truth mesh (PLY), for example `rock_1.ply` from `scarp world`.
    #[arg(long)]
    pub gt: PathBuf,
    /// Reconstructed mesh (PLY), for example `mesh.ply` from `scarp map`.
    #[arg(long)]
    pub mesh: PathBuf,
    /// Precision/recall threshold τ in metres.
    #[arg(long, default_value_t = 0.01)]
    pub tau: f64,
    /// Ignore reconstruction farther than this (metres) from the ground-truth bounding box.
    #[arg(long)]
    pub crop_to_gt: Option<f64>,
    /// Count a ground-truth sample only if visible from a ground-truth pose of this sequence.
    #[arg(long, requires = "world")]
    pub visible_from: Option<PathBuf>,
    /// The world that occludes (`default` or a world TOML), with `--visible-from`.
    #[arg(long)]
    pub world: Option<String>,
    /// Depth tolerance of the visibility test, metres.
    #[arg(long, default_value_t = 0.01)]
    pub visibility_tolerance: f64,
    /// Surface samples per square metre on each mesh.
    #[arg(long, default_value_t = 40_000.0)]
    pub samples_per_m2: f64,
    /// Seed of the surface sampling.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Print the scores as JSON on stdout.
    #[arg(long)]
    pub json: bool,
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
    /// Alignment of the estimate before the ATE: `se3`, `sim3` or `none`.
    #[arg(long, default_value = "se3")]
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
/// Reading, rendering and evaluation errors naming the file.
pub fn run(args: EvalArgs) -> anyhow::Result<()> {
    match args.command {
        EvalCommand::Mesh(a) => run_mesh(a),
        EvalCommand::Traj(a) => run_traj(&a),
    }
}

fn run_mesh(args: EvalMeshArgs) -> anyhow::Result<()> {
    let gt = read_mesh(&args.gt).with_context(|| format!("reading {}", args.gt.display()))?;
    let mesh = read_mesh(&args.mesh).with_context(|| format!("reading {}", args.mesh.display()))?;
    let config = MeshEvalConfig {
        tau_m: args.tau,
        samples_per_m2: args.samples_per_m2,
        crop_to_gt_m: args.crop_to_gt,
        seed: args.seed,
        ..MeshEvalConfig::default()
    };
    let world;
    let visibility = match (&args.visible_from, &args.world) {
        (Some(seq_dir), Some(name)) => {
            world = World::from_name_or_path(name)
                .with_context(|| format!("loading world `{name}`"))?;
            let seq = Sequence::open(seq_dir)
                .with_context(|| format!("opening sequence {}", seq_dir.display()))?;
            let poses = seq
                .entries
                .iter()
                .enumerate()
                .map(|(i, e)| {
                    e.world_from_camera_truth.with_context(|| {
                        format!("{}: frame {i} has no ground-truth pose", seq_dir.display())
                    })
                })
                .collect::<anyhow::Result<Vec<_>>>()?;
            Some(Visibility {
                world: &world,
                camera: seq.camera,
                world_from_camera: poses,
                tolerance_m: args.visibility_tolerance,
            })
        }
        (Some(_), None) => anyhow::bail!("--visible-from needs --world"),
        _ => None,
    };
    let scores = evaluate_mesh(&mesh, &gt, &config, visibility.as_ref())?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&scores)?);
    } else {
        eprintln!(
            "accuracy {:.4}/{:.4}/{:.4} m (mean/median/p90), completeness {:.4}/{:.4}/{:.4} m, \
             precision {:.4}, recall {:.4}, F-score {:.4} at τ = {} m (visible GT {:.3})",
            scores.accuracy_mean_m,
            scores.accuracy_median_m,
            scores.accuracy_p90_m,
            scores.completeness_mean_m,
            scores.completeness_median_m,
            scores.completeness_p90_m,
            scores.precision,
            scores.recall,
            scores.fscore,
            scores.tau_m,
            scores.gt_visible_fraction
        );
    }
    Ok(())
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
