//! The mission modes and the flight log kept at every camera frame.

use nalgebra::Isometry3;

/// What the vehicle is doing.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    /// Flying the lawn-mower pattern, detecting and localizing.
    Search,
    /// Flying the fine-localization circle around one target.
    FineLocalize(u32),
    /// Flying the mapping rings around one target, mapping it.
    Map(u32),
    /// The search pattern is finished.
    Done,
}

impl Mode {
    /// The mode's name in files.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Search => "search",
            Self::FineLocalize(_) => "fine_localize",
            Self::Map(_) => "map",
            Self::Done => "done",
        }
    }

    /// The mode named `name` (as [`Self::as_str`] writes it) working on `target`; `None` for an
    /// unknown name or a missing target.
    pub fn parse(name: &str, target: Option<u32>) -> Option<Self> {
        match (name, target) {
            ("search", _) => Some(Self::Search),
            ("fine_localize", Some(id)) => Some(Self::FineLocalize(id)),
            ("map", Some(id)) => Some(Self::Map(id)),
            ("done", _) => Some(Self::Done),
            _ => None,
        }
    }

    /// The target the mode works on, if any.
    pub fn target(self) -> Option<u32> {
        match self {
            Self::FineLocalize(id) | Self::Map(id) => Some(id),
            _ => None,
        }
    }
}

/// One camera instant of the flight log.
#[derive(Debug, Clone, Copy)]
pub struct FlightLogEntry {
    /// Mission time, seconds.
    pub time_s: f64,
    /// True camera pose (simulation only; `None` for a recorded flight).
    pub world_from_camera_truth: Option<Isometry3<f64>>,
    /// Estimated camera pose (GPS/IMU).
    pub world_from_camera_estimate: Isometry3<f64>,
    /// Mode at that instant.
    pub mode: Mode,
}
