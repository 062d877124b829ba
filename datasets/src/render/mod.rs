//! A z-buffer triangle rasterizer that renders a [`World`] into RGB, z-depth and instance ids.
//!
//! The pipeline per frame:
//! 1. cull mesh chunks against the view frustum (bounding boxes);
//! 2. set up visible triangles in parallel: back-face culling, near-plane clipping, projection;
//! 3. bin triangles into 32×32-pixel tiles;
//! 4. rasterize tiles in parallel (edge functions, top-left rule, 1/z interpolated in screen
//!    space, which is exact for perspective);
//! 5. resolve each pixel: exact depth by intersecting its ray with the winning triangle's plane,
//!    perspective-correct attributes, textured Lambert shading.
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
        let triangles = self.setup(camera, &camera_from_world);
        let (winners, inv_depth) = self.rasterize(camera, &triangles);
        Ok(self.resolve(camera, world_from_camera, &triangles, &winners, &inv_depth))
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

    fn setup(
        &self,
        camera: &PinholeCamera,
        camera_from_world: &Isometry3<f64>,
    ) -> Vec<SetupTriangle> {
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
        let per_chunk: Vec<Vec<SetupTriangle>> = jobs
            .par_iter()
            .map(|&(l, c)| {
                let layer = &self.layers[l];
                let Chunk { start, end, .. } = layer.chunks[c];
                let mut out = Vec::new();
                for face in &layer.faces[start..end] {
                    let corners = face.map(|v| {
                        camera_from_world * layer.mesh.positions[v as usize].cast::<f64>()
                    });
                    let first_new = out.len();
                    setup_triangle(camera, &corners, l as u16, NEAR_PLANE_M, &mut out);
                    if out.len() > first_new {
                        let corner_light = self.corner_light(layer, face);
                        for t in &mut out[first_new..] {
                            t.corner_light = corner_light;
                        }
                    }
                }
                out
            })
            .collect();
        per_chunk.concat()
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
        winners: &[u32],
        inv_depth: &[f32],
    ) -> RenderOutput {
        let (w, h) = (camera.width, camera.height);
        let width = w as usize;
        let world = self.world;
        let texture = &world.config.texture;
        let mut rgb = RgbImage::filled(w, h, [0, 0, 0]);
        let mut depth = DepthImage::filled(w, h, 0.0);
        let mut instance = MaskImage::filled(w, h, 0);
        rgb.as_mut_slice()
            .par_chunks_mut(width)
            .zip(depth.as_mut_slice().par_chunks_mut(width))
            .zip(instance.as_mut_slice().par_chunks_mut(width))
            .enumerate()
            .for_each(|(row, ((rgb_row, depth_row), instance_row))| {
                let v = row as f64;
                for u in 0..width {
                    let i = row * width + u;
                    let ray = Vector3::new(
                        (u as f64 - camera.cx) / camera.fx,
                        (v - camera.cy) / camera.fy,
                        1.0,
                    );
                    let winner = winners[i];
                    if winner == u32::MAX {
                        // Sky: brighter toward the horizon.
                        let up = (world_from_camera.rotation * ray.normalize())
                            .z
                            .clamp(0.0, 1.0) as f32;
                        rgb_row[u] = [(190.0 - 70.0 * up) as u8, (210.0 - 50.0 * up) as u8, 235];
                        continue;
                    }
                    let t = &triangles[winner as usize];
                    let layer = &self.layers[t.layer as usize];
                    let [a, b, c] = &t.corners;
                    let normal = &t.normal;
                    let denominator = normal.dot(&ray);
                    let z = if denominator.abs() > 1e-12 {
                        normal.dot(&a.coords) / denominator
                    } else {
                        1.0 / f64::from(inv_depth[i])
                    };
                    let p = Point3::from(ray * z);
                    let p_world = world_from_camera * p;
                    // Barycentrics of p in the triangle (sub-areas against the face normal).
                    let area2 = normal.norm_squared().max(1e-30);
                    let w_a = ((b - p).cross(&(c - p)).dot(normal) / area2) as f32;
                    let w_b = ((c - p).cross(&(a - p)).dot(normal) / area2) as f32;
                    let [l_a, l_b, l_c] = t.corner_light;
                    let light = l_a * w_a + l_b * w_b + l_c * (1.0 - w_a - w_b);
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
