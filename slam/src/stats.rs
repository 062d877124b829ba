//! Order statistics shared by every crate: one definition of each, so that a median in a report
//! and a median in a test mean the same thing.

/// The `q`-quantile of `values` by nearest rank: the sorted value at index round((n − 1)·q).
/// `q` is clamped to [0, 1]. NaNs sort after every number ([`f64::total_cmp`]).
///
/// Returns `None` for an empty slice.
///
/// ```
/// use scarp_slam::stats::quantile;
/// assert_eq!(quantile(&[3.0, 1.0, 2.0, 4.0, 5.0], 0.5), Some(3.0));
/// assert_eq!(quantile(&[3.0, 1.0, 2.0, 4.0, 5.0], 0.9), Some(5.0));
/// assert_eq!(quantile(&[], 0.5), None);
/// ```
pub fn quantile(values: &[f64], q: f64) -> Option<f64> {
    let mut sorted = values.to_vec();
    quantile_in_place(&mut sorted, q)
}

/// As [`quantile`], sorting `values` in place instead of copying them.
pub fn quantile_in_place(values: &mut [f64], q: f64) -> Option<f64> {
    if values.is_empty() {
        return None;
    }
    values.sort_by(f64::total_cmp);
    let rank = ((values.len() - 1) as f64 * q.clamp(0.0, 1.0)).round() as usize;
    Some(values[rank.min(values.len() - 1)])
}

/// The median: the middle value, or the mean of the two middle values for an even count.
/// `None` for an empty slice.
///
/// ```
/// use scarp_slam::stats::median;
/// assert_eq!(median(&[4.0, 1.0, 3.0, 2.0]), Some(2.5));
/// ```
pub fn median(values: &[f64]) -> Option<f64> {
    if values.is_empty() {
        return None;
    }
    let mut sorted = values.to_vec();
    sorted.sort_by(f64::total_cmp);
    let n = sorted.len();
    Some(if n % 2 == 1 {
        sorted[n / 2]
    } else {
        0.5 * (sorted[n / 2 - 1] + sorted[n / 2])
    })
}

/// The `p`-quantile of already sorted `sorted` values, linearly interpolated between the two
/// nearest ranks (`p` clamped to [0, 1]); NaN for an empty slice.
///
/// ```
/// use scarp_slam::stats::percentile_sorted;
/// assert_eq!(percentile_sorted(&[1.0, 2.0, 4.0], 0.75), 3.0);
/// ```
pub fn percentile_sorted(sorted: &[f64], p: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let rank = p.clamp(0.0, 1.0) * (sorted.len() - 1) as f64;
    let lo = rank.floor() as usize;
    let hi = rank.ceil() as usize;
    sorted[lo] + (sorted[hi] - sorted[lo]) * (rank - lo as f64)
}

/// Root mean square; `None` for an empty slice.
pub fn rms(values: &[f64]) -> Option<f64> {
    if values.is_empty() {
        return None;
    }
    Some((values.iter().map(|v| v * v).sum::<f64>() / values.len() as f64).sqrt())
}

/// The standard normal distribution's quantile Φ⁻¹(p): the z with P(N(0, 1) < z) = p.
///
/// Acklam's rational approximation (relative error below 1.2·10⁻⁹ over (0, 1)): a rational
/// function of p − ½ in the centre, and of √(−2 ln p) in each tail. Returns −∞ at p ≤ 0, +∞ at
/// p ≥ 1, and NaN for a NaN p.
///
/// ```
/// use scarp_slam::stats::standard_normal_quantile;
/// assert!((standard_normal_quantile(0.975) - 1.959964).abs() < 1e-6);
/// assert_eq!(standard_normal_quantile(0.5), 0.0);
/// ```
pub fn standard_normal_quantile(p: f64) -> f64 {
    const A: [f64; 6] = [
        -3.969_683_028_665_376e1,
        2.209_460_984_245_205e2,
        -2.759_285_104_469_687e2,
        1.383_577_518_672_69e2,
        -3.066_479_806_614_716e1,
        2.506_628_277_459_239,
    ];
    const B: [f64; 5] = [
        -5.447_609_879_822_406e1,
        1.615_858_368_580_409e2,
        -1.556_989_798_598_866e2,
        6.680_131_188_771_972e1,
        -1.328_068_155_288_572e1,
    ];
    const C: [f64; 6] = [
        -7.784_894_002_430_293e-3,
        -3.223_964_580_411_365e-1,
        -2.400_758_277_161_838,
        -2.549_732_539_343_734,
        4.374_664_141_464_968,
        2.938_163_982_698_783,
    ];
    const D: [f64; 4] = [
        7.784_695_709_041_462e-3,
        3.224_671_290_700_398e-1,
        2.445_134_137_142_996,
        3.754_408_661_907_416,
    ];
    const P_TAIL: f64 = 0.02425;
    let horner = |coefficients: &[f64], x: f64| coefficients.iter().fold(0.0, |acc, c| acc * x + c);
    let tail = |p: f64| {
        // The lower tail's z for probability p (p < P_TAIL).
        let q = (-2.0 * p.ln()).sqrt();
        horner(&C, q) / (horner(&D, q) * q + 1.0)
    };
    if p.is_nan() {
        f64::NAN
    } else if p <= 0.0 {
        f64::NEG_INFINITY
    } else if p >= 1.0 {
        f64::INFINITY
    } else if p < P_TAIL {
        tail(p)
    } else if p > 1.0 - P_TAIL {
        -tail(1.0 - p)
    } else {
        let q = p - 0.5;
        let r = q * q;
        horner(&A, r) * q / (horner(&B, r) * r + 1.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_normal_quantile_matches_tabulated_values() {
        // (p, z) from standard normal tables.
        for (p, z) in [
            (0.5, 0.0),
            (0.841_344_746, 1.0),
            (0.975, 1.959_963_985),
            (0.999, 3.090_232_306),
            (1e-6, -4.753_424_309),
            (0.01, -2.326_347_874),
            (0.03, -1.880_793_608),
        ] {
            let got = standard_normal_quantile(p);
            assert!((got - z).abs() < 1e-7, "p {p}: {got} vs {z}");
            assert!((standard_normal_quantile(1.0 - p) + z).abs() < 1e-7);
        }
        assert_eq!(standard_normal_quantile(0.0), f64::NEG_INFINITY);
        assert_eq!(standard_normal_quantile(1.0), f64::INFINITY);
        assert!(standard_normal_quantile(f64::NAN).is_nan());
        let grid: Vec<f64> = (1..1000)
            .map(|i| standard_normal_quantile(f64::from(i) / 1000.0))
            .collect();
        assert!(grid.windows(2).all(|w| w[0] < w[1]), "monotone");
    }
    use proptest::prelude::*;

    #[test]
    fn small_cases() {
        assert_eq!(median(&[1.0]), Some(1.0));
        assert_eq!(median(&[2.0, 1.0, 3.0]), Some(2.0));
        assert_eq!(quantile(&[1.0, 2.0], 0.0), Some(1.0));
        assert_eq!(quantile(&[1.0, 2.0], 1.0), Some(2.0));
        assert_eq!(quantile(&[1.0, 2.0], 7.0), Some(2.0));
        assert_eq!(rms(&[3.0, -4.0]), Some((12.5f64).sqrt()));
        assert_eq!(rms(&[]), None);
        assert_eq!(median(&[]), None);
    }

    proptest! {
        #[test]
        fn quantiles_are_monotone_and_bounded(
            values in proptest::collection::vec(-1e6f64..1e6, 1..50),
            a in 0.0f64..1.0,
            b in 0.0f64..1.0,
        ) {
            let (lo, hi) = (a.min(b), a.max(b));
            let ql = quantile(&values, lo).unwrap();
            let qh = quantile(&values, hi).unwrap();
            prop_assert!(ql <= qh);
            let min = values.iter().cloned().fold(f64::INFINITY, f64::min);
            let max = values.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
            prop_assert!(min <= ql && qh <= max);
            let m = median(&values).unwrap();
            prop_assert!(min <= m && m <= max);
            // At least half the values lie on each side of the median.
            let below = values.iter().filter(|v| **v <= m).count();
            let above = values.iter().filter(|v| **v >= m).count();
            prop_assert!(2 * below >= values.len() && 2 * above >= values.len());
        }
    }
}
