//! The generic bundle-adjustment problem: cameras with `C` degrees of freedom, 3D points, and
//! 2D observations of points by cameras, tied together by a [`CameraModel`].

use nalgebra::{SMatrix, SVector, Vector2, Vector3};

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

/// An observation of one point by one camera: the solver groups observations by these indices.
pub trait Indexed {
    /// Index of the observing camera.
    fn camera(&self) -> usize;
    /// Index of the observed point.
    fn point(&self) -> usize;
}

impl Indexed for Observation {
    fn camera(&self) -> usize {
        self.camera
    }
    fn point(&self) -> usize {
        self.point
    }
}

/// A residual of dimension `R` and its Jacobians with respect to the camera's `C` local
/// parameters and the point's three coordinates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Linearization<const C: usize, const R: usize> {
    /// The (whitened) residual: predicted minus observed.
    pub residual: SVector<f64, R>,
    /// ∂residual/∂(camera update), R×C.
    pub jacobian_camera: SMatrix<f64, R, C>,
    /// ∂residual/∂(point), R×3.
    pub jacobian_point: SMatrix<f64, R, 3>,
}

/// A whitened 6-dimensional residual on one or two cameras only (a pose prior) and its
/// Jacobians. `jacobians[k]` belongs to `cameras[k]`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PriorLinearization<const C: usize> {
    /// The whitened residual (‖r‖² is the Mahalanobis distance under the prior's information).
    pub residual: SVector<f64, 6>,
    /// ∂residual/∂(update of each camera of the term).
    pub jacobians: [SMatrix<f64, 6, C>; 2],
}

/// A camera model: how a camera with `C` local degrees of freedom predicts an observation
/// (a residual of dimension `R`), its analytic Jacobians, how a local update is applied, and
/// optionally residuals on cameras alone (pose priors).
///
/// Implementations must be pure (no interior mutability), so the solver may evaluate them in
/// parallel in any order.
pub trait CameraModel<const C: usize, const R: usize>: Sync {
    /// The camera's parameters (pose and, where the model needs them, intrinsics).
    type Camera: Clone + Send + Sync;
    /// One observation of a point by a camera.
    type Observation: Indexed + Sync;

    /// Predicted minus observed (whitened). It may be non-finite (a point on the camera plane);
    /// the solver then rejects the step that led there.
    fn residual(
        &self,
        camera: &Self::Camera,
        point: &Vector3<f64>,
        observation: &Self::Observation,
    ) -> SVector<f64, R>;

    /// The residual with its analytic Jacobians at the current parameters.
    fn linearize(
        &self,
        camera: &Self::Camera,
        point: &Vector3<f64>,
        observation: &Self::Observation,
    ) -> Linearization<C, R>;

    /// Applies a local update `delta` (in the coordinates of the Jacobian's camera columns).
    fn retract(&self, camera: &Self::Camera, delta: &SVector<f64, C>) -> Self::Camera;

    /// Squared norm of the camera's parameters, for the relative step-size test.
    fn parameter_norm_squared(&self, camera: &Self::Camera) -> f64;

    /// Whether all of the camera's parameters are finite.
    fn is_finite(&self, camera: &Self::Camera) -> bool;

    /// Number of residual terms on cameras alone (pose priors). None by default.
    fn num_priors(&self) -> usize {
        0
    }

    /// The cameras of prior `k`: one (absolute prior) or two distinct ones (relative prior).
    /// Only called for `k < num_priors()`.
    fn prior_cameras(&self, k: usize) -> [Option<usize>; 2] {
        let _ = k;
        [None, None]
    }

    /// The whitened residual of prior `k` and its Jacobians. Only called for
    /// `k < num_priors()`, with in-range camera indices.
    fn linearize_prior(&self, k: usize, cameras: &[Self::Camera]) -> PriorLinearization<C> {
        let _ = (k, cameras);
        PriorLinearization {
            residual: SVector::zeros(),
            jacobians: [SMatrix::zeros(); 2],
        }
    }
}
