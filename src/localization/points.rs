//! Point generation in a box's back-projected cone (paper Algorithm 2).

use nalgebra::{Isometry3, Point3};
use rand::RngExt;
use scarp_slam::PinholeCamera;
use scarp_slam::image::DepthImage;
use scarp_slam::stats::quantile_in_place;

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

/// Samples per side of the grid over a box from which [`measured_depth_range`] reads depth.
const DEPTH_GRID: u32 = 17;

/// The fewest valid depth samples [`measured_depth_range`] trusts.
const MIN_DEPTH_SAMPLES: usize = 8;

/// Where along camera z (m) a target seen in `bbox` can lie, by the frame's measured depth
/// (`depth_m`: metres along camera z, 0 where nothing was measured, `camera`'s size): from the
/// 2nd percentile of the depths over the box less a pad, to their 98th percentile plus the pad,
/// the pad being half the box's larger side at the median depth. The near end is at least
/// `min_depth_m`.
///
/// Why (ours, not the paper's Algorithm 2, which draws over a fixed range): the box holds the
/// rock's visible surface and what lies around and behind it, so the rock's centroid is no
/// nearer than the nearest of those depths less its own half-size, and no farther than the
/// farthest plus it. Drawn over the fixed 3–18 m instead, points of a rock first boxed at 17 m
/// are born almost all between the camera and the rock, above it; the box likelihood is too
/// flat to move them out, and the centre kept that history (0.33–0.47 m high on every rock of
/// the default world with an exact state estimate, session 37).
///
/// `None` (use the fixed range) when fewer than 8 of the 17 × 17 samples hold a depth.
pub fn measured_depth_range(
    camera: &PinholeCamera,
    depth_m: &DepthImage,
    bbox: &BoundingBox,
    min_depth_m: f64,
) -> Option<(f64, f64)> {
    let last = f64::from(DEPTH_GRID - 1);
    let mut depths_m: Vec<f64> = (0..DEPTH_GRID * DEPTH_GRID)
        .filter_map(|k| {
            let u = bbox.x_min + bbox.width() * f64::from(k % DEPTH_GRID) / last;
            let v = bbox.y_min + bbox.height() * f64::from(k / DEPTH_GRID) / last;
            let (u, v) = (u.round(), v.round());
            if u < 0.0 || v < 0.0 {
                return None;
            }
            let d = f64::from(*depth_m.get(u as u32, v as u32)?);
            (d.is_finite() && d > 0.0).then_some(d)
        })
        .collect();
    if depths_m.len() < MIN_DEPTH_SAMPLES {
        return None;
    }
    let mut quantile = |q: f64| quantile_in_place(&mut depths_m, q);
    let half_size_m = 0.5
        * quantile(0.5)?
        * (bbox.width() / camera.fx.abs()).max(bbox.height() / camera.fy.abs());
    let near_m = (quantile(0.02)? - half_size_m).max(min_depth_m);
    let far_m = quantile(0.98)? + half_size_m;
    (far_m > near_m).then_some((near_m, far_m))
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

    #[test]
    fn measured_range_brackets_a_plane_and_its_pad() {
        let cam = PinholeCamera::from_hfov(640, 480, 80.0).unwrap();
        let depth = DepthImage::filled(640, 480, 10.0);
        let bbox = BoundingBox::new(300.0, 200.0, 340.0, 260.0).unwrap();
        let (near, far) = measured_depth_range(&cam, &depth, &bbox, 3.0).unwrap();
        // Half of the box's larger side (60 px) at 10 m.
        let pad = 0.5 * 10.0 * 60.0 / cam.fy.abs();
        assert!((near - (10.0 - pad)).abs() < 1e-9, "{near}");
        assert!((far - (10.0 + pad)).abs() < 1e-9, "{far}");
        // The near end never comes closer than the configured minimum.
        let near_wall = DepthImage::filled(640, 480, 3.2);
        let (near, _) = measured_depth_range(&cam, &near_wall, &bbox, 3.0).unwrap();
        assert_eq!(near, 3.0);
    }

    #[test]
    fn measured_range_spans_a_rock_and_the_ground_behind_it() {
        // Left half of the box at 12 m (the rock), right half at 15 m (ground behind), and a
        // hole of missing depth: the range holds both surfaces and ignores the hole.
        let cam = PinholeCamera::from_hfov(640, 480, 80.0).unwrap();
        let mut depth = DepthImage::filled(640, 480, 15.0);
        for v in 0..480 {
            for u in 0..320 {
                *depth.get_mut(u, v).unwrap() = if (250..255).contains(&v) { 0.0 } else { 12.0 };
            }
        }
        let bbox = BoundingBox::new(280.0, 220.0, 360.0, 280.0).unwrap();
        let (near, far) = measured_depth_range(&cam, &depth, &bbox, 3.0).unwrap();
        assert!(near < 12.0 && near > 10.0, "{near}");
        assert!(far > 15.0 && far < 17.0, "{far}");
    }

    #[test]
    fn measured_range_needs_depth() {
        let cam = PinholeCamera::from_hfov(640, 480, 80.0).unwrap();
        let bbox = BoundingBox::new(300.0, 200.0, 340.0, 260.0).unwrap();
        let empty = DepthImage::filled(640, 480, 0.0);
        assert_eq!(measured_depth_range(&cam, &empty, &bbox, 3.0), None);
        let nan = DepthImage::filled(640, 480, f32::NAN);
        assert_eq!(measured_depth_range(&cam, &nan, &bbox, 3.0), None);
        // A box hanging off the image reads only its inside.
        let depth = DepthImage::filled(640, 480, 8.0);
        let edge = BoundingBox::new(-20.0, -20.0, 30.0, 30.0).unwrap();
        let (near, far) = measured_depth_range(&cam, &depth, &edge, 3.0).unwrap();
        assert!(near < 8.0 && far > 8.0);
    }
}
