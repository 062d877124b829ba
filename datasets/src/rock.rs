//! Rock geometry: procedural boulders, pedestals, and seating a rock on its pedestal through a
//! narrow, flat basal contact.

use nalgebra::{Point2, Point3, Vector3};
use scarp_slam::TriangleMesh;
use scarp_slam::geometry::{convex_hull_2d, polygon_centroid, polygon_signed_area};
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

/// Parameters of a procedural block: a joint-bounded stone, a rounded box (superellipsoid) with
/// lumps, for slabs, columns and squat blocks. Its extents are set by `size_m`; the world file's
/// `height_m` then scales the whole block uniformly to its height.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BlockShape {
    /// Seed of the surface lumps.
    pub seed: u64,
    /// Full extents along x, y, z before scaling, metres (only their ratios matter once the
    /// rock is scaled to its height). Default (1.0, 0.8, 0.7).
    pub size_m: [f64; 3],
    /// Superellipsoid exponent, in [2, 12]: 2 is an ellipsoid, 4 a block with well-worn edges,
    /// 8 and above a block with sharp edges. Default 4.
    pub squareness: f64,
    /// Relative amplitude of the lumps, as a fraction of the local radius, in [0, 0.3].
    /// Default 0.08.
    pub roughness: f64,
    /// Number of flat fracture facets (0–32): planes in seeded directions that shave the
    /// block, as joints and spalls do. Default 12.
    pub facets: u32,
    /// Greatest depth of a facet, as a fraction of the block's reach in its direction, in
    /// [0, 0.3]; each facet cuts between half and all of it. Default 0.2.
    pub facet_depth: f64,
    /// Icosphere subdivision level (3–6) of the underlying sphere. Default 5 (20 480
    /// triangles).
    pub subdivisions: u32,
}

impl Default for BlockShape {
    fn default() -> Self {
        Self {
            seed: 1,
            size_m: [1.0, 0.8, 0.7],
            squareness: 4.0,
            roughness: 0.08,
            facets: 12,
            facet_depth: 0.2,
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
    /// A boulder instead of the column: two boulders touching at a small contact. The boulder
    /// (its radii in metres, not scaled) has its top cut flat at the shallowest depth where the
    /// flat top holds a disc of `top_radius_m` about the pedestal's axis, and it is set with
    /// that top `height_m` above the terrain; it must reach `embed_m` below the terrain.
    /// `base_radius_m` is unused. Default none (the column).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub boulder: Option<BoulderShape>,
}

impl Default for PedestalShape {
    fn default() -> Self {
        Self {
            height_m: 1.0,
            base_radius_m: 0.9,
            top_radius_m: 0.35,
            embed_m: 0.5,
            boulder: None,
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

impl BlockShape {
    /// The block mesh, centred on its superellipsoid's centre, in metres: closed, wound
    /// outwards, with the icosphere's vertex density (level 5: 10 242 vertices). Each unit
    /// direction d of the icosphere is pushed onto the superellipsoid
    /// |x/a|ⁿ + |y/b|ⁿ + |z/c|ⁿ = 1 (a, b, c half the extents, n the squareness), then moved
    /// along d by the lumps; a seeded taper of up to ±12% keeps opposite faces from being
    /// parallel, as they seldom are in joint-bounded stone, and the facets shave it. Every
    /// step moves a vertex along its own direction from the centre, so the surface stays a
    /// closed radial graph: it cannot fold.
    ///
    /// # Errors
    /// [`DatasetError::Invalid`] naming the field for non-positive extents, squareness outside
    /// [2, 12], roughness outside [0, 0.3], more than 32 facets, a facet depth outside
    /// [0, 0.3] or a subdivision level outside 3–6.
    pub fn mesh(&self, key: &str) -> Result<TriangleMesh, DatasetError> {
        if !self.size_m.iter().all(|&r| r > 0.0 && r.is_finite()) {
            return Err(DatasetError::invalid(
                format!("{key}.size_m"),
                "extents must be positive",
            ));
        }
        if !(2.0..=12.0).contains(&self.squareness) {
            return Err(DatasetError::invalid(
                format!("{key}.squareness"),
                "must lie in [2, 12]",
            ));
        }
        if !(0.0..=0.3).contains(&self.roughness) {
            return Err(DatasetError::invalid(
                format!("{key}.roughness"),
                "must lie in [0, 0.3]",
            ));
        }
        if self.facets > 32 {
            return Err(DatasetError::invalid(
                format!("{key}.facets"),
                "must be at most 32",
            ));
        }
        if !(0.0..=0.3).contains(&self.facet_depth) {
            return Err(DatasetError::invalid(
                format!("{key}.facet_depth"),
                "must lie in [0, 0.3]",
            ));
        }
        if !(3..=6).contains(&self.subdivisions) {
            return Err(DatasetError::invalid(
                format!("{key}.subdivisions"),
                "must lie in 3..=6",
            ));
        }
        let half = Vector3::from(self.size_m) / 2.0;
        // Lumps are laid out on the surface in units of the mean half-extent, so a slab's lumps
        // are as large as a cube's of the same size.
        let unit = half.mean();
        let n = self.squareness;
        // Uniform in [0, 1) from the seed, stream `index`.
        let uniform = |index: u64| {
            (crate::noise::derive_seed(self.seed, index) >> 11) as f64 / (1u64 << 53) as f64
        };
        let (taper_x, taper_y) = (
            0.12 * (2.0 * uniform(1) - 1.0),
            0.12 * (2.0 * uniform(2) - 1.0),
        );
        let mut mesh = TriangleMesh::icosphere(self.subdivisions);
        for p in &mut mesh.positions {
            let d = p.coords.cast::<f64>();
            let radius = (0..3)
                .map(|i| (d[i] / half[i]).abs().powf(n))
                .sum::<f64>()
                .powf(-1.0 / n);
            let q = d * radius / unit;
            let lumps = 0.7 * fbm_3d(self.seed, q.x, q.y, q.z, 0.9, 4)
                + 0.3 * fbm_3d(self.seed ^ 0x5eed, q.x, q.y, q.z, 0.25, 3);
            let mut r = d * radius * (1.0 + self.roughness * f64::from(lumps));
            let s = r.z / half.z;
            r.x *= 1.0 + taper_x * s;
            r.y *= 1.0 + taper_y * s;
            *p = Point3::from(r).cast();
        }
        for facet in 0..u64::from(self.facets) {
            // A uniform direction on the sphere, and how deep its plane cuts.
            let z = 2.0 * uniform(16 + 3 * facet) - 1.0;
            let azimuth = std::f64::consts::TAU * uniform(17 + 3 * facet);
            let rho = (1.0 - z * z).max(0.0).sqrt();
            let normal = Vector3::new(rho * azimuth.cos(), rho * azimuth.sin(), z);
            let depth = self.facet_depth * (0.5 + 0.5 * uniform(18 + 3 * facet));
            let reach = mesh
                .positions
                .iter()
                .map(|p| p.coords.cast::<f64>().dot(&normal))
                .fold(0.0, f64::max);
            let plane = reach * (1.0 - depth);
            for p in &mut mesh.positions {
                let v = p.coords.cast::<f64>();
                let along = v.dot(&normal);
                if along > plane {
                    // Pull the vertex in along its own ray onto the plane.
                    *p = Point3::from(v * (plane / along)).cast();
                }
            }
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

    /// How far the pedestal reaches horizontally from its axis, metres: the column's foot
    /// radius, or the boulder's largest horizontal radius with its lumps. The terrain under
    /// this circle sets the pedestal's foot.
    pub fn footprint_radius_m(&self) -> f64 {
        match &self.boulder {
            Some(b) => b.radii_m[0].max(b.radii_m[1]) * (1.0 + b.roughness),
            None => self.base_radius_m,
        }
    }

    /// The pedestal as a closed mesh in world metres, flat top at `top_z_m` centred on
    /// `centre_xy_m`: the column of [`Self::mesh`], or the boulder of `boulder` with its top cut
    /// flat (see the field's docs). `foot_z_m` is the lowest terrain under the footprint.
    ///
    /// # Errors
    /// [`DatasetError::Invalid`] naming the key when the boulder is invalid, its top cannot be
    /// cut flat wide enough in its upper half, or it does not reach `embed_m` below
    /// `foot_z_m`.
    pub fn build(
        &self,
        key: &str,
        centre_xy_m: [f64; 2],
        foot_z_m: f64,
        top_z_m: f64,
        seed: u64,
    ) -> Result<TriangleMesh, DatasetError> {
        let Some(boulder) = &self.boulder else {
            return Ok(self.mesh(centre_xy_m, foot_z_m, top_z_m, seed));
        };
        let mut mesh = boulder.mesh(&format!("{key}.boulder"))?;
        let (lo, hi) = mesh
            .bounds()
            .ok_or_else(|| DatasetError::invalid(format!("{key}.boulder"), "empty mesh"))?;
        let (z_min, z_max) = (f64::from(lo.z), f64::from(hi.z));
        let hull_above = |cut: f64| -> Vec<Point2<f64>> {
            let above: Vec<Point2<f64>> = mesh
                .positions
                .iter()
                .filter(|p| f64::from(p.z) >= cut)
                .map(|p| Point2::new(f64::from(p.x), f64::from(p.y)))
                .collect();
            convex_hull_2d(&above)
        };
        let holds_top = |depth: f64| {
            let hull = hull_above(z_max - depth);
            polygon_centroid(&hull).is_some_and(|c| inside_margin(&hull, &c) >= self.top_radius_m)
        };
        // The flat top widens with the cut depth: bisect for the shallowest cut that holds it.
        let max_depth = 0.5 * (z_max - z_min);
        if !holds_top(max_depth) {
            return Err(DatasetError::invalid(
                format!("{key}.top_radius_m"),
                format!(
                    "no flat cut through the boulder's upper half holds a disc of {} m; widen the boulder or narrow the top",
                    self.top_radius_m
                ),
            ));
        }
        let (mut shallow, mut deep) = (0.0, max_depth);
        for _ in 0..40 {
            let mid = 0.5 * (shallow + deep);
            if holds_top(mid) {
                deep = mid;
            } else {
                shallow = mid;
            }
        }
        let cut = z_max - deep;
        // Invariant: `holds_top(deep)` is true, so the hull has an area centroid.
        let centre = polygon_centroid(&hull_above(cut)).unwrap_or_else(Point2::origin);
        let lift = top_z_m - cut;
        let bottom_z = z_min + lift;
        if bottom_z > foot_z_m - self.embed_m {
            return Err(DatasetError::invalid(
                format!("{key}.boulder.radii_m"),
                format!(
                    "the boulder reaches down to {bottom_z:.2} m, above the terrain's {foot_z_m:.2} m less embed_m {} m; make it taller or the pedestal lower",
                    self.embed_m
                ),
            ));
        }
        for p in &mut mesh.positions {
            let z = f64::from(p.z).min(cut);
            *p = Point3::new(
                (f64::from(p.x) - centre.x + centre_xy_m[0]) as f32,
                (f64::from(p.y) - centre.y + centre_xy_m[1]) as f32,
                (z + lift) as f32,
            );
        }
        Ok(mesh)
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

/// Mirrors a mesh across its own x–z plane (y → −y) and reverses every face's winding, so a
/// closed mesh stays wound outwards (positive volume) and its centroid is mirrored too.
/// Normals, when present, are mirrored with it.
pub fn mirror_y(mesh: &mut TriangleMesh) {
    for p in &mut mesh.positions {
        p.y = -p.y;
    }
    for n in &mut mesh.normals {
        n.y = -n.y;
    }
    for f in &mut mesh.faces {
        f.swap(1, 2);
    }
}

/// Splits every triangle into four at its edge midpoints, `levels` times, without moving any
/// point: the same surface with 4^levels as many triangles. Midpoints are shared between the
/// two faces of an edge, so a closed mesh stays closed. Colours and normals are dropped.
pub fn subdivide_flat(mesh: &TriangleMesh, levels: u32) -> TriangleMesh {
    mesh.subdivided(levels, nalgebra::center)
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

    /// Every directed edge has its reverse exactly once: closed and consistently wound.
    fn is_closed(mesh: &TriangleMesh) -> bool {
        let mut edges = std::collections::HashMap::new();
        for f in &mesh.faces {
            for (u, v) in [(f[0], f[1]), (f[1], f[2]), (f[2], f[0])] {
                *edges.entry((u, v)).or_insert(0) += 1;
            }
        }
        edges
            .iter()
            .all(|(&(u, v), &n)| n == 1 && edges.get(&(v, u)) == Some(&1))
    }

    #[test]
    fn block_is_closed_lumpy_and_about_its_size() {
        let shape = BlockShape {
            size_m: [1.6, 0.4, 1.0],
            ..Default::default()
        };
        let m = shape.mesh("rock").unwrap();
        m.validate().unwrap();
        assert!(is_closed(&m));
        assert_eq!(m.vertex_count(), TriangleMesh::icosphere(5).vertex_count());
        let v = m.volume_properties().unwrap();
        // Fuller than the inscribed ellipsoid, emptier than the box.
        let ellipsoid = std::f64::consts::PI / 6.0 * 1.6 * 0.4 * 1.0;
        assert!(
            v.volume_m3 > ellipsoid && v.volume_m3 < 1.6 * 0.4 * 1.0,
            "{}",
            v.volume_m3
        );
        let (lo, hi) = m.bounds().unwrap();
        for (i, size) in shape.size_m.iter().enumerate() {
            let extent = f64::from(hi[i] - lo[i]);
            assert!((extent / size - 1.0).abs() < 0.3, "axis {i}: {extent}");
        }
        // The facets leave flat patches: many vertices share a plane, unlike a smooth block.
        let smooth = BlockShape {
            facets: 0,
            ..shape.clone()
        }
        .mesh("rock")
        .unwrap();
        assert_ne!(smooth.positions, m.positions);
        // Seeds matter, and bad values name their key.
        let other = BlockShape {
            seed: 2,
            ..shape.clone()
        };
        assert_ne!(other.mesh("rock").unwrap().positions, m.positions);
        for (bad, key) in [
            (
                BlockShape {
                    size_m: [1.0, 0.0, 1.0],
                    ..Default::default()
                },
                "rock.size_m",
            ),
            (
                BlockShape {
                    roughness: 0.5,
                    ..Default::default()
                },
                "rock.roughness",
            ),
            (
                BlockShape {
                    facets: 33,
                    ..Default::default()
                },
                "rock.facets",
            ),
            (
                BlockShape {
                    subdivisions: 2,
                    ..Default::default()
                },
                "rock.subdivisions",
            ),
        ] {
            let message = bad.mesh("rock").unwrap_err().to_string();
            assert!(message.contains(key), "{message}");
        }
    }

    #[test]
    fn flat_subdivision_keeps_the_surface_closed() {
        let cube = TriangleMesh::cuboid(Point3::new(-1.0, 0.0, 2.0), Point3::new(1.0, 3.0, 2.5));
        let fine = subdivide_flat(&cube, 2);
        assert_eq!(fine.face_count(), 16 * cube.face_count());
        assert!(is_closed(&fine));
        let (a, b) = (
            cube.volume_properties().unwrap(),
            fine.volume_properties().unwrap(),
        );
        assert!((a.volume_m3 - b.volume_m3).abs() < 1e-9);
        assert!((a.centroid - b.centroid).norm() < 1e-6);
        assert_eq!(cube.bounds(), fine.bounds());
    }

    #[test]
    fn mirroring_keeps_the_volume_positive_and_mirrors_the_centroid() {
        let mut m = BoulderShape {
            subdivisions: 3,
            ..Default::default()
        }
        .mesh("rock")
        .unwrap();
        m.transform(&nalgebra::Isometry3::translation(0.3, 0.7, -0.2));
        let before = m.volume_properties().unwrap();
        mirror_y(&mut m);
        let after = m.volume_properties().unwrap();
        assert!(is_closed(&m));
        assert!(after.volume_m3 > 0.0);
        assert!((after.volume_m3 - before.volume_m3).abs() < 1e-9);
        let expected = Point3::new(before.centroid.x, -before.centroid.y, before.centroid.z);
        assert!((after.centroid - expected).norm() < 1e-6);
    }

    #[test]
    fn boulder_pedestal_has_a_flat_top_holding_its_disc() {
        let pedestal = PedestalShape {
            height_m: 0.8,
            top_radius_m: 0.3,
            embed_m: 0.3,
            boulder: Some(BoulderShape {
                seed: 4,
                radii_m: [1.0, 0.9, 0.8],
                subdivisions: 4,
                ..Default::default()
            }),
            ..Default::default()
        };
        let m = pedestal.build("p", [5.0, -3.0], 10.0, 10.8, 1).unwrap();
        assert!(is_closed(&m));
        assert!(m.volume_properties().unwrap().volume_m3 > 0.0);
        let (lo, hi) = m.bounds().unwrap();
        assert!((hi.z - 10.8).abs() < 1e-5);
        assert!(f64::from(lo.z) <= 10.0 - 0.3);
        // The flat top holds the disc of top_radius_m about the axis.
        let top: Vec<Point2<f64>> = m
            .positions
            .iter()
            .filter(|p| (p.z - hi.z).abs() < 1e-6)
            .map(|p| Point2::new(f64::from(p.x), f64::from(p.y)))
            .collect();
        let hull = convex_hull_2d(&top);
        assert!(inside_margin(&hull, &Point2::new(5.0, -3.0)) >= 0.3 - 1e-4);
        // Too high a top for the boulder to reach the ground is an error naming the radii.
        let message = pedestal
            .build("p", [5.0, -3.0], 10.0, 12.5, 1)
            .unwrap_err()
            .to_string();
        assert!(message.contains("p.boulder.radii_m"), "{message}");
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
