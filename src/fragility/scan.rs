//! Closing a reconstructed scan for the analysis: a TSDF mesh of a rock on its pedestal is open
//! (the terrain is cut by the region of interest, and unseen parts leave holes), so it cannot go
//! to [`super::analyze`] as it is.
//!
//! 1. The neck: walking down from the top, the horizontal extent of the surface (the area of the
//!    convex hull of the vertices in thin slabs) grows over the rock, shrinks to the contact and
//!    grows again over the pedestal. The narrowest slab between the rock's widest part and that
//!    growth is the contact height.
//! 2. The rock: the faces entirely above the neck, largest connected component.
//! 3. Closing: every boundary loop (the cut at the neck, and holes where no camera looked) is
//!    closed by a fan around its centroid, wound to face outward.
//!
//! The closed rock then goes to the analysis, whose contact search finds the flat cap at the
//! neck (`ContactMethod::Base`).

use std::collections::HashMap;

use nalgebra::{Point2, Point3};
use scarp_slam::TriangleMesh;
use scarp_slam::geometry::{convex_hull_2d, polygon_signed_area};

use super::FragilityError;
use super::topology::weld_key;

/// Slab thickness of the extent profile, metres.
const SLAB_M: f64 = 0.02;
/// Step between slabs, metres.
const STEP_M: f64 = 0.01;
/// The neck must narrow to this fraction of the rock's widest slab.
const NARROWING: f64 = 0.6;
/// Below the narrowest slab, an extent this many times the narrowest one ends the search (the
/// pedestal or the ground).
const WIDENING: f64 = 1.5;

/// A scan closed above its neck.
#[derive(Debug, Clone)]
pub struct ClosedScan {
    /// The rock above the neck, closed (watertight), world frame.
    pub mesh: TriangleMesh,
    /// Height of the neck (the contact), metres along z.
    pub contact_height_m: f64,
    /// Boundary loops that were closed (the cut plus holes).
    pub loops_closed: usize,
}

/// Azimuth sectors a slab's vertices must fill (of [`SECTORS`]) to count: a slab seen from
/// one side only has a small hull that is not a neck.
const MIN_SECTORS: usize = 10;
/// Sectors around the axis.
const SECTORS: usize = 12;

/// Area of the convex hull of the vertices with z in `[z, z + SLAB_M)`, m², or 0 when they do
/// not surround `axis_xy` (fewer than [`MIN_SECTORS`] of [`SECTORS`] azimuth sectors filled).
fn slab_extent(mesh: &TriangleMesh, z: f64, axis_xy: &Point2<f64>) -> f64 {
    let points: Vec<Point2<f64>> = mesh
        .positions
        .iter()
        .filter(|p| {
            let pz = f64::from(p.z);
            pz >= z && pz < z + SLAB_M
        })
        .map(|p| Point2::new(f64::from(p.x), f64::from(p.y)))
        .collect();
    if points.len() < 3 {
        return 0.0;
    }
    let mut filled = [false; SECTORS];
    for p in &points {
        let d = p - axis_xy;
        let a = d.y.atan2(d.x).rem_euclid(std::f64::consts::TAU);
        filled[((a / std::f64::consts::TAU * SECTORS as f64) as usize).min(SECTORS - 1)] = true;
    }
    if filled.iter().filter(|&&f| f).count() < MIN_SECTORS {
        return 0.0;
    }
    polygon_signed_area(&convex_hull_2d(&points)).abs()
}

/// The neck height of a scan of a rock on a pedestal or on the ground (z up).
///
/// # Errors
/// [`FragilityError::Degenerate`] when the extent never narrows below the rock (no neck).
pub fn find_scan_neck(mesh: &TriangleMesh) -> Result<f64, FragilityError> {
    let (lo, hi) = mesh
        .bounds()
        .ok_or(FragilityError::EmptyMesh { mesh: "scan" })?;
    let (z_lo, z_hi) = (f64::from(lo.z), f64::from(hi.z));
    // The rock's axis: the mean of the vertices in its top third.
    let top: Vec<Point2<f64>> = mesh
        .positions
        .iter()
        .filter(|p| f64::from(p.z) > z_hi - (z_hi - z_lo) / 3.0)
        .map(|p| Point2::new(f64::from(p.x), f64::from(p.y)))
        .collect();
    let axis_xy =
        top.iter().fold(Point2::origin(), |acc, p| acc + p.coords) / top.len().max(1) as f64;
    let mut widest = 0.0f64;
    let mut narrowest: Option<(f64, f64)> = None;
    let mut z = z_hi - SLAB_M;
    while z >= z_lo {
        let extent = slab_extent(mesh, z, &axis_xy);
        if extent <= 0.0 {
            // No surface seen at this height (a hole): no evidence either way.
            z -= STEP_M;
            continue;
        }
        match narrowest {
            None => {
                widest = widest.max(extent);
                if widest > 0.0 && extent < NARROWING * widest {
                    narrowest = Some((z, extent));
                }
            }
            Some((_, smallest)) if extent < smallest => narrowest = Some((z, extent)),
            Some((_, smallest)) if extent > WIDENING * smallest => break,
            Some(_) => {}
        }
        z -= STEP_M;
    }
    narrowest.map(|(z, _)| z + 0.5 * SLAB_M).ok_or_else(|| {
        FragilityError::Degenerate(
            "the scan never narrows below the rock: no neck to separate it at".into(),
        )
    })
}

/// Faces of the largest edge-connected component.
fn largest_component(faces: &[[u32; 3]]) -> Vec<[u32; 3]> {
    let mut parent: Vec<usize> = (0..faces.len()).collect();
    fn root(parent: &mut [usize], mut i: usize) -> usize {
        while parent[i] != i {
            parent[i] = parent[parent[i]];
            i = parent[i];
        }
        i
    }
    let mut by_vertex: HashMap<u32, usize> = HashMap::new();
    for (i, f) in faces.iter().enumerate() {
        for &v in f {
            match by_vertex.get(&v) {
                Some(&j) => {
                    let (a, b) = (root(&mut parent, i), root(&mut parent, j));
                    parent[a] = b;
                }
                None => {
                    by_vertex.insert(v, i);
                }
            }
        }
    }
    let mut sizes: HashMap<usize, usize> = HashMap::new();
    for i in 0..faces.len() {
        *sizes.entry(root(&mut parent, i)).or_default() += 1;
    }
    let Some((&best, _)) = sizes.iter().max_by_key(|(r, n)| (**n, usize::MAX - **r)) else {
        return Vec::new();
    };
    (0..faces.len())
        .filter(|&i| root(&mut parent, i) == best)
        .map(|i| faces[i])
        .collect()
}

/// For each vertex, the first vertex at a bit-identical position: the analysis welds them,
/// so the cut and the hole filling must see the same topology it will.
fn welded_vertices(mesh: &TriangleMesh) -> Vec<u32> {
    let mut first_at: HashMap<[u32; 3], u32> = HashMap::with_capacity(mesh.positions.len());
    mesh.positions
        .iter()
        .enumerate()
        .map(|(i, p)| *first_at.entry(weld_key(p)).or_insert(i as u32))
        .collect()
}

/// `faces` without those that make an edge shared by more than two faces (marching cubes
/// leaves a few where thin structures touch): at such an edge the first two faces in order
/// stay and the rest go, and holes left behind are closed like any other.
fn manifold_faces(faces: &[[u32; 3]]) -> Vec<[u32; 3]> {
    let mut uses: HashMap<(u32, u32), u8> = HashMap::new();
    faces
        .iter()
        .filter(|f| {
            let edges =
                [(f[0], f[1]), (f[1], f[2]), (f[2], f[0])].map(|(a, b)| (a.min(b), a.max(b)));
            if edges.iter().any(|e| uses.get(e).is_some_and(|&n| n >= 2)) {
                return false;
            }
            for e in edges {
                *uses.entry(e).or_default() += 1;
            }
            true
        })
        .copied()
        .collect()
}

/// Closes every boundary loop of `mesh` with a fan around the loop's centroid. Returns the
/// number of loops closed.
fn fill_holes(mesh: &mut TriangleMesh) -> usize {
    let mut count: HashMap<(u32, u32), i32> = HashMap::new();
    for f in &mesh.faces {
        for k in 0..3 {
            let (a, b) = (f[k], f[(k + 1) % 3]);
            *count.entry((a.min(b), a.max(b))).or_default() += 1;
        }
    }
    // The hole's side of a boundary edge a→b (face order) is walked b→a.
    let mut outgoing: HashMap<u32, Vec<u32>> = HashMap::new();
    let mut boundary: Vec<(u32, u32)> = Vec::new();
    for f in &mesh.faces {
        for k in 0..3 {
            let (a, b) = (f[k], f[(k + 1) % 3]);
            if count[&(a.min(b), a.max(b))] == 1 {
                outgoing.entry(b).or_default().push(a);
                boundary.push((b, a));
            }
        }
    }
    boundary.sort_unstable();
    let mut loops = 0;
    for &(start, _) in &boundary {
        while outgoing.get(&start).is_some_and(|v| !v.is_empty()) {
            // Walk the boundary; a vertex met twice (a pinch, where two holes touch) splits
            // off the simple loop between its two visits, so every fan closes a simple loop.
            let mut chain = vec![start];
            let mut position: HashMap<u32, usize> = HashMap::from([(start, 0)]);
            let mut at = start;
            while let Some(next) = outgoing.get_mut(&at).and_then(Vec::pop) {
                if let Some(&i) = position.get(&next) {
                    let simple: Vec<u32> = chain.drain(i..).collect();
                    for v in &simple {
                        position.remove(v);
                    }
                    loops += usize::from(fan(mesh, &simple));
                    if next == start && chain.is_empty() {
                        break;
                    }
                }
                position.insert(next, chain.len());
                chain.push(next);
                at = next;
            }
            loops += usize::from(fan(mesh, &chain));
        }
    }
    loops
}

/// Closes the simple loop `chain` (hole-side order) with a fan around its centroid; `false`
/// for a loop too short to enclose anything.
fn fan(mesh: &mut TriangleMesh, chain: &[u32]) -> bool {
    if chain.len() < 3 {
        return false;
    }
    let n = chain.len() as f32;
    let centroid = chain.iter().fold(Point3::origin(), |acc: Point3<f32>, &v| {
        acc + mesh.positions[v as usize].coords / n
    });
    let c = mesh.positions.len() as u32;
    mesh.positions.push(centroid);
    if !mesh.normals.is_empty() {
        mesh.normals.push(nalgebra::Vector3::zeros());
    }
    if !mesh.colors.is_empty() {
        mesh.colors.push([128; 3]);
    }
    for k in 0..chain.len() {
        mesh.faces.push([chain[k], chain[(k + 1) % chain.len()], c]);
    }
    true
}

/// Separates the rock from its pedestal and the ground at the neck and closes it.
///
/// # Errors
/// [`FragilityError::EmptyMesh`] for an empty scan or nothing above the neck;
/// [`FragilityError::Degenerate`] when no neck is found.
pub fn close_scan(mesh: &TriangleMesh) -> Result<ClosedScan, FragilityError> {
    let contact_height_m = find_scan_neck(mesh)?;
    let weld = welded_vertices(mesh);
    let above: Vec<[u32; 3]> = mesh
        .faces
        .iter()
        .filter(|f| {
            f.iter()
                .all(|&v| f64::from(mesh.positions[v as usize].z) > contact_height_m)
        })
        .map(|f| f.map(|v| weld[v as usize]))
        .filter(|g| g[0] != g[1] && g[1] != g[2] && g[2] != g[0])
        .collect();
    let faces = largest_component(&manifold_faces(&above));
    if faces.is_empty() {
        return Err(FragilityError::EmptyMesh {
            mesh: "rock above the neck",
        });
    }
    // Compact the vertices.
    let mut remap: HashMap<u32, u32> = HashMap::new();
    let mut rock = TriangleMesh::default();
    let has_normals = mesh.normals.len() == mesh.positions.len();
    let has_colors = mesh.colors.len() == mesh.positions.len();
    for f in &faces {
        let mut g = [0u32; 3];
        for (k, &v) in f.iter().enumerate() {
            g[k] = *remap.entry(v).or_insert_with(|| {
                rock.positions.push(mesh.positions[v as usize]);
                if has_normals {
                    rock.normals.push(mesh.normals[v as usize]);
                }
                if has_colors {
                    rock.colors.push(mesh.colors[v as usize]);
                }
                (rock.positions.len() - 1) as u32
            });
        }
        rock.faces.push(g);
    }
    let loops_closed = fill_holes(&mut rock);
    Ok(ClosedScan {
        mesh: rock,
        contact_height_m,
        loops_closed,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fragility::test_shapes::{loft_solid, regular_ring, to_mesh};
    use crate::fragility::{ContactSpec, FragilityConfig, analyze};

    /// A round rock (0.84 m across, 0.8 m tall) on a narrow neck (0.28 m) on a wide pedestal, as
    /// one open surface: no bottom, like a scan.
    fn open_scan() -> TriangleMesh {
        // (z, radius) keys of a 32-gon section, sampled every centimetre like a scan.
        let keys = [
            (0.0, 0.8),
            (0.5, 0.6),
            (0.9, 0.14),
            (1.0, 0.14),
            (1.02, 0.42),
            (1.8, 0.42),
        ];
        let radius_at = |z: f64| {
            let k = keys.windows(2).find(|w| z <= w[1].0).unwrap_or(&keys[4..6]);
            let t = ((z - k[0].0) / (k[1].0 - k[0].0)).clamp(0.0, 1.0);
            k[0].1 + t * (k[1].1 - k[0].1)
        };
        let rings: Vec<(Vec<(f64, f64)>, f64)> = (0..=180)
            .map(|i| {
                let z = f64::from(i) * 0.01;
                (regular_ring(32, radius_at(z), 0.0), z)
            })
            .collect();
        let refs: Vec<(&[(f64, f64)], f64)> = rings.iter().map(|(r, z)| (&r[..], *z)).collect();
        let mut mesh = to_mesh(&loft_solid(&refs));
        // Open it: drop the bottom cap (faces whose vertices all sit at z = 0).
        mesh.faces
            .retain(|f| f.iter().any(|&v| mesh.positions[v as usize].z > 1e-6));
        mesh
    }

    #[test]
    fn a_third_face_on_an_edge_is_dropped() {
        // Two triangles share edge 0–1; a third on the same edge is dropped, a fourth elsewhere
        // stays.
        let faces = [[0, 1, 2], [1, 0, 3], [0, 1, 4], [2, 1, 5]];
        assert_eq!(
            manifold_faces(&faces),
            vec![[0, 1, 2], [1, 0, 3], [2, 1, 5]]
        );
    }

    #[test]
    fn finds_the_neck_and_closes_the_rock() {
        let scan = open_scan();
        assert!(analyze(&scan, ContactSpec::Auto, &FragilityConfig::default()).is_err());
        let closed = close_scan(&scan).unwrap();
        assert!(
            (0.9..=1.03).contains(&closed.contact_height_m),
            "neck at {}",
            closed.contact_height_m
        );
        assert!(closed.loops_closed >= 1);
        let report = analyze(&closed.mesh, ContactSpec::Auto, &FragilityConfig::default()).unwrap();
        assert!(report.volume_m3 > 0.2, "volume {}", report.volume_m3);
        assert!(report.alpha_min_deg > 0.0 && report.alpha_min_deg < 30.0);
    }

    #[test]
    fn a_scan_without_a_neck_is_refused() {
        let mut cube = TriangleMesh::cuboid(Point3::new(0.0, 0.0, 0.0), Point3::new(1.0, 1.0, 1.0));
        cube.faces.truncate(10);
        assert!(close_scan(&cube).is_err());
    }
}
