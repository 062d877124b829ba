//! The closed-loop mission: Search → FineLocalize → Map → Search, for every target.
//!
//! - [`config`]: every tunable of a mission (`mission.toml`).
//! - [`motion`]: the one motion system (min-snap trajectories flown by the geometric controller
//!   on the quadrotor model) that every mode uses.
//! - [`mode`]: the modes and the flight log.
//! - [`mount`]: the camera mount's pitch servo (γ for search, nearly level on the base ring).
//! - [`catalog`]: the mission's targets and their status.
//! - [`sensors`]: the sensor seam: camera frames with their pose estimate and time, from the
//!   simulated vehicle ([`sensors::Simulated`]) or a recorded flight ([`sensors::Recorded`]).
//! - [`simulation`]: the simulation loop and the state machine.
//! - [`offline`]: the catalog of a recorded flight (`scarp process`).
//! - [`record`]: the flight as sensed (`scarp simulate --record`).
//! - [`perception`]: detect → track → localize during Search and FineLocalize.
//! - [`navigation`]: the position the controller flies on (the estimate, or the map's frame
//!   while mapping).
//! - [`mapping`]: Map mode for one target, then bundle adjustment, mesh, fragility, export.
//! - [`coverage`]: the cylinder-coverage test that ends mapping.
//! - [`evaluation`]: matching targets to the ground truth.
//! - [`safety`]: the flight's true clearance, and collisions as events.
//! - [`report`]: `mission.json`, `targets.geojson`, `targets.csv`.
//! - [`html`]: `report.html` and its pictures.
pub mod catalog;
pub mod config;
pub mod coverage;
pub mod environment;
pub mod error;
pub mod evaluation;
pub mod html;
pub mod mapping;
pub mod mode;
pub mod monitor;
pub mod motion;
pub mod mount;
pub mod navigation;
pub mod offline;
pub mod perception;
pub mod record;
pub mod report;
pub mod report_viewer;
pub mod safety;
pub mod sensors;
pub mod simulation;
