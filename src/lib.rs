//! # scarp
//!
//! The system crate: detection, bounding-box tracking, depth-filter localization, the mission
//! state machine, fragility analysis, evaluation metrics and the `scarp` command-line tool.
//! Geometry and mapping live in [`scarp_slam`], motion in [`scarp_planning`], file formats in
//! [`scarp_export`] and synthetic worlds in [`scarp_datasets`].
//!
//! ## Cargo features
//!
//! - `onnx` (off by default): `detection::OnnxDetector`, which runs YOLO v5/v8 ONNX exports
//!   with `tract-onnx` (pure Rust, nothing downloaded at run time). Off by default because it
//!   lengthens a clean build; CI builds and tests it.

// `!(x > 0.0)` is the NaN-rejecting form of `x <= 0.0`: bad input must fail the check.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod campaign;
pub mod cli;
pub mod detection;
pub mod evaluation;
pub mod fragility;
pub mod localization;
pub mod mission;
pub mod tracking;
