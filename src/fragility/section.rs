//! Horizontal plane sections of a closed surface, cutting a solid at a height and closing the cut
//! by triangulating the section polygons (non-convex, with holes: holes are bridged into their
//! outer loop, then the polygon is ear-clipped).
//!
//! All geometry here is in the levelled frame (z up, metres). A section at height `h` is a set
//! of closed loops oriented with the solid's material on their left seen from above, so outer
//! boundaries run counter-clockwise and holes clockwise.

use std::collections::HashMap;

use nalgebra::{Point2, Point3};

use super::FragilityError;
use super::topology::Solid;

/// Which limit of the section is taken when vertices or faces lie exactly on the plane.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Side {
    /// A vertex counts as above iff `z > h`: the section just above `h` (a face lying on the
    /// plane belongs to the part below).
    Above,
    /// A vertex counts as above iff `z >= h`: the section just below `h`.
    Below,
}

#[inline]
fn is_above(z: f64, h: f64, side: Side) -> bool {
    match side {
        Side::Above => z > h,
        Side::Below => z >= h,
    }
}

/// Identity of a section point: an edge crossing, or a vertex lying exactly on the plane (shared
/// by every edge that crosses there).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
enum Key {
    Vertex(u32),
    Edge(u32, u32),
}

/// The crossing of the plane with the edge between vertices `a` and `b`, one above and one not.
/// Computed from the canonical (low index, high index) order so both faces of an edge agree
/// bit for bit.
fn crossing(positions: &[Point3<f64>], a: u32, b: u32, h: f64) -> (Key, Point3<f64>) {
    let (lo, hi) = if a < b { (a, b) } else { (b, a) };
    let (p, q) = (positions[lo as usize], positions[hi as usize]);
    if p.z == h {
        return (Key::Vertex(lo), p);
    }
    if q.z == h {
        return (Key::Vertex(hi), q);
    }
    // One end is above and the other not, so q.z != p.z.
    let t = (h - p.z) / (q.z - p.z);
    (
        Key::Edge(lo, hi),
        Point3::new(p.x + t * (q.x - p.x), p.y + t * (q.y - p.y), h),
    )
}

/// For a face straddling the plane, the edges where its section segment starts and ends
/// (`(i, j)` vertex pairs in winding order). The segment runs from the crossing of the edge
/// leaving the upper part to the crossing of the edge entering it, which puts the material on
/// its left seen from above.
#[inline]
fn face_segment(f: &[u32; 3], up: [bool; 3]) -> Option<((u32, u32), (u32, u32))> {
    let (mut start, mut end) = (None, None);
    for k in 0..3 {
        let l = (k + 1) % 3;
        if up[k] && !up[l] {
            start = Some((f[k], f[l]));
        } else if !up[k] && up[l] {
            end = Some((f[k], f[l]));
        }
    }
    Some((start?, end?))
}

/// Signed area (m²) of the section at height `h`: outer loops count positive, holes negative.
/// Needs no loop building: each face contributes its oriented segment to the shoelace sum.
pub(crate) fn section_area(solid: &Solid, h: f64, side: Side) -> f64 {
    let pos = &solid.positions;
    let Some(origin) = pos.first().map(|p| Point2::new(p.x, p.y)) else {
        return 0.0;
    };
    let mut twice = 0.0;
    for f in &solid.faces {
        let up = f.map(|v| is_above(pos[v as usize].z, h, side));
        if up[0] == up[1] && up[1] == up[2] {
            continue;
        }
        if let Some(((a, b), (c, d))) = face_segment(f, up) {
            let s = crossing(pos, a, b, h).1;
            let e = crossing(pos, c, d, h).1;
            let (sx, sy) = (s.x - origin.x, s.y - origin.y);
            let (ex, ey) = (e.x - origin.x, e.y - origin.y);
            twice += sx * ey - sy * ex;
        }
    }
    0.5 * twice
}

/// For each face straddling height `h`, the two section points, as `(start, end)`.
pub(crate) fn section_segments(
    solid: &Solid,
    h: f64,
    side: Side,
) -> impl Iterator<Item = (Point3<f64>, Point3<f64>)> + '_ {
    let pos = &solid.positions;
    solid.faces.iter().filter_map(move |f| {
        let up = f.map(|v| is_above(pos[v as usize].z, h, side));
        let ((a, b), (c, d)) = face_segment(f, up)?;
        Some((crossing(pos, a, b, h).1, crossing(pos, c, d, h).1))
    })
}

/// Section points and the oriented segments between them.
#[derive(Default)]
struct Crossings {
    index: HashMap<Key, u32>,
    points: Vec<Point3<f64>>,
    segments: Vec<(u32, u32)>,
}

impl Crossings {
    fn point(&mut self, positions: &[Point3<f64>], a: u32, b: u32, h: f64) -> u32 {
        let (key, p) = crossing(positions, a, b, h);
        let next = self.points.len() as u32;
        let id = *self.index.entry(key).or_insert(next);
        if id == next {
            self.points.push(p);
        }
        id
    }

    /// Chains the segments into closed loops of point indices.
    fn loops(&self, h: f64) -> Result<Vec<Vec<u32>>, FragilityError> {
        let mut outgoing: Vec<Vec<u32>> = vec![Vec::new(); self.points.len()];
        for (s, &(a, _)) in self.segments.iter().enumerate() {
            outgoing[a as usize].push(s as u32);
        }
        let mut used = vec![false; self.segments.len()];
        let mut loops = Vec::new();
        for first in 0..self.segments.len() {
            if used[first] {
                continue;
            }
            used[first] = true;
            let (start, mut at) = self.segments[first];
            let mut ring = vec![start];
            let mut steps = 0usize;
            while at != start {
                ring.push(at);
                let next = outgoing[at as usize]
                    .iter()
                    .copied()
                    .find(|&s| !used[s as usize])
                    .ok_or(FragilityError::OpenSection {
                        height_m: h,
                        reason: "a section segment has no continuation (open or non-manifold surface)",
                    })?;
                used[next as usize] = true;
                at = self.segments[next as usize].1;
                steps += 1;
                if steps > self.segments.len() {
                    return Err(FragilityError::OpenSection {
                        height_m: h,
                        reason: "section loop does not return to its start",
                    });
                }
            }
            if ring.len() >= 3 {
                loops.push(ring);
            }
        }
        Ok(loops)
    }
}

/// The section of a closed surface by the plane `z = h`.
#[derive(Debug, Clone, Default, PartialEq)]
pub(crate) struct Section {
    /// Height of the plane, metres.
    pub height: f64,
    /// Section points (z = `height`).
    pub points: Vec<Point3<f64>>,
    /// Closed loops of indices into `points`: outer loops counter-clockwise, holes clockwise.
    pub loops: Vec<Vec<u32>>,
}

impl Section {
    /// Signed area of all loops, m².
    pub fn area(&self) -> f64 {
        let pts: Vec<Point2<f64>> = self.points.iter().map(|p| p.xy()).collect();
        self.loops.iter().map(|l| ring_area(&pts, l)).sum()
    }
}

/// The section of `solid` by `z = h` as closed loops.
///
/// # Errors
/// [`FragilityError::OpenSection`] when the segments do not close (the surface is not a closed
/// 2-manifold near `h`).
#[cfg(test)]
pub(crate) fn plane_section(solid: &Solid, h: f64, side: Side) -> Result<Section, FragilityError> {
    let pos = &solid.positions;
    let mut cr = Crossings::default();
    for f in &solid.faces {
        let up = f.map(|v| is_above(pos[v as usize].z, h, side));
        if let Some(((a, b), (c, d))) = face_segment(f, up) {
            let s = cr.point(pos, a, b, h);
            let e = cr.point(pos, c, d, h);
            if s != e {
                cr.segments.push((s, e));
            }
        }
    }
    let loops = cr.loops(h)?;
    Ok(Section {
        height: h,
        points: cr.points,
        loops,
    })
}

/// A solid cut at a height and closed.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Cut {
    /// The closed part above the plane; the cap faces point down.
    pub solid: Solid,
    /// The section at the cut; point `i` is vertex `section_offset + i` of `solid`.
    pub section: Section,
    /// Index of the first section vertex in `solid.positions`.
    pub section_offset: u32,
    /// Number of cap triangles that fell back to a fan (a polygon the ear clipper could not
    /// resolve); the closed surface then overlaps itself in the cap but its volume integrals
    /// stay exact.
    pub fan_fallbacks: usize,
}

/// Keeps the part of `solid` strictly above `z = h` and closes it with the triangulated section,
/// so the result is watertight (every edge shared by two faces, shared vertices).
///
/// # Errors
/// [`FragilityError::OpenSection`] when the section does not close.
pub(crate) fn cut_above(solid: &Solid, h: f64) -> Result<Cut, FragilityError> {
    let side = Side::Above;
    let pos = &solid.positions;
    let mut map = vec![u32::MAX; pos.len()];
    let mut out: Vec<Point3<f64>> = Vec::new();
    for (v, p) in pos.iter().enumerate() {
        if is_above(p.z, h, side) {
            map[v] = out.len() as u32;
            out.push(*p);
        }
    }
    let offset = out.len() as u32;
    let mut cr = Crossings::default();
    let mut faces: Vec<[u32; 3]> = Vec::with_capacity(solid.faces.len());
    for f in &solid.faces {
        let up = f.map(|v| is_above(pos[v as usize].z, h, side));
        match up.iter().filter(|&&u| u).count() {
            3 => faces.push(f.map(|v| map[v as usize])),
            0 => {}
            _ => {
                let mut poly = [0u32; 4];
                let mut n = 0;
                let (mut start, mut end) = (0, 0);
                for k in 0..3 {
                    let l = (k + 1) % 3;
                    if up[k] {
                        poly[n] = map[f[k] as usize];
                        n += 1;
                    }
                    if up[k] != up[l] {
                        let c = cr.point(pos, f[k], f[l], h);
                        poly[n] = offset + c;
                        n += 1;
                        if up[k] {
                            start = c;
                        } else {
                            end = c;
                        }
                    }
                }
                if start != end {
                    cr.segments.push((start, end));
                }
                for t in 1..n - 1 {
                    let tri = [poly[0], poly[t], poly[t + 1]];
                    if tri[0] != tri[1] && tri[1] != tri[2] && tri[2] != tri[0] {
                        faces.push(tri);
                    }
                }
            }
        }
    }
    let loops = cr.loops(h)?;
    let flat: Vec<Point2<f64>> = cr.points.iter().map(|p| p.xy()).collect();
    let (cap, fan_fallbacks) = triangulate(&flat, &loops);
    // The cap closes the solid from below: its outward normal is −z, so reverse the CCW triangles.
    faces.extend(
        cap.into_iter()
            .map(|[a, b, c]| [offset + a, offset + c, offset + b]),
    );
    out.extend_from_slice(&cr.points);
    Ok(Cut {
        solid: Solid {
            positions: out,
            faces,
        },
        section: Section {
            height: h,
            points: cr.points,
            loops,
        },
        section_offset: offset,
        fan_fallbacks,
    })
}

/// Twice the signed area of triangle `a, b, c` (positive when counter-clockwise).
#[inline]
pub(crate) fn orient(a: &Point2<f64>, b: &Point2<f64>, c: &Point2<f64>) -> f64 {
    (b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x)
}

/// Signed area of a closed ring of indices into `points`, m².
pub(crate) fn ring_area(points: &[Point2<f64>], ring: &[u32]) -> f64 {
    let Some(&first) = ring.first() else {
        return 0.0;
    };
    let o = points[first as usize];
    let mut twice = 0.0;
    for k in 0..ring.len() {
        let a = points[ring[k] as usize] - o;
        let b = points[ring[(k + 1) % ring.len()] as usize] - o;
        twice += a.x * b.y - a.y * b.x;
    }
    0.5 * twice
}

/// Even-odd point-in-polygon test for a ring of indices.
fn inside_ring(points: &[Point2<f64>], ring: &[u32], p: &Point2<f64>) -> bool {
    let mut inside = false;
    let n = ring.len();
    for k in 0..n {
        let a = points[ring[k] as usize];
        let b = points[ring[(k + 1) % n] as usize];
        if (a.y > p.y) != (b.y > p.y) {
            let x = a.x + (p.y - a.y) / (b.y - a.y) * (b.x - a.x);
            if p.x < x {
                inside = !inside;
            }
        }
    }
    inside
}

/// Triangulates section loops (outer loops counter-clockwise, holes clockwise) into
/// counter-clockwise triangles over the same point indices. Returns the triangles and the number
/// of polygons that fell back to a signed fan because hole bridging or ear clipping failed; a fan
/// covers the polygon with the right signed area, so volume integrals stay exact.
pub(crate) fn triangulate(points: &[Point2<f64>], loops: &[Vec<u32>]) -> (Vec<[u32; 3]>, usize) {
    let areas: Vec<f64> = loops.iter().map(|l| ring_area(points, l)).collect();
    let outers: Vec<usize> = (0..loops.len()).filter(|&i| areas[i] > 0.0).collect();
    let mut holes_of: Vec<Vec<usize>> = vec![Vec::new(); loops.len()];
    let mut orphans = Vec::new();
    for (i, l) in loops.iter().enumerate() {
        if areas[i] > 0.0 {
            continue;
        }
        let probe = points[l[0] as usize];
        // The smallest outer loop around the hole is its parent.
        let parent = outers
            .iter()
            .copied()
            .filter(|&o| inside_ring(points, &loops[o], &probe))
            .min_by(|&a, &b| areas[a].total_cmp(&areas[b]));
        match parent {
            Some(o) => holes_of[o].push(i),
            None => orphans.push(i),
        }
    }
    let mut triangles = Vec::new();
    let mut fallbacks = 0;
    for &o in &outers {
        let holes: Vec<&[u32]> = holes_of[o].iter().map(|&h| loops[h].as_slice()).collect();
        let merged = merge_holes(points, &loops[o], &holes);
        let ok = match merged {
            Some(ring) => ear_clip(points, &ring, &mut triangles),
            None => false,
        };
        if !ok {
            fallbacks += 1;
            fan(&loops[o], &mut triangles);
            for h in &holes {
                fan(h, &mut triangles);
            }
        }
    }
    for &h in &orphans {
        fallbacks += 1;
        fan(&loops[h], &mut triangles);
    }
    (triangles, fallbacks)
}

/// A fan from the ring's first vertex: signed triangles whose sum is the ring's region.
fn fan(ring: &[u32], out: &mut Vec<[u32; 3]>) {
    for k in 1..ring.len().saturating_sub(1) {
        out.push([ring[0], ring[k], ring[k + 1]]);
    }
}

/// Whether segments `p1p2` and `q1q2` cross at a point interior to both (touching at shared
/// endpoints does not count).
fn segments_cross(p1: &Point2<f64>, p2: &Point2<f64>, q1: &Point2<f64>, q2: &Point2<f64>) -> bool {
    let d1 = orient(q1, q2, p1);
    let d2 = orient(q1, q2, p2);
    let d3 = orient(p1, p2, q1);
    let d4 = orient(p1, p2, q2);
    if ((d1 > 0.0 && d2 < 0.0) || (d1 < 0.0 && d2 > 0.0))
        && ((d3 > 0.0 && d4 < 0.0) || (d3 < 0.0 && d4 > 0.0))
    {
        return true;
    }
    // Collinear overlap also blocks a bridge.
    let on = |a: &Point2<f64>, b: &Point2<f64>, p: &Point2<f64>| {
        p.x >= a.x.min(b.x) && p.x <= a.x.max(b.x) && p.y >= a.y.min(b.y) && p.y <= a.y.max(b.y)
    };
    (d1 == 0.0 && on(q1, q2, p1) && p1 != q1 && p1 != q2)
        || (d2 == 0.0 && on(q1, q2, p2) && p2 != q1 && p2 != q2)
        || (d3 == 0.0 && on(p1, p2, q1) && q1 != p1 && q1 != p2)
        || (d4 == 0.0 && on(p1, p2, q2) && q2 != p1 && q2 != p2)
}

/// Joins each hole to the outer ring with a zero-width bridge to a visible vertex, giving one
/// weakly simple counter-clockwise ring. `None` when no bridge is found.
fn merge_holes(points: &[Point2<f64>], outer: &[u32], holes: &[&[u32]]) -> Option<Vec<u32>> {
    let mut ring = outer.to_vec();
    let mut order: Vec<(usize, usize)> = holes
        .iter()
        .enumerate()
        .map(|(i, h)| {
            let m = (0..h.len())
                .max_by(|&a, &b| points[h[a] as usize].x.total_cmp(&points[h[b] as usize].x))
                .unwrap_or(0);
            (i, m)
        })
        .collect();
    order.sort_by(|a, b| {
        let xa = points[holes[a.0][a.1] as usize].x;
        let xb = points[holes[b.0][b.1] as usize].x;
        xb.total_cmp(&xa)
    });
    let edges_of = |r: &[u32]| -> Vec<(u32, u32)> {
        (0..r.len()).map(|k| (r[k], r[(k + 1) % r.len()])).collect()
    };
    let hole_edges: Vec<(u32, u32)> = holes.iter().flat_map(|h| edges_of(h)).collect();
    for (hi, mi) in order {
        let hole = holes[hi];
        let mv = hole[mi];
        let m = points[mv as usize];
        let mut candidates: Vec<usize> = (0..ring.len()).collect();
        candidates.sort_by(|&a, &b| {
            let da = (points[ring[a] as usize] - m).norm_squared();
            let db = (points[ring[b] as usize] - m).norm_squared();
            da.total_cmp(&db)
        });
        let ring_edges = edges_of(&ring);
        let chosen = candidates.into_iter().find(|&c| {
            let p = points[ring[c] as usize];
            if p == m {
                return false;
            }
            let blocked = ring_edges
                .iter()
                .chain(&hole_edges)
                .any(|&(a, b)| segments_cross(&m, &p, &points[a as usize], &points[b as usize]));
            if blocked {
                return false;
            }
            // The bridge must run through material: inside the outer ring and outside every hole.
            let mid = Point2::from((m.coords + p.coords) * 0.5);
            inside_ring(points, outer, &mid) && !holes.iter().any(|h| inside_ring(points, h, &mid))
        })?;
        let mut merged = Vec::with_capacity(ring.len() + hole.len() + 2);
        merged.extend_from_slice(&ring[..=chosen]);
        merged.extend((0..=hole.len()).map(|k| hole[(mi + k) % hole.len()]));
        merged.extend_from_slice(&ring[chosen..]);
        ring = merged;
    }
    Some(ring)
}

/// Whether `p` lies inside or on the counter-clockwise triangle `a, b, c`.
fn in_triangle(a: &Point2<f64>, b: &Point2<f64>, c: &Point2<f64>, p: &Point2<f64>) -> bool {
    orient(a, b, p) >= 0.0 && orient(b, c, p) >= 0.0 && orient(c, a, p) >= 0.0
}

/// Ear-clips a weakly simple counter-clockwise ring. Returns `false` (having emitted nothing)
/// when it gets stuck, so the caller can fall back.
fn ear_clip(points: &[Point2<f64>], ring: &[u32], out: &mut Vec<[u32; 3]>) -> bool {
    let n = ring.len();
    if n < 3 {
        return true;
    }
    let p = |k: usize| &points[ring[k] as usize];
    let mut prev: Vec<usize> = (0..n).map(|i| (i + n - 1) % n).collect();
    let mut next: Vec<usize> = (0..n).map(|i| (i + 1) % n).collect();
    let mut alive = vec![true; n];
    let mut emitted = Vec::with_capacity(n - 2);
    let mut remaining = n;
    let mut i = 0;
    let mut misses = 0;
    while remaining > 3 {
        let (a, c) = (prev[i], next[i]);
        let turn = orient(p(a), p(i), p(c));
        let ear = turn >= 0.0
            && (turn == 0.0
                || !(0..n).any(|k| {
                    alive[k]
                        && k != a
                        && k != i
                        && k != c
                        && p(k) != p(a)
                        && p(k) != p(i)
                        && p(k) != p(c)
                        && in_triangle(p(a), p(i), p(c), p(k))
                }));
        if ear {
            emitted.push([ring[a], ring[i], ring[c]]);
            next[a] = c;
            prev[c] = a;
            alive[i] = false;
            remaining -= 1;
            i = a;
            misses = 0;
        } else {
            i = next[i];
            misses += 1;
            if misses > remaining {
                return false;
            }
        }
    }
    emitted.push([ring[prev[i]], ring[i], ring[next[i]]]);
    out.extend(emitted);
    true
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fragility::test_shapes::{cuboid_solid, loft_solid, regular_ring};

    #[test]
    fn cube_section_is_counter_clockwise_with_unit_area() {
        let cube = cuboid_solid([1.0, 2.0, 3.0]);
        for side in [Side::Above, Side::Below] {
            assert!((section_area(&cube, 1.5, side) - 2.0).abs() < 1e-12);
            let s = plane_section(&cube, 1.5, side).unwrap();
            assert_eq!(s.loops.len(), 1);
            assert!((s.area() - 2.0).abs() < 1e-12);
        }
        // At the bottom face: from above the section is the base, from below nothing.
        assert!((section_area(&cube, 0.0, Side::Above) - 2.0).abs() < 1e-12);
        assert_eq!(section_area(&cube, 0.0, Side::Below), 0.0);
    }

    #[test]
    fn cut_closes_watertight_and_keeps_volume() {
        // An annulus-shaped solid (a square tube) gives a section with a hole.
        let outer = regular_ring(4, 2.0, 0.3);
        let inner = regular_ring(4, 1.0, 0.3);
        let tube = crate::fragility::test_shapes::tube_solid(&outer, &inner, 0.0, 2.0);
        let cut = cut_above(&tube, 0.5).unwrap();
        assert_eq!(cut.fan_fallbacks, 0);
        assert_eq!(cut.section.loops.len(), 2);
        let area = cut.section.area();
        let expected = 0.5 * 4.0 * (4.0 - 1.0) * (std::f64::consts::FRAC_PI_2).sin();
        assert!((area - expected).abs() < 1e-9, "{area} vs {expected}");
        let m = crate::fragility::mass::integrate(&cut.solid).unwrap();
        assert!((m.volume_m3 - expected * 1.5).abs() < 1e-9);
        crate::fragility::test_shapes::assert_closed(&cut.solid);
    }

    #[test]
    fn non_convex_star_is_ear_clipped() {
        let star: Vec<(f64, f64)> = (0..20)
            .map(|k| {
                let t = k as f64 * std::f64::consts::TAU / 20.0;
                let r = if k % 2 == 0 { 1.0 } else { 0.35 };
                (r * t.cos(), r * t.sin())
            })
            .collect();
        let solid = loft_solid(&[(&star, 0.0), (&star, 1.0)]);
        let cut = cut_above(&solid, 0.25).unwrap();
        assert_eq!(cut.fan_fallbacks, 0);
        let a = cut.section.area();
        let m = crate::fragility::mass::integrate(&cut.solid).unwrap();
        assert!((m.volume_m3 - 0.75 * a).abs() < 1e-9);
        crate::fragility::test_shapes::assert_closed(&cut.solid);
        // Every cap triangle is counter-clockwise (non-negative area) before reversal.
        let pts: Vec<Point2<f64>> = cut.section.points.iter().map(|p| p.xy()).collect();
        let (tris, _) = triangulate(&pts, &cut.section.loops);
        assert!(tris.iter().all(|t| orient(
            &pts[t[0] as usize],
            &pts[t[1] as usize],
            &pts[t[2] as usize]
        ) >= 0.0));
        let sum: f64 = tris
            .iter()
            .map(|t| {
                0.5 * orient(
                    &pts[t[0] as usize],
                    &pts[t[1] as usize],
                    &pts[t[2] as usize],
                )
            })
            .sum();
        assert!((sum - a).abs() < 1e-12);
    }

    #[test]
    fn cutting_at_a_vertex_level_snaps_and_stays_closed() {
        let cube = cuboid_solid([1.0, 1.0, 1.0]);
        let cut = cut_above(&cube, 0.0).unwrap();
        crate::fragility::test_shapes::assert_closed(&cut.solid);
        let m = crate::fragility::mass::integrate(&cut.solid).unwrap();
        assert!((m.volume_m3 - 1.0).abs() < 1e-12);
    }
}
