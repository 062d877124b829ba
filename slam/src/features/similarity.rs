//! Robust 2-D similarity fit (scale, rotation, translation) from point pairs.
//!
//! A similarity maps `p ↦ [a −b; b a]·p + t` with scale `√(a² + b²)` and rotation
//! `atan2(b, a)`. Its least-squares fit is closed form and linear in `(a, b, t)`: centre both
//! point sets on their (weighted) means, then `a = Σ p·q / Σ |p|²` and
//! `b = Σ p×q / Σ |p|²`.
//!
//! The robust fit is RANSAC over minimal two-point samples, then least squares on the inliers,
//! repeated until the inlier set stops changing. When the number of pairs is small it tries
//! every pair in order (no randomness at all); otherwise it draws pairs from a seeded RNG.

use nalgebra::{Matrix3, Point2, Vector2};
use rand::rngs::Xoshiro256PlusPlus;
use rand::{RngExt, SeedableRng};
use serde::{Deserialize, Serialize};

use super::FeatureError;

/// A 2-D similarity transform `p ↦ [a −b; b a]·p + t`, in pixels.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Similarity2 {
    /// `scale · cos(rotation)`.
    pub a: f64,
    /// `scale · sin(rotation)`.
    pub b: f64,
    /// Translation, px.
    pub translation: Vector2<f64>,
}

impl Similarity2 {
    /// The identity.
    pub fn identity() -> Self {
        Self {
            a: 1.0,
            b: 0.0,
            translation: Vector2::zeros(),
        }
    }

    /// From a scale (> 0), a rotation (radians, counter-clockwise in (u, v) axes, which is
    /// clockwise on screen since v points down) and a translation, px.
    pub fn from_parts(scale: f64, rotation_rad: f64, translation: Vector2<f64>) -> Self {
        Self {
            a: scale * rotation_rad.cos(),
            b: scale * rotation_rad.sin(),
            translation,
        }
    }

    /// A pure translation, px.
    pub fn from_translation(translation: Vector2<f64>) -> Self {
        Self {
            translation,
            ..Self::identity()
        }
    }

    /// The scale factor.
    pub fn scale(&self) -> f64 {
        self.a.hypot(self.b)
    }

    /// The rotation angle, radians.
    pub fn rotation_rad(&self) -> f64 {
        self.b.atan2(self.a)
    }

    /// Applies the transform to a point.
    pub fn apply(&self, p: &Point2<f64>) -> Point2<f64> {
        Point2::new(
            self.a * p.x - self.b * p.y + self.translation.x,
            self.b * p.x + self.a * p.y + self.translation.y,
        )
    }

    /// The homogeneous 3×3 matrix `[a −b tx; b a ty; 0 0 1]` (the paper's S).
    pub fn matrix(&self) -> Matrix3<f64> {
        Matrix3::new(
            self.a,
            -self.b,
            self.translation.x,
            self.b,
            self.a,
            self.translation.y,
            0.0,
            0.0,
            1.0,
        )
    }

    /// Whether all four parameters are finite.
    pub fn is_finite(&self) -> bool {
        self.a.is_finite()
            && self.b.is_finite()
            && self.translation.x.is_finite()
            && self.translation.y.is_finite()
    }
}

/// Robust-fit parameters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SimilarityFitConfig {
    /// A pair is an inlier when the fitted transform maps its source within this distance of
    /// its destination, px. Default 1.0 (KLT points are good to a few tenths of a pixel).
    pub inlier_threshold_px: f64,
    /// Most RANSAC hypotheses. When the number of point pairs `n` has `n(n−1)/2` at most this,
    /// every pair is tried and the fit is fully deterministic. Default 200 (covers 20 points).
    pub max_hypotheses: usize,
    /// Least-squares refits on the inlier set after RANSAC. Default 3.
    pub refinement_rounds: usize,
    /// Seed for the sampled case. Default 0.
    pub seed: u64,
}

impl Default for SimilarityFitConfig {
    fn default() -> Self {
        Self {
            inlier_threshold_px: 1.0,
            max_hypotheses: 200,
            refinement_rounds: 3,
            seed: 0,
        }
    }
}

/// The result of a robust fit.
#[derive(Debug, Clone, PartialEq)]
pub struct SimilarityFit {
    /// The transform (least squares on the inliers).
    pub transform: Similarity2,
    /// Per input pair, whether it is an inlier.
    pub inliers: Vec<bool>,
    /// Root-mean-square residual of the inliers, px.
    pub rms_px: f64,
}

impl SimilarityFit {
    /// Number of inliers.
    pub fn inlier_count(&self) -> usize {
        self.inliers.iter().filter(|&&i| i).count()
    }
}

fn check_pairs(src: &[Point2<f64>], dst: &[Point2<f64>]) -> Result<(), FeatureError> {
    if src.len() != dst.len() {
        return Err(FeatureError::SizeMismatch {
            what: "source and destination point counts",
            left: src.len(),
            right: dst.len(),
        });
    }
    for (what, pts) in [("source point", src), ("destination point", dst)] {
        if let Some(index) = pts
            .iter()
            .position(|p| !(p.x.is_finite() && p.y.is_finite()))
        {
            return Err(FeatureError::NotFinite { what, index });
        }
    }
    Ok(())
}

/// Weighted least-squares similarity mapping `src[i]` to `dst[i]`; `weights` (≥ 0, one per
/// pair) default to 1.
///
/// # Errors
/// [`FeatureError::SizeMismatch`] when lengths differ; [`FeatureError::NotFinite`] for a NaN or
/// infinite coordinate or weight; [`FeatureError::TooFewPoints`] for fewer than 2 pairs;
/// [`FeatureError::Degenerate`] when the weighted source points coincide.
pub fn fit_similarity_least_squares(
    src: &[Point2<f64>],
    dst: &[Point2<f64>],
    weights: Option<&[f64]>,
) -> Result<Similarity2, FeatureError> {
    check_pairs(src, dst)?;
    if let Some(w) = weights {
        if w.len() != src.len() {
            return Err(FeatureError::SizeMismatch {
                what: "weights and point counts",
                left: w.len(),
                right: src.len(),
            });
        }
        if let Some(index) = w.iter().position(|x| !(x.is_finite() && *x >= 0.0)) {
            return Err(FeatureError::NotFinite {
                what: "weight",
                index,
            });
        }
    }
    if src.len() < 2 {
        return Err(FeatureError::TooFewPoints {
            what: "similarity fit",
            needed: 2,
            got: src.len(),
        });
    }
    let weight = |i: usize| weights.map_or(1.0, |w| w[i]);
    let total: f64 = (0..src.len()).map(weight).sum();
    if !(total > 0.0) {
        return Err(FeatureError::Degenerate("all weights are zero"));
    }
    let (mut ps, mut qs) = (Vector2::zeros(), Vector2::zeros());
    for i in 0..src.len() {
        ps += weight(i) * src[i].coords;
        qs += weight(i) * dst[i].coords;
    }
    let (pm, qm) = (ps / total, qs / total);
    let (mut spp, mut sdot, mut scross) = (0.0, 0.0, 0.0);
    for i in 0..src.len() {
        let w = weight(i);
        let p = src[i].coords - pm;
        let q = dst[i].coords - qm;
        spp += w * p.norm_squared();
        sdot += w * p.dot(&q);
        scross += w * (p.x * q.y - p.y * q.x);
    }
    // Relative to the spread of the points, so the test is scale-free.
    let spread = pm.norm_squared().max(1.0) * total;
    if !(spp > 1e-18 * spread) {
        return Err(FeatureError::Degenerate("source points coincide"));
    }
    let (a, b) = (sdot / spp, scross / spp);
    let translation = qm - Vector2::new(a * pm.x - b * pm.y, b * pm.x + a * pm.y);
    Ok(Similarity2 { a, b, translation })
}

/// Robust similarity fit (RANSAC on pairs, then least-squares refinement on the inliers).
///
/// # Errors
/// As [`fit_similarity_least_squares`]; [`FeatureError::InvalidConfig`] for a bad config;
/// [`FeatureError::Degenerate`] when no hypothesis has two inliers.
pub fn fit_similarity_robust(
    src: &[Point2<f64>],
    dst: &[Point2<f64>],
    config: &SimilarityFitConfig,
) -> Result<SimilarityFit, FeatureError> {
    check_pairs(src, dst)?;
    if !(config.inlier_threshold_px.is_finite() && config.inlier_threshold_px > 0.0) {
        return Err(FeatureError::InvalidConfig {
            field: "inlier_threshold_px",
            reason: "must be finite and > 0",
        });
    }
    if config.max_hypotheses == 0 {
        return Err(FeatureError::InvalidConfig {
            field: "max_hypotheses",
            reason: "must be at least 1",
        });
    }
    let n = src.len();
    if n < 2 {
        return Err(FeatureError::TooFewPoints {
            what: "robust similarity fit",
            needed: 2,
            got: n,
        });
    }
    let threshold_sq = config.inlier_threshold_px * config.inlier_threshold_px;
    // Score: inlier count, then lower truncated squared error (MSAC-style tie break).
    let score = |s: &Similarity2| -> (usize, f64) {
        let mut count = 0;
        let mut cost = 0.0;
        for (p, q) in src.iter().zip(dst) {
            let r = (s.apply(p) - q).norm_squared();
            if r <= threshold_sq {
                count += 1;
                cost += r;
            } else {
                cost += threshold_sq;
            }
        }
        (count, cost)
    };
    let mut best: Option<(Similarity2, (usize, f64))> = None;
    let mut consider = |i: usize, j: usize| {
        if let Ok(s) = fit_similarity_least_squares(&[src[i], src[j]], &[dst[i], dst[j]], None) {
            let sc = score(&s);
            let better = best
                .as_ref()
                .is_none_or(|(_, b)| sc.0 > b.0 || (sc.0 == b.0 && sc.1 < b.1));
            if better {
                best = Some((s, sc));
            }
        }
    };
    let pairs = n * (n - 1) / 2;
    if pairs <= config.max_hypotheses {
        for i in 0..n {
            for j in i + 1..n {
                consider(i, j);
            }
        }
    } else {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(config.seed);
        for _ in 0..config.max_hypotheses {
            let i = rng.random_range(0..n);
            let j = rng.random_range(0..n - 1);
            let j = if j >= i { j + 1 } else { j };
            consider(i, j);
        }
    }
    let Some((mut transform, (count, _))) = best else {
        return Err(FeatureError::Degenerate("every point pair coincides"));
    };
    if count < 2 {
        return Err(FeatureError::Degenerate("no hypothesis has two inliers"));
    }
    let inliers_of = |s: &Similarity2| -> Vec<bool> {
        src.iter()
            .zip(dst)
            .map(|(p, q)| (s.apply(p) - q).norm_squared() <= threshold_sq)
            .collect()
    };
    let mut inliers = inliers_of(&transform);
    for _ in 0..config.refinement_rounds {
        let (s_in, d_in): (Vec<_>, Vec<_>) = src
            .iter()
            .zip(dst)
            .zip(&inliers)
            .filter(|(_, keep)| **keep)
            .map(|((p, q), _)| (*p, *q))
            .unzip();
        let Ok(refit) = fit_similarity_least_squares(&s_in, &d_in, None) else {
            break;
        };
        let new_inliers = inliers_of(&refit);
        if new_inliers.iter().filter(|&&b| b).count() < 2 {
            break;
        }
        transform = refit;
        let unchanged = new_inliers == inliers;
        inliers = new_inliers;
        if unchanged {
            break;
        }
    }
    let (sum_sq, count) = src
        .iter()
        .zip(dst)
        .zip(&inliers)
        .filter(|(_, keep)| **keep)
        .fold((0.0, 0usize), |(s, c), ((p, q), _)| {
            (s + (transform.apply(p) - q).norm_squared(), c + 1)
        });
    Ok(SimilarityFit {
        transform,
        inliers,
        rms_px: (sum_sq / count.max(1) as f64).sqrt(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn exact_fit_and_matrix_agree() {
        let s = Similarity2::from_parts(1.3, 0.4, Vector2::new(5.0, -2.0));
        let src: Vec<_> = [(0.0, 0.0), (10.0, 3.0), (-4.0, 7.0)]
            .iter()
            .map(|&(x, y)| Point2::new(x, y))
            .collect();
        let dst: Vec<_> = src.iter().map(|p| s.apply(p)).collect();
        let fit = fit_similarity_least_squares(&src, &dst, None).unwrap();
        assert!((fit.scale() - 1.3).abs() < 1e-12 && (fit.rotation_rad() - 0.4).abs() < 1e-12);
        let h = fit.matrix() * src[1].to_homogeneous();
        assert!((Point2::from_homogeneous(h).unwrap() - dst[1]).norm() < 1e-9);
    }

    #[test]
    fn degenerate_and_bad_input_are_errors() {
        let p = vec![Point2::new(1.0, 1.0), Point2::new(1.0, 1.0)];
        assert!(matches!(
            fit_similarity_least_squares(&p, &p, None),
            Err(FeatureError::Degenerate(_))
        ));
        assert!(matches!(
            fit_similarity_least_squares(&p[..1], &p[..1], None),
            Err(FeatureError::TooFewPoints { .. })
        ));
        assert!(matches!(
            fit_similarity_least_squares(&p, &p[..1], None),
            Err(FeatureError::SizeMismatch { .. })
        ));
        let nan = vec![Point2::new(f64::NAN, 1.0), Point2::new(2.0, 1.0)];
        assert!(matches!(
            fit_similarity_robust(&nan, &p, &SimilarityFitConfig::default()),
            Err(FeatureError::NotFinite { index: 0, .. })
        ));
    }

    fn outlier_case(
        n: usize,
        outliers: usize,
        seed: u64,
    ) -> (Similarity2, Vec<Point2<f64>>, Vec<Point2<f64>>) {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
        let s = Similarity2::from_parts(
            rng.random_range(0.7..1.4),
            rng.random_range(-0.5..0.5),
            Vector2::new(rng.random_range(-20.0..20.0), rng.random_range(-20.0..20.0)),
        );
        let src: Vec<_> = (0..n)
            .map(|_| Point2::new(rng.random_range(0.0..60.0), rng.random_range(0.0..60.0)))
            .collect();
        let dst = src
            .iter()
            .enumerate()
            .map(|(i, p)| {
                if i < outliers {
                    // A gross error: 5–50 px off in a random direction.
                    let angle: f64 = rng.random_range(0.0..std::f64::consts::TAU);
                    let r: f64 = rng.random_range(5.0..50.0);
                    s.apply(p) + r * Vector2::new(angle.cos(), angle.sin())
                } else {
                    s.apply(p)
                        + Vector2::new(rng.random_range(-0.1..0.1), rng.random_range(-0.1..0.1))
                }
            })
            .collect();
        (s, src, dst)
    }

    #[test]
    fn sampled_ransac_is_seeded_and_robust() {
        let (s, src, dst) = outlier_case(60, 20, 7);
        let config = SimilarityFitConfig::default();
        let a = fit_similarity_robust(&src, &dst, &config).unwrap();
        let b = fit_similarity_robust(&src, &dst, &config).unwrap();
        assert_eq!(a, b);
        assert!((a.transform.scale() - s.scale()).abs() < 0.01);
        assert!(a.inliers[20..].iter().all(|&i| i));
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]
        #[test]
        fn robust_fit_ignores_a_third_of_outliers(seed in 0u64..10_000, n in 8usize..20) {
            let outliers = n / 3;
            let (s, src, dst) = outlier_case(n, outliers, seed);
            let fit = fit_similarity_robust(&src, &dst, &SimilarityFitConfig::default()).unwrap();
            // Exactly the true inliers are kept, and the transform is then the least-squares
            // fit to them: the best any estimator can do with this noise. Comparing with the
            // truth itself would test the noise, not the fit (6 noisy points over 60 px can
            // legitimately extrapolate 0.2 px wrong at the corners).
            let truth: Vec<bool> = (0..n).map(|i| i >= outliers).collect();
            prop_assert_eq!(&fit.inliers, &truth);
            let oracle = fit_similarity_least_squares(&src[outliers..], &dst[outliers..], None).unwrap();
            for p in [Point2::new(0.0, 0.0), Point2::new(60.0, 0.0), Point2::new(0.0, 60.0), Point2::new(60.0, 60.0)] {
                let e = (fit.transform.apply(&p) - oracle.apply(&p)).norm();
                prop_assert!(e < 1e-9, "{e} px from the oracle fit");
                let e_truth = (fit.transform.apply(&p) - s.apply(&p)).norm();
                prop_assert!(e_truth < 0.5, "{e_truth} px from the truth");
            }
        }

        #[test]
        fn least_squares_is_exact_without_noise(
            scale in 0.2f64..5.0, angle in -3.1f64..3.1, tx in -100.0f64..100.0, ty in -100.0f64..100.0,
            pts in proptest::collection::vec((-200.0f64..200.0, -200.0f64..200.0), 3..12),
        ) {
            let src: Vec<_> = pts.iter().map(|&(x, y)| Point2::new(x, y)).collect();
            let spread = src.iter().map(|p| (p - src[0]).norm()).fold(0.0, f64::max);
            prop_assume!(spread > 1.0);
            let s = Similarity2::from_parts(scale, angle, Vector2::new(tx, ty));
            let dst: Vec<_> = src.iter().map(|p| s.apply(p)).collect();
            let fit = fit_similarity_least_squares(&src, &dst, None).unwrap();
            for p in &src {
                prop_assert!((fit.apply(p) - s.apply(p)).norm() < 1e-6);
            }
        }
    }
}
