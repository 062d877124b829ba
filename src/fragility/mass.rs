//! Volume, centre of mass and inertia tensor of a closed surface from signed tetrahedra.

use nalgebra::{Matrix3, Point3, Vector3};
use scarp_slam::TriangleMesh;
use scarp_slam::geometry::tetrahedron_sums;
use serde::{Deserialize, Serialize};

use super::FragilityError;
use super::topology::{Solid, prepare};

/// Volume integrals of a closed, outward-wound surface at unit density.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct VolumeIntegrals {
    /// Enclosed volume, m³.
    pub volume_m3: f64,
    /// Centroid of the enclosed volume, metres (frame of the input positions).
    pub centroid: Point3<f64>,
    /// Second moment ∫(r − c)(r − c)ᵀ dV about the centroid, m⁵.
    pub covariance: Matrix3<f64>,
}

/// Integrates volume, centroid and second moment over a closed surface. Tetrahedra are taken
/// about the centre of the bounds to limit cancellation.
///
/// # Errors
/// [`FragilityError::Degenerate`] when the surface is empty or encloses no positive volume.
pub(crate) fn integrate(solid: &Solid) -> Result<VolumeIntegrals, FragilityError> {
    let (lo, hi) = solid
        .bounds()
        .ok_or_else(|| FragilityError::Degenerate("volume of an empty surface".into()))?;
    let reference = nalgebra::center(&lo, &hi);
    let sums = tetrahedron_sums(
        solid
            .faces
            .iter()
            .map(|f| f.map(|v| solid.positions[v as usize] - reference)),
    );
    let volume6 = sums.volume6;
    let diagonal = (hi - lo).norm();
    if volume6.is_nan() || volume6 <= 1e-12 * diagonal.powi(3) {
        return Err(FragilityError::Degenerate(format!(
            "the closed surface encloses no positive volume ({} m³)",
            volume6 / 6.0
        )));
    }
    let volume = volume6 / 6.0;
    let offset = sums.moment6 / volume6;
    Ok(VolumeIntegrals {
        volume_m3: volume,
        centroid: reference + offset,
        covariance: sums.second - volume * offset * offset.transpose(),
    })
}

/// Mass properties of a uniform-density solid.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct MassProperties {
    /// Volume, m³.
    pub volume_m3: f64,
    /// Mass, kg.
    pub mass_kg: f64,
    /// Centre of mass, metres, in the frame of the input positions.
    pub center_of_mass: Point3<f64>,
    /// Inertia tensor about the centre of mass, kg·m², axes of the input frame.
    pub inertia_kg_m2: Matrix3<f64>,
}

impl MassProperties {
    /// From unit-density integrals and a density in kg/m³.
    pub(crate) fn from_integrals(v: &VolumeIntegrals, density_kg_m3: f64) -> Self {
        let c = v.covariance * density_kg_m3;
        Self {
            volume_m3: v.volume_m3,
            mass_kg: v.volume_m3 * density_kg_m3,
            center_of_mass: v.centroid,
            inertia_kg_m2: Matrix3::identity() * c.trace() - c,
        }
    }

    /// Moment of inertia about the axis through `point` along the unit vector `axis`, kg·m²
    /// (parallel-axis theorem).
    pub fn inertia_about_axis(&self, point: &Point3<f64>, axis: &Vector3<f64>) -> f64 {
        let d = self.center_of_mass - point;
        let perpendicular = d - axis * axis.dot(&d);
        axis.dot(&(self.inertia_kg_m2 * axis)) + self.mass_kg * perpendicular.norm_squared()
    }
}

/// Volume, mass, centre of mass and inertia tensor of a closed mesh at uniform density, from
/// signed tetrahedra. The mesh is checked and repaired as by [`analyze`](super::analyze)
/// (exact-position welding, index-degenerate faces dropped, inward shells flipped). Frame and
/// units are those of the mesh (metres).
///
/// # Errors
/// As the mesh checks of [`analyze`](super::analyze) (open, non-manifold, inconsistent winding,
/// NaN, empty, no volume), or [`FragilityError::InvalidConfig`] for a density that is not
/// positive and finite.
pub fn mass_properties(
    mesh: &TriangleMesh,
    density_kg_m3: f64,
) -> Result<MassProperties, FragilityError> {
    if !(density_kg_m3.is_finite() && density_kg_m3 > 0.0) {
        return Err(FragilityError::InvalidConfig {
            field: "density_kg_m3",
            value: density_kg_m3.to_string(),
            reason: "must be positive and finite",
        });
    }
    let (solid, _) = prepare(mesh, "rock", &nalgebra::Rotation3::identity())?;
    Ok(MassProperties::from_integrals(
        &integrate(&solid)?,
        density_kg_m3,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fragility::test_shapes::{cuboid_solid, icosphere, loft_solid, regular_ring};
    use nalgebra::{Isometry3, Translation3, UnitQuaternion};

    #[test]
    fn box_mass_properties_are_exact() {
        let mut solid = cuboid_solid([2.0, 3.0, 4.0]);
        let motion = Isometry3::from_parts(
            Translation3::new(5.0, -7.0, 3.0),
            UnitQuaternion::from_euler_angles(0.3, -0.2, 1.1),
        );
        for p in &mut solid.positions {
            *p = motion * *p;
        }
        let v = integrate(&solid).unwrap();
        assert!((v.volume_m3 - 24.0).abs() < 1e-9);
        assert!((v.centroid - motion * Point3::new(1.0, 1.5, 2.0)).norm() < 1e-9);
        let m = MassProperties::from_integrals(&v, 2.0);
        let r = motion.rotation.to_rotation_matrix();
        let expected_body =
            Matrix3::from_diagonal(&Vector3::new(9.0 + 16.0, 4.0 + 16.0, 4.0 + 9.0))
                * (48.0 / 12.0);
        let expected = r.matrix() * expected_body * r.matrix().transpose();
        assert!(
            (m.inertia_kg_m2 - expected).norm() < 1e-8,
            "{}",
            m.inertia_kg_m2
        );
    }

    #[test]
    fn sphere_within_a_tenth_of_a_percent() {
        // A fine icosphere; its volume converges to 4/3 π r³ from below.
        let r = 0.8;
        let mut solid = icosphere(5, r);
        for p in &mut solid.positions {
            p.coords += Vector3::new(1.0, 2.0, 3.0);
        }
        let v = integrate(&solid).unwrap();
        let exact = 4.0 / 3.0 * std::f64::consts::PI * r.powi(3);
        assert!(
            ((v.volume_m3 - exact) / exact).abs() < 1e-3,
            "{}",
            v.volume_m3
        );
        assert!((v.centroid - Point3::new(1.0, 2.0, 3.0)).norm() < 1e-3 * r);
        let m = MassProperties::from_integrals(&v, 1.0);
        let i_exact = 0.4 * exact * r * r;
        for k in 0..3 {
            assert!(((m.inertia_kg_m2[(k, k)] - i_exact) / i_exact).abs() < 3e-3);
        }
    }

    #[test]
    fn cylinder_volume_matches_its_polygon_prism() {
        let ring = regular_ring(64, 0.5, 0.0);
        let solid = loft_solid(&[(&ring, 0.0), (&ring, 2.0)]);
        let v = integrate(&solid).unwrap();
        let area = 0.5 * 64.0 * 0.25 * (std::f64::consts::TAU / 64.0).sin();
        assert!((v.volume_m3 - 2.0 * area).abs() < 1e-12);
        assert!((v.centroid - Point3::new(0.0, 0.0, 1.0)).norm() < 1e-12);
    }
}
