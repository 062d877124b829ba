//! Rendered test scenes shared by the localization and mission tests.

use nalgebra::{Isometry3, Point2, Point3};
use scarp_slam::PinholeCamera;
use scarp_slam::image::DepthImage;

/// z-depth of a sphere standing on the ground plane z = 0, ray-cast from `pose`.
pub(crate) fn sphere_on_ground(
    camera: &PinholeCamera,
    pose: &Isometry3<f64>,
    center: &Point3<f64>,
    radius: f64,
) -> DepthImage {
    let mut depth = DepthImage::filled(camera.width, camera.height, 0.0);
    let eye = pose.translation.vector;
    for v in 0..camera.height {
        for u in 0..camera.width {
            let ray_camera = camera.unproject(&Point2::new(f64::from(u), f64::from(v)), 1.0);
            let ray = pose.rotation * ray_camera.coords;
            let oc = eye - center.coords;
            let (b, c) = (oc.dot(&ray), oc.norm_squared() - radius * radius);
            let a = ray.norm_squared();
            let disc = b * b - a * c;
            let sphere_t = (disc >= 0.0)
                .then(|| (-b - disc.sqrt()) / a)
                .filter(|t| *t > 0.0);
            let ground_t = (ray.z < 0.0).then(|| -eye.z / ray.z);
            // The ray is scaled so that t is the z-depth.
            if let Some(t) = sphere_t.or(ground_t) {
                *depth.get_mut(u, v).unwrap() = t as f32;
            }
        }
    }
    depth
}
