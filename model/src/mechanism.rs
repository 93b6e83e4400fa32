//! The pivoting contact arm (docs/model.md section 1; paper eq. 1-4).
//!
//! Everything is referred to the contact point: the arm's inertia becomes an effective mass and the
//! return spring an effective stiffness, so that free flight with gap `x > 0` obeys
//! `m x'' = -F_s - k x` (eq. 1).

use crate::elementary::atan;
use crate::lanes::Real;

/// Effective mass at the contact, `m = J / h'^2` (eq. 1).
pub fn effective_mass(inertia_kg_m2: f64, contact_arm_m: f64) -> f64 {
    inertia_kg_m2 / (contact_arm_m * contact_arm_m)
}

/// Effective stiffness at the contact, `k = K h^2 / h'^2` (eq. 1).
pub fn effective_stiffness(
    spring_stiffness_n_per_m: f64,
    spring_arm_m: f64,
    contact_arm_m: f64,
) -> f64 {
    let lever = spring_arm_m / contact_arm_m;
    spring_stiffness_n_per_m * lever * lever
}

/// Impact velocity after a drop from gap `H` (eq. 2): `u_i = sqrt((k H^2 + 2 F_s H) / m)`.
///
/// Evaluated as `sqrt(H) * sqrt((k H + 2 F_s) / m)` so that `H^2` never overflows.
pub fn impact_velocity(
    mass_kg: f64,
    stiffness_n_per_m: f64,
    static_force_n: f64,
    drop_height_m: f64,
) -> f64 {
    drop_height_m.sqrt()
        * ((stiffness_n_per_m * drop_height_m + 2.0 * static_force_n) / mass_kg).sqrt()
}

/// The flight of the arm between a separation and the next impact, for one set of mechanism constants.
///
/// Flight is conservative: the contact returns at the speed it left with. The constants every flight
/// time needs are worked out once, so that a flight costs one `atan` and no division.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Flight {
    mass_kg: f64,
    stiffness_n_per_m: f64,
    static_force_n: f64,
    /// `w = sqrt(k/m)`, the natural angular frequency of the arm.
    omega: f64,
    /// `2/w`.
    two_over_omega: f64,
    /// `sqrt(k m) / F_s`, so that the angle of eq. 3 is `atan(v sqrt(k m) / F_s)`.
    atan_per_speed: f64,
    /// `2 m / F_s`, eq. 4's time per unit separation speed.
    constant_force_time_per_speed: f64,
    /// `d = F_s / k`, the static deflection of the return spring (infinite when `k = 0`).
    static_deflection_m: f64,
}

impl Flight {
    /// Constants of the flight. `F_s = 0` together with `k = 0` is rejected by scenario validation
    /// (the arm would never return); the functions below assume it does not happen.
    pub fn new(mass_kg: f64, stiffness_n_per_m: f64, static_force_n: f64) -> Self {
        let omega = (stiffness_n_per_m / mass_kg).sqrt();
        Self {
            mass_kg,
            stiffness_n_per_m,
            static_force_n,
            omega,
            two_over_omega: 2.0 / omega,
            atan_per_speed: (stiffness_n_per_m * mass_kg).sqrt() / static_force_n,
            constant_force_time_per_speed: 2.0 * mass_kg / static_force_n,
            static_deflection_m: static_force_n / stiffness_n_per_m,
        }
    }

    pub fn omega(&self) -> f64 {
        self.omega
    }

    /// Exact flight time after a separation at speed `v` (eq. 3, the exact solution of eq. 1):
    /// `T(v) = (2/w) atan2(v w m, F_s)`, evaluated as `(2/w) atan(v sqrt(k m) / F_s)`; it is `pi/w`
    /// when `F_s = 0`, and the constant-force time of eq. 4 when `k = 0`.
    #[inline(always)]
    pub fn exact_time_s<L: Real>(&self, v: L) -> L {
        if self.stiffness_n_per_m == 0.0 {
            self.constant_force_time_s(v)
        } else if self.static_force_n == 0.0 {
            L::splat(std::f64::consts::PI / self.omega)
        } else {
            L::splat(self.two_over_omega) * atan(v * L::splat(self.atan_per_speed))
        }
    }

    /// Constant-force flight time (eq. 4): `T(v) = 2 v m / F_s`, the `k -> 0` limit of eq. 3.
    #[inline(always)]
    pub fn constant_force_time_s<L: Real>(&self, v: L) -> L {
        v * L::splat(self.constant_force_time_per_speed)
    }

    /// Exact peak gap of the flight: with `d = F_s/k` and `x = v/w`,
    /// `g = x^2 / (sqrt(d^2 + x^2) + d)`.
    ///
    /// This is `sqrt(d^2 + x^2) - d` rearranged: the textbook form cancels catastrophically (and returns 0)
    /// when the gap is far below `d`. `hypot` and the factored product keep every intermediate finite.
    pub fn exact_peak_gap_m(&self, v: f64) -> f64 {
        if self.stiffness_n_per_m == 0.0 {
            return self.constant_force_peak_gap_m(v);
        }
        let x = v / self.omega;
        let d = self.static_deflection_m;
        if x == 0.0 {
            // No static deflection and a speed that rounds to 0 over `w`: no gap, not 0/0.
            return 0.0;
        }
        x * (x / (d.hypot(x) + d))
    }

    /// Constant-force peak gap (the `k -> 0` limit): `g = v^2 m / (2 F_s)`.
    pub fn constant_force_peak_gap_m(&self, v: f64) -> f64 {
        v * (v * self.mass_kg / (2.0 * self.static_force_n))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use std::f64::consts::PI;

    const M: f64 = 1.593e-5 / (0.03 * 0.03);

    #[test]
    fn effective_mass_and_stiffness_refer_the_arm_to_the_contact() {
        assert_relative_eq!(effective_mass(2.0, 0.5), 8.0, max_relative = 1e-15);
        assert_relative_eq!(
            effective_stiffness(100.0, 0.02, 0.04),
            25.0,
            max_relative = 1e-15
        );
    }

    #[test]
    fn impact_velocity_is_energy_conservation_over_the_drop() {
        // 1/2 m u^2 = 1/2 k H^2 + F_s H
        let (k, fs, h) = (200.0, 0.344, 1e-3);
        let u = impact_velocity(M, k, fs, h);
        assert_relative_eq!(
            0.5 * M * u * u,
            0.5 * k * h * h + fs * h,
            max_relative = 1e-14
        );
        assert_eq!(impact_velocity(M, k, fs, 0.0), 0.0);
    }

    #[test]
    fn exact_flight_tends_to_constant_force_flight_as_stiffness_vanishes() {
        let v = 0.1;
        let constant = Flight::new(M, 0.0, 0.344).exact_time_s(v);
        assert_relative_eq!(constant, 2.0 * v * M / 0.344, max_relative = 1e-15);
        let mut previous_error = f64::INFINITY;
        for k in [1e2, 1e0, 1e-2, 1e-4, 1e-6, 1e-8] {
            let error = (Flight::new(M, k, 0.344).exact_time_s(v) - constant).abs() / constant;
            assert!(
                error < previous_error,
                "k = {k}: {error} !< {previous_error}"
            );
            previous_error = error;
        }
        assert!(previous_error < 1e-9);
    }

    #[test]
    fn flight_without_static_force_is_half_a_period() {
        let flight = Flight::new(M, 200.0, 0.0);
        for v in [1e-9, 0.1, 1e4] {
            assert_relative_eq!(
                flight.exact_time_s(v),
                PI / flight.omega(),
                max_relative = 1e-15
            );
        }
        // peak gap is then the amplitude v/w
        assert_relative_eq!(
            flight.exact_peak_gap_m(0.1),
            0.1 / flight.omega(),
            max_relative = 1e-15
        );
    }

    #[test]
    fn peak_gap_far_below_the_static_deflection_is_not_lost_to_cancellation() {
        // d = F_s/k = 1e3 m, x = v/w ~ 1e-9 m: sqrt(d^2+x^2) - d is exactly 0 in f64.
        let flight = Flight::new(1.0, 1e-3, 1.0);
        let v = 1e-9 * flight.omega();
        let naive = (1e3_f64.powi(2) + 1e-18).sqrt() - 1e3;
        assert_eq!(naive, 0.0);
        // series: g = x^2/(2d) (1 - x^2/(4 d^2) + ...)
        assert_relative_eq!(
            flight.exact_peak_gap_m(v),
            1e-18 / 2e3,
            max_relative = 1e-15
        );
    }

    #[test]
    fn peak_gap_is_where_the_energy_of_separation_is_stored() {
        // 1/2 m v^2 = F_s g + 1/2 k g^2
        let (k, fs) = (200.0, 0.344);
        let flight = Flight::new(M, k, fs);
        for v in [1e-6, 0.1, 3.0] {
            let g = flight.exact_peak_gap_m(v);
            assert_relative_eq!(
                fs * g + 0.5 * k * g * g,
                0.5 * M * v * v,
                max_relative = 1e-14
            );
        }
    }

    #[test]
    fn flight_stays_finite_for_extreme_constants() {
        for (m, k, fs) in [
            (1e-30, 1e30, 1e-30),
            (1e30, 1e-30, 1e30),
            (1e-30, 0.0, 1e30),
            (1e30, 1e30, 0.0),
        ] {
            let flight = Flight::new(m, k, fs);
            for v in [1e-12, 1.0, 1e4] {
                let (t, g) = (flight.exact_time_s(v), flight.exact_peak_gap_m(v));
                assert!(
                    t.is_finite() && t > 0.0 && g.is_finite() && g > 0.0,
                    "{m} {k} {fs} {v}: {t} {g}"
                );
            }
        }
    }
}
