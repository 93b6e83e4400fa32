//! The post-arc restitution law as a function of current (docs/model.md section 5): the paper's
//! eq. 16 switches on at the minimum arc current; the continuous law fades it in from there to the
//! calibration current, where the two agree to the bit.

use bouncewear_model::mechanism::{Flight, effective_mass, effective_stiffness, impact_velocity};
use bouncewear_model::{Fidelity, Outcome, Scenario, Simulation, simulate};

/// The default rig at 48 V, where an arc first burns at `I_0 = 0.4 A * 48 / 36 = 0.533 A`.
fn at_48_v(current_a: f64, law: &str, min_separation_m: f64) -> Simulation {
    let text = format!(
        r#"{{"circuit": {{"supply_voltage_v": 48, "current_a": {current_a}}},
            "material": {{"arc_restitution": {{"law": "{law}"}}}},
            "losses": {{"min_separation_m": {min_separation_m}}}}}"#
    );
    simulate(&Scenario::from_json(&text).unwrap(), Fidelity::Exact)
}

/// Total bounce time and bounce count at `0, step, 2 step, ..., 20 A`.
fn sweep(law: &str, min_separation_m: f64, step_a: f64) -> Vec<Outcome> {
    let steps = (20.0 / step_a).round() as u32;
    (0..=steps)
        .map(|i| at_48_v(f64::from(i) * step_a, law, min_separation_m).outcome)
        .collect()
}

/// The steps `i` (from current `i` to `i + 1`) whose change in total bounce time is more than
/// three times the larger of its neighbours' changes: a jump, not the step times the local slope.
/// (Three, not one: where the last bounce dies out its duration falls like a square root, and
/// sampled square roots change by up to 2.4 times their neighbours.)
fn jumps(sweep: &[Outcome]) -> Vec<usize> {
    let change: Vec<f64> = sweep
        .windows(2)
        .map(|w| w[1].total_bounce_s - w[0].total_bounce_s)
        .collect();
    (1..change.len() - 1)
        .filter(|&i| {
            let local = change[i - 1].abs().max(change[i + 1].abs());
            change[i].abs() > 3.0 * local + 1e-15
        })
        .collect()
}

const DEFAULT_MIN_SEPARATION_M: f64 = 1e-7;

#[test]
fn the_paper_law_jumps_where_an_arc_first_burns() {
    let below = at_48_v(0.530, "paper", DEFAULT_MIN_SEPARATION_M).outcome;
    let above = at_48_v(0.534, "paper", DEFAULT_MIN_SEPARATION_M).outcome;
    assert!(
        (below.total_bounce_s - 28.6e-3).abs() < 0.05e-3
            && (above.total_bounce_s - 13.3e-3).abs() < 0.05e-3,
        "{} ms -> {} ms",
        below.total_bounce_s * 1e3,
        above.total_bounce_s * 1e3
    );
}

#[test]
fn total_bounce_time_is_continuous_in_current_from_0_to_20_a_under_the_continuous_law() {
    // Without a minimum gap the sequence ends only by the energy lost per impact, which lets the
    // last bounce die out continuously: any jump left would be the arc law's.
    let step_a = 0.001;
    let continuous = sweep("continuous", 0.0, step_a);
    assert_eq!(jumps(&continuous), Vec::<usize>::new());
    let paper = jumps(&sweep("paper", 0.0, step_a));
    assert_eq!(
        paper,
        [533],
        "the check finds the paper law's jump at 0.533 A"
    );
}

#[test]
fn with_the_default_minimum_gap_the_only_jumps_are_bounces_too_small_to_count() {
    // docs/model.md section 3: a flight peaking below g_min is no bounce. Where the last bounce
    // crosses g_min the count drops by one and the time by that bounce's duration, the flight
    // of the speed whose gap just reaches g_min.
    let spec = Scenario::default();
    let mech = &spec.spec().mechanism;
    let mass_kg = effective_mass(mech.inertia_kg_m2, mech.contact_arm_m);
    let stiffness = effective_stiffness(
        mech.spring_stiffness_n_per_m,
        mech.spring_arm_m,
        mech.contact_arm_m,
    );
    let smallest_bounce_s =
        Flight::new(mass_kg, stiffness, mech.static_force_n).exact_time_s(impact_velocity(
            mass_kg,
            stiffness,
            mech.static_force_n,
            DEFAULT_MIN_SEPARATION_M,
        ));
    let step_a = 0.001;
    let sweep = sweep("continuous", DEFAULT_MIN_SEPARATION_M, step_a);
    let found = jumps(&sweep);
    assert_eq!(found.len(), 5, "7 bounces at I_min, 2 at 15 A: {found:?}");
    for i in found {
        let (before, after) = (&sweep[i], &sweep[i + 1]);
        let drop_s = before.total_bounce_s - after.total_bounce_s;
        let local_s = (sweep[i].total_bounce_s - sweep[i - 1].total_bounce_s)
            .abs()
            .max((sweep[i + 2].total_bounce_s - sweep[i + 1].total_bounce_s).abs());
        assert_eq!(before.bounce_count, after.bounce_count + 1, "at step {i}");
        assert!(
            (drop_s - smallest_bounce_s).abs() <= 3.0 * local_s,
            "at step {i}: dropped {drop_s} s, the smallest bounce lasts {smallest_bounce_s} s"
        );
    }
}

#[test]
fn the_continuous_law_is_the_papers_eq_16_at_the_calibration_current() {
    let paper = at_48_v(15.0, "paper", DEFAULT_MIN_SEPARATION_M);
    assert_eq!(
        at_48_v(15.0, "continuous", DEFAULT_MIN_SEPARATION_M),
        paper,
        "to the bit"
    );
    // Eq. 16 itself: the restitution of the second impact, recovered from the bounces' speeds
    // (v_2^2 = (e_2 v_1)^2 - 2 eps / m), is a + b v_1.
    let mass_kg = 1.593e-5 / (0.03 * 0.03);
    let (v1, v2) = (
        paper.bounces[0].separation_velocity_m_s,
        paper.bounces[1].separation_velocity_m_s,
    );
    let e2 = (v2 * v2 + 2.0 * 1e-6 / mass_kg).sqrt() / v1;
    assert!(
        (e2 - (0.235 + 0.371 * v1)).abs() < 1e-12,
        "{e2} vs {}",
        0.235 + 0.371 * v1
    );
}

#[test]
fn a_calibration_current_of_the_users_makes_the_continuous_law_eq_16_there() {
    let scenario = |law: &str| {
        Scenario::from_json(&format!(
            r#"{{"circuit": {{"supply_voltage_v": 48, "current_a": 8}},
                "material": {{"arc_restitution": {{"law": "{law}", "calibration_current_a": 8}}}}}}"#
        ))
        .unwrap()
    };
    assert_eq!(
        simulate(&scenario("continuous"), Fidelity::Exact),
        simulate(&scenario("paper"), Fidelity::Exact)
    );
}

#[test]
fn the_continuous_law_is_mechanical_as_the_arc_current_falls_to_its_minimum() {
    let no_current = at_48_v(0.0, "continuous", DEFAULT_MIN_SEPARATION_M).outcome;
    let first_arc = at_48_v(
        0.4 * 48.0 / 36.0 + 1e-12,
        "continuous",
        DEFAULT_MIN_SEPARATION_M,
    );
    assert!(first_arc.outcome.arc_energy_j > 0.0, "an arc burns");
    assert_eq!(first_arc.outcome.bounce_count, no_current.bounce_count);
    for (got, want) in [
        (first_arc.outcome.e1, no_current.e1),
        (first_arc.outcome.total_bounce_s, no_current.total_bounce_s),
        (first_arc.outcome.peak_force_n, no_current.peak_force_n),
    ] {
        assert!((got - want).abs() <= 1e-9 * want, "{got} vs {want}");
    }
}

/// The default rig at 48 V with the scenario's default post-arc law (no `law` given).
fn at_48_v_by_default(current_a: f64) -> Simulation {
    let text = format!(r#"{{"circuit": {{"supply_voltage_v": 48, "current_a": {current_a}}}}}"#);
    simulate(&Scenario::from_json(&text).unwrap(), Fidelity::Exact)
}

#[test]
fn the_default_law_has_no_cliff_across_the_minimum_arc_current() {
    // From 0.50 A to 0.57 A in steps of 0.1 mA, across I_0 = 0.5333 A where the paper law drops
    // the total bounce time from 28.6 ms to 13.3 ms: the default law is the continuous one, so
    // no step moves the time by more than three times its neighbours'.
    let default: Vec<Outcome> = (0..=700)
        .map(|i| at_48_v_by_default(0.5 + f64::from(i) * 1e-4).outcome)
        .collect();
    let continuous: Vec<Outcome> = (0..=700)
        .map(|i| {
            at_48_v(
                0.5 + f64::from(i) * 1e-4,
                "continuous",
                DEFAULT_MIN_SEPARATION_M,
            )
            .outcome
        })
        .collect();
    assert_eq!(
        default, continuous,
        "the default is the continuous law, to the bit"
    );
    assert_eq!(jumps(&default), Vec::<usize>::new());
    let (below, above) = (&default[333], &default[334]);
    assert!(
        (below.total_bounce_s - above.total_bounce_s).abs() < 0.01e-3,
        "{} ms -> {} ms",
        below.total_bounce_s * 1e3,
        above.total_bounce_s * 1e3
    );
    // At 15 A, the only current the paper measured, it is the paper's law to the bit.
    assert_eq!(
        at_48_v_by_default(15.0),
        at_48_v(15.0, "paper", DEFAULT_MIN_SEPARATION_M)
    );
}

#[test]
fn a_supply_too_close_to_the_minimum_arc_voltage_arcs_only_above_the_calibration_current() {
    // At 12.2 V the calibration current's arc current is 15 A x 0.2 / 12.2 = 0.25 A, below
    // I_min = 0.4 A: an arc burns only above 24.4 A, beyond the calibration current, where the
    // continuous law is eq. 16.
    let at = |current_a: f64, law: &str| {
        let text = format!(
            r#"{{"circuit": {{"supply_voltage_v": 12.2, "current_a": {current_a}}},
                "material": {{"arc_restitution": {{"law": "{law}"}}}}}}"#
        );
        simulate(&Scenario::from_json(&text).unwrap(), Fidelity::Exact)
    };
    for current_a in [20.0, 24.0, 25.0, 30.0] {
        assert_eq!(
            at(current_a, "continuous"),
            at(current_a, "paper"),
            "{current_a} A"
        );
    }
    assert!(at(30.0, "continuous").outcome.arc_energy_j > 0.0);
    assert_eq!(at(20.0, "continuous").outcome.arc_energy_j, 0.0);
}
