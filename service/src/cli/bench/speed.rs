//! Speed against error: each fidelity's time per operation and its error against the
//! 50-digit references, the paper's closed forms, random against Latin hypercube sampling, the
//! reference jobs' throughput against the floor and the faster of the NumPy and Numba peers, and
//! what each skip saves.

use super::{BenchError, io_error};
use crate::progress::Progress;
use bouncewear_model::montecarlo::{
    FLOOR_CHAINS, Job, JobResult, Kernel, OperationMetric, Silent, engine, precision_met, run_job,
    run_job_on, summarize_job,
};
use bouncewear_model::paper_forms::{BounceTimes, constant_restitution, simplified_electrical};
use bouncewear_model::wear::WearLaw;
use bouncewear_model::{Fidelity, Needs, Operation, Outcome, Pointer, Scenario};
use serde::{Deserialize, Serialize};
use serde_json::{Value, json};
use std::collections::BTreeMap;
use std::hint::black_box;
use std::path::Path;
use std::time::Instant;

const REFERENCE: &str = include_str!("../../../../tests/data/reference_spread.json");
const REFERENCE_JOBS: &str = include_str!("../../../../tests/data/reference_jobs.json");

#[derive(Debug, Serialize, Deserialize)]
pub struct Tier {
    pub fidelity: Fidelity,
    pub ns_per_op: f64,
    pub max_rel_error: BTreeMap<String, f64>,
    pub median_rel_error: BTreeMap<String, f64>,
}

/// One of the paper's closed forms of the bounce times (docs/model.md section 7), over the
/// reference scenarios it applies to: its cost and its error against the exact model.
#[derive(Debug, Serialize, Deserialize)]
pub struct PaperForm {
    pub form: String,
    /// How many of the reference scenarios it applies to (`F_s > 0`; arcing for eq. 17/19) and
    /// in which the exact model bounces.
    pub scenarios: usize,
    pub ns_per_op: f64,
    pub max_rel_error: BTreeMap<String, f64>,
    pub median_rel_error: BTreeMap<String, f64>,
}

#[derive(Debug, Serialize, Deserialize)]
pub struct Sampling {
    pub sampler: String,
    pub devices: u64,
    pub wall_s: f64,
    pub ci_half_width_rel: f64,
}

#[derive(Debug, Serialize, Deserialize)]
pub struct Throughput {
    pub job: String,
    pub devices: u64,
    pub operations: u64,
    pub metrics: String,
    pub operations_per_s: f64,
}

/// One reference job: the engine per operation and thread, one device at a time and in lockstep,
/// next to the floor; then the whole `bouncewear run` process against the faster of the peers.
#[derive(Debug, Serialize, Deserialize)]
pub struct EngineRow {
    pub job: String,
    pub devices: u64,
    pub operations: u64,
    pub kernel: String,
    pub ns_per_op_one_device_at_a_time: f64,
    pub ns_per_op_lockstep: f64,
    /// The floor of this job's operation on this CPU: its square roots and divisions alone, at
    /// the throughput measured one device at a time and on the kernel's lanes.
    pub floor_ns_per_op_scalar: f64,
    pub floor_ns_per_op_lockstep: f64,
    /// The CPU all of it ran on (`model name` of `/proc/cpuinfo`).
    pub cpu: String,
    /// `bouncewear run --threads N` as a whole process, wall seconds.
    pub run_process_s: f64,
    /// `python3 tools/numpy_peer.py` as a whole process on one core, when NumPy is installed.
    pub numpy_peer_process_s: Option<f64>,
    /// `python3 tools/numba_peer.py` as a whole process on N threads, when Numba is installed. The
    /// first of the three runs compiles and caches the machine code, so the best loads it.
    pub numba_peer_process_s: Option<f64>,
    /// The faster peer, `numpy` or `numba`, and its wall time.
    pub peer: Option<String>,
    pub peer_process_s: Option<f64>,
    /// The faster peer's wall time over ours.
    pub ratio: Option<f64>,
}

#[derive(Debug, Serialize, Deserialize)]
pub struct Skip {
    pub skip: String,
    pub ns_per_op_doing_it: f64,
    pub ns_per_op_skipping: f64,
}

/// Best of `rounds` timings of `work`, in nanoseconds per item.
fn ns_per_item(rounds: usize, items: usize, mut work: impl FnMut()) -> f64 {
    (0..rounds)
        .map(|_| {
            let started = Instant::now();
            work();
            started.elapsed().as_nanos() as f64 / items as f64
        })
        .fold(f64::INFINITY, f64::min)
}

fn reference_cases() -> Vec<(Scenario, Value)> {
    let cases: Vec<Value> = serde_json::from_str(REFERENCE).expect("the reference spread is JSON");
    cases
        .into_iter()
        .map(|case| {
            let scenario = Scenario::from_json(&case["scenario"].to_string())
                .expect("reference scenarios are valid");
            (scenario, case["exact"].clone())
        })
        .collect()
}

pub(super) fn tier(fidelity: Fidelity, quick: bool) -> Tier {
    let cases = reference_cases();
    let operations: Vec<Operation> = cases
        .iter()
        .map(|(s, _)| Operation::nominal(s, fidelity))
        .collect();
    let outcomes: Vec<Outcome> = operations.iter().map(|op| op.simulate().outcome).collect();
    let repeats = if quick { 2_000 } else { 20_000 };
    let ns_per_op = ns_per_item(5, repeats * operations.len(), || {
        for _ in 0..repeats {
            for op in &operations {
                let law = op.kappa_law();
                black_box(op.run(
                    law.reference_radius_m,
                    law.reference_pressure_pa,
                    Needs::ALL,
                    None,
                ));
            }
        }
    });
    // Only the fields of the `simulate` output the reference carries (not the plastic work).
    let in_reference = |metric: &OperationMetric| cases[0].1.get(metric.name()).is_some();
    let metrics: Vec<OperationMetric> = OperationMetric::ALL
        .into_iter()
        .filter(in_reference)
        .collect();
    let (median_rel_error, max_rel_error) = relative_errors(&metrics, |metric| {
        outcomes
            .iter()
            .zip(&cases)
            .map(|(outcome, (_, reference))| {
                let want = reference[metric.name()].as_f64().expect("number");
                (metric.value(outcome), want)
            })
            .collect()
    });
    Tier {
        fidelity,
        ns_per_op,
        max_rel_error,
        median_rel_error,
    }
}

/// Relative errors by metric name.
type Errors = BTreeMap<String, f64>;

/// The median and largest relative error of each metric over `(got, want)` pairs.
fn relative_errors(
    metrics: &[OperationMetric],
    pairs: impl Fn(OperationMetric) -> Vec<(f64, f64)>,
) -> (Errors, Errors) {
    let mut median = BTreeMap::new();
    let mut max = BTreeMap::new();
    for &metric in metrics {
        let mut errors: Vec<f64> = pairs(metric)
            .into_iter()
            .map(|(got, want)| {
                if got == want {
                    0.0
                } else {
                    (got - want).abs() / want.abs().max(f64::MIN_POSITIVE)
                }
            })
            .collect();
        errors.sort_by(f64::total_cmp);
        median.insert(
            metric.name().to_owned(),
            errors.get(errors.len() / 2).copied().unwrap_or(0.0),
        );
        max.insert(
            metric.name().to_owned(),
            errors.last().copied().unwrap_or(0.0),
        );
    }
    (median, max)
}

/// A closed form of the paper: the bounce times it gives for an operation, where it applies.
type ClosedForm = fn(&Operation) -> Option<BounceTimes>;

/// The paper's closed forms `bench` reports, by name.
pub(super) const PAPER_FORMS: [(&str, ClosedForm); 2] = [
    ("eq. 9/10, e = 0.4", |op| constant_restitution(op, 0.4)),
    ("eq. 17/19", simplified_electrical),
];

/// A closed form of the paper over the reference scenarios it applies to.
pub(super) fn paper_form(name: &'static str, form: ClosedForm, quick: bool) -> PaperForm {
    let cases = reference_cases();
    let (operations, references): (Vec<Operation>, Vec<&Value>) = cases
        .iter()
        .map(|(s, reference)| (Operation::nominal(s, Fidelity::Exact), reference))
        // Where the exact model bounces: a form's relative error against no bounce at all is
        // not a number worth printing.
        .filter(|(op, reference)| {
            form(op).is_some() && reference["bounce_count"].as_u64().is_some_and(|n| n > 0)
        })
        .unzip();
    let times: Vec<BounceTimes> = operations.iter().filter_map(form).collect();
    let repeats = if quick { 20_000 } else { 200_000 };
    let ns_per_op = ns_per_item(5, repeats * operations.len().max(1), || {
        for _ in 0..repeats {
            for op in &operations {
                black_box(form(black_box(op)));
            }
        }
    });
    let metrics = [OperationMetric::FirstBounce, OperationMetric::TotalBounce];
    let (median_rel_error, max_rel_error) = relative_errors(&metrics, |metric| {
        times
            .iter()
            .zip(&references)
            .map(|(t, reference)| {
                let got = match metric {
                    OperationMetric::FirstBounce => t.first_bounce_s,
                    _ => t.total_bounce_s,
                };
                (got, reference[metric.name()].as_f64().expect("number"))
            })
            .collect()
    });
    PaperForm {
        form: name.into(),
        scenarios: operations.len(),
        ns_per_op,
        max_rel_error,
        median_rel_error,
    }
}

/// A reference job of `tests/data/reference_jobs.json` (radius and hardness scattered per device,
/// closing velocity per operation), cut to `devices` x `operations`.
fn reference_job(
    devices: u64,
    operations: u64,
    arcing: bool,
    sampler: &str,
    metrics: Option<&[&str]>,
) -> Job {
    let jobs: Value = serde_json::from_str(REFERENCE_JOBS).expect("the reference jobs are JSON");
    let mut job = jobs[if arcing { "48 V / 15 A" } else { "mechanical" }].clone();
    job["devices"] = json!(devices);
    job["operations"] = json!(operations);
    job["sampler"] = json!(sampler);
    if let Some(metrics) = metrics {
        job["metrics"] = json!(metrics);
    }
    Job::from_json(&job.to_string(), || 0).expect("the reference job is valid")
}

pub(super) fn run(job: &Job) -> JobResult {
    run_job(job, &Silent).expect("nothing cancels a benchmark")
}

/// [`run`] as the service runs a job whose groups it stores: each group keeping its most extreme
/// values for thresholds asked after the run (`engine::run_on`), which `run_job` leaves out; the
/// same Result.
fn run_keeping_tails(job: &Job) -> JobResult {
    let started = Instant::now();
    let tally = engine::run_on(Kernel::active(), job, &Silent, |tally| {
        precision_met(job, tally)
    })
    .expect("nothing cancels a benchmark");
    summarize_job(job, &tally, started.elapsed().as_secs_f64())
}

pub(super) const SAMPLERS: [&str; 2] = ["random", "lhs"];

pub(super) fn sampled_devices(quick: bool) -> &'static [u64] {
    if quick {
        &[100, 400, 1600, 6400]
    } else {
        &[100, 400, 1600, 6400, 25600, 102400]
    }
}

pub(super) fn sampling(quick: bool, progress: &Progress) -> Vec<Sampling> {
    let mut rows = Vec::new();
    for sampler in SAMPLERS {
        for &devices in sampled_devices(quick) {
            let mut spec = reference_job(devices, 20, false, sampler, Some(&["total_bounce_s"]))
                .spec()
                .clone();
            spec.bin_operations = Some(20);
            let job = Job::new(spec, || 0, &Pointer::root()).expect("the reference job is valid");
            let result = progress
                .measure(format!("sampling: {sampler}, {devices} devices"), || {
                    run(&job)
                });
            let p95 = &result.operations["total_bounce_s"][0].summary.quantiles["p95"];
            rows.push(Sampling {
                sampler: if sampler == "lhs" { "lhs" } else { "random" }.into(),
                devices,
                wall_s: result.timing.wall_s,
                ci_half_width_rel: 0.5 * (p95.ci95[1] - p95.ci95[0]) / p95.value,
            });
        }
    }
    rows
}

/// The throughput jobs: a name, and whether it arcs.
pub(super) const THROUGHPUT_JOBS: [(&str, bool); 2] =
    [("48 V / 15 A", true), ("mechanical", false)];
/// Each throughput job with all metrics and with one.
pub(super) const THROUGHPUT_METRICS: [(&str, Option<&[&str]>); 2] =
    [("all", None), ("total_bounce_s", Some(&["total_bounce_s"]))];

pub(super) fn throughput(quick: bool, progress: &Progress) -> Vec<Throughput> {
    let (devices, operations) = if quick { (400, 500) } else { (2000, 500) };
    let mut rows = Vec::new();
    for (name, arcing) in THROUGHPUT_JOBS {
        for (metrics, list) in THROUGHPUT_METRICS {
            let job = reference_job(devices, operations, arcing, "random", list);
            let result = progress.measure(format!("throughput: {name}, {metrics}"), || run(&job));
            rows.push(Throughput {
                job: name.into(),
                devices,
                operations,
                metrics: metrics.into(),
                operations_per_s: result.timing.operations_per_s,
            });
        }
    }
    rows
}

/// The peers: a name, which is also the Python module it needs, its file and its source. The Numba
/// peer imports the NumPy peer's file, so both are written side by side.
const PEERS: [(&str, &str, &str); 2] = [
    (
        "numpy",
        "numpy_peer.py",
        include_str!("../../../../tools/numpy_peer.py"),
    ),
    (
        "numba",
        "numba_peer.py",
        include_str!("../../../../tools/numba_peer.py"),
    ),
];

/// The square roots and divisions one operation of a reference job needs (docs/performance.md,
/// "The floor"): the 15 A job's and the mechanical one's.
fn floor_counts(arcing: bool) -> (f64, f64) {
    if arcing { (20.0, 13.0) } else { (27.0, 21.0) }
}

/// ns per lane of a square root and of a division on `kernel`, on this CPU: the fastest of three
/// timings of [`Kernel::floor_work`], 200,000 rounds each.
fn per_lane_ns(kernel: Kernel) -> (f64, f64) {
    const ROUNDS: u64 = 200_000;
    let lanes = ROUNDS as usize * FLOOR_CHAINS * kernel.lanes();
    let time = |division: bool| {
        ns_per_item(3, lanes, || {
            black_box(kernel.floor_work(division, black_box(ROUNDS)));
        })
    };
    (time(false), time(true))
}

/// The floor of a reference job's operation on this CPU, one device at a time and on `kernel`'s
/// lanes: its square roots and divisions at the throughput measured, nothing else.
fn floor_ns_per_op(arcing: bool, kernel: Kernel) -> (f64, f64) {
    let (sqrts, divisions) = floor_counts(arcing);
    let cost = |(sqrt, division): (f64, f64)| sqrts * sqrt + divisions * division;
    (cost(per_lane_ns(Kernel::SCALAR)), cost(per_lane_ns(kernel)))
}

pub(super) fn engine_row(
    name: &'static str,
    arcing: bool,
    quick: bool,
    out: &Path,
) -> Result<EngineRow, BenchError> {
    let (devices, operations) = if quick { (400, 100) } else { (2000, 500) };
    let job = reference_job(devices, operations, arcing, "random", None);
    let one_thread = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("a pool of one thread");
    let ops = (devices * operations) as usize;
    let per_op = |kernel: Kernel| {
        ns_per_item(3, ops, || {
            black_box(
                one_thread
                    .install(|| run_job_on(kernel, &job, &Silent))
                    .ok(),
            );
        })
    };
    let kernel = Kernel::active();
    let (scalar, lockstep) = (per_op(Kernel::SCALAR), per_op(kernel));
    // The job as a file, for `bouncewear run`.
    std::fs::create_dir_all(out).map_err(|source| io_error(out, source))?;
    let path = out.join("engine-job.json");
    let text = serde_json::to_string(job.spec()).expect("a job serialises");
    std::fs::write(&path, &text).map_err(|source| io_error(&path, source))?;
    let exe = std::env::current_exe().map_err(|source| io_error(&path, source))?;
    let threads = rayon::current_num_threads().to_string();
    let run_process_s = best_process_s(
        std::process::Command::new(exe)
            .args(["run", "--quiet", "--threads", &threads])
            .arg(&path),
    )
    .expect("bouncewear runs its own job");
    let peers = run_peers(&text, &threads)?;
    let [numpy_peer_process_s, numba_peer_process_s] = peers.map(|(_, seconds)| seconds);
    let faster = faster_peer(&peers);
    let (floor_scalar, floor_lanes) = floor_ns_per_op(arcing, kernel);
    Ok(EngineRow {
        job: name.into(),
        devices,
        operations,
        kernel: format!("{} x{}", kernel.name(), kernel.lanes()),
        ns_per_op_one_device_at_a_time: scalar,
        ns_per_op_lockstep: lockstep,
        floor_ns_per_op_scalar: floor_scalar,
        floor_ns_per_op_lockstep: floor_lanes,
        cpu: cpu_name(),
        run_process_s,
        numpy_peer_process_s,
        numba_peer_process_s,
        peer: faster.map(|(name, _)| name.into()),
        peer_process_s: faster.map(|(_, seconds)| seconds),
        ratio: faster.map(|(_, seconds)| seconds / run_process_s),
    })
}

/// Each peer's best whole process on `job` (JSON), by name, `None` where Python cannot import what
/// it needs or the peer fails. The peers run from a directory of their own under the system's
/// temporary one, removed afterwards; the Numba peer on `threads` threads.
fn run_peers(job: &str, threads: &str) -> Result<[(&'static str, Option<f64>); 2], BenchError> {
    let dir = std::env::temp_dir().join(format!("bouncewear-peers-{}", std::process::id()));
    std::fs::create_dir_all(&dir).map_err(|source| io_error(&dir, source))?;
    for (_, file, source) in PEERS {
        let path = dir.join(file);
        std::fs::write(&path, source).map_err(|source| io_error(&path, source))?;
    }
    let times = PEERS.map(|(name, file, _)| {
        let seconds = python_imports(name)
            .then(|| {
                best_process_s(
                    std::process::Command::new("python3")
                        .arg(dir.join(file))
                        .arg(job)
                        .env("NUMBA_NUM_THREADS", threads),
                )
            })
            .flatten();
        (name, seconds)
    });
    // Tidiness only: what a failure leaves behind is the peers and Numba's cache.
    let _ = std::fs::remove_dir_all(&dir);
    Ok(times)
}

/// The faster of the peers that ran, by name, with its time.
pub(super) fn faster_peer(peers: &[(&'static str, Option<f64>)]) -> Option<(&'static str, f64)> {
    peers
        .iter()
        .filter_map(|&(name, seconds)| Some((name, seconds?)))
        .min_by(|a, b| a.1.total_cmp(&b.1))
}

/// The CPU's `model name` from `/proc/cpuinfo`, or the architecture where there is none.
fn cpu_name() -> String {
    std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|info| model_name(&info))
        .unwrap_or_else(|| std::env::consts::ARCH.to_owned())
}

/// The first `model name` of a `/proc/cpuinfo` text.
fn model_name(cpuinfo: &str) -> Option<String> {
    cpuinfo.lines().find_map(|line| {
        let (key, value) = line.split_once(':')?;
        (key.trim() == "model name").then(|| value.trim().to_owned())
    })
}

/// Whether `python3` can import `module` (the peers are optional: CI need not install them).
fn python_imports(module: &str) -> bool {
    std::process::Command::new("python3")
        .args(["-c", &format!("import {module}")])
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .status()
        .is_ok_and(|status| status.success())
}

/// Best of three wall times of a whole process, its output thrown away; `None` if it fails.
fn best_process_s(command: &mut std::process::Command) -> Option<f64> {
    command
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null());
    let mut best = f64::INFINITY;
    for _ in 0..3 {
        let started = Instant::now();
        if !command.status().ok()?.success() {
            return None;
        }
        best = best.min(started.elapsed().as_secs_f64());
    }
    Some(best)
}

pub(super) fn skips(quick: bool) -> Vec<Skip> {
    let repeats = if quick { 200_000 } else { 2_000_000 };
    let mechanical = Operation::nominal(&Scenario::default(), Fidelity::Exact);
    let op_ns = |op: &Operation, needs: Needs| {
        ns_per_item(5, repeats, || {
            for _ in 0..repeats {
                black_box(black_box(op).run(7.7e-3, 2e8, needs, None));
            }
        })
    };
    let arcing_scenario =
        Scenario::from_json(r#"{"circuit": {"supply_voltage_v": 48, "current_a": 15}}"#)
            .expect("valid");
    let arcing = Operation::nominal(&arcing_scenario, Fidelity::Exact);
    let wear = WearLaw::new(&arcing_scenario);
    let worn_ns = ns_per_item(5, repeats, || {
        let mut energy = 0.0;
        for _ in 0..repeats {
            let radius = wear.radius_m(7.7e-3, black_box(energy));
            energy += black_box(arcing.run(radius, 2e8, Needs::ALL, None)).arc_energy_j * 1e-9;
        }
    });
    let (devices, operations) = if quick { (200, 200) } else { (1000, 500) };
    let per_op = |result: JobResult| 1e9 / result.timing.operations_per_s;
    let every_metric = reference_job(devices, operations, true, "random", None);
    vec![
        Skip {
            skip: "first-impact phase when neither peak_force_n nor impact_duration_s is asked for (one operation)".into(),
            ns_per_op_doing_it: op_ns(&mechanical, Needs::ALL),
            ns_per_op_skipping: op_ns(&mechanical, Needs { impact: false }),
        },
        Skip {
            skip: "wear radius and kappa rescaling when nothing can arc or only one operation runs (one operation at 48 V / 15 A)".into(),
            ns_per_op_doing_it: worn_ns,
            ns_per_op_skipping: op_ns(&arcing, Needs::ALL),
        },
        Skip {
            skip: "summaries (and impact phase) of the 13 metrics not asked for (job, 48 V / 15 A, all metrics vs total_bounce_s)".into(),
            ns_per_op_doing_it: per_op(run(&every_metric)),
            ns_per_op_skipping: per_op(run(&reference_job(
                devices,
                operations,
                true,
                "random",
                Some(&["total_bounce_s"]),
            ))),
        },
        Skip {
            skip: "extremes kept for thresholds asked after the run, when the run returns its Result alone (job, 48 V / 15 A, every metric)".into(),
            ns_per_op_doing_it: per_op(run_keeping_tails(&every_metric)),
            ns_per_op_skipping: per_op(run(&every_metric)),
        },
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn relative_errors_give_each_metrics_median_and_max_and_zero_where_exact() {
        let metrics = [OperationMetric::FirstBounce, OperationMetric::TotalBounce];
        let (median, max) = relative_errors(&metrics, |metric| match metric {
            OperationMetric::FirstBounce => vec![(1.1, 1.0), (2.0, 2.0), (2.6, 2.0), (0.0, 0.0)],
            _ => vec![(3.0, 3.0)],
        });
        let first = OperationMetric::FirstBounce.name();
        // Errors 0.1, 0, 0.3, 0 sorted: 0, 0, 0.1, 0.3; the median is the upper middle one.
        approx::assert_relative_eq!(median[first], 0.1, max_relative = 1e-12);
        approx::assert_relative_eq!(max[first], 0.3, max_relative = 1e-12);
        let total = OperationMetric::TotalBounce.name();
        assert_eq!((median[total], max[total]), (0.0, 0.0));
    }

    #[test]
    fn the_faster_peer_is_the_one_that_ran_fastest_and_none_ran_is_none() {
        assert_eq!(
            faster_peer(&[("numpy", Some(0.5)), ("numba", Some(0.25))]),
            Some(("numba", 0.25))
        );
        assert_eq!(
            faster_peer(&[("numpy", Some(0.5)), ("numba", None)]),
            Some(("numpy", 0.5))
        );
        assert_eq!(faster_peer(&[("numpy", None), ("numba", None)]), None);
    }

    #[test]
    fn the_cpu_is_the_first_model_name() {
        let info = "processor\t: 0\nvendor_id\t: AuthenticAMD\nmodel name\t: AMD EPYC 7B13\n\n\
                    processor\t: 1\nmodel name\t: other\n";
        assert_eq!(model_name(info).as_deref(), Some("AMD EPYC 7B13"));
        assert_eq!(model_name("processor\t: 0\n"), None);
    }

    #[test]
    fn an_error_against_an_exact_zero_is_finite_and_large() {
        let (_, max) = relative_errors(&[OperationMetric::FirstBounce], |_| vec![(1e-30, 0.0)]);
        let error = max[OperationMetric::FirstBounce.name()];
        assert!(error.is_finite() && error > 1e270, "{error}");
    }
}
