//! Sparse image features: corners and pyramidal Lucas–Kanade tracking, plus the robust 2-D
//! similarity fit that turns tracked corners into a box motion.
//!
//! One implementation serves both mapping (landmarks for bundle adjustment) and bounding-box
//! tracking (the KLT similarity transform of the box Kalman filter).
//!
//! All positions are pixel coordinates `(u, v)` = (column, row) with pixel centres at integers.
//! Intensities are [`GrayImage`](crate::image::GrayImage) values (any linear scale, usually
//! `[0, 1]`).
//!
//! ```
//! use nalgebra::Point2;
//! use scarp_slam::features::{
//!     CornerConfig, CornerRegion, KltConfig, KltPyramid, KltStatus, detect_corners,
//!     track_points,
//! };
//! use scarp_slam::image::GrayImage;
//!
//! // A textured image and the same image shifted 2 px to the right.
//! let texture = |u: f32, v: f32| 0.5 + 0.25 * (0.3 * u).sin() * (0.23 * v).cos() + 0.2 * (0.11 * (u + 2.0 * v)).sin();
//! let make = |shift: f32| {
//!     let data = (0..120 * 100).map(|i| texture((i % 120) as f32 - shift, (i / 120) as f32)).collect();
//!     GrayImage::from_vec(120, 100, data).unwrap()
//! };
//! let (prev, next) = (make(0.0), make(2.0));
//! let corners = detect_corners(&prev, &CornerConfig::default(), &CornerRegion::Whole).unwrap();
//! assert!(!corners.is_empty());
//! let config = KltConfig::default();
//! let points: Vec<Point2<f32>> = corners.iter().map(|c| c.position).collect();
//! let tracks = track_points(
//!     &KltPyramid::new(&prev, config.pyramid_levels),
//!     &KltPyramid::new(&next, config.pyramid_levels),
//!     &points,
//!     &config,
//! )
//! .unwrap();
//! let good = tracks.iter().zip(&points).filter(|(t, p)| {
//!     t.status == KltStatus::Tracked && (t.position.x - p.x - 2.0).abs() < 0.05
//! });
//! assert!(good.count() > 0);
//! ```

mod corners;
mod klt;
mod motion;
pub mod pattern;
mod similarity;

pub use corners::{Corner, CornerConfig, CornerRegion, CornerScore, PixelRect, detect_corners};
pub use klt::{
    GuidedPoint, KltConfig, KltPyramid, KltStatus, KltTrack, track_points, track_points_guided,
    track_points_warped, track_points_warped_from,
};
pub use motion::{MotionConfig, similarity_from_tracks, track_similarity};
pub use similarity::{
    Similarity2, SimilarityFit, SimilarityFitConfig, fit_similarity_least_squares,
    fit_similarity_robust,
};

use thiserror::Error;

/// An error of the feature module. Each variant names the argument or field at fault.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum FeatureError {
    /// A configuration field is out of its valid range.
    #[error("invalid feature config `{field}`: {reason}")]
    InvalidConfig {
        /// The config field.
        field: &'static str,
        /// Why it was rejected.
        reason: &'static str,
    },
    /// Two inputs that must match in size do not.
    #[error("{what}: {left} vs {right}")]
    SizeMismatch {
        /// What differs (for example `source and destination point counts`).
        what: &'static str,
        /// The first size.
        left: usize,
        /// The second size.
        right: usize,
    },
    /// Too few points (or too few distinct points) for a fit.
    #[error("{what} needs at least {needed} points, got {got}")]
    TooFewPoints {
        /// What was being fitted.
        what: &'static str,
        /// The minimum.
        needed: usize,
        /// What was given.
        got: usize,
    },
    /// An input coordinate is NaN or infinite.
    #[error("{what} {index} is not finite")]
    NotFinite {
        /// Which input (for example `source point`).
        what: &'static str,
        /// Its index.
        index: usize,
    },
    /// The points do not determine the fit (all source points coincide).
    #[error("degenerate fit: {0}")]
    Degenerate(&'static str),
    /// A mask whose size differs from the image's.
    #[error("mask is {mask_width}×{mask_height}, image is {width}×{height}")]
    MaskSize {
        /// Mask width, px.
        mask_width: u32,
        /// Mask height, px.
        mask_height: u32,
        /// Image width, px.
        width: u32,
        /// Image height, px.
        height: u32,
    },
}
