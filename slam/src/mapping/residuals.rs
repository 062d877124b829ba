//! How well landmark observations agree with a set of poses: each landmark is re-triangulated
//! from its pixels with the poses held fixed, and the reprojection residuals are summarised.
//!
//! Against the true poses of a synthetic sequence this measures the observations themselves
//! (KLT noise and bias), independently of the odometry and of the bundle adjustment; against
//! the refined poses it is the adjustment's own fit.
//!
//! [`odometry_nees`] asks the same of the odometry's covariances: how large its keyframe-to-
//! keyframe errors are against the true poses, in units of the σ it claims.

use nalgebra::{Isometry3, Matrix3, Matrix6, Point2, Point3, Vector2, Vector3};
use serde::{Deserialize, Serialize};

use super::landmarks::Landmarks;
use crate::PinholeCamera;
use crate::ba::keyframe::pose_error;
use crate::ba::{KeyframeNoise, KeyframeObservation};

/// Summary of [`reprojection_stats`]. Pixels throughout.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct ReprojectionStats {
    /// Landmarks that could be triangulated (at least two observations in front of the
    /// cameras, a depth on the first one).
    pub landmarks: usize,
    /// Their observations.
    pub observations: usize,
    /// Root mean square of the residual norms, px.
    pub rms_px: f64,
    /// Median residual norm, px.
    pub median_px: f64,
    /// 90th percentile of the residual norms, px.
    pub p90_px: f64,
    /// Mean number of observations per landmark.
    pub mean_track_length: f64,
}

/// The median of a χ² distribution with 6 degrees of freedom: the median NEES of a 6-DoF pose
/// error whose covariance is calibrated.
pub const CHI2_6_MEDIAN: f64 = 5.348;

/// The normalized estimation error squared of every consecutive keyframe motion the odometry
/// measured: e^T Σ^-1 e, with e the right perturbation (translation m, rotation rad) that takes
/// the true `camera_{k-1}_from_camera_k` to the odometry's, and Σ the odometry's covariance of
/// it (`covariance[k]`, as [`super::KeyframeSet::odometry_covariance`]). Entry k - 1 of the
/// result is keyframe k's; pairs without a covariance, or with one that is not invertible, give
/// `None`.
///
/// A calibrated covariance gives a mean of 6 (the degrees of freedom); a mean of 60 says the
/// odometry claims ten times the information it has, which is what
/// [`super::RefineConfig::odometry_information_scale`] corrects.
///
/// # Panics
/// Never; lists of different lengths are read up to the shortest.
pub fn odometry_nees(
    odometry: &[Isometry3<f64>],
    truth: &[Isometry3<f64>],
    covariance: &[Option<Matrix6<f64>>],
) -> Vec<Option<f64>> {
    let n = odometry.len().min(truth.len()).min(covariance.len());
    (1..n)
        .map(|k| {
            let information = covariance[k]?.try_inverse()?;
            let measured = odometry[k - 1].inverse() * odometry[k];
            let true_motion = truth[k - 1].inverse() * truth[k];
            let e = pose_error(&true_motion, &measured);
            let nees = (e.transpose() * information * e)[(0, 0)];
            nees.is_finite().then_some(nees)
        })
        .collect()
}

/// Gauss–Newton on a 3D point (world metres) that minimises the residuals of `observations`
/// (their `camera`, `pixel` and, with `noise`, `depth_m`; `point` is ignored) with
/// `world_from_camera` fixed, from `initial`. Without `noise` only the pixels count; with it
/// pixels and depths are whitened by its σs. Returns `None` when an observation names a missing
/// camera, the point falls behind a camera or the normal equations are singular (fewer than
/// two distinct views and no depth).
pub fn triangulate_point(
    camera: &PinholeCamera,
    world_from_camera: &[Isometry3<f64>],
    observations: &[KeyframeObservation],
    noise: Option<&KeyframeNoise>,
    initial: &Vector3<f64>,
    iterations: usize,
) -> Option<Vector3<f64>> {
    let mut x = *initial;
    let (pixel_weight, depth_weight) = match noise {
        Some(n) => (
            1.0 / (n.pixel_sigma_px * n.pixel_sigma_px),
            1.0 / (n.depth_sigma_m * n.depth_sigma_m),
        ),
        None => (1.0, 0.0),
    };
    for _ in 0..iterations {
        let mut h = Matrix3::zeros();
        let mut g = Vector3::zeros();
        for o in observations {
            let pose = world_from_camera.get(o.camera)?;
            let rotation_t = pose.rotation.to_rotation_matrix().matrix().transpose();
            let p = rotation_t * (x - pose.translation.vector);
            if !(p.z > 1e-6) {
                return None;
            }
            let inv_z = 1.0 / p.z;
            let r = Vector2::new(
                camera.fx * p.x * inv_z + camera.cx - o.pixel.x,
                camera.fy * p.y * inv_z + camera.cy - o.pixel.y,
            );
            let d_r_d_p = nalgebra::Matrix2x3::new(
                camera.fx * inv_z,
                0.0,
                -camera.fx * p.x * inv_z * inv_z,
                0.0,
                camera.fy * inv_z,
                -camera.fy * p.y * inv_z * inv_z,
            );
            let j = d_r_d_p * rotation_t;
            h += j.transpose() * j * pixel_weight;
            g += j.transpose() * r * pixel_weight;
            if let Some(depth) = o.depth_m.filter(|_| depth_weight > 0.0) {
                // d(p.z)/dx is the third row of Rᵀ.
                let j_depth = rotation_t.row(2).transpose();
                h += j_depth * j_depth.transpose() * depth_weight;
                g += j_depth * (p.z - depth) * depth_weight;
            }
        }
        let step = h.cholesky()?.solve(&g);
        x -= step;
        if !x.iter().all(|v| v.is_finite()) {
            return None;
        }
        if step.norm() < 1e-9 {
            break;
        }
    }
    Some(x)
}

/// Re-triangulates every landmark with `world_from_camera` fixed (starting from its first
/// observation's depth back-projected through that pose) and summarises the reprojection
/// residuals of all its observations. Landmarks without a depth on the first observation or
/// with fewer than two observations are skipped; an empty result has zero statistics.
pub fn reprojection_stats(
    camera: &PinholeCamera,
    world_from_camera: &[Isometry3<f64>],
    landmarks: &Landmarks,
) -> ReprojectionStats {
    let mut residuals = Vec::new();
    let mut count = 0;
    for group in landmarks.observations.chunk_by(|a, b| a.point == b.point) {
        let Some((first_pose, first_depth)) = group
            .first()
            .and_then(|o| Some((world_from_camera.get(o.camera)?, o.depth_m?)))
        else {
            continue;
        };
        if group.len() < 2 {
            continue;
        }
        let initial = first_pose * camera.unproject(&Point2::from(group[0].pixel), first_depth);
        let Some(point) =
            triangulate_point(camera, world_from_camera, group, None, &initial.coords, 10)
        else {
            continue;
        };
        count += 1;
        for o in group {
            let p = world_from_camera[o.camera].inverse_transform_point(&Point3::from(point));
            if let Some(projected) = camera.project(&p) {
                residuals.push((projected.coords - o.pixel).norm());
            }
        }
    }
    summarise(count, residuals)
}

fn summarise(landmarks: usize, mut residuals: Vec<f64>) -> ReprojectionStats {
    if residuals.is_empty() {
        return ReprojectionStats::default();
    }
    residuals.sort_by(f64::total_cmp);
    let n = residuals.len();
    let at = |q: f64| residuals[((n - 1) as f64 * q).round() as usize];
    ReprojectionStats {
        landmarks,
        observations: n,
        rms_px: (residuals.iter().map(|r| r * r).sum::<f64>() / n as f64).sqrt(),
        median_px: at(0.5),
        p90_px: at(0.9),
        mean_track_length: n as f64 / landmarks.max(1) as f64,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::look_at;

    /// Motions wrong by exactly what their covariance claims give a median NEES near χ²₆'s
    /// (5.35); the same errors under a covariance claiming 10× the information give 10× that.
    #[test]
    fn the_odometrys_nees_measures_its_covariance() {
        use nalgebra::Vector6;
        use rand::SeedableRng;
        use rand_distr::{Distribution, StandardNormal};
        let mut rng = rand::rngs::Xoshiro256PlusPlus::seed_from_u64(3);
        let mut normal = || -> f64 { StandardNormal.sample(&mut rng) };
        let sigma = Vector6::new(0.002, 0.001, 0.003, 0.001, 0.002, 0.0005);
        let covariance = Matrix6::from_diagonal(&sigma.component_mul(&sigma));
        let mut truth = vec![Isometry3::identity()];
        let mut odometry = vec![Isometry3::identity()];
        for k in 1..801usize {
            let step = Isometry3::new(
                Vector3::new(0.3, 0.02 * (k % 3) as f64, 0.0),
                Vector3::new(0.0, 0.0, 0.05),
            );
            let e = Vector6::from_fn(|i, _| sigma[i] * normal());
            let error = Isometry3::new(
                Vector3::new(e[0], e[1], e[2]),
                Vector3::new(e[3], e[4], e[5]),
            );
            truth.push(truth[k - 1] * step);
            odometry.push(odometry[k - 1] * step * error);
        }
        let median = |covariance: Matrix6<f64>| {
            let mut nees: Vec<f64> = odometry_nees(&odometry, &truth, &vec![Some(covariance); 801])
                .into_iter()
                .map(Option::unwrap)
                .collect();
            nees.sort_by(f64::total_cmp);
            nees[nees.len() / 2]
        };
        let calibrated = median(covariance);
        assert!((4.6..6.2).contains(&calibrated), "median NEES {calibrated}");
        let overconfident = median(covariance * 0.1);
        assert!((overconfident / calibrated - 10.0).abs() < 1e-6);
        // A pair without a covariance has no NEES.
        assert_eq!(
            odometry_nees(&odometry[..2], &truth[..2], &[None, None]),
            vec![None]
        );
    }

    #[test]
    fn exact_observations_have_zero_residual_and_noisy_ones_do_not() {
        let camera = PinholeCamera::from_hfov(640, 480, 80.0).unwrap();
        let poses: Vec<_> = (0..4)
            .map(|i| {
                let a = f64::from(i) * 0.15;
                look_at(
                    &Point3::new(4.0 * a.cos(), 4.0 * a.sin(), 2.0),
                    &Point3::origin(),
                    &Vector3::z(),
                )
                .unwrap()
            })
            .collect();
        let point = Vector3::new(0.1, -0.2, 0.3);
        let mut landmarks = Landmarks {
            points: vec![point],
            observations: Vec::new(),
        };
        for (k, pose) in poses.iter().enumerate() {
            let p = pose.inverse_transform_point(&Point3::from(point));
            landmarks.observations.push(KeyframeObservation {
                camera: k,
                point: 0,
                pixel: camera.project(&p).unwrap().coords,
                // A wrong depth only moves the starting point.
                depth_m: Some(p.z + 0.05),
            });
        }
        let stats = reprojection_stats(&camera, &poses, &landmarks);
        assert_eq!((stats.landmarks, stats.observations), (1, 4));
        assert!(stats.rms_px < 1e-6, "{stats:?}");
        landmarks.observations[2].pixel.x += 2.0;
        let stats = reprojection_stats(&camera, &poses, &landmarks);
        assert!(stats.rms_px > 0.5 && stats.p90_px > 1.0, "{stats:?}");
    }

    #[test]
    fn single_views_are_skipped() {
        let camera = PinholeCamera::from_hfov(640, 480, 80.0).unwrap();
        let landmarks = Landmarks {
            points: vec![Vector3::new(0.0, 0.0, 4.0)],
            observations: vec![KeyframeObservation {
                camera: 0,
                point: 0,
                pixel: Vector2::new(320.0, 240.0),
                depth_m: Some(4.0),
            }],
        };
        let stats = reprojection_stats(&camera, &[Isometry3::identity()], &landmarks);
        assert_eq!(stats, ReprojectionStats::default());
    }
}
