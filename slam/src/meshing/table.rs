//! The marching-cubes case table, derived at run time from a face rule instead of copied.
//!
//! Corner `c` of a cell sits at offset (c & 1, (c >> 1) & 1, (c >> 2) & 1). Edge `e` runs along
//! axis `e / 4` from its lower corner [`EDGE_LOWER_CORNER`]`[e]`. A case index has bit `c` set
//! when corner `c` is inside (TSDF < 0).
//!
//! On each cube face the iso-contour is a set of segments between that face's sign-changing
//! edges. On an ambiguous face (diagonal corners alike) the inside corners are cut off
//! separately, so the outside region is connected across the face. The rule depends only on
//! the face's four signs, which both cells sharing the face see alike, so the mesh has no
//! cracks. Segments are oriented so that the surface normal points outside (toward positive
//! TSDF); they chain into closed loops, which are fan-triangulated.

/// The lower corner of each of the 12 edges.
pub const EDGE_LOWER_CORNER: [usize; 12] = [0, 2, 4, 6, 0, 1, 4, 5, 0, 1, 2, 3];

/// Axis (0 = x, 1 = y, 2 = z) of each edge.
pub const EDGE_AXIS: [usize; 12] = [0, 0, 0, 0, 1, 1, 1, 1, 2, 2, 2, 2];

/// Corner offsets (x, y, z) ∈ {0, 1}³.
pub const fn corner_offset(c: usize) -> [usize; 3] {
    [c & 1, (c >> 1) & 1, (c >> 2) & 1]
}

/// The edge joining corners `a` and `b` (which differ in one bit).
fn edge_between(a: usize, b: usize) -> usize {
    let (lo, hi) = if a < b { (a, b) } else { (b, a) };
    let axis = (hi ^ lo).trailing_zeros() as usize;
    (0..12)
        .find(|&e| EDGE_AXIS[e] == axis && EDGE_LOWER_CORNER[e] == lo)
        .unwrap_or(0)
}

fn edge_midpoint(e: usize) -> [f32; 3] {
    let mut p = corner_offset(EDGE_LOWER_CORNER[e]).map(|v| v as f32);
    p[EDGE_AXIS[e]] += 0.5;
    p
}

/// Triangles (as edge triples) for each of the 256 cases.
#[derive(Debug, Clone)]
pub struct CaseTable {
    cases: Vec<Vec<[u8; 3]>>,
}

impl CaseTable {
    /// Builds the table (microseconds).
    pub fn new() -> Self {
        Self {
            cases: (0..256).map(triangulate_case).collect(),
        }
    }

    /// Triangles of case `index` (bit c set ⇔ corner c inside).
    pub fn triangles(&self, index: usize) -> &[[u8; 3]] {
        &self.cases[index]
    }
}

impl Default for CaseTable {
    fn default() -> Self {
        Self::new()
    }
}

fn triangulate_case(case: usize) -> Vec<[u8; 3]> {
    let inside = |c: usize| case >> c & 1 == 1;
    // next[e] = the edge that follows e along its contour loop.
    let mut next = [usize::MAX; 12];
    for axis in 0..3 {
        for side in 0..2 {
            // Corners of this face in cyclic order around it.
            let (a1, a2) = ((axis + 1) % 3, (axis + 2) % 3);
            let corner = |i: usize, j: usize| (side << axis) | (i << a1) | (j << a2);
            let ring = [corner(0, 0), corner(1, 0), corner(1, 1), corner(0, 1)];
            let mut normal = [0.0f32; 3];
            normal[axis] = if side == 1 { 1.0 } else { -1.0 };
            let mut segments: Vec<(usize, usize, [f32; 3])> = Vec::new();
            let inside_count = ring.iter().filter(|&&c| inside(c)).count();
            let ambiguous = inside_count == 2 && inside(ring[0]) == inside(ring[2]);
            if ambiguous {
                // Cut off each inside corner on its own.
                for k in 0..4 {
                    if inside(ring[k]) {
                        let prev = ring[(k + 3) % 4];
                        let nxt = ring[(k + 1) % 4];
                        let g = sub(face_centre(&ring), corner_f(ring[k]));
                        segments.push((edge_between(ring[k], prev), edge_between(ring[k], nxt), g));
                    }
                }
            } else if inside_count == 1 || inside_count == 2 || inside_count == 3 {
                let crossing: Vec<usize> = (0..4)
                    .filter(|&k| inside(ring[k]) != inside(ring[(k + 1) % 4]))
                    .map(|k| edge_between(ring[k], ring[(k + 1) % 4]))
                    .collect();
                if crossing.len() == 2 {
                    let (mut plus, mut minus) = ([0.0f32; 3], [0.0f32; 3]);
                    for &c in &ring {
                        let p = corner_f(c);
                        let acc = if inside(c) { &mut minus } else { &mut plus };
                        for a in 0..3 {
                            acc[a] += p[a];
                        }
                    }
                    let n_in = inside_count as f32;
                    let n_out = 4.0 - n_in;
                    let g = [0, 1, 2].map(|a| plus[a] / n_out - minus[a] / n_in);
                    segments.push((crossing[0], crossing[1], g));
                }
            }
            for (e0, e1, g) in segments {
                // Orientation: travel along g × n (outward normal of the surface = g).
                let t = cross(g, normal);
                let d = sub(edge_midpoint(e1), edge_midpoint(e0));
                let (from, to) = if dot(t, d) >= 0.0 { (e0, e1) } else { (e1, e0) };
                next[from] = to;
            }
        }
    }
    let mut triangles = Vec::new();
    let mut visited = [false; 12];
    for start in 0..12 {
        if next[start] == usize::MAX || visited[start] {
            continue;
        }
        let mut loop_edges = Vec::new();
        let mut e = start;
        while !visited[e] && next[e] != usize::MAX {
            visited[e] = true;
            loop_edges.push(e);
            e = next[e];
        }
        for k in 1..loop_edges.len().saturating_sub(1) {
            triangles.push([loop_edges[0], loop_edges[k], loop_edges[k + 1]].map(|x| x as u8));
        }
    }
    triangles
}

fn corner_f(c: usize) -> [f32; 3] {
    corner_offset(c).map(|v| v as f32)
}

fn face_centre(ring: &[usize; 4]) -> [f32; 3] {
    let mut p = [0.0; 3];
    for &c in ring {
        let q = corner_f(c);
        for a in 0..3 {
            p[a] += 0.25 * q[a];
        }
    }
    p
}

fn sub(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn cross(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn table_basics() {
        let table = CaseTable::new();
        assert!(table.triangles(0).is_empty());
        assert!(table.triangles(255).is_empty());
        // One corner inside: one triangle on its three edges.
        assert_eq!(table.triangles(1).len(), 1);
        let mut t = table.triangles(1)[0];
        t.sort_unstable();
        assert_eq!(t, [0, 4, 8]);
        // Half the cube inside (z = 0 face): a quad, two triangles.
        assert_eq!(table.triangles(0b0000_1111).len(), 2);
        // Every case uses each crossing edge, and each triangle normal points outside.
        for case in 1..255usize {
            for tri in table.triangles(case) {
                let p = tri.map(|e| edge_midpoint(e as usize));
                let n = cross(sub(p[1], p[0]), sub(p[2], p[0]));
                // The outside direction near the triangle: away from inside corners.
                let c = [0, 1, 2].map(|a| (p[0][a] + p[1][a] + p[2][a]) / 3.0);
                let mut g = [0.0f32; 3];
                for corner in 0..8 {
                    let q = corner_f(corner);
                    let d = sub(q, c);
                    let w = 1.0 / (dot(d, d) + 1e-3);
                    let sign = if case >> corner & 1 == 1 { -1.0 } else { 1.0 };
                    for a in 0..3 {
                        g[a] += sign * w * d[a];
                    }
                }
                assert!(
                    dot(n, g) > 0.0,
                    "case {case}: triangle {tri:?} faces inside"
                );
            }
        }
    }
}
