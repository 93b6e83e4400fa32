//! Numbers the physics is written over: one `f64`, or a batch of devices in lockstep.
//!
//! The operation (docs/model.md sections 1-5) is written once, generic over [`Real`], so the scalar
//! path (`simulate`, one device) and the batch path ([`Lanes`], one value per device) cannot drift
//! apart: the batch path is the scalar path run on every lane.
//!
//! Same bits on every CPU: a [`Real`] offers only `+`, `-`, `*`, `/`, `sqrt` (all correctly rounded
//! by IEEE 754), comparisons, `min`, `max`, selection and exact bit manipulation. No fused
//! multiply-add (Rust never contracts `a * b + c` by itself) and no libm: `atan` and `exp` are this
//! crate's own ([`crate::elementary`]). Whatever instruction set a [`Lanes`] loop is compiled for, and
//! however many lanes it has, each lane rounds exactly as the scalar does.

// Lane loops index several arrays at once: the index is the lane.
#![allow(clippy::needless_range_loop)]

use std::ops::{Add, BitAnd, BitOr, Div, Mul, Neg, Not, Sub};

#[cfg(target_arch = "x86_64")]
pub(crate) mod avx2;

/// A number, or a batch of numbers computed in lockstep.
pub trait Real:
    Copy
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
{
    /// One truth value per lane.
    type Mask: Mask;
    /// How many numbers this is.
    const LANES: usize;

    /// Every lane `x`.
    fn splat(x: f64) -> Self;
    /// Lane `i` is `f(i)`.
    fn from_fn(f: impl FnMut(usize) -> f64) -> Self;
    fn sqrt(self) -> Self;
    /// IEEE `minNum`: the other operand when one is NaN.
    fn min(self, other: Self) -> Self;
    fn max(self, other: Self) -> Self;
    fn abs(self) -> Self;
    /// `self`'s magnitude with `sign`'s sign bit.
    fn copysign(self, sign: Self) -> Self;
    fn lt(self, other: Self) -> Self::Mask;
    fn le(self, other: Self) -> Self::Mask;
    fn eq(self, other: Self) -> Self::Mask;
    /// Where `mask` holds, `yes`; elsewhere `no`.
    fn select(mask: Self::Mask, yes: Self, no: Self) -> Self;
    /// `2^self` for a whole number `self` in `[-1022, 1023]`, built from its bits (exact).
    fn exp2_int(self) -> Self;
    /// Lane `i`.
    fn lane(&self, i: usize) -> f64;

    /// Sets lane `i` to `x`.
    fn set_lane(&mut self, i: usize, x: f64);

    /// A narrower batch the bounce loop moves its last lanes into once few of them still bounce:
    /// one vector register (eight lanes) for a batch of several, else the batch itself
    /// (docs/performance.md "Lanes that have stopped"). A lane computes the same in either.
    type Part: Real;

    // Inlined like every lane operation: a default method is compiled once, in one codegen unit,
    // and test builds (256 units, no LTO) called it out of line from every kernel, 8.7 % of
    // `run`'s time there; inlined, `run` of 10^7 operations took 4.1-4.3 s against 5.1-5.5 s.
    #[inline(always)]
    fn gt(self, other: Self) -> Self::Mask {
        other.lt(self)
    }
    #[inline(always)]
    fn ge(self, other: Self) -> Self::Mask {
        other.le(self)
    }
}

/// One truth value per lane.
pub trait Mask: Copy + BitAnd<Output = Self> + BitOr<Output = Self> + Not<Output = Self> {
    /// Lane `i` is `f(i)`.
    fn from_fn(f: impl FnMut(usize) -> bool) -> Self;
    fn any(self) -> bool;
    /// How many lanes hold.
    fn count(self) -> usize;
    fn lane(&self, i: usize) -> bool;
    fn set_lane(&mut self, i: usize, truth: bool);
}

/// `2^52 + 1023`: adding a whole number `n` in `[-1022, 1023]` leaves `n + 1023` in the low mantissa
/// bits, which shifted into the exponent field are `2^n`.
const EXP2_INT_BIAS: f64 = 4_503_599_627_371_519.0;

impl Real for f64 {
    type Mask = bool;
    const LANES: usize = 1;

    #[inline(always)]
    fn splat(x: f64) -> Self {
        x
    }
    #[inline(always)]
    fn from_fn(mut f: impl FnMut(usize) -> f64) -> Self {
        f(0)
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        f64::sqrt(self)
    }
    #[inline(always)]
    fn min(self, other: Self) -> Self {
        f64::min(self, other)
    }
    #[inline(always)]
    fn max(self, other: Self) -> Self {
        f64::max(self, other)
    }
    #[inline(always)]
    fn abs(self) -> Self {
        f64::abs(self)
    }
    #[inline(always)]
    fn copysign(self, sign: Self) -> Self {
        f64::copysign(self, sign)
    }
    #[inline(always)]
    fn lt(self, other: Self) -> bool {
        self < other
    }
    #[inline(always)]
    fn le(self, other: Self) -> bool {
        self <= other
    }
    #[inline(always)]
    fn eq(self, other: Self) -> bool {
        self == other
    }
    #[inline(always)]
    fn select(mask: bool, yes: Self, no: Self) -> Self {
        if mask { yes } else { no }
    }
    #[inline(always)]
    fn exp2_int(self) -> Self {
        f64::from_bits((self + EXP2_INT_BIAS).to_bits() << 52)
    }
    #[inline(always)]
    fn lane(&self, _: usize) -> f64 {
        *self
    }

    #[inline(always)]
    fn set_lane(&mut self, _: usize, x: f64) {
        *self = x;
    }

    type Part = f64;
}

impl Mask for bool {
    #[inline(always)]
    fn from_fn(mut f: impl FnMut(usize) -> bool) -> bool {
        f(0)
    }
    #[inline(always)]
    fn any(self) -> bool {
        self
    }
    #[inline(always)]
    fn count(self) -> usize {
        usize::from(self)
    }
    #[inline(always)]
    fn lane(&self, _: usize) -> bool {
        *self
    }
    #[inline(always)]
    fn set_lane(&mut self, _: usize, truth: bool) {
        *self = truth;
    }
}

/// `N` devices' values of one quantity, computed lane by lane in loops the compiler vectorises for
/// whatever instruction set the calling function enables (at opt-level 3; the AVX2 kernel's lanes
/// are `avx2::Lanes8`, vectorised at any level).
#[derive(Debug, Clone, Copy, PartialEq)]
#[repr(C, align(64))]
pub struct Lanes<const N: usize>(pub [f64; N]);

/// `N` truth values, one per lane of a [`Lanes`], each a 64-bit word of all ones (true) or all
/// zeros (false): the form vector compares produce and blends consume, so a comparison and a
/// selection stay one instruction per register.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(C, align(64))]
pub struct LaneMask<const N: usize>([u64; N]);

/// The mask word of a truth value.
#[inline(always)]
fn word(truth: bool) -> u64 {
    (truth as u64).wrapping_neg()
}

// Every lane operation below is a plain indexed loop over the arrays: after inlining into a
// kernel compiled for an instruction set, the loop vectoriser turns each into full-width
// instructions of that set (closures through `std::array::from_fn` were left half-vectorised,
// and out of line they ran in the baseline instruction set).
impl<const N: usize> Lanes<N> {
    #[inline(always)]
    fn map(self, f: impl Fn(f64) -> f64) -> Self {
        let mut out = [0.0; N];
        for i in 0..N {
            out[i] = f(self.0[i]);
        }
        Self(out)
    }

    #[inline(always)]
    fn zip(self, other: Self, f: impl Fn(f64, f64) -> f64) -> Self {
        let mut out = [0.0; N];
        for i in 0..N {
            out[i] = f(self.0[i], other.0[i]);
        }
        Self(out)
    }

    #[inline(always)]
    fn compare(self, other: Self, f: impl Fn(f64, f64) -> bool) -> LaneMask<N> {
        let mut out = [0; N];
        for i in 0..N {
            out[i] = word(f(self.0[i], other.0[i]));
        }
        LaneMask(out)
    }
}

macro_rules! lane_operator {
    ($trait:ident, $method:ident, $op:tt) => {
        impl<const N: usize> $trait for Lanes<N> {
            type Output = Self;
            #[inline(always)]
            fn $method(self, other: Self) -> Self {
                self.zip(other, |a, b| a $op b)
            }
        }
    };
}
lane_operator!(Add, add, +);
lane_operator!(Sub, sub, -);
lane_operator!(Mul, mul, *);
lane_operator!(Div, div, /);

impl<const N: usize> Neg for Lanes<N> {
    type Output = Self;
    #[inline(always)]
    fn neg(self) -> Self {
        self.map(|a| -a)
    }
}

/// The narrower batch of a batch ([`Real::Part`]): eight lanes, one AVX-512 register, or the
/// batch itself when it is no wider.
pub trait Split {
    type Part: Real;
}

macro_rules! split {
    ($($lanes:literal => $part:literal),*) => {
        $(impl Split for Lanes<$lanes> {
            type Part = Lanes<$part>;
        })*
    };
}
split!(1 => 1, 2 => 2, 4 => 4, 8 => 8, 16 => 8, 32 => 8, 64 => 8);

impl<const N: usize> Real for Lanes<N>
where
    Lanes<N>: Split,
{
    type Mask = LaneMask<N>;
    const LANES: usize = N;

    #[inline(always)]
    fn splat(x: f64) -> Self {
        Self([x; N])
    }
    #[inline(always)]
    fn from_fn(mut f: impl FnMut(usize) -> f64) -> Self {
        let mut out = [0.0; N];
        for (i, slot) in out.iter_mut().enumerate() {
            *slot = f(i);
        }
        Self(out)
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        self.map(f64::sqrt)
    }
    #[inline(always)]
    fn min(self, other: Self) -> Self {
        self.zip(other, f64::min)
    }
    #[inline(always)]
    fn max(self, other: Self) -> Self {
        self.zip(other, f64::max)
    }
    #[inline(always)]
    fn abs(self) -> Self {
        self.map(f64::abs)
    }
    #[inline(always)]
    fn copysign(self, sign: Self) -> Self {
        self.zip(sign, f64::copysign)
    }
    #[inline(always)]
    fn lt(self, other: Self) -> LaneMask<N> {
        self.compare(other, |a, b| a < b)
    }
    #[inline(always)]
    fn le(self, other: Self) -> LaneMask<N> {
        self.compare(other, |a, b| a <= b)
    }
    #[inline(always)]
    fn eq(self, other: Self) -> LaneMask<N> {
        self.compare(other, |a, b| a == b)
    }
    #[inline(always)]
    fn select(mask: LaneMask<N>, yes: Self, no: Self) -> Self {
        let mut out = [0.0; N];
        for i in 0..N {
            let m = mask.0[i];
            out[i] = f64::from_bits((yes.0[i].to_bits() & m) | (no.0[i].to_bits() & !m));
        }
        Self(out)
    }
    #[inline(always)]
    fn exp2_int(self) -> Self {
        self.map(<f64 as Real>::exp2_int)
    }
    #[inline(always)]
    fn lane(&self, i: usize) -> f64 {
        self.0[i]
    }

    #[inline(always)]
    fn set_lane(&mut self, i: usize, x: f64) {
        self.0[i] = x;
    }

    type Part = <Self as Split>::Part;
}

macro_rules! mask_operator {
    ($trait:ident, $method:ident, $op:tt) => {
        impl<const N: usize> $trait for LaneMask<N> {
            type Output = Self;
            #[inline(always)]
            fn $method(self, other: Self) -> Self {
                let mut out = [0; N];
                for i in 0..N {
                    out[i] = self.0[i] $op other.0[i];
                }
                Self(out)
            }
        }
    };
}
mask_operator!(BitAnd, bitand, &);
mask_operator!(BitOr, bitor, |);

impl<const N: usize> Not for LaneMask<N> {
    type Output = Self;
    #[inline(always)]
    fn not(self) -> Self {
        let mut out = [0; N];
        for i in 0..N {
            out[i] = !self.0[i];
        }
        Self(out)
    }
}

impl<const N: usize> Mask for LaneMask<N> {
    #[inline(always)]
    fn from_fn(mut f: impl FnMut(usize) -> bool) -> Self {
        let mut out = [0; N];
        for i in 0..N {
            out[i] = word(f(i));
        }
        Self(out)
    }
    #[inline(always)]
    fn any(self) -> bool {
        let mut any = 0;
        for i in 0..N {
            any |= self.0[i];
        }
        any != 0
    }
    #[inline(always)]
    fn count(self) -> usize {
        let mut count = 0;
        for i in 0..N {
            count += (self.0[i] & 1) as usize;
        }
        count
    }
    #[inline(always)]
    fn lane(&self, i: usize) -> bool {
        self.0[i] != 0
    }
    #[inline(always)]
    fn set_lane(&mut self, i: usize, truth: bool) {
        self.0[i] = word(truth);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exp2_int_is_the_power_of_two_across_the_normal_range() {
        for n in -1022..=1023 {
            assert_eq!(f64::from(n).exp2_int(), 2f64.powi(n), "2^{n}");
        }
    }

    #[test]
    fn a_lane_of_a_batch_computes_what_the_scalar_does() {
        let x = Lanes([0.3, -2.0, 7.5, 1e300]);
        let y = Lanes([1.1, 0.0, -7.5, 2.0]);
        let batch = Lanes::select(
            (x * y).lt(y / x),
            (x + y).sqrt(),
            (x - y).min(-x).copysign(y),
        );
        for i in 0..4 {
            let (x, y) = (x.0[i], y.0[i]);
            let scalar = f64::select(
                (x * y).lt(y / x),
                (x + y).sqrt(),
                (x - y).min(-x).copysign(y),
            );
            assert_eq!(batch.0[i].to_bits(), scalar.to_bits(), "lane {i}");
        }
    }
}
