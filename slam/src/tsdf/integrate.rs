//! Projective integration of one RGBD frame: allocate the blocks the truncation band touches,
//! then update every voxel of those blocks in parallel.

use std::collections::HashSet;

use nalgebra::{Isometry3, Matrix3, Vector3};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::{BLOCK_SIDE, Block, BlockCoord, BuildBlockHasher, TsdfError, TsdfVolume, local_index};
use crate::frame::RgbdFrame;
use crate::geometry::floor_i32;
use crate::geometry::{PinholeCamera, check_finite_isometry};
use crate::image::{DepthImage, RgbImage};

/// What one integration did.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct IntegrationStats {
    /// Blocks inside the truncation band of this frame (updated).
    pub blocks_updated: usize,
    /// Blocks newly allocated by this frame.
    pub blocks_allocated: usize,
}

/// Rows of the depth image handled by one allocation task.
const ALLOCATION_ROWS: usize = 16;

/// A rigid transform in f32 for the per-voxel inner loops.
#[derive(Debug, Clone, Copy)]
struct RigidF32 {
    rotation: Matrix3<f32>,
    translation: Vector3<f32>,
}

impl RigidF32 {
    fn from_isometry(t: &Isometry3<f64>) -> Self {
        Self {
            rotation: t.rotation.to_rotation_matrix().matrix().cast::<f32>(),
            translation: t.translation.vector.cast::<f32>(),
        }
    }

    #[inline]
    fn apply(&self, p: &Vector3<f32>) -> Vector3<f32> {
        self.rotation * p + self.translation
    }
}

pub(super) fn integrate(
    volume: &mut TsdfVolume,
    frame: &RgbdFrame,
    camera: &PinholeCamera,
    world_from_camera: &Isometry3<f64>,
    frame_index: usize,
) -> Result<IntegrationStats, TsdfError> {
    let geometry = |source| TsdfError::Geometry {
        frame: frame_index,
        source,
    };
    camera.validate().map_err(geometry)?;
    check_finite_isometry(world_from_camera, "world_from_camera").map_err(geometry)?;
    let depth_size = (frame.depth_m.width(), frame.depth_m.height());
    if frame.width() != camera.width
        || frame.height() != camera.height
        || depth_size != (camera.width, camera.height)
    {
        return Err(TsdfError::FrameSize {
            frame: frame_index,
            width: depth_size.0.min(frame.width()),
            height: depth_size.1.min(frame.height()),
            camera_width: camera.width,
            camera_height: camera.height,
        });
    }
    let touched = touched_blocks(volume, &frame.depth_m, camera, world_from_camera);
    let mut allocated = 0;
    let mut update = vec![false; volume.blocks.len() + touched.len()];
    for coord in &touched {
        let index = match volume.index.get(coord) {
            Some(&i) => i as usize,
            None => {
                let i = volume.blocks.len();
                // Block counts stay far below u32::MAX (that would be 20 TB of voxels).
                volume.index.insert(*coord, i as u32);
                volume.coords.push(*coord);
                volume.blocks.push(Block::new());
                allocated += 1;
                i
            }
        };
        update[index] = true;
    }
    update.truncate(volume.blocks.len());
    let kernel = Kernel::new(&volume.config, camera, world_from_camera);
    let depth = &frame.depth_m;
    let rgb = &frame.rgb;
    volume
        .blocks
        .par_iter_mut()
        .zip(volume.coords.par_iter())
        .zip(update.par_iter())
        .filter(|(_, u)| **u)
        .for_each(|((block, coord), _)| kernel.update_block(block, coord, depth, rgb));
    Ok(IntegrationStats {
        blocks_updated: touched.len(),
        blocks_allocated: allocated,
    })
}

/// Blocks (sorted) that the truncation band around the measured depths touches, inside the ROI.
fn touched_blocks(
    volume: &TsdfVolume,
    depth: &DepthImage,
    camera: &PinholeCamera,
    world_from_camera: &Isometry3<f64>,
) -> Vec<BlockCoord> {
    let config = &volume.config;
    let truncation = config.truncation_m();
    let inv_block = 1.0 / config.block_size_m();
    let half_voxel = 0.5 * config.voxel_size_m;
    let block_size_f64 = f64::from(config.block_size_m());
    let transform = RigidF32::from_isometry(world_from_camera);
    let (fx, fy, cx, cy) = (
        camera.fx as f32,
        camera.fy as f32,
        camera.cx as f32,
        camera.cy as f32,
    );
    let width = depth.width() as usize;
    let height = depth.height() as usize;
    let data = depth.as_slice();
    let chunks: Vec<HashSet<BlockCoord, BuildBlockHasher>> = (0..height.div_ceil(ALLOCATION_ROWS))
        .into_par_iter()
        .map(|chunk| {
            let mut set = HashSet::with_hasher(BuildBlockHasher::default());
            // The last few blocks inserted: neighbouring pixels mostly touch the same blocks.
            let mut recent = [[i32::MIN; 3]; 8];
            let mut slot = 0;
            for v in chunk * ALLOCATION_ROWS..((chunk + 1) * ALLOCATION_ROWS).min(height) {
                for u in 0..width {
                    let d = data[v * width + u];
                    if !(d >= config.min_depth_m && d <= config.max_depth_m) {
                        continue;
                    }
                    let ray = Vector3::new((u as f32 - cx) / fx, (v as f32 - cy) / fy, 1.0);
                    let near = transform.apply(&(ray * (d - truncation)));
                    let far = transform.apply(&(ray * (d + truncation)));
                    if let Some(roi) = &config.roi {
                        // Conservative pre-test (one block of margin); blocks are tested exactly
                        // below.
                        let lo = [0, 1, 2].map(|a| f64::from(near[a].min(far[a])) - block_size_f64);
                        let hi = [0, 1, 2].map(|a| f64::from(near[a].max(far[a])) + block_size_f64);
                        if !roi.intersects_box(lo, hi) {
                            continue;
                        }
                    }
                    // Voxel centres sit at integer multiples of the voxel size, so block b
                    // covers [8·b − ½, 8·b + 7½) voxels.
                    let a = (near.add_scalar(half_voxel)) * inv_block;
                    let b = (far.add_scalar(half_voxel)) * inv_block;
                    walk_blocks(&a, &b, |block| {
                        if !recent.contains(&block) {
                            recent[slot] = block;
                            slot = (slot + 1) % recent.len();
                            set.insert(block);
                        }
                    });
                }
            }
            set
        })
        .collect();
    let mut all: HashSet<BlockCoord, BuildBlockHasher> =
        HashSet::with_hasher(BuildBlockHasher::default());
    for set in chunks {
        all.extend(set);
    }
    let block_size = f64::from(config.block_size_m());
    let voxel = f64::from(config.voxel_size_m);
    let mut out: Vec<BlockCoord> = all
        .into_iter()
        .filter(|b| match &config.roi {
            None => true,
            Some(roi) => {
                let lo = [0, 1, 2].map(|a| f64::from(b[a]) * block_size - 0.5 * voxel);
                let hi = [0, 1, 2].map(|a| lo[a] + block_size);
                roi.intersects_box(lo, hi)
            }
        })
        .collect();
    out.sort_unstable();
    out
}

/// Visits every grid cell the segment from `a` to `b` (grid units) passes through, in order
/// (Amanatides–Woo traversal), so no block along the truncation band is skipped.
fn walk_blocks(a: &Vector3<f32>, b: &Vector3<f32>, mut visit: impl FnMut(BlockCoord)) {
    let mut cell = [floor_i32(a.x), floor_i32(a.y), floor_i32(a.z)];
    let end = [floor_i32(b.x), floor_i32(b.y), floor_i32(b.z)];
    let dir = b - a;
    let mut step = [0i32; 3];
    let mut t_max = [f32::INFINITY; 3];
    let mut t_delta = [f32::INFINITY; 3];
    for i in 0..3 {
        if dir[i] > 0.0 {
            step[i] = 1;
            t_delta[i] = 1.0 / dir[i];
            t_max[i] = (cell[i] as f32 + 1.0 - a[i]) / dir[i];
        } else if dir[i] < 0.0 {
            step[i] = -1;
            t_delta[i] = -1.0 / dir[i];
            t_max[i] = (a[i] - cell[i] as f32) / -dir[i];
        }
    }
    visit(cell);
    let max_steps = (0..3)
        .map(|i| (end[i] - cell[i]).unsigned_abs())
        .sum::<u32>();
    for _ in 0..max_steps {
        let axis = if t_max[0] <= t_max[1] && t_max[0] <= t_max[2] {
            0
        } else if t_max[1] <= t_max[2] {
            1
        } else {
            2
        };
        if t_max[axis] > 1.0 {
            break;
        }
        cell[axis] += step[axis];
        t_max[axis] += t_delta[axis];
        visit(cell);
    }
}

/// Everything the per-voxel update needs, in f32.
struct Kernel {
    camera_from_world: RigidF32,
    fx: f32,
    fy: f32,
    cx: f32,
    cy: f32,
    width: usize,
    height: usize,
    voxel_size_m: f32,
    truncation_m: f32,
    max_weight: f32,
    min_depth_m: f32,
    max_depth_m: f32,
}

impl Kernel {
    fn new(
        config: &super::TsdfConfig,
        camera: &PinholeCamera,
        world_from_camera: &Isometry3<f64>,
    ) -> Self {
        Self {
            camera_from_world: RigidF32::from_isometry(&world_from_camera.inverse()),
            fx: camera.fx as f32,
            fy: camera.fy as f32,
            cx: camera.cx as f32,
            cy: camera.cy as f32,
            width: camera.width as usize,
            height: camera.height as usize,
            voxel_size_m: config.voxel_size_m,
            truncation_m: config.truncation_m(),
            max_weight: config.max_weight,
            min_depth_m: config.min_depth_m,
            max_depth_m: config.max_depth_m,
        }
    }

    /// Depth at sub-pixel (u, v): bilinear when the four neighbours are measured and agree
    /// within half the truncation distance, otherwise the nearest pixel. Also returns the
    /// nearest pixel's index for colour. `None` outside the image or without a measurement.
    #[inline]
    fn sample_depth(&self, depth: &[f32], u: f32, v: f32) -> Option<(f32, usize)> {
        if !(u >= -0.5 && v >= -0.5 && u < self.width as f32 - 0.5 && v < self.height as f32 - 0.5)
        {
            return None;
        }
        let nu = (u + 0.5) as usize;
        let nv = (v + 0.5) as usize;
        let nearest = nv * self.width + nu;
        // Truncation is the floor for non-negative values, and avoids the libm call that
        // `f32::floor` becomes on baseline x86-64 (it was a large share of integration time).
        if u >= 0.0 && v >= 0.0 && (u as usize) + 1 < self.width && (v as usize) + 1 < self.height {
            let (u0, v0) = ((u as usize) as f32, (v as usize) as f32);
            let i = v as usize * self.width + u as usize;
            let d = [
                depth[i],
                depth[i + 1],
                depth[i + self.width],
                depth[i + self.width + 1],
            ];
            let lo = d.iter().copied().fold(f32::INFINITY, f32::min);
            let hi = d.iter().copied().fold(0.0f32, f32::max);
            if lo > 0.0 && hi - lo < 0.5 * self.truncation_m {
                let fu = u - u0;
                let fv = v - v0;
                let top = d[0] + (d[1] - d[0]) * fu;
                let bottom = d[2] + (d[3] - d[2]) * fu;
                return Some((top + (bottom - top) * fv, nearest));
            }
        }
        let d = depth[nearest];
        (d > 0.0).then_some((d, nearest))
    }

    fn update_block(
        &self,
        block: &mut Block,
        coord: &BlockCoord,
        depth: &DepthImage,
        rgb: &RgbImage,
    ) {
        let depth = depth.as_slice();
        let rgb = rgb.as_slice();
        let s = self.voxel_size_m;
        let side = BLOCK_SIDE as i32;
        let r = &self.camera_from_world.rotation;
        let step_x = r.column(0) * s;
        let inv_truncation = 1.0 / self.truncation_m;
        for z in 0..BLOCK_SIDE {
            for y in 0..BLOCK_SIDE {
                let origin = Vector3::new(
                    (coord[0] * side) as f32 * s,
                    (coord[1] * side + y as i32) as f32 * s,
                    (coord[2] * side + z as i32) as f32 * s,
                );
                let row_start = self.camera_from_world.apply(&origin);
                for x in 0..BLOCK_SIDE {
                    let p = row_start + step_x * x as f32;
                    if p.z < self.min_depth_m {
                        continue;
                    }
                    let inv_z = 1.0 / p.z;
                    let u = self.fx * p.x * inv_z + self.cx;
                    let v = self.fy * p.y * inv_z + self.cy;
                    let Some((d, pixel)) = self.sample_depth(depth, u, v) else {
                        continue;
                    };
                    if d < self.min_depth_m || d > self.max_depth_m {
                        continue;
                    }
                    let sdf = d - p.z;
                    if sdf < -self.truncation_m {
                        continue;
                    }
                    let tsdf = (sdf * inv_truncation).min(1.0);
                    let w_obs = inv_z * inv_z;
                    let i = local_index(x, y, z);
                    let w_old = block.weight[i];
                    let w_sum = w_old + w_obs;
                    block.tsdf[i] = (block.tsdf[i] * w_old + tsdf * w_obs) / w_sum;
                    let c_old = block.color[i];
                    let c_obs = rgb[pixel];
                    // Adding 0.5 and truncating rounds these non-negative values without the
                    // libm `round` call.
                    block.color[i] = [0, 1, 2].map(|k| {
                        ((f32::from(c_old[k]) * w_old + f32::from(c_obs[k]) * w_obs) / w_sum + 0.5)
                            as u8
                    });
                    block.weight[i] = w_sum.min(self.max_weight);
                }
            }
        }
    }
}
