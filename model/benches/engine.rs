//! Whole jobs on one thread: the reference jobs of `tests/data/reference_jobs.json` (radius and
//! hardness scattered per device, closing velocity per operation, every metric), 48 V / 15 A and
//! mechanical. Divan reports the
//! time per job and, through the item counter, per operation; then the same jobs as the service
//! runs them, keeping each group's extremes for queries after the run. Then the service's small
//! job, its run and its summaries apart.
//!
//! `cargo bench -p bouncewear-model --bench engine`, once per kernel this CPU runs.

use bouncewear_model::montecarlo::engine::{run, run_on};
use bouncewear_model::montecarlo::{Job, Kernel, Silent, run_job_on, summarize_job};
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

/// Every kernel this CPU runs, by name.
fn kernels() -> Vec<String> {
    Kernel::all()
        .into_iter()
        .map(|k| format!("{} x{}", k.isa().as_str(), k.lanes()))
        .collect()
}

fn kernel(name: &str) -> Kernel {
    Kernel::all()
        .into_iter()
        .find(|k| format!("{} x{}", k.isa().as_str(), k.lanes()) == name)
        .expect("a kernel of this CPU")
}

fn job_on_one_thread(bencher: Bencher, scenario: &str, kernel_name: &str) {
    let (job, operations) = reference_job(scenario);
    let (kernel, pool) = (kernel(kernel_name), one_thread());
    bencher
        .counter(ItemsCount::new(operations))
        .bench_local(|| pool.install(|| run_job_on(kernel, black_box(&job), &Silent)));
}

#[divan::bench(args = kernels(), sample_count = 5, sample_size = 1)]
fn arcing_48v_15a(bencher: Bencher, kernel: &str) {
    job_on_one_thread(bencher, "48 V / 15 A", kernel);
}

#[divan::bench(args = kernels(), sample_count = 5, sample_size = 1)]
fn mechanical(bencher: Bencher, kernel: &str) {
    job_on_one_thread(bencher, "mechanical", kernel);
}

/// The reference job of `scenario` on one thread on the active kernel as the service runs it:
/// every group keeping its most extreme values for thresholds asked after the run
/// (`engine::run_on`), which `run_job_on` leaves out (its Result reads none of them); then
/// summarised, to the same Result.
fn job_keeping_tails(bencher: Bencher, scenario: &str) {
    let (job, operations) = reference_job(scenario);
    let (kernel, pool) = (Kernel::active(), one_thread());
    bencher
        .counter(ItemsCount::new(operations))
        .bench_local(|| {
            pool.install(|| {
                let tally =
                    run_on(kernel, black_box(&job), &Silent, |_| false).expect("not cancelled");
                summarize_job(&job, &tally, 0.0)
            })
        });
}

#[divan::bench(sample_count = 5, sample_size = 1)]
fn arcing_48v_15a_keeping_tails(bencher: Bencher) {
    job_keeping_tails(bencher, "48 V / 15 A");
}

#[divan::bench(sample_count = 5, sample_size = 1)]
fn mechanical_keeping_tails(bencher: Bencher) {
    job_keeping_tails(bencher, "mechanical");
}

/// The service's small job, `{"devices": 100, "operations": 100}` (the default scenario, every
/// metric), on one thread: the run alone, and the summaries of its 32 groups alone, the two
/// parts of a small job's compute that `tools/http_bench.py` times end to end.
fn small_job() -> Job {
    Job::from_json(r#"{"devices": 100, "operations": 100, "seed": 1}"#, || 0)
        .expect("the small job is valid")
}

fn one_thread() -> rayon::ThreadPool {
    rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("a pool of one thread")
}

#[divan::bench(sample_count = 200)]
fn small_job_run(bencher: Bencher) {
    let (job, pool) = (small_job(), one_thread());
    bencher.bench_local(|| pool.install(|| run(black_box(&job), &Silent, |_| true)));
}

#[divan::bench(sample_count = 200)]
fn small_job_summaries(bencher: Bencher) {
    let (job, pool) = (small_job(), one_thread());
    let tally = pool
        .install(|| run(&job, &Silent, |_| true))
        .expect("not cancelled");
    bencher.bench_local(|| pool.install(|| summarize_job(black_box(&job), &tally, 0.0)));
}
