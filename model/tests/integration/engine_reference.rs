//! Every Monte Carlo statistic of the reference jobs (`tests/data/reference_jobs.json`, 48 V / 15 A and
//! mechanical, cut to 256 devices x 100 operations), against the values the engine gave before it ran
//! in lockstep with its own `atan` and `exp` (commit a6c3d1d, glibc's `atan` and `exp`): within 1e-12
//! relative, counts exactly. A quantile's interval ends may lie outside the reference's, never
//! inside: they since allow for the density's slope within a sketch bucket
//! (`Sketch::interpolated`), for ties in a count's bucket, and take Student's factor with
//! Satterthwaite's degrees of freedom rather than always the groups' less one, which only ever
//! widens (eight ends in the values' end buckets were updated when those buckets came to be read
//! between the exact min and max: `tests/data/README.md`).

use bouncewear_model::montecarlo::{Job, Silent, run_job};
use serde_json::Value;

const JOBS: &str = include_str!("../../../tests/data/reference_jobs.json");
const REFERENCE: &str = include_str!("../../../tests/data/engine_reference.json");

/// Walks `want` and `got` together, collecting every number that differs by more than 1e-12
/// relative (integers, which are counts, must be equal), or a quantile interval's end inside the
/// reference's.
fn differences(path: &str, want: &Value, got: &Value, out: &mut Vec<String>) {
    match (want, got) {
        (Value::Object(w), Value::Object(g)) => {
            // A quantile's `reason` (a level the data cannot bound) is newer than the reference:
            // words about a statistic, not one.
            let statistics = g.keys().filter(|key| *key != "reason").count();
            assert_eq!(w.len(), statistics, "{path}: keys differ");
            for (key, value) in w {
                differences(&format!("{path}/{key}"), value, &g[key], out);
            }
        }
        (Value::Array(w), Value::Array(g)) => {
            assert_eq!(w.len(), g.len(), "{path}: lengths differ");
            for (i, (w, g)) in w.iter().zip(g).enumerate() {
                differences(&format!("{path}/{i}"), w, g, out);
            }
        }
        (Value::Number(w), Value::Number(g)) if w.is_u64() => {
            if w != g {
                out.push(format!("{path}: {w} != {g}"));
            }
        }
        (Value::Number(w), Value::Number(g)) => {
            let (w, g) = (w.as_f64().unwrap(), g.as_f64().unwrap());
            let interval_end = path.contains("/quantiles/") && path.contains("/ci95/");
            let inwards = match path.ends_with("/ci95/0") {
                true => g > w,
                false => g < w,
            };
            if (w - g).abs() > 1e-12 * w.abs() && (!interval_end || inwards) {
                out.push(format!("{path}: {w:e} != {g:e}"));
            }
        }
        (w, g) => assert_eq!(w, g, "{path}"),
    }
}

#[test]
fn every_statistic_of_the_reference_jobs_is_within_1e_12_of_the_engine_before_lockstep() {
    let jobs: Value = serde_json::from_str(JOBS).unwrap();
    let reference: Value = serde_json::from_str(REFERENCE).unwrap();
    let mut faults = Vec::new();
    for (name, want) in reference.as_object().unwrap() {
        let mut spec = jobs[name].clone();
        spec["devices"] = want["job"]["devices"].clone();
        spec["operations"] = want["job"]["operations"].clone();
        let job = Job::from_json(&spec.to_string(), || 0).unwrap();
        let got = serde_json::to_value(run_job(&job, &Silent).unwrap()).unwrap();
        for part in ["operations", "devices", "counts"] {
            differences(
                &format!("{name}/{part}"),
                &want[part],
                &got[part],
                &mut faults,
            );
        }
    }
    assert!(
        faults.is_empty(),
        "{} differences:\n{}",
        faults.len(),
        faults.join("\n")
    );
}
