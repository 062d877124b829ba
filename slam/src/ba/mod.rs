//! Sparse bundle adjustment: Levenberg–Marquardt over camera parameters and 3D points with the
//! Schur complement eliminating the points, analytic Jacobians, optional robust losses, and the
//! reduced camera system solved with faer (dense Cholesky while small, sparse Cholesky with a
//! reused symbolic analysis when large).
//!
//! - [`problem`]: the generic problem ([`Observation`], the [`CameraModel`] trait).
//! - [`snavely`]: the Snavely (BAL) camera and its reprojection cost.
//! - [`bal`]: the BAL file reader.
//! - [`keyframe`]: the mapping pipeline's problem (SE(3) keyframe poses, fixed pinhole
//!   intrinsics, reprojection and RGBD depth residuals, relative and absolute pose priors).
//! - [`loss`]: robust losses.
//! - [`solver`]: the Levenberg–Marquardt loop ([`solve`], [`LmConfig`], [`BaSummary`]).
//!
//! ```
//! use nalgebra::Vector3;
//! use scarp_slam::ba::{LmConfig, Observation, SnavelyCamera, SnavelyModel, solve};
//!
//! // Two cameras looking down −z at three points; the first point starts off by 0.05.
//! let cameras_truth = [
//!     SnavelyCamera::from_bal_parameters(&[0.0, 0.0, 0.0, 0.0, 0.0, -5.0, 500.0, 0.0, 0.0]),
//!     SnavelyCamera::from_bal_parameters(&[0.0, 0.2, 0.0, 1.0, 0.0, -5.0, 500.0, 0.0, 0.0]),
//! ];
//! let truth = [Vector3::new(0.0, 0.0, 0.0), Vector3::new(0.5, 0.2, 0.1), Vector3::new(-0.3, 0.4, -0.2)];
//! let mut observations = Vec::new();
//! for (c, camera) in cameras_truth.iter().enumerate() {
//!     for (p, x) in truth.iter().enumerate() {
//!         observations.push(Observation { camera: c, point: p, pixel: camera.project(x) });
//!     }
//! }
//! let mut cameras = cameras_truth.to_vec();
//! let mut points = truth.to_vec();
//! points[0].x += 0.05;
//! // Noise-free observations: the solver drives the cost to zero.
//! let summary = solve(&SnavelyModel, &mut cameras, &mut points, &observations, &LmConfig::default()).unwrap();
//! assert!(summary.final_cost < 1e-12 * summary.initial_cost.max(1.0));
//! ```

pub mod bal;
pub mod error;
pub mod keyframe;
mod linear;
pub mod loss;
pub mod problem;
pub mod snavely;
pub mod solver;

pub use bal::{BalProblem, parse_bal, read_bal};
pub use error::BaError;
pub use keyframe::{
    AbsolutePosePrior, KeyframeModel, KeyframeNoise, KeyframeObservation, POSE_DOF,
    RelativePosePrior,
};
pub use linear::LinearSolverKind;
pub use loss::RobustLoss;
pub use problem::{CameraModel, Indexed, Linearization, Observation, PriorLinearization};
pub use snavely::{SNAVELY_CAMERA_DOF, SnavelyCamera, SnavelyModel};
pub use solver::{BaSummary, IterationLog, LmConfig, Termination, solve};

/// Solves a BAL problem in place with the Snavely model.
///
/// # Errors
/// As [`solve`].
pub fn solve_bal(problem: &mut BalProblem, config: &LmConfig) -> Result<BaSummary, BaError> {
    solve(
        &SnavelyModel,
        &mut problem.cameras,
        &mut problem.points,
        &problem.observations,
        config,
    )
}
