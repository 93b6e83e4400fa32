//! Lanes in vector registers, for the AVX2 kernel: its eight lanes in two AVX registers.
//!
//! [`Lanes`](super::Lanes) are arrays that the compiler vectorises, which rustc does only at
//! opt-level 3 (its SLP vectoriser): in test builds, at 2, the AVX2 kernel ran each lane on its
//! own, 2.3x slower. [`Vector`] states the vector operations themselves, so its kernel is
//! vectorised at any level. Each operation is the IEEE one the scalar path does, lane by lane: the
//! same bits. `min` and `max` go lane by lane through `f64::min` and `f64::max`, whose NaN rule no
//! single instruction has.
//!
//! The portable kernel keeps the arrays: as two SSE2 registers it ran 15-20 % slower in release
//! builds (`cargo bench -p bouncewear-model --bench engine -- arcing`, "portable x4"), where it
//! runs the devices left over beside AVX2's batches.
//!
//! SAFETY, for each `unsafe` block of the register below: [`Avx2x8`] is used only inside the
//! AVX2 kernel (`montecarlo::kernel`), which runs only where `Kernel::new` found AVX2 on the CPU,
//! and this module is private to the crate.

use super::{EXP2_INT_BIAS, Mask, Real, word};
use std::arch::x86_64::*;
use std::ops::{Add, BitAnd, BitOr, Div, Mul, Neg, Not, Sub};

/// The AVX2 kernel's lanes: eight, in two AVX registers.
pub(crate) type Avx2x8 = Vector<__m256d, 2>;

/// One vector register of `f64` lanes and the instructions the lanes need. Masks are registers
/// too, each lane a 64-bit word of all ones or all zeros.
pub(crate) trait Register: Copy + std::fmt::Debug {
    const LANES: usize;
    fn splat(x: f64) -> Self;
    /// Lane `i` is `f(i)`.
    fn from_fn(f: impl FnMut(usize) -> f64) -> Self;
    fn lane(self, i: usize) -> f64;
    fn add(self, other: Self) -> Self;
    fn sub(self, other: Self) -> Self;
    fn mul(self, other: Self) -> Self;
    fn div(self, other: Self) -> Self;
    fn sqrt(self) -> Self;
    fn and(self, other: Self) -> Self;
    /// `!self & other`, bit by bit.
    fn and_not(self, other: Self) -> Self;
    fn or(self, other: Self) -> Self;
    fn xor(self, other: Self) -> Self;
    /// Ordered comparisons, as Rust's `<`, `<=` and `==`: false where either is NaN.
    fn lt(self, other: Self) -> Self;
    fn le(self, other: Self) -> Self;
    fn eq(self, other: Self) -> Self;
    /// Every word's low 52 bits shifted into its exponent field ([`Real::exp2_int`]).
    fn shift_52(self) -> Self;
    /// Each lane's sign bit, lane 0 lowest.
    fn signs(self) -> u32;
    /// Every bit set.
    fn ones() -> Self;
}

impl Register for __m256d {
    const LANES: usize = 4;
    #[inline(always)]
    fn splat(x: f64) -> Self {
        unsafe { _mm256_set1_pd(x) }
    }
    #[inline(always)]
    fn from_fn(mut f: impl FnMut(usize) -> f64) -> Self {
        let mut lanes = [0.0; 4];
        for (i, slot) in lanes.iter_mut().enumerate() {
            *slot = f(i);
        }
        // SAFETY: as many `f64` as the register holds, every bit pattern valid.
        unsafe { std::mem::transmute::<[f64; 4], __m256d>(lanes) }
    }
    #[inline(always)]
    fn lane(self, i: usize) -> f64 {
        // SAFETY: as above.
        let lanes = unsafe { std::mem::transmute::<__m256d, [f64; 4]>(self) };
        lanes[i]
    }
    #[inline(always)]
    fn add(self, other: Self) -> Self {
        unsafe { _mm256_add_pd(self, other) }
    }
    #[inline(always)]
    fn sub(self, other: Self) -> Self {
        unsafe { _mm256_sub_pd(self, other) }
    }
    #[inline(always)]
    fn mul(self, other: Self) -> Self {
        unsafe { _mm256_mul_pd(self, other) }
    }
    #[inline(always)]
    fn div(self, other: Self) -> Self {
        unsafe { _mm256_div_pd(self, other) }
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        unsafe { _mm256_sqrt_pd(self) }
    }
    #[inline(always)]
    fn and(self, other: Self) -> Self {
        unsafe { _mm256_and_pd(self, other) }
    }
    #[inline(always)]
    fn and_not(self, other: Self) -> Self {
        unsafe { _mm256_andnot_pd(self, other) }
    }
    #[inline(always)]
    fn or(self, other: Self) -> Self {
        unsafe { _mm256_or_pd(self, other) }
    }
    #[inline(always)]
    fn xor(self, other: Self) -> Self {
        unsafe { _mm256_xor_pd(self, other) }
    }
    #[inline(always)]
    fn lt(self, other: Self) -> Self {
        unsafe { _mm256_cmp_pd::<_CMP_LT_OQ>(self, other) }
    }
    #[inline(always)]
    fn le(self, other: Self) -> Self {
        unsafe { _mm256_cmp_pd::<_CMP_LE_OQ>(self, other) }
    }
    #[inline(always)]
    fn eq(self, other: Self) -> Self {
        unsafe { _mm256_cmp_pd::<_CMP_EQ_OQ>(self, other) }
    }
    #[inline(always)]
    fn shift_52(self) -> Self {
        unsafe { _mm256_castsi256_pd(_mm256_slli_epi64::<52>(_mm256_castpd_si256(self))) }
    }
    #[inline(always)]
    fn signs(self) -> u32 {
        unsafe { _mm256_movemask_pd(self) as u32 }
    }
    #[inline(always)]
    fn ones() -> Self {
        unsafe { _mm256_castsi256_pd(_mm256_set1_epi64x(-1)) }
    }
}

/// `K` registers of `f64` lanes.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Vector<R, const K: usize>([R; K]);

/// A truth value per lane of a [`Vector`], each a 64-bit word of all ones or all zeros.
#[derive(Debug, Clone, Copy)]
pub(crate) struct VectorMask<R, const K: usize>([R; K]);

/// `f` on each register.
#[inline(always)]
fn each<R: Copy, const K: usize>(a: [R; K], f: impl Fn(R) -> R) -> [R; K] {
    let mut out = a;
    for k in 0..K {
        out[k] = f(a[k]);
    }
    out
}

/// `f` on each pair of registers.
#[inline(always)]
fn pairs<R: Copy, const K: usize>(a: [R; K], b: [R; K], f: impl Fn(R, R) -> R) -> [R; K] {
    let mut out = a;
    for k in 0..K {
        out[k] = f(a[k], b[k]);
    }
    out
}

impl<R: Register, const K: usize> Vector<R, K> {
    /// `f` lane by lane, as the scalar path computes it.
    #[inline(always)]
    fn lanewise(self, other: Self, f: impl Fn(f64, f64) -> f64) -> Self {
        Self(pairs(self.0, other.0, |a, b| {
            R::from_fn(|i| f(a.lane(i), b.lane(i)))
        }))
    }
}

macro_rules! vector_operator {
    ($trait:ident, $method:ident) => {
        impl<R: Register, const K: usize> $trait for Vector<R, K> {
            type Output = Self;
            #[inline(always)]
            fn $method(self, other: Self) -> Self {
                Self(pairs(self.0, other.0, R::$method))
            }
        }
    };
}
vector_operator!(Add, add);
vector_operator!(Sub, sub);
vector_operator!(Mul, mul);
vector_operator!(Div, div);

impl<R: Register, const K: usize> Neg for Vector<R, K> {
    type Output = Self;
    /// The sign bit flipped, as `-x` does.
    #[inline(always)]
    fn neg(self) -> Self {
        Self(each(self.0, |a| a.xor(R::splat(-0.0))))
    }
}

impl<R: Register, const K: usize> Real for Vector<R, K> {
    type Mask = VectorMask<R, K>;
    const LANES: usize = K * R::LANES;

    #[inline(always)]
    fn splat(x: f64) -> Self {
        Self([R::splat(x); K])
    }
    #[inline(always)]
    fn from_fn(mut f: impl FnMut(usize) -> f64) -> Self {
        let mut out = [R::splat(0.0); K];
        for (k, register) in out.iter_mut().enumerate() {
            *register = R::from_fn(|i| f(k * R::LANES + i));
        }
        Self(out)
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        Self(each(self.0, R::sqrt))
    }
    #[inline(always)]
    fn min(self, other: Self) -> Self {
        self.lanewise(other, f64::min)
    }
    #[inline(always)]
    fn max(self, other: Self) -> Self {
        self.lanewise(other, f64::max)
    }
    /// The sign bit cleared, as `f64::abs` does.
    #[inline(always)]
    fn abs(self) -> Self {
        Self(each(self.0, |a| R::splat(-0.0).and_not(a)))
    }
    /// The magnitude's bits with the sign's sign bit, as `f64::copysign` does.
    #[inline(always)]
    fn copysign(self, sign: Self) -> Self {
        let bit = R::splat(-0.0);
        Self(pairs(self.0, sign.0, |a, s| bit.and_not(a).or(bit.and(s))))
    }
    #[inline(always)]
    fn lt(self, other: Self) -> Self::Mask {
        VectorMask(pairs(self.0, other.0, R::lt))
    }
    #[inline(always)]
    fn le(self, other: Self) -> Self::Mask {
        VectorMask(pairs(self.0, other.0, R::le))
    }
    #[inline(always)]
    fn eq(self, other: Self) -> Self::Mask {
        VectorMask(pairs(self.0, other.0, R::eq))
    }
    /// Bit by bit, as [`Lanes`](super::Lanes) selects.
    #[inline(always)]
    fn select(mask: Self::Mask, yes: Self, no: Self) -> Self {
        let mut out = no.0;
        for k in 0..K {
            let m = mask.0[k];
            out[k] = m.and(yes.0[k]).or(m.and_not(no.0[k]));
        }
        Self(out)
    }
    #[inline(always)]
    fn exp2_int(self) -> Self {
        Self(each(self.0, |a| a.add(R::splat(EXP2_INT_BIAS)).shift_52()))
    }
    #[inline(always)]
    fn lane(&self, i: usize) -> f64 {
        self.0[i / R::LANES].lane(i % R::LANES)
    }

    #[inline(always)]
    fn set_lane(&mut self, i: usize, x: f64) {
        let (k, j) = (i / R::LANES, i % R::LANES);
        let register = self.0[k];
        self.0[k] = R::from_fn(|l| if l == j { x } else { register.lane(l) });
    }

    type Part = Self;
}

impl<R: Register, const K: usize> BitAnd for VectorMask<R, K> {
    type Output = Self;
    #[inline(always)]
    fn bitand(self, other: Self) -> Self {
        Self(pairs(self.0, other.0, R::and))
    }
}

impl<R: Register, const K: usize> BitOr for VectorMask<R, K> {
    type Output = Self;
    #[inline(always)]
    fn bitor(self, other: Self) -> Self {
        Self(pairs(self.0, other.0, R::or))
    }
}

impl<R: Register, const K: usize> Not for VectorMask<R, K> {
    type Output = Self;
    #[inline(always)]
    fn not(self) -> Self {
        Self(each(self.0, |a| a.xor(R::ones())))
    }
}

impl<R: Register, const K: usize> Mask for VectorMask<R, K> {
    #[inline(always)]
    fn from_fn(mut f: impl FnMut(usize) -> bool) -> Self {
        let mut out = [R::splat(0.0); K];
        for (k, register) in out.iter_mut().enumerate() {
            *register = R::from_fn(|i| f64::from_bits(word(f(k * R::LANES + i))));
        }
        Self(out)
    }
    #[inline(always)]
    fn any(self) -> bool {
        let mut signs = 0;
        for k in 0..K {
            signs |= self.0[k].signs();
        }
        signs != 0
    }
    #[inline(always)]
    fn count(self) -> usize {
        let mut count = 0;
        for k in 0..K {
            count += self.0[k].signs().count_ones() as usize;
        }
        count
    }
    #[inline(always)]
    fn lane(&self, i: usize) -> bool {
        self.0[i / R::LANES].lane(i % R::LANES).to_bits() != 0
    }
    #[inline(always)]
    fn set_lane(&mut self, i: usize, truth: bool) {
        let (k, j) = (i / R::LANES, i % R::LANES);
        let register = self.0[k];
        self.0[k] = R::from_fn(|l| {
            if l == j {
                f64::from_bits(word(truth))
            } else {
                register.lane(l)
            }
        });
    }
}

#[cfg(test)]
mod tests {
    use super::super::Lanes;
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

    fn bits<L: Real>(x: L) -> Vec<u64> {
        (0..L::LANES).map(|i| x.lane(i).to_bits()).collect()
    }

    fn truths<M: Mask>(m: M, lanes: usize) -> Vec<bool> {
        (0..lanes).map(|i| m.lane(i)).collect()
    }

    /// Every operation of `V` gives, bit for bit, what the array lanes `A` (and so the scalar
    /// path) give, on every pair of the edge values.
    fn same_bits<V: Real, A: Real>() {
        assert_eq!(V::LANES, A::LANES);
        let n = V::LANES;
        for shift in 0..EDGES.len() {
            for start in (0..EDGES.len()).step_by(n) {
                let a = |i: usize| EDGES[(start + i) % 16];
                let b = |i: usize| EDGES[(start + i + shift + 8 * (shift % 2)) % 16];
                let (x, y) = (V::from_fn(a), V::from_fn(b));
                let (u, v) = (A::from_fn(a), A::from_fn(b));
                assert_eq!(bits(x + y), bits(u + v));
                assert_eq!(bits(x - y), bits(u - v));
                assert_eq!(bits(x * y), bits(u * v));
                assert_eq!(bits(x / y), bits(u / v));
                assert_eq!(bits(-x), bits(-u));
                assert_eq!(bits(x.sqrt()), bits(u.sqrt()));
                assert_eq!(bits(x.min(y)), bits(u.min(v)));
                assert_eq!(bits(x.max(y)), bits(u.max(v)));
                assert_eq!(bits(x.abs()), bits(u.abs()));
                assert_eq!(bits(x.copysign(y)), bits(u.copysign(v)));
                for (mask, array) in [
                    (x.lt(y), u.lt(v)),
                    (x.le(y), u.le(v)),
                    (x.eq(y), u.eq(v)),
                    (x.gt(y), u.gt(v)),
                    (!x.ge(y) | x.eq(y), !u.ge(v) | u.eq(v)),
                    (x.lt(y) & x.le(y), u.lt(v) & u.le(v)),
                ] {
                    assert_eq!(truths(mask, n), truths(array, n));
                    assert_eq!(mask.any(), array.any());
                    assert_eq!(mask.count(), array.count());
                    assert_eq!(bits(V::select(mask, x, y)), bits(A::select(array, u, v)));
                }
            }
        }
        let powers = |i: usize| i as f64 * 146.0 - 1022.0;
        assert_eq!(
            bits(V::from_fn(powers).exp2_int()),
            bits(A::from_fn(powers).exp2_int())
        );
        let mut set = V::from_fn(powers);
        set.set_lane(n - 1, -0.0);
        assert_eq!(set.lane(n - 1).to_bits(), (-0.0f64).to_bits());
        assert_eq!(set.lane(0), powers(0));
        let mut mask = V::Mask::from_fn(|i| i % 3 == 0);
        mask.set_lane(1, true);
        mask.set_lane(0, false);
        let expected: Vec<bool> = (0..n).map(|i| i == 1 || (i > 0 && i % 3 == 0)).collect();
        assert_eq!(truths(mask, n), expected);
        assert_eq!(mask.count(), expected.iter().filter(|&&t| t).count());
    }

    #[test]
    fn avx2_lanes_give_the_bits_of_the_array_lanes() {
        if !std::arch::is_x86_feature_detected!("avx2") {
            eprintln!("no AVX2 on this CPU: nothing to compare");
            return;
        }
        same_bits::<Avx2x8, Lanes<8>>();
    }
}
