//! `atan` and `exp` of the exact tier, from `+`, `-`, `*`, `/` alone, for any [`Real`].
//!
//! glibc picks its `atan` and `exp` by CPU (and the results differ in the last bit between its
//! variants), so a job that called them gave different bits on different machines. These give the
//! same bits everywhere, one lane or many. They are Moshier's Cephes rational approximations,
//! evaluated branch-free so that every lane takes the same path.
//!
//! Accuracy, measured against 50-digit values over the whole input range (`tools/elementary_reference.py`,
//! checked by the tests below on the committed points of `tests/data/elementary_reference.json`):
//! [`atan`] within [`ATAN_MAX_ULP`] and [`exp`] within [`EXP_MAX_ULP`] units in the last place.

use crate::lanes::Real;

/// The error bound of [`atan`] in units in the last place of the true value (0.90 measured).
pub const ATAN_MAX_ULP: f64 = 1.0;
/// The error bound of [`exp`] in units in the last place of the true value (1.39 measured: the
/// final `1 + 2 y` and the reduced argument each round once).
pub const EXP_MAX_ULP: f64 = 1.5;

/// `tan(3 pi / 8)`: above it, `atan(x) = pi/2 - atan(1/x)`.
const TAN_3_PI_8: f64 = 2.414_213_562_373_095;
/// `pi/2` less its f64 value: what the reduction adds back.
const PI_2_LOW: f64 = 6.123_233_995_736_766e-17;

/// The arc tangent, odd, increasing, in `[-pi/2, pi/2]`.
///
/// `|x|` is reduced to `t` in `[-0.42, 0.66]`: `t = |x|` up to 0.66, `(|x| - 1)/(|x| + 1)` (adding
/// `pi/4`) up to `tan(3 pi/8)`, and `-1/|x|` (adding `pi/2`) above. `atan(t) = t + t^3 P(t^2)/Q(t^2)`
/// with Cephes' degree 4/5 rational function. One division reduces, one evaluates.
#[inline(always)]
pub fn atan<L: Real>(x: L) -> L {
    const P: [f64; 5] = [
        -8.750_608_600_031_904e-1,
        -1.615_753_718_733_365e1,
        -7.500_855_792_314_705e1,
        -1.228_866_684_490_136e2,
        -6.485_021_904_942_025e1,
    ];
    const Q: [f64; 5] = [
        2.485_846_490_142_306e1,
        1.650_270_098_316_988_5e2,
        4.328_810_604_912_903e2,
        4.853_903_996_359_137e2,
        1.945_506_571_482_614e2,
    ];
    let c = L::splat;
    let a = x.abs();
    let far = a.gt(c(TAN_3_PI_8));
    let middle = a.gt(c(0.66)) & !far;
    let numerator = L::select(far, c(-1.0), L::select(middle, a - c(1.0), a));
    let denominator = L::select(far, a, L::select(middle, a + c(1.0), c(1.0)));
    let t = numerator / denominator;
    let z = t * t;
    let p = (((c(P[0]) * z + c(P[1])) * z + c(P[2])) * z + c(P[3])) * z + c(P[4]);
    let q = ((((z + c(Q[0])) * z + c(Q[1])) * z + c(Q[2])) * z + c(Q[3])) * z + c(Q[4]);
    let near_t = t * (z * p / q) + t;
    let base = L::select(
        far,
        c(std::f64::consts::FRAC_PI_2),
        L::select(middle, c(std::f64::consts::FRAC_PI_4), c(0.0)),
    );
    let low = L::select(
        far,
        c(PI_2_LOW),
        L::select(middle, c(0.5 * PI_2_LOW), c(0.0)),
    );
    (base + (near_t + low)).copysign(x)
}

/// `ln((1 - 2^-53) 2^1024)`: above it `exp` overflows.
const EXP_OVERFLOW: f64 = 709.782_712_893_384;
/// `ln(2^-1075)`: below it `exp` rounds to 0.
const EXP_UNDERFLOW: f64 = -745.133_219_101_941_2;

/// `e^x`, over the whole f64 range: `+inf` above 709.78, 0 below -745.13, subnormal between.
///
/// `x = n ln 2 + r` with `n` the nearest whole number to `x / ln 2` and `ln 2` split in two (the
/// first part has few bits, so `n` times it is exact); `e^r = 1 + 2 r P(r^2) / (Q(r^2) - r P(r^2))`
/// with Cephes' Pade coefficients; `2^n` is applied as two exact powers so that results in the
/// subnormal range are rounded once.
#[inline(always)]
pub fn exp<L: Real>(x: L) -> L {
    const P: [f64; 3] = [
        1.261_771_930_748_105_9e-4,
        3.029_944_077_074_419_6e-2,
        9.999_999_999_999_999e-1,
    ];
    const Q: [f64; 4] = [
        3.001_985_051_386_644_5e-6,
        2.524_483_403_496_841e-3,
        2.272_655_482_081_550_3e-1,
        2.0,
    ];
    const LN_2_HIGH: f64 = 6.931_457_519_531_25e-1;
    const LN_2_LOW: f64 = 1.428_606_820_309_417_3e-6;
    // Adding and subtracting 1.5 * 2^52 rounds a number below 2^51 to the nearest whole number.
    const ROUND: f64 = 6_755_399_441_055_744.0;
    let c = L::splat;
    let over = x.gt(c(EXP_OVERFLOW));
    let under = x.lt(c(EXP_UNDERFLOW));
    let x_in = L::select(over | under, c(0.0), x);
    let n = (x_in * c(std::f64::consts::LOG2_E) + c(ROUND)) - c(ROUND);
    let r = (x_in - n * c(LN_2_HIGH)) - n * c(LN_2_LOW);
    let rr = r * r;
    let rp = r * ((c(P[0]) * rr + c(P[1])) * rr + c(P[2]));
    let q = ((c(Q[0]) * rr + c(Q[1])) * rr + c(Q[2])) * rr + c(Q[3]);
    let e_r = c(1.0) + c(2.0) * (rp / (q - rp));
    let half = (n * c(0.5) + c(ROUND)) - c(ROUND);
    let scaled = e_r * half.exp2_int() * (n - half).exp2_int();
    L::select(over, c(f64::INFINITY), L::select(under, c(0.0), scaled))
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const REFERENCE: &str = include_str!("../../tests/data/elementary_reference.json");

    /// `(x, hi, lo)` points: the true value is `hi + lo` to about 1e-32 relative.
    fn points(function: &str) -> Vec<(f64, f64, f64)> {
        let reference: serde_json::Value = serde_json::from_str(REFERENCE).unwrap();
        serde_json::from_value(reference[function].clone()).unwrap()
    }

    /// The error of `got` against `hi + lo` in units in the last place of `hi`.
    fn ulps(got: f64, hi: f64, lo: f64) -> f64 {
        let ulp = if hi.abs() < f64::MIN_POSITIVE {
            f64::from_bits(1)
        } else {
            f64::EPSILON * 2f64.powi(hi.abs().log2().floor() as i32)
        };
        ((got - hi) - lo).abs() / ulp
    }

    fn worst(function: &str, f: impl Fn(f64) -> f64) -> f64 {
        points(function)
            .into_iter()
            .map(|(x, hi, lo)| ulps(f(x), hi, lo))
            .fold(0.0, f64::max)
    }

    #[test]
    fn atan_is_within_its_bound_of_the_50_digit_values() {
        let worst = worst("atan", atan::<f64>);
        assert!(worst <= ATAN_MAX_ULP, "{worst} ulp");
    }

    #[test]
    fn exp_is_within_its_bound_of_the_50_digit_values() {
        let worst = worst("exp", exp::<f64>);
        assert!(worst <= EXP_MAX_ULP, "{worst} ulp");
    }

    #[test]
    fn the_edges_of_the_ranges_are_exact() {
        assert_eq!(atan(0.0f64).to_bits(), 0.0f64.to_bits());
        assert_eq!(atan(-0.0f64).to_bits(), (-0.0f64).to_bits());
        assert_eq!(atan(f64::INFINITY), std::f64::consts::FRAC_PI_2);
        assert_eq!(atan(f64::NEG_INFINITY), -std::f64::consts::FRAC_PI_2);
        assert!(atan(f64::NAN).is_nan() && exp(f64::NAN).is_nan());
        assert_eq!(exp(0.0f64), 1.0);
        assert_eq!(exp(-0.0f64), 1.0);
        assert_eq!(exp(710.0f64), f64::INFINITY);
        assert_eq!(exp(f64::INFINITY), f64::INFINITY);
        assert_eq!(exp(-746.0f64), 0.0);
        assert_eq!(exp(f64::NEG_INFINITY), 0.0);
        assert!(exp(-740.0f64) > 0.0 && exp(-740.0f64) < f64::MIN_POSITIVE);
    }

    fn any_finite() -> impl Strategy<Value = f64> {
        prop_oneof![-1e3..1e3f64, -1e300..1e300f64, -1e-300..1e-300f64]
    }

    proptest! {
        #[test]
        fn atan_is_odd(x in any_finite()) {
            prop_assert_eq!(atan(-x).to_bits(), (-atan(x)).to_bits());
        }

        #[test]
        fn atan_never_decreases_and_stays_within_pi_over_2(x in any_finite(), step in 0.0..1e-3f64) {
            let y = x + step * x.abs().max(1e-300);
            prop_assert!(atan(y) >= atan(x));
            prop_assert!(atan(x).abs() <= std::f64::consts::FRAC_PI_2);
        }

        #[test]
        fn atan_of_a_small_argument_is_the_argument(x in -1e-9..1e-9f64) {
            prop_assert_eq!(atan(x), x);
        }

        #[test]
        fn exp_never_decreases_and_stays_positive(x in -800.0..800.0f64, step in 0.0..1e-3f64) {
            prop_assert!(exp(x + step) >= exp(x));
            prop_assert!(exp(x) >= 0.0);
        }

        #[test]
        fn exp_of_a_sum_is_the_product_to_a_few_ulps(x in -300.0..300.0f64, y in -300.0..300.0f64) {
            let (sum, product) = (exp(x + y), exp(x) * exp(y));
            prop_assume!(sum.is_normal());
            prop_assert!((sum - product).abs() <= 1e-15 * (1.0 + 4.0 * (x.abs() + y.abs())) * sum);
        }
    }
}
