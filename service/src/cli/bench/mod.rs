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
    rare_event_coverage, tail_coverage,
};
pub use intervals::{CalibrationCoverage, Coverage, RareEventCoverage, TailCoverage};
use serde::Serialize;
pub use speed::{EngineRow, PaperForm, Sampling, Skip, Throughput, Tier};
use speed::{
    PAPER_FORMS, SAMPLERS, THROUGHPUT_JOBS, THROUGHPUT_METRICS, engine_row, paper_form,
    sampled_devices, sampling, skips, throughput, tier,
};
use std::path::Path;

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
                progress.measure(format!("engine and its peers: {name}"), || {
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
    write("report.md", report::markdown(&report))?;
    write("report.svg", report::svg(&report))?;
    Ok(report)
}

fn io_error(path: &Path, source: std::io::Error) -> BenchError {
    BenchError::Write {
        path: path.display().to_string(),
        source,
    }
}
