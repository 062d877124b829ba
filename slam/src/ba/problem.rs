//! The generic bundle-adjustment problem: cameras with `C` degrees of freedom, 3D points, and
//! 2D observations of points by cameras, tied together by a [`CameraModel`].

use nalgebra::{Matrix2x3, SMatrix, SVector, Vector2, Vector3};

/// One observation: camera `camera` sees point `point` at `pixel` (in the model's image
/// convention, for example BAL's centred, y-up coordinates for [`crate::ba::SnavelyModel`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Observation {
    /// Index of the observing camera.
    pub camera: usize,
    /// Index of the observed point.
    pub point: usize,
    /// The measured image position, in pixels.
    pub pixel: Vector2<f64>,
}

/// A residual and its Jacobians with respect to the camera's `C` local parameters and the
/// point's three coordinates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Linearization<const C: usize> {
    /// Predicted minus observed pixel position, pixels.
    pub residual: Vector2<f64>,
    /// ∂residual/∂(camera update), 2×C.
    pub jacobian_camera: SMatrix<f64, 2, C>,
    /// ∂residual/∂(point), 2×3.
    pub jacobian_point: Matrix2x3<f64>,
}

/// A camera model: how a camera with `C` local degrees of freedom predicts a point's image
/// position, its analytic Jacobians, and how a local update is applied.
///
/// Implementations must be pure (no interior state), so the solver may evaluate them in
/// parallel in any order.
pub trait CameraModel<const C: usize>: Sync {
    /// The camera's parameters (pose and, where the model needs them, intrinsics).
    type Camera: Clone + Send + Sync;

    /// Predicted minus observed image position. It may be non-finite (a point on the camera
    /// plane); the solver then rejects the step that led there.
    fn residual(
        &self,
        camera: &Self::Camera,
        point: &Vector3<f64>,
        observed: &Vector2<f64>,
    ) -> Vector2<f64>;

    /// The residual with its analytic Jacobians at the current parameters.
    fn linearize(
        &self,
        camera: &Self::Camera,
        point: &Vector3<f64>,
        observed: &Vector2<f64>,
    ) -> Linearization<C>;

    /// Applies a local update `delta` (in the coordinates of the Jacobian's camera columns).
    fn retract(&self, camera: &Self::Camera, delta: &SVector<f64, C>) -> Self::Camera;

    /// Squared norm of the camera's parameters, for the relative step-size test.
    fn parameter_norm_squared(&self, camera: &Self::Camera) -> f64;

    /// Whether all of the camera's parameters are finite.
    fn is_finite(&self, camera: &Self::Camera) -> bool;
}
