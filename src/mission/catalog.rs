//! The mission's target catalog: every target the localization filter registered, with its
//! mission status, the cylinder flown around it and its report row. Keyed by the localization
//! target id, ordered, so iteration (and thus the run) is deterministic.

use std::collections::BTreeMap;

use nalgebra::Point3;
use scarp_planning::prelude::VerticalCylinder;
use serde::{Deserialize, Serialize};

use super::perception::TargetState;
use super::report::TargetReport;

/// Where a target is in the mission.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TargetStatus {
    /// Seen and being localized during the search.
    Localizing,
    /// The fine-localization circle is being flown.
    FineLocalizing,
    /// Localized; waiting to be mapped.
    Localized,
    /// The mapping rings are being flown.
    Mapping,
    /// Mapped, meshed and analysed.
    Mapped,
    /// Mapping ended with too little coverage, or the mesh could not be analysed.
    Incomplete,
    /// The fine-localization circle ended without convergence.
    Unconverged,
    /// The planner could not reach it safely.
    Unreachable,
    /// A second registration of a rock the mission already mapped (or gave up on).
    Duplicate,
}

impl TargetStatus {
    /// Whether the target's reported centre still follows its depth filter (it is being
    /// localized); from mapping on, the centre is the one the mission acted on.
    pub fn follows_filter(self) -> bool {
        matches!(self, Self::Localizing | Self::FineLocalizing)
    }

    /// The status as written in files.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Localizing => "localizing",
            Self::FineLocalizing => "fine_localizing",
            Self::Localized => "localized",
            Self::Mapping => "mapping",
            Self::Mapped => "mapped",
            Self::Incomplete => "incomplete",
            Self::Unconverged => "unconverged",
            Self::Unreachable => "unreachable",
            Self::Duplicate => "duplicate",
        }
    }
}

/// A target as the mission sees it.
#[derive(Debug, Clone)]
pub struct MissionTarget {
    /// Mission status.
    pub status: TargetStatus,
    /// The cylinder flown around it, once planned.
    pub cylinder: Option<VerticalCylinder>,
    /// Horizontal covariance of its localization points `[σxx, σxy, σyy]`, m².
    pub covariance_xy: Option<[f64; 3]>,
    /// The report row.
    pub report: TargetReport,
}

impl MissionTarget {
    /// A newly registered target at `center`, found at mission time `time_s`.
    pub fn new(id: u32, center: &Point3<f64>, time_s: f64) -> Self {
        Self {
            status: TargetStatus::Localizing,
            cylinder: None,
            covariance_xy: None,
            report: {
                let mut report = TargetReport {
                    id: u64::from(id),
                    status: TargetStatus::Localizing.as_str().into(),
                    found_at_s: time_s,
                    ..TargetReport::default()
                };
                report.set_localized_center(center);
                report
            },
        }
    }

    /// Takes the depth filter's current C_e, its spread and its horizontal covariance.
    pub fn follow_filter(&mut self, state: &TargetState) {
        self.report.set_localized_center(&state.center);
        self.report.localized_sigma_m = Some(state.sigma_m);
        self.covariance_xy = Some(state.covariance_xy);
    }

    /// Sets the status in both places it is kept.
    pub fn set_status(&mut self, status: TargetStatus) {
        self.status = status;
        self.report.status = status.as_str().into();
    }

    /// Whether the mission is done with it (mapped or given up): it is skipped from now on.
    pub fn is_finished(&self) -> bool {
        !matches!(
            self.status,
            TargetStatus::Localizing | TargetStatus::FineLocalizing | TargetStatus::Mapping
        )
    }
}

/// The catalog: mission targets by localization id.
pub type Catalog = BTreeMap<u32, MissionTarget>;

/// Whether `center` (a localized centre) lies horizontally within `radius_m` of the localized
/// centre of a target the mission has finished with or is working on (any status but
/// `localizing` and `duplicate`), other than `except`: a re-registration of a rock already
/// handled. Localized centres are compared, not a scan's centroid, so that both carry the
/// filter's own bias.
pub fn is_already_handled(
    catalog: &Catalog,
    center: &Point3<f64>,
    radius_m: f64,
    except: Option<u32>,
) -> bool {
    catalog.iter().any(|(id, m)| {
        Some(*id) != except
            && !matches!(m.status, TargetStatus::Localizing | TargetStatus::Duplicate)
            && (m.report.localized_center[0] - center.x)
                .hypot(m.report.localized_center[1] - center.y)
                < radius_m
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn handled_targets_are_skipped_and_new_ones_are_not() {
        let mut catalog = Catalog::new();
        let mut mapped = MissionTarget::new(1, &Point3::new(0.0, 0.0, 1.0), 3.0);
        mapped.set_status(TargetStatus::Mapped);
        mapped.report.cylinder_radius_m = 1.5;
        assert!(mapped.is_finished());
        catalog.insert(1, mapped);
        assert!(is_already_handled(
            &catalog,
            &Point3::new(1.2, 0.0, 3.0),
            2.0,
            None
        ));
        assert!(!is_already_handled(
            &catalog,
            &Point3::new(1.2, 0.0, 3.0),
            2.0,
            Some(1)
        ));
        assert!(!is_already_handled(
            &catalog,
            &Point3::new(5.0, 0.0, 1.0),
            2.0,
            None
        ));
        let fresh = MissionTarget::new(2, &Point3::new(9.0, 0.0, 1.0), 4.0);
        assert!(!fresh.is_finished());
        assert_eq!(fresh.report.status, "localizing");
    }
}
