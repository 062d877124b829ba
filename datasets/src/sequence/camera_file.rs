//! `camera.toml`: the intrinsics and depth scale of a sequence.

use std::path::Path;

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use scarp_slam::PinholeCamera;
use scarp_slam::image::LensDistortion;
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
    /// The depth sensor's noise σ at 1 m, metres, for a σ growing as z² (stereo, structured
    /// light); 0 for exact depth. Absent when unknown (recorded and outside sequences).
    /// `scarp render` writes it from its sensor model. TSDF fusion uses it to tell precise
    /// pixels from noisy ones ([`scarp_slam::tsdf::TsdfConfig::depth_sigma_at_1m_m`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub depth_sigma_at_1m_m: Option<f64>,
    /// The colour camera, when it is not the depth camera (the `[color]` table). The top-level
    /// intrinsics are then the depth camera's, and each frame's colour is registered to its
    /// depth on load ([`scarp_slam::image::register_color_to_depth`]), so the frames a
    /// [`super::Sequence`] yields are registered whatever `depth_registered` says.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub color: Option<ColorCameraFile>,
    /// The lens distortion of the images the top-level intrinsics describe (the `[distortion]`
    /// table: OpenCV's `k1`, `k2`, `p1`, `p2` and optional `k3`). Absent for a pinhole, as
    /// rendered sequences and undistorted datasets are. TUM RGB-D's freiburg1 and freiburg2
    /// images are distorted, and their depth is registered to the distorted colour, so one
    /// table serves both. Each frame is resampled into the pinhole camera of the same
    /// intrinsics on load ([`scarp_slam::image::Undistortion`]); with a `[color]` table it
    /// describes the depth camera, and the colour is registered to the undistorted depth.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub distortion: Option<LensDistortion>,
}

/// The `[color]` table of `camera.toml`: the colour camera's intrinsics (pixels) and its pose
/// relative to the depth camera.
///
/// For a Kinect v1 whose colour and depth are not registered (Microsoft 7-Scenes), the sensor's
/// nominal colour intrinsics are fx = fy = 525, cx = 319.5, cy = 239.5.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ColorCameraFile {
    /// Horizontal focal length, pixels.
    pub fx: f64,
    /// Vertical focal length, pixels; may be negative.
    pub fy: f64,
    /// Principal point column, pixels.
    pub cx: f64,
    /// Principal point row, pixels.
    pub cy: f64,
    /// Colour image width, pixels; the depth image's when absent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub width: Option<u32>,
    /// Colour image height, pixels; the depth image's when absent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub height: Option<u32>,
    /// The depth camera's origin in the colour camera's frame, metres (the translation of
    /// `color_from_depth`). Zero when absent.
    #[serde(default)]
    pub color_from_depth_translation_m: [f64; 3],
    /// The rotation of `color_from_depth` as a rotation vector (axis × angle), degrees. Zero
    /// when absent.
    #[serde(default)]
    pub color_from_depth_rotation_deg: [f64; 3],
}

impl ColorCameraFile {
    /// `color_from_depth`: points in the depth camera's frame to the colour camera's, metres.
    pub fn color_from_depth(&self) -> Isometry3<f64> {
        let [tx, ty, tz] = self.color_from_depth_translation_m;
        let rotation_rad = Vector3::from(self.color_from_depth_rotation_deg).map(f64::to_radians);
        Isometry3::from_parts(
            Translation3::new(tx, ty, tz),
            UnitQuaternion::from_scaled_axis(rotation_rad),
        )
    }
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
            color: None,
            depth_sigma_at_1m_m: None,
            distortion: None,
        }
    }

    /// Whether the frames read with this file are registered: the files themselves are, or a
    /// `[color]` table registers them on load.
    pub fn frames_registered(&self) -> bool {
        self.depth_registered || self.color.is_some()
    }

    /// The colour camera of a `[color]` table, sized as the depth image unless it says
    /// otherwise.
    ///
    /// # Errors
    /// [`DatasetError::Geometry`] for unusable intrinsics.
    pub fn color_camera(&self) -> Result<Option<PinholeCamera>, DatasetError> {
        self.color
            .map(|c| {
                Ok(PinholeCamera::new(
                    c.fx,
                    c.fy,
                    c.cx,
                    c.cy,
                    c.width.unwrap_or(self.width),
                    c.height.unwrap_or(self.height),
                )?)
            })
            .transpose()
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
        Self::parse(&text, path)
    }

    /// Parses and checks the text of a `camera.toml`; `path` names it in errors.
    ///
    /// # Errors
    /// As [`Self::read`], without the I/O error.
    pub fn parse(text: &str, path: &Path) -> Result<Self, DatasetError> {
        let file: Self = toml::from_str(text).map_err(|e| DatasetError::Toml {
            path: path.to_path_buf(),
            message: e.to_string(),
        })?;
        file.camera()
            .map_err(|e| DatasetError::invalid(path.display().to_string(), e.to_string()))?;
        file.color_camera().map_err(|e| {
            DatasetError::invalid(format!("{}: [color]", path.display()), e.to_string())
        })?;
        if let Some(color) = &file.color {
            let mut pose = color
                .color_from_depth_translation_m
                .iter()
                .chain(&color.color_from_depth_rotation_deg);
            if pose.any(|x| !x.is_finite()) {
                return Err(DatasetError::invalid(
                    format!("{}: [color] color_from_depth", path.display()),
                    "must be finite",
                ));
            }
        }
        if let Some(distortion) = &file.distortion {
            distortion.validate().map_err(|e| {
                DatasetError::invalid(format!("{}: [distortion]", path.display()), e.to_string())
            })?;
        }
        if let Some(sigma) = file.depth_sigma_at_1m_m
            && !(sigma.is_finite() && sigma >= 0.0)
        {
            return Err(DatasetError::invalid(
                format!("{}: depth_sigma_at_1m_m", path.display()),
                "must be finite and ≥ 0",
            ));
        }
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

    /// A 7-Scenes-like camera file's required keys.
    const KINECT_BASE: &str = "fx = 585.0\nfy = 585.0\ncx = 320.0\ncy = 240.0\nwidth = 640\n\
                               height = 480\ndepth_scale = 1000.0\n";

    /// A temporary directory (kept alive by the caller) and its `camera.toml` path.
    fn temp_camera_file() -> (tempfile::TempDir, std::path::PathBuf) {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("camera.toml");
        (dir, path)
    }

    #[test]
    fn depth_is_registered_unless_the_file_says_otherwise() {
        let (_dir, path) = temp_camera_file();
        let base = KINECT_BASE;
        std::fs::write(&path, base).unwrap();
        assert!(CameraFile::read(&path).unwrap().depth_registered);
        std::fs::write(&path, format!("{base}depth_registered = false\n")).unwrap();
        let file = CameraFile::read(&path).unwrap();
        assert!(!file.depth_registered);
        // Written and read back.
        file.write(&path).unwrap();
        assert_eq!(CameraFile::read(&path).unwrap(), file);
        assert!(!file.frames_registered());
    }

    #[test]
    fn the_depth_noise_round_trips_and_must_be_finite() {
        let (_dir, path) = temp_camera_file();
        let base = KINECT_BASE;
        std::fs::write(&path, base).unwrap();
        assert_eq!(CameraFile::read(&path).unwrap().depth_sigma_at_1m_m, None);
        std::fs::write(&path, format!("{base}depth_sigma_at_1m_m = 0.0022\n")).unwrap();
        let mut file = CameraFile::read(&path).unwrap();
        assert_eq!(file.depth_sigma_at_1m_m, Some(0.0022));
        // Written (before a [color] table) and read back.
        file.color = Some(ColorCameraFile {
            fx: 525.0,
            fy: 525.0,
            cx: 319.5,
            cy: 239.5,
            width: None,
            height: None,
            color_from_depth_translation_m: [0.0; 3],
            color_from_depth_rotation_deg: [0.0; 3],
        });
        file.write(&path).unwrap();
        assert_eq!(CameraFile::read(&path).unwrap(), file);
        for bad in ["-0.001", "nan", "inf"] {
            std::fs::write(&path, format!("{base}depth_sigma_at_1m_m = {bad}\n")).unwrap();
            let err = CameraFile::read(&path).unwrap_err().to_string();
            assert!(err.contains("depth_sigma_at_1m_m"), "{bad}: {err}");
        }
    }

    #[test]
    fn a_color_table_round_trips_and_registers_the_frames() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("camera.toml");
        let base = "fx = 585.0\nfy = 585.0\ncx = 320.0\ncy = 240.0\nwidth = 640\nheight = 480\n\
                    depth_scale = 1000.0\ndepth_registered = false\n";
        std::fs::write(
            &path,
            format!(
                "{base}[color]\nfx = 525.0\nfy = 525.0\ncx = 319.5\ncy = 239.5\n\
                 color_from_depth_translation_m = [-0.025, 0.0, 0.0]\n\
                 color_from_depth_rotation_deg = [0.0, 0.0, 90.0]\n"
            ),
        )
        .unwrap();
        let file = CameraFile::read(&path).unwrap();
        assert!(file.frames_registered());
        let color = file.color.unwrap();
        let camera = file.color_camera().unwrap().unwrap();
        assert_eq!((camera.fx, camera.width, camera.height), (525.0, 640, 480));
        let moved = color.color_from_depth() * nalgebra::Point3::new(1.0, 0.0, 0.0);
        assert!((moved - nalgebra::Point3::new(-0.025, 1.0, 0.0)).norm() < 1e-12);
        file.write(&path).unwrap();
        assert_eq!(CameraFile::read(&path).unwrap(), file);

        // A misspelt key and bad intrinsics inside the table are named.
        std::fs::write(
            &path,
            format!("{base}[color]\nfx = 525.0\nfy = 525.0\ncx = 1.0\ncy = 1.0\nbaseline = 1\n"),
        )
        .unwrap();
        let error = CameraFile::read(&path).unwrap_err().to_string();
        assert!(error.contains("baseline"), "{error}");
        std::fs::write(
            &path,
            format!("{base}[color]\nfx = -5.0\nfy = 525.0\ncx = 1.0\ncy = 1.0\n"),
        )
        .unwrap();
        let error = CameraFile::read(&path).unwrap_err().to_string();
        assert!(error.contains("[color]") && error.contains("fx"), "{error}");
    }
}
