//! The pieces of a principal component analysis of a 3-D point set, shared by the planner's
//! target ellipsoid and the localization filter's Gaussian fit.

use nalgebra::{Matrix3, Point3, SymmetricEigen, Vector3};

/// The mean of `points` and their scatter matrix Σ (p − mean)(p − mean)ᵀ, not yet divided by
/// a count: the caller chooses the population (1/n) or the sample (1/(n − 1)) covariance.
/// Units are those of the points (the scatter in their square). An empty slice gives a NaN
/// mean; callers check the count first.
pub fn mean_and_scatter(points: &[Point3<f64>]) -> (Point3<f64>, Matrix3<f64>) {
    let mean = points
        .iter()
        .fold(Vector3::zeros(), |acc, p| acc + p.coords)
        / points.len() as f64;
    let mut scatter = Matrix3::zeros();
    for p in points {
        let d = p.coords - mean;
        scatter += d * d.transpose();
    }
    (Point3::from(mean), scatter)
}

/// The eigenpairs of the symmetric matrix `m`, sorted by increasing eigenvalue (ties keep
/// nalgebra's order). The eigenvectors are nalgebra's columns as they come: unit length up to
/// rounding, with arbitrary signs that the caller fixes by its own convention.
pub fn eigenpairs_ascending(m: &Matrix3<f64>) -> [(f64, Vector3<f64>); 3] {
    let eig = SymmetricEigen::new(*m);
    let mut order = [0usize, 1, 2];
    order.sort_by(|&a, &b| eig.eigenvalues[a].total_cmp(&eig.eigenvalues[b]));
    order.map(|k| (eig.eigenvalues[k], eig.eigenvectors.column(k).into_owned()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scatter_of_a_segment_lies_along_it() {
        let points: Vec<Point3<f64>> = (0..5)
            .map(|k| Point3::new(1.0 + f64::from(k), 2.0, 3.0))
            .collect();
        let (mean, scatter) = mean_and_scatter(&points);
        assert_eq!(mean, Point3::new(3.0, 2.0, 3.0));
        // Σ (x − 3)² over x = 1..5 is 10; nothing across.
        assert_eq!(scatter[(0, 0)], 10.0);
        assert_eq!(scatter.norm(), 10.0);
        let pairs = eigenpairs_ascending(&scatter);
        assert!(pairs[0].0.abs() < 1e-12 && pairs[1].0.abs() < 1e-12);
        assert!((pairs[2].0 - 10.0).abs() < 1e-12);
        assert!((pairs[2].1.x.abs() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn eigenpairs_come_sorted_and_satisfy_the_matrix() {
        let m = Matrix3::new(4.0, 1.0, 0.5, 1.0, 3.0, 0.2, 0.5, 0.2, 1.0);
        let pairs = eigenpairs_ascending(&m);
        assert!(pairs[0].0 <= pairs[1].0 && pairs[1].0 <= pairs[2].0);
        for (value, vector) in pairs {
            assert!((m * vector - value * vector).norm() < 1e-12);
        }
    }
}
