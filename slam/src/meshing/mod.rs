//! Marching cubes over a voxel-hashed TSDF volume.
//!
//! Every grid edge belongs to the block holding its lower endpoint, and only that block creates
//! the edge's vertex; cells in neighbouring blocks look the vertex up there. Vertices are
//! therefore shared across block borders: no duplicates and no cracks. Normals come from the
//! TSDF gradient (central differences), colours from the voxels, both interpolated along the
//! edge. Small connected components can be dropped.
//!
//! The output is deterministic: blocks are processed in parallel but concatenated in storage
//! order.

mod components;
mod table;

use nalgebra::{Point3, Vector3};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::mesh::TriangleMesh;
use std::collections::HashMap;

use crate::tsdf::{
    BLOCK_SIDE, BLOCK_VOXELS, BlockCoord, BuildBlockHasher, TsdfVolume, local_index,
};

pub use components::remove_small_components;
pub use table::{CaseTable, EDGE_AXIS, EDGE_LOWER_CORNER, corner_offset};

/// Meshing parameters.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct MeshingConfig {
    /// A voxel takes part only when its weight exceeds this. Default 0 (any observation); raise
    /// it to drop surfaces seen only once or twice.
    pub min_weight: f32,
    /// Connected components with fewer triangles than this are dropped. Default 0 (keep all);
    /// `scarp map` uses 200 to remove floating noise.
    pub min_component_triangles: usize,
}

impl Default for MeshingConfig {
    fn default() -> Self {
        Self {
            min_weight: 0.0,
            min_component_triangles: 0,
        }
    }
}

/// Side of the gathered neighbourhood: local voxels −1 … 9 around a block.
const GATHER: usize = BLOCK_SIDE + 3;
const GATHER_VOXELS: usize = GATHER * GATHER * GATHER;

#[inline]
fn gather_index(x: i32, y: i32, z: i32) -> usize {
    // Callers stay inside −1 … 9, so the shifted coordinates are in 0 … 10.
    ((x + 1) + GATHER as i32 * ((y + 1) + GATHER as i32 * (z + 1))) as usize
}

/// A block's voxels plus a one-voxel border below and a two-voxel border above (on the stack:
/// no allocation per block).
struct Neighbourhood {
    tsdf: [f32; GATHER_VOXELS],
    valid: [bool; GATHER_VOXELS],
    color: [[u8; 3]; GATHER_VOXELS],
}

impl Neighbourhood {
    /// Gathers the neighbourhood of the block at `coord`; colours only with `with_color`.
    fn gather(volume: &TsdfVolume, coord: &BlockCoord, min_weight: f32, with_color: bool) -> Self {
        let mut n = Self {
            tsdf: [1.0; GATHER_VOXELS],
            valid: [false; GATHER_VOXELS],
            color: [[0; 3]; GATHER_VOXELS],
        };
        let side = BLOCK_SIDE as i32;
        for oz in -1..=1i32 {
            for oy in -1..=1i32 {
                for ox in -1..=1i32 {
                    let nb = [coord[0] + ox, coord[1] + oy, coord[2] + oz];
                    let Some(block) = volume.block(&nb) else {
                        continue;
                    };
                    // Local range of the neighbour copied: offset −1 → last voxel, +1 → first two.
                    let range = |o: i32| match o {
                        -1 => (side - 1)..side,
                        0 => 0..side,
                        _ => 0..2,
                    };
                    for lz in range(oz) {
                        for ly in range(oy) {
                            for lx in range(ox) {
                                let src = local_index(lx as usize, ly as usize, lz as usize);
                                let dst =
                                    gather_index(ox * side + lx, oy * side + ly, oz * side + lz);
                                let w = block.weight[src];
                                n.valid[dst] = w > 0.0 && w > min_weight;
                                n.tsdf[dst] = block.tsdf[src];
                                if with_color {
                                    n.color[dst] = crate::tsdf::rgb_of(block.color[src]);
                                }
                            }
                        }
                    }
                }
            }
        }
        n
    }

    /// TSDF gradient at gathered voxel (x, y, z) ∈ 0 … 8, central differences with one-sided
    /// fallbacks where a neighbour is unobserved.
    fn gradient(&self, x: i32, y: i32, z: i32) -> Vector3<f32> {
        let c = gather_index(x, y, z);
        let mut g = Vector3::zeros();
        for a in 0..3 {
            let mut p = [x, y, z];
            let mut m = [x, y, z];
            p[a] += 1;
            m[a] -= 1;
            let ip = gather_index(p[0], p[1], p[2]);
            let im = gather_index(m[0], m[1], m[2]);
            g[a] = match (self.valid[ip], self.valid[im]) {
                (true, true) => 0.5 * (self.tsdf[ip] - self.tsdf[im]),
                (true, false) => self.tsdf[ip] - self.tsdf[c],
                (false, true) => self.tsdf[c] - self.tsdf[im],
                (false, false) => 0.0,
            };
        }
        g
    }
}

/// A vertex created by a block, keyed by `local_index · 3 + axis` of its edge.
struct BlockVertices {
    keys: Vec<u16>,
    positions: Vec<Point3<f32>>,
    normals: Vec<Vector3<f32>>,
    colors: Vec<[u8; 3]>,
}

/// Extracts the zero level set of `volume` as a triangle mesh in world ENU metres, normals
/// pointing out of the surface (toward positive TSDF, i.e. toward the cameras).
pub fn extract_mesh(volume: &TsdfVolume, config: &MeshingConfig) -> TriangleMesh {
    let table = CaseTable::new();
    let coords = volume.block_coords();
    let voxel = volume.config().voxel_size_m;
    let side = BLOCK_SIDE as i32;
    let active = active_blocks(volume, config.min_weight);
    // Phase 1: each block's own edge vertices.
    let per_block: Vec<BlockVertices> = coords
        .par_iter()
        .zip(&active)
        .map(|(coord, &active)| {
            let mut out = BlockVertices {
                keys: Vec::new(),
                positions: Vec::new(),
                normals: Vec::new(),
                colors: Vec::new(),
            };
            if !active {
                return out;
            }
            let n = Neighbourhood::gather(volume, coord, config.min_weight, true);
            for z in 0..side {
                for y in 0..side {
                    for x in 0..side {
                        let i0 = gather_index(x, y, z);
                        if !n.valid[i0] {
                            continue;
                        }
                        let t0 = n.tsdf[i0];
                        for axis in 0..3 {
                            let mut q = [x, y, z];
                            q[axis] += 1;
                            let i1 = gather_index(q[0], q[1], q[2]);
                            if !n.valid[i1] {
                                continue;
                            }
                            let t1 = n.tsdf[i1];
                            if (t0 < 0.0) == (t1 < 0.0) {
                                continue;
                            }
                            let f = t0 / (t0 - t1);
                            let g = [
                                coord[0] * side + x,
                                coord[1] * side + y,
                                coord[2] * side + z,
                            ];
                            let mut p = Point3::new(g[0] as f32, g[1] as f32, g[2] as f32);
                            p[axis] += f;
                            let normal =
                                n.gradient(x, y, z) * (1.0 - f) + n.gradient(q[0], q[1], q[2]) * f;
                            let c0 = n.color[i0];
                            let c1 = n.color[i1];
                            out.keys.push(
                                (local_index(x as usize, y as usize, z as usize) * 3 + axis) as u16,
                            );
                            out.positions.push(p * voxel);
                            out.normals
                                .push(normal.try_normalize(0.0).unwrap_or_default());
                            out.colors.push([0, 1, 2].map(|k| {
                                (f32::from(c0[k]) * (1.0 - f) + f32::from(c1[k]) * f).round() as u8
                            }));
                        }
                    }
                }
            }
            out
        })
        .collect();
    // Phase 2: global vertex ids by prefix sums in storage order.
    let mut offsets = Vec::with_capacity(per_block.len() + 1);
    let mut total = 0usize;
    for b in &per_block {
        offsets.push(total);
        total += b.keys.len();
    }
    // Phase 3: triangles of the cells whose lower corner lies in each block.
    // Each block's triangles, and which of them lie in a cube face (the only ones that can
    // coincide with another cell's triangle, see [`remove_coincident_face_pairs`]).
    let faces_per_block: Vec<(Vec<[u32; 3]>, Vec<u32>)> = coords
        .par_iter()
        .zip(&active)
        .map(|(coord, &active)| {
            let mut faces = Vec::new();
            let mut in_cube_face = Vec::new();
            if !active {
                return (faces, in_cube_face);
            }
            let n = Neighbourhood::gather(volume, coord, config.min_weight, false);
            // Owner blocks of edges: this block and its +x/+y/+z neighbours.
            let owners: [Option<usize>; 8] = std::array::from_fn(|c| {
                let o = corner_offset(c);
                volume.block_index(&[
                    coord[0] + o[0] as i32,
                    coord[1] + o[1] as i32,
                    coord[2] + o[2] as i32,
                ])
            });
            for z in 0..side {
                for y in 0..side {
                    for x in 0..side {
                        let mut case = 0usize;
                        let mut all_valid = true;
                        for c in 0..8 {
                            let o = corner_offset(c);
                            let i = gather_index(x + o[0] as i32, y + o[1] as i32, z + o[2] as i32);
                            all_valid &= n.valid[i];
                            if n.tsdf[i] < 0.0 {
                                case |= 1 << c;
                            }
                        }
                        if !all_valid || case == 0 || case == 255 {
                            continue;
                        }
                        'triangle: for tri in table.triangles(case) {
                            let mut ids = [0u32; 3];
                            for (slot, &e) in tri.iter().enumerate() {
                                let e = e as usize;
                                let o = corner_offset(EDGE_LOWER_CORNER[e]);
                                let l = [x + o[0] as i32, y + o[1] as i32, z + o[2] as i32];
                                let mut owner_corner = 0;
                                let mut local = [0usize; 3];
                                for a in 0..3 {
                                    if l[a] == side {
                                        owner_corner |= 1 << a;
                                    } else {
                                        local[a] = l[a] as usize;
                                    }
                                }
                                let Some(owner) = owners[owner_corner] else {
                                    continue 'triangle;
                                };
                                let key = (local_index(local[0], local[1], local[2]) * 3
                                    + EDGE_AXIS[e])
                                    as u16;
                                let Ok(k) = per_block[owner].keys.binary_search(&key) else {
                                    continue 'triangle;
                                };
                                // Vertex counts stay below u32::MAX (TriangleMesh uses u32 ids).
                                ids[slot] = (offsets[owner] + k) as u32;
                            }
                            let [a, b, c] = tri.map(|e| EDGE_FACES[e as usize]);
                            if a & b & c != 0 {
                                // Face counts stay below u32::MAX like vertex counts.
                                in_cube_face.push(faces.len() as u32);
                            }
                            faces.push(ids);
                        }
                    }
                }
            }
            (faces, in_cube_face)
        })
        .collect();
    let face_total = faces_per_block.iter().map(|(f, _)| f.len()).sum();
    let mut faces = Vec::with_capacity(face_total);
    let mut candidates = Vec::new();
    for (block_faces, in_cube_face) in faces_per_block {
        let offset = faces.len();
        candidates.extend(in_cube_face.iter().map(|&i| offset + i as usize));
        faces.extend(block_faces);
    }
    let mut mesh = TriangleMesh {
        positions: Vec::with_capacity(total),
        normals: Vec::with_capacity(total),
        colors: Vec::with_capacity(total),
        faces,
    };
    for b in per_block {
        mesh.positions.extend(b.positions);
        mesh.normals.extend(b.normals);
        mesh.colors.extend(b.colors);
    }
    debug_assert!(BLOCK_VOXELS * 3 <= usize::from(u16::MAX));
    remove_coincident_pairs_among(&mut mesh.faces, &candidates);
    if config.min_component_triangles == 0 {
        // Nothing to drop: skip the component pass and its copy.
        return mesh;
    }
    remove_small_components(&mesh, config.min_component_triangles)
}

/// Per cube-edge bit set of the cube faces containing it: bit 2·a + o for the face normal to
/// axis a at offset o ∈ {0, 1}. Three edges lie in one face when their sets intersect.
const EDGE_FACES: [u8; 12] = {
    let mut out = [0u8; 12];
    let mut e = 0;
    while e < 12 {
        let axis = EDGE_AXIS[e];
        let o = corner_offset(EDGE_LOWER_CORNER[e]);
        let mut b = 0;
        while b < 3 {
            if b != axis {
                out[e] |= 1 << (2 * b + o[b]);
            }
            b += 1;
        }
        e += 1;
    }
    out
};

/// Per stored block: whether any cell or edge it owns can cross the surface, i.e. whether the
/// observed voxels of the block and its seven upper neighbours (+x, +y, +z and their
/// combinations, which its cells reach) include both signs. Free-space blocks (all TSDF
/// positive) and blocks behind surfaces are skipped without gathering anything.
fn active_blocks(volume: &TsdfVolume, min_weight: f32) -> Vec<bool> {
    const NEGATIVE: u8 = 1;
    const POSITIVE: u8 = 2;
    let signs: Vec<u8> = volume
        .blocks()
        .par_iter()
        .map(|b| {
            let mut s = 0;
            for (&t, &w) in b.tsdf.iter().zip(b.weight.iter()) {
                if w > 0.0 && w > min_weight {
                    s |= if t < 0.0 { NEGATIVE } else { POSITIVE };
                }
            }
            s
        })
        .collect();
    volume
        .block_coords()
        .par_iter()
        .zip(&signs)
        .map(|(coord, &own)| {
            // Every edge and cell of a block starts at one of its own observed voxels.
            if own == 0 {
                return false;
            }
            let mut s = own;
            for c in 1..8 {
                if s == NEGATIVE | POSITIVE {
                    break;
                }
                let o = corner_offset(c);
                let nb = [
                    coord[0] + o[0] as i32,
                    coord[1] + o[1] as i32,
                    coord[2] + o[2] as i32,
                ];
                s |= volume.block_index(&nb).map_or(0, |i| signs[i]);
            }
            s == NEGATIVE | POSITIVE
        })
        .collect()
}

/// Removes triangles that share all three vertices with another triangle, in pairs.
///
/// Where the surface runs exactly along a cube face, the two cubes on either side each emit a
/// triangle on that face with opposite winding: a zero-thickness flap whose edges belong to
/// four triangles, which makes the mesh non-manifold (and breaks the closing and the mass
/// properties of fragility analysis). The pair adds nothing to the surface, so both go.
pub fn remove_coincident_face_pairs(faces: &mut Vec<[u32; 3]>) {
    let all: Vec<usize> = (0..faces.len()).collect();
    remove_coincident_pairs_among(faces, &all);
}

/// [`remove_coincident_face_pairs`] restricted to the faces at `candidates` (indices into
/// `faces`, increasing): marching cubes only needs to check triangles lying in a cube face.
fn remove_coincident_pairs_among(faces: &mut Vec<[u32; 3]>, candidates: &[usize]) {
    let mut seen: HashMap<[u32; 3], usize, BuildBlockHasher> =
        HashMap::with_capacity_and_hasher(candidates.len(), BuildBlockHasher::default());
    let mut drop = Vec::new();
    for &i in candidates {
        let mut key = faces[i];
        key.sort_unstable();
        match seen.remove(&key) {
            Some(j) => {
                drop.push(i);
                drop.push(j);
            }
            None => {
                seen.insert(key, i);
            }
        }
    }
    if drop.is_empty() {
        return;
    }
    drop.sort_unstable();
    let mut next = drop.iter().peekable();
    let mut index = 0;
    faces.retain(|_| {
        let keep = next.peek() != Some(&&index);
        if !keep {
            next.next();
        }
        index += 1;
        keep
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn coincident_opposite_faces_go_in_pairs() {
        let mut faces = vec![[0, 1, 2], [2, 3, 0], [0, 2, 1], [4, 5, 6]];
        remove_coincident_face_pairs(&mut faces);
        assert_eq!(faces, vec![[2, 3, 0], [4, 5, 6]]);
    }
}
