//! `bouncewear bench`: speed against error.
//!
//! - Tiers: each fidelity's time per operation, and its error against `tests/data/reference_spread.json`,
//!   80 scenarios evaluated at 50 digits by `tools/reference.py` (an independent implementation).
//!   Both tiers are compared with the exact model: the closed form's error is the price of its speed.
//! - Sampling: the 95 % CI half-width of p95 total bounce time against wall time, for growing device
//!   counts, random against Latin hypercube.
//! - Throughput of the reference jobs, and what each skip of unneeded work saves.
//! - Intervals: how often the nominal 95 % intervals (summary, after-run queries, Sobol' indices)
//!   of small jobs cover the truth of a much larger one, and how wide they are.

mod intervals;
mod report;
mod speed;

use crate::progress::Progress;
use bouncewear_model::Fidelity;
use bouncewear_model::calibration;
use intervals::{
    COVERAGE_DESIGNS, COVERAGE_DEVICES, RARE_EVENT_STUDIES, calibration_coverage, coverage,
    default_coverage_seeds, rare_event_coverage, tail_coverage,
};
pub use intervals::{CalibrationCoverage, Coverage, RareEventCoverage, TailCoverage};
use serde::{Deserialize, Serialize};
pub use speed::{EngineRow, PaperForm, Sampling, Skip, Throughput, Tier};
use speed::{
    PAPER_FORMS, SAMPLERS, THROUGHPUT_JOBS, THROUGHPUT_METRICS, engine_row, paper_form,
    sampled_devices, sampling, skips, throughput, tier,
};
use std::path::Path;

#[derive(Debug, Serialize, Deserialize)]
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

#[derive(Debug, Serialize, Deserialize)]
pub struct Machine {
    pub threads: usize,
    pub quick: bool,
    /// The seeds (jobs) each figure of the coverage table is over (`--coverage-seeds`).
    #[serde(default)]
    pub coverage_seeds: Option<u32>,
    pub version: String,
    /// Whether `bench --only intervals` measured the interval tables again over a report of
    /// another run: their jobs are seeded and untimed, so the same figures come on every machine,
    /// while the speed beside them stays as the first run measured it.
    #[serde(default)]
    pub intervals_measured_again: bool,
}

/// A part of the report `bench --only` measures again, keeping the rest as the report in
/// `--out` has it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Only {
    /// The coverage of the intervals, of small exceedance probabilities and of calibration
    /// fits: figures of seeded jobs that no clock enters, the same on every machine (rare
    /// events are timed, so they are measured with the speed).
    Intervals,
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
    /// `--only` found no report in `--out` to measure again.
    #[error("{path}: {source}")]
    Read {
        path: String,
        source: std::io::Error,
    },
    /// `--only` found a file that is not a report `bench` wrote, or one measured with(out)
    /// `--quick` when this run is not.
    #[error("{path}: {reason}")]
    NotTheReport { path: String, reason: String },
}

/// How many measurements [`bench`] makes (with `only`, [`measure_again`]), for its progress bar.
pub fn measurements(quick: bool, only: Option<Only>) -> u64 {
    let intervals =
        COVERAGE_DESIGNS.len() * COVERAGE_DEVICES.len() + 1 + calibration::study::CASES.len();
    let count = match only {
        Some(Only::Intervals) => intervals,
        None => {
            Fidelity::ALL.len()
                + PAPER_FORMS.len()
                + SAMPLERS.len() * sampled_devices(quick).len()
                + THROUGHPUT_JOBS.len() * THROUGHPUT_METRICS.len()
                + 1
                + THROUGHPUT_JOBS.len()
                + intervals
                + RARE_EVENT_STUDIES
        }
    };
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
    let mut report = Report {
        machine: Machine {
            threads: rayon::current_num_threads(),
            quick,
            coverage_seeds: None,
            version: env!("CARGO_PKG_VERSION").into(),
            intervals_measured_again: false,
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
                progress.measure(format!("engine and its peers: {name}"), || {
                    engine_row(name, arcing, quick, out)
                })
            })
            .collect::<Result<_, _>>()?,
        coverage: Vec::new(),
        tail_coverage: Vec::new(),
        calibration_coverage: Vec::new(),
        rare_events: Vec::new(),
    };
    measure_intervals(&mut report, coverage_seeds, progress);
    report.rare_events = rare_event_coverage(quick, progress);
    write_report(out, &report)?;
    Ok(report)
}

/// The report `bench` wrote into `out` before, read for [`measure_again`]: refused when it is
/// not one, or was measured with(out) `--quick` when this run is not, since its tables would
/// then mix two sizes of study.
pub fn read_report(out: &Path, quick: bool) -> Result<Report, BenchError> {
    let path = out.join("report.json");
    let text = std::fs::read_to_string(&path).map_err(|source| BenchError::Read {
        path: path.display().to_string(),
        source,
    })?;
    let not_the_report = |reason: String| BenchError::NotTheReport {
        path: path.display().to_string(),
        reason,
    };
    let report: Report = serde_json::from_str(&text)
        .map_err(|error| not_the_report(format!("not a report of `bench`: {error}")))?;
    if report.machine.quick != quick {
        let (was, is) = if quick {
            ("without", "with")
        } else {
            ("with", "without")
        };
        return Err(not_the_report(format!(
            "measured {was} --quick, so measure it again {was} it (this run is {is})"
        )));
    }
    Ok(report)
}

/// Measures the `only` part of `report` again on the current rayon pool and rewrites
/// `report.{json,md,svg}` in `out`, every other figure kept as it was.
pub fn measure_again(
    mut report: Report,
    only: Only,
    out: &Path,
    coverage_seeds: Option<u32>,
    progress: &Progress,
) -> Result<Report, BenchError> {
    match only {
        Only::Intervals => {
            measure_intervals(&mut report, coverage_seeds, progress);
            report.machine.intervals_measured_again = true;
        }
    }
    write_report(out, &report)?;
    Ok(report)
}

/// The interval tables of `report` (what `--only intervals` names), each coverage figure over
/// `coverage_seeds` jobs (default 400, quick 20), at the report's size of study.
fn measure_intervals(report: &mut Report, coverage_seeds: Option<u32>, progress: &Progress) {
    let quick = report.machine.quick;
    let seeds = coverage_seeds.unwrap_or(default_coverage_seeds(quick));
    report.coverage = coverage(quick, seeds, progress);
    report.tail_coverage = tail_coverage(quick, progress);
    report.calibration_coverage = calibration_coverage(quick, progress);
    report.machine.coverage_seeds = Some(seeds);
}

/// `report.{json,md,svg}` written into `out`.
fn write_report(out: &Path, report: &Report) -> Result<(), BenchError> {
    std::fs::create_dir_all(out).map_err(|source| io_error(out, source))?;
    let write = |name: &str, text: String| {
        let path = out.join(name);
        std::fs::write(&path, text).map_err(|source| io_error(&path, source))
    };
    write(
        "report.json",
        serde_json::to_string_pretty(report).expect("a report serialises") + "\n",
    )?;
    write("report.md", report::markdown(report))?;
    write("report.svg", report::svg(report))
}

fn io_error(path: &Path, source: std::io::Error) -> BenchError {
    BenchError::Write {
        path: path.display().to_string(),
        source,
    }
}
