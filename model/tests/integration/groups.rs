//! A job's groups run one at a time, each alone (as separate machines would run them), serialised,
//! read back and put together in batch and group order give the Result of running the job whole,
//! to the bit: for a precision target too, whose batches are decided one after the other.

use bouncewear_model::montecarlo::engine::{Batch, GroupStats, run_group};
use bouncewear_model::montecarlo::{Job, Silent, Tally, next_batch, run_job, summarize_job};
use serde_json::Value;

/// The Result of running `job` group by group, every group's state through JSON and back, in
/// reverse group order (machines finish in any order).
fn run_group_by_group(job: &Job) -> Value {
    let mut tally = Tally::new();
    let mut next = Batch::of(job, 0);
    while let Some(batch) = next {
        let mut groups: Vec<GroupStats> = (0..batch.groups())
            .rev()
            .map(|group| {
                let stats = run_group(job, batch, group, &Silent).unwrap();
                let text = serde_json::to_string(&stats).unwrap();
                let back: GroupStats = serde_json::from_str(&text).unwrap();
                assert_eq!(back, stats, "group {group} survives serialisation exactly");
                back
            })
            .collect();
        groups.reverse();
        tally.add_batch(batch, groups);
        next = next_batch(job, &tally);
    }
    without_timing(serde_json::to_value(summarize_job(job, &tally, 1.0)).unwrap())
}

fn without_timing(mut result: Value) -> Value {
    result.as_object_mut().unwrap().remove("timing");
    result
}

fn assert_group_by_group_is_whole(text: &str) {
    let job = Job::from_json(text, || 0).unwrap();
    let whole = without_timing(serde_json::to_value(run_job(&job, &Silent).unwrap()).unwrap());
    assert_eq!(run_group_by_group(&job), whole, "{text}");
}

#[test]
fn a_wearing_job_with_scatter_limits_and_failure_criteria() {
    assert_group_by_group_is_whole(
        r#"{"devices": 70, "operations": 60, "seed": 11,
            "scenario": {"circuit": {"supply_voltage_v": 48, "current_a": 15}},
            "scatter": [
              {"parameter": "contact_radius_m", "per": "device",
               "distribution": {"kind": "normal", "mean": 7.7e-3, "sd": 1.5e-3, "min": 1e-3}},
              {"parameter": "impact_velocity_m_s", "per": "operation",
               "distribution": {"kind": "normal", "mean": 0.224, "sd": 0.02, "min": 0.05}}],
            "limits": {"total_bounce_s": 0.011},
            "failure": {"e1": {"below": 0.33}}}"#,
    );
}

#[test]
fn a_sensitivity_analysis_over_both_levels_and_a_scenario_constant() {
    assert_group_by_group_is_whole(
        r#"{"devices": 50, "operations": 12, "bin_operations": 4, "seed": 5, "sampler": "lhs",
            "scenario": {"circuit": {"supply_voltage_v": 48, "current_a": 15}},
            "scatter": [
              {"parameter": "contact_radius_m", "per": "device",
               "distribution": {"kind": "normal", "mean": 7.7e-3, "sd": 1.5e-3, "min": 1e-3}},
              {"parameter": "inertia_kg_m2", "per": "device",
               "distribution": {"kind": "uniform", "min": 1.4e-5, "max": 1.8e-5}},
              {"parameter": "impact_velocity_m_s", "per": "operation",
               "distribution": {"kind": "normal", "mean": 0.224, "sd": 0.02, "min": 0.05}}],
            "sensitivity": {"method": "sobol"}}"#,
    );
}

#[test]
fn a_latin_hypercube_job_whose_groups_share_one_permutation() {
    assert_group_by_group_is_whole(
        r#"{"devices": 45, "operations": 20, "seed": 3, "sampler": "lhs",
            "scatter": [
              {"parameter": "dynamic_yield_pressure_pa", "per": "device",
               "distribution": {"kind": "lognormal", "median": 2e8, "sigma": 0.15}}]}"#,
    );
}

#[test]
fn a_softening_job_with_plastic_work_and_the_anode_cathode_split() {
    assert_group_by_group_is_whole(
        r#"{"devices": 40, "operations": 25, "seed": 5,
            "scenario": {"circuit": {"supply_voltage_v": 48, "current_a": 15},
                         "material": {"wear_law": {"law": "roughening_and_softening"},
                                      "anode_erosion_fraction": 0.7,
                                      "arc_restitution": {"law": "continuous"}}},
            "scatter": [
              {"parameter": "current_a", "per": "device",
               "distribution": {"kind": "uniform", "min": 2, "max": 20}}],
            "metrics": ["first_impact_plastic_work_j", "total_bounce_s", "cumulative_plastic_work_j",
                        "anode_eroded_mass_kg", "cathode_eroded_mass_kg", "final_kappa"],
            "failure": {"cumulative_plastic_work_j": {"above": 0.009}}}"#,
    );
}

#[test]
fn fewer_devices_than_groups_and_a_metric_subset() {
    assert_group_by_group_is_whole(
        r#"{"devices": 5, "operations": 30, "seed": 9, "metrics": ["total_bounce_s", "bounce_count"]}"#,
    );
}

#[test]
fn an_empty_accumulator_keeps_its_infinite_extremes_through_json() {
    use bouncewear_model::stats::Accumulator;
    for limit in [None, Some(0.011)] {
        let empty = Accumulator::new(limit);
        let text = serde_json::to_string(&empty).unwrap();
        let back: Accumulator = serde_json::from_str(&text).unwrap();
        assert_eq!(back, empty, "{text}");
    }
}

#[test]
fn a_precision_target_adds_batches_one_after_the_other_the_last_one_cut() {
    let text = r#"{"devices": 40, "operations": 10, "seed": 5,
        "scatter": [{"parameter": "impact_velocity_m_s", "per": "device",
                     "distribution": {"kind": "normal", "mean": 0.3, "sd": 0.05, "min": 0.05}}],
        "precision": {"metric": "total_bounce_s", "relative_half_width": 0.002, "max_devices": 130}}"#;
    let job = Job::from_json(text, || 0).unwrap();
    let whole = run_job(&job, &Silent).unwrap();
    assert_eq!(
        whole.job.devices_run(),
        130,
        "the target is out of reach: every batch runs, the last one cut to 10 devices"
    );
    assert_group_by_group_is_whole(text);
}

#[test]
fn batches_cover_the_devices_once_and_groups_cut_them_contiguously() {
    let job = Job::from_json(
        r#"{"devices": 50, "operations": 2,
            "precision": {"metric": "e1", "relative_half_width": 0.1, "max_devices": 120}}"#,
        || 0,
    )
    .unwrap();
    let batches: Vec<Batch> = (0..).map_while(|i| Batch::of(&job, i)).collect();
    assert_eq!(
        batches
            .iter()
            .map(|b| (b.first, b.size))
            .collect::<Vec<_>>(),
        [(0, 50), (50, 50), (100, 20)]
    );
    for batch in batches {
        let devices: Vec<u64> = (0..batch.groups())
            .flat_map(|g| batch.group_devices(g))
            .collect();
        assert_eq!(
            devices,
            (batch.first..batch.first + batch.size).collect::<Vec<_>>()
        );
    }
}

/// `run_job` keeps no extremes for queries after the run (`engine::run_for_result`); the groups
/// above keep them. Thresholds counted as the job runs, limits and quantiles come out the same.
#[test]
fn thresholds_and_limits_without_the_extremes_kept_for_later_queries() {
    assert_group_by_group_is_whole(
        r#"{"devices": 64, "operations": 40, "seed": 17, "bin_operations": 20,
            "scenario": {"circuit": {"supply_voltage_v": 48, "current_a": 15}},
            "scatter": [
              {"parameter": "impact_velocity_m_s", "per": "operation",
               "distribution": {"kind": "normal", "mean": 0.224, "sd": 0.02, "min": 0.05}}],
            "limits": {"total_bounce_s": [{"above": 0.0125}, {"below": 0.0105}],
                       "arc_energy_j": 0.05,
                       "final_radius_m": [{"below": 7.69e-3}]}}"#,
    );
}
