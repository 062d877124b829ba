//! Frame-to-model tracking: each new frame is tracked against a raycast of the TSDF being built
//! (at the previous frame's pose), then fused at the pose found.
//!
//! The initial guess is the state estimator's relative motion since the previous frame
//! ([`ModelTracker::process`]), or, for a camera with no state estimate (a handheld RGB-D
//! sequence), the previous frame's tracked motion: a constant-velocity model
//! ([`ModelTracker::process_unaided`]).
//!
//! A frame the tracker cannot trust (the odometry flags its result, or, with a state estimate
//! and an [`EstimateRotationGate`], its tracked rotation strays from the estimator's by more
//! than the estimator could have drifted since the previous frame):
//! - with a state estimate, is dropped (not fused, not a keyframe, not the next frame's
//!   reference), up to [`ModelTrackingConfig::max_dropped_frames`] in a row; beyond that it is
//!   placed by the estimate's motion, fused, and re-anchors the keyframes. An IMU's attitude is
//!   sure over a fraction of a second, so a jump of degrees is the odometry's local minimum;
//!   and the estimate's frame-to-frame position is off by centimetres, so a frame placed by it
//!   (and a keyframe taken there) would shift the rest of the map;
//! - without one, is placed by the constant-velocity guess and never fused, which a failed
//!   frame has no way to check.
//!
//! The tracker also accumulates the covariance of the motion since the last keyframe (the
//! inverse odometry information of each frame, moved to the keyframe pair's frame with the SE(3)
//! adjoint; a fixed fallback covariance for frames that failed), which becomes the odometry
//! relative-pose prior of the bundle adjustment.

use std::time::Instant;

use nalgebra::{Isometry3, Matrix3, Matrix6, Translation3, Vector3, Vector6};
use serde::{Deserialize, Serialize};

use super::MappingError;
use super::reacquisition::ReacquisitionSearch;
use crate::geometry::{check_finite_isometry, renormalized};
use crate::image::gray_from_rgb;
use crate::keyframes::{KeyframeConfig, KeyframeReason, KeyframeSelector};
use crate::odometry::OdometryResult;
use crate::odometry::{
    OdometryConfig, RaycastImages, SourceFrame, TrackingReference, frame_pyramid, track,
    track_multi_start,
};
use crate::tsdf::raycast::{RaycastConfig, raycast};
use crate::tsdf::{TsdfConfig, TsdfVolume};
use crate::{PinholeCamera, RgbdFrame};

/// What each frame is tracked against.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TrackingReferenceKind {
    /// A raycast of the TSDF being built, at the previous frame's pose (KinectFusion's
    /// frame-to-model tracking).
    Model,
    /// The last keyframe's own images (frame-to-keyframe tracking).
    Keyframe,
}

/// Settings of [`ModelTracker`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ModelTrackingConfig {
    /// What frames are tracked against. Default [`TrackingReferenceKind::Keyframe`]: on the
    /// default orbit with the default sensor noise, tracking against a raycast of the model
    /// diverges by decimetres (the noisy far terrain and the ROI cut in the model pull it away),
    /// while keyframe tracking stays within millimetres.
    pub reference: TrackingReferenceKind,
    /// The volume frames are fused into (voxel size, truncation, depth range, ROI). Default
    /// [`TsdfConfig::default`] (1 cm voxels, no ROI).
    pub tsdf: TsdfConfig,
    /// The odometry. Default [`OdometryConfig::default`] with `min_inlier_ratio` 0.05: the
    /// ratio counts inliers against every depth pixel of the frame, and a model limited to a
    /// region of interest covers only part of the frame.
    pub odometry: OdometryConfig,
    /// The raycast that renders the model as the tracking reference. Default
    /// [`RaycastConfig::default`].
    pub raycast: RaycastConfig,
    /// Keyframe thresholds, applied to the tracked poses. Default [`KeyframeConfig::default`].
    pub keyframes: KeyframeConfig,
    /// σ per axis of a frame's motion when the odometry failed and the estimator's motion was
    /// used, metres. Default 0.05 (the simulated estimator's white position noise is 2–3 cm per
    /// sample, so its frame-to-frame motion is off by about 4 cm).
    pub fallback_sigma_m: f64,
    /// The same for rotation, degrees. Default 0.5.
    pub fallback_sigma_deg: f64,
    /// For frames given a state estimate ([`ModelTracker::process`]): up to this many in a row
    /// whose odometry failed or disagreed with the estimate are dropped (not fused, not
    /// keyframes) rather than placed by the estimate's motion; the next one is placed by the
    /// estimate, fused, and becomes the new keyframe reference. Default 10 (the mission sets
    /// it from `mapping.max_dropped_s`). Why: the estimate's motion from frame to frame is off
    /// by centimetres (the simulated GPS's white noise: a median of 8 cm, up to 0.3 m, at the
    /// mission's 20 Hz), so a frame placed by it, and every keyframe tracked from it, shifts
    /// the map by that much; the next frame usually tracks again.
    pub max_dropped_frames: usize,
    /// For frames given a state estimate ([`ModelTracker::process`]): how far their tracked
    /// rotation may stray from the estimator's before they are dropped. Default `None` (no
    /// gate): its scale is the estimator's, which only the caller knows.
    pub estimate_rotation_gate: Option<EstimateRotationGate>,
    /// For frames given a state estimate ([`ModelTracker::process`]): the first frame after a
    /// gap in view is tracked from a grid of guesses spanning the estimate's walk over the
    /// gap (see [`super::reacquisition`]). Default `None` (one guess): the walk's scale is the
    /// estimator's, which only the caller knows.
    pub reacquisition: Option<ReacquisitionSearch>,
}

/// The largest disagreement, degrees, between a frame's tracked rotation since the previous
/// frame and the state estimator's: `min_deg + deg_per_sqrt_s · √Δt`, where Δt is the time
/// between the two frames' timestamps, seconds (the estimator's attitude error walks like a
/// random walk over short times, so its relative rotation is off by a σ growing as √Δt).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EstimateRotationGate {
    /// Allowed at any Δt (the odometry's own error, and the estimator's noise between
    /// frames taken at once), degrees.
    pub min_deg: f64,
    /// Allowed per √second between the frames, degrees/√s.
    pub deg_per_sqrt_s: f64,
}

impl EstimateRotationGate {
    /// The largest disagreement allowed between frames `dt_s` seconds apart, degrees (a
    /// negative or non-finite `dt_s` counts as 0).
    pub fn tolerance_deg(&self, dt_s: f64) -> f64 {
        let dt_s = if dt_s.is_finite() { dt_s.max(0.0) } else { 0.0 };
        self.min_deg + self.deg_per_sqrt_s * dt_s.sqrt()
    }

    fn validate(&self) -> Result<(), MappingError> {
        for (field, value) in [
            ("estimate_rotation_gate.min_deg", self.min_deg),
            ("estimate_rotation_gate.deg_per_sqrt_s", self.deg_per_sqrt_s),
        ] {
            if !(value.is_finite() && value >= 0.0) {
                return Err(MappingError::InvalidConfig {
                    field,
                    reason: "must be finite and not negative",
                });
            }
        }
        Ok(())
    }
}

/// A frame's tracked rotation beyond the [`EstimateRotationGate`] (the frame is then dropped,
/// or, past [`ModelTrackingConfig::max_dropped_frames`], placed by the estimate).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EstimateDisagreement {
    /// Angle between the tracked and the estimated rotation since the previous frame, degrees.
    pub rotation_deg: f64,
    /// The gate's tolerance for the time between the frames, degrees.
    pub tolerance_deg: f64,
}

impl Default for ModelTrackingConfig {
    fn default() -> Self {
        Self {
            reference: TrackingReferenceKind::Keyframe,
            tsdf: TsdfConfig::default(),
            odometry: OdometryConfig {
                min_inlier_ratio: 0.05,
                ..OdometryConfig::default()
            },
            raycast: RaycastConfig::default(),
            keyframes: KeyframeConfig::default(),
            fallback_sigma_m: 0.05,
            fallback_sigma_deg: 0.5,
            max_dropped_frames: 10,
            estimate_rotation_gate: None,
            reacquisition: None,
        }
    }
}

/// What [`ModelTracker::process`] did with one frame.
#[derive(Debug, Clone)]
pub struct TrackedFrame {
    /// Index of the frame (0 for the first processed).
    pub index: usize,
    /// The pose the frame was fused at: the tracked pose, the estimator's relative motion after a
    /// failure, or the state estimate itself for the first frame.
    pub world_from_camera: Isometry3<f64>,
    /// The odometry's result (`None` for the first frame, which has no model to track against).
    /// Its `reference_from_current` is relative to the previous frame's fused pose.
    pub odometry: Option<OdometryResult>,
    /// The odometry failed and the guessed motion was used.
    pub fell_back: bool,
    /// The frame was fused into the model (false for an unaided frame whose odometry failed,
    /// and for a dropped frame).
    pub fused: bool,
    /// The frame, given a state estimate, was not trusted (its odometry failed, or disagreed
    /// with the estimate) and was dropped: not fused, not a keyframe, and the tracker is as it
    /// was before it (see [`ModelTrackingConfig::max_dropped_frames`]). `world_from_camera` is
    /// then where the estimate's motion puts it, and `odometry` holds the untrusted result.
    pub dropped: bool,
    /// The tracked rotation's disagreement with the state estimate, when beyond the
    /// [`EstimateRotationGate`] (the frame was then dropped, or placed by the estimate).
    pub disagreement: Option<EstimateDisagreement>,
    /// For the first frame after a gap tracked from several guesses
    /// ([`ModelTrackingConfig::reacquisition`]): the search, and the guess kept.
    pub reacquisition: Option<Reacquisition>,
    /// Why the frame became a keyframe, or `None`.
    pub keyframe: Option<KeyframeReason>,
    /// For a keyframe after the first: the covariance of the tracked motion since the previous
    /// keyframe, as a right perturbation (translation m, rotation rad) of
    /// `previous_keyframe_from_camera`.
    pub keyframe_covariance: Option<Matrix6<f64>>,
    /// Wall time of the odometry (raycast, reference, source pyramid, Gauss–Newton),
    /// milliseconds; `None` for the first frame.
    pub odometry_ms: Option<f64>,
    /// Wall time of the TSDF integration, milliseconds.
    pub integrate_ms: f64,
}

/// How a frame after a gap in view was re-acquired ([`ModelTrackingConfig::reacquisition`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reacquisition {
    /// Time since the previous kept frame, seconds.
    pub gap_s: f64,
    /// Guesses ranked.
    pub starts: usize,
    /// The kept guess's offset from the plain guess (the previous kept frame moved by the
    /// estimate's motion), world frame, metres.
    pub offset_m: Vector3<f64>,
}

impl TrackedFrame {
    /// Why the frame was not trusted (dropped, or placed by the guess): the odometry's failure,
    /// or its disagreement with the state estimate; `None` for a trusted frame.
    pub fn distrust_reason(&self) -> Option<String> {
        match (
            self.odometry.as_ref().and_then(|o| o.failure.as_ref()),
            &self.disagreement,
        ) {
            (Some(failure), _) => Some(failure.to_string()),
            (None, Some(d)) => Some(format!(
                "the tracked rotation strays {:.2}° from the state estimate's (tolerance {:.2}°)",
                d.rotation_deg, d.tolerance_deg
            )),
            (None, None) => None,
        }
    }
}

/// Frame-to-model RGBD tracking and TSDF fusion with its own poses.
///
/// ```no_run
/// # use scarp_slam::mapping::{ModelTracker, ModelTrackingConfig};
/// # fn frames() -> Vec<(scarp_slam::RgbdFrame, nalgebra::Isometry3<f64>)> { Vec::new() }
/// let camera = scarp_slam::PinholeCamera::from_hfov(640, 480, 80.0).unwrap();
/// let mut tracker = ModelTracker::new(camera, ModelTrackingConfig::default()).unwrap();
/// for (frame, world_from_camera_estimate) in frames() {
///     let tracked = tracker.process(&frame, &world_from_camera_estimate).unwrap();
///     println!("{:?}", tracked.world_from_camera);
/// }
/// ```
#[derive(Debug)]
pub struct ModelTracker {
    camera: PinholeCamera,
    config: ModelTrackingConfig,
    volume: TsdfVolume,
    selector: KeyframeSelector,
    /// The previous frame's fused pose.
    previous: Option<Isometry3<f64>>,
    /// The previous frame's state estimate (frames given one).
    previous_estimate: Option<Isometry3<f64>>,
    /// The previous frame's timestamp, seconds.
    previous_timestamp_s: Option<f64>,
    /// Frames dropped since the last one kept.
    dropped_in_a_row: usize,
    /// The previous frame's motion, `previous_from_current` of the frame before it (the
    /// constant-velocity guess of [`ModelTracker::process_unaided`]).
    last_motion: Isometry3<f64>,
    /// Covariance of the motion since the last keyframe (right perturbation).
    covariance_since_keyframe: Matrix6<f64>,
    /// The last keyframe as a reference (keyframe mode) and its pose.
    keyframe: Option<(TrackingReference, Isometry3<f64>)>,
    frames: usize,
}

impl ModelTracker {
    /// An empty model seen by `camera`.
    ///
    /// # Errors
    /// [`MappingError::Tsdf`] / [`MappingError::Odometry`] for invalid settings,
    /// [`MappingError::Camera`] for invalid intrinsics.
    pub fn new(camera: PinholeCamera, config: ModelTrackingConfig) -> Result<Self, MappingError> {
        camera.validate().map_err(MappingError::Camera)?;
        config.odometry.validate()?;
        config.keyframes.validate().map_err(MappingError::Camera)?;
        if let Some(gate) = &config.estimate_rotation_gate {
            gate.validate()?;
        }
        if let Some(search) = &config.reacquisition {
            search.validate()?;
        }
        for (field, value) in [
            ("fallback_sigma_m", config.fallback_sigma_m),
            ("fallback_sigma_deg", config.fallback_sigma_deg),
        ] {
            if !(value.is_finite() && value > 0.0) {
                return Err(MappingError::InvalidConfig {
                    field,
                    reason: "must be positive and finite",
                });
            }
        }
        let volume = TsdfVolume::new(config.tsdf.clone())?;
        Ok(Self {
            camera,
            selector: KeyframeSelector::new(config.keyframes, camera),
            config,
            volume,
            previous: None,
            previous_estimate: None,
            previous_timestamp_s: None,
            dropped_in_a_row: 0,
            last_motion: Isometry3::identity(),
            covariance_since_keyframe: Matrix6::zeros(),
            keyframe: None,
            frames: 0,
        })
    }

    /// The model built so far.
    pub fn volume(&self) -> &TsdfVolume {
        &self.volume
    }

    /// The model, consuming the tracker.
    pub fn into_volume(self) -> TsdfVolume {
        self.volume
    }

    /// Tracks `frame` against the model (initialised with the estimator's motion since the
    /// previous frame), fuses it at the pose found, and offers it as a keyframe.
    ///
    /// # Errors
    /// [`MappingError::Camera`] for a non-finite estimate; [`MappingError::Tsdf`] when the frame
    /// does not match the camera; [`MappingError::Odometry`] for mismatched inputs. A frame the
    /// odometry cannot track is not an error (see [`TrackedFrame::fell_back`]).
    pub fn process(
        &mut self,
        frame: &RgbdFrame,
        world_from_camera_estimate: &Isometry3<f64>,
    ) -> Result<TrackedFrame, MappingError> {
        check_finite_isometry(world_from_camera_estimate, "world_from_camera_estimate")
            .map_err(MappingError::Camera)?;
        let motion = self
            .previous_estimate
            .map(|previous| previous.inverse() * world_from_camera_estimate);
        let tracked = self.process_with_motion(frame, world_from_camera_estimate, motion, true)?;
        if !tracked.dropped {
            self.previous_estimate = Some(*world_from_camera_estimate);
        }
        Ok(tracked)
    }

    /// Tracks `frame` with no state estimate: the first frame is placed at
    /// `world_from_first_camera` (the map's gauge; ignored afterwards), and each later frame's
    /// guess is the previous frame's motion (constant velocity). Mixing this with
    /// [`ModelTracker::process`] in one sequence guesses from the last frame that had an
    /// estimate.
    ///
    /// # Errors
    /// As [`ModelTracker::process`]; a non-finite `world_from_first_camera` is an error.
    pub fn process_unaided(
        &mut self,
        frame: &RgbdFrame,
        world_from_first_camera: &Isometry3<f64>,
    ) -> Result<TrackedFrame, MappingError> {
        check_finite_isometry(world_from_first_camera, "world_from_first_camera")
            .map_err(MappingError::Camera)?;
        let motion = self.previous.map(|_| self.last_motion);
        self.process_with_motion(frame, world_from_first_camera, motion, false)
    }

    /// Tracks `frame` from the guess `previous_from_current_guess` (`None` for the first frame,
    /// placed at `world_from_first_camera`), fuses it and offers it as a keyframe. A frame whose
    /// odometry failed is fused only when `fuse_on_guess` (the guess is a state estimate).
    fn process_with_motion(
        &mut self,
        frame: &RgbdFrame,
        world_from_first_camera: &Isometry3<f64>,
        previous_from_current_guess: Option<Isometry3<f64>>,
        fuse_on_guess: bool,
    ) -> Result<TrackedFrame, MappingError> {
        let index = self.frames;
        let odometry_config = &self.config.odometry;
        let pyramid = frame_pyramid(frame, odometry_config.levels);
        let (world_from_camera, odometry, disagreement, reacquisition, fell_back, odometry_ms) =
            match self.previous {
                None => (*world_from_first_camera, None, None, None, false, None),
                Some(world_from_previous) => {
                    let started = Instant::now();
                    let motion = previous_from_current_guess.unwrap_or_else(Isometry3::identity);
                    // Where the guess puts the frame: the previous one moved by the motion.
                    let world_from_guess = world_from_previous * motion;
                    let source =
                        SourceFrame::from_pyramid(&self.camera, &pyramid, odometry_config)?;
                    // The reference, its pose, and the guess of `reference_from_current`: the model
                    // seen from the previous frame, or the last keyframe.
                    let model;
                    let (reference, world_from_reference, guess) =
                        match (&self.config.reference, &self.keyframe) {
                            (
                                TrackingReferenceKind::Keyframe,
                                Some((reference, world_from_keyframe)),
                            ) => (
                                reference,
                                *world_from_keyframe,
                                world_from_keyframe.inverse() * world_from_previous * motion,
                            ),
                            _ => {
                                model = self.model_reference(&world_from_previous)?;
                                (&model, world_from_previous, motion)
                            }
                        };
                    let searched = if fuse_on_guess {
                        self.reacquire(
                            reference,
                            &source,
                            &world_from_reference,
                            &world_from_guess,
                            self.seconds_since_previous(frame),
                        )?
                    } else {
                        None
                    };
                    let (result, reacquisition) = match searched {
                        Some((result, reacquisition)) => (result, Some(reacquisition)),
                        None => (track(reference, &source, &guess, odometry_config)?, None),
                    };
                    let ms = started.elapsed().as_secs_f64() * 1e3;
                    let world_from_tracked = world_from_reference * result.reference_from_current;
                    let disagreement = if result.is_ok() {
                        self.disagreement(
                            frame,
                            &world_from_previous,
                            &world_from_tracked,
                            previous_from_current_guess.filter(|_| fuse_on_guess),
                        )
                    } else {
                        None
                    };
                    let trusted = result.is_ok() && disagreement.is_none();
                    if !trusted
                        && fuse_on_guess
                        && self.dropped_in_a_row < self.config.max_dropped_frames
                    {
                        self.dropped_in_a_row += 1;
                        self.frames += 1;
                        return Ok(TrackedFrame {
                            index,
                            world_from_camera: renormalized(&world_from_guess),
                            odometry: Some(result),
                            fell_back: false,
                            fused: false,
                            dropped: true,
                            disagreement,
                            reacquisition,
                            keyframe: None,
                            keyframe_covariance: None,
                            odometry_ms: Some(ms),
                            integrate_ms: 0.0,
                        });
                    }
                    let world_from_camera = if trusted {
                        world_from_tracked
                    } else {
                        world_from_guess
                    };
                    let covariance = trusted
                        .then(|| result.information.try_inverse())
                        .flatten()
                        .filter(|c| c.iter().all(|v| v.is_finite()));
                    let from_keyframe_reference = world_from_reference != world_from_previous
                        || self.config.reference == TrackingReferenceKind::Keyframe;
                    self.covariance_since_keyframe = match covariance {
                        // Tracked against the keyframe itself: its covariance is the whole motion's.
                        Some(c) if from_keyframe_reference => {
                            chain_covariance(&Matrix6::zeros(), &c, &result.reference_from_current)
                        }
                        Some(c) => chain_covariance(
                            &self.covariance_since_keyframe,
                            &c,
                            &result.reference_from_current,
                        ),
                        None => chain_covariance(
                            &self.covariance_since_keyframe,
                            &self.fallback_covariance(),
                            &motion,
                        ),
                    };
                    (
                        renormalized(&world_from_camera),
                        Some(result),
                        disagreement,
                        reacquisition,
                        !trusted,
                        Some(ms),
                    )
                }
            };
        let started = Instant::now();
        let fused = !fell_back || fuse_on_guess;
        if fused {
            self.volume
                .integrate(frame, &self.camera, &world_from_camera)?;
        }
        let integrate_ms = started.elapsed().as_secs_f64() * 1e3;
        let mut keyframe = self.selector.offer(&world_from_camera, &frame.depth_m);
        if fell_back && keyframe.is_none() {
            // A failure re-anchors the keyframe reference on this frame.
            self.selector = KeyframeSelector::new(self.config.keyframes, self.camera);
            keyframe = self.selector.offer(&world_from_camera, &frame.depth_m);
        }
        let keyframe_covariance = match keyframe {
            Some(_) if index > 0 => Some(self.covariance_since_keyframe),
            _ => None,
        };
        if keyframe.is_some() {
            self.covariance_since_keyframe = Matrix6::zeros();
            if self.config.reference == TrackingReferenceKind::Keyframe {
                self.keyframe = Some((
                    TrackingReference::from_pyramid(&self.camera, &pyramid, odometry_config)?,
                    world_from_camera,
                ));
            }
        }
        if let Some(world_from_previous) = self.previous {
            self.last_motion = renormalized(&(world_from_previous.inverse() * world_from_camera));
        }
        self.previous = Some(world_from_camera);
        self.previous_timestamp_s = Some(frame.timestamp_s);
        self.dropped_in_a_row = 0;
        self.frames += 1;
        Ok(TrackedFrame {
            index,
            world_from_camera,
            odometry,
            fell_back,
            fused,
            dropped: false,
            disagreement,
            reacquisition,
            keyframe,
            keyframe_covariance,
            odometry_ms,
            integrate_ms,
        })
    }

    /// Tracks `source` against `reference` (at `world_from_reference`) from the grid of
    /// guesses about `world_from_guess` that [`ModelTrackingConfig::reacquisition`] spans after
    /// a gap of `gap_s` seconds; `None` (track from the one guess) without a search, when it
    /// does not apply (a short gap, no frame dropped since the last one kept:
    /// [`ReacquisitionSearch::applies`]) or when the grid is the one guess.
    fn reacquire(
        &self,
        reference: &TrackingReference,
        source: &SourceFrame,
        world_from_reference: &Isometry3<f64>,
        world_from_guess: &Isometry3<f64>,
        gap_s: f64,
    ) -> Result<Option<(OdometryResult, Reacquisition)>, MappingError> {
        let Some(search) = self
            .config
            .reacquisition
            .as_ref()
            .filter(|search| search.applies(gap_s, self.dropped_in_a_row))
        else {
            return Ok(None);
        };
        let offsets_m = search.offsets_m(gap_s);
        if offsets_m.len() < 2 {
            return Ok(None);
        }
        let reference_from_world = world_from_reference.inverse();
        let starts: Vec<Isometry3<f64>> = offsets_m
            .iter()
            .map(|o| reference_from_world * Translation3::from(*o) * world_from_guess)
            .collect();
        let multi = track_multi_start(
            reference,
            source,
            &starts,
            search.refine_starts,
            &self.config.odometry,
        )?;
        let reacquisition = Reacquisition {
            gap_s,
            starts: starts.len(),
            offset_m: offsets_m[multi.start],
        };
        Ok(Some((multi.result, reacquisition)))
    }

    /// Seconds from the previous kept frame to `frame`, by timestamp (0 for the first frame).
    fn seconds_since_previous(&self, frame: &RgbdFrame) -> f64 {
        self.previous_timestamp_s
            .map_or(0.0, |previous| frame.timestamp_s - previous)
    }

    /// How far the tracked motion since the previous frame turns from the state estimate's
    /// `previous_from_current_estimate` (`None`: no estimate, or no gate), when beyond the
    /// gate's tolerance for the time between the frames.
    fn disagreement(
        &self,
        frame: &RgbdFrame,
        world_from_previous: &Isometry3<f64>,
        world_from_camera: &Isometry3<f64>,
        previous_from_current_estimate: Option<Isometry3<f64>>,
    ) -> Option<EstimateDisagreement> {
        let gate = self.config.estimate_rotation_gate?;
        let estimated = previous_from_current_estimate?;
        let tracked = world_from_previous.inverse() * world_from_camera;
        let rotation_deg = (estimated.rotation.inverse() * tracked.rotation)
            .angle()
            .to_degrees();
        let tolerance_deg = gate.tolerance_deg(self.seconds_since_previous(frame));
        (rotation_deg > tolerance_deg).then_some(EstimateDisagreement {
            rotation_deg,
            tolerance_deg,
        })
    }

    /// The covariance of a frame whose odometry failed.
    fn fallback_covariance(&self) -> Matrix6<f64> {
        let t = self.config.fallback_sigma_m.powi(2);
        let r = self.config.fallback_sigma_deg.to_radians().powi(2);
        Matrix6::from_diagonal(&Vector6::new(t, t, t, r, r, r))
    }

    /// The model raycast at `world_from_reference`, as a tracking reference.
    fn model_reference(
        &self,
        world_from_reference: &Isometry3<f64>,
    ) -> Result<TrackingReference, MappingError> {
        let model = raycast(
            &self.volume,
            &self.camera,
            world_from_reference,
            &self.config.raycast,
        )?;
        Ok(TrackingReference::from_raycast(
            &self.camera,
            &RaycastImages {
                intensity: gray_from_rgb(&model.rgb),
                depth_m: model.depth_m,
                normals: model.normals_camera,
            },
            &self.config.odometry,
        )?)
    }
}

/// The SE(3) adjoint of `t` for perturbations ordered (translation, rotation):
/// `t·exp(δ) = exp(Ad·δ)·t`, Ad = [[R, [t]ₓR], [0, R]].
pub(crate) fn adjoint(t: &Isometry3<f64>) -> Matrix6<f64> {
    let r = *t.rotation.to_rotation_matrix().matrix();
    let p = t.translation.vector;
    let skew = Matrix3::new(0.0, -p.z, p.y, p.z, 0.0, -p.x, -p.y, p.x, 0.0);
    let mut ad = Matrix6::zeros();
    ad.fixed_view_mut::<3, 3>(0, 0).copy_from(&r);
    ad.fixed_view_mut::<3, 3>(0, 3).copy_from(&(skew * r));
    ad.fixed_view_mut::<3, 3>(3, 3).copy_from(&r);
    ad
}

/// Covariance of the right perturbation of `keyframe_from_previous · previous_from_current`
/// given `so_far` (right perturbation of `keyframe_from_previous`) and `frame_left`, the
/// covariance of the left perturbation of `previous_from_current` (as the odometry's
/// information describes it): both move through Ad(previous_from_current⁻¹).
pub(crate) fn chain_covariance(
    so_far: &Matrix6<f64>,
    frame_left: &Matrix6<f64>,
    previous_from_current: &Isometry3<f64>,
) -> Matrix6<f64> {
    let a = adjoint(&previous_from_current.inverse());
    let c = a * (so_far + frame_left) * a.transpose();
    (c + c.transpose()) * 0.5
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion, Vector3};

    #[test]
    fn adjoint_moves_a_right_perturbation_to_the_left() {
        let t = Isometry3::from_parts(
            Translation3::new(0.3, -1.2, 2.0),
            UnitQuaternion::from_scaled_axis(Vector3::new(0.2, -0.4, 0.9)),
        );
        let delta = Vector6::new(1e-6, -2e-6, 3e-6, 2e-6, 1e-6, -3e-6);
        let exp = |d: &Vector6<f64>| {
            Isometry3::from_parts(
                Translation3::new(d[0], d[1], d[2]),
                UnitQuaternion::from_scaled_axis(Vector3::new(d[3], d[4], d[5])),
            )
        };
        let left = exp(&(adjoint(&t) * delta)) * t;
        let right = t * exp(&delta);
        let e = left.inverse() * right;
        assert!(e.translation.vector.norm() < 1e-10, "{e:?}");
        assert!(e.rotation.angle() < 1e-10);
    }

    #[test]
    fn an_unaided_frame_that_fails_is_not_fused() {
        // A textured wall at 2 m, then a frame that sees depth only in a 10×10 patch at 1 m:
        // too few correspondences, so the odometry fails. Unaided, the guessed pose has nothing
        // behind it and the frame is skipped.
        let camera = PinholeCamera::new(100.0, 100.0, 79.5, 59.5, 160, 120).unwrap();
        let pixels = || (0..120u32).flat_map(|v| (0..160u32).map(move |u| (u, v)));
        let rgb = crate::image::Image::from_vec(
            160,
            120,
            pixels()
                .map(|(u, v)| {
                    let c = ((u / 8 + v / 8) % 2 * 200 + 30) as u8;
                    [c, c, c]
                })
                .collect(),
        )
        .unwrap();
        let wall = RgbdFrame::new(
            0.0,
            rgb.clone(),
            crate::image::Image::filled(160, 120, 2.0f32),
            None,
        )
        .unwrap();
        let patch = crate::image::Image::from_vec(
            160,
            120,
            pixels()
                .map(|(u, v)| {
                    if (70..80).contains(&u) && (50..60).contains(&v) {
                        1.0f32
                    } else {
                        0.0
                    }
                })
                .collect(),
        )
        .unwrap();
        let stray = RgbdFrame::new(0.1, rgb, patch, None).unwrap();
        let config = ModelTrackingConfig {
            tsdf: TsdfConfig {
                voxel_size_m: 0.05,
                ..TsdfConfig::default()
            },
            ..ModelTrackingConfig::default()
        };
        let first = Isometry3::identity();
        let mut unaided = ModelTracker::new(camera, config.clone()).unwrap();
        assert!(unaided.process_unaided(&wall, &first).unwrap().fused);
        let blocks = unaided.volume().stats().blocks;
        let tracked = unaided.process_unaided(&stray, &first).unwrap();
        assert!(tracked.fell_back && !tracked.fused);
        assert_eq!(unaided.volume().stats().blocks, blocks);

        // With a state estimate, the failed frame is dropped while fewer than
        // `max_dropped_frames` were dropped in a row, then fused where the estimate puts it.
        let mut aided = ModelTracker::new(camera, config.clone()).unwrap();
        aided.process(&wall, &first).unwrap();
        let tracked = aided.process(&stray, &first).unwrap();
        assert!(tracked.dropped && !tracked.fell_back && !tracked.fused);
        assert_eq!(aided.volume().stats().blocks, blocks);

        let mut placed = ModelTracker::new(
            camera,
            ModelTrackingConfig {
                max_dropped_frames: 0,
                ..config
            },
        )
        .unwrap();
        placed.process(&wall, &first).unwrap();
        let tracked = placed.process(&stray, &first).unwrap();
        assert!(tracked.fell_back && tracked.fused && !tracked.dropped);
        assert!(placed.volume().stats().blocks > blocks);
    }

    #[test]
    fn chained_identity_motions_add_covariances() {
        let a = Matrix6::identity() * 2.0;
        let b = Matrix6::identity() * 3.0;
        let c = chain_covariance(&a, &b, &Isometry3::identity());
        assert!((c - Matrix6::identity() * 5.0).amax() < 1e-12);
    }
}
