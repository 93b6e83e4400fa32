//! `bouncewear bench`: speed against error.
//!
//! - Tiers: each fidelity's time per operation, and its error against `tests/data/reference_spread.json`,
//!   80 scenarios evaluated at 50 digits by `tools/reference.py` (an independent implementation).
//!   Both tiers are compared with the exact model: the closed form's error is the price of its speed.
//! - Sampling: the 95 % CI half-width of p95 total bounce time against wall time, for growing device
//!   counts, random against Latin hypercube.
//! - Throughput of the issue's reference jobs, and what each skip of unneeded work saves.
//! - Intervals: how often the nominal 95 % intervals (summary, after-run queries, Sobol' indices)
//!   of small jobs cover the truth of a much larger one, and how wide they are.

use crate::plots::{Panel, Series, work_precision_svg};
use crate::progress::Progress;
use bouncewear_model::calibration;
use bouncewear_model::montecarlo::{
    Job, JobResult, Kernel, Metric, OperationMetric, Silent, run_job, run_job_on,
};
use bouncewear_model::paper_forms::{BounceTimes, constant_restitution, simplified_electrical};
use bouncewear_model::stats::Accumulator;
use bouncewear_model::wear::WearLaw;
use bouncewear_model::{Fidelity, Needs, Operation, Outcome, Pointer, Scenario};
use serde::Serialize;
use serde_json::{Value, json};
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::hint::black_box;
use std::path::Path;
use std::time::Instant;

const REFERENCE: &str = include_str!("../../tests/data/reference_spread.json");
const REFERENCE_JOBS: &str = include_str!("../../tests/data/reference_jobs.json");

#[derive(Debug, Serialize)]
pub struct Report {
    pub machine: Machine,
    pub tiers: Vec<Tier>,
    pub paper_forms: Vec<PaperForm>,
    pub sampling: Vec<Sampling>,
    pub throughput: Vec<Throughput>,
    pub skips: Vec<Skip>,
    pub engine: Vec<EngineRow>,
    pub coverage: Vec<Coverage>,
    /// Exceedance intervals at a small probability in large jobs, against the exact tail.
    pub tail_coverage: Vec<TailCoverage>,
    /// Calibration intervals against the known truth of synthetic measurements.
    pub calibration_coverage: Vec<CalibrationCoverage>,
    /// Rare-event estimates against an exact tail: coverage, precision and cost per method.
    pub rare_events: Vec<RareEventCoverage>,
}

#[derive(Debug, Serialize)]
pub struct Machine {
    pub threads: usize,
    pub quick: bool,
    pub version: &'static str,
}

#[derive(Debug, Serialize)]
pub struct Tier {
    pub fidelity: Fidelity,
    pub ns_per_op: f64,
    pub max_rel_error: BTreeMap<&'static str, f64>,
    pub median_rel_error: BTreeMap<&'static str, f64>,
}

/// One of the paper's closed forms of the bounce times (docs/model.md section 7), over the
/// reference scenarios it applies to: its cost and its error against the exact model.
#[derive(Debug, Serialize)]
pub struct PaperForm {
    pub form: &'static str,
    /// How many of the reference scenarios it applies to (`F_s > 0`; arcing for eq. 17/19) and
    /// in which the exact model bounces.
    pub scenarios: usize,
    pub ns_per_op: f64,
    pub max_rel_error: BTreeMap<&'static str, f64>,
    pub median_rel_error: BTreeMap<&'static str, f64>,
}

#[derive(Debug, Serialize)]
pub struct Sampling {
    pub sampler: &'static str,
    pub devices: u64,
    pub wall_s: f64,
    pub ci_half_width_rel: f64,
}

#[derive(Debug, Serialize)]
pub struct Throughput {
    pub job: &'static str,
    pub devices: u64,
    pub operations: u64,
    pub metrics: &'static str,
    pub operations_per_s: f64,
}

/// One reference job: the engine per operation and thread, one device at a time and in lockstep,
/// next to the floor; then the whole `bouncewear run` process against the NumPy peer's.
#[derive(Debug, Serialize)]
pub struct EngineRow {
    pub job: &'static str,
    pub devices: u64,
    pub operations: u64,
    pub kernel: String,
    pub ns_per_op_one_device_at_a_time: f64,
    pub ns_per_op_lockstep: f64,
    /// The issue's floor for this job on an AVX-512 core: square roots and divisions alone.
    pub floor_ns_per_op_scalar: f64,
    pub floor_ns_per_op_8_lanes: f64,
    /// `bouncewear run --threads N` as a whole process, wall seconds.
    pub run_process_s: f64,
    /// `python3 tools/numpy_peer.py` as a whole process on one core, when NumPy is installed.
    pub numpy_peer_process_s: Option<f64>,
    /// The peer's wall time over ours.
    pub ratio: Option<f64>,
}

#[derive(Debug, Serialize)]
pub struct Skip {
    pub skip: &'static str,
    pub ns_per_op_doing_it: f64,
    pub ns_per_op_skipping: f64,
}

/// Why `bench` could not finish. Every measurement runs fixed, valid jobs, so only the report's
/// files can fail.
#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    #[error("{path}: {source}")]
    Write {
        path: String,
        source: std::io::Error,
    },
}

/// How many measurements [`bench`] makes, for its progress bar.
pub fn measurements(quick: bool) -> u64 {
    let count = Fidelity::ALL.len()
        + PAPER_FORMS.len()
        + SAMPLERS.len() * sampled_devices(quick).len()
        + THROUGHPUT_JOBS.len() * THROUGHPUT_METRICS.len()
        + 1
        + THROUGHPUT_JOBS.len()
        + COVERAGE_DESIGNS.len() * COVERAGE_DEVICES.len()
        + 1
        + calibration::study::CASES.len()
        + RARE_EVENT_STUDIES;
    count as u64
}

/// Runs every measurement on the current rayon pool and writes `report.{json,md,svg}` into `out`;
/// each coverage figure is over `coverage_seeds` jobs (default 400, quick 20).
pub fn bench(
    out: &Path,
    quick: bool,
    coverage_seeds: Option<u32>,
    progress: &Progress,
) -> Result<Report, BenchError> {
    let report = Report {
        machine: Machine {
            threads: rayon::current_num_threads(),
            quick,
            version: env!("CARGO_PKG_VERSION"),
        },
        tiers: Fidelity::ALL
            .iter()
            .map(|&f| progress.measure(format!("tier {}", f.as_str()), || tier(f, quick)))
            .collect(),
        paper_forms: PAPER_FORMS
            .iter()
            .map(|&(name, form)| {
                progress.measure(format!("paper form {name}"), || {
                    paper_form(name, form, quick)
                })
            })
            .collect(),
        sampling: sampling(quick, progress),
        throughput: throughput(quick, progress),
        skips: progress.measure("what skipping saves", || skips(quick)),
        engine: THROUGHPUT_JOBS
            .iter()
            .map(|&(name, arcing)| {
                progress.measure(format!("engine and NumPy peer: {name}"), || {
                    engine_row(name, arcing, quick, out)
                })
            })
            .collect::<Result<_, _>>()?,
        coverage: coverage(quick, coverage_seeds, progress),
        tail_coverage: tail_coverage(quick, progress),
        calibration_coverage: calibration_coverage(quick, progress),
        rare_events: rare_event_coverage(quick, progress),
    };
    std::fs::create_dir_all(out).map_err(|source| io_error(out, source))?;
    let write = |name: &str, text: String| {
        let path = out.join(name);
        std::fs::write(&path, text).map_err(|source| io_error(&path, source))
    };
    write(
        "report.json",
        serde_json::to_string_pretty(&report).expect("a report serialises") + "\n",
    )?;
    write("report.md", markdown(&report))?;
    write("report.svg", svg(&report))?;
    Ok(report)
}

fn io_error(path: &Path, source: std::io::Error) -> BenchError {
    BenchError::Write {
        path: path.display().to_string(),
        source,
    }
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

fn tier(fidelity: Fidelity, quick: bool) -> Tier {
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
type Errors = BTreeMap<&'static str, f64>;

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
            metric.name(),
            errors.get(errors.len() / 2).copied().unwrap_or(0.0),
        );
        max.insert(metric.name(), errors.last().copied().unwrap_or(0.0));
    }
    (median, max)
}

/// A closed form of the paper: the bounce times it gives for an operation, where it applies.
type ClosedForm = fn(&Operation) -> Option<BounceTimes>;

/// The paper's closed forms `bench` reports, by name.
const PAPER_FORMS: [(&str, ClosedForm); 2] = [
    ("eq. 9/10, e = 0.4", |op| constant_restitution(op, 0.4)),
    ("eq. 17/19", simplified_electrical),
];

/// A closed form of the paper over the reference scenarios it applies to.
fn paper_form(name: &'static str, form: ClosedForm, quick: bool) -> PaperForm {
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
        form: name,
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

fn run(job: &Job) -> JobResult {
    run_job(job, &Silent).expect("nothing cancels a benchmark")
}

const SAMPLERS: [&str; 2] = ["random", "lhs"];

fn sampled_devices(quick: bool) -> &'static [u64] {
    if quick {
        &[100, 400, 1600, 6400]
    } else {
        &[100, 400, 1600, 6400, 25600, 102400]
    }
}

fn sampling(quick: bool, progress: &Progress) -> Vec<Sampling> {
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
                sampler: if sampler == "lhs" { "lhs" } else { "random" },
                devices,
                wall_s: result.timing.wall_s,
                ci_half_width_rel: 0.5 * (p95.ci95[1] - p95.ci95[0]) / p95.value,
            });
        }
    }
    rows
}

/// The throughput jobs: a name, and whether it arcs.
const THROUGHPUT_JOBS: [(&str, bool); 2] = [("48 V / 15 A", true), ("mechanical", false)];
/// Each throughput job with all metrics and with one.
const THROUGHPUT_METRICS: [(&str, Option<&[&str]>); 2] =
    [("all", None), ("total_bounce_s", Some(&["total_bounce_s"]))];

fn throughput(quick: bool, progress: &Progress) -> Vec<Throughput> {
    let (devices, operations) = if quick { (400, 500) } else { (2000, 500) };
    let mut rows = Vec::new();
    for (name, arcing) in THROUGHPUT_JOBS {
        for (metrics, list) in THROUGHPUT_METRICS {
            let job = reference_job(devices, operations, arcing, "random", list);
            let result = progress.measure(format!("throughput: {name}, {metrics}"), || run(&job));
            rows.push(Throughput {
                job: name,
                devices,
                operations,
                metrics,
                operations_per_s: result.timing.operations_per_s,
            });
        }
    }
    rows
}

const NUMPY_PEER: &str = include_str!("../../tools/numpy_peer.py");

/// The issue's floor (square roots and divisions only, Zen 5): scalar and 8-lane ns per operation.
fn floor_ns_per_op(arcing: bool) -> (f64, f64) {
    if arcing { (78.0, 10.0) } else { (136.0, 22.0) }
}

fn engine_row(
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
    let kernel = Kernel::best();
    let (scalar, lockstep) = (per_op(Kernel::SCALAR), per_op(kernel));
    // The job as a file, for the two processes.
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
    let numpy_peer_process_s = numpy_available()
        .then(|| {
            best_process_s(
                std::process::Command::new("python3")
                    .args(["-c", NUMPY_PEER])
                    .arg(&text),
            )
        })
        .flatten();
    let (floor_scalar, floor_lanes) = floor_ns_per_op(arcing);
    Ok(EngineRow {
        job: name,
        devices,
        operations,
        kernel: format!("{} x{}", kernel.isa().as_str(), kernel.lanes()),
        ns_per_op_one_device_at_a_time: scalar,
        ns_per_op_lockstep: lockstep,
        floor_ns_per_op_scalar: floor_scalar,
        floor_ns_per_op_8_lanes: floor_lanes,
        run_process_s,
        numpy_peer_process_s,
        ratio: numpy_peer_process_s.map(|peer| peer / run_process_s),
    })
}

/// Whether `python3` can import NumPy (the peer is optional: CI need not install it).
fn numpy_available() -> bool {
    std::process::Command::new("python3")
        .args(["-c", "import numpy"])
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

fn skips(quick: bool) -> Vec<Skip> {
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
    vec![
        Skip {
            skip: "first-impact phase when neither peak_force_n nor impact_duration_s is asked for (one operation)",
            ns_per_op_doing_it: op_ns(&mechanical, Needs::ALL),
            ns_per_op_skipping: op_ns(&mechanical, Needs { impact: false }),
        },
        Skip {
            skip: "wear radius and kappa rescaling when nothing can arc or only one operation runs (one operation at 48 V / 15 A)",
            ns_per_op_doing_it: worn_ns,
            ns_per_op_skipping: op_ns(&arcing, Needs::ALL),
        },
        Skip {
            skip: "summaries (and impact phase) of the 13 metrics not asked for (job, 48 V / 15 A, all metrics vs total_bounce_s)",
            ns_per_op_doing_it: per_op(run(&reference_job(
                devices, operations, true, "random", None,
            ))),
            ns_per_op_skipping: per_op(run(&reference_job(
                devices,
                operations,
                true,
                "random",
                Some(&["total_bounce_s"]),
            ))),
        },
    ]
}

fn markdown(report: &Report) -> String {
    let mut md = String::new();
    let _ = writeln!(md, "# bouncewear speed against error\n");
    let _ = writeln!(
        md,
        "`bouncewear bench{}` on {} threads, version {}. Regenerate with the same command.\n",
        if report.machine.quick { " --quick" } else { "" },
        report.machine.threads,
        report.machine.version
    );
    let _ = writeln!(md, "![work-precision plot](report.svg)\n");
    let _ = writeln!(
        md,
        "## Tiers\n\nError against the exact model evaluated at 50 digits (`tools/reference.py`) over 80 scenarios; time per operation over the same scenarios, one thread.\n"
    );
    let _ = writeln!(
        md,
        "| fidelity | ns/op | metric | median rel. error | max rel. error |\n|---|---|---|---|---|"
    );
    for tier in &report.tiers {
        for (metric, max) in &tier.max_rel_error {
            let _ = writeln!(
                md,
                "| {} | {:.0} | {metric} | {:.1e} | {:.1e} |",
                tier.fidelity.as_str(),
                tier.ns_per_op,
                tier.median_rel_error[metric],
                max
            );
        }
    }
    for form in &report.paper_forms {
        for (metric, max) in &form.max_rel_error {
            let _ = writeln!(
                md,
                "| paper {} ({} scenarios) | {:.1} | {metric} | {:.1e} | {:.1e} |",
                form.form, form.scenarios, form.ns_per_op, form.median_rel_error[metric], max
            );
        }
    }
    let _ = writeln!(
        md,
        "\n## Sampling\n\n95 % CI half-width of p95 total bounce time (relative), 20 operations per device, radius and hardness scattered per device, velocity per operation.\n"
    );
    let _ = writeln!(
        md,
        "| sampler | devices | wall s | CI half-width |\n|---|---|---|---|"
    );
    for row in &report.sampling {
        let _ = writeln!(
            md,
            "| {} | {} | {:.3} | {:.4} |",
            row.sampler, row.devices, row.wall_s, row.ci_half_width_rel
        );
    }
    let _ = writeln!(
        md,
        "\n## Throughput\n\n| job | devices x operations | metrics | million operations/s |\n|---|---|---|---|"
    );
    for row in &report.throughput {
        let _ = writeln!(
            md,
            "| {} | {} x {} | {} | {:.2} |",
            row.job,
            row.devices,
            row.operations,
            row.metrics,
            row.operations_per_s / 1e6
        );
    }
    let _ = writeln!(
        md,
        "\n## Engine against the NumPy peer\n\nns per operation on one thread (every metric), one device at a time and in lockstep, next to the floor of square roots and divisions on an AVX-512 core; then `bouncewear run` on {} threads against `tools/numpy_peer.py` on one core, whole processes, best of three.\n",
        report.machine.threads
    );
    let _ = writeln!(
        md,
        "| job | devices x operations | kernel | ns/op alone | ns/op lockstep | floor scalar / 8 lanes | run s | NumPy s | ratio |\n|---|---|---|---|---|---|---|---|---|"
    );
    for row in &report.engine {
        let optional =
            |x: Option<f64>, digits: usize| x.map_or("-".to_owned(), |x| format!("{x:.digits$}"));
        let _ = writeln!(
            md,
            "| {} | {} x {} | {} | {:.0} | {:.0} | {:.0} / {:.0} | {:.3} | {} | {} |",
            row.job,
            row.devices,
            row.operations,
            row.kernel,
            row.ns_per_op_one_device_at_a_time,
            row.ns_per_op_lockstep,
            row.floor_ns_per_op_scalar,
            row.floor_ns_per_op_8_lanes,
            row.run_process_s,
            optional(row.numpy_peer_process_s, 3),
            optional(row.ratio, 1),
        );
    }
    let _ = writeln!(
        md,
        "\n## What skipping saves\n\n| skip | ns/op doing it | ns/op skipping |\n|---|---|---|"
    );
    for row in &report.skips {
        let _ = writeln!(
            md,
            "| {} | {:.0} | {:.0} |",
            row.skip, row.ns_per_op_doing_it, row.ns_per_op_skipping
        );
    }
    let _ = writeln!(
        md,
        "\n## Intervals: coverage and width\n\nHow often the nominal 95 % intervals of a job of 64 or 512 devices x 20 operations at 48 V / 15 A cover the truth (the same statistic of one job of 64 000 devices, `--quick`: 1280, its quantiles interpolated within their buckets), and their mean half-width relative to the truth. Radius and hardness scatter per device, the closing velocity per operation. The intervals are built for jobs of 512 devices and more (docs/contract.md); 64 devices shows what falls short below that. A quantile level a job's data cannot bound answers no interval, only the reason: `answered` counts the jobs that gave one, and the coverage is over those.\n"
    );
    let _ = writeln!(
        md,
        "| design | devices | statistic | seeds | answered | coverage | mean rel. half-width |\n|---|---|---|---|---|---|---|"
    );
    for row in &report.coverage {
        let _ = writeln!(
            md,
            "| {} | {} | {} | {} | {} | {:.3} | {:.3} |",
            row.design,
            row.devices,
            row.statistic,
            row.seeds,
            row.answered,
            row.coverage,
            row.mean_relative_half_width
        );
    }
    let _ = writeln!(
        md,
        "\n## Exceedance in the tail\n\nHow often the 95 % interval of a small exceedance probability covers the exact one, in jobs whose metric is the closing velocity itself, drawn N(0.224, 0.02) m/s per operation (so the truth is a normal tail). One threshold is named in the job's `limits` and counted exactly as the job runs; the other, 0.01 sd below it, is asked only after the run and counted from the most extreme values each group keeps (64 at each end): exact whenever it lies beyond every group's 64th largest value, else bucket-limited and conservative by construction.\n\n| statistic | values per job | exact probability | seeds | answered exactly | coverage | mean rel. half-width |\n|---|---|---|---|---|---|---|"
    );
    for row in &report.tail_coverage {
        let _ = writeln!(
            md,
            "| {} | {:.0e} | {:.3e} | {} | {} | {:.3} | {:.3} |",
            row.statistic,
            row.values as f64,
            row.probability,
            row.seeds,
            row.exact,
            row.coverage,
            row.mean_relative_half_width
        );
    }
    let _ = writeln!(
        md,
        "\n## Calibration intervals\n\nHow often the 95 % profile-likelihood interval of a fitted parameter holds the truth, over fits to synthetic measurements with 2 % noise, a noise draw per seed (`bouncewear_model::calibration::study`). The binomial standard deviation of a true 0.95 is 0.015 over 200 draws and 0.007 over 1000.\n\n| case | parameter | truth | draws | coverage |\n|---|---|---|---|---|"
    );
    for row in &report.calibration_coverage {
        let _ = writeln!(
            md,
            "| {} | `{}` | {} | {} | {:.3} |",
            row.case, row.parameter, row.truth, row.draws, row.coverage
        );
    }
    let _ = writeln!(
        md,
        "\n## Rare events\n\nP(total bounce time of one operation above t), the closing velocity drawn N(0.224, 0.02) m/s per operation at 48 V / 15 A: the bounce time rises with the velocity, so the truth is the velocity's normal tail, exact. Each method estimates it once per seed (`rare_event` in a job, docs/contract.md \"Rare events\"). `cov` is the mean of the estimates' own coefficient of variation, `observed` the spread of the estimates about the truth; `crude` is what crude Monte Carlo needs for the same cov. Wall time per estimate on this machine's threads.\n\n| method | exact probability | target cov | seeds | coverage | cov | observed | evaluations | crude needs | wall s |\n|---|---|---|---|---|---|---|---|---|---|"
    );
    for row in &report.rare_events {
        let _ = writeln!(
            md,
            "| {} | {:.1e} | {} | {} | {:.3} | {:.3} | {:.3} | {:.0} | {:.1e} | {:.3} |",
            row.method,
            row.probability,
            row.target_cov,
            row.seeds,
            row.coverage,
            row.mean_cov,
            row.observed_cov,
            row.mean_evaluations,
            row.crude_evaluations,
            row.mean_wall_s
        );
    }
    md
}

/// The work-precision plot: tiers (relative error of total bounce time, median to max, against ns
/// per operation) and samplers (CI half-width against wall time, one line per sampler).
fn svg(report: &Report) -> String {
    const METRIC: &str = "total_bounce_s";
    // The exact tier's error can be 0, which a log axis cannot show: it sits at 1e-17 instead,
    // below any rounding error of an f64 near 1.
    let floor = |e: f64| e.max(1e-17);
    let tiers = Panel {
        title: format!("Tiers: error of {METRIC} vs time"),
        x_label: "relative error (median to max)".to_owned(),
        y_label: "ns per operation".to_owned(),
        series: report
            .tiers
            .iter()
            .map(|t| Series {
                name: t.fidelity.as_str().to_owned(),
                points: vec![
                    (floor(t.median_rel_error[METRIC]), t.ns_per_op),
                    (floor(t.max_rel_error[METRIC]), t.ns_per_op),
                ],
            })
            .chain(report.paper_forms.iter().map(|f| Series {
                name: format!("paper {}", f.form),
                points: vec![
                    (floor(f.median_rel_error[METRIC]), f.ns_per_op),
                    (floor(f.max_rel_error[METRIC]), f.ns_per_op),
                ],
            }))
            .collect(),
    };
    let sampling = Panel {
        title: "Sampling: p95 CI half-width vs wall time".to_owned(),
        x_label: "relative 95 % CI half-width of p95".to_owned(),
        y_label: "wall s".to_owned(),
        series: ["random", "lhs"]
            .into_iter()
            .map(|sampler| Series {
                name: sampler.to_owned(),
                points: report
                    .sampling
                    .iter()
                    .filter(|r| r.sampler == sampler)
                    .map(|r| (r.ci_half_width_rel, r.wall_s))
                    .collect(),
            })
            .collect(),
    };
    work_precision_svg("bouncewear bench: speed against error", &[tiers, sampling])
}

/// How often the nominal 95 % intervals of a small job cover the truth, and how wide they are: one
/// design of scatter, one statistic.
#[derive(Debug, Serialize)]
pub struct Coverage {
    pub design: &'static str,
    /// Devices per job.
    pub devices: u64,
    pub statistic: &'static str,
    /// Jobs (seeds) run.
    pub seeds: u32,
    /// Of those, the jobs whose data could bound the statistic (a quantile level too extreme for
    /// a job answers no interval, only the reason): the share is over these.
    pub answered: u32,
    pub coverage: f64,
    /// The mean of the intervals' half-widths relative to the truth.
    pub mean_relative_half_width: f64,
}

/// The designs: which of the issue's parameters scatter, and how (radius and hardness per
/// device, closing velocity per operation).
const COVERAGE_DESIGNS: [(&str, &[&str]); 3] = [
    ("device-scattered", &["device"]),
    ("operation-scattered", &["operation"]),
    ("both", &["device", "operation"]),
];

/// The job sizes each design runs at: 512, the smallest job the intervals are built for (where the
/// p99 asked after the run has the five devices beyond it that docs/contract.md's rule asks for,
/// `0.01 x 512 = 5.12`), and 64, to show what falls short below it.
const COVERAGE_DEVICES: [u64; 2] = [64, 512];

/// A design's job at 48 V / 15 A: `devices` x 20 operations in one bin, with Sobol' indices
/// when the design scatters per device, counting the values of total bounce time `above` a
/// threshold as it runs when one is given.
fn coverage_job(levels: &[&str], devices: u64, seed: u64, above: Option<f64>) -> Job {
    let mut scatter = Vec::new();
    if levels.contains(&"device") {
        scatter.push(json!({"parameter": "contact_radius_m", "per": "device",
            "distribution": {"kind": "normal", "mean": 7.7e-3, "sd": 1e-3, "min": 1e-3}}));
        scatter.push(
            json!({"parameter": "dynamic_yield_pressure_pa", "per": "device",
            "distribution": {"kind": "lognormal", "median": 2e8, "sigma": 0.1}}),
        );
    }
    if levels.contains(&"operation") {
        scatter.push(
            json!({"parameter": "impact_velocity_m_s", "per": "operation",
            "distribution": {"kind": "normal", "mean": 0.224, "sd": 0.03, "min": 0.05}}),
        );
    }
    let mut job = json!({
        "devices": devices, "operations": 20, "bin_operations": 20, "seed": seed,
        "scenario": {"circuit": {"supply_voltage_v": 48, "current_a": 15}},
        "metrics": ["total_bounce_s"], "scatter": scatter,
        "sensitivity": {"method": "sobol"},
    });
    if let Some(x) = above {
        job["limits"] = json!({"total_bounce_s": [{"above": x}]});
    }
    Job::from_json(&job.to_string(), || 0).expect("the coverage jobs are valid")
}

/// The quantile statistics of [`coverage_estimates`] and their levels.
const COVERAGE_QUANTILES: [(&str, f64); 3] =
    [("p50", 0.5), ("p95", 0.95), ("p99 after the run", 0.99)];

/// One statistic's estimate and its 95 % interval; no interval for a quantile level the job's
/// data cannot bound (its `reason`).
type Estimate = (&'static str, f64, Option<[f64; 2]>);

/// The truth for [`coverage_estimates`]: the same statistics of one large job, each quantile
/// interpolated within its bucket
/// ([`bouncewear_model::stats::Sketch::interpolated_quantile`]). The reported quantiles are
/// bucket midpoints, so judged against a truth on the same grid, an interval would count as
/// covering whenever the truth merely shares a bucket with an end: up to a bucket (0.39 %) wider
/// than it is, which at 512 devices is a quarter of a p50 interval and covered 98 %.
fn coverage_truth(large: &Job, exceedance_above: f64) -> Vec<Estimate> {
    let (mut truth, all) = coverage_run(large, exceedance_above);
    for (statistic, value, _) in &mut truth {
        if let Some(&(_, level)) = COVERAGE_QUANTILES
            .iter()
            .find(|(name, _)| name == statistic)
        {
            *value = all.sketch().interpolated_quantile(level);
        }
    }
    truth
}

/// One run's estimates, each with its 95 % interval, by statistic: the summary's mean, p50 and
/// p95, a quantile asked after the run, the exceedance of a threshold counted as it ran, and the
/// Sobol' indices.
fn coverage_estimates(job: &Job, exceedance_above: f64) -> Vec<Estimate> {
    coverage_run(job, exceedance_above).0
}

/// [`coverage_estimates`], with every value of the bin merged.
fn coverage_run(job: &Job, exceedance_above: f64) -> (Vec<Estimate>, Accumulator) {
    use bouncewear_model::montecarlo::{RunGroups, engine, query_metric, summarize_job};
    use bouncewear_model::stats::Threshold;
    let tally = engine::run(job, &Silent, |_| false).expect("nothing cancels a benchmark");
    let result = summarize_job(job, &tally, 1.0);
    let bin = &result.operations["total_bounce_s"][0].summary;
    let groups = RunGroups::new(job, tally)
        .of("total_bounce_s", 0)
        .expect("the job has the metric");
    let metric = Metric::Operation(OperationMetric::TotalBounce);
    let answer = query_metric(
        metric,
        &groups,
        &[0.99],
        &[Threshold::Above(exceedance_above)],
    );
    let quantile = |key: &str| {
        let q = &bin.quantiles[key];
        (q.value, q.reason.is_none().then_some(q.ci95))
    };
    let p99 = &answer.quantiles["0.99"];
    let mut estimates = vec![
        ("mean", bin.mean, Some(bin.mean_ci95)),
        ("p50", quantile("p50").0, quantile("p50").1),
        ("p95", quantile("p95").0, quantile("p95").1),
        ("p99 after the run", p99.value.unwrap_or(f64::NAN), p99.ci95),
        (
            "P(above the true p90), counted as it ran",
            answer.exceedance[0].probability,
            Some(answer.exceedance[0].ci95),
        ),
    ];
    let sensitivity = &result.sensitivity.as_ref().expect("asked for")["total_bounce_s"][0];
    for (parameter, statistic) in [
        (
            "dynamic_yield_pressure_pa",
            ["pressure: first-order index", "pressure: total index"],
        ),
        (
            "impact_velocity_m_s",
            ["velocity: first-order index", "velocity: total index"],
        ),
    ] {
        if let Some(indices) = sensitivity.indices.get(parameter) {
            for (index, name) in [indices.first, indices.total].into_iter().zip(statistic) {
                if let Some(index) = index {
                    estimates.push((name, index.value, Some(index.ci95)));
                }
            }
        }
    }
    let mut all = groups
        .first()
        .map_or_else(|| Accumulator::new(None), Accumulator::empty_like);
    groups.iter().for_each(|group| all.merge(group));
    (estimates, all)
}

/// Coverage of every statistic in every design at every size of [`COVERAGE_DEVICES`], over `seeds`
/// jobs (400; quick: 20), the truth from one job of 64 000 devices (quick: 1280), at least 125
/// (quick: 2.5) times the largest: its own error then widens the spread an interval must cover by
/// under 0.4 %.
fn coverage(quick: bool, seeds: Option<u32>, progress: &Progress) -> Vec<Coverage> {
    let (default_seeds, truth_devices) = if quick { (20_u32, 1280) } else { (400, 64_000) };
    let seeds = seeds.unwrap_or(default_seeds);
    let mut rows = Vec::new();
    for (design, levels) in COVERAGE_DESIGNS {
        // The exceedance threshold is the truth's p90, so the true probability is about 0.1; the
        // truth's own answer for it, counted as it ran, is the reference.
        let p90 = {
            let result = run(&coverage_job(levels, truth_devices, 1_000_000, None));
            result.operations["total_bounce_s"][0].summary.quantiles["p90"].value
        };
        let large = coverage_job(levels, truth_devices, 1_000_000, Some(p90));
        let truth = coverage_truth(&large, p90);
        for devices in COVERAGE_DEVICES {
            progress.measure(
                format!("interval coverage: {design}, {devices} devices"),
                || {
                    // Per statistic: intervals that covered, intervals given, half-widths.
                    let mut hits = vec![(0_u32, 0_u32, 0.0); truth.len()];
                    for seed in 0..seeds {
                        let job = coverage_job(levels, devices, u64::from(seed), Some(p90));
                        let estimates = coverage_estimates(&job, p90);
                        for ((hit, given, width), ((_, _, ci95), (_, true_value, _))) in
                            hits.iter_mut().zip(estimates.iter().zip(&truth))
                        {
                            let Some([lo, hi]) = ci95 else { continue };
                            *hit += u32::from(lo <= true_value && true_value <= hi);
                            *given += 1;
                            *width += 0.5 * (hi - lo) / true_value.abs().max(f64::MIN_POSITIVE);
                        }
                    }
                    for ((statistic, _, _), (hit, given, width)) in truth.iter().zip(hits) {
                        let given_f = f64::from(given.max(1));
                        rows.push(Coverage {
                            design,
                            devices,
                            statistic,
                            seeds,
                            answered: given,
                            coverage: f64::from(hit) / given_f,
                            mean_relative_half_width: width / given_f,
                        });
                    }
                },
            );
        }
    }
    rows
}

/// How often the exceedance intervals of one kind cover an exact tail probability.
#[derive(Debug, Clone, Serialize)]
pub struct TailCoverage {
    pub statistic: &'static str,
    /// Values per job.
    pub values: u64,
    /// The exact probability beyond the threshold.
    pub probability: f64,
    pub seeds: u32,
    /// Seeds whose answer was exact (`"resolution": "exact"`), not bucket-limited.
    pub exact: u32,
    pub coverage: f64,
    /// The mean of the intervals' half-widths relative to the exact probability.
    pub mean_relative_half_width: f64,
}

/// The closing velocity of [`tail_coverage`]'s jobs: N(0.224, 0.02) m/s, drawn per operation.
const TAIL_VELOCITY: (f64, f64) = (0.224, 0.02);

/// Exceedance intervals at P = 1e-4 in jobs of 1e7 values (quick: P = 1e-3, 1e6 values), over 200
/// seeds (quick: 20), against the exact probability: the metric is the closing velocity itself,
/// drawn N(0.224, 0.02) m/s per operation, so the share beyond any threshold is a normal tail (the
/// truncation at 0.05 m/s moves it by 1e-18). One threshold is named in the job's `limits` and
/// counted as it runs; another, just below it, is asked after the run and counted from the
/// values the groups keep at their ends.
fn tail_coverage(quick: bool, progress: &Progress) -> Vec<TailCoverage> {
    use bouncewear_model::montecarlo::distribution::standard_normal_cdf;
    use bouncewear_model::montecarlo::{RunGroups, engine, query_metric};
    use bouncewear_model::stats::{Resolution, Threshold};
    let (seeds, devices, z) = if quick {
        (20_u32, 1000_u64, 3.090_232_306_167_813)
    } else {
        (200, 10_000, 3.719_016_485_455_709)
    };
    let (mean, sd) = TAIL_VELOCITY;
    let counted = mean + sd * z;
    let asked = mean + sd * (z - 0.01);
    let truth = |x: f64| standard_normal_cdf(-(x - mean) / sd);
    progress.measure("exceedance coverage in the tail", || {
        let mut hits = [(0_u32, 0_u32, 0.0); 2];
        for seed in 0..seeds {
            let job = json!({
                "devices": devices, "operations": 1000, "bin_operations": 1000, "seed": seed,
                "scenario": {"circuit": {"supply_voltage_v": 48, "current_a": 15}},
                "metrics": ["impact_velocity_m_s"],
                "limits": {"impact_velocity_m_s": [{"above": counted}]},
                "scatter": [{"parameter": "impact_velocity_m_s", "per": "operation",
                    "distribution": {"kind": "normal", "mean": mean, "sd": sd, "min": 0.05}}],
            });
            let job = Job::from_json(&job.to_string(), || 0).expect("the tail jobs are valid");
            let tally = engine::run(&job, &Silent, |_| false).expect("nothing cancels a benchmark");
            let groups = RunGroups::new(&job, tally)
                .of("impact_velocity_m_s", 0)
                .expect("the job has the metric");
            let metric = Metric::Operation(OperationMetric::ImpactVelocity);
            let thresholds = [Threshold::Above(counted), Threshold::Above(asked)];
            let answer = query_metric(metric, &groups, &[], &thresholds);
            for ((hit, exact, width), e) in hits.iter_mut().zip(&answer.exceedance) {
                let p = truth(e.threshold.value());
                let [lo, hi] = e.ci95;
                *hit += u32::from(lo <= p && p <= hi);
                *exact += u32::from(e.resolution == Resolution::Exact);
                *width += 0.5 * (hi - lo) / p;
            }
        }
        let names = [
            "P(above), counted as the job ran",
            "P(above), asked after the run (kept tails)",
        ];
        names
            .into_iter()
            .zip(hits)
            .zip([counted, asked])
            .map(|((statistic, (hit, exact, width)), x)| TailCoverage {
                statistic,
                values: devices * 1000,
                probability: truth(x),
                seeds,
                exact,
                coverage: f64::from(hit) / f64::from(seeds),
                mean_relative_half_width: width / f64::from(seeds),
            })
            .collect()
    })
}

#[derive(Debug, Clone, Serialize)]
pub struct CalibrationCoverage {
    pub case: &'static str,
    pub parameter: &'static str,
    pub truth: f64,
    /// Noise draws (seeds 1000 onwards), each fitted once.
    pub draws: u64,
    pub coverage: f64,
}

/// The calibration studies of the model (issue 29's two cases) over the first 200 and the first
/// 1000 noise draws (quick: 20); the 1000 include the 200.
fn calibration_coverage(quick: bool, progress: &Progress) -> Vec<CalibrationCoverage> {
    use bouncewear_model::calibration::study::{CASES, coverage};
    const FIRST: u64 = 1000;
    let draws: &[u64] = if quick { &[20] } else { &[200, 1000] };
    let mut rows = Vec::new();
    for case in &CASES {
        progress.measure(format!("calibration coverage: {}", case.name), || {
            // Covered fits per parameter over the draws so far.
            let mut covered = vec![0.0; case.truths.len()];
            let mut done = 0;
            for &n in draws {
                let shares = coverage(case, FIRST + done..FIRST + n);
                for (total, share) in covered.iter_mut().zip(shares) {
                    *total += share * (n - done) as f64;
                }
                done = n;
                for (&(parameter, truth), total) in case.truths.iter().zip(&covered) {
                    rows.push(CalibrationCoverage {
                        case: case.name,
                        parameter,
                        truth,
                        draws: n,
                        coverage: total / n as f64,
                    });
                }
            }
        });
    }
    rows
}

/// The rare-event studies [`rare_event_coverage`] measures.
const RARE_EVENT_STUDIES: usize = 7;

/// How one rare-event method fares at one probability: its intervals against the exact tail, its
/// precision and its cost.
#[derive(Debug, Clone, Serialize)]
pub struct RareEventCoverage {
    pub method: &'static str,
    /// The exact probability beyond the threshold.
    pub probability: f64,
    pub target_cov: f64,
    pub seeds: u32,
    pub coverage: f64,
    /// The mean of the estimates' own coefficients of variation.
    pub mean_cov: f64,
    /// The spread of the estimates over the seeds, relative to the truth: the realised cov.
    pub observed_cov: f64,
    pub mean_evaluations: f64,
    /// Devices crude Monte Carlo needs for the same coefficient of variation, `(1 - P) / (P cov^2)`.
    pub crude_evaluations: f64,
    /// Mean wall seconds per estimate on this machine's threads.
    pub mean_wall_s: f64,
}

/// The rare-event studies: P(total bounce time of one operation above t) with the closing velocity
/// drawn N(0.224, 0.02) m/s per operation at 48 V / 15 A. The bounce time rises with the velocity
/// (checked over +-6 sd by the model's tests), so the event is the velocity's normal tail beyond
/// the velocity that gives `t`: exact. Each method over 200 seeds (quick: 5) at P = 1e-3, 1e-6
/// and 1e-9; crude Monte Carlo at 1e-3 only (1e-6 would need 1e8 devices per estimate).
fn rare_event_coverage(quick: bool, progress: &Progress) -> Vec<RareEventCoverage> {
    use bouncewear_model::montecarlo::distribution::standard_normal_cdf;
    use bouncewear_model::montecarlo::rare::estimate;
    const Z: [f64; 3] = [
        3.090_232_306_167_813,
        4.753_424_308_817_09,
        5.997_807_015_007_688,
    ];
    let seeds: u32 = if quick { 5 } else { 200 };
    let (mean, sd) = TAIL_VELOCITY;
    let bounce_at = |v: f64| {
        let job = json!({
            "devices": 1, "operations": 1, "seed": 1,
            "scenario": {"circuit": {"supply_voltage_v": 48, "current_a": 15}},
            "scatter": [{"parameter": "impact_velocity_m_s", "per": "device",
                         "distribution": {"kind": "fixed", "value": v}}],
            "metrics": ["total_bounce_s"]
        });
        let job = Job::from_json(&job.to_string(), || 0).expect("a valid job");
        run(&job).operations["total_bounce_s"][0].summary.mean
    };
    let mut rows = Vec::new();
    for z in Z {
        let threshold = bounce_at(mean + sd * z);
        let truth = standard_normal_cdf(-z);
        let methods: &[(&'static str, f64)] = if z < 4.0 {
            &[("subset", 0.25), ("importance", 0.1), ("crude", 0.1)]
        } else {
            &[("subset", 0.25), ("importance", 0.1)]
        };
        for &(method, target_cov) in methods {
            progress.measure(format!("rare event: {method} at {truth:.0e}"), || {
                let (mut covered, mut cov, mut evaluations, mut squares) = (0, 0.0, 0.0, 0.0);
                let started = Instant::now();
                for seed in 0..seeds {
                    let job = json!({
                        "devices": 1, "operations": 1, "seed": seed,
                        "scenario": {"circuit": {"supply_voltage_v": 48, "current_a": 15}},
                        "scatter": [{"parameter": "impact_velocity_m_s", "per": "operation",
                            "distribution": {"kind": "normal", "mean": mean, "sd": sd, "min": 0.01}}],
                        "metrics": ["total_bounce_s"],
                        "rare_event": {"metric": "total_bounce_s", "above": threshold,
                                       "method": method, "target_cov": target_cov,
                                       "max_evaluations": 10_000_000}
                    });
                    let job = Job::from_json(&job.to_string(), || 0).expect("a valid job");
                    let found = estimate(&job, &Silent)
                        .expect("the studies reach their thresholds")
                        .expect("the job asks a rare event");
                    covered += u32::from(found.ci95[0] <= truth && truth <= found.ci95[1]);
                    cov += found.cov.unwrap_or(f64::NAN);
                    evaluations += found.evaluations as f64;
                    squares += (found.probability / truth - 1.0).powi(2);
                }
                let n = f64::from(seeds);
                rows.push(RareEventCoverage {
                    method,
                    probability: truth,
                    target_cov,
                    seeds,
                    coverage: f64::from(covered) / n,
                    mean_cov: cov / n,
                    observed_cov: (squares / n).sqrt(),
                    mean_evaluations: evaluations / n,
                    crude_evaluations: (1.0 - truth) / (truth * (cov / n).powi(2)),
                    mean_wall_s: started.elapsed().as_secs_f64() / n,
                });
            });
        }
    }
    rows
}
