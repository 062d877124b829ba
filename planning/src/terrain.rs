//! Terrain and obstacle inputs, in plain types the world builder can fill in without knowing
//! parry3d. World ENU metres throughout.

use nalgebra::Point3;
use serde::{Deserialize, Serialize};

use crate::error::PlanError;
pub use scarp_slam::geometry::Heightfield;

/// Something the vehicle must keep clear of besides the terrain, in world ENU metres.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum Obstacle {
    /// A triangle mesh, e.g. a rock. Faces index `positions_m`; a closed mesh with outward
    /// (counter-clockwise seen from outside) faces also reports when a point is inside it.
    Mesh {
        /// Vertex positions (world ENU, metres).
        positions_m: Vec<[f64; 3]>,
        /// Triangles as vertex indices.
        faces: Vec<[u32; 3]>,
    },
    /// A solid vertical cylinder, e.g. a rock's bounding volume.
    Cylinder {
        /// World x of the axis (metres).
        center_x_m: f64,
        /// World y of the axis (metres).
        center_y_m: f64,
        /// Radius (metres).
        radius_m: f64,
        /// World z of the bottom face (metres).
        z_bottom_m: f64,
        /// World z of the top face (metres).
        z_top_m: f64,
    },
}

impl Obstacle {
    /// Checks values and indices; `index` names the obstacle in the error.
    pub fn validate(&self, index: usize) -> Result<(), PlanError> {
        let bad = |reason: String| PlanError::InvalidObstacle { index, reason };
        match self {
            Obstacle::Mesh { positions_m, faces } => {
                if faces.is_empty() {
                    return Err(bad("mesh has no faces".into()));
                }
                if let Some(k) = positions_m
                    .iter()
                    .position(|p| p.iter().any(|v| !v.is_finite()))
                {
                    return Err(bad(format!("positions_m[{k}] is not finite")));
                }
                let n = positions_m.len();
                if let Some(k) = faces
                    .iter()
                    .position(|f| f.iter().any(|&v| v as usize >= n))
                {
                    return Err(bad(format!("faces[{k}] indexes past {n} vertices")));
                }
                Ok(())
            }
            Obstacle::Cylinder {
                center_x_m,
                center_y_m,
                radius_m,
                z_bottom_m,
                z_top_m,
            } => {
                for (name, v) in [
                    ("center_x_m", center_x_m),
                    ("center_y_m", center_y_m),
                    ("z_bottom_m", z_bottom_m),
                    ("z_top_m", z_top_m),
                ] {
                    if !v.is_finite() {
                        return Err(bad(format!("{name} = {v} is not finite")));
                    }
                }
                if !(radius_m.is_finite() && *radius_m > 0.0) {
                    return Err(bad(format!("radius_m = {radius_m} must be > 0")));
                }
                if z_top_m <= z_bottom_m {
                    return Err(bad(format!(
                        "z_top_m = {z_top_m} must be above z_bottom_m = {z_bottom_m}"
                    )));
                }
                Ok(())
            }
        }
    }

    /// Mean of the vertices (mesh) or the axis midpoint (cylinder).
    pub fn center_m(&self) -> Point3<f64> {
        match self {
            Obstacle::Mesh { positions_m, .. } => {
                let n = positions_m.len().max(1) as f64;
                let s = positions_m
                    .iter()
                    .fold([0.0; 3], |a, p| [a[0] + p[0], a[1] + p[1], a[2] + p[2]]);
                Point3::new(s[0] / n, s[1] / n, s[2] / n)
            }
            Obstacle::Cylinder {
                center_x_m,
                center_y_m,
                z_bottom_m,
                z_top_m,
                ..
            } => Point3::new(*center_x_m, *center_y_m, 0.5 * (z_bottom_m + z_top_m)),
        }
    }
}
