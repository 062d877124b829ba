//! The mapping pipeline that ties odometry, fusion, landmarks and bundle adjustment together:
//!
//! - [`tracker`]: frame-to-model RGBD tracking and TSDF fusion with the tracked poses
//!   ([`ModelTracker`]).
//! - [`landmarks`]: corners tracked with KLT across keyframes on and around the target,
//!   initialised from depth ([`track_landmarks`]).
//! - [`residuals`]: how well landmark observations fit a set of poses ([`reprojection_stats`]).
//! - [`refine`]: landmarks → bundle adjustment → re-integration → mesh on a target's stored
//!   keyframes ([`refine_keyframes`]), shared by `scarp map --ba` and the mission.
//!
//! World is ENU metres, cameras are OpenCV, transforms are `world_from_camera`.

pub mod landmarks;
pub mod reacquisition;
pub mod refine;
pub mod residuals;
pub mod tracker;

use thiserror::Error;

use crate::SlamError;
use crate::ba::BaError;
use crate::features::FeatureError;
use crate::odometry::OdometryError;
use crate::tsdf::TsdfError;

pub use landmarks::{LandmarkConfig, LandmarkView, Landmarks, track_landmarks};
pub use reacquisition::ReacquisitionSearch;
pub use refine::{
    BetweenFrame, EstimatedNoise, KeyframeSet, RefineConfig, RefinedMap, refine_keyframes,
};
pub use residuals::{
    CHI2_6_MEDIAN, ReprojectionStats, odometry_nees, reprojection_stats, triangulate_point,
};
pub use tracker::{
    EstimateDisagreement, EstimateRotationGate, ModelTracker, ModelTrackingConfig, Reacquisition,
    TrackedFrame, TrackingReferenceKind,
};

/// An error of the mapping pipeline.
#[derive(Debug, Error)]
pub enum MappingError {
    /// Invalid intrinsics or a non-finite pose.
    #[error("camera or pose: {0}")]
    Camera(SlamError),
    /// The TSDF volume or raycaster rejected its input.
    #[error(transparent)]
    Tsdf(#[from] TsdfError),
    /// The odometry rejected its input.
    #[error(transparent)]
    Odometry(#[from] OdometryError),
    /// Corner detection or KLT rejected its input.
    #[error("features: {0}")]
    Features(#[from] FeatureError),
    /// The bundle adjustment rejected the problem.
    #[error("bundle adjustment: {0}")]
    Ba(#[from] BaError),
    /// A mapping setting is out of range.
    #[error("invalid mapping setting `{field}`: {reason}")]
    InvalidConfig {
        /// The field.
        field: &'static str,
        /// Why it was rejected.
        reason: &'static str,
    },
    /// Inconsistent inputs (list lengths, empty sets).
    #[error("invalid mapping input: {0}")]
    InvalidInput(String),
}
