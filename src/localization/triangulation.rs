//! The point nearest the central rays of a target's keyframe boxes: where the views agree the
//! object's middle is, with no depth and no particles.
//!
//! Each keyframe's box says the object's middle lies on the ray through the box centre. The
//! depth filter's points carry that evidence too, but their mean also carries the filter's
//! history: the cone a target was born in, the noise added at each update, the resampling.
//! Replayed on a default-world flight (seed 60) with the true poses and clean images, the
//! filter's mean stood 0.51, 0.33 and 0.09 m above the three targets' centroids while the point
//! nearest the same keyframes' rays was within 0.05 m of each (session 49,
//! `docs/campaigns/2026-11-30-session49-localization-height.md`).

use nalgebra::{Isometry3, Matrix3, Point2, Point3, SymmetricEigen, Unit, Vector3};
use scarp_slam::PinholeCamera;
use scarp_slam::ba::RobustLoss;

use crate::detection::BoundingBox;

/// A ray from a camera through the centre of a box, world frame (ENU, metres).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoxRay {
    /// The camera centre, m.
    pub origin: Point3<f64>,
    /// The direction through the box centre.
    pub direction: Unit<Vector3<f64>>,
}

impl BoxRay {
    /// The ray through `bbox`'s centre seen by `camera` at `world_from_camera`.
    pub fn through_box_center(
        camera: &PinholeCamera,
        world_from_camera: &Isometry3<f64>,
        bbox: &BoundingBox,
    ) -> Self {
        let (u, v) = bbox.center();
        let in_camera = camera.unproject(&Point2::new(u, v), 1.0).coords;
        Self {
            origin: Point3::from(world_from_camera.translation.vector),
            direction: Unit::new_normalize(world_from_camera.rotation * in_camera),
        }
    }

    /// The projector onto the plane across the ray: `I − d dᵀ`.
    fn across(&self) -> Matrix3<f64> {
        Matrix3::identity() - self.direction.into_inner() * self.direction.transpose()
    }

    /// Distance from `point` to the ray's line, m.
    pub fn distance_m(&self, point: &Point3<f64>) -> f64 {
        (self.across() * (point - self.origin)).norm()
    }
}

/// Fewest rays [`nearest_point`] solves with.
const MIN_RAYS: usize = 3;

/// Reweighting rounds of [`nearest_point`].
const ROUNDS: usize = 5;

/// A ray farther from the solution than this many robust scales of the rays' distances is
/// down-weighted in proportion (the Huber weight of [`RobustLoss`]).
const HUBER_SCALES: f64 = 2.0;

/// The smallest robust scale of the rays' distances, m: about the detector's box jitter (σ 4 px)
/// at the fine-localization circle's 12–15 m, so that rays agreeing better than the boxes can
/// are not told apart.
const MIN_SCALE_M: f64 = 0.05;

/// The point nearest `rays` in the least-squares sense, with robust reweighting (a ray whose
/// box was on the wrong object, or a box cut by the image border, counts less); world frame,
/// metres. `None` with fewer than 3 rays, or when their directions spread too little to place
/// the point along them: the smallest eigenvalue of the mean `I − d dᵀ` below
/// `min_spread` (0.067 for two rays 30° apart; 0 for parallel rays).
pub fn nearest_point(rays: &[BoxRay], min_spread: f64) -> Option<Point3<f64>> {
    if rays.len() < MIN_RAYS {
        return None;
    }
    let mut weights = vec![1.0; rays.len()];
    let mut point = None;
    for _ in 0..ROUNDS {
        let (mut normal, mut rhs, mut total) = (Matrix3::zeros(), Vector3::zeros(), 0.0);
        for (ray, w) in rays.iter().zip(&weights) {
            let across = ray.across();
            normal += *w * across;
            rhs += *w * (across * ray.origin.coords);
            total += w;
        }
        let spread = SymmetricEigen::new(normal / total).eigenvalues.min();
        if !(spread >= min_spread) {
            return None;
        }
        let solved = Point3::from(normal.cholesky()?.solve(&rhs));
        let distances: Vec<f64> = rays.iter().map(|r| r.distance_m(&solved)).collect();
        let median = scarp_slam::stats::quantile_in_place(&mut distances.clone(), 0.5)?;
        // The loss's threshold is in the residual's units, here metres.
        let huber = RobustLoss::Huber {
            delta_px: HUBER_SCALES * (1.4826 * median).max(MIN_SCALE_M),
        };
        weights = distances.iter().map(|d| huber.weight(d * d)).collect();
        point = Some(solved);
    }
    point
}

/// How far around `center` the rays were seen from, degrees: 360° less the widest gap between
/// the azimuths of their origins about `center` (world ENU, horizontal). 0 with fewer than two
/// rays off the vertical through `center`.
///
/// Why it matters: the rays' meeting point is a weighted mean of where each view's position
/// error put the target, and a view looking down at a pitch moves it vertically by its
/// horizontal error toward the target times the tangent of that pitch. Views all round cancel
/// that; an arc of views does not, and the state estimate's walk over the arc's time is left in
/// the centre's height (session 64, `docs/campaigns/tools/ray_arc_sim.py`: views over 230° of
/// the circle left 13% of simulated centres over 0.5 m off in the estimate's frame, views all
/// round 6%).
pub fn view_arc_deg(rays: &[BoxRay], center: &Point3<f64>) -> f64 {
    span_deg(
        rays.iter()
            .map(|r| r.origin - center)
            .filter(|v| v.x.hypot(v.y) > 1e-6)
            .map(|v| v.y.atan2(v.x).to_degrees())
            .collect(),
    )
}

/// The arc that holds every angle of `bearings_deg`: 360° less the widest gap between
/// neighbours on the circle; 0 for fewer than two bearings.
pub(crate) fn span_deg(mut bearings_deg: Vec<f64>) -> f64 {
    if bearings_deg.len() < 2 {
        return 0.0;
    }
    for bearing in &mut bearings_deg {
        *bearing = bearing.rem_euclid(360.0);
    }
    bearings_deg.sort_by(f64::total_cmp);
    let wrap_gap = bearings_deg[0] + 360.0 - bearings_deg[bearings_deg.len() - 1];
    let widest = bearings_deg
        .windows(2)
        .map(|w| w[1] - w[0])
        .fold(wrap_gap, f64::max);
    360.0 - widest
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand::rngs::Xoshiro256PlusPlus;
    use rand_distr::{Distribution, Normal};

    /// Rays from a circle 10 m up and 7 m out around `target` (over `arc_deg`), each aimed
    /// `jitter_m` (σ, across the ray) off it.
    fn rays_around(target: &Point3<f64>, n: usize, arc_deg: f64, jitter_m: f64) -> Vec<BoxRay> {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(3);
        let normal = Normal::new(0.0, jitter_m.max(1e-12)).unwrap();
        (0..n)
            .map(|k| {
                let a = (k as f64 / n as f64 * arc_deg).to_radians();
                let origin = target + Vector3::new(7.0 * a.cos(), 7.0 * a.sin(), 10.0);
                let aim = target
                    + Vector3::new(
                        normal.sample(&mut rng),
                        normal.sample(&mut rng),
                        normal.sample(&mut rng),
                    );
                BoxRay {
                    origin,
                    direction: Unit::new_normalize(aim - origin),
                }
            })
            .collect()
    }

    #[test]
    fn rays_from_around_meet_at_their_target() {
        let target = Point3::new(3.0, -2.0, 0.7);
        let exact = nearest_point(&rays_around(&target, 12, 360.0, 0.0), 0.05).unwrap();
        assert!((exact - target).norm() < 1e-9, "{exact}");
        // Boxes jittered by 0.15 m across the ray (4 px at 14 m): 24 views place it within
        // 0.1 m.
        let jittered = nearest_point(&rays_around(&target, 24, 360.0, 0.15), 0.05).unwrap();
        assert!((jittered - target).norm() < 0.1, "{jittered}");
    }

    /// A box on another rock does not drag the point: its ray is down-weighted.
    #[test]
    fn a_ray_through_something_else_counts_less() {
        let target = Point3::new(3.0, -2.0, 0.7);
        let mut rays = rays_around(&target, 12, 360.0, 0.05);
        let origin = rays[0].origin;
        rays.push(BoxRay {
            origin,
            direction: Unit::new_normalize(target + Vector3::new(3.0, 0.0, 0.0) - origin),
        });
        // Unweighted, the thirteen rays would meet about 0.2 m towards the other rock.
        let robust = nearest_point(&rays, 0.05).unwrap();
        assert!((robust - target).norm() < 0.1, "{robust}");
    }

    /// Rays from one direction cannot say how far along them the object is.
    #[test]
    fn rays_that_spread_too_little_place_nothing() {
        let target = Point3::new(3.0, -2.0, 0.7);
        assert!(nearest_point(&rays_around(&target, 12, 10.0, 0.0), 0.05).is_none());
        assert!(nearest_point(&rays_around(&target, 12, 90.0, 0.0), 0.05).is_some());
        assert!(nearest_point(&rays_around(&target, 2, 360.0, 0.0), 0.05).is_none());
        assert!(nearest_point(&[], 0.05).is_none());
    }

    #[test]
    fn the_view_arc_is_the_circle_less_its_widest_gap() {
        let target = Point3::new(4.0, -2.0, 1.0);
        // 12 views over 360° leave 30° gaps; 12 over 180° span 165° (the last view at 165°).
        let all_round = view_arc_deg(&rays_around(&target, 12, 360.0, 0.0), &target);
        assert!((all_round - 330.0).abs() < 1e-9, "{all_round}");
        let half = view_arc_deg(&rays_around(&target, 12, 180.0, 0.0), &target);
        assert!((half - 165.0).abs() < 1e-9, "{half}");
        // Across the ±180° seam: views at 170°, −170° and −150° span 40°.
        let seam: Vec<BoxRay> = [170.0f64, -170.0, -150.0]
            .iter()
            .map(|a| BoxRay {
                origin: target + Vector3::new(a.to_radians().cos(), a.to_radians().sin(), 5.0),
                direction: Vector3::z_axis(),
            })
            .collect();
        assert!((view_arc_deg(&seam, &target) - 40.0).abs() < 1e-9);
        // One view, or views straight above the centre, span nothing.
        assert_eq!(view_arc_deg(&seam[..1], &target), 0.0);
        let above = BoxRay {
            origin: target + Vector3::new(0.0, 0.0, 9.0),
            direction: -Vector3::z_axis(),
        };
        assert_eq!(view_arc_deg(&[above, above, seam[0]], &target), 0.0);
    }
}
