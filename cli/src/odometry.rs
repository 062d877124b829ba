//! `scarp odometry`: track a whole sequence with RGBD odometry, initialised from the state
//! estimator's relative motion, and write the trajectory.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;
use clap::{Args, ValueEnum};
use nalgebra::Isometry3;
use scarp_datasets::sequence::Sequence;
use scarp_export::atomic::write_bytes_atomically;
use scarp_export::tum::{StampedPose, write_tum_trajectory};
use scarp_slam::geometry::renormalized;
use scarp_slam::keyframes::{KeyframeConfig, KeyframeSelector};
use scarp_slam::odometry::{OdometryConfig, SourceFrame, TrackingReference, frame_pyramid, track};
use serde::Serialize;

use scarp::evaluation::trajectory::{TrajectoryEvalConfig, TrajectoryMetrics, evaluate_trajectory};

/// Track a sequence frame-to-frame (or frame-to-keyframe) and write `DIR/trajectory.txt`.
#[derive(Debug, Args)]
pub struct OdometryArgs {
    /// The TUM RGB-D sequence directory (as `scarp render` writes it).
    pub sequence: PathBuf,
    /// Output directory: `trajectory.txt` (TUM) and `odometry.json`.
    #[arg(long)]
    pub out: PathBuf,
    /// What each frame is tracked against.
    #[arg(long, value_enum, default_value = "keyframe")]
    pub reference: ReferenceMode,
    /// A TOML file with `[odometry]` and `[keyframes]` tables overriding the defaults.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// A `camera.toml` to read in place of the sequence's own (for example one with a `[color]`
    /// table, so a Kinect's unregistered colour is registered to its depth on load).
    #[arg(long)]
    pub camera: Option<PathBuf>,
    /// Track only the first N frames.
    #[arg(long)]
    pub frames: Option<usize>,
    /// Print the summary JSON on stdout.
    #[arg(long)]
    pub json: bool,
}

/// The reference a frame is tracked against.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum ReferenceMode {
    /// The previous frame.
    Previous,
    /// The last keyframe (fewer hand-overs, so less drift).
    Keyframe,
}

/// Settings of [`track_sequence`], readable from TOML.
#[derive(Debug, Clone, Default, PartialEq, serde::Deserialize, Serialize)]
#[serde(default, deny_unknown_fields)]
pub struct SequenceOdometryConfig {
    /// The odometry.
    pub odometry: OdometryConfig,
    /// Keyframe thresholds (used with [`ReferenceMode::Keyframe`]).
    pub keyframes: KeyframeConfig,
}

/// The result of tracking a sequence.
#[derive(Debug, Clone)]
pub struct SequenceOdometry {
    /// `world_from_camera` per frame: the first frame's state estimate, then chained odometry
    /// (the estimator's relative motion where odometry failed).
    pub poses: Vec<StampedPose>,
    /// Odometry time per tracked frame (pyramid, preparation and tracking), milliseconds.
    pub odometry_ms: Vec<f64>,
    /// `(frame index, reason)` of every failure.
    pub failures: Vec<(usize, String)>,
    /// Indices of the keyframes.
    pub keyframes: Vec<usize>,
}

/// The JSON summary (`odometry.json`).
#[derive(Debug, Clone, Serialize)]
pub struct OdometrySummary {
    /// Frames in the trajectory.
    pub frames: usize,
    /// The reference mode.
    pub reference: ReferenceMode,
    /// Median odometry time per frame, milliseconds.
    pub odometry_ms_median: f64,
    /// Mean odometry time per frame, milliseconds.
    pub odometry_ms_mean: f64,
    /// Frames where odometry failed and the state estimate was used.
    pub odometry_failures: usize,
    /// The failures: frame index and reason.
    pub failure_reasons: Vec<(usize, String)>,
    /// Number of keyframes.
    pub keyframes: usize,
    /// Trajectory metrics of the odometry against `groundtruth.txt` (SE(3) alignment), when the
    /// sequence has ground truth.
    pub odometry_vs_truth: Option<TrajectoryMetrics>,
    /// The same for the state estimate (`estimate.txt`).
    pub estimate_vs_truth: Option<TrajectoryMetrics>,
}

/// Tracks `frames` frames of `sequence`. Each frame is initialised with the estimator's relative
/// motion since the previous frame (or, without `estimate.txt`, the previous frame's tracked
/// motion), composed onto the previous frame's odometry pose.
///
/// # Errors
/// Frame loading and configuration errors, naming the file.
pub fn track_sequence(
    sequence: &Sequence,
    frames: usize,
    mode: ReferenceMode,
    config: &SequenceOdometryConfig,
    on_frame: &dyn Fn(),
) -> anyhow::Result<SequenceOdometry> {
    let camera = sequence.camera;
    let odo = &config.odometry;
    odo.validate()?;
    // The state estimate guides tracking; a sequence without one (a handheld camera) is
    // tracked from the previous frame's motion, and its first frame sits at its ground-truth
    // pose when there is one (the trajectory's gauge only).
    let estimate = |i: usize| sequence.entries[i].world_from_camera_estimate;
    let world_from_first_camera = sequence
        .entries
        .first()
        .and_then(|e| e.world_from_camera_estimate.or(e.world_from_camera_truth));
    let mut last_motion = Isometry3::identity();
    let mut result = SequenceOdometry {
        poses: Vec::with_capacity(frames),
        odometry_ms: Vec::new(),
        failures: Vec::new(),
        keyframes: Vec::new(),
    };
    let mut selector = KeyframeSelector::new(config.keyframes, camera);
    // The current reference and its world_from_camera.
    let mut reference: Option<(TrackingReference, Isometry3<f64>)> = None;
    for i in 0..frames {
        let frame = sequence
            .load_frame(i)
            .with_context(|| format!("loading frame {i} of {}", sequence.dir.display()))?;
        let timestamp_s = sequence.entries[i].timestamp_s;
        let started = Instant::now();
        let pyramid = frame_pyramid(&frame, odo.levels);
        let world_from_camera = renormalized(&match (&reference, result.poses.last()) {
            (Some((reference_images, world_from_reference)), Some(previous)) => {
                let previous_pose = previous.world_from_camera;
                let relative = match (estimate(i - 1), estimate(i)) {
                    (Some(a), Some(b)) => a.inverse() * b,
                    _ => last_motion,
                };
                let guess = world_from_reference.inverse() * previous_pose * relative;
                let source = SourceFrame::from_pyramid(&camera, &pyramid, odo)?;
                let tracked = track(reference_images, &source, &guess, odo)?;
                tracing::debug!(
                    frame = i,
                    iterations = tracked.iterations,
                    inlier_ratio = tracked.inlier_ratio,
                    correspondences = tracked.correspondences,
                    failure = ?tracked.failure,
                    "tracked"
                );
                match &tracked.failure {
                    None => *world_from_reference * tracked.reference_from_current,
                    Some(failure) => {
                        result.failures.push((i, failure.to_string()));
                        previous_pose * relative
                    }
                }
            }
            _ => world_from_first_camera.unwrap_or_else(Isometry3::identity),
        });
        if let Some(previous) = result.poses.last() {
            last_motion = renormalized(&(previous.world_from_camera.inverse() * world_from_camera));
        }
        let failed_now = result.failures.last().is_some_and(|(k, _)| *k == i);
        let new_reference = match mode {
            ReferenceMode::Previous => true,
            ReferenceMode::Keyframe => {
                // A failure re-anchors on this frame, as does a crossed threshold.
                let offered = selector.offer(&world_from_camera, &frame.depth_m).is_some();
                if failed_now && !offered {
                    selector = KeyframeSelector::new(config.keyframes, camera);
                    selector.offer(&world_from_camera, &frame.depth_m);
                }
                offered || failed_now
            }
        };
        if new_reference {
            reference = Some((
                TrackingReference::from_pyramid(&camera, &pyramid, odo)?,
                world_from_camera,
            ));
            result.keyframes.push(i);
            tracing::debug!(frame = i, "new reference");
        }
        if i > 0 {
            result
                .odometry_ms
                .push(started.elapsed().as_secs_f64() * 1000.0);
        }
        result.poses.push(StampedPose {
            timestamp_s,
            world_from_camera,
        });
        on_frame();
    }
    Ok(result)
}

fn median(values: &[f64]) -> f64 {
    scarp_slam::stats::median(values).unwrap_or(0.0)
}

fn poses_of(sequence: &Sequence, frames: usize, truth: bool) -> Option<Vec<StampedPose>> {
    sequence.entries[..frames]
        .iter()
        .map(|e| {
            let pose = if truth {
                e.world_from_camera_truth
            } else {
                e.world_from_camera_estimate
            };
            pose.map(|world_from_camera| StampedPose {
                timestamp_s: e.timestamp_s,
                world_from_camera,
            })
        })
        .collect()
}

/// Runs `scarp odometry`.
///
/// # Errors
/// Sequence, configuration and writing errors, naming the file.
pub fn run(args: OdometryArgs) -> anyhow::Result<()> {
    let sequence = super::open_sequence(&args.sequence, args.camera.as_deref())?;
    let config = match &args.config {
        Some(path) => super::read_toml_config(path)?,
        None => SequenceOdometryConfig::default(),
    };
    let frames = args.frames.unwrap_or(sequence.len()).min(sequence.len());
    anyhow::ensure!(frames > 0, "the sequence has no frames to track");
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let bar = super::progress_bar(frames as u64, "odometry");
    let tracked = track_sequence(&sequence, frames, args.reference, &config, &|| bar.inc(1))?;
    bar.finish_and_clear();
    let trajectory_path = args.out.join("trajectory.txt");
    write_tum_trajectory(
        &trajectory_path,
        &tracked.poses,
        "scarp odometry: world_from_camera",
    )
    .with_context(|| format!("writing {}", trajectory_path.display()))?;

    let eval = TrajectoryEvalConfig::default();
    let truth = poses_of(&sequence, frames, true);
    let estimate = poses_of(&sequence, frames, false);
    let against_truth = |poses: &[StampedPose]| {
        truth
            .as_ref()
            .and_then(|gt| evaluate_trajectory(gt, poses, &eval).ok())
    };
    let summary = OdometrySummary {
        frames,
        reference: args.reference,
        odometry_ms_median: median(&tracked.odometry_ms),
        odometry_ms_mean: tracked.odometry_ms.iter().sum::<f64>()
            / tracked.odometry_ms.len().max(1) as f64,
        odometry_failures: tracked.failures.len(),
        failure_reasons: tracked.failures.clone(),
        keyframes: tracked.keyframes.len(),
        odometry_vs_truth: against_truth(&tracked.poses),
        estimate_vs_truth: estimate.as_deref().and_then(against_truth),
    };
    let json = serde_json::to_string_pretty(&summary)?;
    let summary_path = args.out.join("odometry.json");
    write_bytes_atomically(&summary_path, json.as_bytes())
        .with_context(|| format!("writing {}", summary_path.display()))?;
    if args.json {
        println!("{json}");
    } else {
        eprintln!(
            "tracked {frames} frames: median {:.2} ms/frame, {} failures, {} keyframes; wrote {}",
            summary.odometry_ms_median,
            summary.odometry_failures,
            summary.keyframes,
            trajectory_path.display()
        );
        if let (Some(o), Some(e)) = (&summary.odometry_vs_truth, &summary.estimate_vs_truth) {
            eprintln!(
                "ATE RMSE: odometry {:.4} m, state estimate {:.4} m",
                o.ate_rmse_m, e.ate_rmse_m
            );
        }
    }
    Ok(())
}
