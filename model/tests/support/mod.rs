//! What the Monte Carlo test files share: a valid job from JSON, and a run on a pool of a given size.

use bouncewear_model::montecarlo::{Job, JobResult, Silent, run_job};
use serde_json::Value;

/// The job `value` describes, which must be valid (a missing seed is 7).
pub fn job(value: Value) -> Job {
    Job::from_json(&value.to_string(), || 7).expect("valid job")
}

/// Runs `job` on a pool of `threads` threads.
pub fn run_on(threads: usize, job: &Job) -> JobResult {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    pool.install(|| run_job(job, &Silent)).unwrap()
}
