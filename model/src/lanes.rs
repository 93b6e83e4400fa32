//! Numbers the physics is written over: one `f64`, or a batch of devices in lockstep.
//!
//! The operation (docs/model.md sections 1-5) is written once, generic over [`Real`], so the scalar
//! path (`simulate`, one device) and the batch path ([`Lanes`], one value per device) cannot drift
//! apart: the batch path is the scalar path run on every lane.
//!
//! Same bits on every CPU: a [`Real`] offers only `+`, `-`, `*`, `/`, `sqrt` (all correctly rounded
//! by IEEE 754), comparisons, `min`, `max`, selection and exact bit manipulation. No fused
//! multiply-add (Rust never contracts `a * b + c` by itself) and no libm: `atan` and `exp` are this
//! crate's own ([`crate::elementary`]). Whatever instruction set a [`Lanes`] batch is compiled for, and
//! however many lanes it has, each lane rounds exactly as the scalar does.

use std::ops::{Add, BitAnd, BitOr, Div, Mul, Neg, Not, Range, Sub};

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
    /// (docs/performance-history.md "Lanes that have stopped"). A lane computes the same in either.
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
    /// One bit per lane that holds, lane 0 lowest (a batch has at most 64 lanes).
    fn bits(self) -> u64;
    fn lane(&self, i: usize) -> bool;
    fn set_lane(&mut self, i: usize, truth: bool);
}

/// The most lanes a batch has: one bit each in a word ([`Mask::bits`]).
pub const MAX_LANES: usize = 64;

/// The lanes `lanes` as [`Mask::bits`] gives them: one bit each, lane 0 lowest.
#[inline(always)]
pub fn lane_bits(lanes: Range<usize>) -> u64 {
    debug_assert!(
        lanes.end <= MAX_LANES,
        "{lanes:?}: a batch has at most 64 lanes"
    );
    match lanes.end.checked_sub(lanes.start) {
        Some(1..) => (u64::MAX >> (64 - lanes.end)) & (u64::MAX << lanes.start),
        _ => 0,
    }
}

/// The lanes `lanes` of a batch as a mask, or `None` when they are all of its lanes: made once
/// for the columns of a batch ([`fill_lanes`]).
#[inline(always)]
pub(crate) fn within_lanes<L: Real>(lanes: &Range<usize>) -> Option<L::Mask> {
    (lanes.len() != L::LANES).then(|| L::Mask::from_fn(|k| lanes.contains(&k)))
}

/// `x` with the lanes outside `lanes` (`within` as [`within_lanes`] made it) set to its first
/// lane within, so that the batch's least and greatest values are those of `lanes`.
#[inline(always)]
pub(crate) fn fill_lanes<L: Real>(x: &L, lanes: &Range<usize>, within: Option<L::Mask>) -> L {
    match within {
        Some(inside) if !lanes.is_empty() => L::select(inside, *x, L::splat(x.lane(lanes.start))),
        _ => *x,
    }
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
    fn bits(self) -> u64 {
        u64::from(self)
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

/// `N` devices' values of one quantity, computed lane by lane in straight-line code the compiler
/// vectorises for whatever instruction set the calling function enables (at opt-level 3; the AVX2
/// kernel's lanes are `avx2::Lanes8`, vectorised at any level).
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

/// One value per lane, `$value` with `$i` bound to each lane's index in turn: an array expression
/// over the list of indices `[..]` (the lanes written out), or a loop over `(loop N)` lanes.
macro_rules! per_lane {
    ([$($index:literal)*], $i:ident => $value:expr) => {
        [$({
            let $i: usize = $index;
            $value
        }),*]
    };
    ((loop $lanes:literal), $i:ident => $value:expr) => {{
        let mut out = [Default::default(); $lanes];
        for $i in 0..$lanes {
            out[$i] = $value;
        }
        out
    }};
}

/// Whether any lane's word of `$words` is set, how many lanes hold and which (one bit each), over
/// the lanes as [`per_lane!`] walks them.
macro_rules! reduce_lanes {
    ([$($index:literal)*], $words:expr, any) => {
        (0 $(| $words[$index])*) != 0
    };
    ([$($index:literal)*], $words:expr, count) => {
        0 $(+ ($words[$index] & 1) as usize)*
    };
    ([$($index:literal)*], $words:expr, bits) => {
        0 $(| (($words[$index] & 1) << $index))*
    };
    ((loop $lanes:literal), $words:expr, any) => {{
        let mut any = 0;
        for i in 0..$lanes {
            any |= $words[i];
        }
        any != 0
    }};
    ((loop $lanes:literal), $words:expr, count) => {{
        let mut count = 0;
        for i in 0..$lanes {
            count += ($words[i] & 1) as usize;
        }
        count
    }};
    ((loop $lanes:literal), $words:expr, bits) => {{
        let mut bits = 0;
        for i in 0..$lanes {
            bits |= ($words[i] & 1) << i;
        }
        bits
    }};
}

/// `$trait` for `Lanes<$lanes>`: `$op` lane by lane.
macro_rules! lane_operator {
    ($lanes:literal, $trait:ident, $method:ident, $op:tt) => {
        impl $trait for Lanes<$lanes> {
            type Output = Self;
            #[inline(always)]
            fn $method(self, other: Self) -> Self {
                self.zip(other, |a, b| a $op b)
            }
        }
    };
}

/// `$trait` for `LaneMask<$lanes>`: `$op` word by word over the lanes as [`per_lane!`] walks them.
macro_rules! mask_operator {
    ($lanes:literal, $trait:ident, $method:ident, $op:tt, $walk:tt) => {
        impl $trait for LaneMask<$lanes> {
            type Output = Self;
            #[inline(always)]
            fn $method(self, other: Self) -> Self {
                Self(per_lane!($walk, i => self.0[i] $op other.0[i]))
            }
        }
    };
}

/// The lanes of each width the kernels use: `$lanes` lanes, narrowing to `$part` ([`Real::Part`]:
/// eight lanes, one AVX-512 register, or the batch itself when it is no wider), walked as `$walk`
/// says ([`per_lane!`]).
///
/// Four and eight lanes are written out lane by lane over the list of their indices, with no
/// loop: after inlining into a kernel compiled for an instruction set, LLVM's SLP vectoriser packs
/// the lanes into full-width instructions of that set. These operations were indexed loops, which
/// gave the same machine code only after LLVM had rotated and fully unrolled each of them: in the
/// portable kernel, thousands of four-lane loops inlined into one function took 89 s of LLVM's
/// time (rotation 67 s, unrolling 22 s; `-Zllvm-time-trace`, test profile, 2-core EPYC VM), and
/// again in the model's test binary. The library took 122 s of rustc's time so, 45 s written out.
/// Thirty-two lanes stay loops, which the loop vectoriser turns into four AVX-512 registers:
/// written out, the AVX-512 kernel ran 8-12 % slower (`cargo bench -p bouncewear-model --bench
/// engine`, 2-core AMD EPYC Zen 5, interleaved: 15 A 79-94 ms against 74-78, mechanical 94 against
/// 82-87), for a library that builds in the same wall time (17 s more CPU, in parallel codegen
/// units), and only where the AVX-512 kernel is built. (Closures through `std::array::from_fn` were
/// left half-vectorised, and out of line they ran in the baseline instruction set.)
macro_rules! lanes {
    ($($lanes:literal lanes, part $part:literal: $walk:tt;)*) => {$(
        const _: () = assert!($lanes <= MAX_LANES, "a lane's bit must fit in a word");
        impl Lanes<$lanes> {
            #[inline(always)]
            fn map(self, f: impl Fn(f64) -> f64) -> Self {
                Self(per_lane!($walk, i => f(self.0[i])))
            }

            #[inline(always)]
            fn zip(self, other: Self, f: impl Fn(f64, f64) -> f64) -> Self {
                Self(per_lane!($walk, i => f(self.0[i], other.0[i])))
            }

            #[inline(always)]
            fn compare(self, other: Self, f: impl Fn(f64, f64) -> bool) -> LaneMask<$lanes> {
                LaneMask(per_lane!($walk, i => word(f(self.0[i], other.0[i]))))
            }
        }

        lane_operator!($lanes, Add, add, +);
        lane_operator!($lanes, Sub, sub, -);
        lane_operator!($lanes, Mul, mul, *);
        lane_operator!($lanes, Div, div, /);

        impl Neg for Lanes<$lanes> {
            type Output = Self;
            #[inline(always)]
            fn neg(self) -> Self {
                self.map(|a| -a)
            }
        }

        impl Real for Lanes<$lanes> {
            type Mask = LaneMask<$lanes>;
            const LANES: usize = $lanes;

            #[inline(always)]
            fn splat(x: f64) -> Self {
                Self([x; $lanes])
            }
            /// `f` called on the lanes in order (an array expression evaluates left to right).
            #[inline(always)]
            fn from_fn(mut f: impl FnMut(usize) -> f64) -> Self {
                Self(per_lane!($walk, i => f(i)))
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
            fn lt(self, other: Self) -> Self::Mask {
                self.compare(other, |a, b| a < b)
            }
            #[inline(always)]
            fn le(self, other: Self) -> Self::Mask {
                self.compare(other, |a, b| a <= b)
            }
            #[inline(always)]
            fn eq(self, other: Self) -> Self::Mask {
                self.compare(other, |a, b| a == b)
            }
            #[inline(always)]
            fn select(mask: Self::Mask, yes: Self, no: Self) -> Self {
                let pick = |m: u64, yes: f64, no: f64| {
                    f64::from_bits((yes.to_bits() & m) | (no.to_bits() & !m))
                };
                Self(per_lane!($walk, i => pick(mask.0[i], yes.0[i], no.0[i])))
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

            type Part = Lanes<$part>;
        }

        mask_operator!($lanes, BitAnd, bitand, &, $walk);
        mask_operator!($lanes, BitOr, bitor, |, $walk);

        impl Not for LaneMask<$lanes> {
            type Output = Self;
            #[inline(always)]
            fn not(self) -> Self {
                Self(per_lane!($walk, i => !self.0[i]))
            }
        }

        impl Mask for LaneMask<$lanes> {
            #[inline(always)]
            fn from_fn(mut f: impl FnMut(usize) -> bool) -> Self {
                Self(per_lane!($walk, i => word(f(i))))
            }
            #[inline(always)]
            fn any(self) -> bool {
                reduce_lanes!($walk, self.0, any)
            }
            #[inline(always)]
            fn count(self) -> usize {
                reduce_lanes!($walk, self.0, count)
            }
            #[inline(always)]
            fn bits(self) -> u64 {
                reduce_lanes!($walk, self.0, bits)
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
    )*};
}
lanes! {
    4 lanes, part 4: [0 1 2 3];
    8 lanes, part 8: [0 1 2 3 4 5 6 7];
    32 lanes, part 8: (loop 32);
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

    /// `bits` are the lanes that hold, on every width the kernels use, against the lanes taken one
    /// by one.
    #[test]
    fn a_mask_reduces_to_its_lanes_bits() {
        fn check<L: Real>(values: &[f64]) {
            let x = L::from_fn(|i| values[i % values.len()]);
            let positive = x.gt(L::splat(0.0));
            let expected = (0..L::LANES)
                .filter(|&i| x.lane(i) > 0.0)
                .fold(0, |bits, i| bits | 1 << i);
            assert_eq!(positive.bits(), expected, "{} lanes", L::LANES);
        }
        let values = [
            3.0, -1.5, 0.0, 7.25, -8.0, 1e-300, 2.5, 1e300, -0.0, 4.0, 0.5,
        ];
        for start in 0..values.len() {
            let values: Vec<f64> = values
                .iter()
                .cycle()
                .skip(start)
                .take(11)
                .copied()
                .collect();
            check::<f64>(&values);
            check::<Lanes<4>>(&values);
            check::<Lanes<8>>(&values);
            check::<Lanes<32>>(&values);
        }
    }

    #[test]
    fn lane_bits_are_the_lanes_of_a_range() {
        assert_eq!(lane_bits(0..0), 0);
        assert_eq!(lane_bits(3..3), 0);
        assert_eq!(lane_bits(0..1), 1);
        assert_eq!(lane_bits(0..8), 0xff);
        assert_eq!(lane_bits(2..5), 0b1_1100);
        assert_eq!(lane_bits(0..32), 0xffff_ffff);
        assert_eq!(lane_bits(31..32), 1 << 31);
        assert_eq!(lane_bits(0..64), u64::MAX);
        assert_eq!(lane_bits(63..64), 1 << 63);
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
