//! # scarp-datasets
//!
//! Synthetic worlds for scarp: fault-scarp terrain, precariously balanced rocks on pedestals and
//! distractor boulders, a z-buffer RGBD rasterizer with instance masks, sensor and
//! state-estimator noise models, and TUM RGB-D sequences (read and write).
//!
//! ```
//! use scarp_datasets::world::World;
//! let world = World::from_toml_str(
//!     r#"
//!     [terrain.procedural]
//!     size_m = 20.0
//!     resolution_m = 1.0
//!     "#,
//!     std::path::Path::new("inline.toml"),
//!     std::path::Path::new("."),
//! ).unwrap();
//! assert!(world.rocks.is_empty());
//! ```

// `!(x > 0.0)` is how this crate rejects NaN along with non-positive values, on purpose.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod error;
pub mod estimator;
pub mod noise;
pub mod paths;
pub mod render;
pub mod rock;
pub mod sensor;
pub mod sequence;
pub mod terrain;
pub mod texture;
pub mod world;

pub use error::DatasetError;
