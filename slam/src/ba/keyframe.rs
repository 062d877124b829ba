//! The mapping pipeline's bundle-adjustment problem: keyframe poses `world_from_camera`
//! (SE(3), f64) with fixed pinhole intrinsics, 3D landmarks in the world frame, and
//! - pixel reprojection residuals (OpenCV camera: x right, y down, z forward), whitened by
//!   `pixel_sigma_px`;
//! - optional RGBD depth residuals (camera z of the landmark minus the measured depth), whitened
//!   by `depth_sigma_m`;
//! - relative-pose priors (odometry) `camera_a_from_camera_b` with a 6×6 information matrix;
//! - absolute pose priors (GPS/IMU) `world_from_camera` with a 6×6 information matrix, which fix
//!   the gauge and keep the geo-reference.
//!
//! Pose errors are ordered (translation, rotation): for a prior with measured transform M and
//! estimate T, the error is E = M⁻¹·T written as (t_E, log R_E) (metres, radians), and its cost
//! is ½·eᵀ·Λ·e. The pose update is (δt, δφ): t ← t + δt (world frame), R ← R·exp(δφ).

use nalgebra::{Isometry3, Matrix3, Matrix6, SMatrix, SVector, UnitQuaternion, Vector2, Vector3};
use serde::{Deserialize, Serialize};

use super::error::BaError;
use super::problem::{CameraModel, Indexed, Linearization, PriorLinearization};
use super::snavely::skew;
use crate::geometry::PinholeCamera;

/// Local degrees of freedom of a keyframe pose: translation (3), rotation (3).
pub const POSE_DOF: usize = 6;

/// One keyframe's observation of a landmark: a pixel and, with RGBD, the measured depth.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KeyframeObservation {
    /// Index of the keyframe.
    pub camera: usize,
    /// Index of the landmark.
    pub point: usize,
    /// Measured pixel (u column, v row; pixel centres at integers).
    pub pixel: Vector2<f64>,
    /// Measured depth along the camera z axis, metres; `None` without a depth measurement.
    pub depth_m: Option<f64>,
}

impl Indexed for KeyframeObservation {
    fn camera(&self) -> usize {
        self.camera
    }
    fn point(&self) -> usize {
        self.point
    }
}

/// An absolute pose prior (GPS/IMU) on one keyframe.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AbsolutePosePrior {
    /// The keyframe.
    pub camera: usize,
    /// The measured pose.
    pub world_from_camera: Isometry3<f64>,
    /// Information (inverse covariance) of the error (translation m, rotation rad); symmetric
    /// positive definite.
    pub information: Matrix6<f64>,
}

/// A relative pose prior (odometry) between two keyframes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RelativePosePrior {
    /// The first keyframe.
    pub camera_a: usize,
    /// The second keyframe (distinct from `camera_a`).
    pub camera_b: usize,
    /// The measured motion: maps camera-b coordinates to camera-a coordinates.
    pub camera_a_from_camera_b: Isometry3<f64>,
    /// Information of the error (translation m, rotation rad); symmetric positive definite.
    pub information: Matrix6<f64>,
}

/// Measurement noise of the keyframe problem.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct KeyframeNoise {
    /// Standard deviation of a pixel measurement, pixels. Default 1.0.
    pub pixel_sigma_px: f64,
    /// Standard deviation of a depth measurement, metres. Default 0.02.
    pub depth_sigma_m: f64,
}

impl Default for KeyframeNoise {
    fn default() -> Self {
        Self {
            pixel_sigma_px: 1.0,
            depth_sigma_m: 0.02,
        }
    }
}

/// The keyframe bundle-adjustment model: fixed intrinsics, noise and pose priors. Solve it with
/// [`crate::ba::solve`] over `world_from_camera` poses and world landmarks.
#[derive(Debug, Clone)]
pub struct KeyframeModel {
    intrinsics: PinholeCamera,
    noise: KeyframeNoise,
    absolute: Vec<AbsolutePosePrior>,
    relative: Vec<RelativePosePrior>,
    /// Lᵀ with Λ = L·Lᵀ, per absolute then relative prior.
    sqrt_information: Vec<Matrix6<f64>>,
}

/// Lᵀ of the Cholesky factor of an information matrix, or an error naming the prior.
fn sqrt_information(information: &Matrix6<f64>, what: &str) -> Result<Matrix6<f64>, BaError> {
    let symmetric = (information - information.transpose()).amax()
        <= 1e-9 * information.amax().max(f64::MIN_POSITIVE);
    if !information.iter().all(|v| v.is_finite()) || !symmetric {
        return Err(BaError::InvalidProblem {
            reason: format!("{what}: the information matrix must be finite and symmetric"),
        });
    }
    nalgebra::Cholesky::new(*information)
        .map(|c| c.l().transpose())
        .ok_or_else(|| BaError::InvalidProblem {
            reason: format!("{what}: the information matrix is not positive definite"),
        })
}

/// Inverse of the right Jacobian of SO(3) at rotation vector `theta`.
fn right_jacobian_inverse(theta: &Vector3<f64>) -> Matrix3<f64> {
    let angle = theta.norm();
    let k = skew(theta);
    let coefficient = if angle < 1e-6 {
        1.0 / 12.0
    } else {
        1.0 / (angle * angle) - (1.0 + angle.cos()) / (2.0 * angle * angle.sin())
    };
    Matrix3::identity() + k * 0.5 + k * k * coefficient
}

/// The error (t_E, log R_E) of E = measured⁻¹·estimate: the right perturbation (translation m,
/// rotation rad) that takes `measured` to `estimate`, as the pose priors whiten it.
pub(crate) fn pose_error(measured: &Isometry3<f64>, estimate: &Isometry3<f64>) -> SVector<f64, 6> {
    let e = measured.inverse() * estimate;
    let mut out = SVector::<f64, 6>::zeros();
    out.fixed_rows_mut::<3>(0).copy_from(&e.translation.vector);
    out.fixed_rows_mut::<3>(3)
        .copy_from(&e.rotation.scaled_axis());
    out
}

impl KeyframeModel {
    /// Builds the model.
    ///
    /// # Errors
    /// [`BaError::InvalidProblem`] if a noise value is not positive and finite, a prior's
    /// transform is not finite, or its information matrix is not symmetric positive definite.
    /// Camera indices are checked by the solver.
    pub fn new(
        intrinsics: PinholeCamera,
        noise: KeyframeNoise,
        absolute: Vec<AbsolutePosePrior>,
        relative: Vec<RelativePosePrior>,
    ) -> Result<Self, BaError> {
        for (field, value) in [
            ("pixel_sigma_px", noise.pixel_sigma_px),
            ("depth_sigma_m", noise.depth_sigma_m),
        ] {
            if !(value.is_finite() && value > 0.0) {
                return Err(BaError::InvalidProblem {
                    reason: format!("noise `{field}` = {value} must be positive and finite"),
                });
            }
        }
        let mut sqrt = Vec::with_capacity(absolute.len() + relative.len());
        for (k, prior) in absolute.iter().enumerate() {
            if !finite_isometry(&prior.world_from_camera) {
                return Err(BaError::InvalidProblem {
                    reason: format!("absolute prior {k}: world_from_camera is not finite"),
                });
            }
            sqrt.push(sqrt_information(
                &prior.information,
                &format!("absolute prior {k}"),
            )?);
        }
        for (k, prior) in relative.iter().enumerate() {
            if !finite_isometry(&prior.camera_a_from_camera_b) {
                return Err(BaError::InvalidProblem {
                    reason: format!("relative prior {k}: camera_a_from_camera_b is not finite"),
                });
            }
            sqrt.push(sqrt_information(
                &prior.information,
                &format!("relative prior {k}"),
            )?);
        }
        Ok(Self {
            intrinsics,
            noise,
            absolute,
            relative,
            sqrt_information: sqrt,
        })
    }

    /// The landmark in camera coordinates.
    fn in_camera(world_from_camera: &Isometry3<f64>, point: &Vector3<f64>) -> Vector3<f64> {
        world_from_camera
            .rotation
            .inverse_transform_vector(&(point - world_from_camera.translation.vector))
    }
}

fn finite_isometry(t: &Isometry3<f64>) -> bool {
    t.translation.vector.iter().all(|v| v.is_finite())
        && t.rotation.coords.iter().all(|v| v.is_finite())
}

impl CameraModel<POSE_DOF, 3> for KeyframeModel {
    type Camera = Isometry3<f64>;
    type Observation = KeyframeObservation;

    fn residual(
        &self,
        world_from_camera: &Isometry3<f64>,
        point: &Vector3<f64>,
        observation: &KeyframeObservation,
    ) -> SVector<f64, 3> {
        let p = Self::in_camera(world_from_camera, point);
        let k = &self.intrinsics;
        let u = k.fx * p.x / p.z + k.cx;
        let v = k.fy * p.y / p.z + k.cy;
        let depth = match observation.depth_m {
            Some(d) => (p.z - d) / self.noise.depth_sigma_m,
            None => 0.0,
        };
        SVector::<f64, 3>::new(
            (u - observation.pixel.x) / self.noise.pixel_sigma_px,
            (v - observation.pixel.y) / self.noise.pixel_sigma_px,
            depth,
        )
    }

    fn linearize(
        &self,
        world_from_camera: &Isometry3<f64>,
        point: &Vector3<f64>,
        observation: &KeyframeObservation,
    ) -> Linearization<POSE_DOF, 3> {
        let rotation_t = world_from_camera
            .rotation
            .to_rotation_matrix()
            .matrix()
            .transpose();
        let p = rotation_t * (point - world_from_camera.translation.vector);
        let k = &self.intrinsics;
        let inv_z = 1.0 / p.z;
        let s = 1.0 / self.noise.pixel_sigma_px;
        // Rows: whitened u, v, depth with respect to camera coordinates P.
        let mut d_r_d_p = SMatrix::<f64, 3, 3>::new(
            k.fx * inv_z * s,
            0.0,
            -k.fx * p.x * inv_z * inv_z * s,
            0.0,
            k.fy * inv_z * s,
            -k.fy * p.y * inv_z * inv_z * s,
            0.0,
            0.0,
            0.0,
        );
        if observation.depth_m.is_some() {
            d_r_d_p[(2, 2)] = 1.0 / self.noise.depth_sigma_m;
        }
        // ∂P/∂δt = −Rᵀ, ∂P/∂δφ = [P]×, ∂P/∂X = Rᵀ.
        let mut jacobian_camera = SMatrix::<f64, 3, POSE_DOF>::zeros();
        jacobian_camera
            .fixed_view_mut::<3, 3>(0, 0)
            .copy_from(&(-(d_r_d_p * rotation_t)));
        jacobian_camera
            .fixed_view_mut::<3, 3>(0, 3)
            .copy_from(&(d_r_d_p * skew(&p)));
        Linearization {
            residual: self.residual(world_from_camera, point, observation),
            jacobian_camera,
            jacobian_point: d_r_d_p * rotation_t,
        }
    }

    fn retract(
        &self,
        world_from_camera: &Isometry3<f64>,
        delta: &SVector<f64, POSE_DOF>,
    ) -> Isometry3<f64> {
        let translation =
            world_from_camera.translation.vector + Vector3::new(delta[0], delta[1], delta[2]);
        let rotation = world_from_camera.rotation
            * UnitQuaternion::from_scaled_axis(Vector3::new(delta[3], delta[4], delta[5]));
        Isometry3::from_parts(translation.into(), rotation)
    }

    fn parameter_norm_squared(&self, world_from_camera: &Isometry3<f64>) -> f64 {
        world_from_camera.translation.vector.norm_squared()
            + world_from_camera.rotation.scaled_axis().norm_squared()
    }

    fn is_finite(&self, world_from_camera: &Isometry3<f64>) -> bool {
        finite_isometry(world_from_camera)
    }

    fn num_priors(&self) -> usize {
        self.absolute.len() + self.relative.len()
    }

    fn prior_cameras(&self, k: usize) -> [Option<usize>; 2] {
        match k.checked_sub(self.absolute.len()) {
            None => [Some(self.absolute[k].camera), None],
            Some(r) => [
                Some(self.relative[r].camera_a),
                Some(self.relative[r].camera_b),
            ],
        }
    }

    fn linearize_prior(
        &self,
        k: usize,
        cameras: &[Isometry3<f64>],
    ) -> PriorLinearization<POSE_DOF> {
        let sqrt_info = &self.sqrt_information[k];
        let mut jacobians = [SMatrix::<f64, 6, POSE_DOF>::zeros(); 2];
        let error = match k.checked_sub(self.absolute.len()) {
            None => {
                let prior = &self.absolute[k];
                let estimate = &cameras[prior.camera];
                let error = pose_error(&prior.world_from_camera, estimate);
                let r_m_t = prior
                    .world_from_camera
                    .rotation
                    .to_rotation_matrix()
                    .matrix()
                    .transpose();
                let j = &mut jacobians[0];
                j.fixed_view_mut::<3, 3>(0, 0).copy_from(&r_m_t);
                j.fixed_view_mut::<3, 3>(3, 3)
                    .copy_from(&right_jacobian_inverse(
                        &error.fixed_rows::<3>(3).into_owned(),
                    ));
                error
            }
            Some(r) => {
                let prior = &self.relative[r];
                let a = &cameras[prior.camera_a];
                let b = &cameras[prior.camera_b];
                let a_from_b = a.inverse() * b;
                let error = pose_error(&prior.camera_a_from_camera_b, &a_from_b);
                let r_m_t = prior
                    .camera_a_from_camera_b
                    .rotation
                    .to_rotation_matrix()
                    .matrix()
                    .transpose();
                let r_a = a.rotation.to_rotation_matrix().into_inner();
                let r_b = b.rotation.to_rotation_matrix().into_inner();
                let v = r_a.transpose() * (b.translation.vector - a.translation.vector);
                let jr_inv = right_jacobian_inverse(&error.fixed_rows::<3>(3).into_owned());
                let [ja, jb] = &mut jacobians;
                ja.fixed_view_mut::<3, 3>(0, 0)
                    .copy_from(&(-(r_m_t * r_a.transpose())));
                ja.fixed_view_mut::<3, 3>(0, 3)
                    .copy_from(&(r_m_t * skew(&v)));
                ja.fixed_view_mut::<3, 3>(3, 3)
                    .copy_from(&(-(jr_inv * r_b.transpose() * r_a)));
                jb.fixed_view_mut::<3, 3>(0, 0)
                    .copy_from(&(r_m_t * r_a.transpose()));
                jb.fixed_view_mut::<3, 3>(3, 3).copy_from(&jr_inv);
                error
            }
        };
        PriorLinearization {
            residual: sqrt_info * error,
            jacobians: [sqrt_info * jacobians[0], sqrt_info * jacobians[1]],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pose(t: [f64; 3], w: [f64; 3]) -> Isometry3<f64> {
        Isometry3::from_parts(
            Vector3::new(t[0], t[1], t[2]).into(),
            UnitQuaternion::from_scaled_axis(Vector3::new(w[0], w[1], w[2])),
        )
    }

    fn model() -> KeyframeModel {
        let mut info = Matrix6::identity() * 4.0;
        info[(0, 4)] = 0.5;
        info[(4, 0)] = 0.5;
        KeyframeModel::new(
            PinholeCamera::new(500.0, 510.0, 320.0, 240.0, 640, 480).unwrap(),
            KeyframeNoise::default(),
            vec![AbsolutePosePrior {
                camera: 0,
                world_from_camera: pose([0.1, 0.0, -0.2], [0.05, -0.1, 0.2]),
                information: info,
            }],
            vec![RelativePosePrior {
                camera_a: 0,
                camera_b: 1,
                camera_a_from_camera_b: pose([1.0, 0.2, 0.1], [0.0, 0.3, -0.1]),
                information: info,
            }],
        )
        .unwrap()
    }

    /// Central differences agree with the analytic Jacobians of observations and priors.
    #[test]
    fn jacobians_match_finite_differences() {
        let model = model();
        let cameras = [
            pose([0.2, -0.1, 0.3], [0.3, -0.2, 0.1]),
            pose([1.1, 0.3, 0.2], [0.1, 0.2, 0.4]),
        ];
        let point = cameras[0] * nalgebra::Point3::new(0.3, -0.2, 4.0);
        let point = point.coords;
        let observation = KeyframeObservation {
            camera: 0,
            point: 0,
            pixel: Vector2::new(300.0, 250.0),
            depth_m: Some(3.9),
        };
        let h = 1e-6;
        let lin = model.linearize(&cameras[0], &point, &observation);
        for k in 0..POSE_DOF {
            let mut d = SVector::<f64, POSE_DOF>::zeros();
            d[k] = h;
            let numeric = (model.residual(&model.retract(&cameras[0], &d), &point, &observation)
                - model.residual(&model.retract(&cameras[0], &(-d)), &point, &observation))
                / (2.0 * h);
            let analytic = lin.jacobian_camera.column(k);
            assert!(
                (numeric - analytic).norm() < 1e-5 * (1.0 + analytic.norm()),
                "pose column {k}"
            );
        }
        for k in 0..3 {
            let mut d = Vector3::zeros();
            d[k] = h;
            let numeric = (model.residual(&cameras[0], &(point + d), &observation)
                - model.residual(&cameras[0], &(point - d), &observation))
                / (2.0 * h);
            let analytic = lin.jacobian_point.column(k);
            assert!(
                (numeric - analytic).norm() < 1e-5 * (1.0 + analytic.norm()),
                "point column {k}"
            );
        }
        for prior in 0..model.num_priors() {
            let lin = model.linearize_prior(prior, &cameras);
            for (slot, cam) in model.prior_cameras(prior).iter().enumerate() {
                let Some(c) = *cam else { continue };
                for k in 0..POSE_DOF {
                    let mut d = SVector::<f64, POSE_DOF>::zeros();
                    d[k] = h;
                    let mut plus = cameras;
                    plus[c] = model.retract(&cameras[c], &d);
                    let mut minus = cameras;
                    minus[c] = model.retract(&cameras[c], &(-d));
                    let numeric = (model.linearize_prior(prior, &plus).residual
                        - model.linearize_prior(prior, &minus).residual)
                        / (2.0 * h);
                    let analytic = lin.jacobians[slot].column(k);
                    assert!(
                        (numeric - analytic).norm() < 1e-5 * (1.0 + analytic.norm()),
                        "prior {prior} camera {c} column {k}: {numeric:?} vs {analytic:?}"
                    );
                }
            }
        }
    }

    #[test]
    fn bad_information_and_noise_are_rejected() {
        let camera = PinholeCamera::new(500.0, 500.0, 320.0, 240.0, 640, 480).unwrap();
        let prior = AbsolutePosePrior {
            camera: 0,
            world_from_camera: Isometry3::identity(),
            information: -Matrix6::identity(),
        };
        let err =
            KeyframeModel::new(camera, KeyframeNoise::default(), vec![prior], vec![]).unwrap_err();
        assert!(err.to_string().contains("absolute prior 0"), "{err}");
        let noise = KeyframeNoise {
            pixel_sigma_px: 0.0,
            ..KeyframeNoise::default()
        };
        assert!(KeyframeModel::new(camera, noise, vec![], vec![]).is_err());
    }
}
