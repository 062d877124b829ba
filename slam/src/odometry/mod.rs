//! RGBD odometry: the camera's motion between a current frame and a reference.
//!
//! Coarse-to-fine Gauss–Newton on SE(3) over an image pyramid (≥ 3 levels). Every current-frame
//! pixel with depth is moved into the reference camera by the estimate, projected, and matched
//! projectively (KinectFusion). It contributes two residuals, each divided by its noise σ and
//! robustly weighted (Huber):
//! - photometric (Steinbrücker 2011, Kerl 2013): reference intensity at the projection minus the
//!   pixel's intensity, with the reference's image gradients in the Jacobian;
//! - geometric (point-to-plane ICP): the distance of the moved point to the reference surface
//!   point's tangent plane.
//!
//! The reference ([`TrackingReference`]) is the previous frame
//! ([`TrackingReference::from_pyramid`]) or a raycast of the TSDF model
//! ([`TrackingReference::from_raycast`]). The result is `reference_from_current`, which maps
//! points in the current camera frame to the reference camera frame, with the Hessian as the
//! 6×6 information matrix, the inlier ratio and a failure flag.
//!
//! ```
//! use nalgebra::Isometry3;
//! use scarp_slam::PinholeCamera;
//! use scarp_slam::image::{DepthImage, GrayImage, ImagePyramid};
//! use scarp_slam::odometry::{OdometryConfig, SourceFrame, TrackingReference, track};
//!
//! let camera = PinholeCamera::from_hfov(64, 48, 80.0).unwrap();
//! let config = OdometryConfig::default();
//! // A flat, textureless wall: the motion along it is unobservable.
//! let pyramid = ImagePyramid::new(
//!     GrayImage::filled(64, 48, 0.5),
//!     DepthImage::filled(64, 48, 2.0),
//!     config.levels,
//! );
//! let reference = TrackingReference::from_pyramid(&camera, &pyramid, &config).unwrap();
//! let current = SourceFrame::from_pyramid(&camera, &pyramid, &config).unwrap();
//! let result = track(&reference, &current, &Isometry3::identity(), &config).unwrap();
//! assert!(result.failure.is_some());
//! ```

mod config;
mod normal_equations;
mod reference;
mod source;

pub use config::OdometryConfig;
pub use reference::{RaycastImages, TrackingReference};
pub use source::SourceFrame;

use nalgebra::{Isometry3, Matrix6, SymmetricEigen, Translation3, UnitQuaternion, Vector3};
use thiserror::Error;

use crate::SlamError;
use crate::geometry::renormalized;
use crate::image::{ImagePyramid, gray_from_rgb};
use crate::{PinholeCamera, RgbdFrame};
use normal_equations::{NormalEquations, normal_equations};
use rayon::prelude::*;

/// Bad arguments to the odometry (not an untrustworthy result: that is an
/// [`OdometryFailure`] inside an `Ok`).
#[derive(Debug, Error, Clone, PartialEq)]
pub enum OdometryError {
    /// A configuration field is out of range.
    #[error("invalid odometry config `{field}`: {reason}")]
    InvalidConfig {
        /// The field's name.
        field: &'static str,
        /// Why it was rejected.
        reason: &'static str,
    },
    /// An image pyramid with too few levels.
    #[error("the image pyramid has {have} levels, the odometry needs {need}")]
    PyramidLevels {
        /// Levels present.
        have: usize,
        /// Levels configured.
        need: usize,
    },
    /// Reference and current frame were prepared with different cameras or level counts.
    #[error("reference and current frame do not match: {0}")]
    Mismatch(String),
    /// [`track_multi_start`] was given no start to track from.
    #[error("a multi-start track needs at least one start; none was given")]
    NoStarts,
    /// An image or camera error (size mismatch, bad intrinsics).
    #[error(transparent)]
    Input(#[from] SlamError),
}

/// Why a tracking result cannot be trusted. The caller falls back to the state estimate.
#[derive(Debug, Clone, PartialEq)]
pub enum OdometryFailure {
    /// The initial guess has NaN or infinite entries.
    NonFiniteInitialGuess,
    /// Too few current-frame pixels found a reference surface at the finest level (no depth,
    /// out of view, occluded).
    TooFewCorrespondences {
        /// Correspondences found.
        found: usize,
        /// Correspondences required.
        required: usize,
    },
    /// The Hessian leaves a direction unconstrained (a flat textureless plane, a corridor).
    Degenerate {
        /// Smallest over largest eigenvalue, rotations scaled to metres at the mean depth.
        eigenvalue_ratio: f64,
    },
    /// The estimate went non-finite or moved implausibly far from the initial guess.
    Diverged {
        /// Translation from the initial guess, metres (NaN when non-finite).
        correction_m: f64,
        /// Rotation from the initial guess, degrees (NaN when non-finite).
        correction_deg: f64,
    },
    /// Too few correspondences agree with the estimate.
    LowInlierRatio {
        /// The inlier ratio found.
        inlier_ratio: f64,
    },
}

impl std::fmt::Display for OdometryFailure {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::NonFiniteInitialGuess => write!(f, "the initial guess is not finite"),
            Self::TooFewCorrespondences { found, required } => {
                write!(f, "{found} correspondences, {required} required")
            }
            Self::Degenerate { eigenvalue_ratio } => {
                write!(
                    f,
                    "degenerate: Hessian eigenvalue ratio {eigenvalue_ratio:.3e}"
                )
            }
            Self::Diverged {
                correction_m,
                correction_deg,
            } => write!(
                f,
                "diverged: {correction_m:.3} m, {correction_deg:.2}° from the initial guess"
            ),
            Self::LowInlierRatio { inlier_ratio } => {
                write!(f, "inlier ratio {inlier_ratio:.3} too low")
            }
        }
    }
}

/// The outcome of [`track`].
#[derive(Debug, Clone, PartialEq)]
pub struct OdometryResult {
    /// Maps points in the current camera frame to the reference camera frame. When `failure`
    /// is set this is the initial guess (or the identity if that was not finite): do not use it.
    pub reference_from_current: Isometry3<f64>,
    /// The Gauss–Newton Hessian at the finest level, Σ JᵀΣ⁻¹J over the robustly weighted
    /// residuals: the information matrix of a left perturbation δ = (translation m, rotation
    /// rad) in the reference frame, `reference_from_current ← exp(δ)·reference_from_current`.
    pub information: Matrix6<f64>,
    /// Inliers (all residuals within `inlier_sigmas`) over the tracked current-frame points
    /// (pixels with depth, subsampled as `max_points_per_level` says).
    pub inlier_ratio: f64,
    /// Finest-level correspondences among the tracked points.
    pub correspondences: usize,
    /// Gauss–Newton iterations, all levels.
    pub iterations: usize,
    /// Why the result cannot be trusted, or `None`.
    pub failure: Option<OdometryFailure>,
}

impl OdometryResult {
    /// Whether the result can be used.
    pub fn is_ok(&self) -> bool {
        self.failure.is_none()
    }
}

/// An intensity/depth pyramid of a frame with `levels` levels.
pub fn frame_pyramid(frame: &RgbdFrame, levels: usize) -> ImagePyramid {
    ImagePyramid::new(gray_from_rgb(&frame.rgb), frame.depth_m.clone(), levels)
}

/// Fewest geometric inliers that the brightness fit of [`OdometryConfig::estimate_brightness`]
/// needs.
const MIN_BRIGHTNESS_SAMPLES: usize = 100;
/// The brightness gain is kept within [`MIN_GAIN`, 1 / `MIN_GAIN`] (an exposure change of more
/// than a factor of two between frames is a failure, not a gain).
const MIN_GAIN: f64 = 0.5;

/// Tracks `current` against `reference`, starting from `initial_reference_from_current` (the
/// state estimator's relative motion).
///
/// # Errors
/// [`OdometryError::InvalidConfig`]; [`OdometryError::Mismatch`] when the two were prepared with
/// different cameras or level counts. Untrustworthy results are `Ok` with `failure` set.
pub fn track(
    reference: &TrackingReference,
    current: &SourceFrame,
    initial_reference_from_current: &Isometry3<f64>,
    config: &OdometryConfig,
) -> Result<OdometryResult, OdometryError> {
    check_inputs(reference, current, config)?;
    let failed = |guess: Isometry3<f64>, failure| OdometryResult {
        reference_from_current: guess,
        information: Matrix6::zeros(),
        inlier_ratio: 0.0,
        correspondences: 0,
        iterations: 0,
        failure: Some(failure),
    };
    if !is_finite(initial_reference_from_current) {
        return Ok(failed(
            Isometry3::identity(),
            OdometryFailure::NonFiniteInitialGuess,
        ));
    }
    // A guess chained from many products may carry a quaternion slightly off unit length;
    // the linearisation's rotation matrix assumes unit length.
    let guess = renormalized(initial_reference_from_current);
    let required = config
        .min_correspondences
        .max((config.min_correspondence_fraction * current.camera.pixel_count() as f64) as usize);
    if current.valid_pixels() < required {
        return Ok(failed(
            guess,
            OdometryFailure::TooFewCorrespondences { found: 0, required },
        ));
    }

    let mut estimate = guess;
    let mut iterations = 0;
    let mut finest = NormalEquations::default();
    // `reference ≈ gain · current + bias`, refitted after every linearisation on the geometric
    // inliers (an exposure change is then not an intensity residual).
    let mut brightness = (1.0, 0.0);
    for level in (0..config.levels).rev() {
        let Some(aligned) = align_level(reference, current, level, estimate, brightness, config)
        else {
            return Ok(failed(
                guess,
                OdometryFailure::Diverged {
                    correction_m: f64::NAN,
                    correction_deg: f64::NAN,
                },
            ));
        };
        estimate = aligned.estimate;
        brightness = aligned.brightness;
        iterations += aligned.iterations;
        finest = aligned.last;
    }
    // The information and statistics come from the last finest-level linearisation (one small
    // step before the final estimate: the step was below the convergence threshold or the
    // iteration budget ran out).
    let information = finest.hessian();
    let inlier_ratio = finest.inliers as f64 / current.tracked_points().max(1) as f64;
    let mut result = OdometryResult {
        reference_from_current: estimate,
        information,
        inlier_ratio,
        correspondences: finest.correspondences,
        iterations,
        failure: None,
    };
    // Correspondences at full resolution, estimated from the subsampled points.
    let scale = current.valid_pixels() as f64 / current.tracked_points().max(1) as f64;
    let full_correspondences = (finest.correspondences as f64 * scale).round() as usize;
    result.failure = judge(
        &result,
        &finest,
        full_correspondences,
        &guess,
        required,
        config,
    );
    if result.failure.is_some() {
        result.reference_from_current = guess;
    }
    Ok(result)
}

/// Checks that `reference` and `current` were prepared for `config` with one camera.
fn check_inputs(
    reference: &TrackingReference,
    current: &SourceFrame,
    config: &OdometryConfig,
) -> Result<(), OdometryError> {
    config.validate()?;
    if reference.levels() < config.levels || current.levels.len() < config.levels {
        return Err(OdometryError::Mismatch(format!(
            "reference has {} levels, current frame {}, config wants {}",
            reference.levels(),
            current.levels.len(),
            config.levels
        )));
    }
    if reference.camera() != &current.camera {
        return Err(OdometryError::Mismatch("the cameras differ".to_string()));
    }
    Ok(())
}

/// Where Gauss–Newton left one pyramid level.
struct LevelAlignment {
    estimate: Isometry3<f64>,
    brightness: (f64, f64),
    /// The level's last linearisation.
    last: NormalEquations,
    iterations: usize,
}

/// Gauss–Newton at pyramid `level` from `estimate` (and the brightness `(gain, bias)`), up to
/// the level's iteration budget; `None` when a step went non-finite.
fn align_level(
    reference: &TrackingReference,
    current: &SourceFrame,
    level: usize,
    mut estimate: Isometry3<f64>,
    mut brightness: (f64, f64),
    config: &OdometryConfig,
) -> Option<LevelAlignment> {
    let ref_level = &reference.levels[level];
    let points = &current.levels[level];
    let mut last_cost_per_point = f64::INFINITY;
    let mut last = NormalEquations::default();
    let mut iterations = 0;
    for _ in 0..config.iterations_at(level) {
        let eq = normal_equations(ref_level, points, &estimate, brightness, config);
        iterations += 1;
        if config.estimate_brightness
            && let Some((gain, bias)) = eq.brightness_fit(MIN_BRIGHTNESS_SAMPLES)
        {
            brightness = (gain.clamp(MIN_GAIN, 1.0 / MIN_GAIN), bias);
        }
        let cost_per_point = eq.cost / eq.correspondences.max(1) as f64;
        last = eq;
        if eq.correspondences < 6 {
            break;
        }
        let Some(step) = solve_step(&eq) else {
            break;
        };
        let (dt, dw) = (step.0.norm(), step.1.norm());
        if !(dt.is_finite() && dw.is_finite()) {
            return None;
        }
        estimate = renormalized(
            &(Isometry3::from_parts(
                Translation3::from(step.0),
                UnitQuaternion::from_scaled_axis(step.1),
            ) * estimate),
        );
        let level_scale = f64::from(1u32 << level);
        let converged = dt < config.convergence_translation_m * level_scale
            && dw < config.convergence_rotation_rad * level_scale;
        let stalled = cost_per_point > last_cost_per_point * (1.0 + 1e-9) && level > 0;
        last_cost_per_point = cost_per_point;
        if converged || stalled {
            break;
        }
    }
    Some(LevelAlignment {
        estimate,
        brightness,
        last,
        iterations,
    })
}

/// Inliers of `current` against `reference` after Gauss–Newton at the coarsest level alone
/// from `guess` (0 for a non-finite guess or a diverged step): a cheap score to rank initial
/// guesses too far apart for one [`track`] to settle between them.
fn coarse_inliers(
    reference: &TrackingReference,
    current: &SourceFrame,
    guess: &Isometry3<f64>,
    config: &OdometryConfig,
) -> usize {
    if !is_finite(guess) {
        return 0;
    }
    align_level(
        reference,
        current,
        config.levels - 1,
        renormalized(guess),
        (1.0, 0.0),
        config,
    )
    .map_or(0, |aligned| aligned.last.inliers)
}

/// A [`track`] from the best of several initial guesses, where the state estimate is known only
/// to within more than [`OdometryConfig::max_correction_m`] (after a gap in view, the estimate's
/// position walks by up to metres, and a single guess that far out converges into a wrong
/// minimum of the cost or diverges).
#[derive(Debug, Clone, PartialEq)]
pub struct MultiStartResult {
    /// The result kept: the trusted one with the highest inlier ratio, or, when none was
    /// trusted, the first start's.
    pub result: OdometryResult,
    /// Index in the starts of the one kept.
    pub start: usize,
}

/// Tracks `current` against `reference` from each of `starts` (initial
/// `reference_from_current`s; the first is the plain guess): every start is ranked by its
/// inliers after Gauss–Newton at the coarsest level, the best `refine` of them and the first
/// start are tracked in full ([`track`]), and the trusted result with the highest inlier ratio is
/// kept (on a tie, the first start, then the better ranked). Deterministic for any thread count.
///
/// # Errors
/// As [`track`]; an empty `starts` is [`OdometryError::NoStarts`].
pub fn track_multi_start(
    reference: &TrackingReference,
    current: &SourceFrame,
    starts: &[Isometry3<f64>],
    refine: usize,
    config: &OdometryConfig,
) -> Result<MultiStartResult, OdometryError> {
    check_inputs(reference, current, config)?;
    if starts.is_empty() {
        return Err(OdometryError::NoStarts);
    }
    // The first start is tracked in full whatever its rank: only the others are scored.
    let scores: Vec<usize> = starts[1..]
        .par_iter()
        .map(|start| coarse_inliers(reference, current, start, config))
        .collect();
    let mut ranked: Vec<usize> = (1..starts.len()).collect();
    ranked.sort_by_key(|&k| (std::cmp::Reverse(scores[k - 1]), k));
    let mut tracked = Vec::with_capacity(refine + 1);
    for k in std::iter::once(0).chain(ranked.into_iter().take(refine)) {
        tracked.push((k, track(reference, current, &starts[k], config)?));
    }
    let mut best = 0;
    for (i, (_, result)) in tracked.iter().enumerate() {
        let kept = &tracked[best].1;
        if result.is_ok() && (!kept.is_ok() || result.inlier_ratio > kept.inlier_ratio) {
            best = i;
        }
    }
    let (start, result) = tracked.swap_remove(best);
    Ok(MultiStartResult { result, start })
}

/// Tracks frame `current` against frame `reference` (frame-to-frame), building both pyramids.
///
/// # Errors
/// As [`track`], plus image size errors.
pub fn track_frames(
    camera: &PinholeCamera,
    reference: &RgbdFrame,
    current: &RgbdFrame,
    initial_reference_from_current: &Isometry3<f64>,
    config: &OdometryConfig,
) -> Result<OdometryResult, OdometryError> {
    config.validate()?;
    let reference =
        TrackingReference::from_pyramid(camera, &frame_pyramid(reference, config.levels), config)?;
    let current =
        SourceFrame::from_pyramid(camera, &frame_pyramid(current, config.levels), config)?;
    track(&reference, &current, initial_reference_from_current, config)
}

fn is_finite(t: &Isometry3<f64>) -> bool {
    t.translation.vector.iter().all(|v| v.is_finite())
        && t.rotation.coords.iter().all(|v| v.is_finite())
}

/// Solves H·δ = −g by Cholesky; `None` when H is not positive definite.
fn solve_step(eq: &NormalEquations) -> Option<(Vector3<f64>, Vector3<f64>)> {
    let h = eq.hessian();
    let g = eq.gradient();
    // A tiny relative damping keeps an almost-singular H solvable; degeneracy is judged later.
    let damping = 1e-9 * (0..6).map(|i| h[(i, i)]).fold(0.0, f64::max);
    let mut damped = h;
    for i in 0..6 {
        damped[(i, i)] += damping;
    }
    let delta = damped.cholesky()?.solve(&(-g));
    Some((
        delta.fixed_rows::<3>(0).into(),
        delta.fixed_rows::<3>(3).into(),
    ))
}

/// Smallest over largest eigenvalue of H with the rotation block scaled to metres at `depth_m`.
pub(crate) fn eigenvalue_ratio(h: &Matrix6<f64>, depth_m: f64) -> f64 {
    let mut s = Matrix6::identity();
    for i in 3..6 {
        s[(i, i)] = 1.0 / depth_m.max(1e-3);
    }
    let scaled = s * h * s;
    let eig = SymmetricEigen::new(scaled).eigenvalues;
    let max = eig.max();
    let min = eig.min();
    if max > 0.0 && max.is_finite() {
        (min / max).max(0.0)
    } else {
        0.0
    }
}

fn judge(
    result: &OdometryResult,
    finest: &NormalEquations,
    full_correspondences: usize,
    guess: &Isometry3<f64>,
    required: usize,
    config: &OdometryConfig,
) -> Option<OdometryFailure> {
    let estimate = &result.reference_from_current;
    let correction = guess.inverse() * estimate;
    let correction_m = correction.translation.vector.norm();
    let correction_deg = correction.rotation.angle().to_degrees();
    if !is_finite(estimate)
        || !(correction_m <= config.max_correction_m)
        || !(correction_deg <= config.max_correction_deg)
    {
        return Some(OdometryFailure::Diverged {
            correction_m,
            correction_deg,
        });
    }
    if full_correspondences < required {
        return Some(OdometryFailure::TooFewCorrespondences {
            found: full_correspondences,
            required,
        });
    }
    let mean_depth = finest.depth_sum / finest.correspondences.max(1) as f64;
    let ratio = eigenvalue_ratio(&result.information, mean_depth);
    if !(ratio >= config.min_eigenvalue_ratio) {
        return Some(OdometryFailure::Degenerate {
            eigenvalue_ratio: ratio,
        });
    }
    if !(result.inlier_ratio >= config.min_inlier_ratio) {
        return Some(OdometryFailure::LowInlierRatio {
            inlier_ratio: result.inlier_ratio,
        });
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::{DepthImage, GrayImage};

    fn pyramid(gray: GrayImage, depth: DepthImage, config: &OdometryConfig) -> ImagePyramid {
        ImagePyramid::new(gray, depth, config.levels)
    }

    #[test]
    fn textureless_plane_is_degenerate() {
        let camera = PinholeCamera::from_hfov(160, 120, 80.0).unwrap();
        let config = OdometryConfig::default();
        let p = pyramid(
            GrayImage::filled(160, 120, 0.4),
            DepthImage::filled(160, 120, 3.0),
            &config,
        );
        let reference = TrackingReference::from_pyramid(&camera, &p, &config).unwrap();
        let current = SourceFrame::from_pyramid(&camera, &p, &config).unwrap();
        let r = track(&reference, &current, &Isometry3::identity(), &config).unwrap();
        assert!(
            matches!(r.failure, Some(OdometryFailure::Degenerate { .. })),
            "{:?}",
            r.failure
        );
    }

    #[test]
    fn zero_depth_and_nan_guess_fail() {
        let camera = PinholeCamera::from_hfov(160, 120, 80.0).unwrap();
        let config = OdometryConfig::default();
        let gray = GrayImage::from_vec(
            160,
            120,
            (0..160 * 120).map(|i| ((i % 7) as f32) / 7.0).collect(),
        )
        .unwrap();
        let empty = pyramid(gray.clone(), DepthImage::filled(160, 120, 0.0), &config);
        let reference = TrackingReference::from_pyramid(&camera, &empty, &config).unwrap();
        let current = SourceFrame::from_pyramid(&camera, &empty, &config).unwrap();
        let r = track(&reference, &current, &Isometry3::identity(), &config).unwrap();
        assert!(matches!(
            r.failure,
            Some(OdometryFailure::TooFewCorrespondences { .. })
        ));

        let full = pyramid(gray, DepthImage::filled(160, 120, 2.0), &config);
        let reference = TrackingReference::from_pyramid(&camera, &full, &config).unwrap();
        let current = SourceFrame::from_pyramid(&camera, &full, &config).unwrap();
        let nan = Isometry3::translation(f64::NAN, 0.0, 0.0);
        let r = track(&reference, &current, &nan, &config).unwrap();
        assert_eq!(r.failure, Some(OdometryFailure::NonFiniteInitialGuess));
        assert!(is_finite(&r.reference_from_current));
    }

    #[test]
    fn a_multi_start_needs_a_start_and_keeps_the_first_of_equals() {
        let camera = PinholeCamera::from_hfov(160, 120, 80.0).unwrap();
        let config = OdometryConfig::default();
        let gray = GrayImage::from_vec(
            160,
            120,
            (0..160 * 120)
                .map(|i| (((i % 160) / 9 + (i / 160) / 7) % 5) as f32 / 5.0)
                .collect(),
        )
        .unwrap();
        let full = pyramid(gray, DepthImage::filled(160, 120, 2.0), &config);
        let reference = TrackingReference::from_pyramid(&camera, &full, &config).unwrap();
        let current = SourceFrame::from_pyramid(&camera, &full, &config).unwrap();
        assert!(matches!(
            track_multi_start(&reference, &current, &[], 4, &config),
            Err(OdometryError::NoStarts)
        ));
        let nan = Isometry3::translation(f64::NAN, 0.0, 0.0);
        assert_eq!(coarse_inliers(&reference, &current, &nan, &config), 0);
        let identity = Isometry3::identity();
        assert!(coarse_inliers(&reference, &current, &identity, &config) > 0);
        let single = track(&reference, &current, &identity, &config).unwrap();
        let multi =
            track_multi_start(&reference, &current, &[identity, identity], 4, &config).unwrap();
        assert_eq!((multi.start, &multi.result), (0, &single));
        // A failed first start gives way to a trusted one, whatever the order.
        let multi = track_multi_start(&reference, &current, &[nan, identity], 1, &config).unwrap();
        assert_eq!(multi.start, usize::from(single.is_ok()));
    }

    #[test]
    fn eigenvalue_ratio_of_identity_is_one() {
        assert!((eigenvalue_ratio(&Matrix6::identity(), 1.0) - 1.0).abs() < 1e-12);
        let mut h = Matrix6::identity();
        h[(5, 5)] = 0.0;
        assert_eq!(eigenvalue_ratio(&h, 2.0), 0.0);
    }

    #[test]
    fn mismatched_levels_are_an_error() {
        let camera = PinholeCamera::from_hfov(64, 48, 80.0).unwrap();
        let config = OdometryConfig::default();
        let short = ImagePyramid::new(
            GrayImage::filled(64, 48, 0.5),
            DepthImage::filled(64, 48, 1.0),
            2,
        );
        assert!(matches!(
            TrackingReference::from_pyramid(&camera, &short, &config),
            Err(OdometryError::PyramidLevels { have: 2, need: 4 })
        ));
        let bad = OdometryConfig {
            levels: 2,
            ..OdometryConfig::default()
        };
        assert!(matches!(
            bad.validate(),
            Err(OdometryError::InvalidConfig {
                field: "levels",
                ..
            })
        ));
    }
}
