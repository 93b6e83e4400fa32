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

/// The pointers of the faults `value` has as a job (none when it is valid).
#[allow(dead_code, reason = "not every test file checks faults")]
pub fn pointers(value: Value) -> Vec<String> {
    match Job::from_json(&value.to_string(), || 7) {
        Ok(_) => Vec::new(),
        Err(invalid) => invalid.errors().iter().map(|e| e.pointer.clone()).collect(),
    }
}
