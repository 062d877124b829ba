//! Registering a colour image to a depth image taken by a second camera.
//!
//! Sensors such as the Kinect v1 (Microsoft 7-Scenes) record colour and depth with two cameras
//! a few centimetres apart and with different focal lengths. Everything downstream (odometry's
//! photometric term, landmarks, mesh colour) assumes that pixel (u, v) of the colour image and
//! of the depth image see the same point, so the colour is resampled into the depth camera.

use nalgebra::{Isometry3, Point2, Point3};
use rayon::prelude::*;

use super::{DepthImage, RgbImage};
use crate::{PinholeCamera, SlamError};

/// The colour image resampled into the depth camera: pixel (u, v) of the result is the colour
/// of the point that depth pixel (u, v) measured.
///
/// - `depth_camera` is the camera of `depth_m` (metres, z-depth; 0 or non-finite is missing).
/// - `color_camera` is the camera of `rgb`; its size may differ from the depth image's.
/// - `color_from_depth` maps points from the depth camera's frame to the colour camera's,
///   metres.
///
/// Where the depth is missing, the pixel's ray is taken at infinity (the rotation alone moves
/// it), which is right for far surfaces and within the baseline's parallax otherwise. Colour is
/// interpolated bilinearly and clamped at the colour image's border. Surfaces the colour camera
/// cannot see (occluded by a nearer one from its viewpoint, a band a few pixels wide at depth
/// edges for a 2.5 cm baseline) take the occluder's colour.
///
/// # Errors
/// [`SlamError`] when either image does not match its camera's size.
pub fn register_color_to_depth(
    rgb: &RgbImage,
    color_camera: &PinholeCamera,
    depth_m: &DepthImage,
    depth_camera: &PinholeCamera,
    color_from_depth: &Isometry3<f64>,
) -> Result<RgbImage, SlamError> {
    rgb.check_size("colour image", color_camera.width, color_camera.height)?;
    depth_m.check_size("depth image", depth_camera.width, depth_camera.height)?;
    let width = depth_camera.width as usize;
    let mut data = vec![[0u8; 3]; depth_m.as_slice().len()];
    data.par_chunks_mut(width)
        .zip(depth_m.as_slice().par_chunks(width))
        .enumerate()
        .for_each(|(v, (row, depth_row))| {
            for (u, (out, &depth)) in row.iter_mut().zip(depth_row).enumerate() {
                let pixel = Point2::new(u as f64, v as f64);
                let depth = f64::from(depth);
                let in_color = if depth > 0.0 && depth.is_finite() {
                    color_from_depth * depth_camera.unproject(&pixel, depth)
                } else {
                    let ray = depth_camera.unproject(&pixel, 1.0).coords;
                    Point3::from(color_from_depth.rotation * ray)
                };
                *out = match color_camera.project(&in_color) {
                    Some(p) => sample_rgb_clamped(rgb, p.x, p.y),
                    None => [0, 0, 0],
                };
            }
        });
    RgbImage::from_vec(depth_camera.width, depth_camera.height, data)
}

/// Bilinear colour at (u, v), with coordinates clamped to the image.
pub(super) fn sample_rgb_clamped(rgb: &RgbImage, u: f64, v: f64) -> [u8; 3] {
    let max_u = f64::from(rgb.width() - 1);
    let max_v = f64::from(rgb.height() - 1);
    let (u, v) = (u.clamp(0.0, max_u), v.clamp(0.0, max_v));
    let (u0, v0) = (u.floor() as u32, v.floor() as u32);
    let (u1, v1) = (
        (u0 + 1).min(rgb.width() - 1),
        (v0 + 1).min(rgb.height() - 1),
    );
    let (fu, fv) = (u - f64::from(u0), v - f64::from(v0));
    let at = |u: u32, v: u32| rgb.as_slice()[v as usize * rgb.width() as usize + u as usize];
    let (a, b, c, d) = (at(u0, v0), at(u1, v0), at(u0, v1), at(u1, v1));
    std::array::from_fn(|k| {
        let top = f64::from(a[k]) + (f64::from(b[k]) - f64::from(a[k])) * fu;
        let bottom = f64::from(c[k]) + (f64::from(d[k]) - f64::from(c[k])) * fu;
        (top + (bottom - top) * fv).round() as u8
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion};

    /// A colour image whose pixel encodes its own coordinates: r = u, g = v.
    fn coordinate_image(width: u32, height: u32) -> RgbImage {
        let data = (0..height)
            .flat_map(|v| (0..width).map(move |u| [u as u8, v as u8, 7]))
            .collect();
        RgbImage::from_vec(width, height, data).unwrap()
    }

    #[test]
    fn identical_cameras_give_the_colour_back() {
        let camera = PinholeCamera::new(60.0, 60.0, 31.5, 23.5, 64, 48).unwrap();
        let rgb = coordinate_image(64, 48);
        let depth = DepthImage::filled(64, 48, 2.0);
        let out = register_color_to_depth(&rgb, &camera, &depth, &camera, &Isometry3::identity())
            .unwrap();
        assert_eq!(out, rgb);
    }

    #[test]
    fn a_plane_is_registered_through_focal_length_and_baseline() {
        // Depth camera f 60; colour camera f 50, 5 cm to the right; a plane 2 m away.
        let depth_camera = PinholeCamera::new(60.0, 60.0, 32.0, 24.0, 64, 48).unwrap();
        let color_camera = PinholeCamera::new(50.0, 50.0, 40.0, 30.0, 80, 60).unwrap();
        let rgb = coordinate_image(80, 60);
        let mut depth = DepthImage::filled(64, 48, 2.0);
        *depth.get_mut(10, 10).unwrap() = 0.0;
        let color_from_depth = Isometry3::from_parts(
            Translation3::new(-0.05, 0.0, 0.0),
            UnitQuaternion::identity(),
        );
        let out = register_color_to_depth(
            &rgb,
            &color_camera,
            &depth,
            &depth_camera,
            &color_from_depth,
        )
        .unwrap();
        for (u, v) in [(32u32, 24u32), (5, 40), (60, 3), (10, 10)] {
            let x = (f64::from(u) - 32.0) / 60.0;
            let y = (f64::from(v) - 24.0) / 60.0;
            // With depth: the point shifts by the baseline; without: the ray at infinity.
            let shift = if (u, v) == (10, 10) { 0.0 } else { -0.05 / 2.0 };
            let expected_u = (50.0 * (x + shift) + 40.0).round();
            let expected_v = (50.0 * y + 30.0).round();
            let got = out.get(u, v).unwrap();
            assert!(
                (f64::from(got[0]) - expected_u).abs() <= 1.0
                    && (f64::from(got[1]) - expected_v).abs() <= 1.0,
                "pixel ({u}, {v}): colour {got:?}, expected ({expected_u}, {expected_v})"
            );
        }
    }

    #[test]
    fn mismatched_sizes_are_refused() {
        let camera = PinholeCamera::new(60.0, 60.0, 31.5, 23.5, 64, 48).unwrap();
        let rgb = coordinate_image(32, 48);
        let depth = DepthImage::filled(64, 48, 2.0);
        let error = register_color_to_depth(&rgb, &camera, &depth, &camera, &Isometry3::identity())
            .unwrap_err();
        assert!(error.to_string().contains("colour image"), "{error}");
    }
}
