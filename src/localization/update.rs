//! The point update (paper Algorithm 3 with DESIGN.md's fix): noise every point, weight the
//! noised points by where they project with respect to the box (and, when the frame has depth,
//! by whether the depth leaves them possible: [`super::free_space`]), and resample those same
//! noised points with low-variance (systematic) resampling.

use nalgebra::{Isometry3, Point2, Point3, Vector3};
use rand::RngExt;
use rand_distr::{Distribution, StandardNormal};
use scarp_slam::PinholeCamera;

use super::free_space::FreeSpace;
use crate::detection::BoundingBox;

/// The mixture weights of the point update.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoxLikelihood {
    /// The tracked box, px.
    pub bbox: BoundingBox,
    /// The box enlarged by the configured margin, px (support of the uniform part).
    pub enlarged: BoundingBox,
    /// Weight w1 of the Gaussian part.
    pub gaussian_weight: f64,
    /// Weight w2 of the uniform part.
    pub uniform_weight: f64,
}

impl BoxLikelihood {
    /// f(p | x) = w1 · N(p; c_x, diag((w/2)², (h/2)²)) + w2 · U(p; enlarged box), a density
    /// over pixels (px⁻²). The box must have positive area.
    pub fn density(&self, pixel: &Point2<f64>) -> f64 {
        let (cx, cy) = self.bbox.center();
        let sx = 0.5 * self.bbox.width();
        let sy = 0.5 * self.bbox.height();
        let dx = (pixel.x - cx) / sx;
        let dy = (pixel.y - cy) / sy;
        let gaussian = (-0.5 * (dx * dx + dy * dy)).exp() / (2.0 * std::f64::consts::PI * sx * sy);
        let e = &self.enlarged;
        let inside =
            pixel.x >= e.x_min && pixel.x <= e.x_max && pixel.y >= e.y_min && pixel.y <= e.y_max;
        let uniform = if inside { 1.0 / e.area() } else { 0.0 };
        self.gaussian_weight * gaussian + self.uniform_weight * uniform
    }
}

/// Low-variance (systematic) resampling: `count` indices drawn in proportion to `weights` with
/// a single uniform offset. Returns `None` when the weights sum to zero or are not finite.
pub fn low_variance_resample<R: rand::Rng + ?Sized>(
    weights: &[f64],
    count: usize,
    rng: &mut R,
) -> Option<Vec<usize>> {
    let total: f64 = weights.iter().sum();
    if !(total > 0.0 && total.is_finite()) || weights.is_empty() {
        return None;
    }
    let step = total / count as f64;
    let mut target = rng.random::<f64>() * step;
    let mut cumulative = weights[0];
    let mut i = 0;
    let mut picks = Vec::with_capacity(count);
    for _ in 0..count {
        while target > cumulative && i + 1 < weights.len() {
            i += 1;
            cumulative += weights[i];
        }
        picks.push(i);
        target += step;
    }
    Some(picks)
}

/// One update of a target's `points` (world, m) with a box seen by `camera` at
/// `world_from_camera`: every point gets isotropic Gaussian noise of `noise_sigma_m`, the noised
/// points are weighted by `likelihood` at their projections (zero behind the camera) times the
/// depth's factor when `free_space` is given, and `points.len()` of those noised points are
/// resampled by weight.
///
/// Returns `None`, leaving nothing changed for the caller, when no noised point has any weight
/// (the box and the points disagree completely).
pub fn update_points<R: rand::Rng + ?Sized>(
    points: &[Point3<f64>],
    camera: &PinholeCamera,
    world_from_camera: &Isometry3<f64>,
    likelihood: &BoxLikelihood,
    free_space: Option<&FreeSpace<'_>>,
    noise_sigma_m: f64,
    rng: &mut R,
) -> Option<Vec<Point3<f64>>> {
    let camera_from_world = world_from_camera.inverse();
    let mut noised = Vec::with_capacity(points.len());
    let mut weights = Vec::with_capacity(points.len());
    for p in points {
        let noise = Vector3::new(
            StandardNormal.sample(rng),
            StandardNormal.sample(rng),
            StandardNormal.sample(rng),
        ) * noise_sigma_m;
        let q = p + noise;
        let weight = camera.project(&(camera_from_world * q)).map_or(0.0, |px| {
            likelihood.density(&px) * free_space.map_or(1.0, |f| f.factor(&q, &px))
        });
        noised.push(q);
        weights.push(weight);
    }
    let picks = low_variance_resample(&weights, points.len(), rng)?;
    Some(picks.into_iter().map(|i| noised[i]).collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand::rngs::Xoshiro256PlusPlus;

    #[test]
    fn resampling_is_deterministic_and_proportional() {
        let weights = [1.0, 0.0, 3.0, 0.0];
        let draw = |seed| {
            let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
            low_variance_resample(&weights, 400, &mut rng).unwrap()
        };
        let a = draw(9);
        assert_eq!(a, draw(9));
        let zeros = a.iter().filter(|&&i| i == 0).count();
        let twos = a.iter().filter(|&&i| i == 2).count();
        assert_eq!(zeros + twos, 400);
        // Systematic resampling is exact to within one draw.
        assert!((zeros as i64 - 100).abs() <= 1, "{zeros}");
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(0);
        assert!(low_variance_resample(&[0.0, 0.0], 3, &mut rng).is_none());
        assert!(low_variance_resample(&[f64::NAN], 3, &mut rng).is_none());
    }

    #[test]
    fn density_prefers_the_box_and_vanishes_far_outside() {
        let bbox = BoundingBox::new(100.0, 100.0, 140.0, 120.0).unwrap();
        let l = BoxLikelihood {
            bbox,
            enlarged: bbox.enlarged(30.0),
            gaussian_weight: 0.2,
            uniform_weight: 0.8,
        };
        let centre = l.density(&Point2::new(120.0, 110.0));
        let edge = l.density(&Point2::new(165.0, 110.0));
        let far = l.density(&Point2::new(400.0, 400.0));
        assert!(centre > edge && edge > far);
        assert!(far < 1e-12);
    }

    #[test]
    fn update_pulls_points_into_the_box_and_repeats_with_a_seed() {
        let cam = PinholeCamera::from_hfov(640, 480, 80.0).unwrap();
        // Points spread along x from −5 to 5 m at z = 10; the box covers the middle.
        let points: Vec<_> = (0..2000)
            .map(|i| Point3::new(-5.0 + 10.0 * i as f64 / 1999.0, 0.0, 10.0))
            .collect();
        let bbox = BoundingBox::new(300.0, 220.0, 340.0, 260.0).unwrap();
        let l = BoxLikelihood {
            bbox,
            enlarged: bbox.enlarged(30.0),
            gaussian_weight: 0.2,
            uniform_weight: 0.8,
        };
        let run = |seed| {
            let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
            update_points(
                &points,
                &cam,
                &Isometry3::identity(),
                &l,
                None,
                0.1,
                &mut rng,
            )
            .unwrap()
        };
        let out = run(4);
        assert_eq!(out, run(4));
        assert_eq!(out.len(), 2000);
        // Enlarged box spans u ∈ [270, 370]: x/z ∈ [−0.19, 0.23] → |x| < 2.5 m.
        assert!(out.iter().all(|p| p.x.abs() < 2.5), "points outside");
        // A box nowhere near any point: no update.
        let off = BoundingBox::new(0.0, 0.0, 10.0, 10.0).unwrap();
        let l_off = BoxLikelihood {
            bbox: off,
            enlarged: off,
            gaussian_weight: 0.0,
            uniform_weight: 1.0,
        };
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(1);
        assert!(
            update_points(
                &points,
                &cam,
                &Isometry3::identity(),
                &l_off,
                None,
                0.1,
                &mut rng
            )
            .is_none()
        );
    }
}
