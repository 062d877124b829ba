//! # scarp-export
//!
//! File formats of scarp: PLY meshes and point clouds ([`ply`]), glTF binary scenes ([`glb`]),
//! GeoJSON target maps ([`geojson`]), OBJ meshes ([`obj`], read), TUM trajectories ([`tum`]),
//! and the crash-safe write helper every output goes through ([`atomic`]).
//!
//! Conventions:
//! - Meshes and clouds are [`scarp_slam::TriangleMesh`] and [`scarp_slam::PointCloud`], in world
//!   ENU metres (x east, y north, z up) unless a function says otherwise.
//! - Readers never panic on bad bytes: they return errors that name the file and the element
//!   at fault.
//! - Writers go through [`atomic::write_atomically`], so a crash never leaves half a file.
//!
//! ```
//! use nalgebra::Point3;
//! use scarp_export::ply::{self, PlyEncoding};
//! use scarp_slam::TriangleMesh;
//!
//! // A tetrahedron, metres, ENU.
//! let mesh = TriangleMesh::new(
//!     vec![
//!         Point3::new(0.0, 0.0, 0.0),
//!         Point3::new(1.0, 0.0, 0.0),
//!         Point3::new(0.0, 1.0, 0.0),
//!         Point3::new(0.0, 0.0, 1.0),
//!     ],
//!     vec![[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]],
//! )
//! .unwrap();
//!
//! let dir = std::env::temp_dir().join(format!("scarp-export-doc-{}", std::process::id()));
//! std::fs::create_dir_all(&dir).unwrap();
//! let path = dir.join("tetra.ply");
//! ply::write_mesh(&path, &mesh, PlyEncoding::BinaryLittleEndian).unwrap();
//! assert_eq!(ply::read_mesh(&path).unwrap(), mesh);
//!
//! // A missing file is an error that names the path.
//! let err = ply::read_mesh(dir.join("missing.ply")).unwrap_err();
//! assert!(err.to_string().contains("missing.ply"));
//! # std::fs::remove_dir_all(&dir).unwrap();
//! ```

#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod atomic;
pub mod geojson;
pub mod glb;
pub mod obj;
pub mod ply;
pub mod tum;
