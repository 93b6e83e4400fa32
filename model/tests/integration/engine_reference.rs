//! Every Monte Carlo statistic of the reference jobs (`tests/data/reference_jobs.json`, 48 V / 15 A and
//! mechanical, cut to 256 devices x 100 operations), against the values the engine gave before it ran
//! in lockstep with its own `atan` and `exp` (commit a6c3d1d, glibc's `atan` and `exp`): within 1e-12
//! relative, counts exactly. A quantile's interval ends may lie outside the reference's, never
//! inside, and at most five times as far from the value plus a bucket (or, for a count, one
//! whole number): they since allow for the density's slope within a sketch bucket
//! (`Sketch::interpolated`), for ties in a count's bucket, and take Student's factor with
//! Satterthwaite's degrees of freedom rather than always the groups' less one, which only ever
//! widens, by at most `t_{0.975, 2} / t_{0.975, 31}`, 2.1 times, in probability, which the
//! quantile function's slope in a tail stretches further in value (the mechanical job's `e1` p01
//! of the fifth bin: 3.2 times; eight ends in the values' end buckets were updated when those
//! buckets came to be read between the exact min and max: `tests/data/README.md`). The mean's
//! interval is Student's t there and Hall's transformation of it here ([`mean_ends`]).

use bouncewear_model::montecarlo::{Job, Silent, run_job};
use serde_json::Value;

const JOBS: &str = include_str!("../../../tests/data/reference_jobs.json");
const REFERENCE: &str = include_str!("../../../tests/data/engine_reference.json");

/// Walks `want` and `got` together, collecting every number that differs by more than 1e-12
/// relative (integers, which are counts, must be equal), or a quantile interval's end that is not
/// where [`interval_ends`] allows.
fn differences(path: &str, want: &Value, got: &Value, out: &mut Vec<String>) {
    match (want, got) {
        (Value::Object(w), Value::Object(g)) => {
            // A quantile's `reason` (a level the data cannot bound) is newer than the reference:
            // words about a statistic, not one.
            let statistics = g.keys().filter(|key| *key != "reason").count();
            assert_eq!(w.len(), statistics, "{path}: keys differ");
            for (key, value) in w {
                let path = format!("{path}/{key}");
                match key.as_str() {
                    "ci95" if path.contains("/quantiles/") => {
                        interval_ends(&path, &w["value"], value, &g[key], out)
                    }
                    "mean_ci95" => mean_ends(&path, &w["mean"], value, &g[key], out),
                    _ => differences(&path, value, &g[key], out),
                }
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
            if (w - g).abs() > 1e-12 * w.abs() {
                out.push(format!("{path}: {w:e} != {g:e}"));
            }
        }
        (w, g) => assert_eq!(w, g, "{path}"),
    }
}

/// A quantile's interval `got` against the reference's `want` about the reference's `value`: each
/// end as far from the value as the reference's (within 1e-12) or further, and no further than
/// five times that plus a bucket (a whole number for `bounce_count`). A whole number's end may lie
/// one nearer: the reference rounded an end at its bucket's upper edge up to the next number,
/// which the bucket cannot hold (d32b03d reads the number the bucket holds).
fn interval_ends(path: &str, value: &Value, want: &Value, got: &Value, out: &mut Vec<String>) {
    let value = value.as_f64().unwrap();
    let whole = path.contains("/bounce_count/");
    let bucket = match whole {
        true => 1.0,
        false => value.abs() / 256.0,
    };
    for end in 0..2 {
        let (w, g) = (want[end].as_f64().unwrap(), got[end].as_f64().unwrap());
        let (reach, now) = ((w - value).abs(), (g - value).abs());
        let rounded = if whole && end == 1 { 1.0 } else { 0.0 };
        let inwards = now < reach - rounded - 1e-12 * w.abs();
        if inwards || now > 5.0 * reach + bucket {
            out.push(format!("{path}/{end}: {w:e} != {g:e} about {value:e}"));
        }
    }
}

/// The mean's interval `got` against the reference's Student's t interval `want`, `mean +- h`:
/// it holds the mean, and each end lies within `h / 4` of the reference's, since Hall's
/// transformation for the groups' skewness moves the ends by `O(g / sqrt G)` of `h`, and
/// Satterthwaite's degrees of freedom widen them where a few groups carry the spread (at most
/// 0.20 h among the reference jobs' 198 intervals of 32 groups, where noise in the skewness of 32
/// group means moves a symmetric metric's ends by up to about a fifth).
fn mean_ends(path: &str, mean: &Value, want: &Value, got: &Value, out: &mut Vec<String>) {
    let mean = mean.as_f64().unwrap();
    let (w, g) = (
        [0, 1].map(|end| want[end].as_f64().unwrap()),
        [0, 1].map(|end| got[end].as_f64().unwrap()),
    );
    let half = (w[1] - w[0]) / 2.0;
    let holds = g[0] <= mean && mean <= g[1];
    if !holds || (0..2).any(|end| (g[end] - w[end]).abs() > half / 4.0) {
        out.push(format!("{path}: {w:?} != {g:?} about {mean:e}"));
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
