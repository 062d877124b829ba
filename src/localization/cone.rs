//! The four-face polyhedral cone back-projected from a box, as four inward half-spaces through
//! the camera centre (paper §III-B, registration condition N·L̃ > 0).

use nalgebra::{Isometry3, Point2, Point3, Vector3};
use scarp_slam::PinholeCamera;

use crate::detection::BoundingBox;

/// The rays through a box's corners (camera frame, z = 1), clockwise on the image with y down:
/// top-left, top-right, bottom-right, bottom-left.
pub fn corner_rays(camera: &PinholeCamera, bbox: &BoundingBox) -> [Vector3<f64>; 4] {
    let corners = [
        (bbox.x_min, bbox.y_min),
        (bbox.x_max, bbox.y_min),
        (bbox.x_max, bbox.y_max),
        (bbox.x_min, bbox.y_max),
    ];
    corners.map(|(u, v)| camera.unproject(&Point2::new(u, v), 1.0).coords)
}

/// The cone of a box in camera coordinates: point L̃ lies strictly inside when N·L̃ > 0 for all
/// four rows of N.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoxCone {
    /// Inward normals n_ij = (K⁻¹l_i) × (K⁻¹l_j) of the four faces (camera frame, unnormalised).
    pub normals: [Vector3<f64>; 4],
}

impl BoxCone {
    /// The cone of `bbox` (already enlarged if wanted) for `camera`.
    ///
    /// The normals come from cross products of adjacent corner rays in clockwise order; each is
    /// flipped if needed so that it points toward the box centre's ray, which keeps them inward
    /// for a camera with a negative `fy` (mirrored rows) too. The box must have positive area.
    pub fn new(camera: &PinholeCamera, bbox: &BoundingBox) -> Self {
        let rays = corner_rays(camera, bbox);
        let (cu, cv) = bbox.center();
        let centre_ray = camera.unproject(&Point2::new(cu, cv), 1.0).coords;
        let normals = std::array::from_fn(|i| {
            let n = rays[i].cross(&rays[(i + 1) % 4]);
            if n.dot(&centre_ray) < 0.0 { -n } else { n }
        });
        Self { normals }
    }

    /// Whether a point in camera coordinates satisfies all four half-spaces.
    pub fn contains(&self, p_camera: &Point3<f64>) -> bool {
        self.normals.iter().all(|n| n.dot(&p_camera.coords) > 0.0)
    }

    /// How many of `points_world` lie inside the cone of a camera at `world_from_camera`.
    pub fn count_inside(
        &self,
        world_from_camera: &Isometry3<f64>,
        points_world: &[Point3<f64>],
    ) -> usize {
        let camera_from_world = world_from_camera.inverse();
        points_world
            .iter()
            .filter(|p| self.contains(&(camera_from_world * *p)))
            .count()
    }
}

/// Whether a point in camera coordinates projects strictly inside `bbox` (in front of the
/// camera): the brute-force counterpart of [`BoxCone::contains`].
pub fn projects_inside(camera: &PinholeCamera, bbox: &BoundingBox, p_camera: &Point3<f64>) -> bool {
    camera.project(p_camera).is_some_and(|px| {
        px.x > bbox.x_min && px.x < bbox.x_max && px.y > bbox.y_min && px.y < bbox.y_max
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn camera() -> PinholeCamera {
        PinholeCamera::from_hfov(640, 480, 80.0).unwrap()
    }

    #[test]
    fn normals_point_inward() {
        let cam = camera();
        let bbox = BoundingBox::new(100.0, 50.0, 200.0, 300.0).unwrap();
        let cone = BoxCone::new(&cam, &bbox);
        let inside = cam.unproject(&Point2::new(150.0, 175.0), 7.0);
        assert!(cone.contains(&inside));
        let left = cam.unproject(&Point2::new(90.0, 175.0), 7.0);
        assert!(!cone.contains(&left));
        // Behind the camera, mirrored through the centre: outside.
        assert!(!cone.contains(&Point3::from(-inside.coords)));
    }

    #[test]
    fn mirrored_rows_keep_normals_inward() {
        let c = camera();
        let cam = PinholeCamera::new(c.fx, -c.fy, c.cx, c.cy, c.width, c.height).unwrap();
        let bbox = BoundingBox::new(100.0, 50.0, 200.0, 300.0).unwrap();
        let cone = BoxCone::new(&cam, &bbox);
        let inside = cam.unproject(&Point2::new(150.0, 175.0), 7.0);
        assert!(cone.contains(&inside));
        assert!(projects_inside(&cam, &bbox, &inside));
    }

    proptest! {
        #[test]
        fn half_spaces_agree_with_projection(
            x0 in -50.0f64..600.0, y0 in -50.0f64..450.0,
            w in 1.0f64..300.0, h in 1.0f64..300.0,
            px in -20.0f64..20.0, py in -20.0f64..20.0, pz in -20.0f64..20.0,
        ) {
            let cam = camera();
            let bbox = BoundingBox::new(x0, y0, x0 + w, y0 + h).unwrap();
            let cone = BoxCone::new(&cam, &bbox);
            let p = Point3::new(px, py, pz);
            // Skip points within rounding distance of a face, where both tests are ill-posed.
            let margin = cone
                .normals
                .iter()
                .map(|n| (n.dot(&p.coords) / (n.norm() * p.coords.norm().max(1e-12))).abs())
                .fold(f64::INFINITY, f64::min);
            prop_assume!(margin > 1e-9 && pz.abs() > 1e-6);
            prop_assert_eq!(cone.contains(&p), projects_inside(&cam, &bbox, &p));
        }

        #[test]
        fn half_spaces_agree_with_projection_near_the_box(
            x0 in 0.0f64..500.0, y0 in 0.0f64..400.0,
            w in 1.0f64..140.0, h in 1.0f64..80.0,
            su in -0.5f64..1.5, sv in -0.5f64..1.5, depth in -20.0f64..20.0,
        ) {
            // Points around the box, half of them inside, at either side of the camera.
            let cam = camera();
            let bbox = BoundingBox::new(x0, y0, x0 + w, y0 + h).unwrap();
            let cone = BoxCone::new(&cam, &bbox);
            let u = x0 + su * w;
            let v = y0 + sv * h;
            prop_assume!((u - bbox.x_min).abs() > 1e-6 && (u - bbox.x_max).abs() > 1e-6);
            prop_assume!((v - bbox.y_min).abs() > 1e-6 && (v - bbox.y_max).abs() > 1e-6);
            prop_assume!(depth.abs() > 1e-3);
            let p = cam.unproject(&Point2::new(u, v), depth);
            prop_assert_eq!(cone.contains(&p), projects_inside(&cam, &bbox, &p));
        }
    }
}
