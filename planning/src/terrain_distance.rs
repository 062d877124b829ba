//! Exact Euclidean distance from a point to a triangulated heightfield, by branch and bound.
//!
//! Each grid cell is the two triangles (i, j)–(i+1, j)–(i+1, j+1) and
//! (i, j)–(i+1, j+1)–(i, j+1), the split the rendered terrain mesh uses. Cells and 8×8 blocks
//! of cells keep their lowest and highest node; their horizontal distance to the query and the
//! vertical gap to that height range bound the distance from below, so only the few cells that
//! could beat the best distance found so far are tested exactly. A vehicle 10 m above the
//! ground tests a handful of triangles instead of every triangle within 10 m.

use nalgebra::Point3;
use scarp_slam::geometry::closest_point_on_triangle;

use crate::terrain::Heightfield;

/// Cells per block side.
const BLOCK_CELLS: usize = 8;

/// A heightfield prepared for distance queries. World ENU metres throughout.
#[derive(Debug, Clone)]
pub struct TerrainDistance {
    grid: Heightfield,
    /// Lowest and highest node of each cell, row-major over `(nx − 1)·(ny − 1)` cells.
    cell_range_m: Vec<(f64, f64)>,
    /// Lowest and highest node of each block of cells, row-major.
    block_range_m: Vec<(f64, f64)>,
    blocks_x: usize,
    blocks_y: usize,
}

/// The smallest distance a point can have to anything inside the box
/// `[x0, x1] × [y0, y1] × [z_lo, z_hi]` (metres).
fn box_lower_bound_m(p: &Point3<f64>, x: (f64, f64), y: (f64, f64), z: (f64, f64)) -> f64 {
    let gap = |v: f64, (lo, hi): (f64, f64)| (lo - v).max(v - hi).max(0.0);
    let (dx, dy, dz) = (gap(p.x, x), gap(p.y, y), gap(p.z, z));
    (dx * dx + dy * dy + dz * dz).sqrt()
}

fn merge_range((lo_a, hi_a): (f64, f64), (lo_b, hi_b): (f64, f64)) -> (f64, f64) {
    (lo_a.min(lo_b), hi_a.max(hi_b))
}

impl TerrainDistance {
    /// Prepares `grid` (which must satisfy [`Heightfield::validate`]).
    pub fn new(grid: Heightfield) -> Self {
        let (cx, cy) = (grid.nx - 1, grid.ny - 1);
        let mut cell_range_m = Vec::with_capacity(cx * cy);
        for j in 0..cy {
            for i in 0..cx {
                let corners = [
                    grid.node(i, j),
                    grid.node(i + 1, j),
                    grid.node(i, j + 1),
                    grid.node(i + 1, j + 1),
                ];
                cell_range_m.push(
                    corners
                        .iter()
                        .fold((f64::INFINITY, f64::NEG_INFINITY), |r, &h| {
                            merge_range(r, (h, h))
                        }),
                );
            }
        }
        let (blocks_x, blocks_y) = (cx.div_ceil(BLOCK_CELLS), cy.div_ceil(BLOCK_CELLS));
        let mut block_range_m = vec![(f64::INFINITY, f64::NEG_INFINITY); blocks_x * blocks_y];
        for j in 0..cy {
            for i in 0..cx {
                let b = (j / BLOCK_CELLS) * blocks_x + i / BLOCK_CELLS;
                block_range_m[b] = merge_range(block_range_m[b], cell_range_m[j * cx + i]);
            }
        }
        Self {
            grid,
            cell_range_m,
            block_range_m,
            blocks_x,
            blocks_y,
        }
    }

    /// The grid this was built from.
    pub fn grid(&self) -> &Heightfield {
        &self.grid
    }

    fn node_point(&self, i: usize, j: usize) -> Point3<f64> {
        let g = &self.grid;
        Point3::new(
            g.origin_x_m + i as f64 * g.spacing_m,
            g.origin_y_m + j as f64 * g.spacing_m,
            g.node(i, j),
        )
    }

    /// Exact distance from `p` to the two triangles of cell (i, j).
    fn cell_distance_m(&self, p: &Point3<f64>, i: usize, j: usize) -> f64 {
        let a = self.node_point(i, j);
        let b = self.node_point(i + 1, j);
        let c = self.node_point(i + 1, j + 1);
        let d = self.node_point(i, j + 1);
        let first = (closest_point_on_triangle(p, &a, &b, &c) - p).norm();
        let second = (closest_point_on_triangle(p, &a, &c, &d) - p).norm();
        first.min(second)
    }

    /// The horizontal extent of cells `i0..i1` × `j0..j1` (metres).
    fn extent(&self, i0: usize, i1: usize, j0: usize, j1: usize) -> ((f64, f64), (f64, f64)) {
        let g = &self.grid;
        (
            (
                g.origin_x_m + i0 as f64 * g.spacing_m,
                g.origin_x_m + i1 as f64 * g.spacing_m,
            ),
            (
                g.origin_y_m + j0 as f64 * g.spacing_m,
                g.origin_y_m + j1 as f64 * g.spacing_m,
            ),
        )
    }

    /// The cell index range `[lo, hi)` along one axis whose cells can lie within `radius_m` of
    /// coordinate `v`.
    fn cell_span(
        v: f64,
        radius_m: f64,
        origin_m: f64,
        spacing_m: f64,
        cells: usize,
    ) -> (usize, usize) {
        let lo = ((v - radius_m - origin_m) / spacing_m).floor().max(0.0);
        let hi = ((v + radius_m - origin_m) / spacing_m).floor() + 1.0;
        let clamp = |x: f64| (x.max(0.0) as usize).min(cells);
        (clamp(lo), clamp(hi))
    }

    /// Unsigned distance from `p` to the triangulated surface (metres); `p` must be finite.
    /// Points off the grid measure to its nearest edge.
    pub fn distance_m(&self, p: &Point3<f64>) -> f64 {
        let g = &self.grid;
        let (cx, cy) = (g.nx - 1, g.ny - 1);
        // The cell under (or nearest to) p gives a first, usually tight, upper bound.
        let cell_of = |v: f64, origin: f64, cells: usize| {
            (((v - origin) / g.spacing_m).floor().max(0.0) as usize).min(cells - 1)
        };
        let (i_p, j_p) = (
            cell_of(p.x, g.origin_x_m, cx),
            cell_of(p.y, g.origin_y_m, cy),
        );
        let mut best = self.cell_distance_m(p, i_p, j_p);
        let block_m = g.spacing_m * BLOCK_CELLS as f64;
        let (bi0, bi1) = Self::cell_span(p.x, best, g.origin_x_m, block_m, self.blocks_x);
        let (bj0, bj1) = Self::cell_span(p.y, best, g.origin_y_m, block_m, self.blocks_y);
        for bj in bj0..bj1 {
            for bi in bi0..bi1 {
                let (i0, j0) = (bi * BLOCK_CELLS, bj * BLOCK_CELLS);
                let (i1, j1) = ((i0 + BLOCK_CELLS).min(cx), (j0 + BLOCK_CELLS).min(cy));
                let (x, y) = self.extent(i0, i1, j0, j1);
                let z = self.block_range_m[bj * self.blocks_x + bi];
                if box_lower_bound_m(p, x, y, z) >= best {
                    continue;
                }
                for j in j0..j1 {
                    for i in i0..i1 {
                        let (x, y) = self.extent(i, i + 1, j, j + 1);
                        let z = self.cell_range_m[j * cx + i];
                        if box_lower_bound_m(p, x, y, z) < best {
                            best = best.min(self.cell_distance_m(p, i, j));
                        }
                    }
                }
            }
        }
        best
    }

    /// Height of the triangulated surface at world (x, y) (metres), or `None` off the grid or
    /// for non-finite input. Matches [`Self::distance_m`]'s surface, which can differ from
    /// [`Heightfield::height_at`]'s bilinear patch inside a cell.
    pub fn surface_height_m(&self, x_m: f64, y_m: f64) -> Option<f64> {
        let g = &self.grid;
        let (i, j, fu, fv) = g.cell_at(x_m, y_m)?;
        let h00 = g.node(i, j);
        let h11 = g.node(i + 1, j + 1);
        // Below the diagonal (fu ≥ fv) the plane through (0,0), (1,0), (1,1); above it the
        // plane through (0,0), (1,1), (0,1).
        Some(if fu >= fv {
            let h10 = g.node(i + 1, j);
            h00 + (h10 - h00) * fu + (h11 - h10) * fv
        } else {
            let h01 = g.node(i, j + 1);
            h00 + (h11 - h01) * fu + (h01 - h00) * fv
        })
    }

    /// Signed distance: negative when `p` is under the surface. `p` must be finite.
    pub fn signed_distance_m(&self, p: &Point3<f64>) -> f64 {
        let d = self.distance_m(p);
        match self.surface_height_m(p.x, p.y) {
            Some(h) if p.z < h => -d,
            _ => d,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn brute_force_m(t: &TerrainDistance, p: &Point3<f64>) -> f64 {
        let g = t.grid();
        let mut best = f64::INFINITY;
        for j in 0..g.ny - 1 {
            for i in 0..g.nx - 1 {
                best = best.min(t.cell_distance_m(p, i, j));
            }
        }
        best
    }

    fn bumpy() -> Heightfield {
        Heightfield::from_fn(-10.0, 5.0, 0.5, 41, 37, |x, y| {
            2.0 * (0.3 * x).sin() * (0.2 * y).cos() + 0.1 * x
        })
        .unwrap()
    }

    #[test]
    fn a_point_above_a_flat_grid_is_its_height_away() {
        let t = TerrainDistance::new(Heightfield::flat(0.0, 0.0, 1.0, 30, 30, 2.0).unwrap());
        assert!((t.signed_distance_m(&Point3::new(12.3, 7.7, 12.0)) - 10.0).abs() < 1e-12);
        assert!((t.signed_distance_m(&Point3::new(12.3, 7.7, 1.5)) + 0.5).abs() < 1e-12);
        // Beyond the east edge, 3 m out and 4 m up: the edge is 5 m away.
        assert!((t.distance_m(&Point3::new(32.0, 10.0, 6.0)) - 5.0).abs() < 1e-12);
    }

    #[test]
    fn the_surface_height_is_planar_on_each_triangle() {
        let t = TerrainDistance::new(bumpy());
        let g = t.grid();
        for (i, j) in [(0, 0), (5, 7), (39, 35)] {
            let node = |a: usize, b: usize| {
                let p = t.node_point(a, b);
                (t.surface_height_m(p.x, p.y).unwrap() - p.z).abs()
            };
            assert!(node(i, j) < 1e-9 && node(i + 1, j + 1) < 1e-9);
            // The diagonal's midpoint is the mean of its two nodes.
            let mid =
                Point3::from((t.node_point(i, j).coords + t.node_point(i + 1, j + 1).coords) / 2.0);
            let h = t.surface_height_m(mid.x, mid.y).unwrap();
            assert!((h - mid.z).abs() < 1e-9, "{h} vs {}", mid.z);
        }
        assert_eq!(t.surface_height_m(g.origin_x_m - 1.0, g.origin_y_m), None);
    }

    proptest! {
        #[test]
        fn branch_and_bound_equals_brute_force(
            x in -15.0f64..15.0,
            y in 0.0f64..28.0,
            z in -6.0f64..25.0,
        ) {
            let t = TerrainDistance::new(bumpy());
            let p = Point3::new(x, y, z);
            let fast = t.distance_m(&p);
            let slow = brute_force_m(&t, &p);
            prop_assert!((fast - slow).abs() < 1e-12, "{fast} vs {slow} at {p:?}");
        }
    }
}
