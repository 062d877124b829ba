//! A regular grid of terrain heights (a DEM) with bilinear interpolation: the one terrain
//! type of the world builder, the renderer's terrain mesh, the planner and the clearance
//! checks. World ENU metres throughout.

use serde::{Deserialize, Serialize};

use crate::SlamError;

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
    ) -> Result<Self, SlamError> {
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
    ) -> Result<Self, SlamError> {
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
    ) -> Result<Self, SlamError> {
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
    pub fn validate(&self) -> Result<(), SlamError> {
        let invalid = |reason: String| Err(SlamError::InvalidHeightfield { reason });
        if !(self.origin_x_m.is_finite() && self.origin_y_m.is_finite()) {
            return invalid(format!(
                "origin ({}, {}) is not finite",
                self.origin_x_m, self.origin_y_m
            ));
        }
        if !(self.spacing_m.is_finite() && self.spacing_m > 0.0) {
            return invalid(format!(
                "spacing_m = {} must be finite and > 0",
                self.spacing_m
            ));
        }
        if self.nx < 2 || self.ny < 2 {
            return invalid(format!(
                "needs at least 2×2 nodes, got nx = {}, ny = {}",
                self.nx, self.ny
            ));
        }
        if Some(self.heights_m.len()) != self.nx.checked_mul(self.ny) {
            return invalid(format!(
                "heights_m has {} values, expected nx·ny = {}·{}",
                self.heights_m.len(),
                self.nx,
                self.ny
            ));
        }
        if let Some(k) = self.heights_m.iter().position(|h| !h.is_finite()) {
            return invalid(format!(
                "heights_m[{k}] = {} is not finite",
                self.heights_m[k]
            ));
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

    /// The (x, y) extent: `(min_x, min_y, max_x, max_y)`, metres.
    pub fn extent(&self) -> (f64, f64, f64, f64) {
        (
            self.origin_x_m,
            self.origin_y_m,
            self.max_x_m(),
            self.max_y_m(),
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
