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
    /// A voxel takes part only when its weight (Σ 1/z², z in metres) exceeds this. Default 0
    /// (any observation).
    pub min_weight: f32,
    /// A voxel takes part only when at least this many frames observed it (counts saturate at
    /// 255). Default 0 (any observation). Open3D's `weight_threshold` t keeps weights above t,
    /// one per frame: the voxels this keeps at t + 1.
    pub min_observations: u8,
    /// Connected components with fewer triangles than this are dropped. Default 0 (keep all);
    /// `scarp map` uses 200 to remove floating noise.
    pub min_component_triangles: usize,
}

impl Default for MeshingConfig {
    fn default() -> Self {
        Self {
            min_weight: 0.0,
            min_observations: 0,
            min_component_triangles: 0,
        }
    }
}

impl MeshingConfig {
    /// Whether a voxel of weight `weight` and stored word `word` (colour, observations) takes
    /// part in meshing. Branch-free, so block scans run in SIMD lanes.
    #[inline]
    fn keeps(&self, weight: f32, word: [u8; 4]) -> bool {
        (weight > 0.0)
            & (weight > self.min_weight)
            & (crate::tsdf::observations_of(word) >= self.min_observations)
    }
}

/// Side of the gathered neighbourhood: local voxels −1 … 9 around a block.
const GATHER: usize = BLOCK_SIDE + 3;
const GATHER_VOXELS: usize = GATHER * GATHER * GATHER;
/// Rows along x of the gathered neighbourhood, one per (y, z).
const GATHER_ROWS: usize = GATHER * GATHER;
/// The bits of a row mask that stand for the block's own voxels x = 0 … 7 (bit x + 1).
const OWN_X: u16 = ((1 << BLOCK_SIDE) - 1) << 1;

#[inline]
fn gather_index(x: i32, y: i32, z: i32) -> usize {
    // Callers stay inside −1 … 9, so the shifted coordinates are in 0 … 10.
    ((x + 1) + GATHER as i32 * ((y + 1) + GATHER as i32 * (z + 1))) as usize
}

/// The row (y, z) of the gathered neighbourhood, y and z in −1 … 9.
#[inline]
fn row_index(y: i32, z: i32) -> usize {
    ((y + 1) + GATHER as i32 * (z + 1)) as usize
}

/// A block's voxels plus a one-voxel border below and a two-voxel border above (on the stack:
/// no allocation per block). Which voxels are observed, and which of those are inside (TSDF
/// < 0), are kept as one bit mask per row along x (bit x + 1 for x ∈ −1 … 9): the edges and
/// cells that cross the surface are then found for a whole row with a few bit operations, and
/// only those are visited.
struct Neighbourhood {
    tsdf: [f32; GATHER_VOXELS],
    color: [[u8; 3]; GATHER_VOXELS],
    valid: [u16; GATHER_ROWS],
    inside: [u16; GATHER_ROWS],
}

impl Neighbourhood {
    /// Gathers the neighbourhood of the block at `coord`, row by row.
    fn gather(volume: &TsdfVolume, coord: &BlockCoord, config: &MeshingConfig) -> Self {
        let mut n = Self {
            tsdf: [1.0; GATHER_VOXELS],
            color: [[0; 3]; GATHER_VOXELS],
            valid: [0; GATHER_ROWS],
            inside: [0; GATHER_ROWS],
        };
        let side = BLOCK_SIDE as i32;
        // Local range of a neighbour copied: offset −1 → its last voxel, +1 → its first two.
        let range = |o: i32| match o {
            -1 => (side - 1)..side,
            0 => 0..side,
            _ => 0..2,
        };
        for oz in -1..=1i32 {
            for oy in -1..=1i32 {
                for ox in -1..=1i32 {
                    let nb = [coord[0] + ox, coord[1] + oy, coord[2] + oz];
                    let Some(block) = volume.block(&nb) else {
                        continue;
                    };
                    let xs = range(ox);
                    let len = xs.len();
                    let x0 = ox * side + xs.start;
                    for lz in range(oz) {
                        for ly in range(oy) {
                            let (y, z) = (oy * side + ly, oz * side + lz);
                            let src = local_index(xs.start as usize, ly as usize, lz as usize);
                            let dst = gather_index(x0, y, z);
                            let tsdf = &block.tsdf[src..src + len];
                            n.tsdf[dst..dst + len].copy_from_slice(tsdf);
                            let words = &block.color[src..src + len];
                            let (mut valid, mut inside) = (0u16, 0u16);
                            for (k, ((&w, &t), &word)) in block.weight[src..src + len]
                                .iter()
                                .zip(tsdf)
                                .zip(words)
                                .enumerate()
                            {
                                if config.keeps(w, word) {
                                    let bit = 1 << (x0 + 1 + k as i32);
                                    valid |= bit;
                                    if t < 0.0 {
                                        inside |= bit;
                                    }
                                }
                            }
                            let row = row_index(y, z);
                            n.valid[row] |= valid;
                            n.inside[row] |= inside;
                            for (c, &rgbx) in n.color[dst..dst + len].iter_mut().zip(words) {
                                *c = crate::tsdf::rgb_of(rgbx);
                            }
                        }
                    }
                }
            }
        }
        n
    }

    /// Whether gathered voxel (x, y, z) is observed (above the minimum weight).
    #[inline]
    fn is_valid(&self, x: i32, y: i32, z: i32) -> bool {
        self.valid[row_index(y, z)] >> (x + 1) & 1 == 1
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
            g[a] = match (
                self.is_valid(p[0], p[1], p[2]),
                self.is_valid(m[0], m[1], m[2]),
            ) {
                (true, true) => 0.5 * (self.tsdf[ip] - self.tsdf[im]),
                (true, false) => self.tsdf[ip] - self.tsdf[c],
                (false, true) => self.tsdf[c] - self.tsdf[im],
                (false, false) => 0.0,
            };
        }
        g
    }
}

/// What one block contributes to the mesh before vertex ids are global.
struct BlockMesh {
    /// The vertices this block creates, keyed by `local_index · 3 + axis` of their edge and
    /// sorted by key.
    keys: Vec<u16>,
    positions: Vec<Point3<f32>>,
    normals: Vec<Vector3<f32>>,
    colors: Vec<[u8; 3]>,
    /// Triangles of the cells whose lower corner lies in this block, each vertex as an edge
    /// reference: owner corner (this block or a +x/+y/+z neighbour, bits 16–18) and key (bits
    /// 0–15); bit 31 of the first marks a triangle lying in a cube face.
    triangles: Vec<[u32; 3]>,
}

/// An edge reference's layout: key in the low bits, owner corner from bit 16, and the
/// in-cube-face mark in bit 31 (of a triangle's first reference).
const EDGE_KEY_MASK: u32 = 0xffff;
const OWNER_SHIFT: u32 = 16;
const IN_CUBE_FACE: u32 = 1 << 31;

impl BlockMesh {
    fn empty() -> Self {
        Self {
            keys: Vec::new(),
            positions: Vec::new(),
            normals: Vec::new(),
            colors: Vec::new(),
            triangles: Vec::new(),
        }
    }

    /// The block's vertices (every sign-changing edge starting at one of its voxels) and its
    /// cells' triangles, from one gathered neighbourhood.
    fn build(
        volume: &TsdfVolume,
        coord: &BlockCoord,
        config: &MeshingConfig,
        table: &CaseTable,
    ) -> Self {
        let mut out = Self::empty();
        let voxel = volume.config().voxel_size_m;
        let side = BLOCK_SIDE as i32;
        let n = Neighbourhood::gather(volume, coord, config);
        for z in 0..side {
            for y in 0..side {
                let r = row_index(y, z);
                let (valid, inside) = (n.valid[r], n.inside[r]);
                let (ry, rz) = (row_index(y + 1, z), row_index(y, z + 1));
                // Bit x + 1: the edge from (x, y, z) to its +axis neighbour has both ends
                // observed and changes sign.
                let crossing = [
                    valid & (valid >> 1) & (inside ^ (inside >> 1)),
                    valid & n.valid[ry] & (inside ^ n.inside[ry]),
                    valid & n.valid[rz] & (inside ^ n.inside[rz]),
                ]
                .map(|m| m & OWN_X);
                let mut bits = crossing[0] | crossing[1] | crossing[2];
                while bits != 0 {
                    let b = bits.trailing_zeros();
                    bits &= bits - 1;
                    let x = b as i32 - 1;
                    for (axis, m) in crossing.iter().enumerate() {
                        if m >> b & 1 == 1 {
                            out.push_vertex(&n, coord, [x, y, z], axis, voxel);
                        }
                    }
                }
            }
        }
        for z in 0..side {
            for y in 0..side {
                // Rows of corners c = 0 … 7 by (y, z) offset: corner c sits in row c >> 1.
                let rows = [
                    row_index(y, z),
                    row_index(y + 1, z),
                    row_index(y, z + 1),
                    row_index(y + 1, z + 1),
                ];
                let all_valid = rows.iter().fold(u16::MAX, |m, &r| m & n.valid[r]);
                let any_inside = rows.iter().fold(0, |m, &r| m | n.inside[r]);
                let all_inside = rows.iter().fold(u16::MAX, |m, &r| m & n.inside[r]);
                // Bit x + 1: cell x has all eight corners observed, some inside, not all.
                let mut cells = all_valid
                    & (all_valid >> 1)
                    & (any_inside | (any_inside >> 1))
                    & !(all_inside & (all_inside >> 1))
                    & OWN_X;
                while cells != 0 {
                    let b = cells.trailing_zeros();
                    cells &= cells - 1;
                    let x = b as i32 - 1;
                    let mut case = 0usize;
                    for c in 0..8 {
                        if n.inside[rows[c >> 1]] >> (b + (c & 1) as u32) & 1 == 1 {
                            case |= 1 << c;
                        }
                    }
                    for tri in table.triangles(case) {
                        let mut refs = tri.map(|e| edge_reference([x, y, z], e as usize));
                        let [a, b, c] = tri.map(|e| EDGE_FACES[e as usize]);
                        if a & b & c != 0 {
                            refs[0] |= IN_CUBE_FACE;
                        }
                        out.triangles.push(refs);
                    }
                }
            }
        }
        out
    }

    /// Adds the vertex on the edge from gathered voxel `at` along `axis` (both ends observed,
    /// of opposite signs), with its normal from the TSDF gradient and its colour, both
    /// interpolated along the edge.
    fn push_vertex(
        &mut self,
        n: &Neighbourhood,
        coord: &BlockCoord,
        at: [i32; 3],
        axis: usize,
        voxel_size_m: f32,
    ) {
        let side = BLOCK_SIDE as i32;
        let [x, y, z] = at;
        let mut q = at;
        q[axis] += 1;
        let (i0, i1) = (gather_index(x, y, z), gather_index(q[0], q[1], q[2]));
        let (t0, t1) = (n.tsdf[i0], n.tsdf[i1]);
        let f = t0 / (t0 - t1);
        let g = [
            coord[0] * side + x,
            coord[1] * side + y,
            coord[2] * side + z,
        ];
        let mut p = Point3::new(g[0] as f32, g[1] as f32, g[2] as f32);
        p[axis] += f;
        let normal = n.gradient(x, y, z) * (1.0 - f) + n.gradient(q[0], q[1], q[2]) * f;
        let (c0, c1) = (n.color[i0], n.color[i1]);
        self.keys
            .push((local_index(x as usize, y as usize, z as usize) * 3 + axis) as u16);
        self.positions.push(p * voxel_size_m);
        self.normals
            .push(normal.try_normalize(0.0).unwrap_or_default());
        self.colors.push(
            [0, 1, 2].map(|k| (f32::from(c0[k]) * (1.0 - f) + f32::from(c1[k]) * f).round() as u8),
        );
    }
}

/// The reference of edge `e` of the cell whose lower corner is local voxel `cell`: the block
/// owning the edge (as the corner offset of this block's +x/+y/+z neighbour that holds the
/// edge's lower end, bits 16–18) and the edge's key in that block (bits 0–15).
fn edge_reference(cell: [i32; 3], e: usize) -> u32 {
    let side = BLOCK_SIDE as i32;
    let o = corner_offset(EDGE_LOWER_CORNER[e]);
    let mut owner_corner = 0;
    let mut local = [0usize; 3];
    for a in 0..3 {
        let l = cell[a] + o[a] as i32;
        if l == side {
            owner_corner |= 1 << a;
        } else {
            local[a] = l as usize;
        }
    }
    let key = local_index(local[0], local[1], local[2]) * 3 + EDGE_AXIS[e];
    ((owner_corner << OWNER_SHIFT) | key) as u32
}

/// Extracts the zero level set of `volume` as a triangle mesh in world ENU metres, normals
/// pointing out of the surface (toward positive TSDF, i.e. toward the cameras).
pub fn extract_mesh(volume: &TsdfVolume, config: &MeshingConfig) -> TriangleMesh {
    let table = CaseTable::new();
    let coords = volume.block_coords();
    let active = active_blocks(volume, config);
    // Phase 1: each block's own edge vertices and its cells' triangles, by edge reference.
    let per_block: Vec<BlockMesh> = coords
        .par_iter()
        .zip(&active)
        .map(|(coord, &active)| {
            if active {
                BlockMesh::build(volume, coord, config, &table)
            } else {
                BlockMesh::empty()
            }
        })
        .collect();
    // Phase 2: global vertex ids by prefix sums in storage order.
    let mut offsets = Vec::with_capacity(per_block.len() + 1);
    let mut total = 0usize;
    for b in &per_block {
        offsets.push(total);
        total += b.keys.len();
    }
    // Phase 3: edge references to global vertex ids. A triangle whose edge has no vertex (its
    // owner block is not stored) is dropped. Each block's triangles, and which of them lie in a
    // cube face (the only ones that can coincide with another cell's triangle, see
    // [`remove_coincident_face_pairs`]).
    let faces_per_block: Vec<(Vec<[u32; 3]>, Vec<u32>)> = coords
        .par_iter()
        .zip(&per_block)
        .map(|(coord, block)| {
            let mut faces = Vec::with_capacity(block.triangles.len());
            let mut in_cube_face = Vec::new();
            if block.triangles.is_empty() {
                return (faces, in_cube_face);
            }
            let owners: [Option<usize>; 8] = std::array::from_fn(|c| {
                let o = corner_offset(c);
                volume.block_index(&[
                    coord[0] + o[0] as i32,
                    coord[1] + o[1] as i32,
                    coord[2] + o[2] as i32,
                ])
            });
            'triangle: for refs in &block.triangles {
                let mut ids = [0u32; 3];
                for (slot, &r) in refs.iter().enumerate() {
                    let Some(owner) = owners[((r >> OWNER_SHIFT) & 7) as usize] else {
                        continue 'triangle;
                    };
                    let key = (r & EDGE_KEY_MASK) as u16;
                    let Ok(k) = per_block[owner].keys.binary_search(&key) else {
                        continue 'triangle;
                    };
                    // Vertex counts stay below u32::MAX (TriangleMesh uses u32 ids).
                    ids[slot] = (offsets[owner] + k) as u32;
                }
                if refs[0] & IN_CUBE_FACE != 0 {
                    // Face counts stay below u32::MAX like vertex counts.
                    in_cube_face.push(faces.len() as u32);
                }
                faces.push(ids);
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
fn active_blocks(volume: &TsdfVolume, config: &MeshingConfig) -> Vec<bool> {
    const NEGATIVE: u8 = 1;
    const POSITIVE: u8 = 2;
    let signs: Vec<u8> = volume
        .blocks()
        .par_iter()
        .map(|b| {
            // Branch-free, so the loop runs in SIMD lanes: most blocks are scanned whole.
            let (mut negative, mut positive) = (false, false);
            for ((&t, &w), &word) in b.tsdf.iter().zip(b.weight.iter()).zip(b.color.iter()) {
                let observed = config.keeps(w, word);
                negative |= observed & (t < 0.0);
                positive |= observed & !(t < 0.0);
            }
            (u8::from(negative) * NEGATIVE) | (u8::from(positive) * POSITIVE)
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
    use proptest::prelude::*;

    use super::*;
    use crate::tsdf::TsdfConfig;

    /// A 2 × 2 × 2-block volume with some blocks missing and random voxels: unobserved, barely
    /// observed (under a minimum weight of 1, or seen by fewer than 3 frames) or observed, of
    /// either sign.
    fn random_volume() -> impl Strategy<Value = TsdfVolume> {
        let voxel = (0u8..3, 1u8..5, -1.0f32..1.0).prop_map(|(w, n, t)| {
            let weight = [0.0, 0.5, 2.0][w as usize];
            (t, weight, if weight > 0.0 { n } else { 0 })
        });
        let block = proptest::option::weighted(0.8, proptest::collection::vec(voxel, BLOCK_VOXELS));
        proptest::collection::vec(block, 8).prop_map(|blocks| {
            let mut volume = TsdfVolume::new(TsdfConfig::default()).expect("default config");
            for (c, voxels) in blocks.into_iter().enumerate() {
                if let Some(voxels) = voxels {
                    let o = corner_offset(c);
                    volume.insert_block_for_test([o[0] as i32, o[1] as i32, o[2] as i32], &voxels);
                }
            }
            volume
        })
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(48))]

        /// The row bit masks find exactly the edges and cells that a voxel-by-voxel scan finds.
        #[test]
        fn row_masks_find_every_crossing_edge_and_cell(
            volume in random_volume(),
            min_weight in prop_oneof![Just(0.0f32), Just(1.0f32)],
            min_observations in prop_oneof![Just(0u8), Just(3u8)],
        ) {
            let table = CaseTable::new();
            let side = BLOCK_SIDE as i32;
            let config = MeshingConfig { min_weight, min_observations, ..MeshingConfig::default() };
            let sample = |v: [i32; 3]| {
                volume
                    .voxel(v)
                    .filter(|s| {
                        s.weight > 0.0 && s.weight > min_weight && s.observations >= min_observations
                    })
                    .map(|s| s.tsdf < 0.0)
            };
            for coord in volume.block_coords() {
                let built = BlockMesh::build(&volume, coord, &config, &table);
                let mut keys = Vec::new();
                let mut triangles = 0;
                for z in 0..side {
                    for y in 0..side {
                        for x in 0..side {
                            let g = [coord[0] * side + x, coord[1] * side + y, coord[2] * side + z];
                            for axis in 0..3 {
                                let mut q = g;
                                q[axis] += 1;
                                if let (Some(a), Some(b)) = (sample(g), sample(q)) && a != b {
                                    keys.push((local_index(x as usize, y as usize, z as usize) * 3 + axis) as u16);
                                }
                            }
                            let corners: Option<Vec<bool>> = (0..8)
                                .map(|c| {
                                    let o = corner_offset(c);
                                    sample([g[0] + o[0] as i32, g[1] + o[1] as i32, g[2] + o[2] as i32])
                                })
                                .collect();
                            if let Some(corners) = corners {
                                let case = corners.iter().enumerate().fold(0, |m, (c, &i)| m | (usize::from(i) << c));
                                triangles += table.triangles(case).len();
                            }
                        }
                    }
                }
                prop_assert_eq!(&built.keys, &keys);
                prop_assert_eq!(built.triangles.len(), triangles);
            }
        }
    }

    #[test]
    fn coincident_opposite_faces_go_in_pairs() {
        let mut faces = vec![[0, 1, 2], [2, 3, 0], [0, 2, 1], [4, 5, 6]];
        remove_coincident_face_pairs(&mut faces);
        assert_eq!(faces, vec![[2, 3, 0], [4, 5, 6]]);
    }
}
