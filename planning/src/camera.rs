//! The forward camera as the planners see it: a pinhole camera fixed to the body, looking along
//! body +x and pitched down by γ. Body is FLU; the camera frame is OpenCV (x right, y down,
//! z forward).

use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

use crate::error::{PlanError, check_positive, check_range};

/// Camera geometry used for planning.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CameraConfig {
    /// Angle γ between the optical axis and the horizontal plane, positive down (degrees).
    /// Default 55° (paper §V, DESIGN defaults).
    pub pitch_down_deg: f64,
    /// Horizontal field of view (degrees). Default 80°.
    pub hfov_deg: f64,
    /// Image width (pixels). Default 640.
    pub width_px: u32,
    /// Image height (pixels). Default 480.
    pub height_px: u32,
    /// Fastest the mount's pitch servo turns when a ring asks for another pitch (degrees per
    /// second). Default 30 (a hobby gimbal's slew rate; slow enough that consecutive frames at
    /// 20 Hz overlap for odometry).
    pub pitch_rate_deg_s: f64,
}

impl Default for CameraConfig {
    fn default() -> Self {
        Self {
            pitch_down_deg: 55.0,
            hfov_deg: 80.0,
            width_px: 640,
            height_px: 480,
            pitch_rate_deg_s: 30.0,
        }
    }
}

/// Ground footprint of the camera over flat ground (metres), for a body flying level.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Footprint {
    /// Across-track width of the image's bottom row on the ground (nearest, narrowest).
    pub near_width_m: f64,
    /// Across-track width at the principal point's row.
    pub center_width_m: f64,
    /// Across-track width of the image's top row (farthest, widest).
    pub far_width_m: f64,
    /// Along-track ground distance from below the camera to the bottom row.
    pub near_distance_m: f64,
    /// Along-track ground distance from below the camera to the principal ray's ground point.
    pub center_distance_m: f64,
    /// Along-track ground distance to the top row.
    pub far_distance_m: f64,
}

impl CameraConfig {
    /// Checks that the angles are in range (γ in (0°, 90°), HFOV in (0°, 180°)) and the image is
    /// non-empty.
    pub fn validate(&self) -> Result<(), PlanError> {
        check_range(
            "camera.pitch_down_deg",
            self.pitch_down_deg,
            1e-6,
            90.0 - 1e-6,
        )?;
        check_range("camera.hfov_deg", self.hfov_deg, 1e-6, 180.0 - 1e-6)?;
        check_positive("camera.width_px", f64::from(self.width_px))?;
        check_positive("camera.height_px", f64::from(self.height_px))?;
        check_positive("camera.pitch_rate_deg_s", self.pitch_rate_deg_s)?;
        Ok(())
    }

    /// γ in radians.
    pub fn pitch_down_rad(&self) -> f64 {
        self.pitch_down_deg.to_radians()
    }

    /// Focal length in pixels, from the HFOV and the width.
    pub fn focal_px(&self) -> f64 {
        0.5 * f64::from(self.width_px) / (0.5 * self.hfov_deg.to_radians()).tan()
    }

    /// Vertical field of view (radians), from the focal length and the height (square pixels).
    pub fn vfov_rad(&self) -> f64 {
        2.0 * (0.5 * f64::from(self.height_px) / self.focal_px()).atan()
    }

    /// Pinhole intrinsics K (pixels), principal point at the image centre; pixel centres at
    /// integers, so c = (size − 1)/2.
    pub fn intrinsics(&self) -> Matrix3<f64> {
        let f = self.focal_px();
        Matrix3::new(
            f,
            0.0,
            0.5 * (f64::from(self.width_px) - 1.0),
            0.0,
            f,
            0.5 * (f64::from(self.height_px) - 1.0),
            0.0,
            0.0,
            1.0,
        )
    }

    /// The camera mount: maps camera (OpenCV) coordinates to body (FLU) coordinates. The camera
    /// sits at the body origin (the paper neglects the offset, d₁:d₂ > 10:1).
    pub fn body_from_camera(&self) -> Isometry3<f64> {
        body_from_camera_at_pitch(self.pitch_down_rad())
    }

    /// Ground footprint over flat ground `height_above_ground_m` below the camera, body level.
    ///
    /// Fails if the height is not positive or the top image row looks at or above the horizon
    /// (γ ≤ VFOV/2), where the footprint is unbounded.
    pub fn footprint(&self, height_above_ground_m: f64) -> Result<Footprint, PlanError> {
        self.validate()?;
        let h = check_positive("height_above_ground_m", height_above_ground_m)?;
        let g = self.pitch_down_rad();
        let half_v = 0.5 * self.vfov_rad();
        if g - half_v <= 1e-6 {
            return Err(PlanError::InvalidParameter {
                field: "camera.pitch_down_deg".into(),
                value: self.pitch_down_deg,
                reason: format!(
                    "the top image row reaches the horizon (VFOV/2 = {:.1}°): footprint unbounded",
                    half_v.to_degrees()
                ),
            });
        }
        let tan_h = (0.5 * self.hfov_deg.to_radians()).tan();
        let tan_v = half_v.tan();
        // A ray (x, y, 1) in camera coordinates descends by sin γ + y cos γ per unit along z.
        let width = |y: f64| 2.0 * tan_h * h / (g.sin() + y * g.cos());
        let dist = |depression: f64| h / depression.tan();
        Ok(Footprint {
            near_width_m: width(tan_v),
            center_width_m: width(0.0),
            far_width_m: width(-tan_v),
            near_distance_m: dist(g + half_v),
            center_distance_m: dist(g),
            far_distance_m: dist(g - half_v),
        })
    }
}

/// The camera mount at pitch `pitch_down_rad` below the body's x axis (negative looks up):
/// maps camera (OpenCV) coordinates to body (FLU) coordinates, the camera at the body origin.
pub fn body_from_camera_at_pitch(pitch_down_rad: f64) -> Isometry3<f64> {
    let g = pitch_down_rad;
    // Columns: camera x (right), y (down), z (forward) expressed in FLU.
    let z_cam = Vector3::new(g.cos(), 0.0, -g.sin());
    let x_cam = Vector3::new(0.0, -1.0, 0.0);
    let y_cam = z_cam.cross(&x_cam);
    let rot = Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[x_cam, y_cam, z_cam]));
    Isometry3::from_parts(
        Translation3::identity(),
        UnitQuaternion::from_rotation_matrix(&rot),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Point3;

    #[test]
    fn defaults_match_design() {
        let c = CameraConfig::default();
        assert!((c.vfov_rad().to_degrees() - 64.4).abs() < 0.2);
        let fp = c.footprint(10.0).unwrap();
        assert!(fp.near_width_m < fp.center_width_m && fp.center_width_m < fp.far_width_m);
        assert!((fp.center_distance_m - 10.0 / 55f64.to_radians().tan()).abs() < 1e-9);
    }

    #[test]
    fn optical_axis_points_forward_and_down() {
        let c = CameraConfig::default();
        let z = c.body_from_camera() * Point3::new(0.0, 0.0, 1.0);
        assert!(z.x > 0.0 && z.z < 0.0 && z.y.abs() < 1e-12);
        let depression = (-z.z).atan2(z.x).to_degrees();
        assert!((depression - 55.0).abs() < 1e-9);
        // Image "down" (camera +y) points down in the body too.
        let y = c.body_from_camera() * Point3::new(0.0, 1.0, 0.0);
        assert!(y.z < 0.0);
        let det = c
            .body_from_camera()
            .rotation
            .to_rotation_matrix()
            .matrix()
            .determinant();
        assert!((det - 1.0).abs() < 1e-12);
    }
}
