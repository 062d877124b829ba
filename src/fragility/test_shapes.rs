//! Procedural closed solids for the tests: boxes, lofts (prisms, cylinders, stacked blocks,
//! pedestals), tubes and icospheres. All wind outwards.

use std::collections::HashMap;

use nalgebra::Point3;
use scarp_slam::TriangleMesh;

use super::topology::Solid;

/// An axis-aligned box with a corner at the origin.
pub(crate) fn cuboid_solid(size: [f64; 3]) -> Solid {
    let [x, y, z] = size;
    let r = [(0.0, 0.0), (x, 0.0), (x, y), (0.0, y)];
    loft_solid(&[(&r, 0.0), (&r, z)])
}

/// `n` points on a circle of radius `r`, counter-clockwise from angle `phase` (radians).
pub(crate) fn regular_ring(n: usize, r: f64, phase: f64) -> Vec<(f64, f64)> {
    (0..n)
        .map(|k| {
            let t = phase + k as f64 * std::f64::consts::TAU / n as f64;
            (r * t.cos(), r * t.sin())
        })
        .collect()
}

/// An axis-aligned rectangle `[x0, x1] × [y0, y1]` as a counter-clockwise ring.
pub(crate) fn rect(x0: f64, y0: f64, x1: f64, y1: f64) -> Vec<(f64, f64)> {
    vec![(x0, y0), (x1, y0), (x1, y1), (x0, y1)]
}

/// A closed loft through counter-clockwise rings of equal length at increasing (or equal)
/// heights; the end caps are fans from the ring's mean, so rings must be star-shaped about it.
pub(crate) fn loft_solid(rings: &[(&[(f64, f64)], f64)]) -> Solid {
    let n = rings[0].0.len();
    let mut positions: Vec<Point3<f64>> = Vec::new();
    for (ring, z) in rings {
        assert_eq!(ring.len(), n);
        positions.extend(ring.iter().map(|&(x, y)| Point3::new(x, y, *z)));
    }
    let mut faces = Vec::new();
    for k in 0..rings.len() - 1 {
        for j in 0..n {
            let a = (k * n + j) as u32;
            let b = (k * n + (j + 1) % n) as u32;
            let c = ((k + 1) * n + (j + 1) % n) as u32;
            let d = ((k + 1) * n + j) as u32;
            faces.push([a, b, c]);
            faces.push([a, c, d]);
        }
    }
    let mut cap = |k: usize, up: bool| {
        let (ring, z) = rings[k];
        let (sx, sy) = ring.iter().fold((0.0, 0.0), |s, p| (s.0 + p.0, s.1 + p.1));
        let centre = positions.len() as u32;
        positions.push(Point3::new(sx / n as f64, sy / n as f64, z));
        for j in 0..n {
            let a = (k * n + j) as u32;
            let b = (k * n + (j + 1) % n) as u32;
            faces.push(if up { [centre, a, b] } else { [centre, b, a] });
        }
    };
    cap(0, false);
    cap(rings.len() - 1, true);
    Solid { positions, faces }
}

/// A vertical tube between two counter-clockwise rings of equal length (`inner` inside `outer`).
pub(crate) fn tube_solid(outer: &[(f64, f64)], inner: &[(f64, f64)], z0: f64, z1: f64) -> Solid {
    let n = outer.len() as u32;
    let mut positions = Vec::new();
    for z in [z0, z1] {
        positions.extend(outer.iter().map(|&(x, y)| Point3::new(x, y, z)));
    }
    for z in [z0, z1] {
        positions.extend(inner.iter().map(|&(x, y)| Point3::new(x, y, z)));
    }
    let (ob, ot, ib, it) = (0, n, 2 * n, 3 * n);
    let mut faces = Vec::new();
    for j in 0..n {
        let k = (j + 1) % n;
        faces.extend([[ob + j, ob + k, ot + k], [ob + j, ot + k, ot + j]]);
        faces.extend([[ib + j, it + j, it + k], [ib + j, it + k, ib + k]]);
        faces.extend([[ot + j, ot + k, it + k], [ot + j, it + k, it + j]]);
        faces.extend([[ob + j, ib + k, ob + k], [ob + j, ib + j, ib + k]]);
    }
    Solid { positions, faces }
}

/// An icosphere of radius `r` about the origin after `level` subdivisions.
pub(crate) fn icosphere(level: usize, r: f64) -> Solid {
    let unit = TriangleMesh::icosphere(level as u32);
    Solid {
        positions: unit
            .positions
            .iter()
            .map(|p| Point3::from(p.coords.cast::<f64>().normalize() * r))
            .collect(),
        faces: unit.faces,
    }
}

/// The solid as an f32 mesh.
pub(crate) fn to_mesh(solid: &Solid) -> TriangleMesh {
    TriangleMesh {
        positions: solid.positions.iter().map(|p| p.cast()).collect(),
        faces: solid.faces.clone(),
        ..TriangleMesh::default()
    }
}

/// Panics unless every directed edge has exactly one reverse twin.
pub(crate) fn assert_closed(solid: &Solid) {
    let mut count: HashMap<(u32, u32), i32> = HashMap::new();
    for f in &solid.faces {
        for k in 0..3 {
            *count.entry((f[k], f[(k + 1) % 3])).or_default() += 1;
        }
    }
    for (&(a, b), &c) in &count {
        assert_eq!(c, 1, "edge {a}-{b} used {c} times");
        assert_eq!(count.get(&(b, a)), Some(&1), "edge {a}-{b} has no twin");
    }
}
