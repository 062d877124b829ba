//! # scarp
//!
//! The mission library: detection, bounding-box tracking, depth-filter localization, the mission
//! state machine (live, recorded and processed offline), fragility analysis, campaigns and
//! evaluation metrics. The `scarp` command-line tool is the `scarp-cli` crate, which alone
//! takes clap and the other command-line dependencies.
//! Geometry and mapping live in [`scarp_slam`], motion in [`scarp_planning`], file formats in
//! [`scarp_export`] and synthetic worlds in [`scarp_datasets`].
//!
//! ## Example
//!
//! The mission's box tracker, with the `scarp` preset (matched to the simulated detector's
//! σ 4 px box jitter), confirms a rock detected on three frames in a row; a detection scored
//! below the preset's 0.6 floor starts nothing.
//!
//! ```
//! use scarp::detection::{BoundingBox, Detection};
//! use scarp::tracking::{Tracker, TrackerConfig, TrackerPreset};
//! use scarp_slam::image::GrayImage;
//!
//! let mut tracker = Tracker::new(TrackerConfig::preset(TrackerPreset::Scarp))?;
//! let frame = GrayImage::filled(320, 240, 0.5);
//! let rock = Detection {
//!     bbox: BoundingBox::new(100.0, 80.0, 150.0, 130.0)?,
//!     score: 0.9,
//!     class_id: 0,
//! };
//! let doubtful = Detection {
//!     bbox: BoundingBox::new(220.0, 150.0, 250.0, 180.0)?,
//!     score: 0.4,
//!     class_id: 0,
//! };
//! for _ in 0..3 {
//!     tracker.step(&frame, &[rock, doubtful])?;
//! }
//! let tracks = tracker.tracks();
//! assert_eq!(tracks.len(), 1);
//! assert!(tracks[0].confirmed);
//! assert!(tracks[0].bbox.iou(&rock.bbox) > 0.99);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! ## Cargo features
//!
//! - `onnx` (off by default): `detection::OnnxDetector`, which runs YOLO v5/v8 ONNX exports
//!   with `tract-onnx` (pure Rust, nothing downloaded at run time). Off by default because it
//!   lengthens a clean build; CI builds and tests it.

// `!(x > 0.0)` is the NaN-rejecting form of `x <= 0.0`: bad input must fail the check.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod campaign;
pub mod detection;
pub mod evaluation;
pub mod fragility;
pub mod localization;
pub mod mission;
pub mod tracking;
