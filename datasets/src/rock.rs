//! Rock geometry: procedural boulders, pedestals, and seating a rock on its pedestal through a
//! narrow, flat basal contact.

use nalgebra::{Point2, Point3, Vector3};
use scarp_slam::TriangleMesh;
use scarp_slam::geometry::{convex_hull_2d, polygon_signed_area};
use serde::{Deserialize, Serialize};

use crate::DatasetError;
use crate::noise::fbm_3d;

/// Parameters of a procedural boulder: a lumpy ellipsoid.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BoulderShape {
    /// Seed of the surface lumps.
    pub seed: u64,
    /// Semi-axes along x, y, z before scaling, metres. Default (0.8, 0.6, 0.7).
    pub radii_m: [f64; 3],
    /// Relative amplitude of the lumps, as a fraction of the radius. Default 0.12.
    pub roughness: f64,
    /// Icosphere subdivision level (3–6); level 5 has 20 480 triangles. Default 5.
    pub subdivisions: u32,
}

impl Default for BoulderShape {
    fn default() -> Self {
        Self {
            seed: 1,
            radii_m: [0.8, 0.6, 0.7],
            roughness: 0.12,
            subdivisions: 5,
        }
    }
}

/// Parameters of a pedestal: a tapered, slightly irregular rock column whose flat top carries the
/// rock.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PedestalShape {
    /// Height of the flat top above the terrain at the rock's position, metres. Default 1.0.
    pub height_m: f64,
    /// Radius at the foot, metres. Default 0.9.
    pub base_radius_m: f64,
    /// Radius of the flat top, metres. Default 0.35.
    pub top_radius_m: f64,
    /// How far the column reaches below the terrain, so it never floats on slopes, metres.
    /// Default 0.5.
    pub embed_m: f64,
}

impl Default for PedestalShape {
    fn default() -> Self {
        Self {
            height_m: 1.0,
            base_radius_m: 0.9,
            top_radius_m: 0.35,
            embed_m: 0.5,
        }
    }
}

/// The flat basal contact of a rock seated on a pedestal, in world coordinates.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Contact {
    /// Height of the contact plane (world z), metres.
    pub height_m: f64,
    /// Convex hull of the contact region in the contact plane (world x, y), counter-clockwise,
    /// metres.
    pub polygon_xy_m: Vec<[f64; 2]>,
    /// Area of the contact polygon, m².
    pub area_m2: f64,
}

impl BoulderShape {
    /// The boulder mesh, centred on its ellipsoid's centre, in metres.
    ///
    /// # Errors
    /// [`DatasetError::Invalid`] for non-positive radii, roughness outside [0, 0.4] (larger
    /// lumps could fold the surface) or a subdivision level outside 1–6.
    pub fn mesh(&self, key: &str) -> Result<TriangleMesh, DatasetError> {
        if !self.radii_m.iter().all(|&r| r > 0.0 && r.is_finite()) {
            return Err(DatasetError::invalid(
                format!("{key}.radii_m"),
                "radii must be positive",
            ));
        }
        if !(0.0..=0.4).contains(&self.roughness) {
            return Err(DatasetError::invalid(
                format!("{key}.roughness"),
                "must lie in [0, 0.4]",
            ));
        }
        if !(1..=6).contains(&self.subdivisions) {
            return Err(DatasetError::invalid(
                format!("{key}.subdivisions"),
                "must lie in 1..=6",
            ));
        }
        let mut mesh = TriangleMesh::icosphere(self.subdivisions);
        let radii = Vector3::from(self.radii_m);
        for p in &mut mesh.positions {
            let d = p.coords.cast::<f64>();
            let lumps = 0.7 * fbm_3d(self.seed, d.x, d.y, d.z, 0.9, 4)
                + 0.3 * fbm_3d(self.seed ^ 0x5eed, d.x, d.y, d.z, 0.25, 3);
            let scale = 1.0 + self.roughness * f64::from(lumps);
            *p = Point3::from(d.component_mul(&radii) * scale).cast();
        }
        Ok(mesh)
    }
}

impl PedestalShape {
    /// Checks the dimensions.
    ///
    /// # Errors
    /// [`DatasetError::Invalid`] naming the field.
    pub fn validate(&self, key: &str) -> Result<(), DatasetError> {
        for (field, value) in [
            ("height_m", self.height_m),
            ("base_radius_m", self.base_radius_m),
            ("top_radius_m", self.top_radius_m),
        ] {
            if !(value > 0.0 && value.is_finite()) {
                return Err(DatasetError::invalid(
                    format!("{key}.{field}"),
                    "must be positive",
                ));
            }
        }
        if !(self.embed_m >= 0.0) {
            return Err(DatasetError::invalid(
                format!("{key}.embed_m"),
                "must be ≥ 0",
            ));
        }
        Ok(())
    }

    /// The pedestal as a closed mesh: a column from `foot_z_m − embed_m` up to a flat top at
    /// `top_z_m`, centred on (x, y), with an irregular (seeded) outline. World metres.
    pub fn mesh(
        &self,
        centre_xy_m: [f64; 2],
        foot_z_m: f64,
        top_z_m: f64,
        seed: u64,
    ) -> TriangleMesh {
        const SEGMENTS: usize = 40;
        const RINGS: usize = 12;
        let bottom_z = foot_z_m - self.embed_m;
        let mut mesh = TriangleMesh::default();
        for ring in 0..=RINGS {
            let s = ring as f64 / RINGS as f64;
            let z = bottom_z + s * (top_z_m - bottom_z);
            // A concave profile: the column narrows quickly and then stays slim up to the top.
            let radius =
                self.top_radius_m + (self.base_radius_m - self.top_radius_m) * (1.0 - s).powi(2);
            for k in 0..SEGMENTS {
                let theta = k as f64 / SEGMENTS as f64 * std::f64::consts::TAU;
                let (dx, dy) = (theta.cos(), theta.sin());
                // Irregularity fades out at the top so the top stays a clean disc.
                let wobble =
                    1.0 + 0.12 * (1.0 - s) * f64::from(fbm_3d(seed, 2.0 * dx, 2.0 * dy, z, 0.8, 3));
                mesh.positions.push(Point3::new(
                    (centre_xy_m[0] + radius * wobble * dx) as f32,
                    (centre_xy_m[1] + radius * wobble * dy) as f32,
                    z as f32,
                ));
            }
        }
        let idx = |ring: usize, k: usize| (ring * SEGMENTS + k % SEGMENTS) as u32;
        for ring in 0..RINGS {
            for k in 0..SEGMENTS {
                let (a, b) = (idx(ring, k), idx(ring, k + 1));
                let (c, d) = (idx(ring + 1, k), idx(ring + 1, k + 1));
                mesh.faces.push([a, b, d]);
                mesh.faces.push([a, d, c]);
            }
        }
        // Caps: fans around centre vertices.
        let top_centre = mesh.positions.len() as u32;
        mesh.positions.push(Point3::new(
            centre_xy_m[0] as f32,
            centre_xy_m[1] as f32,
            top_z_m as f32,
        ));
        let bottom_centre = top_centre + 1;
        mesh.positions.push(Point3::new(
            centre_xy_m[0] as f32,
            centre_xy_m[1] as f32,
            bottom_z as f32,
        ));
        for k in 0..SEGMENTS {
            mesh.faces
                .push([top_centre, idx(RINGS, k), idx(RINGS, k + 1)]);
            mesh.faces.push([bottom_centre, idx(0, k + 1), idx(0, k)]);
        }
        mesh
    }
}

/// Signed distance of `p` inside a counter-clockwise convex polygon (negative outside).
fn inside_margin(polygon: &[Point2<f64>], p: &Point2<f64>) -> f64 {
    (0..polygon.len())
        .map(|i| {
            let (a, b) = (polygon[i], polygon[(i + 1) % polygon.len()]);
            let edge = b - a;
            (edge.x * (p.y - a.y) - edge.y * (p.x - a.x)) / edge.norm().max(1e-12)
        })
        .fold(f64::INFINITY, f64::min)
}

/// Seats a rock on a flat contact, keeping its pose: the bottom is cut flat at the lowest height
/// where (1) the flattened region's radius reaches `contact_radius_m` and (2) the centre of mass
/// stands inside the contact polygon by `stability_margin_m`, so the rock is statically stable.
/// The mesh is then moved so that the contact's centre sits at the origin with the contact at
/// z = 0. Returns the moved mesh and its contact (in that local frame).
///
/// # Errors
/// [`DatasetError::Invalid`] when the mesh is empty or encloses no volume, the radius is not
/// positive, or no cut in the lower 45% of the rock puts the centre of mass over the contact
/// (the rock cannot stand in this pose).
pub fn seat_on_flat_contact(
    mut mesh: TriangleMesh,
    contact_radius_m: f64,
    stability_margin_m: f64,
    key: &str,
) -> Result<(TriangleMesh, Contact), DatasetError> {
    let (lo, hi) = mesh
        .bounds()
        .ok_or_else(|| DatasetError::invalid(key, "rock mesh is empty"))?;
    if !(contact_radius_m > 0.0) {
        return Err(DatasetError::invalid(
            format!("{key}.contact_radius_m"),
            "must be positive",
        ));
    }
    let z_min = f64::from(lo.z);
    let height = f64::from(hi.z - lo.z);
    let hull_below = |cut: f64| -> Vec<Point2<f64>> {
        let below: Vec<Point2<f64>> = mesh
            .positions
            .iter()
            .filter(|p| f64::from(p.z) <= cut)
            .map(|p| Point2::new(f64::from(p.x), f64::from(p.y)))
            .collect();
        convex_hull_2d(&below)
    };
    let radius_of = |hull: &[Point2<f64>]| -> f64 {
        if hull.len() < 3 {
            return 0.0;
        }
        let centre = hull
            .iter()
            .fold(Point2::origin(), |c, p| c + p.coords / hull.len() as f64);
        hull.iter().map(|p| (p - centre).norm()).fold(0.0, f64::max)
    };
    // The centre of mass of the rock as flattened at `cut` (the cut removes volume).
    let flattened_com_xy = |cut: f32| -> Option<Point2<f64>> {
        let mut flat = mesh.clone();
        for p in &mut flat.positions {
            p.z = p.z.max(cut);
        }
        let com = flat.volume_properties().ok()?.centroid;
        Some(Point2::new(com.x, com.y))
    };
    let acceptable = |depth: f64| {
        let hull = hull_below(z_min + depth);
        hull.len() >= 3
            && radius_of(&hull) >= contact_radius_m
            && flattened_com_xy((z_min + depth) as f32)
                .is_some_and(|com| inside_margin(&hull, &com) >= stability_margin_m)
    };
    // Both conditions grow with the cut depth: bisect for the shallowest acceptable cut.
    let max_depth = height * 0.45;
    if !acceptable(max_depth) {
        return Err(DatasetError::invalid(
            format!("{key}.shape"),
            "the rock cannot stand in this pose: its centre of mass is not over any flat contact in its lower 45%; rotate it",
        ));
    }
    let (mut shallow, mut deep) = (0.0, max_depth);
    for _ in 0..40 {
        let mid = 0.5 * (shallow + deep);
        if acceptable(mid) {
            deep = mid;
        } else {
            shallow = mid;
        }
    }
    let cut = z_min + deep;
    let hull = hull_below(cut);
    let area = polygon_signed_area(&hull);
    let centre = hull
        .iter()
        .fold(Point2::origin(), |c, p| c + p.coords / hull.len() as f64);
    for p in &mut mesh.positions {
        let z = f64::from(p.z).max(cut);
        *p = Point3::new(
            (f64::from(p.x) - centre.x) as f32,
            (f64::from(p.y) - centre.y) as f32,
            (z - cut) as f32,
        );
    }
    let contact = Contact {
        height_m: 0.0,
        polygon_xy_m: hull
            .iter()
            .map(|p| [p.x - centre.x, p.y - centre.y])
            .collect(),
        area_m2: area,
    };
    Ok((mesh, contact))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn boulder_keeps_positive_volume() {
        let m = BoulderShape::default().mesh("rock").unwrap();
        let v = m.volume_properties().unwrap();
        let ellipsoid = 4.0 / 3.0 * std::f64::consts::PI * 0.8 * 0.6 * 0.7;
        assert!(
            (v.volume_m3 / ellipsoid - 1.0).abs() < 0.25,
            "{}",
            v.volume_m3
        );
        assert!(
            BoulderShape {
                roughness: 0.9,
                ..Default::default()
            }
            .mesh("rock")
            .is_err()
        );
    }

    #[test]
    fn seated_rock_has_the_requested_narrow_contact() {
        let m = BoulderShape::default().mesh("rock").unwrap();
        let (seated, contact) = seat_on_flat_contact(m, 0.15, 0.03, "rock").unwrap();
        let (lo, _) = seated.bounds().unwrap();
        assert!(lo.z.abs() < 1e-6);
        // A disc of radius ~0.15 m: the hull area is within a factor of that disc's.
        let disc = std::f64::consts::PI * 0.15 * 0.15;
        assert!(
            contact.area_m2 > 0.3 * disc && contact.area_m2 < 1.3 * disc,
            "{}",
            contact.area_m2
        );
        assert!(seated.volume_properties().unwrap().volume_m3 > 0.0);
    }

    #[test]
    fn pedestal_is_closed_with_a_flat_top() {
        let p = PedestalShape::default();
        let m = p.mesh([3.0, 4.0], 10.0, 11.0, 9);
        m.validate().unwrap();
        let v = m.volume_properties().unwrap();
        assert!(v.volume_m3 > 0.0);
        let (lo, hi) = m.bounds().unwrap();
        assert!((hi.z - 11.0).abs() < 1e-5 && (lo.z - 9.5).abs() < 1e-5);
    }
}
