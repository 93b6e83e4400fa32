//! `bouncewear bench`: speed against error.
//!
//! - Tiers: each fidelity's time per operation, and its error against `tests/data/reference_spread.json`,
//!   80 scenarios evaluated at 50 digits by `tools/reference.py` (an independent implementation).
//!   Both tiers are compared with the exact model: the closed form's error is the price of its speed.
//! - Sampling: the 95 % CI half-width of p95 total bounce time against wall time, for growing device
//!   counts, random against Latin hypercube.
//! - Throughput of the issue's reference jobs, and what each skip of unneeded work saves.

use bouncewear_model::montecarlo::{Job, JobResult, OperationMetric, Silent, run_job};
use bouncewear_model::wear::WearLaw;
use bouncewear_model::{Fidelity, Needs, Operation, Outcome, Scenario};
use serde::Serialize;
use serde_json::{Value, json};
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::hint::black_box;
use std::path::Path;
use std::time::Instant;

const REFERENCE: &str = include_str!("../../tests/data/reference_spread.json");

#[derive(Debug, Serialize)]
pub struct Report {
    pub machine: Machine,
    pub tiers: Vec<Tier>,
    pub sampling: Vec<Sampling>,
    pub throughput: Vec<Throughput>,
    pub skips: Vec<Skip>,
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

/// Runs every measurement on the current rayon pool and writes `report.{json,md,svg}` into `out`.
pub fn bench(out: &Path, quick: bool) -> Result<Report, BenchError> {
    let report = Report {
        machine: Machine {
            threads: rayon::current_num_threads(),
            quick,
            version: env!("CARGO_PKG_VERSION"),
        },
        tiers: Fidelity::ALL.iter().map(|&f| tier(f, quick)).collect(),
        sampling: sampling(quick),
        throughput: throughput(quick),
        skips: skips(quick),
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
    let mut max_rel_error = BTreeMap::new();
    let mut median_rel_error = BTreeMap::new();
    for metric in OperationMetric::ALL {
        let mut errors: Vec<f64> = outcomes
            .iter()
            .zip(&cases)
            .map(|(outcome, (_, reference))| {
                let (got, want) = (
                    metric.value(outcome),
                    reference[metric.name()].as_f64().expect("number"),
                );
                if got == want {
                    0.0
                } else {
                    (got - want).abs() / want.abs().max(f64::MIN_POSITIVE)
                }
            })
            .collect();
        errors.sort_by(f64::total_cmp);
        max_rel_error.insert(metric.name(), *errors.last().expect("80 cases"));
        median_rel_error.insert(metric.name(), errors[errors.len() / 2]);
    }
    Tier {
        fidelity,
        ns_per_op,
        max_rel_error,
        median_rel_error,
    }
}

/// The issue's reference job: radius and hardness scattered per device, closing velocity per operation.
fn reference_job(
    devices: u64,
    operations: u64,
    arcing: bool,
    sampler: &str,
    metrics: Option<&[&str]>,
) -> Job {
    let mut job = json!({
        "devices": devices, "operations": operations, "seed": 20261122, "sampler": sampler,
        "scatter": [
            {"parameter": "contact_radius_m", "per": "device",
             "distribution": {"kind": "normal", "mean": 7.7e-3, "sd": 0.8e-3, "min": 1e-3}},
            {"parameter": "dynamic_yield_pressure_pa", "per": "device",
             "distribution": {"kind": "lognormal", "median": 2e8, "sigma": 0.15}},
            {"parameter": "impact_velocity_m_s", "per": "operation",
             "distribution": {"kind": "normal", "mean": 0.224, "sd": 0.02, "min": 0.05}}
        ]
    });
    if arcing {
        job["scenario"] = json!({"circuit": {"supply_voltage_v": 48, "current_a": 15}});
    }
    if let Some(metrics) = metrics {
        job["metrics"] = json!(metrics);
    }
    Job::from_json(&job.to_string(), || 0).expect("the reference job is valid")
}

fn run(job: &Job) -> JobResult {
    run_job(job, &Silent).expect("nothing cancels a benchmark")
}

fn sampling(quick: bool) -> Vec<Sampling> {
    let counts: &[u64] = if quick {
        &[100, 400, 1600, 6400]
    } else {
        &[100, 400, 1600, 6400, 25600, 102400]
    };
    let mut rows = Vec::new();
    for sampler in ["random", "lhs"] {
        for &devices in counts {
            let mut job = reference_job(devices, 20, false, sampler, Some(&["total_bounce_s"]));
            job.bin_operations = 20;
            job.spec.bin_operations = Some(20);
            let result = run(&job);
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

fn throughput(quick: bool) -> Vec<Throughput> {
    let (devices, operations) = if quick { (400, 500) } else { (2000, 500) };
    let mut rows = Vec::new();
    for (name, arcing) in [("48 V / 15 A", true), ("mechanical", false)] {
        for (metrics, list) in [
            ("all", None),
            ("total_bounce_s", Some(&["total_bounce_s"][..])),
        ] {
            let result = run(&reference_job(devices, operations, arcing, "random", list));
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
        "\n## What skipping saves\n\n| skip | ns/op doing it | ns/op skipping |\n|---|---|---|"
    );
    for row in &report.skips {
        let _ = writeln!(
            md,
            "| {} | {:.0} | {:.0} |",
            row.skip, row.ns_per_op_doing_it, row.ns_per_op_skipping
        );
    }
    md
}

/// A two-panel log-log work-precision plot, drawn by hand (no plotting dependency):
/// tiers (relative error of total bounce time, median to max, against ns per operation) and
/// samplers (CI half-width against wall time, one line per sampler).
fn svg(report: &Report) -> String {
    /// A named, coloured polyline of (x, y) points.
    type Line = (String, &'static str, Vec<(f64, f64)>);
    struct Panel {
        x0: f64,
        title: &'static str,
        x_label: &'static str,
        y_label: &'static str,
        lines: Vec<Line>,
    }
    let tier_colours = ["#1f77b4", "#d62728"];
    let panels = [
        Panel {
            x0: 70.0,
            title: "Tiers: error of total_bounce_s vs time",
            x_label: "relative error (median to max)",
            y_label: "ns per operation",
            lines: report
                .tiers
                .iter()
                .zip(tier_colours)
                .map(|(t, colour)| {
                    let floor = |e: f64| e.max(1e-17);
                    let metric = "total_bounce_s";
                    let points = vec![
                        (floor(t.median_rel_error[metric]), t.ns_per_op),
                        (floor(t.max_rel_error[metric]), t.ns_per_op),
                    ];
                    (t.fidelity.as_str().to_owned(), colour, points)
                })
                .collect(),
        },
        Panel {
            x0: 530.0,
            title: "Sampling: p95 CI half-width vs wall time",
            x_label: "relative 95 % CI half-width of p95",
            y_label: "wall s",
            lines: ["random", "lhs"]
                .iter()
                .zip(["#2ca02c", "#9467bd"])
                .map(|(sampler, colour)| {
                    let points = report
                        .sampling
                        .iter()
                        .filter(|r| r.sampler == *sampler)
                        .map(|r| (r.ci_half_width_rel, r.wall_s))
                        .collect();
                    ((*sampler).to_owned(), colour, points)
                })
                .collect(),
        },
    ];
    let (width, height, plot_w, plot_h, top) = (960.0, 420.0, 380.0, 300.0, 40.0);
    let mut s = format!(
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" viewBox="0 0 {width} {height}" font-family="sans-serif" font-size="11">"#
    );
    s.push_str(r#"<rect width="100%" height="100%" fill="white"/>"#);
    for panel in &panels {
        let all: Vec<(f64, f64)> = panel
            .lines
            .iter()
            .flat_map(|l| l.2.iter().copied())
            .filter(|(x, y)| *x > 0.0 && *y > 0.0)
            .collect();
        let decades = |values: Vec<f64>| {
            let lo = values
                .iter()
                .copied()
                .fold(f64::INFINITY, f64::min)
                .log10()
                .floor();
            let hi = values
                .iter()
                .copied()
                .fold(f64::NEG_INFINITY, f64::max)
                .log10()
                .ceil();
            (lo, if hi > lo { hi } else { lo + 1.0 })
        };
        let (x_lo, x_hi) = decades(all.iter().map(|p| p.0).collect());
        let (y_lo, y_hi) = decades(all.iter().map(|p| p.1).collect());
        let px = |x: f64| panel.x0 + (x.log10() - x_lo) / (x_hi - x_lo) * plot_w;
        let py = |y: f64| top + plot_h - (y.log10() - y_lo) / (y_hi - y_lo) * plot_h;
        let _ = write!(
            s,
            r#"<text x="{}" y="22" font-size="13" font-weight="bold">{}</text>"#,
            panel.x0, panel.title
        );
        let _ = write!(
            s,
            r##"<rect x="{}" y="{top}" width="{plot_w}" height="{plot_h}" fill="none" stroke="#444"/>"##,
            panel.x0
        );
        for d in (x_lo as i32)..=(x_hi as i32) {
            let x = panel.x0 + (f64::from(d) - x_lo) / (x_hi - x_lo) * plot_w;
            let _ = write!(
                s,
                r##"<line x1="{x}" y1="{top}" x2="{x}" y2="{}" stroke="#ddd"/><text x="{x}" y="{}" text-anchor="middle">1e{d}</text>"##,
                top + plot_h,
                top + plot_h + 14.0
            );
        }
        for d in (y_lo as i32)..=(y_hi as i32) {
            let y = top + plot_h - (f64::from(d) - y_lo) / (y_hi - y_lo) * plot_h;
            let _ = write!(
                s,
                r##"<line x1="{}" y1="{y}" x2="{}" y2="{y}" stroke="#ddd"/><text x="{}" y="{}" text-anchor="end">1e{d}</text>"##,
                panel.x0,
                panel.x0 + plot_w,
                panel.x0 - 4.0,
                y + 4.0
            );
        }
        let _ = write!(
            s,
            r#"<text x="{}" y="{}" text-anchor="middle">{}</text>"#,
            panel.x0 + plot_w / 2.0,
            top + plot_h + 32.0,
            panel.x_label
        );
        let _ = write!(
            s,
            r#"<text x="{}" y="{}" text-anchor="middle" transform="rotate(-90 {} {})">{}</text>"#,
            panel.x0 - 48.0,
            top + plot_h / 2.0,
            panel.x0 - 48.0,
            top + plot_h / 2.0,
            panel.y_label
        );
        for (i, (name, colour, points)) in panel.lines.iter().enumerate() {
            let path: Vec<String> = points
                .iter()
                .map(|&(x, y)| format!("{:.1},{:.1}", px(x), py(y)))
                .collect();
            let _ = write!(
                s,
                r#"<polyline points="{}" fill="none" stroke="{colour}" stroke-width="2"/>"#,
                path.join(" ")
            );
            for &(x, y) in points {
                let _ = write!(
                    s,
                    r#"<circle cx="{:.1}" cy="{:.1}" r="3.5" fill="{colour}"/>"#,
                    px(x),
                    py(y)
                );
            }
            let legend_y = top + 16.0 + 16.0 * i as f64;
            let _ = write!(
                s,
                r#"<rect x="{}" y="{}" width="10" height="10" fill="{colour}"/><text x="{}" y="{}">{name}</text>"#,
                panel.x0 + plot_w - 110.0,
                legend_y - 9.0,
                panel.x0 + plot_w - 95.0,
                legend_y
            );
        }
    }
    s.push_str("</svg>\n");
    s
}
