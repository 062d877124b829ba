//! Indexed triangle meshes.

use std::collections::HashMap;

use nalgebra::{Isometry3, Point3, Vector3};

use crate::SlamError;

/// An indexed triangle mesh. Faces are counter-clockwise seen from outside, so face normals
/// ((b − a) × (c − a)) point outwards. The frame of the positions is the owner's to state
/// (world ENU metres unless a function says otherwise).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TriangleMesh {
    /// Vertex positions, metres.
    pub positions: Vec<Point3<f32>>,
    /// Unit vertex normals, empty or one per vertex.
    pub normals: Vec<Vector3<f32>>,
    /// 8-bit sRGB vertex colours, empty or one per vertex.
    pub colors: Vec<[u8; 3]>,
    /// Triangles as vertex indices.
    pub faces: Vec<[u32; 3]>,
}

/// Volume and centre of mass of a closed mesh, from signed tetrahedra (uniform density).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VolumeProperties {
    /// Enclosed volume, m³ (negative when faces wind inwards).
    pub volume_m3: f64,
    /// Centre of the enclosed volume, metres.
    pub centroid: Point3<f64>,
}

pub(crate) fn check_attributes(
    positions: &[Point3<f32>],
    normals: &[Vector3<f32>],
    colors: &[[u8; 3]],
) -> Result<(), SlamError> {
    let n = positions.len();
    if !normals.is_empty() && normals.len() != n {
        return Err(SlamError::AttributeLength {
            attribute: "normals",
            len: normals.len(),
            vertex_count: n,
        });
    }
    if !colors.is_empty() && colors.len() != n {
        return Err(SlamError::AttributeLength {
            attribute: "colors",
            len: colors.len(),
            vertex_count: n,
        });
    }
    if let Some(i) = positions
        .iter()
        .position(|p| !p.coords.iter().all(|c| c.is_finite()))
    {
        return Err(SlamError::NotFinite {
            what: format!("vertex {i}"),
        });
    }
    Ok(())
}

pub(crate) fn transform_points(
    positions: &mut [Point3<f32>],
    normals: &mut [Vector3<f32>],
    b_from_a: &Isometry3<f64>,
) {
    let b_from_a: Isometry3<f32> = b_from_a.cast();
    for p in positions.iter_mut() {
        *p = b_from_a * *p;
    }
    for n in normals.iter_mut() {
        *n = b_from_a.rotation * *n;
    }
}

impl TriangleMesh {
    /// A mesh of positions and faces, checked with [`Self::validate`].
    ///
    /// # Errors
    /// As [`Self::validate`].
    pub fn new(positions: Vec<Point3<f32>>, faces: Vec<[u32; 3]>) -> Result<Self, SlamError> {
        let mesh = Self {
            positions,
            faces,
            ..Self::default()
        };
        mesh.validate()?;
        Ok(mesh)
    }

    /// The closed box between two corners (metres), wound outwards: 8 vertices, 12 triangles.
    pub fn cuboid(min: Point3<f32>, max: Point3<f32>) -> Self {
        let positions = (0..8)
            .map(|i| {
                Point3::new(
                    if i & 1 == 0 { min.x } else { max.x },
                    if i & 2 == 0 { min.y } else { max.y },
                    if i & 4 == 0 { min.z } else { max.z },
                )
            })
            .collect();
        let faces = vec![
            [0, 2, 1],
            [1, 2, 3], // −z
            [4, 5, 6],
            [5, 7, 6], // +z
            [0, 1, 4],
            [1, 5, 4], // −y
            [2, 6, 3],
            [3, 6, 7], // +y
            [0, 4, 2],
            [2, 4, 6], // −x
            [1, 3, 5],
            [3, 7, 5], // +x
        ];
        Self {
            positions,
            faces,
            ..Self::default()
        }
    }

    /// A unit-radius icosphere about the origin, wound outwards: the icosahedron subdivided
    /// `level` times (20·4^level triangles), new vertices pushed onto the sphere.
    pub fn icosphere(level: u32) -> Self {
        let t = (1.0 + 5f32.sqrt()) / 2.0;
        let positions: Vec<Point3<f32>> = [
            (-1.0, t, 0.0),
            (1.0, t, 0.0),
            (-1.0, -t, 0.0),
            (1.0, -t, 0.0),
            (0.0, -1.0, t),
            (0.0, 1.0, t),
            (0.0, -1.0, -t),
            (0.0, 1.0, -t),
            (t, 0.0, -1.0),
            (t, 0.0, 1.0),
            (-t, 0.0, -1.0),
            (-t, 0.0, 1.0),
        ]
        .iter()
        .map(|&(x, y, z)| Point3::from(Vector3::new(x, y, z).normalize()))
        .collect();
        let faces: Vec<[u32; 3]> = vec![
            [0, 11, 5],
            [0, 5, 1],
            [0, 1, 7],
            [0, 7, 10],
            [0, 10, 11],
            [1, 5, 9],
            [5, 11, 4],
            [11, 10, 2],
            [10, 7, 6],
            [7, 1, 8],
            [3, 9, 4],
            [3, 4, 2],
            [3, 2, 6],
            [3, 6, 8],
            [3, 8, 9],
            [4, 9, 5],
            [2, 4, 11],
            [6, 2, 10],
            [8, 6, 7],
            [9, 8, 1],
        ];
        let base = Self {
            positions,
            faces,
            ..Self::default()
        };
        base.subdivided(level, |a, b| {
            Point3::from((a.coords + b.coords).normalize())
        })
    }

    /// Splits every triangle into four, `levels` times, placing each new vertex at
    /// `midpoint(a, b)` of its edge's end points (shared between the edge's two triangles).
    /// Only positions and faces are kept; normals and colours are dropped.
    ///
    /// ```
    /// use scarp_slam::TriangleMesh;
    /// let sphere = TriangleMesh::icosphere(0);
    /// let flat = sphere.subdivided(2, nalgebra::center);
    /// assert_eq!(flat.faces.len(), 20 * 16);
    /// assert!((flat.volume_properties().unwrap().volume_m3
    ///     - sphere.volume_properties().unwrap().volume_m3).abs() < 1e-6);
    /// ```
    pub fn subdivided(
        &self,
        levels: u32,
        midpoint: impl Fn(&Point3<f32>, &Point3<f32>) -> Point3<f32>,
    ) -> Self {
        let mut positions = self.positions.clone();
        let mut faces = self.faces.clone();
        for _ in 0..levels {
            let mut midpoints: HashMap<(u32, u32), u32> = HashMap::new();
            let mut split = |a: u32, b: u32, positions: &mut Vec<Point3<f32>>| {
                *midpoints.entry((a.min(b), a.max(b))).or_insert_with(|| {
                    let m = midpoint(&positions[a as usize], &positions[b as usize]);
                    positions.push(m);
                    (positions.len() - 1) as u32
                })
            };
            faces = faces
                .iter()
                .flat_map(|&[a, b, c]| {
                    let ab = split(a, b, &mut positions);
                    let bc = split(b, c, &mut positions);
                    let ca = split(c, a, &mut positions);
                    [[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]
                })
                .collect();
        }
        Self {
            positions,
            faces,
            ..Self::default()
        }
    }

    /// Checks that every face index exists, attribute arrays are empty or one per vertex, and
    /// positions are finite.
    ///
    /// # Errors
    /// [`SlamError::FaceIndexOutOfRange`], [`SlamError::AttributeLength`] or
    /// [`SlamError::NotFinite`], naming the face, attribute or vertex.
    pub fn validate(&self) -> Result<(), SlamError> {
        check_attributes(&self.positions, &self.normals, &self.colors)?;
        let n = self.positions.len();
        for (face, f) in self.faces.iter().enumerate() {
            if let Some(&index) = f.iter().find(|&&i| i as usize >= n) {
                return Err(SlamError::FaceIndexOutOfRange {
                    face,
                    index,
                    vertex_count: n,
                });
            }
        }
        Ok(())
    }

    /// Number of vertices.
    pub fn vertex_count(&self) -> usize {
        self.positions.len()
    }

    /// Number of triangles.
    pub fn face_count(&self) -> usize {
        self.faces.len()
    }

    /// Whether the mesh has no faces.
    pub fn is_empty(&self) -> bool {
        self.faces.is_empty()
    }

    /// The three corners of face `i`, in f64. Panics if `i` or its indices are out of range,
    /// which [`Self::validate`] rules out.
    pub fn triangle(&self, i: usize) -> [Point3<f64>; 3] {
        self.faces[i].map(|v| self.positions[v as usize].cast())
    }

    /// The unnormalised normal (b − a) × (c − a) of face `i`; its norm is twice the area.
    pub fn face_normal(&self, i: usize) -> Vector3<f64> {
        let [a, b, c] = self.triangle(i);
        (b - a).cross(&(c - a))
    }

    /// Total surface area, m².
    pub fn surface_area(&self) -> f64 {
        (0..self.faces.len())
            .map(|i| 0.5 * self.face_normal(i).norm())
            .sum()
    }

    /// Axis-aligned bounds `(min, max)`, or `None` for a mesh without vertices.
    pub fn bounds(&self) -> Option<(Point3<f32>, Point3<f32>)> {
        let first = *self.positions.first()?;
        Some(
            self.positions
                .iter()
                .fold((first, first), |(lo, hi), p| (lo.inf(p), hi.sup(p))),
        )
    }

    /// Replaces the normals by area-weighted averages of the adjacent face normals. Vertices
    /// without faces get +z.
    pub fn compute_vertex_normals(&mut self) {
        let mut sums = vec![Vector3::<f64>::zeros(); self.positions.len()];
        for (i, f) in self.faces.iter().enumerate() {
            let n = self.face_normal(i);
            for &v in f {
                sums[v as usize] += n;
            }
        }
        self.normals = sums
            .into_iter()
            .map(|n| n.try_normalize(1e-20).unwrap_or_else(Vector3::z).cast())
            .collect();
    }

    /// Applies a rigid transform to positions and normals. If the positions are in frame A,
    /// pass `b_from_a` to obtain them in frame B.
    pub fn transform(&mut self, b_from_a: &Isometry3<f64>) {
        transform_points(&mut self.positions, &mut self.normals, b_from_a);
    }

    /// Scales positions uniformly about the origin (normals are unchanged).
    pub fn scale(&mut self, factor: f32) {
        for p in &mut self.positions {
            p.coords *= factor;
        }
    }

    /// Appends another mesh, re-indexing its faces. Attributes are kept only when both meshes
    /// have them (or this mesh is empty).
    pub fn append(&mut self, other: &TriangleMesh) {
        let offset = self.positions.len() as u32;
        let was_empty = self.positions.is_empty();
        let keep = |mine: bool, theirs: bool| (was_empty || mine) && theirs;
        if keep(!self.normals.is_empty(), !other.normals.is_empty()) {
            self.normals.extend_from_slice(&other.normals);
        } else {
            self.normals.clear();
        }
        if keep(!self.colors.is_empty(), !other.colors.is_empty()) {
            self.colors.extend_from_slice(&other.colors);
        } else {
            self.colors.clear();
        }
        self.positions.extend_from_slice(&other.positions);
        self.faces
            .extend(other.faces.iter().map(|f| f.map(|i| i + offset)));
    }

    /// Volume and volume centroid from signed tetrahedra against the origin. The result is only
    /// meaningful for a closed, consistently wound mesh.
    ///
    /// # Errors
    /// [`SlamError::Degenerate`] when the enclosed volume is (numerically) zero.
    pub fn volume_properties(&self) -> Result<VolumeProperties, SlamError> {
        // Tetrahedra are taken about a point inside the bounds to limit cancellation.
        let (lo, hi) = self
            .bounds()
            .ok_or_else(|| SlamError::Degenerate("volume of an empty mesh".into()))?;
        let reference: Point3<f64> = nalgebra::center(&lo, &hi).cast();
        let sums = crate::geometry::tetrahedron_sums(
            (0..self.faces.len()).map(|i| self.triangle(i).map(|p| p - reference)),
        );
        let volume6 = sums.volume6;
        if volume6.abs() < 1e-15 {
            return Err(SlamError::Degenerate("mesh encloses no volume".into()));
        }
        Ok(VolumeProperties {
            volume_m3: volume6 / 6.0,
            centroid: reference + sums.moment6 / volume6,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cuboid(size: [f32; 3]) -> TriangleMesh {
        TriangleMesh::cuboid(Point3::origin(), Point3::from(size))
    }

    #[test]
    fn icosphere_is_closed_and_outward() {
        let m = TriangleMesh::icosphere(3);
        assert_eq!(m.face_count(), 20 * 64);
        m.validate().unwrap();
        let v = m.volume_properties().unwrap();
        assert!((v.volume_m3 - 4.0 / 3.0 * std::f64::consts::PI).abs() < 0.05);
        assert!(v.centroid.coords.norm() < 1e-6);
    }

    #[test]
    fn box_volume_and_centroid() {
        let mut m = cuboid([2.0, 3.0, 4.0]);
        m.transform(&Isometry3::translation(10.0, -5.0, 100.0));
        let p = m.volume_properties().unwrap();
        assert!((p.volume_m3 - 24.0).abs() < 1e-9);
        assert!((p.centroid - Point3::new(11.0, -3.5, 102.0)).norm() < 1e-9);
        assert!((m.surface_area() - 52.0).abs() < 1e-9);
    }

    #[test]
    fn rejects_bad_faces_and_nan() {
        assert!(matches!(
            TriangleMesh::new(vec![Point3::origin(); 2], vec![[0, 1, 2]]),
            Err(SlamError::FaceIndexOutOfRange {
                face: 0,
                index: 2,
                ..
            })
        ));
        assert!(TriangleMesh::new(vec![Point3::new(f32::NAN, 0.0, 0.0)], vec![]).is_err());
    }

    #[test]
    fn normals_point_outwards() {
        let mut m = cuboid([1.0, 1.0, 1.0]);
        m.compute_vertex_normals();
        let centre = Point3::new(0.5, 0.5, 0.5);
        for (p, n) in m.positions.iter().zip(&m.normals) {
            assert!((p - centre).dot(n) > 0.0);
        }
    }

    #[test]
    fn append_reindexes() {
        let a = cuboid([1.0, 1.0, 1.0]);
        let mut b = a.clone();
        b.append(&a);
        assert_eq!(b.vertex_count(), 16);
        assert_eq!(b.faces[12], [8, 10, 9]);
        b.validate().unwrap();
        assert!((b.volume_properties().unwrap().volume_m3 - 2.0).abs() < 1e-9);
    }
}
