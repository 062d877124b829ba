//! The frame being tracked: its valid pixels as camera-frame points with their intensity.

use rayon::prelude::*;

use super::reference::check_pyramid;
use super::{OdometryConfig, OdometryError};
use crate::PinholeCamera;
use crate::image::ImagePyramid;

/// A current-frame pixel with depth: its point in the current camera frame (metres) and its
/// intensity.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct SourcePoint {
    pub p: [f32; 3],
    pub intensity: f32,
}

/// The current frame, prepared for tracking: per pyramid level, the pixels whose depth lies in
/// the configured range.
#[derive(Debug, Clone)]
pub struct SourceFrame {
    /// Per level, the (possibly subsampled) points used for tracking.
    pub(crate) levels: Vec<Vec<SourcePoint>>,
    /// Per level, the number of pixels with a usable depth before subsampling.
    pub(crate) valid_per_level: Vec<usize>,
    pub(crate) camera: PinholeCamera,
}

impl SourceFrame {
    /// Prepares a frame from its intensity/depth pyramid; `camera` is the level-0 camera.
    ///
    /// # Errors
    /// [`OdometryError::InvalidConfig`]; [`OdometryError::Input`] or
    /// [`OdometryError::PyramidLevels`] when the pyramid does not match the camera or is short.
    pub fn from_pyramid(
        camera: &PinholeCamera,
        pyramid: &ImagePyramid,
        config: &OdometryConfig,
    ) -> Result<Self, OdometryError> {
        config.validate()?;
        check_pyramid(camera, pyramid, config.levels)?;
        let (min_z, max_z) = (config.min_depth_m as f32, config.max_depth_m as f32);
        let (levels, valid_per_level) = (0..config.levels)
            .map(|level| {
                let cam = camera.downsampled(level as u32);
                let w = cam.width as usize;
                let (fx, fy, cx, cy) = (cam.fx as f32, cam.fy as f32, cam.cx as f32, cam.cy as f32);
                let (inv_fx, inv_fy) = (1.0 / fx, 1.0 / fy);
                let depth = pyramid.depth_m[level].as_slice();
                let gray = pyramid.gray[level].as_slice();
                let points: Vec<SourcePoint> = depth
                    .par_chunks(w)
                    .enumerate()
                    .flat_map_iter(|(v, row)| {
                        row.iter().enumerate().filter_map(move |(u, &z)| {
                            let i = v * w + u;
                            (z >= min_z && z <= max_z && gray[i].is_finite()).then(|| SourcePoint {
                                p: [
                                    (u as f32 - cx) * inv_fx * z,
                                    (v as f32 - cy) * inv_fy * z,
                                    z,
                                ],
                                intensity: gray[i],
                            })
                        })
                    })
                    .collect();
                let valid = points.len();
                (subsample(points, config.max_points_per_level), valid)
            })
            .unzip();
        Ok(Self {
            levels,
            valid_per_level,
            camera: *camera,
        })
    }

    /// Number of full-resolution pixels with a usable depth.
    pub fn valid_pixels(&self) -> usize {
        self.valid_per_level.first().copied().unwrap_or(0)
    }

    /// Full-resolution points used for tracking (after subsampling).
    pub fn tracked_points(&self) -> usize {
        self.levels.first().map_or(0, Vec::len)
    }
}

/// Keeps every k-th point, with the smallest k that leaves at most `max` (row-major order,
/// so the kept points spread evenly over the image).
fn subsample(points: Vec<SourcePoint>, max: usize) -> Vec<SourcePoint> {
    if points.len() <= max || max == 0 {
        return points;
    }
    let step = points.len().div_ceil(max);
    points.into_iter().step_by(step).collect()
}
