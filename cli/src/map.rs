//! `scarp map`: fuse a TUM RGB-D sequence into a TSDF volume and mesh it.
//!
//! The default-world figures of issue 3 (target 1, 120-frame orbit, 1 cm voxels) come from:
//!
//! ```sh
//! scarp render --path orbit --frames 120 --no-noise --out /tmp/orbit_clean
//! scarp world --out /tmp/world
//! scarp map /tmp/orbit_clean --poses groundtruth --voxel 0.01 --out /tmp/map_clean
//! scarp eval mesh --gt /tmp/world/rock_1.ply --mesh /tmp/map_clean/mesh.ply --tau 0.01 \
//!     --crop-to-gt 0.1 --visible-from /tmp/orbit_clean --world default --json
//! ```
//!
//! (and the same without `--no-noise`, scored at `--tau 0.02`). `tests/map_cli.rs` runs a
//! reduced 8-frame version.
//!
//! The odometry and bundle-adjustment figures of issues 4 and 5 (default orbit, default noise)
//! come from:
//!
//! ```sh
//! scarp render --path orbit --frames 360 --out /tmp/orbit360
//! scarp map /tmp/orbit360 --poses odometry --ba --world default \
//!     --roi cyl:-12.0234,8.0438,-4,4,2.5 --out /tmp/map_ba --json
//! ```
//!
//! (`ate_rmse_m` against `estimate_ate_rmse_m`; `ate_rmse_before_ba_m` / `_after_ba_m` over the
//! keyframes, the BA's variables; `ate_rmse_all_frames_after_ba_m` over every frame, to compare
//! with `ate_rmse_m`; `fscore_before_ba` / `_after_ba` of every frame fused at its odometry pose
//! and at that pose corrected by its keyframe's adjustment; `fscore_keyframes_before_ba` /
//! `_after_ba` of the keyframes alone; `ba_landmark_residuals_truth`: the landmark observations
//! re-triangulated with the true poses). The ROI is tall because the odometry
//! map is anchored at the first state estimate, which can be a metre or more off vertically.
//! `tests/map_odometry_cli.rs` runs a reduced 48-frame version.

use scarp_slam::stats::percentile_sorted as percentile;
use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;
use clap::{Args, ValueEnum};
use nalgebra::{Isometry3, UnitQuaternion};
use scarp_datasets::sequence::Sequence;
use scarp_datasets::sequence::SequenceEntry;
use scarp_datasets::world::World;
use scarp_export::atomic::write_bytes_atomically;
use scarp_export::glb::{GlbNode, GlbOptions, write_glb};
use scarp_export::ply::{PlyEncoding, write_mesh};
use scarp_export::tum::{StampedPose, write_tum_trajectory};
use scarp_slam::TriangleMesh;
use scarp_slam::keyframes::KeyframeConfig;
use scarp_slam::mapping::{
    CHI2_6_MEDIAN, KeyframeSet, ModelTracker, ModelTrackingConfig, RefineConfig,
    TrackingReferenceKind, odometry_nees, refine_keyframes, reprojection_stats,
};
use scarp_slam::meshing::{MeshingConfig, extract_mesh, remove_small_components};
use scarp_slam::tsdf::{DepthSample, Roi, TsdfConfig, TsdfVolume};
use serde::Deserialize;

use scarp::evaluation::mesh::{MeshEvalConfig, evaluate_mesh};
use scarp::evaluation::trajectory::{TrajectoryEvalConfig, evaluate_trajectory, umeyama};

/// Which poses to fuse with.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum PoseSource {
    /// `groundtruth.txt`.
    Groundtruth,
    /// `estimate.txt` (the state estimator's noisy poses).
    Estimate,
    /// Frame-to-model RGBD odometry (each frame tracked against a raycast of the model being
    /// built, initialised with the estimator's motion); writes `trajectory.txt`.
    Odometry,
}

/// Fuse a sequence into a mesh: writes `mesh.ply`, `mesh.glb` and `map.json`.
#[derive(Debug, Args)]
pub struct MapArgs {
    /// The sequence directory (TUM RGB-D layout).
    pub sequence: PathBuf,
    /// Poses to fuse with.
    #[arg(long, value_enum, default_value = "groundtruth")]
    pub poses: PoseSource,
    /// A `camera.toml` to read in place of the sequence's own (for example one with a `[color]`
    /// table, so a Kinect's unregistered colour is registered to its depth on load).
    #[arg(long)]
    pub camera: Option<PathBuf>,
    /// Voxel size in metres.
    #[arg(long, default_value_t = 0.01)]
    pub voxel: f32,
    /// Region of interest: `cyl:x,y,z_min,z_max,r` or `box:x0,y0,z0,x1,y1,z1` (metres).
    #[arg(long)]
    pub roi: Option<Roi>,
    /// Ignore depth beyond this, metres.
    #[arg(long)]
    pub max_depth: Option<f32>,
    /// Allocate a block only where at least this many noisy pixels' truncation bands cross it
    /// in one frame (a precise pixel's band allocates alone). Default 4 when the depth noise is
    /// known (`--depth-sigma-at-1m` or the sequence's `camera.toml`): stray noisy bands then
    /// allocate nothing; 1 (wherever any band reaches) when it is not.
    #[arg(long)]
    pub min_block_support: Option<u32>,
    /// How a voxel reads the depth at its projection: `bilinear` between the four pixels around
    /// it where they agree (the default), or the `nearest` pixel, as Open3D does (one load per voxel
    /// instead of four: integration took 17–22% less time on session 60's sequences; each view
    /// then fuses as a half-pixel staircase).
    #[arg(long, value_enum, default_value = "bilinear")]
    pub depth_sample: DepthSampleArg,
    /// The depth sensor's σ at 1 m, metres (σ grows as z²): pixels whose σ is within the
    /// truncation distance are precise. Default: the sequence's `camera.toml`
    /// (`depth_sigma_at_1m_m`, which `scarp render` writes), else unknown.
    #[arg(long)]
    pub depth_sigma_at_1m: Option<f32>,
    /// Drop mesh components with fewer triangles.
    #[arg(long, default_value_t = 200)]
    pub min_component_triangles: usize,
    /// Mesh only voxels whose weight (Σ 1/z², z in metres) exceeds this.
    #[arg(long, default_value_t = 0.0)]
    pub min_weight: f32,
    /// Mesh only voxels observed by at least this many frames (Open3D's `weight_threshold` + 1:
    /// Open3D keeps weights above its threshold). Default 0 (every observed voxel). 3 halves the
    /// noisy 120-frame orbit's triangles and raises its F-scores, but on 8 noisy views of a rock
    /// it drops F@1 cm from 0.63 to 0.15: sparse sequences see much of a surface only once or
    /// twice.
    #[arg(long, default_value_t = 0)]
    pub min_observations: u8,
    /// Output directory.
    #[arg(long)]
    pub out: PathBuf,
    /// Print `map.json` on stdout too.
    #[arg(long)]
    pub json: bool,
    /// With `--poses odometry`: what frames are tracked against.
    #[arg(long, value_enum, default_value = "keyframe")]
    pub tracking_reference: TrackingReferenceArg,
    /// With `--poses odometry`: keyframe selection. `auto` picks `mission` with `--roi` (a UAV
    /// orbiting a target: a keyframe every 0.5 m or 10°) and `handheld` without (a keyframe at
    /// 1° of parallax, 5° of turn or below 85% overlap).
    #[arg(long, value_enum, default_value = "auto")]
    pub keyframes: KeyframePreset,
    /// With `--poses odometry`: a TOML file of keyframe thresholds (the fields of
    /// `scarp_slam::keyframes::KeyframeConfig`: `min_translation_m`, `min_parallax_deg`,
    /// `min_rotation_deg`, `min_overlap`, `overlap_stride_px`); missing fields keep the
    /// `--keyframes` preset's values.
    #[arg(long)]
    pub keyframe_config: Option<PathBuf>,
    /// With `--poses odometry`: refine the keyframes (KLT landmarks on and around the ROI, bundle
    /// adjustment with odometry and GPS/IMU priors), move every frame by its keyframe's
    /// correction (`trajectory_ba.txt`), re-integrate all frames with those poses and mesh that.
    /// `map.json` then reports the ATE (keyframes and all frames) and, with `--world`, the
    /// target's mesh F-score before and after (all frames, and keyframes alone).
    #[arg(long)]
    pub ba: bool,
    /// With `--ba`: the depth images are not registered to the colour images (Microsoft
    /// 7-Scenes), as `depth_registered = false` in `camera.toml` says: the landmarks' depths are
    /// then not used as residuals.
    #[arg(long, requires = "ba")]
    pub unregistered_depth: bool,
    /// A TOML file of `--ba` settings (the fields of `scarp_slam::mapping::RefineConfig`:
    /// `landmarks`, `noise`, `solver`, `gps_sigma_m`, ...); missing fields keep their defaults.
    #[arg(long, requires = "ba")]
    pub ba_config: Option<PathBuf>,
    /// The world the sequence was rendered from (`default` or a world TOML): its target rock is
    /// the ground truth of the F-scores of `--ba`.
    #[arg(long)]
    pub world: Option<String>,
    /// The rock id scored with `--world`; default the world's first target.
    #[arg(long)]
    pub target: Option<u32>,
    /// F-score threshold τ of `--ba` scores, metres (2 cm: the default sensor noise at 4 m is
    /// about 3.5 cm, so issue 3 scores noisy maps at 2 cm). Reconstruction farther than 0.1 m
    /// from the rock's bounding box is ignored, as `scarp eval mesh --crop-to-gt 0.1`.
    #[arg(long, default_value_t = 0.02)]
    pub tau: f64,
}

/// `--keyframes`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum KeyframePreset {
    /// `mission` with a ROI, `handheld` without.
    Auto,
    /// [`KeyframeConfig::default`]: the mission's mapping rings.
    Mission,
    /// [`KeyframeConfig::handheld`]: a camera carried by hand at 30 Hz.
    Handheld,
}

impl KeyframePreset {
    /// The keyframe thresholds of the preset; `has_roi` decides `auto`.
    pub fn config(self, has_roi: bool) -> KeyframeConfig {
        match self {
            Self::Mission => KeyframeConfig::default(),
            Self::Handheld => KeyframeConfig::handheld(),
            Self::Auto if has_roi => KeyframeConfig::default(),
            Self::Auto => KeyframeConfig::handheld(),
        }
    }
}

/// The keyframe thresholds: the preset, with `--keyframe-config`'s fields over it.
fn keyframe_config(args: &MapArgs) -> anyhow::Result<KeyframeConfig> {
    let preset = args.keyframes.config(args.roi.is_some());
    let Some(path) = &args.keyframe_config else {
        return Ok(preset);
    };
    // Fields missing from the file keep the preset's values, not the struct's defaults.
    let mut merged = toml::Table::try_from(preset)?;
    merged.extend(super::read_toml_config::<toml::Table>(path)?);
    let config = KeyframeConfig::deserialize(merged)
        .with_context(|| format!("keyframe settings in {}", path.display()))?;
    config
        .validate()
        .with_context(|| format!("keyframe settings in {}", path.display()))?;
    Ok(config)
}

/// `--depth-sample`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum DepthSampleArg {
    /// Bilinear between agreeing neighbours, else the nearest pixel.
    Bilinear,
    /// The nearest pixel.
    Nearest,
}

impl From<DepthSampleArg> for DepthSample {
    fn from(arg: DepthSampleArg) -> Self {
        match arg {
            DepthSampleArg::Bilinear => DepthSample::Bilinear,
            DepthSampleArg::Nearest => DepthSample::Nearest,
        }
    }
}

/// `--tracking-reference`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum TrackingReferenceArg {
    /// The last keyframe's images.
    Keyframe,
    /// A raycast of the model being built, at the previous frame's pose.
    Model,
}

/// `--min-block-support` when the depth noise is known: on the noisy 120-frame orbit to 8 m it
/// cuts the blocks from 153k to 100k (volume 956 → 620 MB), moving the target's F-scores by
/// 0.001 at most (docs/campaigns/2026-11-26-session18-noise.md).
const NOISY_BLOCK_SUPPORT: u32 = 4;

/// Runs `scarp map`.
///
/// # Errors
/// Sequence, pose, integration and writing errors naming the file or frame.
pub fn run(args: MapArgs) -> anyhow::Result<()> {
    let seq = super::open_sequence(&args.sequence, args.camera.as_deref())?;
    anyhow::ensure!(!seq.is_empty(), "{}: no frames", args.sequence.display());
    let mut config = TsdfConfig {
        voxel_size_m: args.voxel,
        roi: args.roi,
        depth_sample: args.depth_sample.into(),
        ..TsdfConfig::default()
    };
    if let Some(m) = args.max_depth {
        config.max_depth_m = m;
    }
    config.depth_sigma_at_1m_m = args
        .depth_sigma_at_1m
        .or(seq.camera_file.depth_sigma_at_1m_m.map(|s| s as f32));
    config.min_block_support =
        args.min_block_support
            .unwrap_or(if config.depth_sigma_at_1m_m.is_some() {
                NOISY_BLOCK_SUPPORT
            } else {
                1
            });
    anyhow::ensure!(
        !args.ba || args.poses == PoseSource::Odometry,
        "--ba needs --poses odometry"
    );
    match args.poses {
        PoseSource::Odometry => {
            let (volume, integrate_ms, mut extra, keyframes) =
                fuse_with_odometry(&args, &seq, config.clone())?;
            let refined = match keyframes {
                Some(keyframes) => Some(refine(
                    &args, &seq, config, &volume, &keyframes, &mut extra,
                )?),
                None => None,
            };
            finish(&args, &seq, &volume, integrate_ms, extra, refined)
        }
        PoseSource::Groundtruth | PoseSource::Estimate => {
            let (volume, integrate_ms, mut blocks_updated) =
                fuse_with_given_poses(&args, &seq, config)?;
            blocks_updated.sort_by(f64::total_cmp);
            let mut extra = serde_json::Map::new();
            // The median number of blocks a frame updated: with the time per frame, the cost
            // per block, comparable with Open3D's active blocks per frame.
            extra.insert(
                "blocks_updated_median".into(),
                percentile(&blocks_updated, 0.5).into(),
            );
            finish(&args, &seq, &volume, integrate_ms, extra, None)
        }
    }
}

/// Keyframes kept for `--ba`: the set and each keyframe's timestamp.
struct StoredKeyframes {
    set: KeyframeSet,
    timestamps_s: Vec<f64>,
    truth: Vec<Option<Isometry3<f64>>>,
    /// The sequence index of each keyframe.
    frame_indices: Vec<usize>,
    /// Every frame's odometry pose (filled in after tracking).
    odometry: Vec<StampedPose>,
}

/// Runs [`refine_keyframes`] and adds its figures (and, with ground truth, the before/after
/// ATE and F-scores) to `extra`; returns the mesh of every frame fused at its corrected pose
/// and its meshing time (ms).
fn refine(
    args: &MapArgs,
    seq: &Sequence,
    tsdf: TsdfConfig,
    odometry_volume: &TsdfVolume,
    keyframes: &StoredKeyframes,
    extra: &mut serde_json::Map<String, serde_json::Value>,
) -> anyhow::Result<(TriangleMesh, f64)> {
    let base = match &args.ba_config {
        Some(path) => super::read_toml_config::<RefineConfig>(path)?,
        None => RefineConfig::default(),
    };
    let registered = seq.camera_file.frames_registered() && !args.unregistered_depth;
    let config = RefineConfig {
        depth_residuals: base.depth_residuals && registered,
        tsdf,
        meshing: MeshingConfig {
            min_weight: args.min_weight,
            min_observations: args.min_observations,
            min_component_triangles: args.min_component_triangles,
        },
        // Only the world's F-score reads it: without a world it would fuse every keyframe
        // twice for nothing.
        mesh_before: args.world.is_some(),
        ..base
    };
    let refined =
        refine_keyframes(&seq.camera, &keyframes.set, &config).context("refining the keyframes")?;
    let stamped = |poses: &[Isometry3<f64>]| -> Vec<StampedPose> {
        keyframes
            .timestamps_s
            .iter()
            .zip(poses)
            .map(|(&timestamp_s, p)| StampedPose {
                timestamp_s,
                world_from_camera: *p,
            })
            .collect()
    };
    let path = args.out.join("keyframes_ba.txt");
    write_tum_trajectory(
        &path,
        &stamped(&refined.world_from_camera),
        "scarp map --ba: keyframe world_from_camera after bundle adjustment",
    )
    .with_context(|| format!("writing {}", path.display()))?;
    extra.insert("ba_keyframes".into(), keyframes.set.frames.len().into());
    extra.insert("ba_depth_residuals".into(), config.depth_residuals.into());
    extra.insert("ba_landmarks".into(), refined.landmarks.into());
    extra.insert("ba_observations".into(), refined.observations.into());
    extra.insert("ba_initial_cost".into(), refined.ba.initial_cost.into());
    extra.insert("ba_final_cost".into(), refined.ba.final_cost.into());
    extra.insert("ba_iterations".into(), refined.ba.iterations.into());
    extra.insert("ba_costs".into(), refined.ba.costs.clone().into());
    extra.insert(
        "ba_estimated_noise".into(),
        serde_json::to_value(refined.estimated_noise)?,
    );
    extra.insert("landmarks_ms".into(), refined.landmarks_ms.into());
    extra.insert("ba_ms".into(), refined.ba_ms.into());
    extra.insert("reintegrate_ms".into(), refined.reintegrate_ms.into());
    let truth: Option<Vec<Isometry3<f64>>> = keyframes.truth.iter().copied().collect();
    if let Some(truth) = &truth {
        let eval = TrajectoryEvalConfig::default();
        let gt = stamped(truth);
        let ate = |poses: &[Isometry3<f64>]| {
            evaluate_trajectory(&gt, &stamped(poses), &eval)
                .ok()
                .map(|m| m.ate_rmse_m)
        };
        extra.insert(
            "ate_rmse_before_ba_m".into(),
            ate(&keyframes.set.world_from_camera_odometry).into(),
        );
        extra.insert(
            "ate_rmse_after_ba_m".into(),
            ate(&refined.world_from_camera).into(),
        );
        // The odometry's keyframe-to-keyframe errors in units of its own covariance: a
        // median of 5.35 (χ² with 6 degrees of freedom) means the covariance is calibrated.
        let mut nees: Vec<f64> = odometry_nees(
            &keyframes.set.world_from_camera_odometry,
            truth,
            &keyframes.set.odometry_covariance,
        )
        .into_iter()
        .flatten()
        .collect();
        nees.sort_by(f64::total_cmp);
        if !nees.is_empty() {
            let median = percentile(&nees, 0.5);
            extra.insert("odometry_nees_median".into(), median.into());
            extra.insert(
                "odometry_nees_mean".into(),
                (nees.iter().sum::<f64>() / nees.len() as f64).into(),
            );
            extra.insert(
                "odometry_information_scale_calibrated".into(),
                (CHI2_6_MEDIAN / median).into(),
            );
        }
        // The landmark observations re-triangulated with the true poses: their own noise and
        // bias, whatever the odometry and the adjustment did.
        let residuals = reprojection_stats(&seq.camera, truth, &refined.tracks);
        extra.insert(
            "ba_landmark_residuals_truth".into(),
            serde_json::to_value(residuals)?,
        );
    }
    // The same observations re-triangulated through the odometry's and the adjustment's
    // poses: beside the truth's, they say whether the adjustment fits the images better than
    // the ground truth does (then the ground truth, or the camera model, limits the ATE).
    for (key, poses) in [
        (
            "ba_landmark_residuals_odometry",
            &keyframes.set.world_from_camera_odometry,
        ),
        ("ba_landmark_residuals_after", &refined.world_from_camera),
    ] {
        let residuals = reprojection_stats(&seq.camera, poses, &refined.tracks);
        extra.insert(key.into(), serde_json::to_value(residuals)?);
    }
    // Every frame at its odometry pose corrected by its keyframe's adjustment: a frame is
    // tracked against the last keyframe, so it moves with that keyframe.
    let corrected = correct_all_frames(keyframes, &refined.world_from_camera);
    let started = Instant::now();
    // Before: the tracker's own volume, which fused every frame at its odometry pose with the
    // same settings.
    let mesh_all_before = extract_mesh(odometry_volume, &config.meshing);
    let (mesh_all_after, mesh_ms) = fuse_all_frames(args, seq, &config, &corrected)?;
    extra.insert(
        "reintegrate_all_frames_ms".into(),
        (started.elapsed().as_secs_f64() * 1e3).into(),
    );
    let corrected_stamped: Vec<StampedPose> = keyframes
        .odometry
        .iter()
        .zip(&corrected)
        .map(|(o, p)| StampedPose {
            timestamp_s: o.timestamp_s,
            world_from_camera: *p,
        })
        .collect();
    let path = args.out.join("trajectory_ba.txt");
    write_tum_trajectory(
        &path,
        &corrected_stamped,
        "scarp map --ba: every frame's world_from_camera, odometry corrected by its keyframe's \
         bundle adjustment",
    )
    .with_context(|| format!("writing {}", path.display()))?;
    let all_truth = self::stamped(seq, |e| e.world_from_camera_truth);
    if let Some(gt) = &all_truth {
        let eval = TrajectoryEvalConfig::default();
        extra.insert(
            "ate_rmse_all_frames_after_ba_m".into(),
            evaluate_trajectory(gt, &corrected_stamped, &eval)
                .ok()
                .map(|m| m.ate_rmse_m)
                .into(),
        );
    }
    if let Some(name) = &args.world {
        let world =
            World::from_name_or_path(name).with_context(|| format!("loading world `{name}`"))?;
        let rock = match args.target {
            Some(id) => world.rock(id),
            None => world.targets().next(),
        }
        .with_context(|| format!("world `{name}` has no such target rock"))?;
        let eval = MeshEvalConfig {
            tau_m: args.tau,
            crop_to_gt_m: Some(0.1),
            ..MeshEvalConfig::default()
        };
        // The maps live in the odometry's frame (anchored at the first state estimate, which
        // is decimetres off): each mesh is first moved by the SE(3) alignment of its camera
        // positions onto the ground truth (the ATE's alignment), so the F-score measures the
        // shape, not the GPS error.
        let score =
            |mesh: &TriangleMesh, poses: &[Isometry3<f64>], truth: Option<&Vec<Isometry3<f64>>>| {
                let mut aligned = mesh.clone();
                if let Some(truth) = truth {
                    let source: Vec<_> = poses.iter().map(|p| p.translation.vector).collect();
                    let target: Vec<_> = truth.iter().map(|p| p.translation.vector).collect();
                    let s = umeyama(&source, &target, false).ok()?;
                    aligned.transform(&Isometry3::from_parts(
                        s.translation.into(),
                        UnitQuaternion::from_rotation_matrix(&s.rotation),
                    ));
                }
                evaluate_mesh(&aligned, &rock.mesh, &eval, None)
                    .map(|e| e.fscore)
                    .ok()
            };
        if let Some(before) = &refined.mesh_before {
            extra.insert(
                "fscore_keyframes_before_ba".into(),
                score(
                    before,
                    &keyframes.set.world_from_camera_odometry,
                    truth.as_ref(),
                )
                .into(),
            );
        }
        extra.insert(
            "fscore_keyframes_after_ba".into(),
            score(&refined.mesh, &refined.world_from_camera, truth.as_ref()).into(),
        );
        let all_truth: Option<Vec<Isometry3<f64>>> = all_truth
            .as_ref()
            .map(|gt| gt.iter().map(|p| p.world_from_camera).collect());
        let odometry: Vec<Isometry3<f64>> = keyframes
            .odometry
            .iter()
            .map(|p| p.world_from_camera)
            .collect();
        extra.insert(
            "fscore_before_ba".into(),
            score(&mesh_all_before, &odometry, all_truth.as_ref()).into(),
        );
        extra.insert(
            "fscore_after_ba".into(),
            score(&mesh_all_after, &corrected, all_truth.as_ref()).into(),
        );
        extra.insert("fscore_tau_m".into(), args.tau.into());
        extra.insert("fscore_rock_id".into(), rock.id.into());
    }
    Ok((mesh_all_after, mesh_ms))
}

/// Every frame's odometry pose moved by the bundle adjustment's correction, interpolated
/// between the keyframes around it (linear in translation, slerp in rotation, by frame index):
/// `correction · odometry_frame`, with `correction_k = refined_k · odometry_k⁻¹`. Frames before
/// the first keyframe take its correction, frames after the last take the last one's. A
/// piecewise-constant correction would make every keyframe a step in the trajectory.
fn correct_all_frames(
    keyframes: &StoredKeyframes,
    refined: &[Isometry3<f64>],
) -> Vec<Isometry3<f64>> {
    let corrections: Vec<Isometry3<f64>> = refined
        .iter()
        .zip(&keyframes.set.world_from_camera_odometry)
        .map(|(after, before)| after * before.inverse())
        .collect();
    let indices = &keyframes.frame_indices;
    keyframes
        .odometry
        .iter()
        .enumerate()
        .map(|(i, frame)| {
            let next = indices.partition_point(|&f| f <= i);
            let correction = match (next.checked_sub(1), corrections.get(next)) {
                (None, _) => corrections.first(),
                (Some(k), Some(after)) => {
                    let s = (i - indices[k]) as f64 / (indices[next] - indices[k]) as f64;
                    return corrections[k].lerp_slerp(after, s) * frame.world_from_camera;
                }
                (Some(k), None) => corrections.get(k),
            };
            correction.map_or(frame.world_from_camera, |c| c * frame.world_from_camera)
        })
        .collect()
}

/// Fuses every frame of the sequence at its corrected pose into a fresh volume with the
/// refinement's settings and meshes it; returns the mesh and the meshing time (ms).
fn fuse_all_frames(
    args: &MapArgs,
    seq: &Sequence,
    config: &RefineConfig,
    corrected: &[Isometry3<f64>],
) -> anyhow::Result<(TriangleMesh, f64)> {
    let mut volume = TsdfVolume::new(config.tsdf.clone())?;
    let bar = super::progress_bar(seq.len() as u64, "re-fusing");
    for (i, pose) in corrected.iter().enumerate() {
        let frame = seq
            .load_frame(i)
            .with_context(|| format!("{}: loading frame {i}", args.sequence.display()))?;
        volume
            .integrate(&frame, &seq.camera, pose)
            .with_context(|| format!("integrating frame {i}"))?;
        bar.inc(1);
    }
    bar.finish_and_clear();
    let started = Instant::now();
    let mesh = extract_mesh(&volume, &config.meshing);
    Ok((mesh, started.elapsed().as_secs_f64() * 1e3))
}

/// Fuses every frame at its `groundtruth.txt` or `estimate.txt` pose; returns the volume, the
/// integration time of each frame (ms) and the number of blocks each frame updated.
fn fuse_with_given_poses(
    args: &MapArgs,
    seq: &Sequence,
    config: TsdfConfig,
) -> anyhow::Result<(TsdfVolume, Vec<f64>, Vec<f64>)> {
    let mut volume = TsdfVolume::new(config)?;
    let bar = super::progress_bar(seq.len() as u64, "fusing");
    let mut integrate_ms = Vec::with_capacity(seq.len());
    let mut blocks_updated = Vec::with_capacity(seq.len());
    for (i, entry) in seq.entries.iter().enumerate() {
        let pose = match args.poses {
            PoseSource::Groundtruth => entry.world_from_camera_truth,
            PoseSource::Estimate | PoseSource::Odometry => entry.world_from_camera_estimate,
        }
        .with_context(|| {
            format!(
                "{}: frame {i} has no {:?} pose",
                args.sequence.display(),
                args.poses
            )
        })?;
        let frame = seq
            .load_frame(i)
            .with_context(|| format!("{}: loading frame {i}", args.sequence.display()))?;
        let start = Instant::now();
        let stats = volume
            .integrate(&frame, &seq.camera, &pose)
            .with_context(|| format!("integrating frame {i}"))?;
        integrate_ms.push(start.elapsed().as_secs_f64() * 1e3);
        blocks_updated.push(stats.blocks_updated as f64);
        bar.inc(1);
    }
    bar.finish_and_clear();
    Ok((volume, integrate_ms, blocks_updated))
}

/// Tracks every frame against the model and fuses it at the tracked pose; writes
/// `trajectory.txt`. Returns the volume, the integration times (ms) and the `map.json` fields
/// of the odometry.
type OdometryFusion = (
    TsdfVolume,
    Vec<f64>,
    serde_json::Map<String, serde_json::Value>,
    Option<StoredKeyframes>,
);

fn fuse_with_odometry(
    args: &MapArgs,
    seq: &Sequence,
    config: TsdfConfig,
) -> anyhow::Result<OdometryFusion> {
    let mut tracker = ModelTracker::new(
        seq.camera,
        ModelTrackingConfig {
            tsdf: config,
            reference: match args.tracking_reference {
                TrackingReferenceArg::Keyframe => TrackingReferenceKind::Keyframe,
                TrackingReferenceArg::Model => TrackingReferenceKind::Model,
            },
            keyframes: keyframe_config(args)?,
            ..ModelTrackingConfig::default()
        },
    )?;
    // A sequence without `estimate.txt` (a handheld camera) is tracked unaided: each frame's
    // guess is the previous frame's motion, and the first frame sits at its ground-truth pose
    // when there is one (the map's gauge only; nothing else of the truth is used).
    let unaided = seq
        .entries
        .iter()
        .all(|e| e.world_from_camera_estimate.is_none());
    let world_from_first_camera = seq
        .entries
        .first()
        .and_then(|e| e.world_from_camera_truth)
        .unwrap_or_else(Isometry3::identity);
    let mut stored = args.ba.then(|| StoredKeyframes {
        set: KeyframeSet::default(),
        timestamps_s: Vec::new(),
        truth: Vec::new(),
        frame_indices: Vec::new(),
        odometry: Vec::new(),
    });
    let bar = super::progress_bar(seq.len() as u64, "tracking");
    let mut integrate_ms = Vec::with_capacity(seq.len());
    let mut odometry_ms = Vec::with_capacity(seq.len());
    let mut failures = Vec::new();
    let mut keyframes = Vec::new();
    let mut poses = Vec::with_capacity(seq.len());
    for (i, entry) in seq.entries.iter().enumerate() {
        let estimate = if unaided {
            None
        } else {
            Some(entry.world_from_camera_estimate.with_context(|| {
                format!(
                    "{}: frame {i} has no state estimate (estimate.txt covers only part of the \
                     sequence)",
                    args.sequence.display()
                )
            })?)
        };
        let frame = seq
            .load_frame(i)
            .with_context(|| format!("{}: loading frame {i}", args.sequence.display()))?;
        let tracked = match &estimate {
            Some(estimate) => tracker.process(&frame, estimate),
            None => tracker.process_unaided(&frame, &world_from_first_camera),
        }
        .with_context(|| format!("tracking frame {i}"))?;
        integrate_ms.push(tracked.integrate_ms);
        odometry_ms.extend(tracked.odometry_ms);
        if (tracked.fell_back || tracked.dropped)
            && let Some(reason) = tracked.distrust_reason()
        {
            tracing::debug!(frame = i, %reason, "odometry not trusted; using the guessed motion");
            // Unaided (no estimate.txt), a failed frame is skipped, not fused at a guess; with
            // an estimate it is dropped, up to the tracker's limit in a row, then fused there.
            failures.push(serde_json::json!({
                "frame": i,
                "reason": reason,
                "fused": tracked.fused,
                "dropped": tracked.dropped,
            }));
        }
        if tracked.keyframe.is_some() {
            keyframes.push(i);
            if let Some(stored) = stored.as_mut() {
                stored
                    .set
                    .world_from_camera_odometry
                    .push(tracked.world_from_camera);
                if let Some(estimate) = estimate {
                    stored.set.world_from_camera_estimate.push(estimate);
                }
                stored
                    .set
                    .odometry_covariance
                    .push(tracked.keyframe_covariance);
                stored.set.frames.push(frame);
                stored.timestamps_s.push(entry.timestamp_s);
                stored.truth.push(entry.world_from_camera_truth);
                stored.frame_indices.push(i);
            }
        }
        poses.push(StampedPose {
            timestamp_s: entry.timestamp_s,
            world_from_camera: tracked.world_from_camera,
        });
        bar.inc(1);
    }
    bar.finish_and_clear();
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let trajectory = args.out.join("trajectory.txt");
    write_tum_trajectory(
        &trajectory,
        &poses,
        "scarp map --poses odometry: world_from_camera (frame-to-model)",
    )
    .with_context(|| format!("writing {}", trajectory.display()))?;
    odometry_ms.sort_by(f64::total_cmp);
    let mut extra = serde_json::Map::new();
    extra.insert(
        "odometry_ms_median".into(),
        percentile(&odometry_ms, 0.5).into(),
    );
    extra.insert(
        "odometry_ms_p90".into(),
        percentile(&odometry_ms, 0.9).into(),
    );
    extra.insert("odometry_failures".into(), failures.len().into());
    extra.insert("odometry_failure_frames".into(), failures.into());
    extra.insert("keyframes".into(), keyframes.len().into());
    extra.insert(
        "motion_guess".into(),
        if unaided {
            "constant_velocity"
        } else {
            "state_estimate"
        }
        .into(),
    );
    let eval = TrajectoryEvalConfig::default();
    if let Some(truth) = stamped(seq, |e| e.world_from_camera_truth) {
        let ate = |est: &[StampedPose]| {
            evaluate_trajectory(&truth, est, &eval)
                .ok()
                .map(|m| m.ate_rmse_m)
        };
        extra.insert("ate_rmse_m".into(), ate(&poses).into());
        if let Some(estimate) = stamped(seq, |e| e.world_from_camera_estimate) {
            extra.insert("estimate_ate_rmse_m".into(), ate(&estimate).into());
        }
    }
    if let Some(stored) = stored.as_mut() {
        stored.odometry = poses;
    }
    Ok((tracker.into_volume(), integrate_ms, extra, stored))
}

/// Every frame's pose from `pick`, or `None` when a frame lacks one.
fn stamped(
    seq: &Sequence,
    pick: impl Fn(&SequenceEntry) -> Option<Isometry3<f64>>,
) -> Option<Vec<StampedPose>> {
    seq.entries
        .iter()
        .map(|e| {
            pick(e).map(|world_from_camera| StampedPose {
                timestamp_s: e.timestamp_s,
                world_from_camera,
            })
        })
        .collect()
}

/// Meshes the volume, writes `mesh.ply`, `mesh.glb` and `map.json` (with `extra` fields).
fn finish(
    args: &MapArgs,
    seq: &Sequence,
    volume: &TsdfVolume,
    mut integrate_ms: Vec<f64>,
    extra: serde_json::Map<String, serde_json::Value>,
    refined_mesh: Option<(TriangleMesh, f64)>,
) -> anyhow::Result<()> {
    let start = Instant::now();
    let mut marching_cubes_ms = None;
    let (mesh, mesh_ms) = match refined_mesh {
        Some(refined) => refined,
        None => {
            // Marching cubes alone first (the work Open3D's `extract_triangle_mesh` does, timed
            // for `compare_open3d.py`), then the small-component filter.
            let raw = extract_mesh(
                volume,
                &MeshingConfig {
                    min_weight: args.min_weight,
                    min_observations: args.min_observations,
                    min_component_triangles: 0,
                },
            );
            marching_cubes_ms = Some(start.elapsed().as_secs_f64() * 1e3);
            let mesh = if args.min_component_triangles > 0 {
                remove_small_components(&raw, args.min_component_triangles)
            } else {
                raw
            };
            (mesh, start.elapsed().as_secs_f64() * 1e3)
        }
    };
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    write_mesh(
        args.out.join("mesh.ply"),
        &mesh,
        PlyEncoding::BinaryLittleEndian,
    )?;
    write_glb(
        args.out.join("mesh.glb"),
        &[GlbNode::new("map", &mesh)],
        &GlbOptions::default(),
    )?;
    let stats = volume.stats();
    integrate_ms.sort_by(f64::total_cmp);
    let mut json = serde_json::json!({
        "frames": seq.len(),
        "poses": format!("{:?}", args.poses).to_lowercase(),
        // The f32 argument printed as the decimal the user typed (0.01, not 0.00999999977).
        "voxel_size_m": args.voxel.to_string().parse::<f64>().unwrap_or(f64::from(args.voxel)),
        "roi": args.roi,
        "blocks": stats.blocks,
        "voxels": stats.voxels,
        "observed_voxels": stats.observed_voxels,
        "memory_bytes": stats.memory_bytes,
        "integrate_ms_median": percentile(&integrate_ms, 0.5),
        "integrate_ms_p90": percentile(&integrate_ms, 0.9),
        "mesh_ms": mesh_ms,
        "marching_cubes_ms": marching_cubes_ms,
        "vertices": mesh.vertex_count(),
        "triangles": mesh.face_count(),
    });
    if let Some(object) = json.as_object_mut() {
        object.extend(extra);
    }
    let text = serde_json::to_string_pretty(&json)?;
    write_bytes_atomically(args.out.join("map.json"), text.as_bytes())?;
    if args.json {
        println!("{text}");
    } else {
        eprintln!(
            "fused {} frames into {} blocks; mesh {} triangles; wrote {}",
            seq.len(),
            stats.blocks,
            mesh.face_count(),
            args.out.display()
        );
    }
    Ok(())
}
