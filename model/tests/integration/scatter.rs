//! Scatter beyond the basics: scenario constants drawn per device or operation, truncated
//! lognormal and Weibull draws and their rejection counts, and correlated draws (a Gaussian copula).

use crate::support::{job, run_on};
use bouncewear_model::montecarlo::engine::{Batch, Tally, batch_draws, run_group};
use bouncewear_model::montecarlo::{Job, Silent, summarize_job};
use serde_json::{Value, json};

/// Every fault of a job, as `(pointer, detail)`.
fn faults(value: Value) -> Vec<(String, String)> {
    match Job::from_json(&value.to_string(), || 7) {
        Ok(_) => Vec::new(),
        Err(invalid) => invalid
            .errors()
            .iter()
            .map(|e| (e.pointer.clone(), e.detail.clone()))
            .collect(),
    }
}

fn pointers(value: Value) -> Vec<String> {
    faults(value)
        .into_iter()
        .map(|(pointer, _)| pointer)
        .collect()
}

/// Each new parameter, its field in the scenario (a JSON pointer), and a valid value other than
/// the default.
const CONSTANTS: [(&str, &str, f64); 10] = [
    ("inertia_kg_m2", "/mechanism/inertia_kg_m2", 2.1e-5),
    (
        "spring_stiffness_n_per_m",
        "/mechanism/spring_stiffness_n_per_m",
        150.0,
    ),
    ("supply_voltage_v", "/circuit/supply_voltage_v", 36.0),
    ("impact_energy_loss_j", "/losses/impact_energy_loss_j", 3e-6),
    ("min_separation_m", "/losses/min_separation_m", 2e-5),
    ("arc_restitution_a", "/material/arc_restitution/a", 0.3),
    (
        "arc_restitution_b_s_per_m",
        "/material/arc_restitution/b_s_per_m",
        -0.2,
    ),
    ("erosion_kg_per_j", "/material/erosion_kg_per_j", 5e-9),
    (
        "roughening_energy_j",
        "/material/roughening_energy_j",
        200.0,
    ),
    ("kappa", "/material/kappa", 0.6),
];

/// `document` with `value` at `pointer`, the objects on the way made as needed.
fn with_value(mut document: Value, pointer: &str, value: f64) -> Value {
    let mut at = &mut document;
    for token in pointer.split('/').skip(1) {
        at = at
            .as_object_mut()
            .expect("an object on the way")
            .entry(token)
            .or_insert_with(|| json!({}));
    }
    *at = json!(value);
    document
}

/// An arcing job whose radius scatters per device (so devices differ), with `extra` scatter.
fn arcing_job(scenario: Value, extra: Option<Value>) -> Value {
    let mut scatter = vec![json!({"parameter": "contact_radius_m", "per": "device",
        "distribution": {"kind": "uniform", "min": 5e-3, "max": 9e-3}})];
    scatter.extend(extra);
    json!({"devices": 6, "operations": 8, "bin_operations": 4, "seed": 3, "scenario": scenario,
           "scatter": scatter})
}

#[test]
fn a_fixed_draw_of_a_scenario_constant_runs_as_the_scenario_with_that_value() {
    for (parameter, field, value) in CONSTANTS {
        let scenario = json!({"circuit": {"supply_voltage_v": 48, "current_a": 15}});
        let fixed = json!({"kind": "fixed", "value": value});
        for per in ["device", "operation"] {
            // The erosion rate enters only the device's eroded mass: drawn per device alone.
            if per == "operation" && parameter == "erosion_kg_per_j" {
                continue;
            }
            let drawn = job(arcing_job(
                scenario.clone(),
                Some(json!({"parameter": parameter, "per": per, "distribution": fixed})),
            ));
            let given = with_value(scenario.clone(), field, value);
            let nominal = job(arcing_job(given, None));
            let (drawn, nominal) = (run_on(2, &drawn), run_on(2, &nominal));
            assert_eq!(
                drawn.operations, nominal.operations,
                "{parameter} per {per}"
            );
            // Device metrics take the device's own values, not those of its operations.
            if per == "device" {
                assert_eq!(drawn.devices, nominal.devices, "{parameter}");
            }
        }
    }
}

/// The operation's arguments and conditions: drawn as a lane value of the nominal operation
/// (radius, pressure, velocity) or as a condition, a fixed draw still gives the Result of the
/// scenario that sets the value, to the bit, with other scatter beside it or none.
#[test]
fn a_fixed_draw_of_an_operation_value_runs_as_the_scenario_with_that_value() {
    let lane_values = [
        ("contact_radius_m", "/material/contact_radius_m", 5e-3),
        (
            "dynamic_yield_pressure_pa",
            "/material/dynamic_yield_pressure_pa",
            3e8,
        ),
        ("impact_velocity_m_s", "/mechanism/impact_velocity_m_s", 0.3),
        ("drop_height_m", "/mechanism/drop_height_m", 2e-3),
        ("static_force_n", "/mechanism/static_force_n", 0.5),
        ("current_a", "/circuit/current_a", 10.0),
    ];
    for (parameter, field, value) in lane_values {
        let scenario = json!({"circuit": {"supply_voltage_v": 48, "current_a": 15}});
        let other = if parameter == "impact_velocity_m_s" {
            json!({"parameter": "dynamic_yield_pressure_pa", "per": "device",
                   "distribution": {"kind": "uniform", "min": 1.5e8, "max": 2.5e8}})
        } else {
            json!({"parameter": "impact_velocity_m_s", "per": "operation",
                   "distribution": {"kind": "normal", "mean": 0.25, "sd": 0.02, "min": 0.1}})
        };
        for per in ["device", "operation"] {
            for others in [vec![], vec![other.clone()]] {
                let mut scatter = others.clone();
                scatter.push(json!({"parameter": parameter, "per": per,
                    "distribution": {"kind": "fixed", "value": value}}));
                let shape = |scenario: Value, scatter: Vec<Value>| {
                    job(
                        json!({"devices": 9, "operations": 12, "bin_operations": 4, "seed": 5,
                               "scenario": scenario, "scatter": scatter}),
                    )
                };
                let drawn = run_on(2, &shape(scenario.clone(), scatter));
                let given = run_on(
                    2,
                    &shape(with_value(scenario.clone(), field, value), others),
                );
                let with = if per == "device" {
                    ""
                } else {
                    " per operation"
                };
                assert_eq!(drawn.operations, given.operations, "{parameter}{with}");
                assert_eq!(drawn.devices, given.devices, "{parameter}{with}");
            }
        }
    }
}

#[test]
fn a_scattered_constant_changes_the_devices_it_is_drawn_for() {
    let scenario = json!({"circuit": {"supply_voltage_v": 48, "current_a": 15}});
    let nominal = run_on(2, &job(arcing_job(scenario.clone(), None)));
    for (parameter, _, value) in CONSTANTS {
        let spread = json!({"kind": "uniform", "min": value.abs() * 0.5, "max": value.abs() * 1.5});
        let drawn = run_on(
            2,
            &job(arcing_job(
                scenario.clone(),
                Some(json!({"parameter": parameter, "per": "device", "distribution": spread})),
            )),
        );
        assert!(
            drawn.operations != nominal.operations || drawn.devices != nominal.devices,
            "{parameter}"
        );
    }
}

#[test]
fn a_distribution_that_can_leave_the_domain_names_the_min_that_would_truncate_it() {
    let scatter = |parameter: &str, distribution: Value| json!({"scatter": [{"parameter": parameter, "per": "device", "distribution": distribution}]});
    let radius = faults(scatter(
        "contact_radius_m",
        json!({"kind": "lognormal", "median": 1e-3, "sigma": 0.3}),
    ));
    assert_eq!(radius.len(), 1);
    assert_eq!(radius[0].0, "/scatter/0/distribution/kind");
    assert!(
        radius[0]
            .1
            .contains(r#"add "min": 0.000711 to truncate it"#),
        "{}",
        radius[0].1
    );
    let inertia = faults(scatter(
        "inertia_kg_m2",
        json!({"kind": "normal", "mean": 1.6e-5, "sd": 2e-6}),
    ));
    assert_eq!(inertia[0].0, "/scatter/0/distribution/min");
    assert!(
        inertia[0]
            .1
            .starts_with("a normal(mean 0.000016, sd 2e-6) reaches below 0"),
        "{}",
        inertia[0].1
    );
    assert!(inertia[0].1.contains(r#"add a "min" above 0"#));
    // Eq. 16's coefficients may take any finite value: an untruncated normal is valid for them.
    assert!(
        pointers(scatter(
            "arc_restitution_a",
            json!({"kind": "normal", "mean": 0.2, "sd": 0.1})
        ))
        .is_empty()
    );
    assert_eq!(
        pointers(scatter(
            "contact_radius_m",
            json!({"kind": "weibull", "scale": 1e-3, "shape": 4, "min": 7.11e-4, "max": 7.2e-4})
        )),
        ["/scatter/0/distribution/min"]
    );
}

/// Jobs a sweep of the HTTP API found accepted, whose draws left the magnitudes a scenario admits
/// and made every metric NaN (the summary then panicked): each is refused, naming the bound.
#[test]
fn a_distribution_that_reaches_past_1e30_names_the_max_that_would_truncate_it() {
    let scatter = |parameter: &str, per: &str, distribution: Value| json!({"scatter": [{"parameter": parameter, "per": per, "distribution": distribution}]});
    for (parameter, per, distribution) in [
        (
            "contact_radius_m",
            "device",
            json!({"kind": "uniform", "min": 0.007, "max": 1e308}),
        ),
        (
            "static_force_n",
            "operation",
            json!({"kind": "triangular", "min": 0.3, "mode": 0.344, "max": 1e308}),
        ),
        (
            "inertia_kg_m2",
            "device",
            json!({"kind": "lognormal", "median": 1.6e-5, "sigma": 1e308, "min": 1.3e-5}),
        ),
        (
            "dynamic_yield_pressure_pa",
            "device",
            json!({"kind": "weibull", "scale": 1e9, "shape": 0.05}),
        ),
        (
            "arc_restitution_b_s_per_m",
            "device",
            json!({"kind": "normal", "mean": -1e30, "sd": 1e28, "max": 0}),
        ),
    ] {
        let faults = faults(scatter(parameter, per, distribution));
        let bound = if parameter.starts_with("arc_") {
            "min"
        } else {
            "max"
        };
        assert_eq!(faults.len(), 1, "{parameter}: {faults:?}");
        assert_eq!(
            faults[0].0,
            format!("/scatter/0/distribution/{bound}"),
            "{parameter}"
        );
        assert!(faults[0].1.contains("1e30"), "{}", faults[0].1);
    }
    // Truncated within it, such a distribution runs, to finite statistics.
    let truncated =
        json!({"kind": "weibull", "scale": 1e9, "shape": 0.05, "min": 1e8, "max": 1e30});
    let spread = json!({"parameter": "dynamic_yield_pressure_pa", "per": "device", "distribution": truncated});
    let scenario = json!({"circuit": {"supply_voltage_v": 48, "current_a": 15}});
    let result = run_on(2, &job(arcing_job(scenario, Some(spread))));
    let bins = &result.operations["total_bounce_s"];
    assert!(
        bins.iter()
            .all(|bin| bin.summary.mean.is_finite() && bin.summary.max.is_finite())
    );
}

#[test]
fn scenario_rules_across_fields_hold_for_every_draw() {
    let both = json!({"scatter": [
        {"parameter": "static_force_n", "per": "device",
         "distribution": {"kind": "uniform", "min": 0, "max": 1}},
        {"parameter": "spring_stiffness_n_per_m", "per": "device",
         "distribution": {"kind": "uniform", "min": 0, "max": 300}}]});
    assert_eq!(pointers(both), ["/scatter/1/distribution/min"]);
    // Under the continuous law a supply too close to V_min for the calibration current to arc
    // arcs only above that current, where the law is eq. 16 (docs/model.md section 5): every
    // draw is a valid scenario, the default law's included.
    let continuous = json!({
        "scenario": {"circuit": {"supply_voltage_v": 48, "current_a": 15},
                     "material": {"arc_restitution": {"law": "continuous"}}},
        "scatter": [{"parameter": "supply_voltage_v", "per": "device",
                     "distribution": {"kind": "uniform", "min": 12.2, "max": 60}}]});
    assert_eq!(pointers(continuous), Vec::<String>::new());
}

/// A truncated lognormal radius that keeps about three quarters of its mass.
fn truncated_radius(devices: u64, per: &str) -> Value {
    json!({"devices": devices, "operations": 3, "seed": 11,
           "scenario": {"circuit": {"supply_voltage_v": 48, "current_a": 15}},
           "scatter": [{"parameter": "contact_radius_m", "per": per,
                        "distribution": {"kind": "lognormal", "median": 1e-3, "sigma": 0.5,
                                         "min": 7.11e-4, "max": 5e-3}}]})
}

#[test]
fn truncated_draws_are_counted_over_every_group_and_warned_of() {
    let job = job(truncated_radius(400, "operation"));
    let result = run_on(3, &job);
    let rejected = result.counts.truncation_rejections[0];
    // P(X < 0.711 mm) = Phi(ln(0.711) / 0.5) = 0.248 of 1200 draws kept: about 396 rejected.
    assert!((300..500).contains(&rejected), "{rejected}");
    let warning = result
        .diagnostics
        .iter()
        .find(|d| d.pointer == "/scatter/0/distribution")
        .expect("a warning for the truncated entry");
    assert!(
        warning
            .detail
            .starts_with(&format!("{rejected} random draws"))
    );
    let batch = Batch::of(&job, 0).unwrap();
    let groups = (0..batch.groups())
        .map(|g| run_group(&job, batch, g, &Silent).unwrap())
        .collect();
    let mut tally = Tally::new();
    tally.add_batch(batch, groups);
    assert_eq!(summarize_job(&job, &tally, 1.0).counts, result.counts);
    assert_eq!(run_on(1, &job).counts, result.counts);
}

#[test]
fn an_lhs_truncated_draw_needs_no_rejection_and_keeps_to_its_window() {
    let mut spec = truncated_radius(200, "device");
    spec["sampler"] = json!("lhs");
    let job = job(spec);
    let draws = batch_draws(&job, Batch::of(&job, 0).unwrap());
    assert!(draws.iter().all(|row| (7.11e-4..=5e-3).contains(&row[0])));
    let counts = run_on(2, &job).counts;
    assert!(counts.truncation_rejections.iter().all(|&c| c == 0));
}

/// Spearman's rank correlation of two samples.
fn spearman(x: &[f64], y: &[f64]) -> f64 {
    let ranks = |v: &[f64]| {
        let mut order: Vec<usize> = (0..v.len()).collect();
        order.sort_by(|&a, &b| v[a].total_cmp(&v[b]));
        let mut rank = vec![0.0; v.len()];
        for (r, &i) in order.iter().enumerate() {
            rank[i] = r as f64;
        }
        rank
    };
    let (rx, ry) = (ranks(x), ranks(y));
    let n = x.len() as f64;
    let mean = (n - 1.0) / 2.0;
    let cov: f64 = rx
        .iter()
        .zip(&ry)
        .map(|(a, b)| (a - mean) * (b - mean))
        .sum();
    let var: f64 = rx.iter().map(|a| (a - mean) * (a - mean)).sum();
    cov / var
}

fn correlated(devices: u64, sampler: &str, rho: f64) -> Value {
    json!({"devices": devices, "operations": 2, "seed": 5, "sampler": sampler,
           "scenario": {"circuit": {"supply_voltage_v": 48, "current_a": 15}},
           "scatter": [
               {"parameter": "impact_velocity_m_s", "per": "device",
                "distribution": {"kind": "normal", "mean": 0.3, "sd": 0.05, "min": 0.15}},
               {"parameter": "current_a", "per": "operation",
                "distribution": {"kind": "uniform", "min": 10, "max": 20}},
               {"parameter": "contact_radius_m", "per": "device",
                "distribution": {"kind": "lognormal", "median": 1e-3, "sigma": 0.4,
                                 "min": 7.11e-4}}],
           "correlation": {"parameters": ["impact_velocity_m_s", "contact_radius_m"],
                           "matrix": [[1, rho], [rho, 1]]}})
}

#[test]
fn correlated_draws_have_the_asked_rank_correlation_and_keep_their_marginals() {
    let rho: f64 = -0.6;
    // The rank correlation of a Gaussian copula with correlation rho.
    let spearman_rho = 6.0 / std::f64::consts::PI * (rho / 2.0).asin();
    for sampler in ["random", "lhs"] {
        let job = job(correlated(4000, sampler, rho));
        let draws = batch_draws(&job, Batch::of(&job, 0).unwrap());
        let column = |i: usize| draws.iter().map(|row| row[i]).collect::<Vec<f64>>();
        let (speed, radius) = (column(0), column(2));
        let got = spearman(&speed, &radius);
        assert!(
            (got - spearman_rho).abs() < 0.04,
            "{sampler}: {got} vs {spearman_rho}"
        );
        for (values, distribution) in [
            (&speed, &job.scatter()[0].distribution),
            (&radius, &job.scatter()[2].distribution),
        ] {
            for p in [0.05, 0.25, 0.5, 0.75, 0.95] {
                let below = values
                    .iter()
                    .filter(|&&v| v <= distribution.quantile(p))
                    .count() as f64
                    / values.len() as f64;
                assert!((below - p).abs() < 0.025, "{sampler}: {below} vs {p}");
            }
        }
    }
}

#[test]
fn under_lhs_the_first_correlated_parameter_still_fills_every_stratum_once() {
    let job = job(correlated(500, "lhs", 0.8));
    let draws = batch_draws(&job, Batch::of(&job, 0).unwrap());
    let distribution = &job.scatter()[0].distribution;
    let mut strata: Vec<usize> = draws
        .iter()
        .map(|row| {
            (0..500)
                .position(|s| row[0] < distribution.quantile(f64::from(s + 1) / 500.0))
                .unwrap_or(499)
        })
        .collect();
    strata.sort_unstable();
    assert_eq!(strata, (0..500).collect::<Vec<_>>());
}

#[test]
fn correlated_results_are_bit_identical_for_any_thread_count() {
    let mut spec = correlated(37, "random", 0.5);
    spec["correlation"] = json!({"parameters": ["impact_velocity_m_s", "contact_radius_m"],
                                 "matrix": [[1, 0.5], [0.5, 1]]});
    let job = job(spec);
    let reference = run_on(1, &job);
    for threads in [2, 3] {
        let again = run_on(threads, &job);
        assert_eq!(again.operations, reference.operations, "threads {threads}");
        assert_eq!(again.devices, reference.devices, "threads {threads}");
        assert_eq!(again.counts, reference.counts, "threads {threads}");
    }
}

#[test]
fn bad_correlations_are_refused_naming_the_pointer() {
    let with = |parameters: Value, matrix: Value| {
        let mut spec = correlated(10, "random", 0.0);
        spec["correlation"] = json!({"parameters": parameters, "matrix": matrix});
        spec
    };
    let pair = json!(["impact_velocity_m_s", "contact_radius_m"]);
    let cases = [
        (
            with(pair.clone(), json!([[1, 0.2], [0.3, 1]])),
            vec!["/correlation/matrix/0/1"],
        ),
        (
            with(pair.clone(), json!([[1, 0.2], [0.2, 0.9]])),
            vec!["/correlation/matrix/1/1"],
        ),
        (
            with(pair.clone(), json!([[1, 1.5], [1.5, 1]])),
            vec!["/correlation/matrix/0/1", "/correlation/matrix/1/0"],
        ),
        (
            with(pair.clone(), json!([[1, 0.2], [0.2]])),
            vec!["/correlation/matrix/1"],
        ),
        (
            with(pair.clone(), json!([[1, 0.2], [0.2, 1], [0, 0]])),
            vec!["/correlation/matrix"],
        ),
        (
            with(pair.clone(), json!([[1, 1], [1, 1]])),
            vec!["/correlation/matrix/1"],
        ),
        (
            with(
                json!(["impact_velocity_m_s", "static_force_n"]),
                json!([[1, 0], [0, 1]]),
            ),
            vec!["/correlation/parameters/1"],
        ),
        (
            with(
                json!(["impact_velocity_m_s", "current_a"]),
                json!([[1, 0], [0, 1]]),
            ),
            vec!["/correlation/parameters/1"],
        ),
        (
            with(
                json!(["impact_velocity_m_s", "impact_velocity_m_s"]),
                json!([[1, 0], [0, 1]]),
            ),
            vec!["/correlation/parameters/1"],
        ),
        (
            with(json!(["impact_velocity_m_s"]), json!([[1]])),
            vec!["/correlation/parameters"],
        ),
    ];
    for (spec, expected) in cases {
        assert_eq!(pointers(spec.clone()), expected, "{}", spec["correlation"]);
    }
    let mixed = faults(with(
        json!(["impact_velocity_m_s", "current_a"]),
        json!([[1, 0], [0, 1]]),
    ));
    assert!(mixed[0].1.contains("same `per`"), "{}", mixed[0].1);
}

#[test]
fn an_indefinite_matrix_is_refused_at_the_row_where_cholesky_fails() {
    let spec = json!({"scatter": [
        {"parameter": "impact_velocity_m_s", "per": "device",
         "distribution": {"kind": "uniform", "min": 0.2, "max": 0.3}},
        {"parameter": "static_force_n", "per": "device",
         "distribution": {"kind": "uniform", "min": 0.4, "max": 0.6}},
        {"parameter": "kappa", "per": "device",
         "distribution": {"kind": "uniform", "min": 0.4, "max": 0.6}}],
        "correlation": {"parameters": ["impact_velocity_m_s", "static_force_n", "kappa"],
                        "matrix": [[1, 0.9, 0.9], [0.9, 1, -0.9], [0.9, -0.9, 1]]}});
    let found = faults(spec);
    assert_eq!(found.len(), 1);
    assert_eq!(found[0].0, "/correlation/matrix/2");
    assert!(
        found[0].1.contains("not positive definite"),
        "{}",
        found[0].1
    );
}

#[test]
fn a_correlation_per_operation_is_deterministic() {
    let spec = json!({"devices": 5, "operations": 20, "seed": 9,
        "scenario": {"circuit": {"supply_voltage_v": 48, "current_a": 15}},
        "scatter": [
            {"parameter": "impact_velocity_m_s", "per": "operation",
             "distribution": {"kind": "uniform", "min": 0.2, "max": 0.4}},
            {"parameter": "supply_voltage_v", "per": "operation",
             "distribution": {"kind": "weibull", "scale": 48, "shape": 8, "min": 30}}],
        "correlation": {"parameters": ["supply_voltage_v", "impact_velocity_m_s"],
                        "matrix": [[1, 0.7], [0.7, 1]]}});
    let job = job(spec);
    let (one, three) = (run_on(1, &job), run_on(3, &job));
    assert_eq!(one.operations, three.operations);
    assert_eq!(one.devices, three.devices);
}

/// Each device draws its operations' values ahead, in blocks: the values, their order and the
/// rejections must be those of drawing one operation at a time from the device's own stream, with
/// no draw past its last operation (130 operations: two blocks and a short one).
#[test]
fn operation_draws_are_each_devices_stream_one_operation_at_a_time() {
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    let (devices, operations, seed) = (9_u64, 130_u64, 4242_u64);
    let job = job(json!({
        "devices": devices, "operations": operations, "bin_operations": operations, "seed": seed,
        "scenario": {"circuit": {"supply_voltage_v": 48, "current_a": 15}},
        "metrics": ["impact_velocity_m_s"],
        "scatter": [{"parameter": "impact_velocity_m_s", "per": "operation",
                     "distribution": {"kind": "normal", "mean": 0.2, "sd": 0.1, "min": 0.15}}]}));
    let distribution = &job.scatter()[0].distribution;
    let (mut rejections, mut values) = (0, Vec::new());
    for device in 0..devices {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        rng.set_stream(device);
        for _ in 0..operations {
            values.push(distribution.sample_counting(&mut rng, &mut rejections));
        }
    }
    for threads in [1, 2] {
        let result = run_on(threads, &job);
        assert_eq!(result.counts.truncation_rejections, [rejections]);
        let summary = &result.operations["impact_velocity_m_s"][0].summary;
        assert_eq!(summary.n, devices * operations);
        let min = values.iter().copied().fold(f64::INFINITY, f64::min);
        let max = values.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        assert_eq!((summary.min, summary.max), (min, max));
        let mean = values.iter().sum::<f64>() / values.len() as f64;
        approx::assert_relative_eq!(summary.mean, mean, max_relative = 1e-12);
    }
}

/// A distribution's member of the wrong type, or one its kind does not have, is named at the
/// member, whichever order they come in; serde's tagged enum named the whole distribution (a
/// probe: `{"kind": "fixed", "value": null}` at `/scatter/0/distribution`). Every fault of the
/// distribution is named at once, as elsewhere in a job.
#[test]
fn a_distributions_faults_are_named_at_their_members() {
    let scatter = |distribution: Value| json!({"scatter": [{"parameter": "contact_radius_m", "per": "device", "distribution": distribution}]});
    let at = |member: &str| format!("/scatter/0/distribution{member}");
    for (distribution, expected) in [
        (
            json!({"kind": "fixed", "value": null}),
            vec![(at("/value"), "invalid type: null, expected a number")],
        ),
        (
            json!({"value": "a", "kind": "fixed"}),
            vec![(at("/value"), "invalid type: string")],
        ),
        (
            json!({"kind": "normal", "mean": null, "sd": "x", "min": 1e-3}),
            vec![
                (at("/mean"), "invalid type: null"),
                (at("/sd"), "invalid type: string"),
            ],
        ),
        (
            json!({"kind": "uniform", "min": 1e-3, "max": 2e-3, "sd": 1}),
            vec![(
                at("/sd"),
                "unknown field `sd`, expected one of `kind`, `min`, `max`",
            )],
        ),
        (
            json!({"kind": "uniform", "min": 1e-3, "max": 2e-3, "zeta": 1}),
            vec![(
                at("/zeta"),
                "unknown field `zeta`, expected one of `kind`, `min`, `max`",
            )],
        ),
        // Members are read in their names' order: `extra` before `kind`, `sd` after it.
        (
            json!({"extra": 1, "kind": "fixed", "value": 1e-3}),
            vec![(
                at("/extra"),
                "unknown field `extra`, expected one of `kind`, `value`, `mean`",
            )],
        ),
        (
            json!({"sd": 1, "kind": "fixed", "value": 1e-3}),
            vec![(at("/sd"), "unknown field `sd`, expected `kind` or `value`")],
        ),
        (
            json!({"kind": "uniform", "min": 1e-3}),
            vec![(at("/max"), "missing field `max`")],
        ),
        (
            json!({"min": 1e-3, "max": 2e-3}),
            vec![(at("/kind"), "missing field `kind`")],
        ),
        (
            json!({"kind": "gamma", "min": 1e-3}),
            vec![(
                at("/kind"),
                "unknown value `gamma`, expected one of `fixed`",
            )],
        ),
        (
            json!(1e-3),
            vec![(at(""), "expected a distribution: an object with its `kind`")],
        ),
    ] {
        let found = faults(scatter(distribution.clone()));
        let found: Vec<(&str, &str)> = found
            .iter()
            .map(|(p, d)| (p.as_str(), d.as_str()))
            .collect();
        assert_eq!(found.len(), expected.len(), "{distribution}: {found:?}");
        for ((pointer, detail), (want_pointer, want_detail)) in found.iter().zip(&expected) {
            assert_eq!(pointer, want_pointer, "{distribution}: {detail}");
            assert!(detail.contains(want_detail), "{distribution}: {detail}");
        }
    }
    // Every kind still reads what it wrote.
    for distribution in [
        json!({"kind": "fixed", "value": 1e-3}),
        json!({"kind": "normal", "mean": 1e-3, "sd": 1e-4, "min": 8e-4}),
        json!({"kind": "lognormal", "median": 1e-3, "sigma": 0.1, "min": 8e-4, "max": 2e-3}),
        json!({"kind": "uniform", "min": 8e-4, "max": 2e-3}),
        json!({"kind": "triangular", "min": 8e-4, "mode": 1e-3, "max": 2e-3}),
        json!({"kind": "weibull", "scale": 1e-3, "shape": 8.0, "min": 8e-4}),
    ] {
        assert_eq!(
            faults(scatter(distribution.clone())),
            Vec::<(String, String)>::new()
        );
        let spec: bouncewear_model::montecarlo::distribution::DistributionSpec =
            serde_json::from_value(distribution.clone()).unwrap();
        assert_eq!(serde_json::to_value(&spec).unwrap(), distribution);
    }
}
