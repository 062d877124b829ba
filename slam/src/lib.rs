//! # scarp-slam
//!
//! The geometry core and mapping engine of scarp: pinhole cameras, rigid transforms, RGBD frames,
//! image pyramids, triangle meshes and point clouds; RGBD odometry ([`odometry`]) and keyframe
//! selection ([`keyframes`]); voxel-hashed TSDF fusion and raycasting ([`tsdf`]) and
//! marching-cubes meshing ([`meshing`]); corners and KLT ([`features`]); bundle adjustment
//! ([`ba`]); and the mapping pipeline that ties them together ([`mapping`]: frame-to-model or
//! frame-to-keyframe tracking with fusion, KLT landmarks, keyframe refinement).
//!
//! Conventions, which every public item follows:
//! - World is local ENU (x east, y north, z up), in metres.
//! - Camera is OpenCV (x right, y down, z forward); pixel (u, v) is (column, row) and pixel
//!   centres sit at integer coordinates.
//! - Transforms are named by what they map: `world_from_camera` takes camera coordinates to world
//!   coordinates.
//! - Depth is f32 metres along the camera z axis; 0.0 means "no measurement".
//!
//! ```
//! use nalgebra::{Point3, Vector3};
//! use scarp_slam::geometry::{PinholeCamera, look_at};
//!
//! // A 640×480 camera with an 80° horizontal field of view.
//! let camera = PinholeCamera::from_hfov(640, 480, 80.0).unwrap();
//! // A camera 5 m east of the origin, looking at it.
//! let world_from_camera = look_at(
//!     &Point3::new(5.0, 0.0, 0.0),
//!     &Point3::origin(),
//!     &Vector3::z(),
//! ).unwrap();
//! let p_camera = world_from_camera.inverse() * Point3::origin();
//! let pixel = camera.project(&p_camera).unwrap();
//! assert!((pixel.x - camera.cx).abs() < 1e-9 && (pixel.y - camera.cy).abs() < 1e-9);
//! ```

// `!(x > 0.0)` is the NaN-rejecting form of `x <= 0.0`: bad input must fail the check.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod ba;
pub mod error;
pub mod features;
pub mod frame;
pub mod geometry;
pub mod image;
pub mod keyframes;
pub mod mapping;
pub mod mesh;
pub mod meshing;
pub mod odometry;
pub mod point_cloud;
pub mod stats;
pub mod tsdf;

pub use error::SlamError;
pub use frame::RgbdFrame;
pub use geometry::PinholeCamera;
pub use mesh::TriangleMesh;
pub use point_cloud::PointCloud;
