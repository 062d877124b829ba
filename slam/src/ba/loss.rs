//! Robust losses ρ(s) of a squared residual norm s = ‖r‖²; the cost of a residual is ½·ρ(s).

use serde::{Deserialize, Serialize};

/// A robust loss applied to each observation's squared residual norm.
///
/// The solver uses iteratively reweighted least squares: residual and Jacobians are scaled by
/// √ρ′(s) at the current estimate.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Default)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum RobustLoss {
    /// Plain least squares, ρ(s) = s.
    #[default]
    Trivial,
    /// Huber: ρ(s) = s for s ≤ δ², 2δ√s − δ² beyond. `delta_px` is δ, in residual units (pixels).
    Huber {
        /// The threshold δ, pixels; must be positive.
        delta_px: f64,
    },
    /// Cauchy: ρ(s) = c²·ln(1 + s/c²). `scale_px` is c, in residual units (pixels).
    Cauchy {
        /// The scale c, pixels; must be positive.
        scale_px: f64,
    },
}

impl RobustLoss {
    /// ρ(s) for a squared norm `s` ≥ 0.
    pub fn rho(&self, s: f64) -> f64 {
        match *self {
            RobustLoss::Trivial => s,
            RobustLoss::Huber { delta_px } => {
                let d2 = delta_px * delta_px;
                if s <= d2 {
                    s
                } else {
                    2.0 * delta_px * s.sqrt() - d2
                }
            }
            RobustLoss::Cauchy { scale_px } => {
                let c2 = scale_px * scale_px;
                c2 * (s / c2).ln_1p()
            }
        }
    }

    /// ρ′(s), the weight of a residual with squared norm `s` ≥ 0 (1 for inliers).
    pub fn weight(&self, s: f64) -> f64 {
        match *self {
            RobustLoss::Trivial => 1.0,
            RobustLoss::Huber { delta_px } => {
                if s <= delta_px * delta_px {
                    1.0
                } else {
                    delta_px / s.sqrt()
                }
            }
            RobustLoss::Cauchy { scale_px } => 1.0 / (1.0 + s / (scale_px * scale_px)),
        }
    }

    /// The scale parameter, if any (for validation).
    pub(crate) fn scale(&self) -> Option<(&'static str, f64)> {
        match *self {
            RobustLoss::Trivial => None,
            RobustLoss::Huber { delta_px } => Some(("loss.delta_px", delta_px)),
            RobustLoss::Cauchy { scale_px } => Some(("loss.scale_px", scale_px)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn weight_is_the_derivative_of_rho() {
        for loss in [
            RobustLoss::Trivial,
            RobustLoss::Huber { delta_px: 2.0 },
            RobustLoss::Cauchy { scale_px: 1.5 },
        ] {
            for s in [0.1, 1.0, 3.9, 4.1, 30.0] {
                let h = 1e-6;
                let numeric = (loss.rho(s + h) - loss.rho(s - h)) / (2.0 * h);
                assert!((numeric - loss.weight(s)).abs() < 1e-6, "{loss:?} at {s}");
            }
            assert_eq!(loss.rho(0.0), 0.0);
        }
    }
}
