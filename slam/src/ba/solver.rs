//! Levenberg–Marquardt with the Schur complement that eliminates the points.
//!
//! Each iteration linearises every observation (in parallel), builds the point blocks V_p and
//! camera blocks U_i of JᵀJ, damps both with μ·diag (μ = 1/trust-region radius, as Ceres), forms
//! the reduced camera system S = U − W·V⁻¹·Wᵀ row by row (each camera row owned by one rayon task,
//! summed in a fixed order, so results are identical for any thread count), solves it with faer
//! (dense or sparse Cholesky), back-substitutes the point updates, and accepts the step when the
//! actual cost decrease is a large enough fraction of the predicted one.

use nalgebra::{Matrix3, SMatrix, SVector, Vector3};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::error::BaError;
use super::linear::{BlockPattern, LinearSolverKind, ReducedSolver};
use super::loss::RobustLoss;
use super::problem::{CameraModel, Indexed, PriorLinearization};

/// Settings of the Levenberg–Marquardt solver. The defaults follow Ceres Solver's.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LmConfig {
    /// Maximum number of iterations (accepted or rejected steps). Default 50.
    pub max_iterations: usize,
    /// Stop when |Δcost| / cost of a step falls below this. Default 1e-6.
    pub function_tolerance: f64,
    /// Stop when the largest gradient component falls below this. Default 1e-10.
    pub gradient_tolerance: f64,
    /// Stop when ‖δ‖ ≤ tol·(‖x‖ + tol). Default 1e-8.
    pub parameter_tolerance: f64,
    /// Initial trust-region radius (1/μ). Default 1e4.
    pub initial_trust_region_radius: f64,
    /// Largest trust-region radius. Default 1e16.
    pub max_trust_region_radius: f64,
    /// Stop when the trust-region radius shrinks below this. Default 1e-32.
    pub min_trust_region_radius: f64,
    /// Accept a step when actual/predicted decrease exceeds this. Default 1e-3.
    pub min_relative_decrease: f64,
    /// Lower clamp of the LM damping diagonal. Default 1e-6.
    pub min_diagonal: f64,
    /// Upper clamp of the LM damping diagonal. Default 1e32.
    pub max_diagonal: f64,
    /// Reduced systems with at most this many unknowns use dense Cholesky; larger ones use
    /// sparse Cholesky. Default 1000.
    pub dense_max_unknowns: usize,
    /// Robust loss on each observation. Default [`RobustLoss::Trivial`].
    pub loss: RobustLoss,
}

impl Default for LmConfig {
    fn default() -> Self {
        Self {
            max_iterations: 50,
            function_tolerance: 1e-6,
            gradient_tolerance: 1e-10,
            parameter_tolerance: 1e-8,
            initial_trust_region_radius: 1e4,
            max_trust_region_radius: 1e16,
            min_trust_region_radius: 1e-32,
            min_relative_decrease: 1e-3,
            min_diagonal: 1e-6,
            max_diagonal: 1e32,
            dense_max_unknowns: 1000,
            loss: RobustLoss::Trivial,
        }
    }
}

impl LmConfig {
    /// Checks that every setting is in range.
    ///
    /// # Errors
    /// [`BaError::InvalidConfig`] naming the first bad field.
    pub fn validate(&self) -> Result<(), BaError> {
        let positive = [
            ("function_tolerance", self.function_tolerance),
            ("gradient_tolerance", self.gradient_tolerance),
            ("parameter_tolerance", self.parameter_tolerance),
            (
                "initial_trust_region_radius",
                self.initial_trust_region_radius,
            ),
            ("max_trust_region_radius", self.max_trust_region_radius),
            ("min_trust_region_radius", self.min_trust_region_radius),
            ("min_diagonal", self.min_diagonal),
            ("max_diagonal", self.max_diagonal),
        ];
        for (field, value) in positive {
            if !(value.is_finite() && value >= 0.0) {
                return Err(BaError::InvalidConfig {
                    field,
                    value,
                    reason: "must be finite and non-negative",
                });
            }
        }
        if self.initial_trust_region_radius <= 0.0 {
            return Err(BaError::InvalidConfig {
                field: "initial_trust_region_radius",
                value: self.initial_trust_region_radius,
                reason: "must be positive",
            });
        }
        if !(self.min_relative_decrease.is_finite()
            && (0.0..1.0).contains(&self.min_relative_decrease))
        {
            return Err(BaError::InvalidConfig {
                field: "min_relative_decrease",
                value: self.min_relative_decrease,
                reason: "must lie in [0, 1)",
            });
        }
        if let Some((field, value)) = self.loss.scale()
            && !(value.is_finite() && value > 0.0)
        {
            return Err(BaError::InvalidConfig {
                field,
                value,
                reason: "must be finite and positive",
            });
        }
        Ok(())
    }
}

/// Why the solver stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Termination {
    /// The relative cost change of a step fell below `function_tolerance`.
    FunctionTolerance,
    /// The gradient's largest component fell below `gradient_tolerance`.
    GradientTolerance,
    /// The step fell below `parameter_tolerance` relative to the parameters.
    ParameterTolerance,
    /// `max_iterations` were used.
    MaxIterations,
    /// The trust region shrank below `min_trust_region_radius` without an acceptable step.
    TrustRegionCollapsed,
    /// The problem has nothing to optimise (no observations) or zero cost.
    NothingToDo,
}

/// One iteration of the solver.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct IterationLog {
    /// 1-based iteration number.
    pub iteration: usize,
    /// Cost after the iteration (unchanged when the step was rejected).
    pub cost: f64,
    /// Cost the step led to (its evaluation; `NaN` when the linear solve failed).
    pub candidate_cost: f64,
    /// Whether the step was accepted.
    pub accepted: bool,
    /// Trust-region radius used for the step.
    pub trust_region_radius: f64,
    /// Largest gradient component at the start of the iteration.
    pub gradient_max_norm: f64,
    /// Euclidean norm of the step.
    pub step_norm: f64,
    /// Actual over predicted cost decrease.
    pub step_quality: f64,
}

/// The outcome of a solve.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BaSummary {
    /// Cost ½·Σρ(‖r‖²) at the start.
    pub initial_cost: f64,
    /// Cost at the end.
    pub final_cost: f64,
    /// Number of iterations (accepted and rejected steps).
    pub iterations: usize,
    /// `costs[0]` is the initial cost, `costs[k]` the cost after iteration k.
    pub costs: Vec<f64>,
    /// Per-iteration details.
    pub log: Vec<IterationLog>,
    /// Why the solver stopped.
    pub termination: Termination,
    /// The factorisation used for the reduced camera system.
    pub linear_solver: LinearSolverKind,
}

/// Observation indices grouped by point and by camera, and the block pattern of S.
struct Structure {
    point_offsets: Vec<usize>,
    point_obs: Vec<usize>,
    camera_offsets: Vec<usize>,
    camera_obs: Vec<usize>,
    /// Per camera, the prior terms that involve it (ascending).
    camera_priors: Vec<Vec<usize>>,
    /// Per prior term, its cameras.
    prior_cameras: Vec<[Option<usize>; 2]>,
    pattern: BlockPattern,
}

/// Groups `0..keys.len()` by key (stable: ascending index within a group).
fn group_by(keys: impl Iterator<Item = usize> + Clone, groups: usize) -> (Vec<usize>, Vec<usize>) {
    let mut offsets = vec![0usize; groups + 1];
    for k in keys.clone() {
        offsets[k + 1] += 1;
    }
    for g in 0..groups {
        offsets[g + 1] += offsets[g];
    }
    let mut fill = offsets.clone();
    let mut items = vec![0usize; offsets[groups]];
    for (index, k) in keys.enumerate() {
        items[fill[k]] = index;
        fill[k] += 1;
    }
    (offsets, items)
}

impl Structure {
    fn new<O: Indexed + Sync>(
        observations: &[O],
        prior_cameras: Vec<[Option<usize>; 2]>,
        num_cameras: usize,
        num_points: usize,
    ) -> Self {
        let (point_offsets, point_obs) =
            group_by(observations.iter().map(|o| o.point()), num_points);
        let (camera_offsets, camera_obs) =
            group_by(observations.iter().map(|o| o.camera()), num_cameras);
        let mut camera_priors = vec![Vec::new(); num_cameras];
        for (k, cams) in prior_cameras.iter().enumerate() {
            for &c in cams.iter().flatten() {
                camera_priors[c].push(k);
            }
        }
        let rows: Vec<Vec<usize>> = (0..num_cameras)
            .into_par_iter()
            .map(|i| {
                let mut cols = vec![i];
                for &k in &camera_priors[i] {
                    for &j in prior_cameras[k].iter().flatten() {
                        if j > i {
                            cols.push(j);
                        }
                    }
                }
                for &o in &camera_obs[camera_offsets[i]..camera_offsets[i + 1]] {
                    let p = observations[o].point();
                    for &o2 in &point_obs[point_offsets[p]..point_offsets[p + 1]] {
                        let j = observations[o2].camera();
                        if j > i {
                            cols.push(j);
                        }
                    }
                }
                cols[1..].sort_unstable();
                cols.dedup();
                cols
            })
            .collect();
        let mut row_offsets = Vec::with_capacity(num_cameras + 1);
        row_offsets.push(0);
        let mut cols = Vec::new();
        for r in rows {
            cols.extend(r);
            row_offsets.push(cols.len());
        }
        Self {
            point_offsets,
            point_obs,
            camera_offsets,
            camera_obs,
            camera_priors,
            prior_cameras,
            pattern: BlockPattern { row_offsets, cols },
        }
    }

    fn obs_of_point(&self, p: usize) -> &[usize] {
        &self.point_obs[self.point_offsets[p]..self.point_offsets[p + 1]]
    }

    fn obs_of_camera(&self, i: usize) -> &[usize] {
        &self.camera_obs[self.camera_offsets[i]..self.camera_offsets[i + 1]]
    }
}

/// A weighted residual with its Jacobians and W = Jcᵀ·Jp.
struct ObsLin<const C: usize, const R: usize> {
    r: SVector<f64, R>,
    jc: SMatrix<f64, R, C>,
    jp: SMatrix<f64, R, 3>,
    w: SMatrix<f64, C, 3>,
}

/// The linearised normal equations at the current estimate.
struct Normal<const C: usize, const R: usize> {
    obs: Vec<ObsLin<C, R>>,
    priors: Vec<PriorLinearization<C>>,
    /// Per point: Vp = Σ Jpᵀ·Jp and gp = Σ Jpᵀ·r.
    points: Vec<(Matrix3<f64>, Vector3<f64>)>,
    /// Per camera: Ui = Σ Jcᵀ·Jc and gi = Σ Jcᵀ·r.
    cameras: Vec<(SMatrix<f64, C, C>, SVector<f64, C>)>,
    gradient_max_norm: f64,
}

/// ½·Σρ(‖r‖²) over all observations plus ½·Σ‖r‖² over the priors, summed in a fixed order.
fn total_cost<M: CameraModel<C, R>, const C: usize, const R: usize>(
    model: &M,
    loss: &RobustLoss,
    cameras: &[M::Camera],
    points: &[Vector3<f64>],
    observations: &[M::Observation],
) -> f64 {
    let per_obs: Vec<f64> = observations
        .par_iter()
        .map(|o| {
            let r = model.residual(&cameras[o.camera()], &points[o.point()], o);
            0.5 * loss.rho(r.norm_squared())
        })
        .collect();
    let priors: f64 = (0..model.num_priors())
        .map(|k| 0.5 * model.linearize_prior(k, cameras).residual.norm_squared())
        .sum();
    per_obs.iter().sum::<f64>() + priors
}

fn linearize<M: CameraModel<C, R>, const C: usize, const R: usize>(
    model: &M,
    loss: &RobustLoss,
    structure: &Structure,
    cameras: &[M::Camera],
    points: &[Vector3<f64>],
    observations: &[M::Observation],
) -> Normal<C, R> {
    let priors: Vec<PriorLinearization<C>> = (0..model.num_priors())
        .into_par_iter()
        .map(|k| model.linearize_prior(k, cameras))
        .collect();
    let obs: Vec<ObsLin<C, R>> = observations
        .par_iter()
        .map(|o| {
            let lin = model.linearize(&cameras[o.camera()], &points[o.point()], o);
            let scale = loss.weight(lin.residual.norm_squared()).sqrt();
            let jc = lin.jacobian_camera * scale;
            let jp = lin.jacobian_point * scale;
            ObsLin {
                r: lin.residual * scale,
                jc,
                jp,
                w: jc.transpose() * jp,
            }
        })
        .collect();
    let point_blocks: Vec<(Matrix3<f64>, Vector3<f64>)> = (0..points.len())
        .into_par_iter()
        .map(|p| {
            let mut v = Matrix3::zeros();
            let mut g = Vector3::zeros();
            for &o in structure.obs_of_point(p) {
                v += obs[o].jp.transpose() * obs[o].jp;
                g += obs[o].jp.transpose() * obs[o].r;
            }
            (v, g)
        })
        .collect();
    let camera_blocks: Vec<(SMatrix<f64, C, C>, SVector<f64, C>)> = (0..cameras.len())
        .into_par_iter()
        .map(|i| {
            let mut u = SMatrix::<f64, C, C>::zeros();
            let mut g = SVector::<f64, C>::zeros();
            for &o in structure.obs_of_camera(i) {
                u += obs[o].jc.transpose() * obs[o].jc;
                g += obs[o].jc.transpose() * obs[o].r;
            }
            for &k in &structure.camera_priors[i] {
                for (slot, cam) in structure.prior_cameras[k].iter().enumerate() {
                    if *cam == Some(i) {
                        let j = &priors[k].jacobians[slot];
                        u += j.transpose() * j;
                        g += j.transpose() * priors[k].residual;
                    }
                }
            }
            (u, g)
        })
        .collect();
    let gradient_max_norm = point_blocks
        .iter()
        .map(|(_, g)| g.amax())
        .chain(camera_blocks.iter().map(|(_, g)| g.amax()))
        .fold(0.0, f64::max);
    Normal {
        obs,
        priors,
        points: point_blocks,
        cameras: camera_blocks,
        gradient_max_norm,
    }
}

/// A damped Gauss–Newton step: camera and point updates and the predicted cost decrease.
struct Step<const C: usize> {
    cameras: Vec<SVector<f64, C>>,
    points: Vec<Vector3<f64>>,
    predicted_decrease: f64,
    norm: f64,
}

/// Adds μ·clamp(diag) to the diagonal of a square block.
fn damp<const N: usize>(m: &SMatrix<f64, N, N>, mu: f64, config: &LmConfig) -> SMatrix<f64, N, N> {
    let mut out = *m;
    for k in 0..N {
        out[(k, k)] += mu * m[(k, k)].clamp(config.min_diagonal, config.max_diagonal);
    }
    out
}

fn compute_step<O: Indexed + Sync, const C: usize, const R: usize>(
    normal: &Normal<C, R>,
    structure: &Structure,
    solver: &ReducedSolver,
    observations: &[O],
    mu: f64,
    config: &LmConfig,
) -> Option<Step<C>> {
    // Damped point blocks, inverted (3×3 Cholesky).
    let v_inv: Vec<Option<Matrix3<f64>>> = normal
        .points
        .par_iter()
        .map(|(v, _)| nalgebra::Cholesky::new(damp(v, mu, config)).map(|c| c.inverse()))
        .collect();
    let v_inv: Vec<Matrix3<f64>> = v_inv.into_iter().collect::<Option<Vec<_>>>()?;
    // Y = W·V⁻¹ per observation.
    let y: Vec<SMatrix<f64, C, 3>> = observations
        .par_iter()
        .zip(normal.obs.par_iter())
        .map(|(o, lin)| lin.w * v_inv[o.point()])
        .collect();
    let pattern = &structure.pattern;
    // Reduced camera system, one task per block row.
    let rows: Vec<(Vec<SMatrix<f64, C, C>>, SVector<f64, C>)> = (0..normal.cameras.len())
        .into_par_iter()
        .map(|i| {
            let n_blocks = pattern.row_offsets[i + 1] - pattern.row_offsets[i];
            let mut blocks = vec![SMatrix::<f64, C, C>::zeros(); n_blocks];
            let (u, g) = &normal.cameras[i];
            blocks[0] = damp(u, mu, config);
            let mut rhs = -g;
            // Relative priors couple camera i with a camera j > i.
            for &k in &structure.camera_priors[i] {
                if let [Some(a), Some(b)] = structure.prior_cameras[k] {
                    let (si, sj, j) = if a == i { (0, 1, b) } else { (1, 0, a) };
                    if j > i
                        && let Some(kb) = pattern.find(i, j)
                    {
                        let jac = &normal.priors[k].jacobians;
                        blocks[kb] += jac[si].transpose() * jac[sj];
                    }
                }
            }
            for &o in structure.obs_of_camera(i) {
                let p = observations[o].point();
                rhs += y[o] * normal.points[p].1;
                for &o2 in structure.obs_of_point(p) {
                    let j = observations[o2].camera();
                    if j < i {
                        continue;
                    }
                    // Every (i, j ≥ i) sharing a point is in the pattern by construction.
                    if let Some(k) = pattern.find(i, j) {
                        blocks[k] -= y[o] * normal.obs[o2].w.transpose();
                    }
                }
            }
            (blocks, rhs)
        })
        .collect();
    let (blocks, rhs): (Vec<_>, Vec<_>) = rows.into_iter().unzip();
    let delta_cameras = solver.solve::<C>(pattern, &blocks, &rhs).ok()?;
    // Back-substitution: δp = V⁻¹·(−gp − Σ Wᵀ·δc).
    let delta_points: Vec<Vector3<f64>> = (0..normal.points.len())
        .into_par_iter()
        .map(|p| {
            let mut b = -normal.points[p].1;
            for &o in structure.obs_of_point(p) {
                b -= normal.obs[o].w.transpose() * delta_cameras[observations[o].camera()];
            }
            v_inv[p] * b
        })
        .collect();
    // Predicted decrease of the linear model: −(rᵀ·Jδ + ½‖Jδ‖²).
    let per_obs: Vec<f64> = observations
        .par_iter()
        .zip(normal.obs.par_iter())
        .map(|(o, lin)| {
            let jd = lin.jc * delta_cameras[o.camera()] + lin.jp * delta_points[o.point()];
            -(lin.r.dot(&jd) + 0.5 * jd.norm_squared())
        })
        .collect();
    let prior_decrease: f64 = normal
        .priors
        .iter()
        .zip(&structure.prior_cameras)
        .map(|(lin, cams)| {
            let mut jd = SVector::<f64, 6>::zeros();
            for (slot, cam) in cams.iter().enumerate() {
                if let Some(c) = cam {
                    jd += lin.jacobians[slot] * delta_cameras[*c];
                }
            }
            -(lin.residual.dot(&jd) + 0.5 * jd.norm_squared())
        })
        .sum();
    let predicted_decrease = per_obs.iter().sum::<f64>() + prior_decrease;
    let norm = (delta_cameras.iter().map(|d| d.norm_squared()).sum::<f64>()
        + delta_points.iter().map(|d| d.norm_squared()).sum::<f64>())
    .sqrt();
    Some(Step {
        cameras: delta_cameras,
        points: delta_points,
        predicted_decrease,
        norm,
    })
}

/// Checks indices and finiteness of a problem.
fn validate_problem<M: CameraModel<C, R>, const C: usize, const R: usize>(
    model: &M,
    cameras: &[M::Camera],
    points: &[Vector3<f64>],
    observations: &[M::Observation],
) -> Result<(), BaError> {
    for (k, o) in observations.iter().enumerate() {
        if o.camera() >= cameras.len() || o.point() >= points.len() {
            return Err(BaError::InvalidProblem {
                reason: format!(
                    "observation {k} refers to camera {} and point {}, but there are {} cameras and {} points",
                    o.camera(),
                    o.point(),
                    cameras.len(),
                    points.len()
                ),
            });
        }
    }
    for k in 0..model.num_priors() {
        let cams = model.prior_cameras(k);
        let valid = match cams {
            [Some(a), None] | [None, Some(a)] => a < cameras.len(),
            [Some(a), Some(b)] => a < cameras.len() && b < cameras.len() && a != b,
            [None, None] => false,
        };
        if !valid {
            return Err(BaError::InvalidProblem {
                reason: format!(
                    "prior {k} refers to cameras {cams:?}; it needs one camera or two distinct ones below {}",
                    cameras.len()
                ),
            });
        }
    }
    if let Some(i) = cameras.iter().position(|c| !model.is_finite(c)) {
        return Err(BaError::InvalidProblem {
            reason: format!("camera {i} has a non-finite parameter"),
        });
    }
    if let Some(p) = points.iter().position(|p| !p.iter().all(|v| v.is_finite())) {
        return Err(BaError::InvalidProblem {
            reason: format!("point {p} is not finite"),
        });
    }
    Ok(())
}

/// Refines `cameras` and `points` in place to minimise ½·Σρ(‖r‖²) over `observations` with
/// Levenberg–Marquardt, eliminating the points with the Schur complement.
///
/// Parallel with rayon (the current pool); results are identical for any thread count.
///
/// # Errors
/// [`BaError::InvalidConfig`] for bad settings; [`BaError::InvalidProblem`] for out-of-range
/// indices or non-finite inputs; [`BaError::NonFiniteInitialCost`] when the start cannot be
/// evaluated. A step the solver cannot take (not positive definite, non-finite cost) only
/// shrinks the trust region.
pub fn solve<M: CameraModel<C, R>, const C: usize, const R: usize>(
    model: &M,
    cameras: &mut [M::Camera],
    points: &mut [Vector3<f64>],
    observations: &[M::Observation],
    config: &LmConfig,
) -> Result<BaSummary, BaError> {
    config.validate()?;
    validate_problem(model, cameras, points, observations)?;
    let prior_cameras = (0..model.num_priors())
        .map(|k| model.prior_cameras(k))
        .collect();
    let structure = Structure::new(observations, prior_cameras, cameras.len(), points.len());
    let solver =
        ReducedSolver::new::<C>(&structure.pattern, cameras.len(), config.dense_max_unknowns)
            .map_err(|e| BaError::InvalidProblem { reason: e.0 })?;
    let loss = config.loss;
    let initial_cost = total_cost(model, &loss, cameras, points, observations);
    if !initial_cost.is_finite() {
        return Err(BaError::NonFiniteInitialCost { cost: initial_cost });
    }
    let mut summary = BaSummary {
        initial_cost,
        final_cost: initial_cost,
        iterations: 0,
        costs: vec![initial_cost],
        log: Vec::new(),
        termination: Termination::MaxIterations,
        linear_solver: solver.kind(),
    };
    if (observations.is_empty() && model.num_priors() == 0) || initial_cost == 0.0 {
        summary.termination = Termination::NothingToDo;
        return Ok(summary);
    }
    let mut cost = initial_cost;
    let mut radius = config.initial_trust_region_radius;
    let mut decrease_factor = 2.0;
    let mut normal = linearize(model, &loss, &structure, cameras, points, observations);
    if normal.gradient_max_norm <= config.gradient_tolerance {
        summary.termination = Termination::GradientTolerance;
        return Ok(summary);
    }
    while summary.iterations < config.max_iterations {
        summary.iterations += 1;
        let mut entry = IterationLog {
            iteration: summary.iterations,
            cost,
            candidate_cost: f64::NAN,
            accepted: false,
            trust_region_radius: radius,
            gradient_max_norm: normal.gradient_max_norm,
            step_norm: 0.0,
            step_quality: f64::NAN,
        };
        let step = compute_step(
            &normal,
            &structure,
            &solver,
            observations,
            1.0 / radius,
            config,
        );
        let mut stop = None;
        match step {
            Some(step) if step.norm.is_finite() => {
                entry.step_norm = step.norm;
                let new_cameras: Vec<M::Camera> = cameras
                    .par_iter()
                    .zip(step.cameras.par_iter())
                    .map(|(c, d)| model.retract(c, d))
                    .collect();
                let new_points: Vec<Vector3<f64>> = points
                    .iter()
                    .zip(&step.points)
                    .map(|(p, d)| p + d)
                    .collect();
                let x_norm = (cameras
                    .iter()
                    .map(|c| model.parameter_norm_squared(c))
                    .sum::<f64>()
                    + points.iter().map(|p| p.norm_squared()).sum::<f64>())
                .sqrt();
                let candidate_cost =
                    total_cost(model, &loss, &new_cameras, &new_points, observations);
                entry.candidate_cost = candidate_cost;
                let quality = if step.predicted_decrease > 0.0 {
                    (cost - candidate_cost) / step.predicted_decrease
                } else {
                    f64::NAN
                };
                entry.step_quality = quality;
                if step.norm <= config.parameter_tolerance * (x_norm + config.parameter_tolerance) {
                    stop = Some(Termination::ParameterTolerance);
                } else if candidate_cost.is_finite()
                    && (cost - candidate_cost).abs() <= config.function_tolerance * cost
                {
                    stop = Some(Termination::FunctionTolerance);
                }
                if candidate_cost.is_finite() && quality > config.min_relative_decrease {
                    cameras.clone_from_slice(&new_cameras);
                    points.copy_from_slice(&new_points);
                    cost = candidate_cost;
                    entry.accepted = true;
                    radius = (radius / (1.0_f64 / 3.0).max(1.0 - (2.0 * quality - 1.0).powi(3)))
                        .min(config.max_trust_region_radius);
                    decrease_factor = 2.0;
                } else {
                    radius /= decrease_factor;
                    decrease_factor *= 2.0;
                }
            }
            _ => {
                radius /= decrease_factor;
                decrease_factor *= 2.0;
            }
        }
        entry.cost = cost;
        summary.log.push(entry);
        summary.costs.push(cost);
        if let Some(t) = stop {
            summary.termination = t;
            break;
        }
        if radius < config.min_trust_region_radius {
            summary.termination = Termination::TrustRegionCollapsed;
            break;
        }
        if entry.accepted {
            normal = linearize(model, &loss, &structure, cameras, points, observations);
            if normal.gradient_max_norm <= config.gradient_tolerance {
                summary.termination = Termination::GradientTolerance;
                break;
            }
        }
    }
    summary.final_cost = cost;
    Ok(summary)
}
