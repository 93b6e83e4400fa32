//! Coefficient of restitution (docs/model.md section 2; paper eq. 5-8 and 18).
//!
//! Eq. 7, `u^2 e^8 = kappa^8 (1 - 3e^2/8)^3`, depends on `u` and `kappa` only through the *scaled
//! speed* `eps0 = kappa u^(-1/4)` (the paper's eq. 18 approximation of `e` itself):
//! taking the eighth root, `e = eps0 (1 - 3e^2/8)^(3/8)`.
//! Writing `e = eps0 sqrt(z)` and `a = 3 eps0^2 / 8`, this is the quartic `z^4 = (1 - a z)^3`
//! with `z` in `((5/8)^(3/4), 1]`. No `kappa^8`, `u^2` or `q = kappa^4/u` is ever formed, so nothing
//! overflows or underflows for any finite positive input: a tiny `eps0` gives `a = 0`, `z = 1`, `e = eps0`.

use crate::lanes::Real;

/// The scaled speed at and above which eq. 7 has no root below 1: `eps0 >= (8/5)^(3/8)` gives `e = 1`
/// (equivalently `u <= u_c = (5/8)^(3/2) kappa^4`, or `q >= (8/5)^(3/2)`).
pub const ELASTIC_SCALED_SPEED: f64 = 1.192_737_828_708_026_8;

/// `(5/8)^(3/8)`: eq. 7 gives `e >= eps0 (5/8)^(3/8)` whenever `e <= 1`, a cheap lower bound.
pub const LOWER_BOUND_FACTOR: f64 = 0.838_407_214_000_414_2;

/// `(8/5)^(3/4)`, the square of [`ELASTIC_SCALED_SPEED`].
pub const ELASTIC_SCALED_SPEED_SQ: f64 = 1.422_623_528_031_138_3;

/// Kappa from the material and the arm (eq. 8a/8b): `kappa = 2.784 (p^5 r^3 / (E^4 m))^(1/8)`,
/// in (m/s)^(1/4). Evaluated as a product of separate powers so that no `p^5` or `E^4` is formed.
pub fn kappa(
    dynamic_yield_pressure_pa: f64,
    contact_radius_m: f64,
    youngs_modulus_pa: f64,
    mass_kg: f64,
) -> f64 {
    2.784 * dynamic_yield_pressure_pa.powf(0.625) * contact_radius_m.powf(0.375)
        / (youngs_modulus_pa.sqrt() * mass_kg.powf(0.125))
}

/// `x^(1/8)` by three correctly rounded square roots: within 2 ulps, and about twice as fast as `powf`
/// (kappa is rescaled at every operation of a wearing device).
#[inline(always)]
pub fn eighth_root<L: Real>(x: L) -> L {
    x.sqrt().sqrt().sqrt()
}

/// `x^(3/8)`, the radius scaling of eq. 8.
#[inline(always)]
pub fn pow_3_8<L: Real>(x: L) -> L {
    let t = eighth_root(x);
    t * t * t
}

/// `x^(5/8)`, the pressure scaling of eq. 8.
#[inline(always)]
pub fn pow_5_8<L: Real>(x: L) -> L {
    let t = eighth_root(x);
    let t2 = t * t;
    t2 * t2 * t
}

/// How kappa follows the radius and the pressure of an operation: eq. 8 gives
/// `kappa ~ r^(3/8) p^(5/8)`, so from a reference value at `(r0, p0)` (eq. 8 itself, or a user's
/// override measured on the new contact) `kappa(r, p) = kappa_ref (r/r0)^(3/8) (p/p0)^(5/8)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KappaLaw {
    pub reference_kappa: f64,
    pub reference_radius_m: f64,
    pub reference_pressure_pa: f64,
}

impl KappaLaw {
    /// Kappa at radius `r` and pressure `p`; exactly the reference value at the reference point
    /// (where a factor would round, it is exactly 1 instead).
    #[inline(always)]
    pub fn at<L: Real>(&self, radius_m: L, pressure_pa: L) -> L {
        let (r0, p0) = (
            L::splat(self.reference_radius_m),
            L::splat(self.reference_pressure_pa),
        );
        let one = L::splat(1.0);
        let radius_factor = L::select(radius_m.eq(r0), one, pow_3_8(radius_m / r0));
        let pressure_factor = L::select(pressure_pa.eq(p0), one, pow_5_8(pressure_pa / p0));
        L::splat(self.reference_kappa) * radius_factor * pressure_factor
    }
}

/// The scaled speed `eps0 = kappa u^(-1/4)` (infinite at `u = 0`, which is elastic).
#[inline(always)]
pub fn scaled_speed<L: Real>(impact_speed_m_s: L, kappa: L) -> L {
    kappa / impact_speed_m_s.sqrt().sqrt()
}

/// Exact coefficient of restitution of eq. 7 for impact speed `u` and `kappa`.
///
/// `e = 1` at and below the critical speed `u_c`, continuous across it, decreasing in `u`,
/// increasing in `kappa`, always in `[0, 1]`. Accurate to a few ulps (see [`restitution_scaled`]).
#[inline(always)]
pub fn restitution<L: Real>(impact_speed_m_s: L, kappa: L) -> L {
    restitution_scaled(scaled_speed(impact_speed_m_s, kappa))
}

/// Eq. 7 as a function of the scaled speed alone: `e = eps0 sqrt(z)`, `z` the root of the quartic.
/// Nothing here can overflow or underflow: for tiny `eps0`, `a` is 0, `z` is 1 and `e = eps0`.
#[inline(always)]
pub fn restitution_scaled<L: Real>(eps0: L) -> L {
    let one = L::splat(1.0);
    let inelastic = eps0.lt(L::splat(ELASTIC_SCALED_SPEED));
    let e = (eps0 * quartic_root(L::splat(0.375) * eps0 * eps0).sqrt()).min(one);
    L::select(inelastic, e, one)
}

/// `e^2` of eq. 7 from `eps0^2 = kappa^2 / sqrt(u)`, for the bounce loop, which carries squared
/// speeds: `(e v)^2 = e^2 v^2` needs no square root of its own. Same accuracy as [`restitution_scaled`]
/// as long as `eps0^2` does not underflow (`e > 1e-154`; below that the rebound is zero).
#[inline(always)]
pub fn restitution_squared_scaled<L: Real>(eps0_sq: L) -> L {
    let one = L::splat(1.0);
    let inelastic = eps0_sq.lt(L::splat(ELASTIC_SCALED_SPEED_SQ));
    let e_sq = (eps0_sq * quartic_root(L::splat(0.375) * eps0_sq)).min(one);
    L::select(inelastic, e_sq, one)
}

/// The root `z` of `z^4 = (1 - a z)^3` for `a` in `[0, 3/8 (8/5)^(3/4)]`.
///
/// A degree-6 Chebyshev fit (made at 40 digits; maximum error 2.4e-9 on the whole range) is polished by
/// one Newton step on `F(z) = z^4 - (1 - a z)^3`. Newton squares the error times `|F''/2F'| < 2`, so
/// the step leaves below 1.2e-17: what remains is the rounding of the step itself, a few ulps.
/// A fixed step count keeps the bounce loop free of data-dependent branches.
#[inline(always)]
fn quartic_root<L: Real>(a: L) -> L {
    const C: [f64; 7] = [
        0.999_999_997_672_269_1,
        -0.749_999_575_334_258_9,
        0.468_737_395_651_885_55,
        -0.249_860_634_454_216_4,
        0.112_069_410_449_526_1,
        -0.039_156_188_123_702_57,
        0.008_050_232_553_153_345,
    ];
    let k = L::splat;
    let a2 = a * a;
    // Estrin's scheme: a short dependency chain.
    let z = (k(C[0]) + k(C[1]) * a)
        + a2 * ((k(C[2]) + k(C[3]) * a) + a2 * ((k(C[4]) + k(C[5]) * a) + a2 * k(C[6])));
    let c = k(1.0) - a * z;
    let z2 = z * z;
    z - (z2 * z2 - c * c * c) / (k(4.0) * z2 * z + k(3.0) * a * c * c)
}

/// The paper's approximation (eq. 18): `e ~= min(1, kappa u^(-1/4))`, i.e. `min(1, eps0)`.
///
/// It neglects the `(1 - 3e^2/8)^(3/8)` factor of eq. 7, so it overestimates `e`: by 13.7 % at
/// most, at `eps0 = 1` (`u = kappa^4`, about twice the critical speed, where the `min` stops
/// capping it), and by `3 eps0^2 / 64` for small `eps0`. Without the `min` the overestimate would
/// reach `(8/5)^(3/8) - 1 = 19.3 %` at the elastic limit.
#[inline(always)]
pub fn restitution_closed_form<L: Real>(impact_speed_m_s: L, kappa: L) -> L {
    scaled_speed(impact_speed_m_s, kappa).min(L::splat(1.0))
}

/// The critical speed `u_c = (5/8)^(3/2) kappa^4` at and below which eq. 7 gives `e = 1`.
pub fn critical_speed(kappa: f64) -> f64 {
    let k2 = kappa * kappa;
    0.625_f64.powf(1.5) * k2 * k2
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use proptest::prelude::*;

    /// Log-form residual of eq. 7, `ln(e/eps0) - (3/8) ln(1 - 3e^2/8)`: the relative error of `e`
    /// to first order (its derivative with respect to `ln e` is between 1 and 1.5).
    fn log_residual(eps0: f64, e: f64) -> f64 {
        (e / eps0).ln() - 0.375 * (-0.375 * e * e).ln_1p()
    }

    #[test]
    fn constants_are_the_closed_forms_they_name() {
        assert_relative_eq!(
            ELASTIC_SCALED_SPEED,
            1.6_f64.powf(0.375),
            max_relative = 1e-16
        );
        assert_relative_eq!(
            LOWER_BOUND_FACTOR,
            0.625_f64.powf(0.375),
            max_relative = 1e-16
        );
    }

    #[test]
    fn paper_check_value_kappa_0363_at_04_m_s() {
        // docs/model.md section 2: kappa = 0.363, u = 0.4 m/s gives e = 0.4435 (paper: 0.45).
        assert_relative_eq!(
            restitution(0.4, 0.363),
            0.443_518_694_104_026_7,
            max_relative = 1e-15
        );
    }

    #[test]
    #[expect(
        clippy::excessive_precision,
        reason = "the independent roots are quoted as computed, at 20 digits"
    )]
    fn matches_independent_50_digit_roots_from_q_1e_minus_300_to_1e300() {
        // q = kappa^4/u; e computed with mpmath at 60 digits by bisection on s^2 = q (1 - 3s/8)^(3/2).
        let cases = [
            (1e-300, 1.0e-75),
            (1e-100, 1.0e-25),
            (1e-20, 9.999_999_999_859_375e-6),
            (1e-4, 0.099_859_605_378_529_115_838),
            (1e-2, 0.311_852_724_235_776_626_45),
            (0.1, 0.538_574_226_576_898_430_66),
            (0.5, 0.766_061_453_245_311_489_78),
            (1.0, 0.879_453_432_169_714_964_55),
            (2.0, 0.997_955_491_082_188_189_12),
            (2.02, 0.999_671_046_521_614_262_79),
            (2.0238, 0.999_995_084_214_724_632_14),
            (2.03, 1.0),
            (1e300, 1.0),
        ];
        for (q, expected) in cases {
            let e = restitution_scaled(f64::powf(q, 0.25));
            assert_relative_eq!(e, expected, max_relative = 4.0 * f64::EPSILON);
        }
    }

    #[test]
    fn residual_is_a_few_ulps_for_q_from_1e_minus_300_to_1e300() {
        let mut worst: f64 = 0.0;
        for i in 0..=6000 {
            let q = 10f64.powf(-300.0 + 0.1 * f64::from(i));
            let eps0 = q.powf(0.25);
            let e = restitution_scaled(eps0);
            if e < 1.0 {
                worst = worst.max(log_residual(eps0, e).abs());
            }
        }
        assert!(worst <= 4.0 * f64::EPSILON, "worst residual {worst:e}");
    }

    #[test]
    fn elastic_at_and_below_the_critical_speed_and_continuous_across_it() {
        let kappa = 0.3625;
        let uc = critical_speed(kappa);
        assert_eq!(restitution(uc * (1.0 - 1e-12), kappa), 1.0);
        assert_eq!(restitution(uc * 0.5, kappa), 1.0);
        assert_eq!(restitution(0.0, kappa), 1.0);
        for delta in [1e-3, 1e-6, 1e-9, 1e-12] {
            let e = restitution(uc * (1.0 + delta), kappa);
            assert!(e < 1.0 || delta < 1e-10, "delta {delta}: e = {e}");
            // near the limit 1 - e ~ sqrt(delta)
            assert!(1.0 - e <= 2.0 * delta.sqrt(), "delta {delta}: e = {e}");
        }
    }

    #[test]
    fn closed_form_is_eq_18_and_never_below_exact() {
        assert_relative_eq!(
            restitution_closed_form(0.4, 0.363),
            0.363 / 0.4_f64.powf(0.25),
            max_relative = 1e-15
        );
        assert_eq!(restitution_closed_form(1e-6, 0.363), 1.0);
        for u in [1e-3, 0.01, 0.1, 1.0, 10.0] {
            assert!(restitution_closed_form(u, 0.3625) >= restitution(u, 0.3625));
        }
        // The largest overestimate, at eps0 = 1: e = sqrt(z) with z^4 = (1 - 3z/8)^3, z =
        // 0.773438... (SciPy's brentq), so 1/e - 1 = 0.13707.
        let over = |eps0: f64| restitution_closed_form(1.0, eps0) / restitution(1.0, eps0) - 1.0;
        assert_relative_eq!(over(1.0), 0.13707, max_relative = 1e-4);
        for eps0 in [0.5, 0.9, 0.99, 1.01, 1.1, 1.19] {
            assert!(over(eps0) < over(1.0), "eps0 {eps0}: {}", over(eps0));
        }
    }

    #[test]
    fn kappa_override_scales_as_r_to_3_8_and_p_to_5_8() {
        let law = KappaLaw {
            reference_kappa: 0.5,
            reference_radius_m: 1e-3,
            reference_pressure_pa: 1e8,
        };
        assert_eq!(law.at(1e-3, 1e8), 0.5);
        assert_relative_eq!(
            law.at(2e-3, 1e8),
            0.5 * 2f64.powf(0.375),
            max_relative = 1e-15
        );
        assert_relative_eq!(
            law.at(1e-3, 3e8),
            0.5 * 3f64.powf(0.625),
            max_relative = 1e-15
        );
        // and eq. 8 has the same exponents
        let ratio = kappa(3e8, 2e-3, 1e11, 0.0177) / kappa(1e8, 1e-3, 1e11, 0.0177);
        assert_relative_eq!(
            ratio,
            2f64.powf(0.375) * 3f64.powf(0.625),
            max_relative = 1e-14
        );
    }

    #[test]
    fn kappa_of_the_default_rig() {
        // docs/model.md section 8: kappa = 0.3625 (validation: 0.3624518675972019)
        let m = 1.593e-5 / (0.03 * 0.03);
        assert_relative_eq!(
            kappa(2e8, 7.7e-3, 1e11, m),
            0.362_451_867_597_201_9,
            max_relative = 1e-14
        );
    }

    #[test]
    fn squared_form_agrees_with_the_scaled_form_to_a_few_ulps() {
        for i in 0..=20_000 {
            let eps0 = 1e-6 + ELASTIC_SCALED_SPEED * 1.01 * f64::from(i) / 20_000.0;
            let e = restitution_scaled(eps0);
            let e_sq = restitution_squared_scaled(eps0 * eps0);
            assert!(
                (e_sq - e * e).abs() <= 8.0 * f64::EPSILON * e * e,
                "eps0 {eps0}: {e_sq} vs {}",
                e * e
            );
        }
    }

    #[test]
    fn eighth_root_powers_match_powf() {
        for x in [1e-30, 1e-3, 0.5, 1.0, 2.0, 1e3, 1e30] {
            assert_relative_eq!(pow_3_8(x), x.powf(0.375), max_relative = 4.0 * f64::EPSILON);
            assert_relative_eq!(pow_5_8(x), x.powf(0.625), max_relative = 6.0 * f64::EPSILON);
        }
    }

    proptest! {
        #[test]
        fn e_is_in_unit_interval_for_any_positive_inputs(log_u in -9.0..4.0f64, log_k in -8.0..8.0f64) {
            let e = restitution(10f64.powf(log_u), 10f64.powf(log_k));
            prop_assert!((0.0..=1.0).contains(&e), "e = {e}");
        }

        #[test]
        fn e_decreases_with_speed_and_increases_with_kappa(
            log_u in -9.0..4.0f64, log_k in -8.0..8.0f64, factor in 1.001..100.0f64
        ) {
            let (u, k) = (10f64.powf(log_u), 10f64.powf(log_k));
            let e = restitution(u, k);
            prop_assert!(restitution(u * factor, k) <= e);
            prop_assert!(restitution(u, k * factor) >= e);
        }

        #[test]
        fn residual_is_a_few_ulps_anywhere(log_q in -300.0..300.0f64) {
            let eps0 = 10f64.powf(log_q / 4.0);
            let e = restitution_scaled(eps0);
            if e < 1.0 {
                prop_assert!(log_residual(eps0, e).abs() <= 4.0 * f64::EPSILON);
            } else {
                prop_assert!(eps0 >= ELASTIC_SCALED_SPEED * (1.0 - 1e-15));
            }
        }
    }
}
