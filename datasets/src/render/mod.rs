//! A z-buffer triangle rasterizer that renders a [`World`] into RGB, z-depth and instance ids.
//!
//! The pipeline per frame:
//! 1. cull mesh chunks against the view frustum (bounding boxes);
//! 2. set up visible triangles in parallel: back-face culling, near-plane clipping, projection;
//! 3. bin triangles into 32×32-pixel tiles;
//! 4. rasterize tiles in parallel (edge functions, top-left rule, 1/z interpolated in screen
//!    space, which is exact for perspective);
//! 5. resolve each pixel: exact depth by intersecting its ray with the winning face's plane,
//!    perspective-correct world position and light, textured Lambert shading. Every one of
//!    these is a linear form in the pixel's ray, set up once per face ([`FaceForms`]), so a
//!    pixel costs a few dot products.
//!
//! Every stage is deterministic: tiles are disjoint, triangles keep a global order, and depth
//! ties go to the earlier triangle, so the output does not depend on the thread count.

mod raster;

use nalgebra::{Isometry3, Point3, Vector3};
use rayon::prelude::*;
use scarp_slam::image::{DepthImage, MaskImage, RgbImage};
use scarp_slam::{PinholeCamera, TriangleMesh};

use crate::DatasetError;
use crate::texture::rock_albedo;
use crate::world::{PEDESTAL_INSTANCE_OFFSET, TERRAIN_INSTANCE_ID, World};
use raster::{SetupTriangle, TILE_SIZE, rasterize_tile, setup_triangle};

/// Near clipping distance, metres.
pub const NEAR_PLANE_M: f64 = 0.05;

/// What one render produces. All images share the camera's size.
#[derive(Debug, Clone)]
pub struct RenderOutput {
    /// Shaded colour, 8-bit sRGB; sky where nothing is hit.
    pub rgb: RgbImage,
    /// z-depth in metres along the camera z axis; 0.0 where nothing is hit.
    pub depth_m: DepthImage,
    /// Instance id per pixel (see [`crate::world::TERRAIN_INSTANCE_ID`]); 0 where nothing is hit.
    pub instance: MaskImage,
}

#[derive(Debug, Clone, Copy)]
enum Material {
    Terrain,
    Solid([u8; 3]),
}

/// A face's per-pixel quantities as linear forms in the pixel's ray r = ((u − cx)/fx,
/// (v − cy)/fy, 1), camera frame.
///
/// On the face's plane n·p = d (camera frame), the point seen along r is p = z·r with
/// 1/z = n·r / d, and the barycentric weight of corner A is w_A = ((B − p) × (C − p))·n / |n|².
/// Expanding, w_A / z = g_A·r with g_A = [((B × C)·n / d)·n − (C − B) × n] / |n|², and the same
/// for B and C cyclically. So any attribute f interpolated linearly over the face has
/// f / z = (Σ f_k g_k)·r: exact perspective-correct interpolation from three dot products.
#[derive(Debug, Clone, Copy)]
enum FaceForms {
    /// The face is seen at a usable angle.
    Exact {
        /// 1/z = `inv_depth`·r, 1/metres.
        inv_depth: Vector3<f64>,
        /// World x/z, y/z, z/z (metres per metre of depth).
        world: [Vector3<f64>; 3],
        /// Light / z.
        light: Vector3<f64>,
    },
    /// The face's plane passes (numerically) through the camera centre: it is seen edge-on and
    /// covers at most a sliver, drawn flat at its centroid with the rasterizer's depth.
    EdgeOn {
        centroid_world: Point3<f64>,
        light: f32,
    },
}

impl FaceForms {
    /// Forms of the face with camera-frame corners `camera` and world corners `world`, and light
    /// `light` at each corner.
    fn new(camera: &[Point3<f64>; 3], world: &[Point3<f64>; 3], light: [f32; 3]) -> Self {
        let [a, b, c] = camera.map(|p| p.coords);
        let normal = (b - a).cross(&(c - a));
        let d = normal.dot(&a);
        let norm2 = normal.norm_squared();
        // Relative to the face's size and distance: below this the plane holds the camera centre.
        if !(d.abs() > 1e-9 * norm2.sqrt() * a.norm().max(1e-9)) {
            let centroid = (world[0].coords + world[1].coords + world[2].coords) / 3.0;
            return Self::EdgeOn {
                centroid_world: Point3::from(centroid),
                light: (light[0] + light[1] + light[2]) / 3.0,
            };
        }
        let g = |p: &Vector3<f64>, q: &Vector3<f64>| {
            (normal * (p.cross(q).dot(&normal) / d) - (q - p).cross(&normal)) / norm2
        };
        let weights = [g(&b, &c), g(&c, &a), g(&a, &b)];
        let form = |values: [f64; 3]| {
            weights[0] * values[0] + weights[1] * values[1] + weights[2] * values[2]
        };
        Self::Exact {
            inv_depth: normal / d,
            world: [0, 1, 2].map(|axis| form(world.map(|p| p[axis]))),
            light: form(light.map(f64::from)),
        }
    }

    /// Depth along the camera z axis (metres), world point and light seen along `ray`;
    /// `raster_inv_depth` is the rasterizer's interpolated 1/z, used for edge-on faces.
    #[inline]
    fn at(&self, ray: &Vector3<f64>, raster_inv_depth: f32) -> (f64, Point3<f64>, f32) {
        match self {
            Self::Exact {
                inv_depth,
                world,
                light,
            } => {
                let z = 1.0 / inv_depth.dot(ray);
                let p = Point3::new(world[0].dot(ray), world[1].dot(ray), world[2].dot(ray));
                (z, p * z, (light.dot(ray) * z) as f32)
            }
            Self::EdgeOn {
                centroid_world,
                light,
            } => (1.0 / f64::from(raster_inv_depth), *centroid_world, *light),
        }
    }
}

/// A frustum half-space: a point is inside when the value is ≥ 0.
type FrustumPlane<'a> = &'a dyn Fn(&Point3<f64>) -> f64;

/// One drawable mesh with its faces regrouped into spatial chunks for culling.
struct Layer<'w> {
    mesh: &'w TriangleMesh,
    instance_id: u16,
    material: Material,
    /// Faces reordered so that each chunk is a contiguous range.
    faces: Vec<[u32; 3]>,
    /// Contiguous face ranges with their bounds.
    chunks: Vec<Chunk>,
}

/// Faces `start..end` of a layer's reordered faces, inside the box `lo..hi` (world metres).
#[derive(Debug, Clone, Copy)]
struct Chunk {
    start: usize,
    end: usize,
    lo: Point3<f64>,
    hi: Point3<f64>,
}

/// A renderer bound to one world. Building it groups faces into chunks once; [`Self::render`]
/// can then be called from many threads.
pub struct Renderer<'w> {
    world: &'w World,
    layers: Vec<Layer<'w>>,
}

fn chunk_faces(mesh: &TriangleMesh, cell_m: f64) -> (Vec<[u32; 3]>, Vec<Chunk>) {
    let centroid = |f: &[u32; 3]| -> Point3<f64> {
        let p = f.map(|i| mesh.positions[i as usize].coords.cast::<f64>());
        Point3::from((p[0] + p[1] + p[2]) / 3.0)
    };
    let key = |f: &[u32; 3]| {
        let c = centroid(f);
        ((c.x / cell_m).floor() as i64, (c.y / cell_m).floor() as i64)
    };
    let mut faces = mesh.faces.clone();
    // A stable sort keeps the original order inside each chunk.
    faces.sort_by_key(key);
    let mut chunks = Vec::new();
    let mut start = 0;
    while start < faces.len() {
        let k = key(&faces[start]);
        let mut end = start;
        let (mut lo, mut hi) = (
            Point3::from([f64::INFINITY; 3]),
            Point3::from([f64::NEG_INFINITY; 3]),
        );
        while end < faces.len() && key(&faces[end]) == k {
            for &v in &faces[end] {
                let p = mesh.positions[v as usize].cast::<f64>();
                lo = lo.inf(&p);
                hi = hi.sup(&p);
            }
            end += 1;
        }
        chunks.push(Chunk { start, end, lo, hi });
        start = end;
    }
    (faces, chunks)
}

impl<'w> Renderer<'w> {
    /// Prepares a world for rendering.
    pub fn new(world: &'w World) -> Self {
        let texture = &world.config.texture;
        let mut layers = Vec::new();
        let mut add =
            |mesh: &'w TriangleMesh, instance_id: u16, material: Material, cell_m: f64| {
                let (faces, chunks) = chunk_faces(mesh, cell_m);
                layers.push(Layer {
                    mesh,
                    instance_id,
                    material,
                    faces,
                    chunks,
                });
            };
        add(
            &world.terrain_mesh,
            TERRAIN_INSTANCE_ID,
            Material::Terrain,
            4.0,
        );
        for rock in &world.rocks {
            add(
                &rock.mesh,
                rock.id as u16,
                Material::Solid(texture.rock_color),
                0.5,
            );
            if let Some(p) = &rock.pedestal {
                add(
                    p,
                    PEDESTAL_INSTANCE_OFFSET + rock.id as u16,
                    Material::Solid(texture.pedestal_color),
                    0.5,
                );
            }
        }
        Self { world, layers }
    }

    /// Renders the world seen by `camera` at `world_from_camera`.
    ///
    /// # Errors
    /// [`DatasetError::Geometry`] for invalid intrinsics or a non-finite pose.
    pub fn render(
        &self,
        camera: &PinholeCamera,
        world_from_camera: &Isometry3<f64>,
    ) -> Result<RenderOutput, DatasetError> {
        camera.validate()?;
        scarp_slam::geometry::check_finite_isometry(world_from_camera, "world_from_camera")?;
        let camera_from_world = world_from_camera.inverse();
        let (triangles, forms) = self.setup(camera, &camera_from_world);
        let (winners, inv_depth) = self.rasterize(camera, &triangles);
        Ok(self.resolve(
            camera,
            world_from_camera,
            &triangles,
            &forms,
            &winners,
            &inv_depth,
        ))
    }

    /// Ambient plus Lambert light at the corners of a face, from its vertex normals (or its face
    /// normal when the mesh has none).
    fn corner_light(&self, layer: &Layer, face: &[u32; 3]) -> [f32; 3] {
        let sun = self.world.sun_direction;
        let ambient = self.world.config.sun.ambient as f32;
        let light = |n: Vector3<f64>| {
            let lambert = (n.dot(&sun) / n.norm().max(1e-12)).max(0.0) as f32;
            ambient + (1.0 - ambient) * lambert
        };
        if layer.mesh.normals.is_empty() {
            let p = face.map(|v| layer.mesh.positions[v as usize].cast::<f64>());
            [light((p[1] - p[0]).cross(&(p[2] - p[0]))); 3]
        } else {
            face.map(|v| light(layer.mesh.normals[v as usize].cast::<f64>()))
        }
    }

    fn chunk_visible(
        camera: &PinholeCamera,
        camera_from_world: &Isometry3<f64>,
        lo: &Point3<f64>,
        hi: &Point3<f64>,
    ) -> bool {
        // Runs for every chunk of every frame: a fixed array, no allocation.
        let corners: [Point3<f64>; 8] = std::array::from_fn(|i| {
            camera_from_world
                * Point3::new(
                    if i & 1 == 0 { lo.x } else { hi.x },
                    if i & 2 == 0 { lo.y } else { hi.y },
                    if i & 4 == 0 { lo.z } else { hi.z },
                )
        });
        let (w, h) = (f64::from(camera.width), f64::from(camera.height));
        // Frustum half-spaces in homogeneous form (valid for any sign of fy).
        let planes: [FrustumPlane; 5] = [
            &|p| p.z - NEAR_PLANE_M,
            &|p| camera.fx * p.x + (camera.cx + 0.5) * p.z,
            &|p| (w - 0.5 - camera.cx) * p.z - camera.fx * p.x,
            &|p| camera.fy * p.y + (camera.cy + 0.5) * p.z,
            &|p| (h - 0.5 - camera.cy) * p.z - camera.fy * p.y,
        ];
        planes
            .iter()
            .all(|plane| corners.iter().any(|c| plane(c) >= 0.0))
    }

    /// Culls chunks, then sets up their faces in parallel. Returns the screen triangles and,
    /// for each, its face's per-pixel forms.
    fn setup(
        &self,
        camera: &PinholeCamera,
        camera_from_world: &Isometry3<f64>,
    ) -> (Vec<SetupTriangle>, Vec<FaceForms>) {
        let jobs: Vec<(usize, usize)> = self
            .layers
            .iter()
            .enumerate()
            .flat_map(|(l, layer)| {
                layer
                    .chunks
                    .iter()
                    .enumerate()
                    .filter(|(_, chunk)| {
                        Self::chunk_visible(camera, camera_from_world, &chunk.lo, &chunk.hi)
                    })
                    .map(move |(c, _)| (l, c))
            })
            .collect();
        let per_chunk: Vec<(Vec<SetupTriangle>, Vec<FaceForms>)> = jobs
            .par_iter()
            .map(|&(l, c)| {
                let layer = &self.layers[l];
                let Chunk { start, end, .. } = layer.chunks[c];
                let (mut triangles, mut forms) = (Vec::new(), Vec::new());
                for face in &layer.faces[start..end] {
                    let world = face.map(|v| layer.mesh.positions[v as usize].cast::<f64>());
                    let corners = world.map(|p| camera_from_world * p);
                    let first_new = triangles.len();
                    setup_triangle(camera, &corners, l as u16, NEAR_PLANE_M, &mut triangles);
                    if triangles.len() > first_new {
                        let face_forms =
                            FaceForms::new(&corners, &world, self.corner_light(layer, face));
                        forms.resize(triangles.len(), face_forms);
                    }
                }
                (triangles, forms)
            })
            .collect();
        let count = per_chunk.iter().map(|(t, _)| t.len()).sum();
        let (mut triangles, mut forms) = (Vec::with_capacity(count), Vec::with_capacity(count));
        for (t, f) in per_chunk {
            triangles.extend(t);
            forms.extend(f);
        }
        (triangles, forms)
    }

    fn rasterize(
        &self,
        camera: &PinholeCamera,
        triangles: &[SetupTriangle],
    ) -> (Vec<u32>, Vec<f32>) {
        let tiles_x = camera.width.div_ceil(TILE_SIZE) as usize;
        let tiles_y = camera.height.div_ceil(TILE_SIZE) as usize;
        let mut bins: Vec<Vec<u32>> = vec![Vec::new(); tiles_x * tiles_y];
        for (index, t) in triangles.iter().enumerate() {
            let [x0, y0, x1, y1] = t.bbox;
            for ty in (y0 / TILE_SIZE)..=(y1 / TILE_SIZE) {
                for tx in (x0 / TILE_SIZE)..=(x1 / TILE_SIZE) {
                    bins[ty as usize * tiles_x + tx as usize].push(index as u32);
                }
            }
        }
        let tiles: Vec<_> = bins
            .par_iter()
            .enumerate()
            .map(|(i, bin)| {
                let (tx, ty) = ((i % tiles_x) as u32, (i / tiles_x) as u32);
                rasterize_tile(camera, triangles, bin, tx * TILE_SIZE, ty * TILE_SIZE)
            })
            .collect();
        let n = camera.pixel_count();
        let (mut winners, mut inv_depth) = (vec![u32::MAX; n], vec![0.0f32; n]);
        let width = camera.width as usize;
        for (i, tile) in tiles.iter().enumerate() {
            let (x0, y0) = (
                (i % tiles_x) * TILE_SIZE as usize,
                (i / tiles_x) * TILE_SIZE as usize,
            );
            let tw = (width - x0).min(TILE_SIZE as usize);
            let th = (camera.height as usize - y0).min(TILE_SIZE as usize);
            for row in 0..th {
                let src = row * TILE_SIZE as usize;
                let dst = (y0 + row) * width + x0;
                winners[dst..dst + tw].copy_from_slice(&tile.0[src..src + tw]);
                inv_depth[dst..dst + tw].copy_from_slice(&tile.1[src..src + tw]);
            }
        }
        (winners, inv_depth)
    }

    fn resolve(
        &self,
        camera: &PinholeCamera,
        world_from_camera: &Isometry3<f64>,
        triangles: &[SetupTriangle],
        forms: &[FaceForms],
        winners: &[u32],
        inv_depth: &[f32],
    ) -> RenderOutput {
        let (w, h) = (camera.width, camera.height);
        let width = w as usize;
        let world = self.world;
        let texture = &world.config.texture;
        let ray_x: Vec<f64> = (0..width)
            .map(|u| (u as f64 - camera.cx) / camera.fx)
            .collect();
        let mut rgb = RgbImage::filled(w, h, [0, 0, 0]);
        let mut depth = DepthImage::filled(w, h, 0.0);
        let mut instance = MaskImage::filled(w, h, 0);
        rgb.as_mut_slice()
            .par_chunks_mut(width)
            .zip(depth.as_mut_slice().par_chunks_mut(width))
            .zip(instance.as_mut_slice().par_chunks_mut(width))
            .enumerate()
            .for_each(|(row, ((rgb_row, depth_row), instance_row))| {
                let ray_y = (row as f64 - camera.cy) / camera.fy;
                for u in 0..width {
                    let i = row * width + u;
                    let ray = Vector3::new(ray_x[u], ray_y, 1.0);
                    let winner = winners[i];
                    if winner == u32::MAX {
                        // Sky: brighter toward the horizon.
                        let up = (world_from_camera.rotation * ray.normalize())
                            .z
                            .clamp(0.0, 1.0) as f32;
                        rgb_row[u] = [(190.0 - 70.0 * up) as u8, (210.0 - 50.0 * up) as u8, 235];
                        continue;
                    }
                    let layer = &self.layers[triangles[winner as usize].layer as usize];
                    let (z, p_world, light) = forms[winner as usize].at(&ray, inv_depth[i]);
                    let albedo = match layer.material {
                        Material::Terrain => world.terrain_albedo.sample(p_world.x, p_world.y),
                        Material::Solid(base) => {
                            rock_albedo(texture, base, p_world.x, p_world.y, p_world.z)
                                .map(f32::from)
                        }
                    };
                    rgb_row[u] = albedo.map(|a| (a * light + 0.5).clamp(0.0, 255.0) as u8);
                    depth_row[u] = z as f32;
                    instance_row[u] = layer.instance_id;
                }
            });
        RenderOutput {
            rgb,
            depth_m: depth,
            instance,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn point() -> impl Strategy<Value = [f64; 3]> {
        [-3.0..3.0f64, -3.0..3.0f64, 0.5..20.0f64]
    }

    proptest! {
        /// The forms give back the depth, world point and interpolated light of any point of the
        /// face, seen along its ray.
        #[test]
        fn face_forms_interpolate_exactly(
            corners in [point(), point(), point()],
            weights in [0.01..1.0f64, 0.01..1.0f64, 0.01..1.0f64],
            light in [0.0..1.0f32, 0.0..1.0f32, 0.0..1.0f32],
        ) {
            let camera = corners.map(Point3::from);
            let normal = (camera[1] - camera[0]).cross(&(camera[2] - camera[0]));
            prop_assume!(normal.norm() > 1e-3);
            prop_assume!(normal.dot(&camera[0].coords).abs() > 1e-3 * normal.norm());
            let world_from_camera = Isometry3::new(
                Vector3::new(10.0, -4.0, 2.0),
                Vector3::new(0.3, -0.2, 1.1),
            );
            let world = camera.map(|p| world_from_camera * p);
            let forms = FaceForms::new(&camera, &world, light);
            let exact = matches!(forms, FaceForms::Exact { .. });
            prop_assert!(exact);
            let total = weights.iter().sum::<f64>();
            let w = weights.map(|x| x / total);
            let p = Point3::from(
                camera[0].coords * w[0] + camera[1].coords * w[1] + camera[2].coords * w[2],
            );
            let (z, p_world, l) = forms.at(&(p.coords / p.z), 0.0);
            prop_assert!((z - p.z).abs() < 1e-9 * p.z.max(1.0), "{z} vs {}", p.z);
            prop_assert!((p_world - world_from_camera * p).norm() < 1e-8);
            let expected = light[0] as f64 * w[0] + light[1] as f64 * w[1] + light[2] as f64 * w[2];
            prop_assert!((f64::from(l) - expected).abs() < 1e-5);
        }
    }

    #[test]
    fn a_face_edge_on_to_the_camera_is_drawn_flat_at_the_raster_depth() {
        let camera = [[0.0, 0.0, 1.0], [0.0, 0.0, 2.0], [0.0, 1.0, 2.0]].map(Point3::from);
        let forms = FaceForms::new(&camera, &camera, [0.2, 0.4, 0.6]);
        let (z, p, light) = forms.at(&Vector3::new(0.0, 0.1, 1.0), 0.5);
        assert!(matches!(forms, FaceForms::EdgeOn { .. }));
        assert_eq!(z, 2.0);
        assert!((p - Point3::new(0.0, 1.0 / 3.0, 5.0 / 3.0)).norm() < 1e-12);
        assert!((light - 0.4).abs() < 1e-6);
    }
}
