//! Wear over an endurance test (docs/model.md section 6): one device through 1000 operations at
//! 48 V / 15 A under each wear law (and under the continuous post-arc law at 5 A), matched to 1e-9
//! operation by operation against `tests/data/wear_reference.json`, 50-digit trajectories computed
//! independently by `tools/wear_reference.py` (see `tests/data/README.md`).

use bouncewear_model::montecarlo::Job;
use bouncewear_model::montecarlo::{JobResult, Silent, run_job};
use serde_json::{Value, json};

const MAX_RELATIVE: f64 = 1e-9;

fn reference() -> serde_json::Map<String, Value> {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../tests/data/wear_reference.json"
    );
    serde_json::from_str(&std::fs::read_to_string(path).expect("wear reference")).unwrap()
}

/// A one-device job without scatter, one operation per bin: each bin's mean is that operation.
fn run_one_device(case: &Value) -> JobResult {
    let operations = case["operations"].as_object().unwrap();
    let devices = case["devices"].as_object().unwrap();
    let metrics: Vec<&String> = operations.keys().chain(devices.keys()).collect();
    let length = operations["kappa"].as_array().unwrap().len();
    let job = json!({
        "devices": 1, "operations": length, "bin_operations": 1, "seed": 1,
        "scenario": case["scenario"], "metrics": metrics,
    });
    run_job(&Job::from_json(&job.to_string(), || 1).unwrap(), &Silent).unwrap()
}

fn differs(got: f64, want: f64) -> bool {
    (got - want).abs() > MAX_RELATIVE * want.abs()
}

#[test]
fn every_wear_law_follows_its_50_digit_trajectory_over_1000_operations() {
    let reference = reference();
    assert_eq!(reference.len(), 4);
    let mut failures = Vec::new();
    for (name, case) in &reference {
        let result = run_one_device(case);
        for (metric, values) in case["operations"].as_object().unwrap() {
            for (op, want) in values.as_array().unwrap().iter().enumerate() {
                let bin = &result.operations[metric][op].summary;
                let want = want.as_f64().unwrap();
                if bin.n != 1 || differs(bin.mean, want) {
                    failures.push(format!(
                        "{name} operation {op} {metric}: {} vs {want}",
                        bin.mean
                    ));
                }
            }
        }
        for (metric, want) in case["devices"].as_object().unwrap() {
            let (got, want) = (result.devices[metric].mean, want.as_f64().unwrap());
            if differs(got, want) {
                failures.push(format!("{name} {metric}: {got} vs {want}"));
            }
        }
    }
    assert!(
        failures.is_empty(),
        "{} differences, the first:\n{}",
        failures.len(),
        failures[..failures.len().min(20)].join("\n")
    );
}

/// What the laws are for (the numbers): roughening shortens the first bounce over the test
/// (mean of the first 100 operations 8.3 ms, of the last 100 5.1 ms), holding kappa keeps it, and
/// annealing the surface as well shortens it further.
#[test]
fn the_first_bounce_falls_with_roughening_and_holds_under_constant_kappa() {
    let reference = reference();
    let first_bounce_ms = |name: &str| {
        let values: Vec<f64> = reference[name]["operations"]["first_bounce_s"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap() * 1e3)
            .collect();
        let mean = |bin: &[f64]| bin.iter().sum::<f64>() / bin.len() as f64;
        (mean(&values[..100]), mean(&values[values.len() - 100..]))
    };
    let (new, worn) = first_bounce_ms("roughening");
    assert!(
        (new - 8.3).abs() < 0.05 && (worn - 5.1).abs() < 0.05,
        "{new} -> {worn} ms"
    );
    let (new, worn) = first_bounce_ms("constant");
    assert_eq!(new, worn);
    let (_, softened) = first_bounce_ms("roughening_and_softening");
    assert!(softened < 4.5, "{softened} ms");
}
