//! Whole jobs on one thread: the reference jobs of `tests/data/reference_jobs.json` (radius and
//! hardness scattered per device, closing velocity per operation, every metric), 48 V / 15 A and
//! mechanical. Divan reports the
//! time per job and, through the item counter, per operation.
//!
//! `cargo bench -p bouncewear-model --bench engine`

use bouncewear_model::montecarlo::{Job, Silent, run_job};
use divan::{Bencher, black_box, counter::ItemsCount};
use serde_json::Value;

fn main() {
    divan::main();
}

const JOBS: &str = include_str!("../../tests/data/reference_jobs.json");

/// The reference job of `scenario` as `tests/data/reference_jobs.json` gives it: 2000 devices x 500
/// operations.
fn reference_job(scenario: &str) -> (Job, u64) {
    let jobs: Value = serde_json::from_str(JOBS).expect("the reference jobs are JSON");
    let job =
        Job::from_json(&jobs[scenario].to_string(), || 0).expect("the reference job is valid");
    let operations = job.spec().devices * job.spec().operations;
    (job, operations)
}

#[divan::bench(args = ["48 V / 15 A", "mechanical"], sample_count = 5, sample_size = 1)]
fn job_on_one_thread(bencher: Bencher, scenario: &str) {
    let (job, operations) = reference_job(scenario);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("a pool of one thread");
    bencher
        .counter(ItemsCount::new(operations))
        .bench_local(|| pool.install(|| run_job(black_box(&job), &Silent)));
}
