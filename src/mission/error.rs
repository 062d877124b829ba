//! The mission's typed errors: what can stop a live mission, a recording, or the processing of
//! a recorded flight. Each wraps the error of the crate it came from, and [`Context`] adds the
//! stage it stopped in ("reading flight/flight.txt", "planning the lawn-mower search").

use scarp_datasets::DatasetError;
use scarp_export::atomic::AtomicWriteError;
use scarp_export::geojson::GeoJsonError;
use scarp_export::glb::GlbError;
use scarp_export::ply::PlyError;
use scarp_export::tum::TumError;
use scarp_planning::prelude::PlanError;
use scarp_slam::SlamError;
use scarp_slam::mapping::MappingError;

use crate::detection::DetectionError;
use crate::fragility::FragilityError;
use crate::localization::LocalizationError;
use crate::tracking::TrackingError;

/// What can stop a mission. The message names the stage and the file where there is one.
#[derive(Debug, thiserror::Error)]
pub enum MissionError {
    /// A mission setting out of range; the message names the key.
    #[error("invalid mission config: {0}")]
    Config(String),
    /// A recorded flight or a recording that is incomplete or inconsistent, or a step that
    /// found nothing to work on (an empty search pattern, a mesh without vertices).
    #[error("{0}")]
    Invalid(String),
    /// A figure of the report that could not be drawn.
    #[error("drawing {what}: {message}")]
    Drawing {
        /// Which figure.
        what: &'static str,
        /// The plotting backend's message.
        message: String,
    },
    /// The stage that failed, around the cause.
    #[error("{stage}: {source}")]
    Stage {
        /// What the mission was doing ("reading out/flight.txt").
        stage: String,
        /// Why it failed.
        #[source]
        source: Box<MissionError>,
    },
    /// A file or folder that could not be read or written (the stage names it).
    #[error(transparent)]
    Io(#[from] std::io::Error),
    /// A file that is not valid TOML.
    #[error(transparent)]
    Toml(#[from] toml::de::Error),
    /// A file that cannot be written as TOML.
    #[error(transparent)]
    TomlWrite(#[from] toml::ser::Error),
    /// A file that is not valid JSON, or a report that cannot be written as JSON.
    #[error(transparent)]
    Json(#[from] serde_json::Error),
    /// An output file that could not be written atomically.
    #[error(transparent)]
    Write(#[from] AtomicWriteError),
    /// A TUM trajectory that could not be read or written.
    #[error(transparent)]
    Trajectory(#[from] TumError),
    /// A PLY mesh or point cloud that could not be written.
    #[error(transparent)]
    Ply(#[from] PlyError),
    /// A GLB scene that could not be written.
    #[error(transparent)]
    Glb(#[from] GlbError),
    /// The catalog's GeoJSON that could not be written.
    #[error(transparent)]
    GeoJson(#[from] GeoJsonError),
    /// Cameras, poses, meshes and images.
    #[error(transparent)]
    Slam(#[from] SlamError),
    /// Odometry, fusion, landmarks and bundle adjustment.
    #[error(transparent)]
    Mapping(#[from] MappingError),
    /// Paths, trajectories and clearance.
    #[error(transparent)]
    Planning(#[from] PlanError),
    /// The world, the renderer, sensors and sequences.
    #[error(transparent)]
    Dataset(#[from] DatasetError),
    /// The detector.
    #[error(transparent)]
    Detection(#[from] DetectionError),
    /// The box tracker.
    #[error(transparent)]
    Tracking(#[from] TrackingError),
    /// The depth filter.
    #[error(transparent)]
    Localization(#[from] LocalizationError),
    /// The fragility analysis.
    #[error(transparent)]
    Fragility(#[from] FragilityError),
}

/// The mission's result type.
pub type MissionResult<T> = Result<T, MissionError>;

impl MissionError {
    /// An [`MissionError::Invalid`] with `message`.
    pub(crate) fn invalid(message: impl Into<String>) -> Self {
        Self::Invalid(message.into())
    }
}

/// Names the stage a result or an option failed in, as `anyhow::Context` does, but typed.
pub trait Context<T> {
    /// Wraps a failure in [`MissionError::Stage`] (or, for `None`, says that `stage` found
    /// nothing).
    fn context(self, stage: impl Into<String>) -> MissionResult<T>;
    /// As [`Context::context`], building the stage's text only on failure.
    fn with_context<S: Into<String>>(self, stage: impl FnOnce() -> S) -> MissionResult<T>;
}

impl<T, E: Into<MissionError>> Context<T> for Result<T, E> {
    fn context(self, stage: impl Into<String>) -> MissionResult<T> {
        self.map_err(|e| MissionError::Stage {
            stage: stage.into(),
            source: Box::new(e.into()),
        })
    }

    fn with_context<S: Into<String>>(self, stage: impl FnOnce() -> S) -> MissionResult<T> {
        self.map_err(|e| MissionError::Stage {
            stage: stage().into(),
            source: Box::new(e.into()),
        })
    }
}

impl<T> Context<T> for Option<T> {
    fn context(self, stage: impl Into<String>) -> MissionResult<T> {
        self.ok_or_else(|| MissionError::Invalid(stage.into()))
    }

    fn with_context<S: Into<String>>(self, stage: impl FnOnce() -> S) -> MissionResult<T> {
        self.ok_or_else(|| MissionError::Invalid(stage().into()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_stage_and_the_cause_both_reach_the_message() {
        let missing = std::fs::read_to_string("/nonexistent/flight.txt")
            .context("reading /nonexistent/flight.txt")
            .unwrap_err();
        let text = missing.to_string();
        assert!(
            text.starts_with("reading /nonexistent/flight.txt: "),
            "{text}"
        );
        assert!(std::error::Error::source(&missing).is_some());
        let none: Option<u8> = None;
        assert_eq!(
            none.context("the search pattern is empty")
                .unwrap_err()
                .to_string(),
            "the search pattern is empty"
        );
    }
}
