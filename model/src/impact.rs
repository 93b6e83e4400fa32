//! The first impact (docs/model.md section 4; paper eq. 12, 13 and Fig. 13-16).
//!
//! Two contacts of radius `r` load fully plastically at pressure `p`: the contact force grows as
//! `pi r p d` with the approach `d`, so loading is a spring `k_c = pi r p` driven by the static force,
//! `m d'' = F_s - k_c d`, `d(0) = 0`, `d'(0) = u`. Unloading is elastic (Hertz).

use crate::elementary::atan;
use crate::lanes::Real;
use std::f64::consts::{FRAC_PI_2, PI};

/// Plastic contact stiffness `k_c = pi r p`.
#[inline(always)]
pub fn contact_stiffness<L: Real>(contact_radius_m: L, pressure_pa: L) -> L {
    L::splat(PI) * contact_radius_m * pressure_pa
}

/// Loading of one impact: mass `m` meeting contact stiffness `k_c` at speed `u` under static force `F_s`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Impact<L = f64> {
    pub mass_kg: L,
    pub contact_stiffness_n_per_m: L,
    pub static_force_n: L,
    pub impact_speed_m_s: L,
}

impl<L: Real> Impact<L> {
    /// `sqrt(k_c m) = w_c m`. Where `k_c m` falls below f64's normal range it is formed 2^600
    /// larger and its root taken 2^300 smaller: exact powers of two, so every other product
    /// keeps its bits (a softened pressure of 1e-210 on a radius of 1e-30 and a mass of 1e-90
    /// rounded `k_c m` to 0, and the loading time `m / 0` printed null where it is 8.9e74 s,
    /// found from outside).
    #[inline(always)]
    fn root_km(&self) -> L {
        let (k, m) = (self.contact_stiffness_n_per_m, self.mass_kg);
        let km = k * m;
        let tiny = km.lt(L::splat(f64::MIN_POSITIVE));
        let scaled = L::select(tiny, k * L::splat(2f64.powi(600)) * m, km);
        scaled.sqrt() * L::select(tiny, L::splat(2f64.powi(-300)), L::splat(1.0))
    }

    /// `u sqrt(k_c m) = u w_c m`, the momentum-like term shared by the force and the loading time.
    #[inline(always)]
    fn scaled_momentum(&self) -> L {
        self.impact_speed_m_s * self.root_km()
    }

    /// Peak force (Fig. 15, linear in `u`): `F_max = F_s + sqrt(F_s^2 + k_c m u^2)`, the force at
    /// maximum approach, where `1/2 m u^2 + F_s d = 1/2 k_c d^2`. Within the magnitudes a valid
    /// scenario allows (docs/model.md section 9) the squares stay below f64's largest; where
    /// both forces are below 2^-500 (3e-151) their squares could round to 0 (`F_s = 0` and
    /// `u sqrt(k_c m)` of 1e-195 gave a peak force of 0 and an unloading time of `m e u / 0`),
    /// so they are squared 2^500 larger: exact powers of two, the same bits elsewhere.
    #[inline(always)]
    pub fn peak_force_n(&self) -> L {
        let x = self.scaled_momentum();
        let tiny = self.static_force_n.max(x).lt(L::splat(2f64.powi(-500)));
        let up = L::select(tiny, L::splat(2f64.powi(500)), L::splat(1.0));
        let (fs, x) = (self.static_force_n * up, x * up);
        (fs + (fs * fs + x * x).sqrt()) * L::select(tiny, L::splat(2f64.powi(-500)), L::splat(1.0))
    }

    /// Loading time to maximum approach (eq. 12): `t_load = (pi - atan2(u w_c m, F_s)) / w_c`, which
    /// is `pi / (2 w_c)` when `F_s = 0`. For `u > 0` this is `(pi/2 + atan(F_s / (u w_c m))) / w_c`.
    #[inline(always)]
    pub fn loading_time_s(&self) -> L {
        let root_km = self.root_km();
        let u = self.impact_speed_m_s;
        let angle = L::select(
            L::splat(0.0).lt(u),
            L::splat(FRAC_PI_2) + atan(self.static_force_n / (u * root_km)),
            L::splat(PI),
        );
        angle * self.mass_kg / root_km
    }

    /// Elastic (Hertz) unloading time (eq. 13): `t_unload = 1.8395 m e u / F_max`, the Hertzian
    /// half-period of a rebound at speed `e u` from peak force `F_max`.
    #[inline(always)]
    pub fn unloading_time_s(&self, restitution: L, peak_force_n: L) -> L {
        L::splat(1.8395) * self.mass_kg * restitution * self.impact_speed_m_s / peak_force_n
    }

    /// Plastic work of the impact (Fig. 19): the work the contact absorbs while it loads fully
    /// plastically, from touch to maximum approach,
    ///
    /// `W_p = k_c d_max^2 / 2 = F_max^2 / (2 k_c) = m u^2 / 2 + F_s F_max / k_c`,
    ///
    /// with `d_max = F_max / k_c`. It is Tabor's `p V`: the yield pressure times the indented volume
    /// `pi r d_max^2 / 2`. The last form, the kinetic energy plus the static force's work over the
    /// approach (the energy balance of [`Impact::peak_force_n`]), is the one evaluated: it never
    /// squares `F_max`. The elastic unloading that follows gives back the rebound, `m (e u)^2 / 2`,
    /// out of elastic strain this loading model does not separate from the plastic work.
    #[inline(always)]
    pub fn plastic_work_j(&self, peak_force_n: L) -> L {
        let u = self.impact_speed_m_s;
        L::splat(0.5) * self.mass_kg * u * u
            + self.static_force_n * (peak_force_n / self.contact_stiffness_n_per_m)
    }

    /// Impact duration `t_load + t_unload`, with the peak force it needs; `(F_max, duration)`.
    #[inline(always)]
    pub fn peak_force_and_duration(&self, restitution: L) -> (L, L) {
        let peak = self.peak_force_n();
        (
            peak,
            self.loading_time_s() + self.unloading_time_s(restitution, peak),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    const M: f64 = 1.593e-5 / (0.03 * 0.03);

    fn rig(static_force_n: f64, u: f64) -> Impact {
        Impact {
            mass_kg: M,
            contact_stiffness_n_per_m: contact_stiffness(7.7e-3, 2e8),
            static_force_n,
            impact_speed_m_s: u,
        }
    }

    /// `k_c m` below f64's normal range (3e-330: it rounded to 0, and the loading time to m / 0)
    /// gives `sqrt(k_c m)` through exact powers of two: the loading time `pi/2 sqrt(m / k_c)`
    /// without `F_s` and the peak force `u sqrt(k_c) sqrt(m)`, each as the separate roots give
    /// them; in the normal range the root is `sqrt(k_c m)` to the bit.
    #[test]
    fn a_product_below_the_normal_range_keeps_its_root() {
        let tiny = Impact {
            mass_kg: 1e-90,
            contact_stiffness_n_per_m: 3e-240,
            static_force_n: 0.0,
            impact_speed_m_s: 1e-30,
        };
        assert_relative_eq!(
            tiny.loading_time_s(),
            FRAC_PI_2 * (1e-90_f64 / 3e-240).sqrt(),
            max_relative = 4e-16
        );
        assert_relative_eq!(
            tiny.peak_force_n(),
            1e-30 * 3e-240_f64.sqrt() * 1e-90_f64.sqrt(),
            max_relative = 4e-16
        );
        let with_force = Impact {
            static_force_n: 0.344,
            ..tiny
        };
        let (peak, duration) = with_force.peak_force_and_duration(0.5);
        assert!(peak.is_finite() && duration.is_finite() && duration > 0.0);
        // Without the static force, the unloading time `1.8395 m e u / F_max` with `F_max =
        // u sqrt(k_c m)`, 1e-195 N, whose square alone is below f64's range.
        let quiet = Impact {
            contact_stiffness_n_per_m: 3e-180,
            ..tiny
        };
        let peak = quiet.peak_force_n();
        assert_relative_eq!(
            peak,
            1e-30 * (3e-180_f64 * 1e-90).sqrt(),
            max_relative = 4e-16
        );
        assert_relative_eq!(
            quiet.unloading_time_s(0.5, peak),
            1.8395 * 0.5 * (1e-90_f64 / 3e-180).sqrt(),
            max_relative = 1e-15
        );
        let rig = rig(0.344, 0.224);
        assert_eq!(
            rig.root_km().to_bits(),
            (rig.contact_stiffness_n_per_m * rig.mass_kg)
                .sqrt()
                .to_bits()
        );
    }

    #[test]
    fn peak_force_balances_kinetic_and_static_work_against_the_contact_spring() {
        let impact = rig(0.344, 0.224);
        let f = impact.peak_force_n();
        let d = f / impact.contact_stiffness_n_per_m;
        let kc = impact.contact_stiffness_n_per_m;
        assert_relative_eq!(
            0.5 * kc * d * d,
            0.5 * M * 0.224 * 0.224 + 0.344 * d,
            max_relative = 1e-13
        );
    }

    #[test]
    fn peak_force_of_the_default_rig_is_about_66_n() {
        // docs/model.md section 8: about 66 N at 0.344 N (paper 60 N); validation 65.8902365177217.
        assert_relative_eq!(
            rig(0.344, 0.223_985_471_683_820_85).peak_force_n(),
            65.890_236_517_721_7,
            max_relative = 1e-13
        );
    }

    #[test]
    fn plastic_work_is_the_work_of_the_plastic_loading() {
        let impact = rig(0.344, 0.224);
        let f = impact.peak_force_n();
        let kc = impact.contact_stiffness_n_per_m;
        assert_relative_eq!(
            impact.plastic_work_j(f),
            f * f / (2.0 * kc),
            max_relative = 1e-12
        );
    }

    #[test]
    fn without_static_force_the_plastic_work_is_the_kinetic_energy() {
        let impact = rig(0.0, 0.3);
        assert_relative_eq!(
            impact.plastic_work_j(impact.peak_force_n()),
            0.5 * M * 0.09,
            max_relative = 1e-15
        );
    }

    #[test]
    fn loading_time_is_a_quarter_period_without_static_force() {
        let impact = rig(0.0, 0.3);
        let omega_c = (impact.contact_stiffness_n_per_m / M).sqrt();
        assert_relative_eq!(
            impact.loading_time_s(),
            std::f64::consts::FRAC_PI_2 / omega_c,
            max_relative = 1e-15
        );
        assert_relative_eq!(
            impact.peak_force_n(),
            (impact.contact_stiffness_n_per_m * M).sqrt() * 0.3,
            max_relative = 1e-15
        );
    }

    #[test]
    fn peak_force_is_linear_in_speed_when_static_force_is_small() {
        let (f1, f2) = (rig(1e-9, 0.2).peak_force_n(), rig(1e-9, 0.4).peak_force_n());
        assert_relative_eq!(f2, 2.0 * f1, max_relative = 1e-9);
    }

    #[test]
    fn impact_stays_finite_for_extreme_constants() {
        for (m, kc, fs, u) in [
            (1e-30, 1e60, 1e30, 1e30),
            (1e30, 1e-60, 0.0, 1e-30),
            (1e-30, 1e-60, 1e-30, 1e4),
        ] {
            let impact = Impact {
                mass_kg: m,
                contact_stiffness_n_per_m: kc,
                static_force_n: fs,
                impact_speed_m_s: u,
            };
            let (f, t) = impact.peak_force_and_duration(0.5);
            assert!(
                f.is_finite() && f > 0.0 && t.is_finite() && t > 0.0,
                "{m} {kc} {fs} {u}: {f} {t}"
            );
        }
    }
}
