//! Every kernel (instruction set and number of lanes this CPU has) gives the same bits: lockstep
//! batches against one device at a time, on whole jobs and on single operations.

use bouncewear_model::lanes::Lanes;
use bouncewear_model::montecarlo::{Job, Kernel, Silent, run_job_on};
use bouncewear_model::{Fidelity, Needs, Operation, Outcome, Scenario};
use proptest::prelude::*;
use serde_json::{Value, json};

const JOBS: &str = include_str!("../../../tests/data/reference_jobs.json");

/// The Result without its timing, as text: equal text is equal bits (floats round-trip).
fn result_text(kernel: Kernel, spec: &Value) -> String {
    let job = Job::from_json(&spec.to_string(), || 0).unwrap();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(2)
        .build()
        .unwrap();
    let result = pool.install(|| run_job_on(kernel, &job, &Silent)).unwrap();
    let mut value = serde_json::to_value(result).unwrap();
    value.as_object_mut().unwrap().remove("timing");
    value.to_string()
}

fn jobs() -> Vec<Value> {
    let reference: Value = serde_json::from_str(JOBS).unwrap();
    let mut jobs: Vec<Value> = ["48 V / 15 A", "mechanical"]
        .iter()
        .map(|name| {
            let mut job = reference[name].clone();
            // 37 devices: batches of every width leave a remainder that runs one by one.
            job["devices"] = json!(37);
            job["operations"] = json!(60);
            job
        })
        .collect();
    // 202 devices, groups of 6 and 7: with 8 lanes, one batch with spare lanes per group; with 4,
    // a full batch and one with spare lanes. The velocity's window rejects about a quarter of its
    // draws, and only the devices' rejections may count, not the spare lanes'.
    let mut spare = reference["mechanical"].clone();
    spare["devices"] = json!(202);
    spare["operations"] = json!(12);
    let velocity = &mut spare["scatter"][2];
    assert_eq!(velocity["parameter"], "impact_velocity_m_s");
    velocity["distribution"]["min"] = json!(0.21);
    jobs.push(spare);
    // 320 devices, groups of 10: on 32 lanes three groups share a batch, each counting its values
    // a batch at a time, where the groups of one and two of 37 devices count one at a time.
    let mut shared = reference["48 V / 15 A"].clone();
    shared["devices"] = json!(320);
    shared["operations"] = json!(12);
    shared["limits"] = json!({"e1": 0.5});
    jobs.push(shared);
    // Failure criteria, limits, wear that softens, Latin hypercube strata.
    let mut wearing = reference["48 V / 15 A"].clone();
    wearing["devices"] = json!(40);
    wearing["operations"] = json!(50);
    wearing["sampler"] = json!("lhs");
    wearing["scenario"]["material"] = json!({"wear_law": {"law": "roughening_and_softening"}});
    // Softening needs a pressure above its floor, which a lognormal does not keep.
    wearing["scatter"].as_array_mut().unwrap().remove(1);
    wearing["failure"] = json!({"total_bounce_s": {"above": 2e-3}});
    wearing["limits"] = json!({"e1": 0.5});
    jobs.push(wearing);
    // A scattered current changes the operation's constants: no lockstep, one device at a time.
    let mut current = reference["48 V / 15 A"].clone();
    current["devices"] = json!(20);
    current["operations"] = json!(30);
    current["fidelity"] = json!("closed_form");
    current["scatter"].as_array_mut().unwrap().push(json!(
        {"parameter": "current_a", "per": "device",
         "distribution": {"kind": "uniform", "min": 2, "max": 20}}
    ));
    jobs.push(current);
    jobs
}

#[test]
fn every_kernel_on_this_cpu_gives_the_bits_of_one_device_at_a_time() {
    let kernels = Kernel::all();
    assert!(
        kernels.len() >= 2,
        "one device at a time and the portable lockstep kernel at least: {kernels:?}"
    );
    for spec in jobs() {
        let scalar = result_text(Kernel::SCALAR, &spec);
        if spec["devices"] == 202 {
            assert!(
                scalar.contains("truncation_rejections"),
                "the spare-lane job rejects draws: {scalar}"
            );
        }
        for &kernel in &kernels {
            assert!(
                result_text(kernel, &spec) == scalar,
                "{kernel:?} differs from one device at a time on {spec}"
            );
        }
    }
}

/// A group's last devices, too few for a kernel's lanes, fall to the narrower kernels: each
/// kernel lists itself first, then the narrower ones of this CPU, widest first, never one device
/// at a time (whose bits they all give, above).
#[test]
fn a_kernel_falls_back_to_narrower_kernels_widest_first() {
    assert!(Kernel::SCALAR.narrower().is_empty());
    for kernel in Kernel::all().into_iter().filter(|k| k.lanes() > 1) {
        let narrower = kernel.narrower();
        assert_eq!(narrower[0], kernel, "{narrower:?}");
        assert!(
            narrower.windows(2).all(|w| w[0].lanes() > w[1].lanes()),
            "{narrower:?}"
        );
        assert!(
            narrower
                .iter()
                .all(|k| 1 < k.lanes() && k.lanes() <= kernel.lanes()),
            "{narrower:?}"
        );
    }
}

const SCENARIOS: [&str; 4] = [
    "{}",
    r#"{"circuit": {"supply_voltage_v": 48, "current_a": 15}}"#,
    r#"{"circuit": {"supply_voltage_v": 48, "current_a": 5},
        "material": {"arc_restitution": {"law": "continuous"}}}"#,
    r#"{"mechanism": {"static_force_n": 0.05}, "losses": {"max_bounces": 3}}"#,
];

proptest! {
    /// 32 lanes: the bounce loop moves its last eight or fewer bouncing lanes into a batch of
    /// eight and finishes there.
    #[test]
    fn a_lane_of_a_lockstep_operation_is_the_operation_run_alone(
        scenario in 0..SCENARIOS.len(),
        closed_form in any::<bool>(),
        speeds in prop::array::uniform32(prop_oneof![Just(0.0), 1e-4..2.0f64]),
        radii in prop::array::uniform32(1e-3..2e-2f64),
        pressures in prop::array::uniform32(5e7..5e8f64),
    ) {
        let fidelity = if closed_form { Fidelity::ClosedForm } else { Fidelity::Exact };
        let mut operation =
            Operation::nominal(&Scenario::from_json(SCENARIOS[scenario]).unwrap(), fidelity);
        let mut bounces = vec![Vec::new(); 32];
        let outcomes = operation.run_lanes(
            Lanes(speeds),
            Lanes(radii),
            Lanes(pressures),
            Needs::ALL,
            |lane, v, duration_s, arc_energy_j| {
                bounces[lane].push((v.to_bits(), duration_s.to_bits(), arc_energy_j.to_bits()));
            },
        );
        for i in 0..32 {
            operation.set_impact_velocity(speeds[i]);
            let mut list = Vec::new();
            let alone: Outcome = operation.run(radii[i], pressures[i], Needs::ALL, Some(&mut list));
            let lane = outcomes.lane(i);
            prop_assert_eq!(format!("{lane:?}"), format!("{alone:?}"), "lane {}", i);
            let alone_bounces: Vec<_> = list
                .iter()
                .map(|b| {
                    (
                        b.separation_velocity_m_s.to_bits(),
                        b.duration_s.to_bits(),
                        b.arc_energy_j.to_bits(),
                    )
                })
                .collect();
            prop_assert_eq!(&bounces[i], &alone_bounces, "lane {}", i);
        }
    }
}
