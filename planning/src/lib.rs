//! # scarp-planning
//!
//! Motion for scarp: where the drone flies to find, localize and map a precariously balanced
//! rock, how it gets there smoothly, and a simulation of it doing so.
//!
//! - [`coverage`]: lawn-mower search over a rectangle or polygon at the search altitude.
//! - [`finelocalize`]: the paper's fine-localization circle and next-best view.
//! - [`mapping_rings`]: rings around the target's vertical bounding cylinder.
//! - [`minsnap`]: minimum-snap trajectories (Richter et al. 2016) within v_max and a_max.
//! - [`control`]: geometric SE(3) tracking controller (Lee et al. 2010).
//! - [`dynamics`]: quadrotor rigid-body model with motor limits, drag and gusts, RK4.
//! - [`clearance`]: distance to the terrain (a parry3d heightfield) and the rocks; repairs.
//! - [`flight`]: flies a trajectory and reports the `flight.json` metrics.
//! - `plot` (feature `plot`, on by default): top and side view PNGs, without fonts.
//!
//! Conventions: world ENU (x east, y north, z up, metres), body FLU, camera OpenCV; transforms
//! are named by what they map (`world_from_body`); units are in the names; everything is f64.
//! Every tunable lives in a serde config struct whose `Default` is documented; bad input gives
//! a [`PlanError`], never a panic. Nothing here is random except the optional wind gusts,
//! which take a seed.
//!
//! ## Example: map a 2 m rock and fly it
//!
//! ```
//! use nalgebra::Point3;
//! use scarp_planning::prelude::*;
//!
//! // Flat ground at z = 0 and the rock's bounding cylinder (radius 1 m, 2 m tall).
//! let terrain = Heightfield::flat(-30.0, -30.0, 1.0, 61, 61, 0.0)?;
//! let env = Environment::new(Some(terrain), &[])?;
//! let cylinder = VerticalCylinder::new(0.0, 0.0, 1.0, 0.0, 2.0)?;
//! let cfg = PlanningConfig::default();
//!
//! // Rings from the current pose, checked against the terrain.
//! let start = Waypoint::new(Point3::new(6.0, 0.0, 6.0), std::f64::consts::PI);
//! let rings = plan_mapping_rings_clear(
//!     &cylinder, &start, &cfg.camera, &cfg.mapping, &env, &cfg.clearance,
//! )?;
//! assert!(rings.coverage_gaps().is_empty());
//!
//! // Smooth, limit-respecting trajectory, then a simulated flight.
//! let (trajectory, _report, _repairs) = plan_clear_trajectory(
//!     &rings.path, &StartState::default(), &cfg.min_snap, &env, &cfg.clearance,
//! )?;
//! let flight = fly_trajectory(&trajectory, &env, &cfg.flight)?;
//! assert!(flight.metrics.position_rms_m < 0.1);
//! # Ok::<(), scarp_planning::PlanError>(())
//! ```

#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod camera;
pub mod clearance;
pub mod control;
pub mod coverage;
pub mod dynamics;
pub mod error;
pub mod finelocalize;
pub mod flight;
pub mod geometry;
pub mod mapping_rings;
pub mod minsnap;
#[cfg(feature = "plot")]
pub mod plot;
pub mod terrain;
pub mod terrain_distance;

pub use error::PlanError;

use serde::{Deserialize, Serialize};

/// Every tunable of the crate, grouped by module; `Default` gives the documented defaults.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PlanningConfig {
    /// The forward camera.
    pub camera: camera::CameraConfig,
    /// Lawn-mower search.
    pub coverage: coverage::CoverageConfig,
    /// Fine-localization circle.
    pub fine_localize: finelocalize::FineLocalizeConfig,
    /// Mapping rings.
    pub mapping: mapping_rings::MappingRingConfig,
    /// Trajectory generation and motion limits.
    pub min_snap: minsnap::MinSnapConfig,
    /// Clearance checks and repairs.
    pub clearance: clearance::ClearanceConfig,
    /// Simulated flight (airframe, controller, wind).
    pub flight: flight::FlightConfig,
}

impl PlanningConfig {
    /// [`mapping_rings::plan_mapping_rings_clear`] with this configuration's camera, rings and
    /// clearance: the rings around `cylinder` from `start`, clear of `env`.
    ///
    /// # Errors
    /// Those of [`mapping_rings::plan_mapping_rings_clear`].
    pub fn rings_around(
        &self,
        cylinder: &geometry::VerticalCylinder,
        start: &geometry::Waypoint,
        env: &clearance::Environment,
    ) -> Result<mapping_rings::RingPlan, PlanError> {
        mapping_rings::plan_mapping_rings_clear(
            cylinder,
            start,
            &self.camera,
            &self.mapping,
            env,
            &self.clearance,
        )
    }

    /// [`mapping_rings::plan_neck_ring_clear`] with this configuration's camera, rings and
    /// clearance: the neck ring around `cylinder` at the neck `neck_z_m` (world z, m), from
    /// `start`.
    ///
    /// # Errors
    /// Those of [`mapping_rings::plan_neck_ring_clear`].
    pub fn neck_ring_around(
        &self,
        cylinder: &geometry::VerticalCylinder,
        start: &geometry::Waypoint,
        neck_z_m: f64,
        env: &clearance::Environment,
    ) -> Result<mapping_rings::RingPlan, PlanError> {
        mapping_rings::plan_neck_ring_clear(
            cylinder,
            start,
            &self.camera,
            &self.mapping,
            neck_z_m,
            env,
            &self.clearance,
        )
    }

    /// What the neck ring's plan is flown against with [`Self::for_neck_ring`]: `env` with
    /// this configuration's clearance kept from its obstacles
    /// ([`mapping_rings::neck_ring_environment`]).
    pub fn neck_ring_environment(&self, env: &clearance::Environment) -> clearance::Environment {
        mapping_rings::neck_ring_environment(env, &self.mapping.neck_ring, &self.clearance)
    }

    /// This configuration with the clearance the neck ring keeps from the terrain
    /// ([`mapping_rings::NeckRingConfig::min_clearance_m`]), to fly its plan with (against
    /// [`Self::neck_ring_environment`]).
    pub fn for_neck_ring(&self) -> Self {
        let mut low = *self;
        low.clearance.min_clearance_m = self.mapping.neck_ring.min_clearance_m;
        low
    }
}

/// The types and functions most callers need.
pub mod prelude {
    pub use crate::PlanningConfig;
    pub use crate::camera::CameraConfig;
    pub use crate::clearance::{
        ClearanceConfig, ClearanceReport, Environment, Repair, plan_clear_trajectory,
    };
    pub use crate::control::{ControllerConfig, GeometricController, Reference};
    pub use crate::coverage::{
        CoverageConfig, CoveragePlan, SearchArea, plan_lawn_mower, plan_lawn_mower_clear,
    };
    pub use crate::dynamics::{QuadState, Quadrotor, QuadrotorParams, WindConfig};
    pub use crate::error::PlanError;
    pub use crate::finelocalize::{
        FineLocalizeConfig, FineLocalizePlan, plan_fine_localization, plan_fine_localization_clear,
    };
    pub use crate::flight::{FlightConfig, FlightMetrics, FlightResult, Simulator, fly_trajectory};
    pub use crate::geometry::{Path, PointSetPca, VerticalCylinder, Waypoint};
    pub use crate::mapping_rings::{
        MappingRingConfig, NeckRingConfig, RingPlan, plan_mapping_rings, plan_mapping_rings_clear,
        plan_neck_ring_clear,
    };
    pub use crate::minsnap::{FlatState, MinSnapConfig, StartState, Trajectory, plan_min_snap};
    pub use crate::terrain::{Heightfield, Obstacle};
}
