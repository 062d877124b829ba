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
use crate::tsdf::{BLOCK_SIDE, BLOCK_VOXELS, BlockCoord, TsdfVolume, local_index};

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

/// A block's voxels plus a one-voxel border below and a two-voxel border above.
struct Neighbourhood {
    tsdf: Vec<f32>,
    valid: Vec<bool>,
    color: Vec<[u8; 3]>,
}

impl Neighbourhood {
    fn gather(volume: &TsdfVolume, coord: &BlockCoord, min_weight: f32) -> Self {
        let mut n = Self {
            tsdf: vec![1.0; GATHER_VOXELS],
            valid: vec![false; GATHER_VOXELS],
            color: vec![[0; 3]; GATHER_VOXELS],
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
                                n.color[dst] = block.color[src];
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
    // Phase 1: each block's own edge vertices.
    let per_block: Vec<BlockVertices> = coords
        .par_iter()
        .map(|coord| {
            let n = Neighbourhood::gather(volume, coord, config.min_weight);
            let mut out = BlockVertices {
                keys: Vec::new(),
                positions: Vec::new(),
                normals: Vec::new(),
                colors: Vec::new(),
            };
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
    let faces_per_block: Vec<Vec<[u32; 3]>> = coords
        .par_iter()
        .map(|coord| {
            let n = Neighbourhood::gather(volume, coord, config.min_weight);
            // Owner blocks of edges: this block and its +x/+y/+z neighbours.
            let owners: [Option<usize>; 8] = std::array::from_fn(|c| {
                let o = corner_offset(c);
                volume.block_index(&[
                    coord[0] + o[0] as i32,
                    coord[1] + o[1] as i32,
                    coord[2] + o[2] as i32,
                ])
            });
            let mut faces = Vec::new();
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
                            faces.push(ids);
                        }
                    }
                }
            }
            faces
        })
        .collect();
    let mut mesh = TriangleMesh {
        positions: Vec::with_capacity(total),
        normals: Vec::with_capacity(total),
        colors: Vec::with_capacity(total),
        faces: faces_per_block.concat(),
    };
    for b in per_block {
        mesh.positions.extend(b.positions);
        mesh.normals.extend(b.normals);
        mesh.colors.extend(b.colors);
    }
    debug_assert!(BLOCK_VOXELS * 3 <= usize::from(u16::MAX));
    remove_coincident_face_pairs(&mut mesh.faces);
    remove_small_components(&mesh, config.min_component_triangles)
}

/// Removes triangles that share all three vertices with another triangle, in pairs.
///
/// Where the surface runs exactly along a cube face, the two cubes on either side each emit a
/// triangle on that face with opposite winding: a zero-thickness flap whose edges belong to
/// four triangles, which makes the mesh non-manifold (and breaks the closing and the mass
/// properties of fragility analysis). The pair adds nothing to the surface, so both go.
pub fn remove_coincident_face_pairs(faces: &mut Vec<[u32; 3]>) {
    let mut seen: std::collections::HashMap<[u32; 3], usize> =
        std::collections::HashMap::with_capacity(faces.len());
    let mut drop = vec![false; faces.len()];
    for (i, f) in faces.iter().enumerate() {
        let mut key = *f;
        key.sort_unstable();
        match seen.remove(&key) {
            Some(j) => {
                drop[i] = true;
                drop[j] = true;
            }
            None => {
                seen.insert(key, i);
            }
        }
    }
    let mut keep = drop.iter().map(|d| !d);
    faces.retain(|_| keep.next().unwrap_or(true));
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
