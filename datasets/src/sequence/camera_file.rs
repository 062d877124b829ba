//! `camera.toml`: the intrinsics and depth scale of a sequence.

use std::path::Path;

use scarp_slam::PinholeCamera;
use serde::{Deserialize, Serialize};

use crate::DatasetError;

/// The contents of `camera.toml`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraFile {
    /// Horizontal focal length, pixels.
    pub fx: f64,
    /// Vertical focal length, pixels; may be negative (flipped v axis).
    pub fy: f64,
    /// Principal point column, pixels.
    pub cx: f64,
    /// Principal point row, pixels.
    pub cy: f64,
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    /// Depth PNG units per metre (5000 for TUM).
    pub depth_scale: f64,
    /// Whether the depth image is registered to the colour image (pixel (u, v) of both sees
    /// the same point). Default true (TUM RGB-D, ICL-NUIM, scarp's renders); false for sensors
    /// whose colour and depth come from two cameras unaligned, such as Microsoft 7-Scenes'.
    /// Without registration the depth at a colour corner belongs to a neighbouring point, so it
    /// is not used as a bundle-adjustment residual.
    #[serde(default = "registered_by_default")]
    pub depth_registered: bool,
}

fn registered_by_default() -> bool {
    true
}

impl CameraFile {
    /// The file for a camera and depth scale.
    pub fn new(camera: &PinholeCamera, depth_scale: f64) -> Self {
        Self {
            fx: camera.fx,
            fy: camera.fy,
            cx: camera.cx,
            cy: camera.cy,
            width: camera.width,
            height: camera.height,
            depth_scale,
            depth_registered: true,
        }
    }

    /// The pinhole camera.
    ///
    /// # Errors
    /// [`DatasetError::Geometry`] for unusable intrinsics.
    pub fn camera(&self) -> Result<PinholeCamera, DatasetError> {
        Ok(PinholeCamera::new(
            self.fx,
            self.fy,
            self.cx,
            self.cy,
            self.width,
            self.height,
        )?)
    }

    /// Reads and checks `camera.toml`.
    ///
    /// # Errors
    /// [`DatasetError::Io`] for a missing file, [`DatasetError::Toml`] for an unknown or missing
    /// key, [`DatasetError::Invalid`] for bad intrinsics or a non-positive depth scale.
    pub fn read(path: &Path) -> Result<Self, DatasetError> {
        let text = std::fs::read_to_string(path).map_err(|e| DatasetError::io(path, e))?;
        let file: Self = toml::from_str(&text).map_err(|e| DatasetError::Toml {
            path: path.to_path_buf(),
            message: e.to_string(),
        })?;
        file.camera()
            .map_err(|e| DatasetError::invalid(path.display().to_string(), e.to_string()))?;
        if !(file.depth_scale > 0.0 && file.depth_scale.is_finite()) {
            return Err(DatasetError::invalid(
                format!("{}: depth_scale", path.display()),
                "must be positive",
            ));
        }
        Ok(file)
    }

    /// Writes `camera.toml` atomically.
    ///
    /// # Errors
    /// [`DatasetError::Write`] naming the file.
    pub fn write(&self, path: &Path) -> Result<(), DatasetError> {
        let text = format!(
            "# Pinhole intrinsics (pixels, OpenCV convention) and depth PNG units per metre.\n{}",
            toml::to_string(self)
                .map_err(|e| DatasetError::invalid("camera.toml", e.to_string()))?
        );
        scarp_export::atomic::write_bytes_atomically(path, text.as_bytes())?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn depth_is_registered_unless_the_file_says_otherwise() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("camera.toml");
        let base = "fx = 585.0\nfy = 585.0\ncx = 320.0\ncy = 240.0\nwidth = 640\nheight = 480\n\
                    depth_scale = 1000.0\n";
        std::fs::write(&path, base).unwrap();
        assert!(CameraFile::read(&path).unwrap().depth_registered);
        std::fs::write(&path, format!("{base}depth_registered = false\n")).unwrap();
        let file = CameraFile::read(&path).unwrap();
        assert!(!file.depth_registered);
        // Written and read back.
        file.write(&path).unwrap();
        assert_eq!(CameraFile::read(&path).unwrap(), file);
    }
}
