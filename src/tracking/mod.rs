//! Bounding-box tracking (paper §II, Algorithm 1 with DESIGN.md's errata).
//!
//! [`kalman`] holds the filter maths (homogeneous predict with the KLT similarity, Euclidean
//! update with the detection, box entropy); [`tracker`] the multi-target [`Tracker`]
//! (association, registration, confirmation, deregistration, stable ids).
//!
//! Boxes are in continuous pixel coordinates of the tracked image (pixel centres at integers),
//! as [`crate::detection::BoundingBox`].
//!
//! ```
//! use scarp::detection::{BoundingBox, Detection};
//! use scarp::tracking::{Tracker, TrackerConfig};
//! use scarp_slam::image::GrayImage;
//!
//! let mut tracker = Tracker::new(TrackerConfig::default()).unwrap();
//! let frame = GrayImage::filled(320, 240, 0.5);
//! let detection = Detection {
//!     bbox: BoundingBox::new(100.0, 80.0, 140.0, 120.0).unwrap(),
//!     score: 0.9,
//!     class_id: 0,
//! };
//! let mut last = Vec::new();
//! for _ in 0..3 {
//!     last = tracker.step(&frame, &[detection]).unwrap();
//! }
//! // Three detections in a row confirm the track; its id stays 1.
//! assert_eq!(last.len(), 1);
//! assert!(last[0].confirmed && last[0].id == 1);
//! ```

pub mod kalman;
pub mod tracker;

pub use tracker::{TrackedBox, Tracker, TrackerConfig, TrackerPreset};

use scarp_slam::features::FeatureError;
use thiserror::Error;

/// An error of the tracker. Each variant names the field or input at fault.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum TrackingError {
    /// A tracker config field is out of range.
    #[error("invalid tracker config `{field}`: {reason}")]
    InvalidConfig {
        /// The field.
        field: &'static str,
        /// Why.
        reason: &'static str,
    },
    /// A feature (corner, KLT) config or input was rejected.
    #[error("features: {0}")]
    Feature(#[from] FeatureError),
    /// A frame's size differs from the previous frame's.
    #[error("frame is {width}×{height}, previous frames were {expected_width}×{expected_height}")]
    FrameSize {
        /// Previous width, px.
        expected_width: u32,
        /// Previous height, px.
        expected_height: u32,
        /// This frame's width, px.
        width: u32,
        /// This frame's height, px.
        height: u32,
    },
    /// A detection whose box is not finite or has no area.
    #[error("detection {index} has a non-finite or empty box")]
    InvalidDetection {
        /// Index in the detection slice.
        index: usize,
    },
}
