//! What a frame is tracked against: the previous frame, or a raycast of the TSDF model.
//!
//! Both become the same [`TrackingReference`]: per pyramid level, a vertex map and a normal map
//! in the reference camera's frame, and an intensity image with its gradients. The previous
//! frame gets normals from its depth; a raycast brings the model's normals.

use rayon::prelude::*;

use super::{OdometryConfig, OdometryError};
use crate::PinholeCamera;
use crate::image::{DepthImage, GrayImage, Image, ImagePyramid, downsample_depth, downsample_gray};

/// Images rendered from the TSDF model at the predicted camera pose (the raycaster's output),
/// all in the reference camera's frame and of the camera's size.
#[derive(Debug, Clone)]
pub struct RaycastImages {
    /// z-depth of the model surface, metres; 0.0 where the ray hit nothing.
    pub depth_m: DepthImage,
    /// Unit surface normals in the reference camera frame (any orientation; they are turned to
    /// face the camera); `[0, 0, 0]` where unknown.
    pub normals: Image<[f32; 3]>,
    /// Model intensity (from the fused colour) in [0, 1].
    pub intensity: GrayImage,
}

/// One reference pixel: everything the linearisation reads at a pixel, packed together so a
/// lookup touches few cache lines.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(crate) struct RefPixel {
    /// Camera-frame point; z = 0 marks no surface.
    pub vertex: [f32; 3],
    /// Unit normal facing the camera; zero when unknown.
    pub normal: [f32; 3],
    /// Intensity.
    pub intensity: f32,
    /// ∂I/∂u and ∂I/∂v (central differences; 0 on the border).
    pub grad_u: f32,
    pub grad_v: f32,
}

/// One pyramid level of a reference, row-major, `width × height`.
#[derive(Debug, Clone)]
pub(crate) struct ReferenceLevel {
    pub camera: PinholeCamera,
    pub width: usize,
    pub height: usize,
    pub pixels: Vec<RefPixel>,
    /// Intensity exists only where there is a surface (a raycast): the photometric term then
    /// needs all four bilinear neighbours on the surface.
    pub intensity_needs_surface: bool,
}

/// The reference a frame is tracked against, as a pyramid (level 0 is full resolution).
#[derive(Debug, Clone)]
pub struct TrackingReference {
    pub(crate) levels: Vec<ReferenceLevel>,
}

impl TrackingReference {
    /// A reference from a frame's intensity/depth pyramid (frame-to-frame tracking); normals
    /// come from the depth. `camera` is the level-0 camera of the pyramid.
    ///
    /// # Errors
    /// [`OdometryError::InvalidConfig`]; [`OdometryError::Input`] when the pyramid does not match
    /// the camera or has fewer levels than `config.levels`.
    pub fn from_pyramid(
        camera: &PinholeCamera,
        pyramid: &ImagePyramid,
        config: &OdometryConfig,
    ) -> Result<Self, OdometryError> {
        config.validate()?;
        check_pyramid(camera, pyramid, config.levels)?;
        let levels = (0..config.levels)
            .map(|level| {
                let cam = camera.downsampled(level as u32);
                let vertices = vertex_map(&cam, &pyramid.depth_m[level]);
                let normals = normals_from_vertices(
                    &vertices,
                    cam.width as usize,
                    cam.height as usize,
                    config.normal_radius_px,
                    config.normal_max_depth_jump_ratio as f32,
                );
                build_level(cam, vertices, normals, &pyramid.gray[level], false)
            })
            .collect();
        Ok(Self { levels })
    }

    /// A reference from a raycast of the model (frame-to-model tracking). Coarser levels average
    /// the model's normals over the blocks whose depths agree.
    ///
    /// # Errors
    /// [`OdometryError::InvalidConfig`]; [`OdometryError::Input`] when an image's size differs
    /// from the camera's.
    pub fn from_raycast(
        camera: &PinholeCamera,
        raycast: &RaycastImages,
        config: &OdometryConfig,
    ) -> Result<Self, OdometryError> {
        config.validate()?;
        camera.validate()?;
        raycast
            .depth_m
            .check_size("raycast depth", camera.width, camera.height)?;
        raycast
            .normals
            .check_size("raycast normals", camera.width, camera.height)?;
        raycast
            .intensity
            .check_size("raycast intensity", camera.width, camera.height)?;
        let mut depth = raycast.depth_m.clone();
        let mut gray = raycast.intensity.clone();
        let mut normals = raycast.normals.as_slice().to_vec();
        let mut levels = Vec::with_capacity(config.levels);
        for level in 0..config.levels {
            let cam = camera.downsampled(level as u32);
            let vertices = vertex_map(&cam, &depth);
            // The model's normals where they agree (within 20°) with the normals of the raycast
            // depth, else the depth's; none across silhouettes or at the region-of-interest cut
            // (where a raycast can end on a spurious crossing), where the depth has no normal.
            let from_depth = normals_from_vertices(
                &vertices,
                cam.width as usize,
                cam.height as usize,
                config.normal_radius_px,
                config.normal_max_depth_jump_ratio as f32,
            );
            let facing: Vec<[f32; 3]> = face_camera(&vertices, &normals)
                .into_iter()
                .zip(from_depth)
                .map(|(model, depth)| {
                    // 0.94 ≈ cos 20°.
                    if dot(model, depth) >= 0.94 {
                        model
                    } else {
                        depth
                    }
                })
                .collect();
            if level + 1 < config.levels {
                let next_depth = downsample_depth(&depth);
                normals = downsample_normals(&normals, depth.width() as usize, &next_depth);
                let next_gray = downsample_gray(&gray);
                levels.push(build_level(cam, vertices, facing, &gray, true));
                depth = next_depth;
                gray = next_gray;
            } else {
                levels.push(build_level(cam, vertices, facing, &gray, true));
            }
        }
        Ok(Self { levels })
    }

    /// Number of pyramid levels.
    pub fn levels(&self) -> usize {
        self.levels.len()
    }

    /// The level-0 camera.
    pub fn camera(&self) -> &PinholeCamera {
        &self.levels[0].camera
    }
}

/// Checks that a pyramid has `levels` levels whose sizes follow `camera`.
pub(crate) fn check_pyramid(
    camera: &PinholeCamera,
    pyramid: &ImagePyramid,
    levels: usize,
) -> Result<(), OdometryError> {
    camera.validate()?;
    if pyramid.levels() < levels || pyramid.depth_m.len() < levels {
        return Err(OdometryError::PyramidLevels {
            have: pyramid.levels(),
            need: levels,
        });
    }
    for level in 0..levels {
        let cam = camera.downsampled(level as u32);
        pyramid.gray[level].check_size("pyramid intensity", cam.width, cam.height)?;
        pyramid.depth_m[level].check_size("pyramid depth", cam.width, cam.height)?;
    }
    Ok(())
}

fn build_level(
    camera: PinholeCamera,
    vertices: Vec<[f32; 3]>,
    normals: Vec<[f32; 3]>,
    gray: &GrayImage,
    intensity_needs_surface: bool,
) -> ReferenceLevel {
    let (width, height) = (camera.width as usize, camera.height as usize);
    let intensity = gray.as_slice();
    let (mut grad_u, mut grad_v) = gradients(intensity, width, height);
    if intensity_needs_surface {
        // A raycast has no intensity off the model: no gradient may reach across its border.
        let has = |i: usize| vertices[i][2] > 0.0;
        for v in 0..height {
            for u in 0..width {
                let i = v * width + u;
                let inside = u > 0 && v > 0 && u + 1 < width && v + 1 < height;
                if !(inside
                    && has(i)
                    && has(i - 1)
                    && has(i + 1)
                    && has(i - width)
                    && has(i + width))
                {
                    grad_u[i] = 0.0;
                    grad_v[i] = 0.0;
                }
            }
        }
    }
    let pixels = (0..vertices.len())
        .into_par_iter()
        .map(|i| RefPixel {
            vertex: vertices[i],
            normal: normals[i],
            intensity: intensity[i],
            grad_u: grad_u[i],
            grad_v: grad_v[i],
        })
        .collect();
    ReferenceLevel {
        camera,
        width,
        height,
        pixels,
        intensity_needs_surface,
    }
}

/// Camera-frame points of a depth image; z = 0 where there is no depth (or it is not finite).
fn vertex_map(camera: &PinholeCamera, depth: &DepthImage) -> Vec<[f32; 3]> {
    let w = depth.width() as usize;
    let (fx, fy, cx, cy) = (
        camera.fx as f32,
        camera.fy as f32,
        camera.cx as f32,
        camera.cy as f32,
    );
    let (inv_fx, inv_fy) = (1.0 / fx, 1.0 / fy);
    depth
        .as_slice()
        .par_iter()
        .enumerate()
        .map(|(i, &z)| {
            if z > 0.0 && z.is_finite() {
                let (u, v) = ((i % w) as f32, (i / w) as f32);
                [(u - cx) * inv_fx * z, (v - cy) * inv_fy * z, z]
            } else {
                [0.0; 3]
            }
        })
        .collect()
}

/// Central-difference intensity gradients in pixels; zero on the border rows and columns.
fn gradients(intensity: &[f32], width: usize, height: usize) -> (Vec<f32>, Vec<f32>) {
    let mut gu = vec![0.0f32; intensity.len()];
    let mut gv = vec![0.0f32; intensity.len()];
    if width < 3 || height < 3 {
        return (gu, gv);
    }
    gu.par_chunks_mut(width)
        .zip(gv.par_chunks_mut(width))
        .enumerate()
        .skip(1)
        .take(height - 2)
        .for_each(|(v, (row_u, row_v))| {
            let i0 = v * width;
            for u in 1..width - 1 {
                let i = i0 + u;
                row_u[u] = 0.5 * (intensity[i + 1] - intensity[i - 1]);
                row_v[u] = 0.5 * (intensity[i + width] - intensity[i - width]);
            }
        });
    (gu, gv)
}

fn sub(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn cross(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// `n` scaled to unit length and turned to face the camera at the origin (n·p < 0), or zero
/// when it has no length.
fn unit_facing(n: [f32; 3], p: [f32; 3]) -> [f32; 3] {
    let len = dot(n, n).sqrt();
    if !(len > 1e-12) || !len.is_finite() {
        return [0.0; 3];
    }
    let s = if dot(n, p) > 0.0 {
        -1.0 / len
    } else {
        1.0 / len
    };
    [n[0] * s, n[1] * s, n[2] * s]
}

/// Normals from the cross product of the horizontal and vertical differences `radius` pixels
/// apart; zero where a neighbour is missing or lies across a depth jump.
fn normals_from_vertices(
    vertices: &[[f32; 3]],
    width: usize,
    height: usize,
    radius: usize,
    max_jump_ratio: f32,
) -> Vec<[f32; 3]> {
    let mut normals = vec![[0.0f32; 3]; vertices.len()];
    if width <= 2 * radius || height <= 2 * radius {
        return normals;
    }
    normals
        .par_chunks_mut(width)
        .enumerate()
        .skip(radius)
        .take(height - 2 * radius)
        .for_each(|(v, row)| {
            for (u, out) in row.iter_mut().enumerate().take(width - radius).skip(radius) {
                let i = v * width + u;
                let p = vertices[i];
                if p[2] <= 0.0 {
                    continue;
                }
                let neighbours = [
                    vertices[i - radius],
                    vertices[i + radius],
                    vertices[i - radius * width],
                    vertices[i + radius * width],
                ];
                let ok = neighbours
                    .iter()
                    .all(|q| q[2] > 0.0 && (q[2] - p[2]).abs() <= max_jump_ratio * p[2]);
                if ok {
                    let du = sub(neighbours[1], neighbours[0]);
                    let dv = sub(neighbours[3], neighbours[2]);
                    *out = unit_facing(cross(du, dv), p);
                }
            }
        });
    normals
}

/// Unit normals facing the camera; zero where the vertex is missing.
fn face_camera(vertices: &[[f32; 3]], normals: &[[f32; 3]]) -> Vec<[f32; 3]> {
    vertices
        .par_iter()
        .zip(normals.par_iter())
        .map(|(&p, &n)| {
            if p[2] > 0.0 && n.iter().all(|c| c.is_finite()) {
                unit_facing(n, p)
            } else {
                [0.0; 3]
            }
        })
        .collect()
}

/// Halves a normal map: the sum of the 2×2 block's normals where the coarse depth is valid
/// (renormalised later by [`face_camera`]), zero elsewhere.
fn downsample_normals(
    normals: &[[f32; 3]],
    fine_width: usize,
    coarse_depth: &DepthImage,
) -> Vec<[f32; 3]> {
    let w = coarse_depth.width() as usize;
    let fine_height = normals.len() / fine_width.max(1);
    coarse_depth
        .as_slice()
        .par_iter()
        .enumerate()
        .map(|(i, &z)| {
            if z <= 0.0 {
                return [0.0; 3];
            }
            let (u, v) = (i % w, i / w);
            let mut sum = [0.0f32; 3];
            for (du, dv) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                let (fu, fv) = (2 * u + du, 2 * v + dv);
                if fu < fine_width && fv < fine_height {
                    let n = normals[fv * fine_width + fu];
                    if n.iter().all(|c| c.is_finite()) {
                        sum = [sum[0] + n[0], sum[1] + n[1], sum[2] + n[2]];
                    }
                }
            }
            sum
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plane_normals_face_the_camera() {
        let camera = PinholeCamera::from_hfov(40, 30, 80.0).unwrap();
        let depth = DepthImage::filled(40, 30, 2.0);
        let vertices = vertex_map(&camera, &depth);
        let normals = normals_from_vertices(&vertices, 40, 30, 1, 0.05);
        let n = normals[15 * 40 + 20];
        assert!((n[2] + 1.0).abs() < 1e-5, "{n:?}");
        assert_eq!(normals[0], [0.0; 3]);
    }

    #[test]
    fn gradients_of_a_ramp() {
        let intensity: Vec<f32> = (0..20).map(|i| (i % 5) as f32 * 0.1).collect();
        let (gu, gv) = gradients(&intensity, 5, 4);
        assert!((gu[5 + 2] - 0.1).abs() < 1e-6);
        assert!(gv[5 + 2].abs() < 1e-6);
        assert_eq!(gu[0], 0.0);
    }
}
