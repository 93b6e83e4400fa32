//! The sensitivity analysis of a job (docs/contract.md "Sensitivity"): the same bits on every
//! kernel and thread count and group by group, analytic answers where the model gives them, SALib's
//! indices on the engine's own samples, and the rules of the `sensitivity` field.

use crate::support::{job, run_on};
use bouncewear_model::montecarlo::engine::{Batch, batch_draws, sobol_b_draws};
use bouncewear_model::montecarlo::{Job, JobResult, Kernel, Silent, run_job_on};
use serde_json::{Value, json};

const JOBS: &str = include_str!("../../../tests/data/reference_jobs.json");

/// The issue's job at 48 V / 15 A (radius and hardness per device, closing velocity per
/// operation), smaller, with Sobol' indices.
fn arcing_job(devices: u64, operations: u64) -> Value {
    let reference: Value = serde_json::from_str(JOBS).unwrap();
    let mut job = reference["48 V / 15 A"].clone();
    job["devices"] = json!(devices);
    job["operations"] = json!(operations);
    job["metrics"] = json!(["total_bounce_s", "arc_energy_j", "kappa", "final_radius_m"]);
    job["sensitivity"] = json!({"method": "sobol"});
    job
}

fn run(kernel: Kernel, threads: usize, job: &Job) -> JobResult {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    pool.install(|| run_job_on(kernel, job, &Silent)).unwrap()
}

fn sensitivity_text(result: &JobResult) -> String {
    serde_json::to_string(result.sensitivity.as_ref().expect("asked for")).unwrap()
}

#[test]
fn the_indices_are_the_same_bits_on_every_kernel_and_thread_count() {
    // 37 devices: batches of every width leave a remainder that runs one by one.
    let job = job(arcing_job(37, 40));
    let reference = run(Kernel::SCALAR, 1, &job);
    let text = sensitivity_text(&reference);
    for kernel in Kernel::all() {
        for threads in [1, 2, 3] {
            let result = run(kernel, threads, &job);
            assert_eq!(
                sensitivity_text(&result),
                text,
                "{kernel:?}, {threads} threads"
            );
            // The devices' own statistics do not change with the analysis.
            assert_eq!(result.operations, reference.operations);
        }
    }
}

#[test]
fn asking_for_indices_changes_no_other_number() {
    let with = job(arcing_job(40, 30));
    let mut spec = arcing_job(40, 30);
    spec.as_object_mut().unwrap().remove("sensitivity");
    let without = job(spec);
    let (a, b) = (run_on(2, &with), run_on(2, &without));
    assert_eq!(a.operations, b.operations);
    assert_eq!(a.devices, b.devices);
    assert_eq!(a.counts, b.counts);
    assert!(b.sensitivity.is_none());
}

/// The closing velocity's metric is the closing velocity: it alone drives it (first and total
/// index 1, regression coefficient 1), and a parameter it does not depend on has total index 0
/// exactly, at either level.
#[test]
fn a_metric_one_parameter_fixes_has_index_one_for_it_and_zero_for_the_rest() {
    for per in ["device", "operation"] {
        let job = job(json!({
            "devices": 300, "operations": 4, "bin_operations": 2, "seed": 11,
            "metrics": ["impact_velocity_m_s"],
            "scatter": [
                {"parameter": "impact_velocity_m_s", "per": per,
                 "distribution": {"kind": "uniform", "min": 0.1, "max": 0.4}},
                {"parameter": "contact_radius_m", "per": "device",
                 "distribution": {"kind": "uniform", "min": 0.004, "max": 0.008}}
            ],
            "sensitivity": {"method": "sobol"}
        }));
        let result = run(Kernel::best(), 2, &job);
        let bins = &result.sensitivity.as_ref().unwrap()["impact_velocity_m_s"];
        assert_eq!(bins.len(), 2);
        for bin in bins {
            let velocity = &bin.indices["impact_velocity_m_s"];
            let radius = &bin.indices["contact_radius_m"];
            assert_eq!(velocity.per.name(), per);
            for index in [velocity.first.unwrap(), velocity.total.unwrap()] {
                assert!(
                    index.ci95[0] <= 1.0 && 1.0 <= index.ci95[1],
                    "{per}: velocity {index:?}"
                );
                assert!((index.value - 1.0).abs() < 0.1, "{per}: velocity {index:?}");
            }
            let total = radius.total.unwrap();
            assert_eq!((total.value, total.ci95), (0.0, [0.0, 0.0]), "{per}");
            let first = radius.first.unwrap();
            assert!(
                first.ci95[0] <= 0.0 && 0.0 <= first.ci95[1],
                "{per}: {first:?}"
            );
            assert!((velocity.src.unwrap() - 1.0).abs() < 1e-9, "{per}");
            assert!((bin.r_squared.unwrap() - 1.0).abs() < 1e-9, "{per}");
        }
    }
}

/// One device's operations: the indices are estimated from its values, each interval is its point
/// (there is no spread between devices to measure) and the bin says so. They were 0 in `[0, 0]`,
/// as of an output that does not vary (an outside probe: the velocity's own index 0, its
/// regression coefficient 1). A device-level input does not vary within one device: index 0.
#[test]
fn one_devices_indices_are_estimated_and_their_intervals_are_points() {
    let job = job(json!({
        "devices": 1, "operations": 2000, "seed": 5,
        "metrics": ["impact_velocity_m_s"],
        "scatter": [
            {"parameter": "impact_velocity_m_s", "per": "operation",
             "distribution": {"kind": "uniform", "min": 0.1, "max": 0.4}},
            {"parameter": "contact_radius_m", "per": "device",
             "distribution": {"kind": "uniform", "min": 0.004, "max": 0.008}}
        ],
        "sensitivity": {"method": "sobol"}
    }));
    let result = run(Kernel::best(), 2, &job);
    let bin = &result.sensitivity.as_ref().unwrap()["impact_velocity_m_s"][0];
    let reason = bin.reason.as_deref().unwrap();
    assert!(reason.starts_with("one device"), "{reason}");
    let velocity = &bin.indices["impact_velocity_m_s"];
    for index in [velocity.first.unwrap(), velocity.total.unwrap()] {
        assert!((index.value - 1.0).abs() < 0.1, "{index:?}");
        assert_eq!(index.ci95, [index.value; 2]);
    }
    let radius = &bin.indices["contact_radius_m"];
    assert_eq!(radius.total.unwrap().ci95, [0.0; 2]);
}

/// The job's scenario with the parameter values `row` (one per scatter entry) in it.
fn scenario_with(job: &Job, row: &[f64]) -> Value {
    let mut spec = job.scenario().spec().clone();
    for (entry, &value) in job.scatter().iter().zip(row) {
        entry.parameter.set_in(&mut spec, value);
    }
    serde_json::to_value(spec).unwrap()
}

/// One operation of a new device with the parameter values `row` (one per scatter entry): the
/// metrics, by running it as a one-device job without scatter.
fn evaluate(job: &Job, row: &[f64], metrics: &[&str]) -> Vec<f64> {
    let single = crate::support::job(json!({
        "devices": 1, "operations": 1, "seed": 1,
        "scenario": scenario_with(job, row),
        "metrics": metrics,
    }));
    let result = run(Kernel::SCALAR, 1, &single);
    metrics
        .iter()
        .map(|m| result.operations[*m][0].summary.min)
        .collect()
}

/// The outputs of a one-operation job with device-level scatter, in SALib's order (per device:
/// `A`, `AB_1` .. `AB_k`, `B`), evaluated outside the engine from the engine's draws; with
/// `BOUNCEWEAR_WRITE_SOBOL_SAMPLES=FILE` they are written for `tools/sobol_reference.py --job`.
fn salib_job() -> Value {
    json!({
        "devices": 256, "operations": 1, "seed": 1992,
        "scenario": {"circuit": {"current_a": 15, "supply_voltage_v": 48}},
        "metrics": ["total_bounce_s", "arc_energy_j"],
        "scatter": [
            {"parameter": "contact_radius_m", "per": "device",
             "distribution": {"kind": "normal", "mean": 0.0077, "sd": 0.0008, "min": 0.001}},
            {"parameter": "dynamic_yield_pressure_pa", "per": "device",
             "distribution": {"kind": "lognormal", "median": 2.0e8, "sigma": 0.15}},
            {"parameter": "impact_velocity_m_s", "per": "device",
             "distribution": {"kind": "normal", "mean": 0.224, "sd": 0.02, "min": 0.05}}
        ],
        "sensitivity": {"method": "sobol"}
    })
}

fn salib_order_outputs(job: &Job, metrics: &[&str]) -> Vec<Vec<f64>> {
    let batch = Batch::of(job, 0).unwrap();
    let (a, b) = (batch_draws(job, batch), sobol_b_draws(job, batch));
    let k = job.scatter().len();
    let mut outputs = vec![Vec::new(); metrics.len()];
    for (a_row, b_row) in a.iter().zip(&b) {
        let mut rows = vec![a_row.clone()];
        for i in 0..k {
            let mut ab = a_row.clone();
            ab[i] = b_row[i];
            rows.push(ab);
        }
        rows.push(b_row.clone());
        for row in rows {
            for (m, value) in evaluate(job, &row, metrics).into_iter().enumerate() {
                outputs[m].push(value);
            }
        }
    }
    outputs
}

/// SALib's `sobol.analyze` on the outputs of the engine's own samples, evaluated outside the
/// engine (`tests/data/sobol_job_reference.json`, from `tools/sobol_reference.py --job`): the
/// committed outputs are those of the engine's draws, and the engine's indices are SALib's to
/// 1e-10.
#[test]
fn the_indices_of_a_job_are_salibs_on_its_samples() {
    let base = salib_job();
    let job = job(base.clone());
    let metrics = ["total_bounce_s", "arc_energy_j"];
    let outputs = salib_order_outputs(&job, &metrics);
    if let Ok(path) = std::env::var("BOUNCEWEAR_WRITE_SOBOL_SAMPLES") {
        let names: Vec<String> = job.scatter().iter().map(|s| s.parameter.name()).collect();
        let samples = json!({
            "job": base, "parameters": names, "metrics": metrics, "outputs": outputs,
        });
        std::fs::write(path, samples.to_string()).unwrap();
    }
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../tests/data/sobol_job_reference.json"
    );
    let reference: Value = serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    assert_eq!(reference["job"], base, "the reference is of this job");
    let result = run(Kernel::best(), 2, &job);
    let sensitivity = result.sensitivity.unwrap();
    for (m, metric) in metrics.iter().enumerate() {
        let committed: Vec<f64> = reference["outputs"][m]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        assert_eq!(committed, outputs[m], "{metric}: the engine's samples");
        let indices = &sensitivity[*metric][0].indices;
        for (i, parameter) in reference["parameters"]
            .as_array()
            .unwrap()
            .iter()
            .enumerate()
        {
            let got = &indices[parameter.as_str().unwrap()];
            for (what, value) in [("first", got.first), ("total", got.total)] {
                let want = reference["salib"][metric][what][i].as_f64().unwrap();
                let value = value.unwrap().value;
                assert!(
                    (value - want).abs() <= 1e-10 * want.abs().max(1e-2),
                    "{metric} {parameter} {what}: {value} against SALib's {want}"
                );
            }
        }
    }
}

#[test]
fn regression_alone_reruns_nothing_and_gives_coefficients() {
    let mut spec = arcing_job(64, 20);
    spec["sensitivity"] = json!({"method": "regression"});
    let regression = job(spec);
    assert_eq!(regression.evaluations_per_operation(), 1);
    // Two device-level parameters (B and two AB) and one per operation (B' and one AB').
    assert_eq!(job(arcing_job(64, 20)).evaluations_per_operation(), 6);
    let result = run(Kernel::best(), 2, &regression);
    let bins = &result.sensitivity.as_ref().unwrap()["total_bounce_s"];
    for bin in bins {
        for (name, parameter) in &bin.indices {
            assert!(
                parameter.first.is_none() && parameter.total.is_none(),
                "{name}"
            );
            assert!(parameter.src.unwrap().is_finite(), "{name}");
        }
        assert!((0.0..=1.0).contains(&bin.r_squared.unwrap()));
    }
}

/// A parameter held fixed beside scattered ones has no coefficient of its own, and the others
/// keep theirs: the fit leaves out what does not vary (before, one fixed entry left every entry
/// without `src` and the bin without `r_squared`). Its Sobol' indices are 0.
#[test]
fn a_fixed_parameter_leaves_the_others_coefficients() {
    for method in ["regression", "sobol"] {
        let mut spec = arcing_job(64, 20);
        spec["sensitivity"] = json!({"method": method});
        spec["scatter"]
            .as_array_mut()
            .unwrap()
            .push(json!({"parameter": "current_a",
            "per": "device", "distribution": {"kind": "fixed", "value": 15}}));
        let result = run(Kernel::best(), 2, &job(spec));
        for bin in &result.sensitivity.as_ref().unwrap()["total_bounce_s"] {
            for (name, parameter) in &bin.indices {
                if name == "current_a" {
                    assert_eq!(parameter.src, None, "{method}");
                    if method == "sobol" {
                        assert_eq!(parameter.first.unwrap().value, 0.0, "{method}");
                    }
                } else {
                    assert!(parameter.src.unwrap().is_finite(), "{method} {name}");
                }
            }
            assert!((0.0..=1.0).contains(&bin.r_squared.unwrap()), "{method}");
        }
    }
}

#[test]
fn the_rules_name_the_field() {
    let refused = |spec: Value| -> String {
        let error = Job::from_json(&spec.to_string(), || 7).unwrap_err();
        error
            .errors()
            .iter()
            .map(|e| format!("{:?} {}\n", e.pointer, e.detail))
            .collect()
    };
    let mut unscattered = arcing_job(10, 10);
    unscattered["scatter"] = json!([]);
    assert!(refused(unscattered).contains(r#""/sensitivity""#));

    let mut correlated = arcing_job(10, 10);
    correlated["correlation"] = json!({
        "parameters": ["contact_radius_m", "dynamic_yield_pressure_pa"],
        "matrix": [[1, 0.5], [0.5, 1]]
    });
    let text = refused(correlated.clone());
    assert!(text.contains("/sensitivity/method"), "{text}");
    correlated["sensitivity"] = json!({"method": "regression"});
    assert!(Job::from_json(&correlated.to_string(), || 7).is_ok());

    let mut wide = arcing_job(10, 1000);
    wide["bin_operations"] = json!(1);
    let text = refused(wide);
    assert!(
        text.contains(r#""/sensitivity""#) && text.contains("cells"),
        "{text}"
    );

    let mut unknown = arcing_job(10, 10);
    unknown["sensitivity"] = json!({"method": "morris"});
    assert!(refused(unknown).contains("/sensitivity/method"));
}

/// A tight scatter far from the scenario's own values (48 V / 15 A; the closing velocity 3 m/s and
/// the static force 0.5 N, each 0.01 %, per device): the sums about the nominal scenario's values
/// kept no digit of the operation metrics' variances (an outside probe found zero-width intervals
/// about indices of 1 and 0.0007, and [-1.9, 3.9]). Taken about the scatter's medians, every
/// operation metric's index above 0 has an interval of some width and no bin a reason; the device
/// metrics, which accumulate from a new device's value, lie about 1e4 of their standard
/// deviations from it: their intervals include the sums' rounding, and say so. At 1e-13, their
/// variance is lost: every index unknown, 0 in [0, 1].
#[test]
fn a_tight_scatter_far_from_the_scenario_keeps_honest_intervals() {
    for (sigma, lost) in [(1e-4, false), (1e-13, true)] {
        let job = job(json!({
            "devices": 300, "operations": 6, "bin_operations": 3, "seed": 1,
            "scenario": {"circuit": {"supply_voltage_v": 48, "current_a": 15}},
            "metrics": ["e1", "total_bounce_s", "arc_energy_j", "cumulative_arc_energy_j",
                        "final_radius_m"],
            "scatter": [
                {"parameter": "impact_velocity_m_s", "per": "device",
                 "distribution": {"kind": "lognormal", "median": 3.0, "sigma": sigma}},
                {"parameter": "static_force_n", "per": "device",
                 "distribution": {"kind": "lognormal", "median": 0.5, "sigma": sigma}}],
            "sensitivity": {"method": "sobol"}}));
        let result = run_on(2, &job);
        for (metric, bins) in result.sensitivity.as_ref().unwrap() {
            let device = bins[0].op_start.is_none();
            for bin in bins {
                let said = bin.reason.as_deref().unwrap_or_default();
                let estimates = bin
                    .indices
                    .values()
                    .flat_map(|p| [p.first, p.total])
                    .flatten();
                for e in estimates {
                    let (width, at) = (e.ci95[1] - e.ci95[0], (sigma, metric, bin.op_start));
                    if device && lost {
                        assert_eq!((e.value, e.ci95), (0.0, [0.0, 1.0]), "{at:?}");
                        assert!(said.contains("lost in the rounding"), "{at:?} {said}");
                    } else if device {
                        assert!(width > 0.1, "{at:?} {e:?}");
                        assert!(said.contains("standard deviations from"), "{at:?} {said}");
                    } else {
                        assert!(e.value == 0.0 || width > 0.0, "{at:?} {e:?}");
                        assert!(bin.reason.is_none(), "{at:?} {said}");
                    }
                }
            }
        }
    }
}
