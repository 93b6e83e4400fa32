//! One make operation: analytic limits, the invariants of docs/model.md section 3, hard inputs.

use approx::assert_relative_eq;
use bouncewear_model::mechanism::{Flight, effective_mass};
use bouncewear_model::restitution::critical_speed;
use bouncewear_model::scenario::ScenarioSpec;
use bouncewear_model::{Fidelity, Pointer, Scenario, Simulation, simulate};
use proptest::prelude::*;

fn scenario(edit: impl FnOnce(&mut ScenarioSpec)) -> Scenario {
    let mut spec = ScenarioSpec::default();
    edit(&mut spec);
    Scenario::new(spec, &Pointer::root()).expect("valid scenario")
}

const M: f64 = 1.593e-5 / (0.03 * 0.03);

/// The invariants every simulation satisfies, whatever its inputs.
fn assert_invariants(scenario: &Scenario, sim: &Simulation) {
    let out = &sim.outcome;
    let max_bounces = scenario.spec().losses.max_bounces;
    let numbers = [
        out.impact_velocity_m_s,
        out.kappa,
        out.e1,
        out.first_bounce_s,
        out.total_bounce_s,
        out.pre_arc_s,
        out.arc_energy_j,
        out.peak_force_n,
        out.impact_duration_s,
    ];
    assert!(
        numbers.iter().all(|x| x.is_finite() && *x >= 0.0),
        "{out:?}"
    );
    assert!((0.0..=1.0).contains(&out.e1), "e1 = {}", out.e1);
    assert!(out.bounce_count <= max_bounces);
    assert_eq!(out.bounce_count as usize, sim.bounces.len());
    assert!(
        !out.truncated || out.bounce_count == max_bounces,
        "truncated only at the cap"
    );
    let mut previous_speed = out.impact_velocity_m_s;
    for bounce in &sim.bounces {
        assert!(
            bounce.separation_velocity_m_s <= previous_speed,
            "energy grew at an impact"
        );
        // A flight lasts a positive time, but past f64's speeds (section 3) that rounds to 0.
        assert!(bounce.duration_s.is_finite() && bounce.duration_s >= 0.0);
        assert!(bounce.duration_s > 0.0 || bounce.separation_velocity_m_s < 1e-300);
        assert!(
            bounce.peak_gap_m.is_finite()
                && bounce.peak_gap_m >= scenario.spec().losses.min_separation_m
        );
        previous_speed = bounce.separation_velocity_m_s;
    }
    let total: f64 = sim.bounces.iter().map(|b| b.duration_s).sum();
    assert_relative_eq!(out.total_bounce_s, total, max_relative = 1e-12);
    assert_eq!(
        out.first_bounce_s,
        sim.bounces.first().map_or(0.0, |b| b.duration_s)
    );
}

fn both(scenario: &Scenario) -> [Simulation; 2] {
    Fidelity::ALL.map(|fidelity| {
        let sim = simulate(scenario, fidelity);
        assert_invariants(scenario, &sim);
        sim
    })
}

#[test]
fn default_rig_has_seven_bounces_totalling_about_29_ms() {
    let [exact, closed_form] = both(&Scenario::default());
    assert_eq!(exact.outcome.bounce_count, 7);
    assert!((exact.outcome.total_bounce_s - 0.029).abs() < 0.001);
    // docs/model.md section 7: at 0.344 N the constant-force flight overestimates the first bounce
    // by about 11 % (12 % at the exact separation speed); eq. 18's larger e1 adds 4 % more, 16 % in
    // all (the independent validation values agree).
    let flight = Flight::new(M, 200.0, 0.344);
    let v1 = exact.bounces[0].separation_velocity_m_s;
    let flight_over = flight.constant_force_time_s(v1) / flight.exact_time_s(v1) - 1.0;
    assert!(
        (flight_over - 0.117).abs() < 0.005,
        "flight overestimate {flight_over}"
    );
    let over = closed_form.outcome.first_bounce_s / exact.outcome.first_bounce_s - 1.0;
    assert!(
        (over - 0.160).abs() < 0.005,
        "first bounce overestimate {over}"
    );
}

#[test]
fn elastic_regime_without_energy_loss_runs_to_the_cap_at_constant_speed() {
    let scenario = scenario(|s| {
        s.material.kappa = Some(1e3);
        s.losses.impact_energy_loss_j = 0.0;
    });
    for sim in both(&scenario) {
        assert!(sim.outcome.truncated);
        assert_eq!(sim.outcome.bounce_count, 64);
        assert_eq!(sim.outcome.e1, 1.0);
        assert!(
            sim.bounces
                .iter()
                .all(|b| b.separation_velocity_m_s == sim.outcome.impact_velocity_m_s)
        );
    }
}

#[test]
fn elastic_regime_with_energy_loss_ends_by_losing_eps_per_impact() {
    let eps = 2e-4;
    let scenario = scenario(|s| {
        s.material.kappa = Some(1e3);
        s.losses.impact_energy_loss_j = eps;
    });
    for sim in both(&scenario) {
        assert!(!sim.outcome.truncated && sim.outcome.bounce_count > 1);
        let mut previous = sim.outcome.impact_velocity_m_s;
        for bounce in &sim.bounces {
            let v = bounce.separation_velocity_m_s;
            assert_relative_eq!(
                0.5 * M * (previous * previous - v * v),
                eps,
                max_relative = 1e-9
            );
            previous = v;
        }
    }
}

/// docs/model.md section 3: with neither a loss per impact nor a least gap, nothing but the cap
/// ends a sequence. At 15 A eq. 16 keeps `e` near 0.235, so the speed leaves f64 after about 256
/// bounces; it flies on at the least positive speed. Without a static force every flight lasts
/// half the spring's period whatever its speed: the sequence ended there once, 74 % of its time
/// and arc energy short. The arc energy is an independent 50-digit evaluation of the exact
/// sequence (mpmath, an outside check).
#[test]
fn without_losses_the_sequence_runs_to_the_cap_however_slow() {
    let endless = |static_force_n: f64| {
        scenario(|s| {
            s.mechanism.static_force_n = static_force_n;
            s.circuit.supply_voltage_v = 48.0;
            s.circuit.current_a = 15.0;
            s.losses.impact_energy_loss_j = 0.0;
            s.losses.min_separation_m = 0.0;
            s.losses.max_bounces = 1000;
        })
    };
    let half_period = std::f64::consts::PI * (M / 200.0).sqrt();
    for sim in both(&endless(0.0)) {
        let out = &sim.outcome;
        assert!(out.truncated && out.bounce_count == 1000, "{out:?}");
        assert_relative_eq!(out.first_bounce_s, half_period, max_relative = 1e-15);
        assert_relative_eq!(
            out.total_bounce_s,
            1000.0 * half_period,
            max_relative = 1e-12
        );
        assert_relative_eq!(out.arc_energy_j, 3989.83874, max_relative = 1e-9);
        let last = sim.bounces.last().expect("bounces");
        assert_eq!(
            (last.separation_velocity_m_s, last.peak_gap_m),
            (5e-324, 0.0)
        );
        assert_eq!(last.arc_energy_j, sim.bounces[0].arc_energy_j);
    }
    // With a static force the flights shrink with the speed: the bounces past f64's range add
    // nothing to the times or energies (under 1e-150 s), and the sequence ends at the cap.
    let [short, long] = [300, 1000].map(|cap| {
        let mut spec = endless(0.344).spec().clone();
        spec.losses.max_bounces = cap;
        let scenario = Scenario::new(spec, &Pointer::root()).expect("valid scenario");
        let [exact, _] = both(&scenario);
        assert!(exact.outcome.truncated && exact.outcome.bounce_count == cap);
        exact.outcome
    });
    assert_eq!(short.total_bounce_s, long.total_bounce_s);
    assert_eq!(short.arc_energy_j, long.arc_energy_j);
}

#[test]
fn cap_reached_truncates_with_exactly_max_bounces() {
    let scenario = scenario(|s| s.losses.max_bounces = 3);
    for sim in both(&scenario) {
        assert!(sim.outcome.truncated);
        assert_eq!(sim.outcome.bounce_count, 3);
    }
    let scenario = self::scenario(|s| s.losses.max_bounces = 7);
    assert!(
        !simulate(&scenario, Fidelity::Exact).outcome.truncated,
        "7 bounces fit in a cap of 7"
    );
}

#[test]
fn kappa_towards_zero_is_a_dead_impact_with_e_from_eq_18() {
    for kappa in [1e-8, 1e-20] {
        let scenario = scenario(|s| s.material.kappa = Some(kappa));
        let [exact, closed_form] = both(&scenario);
        let eq18 = kappa / exact.outcome.impact_velocity_m_s.powf(0.25);
        assert_relative_eq!(exact.outcome.e1, eq18, max_relative = 1e-12);
        assert_relative_eq!(closed_form.outcome.e1, eq18, max_relative = 1e-15);
        assert_eq!(
            exact.outcome.bounce_count, 0,
            "peak gap far below min_separation_m"
        );
    }
}

/// docs/contract.md, the `simulate` output's edge cases: with current and no bounce, the bounce
/// times are 0 and `bounces` empty, while the pre-arc still burns before the touch: the same as
/// in the bouncing operation (it depends on the impact speed alone), and all of the arc energy.
#[test]
fn with_no_bounce_the_pre_arc_still_burns() {
    let at_15_a = |s: &mut ScenarioSpec| {
        s.circuit.supply_voltage_v = 48.0;
        s.circuit.current_a = 15.0;
    };
    let bouncing = simulate(&scenario(at_15_a), Fidelity::Exact);
    assert!(bouncing.outcome.bounce_count > 0 && bouncing.outcome.pre_arc_s > 0.0);
    let pre_arc_energy = bouncing.outcome.arc_energy_j
        - bouncing.bounces.iter().map(|b| b.arc_energy_j).sum::<f64>();
    let dead = scenario(|s| {
        at_15_a(s);
        s.material.kappa = Some(0.01);
    });
    for sim in both(&dead) {
        let out = &sim.outcome;
        assert_eq!(
            (out.bounce_count, out.first_bounce_s, out.total_bounce_s),
            (0, 0.0, 0.0)
        );
        assert!(sim.bounces.is_empty());
        assert_eq!(out.pre_arc_s, bouncing.outcome.pre_arc_s);
        assert_relative_eq!(out.arc_energy_j, pre_arc_energy, max_relative = 1e-12);
    }
}

#[test]
fn kappa_towards_infinity_is_elastic_and_ends_at_the_cap_or_by_losses() {
    let scenario = scenario(|s| s.material.kappa = Some(1e8));
    for sim in both(&scenario) {
        assert_eq!(sim.outcome.e1, 1.0);
        assert!(sim.outcome.truncated, "u^2 / (2 eps/m) ~ 440 impacts > 64");
    }
}

#[test]
fn no_static_force_gives_half_period_flights_at_both_fidelities() {
    let scenario = scenario(|s| s.mechanism.static_force_n = 0.0);
    let omega = (200.0 / M).sqrt();
    for sim in both(&scenario) {
        assert!(sim.outcome.bounce_count > 0);
        for bounce in &sim.bounces {
            assert_relative_eq!(
                bounce.duration_s,
                std::f64::consts::PI / omega,
                max_relative = 1e-14
            );
        }
    }
}

#[test]
fn no_spring_makes_exact_and_closed_form_flights_identical() {
    let scenario = scenario(|s| s.mechanism.spring_stiffness_n_per_m = 0.0);
    let [exact, _] = both(&scenario);
    for bounce in &exact.bounces {
        assert_relative_eq!(
            bounce.duration_s,
            2.0 * bounce.separation_velocity_m_s * M / 0.344,
            max_relative = 1e-15
        );
    }
}

#[test]
fn zero_impact_velocity_is_no_impact_at_all() {
    for scenario in [
        scenario(|s| s.mechanism.impact_velocity_m_s = Some(0.0)),
        scenario(|s| {
            s.mechanism.drop_height_m = 0.0;
            s.circuit.supply_voltage_v = 48.0;
            s.circuit.current_a = 15.0;
        }),
    ] {
        for sim in both(&scenario) {
            let out = sim.outcome;
            assert_eq!(
                (
                    out.e1,
                    out.peak_force_n,
                    out.impact_duration_s,
                    out.pre_arc_s
                ),
                (0.0, 0.0, 0.0, 0.0)
            );
            assert_eq!(
                (out.bounce_count, out.total_bounce_s, out.arc_energy_j),
                (0, 0.0, 0.0)
            );
            assert!(sim.bounces.is_empty());
        }
    }
}

#[test]
fn impact_at_1e4_m_s_is_finite_and_nearly_dead() {
    let scenario = scenario(|s| s.mechanism.impact_velocity_m_s = Some(1e4));
    let [exact, _] = both(&scenario);
    assert!(exact.outcome.e1 < 0.04);
    assert!(exact.outcome.peak_force_n > 1e5);
}

#[test]
fn tiny_gaps_far_below_the_static_deflection_still_count() {
    // Soft spring, large static force: d = F_s/k = 1 km; bounces of nanometres must not read as 0.
    let scenario = scenario(|s| {
        s.mechanism.spring_stiffness_n_per_m = 1e-3;
        s.mechanism.static_force_n = 1.0;
        s.mechanism.impact_velocity_m_s = Some(1e-3);
        s.losses.min_separation_m = 1e-15;
        s.losses.impact_energy_loss_j = 0.0;
    });
    let [exact, _] = both(&scenario);
    assert!(exact.outcome.bounce_count > 0);
    let flight = Flight::new(M, 1e-3 * 1.0, 1.0);
    for bounce in &exact.bounces {
        let v = bounce.separation_velocity_m_s;
        assert_relative_eq!(
            bounce.peak_gap_m,
            flight.exact_peak_gap_m(v),
            max_relative = 1e-15
        );
        assert_relative_eq!(bounce.peak_gap_m, v * v * M / 2.0, max_relative = 1e-6);
    }
}

#[test]
fn bounces_settle_at_the_critical_speed_without_losses() {
    // Eq. 7 alone never ends a closure: speeds fall towards u_c and stay (section 3).
    let scenario = scenario(|s| {
        s.losses.impact_energy_loss_j = 0.0;
        s.losses.max_bounces = 10_000;
    });
    let sim = simulate(&scenario, Fidelity::Exact);
    assert!(sim.outcome.truncated);
    let last = sim.bounces.last().unwrap().separation_velocity_m_s;
    let uc = critical_speed(sim.outcome.kappa);
    assert!(last >= uc && last < uc * 1.01, "last {last}, u_c {uc}");
}

#[test]
fn extreme_material_constants_give_finite_answers() {
    for (e_pa, p_pa, r_m) in [
        (1e30, 1e-30, 1e-30),
        (1e-30, 1e30, 1e30),
        (1e30, 1e30, 1e-30),
        (1e-30, 1e-30, 1e30),
    ] {
        let scenario = scenario(|s| {
            s.material.youngs_modulus_pa = e_pa;
            s.material.dynamic_yield_pressure_pa = p_pa;
            s.material.contact_radius_m = r_m;
            s.material.worn_radius_m = r_m;
            s.circuit.supply_voltage_v = 1e30;
            s.circuit.current_a = 1e30;
        });
        both(&scenario);
    }
}

#[test]
fn effective_mass_of_the_rig() {
    assert_relative_eq!(effective_mass(1.593e-5, 0.03), M, max_relative = 1e-15);
}

fn log_uniform(lo: f64, hi: f64) -> impl Strategy<Value = f64> {
    (lo.log10()..hi.log10()).prop_map(|x| 10f64.powf(x))
}

prop_compose! {
    fn any_scenario()(
        inertia in log_uniform(1e-12, 1.0),
        stiffness in prop_oneof![Just(0.0), log_uniform(1e-6, 1e6)],
        static_force in prop_oneof![Just(0.0), log_uniform(1e-6, 1e6)],
        drop_height in log_uniform(1e-9, 1e-1),
        velocity in prop_oneof![Just(None), log_uniform(1e-9, 1e4).prop_map(Some)],
        kappa in prop_oneof![Just(None), log_uniform(1e-8, 1e8).prop_map(Some)],
        pressure in log_uniform(1e3, 1e15),
        radius in log_uniform(1e-9, 1e3),
        youngs in log_uniform(1e5, 1e17),
        supply in prop_oneof![Just(0.0), log_uniform(1.0, 1e6)],
        current in log_uniform(1e-6, 1e6),
        loss in prop_oneof![Just(0.0), log_uniform(1e-15, 1.0)],
        gap in prop_oneof![Just(0.0), log_uniform(1e-15, 1e-3)],
        max_bounces in 1u32..=300,
    ) -> Scenario {
        scenario(|s| {
            s.mechanism.inertia_kg_m2 = inertia;
            s.mechanism.spring_stiffness_n_per_m = stiffness;
            s.mechanism.static_force_n = if stiffness == 0.0 && static_force == 0.0 { 1.0 } else { static_force };
            s.mechanism.drop_height_m = drop_height;
            s.mechanism.impact_velocity_m_s = velocity;
            s.material.kappa = kappa;
            s.material.dynamic_yield_pressure_pa = pressure;
            s.material.contact_radius_m = radius;
            s.material.worn_radius_m = radius;
            s.material.youngs_modulus_pa = youngs;
            s.circuit.supply_voltage_v = supply;
            s.circuit.current_a = current;
            s.losses.impact_energy_loss_j = loss;
            s.losses.min_separation_m = gap;
            s.losses.max_bounces = max_bounces;
        })
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    #[test]
    fn any_valid_scenario_gives_finite_outputs_within_the_invariants(scenario in any_scenario()) {
        both(&scenario);
    }
}

/// Fig. 19: the contact closed at 4.33 N deforms most. Its first impact, at 0.71 m/s against
/// 0.22 m/s, leaves ten times the plastic work of the one at 0.344 N (docs/model.md section 4).
#[test]
fn first_impact_plastic_work_is_ten_times_larger_at_4_33_n_than_at_0_344_n() {
    let work = |static_force_n: f64| {
        let scenario = scenario(|spec| spec.mechanism.static_force_n = static_force_n);
        let outcome = simulate(&scenario, Fidelity::Exact).outcome;
        outcome.first_impact_plastic_work_j
    };
    let ratio = work(4.33) / work(0.344);
    assert!((ratio - 10.3).abs() < 0.05, "{ratio}");
}
