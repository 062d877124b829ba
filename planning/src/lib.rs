//! scarp-planning (WIP)
pub mod camera;
pub mod error;
pub mod geometry;
pub mod minsnap;
pub mod terrain;
