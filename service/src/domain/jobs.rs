//! The rules of a job that the model does not know: where a missing seed comes from, what a queued
//! job holds, and the states a job goes through.

use super::{JobId, Owner, ShardPlan, UnixMs, first_shards};
use bouncewear_model::montecarlo::{Job, JobSpec};
use rand::RngExt;
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

/// A seed for a job that does not give one: from the operating system's entropy, reported in the
/// result. Below 2^53, so that every JSON client (JavaScript's numbers included) reads it exactly;
/// a user may still give any u64.
pub fn draw_seed() -> u64 {
    rand::rng().random::<u64>() >> 11
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum JobStatus {
    Queued,
    Running,
    Succeeded,
    Failed,
    Cancelled,
}

impl JobStatus {
    pub const ALL: [JobStatus; 5] = [
        Self::Queued,
        Self::Running,
        Self::Succeeded,
        Self::Failed,
        Self::Cancelled,
    ];

    pub fn as_str(self) -> &'static str {
        match self {
            JobStatus::Queued => "queued",
            JobStatus::Running => "running",
            JobStatus::Succeeded => "succeeded",
            JobStatus::Failed => "failed",
            JobStatus::Cancelled => "cancelled",
        }
    }

    pub fn parse(text: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|s| s.as_str() == text)
    }

    pub fn is_terminal(self) -> bool {
        matches!(
            self,
            JobStatus::Succeeded | JobStatus::Failed | JobStatus::Cancelled
        )
    }
}

/// How many jobs may wait in the queue: `total` in all, and `per_owner` of any one owner (API
/// key), so that one key cannot fill the queue and lock every other key out; and none while the
/// disk beside a SQLite database has less than `min_free_disk_bytes` free, so that jobs already
/// taken can still store their Results and old ones can be deleted; and none of an owner whose
/// jobs store `stored_per_owner` bytes or more (their `stored_bytes`), so that one key cannot
/// take the disk every key shares.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct QueueBound {
    pub total: u64,
    pub per_owner: u64,
    pub min_free_disk_bytes: u64,
    pub stored_per_owner: Option<u64>,
}

impl QueueBound {
    /// `total` jobs, any owner may queue them all, whatever the free disk and stored bytes.
    pub fn total(total: u64) -> Self {
        Self {
            total,
            per_owner: total,
            min_free_disk_bytes: 0,
            stored_per_owner: None,
        }
    }
}

/// A validated job ready for the queue: its seed is fixed, so that every attempt to run it (after
/// a crash, on another machine) gives the same numbers.
#[derive(Debug, Clone, PartialEq)]
pub struct QueuedJob {
    pub id: JobId,
    pub owner: Owner,
    pub name: Option<String>,
    /// The job as validated, with the seed written in.
    pub spec: JobSpec,
    pub seed: u64,
    /// Devices x operations (a precision target may run more devices).
    pub operations_total: u64,
    pub created_at: UnixMs,
    /// The shards it enters the queue with: its first batch's.
    pub shards: Vec<ShardPlan>,
}

impl QueuedJob {
    /// The one way a job enters the queue, whether a client submitted it or a schedule made it.
    pub fn new(job: &Job, owner: Owner, name: Option<String>, created_at: UnixMs) -> Self {
        Self {
            id: JobId::generate(),
            owner,
            name,
            spec: job.spec().clone(),
            seed: job.seed(),
            operations_total: job.spec().devices.saturating_mul(job.spec().operations),
            created_at,
            shards: first_shards(job),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn drawn_seeds_are_exact_in_every_json_client() {
        assert!((0..1000).all(|_| draw_seed() < 1 << 53));
    }

    #[test]
    fn a_queued_job_carries_its_seed_in_the_spec() {
        let job = Job::from_json(r#"{"devices": 3, "operations": 4}"#, || 7).unwrap();
        let queued = QueuedJob::new(&job, Owner::anonymous(), None, UnixMs(1));
        assert_eq!((queued.seed, queued.spec.seed), (7, Some(7)));
        assert_eq!(queued.operations_total, 12);
    }

    #[test]
    fn statuses_read_back_as_written() {
        for status in JobStatus::ALL {
            assert_eq!(JobStatus::parse(status.as_str()), Some(status));
        }
        assert_eq!(JobStatus::parse("paused"), None);
    }
}
