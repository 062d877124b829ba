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
    /// Depth and light at any pixel, from the unclipped face.
    pub shading: Shading,
}

/// A face's depth and Gouraud light as closed-form functions of the pixel (u, v), set up once
/// per face so that resolving a pixel costs a few multiply-adds instead of a ray–plane
/// intersection and two cross products.
///
/// With the pixel's camera ray r(u, v) = ((u − cx)/fx, (v − cy)/fy, 1), which is affine in
/// (u, v), and the face plane n·p = n·a (camera frame):
/// - the exact z-depth is z = (n·a) / (n·r), and n·r is affine in (u, v);
/// - the camera-frame point is p = z·r, and the barycentric weights of p are affine in p, so
///   the interpolated light is L₀ + z·(g·r) with g·r affine in (u, v).
#[derive(Debug, Clone, Copy)]
pub struct Shading {
    /// n·a, the plane's offset along its (unnormalised) normal, camera frame.
    plane_offset: f64,
    /// n·r(u, v) = c₀ + c₁·u + c₂·v.
    depth_denominator: [f64; 3],
    /// The light's constant part L₀.
    light_offset: f64,
    /// g·r(u, v) = c₀ + c₁·u + c₂·v.
    light_gradient: [f64; 3],
}

/// The coefficients of w·r(u, v) as c₀ + c₁·u + c₂·v, for a camera-frame vector w and the
/// pixel's camera ray r(u, v) = ((u − cx)/fx, (v − cy)/fy, 1).
pub fn along_ray(camera: &PinholeCamera, w: &Vector3<f64>) -> [f64; 3] {
    [
        w.z - w.x * camera.cx / camera.fx - w.y * camera.cy / camera.fy,
        w.x / camera.fx,
        w.y / camera.fy,
    ]
}

/// c₀ + c₁·u + c₂·v.
pub fn affine(c: &[f64; 3], u: f64, v: f64) -> f64 {
    c[0] + c[1] * u + c[2] * v
}

impl Shading {
    /// Sets up a face with camera-frame `corners`, their unnormalised normal
    /// (b − a) × (c − a), and the light (ambient + diffuse, in [0, 1]) at each corner.
    pub fn new(
        camera: &PinholeCamera,
        corners: &[Point3<f64>; 3],
        normal: &Vector3<f64>,
        corner_light: [f32; 3],
    ) -> Self {
        let [a, b, c] = corners;
        let area2 = normal.norm_squared().max(1e-30);
        // Barycentric weight of a at p: ((b − p) × (c − p))·n / |n|²
        //   = ((b × c)·n + p·(n × (c − b))) / |n|², and likewise for b.
        let weight_a = (
            b.coords.cross(&c.coords).dot(normal),
            normal.cross(&(c - b)),
        );
        let weight_b = (
            c.coords.cross(&a.coords).dot(normal),
            normal.cross(&(a - c)),
        );
        let [l_a, l_b, l_c] = corner_light.map(f64::from);
        let (d_a, d_b) = (l_a - l_c, l_b - l_c);
        Self {
            plane_offset: normal.dot(&a.coords),
            depth_denominator: along_ray(camera, normal),
            light_offset: l_c + (d_a * weight_a.0 + d_b * weight_b.0) / area2,
            light_gradient: along_ray(camera, &((weight_a.1 * d_a + weight_b.1 * d_b) / area2)),
        }
    }

    /// The exact z-depth (metres) of the face at pixel (u, v), or `None` when the pixel's ray
    /// grazes the plane.
    pub fn depth_m(&self, u: f64, v: f64) -> Option<f64> {
        let denominator = affine(&self.depth_denominator, u, v);
        (denominator.abs() > 1e-12).then(|| self.plane_offset / denominator)
    }

    /// The interpolated light at pixel (u, v), whose depth is `depth_m`.
    pub fn light(&self, u: f64, v: f64, depth_m: f64) -> f32 {
        (self.light_offset + depth_m * affine(&self.light_gradient, u, v)) as f32
    }
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
/// `corner_light` gives the light at the corners; it is called once for a face that reaches
/// the screen, and not at all for the others.
pub fn setup_triangle(
    camera: &PinholeCamera,
    corners: &[Point3<f64>; 3],
    layer: u16,
    near_m: f64,
    corner_light: impl Fn() -> [f32; 3],
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
    let mut shading = None;
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
        // Both halves of a clipped face share the face's shading; built once, and only for
        // a face that reaches the screen.
        let shading =
            *shading.get_or_insert_with(|| Shading::new(camera, corners, &normal, corner_light()));
        out.push(SetupTriangle {
            screen,
            inv_z,
            bbox: [u0 as u32, v0 as u32, u1 as u32, v1 as u32],
            layer,
            shading,
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

/// The winning triangle index (`u32::MAX` for none) and its 1/z for each pixel of one tile,
/// row-major with stride [`TILE_SIZE`]; reused from tile to tile.
pub struct TileBuffer {
    /// Index into the frame's setup triangles of the nearest fragment.
    pub winners: Vec<u32>,
    /// That fragment's 1/z, 1/metres (0 where nothing was drawn).
    pub inv_depth: Vec<f32>,
}

impl TileBuffer {
    pub fn new() -> Self {
        let n = (TILE_SIZE * TILE_SIZE) as usize;
        Self {
            winners: vec![u32::MAX; n],
            inv_depth: vec![0.0; n],
        }
    }
}

/// Rasterizes the binned triangles of one tile whose top-left pixel is (`x0`, `y0`) into
/// `tile`. Triangles are visited in index order and only a strictly nearer fragment replaces
/// a stored one, so ties keep the earlier triangle.
pub fn rasterize_tile(
    camera: &PinholeCamera,
    triangles: &[SetupTriangle],
    bin: &[u32],
    (x0, y0): (u32, u32),
    tile: &mut TileBuffer,
) {
    tile.winners.fill(u32::MAX);
    tile.inv_depth.fill(0.0);
    let TileBuffer { winners, inv_depth } = tile;
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
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn camera() -> PinholeCamera {
        PinholeCamera::from_hfov(640, 480, 80.0).unwrap()
    }

    proptest! {
        /// At each corner's own pixel the closed-form shading returns that corner's depth and
        /// light, and at the centroid's pixel the depth of the centroid and the mean light.
        #[test]
        fn shading_interpolates_the_corners(
            xs in prop::array::uniform3(-2.0f64..2.0),
            ys in prop::array::uniform3(-1.5f64..1.5),
            zs in prop::array::uniform3(1.0f64..30.0),
            lights in prop::array::uniform3(0.0f32..1.0),
        ) {
            let camera = camera();
            let corners: [Point3<f64>; 3] = std::array::from_fn(|k| Point3::new(xs[k], ys[k], zs[k]));
            let [a, b, c] = &corners;
            let normal = (b - a).cross(&(c - a));
            // Skip slivers and faces seen edge-on, whose plane a ray barely determines.
            let edge_on = normal.normalize().dot(&a.coords.normalize()).abs();
            prop_assume!(normal.norm() > 0.05 && edge_on > 0.1);
            let shading = Shading::new(&camera, &corners, &normal, lights);
            let pixel = |p: &Point3<f64>| {
                (camera.fx * p.x / p.z + camera.cx, camera.fy * p.y / p.z + camera.cy)
            };
            for (p, light) in corners.iter().zip(lights) {
                let (u, v) = pixel(p);
                let z = shading.depth_m(u, v).unwrap();
                prop_assert!((z - p.z).abs() < 1e-9 * p.z, "depth {z} vs {}", p.z);
                prop_assert!((shading.light(u, v, z) - light).abs() < 1e-5);
            }
            let centroid = Point3::from((a.coords + b.coords + c.coords) / 3.0);
            let (u, v) = pixel(&centroid);
            let z = shading.depth_m(u, v).unwrap();
            prop_assert!((z - centroid.z).abs() < 1e-9 * centroid.z);
            let mean = lights.iter().sum::<f32>() / 3.0;
            prop_assert!((shading.light(u, v, z) - mean).abs() < 1e-5);
        }
    }

    #[test]
    fn a_ray_parallel_to_the_plane_has_no_depth() {
        let camera = camera();
        // The plane x = 1 m, camera frame: rays through the principal column (u = cx) run
        // parallel to it; the ray through u = cx + fx, direction (1, ·, 1), meets it at z = 1 m.
        let corners = [
            Point3::new(1.0, 0.0, 1.0),
            Point3::new(1.0, 1.0, 2.0),
            Point3::new(1.0, -1.0, 3.0),
        ];
        let normal = (corners[1] - corners[0]).cross(&(corners[2] - corners[0]));
        let shading = Shading::new(&camera, &corners, &normal, [1.0; 3]);
        assert_eq!(shading.depth_m(camera.cx, camera.cy), None);
        let z = shading.depth_m(camera.cx + camera.fx, 17.0).unwrap();
        assert!((z - 1.0).abs() < 1e-12, "{z}");
    }
}
