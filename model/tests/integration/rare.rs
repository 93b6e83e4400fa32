//! Rare events against the truth without simulation: one scattered input and a metric monotone
//! in it, so that `P(metric > t) = P(input > x*)` with `x*` found by bisection on jobs of one
//! device at a fixed input (the engine's own path, not the rare-event one), and the input's
//! normal tail exact.

use crate::support::{job, pointers, run_on};
use bouncewear_model::Pointer;
use bouncewear_model::montecarlo::distribution::{standard_normal_cdf, standard_normal_quantile};
use bouncewear_model::montecarlo::rare::{RareEventReport, check_threshold, estimate};
use bouncewear_model::montecarlo::{Job, Silent};
use serde_json::{Value, json};

const MEAN: f64 = 0.224;
const SD: f64 = 0.02;

/// The metric of one device at impact velocity `v`: `metric` (an operation metric at operation
/// `operations`, or a device metric after it), from a job of one device with the velocity fixed.
fn exact(metric: &str, operations: u64, v: f64) -> f64 {
    let result = run_on(
        1,
        &job(json!({
            "devices": 1, "operations": operations, "bin_operations": 1, "seed": 1,
            "scenario": {"circuit": {"supply_voltage_v": 48, "current_a": 15}},
            "scatter": [{"parameter": "impact_velocity_m_s", "per": "device",
                         "distribution": {"kind": "fixed", "value": v}}],
            "metrics": [metric]
        })),
    );
    match result.operations.get(metric) {
        Some(bins) => bins.last().unwrap().summary.mean,
        None => result.devices[metric].mean,
    }
}

/// The threshold the metric takes at `z` standard deviations of velocity, after checking that the
/// metric rises with the velocity over the whole range that matters (so that the event is the
/// velocity's tail beyond `z`, probability `Phi(-z)` exactly).
fn threshold_at(metric: &str, operations: u64, z: f64) -> f64 {
    let grid: Vec<f64> = (0..=120)
        .map(|i| exact(metric, operations, MEAN + SD * (-6.0 + 0.1 * f64::from(i))))
        .collect();
    assert!(
        grid.windows(2).all(|w| w[1] > w[0]),
        "{metric} rises with the velocity from -6 to 6 sd: {grid:?}"
    );
    exact(metric, operations, MEAN + SD * z)
}

fn rare_job(metric: &str, operations: u64, per: &str, rare: Value, seed: u64) -> Job {
    job(json!({
        "devices": 1, "operations": operations, "seed": seed,
        "scenario": {"circuit": {"supply_voltage_v": 48, "current_a": 15}},
        "scatter": [{"parameter": "impact_velocity_m_s", "per": per,
                     "distribution": {"kind": "normal", "mean": MEAN, "sd": SD, "min": 0.01}}],
        "metrics": [metric],
        "rare_event": rare
    }))
}

fn report(job: &Job) -> RareEventReport {
    estimate(job, &Silent)
        .unwrap()
        .expect("the job asks a rare event")
}

/// P = 1e-4 (z = 3.719): the total bounce time of the first operation, velocity per operation.
const Z_1E4: f64 = 3.719_016_485_455_709;

#[test]
fn an_operation_metric_at_1e_minus_4_by_each_method_holds_the_truth() {
    let threshold = threshold_at("total_bounce_s", 1, Z_1E4);
    let truth = standard_normal_cdf(-Z_1E4);
    for method in ["subset", "importance", "auto"] {
        let job = rare_job(
            "total_bounce_s",
            1,
            "operation",
            json!({"metric": "total_bounce_s", "above": threshold, "operation": 1,
                   "method": method, "target_cov": 0.1, "max_evaluations": 200_000}),
            4,
        );
        let found = report(&job);
        // One seed's interval misses with probability 0.05 (seed 3's importance estimate does);
        // the coverage over 200 seeds is the test below.
        assert!(
            found.ci95[0] <= truth && truth <= found.ci95[1],
            "{method}: {found:?} against {truth}"
        );
        assert!(
            found.cov.unwrap() <= 0.1 || found.evaluations > 190_000,
            "{found:?}"
        );
        // The design point is the velocity at the threshold, the reliability index its z.
        let v = found.design_point["impact_velocity_m_s@1"];
        assert!(
            (v - (MEAN + SD * Z_1E4)).abs() < 0.01 * SD * Z_1E4,
            "{method}: {v}"
        );
        assert!((found.beta.unwrap() - Z_1E4).abs() < 0.1, "{found:?}");
        let tail = &found.tail;
        assert!(
            tail.windows(2).all(|w| w[0].threshold <= w[1].threshold),
            "{tail:?}"
        );
        assert!(
            tail.windows(2)
                .all(|w| w[0].probability >= w[1].probability),
            "{tail:?}"
        );
        assert_eq!(tail.last().unwrap().threshold, threshold);
    }
    // `auto` chooses importance sampling for one input.
    let auto = rare_job(
        "total_bounce_s",
        1,
        "operation",
        json!({"metric": "total_bounce_s", "above": threshold}),
        3,
    );
    assert_eq!(report(&auto).method, "importance");
}

#[test]
fn a_device_metric_at_1e_minus_4_holds_the_truth_and_below_is_the_other_tail() {
    // Cumulative arc energy after 5 operations, velocity per device.
    let threshold = threshold_at("cumulative_arc_energy_j", 5, Z_1E4);
    let truth = standard_normal_cdf(-Z_1E4);
    for method in ["subset", "importance"] {
        let job = rare_job(
            "cumulative_arc_energy_j",
            5,
            "device",
            json!({"metric": "cumulative_arc_energy_j", "above": threshold,
                   "method": method, "max_evaluations": 100_000}),
            11,
        );
        let found = report(&job);
        assert!(
            found.ci95[0] <= truth && truth <= found.ci95[1],
            "{method}: {found:?} against {truth}"
        );
    }
    let low = threshold_at("cumulative_arc_energy_j", 5, -Z_1E4);
    let job = rare_job(
        "cumulative_arc_energy_j",
        5,
        "device",
        json!({"metric": "cumulative_arc_energy_j", "below": low, "method": "subset"}),
        12,
    );
    let found = report(&job);
    assert!(
        found.ci95[0] <= truth && truth <= found.ci95[1],
        "{found:?}"
    );
    assert!(
        found
            .tail
            .windows(2)
            .all(|w| w[0].threshold >= w[1].threshold)
    );
}

#[test]
fn crude_monte_carlo_is_the_same_question_asked_plainly() {
    let z = 2.326_347_874_040_841; // P = 0.01
    let threshold = threshold_at("total_bounce_s", 1, z);
    let job = rare_job(
        "total_bounce_s",
        1,
        "operation",
        json!({"metric": "total_bounce_s", "above": threshold, "method": "crude",
               "target_cov": 0.05}),
        5,
    );
    let found = report(&job);
    let truth = standard_normal_cdf(-z);
    assert_eq!(found.method, "crude");
    assert!(
        found.ci95[0] <= truth && truth <= found.ci95[1],
        "{found:?}"
    );
    assert!(found.cov.unwrap() <= 0.05);
    // Its tail: at the values 10 % and 1 % of its first batch reach, the shares of all its
    // samples beyond, falling to the estimate's (the first batch's shares alone, 0.1 and 0.01,
    // left a point short of the threshold below the estimate beyond it, 0.0103).
    let shares: Vec<f64> = found.tail.iter().map(|p| p.probability).collect();
    assert_eq!(shares.len(), 3, "{found:?}");
    assert_eq!(shares[2], found.probability);
    assert!(shares.windows(2).all(|w| w[0] > w[1]), "{found:?}");
    // Within five standard deviations of the first batch's (10,000 samples) quantile.
    for (share, level) in shares.iter().zip([0.1_f64, 0.01]) {
        let sd = (level * (1.0 - level) / 10_000.0).sqrt();
        assert!((share - level).abs() < 5.0 * sd, "{found:?}");
    }
}

/// The crude tail reads the share of its first batch beyond each point: a count metric's values
/// tie, and where every sample gives 7 bounces the tail has no point at 7 (it read P(> 7) as 0.1
/// and then 0.01 at the same 7, the levels' nominal shares, a probe), only the threshold's 0.
#[test]
fn the_crude_tail_is_the_share_beyond_each_point_where_values_tie() {
    let ties = job(json!({
        "devices": 16, "operations": 1, "seed": 1,
        "scatter": [{"parameter": "impact_velocity_m_s", "per": "device",
                     "distribution": {"kind": "normal", "mean": 0.3, "sd": 0.01, "min": 0}}],
        "rare_event": {"metric": "bounce_count", "above": 7.5, "method": "crude",
                       "max_evaluations": 2000}
    }));
    let found = report(&ties);
    let tail: Vec<(f64, f64)> = found
        .tail
        .iter()
        .map(|p| (p.threshold, p.probability))
        .collect();
    assert_eq!(tail, [(7.5, 0.0)], "{found:?}");
}

/// A count's plateau: every input the chains of a level reach can give the same bounce count,
/// which failed the job ("never reaches the threshold", 5 % of jobs at 2.8e-3 and 73 % at 2.7e-4
/// in a probe). Such a level is run again on the same threshold until its chains pass it. The
/// truth: the count steps up at a velocity found by bisection, beyond which its normal tail lies.
#[test]
fn a_counts_plateau_is_passed_and_its_interval_holds_the_truth() {
    // No circuit (at 15 A every velocity bounces twice); the velocity N(0.224, 0.05) above 0.05.
    let mechanical = |scatter: Value, extra: Value| {
        let mut value = json!({"devices": 1, "operations": 1, "bin_operations": 1,
                               "scatter": [scatter], "metrics": ["bounce_count"]});
        value
            .as_object_mut()
            .unwrap()
            .extend(extra.as_object().unwrap().clone());
        job(value)
    };
    let count = |v: f64| {
        let fixed = json!({"parameter": "impact_velocity_m_s", "per": "device",
                           "distribution": {"kind": "fixed", "value": v}});
        run_on(1, &mechanical(fixed, json!({"seed": 1}))).operations["bounce_count"][0]
            .summary
            .mean
    };
    let (mean, sd, min) = (0.224, 0.05, 0.05);
    // The count 3 sd out, and the velocity where it steps up to it, by bisection.
    let top = count(mean + 3.0 * sd);
    let (mut lo, mut hi) = (mean, mean + 3.0 * sd);
    assert!(count(lo) < top);
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if count(mid) < top {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let z = |v: f64| (v - mean) / sd;
    let truth = standard_normal_cdf(-z(hi)) / standard_normal_cdf(-z(min));
    assert!((1e-3..1e-2).contains(&truth), "{truth}");
    let mut covered = 0;
    for seed in 0..20 {
        let velocity = json!({"parameter": "impact_velocity_m_s", "per": "operation",
                              "distribution": {"kind": "normal", "mean": mean, "sd": sd,
                                               "min": min}});
        let rare = json!({"seed": seed, "rare_event": {"metric": "bounce_count",
                          "above": top - 1.0, "method": "subset", "target_cov": 0.1,
                          "max_evaluations": 200_000}});
        let found = report(&mechanical(velocity, rare));
        covered += usize::from(found.ci95[0] <= truth && truth <= found.ci95[1]);
        let thresholds: Vec<f64> = found.tail.iter().map(|p| p.threshold).collect();
        assert!(thresholds.windows(2).all(|w| w[0] != w[1]), "{found:?}");
    }
    assert!(covered >= 17, "{covered} of 20 intervals hold {truth}");
    // A first level that ties (a count's failure criterion, the life's margin 0 for every
    // sample) has no level to climb from: said so, not "level after level" (a probe).
    let tied = job(json!({
        "devices": 4, "operations": 10, "seed": 0,
        "scatter": [{"parameter": "impact_velocity_m_s", "per": "operation",
                     "distribution": {"kind": "normal", "mean": mean, "sd": 0.0283, "min": min}}],
        "failure": {"bounce_count": {"above": 7}},
        "rare_event": {"metric": "operations_to_failure", "below": 11, "method": "subset"}
    }));
    let failed = estimate(&tied, &Silent).unwrap_err().to_string();
    assert!(
        failed.contains("sampled at its first level gives"),
        "{failed}"
    );
    assert!(!failed.contains("level after level"), "{failed}");
}

/// Coverage over 200 seeds at P = 1e-4, each method, the operation metric: how often the 95 %
/// interval holds the exact probability.
#[test]
fn intervals_cover_the_truth_at_1e_minus_4_over_200_seeds() {
    let threshold = threshold_at("total_bounce_s", 1, Z_1E4);
    let truth = standard_normal_cdf(-Z_1E4);
    for (method, target) in [("subset", 1.0), ("importance", 0.1)] {
        let mut covered = 0;
        for seed in 0..200 {
            let job = rare_job(
                "total_bounce_s",
                1,
                "operation",
                json!({"metric": "total_bounce_s", "above": threshold,
                       "method": method, "target_cov": target}),
                seed,
            );
            let found = report(&job);
            covered += u32::from(found.ci95[0] <= truth && truth <= found.ci95[1]);
        }
        let coverage = f64::from(covered) / 200.0;
        println!("{method}: coverage {coverage} over 200 seeds at P = 1e-4");
        assert!((0.90..=0.98).contains(&coverage), "{method}: {coverage}");
    }
}

/// The same at P = 1e-6 and 1e-9 (z = 4.753 and 5.998), with each estimate's cov and cost:
/// `cargo test -p bouncewear-model --test integration rare::deep -- --ignored --nocapture` (the model is
/// optimised in test builds).
#[test]
#[ignore = "two minutes; run for the figures in docs/manual.md"]
fn deep_tails_are_covered_over_200_seeds() {
    for z in [4.753_424_308_817_09, 5.997_807_015_007_688] {
        let threshold = threshold_at("total_bounce_s", 1, z);
        let truth = standard_normal_cdf(-z);
        for (method, target) in [("subset", 0.25), ("importance", 0.1)] {
            let (mut covered, mut cov, mut evaluations, mut squares) = (0, 0.0, 0.0, 0.0);
            for seed in 0..200 {
                let job = rare_job(
                    "total_bounce_s",
                    1,
                    "operation",
                    json!({"metric": "total_bounce_s", "above": threshold, "method": method,
                           "target_cov": target, "max_evaluations": 10_000_000}),
                    seed,
                );
                let found = report(&job);
                covered += u32::from(found.ci95[0] <= truth && truth <= found.ci95[1]);
                cov += found.cov.unwrap();
                evaluations += found.evaluations as f64;
                squares += (found.probability / truth - 1.0).powi(2);
            }
            let coverage = f64::from(covered) / 200.0;
            println!(
                "P = {truth:.2e}, {method}: coverage {coverage}, mean cov {:.3}, observed cov \
                 {:.3}, mean evaluations {:.0}",
                cov / 200.0,
                (squares / 200.0).sqrt(),
                evaluations / 200.0
            );
            // Subset simulation's runs after the first claim a cov about a tenth above the one
            // observed (0.235 against 0.214 at 1e-6): its intervals cover 0.975-0.985 here.
            assert!((0.90..=0.99).contains(&coverage), "{method}: {coverage}");
        }
    }
}

/// A budget that ends the estimate short of its target says so in the Result, at
/// `/rare_event/max_evaluations`; one that lets it meet the target says nothing.
#[test]
fn a_budget_that_ends_the_estimate_short_of_its_target_is_named() {
    let t = threshold_at("total_bounce_s", 1, Z_1E4);
    for (method, budget, short) in [
        ("subset", 6000, true),
        ("crude", 20_000, true),
        ("subset", 200_000, false),
        ("importance", 200_000, false),
    ] {
        let rare = json!({"metric": "total_bounce_s", "above": t, "method": method,
                          "max_evaluations": budget});
        let result = run_on(1, &rare_job("total_bounce_s", 1, "operation", rare, 7));
        let report = result.rare_event.as_ref().expect("a rare event");
        let warned: Vec<_> = result
            .diagnostics
            .iter()
            .filter(|d| d.pointer == "/rare_event/max_evaluations")
            .collect();
        assert_eq!(!warned.is_empty(), short, "{method} {budget}: {report:?}");
        assert_eq!(
            report.cov.is_some_and(|cov| cov > 0.1),
            short,
            "{method} {budget}"
        );
        if short {
            assert!(
                warned[0].detail.contains("target_cov 0.1"),
                "{}",
                warned[0].detail
            );
        }
    }
}

#[test]
fn a_rare_event_job_gives_the_same_bits_on_one_thread_and_two() {
    let job = rare_job(
        "total_bounce_s",
        3,
        "operation",
        json!({"metric": "total_bounce_s", "above": 0.0145, "operation": 3,
               "method": "subset", "target_cov": 0.3}),
        9,
    );
    let (one, two) = (run_on(1, &job), run_on(2, &job));
    let (one, two) = (one.rare_event.unwrap(), two.rare_event.unwrap());
    assert_eq!(one.probability.to_bits(), two.probability.to_bits());
    assert_eq!(one, two);
    // Three operations of one input each: the design point names each.
    assert_eq!(one.design_point.len(), 3);
    assert!(one.design_point.contains_key("impact_velocity_m_s@3"));
}

/// Whether one device at impact velocity `v` fails (total bounce time above `limit`) before
/// operation `n`: the job's own life analysis of one device.
fn fails_before(n: u64, limit: f64, v: f64) -> bool {
    let result = run_on(
        1,
        &job(json!({
            "devices": 1, "operations": n - 1, "seed": 1,
            "scenario": {"circuit": {"supply_voltage_v": 48, "current_a": 15}},
            "scatter": [{"parameter": "impact_velocity_m_s", "per": "device",
                         "distribution": {"kind": "fixed", "value": v}}],
            "metrics": ["total_bounce_s"],
            "failure": {"total_bounce_s": {"above": limit}}
        })),
    );
    !result.life.unwrap().devices[0].censored
}

/// Ten devices of 20 operations, the velocity drawn per device, failing once a total bounce time
/// exceeds `limit`; `rare` asks about their life.
fn life_job(limit: f64, rare: Value) -> Job {
    job(json!({
        "devices": 10, "operations": 20, "seed": 2,
        "scenario": {"circuit": {"supply_voltage_v": 48, "current_a": 15}},
        "scatter": [{"parameter": "impact_velocity_m_s", "per": "device",
                     "distribution": {"kind": "normal", "mean": MEAN, "sd": SD, "min": 0.01}}],
        "metrics": ["total_bounce_s"],
        "failure": {"total_bounce_s": {"above": limit}},
        "rare_event": rare
    }))
}

#[test]
fn the_chance_of_failing_before_an_operation_holds_the_truth() {
    // Failing: a total bounce time above what the first operation gives at z = 3.719, within
    // the first 5 operations, the velocity drawn per device.
    let limit = exact("total_bounce_s", 1, MEAN + SD * Z_1E4);
    let n = 6;
    let grid: Vec<bool> = (0..=120)
        .map(|i| fails_before(n, limit, MEAN + SD * (-6.0 + 0.1 * f64::from(i))))
        .collect();
    assert!(
        grid.windows(2).all(|w| w[0] <= w[1]),
        "failing is monotone in the velocity: {grid:?}"
    );
    let (mut lo, mut hi) = (MEAN, MEAN + 6.0 * SD);
    for _ in 0..50 {
        let mid = (lo + hi) / 2.0;
        if fails_before(n, limit, mid) {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    let truth = standard_normal_cdf(-(hi - MEAN) / SD);
    for method in ["subset", "importance"] {
        let job = life_job(
            limit,
            json!({"metric": "operations_to_failure", "below": n, "method": method}),
        );
        let found = report(&job);
        assert!(
            found.ci95[0] <= truth && truth <= found.ci95[1],
            "{method}: {found:?} against {truth}"
        );
        assert_eq!(
            found.tail.last().unwrap().threshold,
            0.0,
            "a margin of 0: failing"
        );
    }
}

/// Failing as soon as one operation's drawn velocity exceeds `t` (the metric is the draw itself),
/// `P(T < 11) = 1 - (1 - p)^10` exactly, with `p = P(v > t)` of the lognormal. The failure
/// domain is ten alike regions, one per operation: `auto` takes subset simulation there, and
/// holds the truth (importance sampling around one centre gave 8.8e-7 for 1.0e-5).
#[test]
fn a_failure_any_of_several_operations_can_cause_is_estimated_whole() {
    let p = 1e-6;
    let z = standard_normal_quantile(1.0 - p);
    let threshold = 0.3 * (0.1 * z).exp();
    let truth = -(10.0 * (-p).ln_1p()).exp_m1();
    let job = job(json!({
        "devices": 2, "operations": 11, "seed": 4,
        "scatter": [{"parameter": "impact_velocity_m_s", "per": "operation",
                     "distribution": {"kind": "lognormal", "median": 0.3, "sigma": 0.1}}],
        "metrics": ["impact_velocity_m_s"],
        "failure": {"impact_velocity_m_s": {"above": threshold}},
        "rare_event": {"metric": "operations_to_failure", "below": 11}
    }));
    let found = report(&job);
    assert_eq!(found.method, "subset");
    assert!(
        found.ci95[0] <= truth && truth <= found.ci95[1],
        "{found:?} against {truth}"
    );
    assert!(
        (found.probability / truth - 1.0).abs() < 0.5,
        "{} against {truth}",
        found.probability
    );
}

/// No arc, `arc_energy_j` below 1e-9, where the supply and the current are scattered: an arc
/// burns only where `V > V_min` and `I (V - V_min) / V >= I_min` (docs/model.md, "Does it
/// arc?"), so the event is a low voltage or a low current, two regions meeting in a corner. The
/// truth is that integral over the voltage's normal, exact to far below the estimates' spread.
/// Importance sampling around the failing samples' mean alone (between the two regions) was 0.89
/// and 0.81 of it at 4.6e-4 and 8.7e-6, and its intervals held it in 119 and 81 of 200 seeds
/// (0 to 199, release build); `auto` takes importance sampling for two inputs.
#[test]
fn no_arc_where_either_the_voltage_or_the_current_is_low_holds_the_truth() {
    for (sigma_v, sigma_i, truth) in [
        (0.185, 0.78, 4.6e-4..4.65e-4),
        (0.146, 0.617, 8.6e-6..8.8e-6),
    ] {
        no_arc_holds_the_truth(sigma_v, sigma_i, truth);
    }
}

fn no_arc_holds_the_truth(sigma_v: f64, sigma_i: f64, expected: std::ops::Range<f64>) {
    const V_MIN: f64 = 12.0;
    const I_MIN: f64 = 0.4;
    let (median_v, median_i) = (24.0, 15.0);
    // P(V <= V_min) plus, above it, P(I < I_min V / (V - V_min)) over the voltage's normal z.
    let below = (V_MIN / median_v).ln() / sigma_v;
    let density = |z: f64| (-z * z / 2.0).exp() / (2.0 * std::f64::consts::PI).sqrt();
    let low_current = |z: f64| {
        let v = median_v * (sigma_v * z).exp();
        let current = I_MIN * v / (v - V_MIN);
        standard_normal_cdf((current / median_i).ln() / sigma_i) * density(z)
    };
    // Simpson's rule from just above the corner (the integrand tends to phi there) to 12 sd.
    let (a, b, n) = (below, 12.0, 200_000);
    let h = (b - a) / f64::from(n);
    let inner: f64 = (1..n)
        .map(|k| f64::from(if k % 2 == 1 { 4 } else { 2 }) * low_current(a + h * f64::from(k)))
        .sum();
    let truth = standard_normal_cdf(below) + h / 3.0 * (density(a) + inner + low_current(b));
    assert!(expected.contains(&truth), "{truth}");
    importance_holds(100, truth, |seed| {
        json!({
            "devices": 1, "operations": 1, "seed": seed,
            "scenario": {"circuit": {"supply_voltage_v": median_v, "current_a": median_i}},
            "scatter": [
                {"parameter": "supply_voltage_v", "per": "operation",
                 "distribution": {"kind": "lognormal", "median": median_v, "sigma": sigma_v}},
                {"parameter": "current_a", "per": "operation",
                 "distribution": {"kind": "lognormal", "median": median_i, "sigma": sigma_i}}],
            "metrics": ["arc_energy_j"],
            "rare_event": {"metric": "arc_energy_j", "below": 1e-9}
        })
    });
}

/// `auto` takes importance sampling for the jobs `job(seed)` of seeds `0..seeds`, and their
/// intervals hold `truth` in at least 95 % less 3 standard deviations of the count, their mean
/// within 3 standard errors (estimates of cov about 0.1) of it.
fn importance_holds(seeds: u32, truth: f64, job_of: impl Fn(u32) -> Value) {
    let (mut covered, mut ratio) = (0, 0.0);
    for seed in 0..seeds {
        let found = report(&job(job_of(seed)));
        assert_eq!(found.method, "importance");
        covered += u32::from(found.ci95[0] <= truth && truth <= found.ci95[1]);
        ratio += found.probability / truth / f64::from(seeds);
    }
    let n = f64::from(seeds);
    let least = 0.95 * n - 3.0 * (0.95 * 0.05 * n).sqrt();
    assert!(f64::from(covered) >= least, "{truth}: {covered} of {seeds}");
    let within = 3.0 * 0.1 / n.sqrt() + 0.01;
    assert!((ratio - 1.0).abs() < within, "{truth}: {ratio}");
}

/// `e1` below 0.395 lies on both sides of its peak in velocity (it rises to about 0.156 m/s and
/// falls after): two regions apart. The first operation's `e1` at a fixed velocity, by bisection
/// on each side, gives the truth `Phi(z_low) + Phi(-z_high)`. The subset run that importance
/// sampling starts from reaches the fast side only; around its samples alone the estimates were
/// half the truth, 0 of 100 intervals holding it. The rays along the velocity find the slow side.
#[test]
fn e1_low_on_both_sides_of_its_peak_holds_the_truth() {
    let e1 = |v: f64| exact("e1", 1, v);
    let crossing = |mut rising: f64, mut falling: f64| {
        // `rising` is where e1 is below 0.395, `falling` where it is above.
        for _ in 0..50 {
            let middle = 0.5 * (rising + falling);
            if e1(middle) < 0.395 {
                rising = middle;
            } else {
                falling = middle;
            }
        }
        0.5 * (rising + falling)
    };
    let (low, high) = (crossing(0.012, 0.156), crossing(0.6, 0.156));
    assert!(e1(0.156) > 0.395 && (0.07..0.09).contains(&low) && (0.3..0.33).contains(&high));
    let (mean, sd) = (0.5 * (low + high), 0.025);
    let truth = standard_normal_cdf((low - mean) / sd) + standard_normal_cdf((mean - high) / sd);
    importance_holds(60, truth, |seed| {
        json!({
            "devices": 1, "operations": 1, "seed": seed,
            "scenario": {"circuit": {"supply_voltage_v": 48, "current_a": 15}},
            "scatter": [{"parameter": "impact_velocity_m_s", "per": "operation",
                         "distribution": {"kind": "normal", "mean": mean, "sd": sd, "min": 0.01}}],
            "metrics": ["e1"],
            "rare_event": {"metric": "e1", "below": 0.395}
        })
    });
}

/// A threshold no input within 11.5 standard deviations of the median reaches (below
/// probability 1e-30) is refused before the job runs, naming its field, above and below and for
/// the life; thresholds far out in the tail but within reach, at 1e-9 and 1e-20, are accepted.
#[test]
fn a_threshold_no_input_reaches_is_refused_before_the_job_runs() {
    let at = Pointer::root().child("rare_event");
    let refused = |job: &Job, pointer: &str, words: &str| {
        let refused = check_threshold(job, &at).unwrap_err();
        let error = &refused.errors()[0];
        assert_eq!(error.pointer, pointer, "{}", error.detail);
        assert!(error.detail.contains(words), "{}", error.detail);
    };
    let never_above = rare_job(
        "total_bounce_s",
        1,
        "operation",
        json!({"metric": "total_bounce_s", "above": 1.0}),
        1,
    );
    refused(
        &never_above,
        "/rare_event/above",
        "total_bounce_s never reaches above 1 in a search of the inputs within 11.5 standard \
         deviations",
    );
    let never_below = rare_job(
        "first_bounce_s",
        1,
        "operation",
        json!({"metric": "first_bounce_s", "below": 0.0}),
        1,
    );
    refused(&never_below, "/rare_event/below", "never reaches below 0");
    let never_fails = life_job(1.0, json!({"metric": "operations_to_failure", "below": 6}));
    refused(
        &never_fails,
        "/rare_event/below",
        "no device fails before operation 6",
    );
    for z in [5.997_807_015_007_688, 9.262_340_089_798_408] {
        let threshold = threshold_at("total_bounce_s", 1, z);
        let reachable = rare_job(
            "total_bounce_s",
            1,
            "operation",
            json!({"metric": "total_bounce_s", "above": threshold}),
            1,
        );
        assert_eq!(check_threshold(&reachable, &at), Ok(()), "z = {z}");
    }
}

#[test]
fn bad_rare_events_name_their_field() {
    let base = |rare: Value, scatter: Value, operations: u64| json!({"devices": 1, "operations": operations, "scatter": scatter, "rare_event": rare});
    let velocity = json!([{"parameter": "impact_velocity_m_s", "per": "operation",
        "distribution": {"kind": "normal", "mean": MEAN, "sd": SD, "min": 0.01}}]);
    let cases = [
        (
            json!({"metric": "total_bounce_s", "above": 0.02}),
            json!([]),
            1,
            "/rare_event",
        ),
        (
            json!({"metric": "total_bounce_s", "above": 0.02, "below": 0.01}),
            velocity.clone(),
            1,
            "/rare_event",
        ),
        (
            json!({"metric": "nope", "above": 0.02}),
            velocity.clone(),
            1,
            "/rare_event/metric",
        ),
        (
            json!({"metric": "total_bounce_s", "above": 0.02, "operation": 2}),
            velocity.clone(),
            1,
            "/rare_event/operation",
        ),
        // Only the operation: an operation of 0 was also told the job needs a scatter it has.
        (
            json!({"metric": "total_bounce_s", "above": 0.02, "operation": 0}),
            velocity.clone(),
            4,
            "/rare_event/operation",
        ),
        (
            json!({"metric": "cumulative_arc_energy_j", "above": 1, "operation": 1}),
            velocity.clone(),
            1,
            "/rare_event/operation",
        ),
        (
            json!({"metric": "total_bounce_s", "above": 0.02, "max_evaluations": 10}),
            velocity.clone(),
            1,
            "/rare_event/max_evaluations",
        ),
        (
            json!({"metric": "total_bounce_s", "above": 0.02, "target_cov": 0}),
            velocity.clone(),
            1,
            "/rare_event/target_cov",
        ),
        (
            json!({"metric": "total_bounce_s", "above": 0.02, "operation": 30,
                   "method": "importance"}),
            velocity.clone(),
            30,
            "/rare_event/method",
        ),
        (
            json!({"metric": "total_bounce_s", "above": 0.02, "operation": 6000}),
            velocity.clone(),
            6000,
            "/rare_event/operation",
        ),
        (
            json!({"metric": "operations_to_failure", "below": 5}),
            velocity.clone(),
            10,
            "/rare_event/metric",
        ),
    ];
    for (rare, scatter, operations, pointer) in cases {
        assert_eq!(
            pointers(base(rare.clone(), scatter, operations)),
            [pointer],
            "{rare}"
        );
    }
    // The life's event is failing before a whole number of operations.
    for (life, pointer) in [
        (
            json!({"metric": "operations_to_failure", "above": 5}),
            "/rare_event/above",
        ),
        (
            json!({"metric": "operations_to_failure", "below": 5.5}),
            "/rare_event/below",
        ),
        (
            json!({"metric": "operations_to_failure", "below": 12}),
            "/rare_event/below",
        ),
    ] {
        let value = json!({"devices": 1, "operations": 10, "scatter": velocity,
                           "failure": {"e1": {"below": 0.3}}, "rare_event": life});
        assert_eq!(pointers(value), [pointer], "{life}");
    }
    // The median device already beyond the threshold: not a rare event.
    let median = rare_job(
        "total_bounce_s",
        1,
        "operation",
        json!({"metric": "total_bounce_s", "above": 0.001}),
        1,
    );
    let refused = check_threshold(&median, &Pointer::root().child("rare_event")).unwrap_err();
    assert_eq!(refused.errors()[0].pointer, "/rare_event/above");
    assert!(refused.errors()[0].detail.contains("median inputs already"));
    // A median on the threshold is not beyond it: no circuit, no device arcs, and "above 0" is
    // an event no input reaches, said so (it was refused as "near one half", a probe); and a
    // number reads as one (1e-300, not 300 zeros after the point).
    for (above, said) in [(0.0, "above 0 in"), (1e-300, "above 1e-300 in")] {
        let never = job(json!({
            "devices": 1, "operations": 1,
            "scatter": [{"parameter": "impact_velocity_m_s", "per": "device",
                         "distribution": {"kind": "normal", "mean": 0.3, "sd": 0.03, "min": 0}}],
            "rare_event": {"metric": "pre_arc_s", "above": above}
        }));
        let refused = check_threshold(&never, &Pointer::root().child("rare_event")).unwrap_err();
        assert_eq!(refused.errors()[0].pointer, "/rare_event/above");
        let message = &refused.errors()[0].detail;
        let never_reaches = format!("pre_arc_s never reaches {said}");
        assert!(message.contains(&never_reaches), "{message}");
    }
    // A rare event counts against the job's size by the operations it may run.
    let sized = rare_job(
        "total_bounce_s",
        4,
        "operation",
        json!({"metric": "total_bounce_s", "above": 0.02, "operation": 3,
               "max_evaluations": 10_000}),
        1,
    );
    assert_eq!(sized.max_operations(), 4 + 30_000);
}

/// Several inputs (radius and hardness per device, correlated; the velocity per operation): the
/// rare-event estimate at operation 20 against the same job run crude, the threshold counted
/// exactly over 200,000 devices (P about 1.3e-3): the two intervals overlap.
#[test]
fn several_correlated_inputs_agree_with_the_jobs_crude_twin() {
    let threshold = 0.0155;
    let twin = |rare: Option<Value>, devices: u64| {
        let mut value = json!({
            "devices": devices, "operations": 20, "bin_operations": 1, "seed": 21,
            "scenario": {"circuit": {"supply_voltage_v": 48, "current_a": 15}},
            "scatter": [
                {"parameter": "contact_radius_m", "per": "device",
                 "distribution": {"kind": "normal", "mean": 7.7e-3, "sd": 0.8e-3, "min": 1e-3}},
                {"parameter": "dynamic_yield_pressure_pa", "per": "device",
                 "distribution": {"kind": "lognormal", "median": 2e8, "sigma": 0.15}},
                {"parameter": "impact_velocity_m_s", "per": "operation",
                 "distribution": {"kind": "normal", "mean": MEAN, "sd": SD, "min": 0.05}}],
            "correlation": {"parameters": ["contact_radius_m", "dynamic_yield_pressure_pa"],
                            "matrix": [[1, 0.5], [0.5, 1]]},
            "metrics": ["total_bounce_s"],
            "limits": {"total_bounce_s": [{"above": threshold}]}
        });
        if let Some(rare) = rare {
            value["rare_event"] = rare;
        }
        job(value)
    };
    let crude = run_on(2, &twin(None, 200_000));
    let counted = &crude.operations["total_bounce_s"]
        .last()
        .unwrap()
        .summary
        .exceedances;
    let counted = &counted[0];
    let found = report(&twin(
        Some(
            json!({"metric": "total_bounce_s", "above": threshold, "operation": 20,
                    "method": "subset", "target_cov": 0.1}),
        ),
        1,
    ));
    assert!(
        found.ci95[0] <= counted.ci95[1] && counted.ci95[0] <= found.ci95[1],
        "subset {found:?} against the crude twin {counted:?}"
    );
    // 22 inputs: 2 per device and one for each of the 20 operations.
    assert_eq!(found.design_point.len(), 22);
}

/// A budget spent before the first run ends says where the levels reached as the metric reads
/// (e1 of the mechanical rig is 0.507 at the mean velocity): a `below` event's level read as its
/// negation ("P(metric beyond -0.4579900885686343)", found
/// from outside).
#[test]
fn a_below_event_out_of_budget_says_its_level_below_the_metric() {
    let job = job(json!({
        "devices": 1, "operations": 1, "seed": 3,
        "scatter": [{"parameter": "impact_velocity_m_s", "per": "device",
                     "distribution": {"kind": "normal", "mean": 0.224, "sd": 0.02, "min": 0.05}}],
        "metrics": ["e1"],
        "rare_event": {"metric": "e1", "below": 0.43, "method": "subset", "max_evaluations": 2000}
    }));
    let failed = estimate(&job, &Silent).unwrap_err().to_string();
    assert!(
        failed.contains("ran out")
            && failed.contains("P(metric below 0.4")
            && !failed.contains("-0."),
        "{failed}"
    );
}

/// A subset run that runs out of `max_evaluations` part-way leaves the runs before it standing:
/// the answer is their mean, not a failed job (a probe: at 2e-12 this failed 10 jobs of 200,
/// after some 17 runs each).
#[test]
fn a_budget_spent_in_a_later_run_keeps_the_runs_before_it() {
    let threshold = 0.6;
    let truth = standard_normal_cdf(-(threshold / 0.3f64).ln() / 0.1);
    let job = job(json!({
        "devices": 2, "operations": 1, "seed": 3,
        "scatter": [{"parameter": "impact_velocity_m_s", "per": "device",
                     "distribution": {"kind": "lognormal", "median": 0.3, "sigma": 0.1}}],
        "metrics": ["impact_velocity_m_s"],
        "rare_event": {"metric": "impact_velocity_m_s", "above": threshold, "method": "subset"}
    }));
    let found = report(&job);
    assert!(found.evaluations <= 200_000, "{found:?}");
    assert!(
        found.ci95[0] <= truth && truth <= found.ci95[1],
        "{found:?} against {truth}"
    );
}

/// Importance sampling forced on an event of several operations' scattered inputs is warned of
/// in the Result's diagnostics (its interval covers less than it claims there, measured from
/// outside); `auto`, which takes subset simulation there, and importance sampling on one
/// operation's or the device's inputs are not.
#[test]
fn forced_importance_over_several_operations_is_warned_of() {
    let rare_job = |per: &str, method: &str| {
        job(json!({
            "devices": 4, "operations": 20,
            "scatter": [{"parameter": "impact_velocity_m_s", "per": per,
                         "distribution": {"kind": "normal", "mean": MEAN, "sd": SD, "min": 0.05}}],
            "metrics": ["cumulative_plastic_work_j"],
            "rare_event": {"metric": "cumulative_plastic_work_j", "above": 0.0107,
                           "method": method}
        }))
    };
    let warned = |job: &Job| {
        bouncewear_model::montecarlo::rare::forced_importance(job).map(|d| (d.pointer, d.detail))
    };
    let (pointer, detail) = warned(&rare_job("operation", "importance")).unwrap();
    assert_eq!(pointer, "/rare_event/method");
    assert!(
        detail.contains("`auto` takes subset simulation here"),
        "{detail}"
    );
    for (per, method) in [
        ("operation", "auto"),
        ("operation", "subset"),
        ("device", "importance"),
    ] {
        assert_eq!(warned(&rare_job(per, method)), None, "{per} {method}");
    }
}
