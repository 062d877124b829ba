//! Connected components of a triangle mesh (faces sharing a vertex are connected).

use crate::mesh::TriangleMesh;

fn find(parent: &mut [u32], mut i: u32) -> u32 {
    while parent[i as usize] != i {
        let p = parent[parent[i as usize] as usize];
        parent[i as usize] = p;
        i = p;
    }
    i
}

/// A copy of `mesh` without the connected components of fewer than `min_triangles` faces and
/// without unreferenced vertices. Face order is preserved; vertices are renumbered in order of
/// first use. Faces with an
/// out-of-range vertex index are dropped.
pub fn remove_small_components(mesh: &TriangleMesh, min_triangles: usize) -> TriangleMesh {
    let n = mesh.positions.len();
    let in_range = |f: &&[u32; 3]| f.iter().all(|&v| (v as usize) < n);
    let faces = || mesh.faces.iter().filter(in_range);
    let mut parent: Vec<u32> = (0..n as u32).collect();
    for f in faces() {
        for &v in &f[1..] {
            let a = find(&mut parent, f[0]);
            let b = find(&mut parent, v);
            if a != b {
                let (lo, hi) = if a < b { (a, b) } else { (b, a) };
                parent[hi as usize] = lo;
            }
        }
    }
    let mut count = vec![0usize; n];
    let roots: Vec<u32> = faces().map(|f| find(&mut parent, f[0])).collect();
    for &r in &roots {
        count[r as usize] += 1;
    }
    let mut remap = vec![u32::MAX; n];
    let has_normals = mesh.normals.len() == n;
    let has_colors = mesh.colors.len() == n;
    // Room for everything kept, so the large arrays are never copied to grow (pages of the
    // room a dropped component leaves unused are never touched).
    let mut out = TriangleMesh {
        positions: Vec::with_capacity(n),
        normals: Vec::with_capacity(if has_normals { n } else { 0 }),
        colors: Vec::with_capacity(if has_colors { n } else { 0 }),
        faces: Vec::with_capacity(roots.len()),
    };
    for (f, &r) in faces().zip(&roots) {
        if count[r as usize] < min_triangles {
            continue;
        }
        let mut g = [0u32; 3];
        for (k, &v) in f.iter().enumerate() {
            if remap[v as usize] == u32::MAX {
                remap[v as usize] = out.positions.len() as u32;
                out.positions.push(mesh.positions[v as usize]);
                if has_normals {
                    out.normals.push(mesh.normals[v as usize]);
                }
                if has_colors {
                    out.colors.push(mesh.colors[v as usize]);
                }
            }
            g[k] = remap[v as usize];
        }
        out.faces.push(g);
    }
    out
}
