//! How a job is cut for many workers: each batch of devices into its groups (the engine's unit of
//! independent work, at most 32), plus one merge step per batch. Any worker on any machine runs any
//! group, alone, under its own lease; the merge step, claimable once the batch's groups are done,
//! puts their accumulators back in group order and either stores the Result or, for a precision
//! target not yet met, adds the next batch. Results are bit-identical to running the job whole.
//!
//! Sharding pays only where other workers can take groups that one worker would otherwise run in
//! turn; each shard costs a claim and a store (about a millisecond each on SQLite, several on
//! PostgreSQL) and the merge reads every group back. So a small job ([`runs_whole`]) enters the
//! queue as its first batch's merge step alone, and the worker that claims it runs the whole job
//! on its compute threads ([`run_whole`]): the same groups in the same order, so the same bits.

use super::rare::{self, Estimated, Rounds};
use bouncewear_model::montecarlo::engine::{Batch, GroupStats, run_on_from};
use bouncewear_model::montecarlo::rare::{Outcome, RareEventError, RareEventReport};
use bouncewear_model::montecarlo::{
    Cancelled, Job, JobResult, Kernel, Observer, OutOfRange, RunError, RunGroups, Tally,
    check_in_range, next_batch, precision_met, summarize_job,
};
use serde::Serialize;
use std::collections::BTreeMap;
use std::fmt;
use std::time::{Duration, Instant};
use utoipa::ToSchema;

/// One shard of a job: a group of a batch, or that batch's merge step (a rare event's round is a
/// batch too, [`rare::RARE_ROUNDS`] on: its tasks and its merge step).
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
        match (self.group, self.batch.checked_sub(rare::RARE_ROUNDS)) {
            (Some(task), Some(round)) => write!(f, "rare-event round {round} task {task}"),
            (None, Some(round)) => write!(f, "rare-event round {round} merge"),
            (Some(group), None) => write!(f, "batch {} group {group}", self.batch),
            (None, None) => write!(f, "batch {} merge", self.batch),
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
            operations: merge_plan(job, batch.index),
        }])
        .collect()
}

/// The operations batch `batch`'s merge step plans: the last merge estimates the job's rare event,
/// if it asks one, planned on the batch that must be the last. A precision target's other
/// batches plan none (each planned the whole budget, and a probe's progress read 600,048,000 of
/// 601,048,000 within 50 ms of the start); one that meets the target early counts the estimate as
/// it runs.
pub fn merge_plan(job: &Job, batch: u64) -> u64 {
    job.rare_event()
        .filter(|_| Batch::of(job, batch + 1).is_none())
        .map_or(0, |rare| rare.max_operations())
}

/// The most operations (devices x operations) of a job that runs whole, as one shard: about a
/// tenth of a second of one compute thread (50-70 ns per operation), where 33 claims and stores
/// and a merge of 32 groups would cost as much as the run itself, or more. A job of one instance
/// runs whole on all its compute threads anyway; more instances help only a larger job.
pub const WHOLE_JOB_OPERATIONS: u64 = 2_000_000;

/// The most operations of a shard during whose run its worker claims the next one: the claim's
/// round trip (a few milliseconds) then overlaps the run instead of following it, a tenth of a
/// 30 ms group. A larger shard runs long enough that its claim costs little, and a job queued
/// meanwhile would wait for the shard claimed ahead too (fair share, docs/contract.md).
pub const CLAIM_AHEAD_OPERATIONS: u64 = WHOLE_JOB_OPERATIONS;

/// Whether a worker running `shard` of `operations` claims its next shard meanwhile: a group or
/// a rare event's task (a merge step reads before it computes) of at most
/// [`CLAIM_AHEAD_OPERATIONS`].
pub fn claims_ahead(shard: ShardId, operations: u64) -> bool {
    shard.group.is_some() && operations <= CLAIM_AHEAD_OPERATIONS
}

/// Whether `job` runs whole, as one shard: its batch of devices is at most
/// [`WHOLE_JOB_OPERATIONS`] operations. A precision target adds batches of that size one after
/// another, each too small to pay for its shards: cut into them, a target of batches of 16
/// devices of one operation took 25 ms of claims and stores a batch, growing with every batch
/// (the job's progress is summed over its shards), so 10^8 devices never ended where `bouncewear
/// run` takes minutes. Run whole, the merge step runs its batches one after another and checks
/// the target after each, as [`run_on_from`] does; a rare event after them reads the devices'
/// groups from the last batch run, where the step keeps their fold ([`Merged::folded_through`]).
/// With a rare event such a job was kept sharded, and slowed to 31 devices a second as its
/// shards' rows grew (7,888 rows and 20 MB after 100 s, a probe).
pub fn runs_whole(job: &Job) -> bool {
    job.spec().devices.saturating_mul(job.spec().operations) <= WHOLE_JOB_OPERATIONS
}

/// The shards a job enters the queue with: its first batch's groups and merge step or, for a job
/// that [`runs_whole`], that merge step alone, carrying the job's operations.
pub fn first_shards(job: &Job) -> Vec<ShardPlan> {
    let mut shards = grouped_shards(job);
    if runs_whole(job) {
        let merge = shards.pop().expect("a batch ends with its merge step");
        let operations = shards.iter().map(|s| s.operations).sum::<u64>();
        shards = vec![ShardPlan {
            operations: merge.operations.saturating_add(operations),
            ..merge
        }];
    }
    shards
}

/// The merge step alone of `batch`, carrying its operations: a job run whole from there.
fn whole_shards(job: &Job, batch: Batch) -> Vec<ShardPlan> {
    let merge = ShardPlan {
        shard: ShardId::merge(batch.index),
        operations: batch.size.saturating_mul(job.spec().operations),
    };
    vec![merge]
}

/// The first batch's groups and merge step, whatever the job's size: how a job larger than
/// [`WHOLE_JOB_OPERATIONS`] is cut (and how tests of the queue cut small jobs).
pub fn grouped_shards(job: &Job) -> Vec<ShardPlan> {
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
    /// The devices are done and the job's rare event goes on in a round of shards
    /// ([`super::rare`]): the round, its shards to queue, and the devices' groups folded, to store
    /// in place of theirs until the estimate is made.
    Round {
        rounds: Rounds,
        shards: Vec<ShardPlan>,
        folded: Vec<GroupStats>,
    },
}

impl Merged {
    /// The last batch of devices whose groups a merge step's fold holds, where the store keeps it
    /// (the store's `Store::add_batch`): the batch before the next one, or the devices'
    /// last batch ahead of a rare event's round; none for a Result.
    pub fn folded_through(&self) -> Option<u64> {
        match self {
            Merged::Result { .. } => None,
            Merged::Next { shards, .. } => shards.first().map(|next| next.shard.batch - 1),
            Merged::Round { rounds, .. } => Some(rounds.devices_last),
        }
    }
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
    /// A summary beyond f64 (the same on every attempt).
    #[error(transparent)]
    OutOfRange(#[from] OutOfRange),
    #[error(transparent)]
    Cancelled(#[from] Cancelled),
}

/// A merge step's done groups as the store reads them, in batch and group order, folded as they
/// arrive: the first batch listed (batch 0, or the fold of every batch up to it that an earlier
/// merge stored, [`Merged::Next`]) is kept, and each group of a later batch is merged into its
/// own group at once and dropped, as [`Tally::add_batch`] merges them. A merge holds one batch's
/// groups and the one being read, however many batches it reads; the sequence of merges, and so
/// every bit, is the same as from each batch's own groups.
#[derive(Debug)]
pub struct Folding {
    job: Job,
    last: u64,
    tally: Tally,
    /// The first batch listed, whose groups are kept as they come.
    first: Option<u64>,
    /// The batch being read and how many of its groups are in.
    reading: Option<(Batch, u64)>,
    /// Every group read, in order.
    read: Vec<ShardId>,
    /// Groups of batch `last` this process ran and still holds, by group: the store lists them
    /// without their accumulators ([`Folding::push_held`]).
    held: BTreeMap<u64, GroupStats>,
    /// The first group that did not fit: the rest are ignored.
    error: Option<Incomplete>,
}

impl Folding {
    /// Ready for the groups of `job`'s batches up to `last`, the merge step's batch.
    pub fn new(job: Job, last: u64) -> Self {
        Self {
            job,
            last,
            tally: Tally::new(),
            first: None,
            reading: None,
            read: Vec::new(),
            held: BTreeMap::new(),
            error: None,
        }
    }

    /// With `groups` of batch `last` (group, accumulators) that this process ran and stored: the
    /// store need not send them back nor decode them. A group's accumulators are the same bits
    /// whoever ran it, so holding changes no bit of the merge.
    pub fn holding(mut self, groups: impl IntoIterator<Item = (u64, GroupStats)>) -> Self {
        self.held.extend(groups);
        self
    }

    /// The groups of batch `last` held ([`Folding::holding`]), in order.
    pub fn held(&self) -> impl Iterator<Item = u64> + '_ {
        self.held.keys().copied()
    }

    /// The job whose groups these are.
    pub fn job(&self) -> &Job {
        &self.job
    }

    /// The last batch it reads.
    pub fn last(&self) -> u64 {
        self.last
    }

    /// The groups read so far, in order.
    pub fn read(&self) -> &[ShardId] {
        &self.read
    }

    /// Takes the next group the store lists.
    pub fn push(&mut self, shard: ShardId, stats: GroupStats) {
        self.read.push(shard);
        if self.error.is_none()
            && let Err(error) = self.fold(shard, stats)
        {
            self.error = Some(error);
        }
    }

    /// Takes the next group the store lists as held ([`Folding::holding`]), without its
    /// accumulators.
    pub fn push_held(&mut self, shard: ShardId) {
        let held = match shard.group {
            Some(group) if shard.batch == self.last => self.held.remove(&group),
            _ => None,
        };
        match held {
            Some(stats) => self.push(shard, stats),
            None => {
                self.read.push(shard);
                self.error.get_or_insert_with(|| Incomplete {
                    batch: shard.batch,
                    detail: format!("{shard} came without its accumulators, and none are held"),
                });
            }
        }
    }

    fn fold(&mut self, shard: ShardId, stats: GroupStats) -> Result<(), Incomplete> {
        if shard.batch > self.last {
            return Err(Incomplete {
                batch: shard.batch,
                detail: format!("{shard} is stored after batch {}'s merge", self.last),
            });
        }
        let (batch, count) = match self.reading {
            Some((batch, count)) if batch.index == shard.batch => (batch, count),
            Some((batch, count)) => {
                self.complete(batch, count)?;
                (self.batch(batch.index + 1)?, 0)
            }
            None => {
                self.first = Some(shard.batch);
                (self.batch(shard.batch)?, 0)
            }
        };
        let expected = ShardId::group(batch.index, count);
        if shard != expected {
            let detail = format!("found {shard} where {expected} belongs");
            return Err(Incomplete {
                batch: batch.index,
                detail,
            });
        }
        if self.first == Some(batch.index) {
            self.tally.groups.push(stats);
        } else if let Some(group) = self.tally.groups.get_mut(count as usize) {
            group.merge(&stats);
        }
        self.reading = Some((batch, count + 1));
        Ok(())
    }

    /// Batch `index` of the job, or why it has none.
    fn batch(&self, index: u64) -> Result<Batch, Incomplete> {
        Batch::of(&self.job, index).ok_or_else(|| Incomplete {
            batch: index,
            detail: "the job runs no such batch".to_owned(),
        })
    }

    /// Checks that `batch` has all its groups (`count` read); counts its devices. The first batch
    /// listed may be a fold an earlier merge stored in its place ([`Merged::Next`], a rare event's
    /// [`Merged::Round`]), which has as many groups as the job's first batch: more than the batch
    /// itself when it is a last batch cut short by `max_devices` (16 groups stored at a batch of
    /// 8 devices failed every rare event's last merge, found from outside).
    fn complete(&mut self, batch: Batch, count: u64) -> Result<(), Incomplete> {
        let fold = (self.first == Some(batch.index))
            .then(|| Batch::of(&self.job, 0).map(|first| first.groups()))
            .flatten();
        if count != batch.groups() && Some(count) != fold {
            return Err(Incomplete {
                batch: batch.index,
                detail: format!("{count} of its {} groups are stored", batch.groups()),
            });
        }
        self.tally.devices = batch.first + batch.size;
        Ok(())
    }

    /// The job and the fold of every batch before `last`, for a merge step that runs batch
    /// `last` on itself ([`run_whole`]): none for batch 0, else the fold an earlier step stored.
    pub fn finish_before_last(mut self) -> Result<(Job, Tally), Incomplete> {
        match self.last.checked_sub(1) {
            Some(before) => {
                self.last = before;
                self.finish()
            }
            None if self.read.is_empty() => Ok((self.job, Tally::new())),
            None => Err(Incomplete {
                batch: 0,
                detail: "a job run whole from its start has groups stored".to_owned(),
            }),
        }
    }

    /// The job and the fold of every batch up to `last`, or why the groups read do not make them up.
    pub fn finish(mut self) -> Result<(Job, Tally), Incomplete> {
        if let Some(error) = self.error.take() {
            return Err(error);
        }
        let (mut batch, mut count) = match self.reading {
            Some(reading) => reading,
            None => (self.batch(0)?, 0),
        };
        loop {
            self.complete(batch, count)?;
            if batch.index >= self.last {
                return Ok((self.job, self.tally));
            }
            (batch, count) = (self.batch(batch.index + 1)?, 0);
        }
    }
}

/// The merge step of batch `last`, from its groups as [`Folding`] read them: decides as
/// [`run_job`] does after that batch: the Result, after `wall_s` seconds of running, the next
/// batch, or the rare event's first round of at least `sharded_from` operations.
///
/// [`run_job`]: bouncewear_model::montecarlo::run_job
pub fn merge(
    partials: Folding,
    sharded_from: u64,
    wall_s: f64,
    observer: &dyn Observer,
) -> Result<Merged, MergeError> {
    let last = partials.last();
    let (job, tally) = partials.finish()?;
    match next_batch(&job, &tally) {
        Some(batch) => Ok(Merged::Next {
            shards: batch_shards(&job, batch),
            folded: tally.groups,
        }),
        None => finish(&job, tally, last, sharded_from, wall_s, observer),
    }
}

/// Runs the whole job here, as the merge step of a job that entered the queue without groups
/// ([`first_shards`]): every batch's groups after those `ran` holds on the calling compute pool,
/// each group listing the lives the job lists ([`Job::with_listed_lives`]) as a group's shard
/// does, then as [`merge`] after the last batch. The Result is the one the groups' shards and
/// merges would give, to the bit.
///
/// A precision target's batches stop after the first that ends `step` or more after the start
/// with a batch still to run: the next batch's merge step alone is queued with the fold of every
/// batch so far, and the worker that claims it goes on from there
/// ([`Folding::finish_before_last`]), so that a long run does not hold its worker while other
/// jobs wait (fair share, docs/contract.md). Where a step ends changes no bit.
pub fn run_whole(
    job: &Job,
    ran: Tally,
    step: Duration,
    sharded_from: u64,
    wall_s: f64,
    observer: &dyn Observer,
) -> Result<Merged, MergeError> {
    let started = Instant::now();
    let ran_before = ran.devices;
    let tally = run_on_from(Kernel::active(), job, ran, observer, |tally| {
        precision_met(job, tally) || started.elapsed() >= step
    })?;
    if let Some(batch) = next_batch(job, &tally) {
        return Ok(Merged::Next {
            shards: whole_shards(job, batch),
            folded: tally.groups,
        });
    }
    // Its devices' groups, for a rare event's rounds, are kept at the last batch it ran.
    let last_run = tally.devices.saturating_sub(1) / job.spec().devices;
    let after = StepProgress {
        inner: observer,
        ran: (tally.devices - ran_before).saturating_mul(job.spec().operations),
        told_before: 0,
    };
    finish(
        job,
        tally,
        last_run,
        sharded_from,
        wall_s + started.elapsed().as_secs_f64(),
        &after,
    )
}

/// The progress of a rare event estimated in a merge step: the operations the step `ran` before
/// it (a step's batches, [`run_whole`]) and those of the estimate it runs itself, past the
/// `told_before` the estimate had counted (its earlier rounds and the round's tasks, each a shard
/// of its own, [`merge_round`]), with a total that grows as it runs. Its budget is a cap, and a
/// round the step queues is planned by its own shards: a step that told the budget as its total
/// counted those rounds twice, and a round's merge that told the estimate's whole count counted
/// the earlier rounds again (a probe: 22.3-23.2 million operations for about 10 million run,
/// different from run to run); a step that told the estimate's count alone lost the devices'
/// (3,600,000 for 1,671,000 run).
struct StepProgress<'a> {
    inner: &'a dyn Observer,
    ran: u64,
    told_before: u64,
}

impl Observer for StepProgress<'_> {
    fn progress(&self, done: u64, _: u64) {
        let done = self
            .ran
            .saturating_add(done.saturating_sub(self.told_before));
        self.inner.progress(done, done);
    }

    fn cancelled(&self) -> bool {
        self.inner.cancelled()
    }
}

/// How long a merge step running a job whole ([`run_whole`]) runs batches before it hands the
/// job on: a job queued behind waits about this long, and each step costs a few milliseconds to
/// store and read back the fold of its batches' groups. By operations it would not do: a batch
/// of 16 operations costs about 80 us, its precision check most of it, so 2e7 operations of
/// them took about 100 s.
pub const WHOLE_STEP: Duration = Duration::from_secs(1);

/// The job's devices are all in `tally` (batches up to `devices_last`): its rare event, if it asks
/// one, estimated here while its rounds are small, then the Result; or the first round that is
/// not, with the devices' groups to keep until the estimate is made.
fn finish(
    job: &Job,
    tally: Tally,
    devices_last: u64,
    sharded_from: u64,
    wall_s: f64,
    observer: &dyn Observer,
) -> Result<Merged, MergeError> {
    let started = Instant::now();
    match rare::first_round(job, devices_last, sharded_from, observer)? {
        Estimated::Made(report) => {
            let wall_s = wall_s + started.elapsed().as_secs_f64();
            result(job, tally, report, wall_s)
        }
        Estimated::Queued(rounds) => Ok(Merged::Round {
            shards: round_shards(job, &rounds),
            rounds,
            folded: tally.groups,
        }),
    }
}

/// What a rare event's round's merge step leads to.
#[derive(Debug)]
pub enum RoundMerged {
    /// The estimate is made: the Result follows from the devices' groups.
    Estimated(RareEventReport),
    /// The next round, and its shards to queue.
    Next {
        rounds: Rounds,
        shards: Vec<ShardPlan>,
    },
}

/// A rare event's round's merge step ([`rare::merge_round`]).
/// The second of each pair is the operations the step ran itself: the rounds it estimated
/// after the round's tasks.
pub fn merge_round(
    job: &Job,
    rounds: Rounds,
    outcomes: Vec<Outcome>,
    sharded_from: u64,
    observer: &dyn Observer,
) -> Result<(RoundMerged, u64), MergeError> {
    let per_evaluation = bouncewear_model::montecarlo::rare::operations_per_evaluation(job);
    let estimator = &rounds.estimator;
    let told_before = (estimator.evaluations() + estimator.round_evaluations()) * per_evaluation;
    let step = StepProgress {
        inner: observer,
        ran: 0,
        told_before,
    };
    let ran = |evaluations: u64| (evaluations * per_evaluation).saturating_sub(told_before);
    Ok(
        match rare::merge_round(job, rounds, outcomes, sharded_from, &step)? {
            Estimated::Made(report) => {
                let report = report.ok_or_else(|| {
                    MergeError::RareEvent(RareEventError("the job asks no rare event".to_owned()))
                })?;
                let here = ran(report.evaluations);
                (RoundMerged::Estimated(report), here)
            }
            Estimated::Queued(rounds) => {
                let here = ran(rounds.estimator.evaluations());
                let shards = round_shards(job, &rounds);
                (RoundMerged::Next { rounds, shards }, here)
            }
        },
    )
}

/// A round's shards: its tasks as groups of its batch, each with its operations, then its merge
/// step.
fn round_shards(job: &Job, rounds: &Rounds) -> Vec<ShardPlan> {
    let batch = rounds.batch();
    (0..)
        .zip(rounds.task_operations(job))
        .map(|(group, operations)| ShardPlan {
            shard: ShardId::group(batch, group),
            operations,
        })
        .chain([ShardPlan {
            shard: ShardId::merge(batch),
            operations: 0,
        }])
        .collect()
}

/// The Result from the devices' groups as [`Folding`] read them and the rare event's report.
pub fn estimated(
    devices: Folding,
    report: RareEventReport,
    wall_s: f64,
) -> Result<Merged, MergeError> {
    let (job, tally) = devices.finish()?;
    result(&job, tally, Some(report), wall_s)
}

fn result(
    job: &Job,
    tally: Tally,
    report: Option<RareEventReport>,
    wall_s: f64,
) -> Result<Merged, MergeError> {
    let mut result = summarize_job(job, &tally, wall_s);
    check_in_range(&result)?;
    result.put_rare_event(job, report);
    Ok(Merged::Result {
        result: Box::new(result),
        groups: RunGroups::new(job, tally),
    })
}

impl From<RunError> for MergeError {
    fn from(error: RunError) -> Self {
        match error {
            RunError::Cancelled(cancelled) => MergeError::Cancelled(cancelled),
            RunError::RareEvent(failed) => MergeError::RareEvent(failed),
            RunError::OutOfRange(beyond) => MergeError::OutOfRange(beyond),
        }
    }
}

/// The accumulators a merge step of `job` holds decoded: one batch's groups, each with every
/// (bin, operation metric) and every device metric. What its memory follows (about 900 bytes an
/// accumulator with the README's scatter, so 0.5 GB for the largest job the defaults accept).
pub fn merge_accumulators(job: &Job) -> u64 {
    let groups = Batch::of(job, 0).map_or(0, |batch| batch.groups());
    let per_group =
        job.bins() * job.operation_metrics().len() as u64 + job.device_metrics().len() as u64;
    groups.saturating_mul(per_group)
}

/// At most this many [`merge_accumulators`], a job's Result merged from its first batch's
/// groups as their shards stored them leaves them there for queries after the run
/// ([`groups_stay_in_shards`]). A query then decodes every group of the job, about 900 bytes an
/// accumulator: at most about 7 MB, where a bin's own groups are one bin's.
pub const GROUPS_IN_SHARDS_ACCUMULATORS: u64 = 8_192;

/// Whether the Result that the merge step of batch `last` of `job` makes from its groups as their
/// shards stored them (not a step that ran the job `whole`) leaves them in the shards rather than
/// writing them again, each bin's in its distribution row: its final groups are those of its
/// first batch, and their accumulators few enough ([`GROUPS_IN_SHARDS_ACCUMULATORS`]). The
/// scale-out job's merge wrote 2.5 MB of groups its shards had written already, about half of
/// the merge's time on PostgreSQL (docs/performance.md).
pub fn groups_stay_in_shards(job: &Job, last: u64, whole: bool) -> bool {
    !whole && last == 0 && merge_accumulators(job) <= GROUPS_IN_SHARDS_ACCUMULATORS
}

/// Beyond this many [`merge_accumulators`], a merge step runs alone on its instance (other large
/// merges wait for it), so that an instance's memory holds one large merge at a time however many
/// workers it runs: 32 groups of 180 bins x 18 metrics, about 90 MB with the README's scatter.
pub const LARGE_MERGE_ACCUMULATORS: u64 = 100_000;

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

/// The wait before a shard whose outcome the disk had no room for is claimed again (counting
/// nothing against it: its job waits for room rather than fail).
pub const ROOM_RETRY_MS: i64 = 15_000;

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
        let shards = grouped_shards(&job);
        assert_eq!(shards.len(), 33);
        assert_eq!(shards[32].shard, ShardId::merge(0));
        assert_eq!(shards.iter().map(|s| s.operations).sum::<u64>(), 210);
        assert!(shards[..32].iter().all(|s| [6, 9].contains(&s.operations)));
    }

    #[test]
    fn fewer_devices_than_groups_make_one_group_per_device() {
        let job = Job::from_json(r#"{"devices": 2, "operations": 5}"#, || 1).unwrap();
        let groups: Vec<_> = grouped_shards(&job)
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

    /// A job of at most [`WHOLE_JOB_OPERATIONS`] operations enters the queue as one shard carrying
    /// them all; one more operation and it is cut into groups. With a precision target, the size
    /// of a batch decides, a rare event after it or not.
    #[test]
    fn a_small_job_is_one_shard_and_a_larger_one_its_groups() {
        let first = |text: &str| first_shards(&Job::from_json(text, || 1).unwrap());
        let whole = first(r#"{"devices": 1000, "operations": 2000}"#);
        let expected = ShardPlan {
            shard: ShardId::merge(0),
            operations: WHOLE_JOB_OPERATIONS,
        };
        assert_eq!(whole, [expected]);
        assert_eq!(first(r#"{"devices": 1, "operations": 2000001}"#).len(), 2);
        assert_eq!(first(r#"{"devices": 2000, "operations": 1001}"#).len(), 33);
        let precision = |devices: u64, rare: &str| {
            let text = format!(
                r#"{{"devices": {devices}, "operations": 1000, {rare}
                    "precision": {{"metric": "e1", "relative_half_width": 0.01,
                                   "max_devices": 100000}}}}"#
            );
            first(&text).len()
        };
        assert_eq!(
            precision(2000, ""),
            1,
            "batches of 2e6 operations run whole"
        );
        assert_eq!(precision(2001, ""), 33);
        assert_eq!(precision(16, RARE_EVENT), 1);
        assert_eq!(precision(2001, RARE_EVENT), 33);
    }

    /// A rare event of e1 and the scattered input it needs, as members of a job.
    const RARE_EVENT: &str = r#""rare_event": {"metric": "e1", "below": 0.1, "operation": 1},
        "scatter": [{"parameter": "impact_velocity_m_s", "per": "device",
                     "distribution": {"kind": "normal", "mean": 0.3, "sd": 0.05, "min": 0}}],"#;

    /// A precision target's batches before its last plan no rare-event operations for their merge
    /// step; the last possible batch plans the estimate's whole budget.
    #[test]
    fn only_the_last_possible_batch_plans_the_rare_event() {
        let text = format!(
            r#"{{"devices": 16, "operations": 10, {RARE_EVENT}
                "precision": {{"metric": "e1", "relative_half_width": 0.01, "max_devices": 40}}}}"#
        );
        let job = Job::from_json(&text, || 1).unwrap();
        let merge = |index| {
            let shards = batch_shards(&job, Batch::of(&job, index).unwrap());
            shards.last().unwrap().operations
        };
        assert_eq!((merge(0), merge(1)), (0, 0));
        assert_eq!(merge(2), job.rare_event().unwrap().max_operations());
        assert!(merge(2) > 0);
    }

    /// A worker claims ahead while it runs a group or a task of at most
    /// [`CLAIM_AHEAD_OPERATIONS`], never during a merge step.
    #[test]
    fn only_short_groups_and_tasks_are_claimed_past() {
        let group = ShardId::group(0, 31);
        assert!(claims_ahead(group, 312_500));
        assert!(claims_ahead(group, CLAIM_AHEAD_OPERATIONS));
        assert!(!claims_ahead(group, CLAIM_AHEAD_OPERATIONS + 1));
        assert!(claims_ahead(ShardId::group(rare::RARE_ROUNDS, 3), 1000));
        assert!(!claims_ahead(ShardId::merge(0), 0));
        assert!(!claims_ahead(ShardId::merge(rare::RARE_ROUNDS), 0));
    }

    #[test]
    fn a_merge_holds_one_batchs_groups_of_every_bin_and_metric() {
        let accumulators = |text: &str| merge_accumulators(&Job::from_json(text, || 1).unwrap());
        // 32 groups x (1000 bins x 3 operation metrics + 1 device metric).
        let largest = accumulators(
            r#"{"devices": 2000000, "operations": 1000, "bin_operations": 1,
                "metrics": ["e1", "total_bounce_s", "bounce_count", "eroded_mass_kg"]}"#,
        );
        assert_eq!(largest, 32 * 3001);
        assert!(largest < LARGE_MERGE_ACCUMULATORS);
        let every = accumulators(
            r#"{"devices": 64, "operations": 1000, "bin_operations": 1,
                "metrics": ["impact_velocity_m_s", "kappa", "e1", "first_bounce_s",
                            "total_bounce_s", "bounce_count", "pre_arc_s", "arc_energy_j",
                            "peak_force_n", "impact_duration_s", "first_impact_plastic_work_j",
                            "cumulative_arc_energy_j", "eroded_mass_kg", "final_radius_m",
                            "final_kappa", "cumulative_plastic_work_j"]}"#,
        );
        assert!(every > LARGE_MERGE_ACCUMULATORS);
        // Two devices make two groups.
        assert_eq!(accumulators(r#"{"devices": 2, "operations": 10}"#) % 2, 0);
    }

    /// The groups of each batch of [`three_batches`]: one per device.
    const G: usize = 16;

    /// A precision job of three batches of [`G`] devices (one group each): its groups as a worker
    /// runs them, and the engine's own tally of all three batches.
    fn three_batches() -> (Job, Vec<Vec<GroupStats>>, Tally) {
        use bouncewear_model::montecarlo::Silent;
        use bouncewear_model::montecarlo::engine::run_group;
        use bouncewear_model::montecarlo::engine::run_on;
        let job = Job::from_json(
            r#"{"devices": 16, "operations": 4,
                "scenario": {"circuit": {"supply_voltage_v": 48, "current_a": 15}},
                "scatter": [{"parameter": "impact_velocity_m_s", "per": "operation",
                             "distribution": {"kind": "normal", "mean": 0.224, "sd": 0.02, "min": 0.05}}],
                "precision": {"metric": "total_bounce_s", "relative_half_width": 1e-9, "max_devices": 48}}"#,
            || 7,
        )
        .unwrap();
        let batches: Vec<Vec<GroupStats>> = (0..3)
            .map(|index| {
                let batch = Batch::of(&job, index).unwrap();
                (0..batch.groups())
                    .map(|group| run_group(&job, batch, group, &Silent).unwrap())
                    .collect()
            })
            .collect();
        let whole = run_on(Kernel::SCALAR, &job, &Silent, |_| false).unwrap();
        (job, batches, whole)
    }

    fn fold(job: &Job, last: u64, groups: &[(ShardId, &GroupStats)]) -> Result<Tally, Incomplete> {
        let mut folding = Folding::new(job.clone(), last);
        for (shard, stats) in groups {
            folding.push(*shard, (*stats).clone());
        }
        assert_eq!(
            folding.read(),
            groups.iter().map(|(shard, _)| *shard).collect::<Vec<_>>()
        );
        folding.finish().map(|(_, tally)| tally)
    }

    fn listed(batch: u64, groups: &[GroupStats]) -> Vec<(ShardId, &GroupStats)> {
        (0..)
            .map(|g| ShardId::group(batch, g))
            .zip(groups)
            .collect()
    }

    /// Folding the groups as they are read gives the engine's tally to the bit, from each batch's
    /// own groups or from the fold an earlier merge stored.
    #[test]
    fn groups_folded_as_read_give_the_engines_tally() {
        let (job, batches, whole) = three_batches();
        let every: Vec<_> = (0..3)
            .flat_map(|b| listed(b, &batches[b as usize]))
            .collect();
        let folded = fold(&job, 2, &every).unwrap();
        assert_eq!((folded.devices, &folded.groups), (48, &whole.groups));

        let first_two = fold(&job, 1, &every[..2 * G]).unwrap();
        assert_eq!(first_two.devices, 32);
        let mut resumed = listed(1, &first_two.groups);
        resumed.extend(listed(2, &batches[2]));
        let folded = fold(&job, 2, &resumed).unwrap();
        assert_eq!((folded.devices, &folded.groups), (48, &whole.groups));
    }

    /// A last batch cut short by `max_devices` (8 devices, 8 groups) holds, once merged, the fold
    /// of every batch: 16 groups, which a rare event's last merge reads back at that batch.
    #[test]
    fn a_fold_stored_at_a_short_last_batch_reads_back() {
        use bouncewear_model::montecarlo::Silent;
        use bouncewear_model::montecarlo::engine::{run_group, run_on};
        let job = Job::from_json(
            r#"{"devices": 16, "operations": 4,
                "scatter": [{"parameter": "impact_velocity_m_s", "per": "operation",
                             "distribution": {"kind": "normal", "mean": 0.224, "sd": 0.02, "min": 0.05}}],
                "precision": {"metric": "total_bounce_s", "relative_half_width": 1e-9, "max_devices": 40}}"#,
            || 7,
        )
        .unwrap();
        let last = Batch::of(&job, 2).unwrap();
        assert_eq!((last.size, last.groups()), (8, 8));
        let whole = run_on(Kernel::SCALAR, &job, &Silent, |_| false).unwrap();
        assert_eq!((whole.devices, whole.groups.len()), (40, G));
        let folded = fold(&job, 2, &listed(2, &whole.groups)).unwrap();
        assert_eq!((folded.devices, &folded.groups), (40, &whole.groups));
        // The batch's own groups still count as its own: 8, not more nor fewer.
        let own: Vec<GroupStats> = (0..8)
            .map(|g| run_group(&job, last, g, &Silent).unwrap())
            .collect();
        assert_eq!(fold(&job, 2, &listed(2, &own[..7])).unwrap_err().batch, 2);
    }

    #[test]
    fn groups_that_do_not_make_up_the_batches_are_named() {
        let (job, batches, _) = three_batches();
        let every: Vec<_> = (0..3)
            .flat_map(|b| listed(b, &batches[b as usize]))
            .collect();
        let detail = |last, groups: &[(ShardId, &GroupStats)]| {
            let error = fold(&job, last, groups).unwrap_err();
            (error.batch, error.detail)
        };
        assert_eq!(
            detail(0, &[]),
            (0, format!("0 of its {G} groups are stored"))
        );
        assert_eq!(
            detail(2, &every[..G + 2]),
            (1, format!("2 of its {G} groups are stored"))
        );
        assert_eq!(
            detail(2, &every[..2 * G]),
            (2, format!("0 of its {G} groups are stored"))
        );
        let skipped = [every[0], every[2]];
        assert_eq!(
            detail(0, &skipped),
            (
                0,
                "found batch 0 group 2 where batch 0 group 1 belongs".to_owned()
            )
        );
        assert_eq!(
            detail(0, &every[..G + 1]),
            (
                1,
                "batch 1 group 0 is stored after batch 0's merge".to_owned()
            )
        );
        let gap = [&every[..G], &every[2 * G..]].concat();
        assert_eq!(
            detail(2, &gap),
            (
                1,
                "found batch 2 group 0 where batch 1 group 0 belongs".to_owned()
            )
        );
        assert_eq!(
            detail(5, &every),
            (3, "the job runs no such batch".to_owned())
        );
    }
}
