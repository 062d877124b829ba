//! Trajectory error as the TUM RGB-D benchmark tools (`associate.py`, `evaluate_ate.py`,
//! `evaluate_rpe.py`) define it.
//!
//! - **Association.** Estimated and ground-truth poses are paired by timestamp: candidate pairs
//!   within `max_dt_s` are taken greedily, closest first, each pose at most once.
//! - **ATE** (absolute trajectory error). The estimated positions are aligned to the ground truth
//!   by Horn/Umeyama least squares (SE(3), Sim(3) or none); the errors are the distances between
//!   aligned estimated and true positions.
//! - **RPE** (relative pose error). For associated pairs (i, j) the error is
//!   E = (Gᵢ⁻¹Gⱼ)⁻¹(Pᵢ⁻¹Pⱼ); its translation norm and rotation angle are reported as RMSEs, for
//!   consecutive pairs (per frame), for pairs 1 m of true path apart (per metre, divided by the
//!   path length) and for pairs 1 s apart (per second). With Sim(3) alignment the estimate's
//!   translations are scaled by the alignment scale first.

use nalgebra::{Isometry3, Matrix3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};
use scarp_export::tum::StampedPose;
use serde::{Deserialize, Serialize};
use thiserror::Error;

/// How the estimate is aligned to the ground truth before the ATE.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Alignment {
    /// Rotation and translation (Horn).
    Se3,
    /// Rotation, translation and scale (Umeyama).
    Sim3,
    /// No alignment: both are in the same world frame.
    None,
}

impl std::str::FromStr for Alignment {
    type Err = String;

    /// Parses the names that the config files use: `se3`, `sim3` or `none` (any case).
    fn from_str(name: &str) -> Result<Self, Self::Err> {
        match name.to_ascii_lowercase().as_str() {
            "se3" => Ok(Self::Se3),
            "sim3" => Ok(Self::Sim3),
            "none" => Ok(Self::None),
            _ => Err(format!(
                "unknown alignment `{name}`: expected `se3`, `sim3` or `none`"
            )),
        }
    }
}

/// Settings of [`evaluate_trajectory`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TrajectoryEvalConfig {
    /// Largest timestamp difference of an associated pair, seconds. Default 0.02 s (TUM).
    pub max_dt_s: f64,
    /// Alignment before the ATE. Default SE(3).
    pub alignment: Alignment,
    /// True path length between the poses of a per-metre RPE pair. Default 1 m.
    pub rpe_distance_m: f64,
    /// Time between the poses of a per-second RPE pair. Default 1 s.
    pub rpe_interval_s: f64,
}

impl Default for TrajectoryEvalConfig {
    fn default() -> Self {
        Self {
            max_dt_s: 0.02,
            alignment: Alignment::Se3,
            rpe_distance_m: 1.0,
            rpe_interval_s: 1.0,
        }
    }
}

/// Why a trajectory could not be evaluated.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum TrajectoryEvalError {
    /// Too few poses were associated by timestamp.
    #[error("only {pairs} poses associated within {max_dt_s} s; {required} needed")]
    TooFewPairs {
        /// Pairs found.
        pairs: usize,
        /// Pairs needed (1 without alignment, 3 with).
        required: usize,
        /// The association window, seconds.
        max_dt_s: f64,
    },
    /// A setting is out of range.
    #[error("invalid trajectory evaluation setting `{field}`: {reason}")]
    InvalidConfig {
        /// The field.
        field: &'static str,
        /// Why.
        reason: &'static str,
    },
    /// The alignment has no unique answer (all positions equal).
    #[error("alignment is degenerate: {0}")]
    Degenerate(&'static str),
}

/// The trajectory metrics (JSON field names are the interface other tools rely on).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrajectoryMetrics {
    /// ATE root mean square, metres.
    pub ate_rmse_m: f64,
    /// ATE mean, metres.
    pub ate_mean_m: f64,
    /// ATE median, metres.
    pub ate_median_m: f64,
    /// ATE maximum, metres.
    pub ate_max_m: f64,
    /// RPE translation RMSE over consecutive associated pairs, metres per frame.
    pub rpe_trans_m_per_frame: f64,
    /// RPE translation RMSE per metre of true path (dimensionless); `None` when the path is
    /// shorter than `rpe_distance_m`.
    pub rpe_trans_per_m: Option<f64>,
    /// RPE translation RMSE per second, metres per second; `None` when the trajectory is shorter
    /// than `rpe_interval_s`.
    pub rpe_trans_m_per_s: Option<f64>,
    /// RPE rotation RMSE over consecutive associated pairs, degrees per frame.
    pub rpe_rot_deg_per_frame: f64,
    /// Associated pose pairs.
    pub pairs: usize,
    /// The alignment used.
    pub alignment: Alignment,
    /// The alignment scale (1 unless Sim(3)).
    pub scale: f64,
}

/// A similarity transform y = s·R·x + t.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Similarity {
    /// Scale s.
    pub scale: f64,
    /// Rotation R.
    pub rotation: Rotation3<f64>,
    /// Translation t.
    pub translation: Vector3<f64>,
}

impl Similarity {
    /// The identity.
    pub fn identity() -> Self {
        Self {
            scale: 1.0,
            rotation: Rotation3::identity(),
            translation: Vector3::zeros(),
        }
    }

    /// Applies the transform to a point.
    pub fn apply(&self, x: &Vector3<f64>) -> Vector3<f64> {
        self.scale * (self.rotation * x) + self.translation
    }
}

/// Pairs estimated and true poses by timestamp (TUM `associate.py`): every pair within
/// `max_dt_s` is a candidate; candidates are taken closest first, each pose once. Returns
/// `(ground_truth_index, estimate_index)` sorted by the estimate's timestamp.
pub fn associate(
    ground_truth: &[StampedPose],
    estimate: &[StampedPose],
    max_dt_s: f64,
) -> Vec<(usize, usize)> {
    let mut gt_order: Vec<usize> = (0..ground_truth.len())
        .filter(|&i| ground_truth[i].timestamp_s.is_finite())
        .collect();
    gt_order.sort_by(|&a, &b| {
        ground_truth[a]
            .timestamp_s
            .total_cmp(&ground_truth[b].timestamp_s)
    });
    let gt_times: Vec<f64> = gt_order
        .iter()
        .map(|&i| ground_truth[i].timestamp_s)
        .collect();
    let mut candidates = Vec::new();
    for (e, pose) in estimate.iter().enumerate() {
        let t = pose.timestamp_s;
        if !t.is_finite() {
            continue;
        }
        let start = gt_times.partition_point(|&g| g < t - max_dt_s);
        for k in start..gt_times.len() {
            let dt = (gt_times[k] - t).abs();
            if gt_times[k] > t + max_dt_s {
                break;
            }
            if dt <= max_dt_s {
                candidates.push((dt, gt_order[k], e));
            }
        }
    }
    candidates.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)).then(a.2.cmp(&b.2)));
    let mut gt_used = vec![false; ground_truth.len()];
    let mut est_used = vec![false; estimate.len()];
    let mut pairs = Vec::new();
    for (_, g, e) in candidates {
        if !gt_used[g] && !est_used[e] {
            gt_used[g] = true;
            est_used[e] = true;
            pairs.push((g, e));
        }
    }
    pairs.sort_by(|a, b| {
        estimate[a.1]
            .timestamp_s
            .total_cmp(&estimate[b.1].timestamp_s)
    });
    pairs
}

/// Least-squares alignment y ≈ s·R·x + t of `source` onto `target` (Umeyama 1991; Horn's
/// closed form when `with_scale` is false). The two slices pair up by index.
///
/// # Errors
/// [`TrajectoryEvalError::Degenerate`] when the slices are empty or differ in length, or the
/// source points all coincide while a scale is wanted.
pub fn umeyama(
    source: &[Vector3<f64>],
    target: &[Vector3<f64>],
    with_scale: bool,
) -> Result<Similarity, TrajectoryEvalError> {
    if source.is_empty() || source.len() != target.len() {
        return Err(TrajectoryEvalError::Degenerate(
            "alignment needs equally many source and target points",
        ));
    }
    let n = source.len() as f64;
    let mu_x = source.iter().sum::<Vector3<f64>>() / n;
    let mu_y = target.iter().sum::<Vector3<f64>>() / n;
    let mut cov = Matrix3::zeros();
    let mut var_x = 0.0;
    for (x, y) in source.iter().zip(target) {
        let (dx, dy) = (x - mu_x, y - mu_y);
        cov += dy * dx.transpose();
        var_x += dx.norm_squared();
    }
    cov /= n;
    var_x /= n;
    let svd = cov.svd(true, true);
    let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else {
        return Err(TrajectoryEvalError::Degenerate("SVD failed"));
    };
    let mut s = Matrix3::identity();
    if u.determinant() * v_t.determinant() < 0.0 {
        s[(2, 2)] = -1.0;
    }
    let rotation = Rotation3::from_matrix_unchecked(u * s * v_t);
    let scale = if with_scale {
        if var_x.is_nan() || var_x <= 0.0 {
            return Err(TrajectoryEvalError::Degenerate(
                "all estimated positions coincide; no scale",
            ));
        }
        (Matrix3::from_diagonal(&svd.singular_values) * s).trace() / var_x
    } else {
        1.0
    };
    let translation = mu_y - scale * (rotation * mu_x);
    Ok(Similarity {
        scale,
        rotation,
        translation,
    })
}

fn rmse(values: &[f64]) -> f64 {
    if values.is_empty() {
        return 0.0;
    }
    (values.iter().map(|v| v * v).sum::<f64>() / values.len() as f64).sqrt()
}

fn median(values: &[f64]) -> f64 {
    scarp_slam::stats::median(values).unwrap_or(0.0)
}

/// The relative pose error E = (Gᵢ⁻¹Gⱼ)⁻¹(Pᵢ⁻¹Pⱼ): (translation norm, rotation angle in rad).
pub fn relative_pose_error(
    gt_i: &Isometry3<f64>,
    gt_j: &Isometry3<f64>,
    est_i: &Isometry3<f64>,
    est_j: &Isometry3<f64>,
) -> (f64, f64) {
    let e = (gt_i.inverse() * gt_j).inverse() * (est_i.inverse() * est_j);
    (e.translation.vector.norm(), e.rotation.angle())
}

/// Evaluates `estimate` against `ground_truth`.
///
/// # Errors
/// [`TrajectoryEvalError::TooFewPairs`] (fewer than 3 associated pairs with alignment, 1
/// without); [`TrajectoryEvalError::InvalidConfig`]; [`TrajectoryEvalError::Degenerate`].
pub fn evaluate_trajectory(
    ground_truth: &[StampedPose],
    estimate: &[StampedPose],
    config: &TrajectoryEvalConfig,
) -> Result<TrajectoryMetrics, TrajectoryEvalError> {
    for (field, value) in [
        ("max_dt_s", config.max_dt_s),
        ("rpe_distance_m", config.rpe_distance_m),
        ("rpe_interval_s", config.rpe_interval_s),
    ] {
        if !(value.is_finite() && value >= 0.0) {
            return Err(TrajectoryEvalError::InvalidConfig {
                field,
                reason: "must be finite and non-negative",
            });
        }
    }
    let pairs = associate(ground_truth, estimate, config.max_dt_s);
    let required = if config.alignment == Alignment::None {
        1
    } else {
        3
    };
    if pairs.len() < required {
        return Err(TrajectoryEvalError::TooFewPairs {
            pairs: pairs.len(),
            required,
            max_dt_s: config.max_dt_s,
        });
    }
    let gt: Vec<&StampedPose> = pairs.iter().map(|&(g, _)| &ground_truth[g]).collect();
    let est: Vec<&StampedPose> = pairs.iter().map(|&(_, e)| &estimate[e]).collect();
    let gt_pos: Vec<Vector3<f64>> = gt
        .iter()
        .map(|p| p.world_from_camera.translation.vector)
        .collect();
    let est_pos: Vec<Vector3<f64>> = est
        .iter()
        .map(|p| p.world_from_camera.translation.vector)
        .collect();
    let alignment = match config.alignment {
        Alignment::None => Similarity::identity(),
        Alignment::Se3 => umeyama(&est_pos, &gt_pos, false)?,
        Alignment::Sim3 => umeyama(&est_pos, &gt_pos, true)?,
    };
    let ate: Vec<f64> = est_pos
        .iter()
        .zip(&gt_pos)
        .map(|(x, y)| (alignment.apply(x) - y).norm())
        .collect();

    // RPE on the estimate scaled by the alignment scale (1 unless Sim(3)).
    let scaled: Vec<Isometry3<f64>> = est
        .iter()
        .map(|p| {
            let t = p.world_from_camera;
            Isometry3::from_parts(
                Translation3::from(t.translation.vector * alignment.scale),
                t.rotation,
            )
        })
        .collect();
    let gt_iso: Vec<Isometry3<f64>> = gt.iter().map(|p| p.world_from_camera).collect();
    let (mut trans, mut rot) = (Vec::new(), Vec::new());
    for i in 0..gt.len().saturating_sub(1) {
        let (t, r) = relative_pose_error(&gt_iso[i], &gt_iso[i + 1], &scaled[i], &scaled[i + 1]);
        trans.push(t);
        rot.push(r.to_degrees());
    }
    // Cumulative true path length.
    let mut path = vec![0.0; gt.len()];
    for i in 1..gt.len() {
        path[i] = path[i - 1] + (gt_pos[i] - gt_pos[i - 1]).norm();
    }
    let per_metre = paired_errors(&path, config.rpe_distance_m, &gt_iso, &scaled);
    let times: Vec<f64> = gt.iter().map(|p| p.timestamp_s).collect();
    let per_second = paired_errors(&times, config.rpe_interval_s, &gt_iso, &scaled);
    let mean = ate.iter().sum::<f64>() / ate.len() as f64;
    Ok(TrajectoryMetrics {
        ate_rmse_m: rmse(&ate),
        ate_mean_m: mean,
        ate_median_m: median(&ate),
        ate_max_m: ate.iter().copied().fold(0.0, f64::max),
        rpe_trans_m_per_frame: rmse(&trans),
        rpe_trans_per_m: per_metre,
        rpe_trans_m_per_s: per_second,
        rpe_rot_deg_per_frame: rmse(&rot),
        pairs: pairs.len(),
        alignment: config.alignment,
        scale: alignment.scale,
    })
}

/// RMSE of the RPE translation divided by the spacing, over pairs (i, j) where j is the first
/// index whose `axis` value is at least `spacing` beyond i's. `None` when no pair exists.
fn paired_errors(
    axis: &[f64],
    spacing: f64,
    gt: &[Isometry3<f64>],
    est: &[Isometry3<f64>],
) -> Option<f64> {
    let mut normalised = Vec::new();
    let mut j = 0;
    for i in 0..axis.len() {
        j = j.max(i + 1);
        while j < axis.len() && axis[j] - axis[i] < spacing {
            j += 1;
        }
        if j >= axis.len() {
            break;
        }
        let span = axis[j] - axis[i];
        if span > 0.0 {
            let (t, _) = relative_pose_error(&gt[i], &gt[j], &est[i], &est[j]);
            normalised.push(t / span);
        }
    }
    (!normalised.is_empty()).then(|| rmse(&normalised))
}

/// Helper for tests and callers: a pose at `position` with `rotation`.
pub fn pose_at(
    timestamp_s: f64,
    position: Point3<f64>,
    rotation: UnitQuaternion<f64>,
) -> StampedPose {
    StampedPose {
        timestamp_s,
        world_from_camera: Isometry3::from_parts(Translation3::from(position.coords), rotation),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square(n: usize) -> Vec<StampedPose> {
        // A 1 m square walked in n steps per side, at 10 Hz, camera turning slowly.
        let corners = [
            Vector3::new(0.0, 0.0, 0.0),
            Vector3::new(1.0, 0.0, 0.0),
            Vector3::new(1.0, 1.0, 0.0),
            Vector3::new(0.0, 1.0, 0.5),
        ];
        let mut out = Vec::new();
        for side in 0..4 {
            for k in 0..n {
                let a = corners[side];
                let b = corners[(side + 1) % 4];
                let p = a + (b - a) * (k as f64 / n as f64);
                let idx = side * n + k;
                out.push(pose_at(
                    idx as f64 * 0.1,
                    Point3::from(p),
                    UnitQuaternion::from_euler_angles(0.0, 0.0, idx as f64 * 0.05),
                ));
            }
        }
        out
    }

    #[test]
    fn identical_trajectories_have_zero_error() {
        let gt = square(5);
        let m = evaluate_trajectory(&gt, &gt, &TrajectoryEvalConfig::default()).unwrap();
        assert_eq!(m.pairs, 20);
        assert!(m.ate_rmse_m < 1e-12 && m.rpe_trans_m_per_frame < 1e-12);
        assert!(m.rpe_rot_deg_per_frame < 1e-9);
        assert!(m.rpe_trans_per_m.unwrap() < 1e-12);
    }

    #[test]
    fn sim3_alignment_removes_a_known_rotation_translation_and_scale() {
        let gt = square(5);
        let g = Similarity {
            scale: 2.5,
            rotation: Rotation3::from_euler_angles(0.3, -0.2, 1.1),
            translation: Vector3::new(4.0, -3.0, 2.0),
        };
        let est: Vec<StampedPose> = gt
            .iter()
            .map(|p| StampedPose {
                timestamp_s: p.timestamp_s + 0.005,
                world_from_camera: Isometry3::from_parts(
                    Translation3::from(g.apply(&p.world_from_camera.translation.vector)),
                    UnitQuaternion::from_rotation_matrix(&g.rotation)
                        * p.world_from_camera.rotation,
                ),
            })
            .collect();
        let sim = TrajectoryEvalConfig {
            alignment: Alignment::Sim3,
            ..Default::default()
        };
        let m = evaluate_trajectory(&gt, &est, &sim).unwrap();
        assert!(m.ate_rmse_m < 1e-9, "{m:?}");
        assert!((m.scale - 1.0 / 2.5).abs() < 1e-9);
        // SE(3) cannot remove the scale: the error is the scaled square's spread.
        let se3 = evaluate_trajectory(&gt, &est, &TrajectoryEvalConfig::default()).unwrap();
        assert!(se3.ate_rmse_m > 0.5);
    }

    #[test]
    fn hand_computed_ate_and_rpe_without_alignment() {
        // Truth: 0, 1, 2, 3 m along x. Estimate offsets (y): 0, 0.1, 0, -0.2.
        let q = UnitQuaternion::identity();
        let gt: Vec<_> = (0..4)
            .map(|i| pose_at(i as f64, Point3::new(i as f64, 0.0, 0.0), q))
            .collect();
        let dy = [0.0, 0.1, 0.0, -0.2];
        let est: Vec<_> = (0..4)
            .map(|i| pose_at(i as f64 + 0.01, Point3::new(i as f64, dy[i], 0.0), q))
            .collect();
        let cfg = TrajectoryEvalConfig {
            alignment: Alignment::None,
            ..Default::default()
        };
        let m = evaluate_trajectory(&gt, &est, &cfg).unwrap();
        assert_eq!(m.pairs, 4);
        assert!((m.ate_rmse_m - (0.05f64 / 4.0).sqrt()).abs() < 1e-12);
        assert!((m.ate_mean_m - 0.075).abs() < 1e-12);
        assert!((m.ate_median_m - 0.05).abs() < 1e-12);
        assert!((m.ate_max_m - 0.2).abs() < 1e-12);
        // Consecutive RPEs: |Δdy| = 0.1, 0.1, 0.2.
        let expected = ((0.01 + 0.01 + 0.04) / 3.0f64).sqrt();
        assert!((m.rpe_trans_m_per_frame - expected).abs() < 1e-12);
        assert!((m.rpe_trans_per_m.unwrap() - expected).abs() < 1e-12);
        assert!((m.rpe_trans_m_per_s.unwrap() - expected).abs() < 1e-12);
        assert!(m.rpe_rot_deg_per_frame < 1e-12);
    }

    #[test]
    fn association_is_greedy_and_unique() {
        let q = UnitQuaternion::identity();
        let gt: Vec<_> = [0.0, 0.1, 0.2]
            .iter()
            .map(|&t| pose_at(t, Point3::origin(), q))
            .collect();
        let est: Vec<_> = [0.005, 0.012, 0.19, 0.5]
            .iter()
            .map(|&t| pose_at(t, Point3::origin(), q))
            .collect();
        assert_eq!(associate(&gt, &est, 0.02), vec![(0, 0), (2, 2)]);
        let err = evaluate_trajectory(&gt, &est, &TrajectoryEvalConfig::default()).unwrap_err();
        assert!(matches!(
            err,
            TrajectoryEvalError::TooFewPairs { pairs: 2, .. }
        ));
    }

    #[test]
    fn umeyama_recovers_a_reflection_free_rotation() {
        let src = [
            Vector3::new(0.0, 0.0, 0.0),
            Vector3::new(1.0, 0.0, 0.0),
            Vector3::new(0.0, 2.0, 0.0),
            Vector3::new(0.0, 0.0, 3.0),
        ];
        let r = Rotation3::from_euler_angles(0.1, 0.2, 2.9);
        let dst: Vec<_> = src
            .iter()
            .map(|x| r * x + Vector3::new(1.0, 2.0, 3.0))
            .collect();
        let s = umeyama(&src, &dst, false).unwrap();
        assert!((s.rotation.matrix() - r.matrix()).norm() < 1e-9);
        assert!(s.rotation.matrix().determinant() > 0.0);
    }
}
