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
use crate::ba::{
    AbsolutePosePrior, BaSummary, KeyframeModel, KeyframeNoise, KeyframeObservation, LmConfig,
    RelativePosePrior, RobustLoss, solve,
};
use crate::image::gray_from_rgb;
use crate::meshing::{MeshingConfig, extract_mesh};
use crate::tsdf::{TsdfConfig, TsdfVolume};
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
    /// Frames between keyframes k and k + 1 are re-integrated only when the adjustment's
    /// corrections of the two keyframes differ by at most this translation, metres. Default
    /// 0.005 (half a voxel): a larger change means the odometry drifted within the stretch.
    pub between_max_correction_change_m: f64,
    /// ... and at most this rotation, degrees. Default 0.25.
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
            gps_sigma_m: 0.8,
            attitude_sigma_deg: 2.0,
            odometry_information_scale: 0.1,
            reject_residual_px: Some(0.75),
            tsdf: TsdfConfig::default(),
            meshing: MeshingConfig::default(),
            mesh_before: false,
            between_max_correction_change_m: 0.005,
            between_max_correction_change_deg: 0.25,
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
    /// pose: keyframe k at `keyframe_poses[k]`, a frame between at its odometry pose moved by
    /// its keyframe's correction `keyframe_poses[k] · odometry_k⁻¹`.
    ///
    /// A frame between keyframes k and k + 1 is left out when their corrections differ by more
    /// than `max_correction_change_m` or `max_correction_change_rad`: the odometry drifted or
    /// failed within that stretch, so its poses there are not worth fusing.
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
        let corrections: Vec<Isometry3<f64>> = keyframe_poses
            .iter()
            .zip(&self.world_from_camera_odometry)
            .map(|(refined, odometry)| refined * odometry.inverse())
            .collect();
        for (k, (frame, pose)) in self.frames.iter().zip(keyframe_poses).enumerate() {
            order.push((frame, *pose));
            let consistent = corrections.get(k + 1).is_none_or(|next| {
                let change = corrections[k].inverse() * next;
                change.translation.vector.norm() <= max_correction_change_m
                    && change.rotation.angle() <= max_correction_change_rad
            });
            while let Some(b) = between.next_if(|b| b.keyframe == k) {
                if consistent {
                    order.push((&b.frame, corrections[k] * b.world_from_camera_odometry));
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
    let landmarks = track_landmarks(camera, &views, config.tsdf.roi.as_ref(), &config.landmarks)?;
    let landmarks_ms = started.elapsed().as_secs_f64() * 1e3;

    let started = Instant::now();
    let model = KeyframeModel::new(
        *camera,
        config.noise,
        absolute_priors(keyframes, config),
        relative_priors(keyframes, config),
    )?;
    let mut poses = keyframes.world_from_camera_odometry.clone();
    let mut points = landmarks.points.clone();
    let mut ba = solve(
        &model,
        &mut poses,
        &mut points,
        &landmarks.observations,
        &config.solver,
    )?;
    let mut landmarks = landmarks;
    if let Some(threshold_px) = config.reject_residual_px {
        let kept = reject_outliers(
            camera,
            &poses,
            &points,
            &landmarks,
            threshold_px,
            config.landmarks.min_observations,
        );
        if kept.observations.len() < landmarks.observations.len() {
            points = kept.points.clone();
            landmarks = kept;
            let first = ba;
            ba = solve(
                &model,
                &mut poses,
                &mut points,
                &landmarks.observations,
                &config.solver,
            )?;
            // One report for both solves: the first solve's costs come first.
            let mut costs = first.costs;
            costs.extend(ba.costs.iter().copied());
            ba.initial_cost = first.initial_cost;
            ba.iterations += first.iterations;
            ba.costs = costs;
            let mut log = first.log;
            log.append(&mut ba.log);
            ba.log = log;
        }
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
    let volume = fuse_in_order(camera, &order(&poses)?, &config.tsdf)?;
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
        landmarks_ms,
        ba_ms,
        reintegrate_ms,
        mesh_ms,
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

/// Odometry priors between consecutive keyframes, with the scaled inverse of the accumulated
/// odometry covariance; pairs whose covariance is missing or not invertible get none.
fn relative_priors(keyframes: &KeyframeSet, config: &RefineConfig) -> Vec<RelativePosePrior> {
    let poses = &keyframes.world_from_camera_odometry;
    (1..poses.len())
        .filter_map(|b| {
            let covariance = keyframes.odometry_covariance[b]?;
            let information = covariance.try_inverse()?;
            let information =
                (information + information.transpose()) * (0.5 * config.odometry_information_scale);
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
        // Between frames keep their odometry pose relative to their keyframe.
        for (i, k, odometry_frame) in [(1, 0, at(0.5, 0.1)), (3, 1, at(1.5, 0.4))] {
            let relative_before = odometry[k].inverse() * odometry_frame;
            let relative_after = refined[k].inverse() * order[i].1;
            assert!(
                (relative_after.to_homogeneous() - relative_before.to_homogeneous()).norm() < 1e-12
            );
        }
        assert!((order[1].1.translation.x - 0.52).abs() < 1e-12);

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
