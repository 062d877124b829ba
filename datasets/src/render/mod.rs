//! A z-buffer triangle rasterizer that renders a [`World`] into RGB, z-depth and instance ids.
//!
//! The pipeline per frame:
//! 1. cull mesh chunks against the view frustum (bounding boxes);
//! 2. set up visible triangles in parallel: back-face culling, near-plane clipping, projection;
//! 3. bin triangles into bands of 32 image rows, and inside a band into 32×32-pixel tiles;
//! 4. draw bands in parallel: rasterize each tile (edge functions, top-left rule, 1/z
//!    interpolated in screen space, which is exact for perspective), then resolve its pixels
//!    while the tile is hot in cache: exact depth on the winning triangle's plane,
//!    perspective-correct light, textured Lambert shading.
//!
//! Every stage is deterministic: bands and tiles are disjoint, triangles keep a global order,
//! and depth ties go to the earlier triangle, so the output does not depend on the thread
//! count.

mod raster;

use nalgebra::{Isometry3, Matrix3, Point3, Vector3};
use rayon::prelude::*;
use scarp_slam::image::{DepthImage, MaskImage, RgbImage};
use scarp_slam::{PinholeCamera, TriangleMesh};
use wide::f32x4;

use crate::DatasetError;
use crate::texture::RockTexture;
use crate::world::{PEDESTAL_INSTANCE_OFFSET, TERRAIN_INSTANCE_ID, World};
use raster::{
    SetupTriangle, TILE_SIZE, TileBuffer, affine, along_ray, rasterize_tile, setup_triangle,
};

/// Near clipping distance, metres.
pub const NEAR_PLANE_M: f64 = 0.05;

/// What a geometry-only render produces ([`Renderer::render_geometry`]): the depth and
/// instance images of [`RenderOutput`], bit for bit, without the shading.
#[derive(Debug, Clone)]
pub struct GeometryOutput {
    /// z-depth in metres along the camera z axis; 0.0 where nothing is hit.
    pub depth_m: DepthImage,
    /// Instance id per pixel (see [`crate::world::TERRAIN_INSTANCE_ID`]); 0 where nothing is hit.
    pub instance: MaskImage,
}

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
    /// The layer's light, computed once: the sun and the world stand still.
    light: LayerLight,
}

/// Ambient plus Lambert light of a layer's surface, in [0, 1].
enum LayerLight {
    /// Per vertex, from the mesh's vertex normals.
    PerVertex(Vec<f32>),
    /// Per face of the layer's reordered faces, from the face normals (a mesh without normals).
    PerFace(Vec<f32>),
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
    rock_texture: RockTexture,
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
                let light = Self::precomputed_light(world, mesh, &faces);
                layers.push(Layer {
                    mesh,
                    instance_id,
                    material,
                    faces,
                    chunks,
                    light,
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
        Self {
            world,
            layers,
            rock_texture: RockTexture::new(texture),
        }
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
        let mut rgb = RgbImage::filled(camera.width, camera.height, [0, 0, 0]);
        let geometry = self.render_into(camera, world_from_camera, Some(&mut rgb))?;
        Ok(RenderOutput {
            rgb,
            depth_m: geometry.depth_m,
            instance: geometry.instance,
        })
    }

    /// The depth and instance images of [`Self::render`], bit for bit, without shading: for
    /// visibility and occlusion tests, where the colour's texture lookups would be two thirds
    /// of the drawing time.
    ///
    /// # Errors
    /// [`DatasetError::Geometry`] for invalid intrinsics or a non-finite pose.
    pub fn render_geometry(
        &self,
        camera: &PinholeCamera,
        world_from_camera: &Isometry3<f64>,
    ) -> Result<GeometryOutput, DatasetError> {
        self.render_into(camera, world_from_camera, None)
    }

    /// Renders depth and instances, and colour into `rgb` (of the camera's size) when given.
    fn render_into(
        &self,
        camera: &PinholeCamera,
        world_from_camera: &Isometry3<f64>,
        rgb: Option<&mut RgbImage>,
    ) -> Result<GeometryOutput, DatasetError> {
        let triangles = self.visible_triangles(camera, world_from_camera)?;
        let (w, h) = (camera.width, camera.height);
        let mut depth_m = DepthImage::filled(w, h, 0.0);
        let mut instance = MaskImage::filled(w, h, 0);
        self.draw(
            camera,
            world_from_camera,
            &triangles,
            rgb.map(|rgb| rgb.as_mut_slice()),
            depth_m.as_mut_slice(),
            instance.as_mut_slice(),
        );
        Ok(GeometryOutput { depth_m, instance })
    }

    /// Checks the inputs and sets up the triangles in view.
    fn visible_triangles(
        &self,
        camera: &PinholeCamera,
        world_from_camera: &Isometry3<f64>,
    ) -> Result<Vec<SetupTriangle>, DatasetError> {
        camera.validate()?;
        scarp_slam::geometry::check_finite_isometry(world_from_camera, "world_from_camera")?;
        Ok(self.setup(camera, &world_from_camera.inverse()))
    }

    /// A layer's light: per vertex from the vertex normals, or per face (in the order of
    /// `faces`) from the face normals when the mesh has none.
    fn precomputed_light(world: &World, mesh: &TriangleMesh, faces: &[[u32; 3]]) -> LayerLight {
        let sun = world.sun_direction;
        let ambient = world.config.sun.ambient as f32;
        let light = |n: Vector3<f64>| {
            let lambert = (n.dot(&sun) / n.norm().max(1e-12)).max(0.0) as f32;
            ambient + (1.0 - ambient) * lambert
        };
        if mesh.normals.is_empty() {
            LayerLight::PerFace(
                faces
                    .iter()
                    .map(|face| {
                        let p = face.map(|v| mesh.positions[v as usize].cast::<f64>());
                        light((p[1] - p[0]).cross(&(p[2] - p[0])))
                    })
                    .collect(),
            )
        } else {
            LayerLight::PerVertex(
                mesh.normals
                    .iter()
                    .map(|n| light(n.cast::<f64>()))
                    .collect(),
            )
        }
    }

    /// Ambient plus Lambert light at the corners of face `index` (of the layer's reordered
    /// faces).
    fn corner_light(layer: &Layer, index: usize) -> [f32; 3] {
        match &layer.light {
            LayerLight::PerVertex(light) => layer.faces[index].map(|v| light[v as usize]),
            LayerLight::PerFace(light) => [light[index]; 3],
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
        // A matrix rotates a vertex in 15 flops, a unit quaternion in about twice that.
        let rotation: Matrix3<f64> = camera_from_world.rotation.to_rotation_matrix().into_inner();
        let translation = camera_from_world.translation.vector;
        let per_chunk: Vec<Vec<SetupTriangle>> = jobs
            .par_iter()
            .map(|&(l, c)| {
                let layer = &self.layers[l];
                let Chunk { start, end, .. } = layer.chunks[c];
                let mut out = Vec::new();
                for (offset, face) in layer.faces[start..end].iter().enumerate() {
                    let index = start + offset;
                    let corners = face.map(|v| {
                        Point3::from(
                            rotation * layer.mesh.positions[v as usize].coords.cast::<f64>()
                                + translation,
                        )
                    });
                    let light = || Self::corner_light(layer, index);
                    setup_triangle(camera, &corners, l as u16, NEAR_PLANE_M, light, &mut out);
                }
                out
            })
            .collect();
        per_chunk.concat()
    }

    /// Rasterizes and resolves the images band by band (32 rows each), in parallel, into
    /// buffers of the camera's size: colour only when `rgb` is given.
    fn draw(
        &self,
        camera: &PinholeCamera,
        world_from_camera: &Isometry3<f64>,
        triangles: &[SetupTriangle],
        rgb: Option<&mut [[u8; 3]]>,
        depth_m: &mut [f32],
        instance: &mut [u16],
    ) {
        let h = camera.height;
        let band_len = camera.width as usize * TILE_SIZE as usize;
        let mut bands: Vec<Vec<u32>> = vec![Vec::new(); h.div_ceil(TILE_SIZE) as usize];
        for (index, t) in triangles.iter().enumerate() {
            for band in
                &mut bands[(t.bbox[1] / TILE_SIZE) as usize..=(t.bbox[3] / TILE_SIZE) as usize]
            {
                band.push(index as u32);
            }
        }
        let view = ViewRays::new(camera, world_from_camera);
        // Each band's rows of the colour image, or none for every band.
        let rgb_bands: Vec<Option<&mut [[u8; 3]]>> = match rgb {
            Some(rgb) => rgb.chunks_mut(band_len).map(Some).collect(),
            None => bands.iter().map(|_| None).collect(),
        };
        depth_m
            .par_chunks_mut(band_len)
            .zip(instance.par_chunks_mut(band_len))
            .zip(rgb_bands.into_par_iter())
            .zip(bands.par_iter())
            .enumerate()
            .for_each(|(band, (((depth_m, instance), rgb), in_band))| {
                let mut out = BandOutput {
                    rgb,
                    depth_m,
                    instance,
                };
                self.draw_band(camera, &view, triangles, in_band, band as u32, &mut out);
            });
    }

    /// Bins a band's triangles into its tiles, then rasterizes and resolves tile by tile.
    fn draw_band(
        &self,
        camera: &PinholeCamera,
        view: &ViewRays,
        triangles: &[SetupTriangle],
        in_band: &[u32],
        band: u32,
        out: &mut BandOutput,
    ) {
        let mut bins: Vec<Vec<u32>> = vec![Vec::new(); camera.width.div_ceil(TILE_SIZE) as usize];
        for &index in in_band {
            let [x0, _, x1, _] = triangles[index as usize].bbox;
            for bin in &mut bins[(x0 / TILE_SIZE) as usize..=(x1 / TILE_SIZE) as usize] {
                bin.push(index);
            }
        }
        let mut tile = TileBuffer::new();
        let y0 = band * TILE_SIZE;
        let rows = (camera.height - y0).min(TILE_SIZE);
        for (tx, bin) in bins.iter().enumerate() {
            let x0 = tx as u32 * TILE_SIZE;
            rasterize_tile(camera, triangles, bin, (x0, y0), &mut tile);
            let columns = (camera.width - x0).min(TILE_SIZE);
            for row in 0..rows {
                for column in 0..columns {
                    let slot = (row * TILE_SIZE + column) as usize;
                    let pixel = (row * camera.width + x0 + column) as usize;
                    let (u, v) = (f64::from(x0 + column), f64::from(y0 + row));
                    let winner = tile.winners[slot];
                    if winner == u32::MAX {
                        if let Some(rgb) = out.rgb.as_deref_mut() {
                            rgb[pixel] = view.sky(u, v);
                        }
                        continue;
                    }
                    let t = &triangles[winner as usize];
                    let z = t
                        .shading
                        .depth_m(u, v)
                        .unwrap_or_else(|| 1.0 / f64::from(tile.inv_depth[slot]));
                    let layer = &self.layers[t.layer as usize];
                    if let Some(rgb) = out.rgb.as_deref_mut() {
                        let light = t.shading.light(u, v, z);
                        let albedo = self.albedo(layer.material, &view.world_point(u, v, z));
                        rgb[pixel] = shade(albedo, light);
                    }
                    out.depth_m[pixel] = z as f32;
                    out.instance[pixel] = layer.instance_id;
                }
            }
        }
    }

    /// Albedo (0–255 per channel) of a material at a world point.
    fn albedo(&self, material: Material, p_world: &Point3<f64>) -> [f32; 3] {
        match material {
            Material::Terrain => self.world.terrain_albedo.sample(p_world.x, p_world.y),
            Material::Solid(base) => self
                .rock_texture
                .albedo(base, p_world.x, p_world.y, p_world.z)
                .map(f32::from),
        }
    }
}

/// A pixel's colour: `albedo` (0–255 per channel) times `light`, rounded half up and clamped
/// to 0–255, as `(a · light + ½).clamp(0, 255) as u8` per channel gives it, bit for bit (a NaN
/// channel is 0 either way).
///
/// Why lanes: it runs for every shaded pixel of every frame, and three saturating `f32 as u8`
/// conversions cost more there than one clamp and one truncating conversion of the three
/// channels together (the clamped value is in 0–255, where truncation is the cast's rounding).
#[inline]
fn shade(albedo: [f32; 3], light: f32) -> [u8; 3] {
    let [r, g, b] = albedo;
    let lit = f32x4::new([r, g, b, 0.0]) * f32x4::splat(light) + f32x4::splat(0.5);
    let [r, g, b, _] = lit
        .fast_max(f32x4::ZERO)
        .fast_min(f32x4::splat(255.0))
        .fast_trunc_int()
        .to_array();
    // A NaN lane truncates to i32::MIN, whose low byte is 0, as `NaN as u8` is.
    [r as u8, g as u8, b as u8]
}

/// One band's rows of the output images (colour only when shading).
struct BandOutput<'a> {
    rgb: Option<&'a mut [[u8; 3]]>,
    depth_m: &'a mut [f32],
    instance: &'a mut [u16],
}

/// The world-frame pixel rays of one view. The camera-frame ray r(u, v) is affine in (u, v)
/// (see [`along_ray`]), so each world component of its direction, a row of the rotation dotted
/// with r, is too; the world point at z-depth z is `origin + z·direction(u, v)`.
struct ViewRays {
    /// The camera centre, world frame, metres.
    origin: Vector3<f64>,
    /// Per world axis, the coefficients of the ray direction's component.
    direction: [[f64; 3]; 3],
}

impl ViewRays {
    fn new(camera: &PinholeCamera, world_from_camera: &Isometry3<f64>) -> Self {
        let rotation = world_from_camera.rotation.to_rotation_matrix();
        Self {
            origin: world_from_camera.translation.vector,
            direction: std::array::from_fn(|axis| {
                along_ray(camera, &rotation.matrix().row(axis).transpose())
            }),
        }
    }

    fn direction(&self, u: f64, v: f64) -> Vector3<f64> {
        Vector3::from(self.direction.map(|c| affine(&c, u, v)))
    }

    /// The world point at z-depth `depth_m` on pixel (u, v)'s ray.
    fn world_point(&self, u: f64, v: f64, depth_m: f64) -> Point3<f64> {
        Point3::from(self.origin + self.direction(u, v) * depth_m)
    }

    /// Sky colour, brighter toward the horizon.
    fn sky(&self, u: f64, v: f64) -> [u8; 3] {
        let up = self.direction(u, v).normalize().z.clamp(0.0, 1.0) as f32;
        [(190.0 - 70.0 * up) as u8, (210.0 - 50.0 * up) as u8, 235]
    }
}

#[cfg(test)]
mod tests {
    use proptest::prelude::*;

    use super::shade;

    /// The per-channel rule `shade` replaces.
    fn scalar_shade(albedo: [f32; 3], light: f32) -> [u8; 3] {
        albedo.map(|a| (a * light + 0.5).clamp(0.0, 255.0) as u8)
    }

    #[test]
    fn shading_edge_cases_match_the_scalar_rule() {
        for (albedo, light) in [
            ([0.0, 127.5, 255.0], 1.0),
            ([254.5, 0.49, 300.0], 1.0),
            ([-3.0, f32::NAN, f32::INFINITY], 1.0),
            ([200.0, 100.0, 50.0], f32::NAN),
            ([200.0, 100.0, 50.0], -1.0),
            ([200.0, 100.0, 50.0], 1e30),
        ] {
            assert_eq!(
                shade(albedo, light),
                scalar_shade(albedo, light),
                "{albedo:?} × {light}"
            );
        }
    }

    proptest! {
        #[test]
        fn shading_is_the_scalar_rule_bit_for_bit(
            r in -10.0f32..300.0, g in -10.0f32..300.0, b in -10.0f32..300.0,
            light in -0.5f32..3.0,
        ) {
            prop_assert_eq!(shade([r, g, b], light), scalar_shade([r, g, b], light));
        }
    }
}
