//! The paper's closed forms of the bounce times, and its ways of reading the coefficient of
//! restitution off measured bounce times (docs/model.md section 7). They are reported checks
//! against the exact model (`bouncewear bench` prints their error; the calibration reports the
//! bias of the readings), not a tier of the engine.
//!
//! All of them fly at constant force (eq. 4, `T(v) = 2 m v / F_s`), so they need `F_s > 0`.
//! - Eq. 9, 10: a constant coefficient `e`. Bounce `n` leaves at `u_i e^n`, so it lasts
//!   `T_n = 2 m u_i e^n / F_s`, and the bounces sum to `T = 2 m u_i e / ((1 - e) F_s)`, the
//!   geometric series the paper expands binomially.
//! - Eq. 17, 19: the simplified electrical bounce. The first impact follows eq. 18,
//!   `v_1 = u_i min(1, kappa u_i^(-1/4))` (`kappa u_i^(3/4)` when inelastic), with kappa held at
//!   its new-contact value; the impacts after an arcing bounce follow eq. 16, `e = a + b v`; and
//!   there are two bounces: `T_1 = 2 m v_1 / F_s` (eq. 17), `T = T_1 (1 + a + b v_1)` (eq. 19).
//! - Eq. 14 read through eq. 4: `e_1 = u_1 / u_i` with the separation speed `u_1 = T_1 F_s / (2 m)`
//!   taken from the first bounce time. Eq. 15: `e_2 = T_2 / T_1`.
//!
//! Each is exact only in its limit (no return spring, no energy loss per impact, no pre-arc
//! softening); what that costs is measured, not assumed.

use crate::operation::Operation;
use crate::restitution::restitution_closed_form;

/// The first and total bounce times of a closed form.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BounceTimes {
    pub first_bounce_s: f64,
    pub total_bounce_s: f64,
}

/// Eq. 9 and 10 for the operation's impact velocity and a constant coefficient `e` (the paper's
/// Fig. 6 and 7 use 0.4). `None` when `F_s = 0` (eq. 4 needs a force) or `e` is outside `[0, 1)`
/// (with `e = 1` the bounces never end).
pub fn constant_restitution(operation: &Operation, e: f64) -> Option<BounceTimes> {
    if !(operation.static_force_n() > 0.0 && (0.0..1.0).contains(&e)) {
        return None;
    }
    let (flight, u) = (operation.flight(), operation.impact_velocity_m_s());
    Some(BounceTimes {
        first_bounce_s: flight.constant_force_time_s(u * e),
        total_bounce_s: flight.constant_force_time_s(u * e / (1.0 - e)),
    })
}

/// Eq. 17 and 19 for an arcing operation. `None` when the operation does not arc (eq. 19 is the
/// electrical bounce) or `F_s = 0`. The second coefficient `a + b v_1` is held in `[0, 1]`, as the
/// engine holds eq. 16.
pub fn simplified_electrical(operation: &Operation) -> Option<BounceTimes> {
    if !(operation.static_force_n() > 0.0 && operation.arcs()) {
        return None;
    }
    let u = operation.impact_velocity_m_s();
    let v1 = u * restitution_closed_form(u, operation.kappa_law().reference_kappa);
    let (a, b) = operation.arc_restitution_line();
    let e2 = (a + b * v1).clamp(0.0, 1.0);
    let first_bounce_s = operation.flight().constant_force_time_s(v1);
    Some(BounceTimes {
        first_bounce_s,
        total_bounce_s: first_bounce_s * (1.0 + e2),
    })
}

/// Eq. 14 with the separation speed read off the first bounce time through eq. 4:
/// `e_1 = T_1 F_s / (2 m u_i)`. `None` when `F_s = 0`.
pub fn e1_from_first_bounce(operation: &Operation, first_bounce_s: f64) -> Option<f64> {
    (operation.static_force_n() > 0.0).then(|| {
        first_bounce_s
            / operation
                .flight()
                .constant_force_time_s(operation.impact_velocity_m_s())
    })
}

/// Eq. 15: the coefficient of the impact between two bounces, `e = T_next / T_previous`.
pub fn e_from_bounce_times(previous_s: f64, next_s: f64) -> f64 {
    next_s / previous_s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Fidelity;
    use crate::error::Pointer;
    use crate::scenario::{Scenario, ScenarioSpec};
    use approx::assert_relative_eq;

    fn operation(spec: ScenarioSpec, fidelity: Fidelity) -> Operation {
        Operation::nominal(&Scenario::new(spec, &Pointer::root()).unwrap(), fidelity)
    }

    fn arcing() -> ScenarioSpec {
        let mut spec = ScenarioSpec::default();
        spec.circuit.supply_voltage_v = 48.0;
        spec.circuit.current_a = 15.0;
        spec
    }

    /// Eq. 10 is the sum of eq. 9's bounces.
    #[test]
    fn the_total_is_the_sum_of_the_bounces() {
        let op = operation(ScenarioSpec::default(), Fidelity::Exact);
        let times = constant_restitution(&op, 0.4).unwrap();
        let u = op.impact_velocity_m_s();
        let sum: f64 = (1..200)
            .map(|n| op.flight().constant_force_time_s(u * 0.4f64.powi(n)))
            .sum();
        assert_relative_eq!(times.total_bounce_s, sum, max_relative = 1e-14);
        assert_relative_eq!(
            times.first_bounce_s,
            op.flight().constant_force_time_s(u * 0.4),
            max_relative = 1e-15
        );
    }

    /// Eq. 17 is the closed-form tier's first bounce (eq. 18 then eq. 4) where its assumptions
    /// hold, a pre-arc that does not soften and no energy lost per impact: two paths through the
    /// code, one number.
    #[test]
    fn the_simplified_first_bounce_is_the_closed_form_tiers() {
        let mut spec = arcing();
        spec.material.softening_energy_j = 1e30;
        spec.losses.impact_energy_loss_j = 0.0;
        let op = operation(spec, Fidelity::ClosedForm);
        let simplified = simplified_electrical(&op).unwrap();
        assert_relative_eq!(
            simplified.first_bounce_s,
            op.simulate().outcome.first_bounce_s,
            max_relative = 1e-14
        );
    }

    /// Reading e1 back from a first bounce eq. 4 produced gives e1; eq. 15 of eq. 9's bounces
    /// gives e.
    #[test]
    fn the_readings_invert_the_forms() {
        let op = operation(ScenarioSpec::default(), Fidelity::Exact);
        let times = constant_restitution(&op, 0.37).unwrap();
        assert_relative_eq!(
            e1_from_first_bounce(&op, times.first_bounce_s).unwrap(),
            0.37,
            max_relative = 1e-15
        );
        let u = op.impact_velocity_m_s();
        let [t1, t2] = [1, 2].map(|n| op.flight().constant_force_time_s(u * 0.37f64.powi(n)));
        assert_relative_eq!(e_from_bounce_times(t1, t2), 0.37, max_relative = 1e-15);
    }

    #[test]
    fn without_a_static_force_or_an_arc_there_is_no_form() {
        let mut spec = ScenarioSpec::default();
        spec.mechanism.static_force_n = 0.0;
        let op = operation(spec, Fidelity::Exact);
        assert_eq!(constant_restitution(&op, 0.4), None);
        assert_eq!(e1_from_first_bounce(&op, 0.01), None);
        let mechanical = operation(ScenarioSpec::default(), Fidelity::Exact);
        assert_eq!(simplified_electrical(&mechanical), None);
        assert_eq!(constant_restitution(&mechanical, 1.0), None);
    }
}
