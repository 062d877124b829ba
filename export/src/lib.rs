//! # scarp-export
//!
//! File formats that other tools open: OBJ meshes (read), TUM trajectories, and the atomic
//! write helper every writer uses.
//!
//! ```
//! use scarp_export::tum::{StampedPose, format_tum_trajectory, parse_tum_trajectory};
//! let pose = StampedPose { timestamp_s: 1.0, world_from_camera: nalgebra::Isometry3::identity() };
//! let text = format_tum_trajectory(&[pose], "one pose");
//! assert_eq!(parse_tum_trajectory(&text).unwrap(), vec![pose]);
//! ```

pub mod atomic;
pub mod obj;
pub mod tum;
