//! The pinhole camera model.

use nalgebra::{Point2, Point3};
use serde::{Deserialize, Serialize};

use crate::SlamError;

/// A pinhole camera without distortion, in the OpenCV convention: camera x right, y down,
/// z forward; pixel (u, v) is (column, row) with pixel centres at integer coordinates, so the
/// image spans u ∈ [−0.5, width − 0.5).
///
/// Focal lengths and principal point are in pixels. `fy` may be negative: some public
/// sequences store images with the vertical axis flipped that way; projection then mirrors v.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PinholeCamera {
    /// Horizontal focal length, pixels (> 0).
    pub fx: f64,
    /// Vertical focal length, pixels (non-zero; negative flips the v axis).
    pub fy: f64,
    /// Principal point column, pixels.
    pub cx: f64,
    /// Principal point row, pixels.
    pub cy: f64,
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
}

impl PinholeCamera {
    /// Builds a camera, checking that the intrinsics are usable.
    ///
    /// # Errors
    /// [`SlamError::InvalidCamera`] when `fx ≤ 0`, `fy = 0`, any value is not finite, or the image
    /// is empty.
    pub fn new(
        fx: f64,
        fy: f64,
        cx: f64,
        cy: f64,
        width: u32,
        height: u32,
    ) -> Result<Self, SlamError> {
        let camera = Self {
            fx,
            fy,
            cx,
            cy,
            width,
            height,
        };
        camera.validate()?;
        Ok(camera)
    }

    /// A camera with square pixels and the principal point at the image centre, given the
    /// horizontal field of view in degrees.
    ///
    /// # Errors
    /// [`SlamError::InvalidCamera`] when the field of view is not in (0°, 180°) or the image is
    /// empty.
    pub fn from_hfov(width: u32, height: u32, hfov_deg: f64) -> Result<Self, SlamError> {
        if !(hfov_deg > 0.0 && hfov_deg < 180.0) {
            return Err(SlamError::InvalidCamera {
                field: "hfov_deg",
                value: hfov_deg,
                reason: "must lie in (0, 180) degrees",
            });
        }
        let f = f64::from(width) / 2.0 / (hfov_deg.to_radians() / 2.0).tan();
        Self::new(
            f,
            f,
            (f64::from(width) - 1.0) / 2.0,
            (f64::from(height) - 1.0) / 2.0,
            width,
            height,
        )
    }

    /// Checks the intrinsics.
    ///
    /// # Errors
    /// [`SlamError::InvalidCamera`] naming the first field at fault.
    pub fn validate(&self) -> Result<(), SlamError> {
        let bad = |field, value, reason| {
            Err(SlamError::InvalidCamera {
                field,
                value,
                reason,
            })
        };
        for (field, value) in [
            ("fx", self.fx),
            ("fy", self.fy),
            ("cx", self.cx),
            ("cy", self.cy),
        ] {
            if !value.is_finite() {
                return bad(field, value, "must be finite");
            }
        }
        if self.fx <= 0.0 {
            return bad("fx", self.fx, "must be positive");
        }
        if self.fy == 0.0 {
            return bad("fy", self.fy, "must be non-zero");
        }
        if self.width == 0 {
            return bad("width", 0.0, "must be positive");
        }
        if self.height == 0 {
            return bad("height", 0.0, "must be positive");
        }
        Ok(())
    }

    /// Projects a point in camera coordinates (metres) to a pixel. Returns `None` for points at
    /// or behind the camera centre (z ≤ 0). The pixel may lie outside the image; see
    /// [`Self::in_bounds`].
    pub fn project(&self, p_camera: &Point3<f64>) -> Option<Point2<f64>> {
        if p_camera.z <= 0.0 || !p_camera.z.is_finite() {
            return None;
        }
        let inv_z = 1.0 / p_camera.z;
        Some(Point2::new(
            self.fx * p_camera.x * inv_z + self.cx,
            self.fy * p_camera.y * inv_z + self.cy,
        ))
    }

    /// Back-projects pixel (u, v) with z-depth `depth_m` (metres along the camera z axis) to a
    /// point in camera coordinates.
    pub fn unproject(&self, pixel: &Point2<f64>, depth_m: f64) -> Point3<f64> {
        Point3::new(
            (pixel.x - self.cx) / self.fx * depth_m,
            (pixel.y - self.cy) / self.fy * depth_m,
            depth_m,
        )
    }

    /// Whether a pixel lies inside the image, `margin_px` away from every border. Pixel centres
    /// sit at integers, so the image covers [−0.5, width − 0.5) × [−0.5, height − 0.5).
    pub fn in_bounds(&self, pixel: &Point2<f64>, margin_px: f64) -> bool {
        pixel.x >= -0.5 + margin_px
            && pixel.y >= -0.5 + margin_px
            && pixel.x < f64::from(self.width) - 0.5 - margin_px
            && pixel.y < f64::from(self.height) - 0.5 - margin_px
    }

    /// The camera of an image downsampled by 2^`level` (as in [`crate::image::ImagePyramid`]):
    /// each coarse pixel averages a 2^level × 2^level block, so pixel centres map as
    /// u_coarse = (u + 0.5) / 2^level − 0.5.
    pub fn downsampled(&self, level: u32) -> Self {
        let s = f64::from(1u32 << level);
        Self {
            fx: self.fx / s,
            fy: self.fy / s,
            cx: (self.cx + 0.5) / s - 0.5,
            cy: (self.cy + 0.5) / s - 0.5,
            width: (self.width >> level).max(1),
            height: (self.height >> level).max(1),
        }
    }

    /// Horizontal field of view in degrees.
    pub fn hfov_deg(&self) -> f64 {
        2.0 * (f64::from(self.width) / 2.0 / self.fx).atan().to_degrees()
    }

    /// Number of pixels, width × height.
    pub fn pixel_count(&self) -> usize {
        self.width as usize * self.height as usize
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn camera() -> PinholeCamera {
        PinholeCamera::from_hfov(640, 480, 80.0).unwrap()
    }

    #[test]
    fn rejects_bad_intrinsics() {
        assert!(matches!(
            PinholeCamera::new(0.0, 1.0, 0.0, 0.0, 10, 10),
            Err(SlamError::InvalidCamera { field: "fx", .. })
        ));
        assert!(matches!(
            PinholeCamera::new(1.0, f64::NAN, 0.0, 0.0, 10, 10),
            Err(SlamError::InvalidCamera { field: "fy", .. })
        ));
        assert!(PinholeCamera::new(1.0, -1.0, 0.0, 0.0, 10, 10).is_ok());
        assert!(PinholeCamera::from_hfov(10, 10, 180.0).is_err());
    }

    #[test]
    fn hfov_round_trips() {
        assert!((camera().hfov_deg() - 80.0).abs() < 1e-9);
    }

    #[test]
    fn principal_point_projects_to_centre() {
        let c = camera();
        let p = c.project(&Point3::new(0.0, 0.0, 3.0)).unwrap();
        assert!((p.x - 319.5).abs() < 1e-12 && (p.y - 239.5).abs() < 1e-12);
        assert!(c.project(&Point3::new(0.0, 0.0, -1.0)).is_none());
    }

    #[test]
    fn bounds_follow_pixel_centres() {
        let c = camera();
        assert!(c.in_bounds(&Point2::new(-0.49, 0.0), 0.0));
        assert!(!c.in_bounds(&Point2::new(-0.51, 0.0), 0.0));
        assert!(c.in_bounds(&Point2::new(639.49, 479.49), 0.0));
        assert!(!c.in_bounds(&Point2::new(639.5, 0.0), 0.0));
        assert!(!c.in_bounds(&Point2::new(3.0, 3.0), 5.0));
    }

    #[test]
    fn downsampled_camera_maps_block_centres() {
        let c = camera();
        let d = c.downsampled(1);
        // Fine pixels 0 and 1 average into coarse pixel 0, whose centre is fine 0.5.
        let p = Point3::new(0.3, -0.2, 2.0);
        let fine = c.project(&p).unwrap();
        let coarse = d.project(&p).unwrap();
        assert!(((fine.x + 0.5) / 2.0 - 0.5 - coarse.x).abs() < 1e-9);
        assert!(((fine.y + 0.5) / 2.0 - 0.5 - coarse.y).abs() < 1e-9);
    }

    proptest! {
        #[test]
        fn project_unproject_round_trip(u in -0.5f64..639.4, v in -0.5f64..479.4, z in 0.1f64..100.0) {
            let c = camera();
            let p = c.unproject(&Point2::new(u, v), z);
            prop_assert!((p.z - z).abs() < 1e-12);
            let q = c.project(&p).unwrap();
            prop_assert!((q.x - u).abs() < 1e-9 && (q.y - v).abs() < 1e-9);
            prop_assert!(c.in_bounds(&q, 0.0));
        }
    }
}
