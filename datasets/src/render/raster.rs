//! Triangle setup (culling, near-plane clipping, projection) and tile rasterization.

use nalgebra::{Point3, Vector3};
use scarp_slam::PinholeCamera;

/// Side of a square screen tile, pixels.
pub const TILE_SIZE: u32 = 32;

/// A projected triangle ready to rasterize.
#[derive(Debug, Clone, Copy)]
pub struct SetupTriangle {
    /// Screen positions (u, v), pixels, ordered so the signed area is positive.
    pub screen: [[f64; 2]; 3],
    /// 1/z at each corner, 1/metres.
    pub inv_z: [f64; 3],
    /// Inclusive pixel bounds `[u0, v0, u1, v1]`, clamped to the image.
    pub bbox: [u32; 4],
    /// Index of the source layer.
    pub layer: u16,
    /// The unclipped face's corners in camera coordinates, metres.
    pub corners: [Point3<f64>; 3],
    /// The face's unnormalised normal (b − a) × (c − a), camera frame.
    pub normal: Vector3<f64>,
    /// Light (ambient + diffuse, in [0, 1]) at each corner, interpolated across the face
    /// (Gouraud shading); set by the caller after setup.
    pub corner_light: [f32; 3],
}

/// A face clipped against the near plane: up to 4 corners (a triangle loses one corner and
/// gains two), kept on the stack because setup runs for every visible face of every frame.
struct ClippedPolygon {
    corners: [Point3<f64>; 4],
    len: usize,
}

impl ClippedPolygon {
    fn push(&mut self, p: Point3<f64>) {
        self.corners[self.len] = p;
        self.len += 1;
    }
}

/// Sets up one camera-space triangle: culls back faces (faces wound clockwise seen from the
/// camera), clips against z = `near_m`, projects, and appends 0–2 screen triangles to `out`.
pub fn setup_triangle(
    camera: &PinholeCamera,
    corners: &[Point3<f64>; 3],
    layer: u16,
    near_m: f64,
    out: &mut Vec<SetupTriangle>,
) {
    let [a, b, c] = corners;
    let normal = (b - a).cross(&(c - a));
    if normal.dot(&a.coords) >= 0.0 {
        return;
    }
    let inside = corners.map(|p| p.z >= near_m);
    let mut polygon = ClippedPolygon {
        corners: [Point3::origin(); 4],
        len: 0,
    };
    if inside.iter().all(|&i| i) {
        corners.iter().for_each(|&p| polygon.push(p));
    } else if inside.iter().any(|&i| i) {
        for k in 0..3 {
            let (p, q) = (corners[k], corners[(k + 1) % 3]);
            if p.z >= near_m {
                polygon.push(p);
            }
            if (p.z >= near_m) != (q.z >= near_m) {
                let t = (near_m - p.z) / (q.z - p.z);
                polygon.push(p + (q - p) * t);
            }
        }
    } else {
        return;
    }
    let polygon = &polygon.corners[..polygon.len];
    for k in 1..polygon.len() - 1 {
        let tri = [polygon[0], polygon[k], polygon[k + 1]];
        let mut screen = tri.map(|p| {
            [
                camera.fx * p.x / p.z + camera.cx,
                camera.fy * p.y / p.z + camera.cy,
            ]
        });
        let mut inv_z = tri.map(|p| 1.0 / p.z);
        let area = edge(&screen[0], &screen[1], &screen[2]);
        if !(area.abs() > 1e-12) {
            continue;
        }
        if area < 0.0 {
            screen.swap(1, 2);
            inv_z.swap(1, 2);
        }
        let (min_u, max_u) = min_max(screen.map(|s| s[0]));
        let (min_v, max_v) = min_max(screen.map(|s| s[1]));
        let u0 = min_u.ceil().max(0.0);
        let v0 = min_v.ceil().max(0.0);
        let u1 = max_u.floor().min(f64::from(camera.width) - 1.0);
        let v1 = max_v.floor().min(f64::from(camera.height) - 1.0);
        if u0 > u1 || v0 > v1 {
            continue;
        }
        out.push(SetupTriangle {
            screen,
            inv_z,
            bbox: [u0 as u32, v0 as u32, u1 as u32, v1 as u32],
            layer,
            corners: *corners,
            normal,
            corner_light: [1.0; 3],
        });
    }
}

fn min_max(values: [f64; 3]) -> (f64, f64) {
    (
        values[0].min(values[1]).min(values[2]),
        values[0].max(values[1]).max(values[2]),
    )
}

/// Edge function of p against the directed edge a→b; positive on the interior side of a
/// positively oriented triangle.
fn edge(a: &[f64; 2], b: &[f64; 2], p: &[f64; 2]) -> f64 {
    (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0])
}

/// Whether a→b is a top or left edge (top-left fill rule), so pixels on shared edges are drawn
/// exactly once.
fn is_top_left(a: &[f64; 2], b: &[f64; 2]) -> bool {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    (dy == 0.0 && dx > 0.0) || dy < 0.0
}

/// Rasterizes the binned triangles of one tile whose top-left pixel is (`x0`, `y0`). Returns
/// the winning triangle index (`u32::MAX` for none) and its 1/z per tile pixel, row-major with
/// stride [`TILE_SIZE`]. Triangles are visited in index order and only a strictly nearer
/// fragment replaces a stored one, so ties keep the earlier triangle.
pub fn rasterize_tile(
    camera: &PinholeCamera,
    triangles: &[SetupTriangle],
    bin: &[u32],
    x0: u32,
    y0: u32,
) -> (Vec<u32>, Vec<f32>) {
    let n = (TILE_SIZE * TILE_SIZE) as usize;
    let (mut winners, mut inv_depth) = (vec![u32::MAX; n], vec![0.0f32; n]);
    let x_end = (x0 + TILE_SIZE).min(camera.width) - 1;
    let y_end = (y0 + TILE_SIZE).min(camera.height) - 1;
    for &index in bin {
        let t = &triangles[index as usize];
        let [s0, s1, s2] = &t.screen;
        let area = edge(s0, s1, s2);
        let (u_lo, u_hi) = (t.bbox[0].max(x0), t.bbox[2].min(x_end));
        let (v_lo, v_hi) = (t.bbox[1].max(y0), t.bbox[3].min(y_end));
        if u_lo > u_hi || v_lo > v_hi {
            continue;
        }
        // Edge functions and 1/z are affine in (u, v): evaluate them at the first pixel, then
        // step by their gradients along the row and down the rows.
        let edges = [(s1, s2), (s2, s0), (s0, s1)];
        let origin = [f64::from(u_lo), f64::from(v_lo)];
        let start = edges.map(|(a, b)| edge(a, b, &origin));
        let step_u = edges.map(|(a, b)| -(b[1] - a[1]));
        let step_v = edges.map(|(a, b)| b[0] - a[0]);
        let top_left = edges.map(|(a, b)| is_top_left(a, b));
        let inv_area = 1.0 / area;
        let iz_of =
            |w: [f64; 3]| (w[0] * t.inv_z[0] + w[1] * t.inv_z[1] + w[2] * t.inv_z[2]) * inv_area;
        let (iz_start, iz_step_u, iz_step_v) = (iz_of(start), iz_of(step_u), iz_of(step_v));
        for v in v_lo..=v_hi {
            let dv = f64::from(v - v_lo);
            let mut w = [0, 1, 2].map(|k| start[k] + step_v[k] * dv);
            let mut iz = iz_start + iz_step_v * dv;
            let row = ((v - y0) * TILE_SIZE) as usize;
            for u in u_lo..=u_hi {
                let covered = (0..3).all(|k| w[k] > 0.0 || (w[k] == 0.0 && top_left[k]));
                if covered {
                    let slot = row + (u - x0) as usize;
                    let depth_key = iz as f32;
                    if depth_key > inv_depth[slot] {
                        inv_depth[slot] = depth_key;
                        winners[slot] = index;
                    }
                }
                for k in 0..3 {
                    w[k] += step_u[k];
                }
                iz += iz_step_u;
            }
        }
    }
    (winners, inv_depth)
}
