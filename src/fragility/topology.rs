//! Checking and repairing an input mesh before the analysis: welding, degenerate faces, closed
//! 2-manifold test, winding per connected shell, and levelling into an f64 working copy.

use std::collections::HashMap;

use nalgebra::{Point3, Rotation3};
use scarp_slam::TriangleMesh;
use serde::{Deserialize, Serialize};

use super::FragilityError;

/// A closed triangle surface in f64, in the levelled frame (z along up, metres). Faces wind
/// counter-clockwise seen from outside.
#[derive(Debug, Clone, Default, PartialEq)]
pub(crate) struct Solid {
    /// Vertex positions, metres, levelled frame.
    pub positions: Vec<Point3<f64>>,
    /// Triangles as vertex indices.
    pub faces: Vec<[u32; 3]>,
}

impl Solid {
    /// Lowest and highest z of the vertices, or `None` without vertices.
    pub fn z_range(&self) -> Option<(f64, f64)> {
        let first = self.positions.first()?.z;
        Some(
            self.positions
                .iter()
                .fold((first, first), |(lo, hi), p| (lo.min(p.z), hi.max(p.z))),
        )
    }

    /// Axis-aligned bounds `(min, max)`, or `None` without vertices.
    pub fn bounds(&self) -> Option<(Point3<f64>, Point3<f64>)> {
        let first = *self.positions.first()?;
        Some(
            self.positions
                .iter()
                .fold((first, first), |(lo, hi), p| (lo.inf(p), hi.sup(p))),
        )
    }

    /// The mesh in f32, for output (positions rotated by `out_from_levelled`).
    pub fn to_mesh(&self, out_from_levelled: &Rotation3<f64>) -> TriangleMesh {
        TriangleMesh {
            positions: self
                .positions
                .iter()
                .map(|p| (out_from_levelled * p).cast())
                .collect(),
            faces: self.faces.clone(),
            ..TriangleMesh::default()
        }
    }
}

/// The repairs [`analyze`](super::analyze) made to an input mesh before analysing it. All are exact: none moves a vertex.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct MeshRepairs {
    /// Vertices merged into an earlier vertex at exactly the same position (meshes exported
    /// with split corners, such as STL or some Collada conversions).
    pub welded_vertices: usize,
    /// Faces dropped because two of their corners are the same vertex (after welding). They
    /// have no area and no volume.
    pub dropped_degenerate_faces: usize,
    /// Connected shells whose faces wound inwards (negative volume) and were flipped.
    pub flipped_shells: usize,
}

/// The key under which vertices are welded: their bit-identical position (+0.0 and −0.0
/// count as equal).
pub(crate) fn weld_key(p: &Point3<f32>) -> [u32; 3] {
    [p.x, p.y, p.z].map(|c| (c + 0.0).to_bits())
}

/// Welds, drops index-degenerate faces, checks that the surface is a closed, consistently wound
/// 2-manifold, flips inward shells and rotates into the levelled frame (`levelled_from_input`).
///
/// # Errors
/// [`FragilityError::InvalidMesh`] (NaN, bad index), [`FragilityError::EmptyMesh`],
/// [`FragilityError::OpenMesh`], [`FragilityError::NonManifold`],
/// [`FragilityError::InconsistentWinding`], or [`FragilityError::Degenerate`] when the surface
/// encloses no volume.
pub(crate) fn prepare(
    mesh: &TriangleMesh,
    which: &'static str,
    levelled_from_input: &Rotation3<f64>,
) -> Result<(Solid, MeshRepairs), FragilityError> {
    mesh.validate()
        .map_err(|source| FragilityError::InvalidMesh {
            mesh: which,
            source,
        })?;
    if mesh.faces.is_empty() {
        return Err(FragilityError::EmptyMesh { mesh: which });
    }
    let mut repairs = MeshRepairs::default();

    // Weld vertices at bit-identical positions (+0.0 and −0.0 count as equal).
    let mut first_at: HashMap<[u32; 3], u32> = HashMap::with_capacity(mesh.positions.len());
    let mut remap = Vec::with_capacity(mesh.positions.len());
    let mut kept: Vec<u32> = Vec::new(); // input index of each kept vertex
    for (i, p) in mesh.positions.iter().enumerate() {
        let key = weld_key(p);
        let next = kept.len() as u32;
        let id = *first_at.entry(key).or_insert(next);
        if id == next {
            kept.push(i as u32);
        } else {
            repairs.welded_vertices += 1;
        }
        remap.push(id);
    }
    let mut faces: Vec<[u32; 3]> = Vec::with_capacity(mesh.faces.len());
    for f in &mesh.faces {
        let g = f.map(|v| remap[v as usize]);
        if g[0] == g[1] || g[1] == g[2] || g[2] == g[0] {
            repairs.dropped_degenerate_faces += 1;
        } else {
            faces.push(g);
        }
    }
    if faces.is_empty() {
        return Err(FragilityError::EmptyMesh { mesh: which });
    }
    let position_of = |v: u32| {
        let p = mesh.positions[kept[v as usize] as usize];
        [p.x, p.y, p.z]
    };
    check_manifold(&faces, which, |v| kept[v as usize], position_of)?;

    let positions: Vec<Point3<f64>> = kept
        .iter()
        .map(|&i| levelled_from_input * mesh.positions[i as usize].cast::<f64>())
        .collect();
    let mut solid = Solid { positions, faces };
    repairs.flipped_shells = orient_shells(&mut solid, which)?;
    Ok((solid, repairs))
}

/// Checks that every undirected edge is used exactly once in each direction.
fn check_manifold(
    faces: &[[u32; 3]],
    which: &'static str,
    input_index: impl Fn(u32) -> u32,
    position_of: impl Fn(u32) -> [f32; 3],
) -> Result<(), FragilityError> {
    // (low vertex, high vertex, traversed low→high).
    let mut edges: Vec<(u32, u32, bool)> = faces
        .iter()
        .flat_map(|f| {
            [(f[0], f[1]), (f[1], f[2]), (f[2], f[0])]
                .map(|(a, b)| if a < b { (a, b, true) } else { (b, a, false) })
        })
        .collect();
    edges.sort_unstable();
    let (mut open, mut non_manifold, mut flipped) = (None, None, None);
    let (mut n_open, mut n_non_manifold, mut n_flipped) = (0usize, 0usize, 0usize);
    for group in edges.chunk_by(|x, y| x.0 == y.0 && x.1 == y.1) {
        let edge = (group[0].0, group[0].1);
        let forward = group.iter().filter(|e| e.2).count();
        match (group.len(), forward) {
            (2, 1) => {}
            (1, _) => {
                n_open += 1;
                open.get_or_insert(edge);
            }
            (2, _) => {
                n_flipped += 1;
                flipped.get_or_insert(edge);
            }
            _ => {
                n_non_manifold += 1;
                non_manifold.get_or_insert(edge);
            }
        }
    }
    let describe = |(a, b): (u32, u32)| (input_index(a), input_index(b), position_of(a));
    if let Some(edge) = non_manifold {
        let (a, b, position) = describe(edge);
        return Err(FragilityError::NonManifold {
            mesh: which,
            count: n_non_manifold,
            a,
            b,
            position,
        });
    }
    if let Some(edge) = open {
        let (a, b, position) = describe(edge);
        return Err(FragilityError::OpenMesh {
            mesh: which,
            count: n_open,
            a,
            b,
            position,
        });
    }
    if let Some(edge) = flipped {
        let (a, b, position) = describe(edge);
        return Err(FragilityError::InconsistentWinding {
            mesh: which,
            count: n_flipped,
            a,
            b,
            position,
        });
    }
    Ok(())
}

fn find(parent: &mut [u32], mut v: u32) -> u32 {
    while parent[v as usize] != v {
        let up = parent[parent[v as usize] as usize];
        parent[v as usize] = up;
        v = up;
    }
    v
}

/// Flips every connected shell with negative signed volume; returns how many were flipped.
///
/// # Errors
/// [`FragilityError::Degenerate`] when the whole surface encloses no volume.
fn orient_shells(solid: &mut Solid, which: &'static str) -> Result<usize, FragilityError> {
    let n = solid.positions.len();
    let mut parent: Vec<u32> = (0..n as u32).collect();
    for f in &solid.faces {
        let r0 = find(&mut parent, f[0]);
        for &v in &f[1..] {
            let r = find(&mut parent, v);
            if r != r0 {
                parent[r as usize] = r0;
            }
        }
    }
    let (lo, hi) = solid
        .bounds()
        .ok_or(FragilityError::EmptyMesh { mesh: which })?;
    let reference = nalgebra::center(&lo, &hi);
    let mut volume6 = vec![0.0f64; n];
    let mut roots = Vec::with_capacity(solid.faces.len());
    for f in &solid.faces {
        let root = find(&mut parent, f[0]);
        let [a, b, c] = f.map(|v| solid.positions[v as usize] - reference);
        volume6[root as usize] += a.dot(&b.cross(&c));
        roots.push(root);
    }
    let total: f64 = volume6.iter().map(|v| v.abs()).sum();
    let diagonal = (hi - lo).norm();
    if total.is_nan() || total <= 1e-12 * diagonal.powi(3) {
        return Err(FragilityError::Degenerate(format!(
            "{which} mesh encloses no volume (flat or collapsed surface)"
        )));
    }
    let mut flipped = 0;
    for (root, v) in volume6.iter().enumerate() {
        if *v < 0.0 && parent[root] == root as u32 {
            flipped += 1;
        }
    }
    if flipped > 0 {
        for (f, root) in solid.faces.iter_mut().zip(&roots) {
            if volume6[*root as usize] < 0.0 {
                f.swap(1, 2);
            }
        }
    }
    Ok(flipped)
}
