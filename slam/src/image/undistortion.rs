//! Lens distortion, and undistorting images into the ideal pinhole camera.
//!
//! Real RGB-D cameras are not pinholes: TUM RGB-D's freiburg1 Kinect bends a point near the
//! image corner by tens of pixels (k1 = 0.26). Everything in scarp (odometry, landmarks, TSDF,
//! BA) assumes a pinhole, so a distorted sequence is resampled once, on load, into the pinhole
//! camera with the same intrinsics.

use nalgebra::Point2;
use serde::{Deserialize, Serialize};

use super::{DepthImage, Image, MaskImage, RgbImage};
use crate::{PinholeCamera, SlamError};

/// Brown–Conrady lens distortion, with OpenCV's coefficients and conventions.
///
/// A point with ideal normalized coordinates (x, y) = (X/Z, Y/Z) in the camera frame is imaged
/// at the normalized coordinates
///
/// - x_d = x·(1 + k1·r² + k2·r⁴ + k3·r⁶) + 2·p1·x·y + p2·(r² + 2x²)
/// - y_d = y·(1 + k1·r² + k2·r⁴ + k3·r⁶) + p1·(r² + 2y²) + 2·p2·x·y
///
/// with r² = x² + y², and then at pixel (fx·x_d + cx, fy·y_d + cy). All coefficients are
/// dimensionless.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LensDistortion {
    /// Radial coefficient of r².
    pub k1: f64,
    /// Radial coefficient of r⁴.
    pub k2: f64,
    /// Tangential coefficient p1.
    pub p1: f64,
    /// Tangential coefficient p2.
    pub p2: f64,
    /// Radial coefficient of r⁶. Default 0.
    #[serde(default)]
    pub k3: f64,
}

impl LensDistortion {
    /// Where the lens images the ideal normalized point `(x, y)` (see the type's formulas).
    pub fn distort(&self, x: f64, y: f64) -> (f64, f64) {
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3));
        (
            x * radial + 2.0 * self.p1 * x * y + self.p2 * (r2 + 2.0 * x * x),
            y * radial + self.p1 * (r2 + 2.0 * y * y) + 2.0 * self.p2 * x * y,
        )
    }

    /// The ideal normalized point that the lens images at `(x_d, y_d)`: [`Self::distort`]
    /// inverted by fixed-point iteration (50 steps). It converges wherever the lens maps the
    /// image one to one, which covers the field of view of a calibrated camera; beyond it (far
    /// outside the image) the result is meaningless.
    pub fn undistort(&self, x_d: f64, y_d: f64) -> (f64, f64) {
        let (mut x, mut y) = (x_d, y_d);
        for _ in 0..50 {
            let (dx, dy) = self.distort(x, y);
            x -= dx - x_d;
            y -= dy - y_d;
        }
        (x, y)
    }

    /// Checks that every coefficient is finite.
    ///
    /// # Errors
    /// [`SlamError::InvalidConfig`] naming the first non-finite coefficient.
    pub fn validate(&self) -> Result<(), SlamError> {
        for (field, value) in [
            ("k1", self.k1),
            ("k2", self.k2),
            ("p1", self.p1),
            ("p2", self.p2),
            ("k3", self.k3),
        ] {
            if !value.is_finite() {
                return Err(SlamError::InvalidConfig {
                    field,
                    reason: "distortion coefficients must be finite",
                });
            }
        }
        Ok(())
    }
}

/// A precomputed resampling from a distorted camera's images to the pinhole camera with the
/// same intrinsics: for every pixel of the pinhole image, where the lens put it.
///
/// Pixels whose source falls outside the distorted image (the corners, for a pincushion lens)
/// come out empty: depth 0 (no measurement), colour black, mask 0.
#[derive(Debug, Clone, PartialEq)]
pub struct Undistortion {
    width: u32,
    height: u32,
    /// For each pinhole pixel in row-major order, its position in the distorted image, or
    /// `None` outside it.
    source_px: Vec<Option<Point2<f32>>>,
}

impl Undistortion {
    /// The map for `camera` (the intrinsics of both images) and `distortion`.
    ///
    /// # Errors
    /// [`SlamError::InvalidConfig`] for a non-finite coefficient.
    pub fn new(camera: &PinholeCamera, distortion: &LensDistortion) -> Result<Self, SlamError> {
        distortion.validate()?;
        let (width, height) = (camera.width, camera.height);
        let max_u = f64::from(width) - 1.0;
        let max_v = f64::from(height) - 1.0;
        let source_px = (0..height)
            .flat_map(|v| (0..width).map(move |u| (u, v)))
            .map(|(u, v)| {
                let x = (f64::from(u) - camera.cx) / camera.fx;
                let y = (f64::from(v) - camera.cy) / camera.fy;
                let (xd, yd) = distortion.distort(x, y);
                let (ud, vd) = (camera.fx * xd + camera.cx, camera.fy * yd + camera.cy);
                // Half a pixel beyond the border still rounds onto the image.
                let inside =
                    (-0.5..=max_u + 0.5).contains(&ud) && (-0.5..=max_v + 0.5).contains(&vd);
                inside.then(|| Point2::new(ud as f32, vd as f32))
            })
            .collect();
        Ok(Self {
            width,
            height,
            source_px,
        })
    }

    /// Depth resampled by nearest neighbour: interpolating would invent depths between a
    /// foreground edge and the background behind it. A z-depth stays a z-depth, since the lens
    /// moves where a point is imaged, not how far it is.
    ///
    /// # Errors
    /// [`SlamError`] when the image is not the camera's size.
    pub fn depth(&self, depth_m: &DepthImage) -> Result<DepthImage, SlamError> {
        self.nearest(depth_m, "depth image", 0.0)
    }

    /// An instance mask resampled by nearest neighbour (labels cannot be interpolated).
    ///
    /// # Errors
    /// [`SlamError`] when the image is not the camera's size.
    pub fn mask(&self, mask: &MaskImage) -> Result<MaskImage, SlamError> {
        self.nearest(mask, "mask", 0)
    }

    /// Colour resampled bilinearly.
    ///
    /// # Errors
    /// [`SlamError`] when the image is not the camera's size.
    pub fn rgb(&self, rgb: &RgbImage) -> Result<RgbImage, SlamError> {
        rgb.check_size("colour image", self.width, self.height)?;
        let data = self
            .source_px
            .iter()
            .map(|source| match source {
                Some(p) => {
                    super::registration::sample_rgb_clamped(rgb, f64::from(p.x), f64::from(p.y))
                }
                None => [0, 0, 0],
            })
            .collect();
        RgbImage::from_vec(self.width, self.height, data)
    }

    fn nearest<T: Copy>(
        &self,
        image: &Image<T>,
        what: &'static str,
        empty: T,
    ) -> Result<Image<T>, SlamError> {
        image.check_size(what, self.width, self.height)?;
        let max_u = self.width - 1;
        let max_v = self.height - 1;
        let data = self
            .source_px
            .iter()
            .map(|source| match source {
                Some(p) => {
                    let u = (p.x.round().max(0.0) as u32).min(max_u);
                    let v = (p.y.round().max(0.0) as u32).min(max_v);
                    image.as_slice()[v as usize * self.width as usize + u as usize]
                }
                None => empty,
            })
            .collect();
        Image::from_vec(self.width, self.height, data)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// TUM RGB-D freiburg1's published RGB distortion.
    const FREIBURG1: LensDistortion = LensDistortion {
        k1: 0.2624,
        k2: -0.9531,
        p1: -0.0054,
        p2: 0.0026,
        k3: 1.1633,
    };

    fn freiburg1_camera() -> PinholeCamera {
        PinholeCamera::new(517.3, 516.5, 318.6, 255.3, 640, 480).unwrap()
    }

    #[test]
    fn zero_distortion_is_the_identity() {
        let camera = PinholeCamera::new(50.0, 50.0, 15.5, 11.5, 32, 24).unwrap();
        let none = LensDistortion {
            k1: 0.0,
            k2: 0.0,
            p1: 0.0,
            p2: 0.0,
            k3: 0.0,
        };
        let map = Undistortion::new(&camera, &none).unwrap();
        let depth = DepthImage::from_vec(32, 24, (0..32 * 24).map(|i| i as f32).collect()).unwrap();
        assert_eq!(map.depth(&depth).unwrap(), depth);
        let rgb =
            RgbImage::from_vec(32, 24, (0..32 * 24).map(|i| [i as u8, 3, 9]).collect()).unwrap();
        assert_eq!(map.rgb(&rgb).unwrap(), rgb);
    }

    /// A distorted image of a known scene, undistorted, is the pinhole image of that scene:
    /// each depth pixel of the "scene" encodes the ideal pixel that sees it, the lens moves it
    /// by the forward model, and undistortion must bring every encoded value back to its
    /// pinhole pixel.
    #[test]
    fn undistortion_inverts_the_lens() {
        let camera = freiburg1_camera();
        // Render the distorted image: each distorted pixel shows the ideal point the lens puts
        // there.
        let (w, h) = (camera.width, camera.height);
        let mut distorted = vec![0.0f32; (w * h) as usize];
        for v in 0..h {
            for u in 0..w {
                let (x, y) = FREIBURG1.undistort(
                    (f64::from(u) - camera.cx) / camera.fx,
                    (f64::from(v) - camera.cy) / camera.fy,
                );
                // Encode the ideal pixel (column, row) in one float: column + 1000·row.
                let ideal_u = camera.fx * x + camera.cx;
                let ideal_v = camera.fy * y + camera.cy;
                distorted[(v * w + u) as usize] =
                    (ideal_u.round() + 1000.0 * ideal_v.round()) as f32;
            }
        }
        let distorted = DepthImage::from_vec(w, h, distorted).unwrap();
        let map = Undistortion::new(&camera, &FREIBURG1).unwrap();
        let pinhole = map.depth(&distorted).unwrap();
        let (mut checked, mut off) = (0, 0);
        for v in 0..h {
            for u in 0..w {
                let value = *pinhole.get(u, v).unwrap();
                if value == 0.0 {
                    continue;
                }
                checked += 1;
                let (ideal_u, ideal_v) = ((value % 1000.0).round(), (value / 1000.0).floor());
                // Nearest-neighbour sampling may land one pixel over.
                if (ideal_u - u as f32).abs() > 1.0 || (ideal_v - v as f32).abs() > 1.0 {
                    off += 1;
                }
            }
        }
        assert!(checked > 250_000, "{checked} pixels kept");
        assert_eq!(
            off, 0,
            "{off} of {checked} pixels land away from their pinhole pixel"
        );
        // The lens moves image corners by tens of pixels: the map is not a near-identity.
        let corner = map.source_px[0].unwrap_or(Point2::new(f32::NAN, f32::NAN));
        let centre = map.source_px[(255 * w + 318) as usize].unwrap();
        assert!((centre.x - 318.0).abs() < 0.5 && (centre.y - 255.0).abs() < 0.5);
        assert!(corner.x.is_nan() || corner.x.abs() > 5.0 || corner.y.abs() > 5.0);
    }

    #[test]
    fn undistort_inverts_distort() {
        for (x, y) in [(0.0, 0.0), (0.3, -0.2), (-0.55, 0.4), (0.6, 0.45)] {
            let (xd, yd) = FREIBURG1.distort(x, y);
            let (xu, yu) = FREIBURG1.undistort(xd, yd);
            assert!((xu - x).abs() < 1e-9 && (yu - y).abs() < 1e-9, "({x}, {y})");
        }
    }

    #[test]
    fn images_of_the_wrong_size_and_bad_coefficients_are_errors() {
        let camera = freiburg1_camera();
        let map = Undistortion::new(&camera, &FREIBURG1).unwrap();
        assert!(map.depth(&DepthImage::filled(64, 48, 1.0)).is_err());
        assert!(map.rgb(&RgbImage::filled(64, 48, [0; 3])).is_err());
        let bad = LensDistortion {
            k1: f64::NAN,
            ..FREIBURG1
        };
        assert!(Undistortion::new(&camera, &bad).is_err());
    }
}
