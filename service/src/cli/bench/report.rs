//! The report as people read it: `report.md` (one table per measurement) and `report.svg` (the
//! work-precision plot).

use super::Report;
use crate::plots::{Panel, Series, work_precision_svg};
use std::fmt::Write as _;

/// `report.md`: a heading, then one section per measurement, each a short text and a table.
pub(super) fn markdown(report: &Report) -> String {
    let machine = &report.machine;
    let seeds = machine
        .coverage_seeds
        .map(|seeds| format!(" --coverage-seeds {seeds}"))
        .unwrap_or_default();
    let quick = if machine.quick { " --quick" } else { "" };
    let again = if machine.intervals_measured_again {
        format!(
            " The interval tables (coverage, tail, calibration) were measured again over it with \
             `bouncewear bench{quick}{seeds} --only intervals`: their jobs are seeded and untimed, \
             so they give the same figures on every machine."
        )
    } else {
        String::new()
    };
    let mut md = format!(
        "# bouncewear speed against error\n\n`bouncewear bench{quick}{seeds}` on {} threads, \
         version {}. Regenerate with the same command.{again}\n\n\
         ![work-precision plot](report.svg)\n\n",
        machine.threads, machine.version
    );
    let sections = [
        tiers(report),
        sampling(report),
        throughput(report),
        engine(report),
        skips(report),
        coverage(report),
        tail_coverage(report),
        calibration(report),
        rare_events(report),
    ];
    md.push_str(&sections.map(|section| section.to_markdown()).join("\n"));
    md
}

/// One section of `report.md`: its heading, what it measures (may be empty), and its table.
struct Section {
    title: &'static str,
    text: String,
    columns: &'static [&'static str],
    rows: Vec<Vec<String>>,
}

impl Section {
    /// The heading, the text and the table, ending with the table's last row.
    fn to_markdown(&self) -> String {
        let mut md = format!("## {}\n\n", self.title);
        if !self.text.is_empty() {
            let _ = write!(md, "{}\n\n", self.text);
        }
        let _ = writeln!(md, "| {} |", self.columns.join(" | "));
        let _ = writeln!(md, "|{}", "---|".repeat(self.columns.len()));
        for row in &self.rows {
            let _ = writeln!(md, "| {} |", row.join(" | "));
        }
        md
    }
}

fn tiers(report: &Report) -> Section {
    let fidelities = report.tiers.iter().flat_map(|tier| {
        tier.max_rel_error.iter().map(|(metric, max)| {
            vec![
                tier.fidelity.as_str().to_owned(),
                format!("{:.0}", tier.ns_per_op),
                (*metric).to_owned(),
                format!("{:.1e}", tier.median_rel_error[metric]),
                format!("{max:.1e}"),
            ]
        })
    });
    let forms = report.paper_forms.iter().flat_map(|form| {
        form.max_rel_error.iter().map(|(metric, max)| {
            vec![
                format!("paper {} ({} scenarios)", form.form, form.scenarios),
                format!("{:.1}", form.ns_per_op),
                (*metric).to_owned(),
                format!("{:.1e}", form.median_rel_error[metric]),
                format!("{max:.1e}"),
            ]
        })
    });
    Section {
        title: "Tiers",
        text:
            "Error against the exact model evaluated at 50 digits (`tools/reference.py`) over 80 \
               scenarios; time per operation over the same scenarios, one thread."
                .to_owned(),
        columns: &[
            "fidelity",
            "ns/op",
            "metric",
            "median rel. error",
            "max rel. error",
        ],
        rows: fidelities.chain(forms).collect(),
    }
}

fn sampling(report: &Report) -> Section {
    Section {
        title: "Sampling",
        text: "95 % CI half-width of p95 total bounce time (relative), 20 operations per device, \
               radius and hardness scattered per device, velocity per operation."
            .to_owned(),
        columns: &["sampler", "devices", "wall s", "CI half-width"],
        rows: report
            .sampling
            .iter()
            .map(|row| {
                vec![
                    row.sampler.to_owned(),
                    row.devices.to_string(),
                    format!("{:.3}", row.wall_s),
                    format!("{:.4}", row.ci_half_width_rel),
                ]
            })
            .collect(),
    }
}

fn throughput(report: &Report) -> Section {
    Section {
        title: "Throughput",
        text: String::new(),
        columns: &[
            "job",
            "devices x operations",
            "metrics",
            "million operations/s",
        ],
        rows: report
            .throughput
            .iter()
            .map(|row| {
                vec![
                    row.job.to_owned(),
                    format!("{} x {}", row.devices, row.operations),
                    row.metrics.to_owned(),
                    format!("{:.2}", row.operations_per_s / 1e6),
                ]
            })
            .collect(),
    }
}

fn engine(report: &Report) -> Section {
    let optional =
        |x: Option<f64>, digits: usize| x.map_or("-".to_owned(), |x| format!("{x:.digits$}"));
    let cpu = report
        .engine
        .first()
        .map_or("this machine", |row| row.cpu.as_str());
    Section {
        title: "Engine against the NumPy and Numba peers",
        text: format!(
            "ns per operation on one thread (every metric), one device at a time and in lockstep, \
             next to the floor: the job's square roots and divisions alone, at the throughput \
             this CPU gives them one at a time and on the kernel's lanes; then, on {cpu}, \
             `bouncewear run` on {threads} threads against `tools/numpy_peer.py` on one core and \
             `tools/numba_peer.py` on {threads} threads (its machine code compiled by an earlier \
             run), whole processes, best of three; the ratio is against the faster peer.",
            threads = report.machine.threads
        ),
        columns: &[
            "job",
            "devices x operations",
            "kernel",
            "ns/op alone",
            "ns/op lockstep",
            "floor alone / lockstep",
            "run s",
            "NumPy s",
            "Numba s",
            "faster peer",
            "ratio",
        ],
        rows: report
            .engine
            .iter()
            .map(|row| {
                vec![
                    row.job.to_owned(),
                    format!("{} x {}", row.devices, row.operations),
                    row.kernel.clone(),
                    format!("{:.0}", row.ns_per_op_one_device_at_a_time),
                    format!("{:.0}", row.ns_per_op_lockstep),
                    format!(
                        "{:.0} / {:.0}",
                        row.floor_ns_per_op_scalar, row.floor_ns_per_op_lockstep
                    ),
                    format!("{:.3}", row.run_process_s),
                    optional(row.numpy_peer_process_s, 3),
                    optional(row.numba_peer_process_s, 3),
                    row.peer.as_deref().unwrap_or("-").to_owned(),
                    optional(row.ratio, 1),
                ]
            })
            .collect(),
    }
}

fn skips(report: &Report) -> Section {
    Section {
        title: "What skipping saves",
        text: String::new(),
        columns: &["skip", "ns/op doing it", "ns/op skipping"],
        rows: report
            .skips
            .iter()
            .map(|row| {
                vec![
                    row.skip.to_owned(),
                    format!("{:.0}", row.ns_per_op_doing_it),
                    format!("{:.0}", row.ns_per_op_skipping),
                ]
            })
            .collect(),
    }
}

fn coverage(report: &Report) -> Section {
    Section {
        title: "Intervals: coverage and width",
        text: "How often the nominal 95 % intervals of a job of 64 or 512 devices x 20 operations \
               at 48 V / 15 A cover the truth (the same statistic of one job of 64 000 devices, \
               `--quick`: 1280, its quantiles interpolated within their buckets), and their mean \
               half-width relative to the truth. Radius and hardness scatter per device, the \
               closing velocity per operation. The intervals are built for jobs of 512 devices and \
               more (docs/contract.md); 64 devices shows what falls short below that. A quantile \
               level a job's data cannot bound answers no interval, only the reason: `answered` \
               counts the jobs that gave one, and the coverage is over those."
            .to_owned(),
        columns: &[
            "design",
            "devices",
            "statistic",
            "seeds",
            "answered",
            "coverage",
            "mean rel. half-width",
        ],
        rows: report
            .coverage
            .iter()
            .map(|row| {
                vec![
                    row.design.to_owned(),
                    row.devices.to_string(),
                    row.statistic.to_owned(),
                    row.seeds.to_string(),
                    row.answered.to_string(),
                    format!("{:.3}", row.coverage),
                    format!("{:.3}", row.mean_relative_half_width),
                ]
            })
            .collect(),
    }
}

fn tail_coverage(report: &Report) -> Section {
    Section {
        title: "Exceedance in the tail",
        text: "How often the 95 % interval of a small exceedance probability covers the exact \
               one, in jobs whose metric is the closing velocity itself, drawn N(0.224, 0.02) m/s \
               per operation (so the truth is a normal tail). One threshold is named in the job's \
               `limits` and counted exactly as the job runs; the other, 0.01 sd below it, is \
               asked only after the run and counted from the most extreme values each group keeps \
               (64 at each end): exact whenever it lies beyond every group's 64th largest value, \
               else bucket-limited and conservative by construction."
            .to_owned(),
        columns: &[
            "statistic",
            "values per job",
            "exact probability",
            "seeds",
            "answered exactly",
            "coverage",
            "mean rel. half-width",
        ],
        rows: report
            .tail_coverage
            .iter()
            .map(|row| {
                vec![
                    row.statistic.to_owned(),
                    format!("{:.0e}", row.values as f64),
                    format!("{:.3e}", row.probability),
                    row.seeds.to_string(),
                    row.exact.to_string(),
                    format!("{:.3}", row.coverage),
                    format!("{:.3}", row.mean_relative_half_width),
                ]
            })
            .collect(),
    }
}

fn calibration(report: &Report) -> Section {
    Section {
        title: "Calibration intervals",
        text: "How often the 95 % profile-likelihood interval of a fitted parameter holds the \
               truth, over fits to synthetic measurements with 2 % noise, a noise draw per seed \
               (`bouncewear_model::calibration::study`): each disjoint block of 200 seeds, then \
               the five blocks together. The binomial standard deviation of a true 0.95 is 0.015 \
               over 200 draws and 0.007 over 1000, so one block in five may well stray past \
               0.93 or 0.97 by chance alone; the 1000 draws are the measurement. `exact \
               linearised` is the share of the same draws on which the exact t interval of the \
               model linearised at the truth holds it (`study::linear_reference`): 0.95 in \
               expectation by construction, so where a block strays, it shows how much of that \
               is the draws themselves."
            .to_owned(),
        columns: &[
            "case",
            "parameter",
            "truth",
            "seeds",
            "coverage",
            "exact linearised",
        ],
        rows: report
            .calibration_coverage
            .iter()
            .map(|row| {
                vec![
                    row.case.to_owned(),
                    format!("`{}`", row.parameter),
                    row.truth.to_string(),
                    format!("{}-{}", row.first_seed, row.first_seed + row.draws - 1),
                    format!("{:.3}", row.coverage),
                    format!("{:.3}", row.linear_reference),
                ]
            })
            .collect(),
    }
}

fn rare_events(report: &Report) -> Section {
    Section {
        title: "Rare events",
        text: "P(total bounce time of one operation above t), the closing velocity drawn \
               N(0.224, 0.02) m/s per operation at 48 V / 15 A: the bounce time rises with the \
               velocity, so the truth is the velocity's normal tail, exact. Each method estimates \
               it once per seed (`rare_event` in a job, docs/contract.md \"Rare events\"). `cov` \
               is the mean of the estimates' own coefficient of variation, `observed` the spread \
               of the estimates about the truth; `crude` is what crude Monte Carlo needs for the \
               same cov. Wall time per estimate on this machine's threads."
            .to_owned(),
        columns: &[
            "method",
            "exact probability",
            "target cov",
            "seeds",
            "coverage",
            "cov",
            "observed",
            "evaluations",
            "crude needs",
            "wall s",
        ],
        rows: report
            .rare_events
            .iter()
            .map(|row| {
                vec![
                    row.method.to_owned(),
                    format!("{:.1e}", row.probability),
                    row.target_cov.to_string(),
                    row.seeds.to_string(),
                    format!("{:.3}", row.coverage),
                    format!("{:.3}", row.mean_cov),
                    format!("{:.3}", row.observed_cov),
                    format!("{:.0}", row.mean_evaluations),
                    format!("{:.1e}", row.crude_evaluations),
                    format!("{:.3}", row.mean_wall_s),
                ]
            })
            .collect(),
    }
}

/// The work-precision plot: tiers (relative error of total bounce time, median to max, against ns
/// per operation) and samplers (CI half-width against wall time, one line per sampler).
pub(super) fn svg(report: &Report) -> String {
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

#[cfg(test)]
mod tests {
    use super::super::*;
    use super::*;
    use std::collections::BTreeMap;

    /// The engine's row of [`report`]: the faster of the peers given against a 0.5 s run.
    fn engine_row(numpy: Option<f64>, numba: Option<f64>) -> EngineRow {
        let faster = speed::faster_peer(&[("numpy", numpy), ("numba", numba)]);
        EngineRow {
            job: "mechanical".into(),
            devices: 2000,
            operations: 500,
            kernel: "avx512".to_owned(),
            ns_per_op_one_device_at_a_time: 71.2,
            ns_per_op_lockstep: 40.9,
            floor_ns_per_op_scalar: 21.0,
            floor_ns_per_op_lockstep: 2.6,
            cpu: "AMD EPYC 9B45".to_owned(),
            run_process_s: 0.5,
            numpy_peer_process_s: numpy,
            numba_peer_process_s: numba,
            peer: faster.map(|(name, _)| name.into()),
            peer_process_s: faster.map(|(_, seconds)| seconds),
            ratio: faster.map(|(_, seconds)| seconds / 0.5),
        }
    }

    /// A report with one row of each kind, as `bench` would make it, with the peers' times.
    fn report(numpy: Option<f64>, numba: Option<f64>) -> Report {
        let errors = BTreeMap::from([
            ("total_bounce_s".to_owned(), 1.5e-9),
            ("e1".to_owned(), 2.5e-12),
        ]);
        Report {
            machine: Machine {
                threads: 2,
                quick: true,
                coverage_seeds: Some(20),
                version: "0.1.0".into(),
                intervals_measured_again: false,
            },
            tiers: vec![Tier {
                fidelity: Fidelity::Exact,
                ns_per_op: 61.4,
                max_rel_error: errors.clone(),
                median_rel_error: errors.clone(),
            }],
            paper_forms: vec![PaperForm {
                form: "eq. 10".into(),
                scenarios: 53,
                ns_per_op: 4.25,
                max_rel_error: errors.clone(),
                median_rel_error: errors,
            }],
            sampling: vec![Sampling {
                sampler: "lhs".into(),
                devices: 1000,
                wall_s: 0.0123,
                ci_half_width_rel: 0.00456,
            }],
            throughput: vec![Throughput {
                job: "48 V / 15 A".into(),
                devices: 8000,
                operations: 1000,
                metrics: "all".into(),
                operations_per_s: 2.345e7,
            }],
            skips: vec![Skip {
                skip: "no wear".into(),
                ns_per_op_doing_it: 52.0,
                ns_per_op_skipping: 31.0,
            }],
            engine: vec![engine_row(numpy, numba)],
            coverage: vec![Coverage {
                design: "radius, hardness".into(),
                devices: 512,
                statistic: "p95".into(),
                seeds: 400,
                answered: 399,
                coverage: 0.9475,
                mean_relative_half_width: 0.0123,
            }],
            tail_coverage: vec![TailCoverage {
                statistic: "exceedance, after the run".into(),
                values: 10_000_000,
                probability: 1.04e-4,
                seeds: 200,
                exact: 200,
                coverage: 0.95,
                mean_relative_half_width: 0.063,
            }],
            calibration_coverage: vec![CalibrationCoverage {
                case: "wear curve".into(),
                parameter: "roughening_energy_j".into(),
                truth: 0.5,
                first_seed: 1000,
                draws: 1000,
                coverage: 0.943,
                linear_reference: 0.945,
            }],
            rare_events: vec![RareEventCoverage {
                method: "subset".into(),
                probability: 1e-6,
                target_cov: 0.1,
                seeds: 20,
                coverage: 0.95,
                mean_cov: 0.11,
                observed_cov: 0.12,
                mean_evaluations: 22000.0,
                crude_evaluations: 1e8,
                mean_wall_s: 0.4,
            }],
        }
    }

    /// The tables of `report.md`: each as its header's cells and its rows' cells.
    fn tables(md: &str) -> Vec<(Vec<String>, Vec<Vec<String>>)> {
        let cells = |line: &str| -> Vec<String> {
            let inner = line.trim().trim_start_matches('|').trim_end_matches('|');
            inner.split('|').map(|c| c.trim().to_owned()).collect()
        };
        let mut tables = Vec::new();
        let lines: Vec<&str> = md.lines().collect();
        let mut at = 0;
        while at < lines.len() {
            if lines[at].starts_with('|') {
                let header = cells(lines[at]);
                let mut rows = Vec::new();
                at += 2; // the separator
                while at < lines.len() && lines[at].starts_with('|') {
                    rows.push(cells(lines[at]));
                    at += 1;
                }
                tables.push((header, rows));
            }
            at += 1;
        }
        tables
    }

    #[test]
    fn every_section_is_a_heading_a_text_and_a_table_whose_rows_fit_its_header() {
        let md = markdown(&report(Some(12.25), Some(14.0)));
        let headings: Vec<&str> = md.lines().filter(|l| l.starts_with("## ")).collect();
        assert_eq!(headings.len(), 9, "{md}");
        let tables = tables(&md);
        assert_eq!(tables.len(), 9);
        for (header, rows) in &tables {
            assert!(!rows.is_empty(), "{header:?} has no rows");
            for row in rows {
                assert_eq!(row.len(), header.len(), "{row:?} under {header:?}");
                assert!(row.iter().all(|cell| !cell.is_empty()), "{row:?}");
            }
        }
        // Two tiers' metrics plus the paper form's.
        assert_eq!(tables[0].1.len(), 4);
        assert!(md.starts_with(
            "# bouncewear speed against error\n\n`bouncewear bench --quick --coverage-seeds 20` \
             on 2 threads, version 0.1.0. Regenerate with the same command.\n\n"
        ));
    }

    #[test]
    fn a_report_reads_back_as_written_and_says_when_its_intervals_were_measured_again() {
        let mut written = report(Some(12.25), Some(14.0));
        let json = serde_json::to_string_pretty(&written).unwrap();
        let read: Report = serde_json::from_str(&json).unwrap();
        assert_eq!(serde_json::to_string_pretty(&read).unwrap(), json);
        assert_eq!(markdown(&read), markdown(&written));
        written.machine.intervals_measured_again = true;
        let md = markdown(&written);
        assert!(
            md.contains(
                "Regenerate with the same command. The interval tables (coverage, tail, \
                 calibration) were measured again over it with `bouncewear bench --quick \
                 --coverage-seeds 20 --only intervals`"
            ),
            "{md}"
        );
        // A report from before the seeds were recorded reads, and names none.
        let mut old: serde_json::Value = serde_json::from_str(&json).unwrap();
        let machine = old["machine"].as_object_mut().unwrap();
        machine.remove("coverage_seeds");
        machine.remove("intervals_measured_again");
        let old: Report = serde_json::from_value(old).unwrap();
        assert!(markdown(&old).contains("`bouncewear bench --quick` on 2 threads"));
    }

    #[test]
    fn numbers_are_written_to_their_columns_precision() {
        let md = markdown(&report(Some(12.25), Some(14.0)));
        assert!(
            md.contains("| exact | 61 | e1 | 2.5e-12 | 2.5e-12 |"),
            "{md}"
        );
        assert!(
            md.contains("| paper eq. 10 (53 scenarios) | 4.2 | total_bounce_s | 1.5e-9 | 1.5e-9 |"),
            "{md}"
        );
        assert!(md.contains("| lhs | 1000 | 0.012 | 0.0046 |"), "{md}");
        assert!(
            md.contains("| 48 V / 15 A | 8000 x 1000 | all | 23.45 |"),
            "{md}"
        );
        assert!(
            md.contains("| 21 / 3 | 0.500 | 12.250 | 14.000 | numpy | 24.5 |"),
            "{md}"
        );
        assert!(
            md.contains("| wear curve | `roughening_energy_j` | 0.5 | 1000-1999 | 0.943 | 0.945 |"),
            "{md}"
        );
        assert!(
            md.contains(
                "| exceedance, after the run | 1e7 | 1.040e-4 | 200 | 200 | 0.950 | 0.063 |"
            ),
            "{md}"
        );
    }

    #[test]
    fn an_engine_row_without_the_peers_says_so_with_dashes() {
        let md = markdown(&report(None, None));
        assert!(md.contains("| 0.500 | - | - | - | - |"), "{md}");
    }

    #[test]
    fn the_ratio_is_against_the_faster_peer_which_the_row_names() {
        let md = markdown(&report(Some(12.25), Some(3.5)));
        assert!(
            md.contains("| 0.500 | 12.250 | 3.500 | numba | 7.0 |"),
            "{md}"
        );
        let md = markdown(&report(None, Some(3.5)));
        assert!(md.contains("| 0.500 | - | 3.500 | numba | 7.0 |"), "{md}");
        assert!(
            md.contains("then, on AMD EPYC 9B45, `bouncewear run` on 2 threads"),
            "{md}"
        );
    }
}
