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

/// Root mean square; `None` for an empty slice.
pub fn rms(values: &[f64]) -> Option<f64> {
    if values.is_empty() {
        return None;
    }
    Some((values.iter().map(|v| v * v).sum::<f64>() / values.len() as f64).sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;
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
