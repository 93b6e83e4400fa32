//! How a job is cut for many workers: each batch of devices into its groups (the engine's unit of
//! independent work, at most 32), plus one merge step per batch. Any worker on any machine runs any
//! group, alone, under its own lease; the merge step, claimable once the batch's groups are done,
//! puts their accumulators back in group order and either stores the Result or, for a precision
//! target not yet met, adds the next batch. Results are bit-identical to running the job whole.

use bouncewear_model::montecarlo::engine::{Batch, GroupStats};
use bouncewear_model::montecarlo::rare::{RareEventError, estimate};
use bouncewear_model::montecarlo::{
    Cancelled, Job, JobResult, Observer, RunError, RunGroups, Tally, next_batch, summarize_job,
};
use serde::Serialize;
use std::fmt;
use utoipa::ToSchema;

/// One shard of a job: a group of a batch, or that batch's merge step.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, ToSchema)]
pub struct ShardId {
    pub batch: u64,
    /// The group within the batch; `None` for the batch's merge step.
    pub group: Option<u64>,
}

impl ShardId {
    pub fn group(batch: u64, group: u64) -> Self {
        Self {
            batch,
            group: Some(group),
        }
    }

    pub fn merge(batch: u64) -> Self {
        Self { batch, group: None }
    }
}

impl fmt::Display for ShardId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.group {
            Some(group) => write!(f, "batch {} group {group}", self.batch),
            None => write!(f, "batch {} merge", self.batch),
        }
    }
}

/// A shard to be queued, with the operations it runs (none for a merge step).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ShardPlan {
    pub shard: ShardId,
    pub operations: u64,
}

/// The shards of one batch: its groups in order, then its merge step.
pub fn batch_shards(job: &Job, batch: Batch) -> Vec<ShardPlan> {
    let operations = job.spec().operations;
    (0..batch.groups())
        .map(|group| {
            let devices = batch.group_devices(group);
            ShardPlan {
                shard: ShardId::group(batch.index, group),
                operations: (devices.end - devices.start).saturating_mul(operations),
            }
        })
        .chain([ShardPlan {
            shard: ShardId::merge(batch.index),
            // The last merge estimates the job's rare event, if it asks one.
            operations: job.rare_event().map_or(0, |rare| rare.max_operations()),
        }])
        .collect()
}

/// The shards a job enters the queue with: those of its first batch.
pub fn first_shards(job: &Job) -> Vec<ShardPlan> {
    let first = Batch::of(job, 0).expect("a valid job runs at least one device");
    batch_shards(job, first)
}

/// What a batch's merge step leads to.
#[derive(Debug)]
pub enum Merged {
    /// The job is done: its Result, and the final groups' accumulators of each of its (metric,
    /// bin), kept for queries after the run.
    Result {
        result: Box<JobResult>,
        groups: RunGroups,
    },
    /// A precision target is not met yet: the next batch's shards, to queue, and the groups of
    /// every batch so far folded into one set (group `i` of each batch merged into group `i`, in
    /// batch order, as [`Tally::add_batch`] does), to store in place of theirs: a job's stored
    /// accumulators, and what a merge reads, stay those of two batches however many it runs.
    Next {
        shards: Vec<ShardPlan>,
        folded: Vec<GroupStats>,
    },
}

/// Stored accumulators that do not make up the batches they should.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("the stored groups of batch {batch} do not make it up: {detail}")]
pub struct Incomplete {
    pub batch: u64,
    pub detail: String,
}

/// Why a merge step gave neither a Result nor a next batch.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum MergeError {
    /// The store's groups are not the job's: worth another attempt.
    #[error(transparent)]
    Incomplete(#[from] Incomplete),
    /// The job's rare event has no answer (the same on every attempt).
    #[error(transparent)]
    RareEvent(#[from] RareEventError),
    #[error(transparent)]
    Cancelled(#[from] Cancelled),
}

/// The merge step of batch `last`: puts every done group of batches `0..=last` back in batch and
/// group order (`partials` as the store lists them) and decides as [`run_job`] does after that
/// batch: the Result, after `wall_s` seconds of running, or the next batch. The first batch
/// listed may be the fold of every batch up to it ([`Merged::Next`]); the sequence of merges, and
/// so every bit, is the same as from each batch's own groups.
///
/// [`run_job`]: bouncewear_model::montecarlo::run_job
pub fn merge(
    job: &Job,
    last: u64,
    partials: Vec<(ShardId, GroupStats)>,
    wall_s: f64,
    observer: &dyn Observer,
) -> Result<Merged, MergeError> {
    let mut tally = Tally::new();
    let mut partials = partials.into_iter().peekable();
    // Batches before the first listed were folded into it: it stands for all of them.
    let first = partials
        .peek()
        .map_or(0, |(shard, _)| shard.batch.min(last));
    for index in first..=last {
        let incomplete = |detail: String| Incomplete {
            batch: index,
            detail,
        };
        let batch = Batch::of(job, index)
            .ok_or_else(|| incomplete("the job runs no such batch".to_owned()))?;
        let mut groups = Vec::new();
        while let Some((shard, stats)) = partials.next_if(|(shard, _)| shard.batch == index) {
            let expected = ShardId::group(index, groups.len() as u64);
            if shard != expected {
                return Err(incomplete(format!("found {shard} where {expected} belongs")).into());
            }
            groups.push(stats);
        }
        if groups.len() as u64 != batch.groups() {
            let detail = format!(
                "{} of its {} groups are stored",
                groups.len(),
                batch.groups()
            );
            return Err(incomplete(detail).into());
        }
        if index == first && first > 0 {
            tally = Tally {
                groups,
                devices: batch.first + batch.size,
            };
        } else {
            tally.add_batch(batch, groups);
        }
    }
    if let Some((shard, _)) = partials.peek() {
        return Err(Incomplete {
            batch: shard.batch,
            detail: format!("{shard} is stored after batch {last}'s merge"),
        }
        .into());
    }
    Ok(match next_batch(job, &tally) {
        Some(batch) => Merged::Next {
            shards: batch_shards(job, batch),
            folded: tally.groups,
        },
        None => {
            let started = std::time::Instant::now();
            let rare_event = estimate(job, observer).map_err(|error| match error {
                RunError::Cancelled(cancelled) => MergeError::Cancelled(cancelled),
                RunError::RareEvent(failed) => MergeError::RareEvent(failed),
            })?;
            let mut result = summarize_job(job, &tally, wall_s + started.elapsed().as_secs_f64());
            result.rare_event = rare_event;
            Merged::Result {
                result: Box::new(result),
                groups: RunGroups::new(job, tally),
            }
        }
    })
}

/// What a shard costs beyond its operations, in operations, for fair share: a claim and a store
/// take about as long as simulating this many (1-2 ms each on SQLite at 5-10 M operations/s per
/// thread), so a job of many tiny shards is charged for them and cannot crowd out a large one.
pub const SHARD_OVERHEAD_OPERATIONS: i64 = 10_000;

/// How often a shard may be run again before its job fails: after runs that failed (the job's own
/// error, each retried after a backoff) and, apart, after leases lost (its worker killed or
/// stalled, or the database out of its reach: nothing wrong with the job).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RetryBudget {
    pub failures: u64,
    pub lost_leases: u64,
}

/// The wait before a shard whose run failed `failures` times is claimed again: 1 s, doubling, at
/// most a minute.
pub fn retry_backoff_ms(failures: u64) -> i64 {
    (1000_i64 << failures.saturating_sub(1).min(6)).min(60_000)
}

#[cfg(test)]
mod tests {
    #[test]
    fn a_failed_run_waits_one_second_doubling_to_a_minute() {
        let waits: Vec<i64> = (0..=9).map(super::retry_backoff_ms).collect();
        assert_eq!(
            waits,
            [
                1000, 1000, 2000, 4000, 8000, 16_000, 32_000, 60_000, 60_000, 60_000
            ]
        );
        assert_eq!(super::retry_backoff_ms(u64::MAX), 60_000);
    }

    use super::*;

    #[test]
    fn a_batch_is_its_groups_and_a_merge_and_the_groups_share_its_operations() {
        let job = Job::from_json(r#"{"devices": 70, "operations": 3}"#, || 1).unwrap();
        let shards = first_shards(&job);
        assert_eq!(shards.len(), 33);
        assert_eq!(shards[32].shard, ShardId::merge(0));
        assert_eq!(shards.iter().map(|s| s.operations).sum::<u64>(), 210);
        assert!(shards[..32].iter().all(|s| [6, 9].contains(&s.operations)));
    }

    #[test]
    fn fewer_devices_than_groups_make_one_group_per_device() {
        let job = Job::from_json(r#"{"devices": 2, "operations": 5}"#, || 1).unwrap();
        let groups: Vec<_> = first_shards(&job)
            .iter()
            .map(|s| (s.shard.to_string(), s.operations))
            .collect();
        assert_eq!(
            groups,
            [
                ("batch 0 group 0".to_owned(), 5),
                ("batch 0 group 1".to_owned(), 5),
                ("batch 0 merge".to_owned(), 0)
            ]
        );
    }
}
