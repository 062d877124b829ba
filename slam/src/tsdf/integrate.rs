//! Projective integration of one RGBD frame: find the blocks the truncation band touches,
//! allocate the new ones, then update every voxel of those blocks in parallel.
//!
//! Block finding walks each pixel's truncation band through the block grid (exact: no block the
//! band crosses is skipped) and collects packed block keys per tile of rows; consecutive pixels
//! mostly hit the blocks their neighbours hit, so a tiny cache of recent keys removes most
//! repeats before the per-tile sort and the final sort + deduplication. Nothing is hashed per
//! pixel: the hash map is only consulted once per distinct block. The sorted keys make the
//! allocation order, and so the whole result, independent of the thread count.

use nalgebra::{Isometry3, Matrix3, Vector3};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use wide::f32x4;

#[cfg(target_arch = "x86_64")]
use super::lanes::{Avx2, avx2};
use super::lanes::{Float8, Int8, Mask8, Portable, Simd8};
use super::{BLOCK_SIDE, Block, BlockCoord, DepthSample, TsdfError, TsdfVolume};
use crate::frame::RgbdFrame;
use crate::geometry::{PinholeCamera, check_finite_isometry};

/// What one integration did.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct IntegrationStats {
    /// Blocks inside the truncation band of this frame (updated).
    pub blocks_updated: usize,
    /// Blocks newly allocated by this frame.
    pub blocks_allocated: usize,
}

/// Rows of the depth image handled by one block-finding task (a multiple of nothing in
/// particular: small enough to balance two to eight threads, large enough that the per-task
/// sort runs over many repeats).
const ALLOCATION_ROWS: usize = 8;

/// Bits per axis of a packed block key; block coordinates must lie in ±2^20 (±84 km at 1 cm
/// voxels, far beyond any mapped site).
const KEY_BITS: u32 = 21;
const KEY_OFFSET: i32 = 1 << (KEY_BITS - 1);
const KEY_MASK: u64 = (1 << KEY_BITS) - 1;

/// Packs a block coordinate into a `u64` whose order is the lexicographic order of (x, y, z);
/// `None` outside the representable range.
#[inline]
fn pack(b: BlockCoord) -> Option<u64> {
    // Offset into 0..2^21: a coordinate outside ±2^20 wraps (or overflows) to a u32 ≥ 2^21, so
    // one unsigned test of the three ORed together checks every axis without a branch each.
    let [x, y, z] = b.map(|c| c.wrapping_add(KEY_OFFSET) as u32);
    if (x | y | z) >> KEY_BITS != 0 {
        return None;
    }
    Some((u64::from(x) << (2 * KEY_BITS)) | (u64::from(y) << KEY_BITS) | u64::from(z))
}

/// Inverse of [`pack`].
#[inline]
fn unpack(key: u64) -> BlockCoord {
    let axis = |shift: u32| ((key >> shift) & KEY_MASK) as i32 - KEY_OFFSET;
    [axis(2 * KEY_BITS), axis(KEY_BITS), axis(0)]
}

/// Reusable per-volume buffers of the integration, so a frame allocates nothing once the
/// volume has seen a few frames.
#[derive(Debug, Clone, Default)]
pub(super) struct Scratch {
    /// Packed keys of the blocks each row tile touches and their support (pixels whose band
    /// crosses each; sorted, unique after the tile pass).
    tiles: Vec<Vec<(u64, u32)>>,
    /// All touched keys and their support, sorted and unique.
    keys: Vec<(u64, u32)>,
    /// Storage index of each touched block (`u32::MAX` while unallocated).
    indices: Vec<u32>,
    /// Per stored block: updated by this frame.
    update: Vec<bool>,
    /// The frame's colours as little-endian (r, g, b, 0) words.
    rgbx: Vec<u32>,
}

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
    let mut scratch = std::mem::take(&mut volume.scratch);
    let window = PixelWindow::for_roi(&volume.config, camera, world_from_camera);
    touched_blocks(
        volume,
        &mut scratch,
        frame,
        camera,
        world_from_camera,
        &window,
    );
    // Look the touched blocks up in parallel (read-only), then allocate the missing ones with
    // enough support serially in key order, which keeps storage order independent of the
    // thread count.
    let index = &volume.index;
    scratch.indices.clear();
    scratch.indices.par_extend(
        scratch
            .keys
            .par_iter()
            .map(|&(k, _)| index.get(&unpack(k)).copied().unwrap_or(u32::MAX)),
    );
    let min_support = volume.config.min_block_support;
    let mut allocated = 0;
    for (slot, &(key, support)) in scratch.indices.iter_mut().zip(&scratch.keys) {
        if *slot == u32::MAX && support >= min_support {
            let coord = unpack(key);
            // Block counts stay far below u32::MAX (that would be 20 TB of voxels).
            let i = volume.blocks.len() as u32;
            volume.index.insert(coord, i);
            volume.coords.push(coord);
            volume.blocks.push(Block::new());
            allocated += 1;
            *slot = i;
        }
    }
    scratch.update.clear();
    scratch.update.resize(volume.blocks.len(), false);
    let mut updated = 0;
    for &i in &scratch.indices {
        if let Some(u) = scratch.update.get_mut(i as usize) {
            *u = true;
            updated += 1;
        }
    }
    let kernel = Kernel::new(&volume.config, camera, world_from_camera);
    let depth = frame.depth_m.as_slice();
    scratch.rgbx.clear();
    scratch
        .rgbx
        .par_extend(frame.rgb.as_slice().par_iter().map(rgbx_word));
    let rgbx = &scratch.rgbx;
    volume
        .blocks
        .par_iter_mut()
        .zip(volume.coords.par_iter())
        .zip(scratch.update.par_iter())
        .filter(|(_, u)| **u)
        .for_each(|((block, coord), _)| kernel.update_block(block, coord, depth, rgbx));
    let stats = IntegrationStats {
        blocks_updated: updated,
        blocks_allocated: allocated,
    };
    volume.scratch = scratch;
    Ok(stats)
}

/// A pixel's colour as the little-endian word (r, g, b, 0) that voxels store, so that the
/// kernel fetches it with one load.
#[inline]
fn rgbx_word(&[r, g, b]: &[u8; 3]) -> u32 {
    u32::from_le_bytes([r, g, b, 0])
}

/// Fills `scratch.keys` with the packed keys (sorted, unique) of the blocks that the truncation
/// band around the measured depths touches inside the ROI, each with its support: the number of
/// pixels whose band crosses it, a precise pixel (see
/// [`super::TsdfConfig::precise_depth_limit_m`]) counting as `min_block_support` of them. Only
/// the pixels of `window` are walked: it must hold every pixel whose band can reach a block of
/// the ROI.
fn touched_blocks(
    volume: &TsdfVolume,
    scratch: &mut Scratch,
    frame: &RgbdFrame,
    camera: &PinholeCamera,
    world_from_camera: &Isometry3<f64>,
    window: &PixelWindow,
) {
    let config = &volume.config;
    let depth = &frame.depth_m;
    let truncation = config.truncation_m();
    let inv_block = 1.0 / config.block_size_m();
    let transform = RigidF32::from_isometry(world_from_camera);
    let (fx, fy, cx, cy) = (
        camera.fx as f32,
        camera.fy as f32,
        camera.cx as f32,
        camera.cy as f32,
    );
    // Everything in block units. Voxel centres sit at integer multiples of the voxel size, so
    // block b covers [8·b − ½, 8·b + 7½) voxels: shift by half a voxel before flooring.
    let r = transform.rotation * inv_block;
    let origin = (transform.translation.add_scalar(0.5 * config.voxel_size_m)) * inv_block;
    let step_u = r.column(0) / fx;
    let width = depth.width() as usize;
    let data = depth.as_slice();
    // A pixel's band [d − truncation, d + truncation] must reach the window's depth range.
    let min_depth_m = config.min_depth_m.max(window.near_m - truncation);
    let max_depth_m = config.max_depth_m.min(window.far_m + truncation);
    let precise_depth_m = config.precise_depth_limit_m();
    let min_support = config.min_block_support;
    let tiles = window.rows.len().div_ceil(ALLOCATION_ROWS);
    scratch.tiles.resize_with(tiles, Vec::new);
    let roi_blocks = config.roi.map(|roi| RoiBlocks::new(roi, config));
    let in_roi = |b: BlockCoord| roi_blocks.as_ref().is_none_or(|r| r.meets(b));
    scratch
        .tiles
        .par_iter_mut()
        .enumerate()
        .for_each(|(tile, keys)| {
            keys.clear();
            let mut recent = RecentBlocks::new(keys, &in_roi);
            let first_row = window.rows.start + tile * ALLOCATION_ROWS;
            for v in first_row..(first_row + ALLOCATION_ROWS).min(window.rows.end) {
                // Viewing ray of pixel (u, v) at unit camera depth, world axes, block units;
                // stepped along the row.
                let u0 = window.columns.start as f32;
                let mut ray = r * Vector3::new((u0 - cx) / fx, (v as f32 - cy) / fy, 1.0);
                for &d in &data[v * width + window.columns.start..v * width + window.columns.end] {
                    if d >= min_depth_m && d <= max_depth_m {
                        let a = origin + ray * (d - truncation);
                        let b = origin + ray * (d + truncation);
                        if roi_blocks.as_ref().is_none_or(|r| r.band_may_reach(&a, &b)) {
                            let support = if d <= precise_depth_m { min_support } else { 1 };
                            walk_blocks(&a, &b, |cell| recent.visit(cell, support));
                        }
                    }
                    ray += step_u;
                }
            }
            recent.flush();
            merge_counts(keys);
        });
    scratch.keys.clear();
    for tile in &scratch.tiles {
        scratch.keys.extend_from_slice(tile);
    }
    merge_counts(&mut scratch.keys);
}

/// The last few blocks a row tile's bands crossed (inside the ROI or not) and the support each
/// gathered since it entered: neighbouring pixels mostly touch the same blocks, so only a miss
/// pays for the ROI test and a push to the tile's keys. The hit path is small enough to inline
/// into the band walk; a call per block visited cost a quarter of the block finding.
struct RecentBlocks<'a, F> {
    entries: [(u64, u32); 4],
    slot: usize,
    keys: &'a mut Vec<(u64, u32)>,
    in_roi: F,
}

impl<'a, F: Fn(BlockCoord) -> bool> RecentBlocks<'a, F> {
    fn new(keys: &'a mut Vec<(u64, u32)>, in_roi: F) -> Self {
        Self {
            entries: [(u64::MAX, 0); 4],
            slot: 0,
            keys,
            in_roi,
        }
    }

    /// Adds `support` (1 for a noisy pixel's band, the whole minimum for a precise one) to
    /// block `b`.
    #[inline(always)]
    fn visit(&mut self, b: BlockCoord, support: u32) {
        let Some(key) = pack(b) else { return };
        if let Some(entry) = self.entries.iter_mut().find(|(k, _)| *k == key) {
            // Blocks outside the ROI stay at 0 and are never pushed.
            if entry.1 > 0 {
                entry.1 = entry.1.saturating_add(support);
            }
            return;
        }
        self.miss(b, key, support);
    }

    /// Evicts the oldest entry (pushing it if it is in the ROI) for block `b`.
    #[inline(never)]
    fn miss(&mut self, b: BlockCoord, key: u64, support: u32) {
        let (old, count) = self.entries[self.slot];
        if count > 0 {
            self.keys.push((old, count));
        }
        self.entries[self.slot] = (key, if (self.in_roi)(b) { support } else { 0 });
        self.slot = (self.slot + 1) % self.entries.len();
    }

    /// Pushes the entries still held.
    fn flush(self) {
        let Self { entries, keys, .. } = self;
        keys.extend(entries.iter().copied().filter(|&(_, count)| count > 0));
    }
}

/// A region of interest and the box of block coordinates holding every block that can meet it
/// (grown by a block each way against rounding): a cheap first test for blocks and for whole
/// bands before the exact one.
struct RoiBlocks {
    roi: super::Roi,
    /// First and one-past-last block coordinate on each axis.
    lo: [i32; 3],
    hi: [i32; 3],
    block_size_m: f64,
    voxel_size_m: f64,
}

impl RoiBlocks {
    fn new(roi: super::Roi, config: &super::TsdfConfig) -> Self {
        let block_size_m = f64::from(config.block_size_m());
        let voxel_size_m = f64::from(config.voxel_size_m);
        let (min, max) = roi.bounding_box();
        // Block b spans [b·block − ½ voxel, (b + 1)·block − ½ voxel).
        let to_block = |x: f64| ((x + 0.5 * voxel_size_m) / block_size_m).floor() as i32;
        Self {
            roi,
            lo: min.map(|x| to_block(x).saturating_sub(2)),
            hi: max.map(|x| to_block(x).saturating_add(2)),
            block_size_m,
            voxel_size_m,
        }
    }

    /// Whether block `b` meets the region (exact).
    fn meets(&self, b: BlockCoord) -> bool {
        (0..3).all(|a| (self.lo[a]..self.hi[a]).contains(&b[a])) && {
            let lo = b.map(|c| f64::from(c) * self.block_size_m - 0.5 * self.voxel_size_m);
            self.roi
                .intersects_box(lo, lo.map(|x| x + self.block_size_m))
        }
    }

    /// Whether a band from `a` to `b` (block units) can reach a block that meets the region.
    #[inline]
    fn band_may_reach(&self, a: &Vector3<f32>, b: &Vector3<f32>) -> bool {
        (0..3).all(|i| a[i].max(b[i]) >= self.lo[i] as f32 && a[i].min(b[i]) < self.hi[i] as f32)
    }
}

/// The pixels whose truncation band can reach a region: a rectangle of columns and rows, and
/// the range of camera depths (metres along the optical axis) the region spans.
#[derive(Debug, Clone, PartialEq)]
struct PixelWindow {
    columns: std::ops::Range<usize>,
    rows: std::ops::Range<usize>,
    near_m: f32,
    far_m: f32,
}

impl PixelWindow {
    /// The pixels whose bands can reach a block of `config`'s region of interest (every pixel
    /// without one).
    fn for_roi(
        config: &super::TsdfConfig,
        camera: &PinholeCamera,
        world_from_camera: &Isometry3<f64>,
    ) -> Self {
        match &config.roi {
            // A block meeting the region lies within its bounding box grown by a block; the
            // extra voxel covers the f32 rounding of the band ends.
            Some(roi) => Self::of_box(
                roi,
                f64::from(config.block_size_m() + config.voxel_size_m),
                camera,
                world_from_camera,
            ),
            None => Self::full(camera),
        }
    }

    /// Every pixel, every depth.
    fn full(camera: &PinholeCamera) -> Self {
        Self {
            columns: 0..camera.width as usize,
            rows: 0..camera.height as usize,
            near_m: f32::NEG_INFINITY,
            far_m: f32::INFINITY,
        }
    }

    /// The pixels whose rays meet the bounding box of `roi` grown by `margin_m` on every side,
    /// with one pixel to spare, and the grown box's camera depths. A box reaching behind the
    /// camera's centre keeps every column and row (its projection is unbounded); one wholly
    /// behind it leaves no pixel.
    fn of_box(
        roi: &super::Roi,
        margin_m: f64,
        camera: &PinholeCamera,
        world_from_camera: &Isometry3<f64>,
    ) -> Self {
        let camera_from_world = world_from_camera.inverse();
        let corners = roi.corners(margin_m).map(|c| camera_from_world * c);
        let mut window = Self::full(camera);
        let (mut near, mut far) = (f64::INFINITY, f64::NEG_INFINITY);
        let (mut u_lo, mut u_hi, mut v_lo, mut v_hi) = (
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
        );
        let mut in_front = true;
        for p in corners {
            near = near.min(p.z);
            far = far.max(p.z);
            // Depth is linear in position, so the box's depths lie between its corners'; and
            // with every corner in front the box's image lies in the hull of theirs.
            match camera.project(&p) {
                Some(q) => {
                    (u_lo, u_hi) = (u_lo.min(q.x), u_hi.max(q.x));
                    (v_lo, v_hi) = (v_lo.min(q.y), v_hi.max(q.y));
                }
                None => in_front = false,
            }
        }
        window.near_m = near as f32;
        window.far_m = far as f32;
        if far <= 0.0 {
            window.rows = 0..0;
        } else if in_front {
            let span = |lo: f64, hi: f64, size: u32| {
                let clamp = |x: f64| x.clamp(0.0, f64::from(size)) as usize;
                clamp(lo.floor() - 1.0)..clamp(hi.ceil() + 2.0)
            };
            window.columns = span(u_lo, u_hi, camera.width);
            window.rows = span(v_lo, v_hi, camera.height);
        }
        window
    }
}

/// Sorts `(key, count)` pairs by key and sums the counts of equal keys (saturating).
fn merge_counts(keys: &mut Vec<(u64, u32)>) {
    keys.par_sort_unstable_by_key(|&(k, _)| k);
    keys.dedup_by(|next, kept| {
        if next.0 == kept.0 {
            kept.1 = kept.1.saturating_add(next.1);
            true
        } else {
            false
        }
    });
}

/// Visits every grid cell the segment from `a` to `b` (grid units) passes through, in order
/// (Amanatides–Woo traversal), so no block along the truncation band is skipped.
#[inline]
fn walk_blocks(a: &Vector3<f32>, b: &Vector3<f32>, mut visit: impl FnMut(BlockCoord)) {
    let mut cell = floor_cell(a);
    let end = floor_cell(b);
    visit(cell);
    let crossed = [0, 1, 2].map(|i| cell[i] != end[i]);
    match crossed {
        [false, false, false] => return,
        // The usual case: the band crosses the planes of one axis only, so the blocks it
        // passes are those between its ends along that axis, in order, and no crossing needs
        // ordering against another axis's.
        [true, false, false] | [false, true, false] | [false, false, true] => {
            let axis = crossed.iter().position(|&c| c).unwrap_or(0);
            let step = (end[axis] - cell[axis]).signum();
            while cell[axis] != end[axis] {
                cell[axis] += step;
                visit(cell);
            }
            return;
        }
        _ => {}
    }
    let dir = b - a;
    let diff = [0, 1, 2].map(|i| end[i] - cell[i]);
    if diff.iter().all(|d| d.abs() <= 1) {
        // A short band (the usual one: truncation ≤ half a block) crosses at most one plane
        // per axis: the crossings in order of their ray parameter, ties to the lower axis as
        // the general walk breaks them, through a three-element sorting network rather than
        // that walk's data-dependent loop. Every crossing is taken, so the walk ends in `b`'s
        // cell even where rounding puts a crossing's parameter a hair beyond 1.
        let t = |i: usize| match diff[i] {
            1 => (cell[i] as f32 + 1.0 - a[i]) / dir[i],
            -1 => (a[i] - cell[i] as f32) / -dir[i],
            _ => f32::INFINITY,
        };
        let mut order = [(t(0), 0), (t(1), 1), (t(2), 2)];
        for (i, j) in [(0, 1), (1, 2), (0, 1)] {
            if order[j].0 < order[i].0 {
                order.swap(i, j);
            }
        }
        for (_, axis) in order {
            if diff[axis] == 0 {
                break;
            }
            cell[axis] += diff[axis];
            visit(cell);
        }
        return;
    }
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

/// The grid cell holding point `p` (grid units), its three floors in one set of lanes: the
/// saturating `f32 as i32` conversion costs more than the walk around it. Coordinates beyond
/// ±2^31 (far outside any packable block key) come out as `i32::MIN`.
#[inline]
fn floor_cell(p: &Vector3<f32>) -> BlockCoord {
    let v = f32x4::new([p.x, p.y, p.z, 0.0]);
    let truncated = v.fast_trunc_int().round_float();
    let floor = truncated - truncated.simd_gt(v).select(f32x4::ONE, f32x4::ZERO);
    let [x, y, z, _] = floor.fast_trunc_int().to_array();
    [x, y, z]
}

/// Lane-wise floor of non-negative values below 2^31 (truncation toward zero is the floor
/// there), without the libm call `f32::floor` becomes on baseline x86-64.
#[inline(always)]
fn floor_small<F: Float8>(x: F) -> F {
    x.fast_trunc_int().round_float()
}

/// Everything the per-voxel update needs, in f32.
struct Kernel {
    camera_from_world: RigidF32,
    fx: f32,
    fy: f32,
    cx: f32,
    cy: f32,
    width: usize,
    /// Projections (u, v) in [−½, `u_max`) × [−½, `v_max`) fall on a pixel: `width − ½`,
    /// `height − ½`.
    u_max: f32,
    v_max: f32,
    /// The largest u (v) with a pixel to its right (below), just under `width − 1`
    /// (`height − 1`): projections on the outer half of a border pixel are clamped to it.
    u_last: f32,
    v_last: f32,
    voxel_size_m: f32,
    truncation_m: f32,
    max_weight: f32,
    min_depth_m: f32,
    max_depth_m: f32,
    depth_sample: DepthSample,
    /// AVX2 lanes when the running processor has them.
    #[cfg(target_arch = "x86_64")]
    avx2: Option<Avx2>,
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
            u_max: camera.width as f32 - 0.5,
            v_max: camera.height as f32 - 0.5,
            // 1/1024 pixel short of the last column (row): the bilinear weight of the pixel
            // beyond is then 0.999, a depth error under 0.001 of the (agreeing, < ½ truncation)
            // neighbour difference.
            u_last: camera.width as f32 - 1.0 - 1.0 / 1024.0,
            v_last: camera.height as f32 - 1.0 - 1.0 / 1024.0,
            voxel_size_m: config.voxel_size_m,
            truncation_m: config.truncation_m(),
            max_weight: config.max_weight,
            min_depth_m: config.min_depth_m,
            max_depth_m: config.max_depth_m,
            depth_sample: config.depth_sample,
            #[cfg(target_arch = "x86_64")]
            avx2: avx2(),
        }
    }

    /// Updates every voxel of `block` (at block coordinate `coord`) that projects into the image
    /// in front of, or less than the truncation distance behind, the measured depth.
    ///
    /// Depth is sampled at the voxel's sub-pixel projection (u, v) (pixel centres at integers;
    /// projections within half a pixel outside the outer centres are clamped onto them) as
    /// [`DepthSample`] says: with `Bilinear`, bilinear when the four neighbouring pixels are
    /// measured and agree within half the truncation distance, otherwise the nearest of them;
    /// with `Nearest`, the nearest pixel. An unmeasured pixel (depth 0) observes nothing. Colour
    /// comes from the nearest pixel. Observations weigh 1/z².
    ///
    /// Each row of eight voxels (along x) is one set of eight SIMD lanes: projection, depth
    /// interpolation, the TSDF and weight update and the colour blend are lane-wise and
    /// branch-free; only the pixel loads go voxel by voxel.
    fn update_block(&self, block: &mut Block, coord: &BlockCoord, depth: &[f32], rgbx: &[u32]) {
        // One closure per sampling rule, each with its own kernel instance: with both behind
        // one closure, LLVM stopped inlining it into the AVX2 function (see `lanes.rs`).
        #[cfg(target_arch = "x86_64")]
        if let Some(simd) = self.avx2 {
            match self.depth_sample {
                DepthSample::Bilinear => simd.vectorize(|| {
                    self.update_block_with::<_, false>(simd, block, coord, depth, rgbx)
                }),
                DepthSample::Nearest => simd.vectorize(|| {
                    self.update_block_with::<_, true>(simd, block, coord, depth, rgbx)
                }),
            }
            return;
        }
        self.update_block_portable(block, coord, depth, rgbx);
    }

    /// [`Self::update_block`] in `wide`'s portable lanes, whatever the processor has.
    fn update_block_portable(
        &self,
        block: &mut Block,
        coord: &BlockCoord,
        depth: &[f32],
        rgbx: &[u32],
    ) {
        match self.depth_sample {
            DepthSample::Bilinear => {
                self.update_block_with::<_, false>(Portable, block, coord, depth, rgbx)
            }
            DepthSample::Nearest => {
                self.update_block_with::<_, true>(Portable, block, coord, depth, rgbx)
            }
        }
    }

    /// [`Self::update_block`] in the lanes of `simd`, bit for bit the same result with any of
    /// them; the nearest pixel's depth when `NEAREST`, else [`DepthSample::Bilinear`]'s sample.
    #[inline(always)]
    fn update_block_with<S: Simd8, const NEAREST: bool>(
        &self,
        simd: S,
        block: &mut Block,
        coord: &BlockCoord,
        depth: &[f32],
        rgbx: &[u32],
    ) {
        const N: usize = BLOCK_SIDE;
        let w = self.width;
        let s = self.voxel_size_m;
        let side = BLOCK_SIDE as i32;
        let r = &self.camera_from_world.rotation;
        let (step_x, step_y, step_z) = (r.column(0) * s, r.column(1) * s, r.column(2) * s);
        let origin = self.camera_from_world.apply(&Vector3::new(
            (coord[0] * side) as f32 * s,
            (coord[1] * side) as f32 * s,
            (coord[2] * side) as f32 * s,
        ));
        let lane = simd.f32s([0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0]);
        let splat = |x: f32| simd.splat(x);
        let (sx, sy, sz) = (
            lane * splat(step_x.x),
            lane * splat(step_x.y),
            lane * splat(step_x.z),
        );
        let (fx, fy, cx, cy) = (
            splat(self.fx),
            splat(self.fy),
            splat(self.cx),
            splat(self.cy),
        );
        let (zero, one, half) = (splat(0.0), splat(1.0), splat(0.5));
        let (min_depth, max_depth) = (splat(self.min_depth_m), splat(self.max_depth_m));
        let (u_max, v_max) = (splat(self.u_max), splat(self.v_max));
        let (u_last, v_last) = (splat(self.u_last), splat(self.v_last));
        let neg_half = splat(-0.5);
        let neg_truncation = splat(-self.truncation_m);
        let inv_truncation = splat(1.0 / self.truncation_m);
        let agree = splat(0.5 * self.truncation_m);
        let max_weight = splat(self.max_weight);
        // The last index whose 2×2 neighbourhood lies inside the depth image.
        let last_quad = splat(depth.len().saturating_sub(w + 2) as f32);
        let Block {
            tsdf,
            weight,
            color,
        } = block;
        for z in 0..N {
            for y in 0..N {
                let row = origin + step_y * y as f32 + step_z * z as f32;
                let zc = splat(row.z) + sz;
                let inv_z = one / zc;
                let u = fx * (splat(row.x) + sx) * inv_z + cx;
                let v = fy * (splat(row.y) + sy) * inv_z + cy;
                let inside = zc.simd_ge(min_depth)
                    & u.simd_ge(neg_half)
                    & v.simd_ge(neg_half)
                    & u.simd_lt(u_max)
                    & v.simd_lt(v_max);
                if inside.to_bitmask() == 0 {
                    continue;
                }
                // Projections on the outer half of a border pixel are clamped onto that pixel
                // (the sample is then that pixel's depth, as the nearest-pixel rule gives).
                // Clamped, 0 ≤ u, v < 2^31, so truncation is the floor (neither the libm
                // `floor` call nor a saturating conversion); outside lanes read pixel (0, 0).
                let u = inside.select(u.fast_max(zero).fast_min(u_last), zero);
                let v = inside.select(v.fast_max(zero).fast_min(v_last), zero);
                let (sample, nearest) = if NEAREST {
                    // Clamped, u + ½ < width and v + ½ < height: the nearest pixel is in the
                    // image.
                    let nearest_f = floor_small(v + half) * splat(w as f32) + floor_small(u + half);
                    let nearest = nearest_f.fast_trunc_int().to_array();
                    let mut d = [0.0f32; N];
                    for x in 0..N {
                        d[x] = depth[nearest[x] as usize];
                    }
                    (simd.f32s(d), nearest)
                } else {
                    let (fu, fv) = (u - floor_small(u), v - floor_small(v));
                    // Index of the top-left pixel of the 2×2 neighbourhood, computed in f32
                    // (exact: image sizes stay far below 2^24 pixels) and clamped so that every
                    // lane's neighbourhood lies in the image.
                    let quad_f = ((v - fv) * splat(w as f32) + (u - fu)).fast_min(last_quad);
                    let quad = quad_f.fast_trunc_int().to_array();
                    // Pixel loads (a gather: one voxel at a time).
                    let (mut d00, mut d01, mut d10, mut d11) =
                        ([0.0f32; N], [0.0; N], [0.0; N], [0.0; N]);
                    for x in 0..N {
                        let q = quad[x] as usize;
                        let p = &depth[q..q + w + 2];
                        (d00[x], d01[x], d10[x], d11[x]) = (p[0], p[1], p[w], p[w + 1]);
                    }
                    let (d00, d01, d10, d11) = (
                        simd.f32s(d00),
                        simd.f32s(d01),
                        simd.f32s(d10),
                        simd.f32s(d11),
                    );
                    let right = fu.simd_ge(half);
                    let below = fv.simd_ge(half);
                    let near = below.select(right.select(d11, d10), right.select(d01, d00));
                    // Depths are never NaN, so the fast (NaN-unaware) min and max are exact.
                    let lo = d00.fast_min(d01).fast_min(d10.fast_min(d11));
                    let hi = d00.fast_max(d01).fast_max(d10.fast_max(d11));
                    let top = d00 + (d01 - d00) * fu;
                    let bottom = d10 + (d11 - d10) * fu;
                    let bilinear = top + (bottom - top) * fv;
                    let agreeing = lo.simd_gt(zero) & (hi - lo).simd_lt(agree);
                    // The pixel nearest to each projection: its neighbourhood's corner on the
                    // projection's side.
                    let nearest =
                        (quad_f + right.select(one, zero) + below.select(splat(w as f32), zero))
                            .fast_trunc_int()
                            .to_array();
                    (agreeing.select(bilinear, near), nearest)
                };
                let sdf = sample - zc;
                let observed = inside
                    & sample.simd_ge(min_depth)
                    & sample.simd_le(max_depth)
                    & sdf.simd_ge(neg_truncation);
                let mask = observed.to_bitmask();
                if mask == 0 {
                    continue;
                }
                let t_obs = (sdf * inv_truncation).fast_min(one);
                let w_obs = observed.select(inv_z * inv_z, zero);
                let base = N * (y + N * z);
                let tsdf_row: &mut [f32; N] = (&mut tsdf[base..base + N])
                    .try_into()
                    .expect("a block row holds eight voxels");
                let weight_row: &mut [f32; N] = (&mut weight[base..base + N])
                    .try_into()
                    .expect("a block row holds eight voxels");
                let t_old = simd.f32s(*tsdf_row);
                let w_old = simd.f32s(*weight_row);
                let w_sum = w_old + w_obs;
                // One division for the TSDF and the colour; unobserved lanes keep their values
                // (their 0/0 never reaches the result).
                let inv_sum = observed.select(one / w_sum, zero);
                let share = w_obs * inv_sum;
                let blended = t_old * (w_old * inv_sum) + t_obs * share;
                *tsdf_row = observed.select(blended, t_old).to_array();
                *weight_row = w_sum.fast_min(max_weight).to_array();
                // Colour blends in 16-bit fixed point: the observation's share in units of
                // 2⁻¹⁶, rounded, then (old·(2¹⁶ − b) + new·b + 2¹⁵) >> 16 per channel. Every term
                // is an integer below 2²⁴, so f32 lanes compute it exactly. Unobserved lanes have
                // a share of 0 and keep their colour.
                let b16 = floor_small(share * splat(65536.0) + half).fast_min(splat(65536.0));
                let a16 = splat(65536.0) - b16;
                let row_color: &mut [[u8; 4]; N] = (&mut color[base..base + N])
                    .try_into()
                    .expect("a block row holds eight voxels");
                let old = simd.i32s(row_color.map(|c| u32::from_le_bytes(c) as i32));
                let new = simd.i32s(nearest.map(|i| rgbx[i as usize] as i32));
                let byte = simd.splat_i32(0xff);
                // The fourth byte counts the frames that observed the voxel, up to 255.
                let count = (old.shr(24) & byte) + observed.select(one, zero).fast_trunc_int();
                let mut blended = count.min(byte).shl(24);
                for shift in [0u32, 8, 16] {
                    let old = (old.shr(shift) & byte).round_float();
                    let new = (new.shr(shift) & byte).round_float();
                    // Each blend of two bytes with shares summing to one stays within 0..=255.
                    let channel = floor_small(
                        (old * a16 + new * b16 + splat(32768.0)) * splat(1.0 / 65536.0),
                    );
                    blended = blended | channel.fast_trunc_int().shl(shift);
                }
                *row_color = blended.to_array().map(|c| (c as u32).to_le_bytes());
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use nalgebra::Point3;
    use proptest::prelude::*;

    use super::*;
    use crate::geometry::look_at;
    use crate::image::{DepthImage, RgbImage};
    use crate::tsdf::{BLOCK_VOXELS, Roi, TsdfConfig};

    fn touched(
        volume: &TsdfVolume,
        frame: &RgbdFrame,
        camera: &PinholeCamera,
        pose: &Isometry3<f64>,
        window: &PixelWindow,
    ) -> Vec<(u64, u32)> {
        let mut scratch = Scratch::default();
        touched_blocks(volume, &mut scratch, frame, camera, pose, window);
        scratch.keys
    }

    /// The blocks of the ROI each pixel's band crosses, and how many bands cross each, walking
    /// every pixel and testing every block against the ROI: what `touched_blocks` must find.
    fn touched_by_brute_force(
        volume: &TsdfVolume,
        frame: &RgbdFrame,
        camera: &PinholeCamera,
        pose: &Isometry3<f64>,
    ) -> Vec<(u64, u32)> {
        let config = volume.config();
        let (block, voxel) = (config.block_size_m(), config.voxel_size_m);
        let truncation = config.truncation_m();
        let transform = RigidF32::from_isometry(pose);
        // The same arithmetic as `touched_blocks`, so that the band ends round alike.
        let r = transform.rotation * (1.0 / block);
        let origin = transform.translation.add_scalar(0.5 * voxel) * (1.0 / block);
        let (fx, fy, cx, cy) = (
            camera.fx as f32,
            camera.fy as f32,
            camera.cx as f32,
            camera.cy as f32,
        );
        let mut counts = std::collections::BTreeMap::new();
        let width = camera.width as usize;
        for (v, row) in frame.depth_m.as_slice().chunks(width).enumerate() {
            let mut ray = r * Vector3::new((0.0 - cx) / fx, (v as f32 - cy) / fy, 1.0);
            for &d in row {
                if d >= config.min_depth_m && d <= config.max_depth_m {
                    let a = origin + ray * (d - truncation);
                    let b = origin + ray * (d + truncation);
                    // Each band counts once per block, as the walk visits a block once.
                    walk_blocks(&a, &b, |c| {
                        let lo =
                            c.map(|x| f64::from(x) * f64::from(block) - 0.5 * f64::from(voxel));
                        let hi = lo.map(|x| x + f64::from(block));
                        if config.roi.is_none_or(|roi| roi.intersects_box(lo, hi)) {
                            *counts.entry(pack(c).unwrap()).or_insert(0) += 1;
                        }
                    });
                }
                ray += r.column(0) / fx;
            }
        }
        counts.into_iter().collect()
    }

    /// The pose of a camera at `eye` looking at `target` (world z up) and the distance between
    /// them; `None` for a degenerate view.
    fn view(eye: (f64, f64, f64), target: (f64, f64, f64)) -> Option<(Isometry3<f64>, f64)> {
        let eye = Point3::new(eye.0, eye.1, eye.2);
        let target = Point3::new(target.0, target.1, target.2);
        let pose = look_at(&eye, &target, &Vector3::z()).ok()?;
        Some((pose, (target - eye).norm()))
    }

    /// An 80 × 60 frame whose depths are drawn uniformly from `range_m` times `spread` (5% of
    /// them missing) and whose colours are random, from `seed`.
    fn scattered_frame(seed: u64, range_m: f64, spread: std::ops::Range<f64>) -> RgbdFrame {
        let mut state = seed;
        let mut uniform = move || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 40) as f64 / (1u64 << 24) as f64
        };
        let depth: Vec<f32> = (0..80 * 60)
            .map(|_| {
                let r = uniform();
                if r < 0.05 {
                    0.0
                } else {
                    (range_m * (spread.start + (spread.end - spread.start) * r)) as f32
                }
            })
            .collect();
        let rgb: Vec<[u8; 3]> = (0..80 * 60)
            .map(|_| [0, 1, 2].map(|_| (uniform() * 256.0) as u8))
            .collect();
        RgbdFrame::new(
            0.0,
            RgbImage::from_vec(80, 60, rgb).unwrap(),
            DepthImage::from_vec(80, 60, depth).unwrap(),
            None,
        )
        .unwrap()
    }

    fn coordinate() -> impl Strategy<Value = i32> {
        prop_oneof![
            -(1 << 20) - 2..-(1 << 20) + 2,
            -300i32..300,
            (1 << 20) - 2..(1 << 20) + 2,
            any::<i32>(),
        ]
    }

    proptest! {
        /// The lane-wise floor of a point is `f32::floor` of each coordinate, integers and
        /// negative values included.
        #[test]
        fn floor_cell_is_the_floor(
            large in -3.0e6f32..3.0e6,
            small in -40.0f32..40.0,
            integer in -5i32..5,
        ) {
            let p = [large, small, integer as f32];
            for v in [p, [p[1], p[2], p[0]], [p[2], p[0], p[1]]] {
                prop_assert_eq!(
                    floor_cell(&Vector3::from(v)),
                    v.map(|x| x.floor() as i32)
                );
            }
        }

        /// The walk goes from `a`'s cell to `b`'s by face-adjacent steps, in order along the
        /// segment, and visits every cell that points sampled densely along it fall in (points
        /// within 10⁻⁴ of a cell face are left out: rounding may put them either side). Short
        /// segments take the sorted-crossings path, long ones the general walk.
        #[test]
        fn the_walk_visits_the_cells_along_the_segment(
            a in [-20.0f32..20.0, -20.0f32..20.0, -20.0f32..20.0],
            dir in [-1.0f32..1.0, -1.0f32..1.0, -1.0f32..1.0],
            length in prop_oneof![0.0f32..1.0, 1.0f32..6.0],
        ) {
            let a = Vector3::from(a);
            let norm = Vector3::from(dir).norm();
            prop_assume!(norm > 1e-3);
            let b = a + Vector3::from(dir) * (length / norm);
            let mut cells = Vec::new();
            walk_blocks(&a, &b, |c| cells.push(c));
            prop_assert_eq!(cells[0], floor_cell(&a));
            prop_assert_eq!(*cells.last().unwrap(), floor_cell(&b));
            for pair in cells.windows(2) {
                let steps: i32 = (0..3).map(|i| (pair[1][i] - pair[0][i]).abs()).sum();
                prop_assert_eq!(steps, 1, "{:?}", cells);
            }
            for k in 0..=2000 {
                let p = a + (b - a) * (k as f32 / 2000.0);
                let near_face = (0..3).any(|i| (p[i] - p[i].round()).abs() < 1e-4);
                if !near_face {
                    prop_assert!(cells.contains(&floor_cell(&p)), "{:?} misses {:?}", cells, p);
                }
            }
        }

        /// Packing keeps exactly the coordinates within ±2^20, round-trips them and orders keys
        /// as the coordinates' lexicographic order.
        #[test]
        fn packed_keys_round_trip_and_keep_the_order(
            a in [coordinate(), coordinate(), coordinate()],
            b in [coordinate(), coordinate(), coordinate()],
        ) {
            let representable = |c: BlockCoord| c.iter().all(|&x| (-(1 << 20)..1 << 20).contains(&x));
            prop_assert_eq!(pack(a).is_some(), representable(a));
            if let (Some(ka), Some(kb)) = (pack(a), pack(b)) {
                prop_assert_eq!(unpack(ka), a);
                prop_assert_eq!(ka.cmp(&kb), a.cmp(&b));
            }
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]

        /// Walking only the ROI's pixel window finds the same blocks, with the same pixel
        /// counts, as walking every pixel, and both the same as testing every block of every
        /// band: neither the window nor the band and block pre-tests drop a band that reaches
        /// the region, whether it lies ahead, to the side, around or behind the camera.
        #[test]
        fn the_roi_window_loses_no_block(
            eye in (-2.5f64..2.5, -2.5f64..2.5, -1.0f64..2.5),
            target in (-1.5f64..1.5, -1.5f64..1.5, -0.5f64..0.5),
            radius_m in 0.05f64..1.0,
            seed in any::<u64>(),
        ) {
            let Some((pose, range)) = view(eye, target) else {
                return Ok(());
            };
            prop_assume!(range > 0.2);
            let camera = PinholeCamera::from_hfov(80, 60, 70.0).unwrap();
            // Depths scattered around the target's range, so that many bands cross the region
            // and many miss it.
            let frame = scattered_frame(seed, range, 0.3..1.7);
            let volume = TsdfVolume::new(TsdfConfig {
                voxel_size_m: 0.02,
                roi: Some(Roi::Cylinder {
                    center_xy: [0.1, -0.2],
                    z_min: -0.3,
                    z_max: 0.4,
                    radius_m,
                }),
                ..TsdfConfig::default()
            })
            .unwrap();
            let window = PixelWindow::for_roi(volume.config(), &camera, &pose);
            let every_pixel = touched(&volume, &frame, &camera, &pose, &PixelWindow::full(&camera));
            prop_assert_eq!(&every_pixel, &touched_by_brute_force(&volume, &frame, &camera, &pose));
            prop_assert_eq!(touched(&volume, &frame, &camera, &pose, &window), every_pixel);
        }

        /// On a smooth surface, where long runs of pixels put their bands on the same blocks and
        /// the cache of recent blocks counts most of them, the blocks found and their counts are
        /// those of the brute force, with and without a region.
        #[test]
        fn a_smooth_surface_finds_what_the_brute_force_finds(
            eye in (-2.5f64..2.5, -2.5f64..2.5, -1.0f64..2.5),
            target in (-1.5f64..1.5, -1.5f64..1.5, -0.5f64..0.5),
            slope in (-0.01f64..0.01, -0.01f64..0.01),
            voxel_size_m in prop_oneof![Just(0.01f32), Just(0.02f32)],
            with_roi in any::<bool>(),
        ) {
            let Some((pose, range)) = view(eye, target) else {
                return Ok(());
            };
            prop_assume!(range > 0.3);
            let camera = PinholeCamera::from_hfov(80, 60, 70.0).unwrap();
            // A tilted plane, with a hole every 37th pixel to break runs.
            let depth: Vec<f32> = (0..80 * 60)
                .map(|i| {
                    let (u, v) = (f64::from(i % 80), f64::from(i / 80));
                    let d = range + slope.0 * u + slope.1 * v;
                    if i % 37 == 0 { 0.0 } else { d as f32 }
                })
                .collect();
            let frame = RgbdFrame::new(
                0.0,
                RgbImage::filled(80, 60, [0, 0, 0]),
                DepthImage::from_vec(80, 60, depth).unwrap(),
                None,
            )
            .unwrap();
            let roi = Roi::Cylinder {
                center_xy: [target.0, target.1],
                z_min: target.2 - 0.3,
                z_max: target.2 + 0.3,
                radius_m: 0.4,
            };
            let volume = TsdfVolume::new(TsdfConfig {
                voxel_size_m,
                roi: with_roi.then_some(roi),
                ..TsdfConfig::default()
            })
            .unwrap();
            let found = touched(&volume, &frame, &camera, &pose, &PixelWindow::full(&camera));
            prop_assert!(!found.is_empty() || with_roi);
            prop_assert_eq!(found, touched_by_brute_force(&volume, &frame, &camera, &pose));
        }
    }

    /// The AVX2 kernel (where the processor has it) and the portable one leave every voxel of
    /// every block bit for bit alike, over two frames from different views.
    #[test]
    fn the_voxel_update_is_the_same_in_every_lane_implementation() {
        let camera = scattered_camera();
        let (coords, views) = scattered_views();
        for depth_sample in [DepthSample::Bilinear, DepthSample::Nearest] {
            let config = TsdfConfig {
                voxel_size_m: 0.02,
                depth_sample,
                ..TsdfConfig::default()
            };
            let mut portable: Vec<Block> = coords.iter().map(|_| Block::new()).collect();
            let mut fast = portable.clone();
            for (pose, frame) in &views {
                let kernel = Kernel::new(&config, &camera, pose);
                let depth = frame.depth_m.as_slice();
                let rgbx: Vec<u32> = frame.rgb.as_slice().iter().map(rgbx_word).collect();
                for ((a, b), coord) in portable.iter_mut().zip(&mut fast).zip(&coords) {
                    kernel.update_block_portable(a, coord, depth, &rgbx);
                    kernel.update_block(b, coord, depth, &rgbx);
                }
            }
            let observed: usize = portable
                .iter()
                .map(|b| b.weight.iter().filter(|&&w| w > 0.0).count())
                .sum();
            assert!(
                observed > 10_000,
                "{depth_sample:?}: only {observed} voxels observed"
            );
            for (a, b) in portable.iter().zip(&fast) {
                let bits = |x: &[f32; BLOCK_VOXELS]| x.map(f32::to_bits);
                assert_eq!(bits(&a.tsdf), bits(&b.tsdf), "{depth_sample:?}");
                assert_eq!(bits(&a.weight), bits(&b.weight), "{depth_sample:?}");
                assert_eq!(a.color, b.color, "{depth_sample:?}");
            }
        }
    }

    /// The camera of [`scattered_views`].
    fn scattered_camera() -> PinholeCamera {
        PinholeCamera::from_hfov(80, 60, 70.0).unwrap()
    }

    /// Every block of a 6-block cube around the origin (at 2 cm voxels: in front of, inside and
    /// behind the scattered surfaces), and two views of scattered depth towards the origin.
    fn scattered_views() -> (Vec<BlockCoord>, Vec<(Isometry3<f64>, RgbdFrame)>) {
        let coords = (-3..3)
            .flat_map(|x| (-3..3).flat_map(move |y| (-3..3).map(move |z| [x, y, z])))
            .collect();
        let target = Point3::origin();
        let views = [
            (Point3::new(1.2, -0.4, 0.5), 11),
            (Point3::new(-0.3, 1.0, 0.9), 12),
        ]
        .map(|(eye, seed)| {
            let pose = look_at(&eye, &target, &Vector3::z()).unwrap();
            (pose, scattered_frame(seed, (target - eye).norm(), 0.9..1.1))
        });
        (coords, views.into())
    }

    #[test]
    fn the_nearest_sample_reads_the_pixel_nearest_each_voxel() {
        // One view into empty blocks: every voxel's TSDF, weight and colour must be what the
        // pixel nearest its projection says, computed here in f64, voxel by voxel.
        let camera = scattered_camera();
        let (coords, views) = scattered_views();
        let (pose, frame) = &views[0];
        let config = TsdfConfig {
            voxel_size_m: 0.02,
            depth_sample: DepthSample::Nearest,
            ..TsdfConfig::default()
        };
        let kernel = Kernel::new(&config, &camera, pose);
        let rgbx: Vec<u32> = frame.rgb.as_slice().iter().map(rgbx_word).collect();
        let camera_from_world = pose.inverse();
        let truncation = f64::from(config.truncation_m());
        let (mut checked, mut observed) = (0, 0);
        for coord in &coords {
            let mut block = Block::new();
            kernel.update_block(&mut block, coord, frame.depth_m.as_slice(), &rgbx);
            for i in 0..BLOCK_VOXELS {
                let local = [i % 8, (i / 8) % 8, i / 64];
                let centre = Point3::from(Vector3::from_fn(|a, _| {
                    f64::from(coord[a] * 8 + local[a] as i32) * f64::from(config.voxel_size_m)
                }));
                let p = camera_from_world * centre;
                let Some(projection) = camera.project(&p) else {
                    continue;
                };
                let (u, v) = (projection.x, projection.y);
                let (wf, hf) = (f64::from(camera.width), f64::from(camera.height));
                // Leave out voxels within rounding of a decision: a pixel border, the image's
                // edge, or the truncation band's far side.
                let near_edge = |x: f64| (x + 0.5 - (x + 0.5).round()).abs() < 1e-3;
                if p.z < 0.2 || near_edge(u) || near_edge(v) {
                    continue;
                }
                if !(-0.5..wf - 0.5).contains(&u) || !(-0.5..hf - 0.5).contains(&v) {
                    assert_eq!(
                        block.weight[i], 0.0,
                        "voxel {i} of {coord:?} projects outside"
                    );
                    continue;
                }
                let pixel =
                    (v + 0.5).floor() as usize * camera.width as usize + (u + 0.5).floor() as usize;
                let d = f64::from(frame.depth_m.as_slice()[pixel]);
                let sdf = d - p.z;
                if (sdf + truncation).abs() < 1e-4 {
                    continue;
                }
                checked += 1;
                if d < f64::from(config.min_depth_m) || sdf < -truncation {
                    assert_eq!(
                        block.weight[i], 0.0,
                        "voxel {i} of {coord:?}: d {d}, sdf {sdf}"
                    );
                    continue;
                }
                observed += 1;
                let expected = (sdf / truncation).min(1.0);
                assert!(
                    (f64::from(block.tsdf[i]) - expected).abs() < 1e-4,
                    "voxel {i} of {coord:?}: TSDF {} against {expected}",
                    block.tsdf[i]
                );
                let weight = 1.0 / (p.z * p.z);
                assert!((f64::from(block.weight[i]) / weight - 1.0).abs() < 1e-4);
                let [r, g, b] = frame.rgb.as_slice()[pixel];
                assert_eq!(block.color[i], [r, g, b, 1], "voxel {i} of {coord:?}");
            }
        }
        assert!(
            checked > 50_000 && observed > 5_000,
            "{checked} checked, {observed} observed"
        );
    }

    #[test]
    fn a_region_behind_the_camera_leaves_no_pixel() {
        let camera = PinholeCamera::from_hfov(80, 60, 70.0).unwrap();
        // Identity pose: the camera looks along +z; the box lies at z < 0.
        let window = PixelWindow::of_box(
            &Roi::Box {
                min: [-1.0, -1.0, -3.0],
                max: [1.0, 1.0, -2.0],
            },
            0.1,
            &camera,
            &Isometry3::identity(),
        );
        assert!(window.rows.is_empty());
        // Ahead of it, the box covers the image's centre and not its corners.
        let window = PixelWindow::of_box(
            &Roi::Box {
                min: [-0.1, -0.1, 2.0],
                max: [0.1, 0.1, 2.5],
            },
            0.0,
            &camera,
            &Isometry3::identity(),
        );
        assert!(window.columns.contains(&40) && window.rows.contains(&30));
        assert!(!window.columns.contains(&0) && !window.rows.contains(&59));
        assert!((window.near_m - 2.0).abs() < 1e-6 && (window.far_m - 2.5).abs() < 1e-6);
    }
}
