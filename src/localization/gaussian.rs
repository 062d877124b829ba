//! The Gaussian fit of a point set and what is derived from it: the PCA ellipsoid, λ_max, the
//! KL divergence between two fits and the differential entropy (paper §III-D).

use nalgebra::{Matrix3, Point3, Rotation3, SymmetricEigen};
use scarp_slam::geometry::{eigenpairs_ascending, mean_and_scatter};
use serde::{Deserialize, Serialize};

use super::LocalizationError;

/// A 3-D Gaussian: mean (world, m) and covariance (m²).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Gaussian3 {
    /// Mean, world frame, m.
    pub mean: Point3<f64>,
    /// Covariance, m².
    pub covariance: Matrix3<f64>,
}

/// The PCA ellipsoid of a point set: centre, a right-handed frame of principal axes (largest
/// variance first), and the one-standard-deviation semi-axes.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Ellipsoid {
    /// Centre, world frame, m.
    pub center: Point3<f64>,
    /// `world_from_ellipsoid` rotation: its columns are the principal axes, sorted by
    /// decreasing eigenvalue; determinant +1 (right-handed; the seed code negated one axis).
    pub world_from_ellipsoid: Rotation3<f64>,
    /// Eigenvalues of the covariance, decreasing, m².
    pub eigenvalues_m2: [f64; 3],
    /// Semi-axes √λ (one standard deviation) along the columns of `world_from_ellipsoid`, m.
    pub semi_axes_m: [f64; 3],
}

impl Gaussian3 {
    /// Mean and sample covariance (1/(n − 1)) of `points`.
    ///
    /// # Errors
    /// [`LocalizationError::TooFewPoints`] for fewer than 2 points or a non-finite coordinate.
    pub fn from_points(points: &[Point3<f64>]) -> Result<Self, LocalizationError> {
        let n = points.len();
        let finite = points
            .iter()
            .all(|p| p.coords.iter().all(|c| c.is_finite()));
        if n < 2 || !finite {
            return Err(LocalizationError::TooFewPoints { count: n });
        }
        let (mean, scatter) = mean_and_scatter(points);
        Ok(Self {
            mean,
            covariance: scatter / (n - 1) as f64,
        })
    }

    /// The PCA ellipsoid (right-handed frame, axes sorted by decreasing eigenvalue).
    pub fn ellipsoid(&self) -> Ellipsoid {
        let mut pairs = eigenpairs_ascending(&self.covariance);
        pairs.reverse();
        let mut columns = pairs.map(|(_, vector)| vector);
        // Deterministic signs: the largest component of each of the first two axes positive.
        for c in columns.iter_mut().take(2) {
            let imax = c.iamax();
            if c[imax] < 0.0 {
                *c = -*c;
            }
        }
        // Right-handed: the third axis is the cross product of the first two.
        columns[2] = columns[0].cross(&columns[1]);
        let matrix = Matrix3::from_columns(&columns);
        let eigenvalues_m2 = pairs.map(|(value, _)| value.max(0.0));
        Ellipsoid {
            center: self.mean,
            world_from_ellipsoid: Rotation3::from_matrix(&matrix),
            eigenvalues_m2,
            semi_axes_m: eigenvalues_m2.map(f64::sqrt),
        }
    }

    /// The largest eigenvalue λ_max of the covariance, m².
    pub fn lambda_max(&self) -> f64 {
        SymmetricEigen::new(self.covariance)
            .eigenvalues
            .iter()
            .cloned()
            .fold(f64::NEG_INFINITY, f64::max)
    }

    /// Differential entropy ½ ln((2πe)³ |Σ|), nats; −∞ for a singular covariance.
    pub fn entropy_nats(&self) -> f64 {
        let det = self.covariance.determinant();
        if det > 0.0 {
            0.5 * (3.0 * (2.0 * std::f64::consts::PI * std::f64::consts::E).ln() + det.ln())
        } else {
            f64::NEG_INFINITY
        }
    }

    /// This Gaussian with `variance_m2` added along every axis (Σ + v·I), m².
    ///
    /// Why: KL between two fits is scale-free, so the same shift of the centre costs more in a
    /// tight cloud than in a wide one. Comparing fits widened by a floor makes "no change" mean
    /// that the centre moved little on the floor's scale, whatever the cloud's size.
    pub fn with_variance_floor(&self, variance_m2: f64) -> Self {
        Self {
            mean: self.mean,
            covariance: self.covariance + Matrix3::identity() * variance_m2,
        }
    }

    /// KL divergence D(self ‖ other) = ½ (tr(Σ₁⁻¹Σ₀) + (μ₁ − μ₀)ᵀΣ₁⁻¹(μ₁ − μ₀) − 3 + ln(|Σ₁|/|Σ₀|)),
    /// nats, with `self` = N₀ (the updated fit) and `other` = N₁ (the previous one). +∞ when
    /// either covariance is singular.
    pub fn kl_divergence(&self, other: &Self) -> f64 {
        let (det0, det1) = (
            self.covariance.determinant(),
            other.covariance.determinant(),
        );
        let Some(chol1) = other.covariance.cholesky() else {
            return f64::INFINITY;
        };
        if !(det0 > 0.0 && det1 > 0.0) {
            return f64::INFINITY;
        }
        let trace = chol1.solve(&self.covariance).trace();
        let d = other.mean - self.mean;
        let mahalanobis = d.dot(&chol1.solve(&d));
        (0.5 * (trace + mahalanobis - 3.0 + (det1 / det0).ln())).max(0.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;
    use rand::SeedableRng;
    use rand::rngs::Xoshiro256PlusPlus;
    use rand_distr::{Distribution, StandardNormal};

    fn sample(mean: Vector3<f64>, scales: Vector3<f64>, n: usize, seed: u64) -> Vec<Point3<f64>> {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
        (0..n)
            .map(|_| {
                let z = Vector3::from_fn(|_, _| StandardNormal.sample(&mut rng));
                Point3::from(mean + z.component_mul(&scales))
            })
            .collect()
    }

    #[test]
    fn kl_is_zero_for_identical_sets_and_positive_otherwise() {
        let a = sample(
            Vector3::new(1.0, 2.0, 3.0),
            Vector3::new(0.5, 0.2, 0.1),
            2000,
            1,
        );
        let ga = Gaussian3::from_points(&a).unwrap();
        assert!(ga.kl_divergence(&ga).abs() < 1e-12);
        let shifted: Vec<_> = a.iter().map(|p| p + Vector3::new(0.05, 0.0, 0.0)).collect();
        let gs = Gaussian3::from_points(&shifted).unwrap();
        assert!(gs.kl_divergence(&ga) > 1e-4);
        let b = sample(
            Vector3::new(1.0, 2.0, 3.0),
            Vector3::new(0.5, 0.2, 0.1),
            2000,
            2,
        );
        let gb = Gaussian3::from_points(&b).unwrap();
        assert!(gb.kl_divergence(&ga) > 0.0);
        // Closed form for a pure mean shift along x: ½ d²/σ².
        let expected = 0.5 * 0.05f64.powi(2) * ga.covariance.try_inverse().unwrap()[(0, 0)];
        assert!((gs.kl_divergence(&ga) - expected).abs() < 1e-9);
    }

    #[test]
    fn a_variance_floor_makes_kl_measure_the_shift_on_the_floor_scale() {
        // The same 5 cm shift: in a cloud 2 cm thick the paper's KL calls it a change (3.1
        // nats); on a 0.3 m floor it is about ½·0.05²/(0.02² + 0.3²) ≈ 0.014 nats.
        let tight = sample(Vector3::zeros(), Vector3::new(0.02, 0.02, 0.02), 2000, 4);
        let shifted: Vec<_> = tight
            .iter()
            .map(|p| p + Vector3::new(0.0, 0.0, 0.05))
            .collect();
        let (g0, g1) = (
            Gaussian3::from_points(&shifted).unwrap(),
            Gaussian3::from_points(&tight).unwrap(),
        );
        assert!(g0.kl_divergence(&g1) > 1.0);
        let floor = 0.3f64.powi(2);
        let floored = g0
            .with_variance_floor(floor)
            .kl_divergence(&g1.with_variance_floor(floor));
        let expected = 0.5 * 0.05f64.powi(2) / (g1.covariance[(2, 2)] + floor);
        assert!((floored - expected).abs() < 2e-3, "{floored} vs {expected}");
        // A zero floor is the paper's KL.
        assert_eq!(
            g0.with_variance_floor(0.0)
                .kl_divergence(&g1.with_variance_floor(0.0)),
            g0.kl_divergence(&g1)
        );
    }

    #[test]
    fn entropy_of_a_known_gaussian() {
        // Exact covariance diag(1, 4, 9): h = ½ ln((2πe)³ · 36).
        let g = Gaussian3 {
            mean: Point3::origin(),
            covariance: Matrix3::from_diagonal(&Vector3::new(1.0, 4.0, 9.0)),
        };
        let expected =
            0.5 * ((2.0 * std::f64::consts::PI * std::f64::consts::E).powi(3) * 36.0).ln();
        assert!((g.entropy_nats() - expected).abs() < 1e-12);
        // And from samples: within sampling error.
        let pts = sample(Vector3::zeros(), Vector3::new(1.0, 2.0, 3.0), 20000, 5);
        let h = Gaussian3::from_points(&pts).unwrap().entropy_nats();
        assert!((h - expected).abs() < 0.03, "{h} vs {expected}");
    }

    #[test]
    fn ellipsoid_is_right_handed_and_sorted() {
        let pts = sample(
            Vector3::new(4.0, 0.0, 1.0),
            Vector3::new(0.1, 2.0, 0.5),
            5000,
            3,
        );
        let e = Gaussian3::from_points(&pts).unwrap().ellipsoid();
        let m = e.world_from_ellipsoid.matrix();
        assert!((m.determinant() - 1.0).abs() < 1e-9);
        assert!(e.eigenvalues_m2[0] >= e.eigenvalues_m2[1]);
        assert!(e.eigenvalues_m2[1] >= e.eigenvalues_m2[2]);
        // Largest axis along y, smallest along x.
        assert!(m.column(0).y.abs() > 0.99);
        assert!(m.column(2).x.abs() > 0.99);
        assert!((e.semi_axes_m[0] - 2.0).abs() < 0.1);
        let g = Gaussian3::from_points(&pts).unwrap();
        assert!((g.lambda_max() - e.eigenvalues_m2[0]).abs() < 1e-12);
    }

    #[test]
    fn too_few_or_nan_points_are_errors() {
        assert!(Gaussian3::from_points(&[Point3::origin()]).is_err());
        let nan = [Point3::origin(), Point3::new(f64::NAN, 0.0, 0.0)];
        assert!(Gaussian3::from_points(&nan).is_err());
    }
}
