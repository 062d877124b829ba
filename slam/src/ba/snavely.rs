//! The Snavely (Bundler / BAL) camera: a rigid transform, one focal length and two radial
//! distortion terms; its reprojection residual and analytic Jacobians.
//!
//! Model, for a world point X: P = R·X + t (camera coordinates, camera looking down −z);
//! p = −P.xy / P.z; d = 1 + k1‖p‖² + k2‖p‖⁴; prediction = f·d·p (pixels, origin at the image
//! centre, y up).

use nalgebra::{Isometry3, Matrix2, Matrix2x3, Matrix3, SMatrix, SVector, Vector2, Vector3};

use super::problem::Observation;

use super::bal::isometry_from_angle_axis;
use super::problem::{CameraModel, Linearization};

/// Number of local degrees of freedom of a [`SnavelyCamera`]: rotation (3), translation (3),
/// focal length, k1, k2.
pub const SNAVELY_CAMERA_DOF: usize = 9;

/// A Snavely camera.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SnavelyCamera {
    /// Maps world points into the camera frame (Snavely's frame: x right, y up, looking down −z).
    pub camera_from_world: Isometry3<f64>,
    /// Focal length, pixels.
    pub focal_px: f64,
    /// Radial distortion coefficient of ‖p‖².
    pub k1: f64,
    /// Radial distortion coefficient of ‖p‖⁴.
    pub k2: f64,
}

impl SnavelyCamera {
    /// Builds a camera from BAL's nine parameters: angle-axis rotation (radians), translation,
    /// focal length (pixels), k1, k2.
    pub fn from_bal_parameters(p: &[f64; 9]) -> Self {
        Self {
            camera_from_world: isometry_from_angle_axis(
                &Vector3::new(p[0], p[1], p[2]),
                &Vector3::new(p[3], p[4], p[5]),
            ),
            focal_px: p[6],
            k1: p[7],
            k2: p[8],
        }
    }

    /// BAL's nine parameters of this camera (inverse of [`Self::from_bal_parameters`]).
    pub fn bal_parameters(&self) -> [f64; 9] {
        let w = self.camera_from_world.rotation.scaled_axis();
        let t = self.camera_from_world.translation.vector;
        [
            w.x,
            w.y,
            w.z,
            t.x,
            t.y,
            t.z,
            self.focal_px,
            self.k1,
            self.k2,
        ]
    }

    /// The predicted image position of world point `point_world` (pixels, BAL convention).
    /// Non-finite when the point lies on the camera plane (P.z = 0).
    pub fn project(&self, point_world: &Vector3<f64>) -> Vector2<f64> {
        let p_cam = self.camera_from_world.rotation * point_world
            + self.camera_from_world.translation.vector;
        let p = -p_cam.xy() / p_cam.z;
        let r2 = p.norm_squared();
        let d = 1.0 + r2 * (self.k1 + self.k2 * r2);
        p * (self.focal_px * d)
    }
}

/// Skew-symmetric cross-product matrix: `skew(a) * b == a.cross(&b)`.
pub(crate) fn skew(a: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -a.z, a.y, a.z, 0.0, -a.x, -a.y, a.x, 0.0)
}

/// The BAL reprojection cost with [`SnavelyCamera`]s. The camera update is
/// (δω, δt, δf, δk1, δk2) with the rotation perturbed on the left: R ← exp(δω)·R, t ← t + δt.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct SnavelyModel;

impl CameraModel<SNAVELY_CAMERA_DOF, 2> for SnavelyModel {
    type Camera = SnavelyCamera;
    type Observation = Observation;

    fn residual(
        &self,
        camera: &SnavelyCamera,
        point: &Vector3<f64>,
        observation: &Observation,
    ) -> Vector2<f64> {
        camera.project(point) - observation.pixel
    }

    fn linearize(
        &self,
        camera: &SnavelyCamera,
        point: &Vector3<f64>,
        observation: &Observation,
    ) -> Linearization<SNAVELY_CAMERA_DOF, 2> {
        let observed = &observation.pixel;
        let rotation = camera.camera_from_world.rotation.to_rotation_matrix();
        let rotated = rotation * point;
        let p_cam = rotated + camera.camera_from_world.translation.vector;
        let inv_z = 1.0 / p_cam.z;
        let p = -p_cam.xy() * inv_z;
        let r2 = p.norm_squared();
        let d = 1.0 + r2 * (camera.k1 + camera.k2 * r2);
        let f = camera.focal_px;
        let prediction = p * (f * d);

        // ∂prediction/∂p = f·(d·I + (2k1 + 4k2‖p‖²)·p·pᵀ).
        let dd = 2.0 * camera.k1 + 4.0 * camera.k2 * r2;
        let d_pred_d_p = (Matrix2::identity() * d + p * p.transpose() * dd) * f;
        // ∂p/∂P for p = −P.xy/P.z.
        let d_p_d_pcam = Matrix2x3::new(-inv_z, 0.0, -p.x * inv_z, 0.0, -inv_z, -p.y * inv_z);
        let d_pred_d_pcam = d_pred_d_p * d_p_d_pcam;

        let mut jacobian_camera = SMatrix::<f64, 2, SNAVELY_CAMERA_DOF>::zeros();
        // ∂P/∂δω = −[R·X]×, ∂P/∂δt = I.
        jacobian_camera
            .fixed_view_mut::<2, 3>(0, 0)
            .copy_from(&(d_pred_d_pcam * (-skew(&rotated))));
        jacobian_camera
            .fixed_view_mut::<2, 3>(0, 3)
            .copy_from(&d_pred_d_pcam);
        jacobian_camera.set_column(6, &(p * d));
        jacobian_camera.set_column(7, &(p * (f * r2)));
        jacobian_camera.set_column(8, &(p * (f * r2 * r2)));
        Linearization {
            residual: prediction - observed,
            jacobian_camera,
            jacobian_point: d_pred_d_pcam * rotation.matrix(),
        }
    }

    fn retract(
        &self,
        camera: &SnavelyCamera,
        delta: &SVector<f64, SNAVELY_CAMERA_DOF>,
    ) -> SnavelyCamera {
        let rotation =
            nalgebra::UnitQuaternion::from_scaled_axis(Vector3::new(delta[0], delta[1], delta[2]))
                * camera.camera_from_world.rotation;
        let translation = camera.camera_from_world.translation.vector
            + Vector3::new(delta[3], delta[4], delta[5]);
        SnavelyCamera {
            camera_from_world: Isometry3::from_parts(translation.into(), rotation),
            focal_px: camera.focal_px + delta[6],
            k1: camera.k1 + delta[7],
            k2: camera.k2 + delta[8],
        }
    }

    fn parameter_norm_squared(&self, camera: &SnavelyCamera) -> f64 {
        camera.bal_parameters().iter().map(|v| v * v).sum()
    }

    fn is_finite(&self, camera: &SnavelyCamera) -> bool {
        camera.bal_parameters().iter().all(|v| v.is_finite())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Central differences of the residual agree with the analytic Jacobians.
    #[test]
    fn jacobians_match_finite_differences() {
        let model = SnavelyModel;
        let camera = SnavelyCamera::from_bal_parameters(&[
            0.1, -0.2, 0.3, 0.5, -0.4, -6.0, 520.0, -0.03, 0.002,
        ]);
        let point = Vector3::new(0.3, -0.7, 0.4);
        let observed = Observation {
            camera: 0,
            point: 0,
            pixel: Vector2::new(10.0, -4.0),
        };
        let lin = model.linearize(&camera, &point, &observed);
        assert!((lin.residual - model.residual(&camera, &point, &observed)).norm() < 1e-9);
        let h = 1e-6;
        for k in 0..SNAVELY_CAMERA_DOF {
            let mut delta = SVector::<f64, SNAVELY_CAMERA_DOF>::zeros();
            delta[k] = h;
            let plus = model.residual(&model.retract(&camera, &delta), &point, &observed);
            let minus = model.residual(&model.retract(&camera, &(-delta)), &point, &observed);
            let numeric = (plus - minus) / (2.0 * h);
            let analytic = lin.jacobian_camera.column(k);
            assert!(
                (numeric - analytic).norm() < 1e-5 * (1.0 + analytic.norm()),
                "camera column {k}: numeric {numeric:?} analytic {analytic:?}"
            );
        }
        for k in 0..3 {
            let mut dx = Vector3::zeros();
            dx[k] = h;
            let numeric = (model.residual(&camera, &(point + dx), &observed)
                - model.residual(&camera, &(point - dx), &observed))
                / (2.0 * h);
            let analytic = lin.jacobian_point.column(k);
            assert!(
                (numeric - analytic).norm() < 1e-5 * (1.0 + analytic.norm()),
                "point column {k}: numeric {numeric:?} analytic {analytic:?}"
            );
        }
    }

    #[test]
    fn bal_parameters_round_trip() {
        let p = [0.1, -0.2, 0.3, 0.5, -0.4, -6.0, 520.0, -0.03, 0.002];
        let q = SnavelyCamera::from_bal_parameters(&p).bal_parameters();
        for (a, b) in p.iter().zip(q.iter()) {
            assert!((a - b).abs() < 1e-12);
        }
    }
}
