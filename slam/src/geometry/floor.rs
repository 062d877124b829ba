//! Floor to integer without libm: on baseline x86-64 (no SSE4.1), `f32::floor` and `f64::floor`
//! compile to library calls, which dominated voxel-grid traversal and noise evaluation.

/// `x.floor()` as an `i32`. Exact for |x| < 2^24; saturates like `as` beyond `i32`'s range.
#[inline]
pub fn floor_i32(x: f32) -> i32 {
    let truncated = x as i32;
    if (truncated as f32) > x {
        truncated - 1
    } else {
        truncated
    }
}

/// `x.floor()` as an `i64`. Exact for |x| < 2^53.
#[inline]
pub fn floor_i64(x: f64) -> i64 {
    let truncated = x as i64;
    if (truncated as f64) > x {
        truncated - 1
    } else {
        truncated
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #[test]
        fn matches_floor(x in -1.0e6f64..1.0e6) {
            prop_assert_eq!(floor_i64(x), x.floor() as i64);
            let y = x as f32;
            prop_assert_eq!(floor_i32(y), y.floor() as i32);
        }
    }

    #[test]
    fn integers_and_signs() {
        for x in [-2.0f32, -1.5, -1e-7, 0.0, 1e-7, 0.999, 1.0, 7.5] {
            assert_eq!(floor_i32(x), x.floor() as i32, "{x}");
            assert_eq!(floor_i64(f64::from(x)), f64::from(x).floor() as i64, "{x}");
        }
    }
}
