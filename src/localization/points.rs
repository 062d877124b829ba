//! Point generation in a box's back-projected cone (paper Algorithm 2).

use nalgebra::{Isometry3, Point3};
use rand::RngExt;
use scarp_slam::PinholeCamera;

use super::cone::corner_rays;
use crate::detection::BoundingBox;

/// Draws `count` points (world frame, m) inside the cone of `enlarged_box` seen by `camera` at
/// `world_from_camera`, Algorithm 2: each direction is a convex combination Σαᵢ K⁻¹lᵢ of the four
/// corner rays with αᵢ ~ U(0, 1) normalised to sum 1 (so the direction has z = 1), scaled by a
/// depth δ ~ U(`min_depth_m`, `max_depth_m`) along the camera z axis, then mapped to the world.
///
/// The caller validates the box (positive area), the pose (finite) and the depths
/// (0 < min < max); see [`super::check_box`] and [`super::LocalizationConfig::validate`].
pub fn generate_points<R: rand::Rng + ?Sized>(
    camera: &PinholeCamera,
    world_from_camera: &Isometry3<f64>,
    enlarged_box: &BoundingBox,
    count: usize,
    min_depth_m: f64,
    max_depth_m: f64,
    rng: &mut R,
) -> Vec<Point3<f64>> {
    let rays = corner_rays(camera, enlarged_box);
    (0..count)
        .map(|_| {
            let alphas: [f64; 4] = std::array::from_fn(|_| rng.random::<f64>());
            let sum: f64 = alphas.iter().sum();
            // All four are 0 with probability ~2⁻²¹²; fall back to the centre ray then.
            let alphas = if sum > 0.0 {
                alphas.map(|a| a / sum)
            } else {
                [0.25; 4]
            };
            let direction = rays
                .iter()
                .zip(alphas)
                .fold(nalgebra::Vector3::zeros(), |acc, (r, a)| acc + r * a);
            let depth_m = min_depth_m + (max_depth_m - min_depth_m) * rng.random::<f64>();
            world_from_camera * Point3::from(direction * depth_m)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::localization::cone::{BoxCone, projects_inside};
    use nalgebra::{Translation3, UnitQuaternion, Vector3};
    use rand::SeedableRng;
    use rand::rngs::Xoshiro256PlusPlus;

    #[test]
    fn points_lie_in_the_cone_and_depth_range() {
        let cam = PinholeCamera::from_hfov(640, 480, 80.0).unwrap();
        let world_from_camera = Isometry3::from_parts(
            Translation3::new(5.0, -3.0, 20.0),
            UnitQuaternion::from_scaled_axis(Vector3::new(2.0, 0.3, -0.5)),
        );
        let bbox = BoundingBox::new(120.0, 80.0, 180.0, 160.0).unwrap();
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(3);
        let pts = generate_points(&cam, &world_from_camera, &bbox, 5000, 3.0, 18.0, &mut rng);
        assert_eq!(pts.len(), 5000);
        let camera_from_world = world_from_camera.inverse();
        let cone = BoxCone::new(&cam, &bbox);
        let mut depths = Vec::new();
        for p in &pts {
            let q = camera_from_world * p;
            assert!((3.0 - 1e-9..=18.0 + 1e-9).contains(&q.z), "depth {}", q.z);
            // On or inside the box (a combination can touch an edge only with α = 0).
            let px = cam.project(&q).unwrap();
            assert!(px.x >= 120.0 - 1e-6 && px.x <= 180.0 + 1e-6, "{px}");
            assert!(px.y >= 80.0 - 1e-6 && px.y <= 160.0 + 1e-6, "{px}");
            assert!(cone.contains(&q));
            assert!(projects_inside(&cam, &bbox, &q));
            depths.push(q.z);
        }
        // Depths spread over the whole range.
        let lo = depths.iter().cloned().fold(f64::INFINITY, f64::min);
        let hi = depths.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
        assert!(lo < 3.1 && hi > 17.9, "{lo} {hi}");
    }

    #[test]
    fn same_seed_same_points() {
        let cam = PinholeCamera::from_hfov(640, 480, 80.0).unwrap();
        let bbox = BoundingBox::new(10.0, 10.0, 50.0, 40.0).unwrap();
        let draw = |seed| {
            let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
            generate_points(
                &cam,
                &Isometry3::identity(),
                &bbox,
                100,
                3.0,
                18.0,
                &mut rng,
            )
        };
        assert_eq!(draw(1), draw(1));
        assert_ne!(draw(1), draw(2));
    }
}
