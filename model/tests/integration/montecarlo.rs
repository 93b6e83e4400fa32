//! The Monte Carlo engine: validation, determinism, skips that change nothing, wear, sampling,
//! precision targets and honest confidence intervals.

use crate::support::{job, pointers, run_on};
use bouncewear_model::montecarlo::{
    Job, JobResult, JobSpec, RunGroups, Silent, engine, summarize_job,
};
use bouncewear_model::stats::Accumulator;
use bouncewear_model::{FieldError, Pointer};
use serde_json::{Value, json};

fn run(job: &Job) -> JobResult {
    run_on(2, job)
}

const ARCING: &str = r#"{"circuit": {"supply_voltage_v": 48, "current_a": 15}}"#;

fn arcing() -> Value {
    serde_json::from_str(ARCING).unwrap()
}

fn scattered(devices: u64, operations: u64, seed: u64) -> Value {
    json!({
        "devices": devices, "operations": operations, "seed": seed, "scenario": arcing(),
        "scatter": [
            {"parameter": "contact_radius_m", "per": "device",
             "distribution": {"kind": "normal", "mean": 7.7e-3, "sd": 1e-3, "min": 1e-3}},
            {"parameter": "dynamic_yield_pressure_pa", "per": "device",
             "distribution": {"kind": "lognormal", "median": 2e8, "sigma": 0.1}},
            {"parameter": "impact_velocity_m_s", "per": "operation",
             "distribution": {"kind": "normal", "mean": 0.224, "sd": 0.03, "min": 0.05}}
        ]
    })
}

#[test]
fn every_job_rule_names_its_field() {
    let cases = [
        (json!({"devices": 0}), "/devices"),
        (json!({"operations": 0}), "/operations"),
        (
            json!({"operations": 10, "bin_operations": 11}),
            "/bin_operations",
        ),
        (
            json!({"operations": 10, "bin_operations": 0}),
            "/bin_operations",
        ),
        (
            json!({"operations": 100000, "bin_operations": 1}),
            "/bin_operations",
        ),
        (json!({"fidelity": "approximate"}), "/fidelity"),
        (json!({"sampler": "sobol"}), "/sampler"),
        (json!({"seed": -1}), "/seed"),
        (
            json!({"scenario": {"mechanism": {"static_force_n": -1}}}),
            "/scenario/mechanism/static_force_n",
        ),
        (
            json!({"metrics": ["total_bounce_s", "bogus"]}),
            "/metrics/1",
        ),
        (json!({"metrics": ["e1", "e1"]}), "/metrics/1"),
        (json!({"metrics": []}), "/metrics"),
        (json!({"limits": {"bogus": 1}}), "/limits/bogus"),
        (
            json!({"metrics": ["e1"], "limits": {"total_bounce_s": 0.01}}),
            "/limits/total_bounce_s",
        ),
        (
            json!({"precision": {"metric": "bogus", "relative_half_width": 0.1, "max_devices": 2000}}),
            "/precision/metric",
        ),
        (
            json!({"precision": {"metric": "e1", "statistic": "p42", "relative_half_width": 0.1, "max_devices": 2000}}),
            "/precision/statistic",
        ),
        (
            json!({"precision": {"metric": "e1", "relative_half_width": 0, "max_devices": 2000}}),
            "/precision/relative_half_width",
        ),
        (
            json!({"precision": {"metric": "e1", "relative_half_width": 0.1, "max_devices": 10}}),
            "/precision/max_devices",
        ),
        (
            json!({"scatter": [{"parameter": "mass", "per": "device", "distribution": {"kind": "fixed", "value": 1}}]}),
            "/scatter/0/parameter",
        ),
        (
            json!({"scatter": [{"parameter": "current_a", "per": "batch", "distribution": {"kind": "fixed", "value": 1}}]}),
            "/scatter/0/per",
        ),
        (
            json!({"scatter": [{"parameter": "contact_radius_m", "per": "device", "distribution": {"kind": "normal", "mean": 7e-3, "sd": 1e-3}}]}),
            "/scatter/0/distribution/min",
        ),
        (
            json!({"scatter": [{"parameter": "contact_radius_m", "per": "device", "distribution": {"kind": "uniform", "min": 1e-4, "max": 1e-2}}]}),
            "/scatter/0/distribution/min",
        ),
        (
            json!({"scatter": [{"parameter": "static_force_n", "per": "operation", "distribution": {"kind": "uniform", "min": -1, "max": 1}}]}),
            "/scatter/0/distribution/min",
        ),
        (
            json!({"scatter": [
            {"parameter": "current_a", "per": "device", "distribution": {"kind": "fixed", "value": 1}},
            {"parameter": "current_a", "per": "operation", "distribution": {"kind": "fixed", "value": 2}}]}),
            "/scatter/1/parameter",
        ),
        (json!({"scatter": {"parameter": "current_a"}}), "/scatter"),
        (json!({"unknown": 1}), "/unknown"),
    ];
    for (document, pointer) in cases {
        let found = pointers(document.clone());
        assert!(
            found.first().is_some_and(|p| p.starts_with(pointer)),
            "{document}: {found:?}, expected {pointer}"
        );
    }
}

#[test]
fn a_jobs_errors_nest_under_the_root_it_is_given() {
    let documents = [
        json!({
            "devices": 0, "operations": 10, "bin_operations": 0,
            "metrics": ["e1", "bogus"], "limits": {"final_kappa": 1},
            "precision": {"metric": "kappa", "relative_half_width": 2, "max_devices": 2000},
            "failure": {"e1": {}},
            "scatter": [{"parameter": "current_a", "per": "device",
                         "distribution": {"kind": "uniform", "min": -1, "max": 1}}]
        }),
        json!({"scenario": {"mechanism": {"static_force_n": -1}}}),
    ];
    for document in documents {
        let spec: JobSpec = serde_json::from_value(document.clone()).unwrap();
        let at_root = Job::new(spec, || 7, &Pointer::root()).unwrap_err();
        let expected: Vec<FieldError> = at_root
            .errors()
            .iter()
            .map(|e| FieldError {
                pointer: format!("/template{}", e.pointer),
                detail: e.detail.clone(),
            })
            .collect();
        let spec: JobSpec = serde_json::from_value(document).unwrap();
        let nested = Job::new(spec, || 7, &Pointer::root().child("template")).unwrap_err();
        assert_eq!(nested.errors(), expected);
    }
}

#[test]
fn defaults_are_filled_in_and_the_seed_is_reported() {
    let job = Job::from_json("{}", || 12345).unwrap();
    assert_eq!(
        (
            job.spec().devices,
            job.spec().operations,
            job.bin_operations(),
            job.seed()
        ),
        (1000, 1000, 100, 12345)
    );
    let small = job_with(json!({"devices": 1, "operations": 5}));
    let result = run(&small);
    let resolved = result.job.spec();
    assert_eq!(resolved.seed, Some(12345));
    assert_eq!(resolved.bin_operations, Some(1), "max(1, 5 / 10)");
    assert_eq!(resolved.scenario.mechanism.static_force_n, 0.344);
    assert_eq!(result.operations["total_bounce_s"].len(), 5);
    assert!(
        result.job.versions().contains_key("rand_chacha") && !result.job.generator().is_empty()
    );
    // A rare event's defaults, the operation it reads at among them.
    let rare = job_with(json!({"devices": 1, "operations": 5,
        "scatter": [{"parameter": "impact_velocity_m_s", "per": "operation",
            "distribution": {"kind": "normal", "mean": 0.224, "sd": 0.02, "min": 0.01}}],
        "rare_event": {"metric": "total_bounce_s", "above": 1e-3, "method": "crude",
            "max_evaluations": 2000}}));
    let rare = serde_json::to_value(run(&rare).job).unwrap();
    assert_eq!(
        rare["rare_event"],
        json!({"metric": "total_bounce_s", "above": 1e-3, "method": "crude", "operation": 1,
            "target_cov": 0.1, "max_evaluations": 2000})
    );
}

#[test]
fn the_resolved_jobs_keys_are_sorted_at_every_depth() {
    let result = run(&job_with(json!({"devices": 1, "operations": 5})));
    let text = serde_json::to_string(&result.job).unwrap();
    assert!(
        text.starts_with(r#"{"bin_operations":1,"devices":1,"devices_run":1,"fidelity":"exact","generator":"#)
            && text.contains(r#","scenario":{"circuit":{"current_a":0.0,"supply_voltage_v":0.0},"losses":{"impact_energy_loss_j":1e-6,"#),
        "{text}"
    );
}

#[test]
fn a_result_reads_back_as_it_was_written() {
    let doc = json!({"devices": 16, "operations": 20, "metrics": ["e1", "eroded_mass_kg"],
        "precision": {"metric": "e1", "relative_half_width": 0.5, "max_devices": 32},
        "failure": {"e1": {"below": 0.2}}, "scenario": arcing()});
    let text = serde_json::to_string(&run(&job_with(doc))).unwrap();
    let read: JobResult = serde_json::from_str(&text).unwrap();
    assert_eq!(serde_json::to_string(&read).unwrap(), text);
}

fn job_with(value: Value) -> Job {
    Job::from_json(&value.to_string(), || 12345).unwrap()
}

#[test]
fn results_are_bit_identical_for_any_thread_count_and_on_a_rerun() {
    let job = job(scattered(37, 40, 99));
    let reference = run_on(1, &job);
    for threads in [2, 3, 1] {
        let again = run_on(threads, &job);
        assert_eq!(again.operations, reference.operations, "threads {threads}");
        assert_eq!(again.devices, reference.devices, "threads {threads}");
    }
}

#[test]
fn recorded_random_crate_versions_match_cargo_lock() {
    let lock =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../Cargo.lock")).unwrap();
    for (name, version) in bouncewear_model::montecarlo::RANDOM_CRATES {
        assert!(
            lock.contains(&format!("name = \"{name}\"\nversion = \"{version}\"")),
            "{name} {version}"
        );
    }
}

#[test]
fn skipping_unrequested_metrics_changes_no_number() {
    let mut full = scattered(20, 30, 5);
    full["limits"] = json!({"total_bounce_s": 0.008});
    let mut lean = full.clone();
    lean["metrics"] = json!(["total_bounce_s"]);
    let (full, lean) = (run(&job(full)), run(&job(lean)));
    assert_eq!(
        full.operations["total_bounce_s"],
        lean.operations["total_bounce_s"]
    );
    assert_eq!(lean.operations.len(), 1);
    assert!(lean.devices.is_empty());
    assert!(
        lean.operations["total_bounce_s"][0]
            .summary
            .exceedance
            .is_some()
    );
}

#[test]
fn only_device_metrics_still_run_every_operation() {
    let mut doc = scattered(10, 20, 3);
    let all = run(&job(doc.clone()));
    doc["metrics"] = json!(["cumulative_arc_energy_j"]);
    let lean = run(&job(doc));
    assert_eq!(
        all.devices["cumulative_arc_energy_j"],
        lean.devices["cumulative_arc_energy_j"]
    );
    assert!(lean.devices["cumulative_arc_energy_j"].mean > 10.0);
}

#[test]
fn arcs_wear_the_surface_and_lower_kappa_operation_by_operation() {
    let result = run(&job(
        json!({"devices": 4, "operations": 200, "bin_operations": 20, "scenario": arcing()}),
    ));
    let kappa: Vec<f64> = result.operations["kappa"]
        .iter()
        .map(|b| b.summary.mean)
        .collect();
    assert!(kappa.windows(2).all(|w| w[1] < w[0]), "{kappa:?}");
    let devices = &result.devices;
    assert!(devices["final_radius_m"].mean < 7.7e-3 && devices["final_radius_m"].mean > 0.711e-3);
    let eroded = devices["eroded_mass_kg"].mean / devices["cumulative_arc_energy_j"].mean;
    assert!((eroded - 2e-9).abs() < 1e-20);
}

#[test]
fn without_current_nothing_wears() {
    let result = run(&job(json!({"devices": 3, "operations": 50})));
    assert_eq!(result.devices["final_radius_m"].min, 7.7e-3);
    assert_eq!(result.devices["cumulative_arc_energy_j"].max, 0.0);
    let kappa = &result.operations["kappa"];
    assert_eq!(
        kappa.first().unwrap().summary.mean,
        kappa.last().unwrap().summary.mean
    );
}

#[test]
fn latin_hypercube_pins_the_sample_mean_far_closer_than_random_draws() {
    // Without current nothing wears, so final_radius_m is the device's drawn radius.
    let (lo, hi, n) = (5e-3, 1e-2, 1000u64);
    let mean_error = |sampler: &str, seed: u64| {
        let result = run(&job(json!({
            "devices": n, "operations": 1, "seed": seed, "sampler": sampler, "metrics": ["final_radius_m"],
            "scatter": [{"parameter": "contact_radius_m", "per": "device",
                         "distribution": {"kind": "uniform", "min": lo, "max": hi}}]
        })));
        (result.devices["final_radius_m"].mean - 0.5 * (lo + hi)).abs()
    };
    // LHS: one point per stratum, so the mean's sd is (hi - lo) / (n sqrt(12 n)); random: (hi - lo) / sqrt(12 n).
    let lhs_sd = (hi - lo) / (n as f64 * (12.0 * n as f64).sqrt());
    for seed in 0..5 {
        assert!(mean_error("lhs", seed) < 5.0 * lhs_sd, "seed {seed}");
    }
    let random_errors: f64 = (0..5).map(|seed| mean_error("random", seed)).sum();
    assert!(random_errors > 5.0 * 5.0 * lhs_sd);
}

#[test]
fn precision_target_adds_device_batches_until_met() {
    let mut doc = scattered(50, 10, 11);
    doc["metrics"] = json!(["total_bounce_s"]);
    doc["bin_operations"] = json!(10);
    doc["precision"] = json!({"metric": "total_bounce_s", "statistic": "mean", "relative_half_width": 0.01, "max_devices": 5000});
    let result = run(&job(doc.clone()));
    let report = result.precision.clone().unwrap();
    assert!(
        report.met && report.devices > 50 && report.devices.is_multiple_of(50),
        "{report:?}"
    );
    assert!(report.achieved_relative_half_width <= 0.01);
    // A target met stopped the run when the interval was narrow enough: the Result says how far
    // to trust such an interval, where a decision reads it.
    let stopped: Vec<_> = result
        .diagnostics
        .iter()
        .filter(|d| d.pointer == "/precision")
        .collect();
    assert_eq!(stopped.len(), 1, "{:?}", result.diagnostics);
    assert!(
        stopped[0].detail.contains("about 90 % of runs, not 95 %")
            && stopped[0]
                .detail
                .contains(&format!("run {} devices again", report.devices)),
        "{}",
        stopped[0].detail
    );
    let bin = &result.operations["total_bounce_s"][0].summary;
    assert_eq!(bin.n, report.devices * 10);
    assert_eq!(result.job.devices_run(), report.devices);

    doc["precision"]["max_devices"] = json!(100);
    doc["precision"]["relative_half_width"] = json!(1e-6);
    let capped = run(&job(doc.clone()));
    assert!(capped.diagnostics.iter().all(|d| d.pointer != "/precision"));
    let capped = capped.precision.unwrap();
    assert!(!capped.met && capped.devices == 100, "{capped:?}");
    assert_eq!(capped.reason, None, "a mean is always bounded");

    // A p99 of 32 devices of one operation lies beyond what they bound: not met, however narrow
    // its interval, and the report says why (it said only `met: false` beside a width within the
    // target).
    let mut doc = scattered(16, 1, 11);
    doc["metrics"] = json!(["total_bounce_s"]);
    doc["precision"] = json!({"metric": "total_bounce_s", "statistic": "p99",
                              "relative_half_width": 0.5, "max_devices": 32});
    let beyond = run(&job(doc)).precision.unwrap();
    assert!(beyond.achieved_relative_half_width <= 0.5, "{beyond:?}");
    assert!(!beyond.met, "{beyond:?}");
    assert!(
        beyond
            .reason
            .as_deref()
            .is_some_and(|r| r.starts_with("beyond the data")),
        "{beyond:?}"
    );
}

/// A quantile's target is checked once 5 devices' share lies beyond its level (a p99 from 500
/// devices): the groups' count alone bounded this p99 of one operation per device at 304 devices,
/// 3 values beyond it, and the target was met there (an outside probe's seed; such stops held the
/// truth in 89 % of jobs).
#[test]
fn a_quantile_target_waits_for_five_devices_beyond_its_level() {
    let mut doc = json!({
        "devices": 16, "operations": 1, "seed": 1121, "metrics": ["impact_velocity_m_s"],
        "scatter": [{"parameter": "impact_velocity_m_s", "per": "device",
                     "distribution": {"kind": "lognormal", "median": 0.3, "sigma": 0.1}}],
        "precision": {"metric": "impact_velocity_m_s", "statistic": "p99",
                      "relative_half_width": 0.01, "max_devices": 2_000_000}
    });
    let met = run(&job(doc.clone())).precision.unwrap();
    assert!(met.met && met.devices >= 500, "{met:?}");
    doc["precision"]["max_devices"] = json!(304);
    let short = run(&job(doc)).precision.unwrap();
    assert!(!short.met && short.devices == 304, "{short:?}");
    assert!(
        short.achieved_relative_half_width <= 0.01,
        "the groups bound it: {short:?}"
    );
    assert_eq!(
        short.reason.as_deref(),
        Some(
            "a precision target on p99 is checked once 500 devices have run (5 devices' share \
             beyond the level), and 304 have"
        )
    );
}

#[test]
fn exceedance_of_a_deterministic_metric_is_all_or_nothing() {
    let result = run(&job(
        json!({"devices": 3, "operations": 4, "limits": {"bounce_count": 6.5, "e1": 0.9}}),
    ));
    let bounce = result.operations["bounce_count"][0]
        .summary
        .exceedance
        .clone()
        .unwrap();
    assert_eq!((bounce.probability, bounce.limit), (1.0, 6.5));
    assert_eq!(
        result.operations["e1"][0]
            .summary
            .exceedance
            .clone()
            .unwrap()
            .probability,
        0.0
    );
    assert_eq!(
        result.operations["bounce_count"][0].summary.quantiles["p50"].value,
        7.0
    );
}

/// 95 % intervals must cover the truth 90-99 % of the time over at least 100 seeds, for a job whose
/// operations are correlated through device scatter and wear. The truth is the same statistic from a
/// run 3000 times larger, its quantiles interpolated within their buckets (a truth at a bucket
/// midpoint would count an interval as covering whenever the two merely share a bucket). Observed:
/// printed, and recorded in the README.
#[test]
fn confidence_intervals_cover_the_truth_over_200_seeds() {
    let metrics = json!(["total_bounce_s"]);
    let mut reference = scattered(192_000, 20, 1_000_000);
    reference["metrics"] = metrics.clone();
    let reference = job(reference);
    let tally = engine::run(&reference, &Silent, |_| false).unwrap();
    let truth_mean = summarize_job(&reference, &tally, 1.0).operations["total_bounce_s"][0]
        .summary
        .mean;
    let all = merged(&reference, tally, "total_bounce_s");
    let [truth_p50, truth_p95] = [0.5, 0.95].map(|q| all.sketch().interpolated_quantile(q));
    let seeds: u32 = 200;
    let mut covered = [0u32; 3];
    for seed in 0..seeds {
        let mut doc = scattered(64, 20, u64::from(seed));
        doc["metrics"] = metrics.clone();
        let bin = run(&job(doc)).operations["total_bounce_s"][0]
            .summary
            .clone();
        let inside = |[lo, hi]: [f64; 2], x: f64| lo <= x && x <= hi;
        covered[0] += u32::from(inside(bin.mean_ci95, truth_mean));
        covered[1] += u32::from(inside(bin.quantiles["p50"].ci95, truth_p50));
        covered[2] += u32::from(inside(bin.quantiles["p95"].ci95, truth_p95));
    }
    let coverage = covered.map(|c| f64::from(c) / f64::from(seeds));
    println!(
        "coverage over {seeds} seeds: mean {:.3}, p50 {:.3}, p95 {:.3}",
        coverage[0], coverage[1], coverage[2]
    );
    assert!(
        coverage.iter().all(|c| (0.90..=0.99).contains(c)),
        "{coverage:?}"
    );
}

/// Every value of `metric`'s first bin of a run of `job`, merged.
fn merged(job: &Job, tally: engine::Tally, metric: &str) -> Accumulator {
    let groups = RunGroups::new(job, tally);
    let groups = groups.of(metric, 0).unwrap();
    let mut all = groups[0].empty_like();
    groups.iter().for_each(|group| all.merge(group));
    all
}

/// A mechanical job (hardness scattered 10 % per device, velocity 20 % per operation, 50
/// operations) of `devices`, its `total_bounce_s` alone, with `limits` if any.
fn mechanical(devices: u64, seed: u64, limits: Value) -> Job {
    job(json!({
        "devices": devices, "operations": 50, "bin_operations": 50, "seed": seed,
        "scenario": {}, "metrics": ["total_bounce_s"], "limits": limits,
        "scatter": [
            {"parameter": "impact_velocity_m_s", "per": "operation",
             "distribution": {"kind": "normal", "mean": 0.3, "sd": 0.06, "min": 0.1}},
            {"parameter": "dynamic_yield_pressure_pa", "per": "device",
             "distribution": {"kind": "normal", "mean": 2e8, "sd": 2e7, "min": 1e8}}
        ]
    }))
}

/// The [`mechanical`] job of 64 devices, where a few devices' groups carry an extreme quantile's
/// spread: Student's t with Satterthwaite's degrees of freedom covers it. Over these 400 seeds
/// (the truth from 64,000 devices) the p95 covered 92.8 % and the p99, where answered, 88.9 % of
/// 262 with t for one less than the groups; now 95.3 % and 93.1 %. Since the p99 needs 1.5 of the
/// values' effective number beyond it as well, it is answered in 186 of them, covering 93.5 %.
#[test]
fn extreme_quantiles_carried_by_few_groups_are_covered() {
    let reference = mechanical(64_000, 1_000_000, json!({}));
    let tally = engine::run(&reference, &Silent, |_| false).unwrap();
    let all = merged(&reference, tally, "total_bounce_s");
    let levels = ["p95", "p99"];
    let truth = [0.95, 0.99].map(|q| all.sketch().interpolated_quantile(q));
    let (mut answered, mut covered) = ([0_u32; 2], [0_u32; 2]);
    for seed in 0..400 {
        let bin = run(&mechanical(64, seed, json!({}))).operations["total_bounce_s"][0]
            .summary
            .clone();
        for (i, level) in levels.iter().enumerate() {
            let quantile = &bin.quantiles[*level];
            if quantile.reason.is_none() {
                answered[i] += 1;
                let [lo, hi] = quantile.ci95;
                covered[i] += u32::from(lo <= truth[i] && truth[i] <= hi);
            }
        }
    }
    println!("answered {answered:?}, covered {covered:?}");
    assert!(answered[0] == 400 && answered[1] >= 150, "{answered:?}");
    // The seeds are fixed: with the old t the p95 falls 5 jobs short, the p99 9.
    for (i, least) in [0.94, 0.92].into_iter().enumerate() {
        let coverage = f64::from(covered[i]) / f64::from(answered[i]);
        assert!(coverage >= least, "{}: {coverage:.3}", levels[i]);
    }
}

/// The [`mechanical`] job of 64 devices, the probability above the population's p99 counted as it
/// ran: the events lie in the few devices hard enough, so the groups' spread of their share rests
/// on a few groups. Over these 400 seeds (the truth counted in 64,000 devices) the interval held
/// it in 85.0 % with t for one less than the groups; with Satterthwaite's degrees of freedom,
/// 92.2 %.
#[test]
fn an_exceedance_held_by_few_devices_is_covered() {
    let reference = mechanical(64_000, 1_000_000, json!({}));
    let tally = engine::run(&reference, &Silent, |_| false).unwrap();
    let limit = merged(&reference, tally, "total_bounce_s")
        .sketch()
        .interpolated_quantile(0.99);
    let counting = mechanical(64_000, 1_000_001, json!({"total_bounce_s": limit}));
    let tally = engine::run(&counting, &Silent, |_| false).unwrap();
    let all = merged(&counting, tally, "total_bounce_s");
    let truth = all.count_above() as f64 / all.count() as f64;
    let covered: u32 = (0..400)
        .map(|seed| {
            let result = run(&mechanical(64, seed, json!({"total_bounce_s": limit})));
            let exceedance = result.operations["total_bounce_s"][0]
                .summary
                .exceedance
                .clone()
                .unwrap();
            let [lo, hi] = exceedance.ci95;
            u32::from(lo <= truth && truth <= hi)
        })
        .sum();
    println!("P = {truth:.5}: covered {covered} of 400");
    // The seeds are fixed: with the old t 340 of them.
    assert!(covered >= 360, "covered {covered} of 400");
}

#[test]
fn a_device_fails_at_the_first_operation_that_meets_a_criterion() {
    // One device without scatter: its e1 falls as it wears; the life must be the first operation
    // whose e1 (seen in the one-operation bins) is below the limit.
    let limit = 0.33;
    let result = run(&job(json!({
        "devices": 1, "operations": 400, "bin_operations": 1, "seed": 1, "scenario": arcing(),
        "metrics": ["e1"], "failure": {"e1": {"below": limit}}
    })));
    let first_below = result.operations["e1"]
        .iter()
        .position(|bin| bin.summary.mean < limit)
        .expect("e1 falls below the limit");
    let life = result.life.expect("life analysis");
    assert_eq!((life.failures, life.censored), (1, 0));
    assert_eq!(
        life.devices[0].operations_to_failure,
        first_below as u64 + 1
    );
    assert!(
        life.analysis.weibull.is_none(),
        "one failure time cannot fix a Weibull"
    );
}

#[test]
fn scattered_devices_give_a_weibull_life_with_censoring() {
    let mut doc = scattered(300, 1000, 5);
    doc["metrics"] = json!(["total_bounce_s"]);
    doc["failure"] = json!({"eroded_mass_kg": {"above": 2e-6}});
    let life = run(&job(doc)).life.unwrap();
    assert_eq!(life.failures + life.censored, 300);
    assert!(
        life.failures > 100 && life.censored > 10,
        "{} failures, {} censored",
        life.failures,
        life.censored
    );
    assert!(
        life.devices
            .iter()
            .all(|d| !d.censored || d.operations_to_failure == 1000),
        "censored at the end of the test"
    );
    assert!(life.devices.windows(2).all(|w| w[0].device < w[1].device));
    // A Result stored before the candidate fits were compared gets them as its run does.
    assert!(life.analysis.fits.len() >= 2);
    let mut older = life.clone();
    (older.analysis.fits, older.analysis.fit_warning) = (Vec::new(), None);
    assert_eq!(older.with_fits(1000).analysis, life.analysis);
    assert_eq!(life.clone().with_fits(1000).analysis, life.analysis);
    let weibull = life.analysis.weibull.clone().expect("a fit");
    assert!(
        weibull.beta > 1.0 && weibull.eta > 500.0 && weibull.eta < 2000.0,
        "{weibull:?}"
    );
    let b10 = life.analysis.b10.clone().unwrap();
    assert!(b10.ci95[0] < b10.value && b10.value < b10.ci95[1]);
}

#[test]
fn failure_criteria_are_validated() {
    for (failure, pointer) in [
        (json!({"bogus": {"above": 1}}), "/failure/bogus"),
        (json!({"e1": {"above": 1, "below": 0}}), "/failure/e1"),
        (json!({"e1": {}}), "/failure/e1"),
        (json!({"e1": {"over": 1}}), "/failure/e1/over"),
        // No criterion asks for no life analysis while looking as though it asked for one.
        (json!({}), "/failure"),
    ] {
        let found = pointers(json!({"failure": failure}));
        assert_eq!(
            found.first().map(String::as_str),
            Some(pointer),
            "{failure}"
        );
    }
}

#[test]
fn the_anode_cathode_split_needs_the_anodes_share_and_names_where_it_is_asked_for() {
    let cases = [
        (
            json!({"metrics": ["e1", "anode_eroded_mass_kg"]}),
            "/metrics/1",
        ),
        (
            json!({"failure": {"cathode_eroded_mass_kg": {"above": 1e-9}}}),
            "/failure/cathode_eroded_mass_kg",
        ),
        (
            json!({"scenario": {"material": {"wear_law": {"law": "roughening_and_softening"}}},
                   "scatter": [{"parameter": "dynamic_yield_pressure_pa", "per": "device",
                                "distribution": {"kind": "uniform", "min": 5e7, "max": 3e8}}]}),
            "/scatter/0/distribution/min",
        ),
    ];
    for (document, pointer) in cases {
        assert_eq!(pointers(document.clone()), [pointer], "{document}");
    }
    // The field to set is named by its pointer, in a job's metrics and in its rare event alike.
    for document in [
        json!({"metrics": ["anode_eroded_mass_kg"]}),
        json!({"rare_event": {"metric": "anode_eroded_mass_kg", "above": 1e-9}}),
    ] {
        let invalid = Job::from_json(&document.to_string(), || 7).unwrap_err();
        let detail = &invalid.errors()[0].detail;
        let set = "set the job's /scenario/material/anode_erosion_fraction";
        assert!(detail.contains(set), "{detail}");
    }
    let split = json!({"scenario": {"material": {"anode_erosion_fraction": 0.7}},
                       "metrics": ["anode_eroded_mass_kg", "cathode_eroded_mass_kg"]});
    assert_eq!(pointers(split), Vec::<String>::new());
}

#[test]
fn all_metrics_include_plastic_work_and_the_split_only_with_a_polarity() {
    let names = |document: Value| {
        let result = run(&job(document));
        let mut names: Vec<String> = result.operations.keys().cloned().collect();
        names.extend(result.devices.keys().cloned());
        names
    };
    let plain = names(json!({"devices": 2, "operations": 3}));
    assert!(plain.contains(&"first_impact_plastic_work_j".to_owned()));
    assert!(plain.contains(&"cumulative_plastic_work_j".to_owned()));
    assert!(!plain.iter().any(|name| name.contains("anode")));
    let split = names(json!({"devices": 2, "operations": 3,
                             "scenario": {"material": {"anode_erosion_fraction": 0.5}}}));
    assert_eq!(split.len(), plain.len() + 2);
}

#[test]
fn cumulative_plastic_work_is_the_sum_of_the_first_impacts() {
    let result = run(&job(json!({
        "devices": 3, "operations": 40, "bin_operations": 40, "scenario": arcing(),
        "metrics": ["first_impact_plastic_work_j", "cumulative_plastic_work_j"]})));
    let per_operation = result.operations["first_impact_plastic_work_j"][0]
        .summary
        .mean;
    let per_device = result.devices["cumulative_plastic_work_j"].mean;
    assert!(
        (per_device - 40.0 * per_operation).abs() <= 1e-12 * per_device,
        "{per_device} vs 40 x {per_operation}"
    );
}

#[test]
fn a_result_warns_when_the_paper_law_runs_far_from_its_calibration_current() {
    let far = run(&job(json!({"devices": 2, "operations": 3,
        "scenario": {"circuit": {"supply_voltage_v": 48, "current_a": 2},
                     "material": {"arc_restitution": {"law": "paper"}}}})));
    assert_eq!(far.diagnostics.len(), 1);
    assert_eq!(far.diagnostics[0].pointer, "/scenario/circuit/current_a");
    let text = serde_json::to_string(&far).unwrap();
    assert!(text.contains(r#""diagnostics":[{"pointer":"/scenario/circuit/current_a""#));
    let near = run(&job(
        json!({"devices": 2, "operations": 3, "scenario": arcing()}),
    ));
    assert!(near.diagnostics.is_empty());
    assert!(
        !serde_json::to_string(&near)
            .unwrap()
            .contains("diagnostics")
    );
}

#[test]
fn a_query_after_the_run_at_the_standard_levels_answers_the_results_summaries() {
    use bouncewear_model::montecarlo::{
        Metric, RunGroups, Silent, engine, query_metric, summarize_job,
    };
    use bouncewear_model::stats::{QUANTILES, QueryQuantile};
    let job = job(json!({"devices": 24, "operations": 20, "bin_operations": 5,
        "scatter": [{"parameter": "impact_velocity_m_s", "per": "device",
                     "distribution": {"kind": "uniform", "min": 0.2, "max": 0.6}}]}));
    let tally = engine::run(&job, &Silent, |_| false).unwrap();
    let result = summarize_job(&job, &tally, 1.0);
    let groups = RunGroups::new(&job, tally);
    let levels = QUANTILES.map(|(_, q)| q);
    let summaries = result
        .operations
        .iter()
        .flat_map(|(metric, bins)| {
            bins.iter()
                .enumerate()
                .map(move |(bin, b)| (metric, bin as u64, &b.summary))
        })
        .chain(result.devices.iter().map(|(metric, s)| (metric, 0, s)));
    for (metric, bin, summary) in summaries {
        let at = groups
            .of(metric, bin)
            .expect("every summary has its groups");
        let metric_of = Metric::parse(metric).unwrap();
        let answer = query_metric(metric_of, job.bin_range(bin), &at, &levels, &[]);
        for (key, level) in QUANTILES {
            assert_eq!(
                answer.quantiles[&level.to_string()],
                QueryQuantile::from(summary.quantiles[key].clone()),
                "{metric} bin {bin} {key}"
            );
        }
    }
    assert!(groups.of("total_bounce_s", 4).is_none());
    assert!(groups.of("eroded_mass_kg", 1).is_none());
    // Moved out one (metric, bin) at a time, every summary's groups come once, the same.
    let expected: Vec<_> = summaries_of(&result)
        .map(|(metric, bin)| (metric.clone(), bin, groups.of(metric, bin).unwrap()))
        .collect();
    let mut moved: Vec<_> = groups
        .into_bins()
        .map(|(metric, bin, at)| (metric.name().to_owned(), bin, at))
        .collect();
    moved.sort_by(|a, b| (&a.0, a.1).cmp(&(&b.0, b.1)));
    assert_eq!(moved, expected);
}

/// Every (metric, bin) a Result summarises, by metric name then bin.
fn summaries_of(
    result: &bouncewear_model::montecarlo::JobResult,
) -> impl Iterator<Item = (&String, u64)> {
    let bins = result
        .operations
        .iter()
        .flat_map(|(metric, bins)| (0..bins.len() as u64).map(move |bin| (metric, bin)));
    let mut all: Vec<_> = bins
        .chain(result.devices.keys().map(|metric| (metric, 0)))
        .collect();
    all.sort();
    all.into_iter()
}

#[test]
fn a_metric_may_have_several_limits_answered_as_a_query_after_the_run_answers_them() {
    use bouncewear_model::montecarlo::{RunGroups, Silent, engine, summarize_job};
    use bouncewear_model::stats::{Threshold, query};
    let spec = json!({"devices": 16, "operations": 10, "bin_operations": 5,
        "scatter": [{"parameter": "impact_velocity_m_s", "per": "device",
                     "distribution": {"kind": "uniform", "min": 0.2, "max": 0.6}}],
        "limits": {"e1": [{"above": 0.4}, {"below": 0.3}], "total_bounce_s": 0.002}});
    let job = job(spec.clone());
    let tally = engine::run(&job, &Silent, |_| false).unwrap();
    let result = summarize_job(&job, &tally, 1.0);
    let groups = RunGroups::new(&job, tally);
    let thresholds = [Threshold::Above(0.4), Threshold::Below(0.3)];
    for (bin, summary) in result.operations["e1"].iter().enumerate() {
        let groups = groups.of("e1", bin as u64).unwrap();
        let operations = job.bin_range(bin as u64);
        let asked = query(&groups, operations.end - operations.start, &[], &thresholds);
        assert_eq!(summary.summary.exceedances, asked.exceedance);
        assert_eq!(summary.summary.exceedance, None);
    }
    // The one-number form keeps its shape: `exceedance`, and no `exceedances`.
    let json = serde_json::to_value(&result).unwrap();
    let bin = &json["operations"]["total_bounce_s"][0];
    assert_eq!(bin["exceedance"]["limit"], 0.002);
    assert!(bin.get("exceedances").is_none());
    assert_eq!(json["operations"]["e1"][0]["exceedances"][1]["below"], 0.3);
    assert_eq!(json["job"]["limits"], spec["limits"]);
}

/// A member of the wrong type or unknown to the job is named and read past, so that every other
/// field at fault is named too (the contract's "every field at fault"); a fault that cannot be
/// read past (a missing field, an item of a list) ends the list there, and a member left out
/// adds no fault of its own (its `missing field`).
#[test]
fn every_field_at_fault_is_named_past_a_wrong_type_or_an_unknown_field() {
    let cases = [
        (
            json!({"devices": 0, "operations": 0, "foo": 1}),
            vec!["/foo", "/devices", "/operations"],
        ),
        (
            json!({"devices": 0, "operations": 0, "seed": -1}),
            vec!["/seed", "/devices", "/operations"],
        ),
        (
            json!({"scenario": {"circuit": {"current_a": "x", "volts": 1}}, "devices": 0}),
            vec![
                "/scenario/circuit/current_a",
                "/scenario/circuit/volts",
                "/devices",
            ],
        ),
        (
            json!({"scatter": [{"parameter": 5, "per": "device",
                                "distribution": {"kind": "fixed", "value": 1}}], "devices": 0}),
            vec!["/scatter/0/parameter"],
        ),
        (
            json!({"metrics": [1, "e1"], "devices": 0}),
            vec!["/metrics/0"],
        ),
    ];
    for (job, expected) in cases {
        assert_eq!(pointers(job.clone()), expected, "{job}");
    }
    let many: serde_json::Map<String, Value> =
        (0..30).map(|i| (format!("x{i}"), json!(i))).collect();
    let named = pointers(Value::Object(many));
    assert_eq!(
        named.len(),
        21,
        "at most 20 read past, then a last entry: {named:?}"
    );
    assert_eq!(
        named[20], "",
        "the last entry says the rest is unchecked: {named:?}"
    );
}

#[test]
fn a_list_of_limits_holds_1_to_20_finite_thresholds() {
    assert_eq!(pointers(json!({"limits": {"e1": []}})), ["/limits/e1"]);
    let invalid = Job::from_json(
        r#"{"limits": {"e1": [{"above": 1}, {"below": 1e400}]}}"#,
        || 7,
    )
    .unwrap_err();
    assert_eq!(invalid.pointers(), ["/limits/e1/1/below"], "{invalid}");
    let many: Vec<Value> = (0..21).map(|i| json!({"above": i})).collect();
    assert_eq!(pointers(json!({"limits": {"e1": many}})), ["/limits/e1"]);
    assert!(pointers(json!({"limits": {"e1": [{"above": 1}, {"below": 2}]}})).is_empty());
    // A fault names its item and the rule, not the shapes tried.
    for (limits, pointer, rule) in [
        (
            r#"[{"above": 1}, {"above": 1, "below": 2}]"#,
            "/limits/e1/1",
            "exactly one",
        ),
        (r#"[{}]"#, "/limits/e1/0", "exactly one"),
        (
            r#"[{"beyond": 1}]"#,
            "/limits/e1/0/beyond",
            "expected `above` or `below`",
        ),
        (
            r#""x""#,
            "/limits/e1",
            r#"a number, or a list of thresholds"#,
        ),
    ] {
        let body = format!(r#"{{"limits": {{"e1": {limits}}}}}"#);
        let invalid = Job::from_json(&body, || 7).unwrap_err();
        assert_eq!(invalid.pointers(), [pointer], "{invalid}");
        assert!(invalid.errors()[0].detail.contains(rule), "{invalid}");
    }
}

/// `P(Z > z)` for a standard normal `Z`.
fn normal_tail(z: f64) -> f64 {
    0.5 * libm::erfc(z / std::f64::consts::SQRT_2)
}

/// Ten million closing velocities drawn N(0.224, 0.02) m/s per operation: the share beyond any
/// threshold is a normal tail (the truncation at 0.05 m/s moves it by 1e-18), so every interval
/// can be held to the exact probability at a size where a bucket's bias would show (half a bucket
/// is 0.2 %, several standard errors of a share near 0.02 here). Thresholds named in the job are
/// counted exactly as it runs; the after-run query counts the far tail exactly from the values each
/// group keeps at its ends, and its bucket-limited intervals in the bulk hold the truth whatever
/// the values in the threshold's bucket.
#[test]
fn every_exceedance_interval_covers_the_exact_probability_at_ten_million_values() {
    use bouncewear_model::montecarlo::{Metric, RunGroups, Silent, engine, query_metric};
    use bouncewear_model::stats::{Resolution, Threshold};
    let (mean, sd) = (0.224, 0.02);
    let at = |z: f64| mean + sd * z;
    let listed = [
        Threshold::Above(at(2.0)),
        Threshold::Above(at(3.719_016_485_455_709)),
        Threshold::Below(at(-1.5)),
        Threshold::Above(at(0.7)),
    ];
    let limits: Vec<Value> = listed
        .iter()
        .map(|t| match t {
            Threshold::Above(x) => json!({"above": x}),
            Threshold::Below(x) => json!({"below": x}),
        })
        .collect();
    let job = job(
        json!({"devices": 10_000, "operations": 1000, "bin_operations": 1000,
        "seed": 29, "metrics": ["impact_velocity_m_s"],
        "limits": {"impact_velocity_m_s": limits},
        "scatter": [{"parameter": "impact_velocity_m_s", "per": "operation",
                     "distribution": {"kind": "normal", "mean": mean, "sd": sd, "min": 0.05}}]}),
    );
    let tally = engine::run(&job, &Silent, |_| false).unwrap();
    let result = summarize_job(&job, &tally, 1.0);
    let truth = |t: Threshold| match t {
        Threshold::Above(x) => normal_tail((x - mean) / sd),
        Threshold::Below(x) => normal_tail((mean - x) / sd),
    };
    let summary = &result.operations["impact_velocity_m_s"][0].summary;
    assert_eq!(summary.n, 10_000_000);
    for e in &summary.exceedances {
        let p = truth(e.threshold);
        assert_eq!(e.resolution, Resolution::Exact, "{e:?}");
        assert!(e.ci95[0] <= p && p <= e.ci95[1], "{e:?} against {p}");
    }
    // After the run: the listed thresholds again (exact); others in the bulk, bucket-limited;
    // and others in the far tail (about 1e-4, 30 values per group), counted exactly from the
    // values each group keeps at its ends.
    let mut asked = listed.to_vec();
    let bulk = [0.2, 0.2631, 0.27, 0.29]
        .map(Threshold::Above)
        .into_iter()
        .chain([0.2, 0.21].map(Threshold::Below));
    let far = [at(3.709_016_485_455_709), 0.3]
        .map(Threshold::Above)
        .into_iter()
        .chain([Threshold::Below(at(-3.719_016_485_455_709))]);
    asked.extend(bulk.clone().chain(far.clone()));
    let groups = RunGroups::new(&job, tally)
        .of("impact_velocity_m_s", 0)
        .unwrap();
    let metric = Metric::parse("impact_velocity_m_s").unwrap();
    let answer = query_metric(metric, job.bin_range(0), &groups, &[], &asked);
    assert_eq!(answer.exceedance[..listed.len()], summary.exceedances[..]);
    let bulk = bulk.count();
    for (i, e) in answer.exceedance[listed.len()..].iter().enumerate() {
        let p = truth(e.threshold);
        if i < bulk {
            assert_eq!(e.resolution, Resolution::Bucket, "{e:?}");
            let [lo, hi] = e.bucket.expect("bucket-limited");
            assert!(
                lo <= e.threshold.value() && e.threshold.value() <= hi,
                "{e:?}"
            );
        } else {
            assert_eq!(e.resolution, Resolution::Exact, "{e:?}");
            let beyond = (e.probability * 1e7).round();
            assert!(beyond > 300.0, "{e:?}: counted from the kept values");
        }
        assert!(e.ci95[0] <= p && p <= e.ci95[1], "{e:?} against {p}");
        assert!(
            e.ci95[0] <= e.probability && e.probability <= e.ci95[1],
            "{e:?}"
        );
    }
}

/// A body that breaks a rule in every item of a long list (200,000 unknown metric names, as a
/// megabyte holds) lists 50 faults and says there are more: the whole list once made an answer
/// of 145 MB.
#[test]
fn a_list_of_faults_stops_at_fifty() {
    use bouncewear_model::error::MAX_LISTED_FAULTS;
    let text = json!({"metrics": vec!["zz"; 200_000]}).to_string();
    let error = bouncewear_model::montecarlo::Job::from_json(&text, || 1).unwrap_err();
    let errors = error.errors();
    assert_eq!(errors.len(), MAX_LISTED_FAULTS + 1);
    assert_eq!(errors[0].pointer, "/metrics/0");
    assert_eq!(errors[MAX_LISTED_FAULTS - 1].pointer, "/metrics/49");
    assert_eq!(
        errors[MAX_LISTED_FAULTS].detail,
        "more faults than the 50 listed: mend these and send it again"
    );
    assert!(
        error.to_string().len() < 100_000,
        "{}",
        error.to_string().len()
    );
}

/// A job listing the lives of its first devices only lists those, and counts every device as the
/// job listing all of them does.
#[test]
fn listed_lives_are_the_first_devices_and_every_device_is_counted() {
    let text = json!({"devices": 40, "operations": 30, "seed": 4,
        "scenario": {"circuit": {"supply_voltage_v": 48, "current_a": 15}},
        "failure": {"e1": {"below": 0.36}}});
    let all = run_on(2, &job(text.clone())).life.unwrap();
    assert_eq!(all.devices.len(), 40);
    let some = run_on(2, &job(text.clone()).with_listed_lives(7))
        .life
        .unwrap();
    assert_eq!(some.devices, all.devices[..7]);
    assert_eq!(some.analysis, all.analysis);
    let none = run_on(2, &job(text.clone()).with_listed_lives(0))
        .life
        .unwrap();
    assert!(none.devices.is_empty());
    assert_eq!((none.failures, none.censored), (all.failures, all.censored));
}

/// Inputs each within the magnitudes a scenario admits can still combine past f64 (forces of
/// 1e30 N, lengths and pressures of 1e-30, an arc of 1e30 V and 1e30 A: a first impact's plastic
/// work beyond f64). The run says which metric and where, instead of a Result whose summaries are `null`.
#[test]
fn a_metric_beyond_f64_ends_the_run_with_its_name() {
    let text = include_str!("../../../tests/data/beyond_f64_job.json");
    let job = Job::from_json(text, || 1).unwrap();
    let error = bouncewear_model::montecarlo::run_job(&job, &Silent).unwrap_err();
    assert_eq!(
        error.to_string(),
        "first_impact_plastic_work_j leaves the range of f64 (beyond 1.8e308) in the bin from \
         operation 0: the scenario's magnitudes combine past what the model can represent \
         (docs/model.md section 9)"
    );
    // Values within f64 (impacts of about 1e156 s, the current scattered) whose squares are
    // not: the spread is what leaves, and the run says so (it read as if the values had).
    let mut spread = serde_json::from_str::<serde_json::Value>(text).unwrap();
    spread["metrics"] = serde_json::json!(["impact_duration_s"]);
    spread["devices"] = serde_json::json!(64);
    spread["operations"] = serde_json::json!(1);
    spread["scenario"]["circuit"]["supply_voltage_v"] = serde_json::json!(1e14);
    spread["scenario"]["material"]["min_arc_voltage_v"] = serde_json::json!(5e13);
    spread["scatter"] = serde_json::json!([{"parameter": "current_a", "per": "device",
        "distribution": {"kind": "uniform", "min": 1e29, "max": 1e30}}]);
    let job = Job::from_json(&spread.to_string(), || 1).unwrap();
    let error = bouncewear_model::montecarlo::run_job(&job, &Silent).unwrap_err();
    let told = error.to_string();
    assert!(
        told.starts_with(
            "impact_duration_s leaves the range of f64 (beyond 1.8e308) in the bin from operation \
             0 in its spread (values reach 2."
        ) && told.contains("e156, whose squares pass 1.8e308)"),
        "{told}"
    );
}

/// An input drawn far below 1e-30 (a Weibull's lower tail, left to its draws: shape 0.002) with
/// an arm of 1e6 m leaves a mass of 0, and every peak force is NaN: the run panicked summarizing
/// them (found from outside). It ends naming the metric and saying what its values are.
#[test]
fn values_that_are_not_numbers_end_the_run_with_its_name() {
    let job = json!({"devices": 1, "operations": 1, "seed": 15,
        "scenario": {"mechanism": {"contact_arm_m": 1e6}},
        "metrics": ["peak_force_n", "total_bounce_s"],
        "scatter": [{"parameter": "inertia_kg_m2", "per": "device",
            "distribution": {"kind": "weibull", "scale": 1.593e-5, "shape": 0.002, "max": 1e30}}]});
    let job = Job::from_json(&job.to_string(), || 1).unwrap();
    let error = bouncewear_model::montecarlo::run_job(&job, &Silent).unwrap_err();
    assert_eq!(
        error.to_string(),
        "peak_force_n leaves the range of f64 (beyond 1.8e308) in the bin from operation 0 (its \
         values are NaN: an intermediate passed f64's range, 0 times infinity): the scenario's \
         magnitudes combine past what the model can represent (docs/model.md section 9)"
    );
}

/// Values of 1e153 to 1e154 whose sum's square passes f64 (`inf - inf` in the variance) read a
/// spread of 0 and succeeded, and their Sobol' indices printed `null` (found from outside): the
/// run ends naming the metric, as where the squares alone pass it.
#[test]
fn a_spread_whose_squares_pass_f64_is_no_spread_of_zero() {
    let extreme = json!({
        "mechanism": {"spring_stiffness_n_per_m": 0, "static_force_n": 1e-30,
                      "inertia_kg_m2": 1e30, "contact_arm_m": 1e-30, "impact_velocity_m_s": 1e30},
        "material": {"kappa": 1e30},
        "losses": {"impact_energy_loss_j": 0, "min_separation_m": 0, "max_bounces": 10000}});
    let velocity = |per: &str, min: f64, max: f64| {
        json!([{"parameter": "impact_velocity_m_s",
        "per": per, "distribution": {"kind": "uniform", "min": min, "max": max}}])
    };
    let told = |text: serde_json::Value| {
        let error = bouncewear_model::montecarlo::run_job(&job(text), &Silent).unwrap_err();
        error.to_string()
    };
    let eight = told(
        json!({"scenario": extreme, "devices": 4, "operations": 2, "seed": 1,
        "metrics": ["total_bounce_s"], "scatter": velocity("operation", 1e29, 1e30)}),
    );
    assert!(
        eight.starts_with("total_bounce_s leaves the range of f64"),
        "{eight}"
    );
    assert!(eight.contains("in its spread (values reach 1."), "{eight}");
    // Four to sixteen devices of one operation: their shifted squares finite, the sum's square
    // not (Q - inf), read a spread of 0 as well (found from outside, after the first mend). Now
    // the spread is read where it fits in f64, and the run refuses it where it does not; never
    // 0. A sample's sd lies between (max - min) / sqrt(2 (n - 1)) (its extremes alone) and
    // (max - min) sqrt(n / (4 (n - 1))).
    for devices in [4, 8, 16] {
        let text = json!({"scenario": extreme, "devices": devices, "operations": 1, "seed": 1,
            "metrics": ["total_bounce_s"], "scatter": velocity("device", 1e29, 1e30)});
        match bouncewear_model::montecarlo::run_job(&job(text), &Silent) {
            Ok(result) => {
                let s = &result.operations["total_bounce_s"][0].summary;
                let (range, n) = (s.max - s.min, devices as f64);
                let bounds = [
                    range / (2.0 * (n - 1.0)).sqrt(),
                    range * (n / (4.0 * (n - 1.0))).sqrt(),
                ];
                assert!(
                    bounds[0] <= s.sd && s.sd <= bounds[1],
                    "{devices}: {} {bounds:?}",
                    s.sd
                );
            }
            Err(error) => assert!(
                error.to_string().contains("in its spread"),
                "{devices}: {error}"
            ),
        }
    }
    // Ten thousand values of 2e150 to 2e151 (ten bounces): their squares within f64, their
    // sum's square not (S^2 alone passes it). Their spread is read, not refused (a re-probe).
    let mut ten = extreme.clone();
    ten["losses"]["max_bounces"] = json!(10);
    let result = run_on(
        1,
        &job(json!({"scenario": ten, "devices": 10_000, "operations": 1,
        "seed": 1, "metrics": ["total_bounce_s"], "scatter": velocity("device", 1e29, 1e30)})),
    );
    let summary = &result.operations["total_bounce_s"][0].summary;
    // Uniform velocities and bounce times in proportion: the spread of a uniform, within 5 %.
    let uniform = (summary.max - summary.min) / 12f64.sqrt();
    assert!(summary.min > 1e150 && summary.max < 1e152, "{summary:?}");
    assert!(
        (summary.sd / uniform - 1.0).abs() < 0.05,
        "{} {uniform}",
        summary.sd
    );
    let sobol = told(
        json!({"scenario": extreme, "devices": 8, "operations": 1, "seed": 1,
        "metrics": ["total_bounce_s"], "scatter": velocity("device", 1e29, 1e30),
        "sensitivity": {"method": "sobol"}}),
    );
    assert!(
        sobol.starts_with("total_bounce_s leaves the range of f64"),
        "{sobol}"
    );
}

/// A whole-number metric's quantiles and thresholds, against the job's own exact counts (its
/// listed thresholds half-way between whole numbers): a level whose whole number the shares
/// settle has the interval of that number alone (p01 to p75 of counts 86 % at 7 read `[7, 8]`),
/// and a threshold asked after the run on a whole number is answered exactly (`above:7` read 1.0
/// for 0.139, counted as if the 7s spread over their bucket; found from outside).
#[test]
fn whole_number_quantiles_and_thresholds_are_those_of_the_counts() {
    use bouncewear_model::montecarlo::{Metric, RunGroups, Silent, engine, query_metric};
    use bouncewear_model::stats::{QUANTILES, Resolution, Threshold};
    let halves = [5.5, 6.5, 7.5, 8.5];
    let listed: Vec<Value> = halves.iter().map(|h| json!({"above": h})).collect();
    let job = job(
        json!({"devices": 300, "operations": 300, "bin_operations": 300, "seed": 1,
        "metrics": ["bounce_count"], "limits": {"bounce_count": listed},
        "scatter": [{"parameter": "impact_velocity_m_s", "per": "operation",
                     "distribution": {"kind": "normal", "mean": 0.33, "sd": 0.03, "min": 0.05}}]}),
    );
    let tally = engine::run(&job, &Silent, |_| false).unwrap();
    let result = summarize_job(&job, &tally, 1.0);
    let summary = &result.operations["bounce_count"][0].summary;
    // The share at or below each whole number from 5 to 8, exact.
    let above: Vec<f64> = summary.exceedances.iter().map(|e| e.probability).collect();
    let at_or_below = |k: f64| match halves.iter().position(|h| *h == k + 0.5) {
        Some(i) => 1.0 - above[i],
        None if k < 5.0 => 0.0,
        None => 1.0,
    };
    assert!(
        at_or_below(7.0) > 0.8 && at_or_below(6.0) < 0.01,
        "{above:?}"
    );
    let mut settled = 0;
    for (key, level) in QUANTILES {
        let q = &summary.quantiles[key];
        let k = q.value;
        // The exact sample quantile: the least whole number whose share reaches the level.
        assert!(
            at_or_below(k) >= level && at_or_below(k - 1.0) < level,
            "{key}: {q:?}"
        );
        assert!(q.ci95[0] <= k && k <= q.ci95[1], "{key}: {q:?}");
        if at_or_below(k) > level + 0.02 && at_or_below(k - 1.0) < level - 0.02 {
            assert_eq!(q.ci95, [k, k], "{key}: a level the counts settle");
            settled += 1;
        }
    }
    assert!(settled >= 5, "{settled}");
    let asked = [
        Threshold::Above(7.0),
        Threshold::Below(7.0),
        Threshold::Above(7.2),
        Threshold::Below(8.0),
        Threshold::Above(6.0),
    ];
    let groups = RunGroups::new(&job, tally).of("bounce_count", 0).unwrap();
    let metric = Metric::parse("bounce_count").unwrap();
    let answer = query_metric(metric, job.bin_range(0), &groups, &[], &asked);
    let exact = [
        1.0 - at_or_below(7.0),
        at_or_below(6.0),
        1.0 - at_or_below(7.0),
        at_or_below(7.0),
        1.0 - at_or_below(6.0),
    ];
    for ((e, asked), p) in answer.exceedance.iter().zip(asked).zip(exact) {
        assert!(e.threshold.same(asked), "{e:?}: told as asked");
        assert_eq!(e.resolution, Resolution::Exact, "{e:?}");
        assert!((e.probability - p).abs() <= 1e-12, "{e:?} against {p}");
        assert!(e.ci95[0] <= p && p <= e.ci95[1], "{e:?}");
    }
}
