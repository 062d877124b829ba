//! # scarp
//!
//! The system crate: detection, bounding-box tracking, depth-filter localization, the mission
//! state machine, fragility analysis, evaluation metrics and the `scarp` command-line tool.
//! Geometry and mapping live in [`scarp_slam`], motion in [`scarp_planning`], file formats in
//! [`scarp_export`] and synthetic worlds in [`scarp_datasets`].

pub mod cli;
pub mod detection;
pub mod evaluation;
pub mod fragility;
pub mod tracking;
