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
    pub(crate) levels: Vec<Vec<SourcePoint>>,
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
        let levels = (0..config.levels)
            .map(|level| {
                let cam = camera.downsampled(level as u32);
                let w = cam.width as usize;
                let (fx, fy, cx, cy) = (cam.fx as f32, cam.fy as f32, cam.cx as f32, cam.cy as f32);
                let depth = pyramid.depth_m[level].as_slice();
                let gray = pyramid.gray[level].as_slice();
                depth
                    .par_chunks(w)
                    .enumerate()
                    .flat_map_iter(|(v, row)| {
                        row.iter().enumerate().filter_map(move |(u, &z)| {
                            let i = v * w + u;
                            (z >= min_z && z <= max_z && gray[i].is_finite()).then(|| SourcePoint {
                                p: [(u as f32 - cx) / fx * z, (v as f32 - cy) / fy * z, z],
                                intensity: gray[i],
                            })
                        })
                    })
                    .collect()
            })
            .collect();
        Ok(Self {
            levels,
            camera: *camera,
        })
    }

    /// Number of full-resolution pixels with a usable depth.
    pub fn valid_pixels(&self) -> usize {
        self.levels.first().map_or(0, Vec::len)
    }
}
