//! Eight lanes in two AVX registers, for the AVX2 kernel alone.
//!
//! [`Lanes`](super::Lanes) are arrays that the compiler vectorises, which rustc does only at
//! opt-level 3 (its SLP vectoriser): in test builds, at 2, the AVX2 kernel ran each lane on its
//! own. This type states the vector operations themselves, so the kernel is vectorised at any
//! level. Each operation is the IEEE one the scalar path does, lane by lane: the same bits.
//! `min` and `max` go lane by lane through `f64::min` and `f64::max`, whose NaN rule no single
//! instruction has.
//!
//! Every method calls AVX or AVX2 intrinsics. SAFETY, for each `unsafe` block here: the type is
//! used only inside the AVX2 kernel (`montecarlo::kernel`), which runs only where
//! `Kernel::new` found AVX2 on the CPU, and the module is private to the crate.

use super::{EXP2_INT_BIAS, Lanes, Mask, Real, word};
use std::arch::x86_64::*;
use std::ops::{Add, BitAnd, BitOr, Div, Mul, Neg, Not, Sub};

/// Eight `f64` lanes, four to a register.
#[derive(Debug, Clone, Copy)]
#[repr(C, align(32))]
pub(crate) struct Lanes8([__m256d; 2]);

/// Eight truth values, each a 64-bit word of all ones or all zeros, as in [`Lanes8`].
#[derive(Debug, Clone, Copy)]
#[repr(C, align(32))]
pub(crate) struct Mask8([__m256d; 2]);

/// The sign bit of every lane.
#[inline(always)]
fn sign() -> __m256d {
    unsafe { _mm256_set1_pd(-0.0) }
}

/// `f` on each register of a batch.
#[inline(always)]
fn each(a: [__m256d; 2], f: impl Fn(__m256d) -> __m256d) -> [__m256d; 2] {
    [f(a[0]), f(a[1])]
}

/// `f` on each pair of registers of two batches.
#[inline(always)]
fn pairs(
    a: [__m256d; 2],
    b: [__m256d; 2],
    f: impl Fn(__m256d, __m256d) -> __m256d,
) -> [__m256d; 2] {
    [f(a[0], b[0]), f(a[1], b[1])]
}

impl Lanes8 {
    #[inline(always)]
    fn array(self) -> [f64; 8] {
        unsafe { std::mem::transmute(self.0) }
    }

    #[inline(always)]
    fn of(lanes: [f64; 8]) -> Self {
        Self(unsafe { std::mem::transmute::<[f64; 8], [__m256d; 2]>(lanes) })
    }

    /// The same lanes as an array batch, whose operations go lane by lane.
    #[inline(always)]
    fn lanes(self) -> Lanes<8> {
        Lanes(self.array())
    }
}

impl Mask8 {
    #[inline(always)]
    fn words(self) -> [u64; 8] {
        unsafe { std::mem::transmute(self.0) }
    }

    #[inline(always)]
    fn of(words: [u64; 8]) -> Self {
        Self(unsafe { std::mem::transmute::<[u64; 8], [__m256d; 2]>(words) })
    }

    /// One bit per lane, lane 0 lowest: each word's sign bit.
    #[inline(always)]
    fn signs(self) -> u32 {
        let [low, high] = self.0;
        unsafe { (_mm256_movemask_pd(low) | (_mm256_movemask_pd(high) << 4)) as u32 }
    }
}

macro_rules! lane_operator {
    ($trait:ident, $method:ident, $intrinsic:ident) => {
        impl $trait for Lanes8 {
            type Output = Self;
            #[inline(always)]
            fn $method(self, other: Self) -> Self {
                Self(pairs(self.0, other.0, |a, b| unsafe { $intrinsic(a, b) }))
            }
        }
    };
}
lane_operator!(Add, add, _mm256_add_pd);
lane_operator!(Sub, sub, _mm256_sub_pd);
lane_operator!(Mul, mul, _mm256_mul_pd);
lane_operator!(Div, div, _mm256_div_pd);

impl Neg for Lanes8 {
    type Output = Self;
    /// The sign bit flipped, as `-x` does.
    #[inline(always)]
    fn neg(self) -> Self {
        Self(each(self.0, |a| unsafe { _mm256_xor_pd(a, sign()) }))
    }
}

impl Real for Lanes8 {
    type Mask = Mask8;
    const LANES: usize = 8;

    #[inline(always)]
    fn splat(x: f64) -> Self {
        let all = unsafe { _mm256_set1_pd(x) };
        Self([all, all])
    }
    #[inline(always)]
    fn from_fn(f: impl FnMut(usize) -> f64) -> Self {
        Self::of(Lanes::<8>::from_fn(f).0)
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        Self(each(self.0, |a| unsafe { _mm256_sqrt_pd(a) }))
    }
    #[inline(always)]
    fn min(self, other: Self) -> Self {
        Self::of(self.lanes().min(other.lanes()).0)
    }
    #[inline(always)]
    fn max(self, other: Self) -> Self {
        Self::of(self.lanes().max(other.lanes()).0)
    }
    /// The sign bit cleared, as `f64::abs` does.
    #[inline(always)]
    fn abs(self) -> Self {
        Self(each(self.0, |a| unsafe { _mm256_andnot_pd(sign(), a) }))
    }
    /// The magnitude's bits with the sign's sign bit, as `f64::copysign` does.
    #[inline(always)]
    fn copysign(self, sign_of: Self) -> Self {
        Self(pairs(self.0, sign_of.0, |a, s| unsafe {
            _mm256_or_pd(_mm256_andnot_pd(sign(), a), _mm256_and_pd(sign(), s))
        }))
    }
    /// Ordered and quiet, as `<` is: false where either is NaN.
    #[inline(always)]
    fn lt(self, other: Self) -> Mask8 {
        Mask8(pairs(self.0, other.0, |a, b| unsafe {
            _mm256_cmp_pd::<_CMP_LT_OQ>(a, b)
        }))
    }
    #[inline(always)]
    fn le(self, other: Self) -> Mask8 {
        Mask8(pairs(self.0, other.0, |a, b| unsafe {
            _mm256_cmp_pd::<_CMP_LE_OQ>(a, b)
        }))
    }
    #[inline(always)]
    fn eq(self, other: Self) -> Mask8 {
        Mask8(pairs(self.0, other.0, |a, b| unsafe {
            _mm256_cmp_pd::<_CMP_EQ_OQ>(a, b)
        }))
    }
    /// Bit by bit, as [`Lanes`](super::Lanes) selects.
    #[inline(always)]
    fn select(mask: Mask8, yes: Self, no: Self) -> Self {
        let [m0, m1] = mask.0;
        let pick = |m, y, n| unsafe { _mm256_or_pd(_mm256_and_pd(m, y), _mm256_andnot_pd(m, n)) };
        Self([pick(m0, yes.0[0], no.0[0]), pick(m1, yes.0[1], no.0[1])])
    }
    #[inline(always)]
    fn exp2_int(self) -> Self {
        Self(each(self.0, |a| unsafe {
            let biased = _mm256_add_pd(a, _mm256_set1_pd(EXP2_INT_BIAS));
            _mm256_castsi256_pd(_mm256_slli_epi64::<52>(_mm256_castpd_si256(biased)))
        }))
    }
    #[inline(always)]
    fn lane(&self, i: usize) -> f64 {
        self.array()[i]
    }

    #[inline(always)]
    fn set_lane(&mut self, i: usize, x: f64) {
        let mut lanes = self.array();
        lanes[i] = x;
        *self = Self::of(lanes);
    }

    type Part = Self;
}

impl BitAnd for Mask8 {
    type Output = Self;
    #[inline(always)]
    fn bitand(self, other: Self) -> Self {
        Self(pairs(self.0, other.0, |a, b| unsafe {
            _mm256_and_pd(a, b)
        }))
    }
}

impl BitOr for Mask8 {
    type Output = Self;
    #[inline(always)]
    fn bitor(self, other: Self) -> Self {
        Self(pairs(self.0, other.0, |a, b| unsafe { _mm256_or_pd(a, b) }))
    }
}

impl Not for Mask8 {
    type Output = Self;
    #[inline(always)]
    fn not(self) -> Self {
        let ones = unsafe { _mm256_castsi256_pd(_mm256_set1_epi64x(-1)) };
        Self(each(self.0, |a| unsafe { _mm256_xor_pd(a, ones) }))
    }
}

impl Mask for Mask8 {
    #[inline(always)]
    fn from_fn(mut f: impl FnMut(usize) -> bool) -> Self {
        let mut out = [0; 8];
        for (i, slot) in out.iter_mut().enumerate() {
            *slot = word(f(i));
        }
        Self::of(out)
    }
    #[inline(always)]
    fn any(self) -> bool {
        self.signs() != 0
    }
    #[inline(always)]
    fn count(self) -> usize {
        self.signs().count_ones() as usize
    }
    #[inline(always)]
    fn bits(self) -> u64 {
        u64::from(self.signs())
    }
    #[inline(always)]
    fn lane(&self, i: usize) -> bool {
        self.words()[i] != 0
    }
    #[inline(always)]
    fn set_lane(&mut self, i: usize, truth: bool) {
        let mut words = self.words();
        words[i] = word(truth);
        *self = Self::of(words);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Values where the operations differ most: zeros of both signs, infinities, NaN, the
    /// smallest subnormal, the largest finite and numbers whose results round.
    const EDGES: [f64; 16] = [
        0.0,
        -0.0,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::NAN,
        5e-324,
        f64::MAX,
        -1.0,
        0.1,
        -0.3,
        7.5,
        1e300,
        -2.5e-310,
        3.0,
        -7.5,
        1.0 / 3.0,
    ];

    fn bits8(x: Lanes8) -> [u64; 8] {
        x.array().map(f64::to_bits)
    }

    fn bits(x: Lanes<8>) -> [u64; 8] {
        std::array::from_fn(|i| x.lane(i).to_bits())
    }

    /// Every operation gives, bit for bit, what the array lanes (and so the scalar path) give,
    /// on every pair of the edge values.
    #[test]
    fn every_operation_gives_the_bits_of_the_array_lanes() {
        if !std::arch::is_x86_feature_detected!("avx2") {
            eprintln!("no AVX2 on this CPU: nothing to compare");
            return;
        }
        for shift in 0..EDGES.len() {
            let a = |i: usize| EDGES[i % 16];
            let b = |i: usize| EDGES[(i + shift + 8 * (shift % 2)) % 16];
            for half in [0, 8] {
                let (x, y) = (
                    Lanes8::from_fn(|i| a(i + half)),
                    Lanes8::from_fn(|i| b(i + half)),
                );
                let (u, v) = (
                    Lanes::<8>::from_fn(|i| a(i + half)),
                    Lanes::<8>::from_fn(|i| b(i + half)),
                );
                assert_eq!(bits8(x + y), bits(u + v));
                assert_eq!(bits8(x - y), bits(u - v));
                assert_eq!(bits8(x * y), bits(u * v));
                assert_eq!(bits8(x / y), bits(u / v));
                assert_eq!(bits8(-x), bits(-u));
                assert_eq!(bits8(x.sqrt()), bits(u.sqrt()));
                assert_eq!(bits8(x.min(y)), bits(u.min(v)));
                assert_eq!(bits8(x.max(y)), bits(u.max(v)));
                assert_eq!(bits8(x.abs()), bits(u.abs()));
                assert_eq!(bits8(x.copysign(y)), bits(u.copysign(v)));
                for (mask, array) in [
                    (x.lt(y), u.lt(v)),
                    (x.le(y), u.le(v)),
                    (x.eq(y), u.eq(v)),
                    (x.gt(y), u.gt(v)),
                    (!x.ge(y) | x.eq(y), !u.ge(v) | u.eq(v)),
                    (x.lt(y) & x.le(y), u.lt(v) & u.le(v)),
                ] {
                    let lanes: [bool; 8] = std::array::from_fn(|i| mask.lane(i));
                    assert_eq!(lanes, std::array::from_fn(|i| array.lane(i)));
                    assert_eq!(mask.any(), array.any());
                    assert_eq!(mask.count(), array.count());
                    assert_eq!(mask.bits(), array.bits());
                    assert_eq!(
                        bits8(Lanes8::select(mask, x, y)),
                        bits(Lanes::select(array, u, v))
                    );
                }
            }
        }
        let whole = Lanes8::from_fn(|i| i as f64 * 146.0 - 1022.0);
        let array = Lanes::<8>::from_fn(|i| i as f64 * 146.0 - 1022.0);
        assert_eq!(bits8(whole.exp2_int()), bits(array.exp2_int()));
        let mut set = whole;
        set.set_lane(5, -0.0);
        assert_eq!(set.lane(5).to_bits(), (-0.0f64).to_bits());
        let mut mask = Mask8::from_fn(|i| i % 3 == 0);
        mask.set_lane(1, true);
        mask.set_lane(0, false);
        assert_eq!(
            std::array::from_fn::<bool, 8, _>(|i| mask.lane(i)),
            [false, true, false, true, false, false, true, false]
        );
        assert_eq!(mask.count(), 3);
    }
}
