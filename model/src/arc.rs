//! Arcing while the contacts are open (docs/model.md section 5; paper Section IV, Fig. 8-10 and
//! eq. 16).
//!
//! A DC supply `V_s` drives a resistive load at steady current `I_0`. While the gap is open an arc
//! burns at the material's minimum arc voltage `V_min`, so the load sees `V_s - V_min` and the arc
//! current is `I_arc = I_0 (V_s - V_min) / V_s`.

use crate::lanes::Real;

/// Arc current `I_arc = I_0 (V_s - V_min) / V_s`; zero without supply.
pub fn arc_current_a(current_a: f64, supply_voltage_v: f64, min_arc_voltage_v: f64) -> f64 {
    if supply_voltage_v <= min_arc_voltage_v {
        return 0.0;
    }
    current_a * ((supply_voltage_v - min_arc_voltage_v) / supply_voltage_v)
}

/// The arc of one circuit and material, or `None` when it cannot burn
/// (`V_s <= V_min`, or `I_arc < I_min`): then every arc term of the operation is zero.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Arc {
    /// `P = V_min I_arc`.
    pub power_w: f64,
    /// Field-emission breakdown gap `d_b = V_s / E_b` at which the pre-impact arc strikes.
    pub breakdown_gap_m: f64,
    pub softening_energy_j: f64,
}

impl Arc {
    pub fn strike(
        supply_voltage_v: f64,
        current_a: f64,
        min_arc_voltage_v: f64,
        min_arc_current_a: f64,
        breakdown_field_v_per_m: f64,
        softening_energy_j: f64,
    ) -> Option<Self> {
        let arc_current = arc_current_a(current_a, supply_voltage_v, min_arc_voltage_v);
        let burns = supply_voltage_v > min_arc_voltage_v
            && arc_current >= min_arc_current_a
            && arc_current > 0.0;
        burns.then(|| Self {
            power_w: min_arc_voltage_v * arc_current,
            breakdown_gap_m: supply_voltage_v / breakdown_field_v_per_m,
            softening_energy_j,
        })
    }

    /// Pre-impact arc (Fig. 8, 9): it burns from the breakdown gap to touch, `t_p = d_b / u_i`.
    #[inline(always)]
    pub fn pre_arc_duration_s<L: Real>(&self, impact_speed_m_s: L) -> L {
        L::splat(self.breakdown_gap_m) / impact_speed_m_s
    }

    /// Energy of an arc of the given duration, `E = P t` (pre-arc and every bounce alike).
    #[inline(always)]
    pub fn energy_j<L: Real>(&self, duration_s: L) -> L {
        L::splat(self.power_w) * duration_s
    }

    /// Surface softening by the pre-arc energy (Fig. 10): `p_1 / p = 1 / (1 + E_p / E_s)`.
    #[inline(always)]
    pub fn softening_ratio<L: Real>(&self, pre_arc_energy_j: L) -> L {
        let one = L::splat(1.0);
        one / (one + pre_arc_energy_j / L::splat(self.softening_energy_j))
    }
}

/// Kappa of the softened surface: eq. 8 scales as `p^(5/8)`, so `kappa_1 = kappa (p_1/p)^(5/8)`.
#[inline(always)]
pub fn softened_kappa<L: Real>(kappa: L, softening_ratio: L) -> L {
    kappa * crate::restitution::pow_5_8(softening_ratio)
}

/// Restitution of an impact after an arcing bounce (eq. 16, empirical):
/// `e = min(e_mechanical, max(0, a + b v))`, where `e_mechanical` is eq. 7 (or 18) with the softened
/// kappa; under the continuous law, weighted by the arc current (docs/model.md section 5).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ArcRestitution {
    pub a: f64,
    pub b_s_per_m: f64,
    pub law: ArcRestitutionLaw,
}

/// How strongly an arc changes restitution.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ArcRestitutionLaw {
    /// Fully, whatever its current: eq. 16 as the paper fitted it at 15 A.
    Paper,
    /// In proportion to `w = (I_arc - I_min) / (I_cal - I_min)`, clamped to `[0, 1]`, where `I_cal`
    /// is the arc current at the calibration current for this supply (above `I_min`: the scenario
    /// checks it).
    Continuous { calibration_arc_current_a: f64 },
}

impl ArcRestitution {
    /// The linear law `max(0, a + b v)` alone.
    #[inline(always)]
    pub fn linear<L: Real>(&self, impact_speed_m_s: L) -> L {
        (L::splat(self.a) + L::splat(self.b_s_per_m) * impact_speed_m_s).max(L::splat(0.0))
    }

    /// The weight `w` of an arc of current `I_arc`: 1 under the paper law; under the continuous law
    /// 0 at the minimum arc current, rising linearly to 1 at the calibration current, and 1 above it.
    /// A supply so close to the minimum arc voltage that the calibration current would not arc
    /// (`I_cal <= I_min`) arcs only above the calibration current (the arc current is proportional
    /// to the circuit current), so there `w = 1`.
    pub fn weight(&self, arc_current_a: f64, min_arc_current_a: f64) -> f64 {
        match self.law {
            ArcRestitutionLaw::Paper => 1.0,
            ArcRestitutionLaw::Continuous {
                calibration_arc_current_a,
            } if calibration_arc_current_a <= min_arc_current_a => 1.0,
            ArcRestitutionLaw::Continuous {
                calibration_arc_current_a,
            } => ((arc_current_a - min_arc_current_a)
                / (calibration_arc_current_a - min_arc_current_a))
                .clamp(0.0, 1.0),
        }
    }

    /// Eq. 16 weighted by `w`: `e = (1 - w) e_m + w min(e_m, max(0, a + b v))`, where `e_m` is the
    /// mechanical restitution on the softened surface. `w = 1` is eq. 16 and `w = 0` is `e_m`, both
    /// exactly; the final `min` keeps rounding from lifting `e` above `e_m` (and so above 1).
    #[inline(always)]
    pub fn weighted<L: Real>(&self, mechanical: L, impact_speed_m_s: L, weight: f64) -> L {
        let eq_16 = mechanical.min(self.linear(impact_speed_m_s));
        (L::splat(1.0 - weight) * mechanical + L::splat(weight) * eq_16).min(mechanical)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    fn rig_arc(supply_voltage_v: f64, current_a: f64) -> Option<Arc> {
        Arc::strike(supply_voltage_v, current_a, 12.0, 0.4, 1e8, 6.2e-4)
    }

    #[test]
    fn arcs_only_above_minimum_voltage_and_current() {
        assert!(rig_arc(0.0, 0.0).is_none());
        assert!(rig_arc(12.0, 15.0).is_none(), "V_s = V_min does not arc");
        assert!(rig_arc(48.0, 0.5).is_none(), "I_arc = 0.375 A < I_min");
        assert!(rig_arc(48.0, 15.0).is_some());
        // exactly at I_min it arcs: I_arc = I_0 (48 - 12)/48 = 0.4 A
        let at_min = rig_arc(48.0, 0.4 * 48.0 / 36.0).map(|arc| arc.power_w);
        assert_relative_eq!(at_min.unwrap(), 12.0 * 0.4, max_relative = 1e-15);
    }

    #[test]
    fn power_and_pre_arc_at_48_v_15_a() {
        let arc = rig_arc(48.0, 15.0).unwrap();
        assert_relative_eq!(arc.power_w, 12.0 * 11.25, max_relative = 1e-15);
        assert_relative_eq!(arc.breakdown_gap_m, 4.8e-7, max_relative = 1e-15);
        assert_relative_eq!(
            arc.pre_arc_duration_s(0.223_985_471_683_820_85),
            2.142_996_134_488_448_6e-6,
            max_relative = 1e-14
        );
    }

    #[test]
    fn pre_arc_at_01_m_s_lowers_e1_to_064_of_its_mechanical_value() {
        // docs/model.md section 8: softening_energy_j is calibrated on this (paper: 0.5 -> 0.32),
        // in the paper's own terms, eq. 18, where e is proportional to kappa. Eq. 7 saturates a
        // little: 0.66.
        use crate::restitution::{restitution, restitution_closed_form};
        let arc = rig_arc(48.0, 15.0).unwrap();
        let pre_arc_energy = arc.energy_j(arc.pre_arc_duration_s(0.1));
        let (kappa, u) = (0.3625, 0.1);
        let kappa_1 = softened_kappa(kappa, arc.softening_ratio(pre_arc_energy));
        let closed_form = restitution_closed_form(u, kappa_1) / restitution_closed_form(u, kappa);
        assert!(
            (closed_form - 0.64).abs() < 0.005,
            "eq. 18 ratio {closed_form}"
        );
        let exact = restitution(u, kappa_1) / restitution(u, kappa);
        assert!((exact - 0.66).abs() < 0.005, "eq. 7 ratio {exact}");
    }

    fn paper_law(a: f64, b_s_per_m: f64) -> ArcRestitution {
        ArcRestitution {
            a,
            b_s_per_m,
            law: ArcRestitutionLaw::Paper,
        }
    }

    #[test]
    fn arc_restitution_law_is_clamped_at_zero() {
        assert_relative_eq!(
            paper_law(0.235, 0.371).linear(0.1),
            0.2721,
            max_relative = 1e-15
        );
        assert_eq!(paper_law(-1.0, 0.1).linear(0.1), 0.0);
    }

    #[test]
    fn the_continuous_weight_rises_from_the_minimum_arc_current_to_the_calibration_current() {
        // 48 V: the calibration current 15 A arcs at 11.25 A; I_min = 0.4 A.
        let law = ArcRestitution {
            law: ArcRestitutionLaw::Continuous {
                calibration_arc_current_a: arc_current_a(15.0, 48.0, 12.0),
            },
            ..paper_law(0.235, 0.371)
        };
        let weight = |current_a: f64| law.weight(arc_current_a(current_a, 48.0, 12.0), 0.4);
        assert_eq!(weight(0.5), 0.0, "below I_min, were it to arc");
        assert!(weight(0.4 * 48.0 / 36.0) < 1e-15, "at I_min");
        assert_eq!(weight(15.0), 1.0);
        assert_eq!(weight(20.0), 1.0);
        assert_relative_eq!(
            weight(7.5),
            (5.625 - 0.4) / (11.25 - 0.4),
            max_relative = 1e-15
        );
        assert_eq!(paper_law(0.235, 0.371).weight(0.4, 0.4), 1.0);
    }

    #[test]
    fn weighted_restitution_runs_from_mechanical_to_eq_16() {
        let law = paper_law(0.235, 0.371);
        let (mechanical, v) = (0.6, 0.1);
        assert_eq!(law.weighted(mechanical, v, 0.0), mechanical);
        assert_eq!(law.weighted(mechanical, v, 1.0), law.linear(v));
        assert_relative_eq!(
            law.weighted(mechanical, v, 0.25),
            0.75 * mechanical + 0.25 * law.linear(v),
            max_relative = 1e-15
        );
        // Below the linear law, eq. 16 keeps the mechanical value at every weight.
        assert_eq!(law.weighted(0.2, v, 0.5), 0.2);
    }
}
