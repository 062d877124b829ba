//! Keyframe refinement: landmarks → bundle adjustment → TSDF re-integration → mesh.
//!
//! [`refine_keyframes`] is the step that the mapping mode of a mission (and `scarp map --ba`)
//! runs once a target's keyframes are stored. The bundle adjustment ([`crate::ba`]) refines the
//! keyframe poses and the landmarks jointly, with
//! - reprojection residuals (robust loss) and RGBD depth residuals of the landmarks;
//! - odometry relative-pose priors between consecutive keyframes, with the odometry's
//!   information (scaled by `odometry_information_scale`);
//! - GPS/IMU absolute priors from the state estimate on every keyframe, which fix the gauge and
//!   keep the geo-reference; a sequence with no state estimate (a handheld RGB-D camera) instead
//!   holds its first keyframe at its odometry pose, which fixes the gauge alone.
//!
//! After a first solve, observations that reproject farther than `reject_residual_px` are
//! dropped and the adjustment is solved again.

use std::time::Instant;

use nalgebra::{Isometry3, Matrix6, Point3, Vector3};
use serde::{Deserialize, Serialize};

use super::MappingError;
use super::landmarks::{LandmarkConfig, LandmarkView, Landmarks, track_landmarks};
use super::residuals::CHI2_6_MEDIAN;
use crate::ba::keyframe::pose_error;
use crate::ba::{
    AbsolutePosePrior, BaSummary, KeyframeModel, KeyframeNoise, KeyframeObservation, LmConfig,
    RelativePosePrior, RobustLoss, solve,
};
use crate::image::gray_from_rgb;
use crate::meshing::{MeshingConfig, extract_mesh};
use crate::tsdf::{Roi, TsdfConfig, TsdfVolume};
use crate::{PinholeCamera, RgbdFrame, TriangleMesh};

/// Settings of [`refine_keyframes`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RefineConfig {
    /// Landmark tracking. Default [`LandmarkConfig::default`].
    pub landmarks: LandmarkConfig,
    /// Pixel and depth noise of the landmark observations. Default: 0.15 px (landmarks are
    /// matched from their anchor keyframe with a predicted warp; on the default orbit, seeds
    /// 0–2, their residuals against the true poses have an RMS of 0.11 px and a 90th
    /// percentile of 0.17 px; 0.3 px gave the odometry priors too much say, and the old
    /// keyframe-to-keyframe chains needed 2 px), 0.045 m (the simulated stereo depth σ at
    /// 4.5 m).
    pub noise: KeyframeNoise,
    /// The solver. Default [`LmConfig::default`] with a Huber loss at 2 (whitened units: two
    /// pixel σ) and at most 30 iterations.
    pub solver: LmConfig,
    /// After a first solve, observations whose reprojection error exceeds this are removed
    /// (with landmarks left with fewer than `landmarks.min_observations` observations) and the
    /// adjustment is solved again from the first solution, pixels; `None` solves once.
    /// Default 0.75 px (five σ of the default `noise`).
    pub reject_residual_px: Option<f64>,
    /// Estimate the noise from the data (variance component estimation): after the first solve,
    /// the pixel σ, the depth σ and the odometry's information scale are re-estimated from the
    /// residuals (robustly, by their medians, and corrected for the degrees of freedom the
    /// landmarks take), outliers are rejected at `max(reject_residual_px, 5 σ̂)`, and the
    /// adjustment is solved again with those weights; twice. `noise` and
    /// `odometry_information_scale` are then only the starting point.
    ///
    /// Default false. It helps where the residuals' scatter is the noise, as with the
    /// simulated sensor: on 120-frame noisy orbits of the three worlds (seeds 0 and 1) the
    /// keyframe ATE after BA went from 1.08–1.63 to 1.01–1.44 mm, never worse, and over a
    /// 33-target mission campaign its median from 1.39 to 1.19 mm (see the mission's
    /// `[mapping.refine]` for why the mission keeps it off for now). On real sensors the
    /// landmarks' errors are systematic (a rolling shutter, colour calibrated to depth by
    /// nominal intrinsics), which a scatter cannot show: it trusted the landmarks more and
    /// raised the ATE on 7-Scenes (keyframes 4.55 → 4.96 mm) and on TUM freiburg1_rpy
    /// (45.8 → 47.7 mm, motion-capture truth).
    pub estimate_noise: bool,
    /// Use the measured depth at each landmark observation as a residual. Default true. Turn it
    /// off for a sensor whose depth is not registered to its colour image: the depth read at a
    /// colour corner then belongs to a neighbouring point (landmarks are still initialised from
    /// it, and triangulation across keyframes corrects that).
    pub depth_residuals: bool,
    /// σ of the GPS/IMU position prior per axis, metres. Default 0.8 (the simulated estimator's
    /// vertical random walk; its horizontal one is 0.5).
    pub gps_sigma_m: f64,
    /// σ of the GPS/IMU attitude prior per axis, degrees. Default 2 (the simulated estimator's
    /// yaw σ; roll and pitch are 0.5°).
    pub attitude_sigma_deg: f64,
    /// The odometry's information is multiplied by this before it becomes a relative prior:
    /// its pixels are treated as independent, which makes it overconfident. Default 0.1
    /// (chosen with the earlier keyframe-to-keyframe landmarks, where 0.01 let them pull the
    /// default orbit's ATE from 3.7 to 9.9 mm and 1.0 left the poses where odometry put them;
    /// not re-tuned for the anchor-matched landmarks).
    pub odometry_information_scale: f64,
    /// The volume re-integrated with the refined poses (voxel size, truncation, ROI; the ROI
    /// also limits where landmarks are started). Default [`TsdfConfig::default`].
    pub tsdf: TsdfConfig,
    /// Meshing of the re-integrated volume. Default [`MeshingConfig::default`].
    pub meshing: MeshingConfig,
    /// Also fuse and mesh the keyframes at their odometry poses (for before/after comparisons).
    /// Default false.
    pub mesh_before: bool,
    /// Frames between keyframes k and k + 1 are re-integrated (with the two keyframes'
    /// corrections interpolated, [`KeyframeSet::fusion_order`]) only when those corrections
    /// differ by at most this translation, metres. Default 0.02: a larger change means the
    /// odometry failed within the stretch.
    ///
    /// Why not less: the adjustment's own corrections differ from keyframe to keyframe by a
    /// median of 1.0–1.2 mm per target on mission flights, and 0.2–1.7% of stretches exceed
    /// 5 mm (19 campaigns of sessions 26–29, `docs/campaigns/tools/ba_refusion.py`);
    /// interpolated (not one keyframe's), a frame is placed within half the change. At 5 mm
    /// (the earlier default) two stretches of a base ring were left out on a flight whose
    /// keyframe ATE the adjustment had lowered from 1.9 to 1.3 mm (default world, seed 39,
    /// rock 3, with `coverage.min_sweep_deg` 345).
    pub between_max_correction_change_m: f64,
    /// ... and at most this rotation, degrees. Default 1.
    pub between_max_correction_change_deg: f64,
}

impl Default for RefineConfig {
    fn default() -> Self {
        Self {
            landmarks: LandmarkConfig::default(),
            noise: KeyframeNoise {
                pixel_sigma_px: 0.15,
                depth_sigma_m: 0.045,
            },
            solver: LmConfig {
                max_iterations: 30,
                loss: RobustLoss::Huber { delta_px: 2.0 },
                ..LmConfig::default()
            },
            depth_residuals: true,
            estimate_noise: false,
            gps_sigma_m: 0.8,
            attitude_sigma_deg: 2.0,
            odometry_information_scale: 0.1,
            reject_residual_px: Some(0.75),
            tsdf: TsdfConfig::default(),
            meshing: MeshingConfig::default(),
            mesh_before: false,
            between_max_correction_change_m: 0.02,
            between_max_correction_change_deg: 1.0,
        }
    }
}

/// The stored keyframes of one target, in flight order.
#[derive(Debug, Clone, Default)]
pub struct KeyframeSet {
    /// The frames.
    pub frames: Vec<RgbdFrame>,
    /// Their poses from odometry.
    pub world_from_camera_odometry: Vec<Isometry3<f64>>,
    /// Their poses from the state estimator (GPS/IMU), one per keyframe; empty when the
    /// sequence has no state estimate (then the first keyframe is held at its odometry pose).
    pub world_from_camera_estimate: Vec<Isometry3<f64>>,
    /// Covariance of the odometry motion from keyframe k − 1 to keyframe k, as a right
    /// perturbation (translation m, rotation rad) of `camera_{k−1}_from_camera_k`
    /// ([`super::TrackedFrame::keyframe_covariance`]); entry 0 is not used. `None` leaves that
    /// pair without a relative prior.
    pub odometry_covariance: Vec<Option<Matrix6<f64>>>,
    /// Frames between keyframes that are not adjusted but re-integrated, in flight order. Each
    /// is fused at its odometry pose moved by its keyframe's adjustment,
    /// `refined_k · odometry_k⁻¹ · odometry_frame`. Keyframes alone are too sparse for a
    /// fragility-grade surface: their fusion leaves holes and noise that more views fill.
    pub between_frames: Vec<BetweenFrame>,
}

/// A frame re-integrated with its keyframe's correction (see [`KeyframeSet::between_frames`]).
#[derive(Debug, Clone)]
pub struct BetweenFrame {
    /// Index of the keyframe it was tracked after (the last one at or before it).
    pub keyframe: usize,
    /// The frame.
    pub frame: RgbdFrame,
    /// Its pose from odometry.
    pub world_from_camera_odometry: Isometry3<f64>,
}

impl KeyframeSet {
    /// Every frame to fuse, keyframes and the frames between them, in flight order, with its
    /// pose: keyframe k at `keyframe_poses[k]`, a frame between keyframes k and k + 1 at its
    /// odometry pose moved by the correction `C = keyframe_poses · odometry⁻¹` interpolated
    /// between C_k and C_k+1 by its time (translation linearly, rotation by slerp); a frame
    /// after the last keyframe by that keyframe's correction.
    ///
    /// Why interpolate: the odometry's error grows between keyframes, so the correction a frame
    /// needs moves from one keyframe's towards the next's. Moving every frame by C_k alone puts
    /// the last frames of a stretch up to |C_k⁻¹·C_k+1| off their neighbours.
    ///
    /// A frame between keyframes k and k + 1 is left out when their corrections differ by more
    /// than `max_correction_change_m` or `max_correction_change_rad`: the odometry failed within
    /// that stretch, so its poses there are not worth fusing.
    ///
    /// # Errors
    /// [`MappingError::InvalidInput`] when `keyframe_poses` does not match the keyframes or a
    /// frame between names a keyframe that does not exist.
    pub fn fusion_order(
        &self,
        keyframe_poses: &[Isometry3<f64>],
        max_correction_change_m: f64,
        max_correction_change_rad: f64,
    ) -> Result<Vec<(&RgbdFrame, Isometry3<f64>)>, MappingError> {
        if keyframe_poses.len() != self.frames.len()
            || self.world_from_camera_odometry.len() != self.frames.len()
        {
            return Err(MappingError::InvalidInput(format!(
                "{} keyframe poses for {} keyframes",
                keyframe_poses.len(),
                self.frames.len()
            )));
        }
        let mut order = Vec::with_capacity(self.frames.len() + self.between_frames.len());
        let mut between = self.between_frames.iter().peekable();
        let corrections: Vec<Isometry3<f64>> =
            corrections(&self.world_from_camera_odometry, keyframe_poses).collect();
        for (k, (frame, pose)) in self.frames.iter().zip(keyframe_poses).enumerate() {
            order.push((frame, *pose));
            let next = corrections
                .get(k + 1)
                .map(|correction| (correction, self.frames[k + 1].timestamp_s));
            let consistent = next.is_none_or(|(next, _)| {
                let change = corrections[k].inverse() * next;
                change.translation.vector.norm() <= max_correction_change_m
                    && change.rotation.angle() <= max_correction_change_rad
            });
            while let Some(b) = between.next_if(|b| b.keyframe == k) {
                if consistent {
                    let correction = next.map_or(corrections[k], |(next, next_s)| {
                        let s = stretch_fraction(frame.timestamp_s, next_s, b.frame.timestamp_s);
                        corrections[k].lerp_slerp(next, s)
                    });
                    order.push((&b.frame, correction * b.world_from_camera_odometry));
                }
            }
        }
        if let Some(b) = between.next() {
            return Err(MappingError::InvalidInput(format!(
                "a frame between keyframes follows keyframe {} of {} (out of range or out of \
                 order)",
                b.keyframe,
                self.frames.len()
            )));
        }
        Ok(order)
    }
}

/// The region of interest, given in the frame of the odometry poses, moved with the map by the
/// adjustment: its centre taken through each keyframe's correction `refined · odometry⁻¹`,
/// averaged. Unchanged without keyframes.
///
/// Why: with a state estimate, the adjustment's absolute priors pull the whole map from the
/// odometry's frame (anchored where mapping began) towards the estimate's mean over the
/// flight, by as much as the GPS walked meanwhile: 1.2 m on the default world's seed 39. A
/// region left where it was cut the re-fused rock's far side off (a hole of the rock's side,
/// F@2cm 0.968 → 0.905, α_min 4.2° low).
fn roi_after_adjustment(roi: &Roi, odometry: &[Isometry3<f64>], refined: &[Isometry3<f64>]) -> Roi {
    let center = roi.center();
    let n = odometry.len().min(refined.len());
    if n == 0 {
        return *roi;
    }
    let offset_m = corrections(odometry, refined)
        .map(|correction| correction * center - center)
        .sum::<Vector3<f64>>()
        / n as f64;
    roi.translated(&offset_m)
}

/// Each keyframe's correction `refined · odometry⁻¹`: what moves a pose of the odometry's
/// frame to where the adjustment put it (pairs up to the shorter list).
fn corrections<'a>(
    odometry: &'a [Isometry3<f64>],
    refined: &'a [Isometry3<f64>],
) -> impl Iterator<Item = Isometry3<f64>> + 'a {
    odometry
        .iter()
        .zip(refined)
        .map(|(odometry, refined)| refined * odometry.inverse())
}

/// Where `t_s` lies between `start_s` and `end_s`, in [0, 1]; 0 when the stretch has no
/// duration or a time is not finite.
fn stretch_fraction(start_s: f64, end_s: f64, t_s: f64) -> f64 {
    let fraction = (t_s - start_s) / (end_s - start_s);
    if fraction.is_finite() {
        fraction.clamp(0.0, 1.0)
    } else {
        0.0
    }
}

/// Fuses `(frame, world_from_camera)` pairs in order into a fresh volume.
fn fuse_in_order(
    camera: &PinholeCamera,
    order: &[(&RgbdFrame, Isometry3<f64>)],
    tsdf: &TsdfConfig,
) -> Result<TsdfVolume, MappingError> {
    let mut volume = TsdfVolume::new(tsdf.clone())?;
    for (frame, pose) in order {
        volume.integrate(frame, camera, pose)?;
    }
    Ok(volume)
}

/// The outcome of [`refine_keyframes`].
#[derive(Debug, Clone)]
pub struct RefinedMap {
    /// Mesh of the keyframes (and the frames between them) re-integrated at the refined poses.
    pub mesh: TriangleMesh,
    /// Mesh of the same frames at their odometry poses (with `mesh_before`).
    pub mesh_before: Option<TriangleMesh>,
    /// Keyframe poses after bundle adjustment.
    pub world_from_camera: Vec<Isometry3<f64>>,
    /// Landmarks in the adjustment.
    pub landmarks: usize,
    /// Landmark observations in the adjustment.
    pub observations: usize,
    /// The tracked landmarks (initial positions) and their observations, as they entered the
    /// adjustment (for diagnostics such as [`super::reprojection_stats`]).
    pub tracks: Landmarks,
    /// The solver's report (cost of every iteration).
    pub ba: BaSummary,
    /// The noise the last solve weighted with, when [`RefineConfig::estimate_noise`] estimated
    /// it.
    pub estimated_noise: Option<EstimatedNoise>,
    /// Wall times, milliseconds: landmark tracking, bundle adjustment, re-integration, meshing.
    pub landmarks_ms: f64,
    /// See `landmarks_ms`.
    pub ba_ms: f64,
    /// See `landmarks_ms`.
    pub reintegrate_ms: f64,
    /// See `landmarks_ms`.
    pub mesh_ms: f64,
}

/// Runs landmarks → bundle adjustment → re-integration → mesh on a target's keyframes.
///
/// # Errors
/// [`MappingError::InvalidInput`] when the keyframe lists differ in length or are empty, or a
/// setting is out of range; [`MappingError::Features`] / [`MappingError::Ba`] /
/// [`MappingError::Tsdf`] from the stages.
pub fn refine_keyframes(
    camera: &PinholeCamera,
    keyframes: &KeyframeSet,
    config: &RefineConfig,
) -> Result<RefinedMap, MappingError> {
    let n = keyframes.frames.len();
    if n == 0
        || keyframes.world_from_camera_odometry.len() != n
        || !(keyframes.world_from_camera_estimate.is_empty()
            || keyframes.world_from_camera_estimate.len() == n)
        || keyframes.odometry_covariance.len() != n
    {
        return Err(MappingError::InvalidInput(format!(
            "keyframe set: {n} frames, {} odometry poses, {} estimates, {} covariances (all must \
             match and be non-zero; estimates may also be absent)",
            keyframes.world_from_camera_odometry.len(),
            keyframes.world_from_camera_estimate.len(),
            keyframes.odometry_covariance.len()
        )));
    }
    for (field, value) in [
        ("gps_sigma_m", config.gps_sigma_m),
        ("attitude_sigma_deg", config.attitude_sigma_deg),
        (
            "odometry_information_scale",
            config.odometry_information_scale,
        ),
    ] {
        if !(value.is_finite() && value > 0.0) {
            return Err(MappingError::InvalidConfig {
                field,
                reason: "must be positive and finite",
            });
        }
    }
    let started = Instant::now();
    let grays: Vec<_> = keyframes
        .frames
        .iter()
        .map(|f| gray_from_rgb(&f.rgb))
        .collect();
    let views: Vec<LandmarkView<'_>> = keyframes
        .frames
        .iter()
        .zip(&grays)
        .zip(&keyframes.world_from_camera_odometry)
        .map(|((frame, gray), pose)| LandmarkView {
            gray,
            depth_m: &frame.depth_m,
            world_from_camera: pose,
        })
        .collect();
    let mut landmarks =
        track_landmarks(camera, &views, config.tsdf.roi.as_ref(), &config.landmarks)?;
    if !config.depth_residuals {
        for observation in &mut landmarks.observations {
            observation.depth_m = None;
        }
    }
    let landmarks_ms = started.elapsed().as_secs_f64() * 1e3;

    let started = Instant::now();
    let absolute = absolute_priors(keyframes, config);
    let model_with = |noise: KeyframeNoise, odometry_scale: f64| {
        KeyframeModel::new(
            *camera,
            noise,
            absolute.clone(),
            relative_priors(keyframes, odometry_scale),
        )
    };
    let mut noise = config.noise;
    let mut odometry_scale = config.odometry_information_scale;
    let mut model = model_with(noise, odometry_scale)?;
    let mut poses = keyframes.world_from_camera_odometry.clone();
    let mut points = landmarks.points.clone();
    let solve_from = |model: &KeyframeModel,
                      poses: &mut Vec<Isometry3<f64>>,
                      points: &mut Vec<Vector3<f64>>,
                      landmarks: &Landmarks| {
        solve(
            model,
            poses,
            points,
            &landmarks.observations,
            &config.solver,
        )
    };
    let mut ba = solve_from(&model, &mut poses, &mut points, &landmarks)?;
    let mut threshold_px = config.reject_residual_px;
    let mut estimated_noise = None;
    let rounds = if config.estimate_noise {
        NOISE_ROUNDS
    } else {
        1
    };
    for _ in 0..rounds {
        if config.estimate_noise {
            let relative = relative_priors(keyframes, odometry_scale);
            let Some(estimate) =
                estimate_noise(camera, &poses, &points, &landmarks, &relative, noise)
            else {
                break;
            };
            noise = KeyframeNoise {
                pixel_sigma_px: estimate.pixel_sigma_px,
                depth_sigma_m: estimate.depth_sigma_m,
            };
            odometry_scale /= estimate.odometry_variance_factor;
            threshold_px = config
                .reject_residual_px
                .map(|t| t.max(REJECT_SIGMAS * noise.pixel_sigma_px));
            model = model_with(noise, odometry_scale)?;
            estimated_noise = Some(EstimatedNoise {
                noise,
                odometry_information_scale: odometry_scale,
            });
        }
        let before = landmarks.observations.len();
        if let Some(threshold_px) = threshold_px {
            let kept = reject_outliers(
                camera,
                &poses,
                &points,
                &landmarks,
                threshold_px,
                config.landmarks.min_observations,
            );
            points = kept.points.clone();
            landmarks = kept;
        }
        if !config.estimate_noise && landmarks.observations.len() == before {
            break;
        }
        let first = ba;
        ba = solve_from(&model, &mut poses, &mut points, &landmarks)?;
        // One report for every solve: the earlier solves' costs come first.
        let mut costs = first.costs;
        costs.extend(ba.costs.iter().copied());
        ba.initial_cost = first.initial_cost;
        ba.iterations += first.iterations;
        ba.costs = costs;
        let mut log = first.log;
        log.append(&mut ba.log);
        ba.log = log;
    }
    let ba_ms = started.elapsed().as_secs_f64() * 1e3;

    let order = |keyframe_poses| {
        keyframes.fusion_order(
            keyframe_poses,
            config.between_max_correction_change_m,
            config.between_max_correction_change_deg.to_radians(),
        )
    };
    let mesh_before = if config.mesh_before {
        let volume = fuse_in_order(
            camera,
            &order(&keyframes.world_from_camera_odometry)?,
            &config.tsdf,
        )?;
        Some(extract_mesh(&volume, &config.meshing))
    } else {
        None
    };
    let started = Instant::now();
    let tsdf_adjusted = TsdfConfig {
        roi: config
            .tsdf
            .roi
            .map(|roi| roi_after_adjustment(&roi, &keyframes.world_from_camera_odometry, &poses)),
        ..config.tsdf.clone()
    };
    let volume = fuse_in_order(camera, &order(&poses)?, &tsdf_adjusted)?;
    let reintegrate_ms = started.elapsed().as_secs_f64() * 1e3;
    let started = Instant::now();
    let mesh = extract_mesh(&volume, &config.meshing);
    let mesh_ms = started.elapsed().as_secs_f64() * 1e3;
    Ok(RefinedMap {
        mesh,
        mesh_before,
        world_from_camera: poses,
        landmarks: points.len(),
        observations: landmarks.observations.len(),
        tracks: landmarks,
        ba,
        estimated_noise,
        landmarks_ms,
        ba_ms,
        reintegrate_ms,
        mesh_ms,
    })
}

/// Rounds of noise estimation and re-solving with [`RefineConfig::estimate_noise`]. The second
/// round starts from weights already near their estimates and rejects outliers at the
/// estimated σ, so a third changes them by a few percent at most.
const NOISE_ROUNDS: usize = 2;

/// Outliers are observations beyond this many estimated pixel σ.
const REJECT_SIGMAS: f64 = 5.0;

/// Fewest residuals of a landmark group whose σ is estimated; a smaller group keeps its weight.
const MIN_NOISE_SAMPLES: usize = 30;

/// Fewest odometry priors whose variance factor is estimated (a handheld piece of 50 frames has
/// 8 keyframes).
const MIN_ODOMETRY_PRIORS: usize = 5;

/// The noise estimated from a solution's residuals ([`RefineConfig::estimate_noise`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct EstimatedNoise {
    /// The landmarks' pixel σ (per axis, px) and depth σ (m).
    pub noise: KeyframeNoise,
    /// The scale applied to the odometry's information (see
    /// [`RefineConfig::odometry_information_scale`]).
    pub odometry_information_scale: f64,
}

/// Variance components at a solution: what each residual group's σ must be for its residuals
/// to be as large as they are.
struct NoiseEstimate {
    pixel_sigma_px: f64,
    depth_sigma_m: f64,
    /// The odometry priors' whitened residuals are this many times their claimed variance.
    odometry_variance_factor: f64,
}

/// σ of zero-mean residuals from their median absolute value (robust to a minority of outliers),
/// or `None` for too few of them.
fn robust_sigma(residuals: &mut [f64]) -> Option<f64> {
    if residuals.len() < MIN_NOISE_SAMPLES {
        return None;
    }
    for r in residuals.iter_mut() {
        *r = r.abs();
    }
    residuals.sort_by(f64::total_cmp);
    let sigma = 1.4826 * crate::stats::percentile_sorted(residuals, 0.5);
    (sigma.is_finite() && sigma > 0.0).then_some(sigma)
}

/// Estimates the landmarks' pixel and depth σ and the odometry priors' variance factor from the
/// residuals at `poses` and `points`. Each group's median-based σ is divided by the fraction of
/// the landmark residuals left after the landmarks' and poses' degrees of freedom, since a
/// solution fits part of its own noise. Groups with too few residuals keep `current`'s value
/// (factor 1 for the odometry). `None` when there are too few pixel residuals to estimate from.
fn estimate_noise(
    camera: &PinholeCamera,
    poses: &[Isometry3<f64>],
    points: &[Vector3<f64>],
    landmarks: &Landmarks,
    relative: &[RelativePosePrior],
    current: KeyframeNoise,
) -> Option<NoiseEstimate> {
    let mut pixel = Vec::with_capacity(2 * landmarks.observations.len());
    let mut depth = Vec::new();
    for o in &landmarks.observations {
        let (Some(pose), Some(point)) = (poses.get(o.camera), points.get(o.point)) else {
            continue;
        };
        let p = pose.inverse_transform_point(&Point3::from(*point));
        let Some(q) = camera.project(&p) else {
            continue;
        };
        pixel.extend([q.x - o.pixel.x, q.y - o.pixel.y]);
        if let Some(d) = o.depth_m {
            depth.push(p.z - d);
        }
    }
    let residuals = (pixel.len() + depth.len()) as f64;
    let parameters = (3 * points.len() + 6 * poses.len()) as f64;
    let redundancy = ((residuals - parameters) / residuals).clamp(0.1, 1.0);
    let pixel_sigma_px = robust_sigma(&mut pixel)? / redundancy.sqrt();
    let depth_sigma_m =
        robust_sigma(&mut depth).map_or(current.depth_sigma_m, |s| s / redundancy.sqrt());
    let mut whitened: Vec<f64> = relative
        .iter()
        .filter_map(|prior| {
            let estimate = poses.get(prior.camera_a)?.inverse() * poses.get(prior.camera_b)?;
            let e = pose_error(&prior.camera_a_from_camera_b, &estimate);
            Some((e.transpose() * prior.information * e)[(0, 0)])
        })
        .filter(|w| w.is_finite())
        .collect();
    whitened.sort_by(f64::total_cmp);
    let odometry_variance_factor = (whitened.len() >= MIN_ODOMETRY_PRIORS)
        .then(|| crate::stats::percentile_sorted(&whitened, 0.5) / CHI2_6_MEDIAN)
        .filter(|f| f.is_finite() && *f > 0.0)
        .unwrap_or(1.0);
    Some(NoiseEstimate {
        pixel_sigma_px,
        depth_sigma_m,
        odometry_variance_factor,
    })
}

/// σ of the prior that holds the first keyframe at its odometry pose when there is no state
/// estimate, metres and degrees: tight enough to fix the gauge (the solution's frame) and loose
/// enough to keep the normal equations well conditioned.
const GAUGE_SIGMA_M: f64 = 1e-4;
const GAUGE_SIGMA_DEG: f64 = 1e-3;

/// GPS/IMU priors: every keyframe's state estimate, isotropic σ in translation and rotation; with
/// no estimate, the first keyframe held at its odometry pose (the gauge).
fn absolute_priors(keyframes: &KeyframeSet, config: &RefineConfig) -> Vec<AbsolutePosePrior> {
    if keyframes.world_from_camera_estimate.is_empty() {
        let t = GAUGE_SIGMA_M.powi(-2);
        let r = GAUGE_SIGMA_DEG.to_radians().powi(-2);
        return keyframes
            .world_from_camera_odometry
            .first()
            .map(|first| AbsolutePosePrior {
                camera: 0,
                world_from_camera: *first,
                information: Matrix6::from_diagonal(&nalgebra::Vector6::new(t, t, t, r, r, r)),
            })
            .into_iter()
            .collect();
    }
    let t = 1.0 / (config.gps_sigma_m * config.gps_sigma_m);
    let r = 1.0 / config.attitude_sigma_deg.to_radians().powi(2);
    let information = Matrix6::from_diagonal(&nalgebra::Vector6::new(t, t, t, r, r, r));
    keyframes
        .world_from_camera_estimate
        .iter()
        .enumerate()
        .map(|(camera, world_from_camera)| AbsolutePosePrior {
            camera,
            world_from_camera: *world_from_camera,
            information,
        })
        .collect()
}

/// Odometry priors between consecutive keyframes, with the inverse of the accumulated
/// odometry covariance; pairs whose covariance is missing or not invertible get none.
fn relative_priors(keyframes: &KeyframeSet, information_scale: f64) -> Vec<RelativePosePrior> {
    let poses = &keyframes.world_from_camera_odometry;
    (1..poses.len())
        .filter_map(|b| {
            let covariance = keyframes.odometry_covariance[b]?;
            let information = covariance.try_inverse()?;
            let information = (information + information.transpose()) * (0.5 * information_scale);
            // Only positive-definite information makes a usable prior.
            nalgebra::Cholesky::new(information)?;
            Some(RelativePosePrior {
                camera_a: b - 1,
                camera_b: b,
                camera_a_from_camera_b: poses[b - 1].inverse() * poses[b],
                information,
            })
        })
        .collect()
}

/// The landmarks without the observations whose reprojection error through `world_from_camera`
/// at `points` exceeds `threshold_px` (or that fall behind their camera), and without the
/// landmarks left with fewer than `min_observations` observations. Positions come from
/// `points`; observations keep their order and are renumbered.
fn reject_outliers(
    camera: &PinholeCamera,
    world_from_camera: &[Isometry3<f64>],
    points: &[Vector3<f64>],
    landmarks: &Landmarks,
    threshold_px: f64,
    min_observations: usize,
) -> Landmarks {
    let mut kept = Landmarks::default();
    for group in landmarks.observations.chunk_by(|a, b| a.point == b.point) {
        let Some(point) = group.first().and_then(|o| points.get(o.point)) else {
            continue;
        };
        let good: Vec<KeyframeObservation> = group
            .iter()
            .filter(|o| {
                world_from_camera.get(o.camera).is_some_and(|pose| {
                    let p = pose.inverse_transform_point(&Point3::from(*point));
                    camera
                        .project(&p)
                        .is_some_and(|q| (q.coords - o.pixel).norm() <= threshold_px)
                })
            })
            .copied()
            .collect();
        if good.len() < min_observations {
            continue;
        }
        let index = kept.points.len();
        kept.points.push(*point);
        kept.observations.extend(
            good.into_iter()
                .map(|o| KeyframeObservation { point: index, ..o }),
        );
    }
    kept
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::Image;
    use nalgebra::{Translation3, UnitQuaternion};

    fn frame(timestamp_s: f64) -> RgbdFrame {
        RgbdFrame::new(
            timestamp_s,
            Image::filled(4, 3, [0u8; 3]),
            Image::filled(4, 3, 1.0f32),
            None,
        )
        .unwrap()
    }

    fn at(x: f64, yaw: f64) -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::new(x, 0.0, 0.0),
            UnitQuaternion::from_euler_angles(0.0, 0.0, yaw),
        )
    }

    /// A standard normal draw, deterministic for a seeded generator.
    fn normal(rng: &mut rand::rngs::Xoshiro256PlusPlus) -> f64 {
        use rand_distr::Distribution;
        rand_distr::StandardNormal.sample(rng)
    }

    /// Observations with a known pixel and depth noise, and odometry priors whose errors are
    /// three times the σ they claim: the estimate recovers both σs and a variance factor near 9.
    #[test]
    fn the_noise_is_estimated_from_the_residuals() {
        use rand::SeedableRng;
        let mut rng = rand::rngs::Xoshiro256PlusPlus::seed_from_u64(7);
        let camera = PinholeCamera::new(500.0, 500.0, 320.0, 240.0, 640, 480).unwrap();
        // Twelve cameras along a line, looking along +z at points 3–5 m away.
        let poses: Vec<Isometry3<f64>> = (0..12).map(|k| at(0.1 * f64::from(k), 0.0)).collect();
        let points: Vec<Vector3<f64>> = (0..400)
            .map(|i| {
                let i = f64::from(i);
                Vector3::new(
                    (i * 0.37) % 2.4 - 0.6,
                    (i * 0.11) % 1.6 - 0.8,
                    3.0 + (i * 0.05) % 2.0,
                )
            })
            .collect();
        let (pixel_sigma, depth_sigma) = (0.5, 0.02);
        let mut landmarks = Landmarks {
            points: points.clone(),
            observations: Vec::new(),
        };
        for (j, point) in points.iter().enumerate() {
            for (k, pose) in poses.iter().enumerate().skip(j % 6).take(5) {
                let p = pose.inverse_transform_point(&Point3::from(*point));
                let q = camera.project(&p).unwrap();
                landmarks.observations.push(KeyframeObservation {
                    camera: k,
                    point: j,
                    pixel: q.coords
                        + nalgebra::Vector2::new(normal(&mut rng), normal(&mut rng)) * pixel_sigma,
                    depth_m: Some(p.z + depth_sigma * normal(&mut rng)),
                });
            }
        }
        // Odometry priors claiming 1 mm and 0.01 rad, wrong by three times that.
        let information =
            Matrix6::from_diagonal(&nalgebra::Vector6::new(1e6, 1e6, 1e6, 1e4, 1e4, 1e4));
        let relative: Vec<RelativePosePrior> = (1..poses.len())
            .map(|b| {
                let noise = Vector3::new(normal(&mut rng), normal(&mut rng), normal(&mut rng));
                let turn = Vector3::new(normal(&mut rng), normal(&mut rng), normal(&mut rng));
                let error = Isometry3::from_parts(
                    (noise * 0.003).into(),
                    UnitQuaternion::from_scaled_axis(turn * 0.03),
                );
                RelativePosePrior {
                    camera_a: b - 1,
                    camera_b: b,
                    camera_a_from_camera_b: poses[b - 1].inverse() * poses[b] * error,
                    information,
                }
            })
            .collect();
        let configured = KeyframeNoise {
            pixel_sigma_px: 0.15,
            depth_sigma_m: 0.045,
        };
        let estimate =
            estimate_noise(&camera, &poses, &points, &landmarks, &relative, configured).unwrap();
        // At the true poses and points nothing was fitted, so the redundancy correction
        // (about 1.1 here) shows as an overestimate of that size.
        let ratio = estimate.pixel_sigma_px / pixel_sigma;
        assert!(
            (0.95..1.3).contains(&ratio),
            "pixel σ {}",
            estimate.pixel_sigma_px
        );
        let ratio = estimate.depth_sigma_m / depth_sigma;
        assert!(
            (0.95..1.3).contains(&ratio),
            "depth σ {}",
            estimate.depth_sigma_m
        );
        let factor = estimate.odometry_variance_factor;
        assert!(
            (4.0..20.0).contains(&factor),
            "odometry variance factor {factor}"
        );
        // Too few observations to estimate from: the configured noise stays.
        let few = Landmarks {
            points: points.clone(),
            observations: landmarks.observations[..10].to_vec(),
        };
        assert!(estimate_noise(&camera, &poses, &points, &few, &relative, configured).is_none());
    }

    #[test]
    fn frames_between_keyframes_follow_their_keyframes_correction() {
        let odometry = vec![at(0.0, 0.0), at(1.0, 0.3)];
        let between = |keyframe: usize, t: f64, pose: Isometry3<f64>| BetweenFrame {
            keyframe,
            frame: frame(t),
            world_from_camera_odometry: pose,
        };
        let set = KeyframeSet {
            frames: vec![frame(0.0), frame(1.0)],
            world_from_camera_odometry: odometry.clone(),
            world_from_camera_estimate: odometry.clone(),
            odometry_covariance: vec![None, None],
            between_frames: vec![
                between(0, 0.5, at(0.5, 0.1)),
                between(1, 1.5, at(1.5, 0.4)),
                between(1, 1.6, at(1.6, 0.5)),
            ],
        };
        // The adjustment moves keyframe 0 by 2 cm and turns keyframe 1 by 0.01 rad.
        let refined = vec![at(0.02, 0.0), at(1.0, 0.31)];
        let order = set.fusion_order(&refined, 1.0, 1.0).unwrap();
        let stamps: Vec<f64> = order.iter().map(|(f, _)| f.timestamp_s).collect();
        assert_eq!(stamps, vec![0.0, 0.5, 1.0, 1.5, 1.6]);
        assert_eq!(order[0].1, refined[0]);
        assert_eq!(order[2].1, refined[1]);
        // Frames after the last keyframe keep their odometry pose relative to it.
        for (i, odometry_frame) in [(3, at(1.5, 0.4)), (4, at(1.6, 0.5))] {
            let relative_before = odometry[1].inverse() * odometry_frame;
            let relative_after = refined[1].inverse() * order[i].1;
            assert!(
                (relative_after.to_homogeneous() - relative_before.to_homogeneous()).norm() < 1e-12
            );
        }
        // The frame halfway between the keyframes takes half of each one's correction.
        let corrections: Vec<_> = corrections(&odometry, &refined).collect();
        let halfway = corrections[0].lerp_slerp(&corrections[1], 0.5) * at(0.5, 0.1);
        assert!((order[1].1.to_homogeneous() - halfway.to_homogeneous()).norm() < 1e-12);
        // Not keyframe 0's correction alone (2 cm along x), nor keyframe 1's (none).
        let moved_m = (order[1].1.translation.vector - at(0.5, 0.1).translation.vector).norm();
        assert!(moved_m > 0.008 && moved_m < 0.013, "{moved_m}");
        // The region moves with the map: by the mean of the corrections at its centre.
        let roi = Roi::Cylinder {
            center_xy: [0.5, 0.0],
            z_min: -1.0,
            z_max: 1.0,
            radius_m: 0.5,
        };
        let moved = roi_after_adjustment(&roi, &odometry, &refined);
        let expected_m = corrections
            .iter()
            .map(|c| c * roi.center() - roi.center())
            .sum::<Vector3<f64>>()
            / 2.0;
        assert!((moved.center() - roi.center() - expected_m).norm() < 1e-12);
        assert!(expected_m.norm() > 0.005);
        assert_eq!(roi_after_adjustment(&roi, &[], &[]), roi);
        assert_eq!(stretch_fraction(0.0, 1.0, 0.25), 0.25);
        assert_eq!(stretch_fraction(1.0, 1.0, 1.0), 0.0);
        assert_eq!(stretch_fraction(0.0, 1.0, 2.0), 1.0);

        let mut bad = set.clone();
        bad.between_frames.push(between(2, 2.0, at(2.0, 0.0)));
        assert!(bad.fusion_order(&refined, 1.0, 1.0).is_err());
        assert!(set.fusion_order(&refined[..1], 1.0, 1.0).is_err());
        // The two corrections differ by 2 cm and 0.01 rad: with a tighter tolerance the frame
        // between them is left out; the frames after the last keyframe stay.
        let strict = set.fusion_order(&refined, 0.005, 1.0).unwrap();
        let stamps: Vec<f64> = strict.iter().map(|(f, _)| f.timestamp_s).collect();
        assert_eq!(stamps, vec![0.0, 1.0, 1.5, 1.6]);
    }
}
