//! # scarp-datasets
//!
//! Synthetic worlds for scarp: fault-scarp terrain, precariously balanced rocks on pedestals and
//! distractor boulders, a z-buffer RGBD rasterizer with instance masks, sensor and
//! state-estimator noise models, and TUM RGB-D sequences (read and write).
//!
//! The world file format is documented with a complete example in `datasets/README.md`, which
//! is included below; a test builds that example, so it always parses.
//!
//! ```
//! use scarp_datasets::world::World;
//! use scarp_datasets::render::Renderer;
//! use scarp_slam::{PinholeCamera, geometry::look_at};
//! use nalgebra::{Point3, Vector3};
//!
//! let world = World::from_toml_str(
//!     r#"
//!     [terrain.procedural]
//!     size_m = 20.0
//!     resolution_m = 1.0
//!
//!     [[rocks]]
//!     id = 1
//!     role = "target"
//!     position_m = [0.0, 0.0]
//!     height_m = 1.5
//!     shape = { boulder = { seed = 3, subdivisions = 3 } }
//!     pedestal = { height_m = 1.0, top_radius_m = 0.3 }
//!     "#,
//!     std::path::Path::new("inline.toml"),
//!     std::path::Path::new("."),
//! ).unwrap();
//! let rock = world.rock(1).unwrap();
//! let camera = PinholeCamera::from_hfov(64, 48, 80.0).unwrap();
//! let world_from_camera =
//!     look_at(&(rock.centroid + Vector3::new(4.0, 0.0, 2.0)), &rock.centroid, &Vector3::z()).unwrap();
//! let frame = Renderer::new(&world).render(&camera, &world_from_camera).unwrap();
//! // The rock fills the centre of the image.
//! assert_eq!(*frame.instance.get(32, 24).unwrap(), 1);
//! ```
#![doc = include_str!("../README.md")]
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
