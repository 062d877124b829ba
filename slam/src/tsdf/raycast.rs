//! Raycasting a TSDF volume into depth, normal and colour images from any pinhole camera
//! (model-to-frame tracking in odometry, previews).

use nalgebra::{Isometry3, Point3, Vector3};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::{TsdfError, TsdfVolume};
use crate::geometry::{PinholeCamera, check_finite_isometry};
use crate::image::{DepthImage, Image, RgbImage};

/// Raycasting parameters.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RaycastConfig {
    /// Rays start at this z-depth, metres. Default 0.1.
    pub min_depth_m: f32,
    /// Rays stop at this z-depth, metres. Default 10.
    pub max_depth_m: f32,
    /// Voxels with a weight at or below this count as unobserved. Default 0.
    pub min_weight: f32,
    /// Step inside observed space, as a fraction of the TSDF value times the truncation
    /// distance. Default 0.8 (never overshoots a zero crossing by more than the TSDF allows).
    pub step_fraction: f32,
}

impl Default for RaycastConfig {
    fn default() -> Self {
        Self {
            min_depth_m: 0.1,
            max_depth_m: 10.0,
            min_weight: 0.0,
            step_fraction: 0.8,
        }
    }
}

/// Images raycast from a volume. Pixels without a surface have depth 0, normal zero and colour
/// black.
#[derive(Debug, Clone, PartialEq)]
pub struct RaycastOutput {
    /// z-depth in metres along the camera z axis; 0 where no surface was hit.
    pub depth_m: DepthImage,
    /// Unit surface normals in the camera frame (OpenCV), facing the camera.
    pub normals_camera: Image<[f32; 3]>,
    /// sRGB colour of the voxel nearest the hit.
    pub rgb: RgbImage,
}

/// One pixel's result: z-depth, camera-frame normal, colour.
type RayHit = (f32, [f32; 3], [u8; 3]);

/// Raycasts `volume` from `camera` at `world_from_camera`: the first zero crossing from positive
/// to negative TSDF along each pixel ray.
///
/// # Errors
/// [`TsdfError::Geometry`] for invalid intrinsics or a non-finite pose.
pub fn raycast(
    volume: &TsdfVolume,
    camera: &PinholeCamera,
    world_from_camera: &Isometry3<f64>,
    config: &RaycastConfig,
) -> Result<RaycastOutput, TsdfError> {
    let geometry = |source| TsdfError::Geometry { frame: 0, source };
    camera.validate().map_err(geometry)?;
    check_finite_isometry(world_from_camera, "world_from_camera").map_err(geometry)?;
    let width = camera.width as usize;
    let height = camera.height as usize;
    let origin = world_from_camera.translation.vector.cast::<f32>();
    let rotation = world_from_camera
        .rotation
        .to_rotation_matrix()
        .matrix()
        .cast::<f32>();
    let camera_from_world_rotation = rotation.transpose();
    // Rays are marched only through the box of the allocated blocks: outside it every voxel
    // is unobserved.
    let Some(bounds) = allocated_bounds(volume) else {
        return Ok(RaycastOutput {
            depth_m: DepthImage::filled(camera.width, camera.height, 0.0),
            normals_camera: Image::filled(camera.width, camera.height, [0.0; 3]),
            rgb: Image::filled(camera.width, camera.height, [0; 3]),
        });
    };
    let rows: Vec<Vec<RayHit>> = (0..height)
        .into_par_iter()
        .map(|v| {
            (0..width)
                .map(|u| {
                    let ray_camera = Vector3::new(
                        ((u as f64 - camera.cx) / camera.fx) as f32,
                        ((v as f64 - camera.cy) / camera.fy) as f32,
                        1.0,
                    );
                    let ray_world = rotation * ray_camera;
                    match cast_ray(volume, &origin, &ray_world, &bounds, config) {
                        Some((z, normal_world, color)) => {
                            let mut n = camera_from_world_rotation * normal_world;
                            if n.dot(&ray_camera) > 0.0 {
                                n = -n;
                            }
                            (z, [n.x, n.y, n.z], color)
                        }
                        None => (0.0, [0.0; 3], [0; 3]),
                    }
                })
                .collect()
        })
        .collect();
    let mut depth = Vec::with_capacity(width * height);
    let mut normals = Vec::with_capacity(width * height);
    let mut rgb = Vec::with_capacity(width * height);
    for row in rows {
        for (z, n, c) in row {
            depth.push(z);
            normals.push(n);
            rgb.push(c);
        }
    }
    let size_error = |source| TsdfError::Geometry { frame: 0, source };
    Ok(RaycastOutput {
        depth_m: Image::from_vec(camera.width, camera.height, depth).map_err(size_error)?,
        normals_camera: Image::from_vec(camera.width, camera.height, normals)
            .map_err(size_error)?,
        rgb: Image::from_vec(camera.width, camera.height, rgb).map_err(size_error)?,
    })
}

/// Marches one ray parameterised by z-depth (`origin + z · ray`, `ray.z_camera = 1`); returns
/// the hit's z-depth, world normal and colour.
fn cast_ray(
    volume: &TsdfVolume,
    origin: &Vector3<f32>,
    ray: &Vector3<f32>,
    bounds: &(Vector3<f32>, Vector3<f32>),
    config: &RaycastConfig,
) -> Option<(f32, Vector3<f32>, [u8; 3])> {
    let vc = volume.config();
    let ray_length = ray.norm();
    let truncation = vc.truncation_m();
    let unknown_step = 0.5 * vc.block_size_m() / ray_length;
    let min_step = 0.5 * vc.voxel_size_m / ray_length;
    let at = |z: f32| Point3::from(origin + ray * z);
    let (enter, exit) = clip_to_box(origin, ray, bounds)?;
    let mut z = config.min_depth_m.max(enter);
    let z_end = config.max_depth_m.min(exit);
    let mut previous: Option<(f32, f32)> = None;
    while z <= z_end {
        match volume.tsdf_at(&at(z), config.min_weight) {
            None => {
                previous = None;
                z += unknown_step;
            }
            Some(t) => {
                if let Some((z0, t0)) = previous
                    && t0 > 0.0
                    && t <= 0.0
                {
                    let hit = z0 + (z - z0) * t0 / (t0 - t);
                    let p = at(hit);
                    let normal = gradient(volume, &p, config.min_weight)?;
                    let s = vc.voxel_size_m;
                    let nearest = [p.x, p.y, p.z].map(|c| (c / s).round() as i32);
                    let color = volume.voxel(nearest).map_or([0; 3], |v| v.color);
                    return Some((hit, normal, color));
                }
                previous = Some((z, t));
                z += (config.step_fraction * t * truncation / ray_length).max(min_step);
            }
        }
    }
    None
}

/// Unit TSDF gradient (pointing out of the surface) at `p` by central differences of the
/// trilinear TSDF, one voxel apart; `None` where a neighbour is unobserved or the gradient
/// vanishes.
fn gradient(volume: &TsdfVolume, p: &Point3<f32>, min_weight: f32) -> Option<Vector3<f32>> {
    let s = volume.config().voxel_size_m;
    let mut g = Vector3::zeros();
    for a in 0..3 {
        let mut offset = Vector3::zeros();
        offset[a] = s;
        let plus = volume.tsdf_at(&(p + offset), min_weight)?;
        let minus = volume.tsdf_at(&(p - offset), min_weight)?;
        g[a] = plus - minus;
    }
    let n = g.norm();
    (n > 0.0).then(|| g / n)
}

/// The box (metres) spanned by the allocated blocks, or `None` for an empty volume.
fn allocated_bounds(volume: &TsdfVolume) -> Option<(Vector3<f32>, Vector3<f32>)> {
    let coords = volume.block_coords();
    let first = coords.first()?;
    let (mut lo, mut hi) = (*first, *first);
    for c in coords {
        for a in 0..3 {
            lo[a] = lo[a].min(c[a]);
            hi[a] = hi[a].max(c[a]);
        }
    }
    let block = volume.config().block_size_m();
    let voxel = volume.config().voxel_size_m;
    // Voxel centres of block b span b·block … b·block + 7 voxels; one voxel of slack each side.
    Some((
        Vector3::from(lo.map(|c| c as f32 * block - voxel)),
        Vector3::from(hi.map(|c| (c + 1) as f32 * block + voxel)),
    ))
}

/// The ray parameters (z-depth) where `origin + z·ray` enters and leaves the box; `None` when
/// it misses (slab method).
fn clip_to_box(
    origin: &Vector3<f32>,
    ray: &Vector3<f32>,
    (lo, hi): &(Vector3<f32>, Vector3<f32>),
) -> Option<(f32, f32)> {
    let (mut enter, mut exit) = (f32::NEG_INFINITY, f32::INFINITY);
    for a in 0..3 {
        if ray[a] == 0.0 {
            if origin[a] < lo[a] || origin[a] > hi[a] {
                return None;
            }
            continue;
        }
        let (t0, t1) = ((lo[a] - origin[a]) / ray[a], (hi[a] - origin[a]) / ray[a]);
        enter = enter.max(t0.min(t1));
        exit = exit.min(t0.max(t1));
    }
    (enter <= exit).then_some((enter, exit))
}
