//! The bounding-box Kalman filter of the paper's Algorithm 1, with DESIGN.md's errata.
//!
//! The state is the box `u = (x_min, y_min, x_max, y_max)` in px (Euclidean form) with a 4×4
//! covariance Σ in px². Prediction runs in homogeneous form `x = T u + a =
//! (x_min, y_min, 1, x_max, y_max, 1)` so that the KLT similarity `S` (3×3, homogeneous) acts on
//! both corners through `F = diag(S, S)`:
//!
//! 1. `x = T u + a`
//! 2. `Ω = T Σ Tᵀ` (erratum: the paper prints `T Σ + a`)
//! 3. `x ← F x`
//! 4. `Ω ← F Ω Fᵀ + R`, with `R = diag(r, r, 0, r, r, 0)` the prediction noise
//! 5. `u = M x`
//! 6. `Σ = M Ω Mᵀ` (erratum: the paper prints `M Ω`)
//!
//! The update is Euclidean, with the detection `z` and detection noise `Q = q·I₄`:
//! `K = Σ (Σ + Q)⁻¹`, `u ← u + K (z − u)`, `Σ ← (I − K) Σ`. The covariance update is computed
//! in Joseph form `(I − K) Σ (I − K)ᵀ + K Q Kᵀ`, which equals `(I − K) Σ` for this gain but
//! stays symmetric positive definite under rounding. As the errata say, R is the prediction
//! noise and Q the detection noise, the other way round from the usual naming.
//!
//! The box entropy is the differential entropy of the 4-D Gaussian,
//! `h = k/2 + (k/2)·ln(2π) + ½·ln|Σ|` with `k = 4`.

use nalgebra::{Matrix3, Matrix4, Matrix4x6, Matrix6, Matrix6x4, Vector4, Vector6};

/// A box estimate: state and covariance.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoxEstimate {
    /// `(x_min, y_min, x_max, y_max)`, px, continuous coordinates (pixel centres at integers).
    pub state_px: Vector4<f64>,
    /// Covariance of `state_px`, px².
    pub covariance_px2: Matrix4<f64>,
}

/// `T`: Euclidean box to homogeneous corners (without the constant `a`).
pub fn homogeneous_from_euclidean() -> Matrix6x4<f64> {
    let mut t = Matrix6x4::zeros();
    t[(0, 0)] = 1.0;
    t[(1, 1)] = 1.0;
    t[(3, 2)] = 1.0;
    t[(4, 3)] = 1.0;
    t
}

/// `a`: the constant ones of the homogeneous form.
pub fn homogeneous_offset() -> Vector6<f64> {
    Vector6::new(0.0, 0.0, 1.0, 0.0, 0.0, 1.0)
}

/// `M`: homogeneous corners back to the Euclidean box.
pub fn euclidean_from_homogeneous() -> Matrix4x6<f64> {
    homogeneous_from_euclidean().transpose()
}

/// `R = diag(r, r, 0, r, r, 0)`: prediction noise in homogeneous form, `r` in px².
pub fn prediction_noise(variance_px2: f64) -> Matrix6<f64> {
    Matrix6::from_diagonal(&Vector6::new(
        variance_px2,
        variance_px2,
        0.0,
        variance_px2,
        variance_px2,
        0.0,
    ))
}

/// `F = diag(S, S)` for a homogeneous 2-D transform `S`.
pub fn transition(s: &Matrix3<f64>) -> Matrix6<f64> {
    let mut f = Matrix6::zeros();
    f.fixed_view_mut::<3, 3>(0, 0).copy_from(s);
    f.fixed_view_mut::<3, 3>(3, 3).copy_from(s);
    f
}

/// Predict (Algorithm 1, lines 1–6): moves the box by `next_from_prev` (the KLT similarity,
/// homogeneous, bottom row `0 0 1`) and adds the prediction noise `r` (px²).
pub fn predict(
    estimate: &BoxEstimate,
    next_from_prev: &Matrix3<f64>,
    prediction_variance_px2: f64,
) -> BoxEstimate {
    let t = homogeneous_from_euclidean();
    let m = euclidean_from_homogeneous();
    let f = transition(next_from_prev);
    let x = t * estimate.state_px + homogeneous_offset();
    let omega = t * estimate.covariance_px2 * t.transpose();
    let x = f * x;
    let omega = f * omega * f.transpose() + prediction_noise(prediction_variance_px2);
    let sigma = m * omega * m.transpose();
    BoxEstimate {
        state_px: m * x,
        covariance_px2: symmetrized(&sigma),
    }
}

/// Update (Algorithm 1, lines 7–9) with a detected box `z` (px) of isotropic noise `q` (px²).
///
/// Returns `None` when `Σ + Q` is not invertible (only for a non-positive `q` and a singular
/// Σ, which the tracker's validated config rules out).
pub fn update(
    estimate: &BoxEstimate,
    detection_px: &Vector4<f64>,
    detection_variance_px2: f64,
) -> Option<BoxEstimate> {
    let sigma = estimate.covariance_px2;
    let q = Matrix4::identity() * detection_variance_px2;
    let innovation_cov = (sigma + q).cholesky()?;
    // K = Σ S⁻¹ = (S⁻¹ Σ)ᵀ since both are symmetric.
    let k = innovation_cov.solve(&sigma).transpose();
    let state = estimate.state_px + k * (detection_px - estimate.state_px);
    let i_k = Matrix4::identity() - k;
    let cov = i_k * sigma * i_k.transpose() + k * q * k.transpose();
    Some(BoxEstimate {
        state_px: state,
        covariance_px2: symmetrized(&cov),
    })
}

/// Differential entropy of the box distribution, nats: `2 + 2·ln(2π) + ½·ln|Σ|`. Infinite
/// when Σ is not positive definite (such a box is treated as lost).
pub fn box_entropy(covariance_px2: &Matrix4<f64>) -> f64 {
    let k = 4.0;
    match covariance_px2.cholesky() {
        Some(chol) => {
            let half_log_det: f64 = (0..4).map(|i| chol.l_dirty()[(i, i)].ln()).sum();
            k / 2.0 + k / 2.0 * (2.0 * std::f64::consts::PI).ln() + half_log_det
        }
        None => f64::INFINITY,
    }
}

fn symmetrized(m: &Matrix4<f64>) -> Matrix4<f64> {
    (m + m.transpose()) * 0.5
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() < 1e-9
    }

    #[test]
    fn predict_matches_hand_computation() {
        // Translation (3, −1), no rotation or scale: the box shifts, Σ gains r on each axis.
        let est = BoxEstimate {
            state_px: Vector4::new(10.0, 20.0, 50.0, 60.0),
            covariance_px2: Matrix4::identity() * 2.0,
        };
        let s = Matrix3::new(1.0, 0.0, 3.0, 0.0, 1.0, -1.0, 0.0, 0.0, 1.0);
        let p = predict(&est, &s, 10.0);
        assert_eq!(p.state_px, Vector4::new(13.0, 19.0, 53.0, 59.0));
        assert!((p.covariance_px2 - Matrix4::identity() * 12.0).norm() < 1e-12);
        // Scale 2 with a 90° rotation: (x, y) ↦ (−2y, 2x); Σ = 2·4·I + 10·I on the diagonal.
        let s = Matrix3::new(0.0, -2.0, 0.0, 2.0, 0.0, 0.0, 0.0, 0.0, 1.0);
        let p = predict(&est, &s, 10.0);
        assert_eq!(p.state_px, Vector4::new(-40.0, 20.0, -120.0, 100.0));
        assert!((p.covariance_px2 - Matrix4::identity() * 18.0).norm() < 1e-12);
        // Correlated x_min/y_min covariance rotates with the corner: [[2,1],[1,2]] under a 90°
        // rotation becomes [[2,−1],[−1,2]].
        let mut cov = Matrix4::identity() * 2.0;
        cov[(0, 1)] = 1.0;
        cov[(1, 0)] = 1.0;
        let est = BoxEstimate {
            covariance_px2: cov,
            ..est
        };
        let rot = Matrix3::new(0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0);
        let p = predict(&est, &rot, 0.0);
        assert!(close(p.covariance_px2[(0, 1)], -1.0) && close(p.covariance_px2[(0, 0)], 2.0));
        assert!(close(p.covariance_px2[(2, 3)], 0.0));
    }

    #[test]
    fn update_matches_hand_computation() {
        // Σ = 12·I, Q = 0.2·I: K = 12/12.2·I, Σ' = 0.2·12/12.2·I.
        let est = BoxEstimate {
            state_px: Vector4::new(13.0, 19.0, 53.0, 59.0),
            covariance_px2: Matrix4::identity() * 12.0,
        };
        let z = Vector4::new(15.0, 19.0, 53.0, 61.0);
        let u = update(&est, &z, 0.2).unwrap();
        let k = 12.0 / 12.2;
        assert!(close(u.state_px[0], 13.0 + 2.0 * k));
        assert!(close(u.state_px[1], 19.0) && close(u.state_px[2], 53.0));
        assert!(close(u.state_px[3], 59.0 + 2.0 * k));
        assert!((u.covariance_px2 - Matrix4::identity() * (0.2 * 12.0 / 12.2)).norm() < 1e-12);
        // The paper's (I − K)Σ form gives the same covariance.
        let kmat = est.covariance_px2
            * (est.covariance_px2 + Matrix4::identity() * 0.2)
                .try_inverse()
                .unwrap();
        let paper = (Matrix4::identity() - kmat) * est.covariance_px2;
        assert!((paper - u.covariance_px2).norm() < 1e-12);
    }

    #[test]
    fn entropy_matches_formula_and_grows_without_updates() {
        let h = box_entropy(&(Matrix4::identity() * 3.0));
        let expected = 2.0 + 2.0 * (2.0 * std::f64::consts::PI).ln() + 0.5 * (81.0f64).ln();
        assert!(close(h, expected));
        assert_eq!(box_entropy(&Matrix4::zeros()), f64::INFINITY);
        // With the default noises, a box that stops being detected crosses h = 16 after 18
        // predictions (0.9 s at 20 Hz).
        let mut est = BoxEstimate {
            state_px: Vector4::new(0.0, 0.0, 10.0, 10.0),
            covariance_px2: Matrix4::identity() * 0.2,
        };
        let mut steps = 0;
        while box_entropy(&est.covariance_px2) < 16.0 {
            est = predict(&est, &Matrix3::identity(), 10.0);
            steps += 1;
        }
        assert_eq!(steps, 18);
    }

    fn spd(m: &Matrix4<f64>) -> bool {
        (m - m.transpose()).norm() <= 1e-9 * m.norm().max(1.0) && m.cholesky().is_some()
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(128))]
        #[test]
        fn covariance_stays_symmetric_positive_definite(
            steps in proptest::collection::vec(
                (0.8f64..1.25, -0.3f64..0.3, -20.0f64..20.0, -20.0f64..20.0,
                 proptest::bool::ANY, -5.0f64..5.0),
                1..60,
            ),
            r in 0.01f64..50.0,
            q in 0.01f64..50.0,
        ) {
            let mut est = BoxEstimate {
                state_px: Vector4::new(100.0, 80.0, 140.0, 130.0),
                covariance_px2: Matrix4::identity() * q,
            };
            for (scale, angle, tx, ty, detected, noise) in steps {
                let s = Matrix3::new(
                    scale * angle.cos(), -scale * angle.sin(), tx,
                    scale * angle.sin(), scale * angle.cos(), ty,
                    0.0, 0.0, 1.0,
                );
                est = predict(&est, &s, r);
                prop_assert!(spd(&est.covariance_px2), "after predict: {}", est.covariance_px2);
                if detected {
                    let z = est.state_px + Vector4::new(noise, -noise, 0.5 * noise, 0.0);
                    est = update(&est, &z, q).unwrap();
                    prop_assert!(spd(&est.covariance_px2), "after update: {}", est.covariance_px2);
                }
                prop_assert!(box_entropy(&est.covariance_px2).is_finite());
            }
        }
    }
}
