//! The closed-loop mission: Search → FineLocalize → Map → Search, for every target.
//!
//! - [`motion`]: the one motion system (min-snap trajectories flown by the geometric controller
//!   on the quadrotor model) that every mode uses.
//! - [`coverage`]: the cylinder-coverage test that ends mapping.
pub mod coverage;
pub mod motion;
