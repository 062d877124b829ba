//! Opening a sequence and loading its frames.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use nalgebra::Isometry3;
use scarp_export::tum::{StampedPose, read_tum_trajectory};
use scarp_slam::image::{Undistortion, register_color_to_depth};
use scarp_slam::{PinholeCamera, RgbdFrame};

use super::camera_file::CameraFile;
use super::images::{read_depth_png, read_mask_png, read_rgb_png};
use super::lists::{BoxRecord, parse_boxes, parse_image_list};
use crate::DatasetError;

/// Largest time difference between a colour and a depth image of one frame, seconds (as TUM's
/// `associate.py`).
pub const MAX_ASSOCIATION_DT_S: f64 = 0.02;

/// Poses are interpolated between samples at most this far apart, seconds.
const MAX_POSE_GAP_S: f64 = 0.5;

/// One associated frame of a sequence.
#[derive(Debug, Clone, PartialEq)]
pub struct SequenceEntry {
    /// The colour image's timestamp, seconds.
    pub timestamp_s: f64,
    /// Colour PNG.
    pub rgb_path: PathBuf,
    /// Depth PNG.
    pub depth_path: PathBuf,
    /// Instance mask PNG, when `mask/` holds one for this frame.
    pub mask_path: Option<PathBuf>,
    /// True `world_from_camera`, interpolated from `groundtruth.txt`.
    pub world_from_camera_truth: Option<Isometry3<f64>>,
    /// Estimated `world_from_camera`, interpolated from `estimate.txt`.
    pub world_from_camera_estimate: Option<Isometry3<f64>>,
}

/// An opened sequence: intrinsics, associated frames, and optional boxes.
#[derive(Debug, Clone)]
pub struct Sequence {
    /// The sequence directory.
    pub dir: PathBuf,
    /// `camera.toml`.
    pub camera_file: CameraFile,
    /// The camera.
    pub camera: PinholeCamera,
    /// Frames in time order.
    pub entries: Vec<SequenceEntry>,
    /// `boxes.txt`, empty when absent.
    pub boxes: Vec<BoxRecord>,
    /// The resampling into the pinhole camera when `camera.toml` has a `[distortion]` table,
    /// built by the first [`Self::load_frame`] (after that frame's size matched `camera.toml`,
    /// so a corrupt size cannot make it allocate) and reused by every later one.
    undistortion: OnceLock<Undistortion>,
}

fn read_text(path: &Path) -> Result<String, DatasetError> {
    std::fs::read_to_string(path).map_err(|e| DatasetError::io(path, e))
}

/// The pose at `t`, interpolated (linear translation, slerp rotation) between the samples that
/// bracket it when they are close enough, or the nearest sample within
/// [`MAX_ASSOCIATION_DT_S`].
pub fn interpolate_pose(poses: &[StampedPose], t: f64) -> Option<Isometry3<f64>> {
    let after = poses.partition_point(|p| p.timestamp_s < t);
    let nearest = [after.checked_sub(1), Some(after)]
        .into_iter()
        .flatten()
        .filter_map(|i| poses.get(i))
        .min_by(|a, b| {
            (a.timestamp_s - t)
                .abs()
                .total_cmp(&(b.timestamp_s - t).abs())
        })?;
    if (nearest.timestamp_s - t).abs() <= 1e-9 {
        return Some(nearest.world_from_camera);
    }
    if after > 0 && after < poses.len() {
        let (a, b) = (&poses[after - 1], &poses[after]);
        if b.timestamp_s - a.timestamp_s <= MAX_POSE_GAP_S {
            let s = (t - a.timestamp_s) / (b.timestamp_s - a.timestamp_s);
            return Some(a.world_from_camera.lerp_slerp(&b.world_from_camera, s));
        }
    }
    ((nearest.timestamp_s - t).abs() <= MAX_ASSOCIATION_DT_S).then_some(nearest.world_from_camera)
}

impl Sequence {
    /// Opens a sequence directory: reads `camera.toml`, `rgb.txt` and `depth.txt` (required),
    /// associates colour and depth by timestamp (at most [`MAX_ASSOCIATION_DT_S`] apart, each
    /// image used once), and attaches poses from `groundtruth.txt` and `estimate.txt` and boxes
    /// from `boxes.txt` when present. Images are loaded lazily by [`Self::load_frame`].
    ///
    /// # Errors
    /// [`DatasetError::Io`] for a missing required file; [`DatasetError::Parse`] naming the
    /// file and line for bad or out-of-order lines; [`DatasetError::Toml`] for a bad
    /// `camera.toml`.
    pub fn open(dir: &Path) -> Result<Self, DatasetError> {
        Self::open_with_camera_file(dir, &dir.join("camera.toml"))
    }

    /// Opens a sequence directory as [`Self::open`] does, but with the intrinsics of
    /// `camera_toml` in place of the directory's own `camera.toml`: for a sequence whose file
    /// lacks what the sensor is known to have (a `[color]` table for a Kinect whose colour is
    /// not registered to its depth), without editing the dataset.
    ///
    /// # Errors
    /// As [`Self::open`], naming `camera_toml` for its errors.
    pub fn open_with_camera_file(dir: &Path, camera_toml: &Path) -> Result<Self, DatasetError> {
        let camera_file = CameraFile::read(camera_toml)?;
        let camera = camera_file.camera()?;
        let rgb_list = parse_image_list(&read_text(&dir.join("rgb.txt"))?, &dir.join("rgb.txt"))?;
        let depth_list =
            parse_image_list(&read_text(&dir.join("depth.txt"))?, &dir.join("depth.txt"))?;
        let read_poses = |name: &str| -> Result<Vec<StampedPose>, DatasetError> {
            let path = dir.join(name);
            if path.exists() {
                Ok(read_tum_trajectory(&path)?)
            } else {
                Ok(Vec::new())
            }
        };
        let truth = read_poses("groundtruth.txt")?;
        let estimate = read_poses("estimate.txt")?;
        let boxes_path = dir.join("boxes.txt");
        let boxes = if boxes_path.exists() {
            parse_boxes(&read_text(&boxes_path)?, &boxes_path)?
        } else {
            Vec::new()
        };
        let mask_dir = dir.join("mask");
        let mut entries = Vec::with_capacity(rgb_list.len());
        let mut depth_cursor = 0;
        for (t, rgb_file) in &rgb_list {
            // Both lists are sorted: advance to the depth image nearest in time.
            while depth_cursor + 1 < depth_list.len()
                && (depth_list[depth_cursor + 1].0 - t).abs()
                    <= (depth_list[depth_cursor].0 - t).abs()
            {
                depth_cursor += 1;
            }
            let Some((depth_t, depth_file)) = depth_list.get(depth_cursor) else {
                break;
            };
            if (depth_t - t).abs() > MAX_ASSOCIATION_DT_S {
                continue;
            }
            let rgb_path = dir.join(rgb_file);
            let mask_path = rgb_path
                .file_name()
                .map(|name| mask_dir.join(name))
                .filter(|p| p.exists());
            entries.push(SequenceEntry {
                timestamp_s: *t,
                rgb_path,
                depth_path: dir.join(depth_file),
                mask_path,
                world_from_camera_truth: interpolate_pose(&truth, *t),
                world_from_camera_estimate: interpolate_pose(&estimate, *t),
            });
            depth_cursor += 1;
            if depth_cursor >= depth_list.len() {
                break;
            }
        }
        Ok(Self {
            dir: dir.to_path_buf(),
            camera_file,
            camera,
            entries,
            boxes,
            undistortion: OnceLock::new(),
        })
    }

    /// Number of associated frames.
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    /// Whether the sequence has no frames.
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// The map into the pinhole camera when `camera.toml` has a `[distortion]` table, built on
    /// the first call and kept.
    fn undistortion(&self) -> Result<Option<&Undistortion>, DatasetError> {
        let Some(distortion) = &self.camera_file.distortion else {
            return Ok(None);
        };
        if let Some(map) = self.undistortion.get() {
            return Ok(Some(map));
        }
        let map = Undistortion::new(&self.camera, distortion)?;
        Ok(Some(self.undistortion.get_or_init(|| map)))
    }

    /// Loads frame `index`: colour, depth (metres) and the mask when present. With a
    /// `[distortion]` table in `camera.toml`, the images are first resampled into the pinhole
    /// camera ([`scarp_slam::image::Undistortion`]). With a `[color]` table, the colour is
    /// registered to the depth ([`scarp_slam::image::register_color_to_depth`]), so the frame
    /// is always registered.
    ///
    /// # Errors
    /// [`DatasetError::Invalid`] for an index out of range; image errors naming the file; a size
    /// that differs from `camera.toml` names the file too.
    pub fn load_frame(&self, index: usize) -> Result<RgbdFrame, DatasetError> {
        let entry = self.entries.get(index).ok_or_else(|| {
            DatasetError::invalid(
                "frame index",
                format!("{index} is beyond the {} frames", self.entries.len()),
            )
        })?;
        let color_camera = self.camera_file.color_camera()?;
        let depth_size = (self.camera.width, self.camera.height);
        let color_size = color_camera
            .as_ref()
            .map_or(depth_size, |c| (c.width, c.height));
        let check = |path: &Path, (width, height): (u32, u32), (w, h): (u32, u32)| {
            if (width, height) == (w, h) {
                Ok(())
            } else {
                Err(DatasetError::Image {
                    path: path.to_path_buf(),
                    message: format!("image is {width}×{height}, camera.toml says {w}×{h}"),
                })
            }
        };
        let rgb = read_rgb_png(&entry.rgb_path)?;
        check(&entry.rgb_path, (rgb.width(), rgb.height()), color_size)?;
        let depth = read_depth_png(&entry.depth_path, self.camera_file.depth_scale)?;
        check(
            &entry.depth_path,
            (depth.width(), depth.height()),
            depth_size,
        )?;
        let undistortion = self.undistortion()?;
        let depth = match undistortion {
            Some(map) => map.depth(&depth)?,
            None => depth,
        };
        let rgb = match (&color_camera, &self.camera_file.color) {
            (Some(color_camera), Some(color)) => register_color_to_depth(
                &rgb,
                color_camera,
                &depth,
                &self.camera,
                &color.color_from_depth(),
            )?,
            _ => match undistortion {
                Some(map) => map.rgb(&rgb)?,
                None => rgb,
            },
        };
        let mask = match &entry.mask_path {
            Some(path) => {
                let mask = read_mask_png(path)?;
                check(path, (mask.width(), mask.height()), depth_size)?;
                Some(match undistortion {
                    Some(map) => map.mask(&mask)?,
                    None => mask,
                })
            }
            None => None,
        };
        Ok(RgbdFrame::new(entry.timestamp_s, rgb, depth, mask)?)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    #[test]
    fn interpolation_brackets_and_limits() {
        let poses = vec![
            StampedPose {
                timestamp_s: 0.0,
                world_from_camera: Isometry3::translation(0.0, 0.0, 0.0),
            },
            StampedPose {
                timestamp_s: 0.1,
                world_from_camera: Isometry3::new(
                    Vector3::new(1.0, 0.0, 0.0),
                    Vector3::new(0.0, 0.0, 0.2),
                ),
            },
        ];
        let mid = interpolate_pose(&poses, 0.05).unwrap();
        assert!((mid.translation.x - 0.5).abs() < 1e-12);
        assert!((mid.rotation.angle() - 0.1).abs() < 1e-12);
        assert!(interpolate_pose(&poses, 0.115).is_some());
        assert!(interpolate_pose(&poses, 0.2).is_none());
        assert!(interpolate_pose(&[], 0.0).is_none());
    }
}
