//! Minimum-snap trajectories through waypoints (Richter, Bry and Roy 2016), with a yaw
//! trajectory, time allocation and time scaling to the motion limits.
//!
//! Each segment is a degree-9 polynomial (10 coefficients) per flat output (x, y, z, yaw). That
//! is the smallest degree whose endpoint values of position through snap (5 each end) determine
//! the polynomial, so the closed-form (unconstrained) QP of Richter et al. applies: the
//! optimisation variables are the derivatives 1–4 at the interior knots, shared by the two
//! segments that meet there, so the trajectory is continuous up to snap by construction.
//! Positions and yaws at all knots are fixed (the waypoints are hit exactly); the start takes
//! the current velocity, acceleration and yaw rate; the end is at rest.
//!
//! The reduced Hessian `H_PP` is symmetric positive definite; it is Jacobi-scaled and factored
//! with faer's Cholesky: dense and sequential (bit-for-bit reproducible) up to 240 unknowns
//! (60 segments), sparse beyond, where its block-tridiagonal structure makes that linear in the
//! number of segments.
//!
//! Time allocation: a trapezoidal-profile guess per segment, then (optionally) gradient descent
//! on the relative segment times at fixed total time, with the analytic gradient from the
//! envelope theorem. Time scaling: all durations are multiplied by one factor, found from dense
//! sampling, until the peak speed, acceleration and yaw rate sit just under their limits.

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt;
use faer::linalg::solvers::Solve;
use faer::sparse::{SparseColMat, Triplet};
use faer::{Mat, Par, Side};
use nalgebra::{Point3, SMatrix, SVector, Vector3, Vector4};
use serde::{Deserialize, Serialize};

use crate::error::{PlanError, check_positive, check_range, check_vector};
use crate::geometry::{Path, Waypoint};

/// Coefficients of one segment polynomial (degree 9).
pub const POLY_COEFFS: usize = 10;
/// Derivatives pinned or shared at each knot: position, velocity, acceleration, jerk, snap.
const KNOT_DERIVS: usize = 5;
/// Flat outputs: x, y, z (metres) and yaw (radians).
pub const FLAT_DIMS: usize = 4;

type Mat10 = SMatrix<f64, POLY_COEFFS, POLY_COEFFS>;
type Vec10 = SVector<f64, POLY_COEFFS>;

/// Tunables of trajectory generation.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct MinSnapConfig {
    /// Speed limit v_max (m/s). Default 1.0 (paper §V; DESIGN defaults).
    pub max_speed_mps: f64,
    /// Acceleration limit a_max (m/s²). Default 1.0 (paper §V; DESIGN fixes the seed's 2.0 typo).
    pub max_accel_mps2: f64,
    /// Yaw-rate limit (rad/s). Default 0.8 (≈ 46°/s; ours: keeps the camera image sharp).
    pub max_yaw_rate_radps: f64,
    /// Time scaling aims at this fraction of each limit, so that the peaks between samples also
    /// stay under it. Default 0.97.
    pub limit_margin: f64,
    /// Scaling stops once the tightest limit is used to at least `1 − scaling_tolerance` of the
    /// margin. Default 0.03.
    pub scaling_tolerance: f64,
    /// Period of the dense sampling that measures the peaks (s). Default 0.01.
    pub sample_period_s: f64,
    /// Gradient steps of the relative time allocation (0 disables it). Default 15.
    pub time_refine_iterations: usize,
    /// Maximum time-scaling rounds before giving up. Default 40.
    pub max_scaling_iterations: usize,
    /// Shortest allowed segment duration (s). Default 0.1.
    pub min_segment_time_s: f64,
    /// Legs longer than this are split into equal segments with intermediate waypoints on the
    /// straight line (and interpolated yaw), so the trajectory can cruise near v_max instead of
    /// following one bell-shaped polynomial (m). 0 disables. Default 8 (longer than the chords of
    /// the fine-localization and ring paths, whose waypoints already shape the curve).
    pub max_segment_length_m: f64,
}

impl Default for MinSnapConfig {
    fn default() -> Self {
        Self {
            max_speed_mps: 1.0,
            max_accel_mps2: 1.0,
            max_yaw_rate_radps: 0.8,
            limit_margin: 0.97,
            scaling_tolerance: 0.03,
            sample_period_s: 0.01,
            time_refine_iterations: 15,
            max_scaling_iterations: 40,
            min_segment_time_s: 0.1,
            max_segment_length_m: 8.0,
        }
    }
}

impl MinSnapConfig {
    /// Checks that every limit and period is finite and positive and the fractions are in range.
    pub fn validate(&self) -> Result<(), PlanError> {
        check_positive("min_snap.max_speed_mps", self.max_speed_mps)?;
        check_positive("min_snap.max_accel_mps2", self.max_accel_mps2)?;
        check_positive("min_snap.max_yaw_rate_radps", self.max_yaw_rate_radps)?;
        check_range("min_snap.limit_margin", self.limit_margin, 0.1, 1.0)?;
        check_range(
            "min_snap.scaling_tolerance",
            self.scaling_tolerance,
            1e-4,
            0.5,
        )?;
        check_positive("min_snap.sample_period_s", self.sample_period_s)?;
        check_positive("min_snap.min_segment_time_s", self.min_segment_time_s)?;
        check_range(
            "min_snap.max_segment_length_m",
            self.max_segment_length_m,
            0.0,
            1e9,
        )?;
        Ok(())
    }
}

/// The vehicle's state when the trajectory starts (world ENU). Position and yaw come from the
/// first waypoint.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct StartState {
    /// Current velocity (m/s).
    pub velocity_mps: Vector3<f64>,
    /// Current acceleration (m/s²).
    pub acceleration_mps2: Vector3<f64>,
    /// Current yaw rate (rad/s).
    pub yaw_rate_radps: f64,
}

/// Flat outputs and their derivatives at one instant (world ENU).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FlatState {
    /// Time since the trajectory start (s).
    pub time_s: f64,
    /// Position (m).
    pub position_m: Point3<f64>,
    /// Velocity (m/s).
    pub velocity_mps: Vector3<f64>,
    /// Acceleration (m/s²).
    pub acceleration_mps2: Vector3<f64>,
    /// Jerk (m/s³).
    pub jerk_mps3: Vector3<f64>,
    /// Snap (m/s⁴).
    pub snap_mps4: Vector3<f64>,
    /// Yaw, unwrapped (rad).
    pub yaw_rad: f64,
    /// Yaw rate (rad/s).
    pub yaw_rate_radps: f64,
    /// Yaw acceleration (rad/s²).
    pub yaw_accel_radps2: f64,
}

impl FlatState {
    /// Hovering at `position_m` with heading `yaw_rad`.
    pub fn hover(position_m: Point3<f64>, yaw_rad: f64) -> Self {
        Self {
            time_s: 0.0,
            position_m,
            velocity_mps: Vector3::zeros(),
            acceleration_mps2: Vector3::zeros(),
            jerk_mps3: Vector3::zeros(),
            snap_mps4: Vector3::zeros(),
            yaw_rad,
            yaw_rate_radps: 0.0,
            yaw_accel_radps2: 0.0,
        }
    }
}

/// One polynomial piece. Coefficients are in normalised time τ = (t − t_start)/duration ∈ [0, 1]:
/// `value(τ) = Σ coeffs[dim][i] τ^i`, dims x, y, z (m) and yaw (rad).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Segment {
    /// Duration (s).
    pub duration_s: f64,
    /// Coefficients per flat output, lowest power first.
    pub coeffs: [[f64; POLY_COEFFS]; FLAT_DIMS],
}

impl Segment {
    /// The `order`-th time derivative of every flat output at normalised time `tau`.
    pub fn derivative(&self, tau: f64, order: usize) -> Vector4<f64> {
        let scale = self.duration_s.powi(-(order as i32));
        let mut out = Vector4::zeros();
        for (d, c) in self.coeffs.iter().enumerate() {
            // Horner on the differentiated polynomial.
            let mut acc = 0.0;
            for i in (order..POLY_COEFFS).rev() {
                acc = acc * tau + c[i] * falling(i, order);
            }
            out[d] = acc * scale;
        }
        out
    }
}

/// i·(i−1)·…·(i−k+1).
fn falling(i: usize, k: usize) -> f64 {
    (0..k).map(|m| (i - m) as f64).product()
}

/// A piecewise-polynomial trajectory starting at t = 0.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Trajectory {
    segments: Vec<Segment>,
    knot_times_s: Vec<f64>,
    /// Knot index of each input waypoint (knots added by subdividing long legs are not listed).
    waypoint_knots: Vec<usize>,
}

impl Trajectory {
    /// Builds a trajectory from segments (no continuity is checked).
    ///
    /// Fails if there is no segment or a duration is not finite and positive.
    pub fn from_segments(segments: Vec<Segment>) -> Result<Self, PlanError> {
        if segments.is_empty() {
            return Err(PlanError::TooFew {
                field: "segments".into(),
                got: 0,
                need: 1,
            });
        }
        let mut knots = Vec::with_capacity(segments.len() + 1);
        knots.push(0.0);
        for (i, s) in segments.iter().enumerate() {
            check_positive(format!("segments[{i}].duration_s"), s.duration_s)?;
            knots.push(knots[i] + s.duration_s);
        }
        Ok(Self {
            waypoint_knots: (0..knots.len()).collect(),
            segments,
            knot_times_s: knots,
        })
    }

    /// Times (s) at which the trajectory passes the input waypoints, in order. Equal to
    /// [`Trajectory::knot_times_s`] unless long legs were subdivided.
    pub fn waypoint_times_s(&self) -> Vec<f64> {
        self.waypoint_knots
            .iter()
            .map(|&k| self.knot_times_s[k])
            .collect()
    }

    /// The polynomial pieces.
    pub fn segments(&self) -> &[Segment] {
        &self.segments
    }

    /// Times of the knots (s), from 0 to the duration; one more than the segments.
    pub fn knot_times_s(&self) -> &[f64] {
        &self.knot_times_s
    }

    /// Total duration (s).
    pub fn duration_s(&self) -> f64 {
        // Invariant: `from_segments` pushes at least two knots.
        self.knot_times_s[self.knot_times_s.len() - 1]
    }

    /// Segment index and normalised time for `t_s`, clamped to the trajectory.
    fn locate(&self, t_s: f64) -> (usize, f64) {
        let n = self.segments.len();
        let t = if t_s.is_finite() {
            t_s.clamp(0.0, self.duration_s())
        } else {
            0.0
        };
        // First knot strictly greater than t, minus one.
        let idx = self
            .knot_times_s
            .partition_point(|&k| k <= t)
            .saturating_sub(1)
            .min(n - 1);
        let tau = ((t - self.knot_times_s[idx]) / self.segments[idx].duration_s).clamp(0.0, 1.0);
        (idx, tau)
    }

    /// The `order`-th derivative of (x, y, z, yaw) at `t_s`, clamped to [0, duration].
    pub fn derivative(&self, t_s: f64, order: usize) -> Vector4<f64> {
        let (i, tau) = self.locate(t_s);
        self.segments[i].derivative(tau, order)
    }

    /// Flat state at `t_s`. Before the start it returns the start state; after the end it returns
    /// the final position at rest.
    pub fn sample(&self, t_s: f64) -> FlatState {
        let (i, tau) = self.locate(t_s);
        let seg = &self.segments[i];
        let d: [Vector4<f64>; 5] = std::array::from_fn(|k| seg.derivative(tau, k));
        let after_end = t_s > self.duration_s();
        let v3 = |k: usize| {
            if after_end && k > 0 {
                Vector3::zeros()
            } else {
                d[k].xyz()
            }
        };
        FlatState {
            time_s: t_s,
            position_m: Point3::from(d[0].xyz()),
            velocity_mps: v3(1),
            acceleration_mps2: v3(2),
            jerk_mps3: v3(3),
            snap_mps4: v3(4),
            yaw_rad: d[0][3],
            yaw_rate_radps: if after_end { 0.0 } else { d[1][3] },
            yaw_accel_radps2: if after_end { 0.0 } else { d[2][3] },
        }
    }

    /// Samples every `period_s` from 0 to the end (the end included).
    pub fn sample_uniform(&self, period_s: f64) -> Vec<FlatState> {
        let period = if period_s.is_finite() && period_s > 0.0 {
            period_s
        } else {
            0.01
        };
        let n = (self.duration_s() / period).ceil() as usize;
        (0..=n)
            .map(|k| self.sample((k as f64 * period).min(self.duration_s())))
            .collect()
    }

    /// Peak speed (m/s), acceleration (m/s²) and |yaw rate| (rad/s) over a dense sampling
    /// (at most `period_s` apart in every segment, both ends of each segment included).
    pub fn peaks(&self, period_s: f64) -> TrajectoryPeaks {
        let mut p = TrajectoryPeaks::default();
        let period = if period_s.is_finite() && period_s > 0.0 {
            period_s
        } else {
            0.01
        };
        for seg in &self.segments {
            // A segment is one degree-7 polynomial: a few thousand samples see its peaks, and
            // the cap keeps an absurdly long segment from stalling the caller.
            let n = (seg.duration_s / period)
                .ceil()
                .clamp(1.0, MAX_PEAK_SAMPLES) as usize;
            for k in 0..=n {
                let tau = k as f64 / n as f64;
                let v = seg.derivative(tau, 1);
                let a = seg.derivative(tau, 2);
                p.speed_mps = p.speed_mps.max(v.xyz().norm());
                p.accel_mps2 = p.accel_mps2.max(a.xyz().norm());
                p.yaw_rate_radps = p.yaw_rate_radps.max(v[3].abs());
            }
        }
        p
    }

    /// ∫ ‖snap‖² dt over the whole trajectory (position only), computed exactly.
    pub fn snap_cost(&self) -> f64 {
        let q = snap_cost_matrix();
        self.segments
            .iter()
            .map(|s| {
                (0..3)
                    .map(|d| {
                        let c = Vec10::from_row_slice(&s.coeffs[d]);
                        (c.transpose() * q * c)[(0, 0)]
                    })
                    .sum::<f64>()
                    * s.duration_s.powi(-7)
            })
            .sum()
    }

    /// The waypoints at the knots (positions and yaws), as a path.
    pub fn knot_path(&self) -> Path {
        Path::new(
            self.knot_times_s
                .iter()
                .map(|&t| {
                    let s = self.sample(t);
                    Waypoint::new(s.position_m, s.yaw_rad)
                })
                .collect(),
        )
    }
}

/// Peaks of a trajectory over dense sampling.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct TrajectoryPeaks {
    /// Peak speed (m/s).
    pub speed_mps: f64,
    /// Peak acceleration magnitude (m/s²).
    pub accel_mps2: f64,
    /// Peak |yaw rate| (rad/s).
    pub yaw_rate_radps: f64,
}

/// Q with ∫₀¹ (p⁗(τ))² dτ = cᵀ Q c.
fn snap_cost_matrix() -> Mat10 {
    Mat10::from_fn(|i, j| {
        if i < 4 || j < 4 {
            0.0
        } else {
            falling(i, 4) * falling(j, 4) / (i + j - 7) as f64
        }
    })
}

/// A: maps coefficients to [derivatives 0..4 at τ = 0, derivatives 0..4 at τ = 1].
fn endpoint_matrix() -> Mat10 {
    Mat10::from_fn(|r, i| {
        let k = r % KNOT_DERIVS;
        if r < KNOT_DERIVS {
            if i == k { falling(i, k) } else { 0.0 }
        } else if i >= k {
            falling(i, k)
        } else {
            0.0
        }
    })
}

/// Precomputed per-basis matrices.
struct Basis {
    a_inv: Mat10,
    /// M = A⁻ᵀ Q A⁻¹: snap cost as a quadratic form in the τ-derivatives at both ends.
    m: Mat10,
}

impl Basis {
    fn new() -> Result<Self, PlanError> {
        let a_inv = endpoint_matrix()
            .try_inverse()
            .ok_or_else(|| PlanError::Solver {
                reason: "endpoint matrix is singular".into(),
            })?;
        let m = a_inv.transpose() * snap_cost_matrix() * a_inv;
        Ok(Self { a_inv, m })
    }

    /// Hessian of one segment's snap cost in physical endpoint derivatives, duration `t`.
    fn segment_hessian(&self, t: f64) -> Mat10 {
        Mat10::from_fn(|a, b| {
            let e = (a % KNOT_DERIVS + b % KNOT_DERIVS) as i32 - 7;
            self.m[(a, b)] * t.powi(e)
        })
    }

    /// d/dt of [`Basis::segment_hessian`].
    fn segment_hessian_dt(&self, t: f64) -> Mat10 {
        Mat10::from_fn(|a, b| {
            let e = (a % KNOT_DERIVS + b % KNOT_DERIVS) as i32 - 7;
            self.m[(a, b)] * f64::from(e) * t.powi(e - 1)
        })
    }
}

/// Reduced systems up to this size use dense Cholesky; larger ones (long lawn-mower patterns)
/// use faer's sparse Cholesky, since H_PP is block-tridiagonal.
const DENSE_MAX_UNKNOWNS: usize = 240;

/// Solves the SPD system given by its lower-triangle triplets in place of `rhs`, densely and
/// sequentially (bit-for-bit reproducible).
fn solve_dense(
    n: usize,
    lower: &[(usize, usize, f64)],
    rhs: &mut Mat<f64>,
) -> Result<(), PlanError> {
    let mut h = Mat::<f64>::zeros(n, n);
    for &(r, c, v) in lower {
        h[(r, c)] += v;
    }
    let mut buf = MemBuffer::new(llt::factor::cholesky_in_place_scratch::<f64>(
        n,
        Par::Seq,
        Default::default(),
    ));
    llt::factor::cholesky_in_place(
        h.as_mut(),
        Default::default(),
        Par::Seq,
        MemStack::new(&mut buf),
        Default::default(),
    )
    .map_err(|e| PlanError::Solver {
        reason: format!("Cholesky of the reduced Hessian failed: {e:?}"),
    })?;
    let mut sbuf = MemBuffer::new(llt::solve::solve_in_place_scratch::<f64>(
        n,
        FLAT_DIMS,
        Par::Seq,
    ));
    llt::solve::solve_in_place(h.as_ref(), rhs.as_mut(), Par::Seq, MemStack::new(&mut sbuf));
    Ok(())
}

/// Sparse counterpart of [`solve_dense`] (faer sparse Cholesky, lower side).
fn solve_sparse(
    n: usize,
    lower: &[(usize, usize, f64)],
    rhs: &mut Mat<f64>,
) -> Result<(), PlanError> {
    let trips: Vec<Triplet<usize, usize, f64>> = lower
        .iter()
        .map(|&(r, c, v)| Triplet::new(r, c, v))
        .collect();
    let h = SparseColMat::<usize, f64>::try_new_from_triplets(n, n, &trips).map_err(|e| {
        PlanError::Solver {
            reason: format!("building the sparse Hessian failed: {e:?}"),
        }
    })?;
    let llt = h.sp_cholesky(Side::Lower).map_err(|e| PlanError::Solver {
        reason: format!("sparse Cholesky of the reduced Hessian failed: {e:?}"),
    })?;
    llt.solve_in_place(rhs.as_mut());
    Ok(())
}

/// Result of one fixed-time solve: the trajectory and all knot derivatives (per dim).
struct Solved {
    trajectory: Trajectory,
    /// knot_values[dim][5·knot + k].
    knot_values: [Vec<f64>; FLAT_DIMS],
}

/// Validates a path for trajectory generation and returns it as a slice.
fn validate_path(path: &Path) -> Result<&[Waypoint], PlanError> {
    if path.waypoints.len() < 2 {
        return Err(PlanError::TooFew {
            field: "waypoints".into(),
            got: path.waypoints.len(),
            need: 2,
        });
    }
    path.validate()?;
    for (i, w) in path.waypoints.windows(2).enumerate() {
        if (w[1].position_m - w[0].position_m).norm() < 1e-9
            && (w[1].yaw_rad - w[0].yaw_rad).abs() < 1e-9
        {
            return Err(PlanError::DuplicateWaypoint { index: i });
        }
    }
    Ok(&path.waypoints)
}

fn validate_start(start: &StartState) -> Result<(), PlanError> {
    check_vector("start.velocity_mps", &start.velocity_mps)?;
    check_vector("start.acceleration_mps2", &start.acceleration_mps2)?;
    crate::error::check_finite("start.yaw_rate_radps", start.yaw_rate_radps)?;
    Ok(())
}

/// Solves the min-snap problem for fixed segment durations.
///
/// `durations_s` has one entry per segment (`waypoints.len() − 1`). Fails on bad input (too few
/// or duplicate waypoints, NaN values, non-positive durations) or if the Cholesky factorisation
/// fails (ill-conditioned durations).
pub fn solve_fixed_times(
    path: &Path,
    start: &StartState,
    durations_s: &[f64],
) -> Result<Trajectory, PlanError> {
    let wps = validate_path(path)?;
    validate_start(start)?;
    if durations_s.len() != wps.len() - 1 {
        return Err(PlanError::InvalidParameter {
            field: "durations_s.len()".into(),
            value: durations_s.len() as f64,
            reason: format!("must equal the number of segments, {}", wps.len() - 1),
        });
    }
    for (i, &t) in durations_s.iter().enumerate() {
        check_positive(format!("durations_s[{i}]"), t)?;
    }
    Ok(solve_inner(&Basis::new()?, wps, start, durations_s)?.trajectory)
}

fn solve_inner(
    basis: &Basis,
    wps: &[Waypoint],
    start: &StartState,
    durations: &[f64],
) -> Result<Solved, PlanError> {
    solve_inner_with(basis, wps, start, durations, DENSE_MAX_UNKNOWNS)
}

/// [`solve_inner`] with the dense/sparse switch point as a parameter.
fn solve_inner_with(
    basis: &Basis,
    wps: &[Waypoint],
    start: &StartState,
    durations: &[f64],
    dense_max_unknowns: usize,
) -> Result<Solved, PlanError> {
    let n_seg = durations.len();
    let n_knots = n_seg + 1;
    let n_vals = KNOT_DERIVS * n_knots;
    let is_free = |g: usize| {
        let knot = g / KNOT_DERIVS;
        let k = g % KNOT_DERIVS;
        k != 0 && knot != 0 && knot != n_seg
    };
    // Fixed values (free entries are filled after the solve).
    let mut values: [Vec<f64>; FLAT_DIMS] = std::array::from_fn(|_| vec![0.0; n_vals]);
    for (knot, w) in wps.iter().enumerate() {
        for (d, v) in values.iter_mut().take(3).enumerate() {
            v[KNOT_DERIVS * knot] = w.position_m[d];
        }
        values[3][KNOT_DERIVS * knot] = w.yaw_rad;
    }
    for (d, v) in values.iter_mut().take(3).enumerate() {
        v[1] = start.velocity_mps[d];
        v[2] = start.acceleration_mps2[d];
    }
    values[3][1] = start.yaw_rate_radps;

    let free_index: Vec<Option<usize>> = {
        let mut next = 0;
        (0..n_vals)
            .map(|g| {
                is_free(g).then(|| {
                    next += 1;
                    next - 1
                })
            })
            .collect()
    };
    let n_free = free_index.iter().filter(|f| f.is_some()).count();

    if n_free > 0 {
        // Lower triangle of H_PP as triplets (duplicates are summed), and the right-hand side
        // −H_PF d_F for the four flat outputs.
        let mut trips: Vec<(usize, usize, f64)> = Vec::with_capacity(n_seg * 64);
        let mut rhs = Mat::<f64>::zeros(n_free, FLAT_DIMS);
        let mut diag = vec![0.0; n_free];
        for (j, &t) in durations.iter().enumerate() {
            let hs = basis.segment_hessian(t);
            let base = KNOT_DERIVS * j;
            for a in 0..POLY_COEFFS {
                let Some(pa) = free_index[base + a] else {
                    continue;
                };
                for b in 0..POLY_COEFFS {
                    let hab = hs[(a, b)];
                    match free_index[base + b] {
                        Some(pb) if pb <= pa => {
                            trips.push((pa, pb, hab));
                            if pa == pb {
                                diag[pa] += hab;
                            }
                        }
                        Some(_) => {}
                        None => {
                            for d in 0..FLAT_DIMS {
                                rhs[(pa, d)] -= hab * values[d][base + b];
                            }
                        }
                    }
                }
            }
        }
        // Jacobi scaling: the entries span many orders of magnitude (T^(k+l−7)).
        let mut scale = vec![0.0; n_free];
        for (i, (s, &d)) in scale.iter_mut().zip(&diag).enumerate() {
            if !(d.is_finite() && d > 0.0) {
                return Err(PlanError::Solver {
                    reason: format!("non-positive Hessian diagonal {d} at free variable {i}"),
                });
            }
            *s = 1.0 / d.sqrt();
        }
        for (r, c, v) in &mut trips {
            *v *= scale[*r] * scale[*c];
        }
        for j in 0..n_free {
            for d in 0..FLAT_DIMS {
                rhs[(j, d)] *= scale[j];
            }
        }
        if n_free <= dense_max_unknowns {
            solve_dense(n_free, &trips, &mut rhs)?;
        } else {
            solve_sparse(n_free, &trips, &mut rhs)?;
        }
        for (g, f) in free_index.iter().enumerate() {
            if let Some(p) = *f {
                for d in 0..FLAT_DIMS {
                    values[d][g] = rhs[(p, d)] * scale[p];
                }
            }
        }
    }

    let mut segments = Vec::with_capacity(n_seg);
    for (j, &t) in durations.iter().enumerate() {
        let base = KNOT_DERIVS * j;
        let mut coeffs = [[0.0; POLY_COEFFS]; FLAT_DIMS];
        for d in 0..FLAT_DIMS {
            let d_tau =
                Vec10::from_fn(|a, _| values[d][base + a] * t.powi((a % KNOT_DERIVS) as i32));
            let c = basis.a_inv * d_tau;
            if c.iter().any(|v| !v.is_finite()) {
                return Err(PlanError::Solver {
                    reason: format!("non-finite coefficients in segment {j}"),
                });
            }
            coeffs[d].copy_from_slice(c.as_slice());
        }
        segments.push(Segment {
            duration_s: t,
            coeffs,
        });
    }
    Ok(Solved {
        trajectory: Trajectory::from_segments(segments)?,
        knot_values: values,
    })
}

/// Position snap cost and its gradient with respect to each duration (envelope theorem: at the
/// optimum, dJ/dT_j = dᵀ (∂H_j/∂T_j) d with the free derivatives held).
fn cost_and_gradient(basis: &Basis, solved: &Solved, durations: &[f64]) -> (f64, Vec<f64>) {
    let mut cost = 0.0;
    let mut grad = vec![0.0; durations.len()];
    for (j, &t) in durations.iter().enumerate() {
        let h = basis.segment_hessian(t);
        let hd = basis.segment_hessian_dt(t);
        for d in 0..3 {
            let v = Vec10::from_fn(|a, _| solved.knot_values[d][KNOT_DERIVS * j + a]);
            cost += (v.transpose() * h * v)[(0, 0)];
            grad[j] += (v.transpose() * hd * v)[(0, 0)];
        }
    }
    (cost, grad)
}

/// Rest-to-rest trapezoidal time for `distance` under `v_max`, `a_max`.
fn trapezoid_time(distance: f64, v_max: f64, a_max: f64) -> f64 {
    if distance >= v_max * v_max / a_max {
        distance / v_max + v_max / a_max
    } else {
        2.0 * (distance / a_max).sqrt()
    }
}

/// The initial time allocation: per segment, the larger of the rest-to-rest trapezoidal time of
/// its length and its yaw change at the yaw-rate limit, at least `min_segment_time_s`.
pub fn initial_durations(path: &Path, cfg: &MinSnapConfig) -> Vec<f64> {
    path.waypoints
        .windows(2)
        .map(|w| {
            let dist = (w[1].position_m - w[0].position_m).norm();
            let t_pos = trapezoid_time(dist, cfg.max_speed_mps, cfg.max_accel_mps2);
            let t_yaw = 2.0 * (w[1].yaw_rad - w[0].yaw_rad).abs() / cfg.max_yaw_rate_radps;
            t_pos.max(t_yaw).max(cfg.min_segment_time_s)
        })
        .collect()
}

/// Gradient descent on the relative durations at fixed total time.
fn refine_durations(
    basis: &Basis,
    wps: &[Waypoint],
    start: &StartState,
    mut durations: Vec<f64>,
    cfg: &MinSnapConfig,
) -> Result<Vec<f64>, PlanError> {
    let n = durations.len();
    if n < 2 || cfg.time_refine_iterations == 0 {
        return Ok(durations);
    }
    let mut solved = solve_inner(basis, wps, start, &durations)?;
    let (mut cost, mut grad) = cost_and_gradient(basis, &solved, &durations);
    for _ in 0..cfg.time_refine_iterations {
        // Project out the component that changes the total time.
        let mean = grad.iter().sum::<f64>() / n as f64;
        let dir: Vec<f64> = grad.iter().map(|g| -(g - mean)).collect();
        // Step so that the largest relative change is 10 %.
        let max_rel = dir
            .iter()
            .zip(&durations)
            .map(|(g, t)| (g / t).abs())
            .fold(0.0, f64::max);
        if !(max_rel.is_finite() && max_rel > 0.0) {
            break;
        }
        let mut step = 0.1 / max_rel;
        let mut improved = false;
        for _ in 0..8 {
            let trial: Vec<f64> = durations
                .iter()
                .zip(&dir)
                .map(|(t, g)| (t + step * g).max(cfg.min_segment_time_s))
                .collect();
            if let Ok(s) = solve_inner(basis, wps, start, &trial) {
                let (c, g) = cost_and_gradient(basis, &s, &trial);
                if c < cost {
                    durations = trial;
                    solved = s;
                    cost = c;
                    grad = g;
                    improved = true;
                    break;
                }
            }
            step *= 0.5;
        }
        if !improved {
            break;
        }
    }
    drop(solved);
    Ok(durations)
}

/// Splits legs longer than `max_len` (0 = never) into equal pieces; returns the new path and
/// the index of each original waypoint in it.
fn subdivide(wps: &[Waypoint], max_len: f64) -> (Path, Vec<usize>) {
    let mut out = Vec::with_capacity(wps.len());
    let mut index = Vec::with_capacity(wps.len());
    for (i, w) in wps.iter().enumerate() {
        if i > 0 && max_len > 0.0 {
            let a = wps[i - 1];
            let len = (w.position_m - a.position_m).norm();
            let pieces = (len / max_len).ceil() as usize;
            for k in 1..pieces {
                let f = k as f64 / pieces as f64;
                out.push(Waypoint::new(
                    a.position_m + (w.position_m - a.position_m) * f,
                    a.yaw_rad + (w.yaw_rad - a.yaw_rad) * f,
                ));
            }
        }
        index.push(out.len());
        out.push(*w);
    }
    (Path::new(out), index)
}

/// Samples per segment at most when looking for a trajectory's peaks.
const MAX_PEAK_SAMPLES: f64 = 4096.0;

/// Longest trajectory the time scaling may produce (s): beyond it the scaling has diverged.
const MAX_TRAJECTORY_S: f64 = 36_000.0;

/// Plans a minimum-snap trajectory through `path`, starting from `start` and ending at rest,
/// then scales time so that speed, acceleration and yaw rate stay within `cfg`'s limits
/// (verified by dense sampling at `cfg.sample_period_s`).
///
/// Legs longer than `cfg.max_segment_length_m` get intermediate waypoints on the straight line
/// (see [`Trajectory::waypoint_times_s`] for when the input waypoints are passed).
///
/// The first waypoint is the start position and yaw. Fails on bad input (fewer than 2
/// waypoints, NaN, identical consecutive waypoints), a start faster than the limits, a failed
/// solve, or if scaling cannot meet the limits.
///
/// A moving start can make the limits unreachable at any timing: stretching time does not
/// scale the start's velocity, and it multiplies the velocity a fixed start acceleration
/// builds up. Then the start's acceleration and yaw rate are dropped, and failing that its
/// velocity too; the reference steps there (by at most the start state, which the controller
/// absorbs), and the trajectory meets the limits.
pub fn plan_min_snap(
    path: &Path,
    start: &StartState,
    cfg: &MinSnapConfig,
) -> Result<Trajectory, PlanError> {
    let exact = plan_min_snap_from(path, start, cfg);
    let rest = StartState::default();
    let timing_failed = matches!(
        exact,
        Err(PlanError::Solver { .. } | PlanError::LimitsNotMet { .. })
    );
    if !timing_failed || *start == rest {
        return exact;
    }
    let velocity_only = StartState {
        velocity_mps: start.velocity_mps,
        ..rest
    };
    plan_min_snap_from(path, &velocity_only, cfg)
        .or_else(|_| plan_min_snap_from(path, &rest, cfg))
        .or(exact)
}

/// [`plan_min_snap`] with `start` held exactly.
fn plan_min_snap_from(
    path: &Path,
    start: &StartState,
    cfg: &MinSnapConfig,
) -> Result<Trajectory, PlanError> {
    cfg.validate()?;
    let wps = validate_path(path)?;
    validate_start(start)?;
    let v0 = start.velocity_mps.norm();
    if v0 > cfg.max_speed_mps {
        return Err(PlanError::StartTooFast {
            speed_mps: v0,
            v_max_mps: cfg.max_speed_mps,
        });
    }
    let basis = Basis::new()?;
    let (dense_path, waypoint_knots) = subdivide(wps, cfg.max_segment_length_m);
    let wps = &dense_path.waypoints[..];
    let durations = initial_durations(&dense_path, cfg);
    let mut durations = refine_durations(&basis, wps, start, durations, cfg)?;

    // The start values cannot be scaled away: never aim below them.
    let v_lim = (cfg.limit_margin * cfg.max_speed_mps).max(v0);
    let a_lim = (cfg.limit_margin * cfg.max_accel_mps2).max(start.acceleration_mps2.norm());
    let w_lim = (cfg.limit_margin * cfg.max_yaw_rate_radps).max(start.yaw_rate_radps.abs());
    // The hard limits, which the margin above aims under.
    let v_max = cfg.max_speed_mps.max(v0);
    let a_max = cfg.max_accel_mps2.max(start.acceleration_mps2.norm());
    let w_max = cfg.max_yaw_rate_radps.max(start.yaw_rate_radps.abs());
    let mut best_feasible: Option<Trajectory> = None;
    // The trajectory with the lowest peaks relative to the hard limits, and that ratio.
    let mut least_over: Option<(f64, Trajectory)> = None;
    let mut last_peaks = TrajectoryPeaks::default();
    for _ in 0..cfg.max_scaling_iterations.max(1) {
        let total_s: f64 = durations.iter().sum();
        if !(total_s.is_finite() && total_s <= MAX_TRAJECTORY_S) {
            if least_over
                .as_ref()
                .is_some_and(|(over_hard, _)| *over_hard <= 1.0)
            {
                break;
            }
            return Err(PlanError::Solver {
                reason: format!(
                    "time scaling stretched the trajectory to {total_s:.3e} s (more than {MAX_TRAJECTORY_S} s): the waypoints cannot be flown within the limits"
                ),
            });
        }
        let traj = solve_inner(&basis, wps, start, &durations)?.trajectory;
        let p = traj.peaks(cfg.sample_period_s);
        last_peaks = p;
        let ratio = (p.speed_mps / v_lim)
            .max((p.accel_mps2 / a_lim).sqrt())
            .max(p.yaw_rate_radps / w_lim);
        if !ratio.is_finite() || ratio <= 0.0 {
            // Nothing moves (cannot happen for validated waypoints); keep the allocation.
            return Ok(traj);
        }
        if ratio <= 1.0 {
            let done = ratio >= 1.0 - cfg.scaling_tolerance;
            best_feasible = Some(traj);
            if done {
                break;
            }
        } else {
            // A start speed (or acceleration) near the limit is not scaled away, and the
            // trajectory leaving it overshoots it by a fixed factor: stretching may never get
            // under the margin. Then the trajectory with the lowest peaks is the answer, if
            // they are within the hard limits.
            let over_hard = (p.speed_mps / v_max)
                .max((p.accel_mps2 / a_max).sqrt())
                .max(p.yaw_rate_radps / w_max);
            if least_over.as_ref().is_none_or(|(r, _)| over_hard < *r) {
                least_over = Some((over_hard, traj));
            }
        }
        // Over the limit: stretch a little more than needed, so the loop terminates even when
        // the start state makes the scaling inexact.
        let factor = if ratio > 1.0 {
            ratio * 1.005
        } else {
            ratio.max(0.5)
        };
        for t in &mut durations {
            *t = (*t * factor).max(cfg.min_segment_time_s);
        }
    }
    best_feasible
        .or_else(|| {
            least_over
                .filter(|(over_hard, _)| *over_hard <= 1.0)
                .map(|(_, t)| t)
        })
        .map(|mut t| {
            t.waypoint_knots = waypoint_knots;
            t
        })
        .ok_or(PlanError::LimitsNotMet {
            speed_mps: last_peaks.speed_mps,
            accel_mps2: last_peaks.accel_mps2,
            v_max_mps: cfg.max_speed_mps,
            a_max_mps2: cfg.max_accel_mps2,
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn basis_matrices_are_consistent() {
        let b = Basis::new().unwrap();
        let a = endpoint_matrix();
        let eye = a * b.a_inv;
        assert!((eye - Mat10::identity()).abs().max() < 1e-8);
        // M is symmetric positive semi-definite.
        assert!((b.m - b.m.transpose()).abs().max() < 1e-6 * b.m.abs().max());
    }

    #[test]
    fn single_segment_rest_to_rest() {
        let path = Path::new(vec![
            Waypoint::new(Point3::new(0.0, 0.0, 1.0), 0.0),
            Waypoint::new(Point3::new(2.0, 0.0, 1.0), 0.5),
        ]);
        let traj = solve_fixed_times(&path, &StartState::default(), &[4.0]).unwrap();
        let end = traj.sample(4.0);
        assert!((end.position_m - Point3::new(2.0, 0.0, 1.0)).norm() < 1e-12);
        assert!(end.velocity_mps.norm() < 1e-12);
        // Symmetric profile: halfway at half time.
        assert!((traj.sample(2.0).position_m.x - 1.0).abs() < 1e-12);
    }

    #[test]
    fn sparse_and_dense_solves_agree() {
        let basis = Basis::new().unwrap();
        let wps: Vec<Waypoint> = (0..90)
            .map(|i| {
                let t = i as f64 * 0.7;
                Waypoint::new(
                    Point3::new(10.0 * t.cos() + t, 10.0 * t.sin(), 5.0 + (2.0 * t).sin()),
                    0.1 * t,
                )
            })
            .collect();
        let durations = vec![3.0; wps.len() - 1];
        let start = StartState {
            velocity_mps: Vector3::new(0.3, 0.0, 0.1),
            ..Default::default()
        };
        let dense = solve_inner_with(&basis, &wps, &start, &durations, usize::MAX).unwrap();
        let sparse = solve_inner_with(&basis, &wps, &start, &durations, 0).unwrap();
        for d in 0..FLAT_DIMS {
            for (a, b) in dense.knot_values[d].iter().zip(&sparse.knot_values[d]) {
                assert!((a - b).abs() < 1e-9 * (1.0 + a.abs()), "{a} vs {b}");
            }
        }
        let (c0, _) = cost_and_gradient(&basis, &dense, &durations);
        assert!(c0.is_finite() && c0 > 0.0);
    }

    #[test]
    fn gradient_matches_finite_difference() {
        let basis = Basis::new().unwrap();
        let wps = vec![
            Waypoint::new(Point3::new(0.0, 0.0, 0.0), 0.0),
            Waypoint::new(Point3::new(1.0, 2.0, 0.0), 0.0),
            Waypoint::new(Point3::new(3.0, 1.0, 1.0), 0.0),
            Waypoint::new(Point3::new(4.0, -1.0, 0.5), 0.0),
        ];
        let start = StartState::default();
        let t = vec![2.0, 2.5, 3.0];
        let s = solve_inner(&basis, &wps, &start, &t).unwrap();
        let (_, g) = cost_and_gradient(&basis, &s, &t);
        for j in 0..3 {
            let h = 1e-5;
            let mut tp = t.clone();
            tp[j] += h;
            let mut tm = t.clone();
            tm[j] -= h;
            let cp = cost_and_gradient(
                &basis,
                &solve_inner(&basis, &wps, &start, &tp).unwrap(),
                &tp,
            )
            .0;
            let cm = cost_and_gradient(
                &basis,
                &solve_inner(&basis, &wps, &start, &tm).unwrap(),
                &tm,
            )
            .0;
            let fd = (cp - cm) / (2.0 * h);
            assert!(
                (fd - g[j]).abs() < 1e-4 * fd.abs().max(1e-6),
                "{j}: {fd} vs {}",
                g[j]
            );
        }
    }
}
