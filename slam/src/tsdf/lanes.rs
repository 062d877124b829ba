//! Eight SIMD lanes of `f32` (and of `i32`), the width of one row of a voxel block, in two
//! implementations of one interface: `wide`'s portable lanes, whose instruction set is fixed
//! when the crate is compiled (two SSE halves on baseline x86-64), and, on x86-64, AVX2 lanes
//! chosen at run time when the processor has them.
//!
//! Why: the TSDF voxel update is compute-bound, and a baseline x86-64 build runs each of its
//! eight-lane operations as two four-lane ones. Compiled for AVX2 it ran 10–20% faster, but a
//! binary built that way does not start on a processor without AVX2. Writing the kernel once,
//! generic over [`Simd8`], and instantiating it inside [`pulp::x86::V3::vectorize`] gives the
//! AVX2 speed on the machines that have it and the portable code elsewhere, with no `unsafe`
//! in this crate.
//!
//! Both implementations compute bit-identical results: every operation is the same IEEE-754
//! single-precision operation lane by lane (no fused multiply-add, no approximations), and the
//! comparisons, min/max and conversions have the same semantics on both (`min`/`max` return the
//! second operand when either is NaN; conversions truncate toward zero and give `i32::MIN` out
//! of range).

use std::ops::{Add, BitAnd, BitOr, Div, Mul, Sub};

/// A set of eight-lane operations: a zero-sized token that makes lanes.
pub(super) trait Simd8: Copy {
    /// Eight `f32` lanes.
    type F: Float8<Mask = Self::M, Int = Self::I>;
    /// Eight lane masks (all ones or all zeros per lane), from comparing [`Self::F`] lanes.
    type M: Mask8<Float = Self::F>;
    /// Eight `i32` lanes.
    type I: Int8<Float = Self::F>;
    fn f32s(self, lanes: [f32; 8]) -> Self::F;
    fn splat(self, x: f32) -> Self::F;
    fn i32s(self, lanes: [i32; 8]) -> Self::I;
    fn splat_i32(self, x: i32) -> Self::I;
}

pub(super) trait Float8:
    Copy + Add<Output = Self> + Sub<Output = Self> + Mul<Output = Self> + Div<Output = Self>
{
    type Mask: Mask8<Float = Self>;
    type Int: Int8<Float = Self>;
    fn simd_ge(self, rhs: Self) -> Self::Mask;
    fn simd_gt(self, rhs: Self) -> Self::Mask;
    fn simd_lt(self, rhs: Self) -> Self::Mask;
    fn simd_le(self, rhs: Self) -> Self::Mask;
    /// The lane-wise minimum; `rhs` where either lane is NaN.
    fn fast_min(self, rhs: Self) -> Self;
    /// The lane-wise maximum; `rhs` where either lane is NaN.
    fn fast_max(self, rhs: Self) -> Self;
    /// Truncation toward zero; `i32::MIN` for NaN and out-of-range lanes.
    fn fast_trunc_int(self) -> Self::Int;
    fn to_array(self) -> [f32; 8];
}

pub(super) trait Mask8: Copy + BitAnd<Output = Self> {
    type Float;
    /// `if_true` in the lanes set, `if_false` in the others.
    fn select(self, if_true: Self::Float, if_false: Self::Float) -> Self::Float;
    /// Bit i set when lane i is set.
    fn to_bitmask(self) -> u32;
}

pub(super) trait Int8:
    Copy + Add<Output = Self> + BitAnd<Output = Self> + BitOr<Output = Self>
{
    type Float;
    /// Arithmetic (sign-filling) right shift of every lane by `bits` (< 32).
    fn shr(self, bits: u32) -> Self;
    /// Left shift of every lane by `bits` (< 32).
    fn shl(self, bits: u32) -> Self;
    fn min(self, rhs: Self) -> Self;
    /// The nearest `f32` of every lane (exact below 2^24).
    fn round_float(self) -> Self::Float;
    fn to_array(self) -> [i32; 8];
}

/// `wide`'s lanes, whatever instruction set the crate was compiled for.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct Portable;

impl Simd8 for Portable {
    type F = wide::f32x8;
    type M = wide::f32x8;
    type I = wide::i32x8;
    #[inline(always)]
    fn f32s(self, lanes: [f32; 8]) -> Self::F {
        wide::f32x8::new(lanes)
    }
    #[inline(always)]
    fn splat(self, x: f32) -> Self::F {
        wide::f32x8::splat(x)
    }
    #[inline(always)]
    fn i32s(self, lanes: [i32; 8]) -> Self::I {
        wide::i32x8::new(lanes)
    }
    #[inline(always)]
    fn splat_i32(self, x: i32) -> Self::I {
        wide::i32x8::splat(x)
    }
}

impl Float8 for wide::f32x8 {
    type Mask = wide::f32x8;
    type Int = wide::i32x8;
    #[inline(always)]
    fn simd_ge(self, rhs: Self) -> Self {
        wide::f32x8::simd_ge(self, rhs)
    }
    #[inline(always)]
    fn simd_gt(self, rhs: Self) -> Self {
        wide::f32x8::simd_gt(self, rhs)
    }
    #[inline(always)]
    fn simd_lt(self, rhs: Self) -> Self {
        wide::f32x8::simd_lt(self, rhs)
    }
    #[inline(always)]
    fn simd_le(self, rhs: Self) -> Self {
        wide::f32x8::simd_le(self, rhs)
    }
    #[inline(always)]
    fn fast_min(self, rhs: Self) -> Self {
        wide::f32x8::fast_min(self, rhs)
    }
    #[inline(always)]
    fn fast_max(self, rhs: Self) -> Self {
        wide::f32x8::fast_max(self, rhs)
    }
    #[inline(always)]
    fn fast_trunc_int(self) -> wide::i32x8 {
        wide::f32x8::fast_trunc_int(self)
    }
    #[inline(always)]
    fn to_array(self) -> [f32; 8] {
        wide::f32x8::to_array(self)
    }
}

impl Mask8 for wide::f32x8 {
    type Float = wide::f32x8;
    #[inline(always)]
    fn select(self, if_true: Self, if_false: Self) -> Self {
        wide::f32x8::select(self, if_true, if_false)
    }
    #[inline(always)]
    fn to_bitmask(self) -> u32 {
        wide::f32x8::to_bitmask(self)
    }
}

impl Int8 for wide::i32x8 {
    type Float = wide::f32x8;
    #[inline(always)]
    fn shr(self, bits: u32) -> Self {
        self >> bits
    }
    #[inline(always)]
    fn shl(self, bits: u32) -> Self {
        self << bits
    }
    #[inline(always)]
    fn min(self, rhs: Self) -> Self {
        wide::i32x8::min(self, rhs)
    }
    #[inline(always)]
    fn round_float(self) -> wide::f32x8 {
        wide::i32x8::round_float(self)
    }
    #[inline(always)]
    fn to_array(self) -> [i32; 8] {
        wide::i32x8::to_array(self)
    }
}

#[cfg(target_arch = "x86_64")]
pub(super) use avx2::{Avx2, avx2};

#[cfg(target_arch = "x86_64")]
mod avx2 {
    //! AVX2 lanes through `pulp`'s token, which proves at run time that the processor has the
    //! instructions and makes the intrinsics safe to call. Every method is `#[inline(always)]`
    //! so that it lands inside [`pulp::x86::V3::vectorize`]'s AVX2-enabled function: called
    //! anywhere else, it would still be correct, only slow.

    use std::arch::x86_64::{__m256, __m256i, _CMP_GE_OQ, _CMP_GT_OQ, _CMP_LE_OQ, _CMP_LT_OQ};
    use std::ops::{Add, BitAnd, BitOr, Div, Mul, Sub};

    use pulp::x86::V3;

    use super::{Float8, Int8, Mask8, Simd8};

    /// The AVX2 token, when the running processor has AVX2 (and the rest of x86-64-v3).
    pub(in crate::tsdf) fn avx2() -> Option<Avx2> {
        V3::try_new().map(Avx2)
    }

    /// Proof that the processor has x86-64-v3 (AVX2, FMA, BMI1/2): run code that uses it
    /// through [`Avx2::vectorize`].
    #[derive(Debug, Clone, Copy)]
    pub(in crate::tsdf) struct Avx2(V3);

    impl Avx2 {
        /// Runs `f` compiled for x86-64-v3; `f` must be `#[inline(always)]` all the way down to
        /// the lane operations for them to become AVX2 instructions.
        ///
        /// Nothing forces the closure itself inline into pulp's AVX2-enabled function. With one
        /// kernel instance it is (callgrind: 2.89 G instructions on 10 orbit frames). A trial
        /// with two instances behind one closure was not, and every intrinsic became a call:
        /// 8.0 G. Routing the work through a struct with an `#[inline(always)]` call instead
        /// cost 2.96 G. So after changing the kernel, count its instructions again.
        #[inline(always)]
        pub(in crate::tsdf) fn vectorize<R>(self, f: impl FnOnce() -> R) -> R {
            self.0.vectorize(f)
        }
    }

    #[derive(Clone, Copy)]
    pub(in crate::tsdf) struct F(V3, __m256);
    #[derive(Clone, Copy)]
    pub(in crate::tsdf) struct M(V3, __m256);
    #[derive(Clone, Copy)]
    pub(in crate::tsdf) struct I(V3, __m256i);

    impl Simd8 for Avx2 {
        type F = F;
        type M = M;
        type I = I;
        #[inline(always)]
        fn f32s(self, lanes: [f32; 8]) -> F {
            F(self.0, pulp::cast(lanes))
        }
        #[inline(always)]
        fn splat(self, x: f32) -> F {
            F(self.0, self.0.avx._mm256_set1_ps(x))
        }
        #[inline(always)]
        fn i32s(self, lanes: [i32; 8]) -> I {
            I(self.0, pulp::cast(lanes))
        }
        #[inline(always)]
        fn splat_i32(self, x: i32) -> I {
            I(self.0, self.0.avx._mm256_set1_epi32(x))
        }
    }

    /// Implements a binary operator trait with one intrinsic.
    macro_rules! binary {
        ($lanes:ident, $op:ident, $method:ident, $feature:ident, $intrinsic:ident) => {
            impl $op for $lanes {
                type Output = $lanes;
                #[inline(always)]
                fn $method(self, rhs: $lanes) -> $lanes {
                    $lanes(self.0, self.0.$feature.$intrinsic(self.1, rhs.1))
                }
            }
        };
    }
    binary!(F, Add, add, avx, _mm256_add_ps);
    binary!(F, Sub, sub, avx, _mm256_sub_ps);
    binary!(F, Mul, mul, avx, _mm256_mul_ps);
    binary!(F, Div, div, avx, _mm256_div_ps);
    binary!(M, BitAnd, bitand, avx, _mm256_and_ps);
    binary!(I, Add, add, avx2, _mm256_add_epi32);
    binary!(I, BitAnd, bitand, avx2, _mm256_and_si256);
    binary!(I, BitOr, bitor, avx2, _mm256_or_si256);

    impl Float8 for F {
        type Mask = M;
        type Int = I;
        #[inline(always)]
        fn simd_ge(self, rhs: F) -> M {
            M(
                self.0,
                self.0.avx._mm256_cmp_ps::<_CMP_GE_OQ>(self.1, rhs.1),
            )
        }
        #[inline(always)]
        fn simd_gt(self, rhs: F) -> M {
            M(
                self.0,
                self.0.avx._mm256_cmp_ps::<_CMP_GT_OQ>(self.1, rhs.1),
            )
        }
        #[inline(always)]
        fn simd_lt(self, rhs: F) -> M {
            M(
                self.0,
                self.0.avx._mm256_cmp_ps::<_CMP_LT_OQ>(self.1, rhs.1),
            )
        }
        #[inline(always)]
        fn simd_le(self, rhs: F) -> M {
            M(
                self.0,
                self.0.avx._mm256_cmp_ps::<_CMP_LE_OQ>(self.1, rhs.1),
            )
        }
        #[inline(always)]
        fn fast_min(self, rhs: F) -> F {
            F(self.0, self.0.avx._mm256_min_ps(self.1, rhs.1))
        }
        #[inline(always)]
        fn fast_max(self, rhs: F) -> F {
            F(self.0, self.0.avx._mm256_max_ps(self.1, rhs.1))
        }
        #[inline(always)]
        fn fast_trunc_int(self) -> I {
            I(self.0, self.0.avx._mm256_cvttps_epi32(self.1))
        }
        #[inline(always)]
        fn to_array(self) -> [f32; 8] {
            pulp::cast(self.1)
        }
    }

    impl Mask8 for M {
        type Float = F;
        #[inline(always)]
        fn select(self, if_true: F, if_false: F) -> F {
            F(
                self.0,
                self.0.avx._mm256_blendv_ps(if_false.1, if_true.1, self.1),
            )
        }
        #[inline(always)]
        fn to_bitmask(self) -> u32 {
            self.0.avx._mm256_movemask_ps(self.1) as u32
        }
    }

    impl Int8 for I {
        type Float = F;
        #[inline(always)]
        fn shr(self, bits: u32) -> I {
            let count = self.0.avx._mm256_set1_epi32(bits as i32);
            I(self.0, self.0.avx2._mm256_srav_epi32(self.1, count))
        }
        #[inline(always)]
        fn shl(self, bits: u32) -> I {
            let count = self.0.avx._mm256_set1_epi32(bits as i32);
            I(self.0, self.0.avx2._mm256_sllv_epi32(self.1, count))
        }
        #[inline(always)]
        fn min(self, rhs: I) -> I {
            I(self.0, self.0.avx2._mm256_min_epi32(self.1, rhs.1))
        }
        #[inline(always)]
        fn round_float(self) -> F {
            F(self.0, self.0.avx._mm256_cvtepi32_ps(self.1))
        }
        #[inline(always)]
        fn to_array(self) -> [i32; 8] {
            pulp::cast(self.1)
        }
    }
}

#[cfg(test)]
mod tests {
    //! The AVX2 lanes against the portable ones, operation by operation, on values that include
    //! the edge cases (NaN, ±∞, ±0, out of `i32` range); skipped where the processor lacks AVX2.

    use proptest::prelude::*;

    use super::*;

    fn special() -> impl Strategy<Value = f32> {
        prop_oneof![
            4 => -1.0e4f32..1.0e4,
            1 => prop::sample::select(vec![
                0.0f32, -0.0, 1.0, -1.0, 0.5, -0.5, f32::NAN, f32::INFINITY,
                f32::NEG_INFINITY, 3.0e9, -3.0e9, f32::MIN_POSITIVE, 16_777_217.0,
            ]),
        ]
    }

    /// Every lane operation of `s` on `a` and `b`, flattened to bits.
    #[inline(always)]
    fn everything<S: Simd8>(s: S, a: [f32; 8], b: [f32; 8], ints: [i32; 8], bits: u32) -> Vec<u32> {
        let (x, y) = (s.f32s(a), s.f32s(b));
        let i = s.i32s(ints);
        let j = s.splat_i32(0x00ff_00ff);
        let mut out = Vec::new();
        let mut push_f = |v: S::F| out.extend(v.to_array().map(f32::to_bits));
        push_f(x + y);
        push_f(x - y);
        push_f(x * y);
        push_f(x / y);
        push_f(x.fast_min(y));
        push_f(x.fast_max(y));
        push_f(s.splat(a[3]));
        for mask in [x.simd_ge(y), x.simd_gt(y), x.simd_lt(y), x.simd_le(y)] {
            push_f((mask & y.simd_ge(s.splat(0.0))).select(x, y));
            push_f(s.splat(mask.to_bitmask() as f32));
        }
        push_f(i.round_float());
        out.extend(x.fast_trunc_int().to_array().map(|v| v as u32));
        for v in [i + j, i & j, i | j, i.min(j), i.shr(bits), i.shl(bits)] {
            out.extend(v.to_array().map(|v| v as u32));
        }
        out
    }

    proptest! {
        #[test]
        fn avx2_lanes_compute_what_portable_lanes_compute(
            a in prop::array::uniform8(special()),
            b in prop::array::uniform8(special()),
            ints in prop::array::uniform8(any::<i32>()),
            bits in 0u32..32,
        ) {
            let portable = everything(Portable, a, b, ints, bits);
            #[cfg(target_arch = "x86_64")]
            if let Some(simd) = avx2() {
                let fast = simd.vectorize(|| everything(simd, a, b, ints, bits));
                prop_assert_eq!(fast, portable);
            }
            #[cfg(not(target_arch = "x86_64"))]
            prop_assert!(!portable.is_empty());
        }
    }
}
