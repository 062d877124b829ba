//! Terrain and obstacle inputs, in plain types the world builder can fill in without knowing
//! parry3d. World ENU metres throughout.

use nalgebra::Point3;
use serde::{Deserialize, Serialize};

use crate::error::{PlanError, check_finite, check_positive};

/// A regular elevation grid (DEM). Node (i, j) sits at
/// `(origin_x_m + i·spacing_m, origin_y_m + j·spacing_m)` and has height
/// `heights_m[j·nx + i]` (row-major, rows advance north).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Heightfield {
    /// World x of node (0, 0) (metres).
    pub origin_x_m: f64,
    /// World y of node (0, 0) (metres).
    pub origin_y_m: f64,
    /// Grid spacing in x and y (metres).
    pub spacing_m: f64,
    /// Number of nodes along x (columns).
    pub nx: usize,
    /// Number of nodes along y (rows).
    pub ny: usize,
    /// Terrain height of each node (world z, metres), row-major.
    pub heights_m: Vec<f64>,
}

impl Heightfield {
    /// Creates a heightfield, checking its shape and values.
    ///
    /// Fails if `nx` or `ny` is below 2, the height count is not `nx·ny`, the spacing is not
    /// positive, or any value is not finite.
    pub fn new(
        origin_x_m: f64,
        origin_y_m: f64,
        spacing_m: f64,
        nx: usize,
        ny: usize,
        heights_m: Vec<f64>,
    ) -> Result<Self, PlanError> {
        let hf = Self {
            origin_x_m,
            origin_y_m,
            spacing_m,
            nx,
            ny,
            heights_m,
        };
        hf.validate()?;
        Ok(hf)
    }

    /// A flat grid at height `z_m` covering `[x0, x0 + (nx−1)·spacing] × [y0, y0 + (ny−1)·spacing]`.
    pub fn flat(
        origin_x_m: f64,
        origin_y_m: f64,
        spacing_m: f64,
        nx: usize,
        ny: usize,
        z_m: f64,
    ) -> Result<Self, PlanError> {
        Self::new(
            origin_x_m,
            origin_y_m,
            spacing_m,
            nx,
            ny,
            vec![z_m; nx.saturating_mul(ny)],
        )
    }

    /// A grid sampled from a function of world (x, y).
    pub fn from_fn(
        origin_x_m: f64,
        origin_y_m: f64,
        spacing_m: f64,
        nx: usize,
        ny: usize,
        f: impl Fn(f64, f64) -> f64,
    ) -> Result<Self, PlanError> {
        let mut heights = Vec::with_capacity(nx.saturating_mul(ny));
        for j in 0..ny {
            for i in 0..nx {
                heights.push(f(
                    origin_x_m + i as f64 * spacing_m,
                    origin_y_m + j as f64 * spacing_m,
                ));
            }
        }
        Self::new(origin_x_m, origin_y_m, spacing_m, nx, ny, heights)
    }

    /// Checks the invariants listed in [`Heightfield::new`].
    pub fn validate(&self) -> Result<(), PlanError> {
        check_finite("terrain.origin_x_m", self.origin_x_m)?;
        check_finite("terrain.origin_y_m", self.origin_y_m)?;
        check_positive("terrain.spacing_m", self.spacing_m)?;
        if self.nx < 2 || self.ny < 2 {
            return Err(PlanError::InvalidTerrain {
                reason: format!(
                    "needs at least 2×2 nodes, got nx = {}, ny = {}",
                    self.nx, self.ny
                ),
            });
        }
        if Some(self.heights_m.len()) != self.nx.checked_mul(self.ny) {
            return Err(PlanError::InvalidTerrain {
                reason: format!(
                    "heights_m has {} values, expected nx·ny = {}·{}",
                    self.heights_m.len(),
                    self.nx,
                    self.ny
                ),
            });
        }
        if let Some(k) = self.heights_m.iter().position(|h| !h.is_finite()) {
            return Err(PlanError::NonFinite {
                field: format!("terrain.heights_m[{k}]"),
                value: self.heights_m[k],
            });
        }
        Ok(())
    }

    /// World x of the last column (metres).
    pub fn max_x_m(&self) -> f64 {
        self.origin_x_m + (self.nx - 1) as f64 * self.spacing_m
    }

    /// World y of the last row (metres).
    pub fn max_y_m(&self) -> f64 {
        self.origin_y_m + (self.ny - 1) as f64 * self.spacing_m
    }

    /// Whether (x, y) lies on the grid (edges included).
    pub fn contains(&self, x_m: f64, y_m: f64) -> bool {
        x_m >= self.origin_x_m
            && x_m <= self.max_x_m()
            && y_m >= self.origin_y_m
            && y_m <= self.max_y_m()
    }

    /// Height of node (i, j). Panics if out of range (callers index within `nx`, `ny`).
    pub fn node(&self, i: usize, j: usize) -> f64 {
        self.heights_m[j * self.nx + i]
    }

    /// The cell holding world (x, y) and the fractional position in it: `(i, j, fu, fv)` with
    /// node (i, j) at its south-west corner and `fu`, `fv` in [0, 1]. `None` off the grid or
    /// for non-finite input; the north and east edges belong to the last cell.
    pub fn cell_at(&self, x_m: f64, y_m: f64) -> Option<(usize, usize, f64, f64)> {
        if !(x_m.is_finite() && y_m.is_finite() && self.contains(x_m, y_m)) {
            return None;
        }
        let u = (x_m - self.origin_x_m) / self.spacing_m;
        let v = (y_m - self.origin_y_m) / self.spacing_m;
        // Both are ≥ 0 and ≤ n − 1 here, so the casts and the clamped indices are in range.
        let i = (u.floor() as usize).min(self.nx - 2);
        let j = (v.floor() as usize).min(self.ny - 2);
        Some((i, j, u - i as f64, v - j as f64))
    }

    /// Bilinear terrain height at world (x, y) (metres), or `None` off the grid or for
    /// non-finite input.
    pub fn height_at(&self, x_m: f64, y_m: f64) -> Option<f64> {
        let (i, j, fu, fv) = self.cell_at(x_m, y_m)?;
        let h00 = self.node(i, j);
        let h10 = self.node(i + 1, j);
        let h01 = self.node(i, j + 1);
        let h11 = self.node(i + 1, j + 1);
        Some(
            h00 * (1.0 - fu) * (1.0 - fv)
                + h10 * fu * (1.0 - fv)
                + h01 * (1.0 - fu) * fv
                + h11 * fu * fv,
        )
    }

    /// Lowest and highest node heights (metres).
    pub fn height_range_m(&self) -> (f64, f64) {
        self.heights_m
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &h| {
                (lo.min(h), hi.max(h))
            })
    }
}

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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bilinear_reproduces_planes() {
        let hf =
            Heightfield::from_fn(-10.0, -5.0, 0.5, 41, 21, |x, y| 0.3 * x - 0.2 * y + 1.0).unwrap();
        for &(x, y) in &[(0.1, 0.2), (-10.0, -5.0), (10.0, 5.0), (3.33, -4.9)] {
            let h = hf.height_at(x, y).unwrap();
            assert!((h - (0.3 * x - 0.2 * y + 1.0)).abs() < 1e-12, "{x} {y} {h}");
        }
        assert!(hf.height_at(10.1, 0.0).is_none());
        assert!(hf.height_at(f64::NAN, 0.0).is_none());
    }

    #[test]
    fn rejects_bad_grids() {
        assert!(Heightfield::new(0.0, 0.0, 1.0, 2, 2, vec![0.0; 3]).is_err());
        assert!(Heightfield::new(0.0, 0.0, 0.0, 2, 2, vec![0.0; 4]).is_err());
        assert!(Heightfield::new(0.0, 0.0, 1.0, 2, 2, vec![0.0, f64::NAN, 0.0, 0.0]).is_err());
        assert!(Heightfield::new(0.0, 0.0, 1.0, 1, 2, vec![0.0; 2]).is_err());
    }
}
