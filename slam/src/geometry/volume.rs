//! Volume integrals of a closed triangulated surface by signed tetrahedra, shared by the mesh's
//! volume and centroid and the fragility analysis's mass properties.

use nalgebra::{Matrix3, Vector3};

/// Sums over the signed tetrahedra (reference, a, b, c) of a closed, outward-wound surface,
/// with every vertex given relative to the reference point. Units are those of the vertices:
/// metres give m³, m⁴ and m⁵. A surface that is not closed gives sums without meaning.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TetrahedronSums {
    /// Six times the enclosed volume: Σ a·(b × c).
    pub volume6: f64,
    /// Six times the first moment ∫ r dV: Σ det·(a + b + c)/4. The centroid is
    /// `reference + moment6 / volume6`.
    pub moment6: Vector3<f64>,
    /// The second moment ∫ r rᵀ dV about the reference point (not scaled by six).
    pub second: Matrix3<f64>,
}

/// Accumulates [`TetrahedronSums`] over `triangles`, each `[a, b, c]` relative to the
/// reference point. Taking the reference inside the surface (for example the centre of its
/// bounds) limits cancellation.
pub fn tetrahedron_sums(triangles: impl IntoIterator<Item = [Vector3<f64>; 3]>) -> TetrahedronSums {
    let mut sums = TetrahedronSums::default();
    for [a, b, c] in triangles {
        let det = a.dot(&b.cross(&c));
        let s = a + b + c;
        sums.volume6 += det;
        sums.moment6 += det * s / 4.0;
        // For a tetrahedron with one vertex at the origin,
        // ∫ r rᵀ dV = det/120 · (Σ vᵢvᵢᵀ + (Σ vᵢ)(Σ vᵢ)ᵀ).
        let outer = a * a.transpose() + b * b.transpose() + c * c.transpose() + s * s.transpose();
        sums.second += outer * (det / 120.0);
    }
    sums
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The 12 outward triangles of the box [0, x] × [0, y] × [0, z], relative to `reference`.
    fn box_triangles(size: Vector3<f64>, reference: Vector3<f64>) -> Vec<[Vector3<f64>; 3]> {
        let corner = |i: usize| {
            Vector3::new(
                if i & 1 == 1 { size.x } else { 0.0 },
                if i & 2 == 2 { size.y } else { 0.0 },
                if i & 4 == 4 { size.z } else { 0.0 },
            ) - reference
        };
        let quads = [
            [0, 2, 3, 1],
            [4, 5, 7, 6],
            [0, 1, 5, 4],
            [2, 6, 7, 3],
            [0, 4, 6, 2],
            [1, 3, 7, 5],
        ];
        quads
            .iter()
            .flat_map(|q| {
                [
                    [corner(q[0]), corner(q[1]), corner(q[2])],
                    [corner(q[0]), corner(q[2]), corner(q[3])],
                ]
            })
            .collect()
    }

    #[test]
    fn a_box_has_its_volume_centroid_and_second_moment() {
        let size = Vector3::new(2.0, 3.0, 4.0);
        let reference = Vector3::new(0.3, 0.2, 0.1);
        let sums = tetrahedron_sums(box_triangles(size, reference));
        assert!((sums.volume6 / 6.0 - 24.0).abs() < 1e-12);
        let centroid = reference + sums.moment6 / sums.volume6;
        assert!((centroid - size / 2.0).norm() < 1e-12);
        // About the centroid, ∫ x² dV = V·a²/12 for side a.
        let offset = sums.moment6 / sums.volume6;
        let central = sums.second - (sums.volume6 / 6.0) * offset * offset.transpose();
        assert!((central[(0, 0)] - 24.0 * 4.0 / 12.0).abs() < 1e-9);
        assert!((central[(2, 2)] - 24.0 * 16.0 / 12.0).abs() < 1e-9);
        assert!(central[(0, 1)].abs() < 1e-9);
    }
}
