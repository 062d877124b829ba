//! `scarp localize`: run detection, tracking and the depth filter over a sequence and write
//! each target's point set, ellipsoid and status. It runs the mission's perception path
//! ([`scarp::mission::perception::Perception`]) with the mission's default detector, tracker and
//! box-filter settings.

use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::{Args, ValueEnum};
use nalgebra::{Isometry3, Point3};
use scarp_datasets::sequence::Sequence;
use scarp_datasets::world::{RockRole, World};
use scarp_export::atomic::write_bytes_atomically;
use scarp_export::ply::{PlyEncoding, write_point_cloud};
use scarp_slam::PointCloud;
use serde::Serialize;

use scarp::detection::simulated::roles_from_boxes;
use scarp::detection::{BoundingBox, Detection, Detector, ReplayDetector};
use scarp::evaluation::mesh::MeshDistance;
use scarp::localization::{LocalizationConfig, Target, TargetStatus};
use scarp::mission::config::MissionConfig;
use scarp::mission::evaluation::{EstimatorErrorByTarget, estimate_frame_error_m};
use scarp::mission::perception::{BoxSource, Perception, mission_detector};

/// Localize targets in a sequence with the bounding-box depth filter.
#[derive(Debug, Args)]
pub struct LocalizeArgs {
    /// Sequence directory (TUM RGB-D layout as written by `scarp render`).
    pub sequence: PathBuf,
    /// Where the boxes come from: `simulated` (the modelled network on the instance masks:
    /// jitter, misses, sporadic false positives) or `groundtruth` (the sequence's `boxes.txt`,
    /// targets only, one track per rock).
    #[arg(long, value_enum, default_value_t = DetectorKind::Simulated)]
    pub detector: DetectorKind,
    /// Bounding-box tracker between the detector and the filter: `klt` (Kalman filter with KLT
    /// prediction; only confirmed tracks reach the filter) or `none` (every detection is fed
    /// directly, as its own track).
    #[arg(long, value_enum, default_value_t = TrackerKind::Klt)]
    pub tracker: TrackerKind,
    /// Also feed the filter confirmed tracks that no detection updated in this frame (boxes
    /// predicted by KLT alone). Off by default: on sparse frames the prediction drifts, and a
    /// drifted box on a keyframe pulls the points away.
    #[arg(long)]
    pub predicted_boxes: bool,
    /// Camera poses fed to the filter: the noisy state `estimate` or the `groundtruth`.
    #[arg(long, value_enum, default_value_t = PoseSource::Estimate)]
    pub poses: PoseSource,
    /// The world the sequence was rendered from (`default` or a TOML file), for ground truth.
    #[arg(long, default_value = "default")]
    pub world: String,
    /// Skip the comparison with the world's rocks.
    #[arg(long)]
    pub no_ground_truth: bool,
    /// A target matches the nearest true rock whose centroid lies within this distance, m.
    /// Default 3 m: rocks of the built-in world are at least 9 m apart, and the state
    /// estimate's bias (about 1 m) shifts every estimated target.
    #[arg(long, default_value_t = 3.0)]
    pub match_radius_m: f64,
    /// A TOML file with `LocalizationConfig` fields (missing ones take their defaults).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Seed of the depth filter (and of the simulated detector).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Output directory: `targets/<id>/points.ply`, `targets/<id>/target.json`,
    /// `localization.json`.
    #[arg(long)]
    pub out: PathBuf,
    /// Print the summary JSON on stdout.
    #[arg(long)]
    pub json: bool,
}

/// The source of boxes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum DetectorKind {
    /// [`scarp::detection::simulated::SimulatedDetector`] with the mission's default
    /// configuration, seeded from `--seed`, on the sequence's instance masks; the roles of the
    /// rocks come from `boxes.txt`.
    Simulated,
    /// Perfect boxes of the target rocks from `boxes.txt`; the rock id is the track id.
    Groundtruth,
}

/// The tracker stage.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum TrackerKind {
    /// The mission's KLT/Kalman box tracker with its default configuration, on the grey image
    /// of each frame.
    Klt,
    /// No tracker: detections go straight to the depth filter.
    None,
}

/// Which poses drive the filter.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum PoseSource {
    /// The noisy state estimate (`estimate.txt`).
    Estimate,
    /// The true poses (`groundtruth.txt`).
    Groundtruth,
}

/// One target in the summary.
#[derive(Debug, Clone, Serialize)]
pub struct TargetSummary {
    /// Catalog id.
    pub id: u32,
    /// `tracking`, `ready_for_fine_localization` or `converged`.
    pub status: TargetStatus,
    /// Point-set centre C_e, world ENU, m.
    pub center: [f64; 3],
    /// Largest covariance eigenvalue, m².
    pub lambda_max: f64,
    /// Differential entropy of the Gaussian fit, nats.
    pub entropy: f64,
    /// KL divergence of the last update, nats.
    pub last_kl: Option<f64>,
    /// The point set, relative to the output directory.
    pub points: String,
    /// Number of points.
    pub point_count: usize,
    /// Updates applied.
    pub updates: u32,
    /// Frames with a box on the target.
    pub hits: u32,
    /// The matched true rock, when ground truth is used.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub gt_rock_id: Option<u32>,
    /// Its role (`target` or `distractor`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub gt_role: Option<&'static str>,
    /// Distance from the centre to the true rock's centroid, m.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub centroid_error_m: Option<f64>,
    /// The error in the frame the vehicle flies in: from the centre to the true centroid moved
    /// by the mean estimate − truth position error over the frames that updated this target,
    /// m. Needs both trajectories in the sequence.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub localization_error_estimate_frame_m: Option<f64>,
    /// Fraction of points within 0.5 m of the true rock's surface.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fraction_on_surface: Option<f64>,
}

/// The output of `scarp localize`.
#[derive(Debug, Clone, Serialize)]
pub struct LocalizeSummary {
    /// The sequence read.
    pub sequence: String,
    /// Frames processed.
    pub frames: usize,
    /// Box source.
    pub detector: DetectorKind,
    /// Tracker stage.
    pub tracker: TrackerKind,
    /// Pose source.
    pub poses: PoseSource,
    /// Confirmed targets at the end (hit by boxes in at least `confirm_hits` frames).
    pub targets: Vec<TargetSummary>,
    /// Live targets still unconfirmed at the end (not reported as targets).
    pub tentative_targets: usize,
    /// Ids of live targets that match no true rock (only with ground truth).
    pub false_targets: Vec<u32>,
    /// Targets removed by the hit/miss counters during the run.
    pub removed_targets: usize,
    /// Converged duplicates merged during the run.
    pub merged_targets: usize,
    /// Wall time, s.
    pub seconds: f64,
}

/// The `world_from_camera` of frame `index` from the chosen source.
fn frame_pose(seq: &Sequence, index: usize, source: PoseSource) -> anyhow::Result<Isometry3<f64>> {
    let entry = &seq.entries[index];
    let pose = match source {
        PoseSource::Estimate => entry.world_from_camera_estimate,
        PoseSource::Groundtruth => entry.world_from_camera_truth,
    };
    pose.with_context(|| {
        format!(
            "{}: frame {index} (t = {:.6} s) has no {} pose",
            seq.dir.display(),
            entry.timestamp_s,
            match source {
                PoseSource::Estimate => "estimated (estimate.txt)",
                PoseSource::Groundtruth => "ground-truth (groundtruth.txt)",
            }
        )
    })
}

/// Perfect detections of the target rocks in frame `index`, from `boxes.txt` (matched by
/// The sequence's `boxes.txt` target boxes as timestamped detections (a perfect detector).
fn ground_truth_detections(seq: &Sequence) -> Vec<(f64, Detection)> {
    seq.boxes
        .iter()
        .filter(|b| b.role == RockRole::Target)
        .map(|b| {
            (
                b.timestamp_s,
                Detection {
                    bbox: BoundingBox::from_inclusive_pixels(b.bbox_px),
                    score: 1.0,
                    class_id: 0,
                },
            )
        })
        .collect()
}

/// Ground-truth comparison of one target located at `c` (its C_e): the nearest rock within
/// `radius_m`, the centroid error and the fraction of points within 0.5 m of its surface.
fn compare_with_world(
    target: &Target,
    c: &Point3<f64>,
    world: &World,
    radius_m: f64,
) -> anyhow::Result<Option<(u32, &'static str, f64, f64)>> {
    let nearest = world
        .rocks
        .iter()
        .map(|r| (r, (r.centroid - c).norm()))
        .filter(|(_, d)| *d <= radius_m)
        .min_by(|a, b| a.1.total_cmp(&b.1));
    let Some((rock, error_m)) = nearest else {
        return Ok(None);
    };
    let distance = MeshDistance::new(&rock.mesh, "rock")
        .with_context(|| format!("rock {} has an empty mesh", rock.id))?;
    let on = target
        .points()
        .iter()
        .filter(|p| distance.distance(p) <= 0.5)
        .count();
    let fraction = on as f64 / target.points().len().max(1) as f64;
    Ok(Some((rock.id, rock.role.as_str(), error_m, fraction)))
}

fn write_target(dir: &Path, summary: &TargetSummary, target: &Target) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let cloud = PointCloud::from_positions(target.points().iter().map(|p| p.cast()).collect());
    let ply = dir.join("points.ply");
    write_point_cloud(&ply, &cloud, PlyEncoding::BinaryLittleEndian)
        .with_context(|| format!("writing {}", ply.display()))?;
    let ellipsoid = target.ellipsoid();
    let json = serde_json::json!({
        "id": summary.id,
        "status": summary.status,
        "center": summary.center,
        "covariance": target.covariance(),
        "ellipsoid": {
            "center": [ellipsoid.center.x, ellipsoid.center.y, ellipsoid.center.z],
            "axes_world": ellipsoid.world_from_ellipsoid.matrix(),
            "eigenvalues_m2": ellipsoid.eigenvalues_m2,
            "semi_axes_m": ellipsoid.semi_axes_m,
        },
        "lambda_max": summary.lambda_max,
        "entropy": summary.entropy,
        "last_kl": summary.last_kl,
        "updates": summary.updates,
        "hits": summary.hits,
        "gt_rock_id": summary.gt_rock_id,
        "centroid_error_m": summary.centroid_error_m,
        "fraction_on_surface": summary.fraction_on_surface,
    });
    let path = dir.join("target.json");
    write_bytes_atomically(&path, serde_json::to_string_pretty(&json)?.as_bytes())
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(())
}

/// Runs the depth filter over a sequence and writes the outputs.
///
/// # Errors
/// Unreadable sequence, world or config; a frame without the chosen pose; bad boxes or poses
/// (named by frame); write failures.
pub fn localize(args: &LocalizeArgs) -> anyhow::Result<LocalizeSummary> {
    let started = std::time::Instant::now();
    let seq = Sequence::open(&args.sequence)
        .with_context(|| format!("opening sequence {}", args.sequence.display()))?;
    let config = match &args.config {
        Some(path) => super::read_toml_config::<LocalizationConfig>(path)?,
        None => LocalizationConfig::default(),
    };
    let world = if args.no_ground_truth {
        None
    } else {
        Some(
            World::from_name_or_path(&args.world)
                .with_context(|| format!("loading world `{}`", args.world))?,
        )
    };
    // The mission's perception path and defaults: the same detector settings, tracker and box
    // filter, only the detector's and the filter's seeds come from `--seed`.
    let defaults = MissionConfig::default();
    let detector: Box<dyn Detector> = match args.detector {
        DetectorKind::Simulated => Box::new(mission_detector(
            &defaults.detection.simulated,
            roles_from_boxes(&seq.boxes),
            args.seed,
        )?),
        DetectorKind::Groundtruth => Box::new(ReplayDetector::new(ground_truth_detections(&seq))),
    };
    let box_source = match (args.tracker, args.predicted_boxes) {
        (TrackerKind::None, _) => BoxSource::Detections,
        (TrackerKind::Klt, false) => BoxSource::UpdatedTracks,
        (TrackerKind::Klt, true) => BoxSource::ConfirmedTracks,
    };
    let mut perception = Perception::with_detector(
        detector,
        defaults.tracker.clone(),
        box_source,
        config,
        args.seed,
    )?;
    let mut merged = 0;
    let mut pose_error_by_target = EstimatorErrorByTarget::default();
    // No mission here: every update localizes (no centre is frozen for mapping).
    let no_mission_targets = scarp::mission::catalog::Catalog::new();
    let bar = super::progress_bar(seq.len() as u64, "localizing");
    for index in 0..seq.len() {
        let world_from_camera = frame_pose(&seq, index, args.poses)?;
        let frame = seq
            .load_frame(index)
            .with_context(|| format!("{}: loading frame {index}", seq.dir.display()))?;
        let step = perception
            .process(&frame, &seq.camera, &world_from_camera)
            .with_context(|| format!("frame {index} of {}", seq.dir.display()))?;
        let report = &step.observed;
        for id in &report.registered {
            tracing::debug!(frame = index, target = id, "registered");
        }
        for id in &report.removed {
            tracing::debug!(frame = index, target = id, "removed as false");
        }
        merged += report.merged.len();
        let entry = &seq.entries[index];
        if let (Some(estimate), Some(truth)) = (
            entry.world_from_camera_estimate,
            entry.world_from_camera_truth,
        ) {
            pose_error_by_target.record(&report.updated, &no_mission_targets, &estimate, &truth);
        }
        bar.inc(1);
    }
    bar.finish_and_clear();
    let catalog = perception.catalog();

    let mut targets = Vec::new();
    let mut false_targets = Vec::new();
    let mut tentative = 0;
    for target in catalog.targets() {
        if !target.is_confirmed(catalog.config()) {
            tentative += 1;
            continue;
        }
        let c = target.located_center(catalog.config().center_from_depth_views);
        let mut summary = TargetSummary {
            id: target.id(),
            status: target.status(),
            center: [c.x, c.y, c.z],
            lambda_max: target.lambda_max(),
            entropy: target.entropy_nats(),
            last_kl: target.last_kl_nats(),
            points: format!("targets/{}/points.ply", target.id()),
            point_count: target.points().len(),
            updates: target.updates(),
            hits: target.hits(),
            gt_rock_id: None,
            gt_role: None,
            centroid_error_m: None,
            localization_error_estimate_frame_m: None,
            fraction_on_surface: None,
        };
        if let Some(world) = &world {
            match compare_with_world(target, &c, world, args.match_radius_m)? {
                Some((rock, role, error_m, fraction)) => {
                    summary.localization_error_estimate_frame_m = pose_error_by_target
                        .mean_m(target.id())
                        .zip(world.rocks.iter().find(|r| r.id == rock))
                        .map(|(mean, r)| estimate_frame_error_m(&c, &r.centroid, &mean));
                    summary.gt_rock_id = Some(rock);
                    summary.gt_role = Some(role);
                    summary.centroid_error_m = Some(error_m);
                    summary.fraction_on_surface = Some(fraction);
                }
                None => false_targets.push(target.id()),
            }
        }
        write_target(
            &args.out.join("targets").join(target.id().to_string()),
            &summary,
            target,
        )?;
        targets.push(summary);
    }
    let summary = LocalizeSummary {
        sequence: args.sequence.display().to_string(),
        frames: seq.len(),
        detector: args.detector,
        tracker: args.tracker,
        poses: args.poses,
        targets,
        false_targets,
        tentative_targets: tentative,
        removed_targets: catalog.removed_count(),
        merged_targets: merged,
        seconds: started.elapsed().as_secs_f64(),
    };
    let path = args.out.join("localization.json");
    write_bytes_atomically(&path, serde_json::to_string_pretty(&summary)?.as_bytes())
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(summary)
}

/// Runs `scarp localize`.
///
/// # Errors
/// As [`localize`].
pub fn run(args: LocalizeArgs) -> anyhow::Result<()> {
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let summary = localize(&args)?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
    } else {
        for t in &summary.targets {
            eprintln!(
                "target {}: {} at ({:.2}, {:.2}, {:.2}) m, h = {:.2}, λ_max = {:.3} m²{}",
                t.id,
                t.status.as_str(),
                t.center[0],
                t.center[1],
                t.center[2],
                t.entropy,
                t.lambda_max,
                t.centroid_error_m
                    .map(|e| format!(", {e:.2} m from rock {}", t.gt_rock_id.unwrap_or(0)))
                    .unwrap_or_default()
            );
        }
        eprintln!(
            "{} frames, {} targets, {} false, {} removed, {:.1} s",
            summary.frames,
            summary.targets.len(),
            summary.false_targets.len(),
            summary.removed_targets,
            summary.seconds
        );
    }
    Ok(())
}
