//! The durable job queue's workers: claim a shard of a job with a lease, run it on the compute pool
//! (never on the async runtime, one compute thread per shard), heartbeat with the fencing attempt
//! number, and write its outcome only while the attempt still holds the shard.
//!
//! A shard is one group of devices of one batch ([`crate::domain::shards`]): its accumulators are
//! stored when it is done. A worker slot computes one shard at a time but does not wait on the
//! database between groups: while a short group runs it claims the next shard
//! ([`crate::domain::shards::claims_ahead`]), and a group's store goes on while the next one
//! computes (one store at a time per slot). A batch's merge step, claimable once its groups are
//! done, puts them back in order (those this process ran from memory, [`HeldGroups`], the others
//! read back) and stores the Result (or queues a precision target's next batch). A small job is its
//! first merge step alone, which runs the whole job on the compute pool. A rare event's large
//! rounds ([`crate::domain::rare`]) are batches too: any worker runs a round's tasks as it runs
//! groups, and the round's merge step takes their outcomes. The shards a process held when it
//! crashed or was killed (the one it ran, the one it claimed ahead, the group it was storing) keep
//! their leases until they expire; then any worker on any machine claims them again and reruns
//! those shards alone. Seeds are fixed at submission and each device has its own random stream, so
//! the Result is identical to an uninterrupted run on one machine. On a graceful shutdown the
//! running shard is stopped and handed back to the queue at once, with the one claimed ahead; a
//! group being stored is stored first.

use crate::domain::rare::{Rounds, is_round};
use crate::domain::shards::{
    Folding, LARGE_MERGE_ACCUMULATORS, MergeError, Merged, RoundMerged, ShardPlan, claims_ahead,
    estimated, groups_stay_in_shards, merge, merge_accumulators, merge_plan, merge_round,
    run_whole,
};
use crate::domain::{JobId, UnixMs};
use crate::store::{
    Awaited, Claim, EncodedGroups, EncodedResult, Fence, Lease, LeaseTerms, QueueEvent,
    RetryBudget, Store, StoreError, StoreResult, encode, partial_to_sql,
};
use crate::telemetry::{record_job_finished, record_shard_step, record_shard_time};
use bouncewear_model::Pointer;
use bouncewear_model::montecarlo::engine::{Batch, GroupStats, run_group};
use bouncewear_model::montecarlo::rare;
use bouncewear_model::montecarlo::{Cancelled, Job, JobResult, Observer, RunError, Watch};
use std::collections::VecDeque;
use std::panic::AssertUnwindSafe;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::{Duration, Instant};
use tokio::sync::{Notify, Semaphore, SemaphorePermit, broadcast, oneshot, watch};
use tokio::task::JoinHandle;
use tracing::Instrument;

/// Progress and the lease are written at most this often per running shard.
const HEARTBEAT_MAX_PERIOD: Duration = Duration::from_millis(500);
/// An idle worker looks for expired leases at least this often.
const IDLE_POLL: Duration = Duration::from_millis(500);

/// How long a worker waits before it claims again after `failed` claims in a row failed:
/// [`IDLE_POLL`], doubling to 8 s. A database that cannot answer (PostgreSQL down, a SQLite file
/// it may not write) was asked, and its error logged, twice a second by every worker slot.
fn claim_retry_delay(failed: u32) -> Duration {
    IDLE_POLL.saturating_mul(1 << failed.min(4))
}
/// A write the database could not take is tried again after this, doubling up to
/// [`STORE_RETRY_MAX_DELAY`], at most `budget.lost_leases` times, with the lease kept meanwhile.
const STORE_RETRY_FIRST_DELAY: Duration = Duration::from_millis(250);
const STORE_RETRY_MAX_DELAY: Duration = Duration::from_secs(8);

pub struct Workers {
    pub store: Arc<Store>,
    pub compute: Arc<rayon::ThreadPool>,
    pub lease: Duration,
    /// Times a shard is run again after it failed, or apart after its lease expired, before its
    /// job fails.
    pub budget: RetryBudget,
    pub instance: String,
    /// Notified on every submission, so an idle worker starts at once.
    pub wake: Arc<Notify>,
    /// Devices whose own life a job lists (the life CSV); the life analysis counts every device.
    pub listed_lives: u64,
    /// Held by a merge step beyond [`LARGE_MERGE_ACCUMULATORS`] from reading its groups to storing
    /// what it made: one such merge at a time in this instance (one permit).
    pub large_merges: Semaphore,
    /// The fewest operations of a rare event's round that goes to the queue as shards
    /// ([`crate::domain::rare::SHARDED_ROUND_OPERATIONS`]); smaller rounds run in the merge step.
    /// Where a round runs changes no bit.
    pub sharded_round_operations: u64,
    /// How long a merge step running a job whole runs batches before it hands the job on
    /// ([`crate::domain::shards::WHOLE_STEP`]). Where a step ends changes no bit.
    pub whole_step: Duration,
    /// Groups this process ran, for their merge step if it runs here too.
    pub held: HeldGroups,
}

/// The stored bytes of the groups a worker process holds after running them ([`HeldGroups`]);
/// decoded they take more (a sketch's counts in fixed width with room to grow, where stored
/// they are varints): a 10^7-operation job's 32 groups are 2.5 MB stored.
pub const HELD_GROUP_BYTES: usize = 32 << 20;

/// How long an idle worker keeps groups it holds ([`HeldGroups`]) before it gives them up: a
/// batch's merge is claimable as soon as its last group is stored, so a group held this long
/// is one whose merge ran elsewhere.
const HELD_GROUP_AGE: Duration = Duration::from_secs(60);

/// Groups this process ran, held for their batch's merge step: a merge that runs here takes them
/// ([`Folding::holding`]) instead of reading them back from the database and decoding them. A
/// group's accumulators are the same bits whoever ran it and however often, so a group held here
/// and stored by another attempt merge alike. The oldest go once their stored bytes pass the
/// budget; a batch's go to its merge step, or age out once another process merged it.
pub struct HeldGroups {
    budget: usize,
    held: Mutex<Held>,
}

#[derive(Default)]
struct Held {
    bytes: usize,
    groups: VecDeque<HeldGroup>,
}

impl Held {
    /// Takes out the oldest groups while `beyond` (the bytes held, the oldest group) holds.
    fn pop_oldest_while(&mut self, beyond: impl Fn(usize, &HeldGroup) -> bool) -> Vec<HeldGroup> {
        let mut popped = Vec::new();
        while let Some(oldest) = self.groups.front()
            && beyond(self.bytes, oldest)
            && let Some(oldest) = self.groups.pop_front()
        {
            self.bytes -= oldest.bytes;
            popped.push(oldest);
        }
        popped
    }
}

struct HeldGroup {
    job: JobId,
    batch: u64,
    group: u64,
    bytes: usize,
    stats: GroupStats,
    since: Instant,
}

impl HeldGroups {
    /// Holding at most `budget` stored bytes of groups.
    pub fn new(budget: usize) -> Self {
        Self {
            budget,
            held: Mutex::default(),
        }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Held> {
        self.held.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// Holds `group` of `job`'s batch `batch`, `bytes` once stored; drops the oldest beyond the
    /// budget.
    pub fn keep(&self, job: &JobId, batch: u64, group: u64, bytes: usize, stats: GroupStats) {
        if bytes > self.budget {
            return;
        }
        let dropped = {
            let mut held = self.lock();
            held.bytes += bytes;
            held.groups.push_back(HeldGroup {
                job: job.clone(),
                batch,
                group,
                bytes,
                stats,
                since: Instant::now(),
            });
            held.pop_oldest_while(|bytes, _| bytes > self.budget)
        };
        drop(dropped); // freed outside the lock
    }

    /// Gives up the groups held longer than `age`.
    fn expire(&self, age: Duration) {
        let dropped = self
            .lock()
            .pop_oldest_while(|_, oldest| oldest.since.elapsed() > age);
        drop(dropped); // freed outside the lock
    }

    /// The held groups of `job`'s batch `batch`, as (group, accumulators), no longer held.
    fn take(&self, job: &JobId, batch: u64) -> Vec<(u64, GroupStats)> {
        let mut held = self.lock();
        let (taken, kept): (VecDeque<_>, VecDeque<_>) = std::mem::take(&mut held.groups)
            .into_iter()
            .partition(|g| g.job == *job && g.batch == batch);
        held.groups = kept;
        held.bytes -= taken.iter().map(|g| g.bytes).sum::<usize>();
        taken.into_iter().map(|g| (g.group, g.stats)).collect()
    }
}

/// Whether a merge may take the groups this process ran and holds ([`HeldGroups`]) in place of
/// their stored rows.
#[derive(Clone, Copy)]
enum Holding {
    /// A batch's own merge: its groups' rows are theirs until it ends.
    Use,
    /// A rare event's last merge, reading the devices' groups at their last batch: the batch's
    /// merge replaced its rows with the fold of every batch, and a group this process ran there
    /// and still holds is that batch's alone. Taken in their place (a process that ran some of the
    /// last batch's groups but not its merge), they left every earlier batch out of those groups:
    /// bins of 3200 values where 4800 ran, on PostgreSQL with two worker processes (found from
    /// outside). They are dropped instead.
    Stale,
}

/// What a computation's progress says of its shard's work.
#[derive(Debug, Clone, Copy)]
enum Work {
    /// Its operations done so far, of the total planned for the shard (a rare event's budget
    /// is a cap, not a plan: its rounds end sooner).
    Planned,
    /// Its operations done so far and its total as it learns it: a job run whole, whose
    /// precision target adds a batch at a time.
    Growing,
}

/// A shard's lease, heartbeated by a task of its own for as long as this lives.
struct KeptLease {
    /// Set when the computation must stop: the job ended, the lease was lost, or shutdown.
    cancel: Arc<AtomicBool>,
    /// Set when the stop is this process's shutdown (the shard goes back to the queue).
    stopping: Arc<AtomicBool>,
    /// The shard's operations done so far, reported with each heartbeat.
    done: Arc<AtomicU64>,
    /// Its operations in all as its computation learns them ([`Work::Growing`]), else 0.
    total: Arc<AtomicU64>,
    keeper: JoinHandle<()>,
    /// The database's clock less this machine's, as the claim found them: times that the
    /// database also keeps (a job's start) are read on its clock, whatever this machine's says.
    clock_offset_ms: i64,
}

impl KeptLease {
    /// Seconds from `started_at` (the database's clock) to now, on the database's clock.
    fn wall_s_since(&self, started_at: UnixMs) -> f64 {
        let now = UnixMs::now().0.saturating_add(self.clock_offset_ms);
        now.saturating_sub(started_at.0).max(0) as f64 / 1000.0
    }
}

impl Drop for KeptLease {
    fn drop(&mut self) {
        self.keeper.abort();
    }
}

/// What a merge step's computation leaves to write: the Result, encoded for the store, or the next
/// step (a precision target's next batch, or a rare event's round with its state) with the fold of
/// the groups, encoded; or why it could not be encoded.
enum Outcome {
    Result {
        result: Box<JobResult>,
        encoded: EncodedResult,
    },
    Next {
        shards: Vec<ShardPlan>,
        folded: EncodedGroups,
        /// The last batch of devices `folded` holds ([`Merged::folded_through`]).
        folded_through: u64,
        /// The rare event's evaluations so far, before a round it queues.
        rare_evaluations: u64,
        state: Option<Vec<u8>>,
    },
    Unencodable(String),
}

/// What a merge step made, encoded on the compute pool so that the writes bind bytes (each group
/// goes once encoded; a Result's not at all where they stay in the job's shards,
/// `groups_in_shards`); `Err` for a cancelled computation.
fn encoded(
    merged: Result<Merged, MergeError>,
    groups_in_shards: bool,
) -> Result<Result<Outcome, MergeError>, Cancelled> {
    let folded_through = merged.as_ref().ok().and_then(Merged::folded_through);
    let outcome = match merged {
        Err(MergeError::Cancelled(cancelled)) => return Err(cancelled),
        Err(other) => return Ok(Err(other)),
        Ok(Merged::Result { mut result, groups }) => {
            let encoding = match groups_in_shards {
                true => EncodedResult::with_groups_in_shards,
                false => EncodedResult::new,
            };
            match encoding(&mut result, groups) {
                Ok(encoded) => Outcome::Result { result, encoded },
                Err(error) => Outcome::Unencodable(format!("encoding the result failed: {error}")),
            }
        }
        Ok(Merged::Next { shards, folded }) => match EncodedGroups::new(folded) {
            Ok(folded) => Outcome::Next {
                folded_through: folded_through.unwrap_or_default(),
                rare_evaluations: 0,
                shards,
                folded,
                state: None,
            },
            Err(error) => {
                Outcome::Unencodable(format!("encoding the folded groups failed: {error}"))
            }
        },
        Ok(Merged::Round {
            rounds,
            shards,
            folded,
        }) => round_outcome(&rounds, shards, folded),
    };
    Ok(Ok(outcome))
}

/// A part of a merge step, as `bouncewear_shard_step_seconds` names it.
#[derive(Clone, Copy)]
enum Part {
    Read,
    Compute,
    Write,
}

/// A merge step's time in its parts, each summed over the times it comes back (a rare event's
/// round reads and computes twice once its estimate is made), recorded with the whole step as
/// `merge` ([`crate::telemetry::record_shard_step`]).
struct MergeClock {
    started: Instant,
    parts: [Duration; 3],
}

impl MergeClock {
    const NAMES: [&'static str; 3] = ["merge_read", "merge_compute", "merge_write"];

    fn start() -> Self {
        Self {
            started: Instant::now(),
            parts: [Duration::ZERO; 3],
        }
    }

    /// Awaits `work`, its time counted to `part`.
    async fn time<T>(&mut self, part: Part, work: impl Future<Output = T>) -> T {
        let started = Instant::now();
        let out = work.await;
        self.parts[part as usize] += started.elapsed();
        out
    }

    fn record(self) {
        for (name, took) in Self::NAMES.into_iter().zip(self.parts) {
            record_shard_time(name, took);
        }
        record_shard_step("merge", self.started);
    }
}

/// A rare event's round to queue, its shards and `folded`, encoded.
fn round_outcome(rounds: &Rounds, shards: Vec<ShardPlan>, folded: Vec<GroupStats>) -> Outcome {
    match (
        encode("rare-event round", rounds),
        EncodedGroups::new(folded),
    ) {
        (Ok(state), Ok(folded)) => Outcome::Next {
            shards,
            folded,
            // The devices' fold, or (a round after a round) none.
            folded_through: rounds.devices_last,
            rare_evaluations: rounds.estimator.evaluations(),
            state: Some(state),
        },
        (Err(error), _) | (_, Err(error)) => {
            Outcome::Unencodable(format!("encoding the rare event's round failed: {error}"))
        }
    }
}

/// The operations a merge step of `job`'s batch `last` ran itself, by what it made: a job run
/// `whole` its batches from this one on; a rare event estimated in the step its whole estimate,
/// or the rounds before the one it queues.
fn simulated_in_step(
    job: &Job,
    last: u64,
    whole: bool,
    ran: &Ran<Result<Outcome, MergeError>>,
) -> u64 {
    let operations = job.spec().operations;
    let batch_operations = job.spec().devices * operations;
    // The operations of the devices' batches up to `through`, the last run.
    let run_through =
        |through: u64| Batch::of(job, through).map_or(0, |b| (b.first + b.size) * operations);
    let before = last * batch_operations;
    let rare_here = rare::operations_per_evaluation(job)
        * match ran {
            Ran::Done(Ok(Outcome::Result { result, .. })) => {
                result.rare_event.as_ref().map_or(0, |r| r.evaluations)
            }
            Ran::Done(Ok(Outcome::Next {
                rare_evaluations, ..
            })) => *rare_evaluations,
            _ => 0,
        };
    match ran {
        _ if !whole => rare_here,
        Ran::Done(Ok(Outcome::Result { result, .. })) => {
            (result.counts.operations + rare_here).saturating_sub(before)
        }
        // A rare event's round follows the devices, every batch of them run, up to the last
        // (cut short by `max_devices`, perhaps); another batch follows those before it.
        Ran::Done(Ok(Outcome::Next {
            shards,
            folded_through,
            ..
        })) => match shards[0].shard.batch {
            batch if is_round(batch) => {
                (run_through(*folded_through) + rare_here).saturating_sub(before)
            }
            batch => batch * batch_operations - before,
        },
        _ => batch_operations,
    }
}

/// How a computation under a lease ended.
enum Ran<T> {
    Done(T),
    /// Stopped through the observer: `shutdown` when this process is stopping (the shard goes
    /// back to the queue), otherwise the job ended or the lease was lost (nothing to write).
    Stopped {
        shutdown: bool,
    },
    Panicked,
}

impl Workers {
    /// The shards run at the same time: as asked, or one per compute thread.
    pub fn slots(&self, requested: Option<usize>) -> usize {
        requested.unwrap_or_else(|| self.compute.current_num_threads())
    }

    /// Starts `count` worker loops; they stop, handing running shards back, when `shutdown` turns
    /// true.
    pub fn spawn(
        self: Arc<Self>,
        count: usize,
        shutdown: watch::Receiver<bool>,
    ) -> Vec<JoinHandle<()>> {
        if count > 0
            && let Some(events) = self.store.events()
        {
            tokio::spawn(wake_on_announcements(
                events,
                Arc::clone(&self.wake),
                shutdown.clone(),
            ));
        }
        (0..count)
            .map(|slot| {
                let workers = Arc::clone(&self);
                let shutdown = shutdown.clone();
                tokio::spawn(async move { workers.work(slot, shutdown).await })
            })
            .collect()
    }

    /// The lease a claim or heartbeat asks for, from now on the database's clock.
    fn lease_terms(&self) -> LeaseTerms {
        LeaseTerms::for_ms(i64::try_from(self.lease.as_millis()).unwrap_or(i64::MAX))
    }

    async fn work(self: Arc<Self>, slot: usize, shutdown: watch::Receiver<bool>) {
        let worker = format!("{}/{slot}", self.instance);
        // The next shard, claimed while a group computes; the last group's store, still writing.
        let mut ahead: Option<JoinHandle<StoreResult<Option<Claimed>>>> = None;
        let mut storing: Option<JoinHandle<()>> = None;
        // Claims that failed in a row: a database that cannot answer is asked less and less often.
        let mut failed_claims = 0;
        while !*shutdown.borrow() {
            let claimed_before = ahead.is_some();
            let claimed = match ahead.take() {
                Some(claiming) => claiming.await.unwrap_or_else(|panicked| {
                    tracing::error!(%panicked, "claiming ahead panicked");
                    Ok(None)
                }),
                None => self.claim(&worker, &shutdown).await,
            };
            if claimed.is_ok() {
                failed_claims = 0;
            }
            match claimed {
                Ok(Some((claim, lease))) => {
                    if !*shutdown.borrow()
                        && claims_ahead(claim.fence.shard, claim.operations_total)
                    {
                        let (workers, worker) = (Arc::clone(&self), worker.clone());
                        let shutdown = shutdown.clone();
                        ahead = Some(tokio::spawn(async move {
                            workers.claim(&worker, &shutdown).await
                        }));
                    }
                    self.run(claim, lease, &mut storing).await
                }
                // Nothing was claimable when the shard before began: look again before sleeping,
                // once the group still being stored (which may make its merge claimable) is in.
                Ok(None) if claimed_before || storing.is_some() => finish(storing.take()).await,
                Ok(None) => {
                    self.held.expire(HELD_GROUP_AGE);
                    let mut shutdown = shutdown.clone();
                    tokio::select! {
                        () = self.wake.notified() => {}
                        () = tokio::time::sleep(IDLE_POLL) => {}
                        _ = shutdown.changed() => {}
                    }
                }
                Err(error) => {
                    let why = match error.is_unreachable() {
                        true => self.store.why_unreachable().await,
                        false => None,
                    };
                    let wait = claim_retry_delay(failed_claims);
                    failed_claims += 1;
                    let wait_s = wait.as_secs_f64();
                    // A database that cannot answer for now is a warning: it is waited for.
                    match (why, error.is_unavailable()) {
                        (Some(why), _) => {
                            tracing::warn!(%error, why, wait_s, "claiming a shard failed")
                        }
                        (None, true) => tracing::warn!(%error, wait_s, "claiming a shard failed"),
                        (None, false) => tracing::error!(%error, wait_s, "claiming a shard failed"),
                    }
                    let mut shutdown = shutdown.clone();
                    tokio::select! {
                        () = tokio::time::sleep(wait) => {}
                        _ = shutdown.changed() => {}
                    }
                }
            }
        }
        // Stopping: a shard claimed ahead goes back to the queue at once (its heartbeat has
        // stopped), then the last group's store ends.
        if let Some(claiming) = ahead
            && let Ok(Ok(Some((claim, _lease)))) = claiming.await
        {
            self.stopped(&claim.fence, true).await;
        }
        finish(storing).await;
    }

    /// Leases the next shard, and keeps its lease from now on; the claim's time is recorded.
    async fn claim(
        &self,
        worker: &str,
        shutdown: &watch::Receiver<bool>,
    ) -> StoreResult<Option<Claimed>> {
        let claiming = Instant::now();
        let claim = self
            .store
            .claim(worker, self.lease_terms(), self.budget)
            .await?;
        Ok(claim.map(|claim| {
            record_shard_step("claim", claiming);
            let mut lease = self.keep_lease(&claim.fence, shutdown.clone());
            lease.clock_offset_ms = claim.claimed_at.0 - UnixMs::now().0;
            (claim, lease)
        }))
    }

    #[tracing::instrument(skip_all, fields(job = %claim.fence.job, shard = %claim.fence.shard, attempt = claim.fence.attempt.0))]
    async fn run(
        self: &Arc<Self>,
        claim: Claim,
        lease: KeptLease,
        storing: &mut Option<JoinHandle<()>>,
    ) {
        let fence = &claim.fence;
        let job = match Job::new(claim.spec, || 0, &Pointer::root()) {
            Ok(job) => job.with_listed_lives(self.listed_lives),
            Err(invalid) => {
                let reason = format!("the stored job no longer validates: {invalid}");
                return self.fail(fence, &lease, &reason).await;
            }
        };
        // The lease is kept from the claim to the last write: reading, computing and storing.
        match (fence.shard.group, is_round(fence.shard.batch)) {
            (Some(group), false) => self.run_group(fence, job, group, lease, storing).await,
            (None, false) => self.merge(fence, job, claim.started_at, &lease).await,
            (Some(group), true) => self.run_task(fence, job, group, &lease).await,
            (None, true) => self.merge_round(fence, job, claim.started_at, &lease).await,
        }
    }

    /// Runs one group, then encodes and stores its accumulators behind: the encoding (on the
    /// blocking pool, never on an async thread) and the write go on while this slot claims and
    /// computes its next shard (`storing`, at most one store at a time per slot).
    async fn run_group(
        self: &Arc<Self>,
        fence: &Fence,
        job: Job,
        group: u64,
        lease: KeptLease,
        storing: &mut Option<JoinHandle<()>>,
    ) {
        let Some(batch) = Batch::of(&job, fence.shard.batch).filter(|b| group < b.groups()) else {
            let reason = format!("{} is not part of the job", fence.shard);
            return self.fail(fence, &lease, &reason).await;
        };
        let devices = batch.group_devices(group);
        let operations = (devices.end - devices.start) * job.spec().operations;
        tracing::debug!(operations, "group started");
        let running = Instant::now();
        let ran = self
            .compute(&lease, Work::Planned, move |observer| {
                run_group(&job, batch, group, observer)
            })
            .await;
        let stats = match ran {
            Ran::Done(stats) => {
                record_shard_step("run", running);
                stats
            }
            Ran::Stopped { shutdown } => return self.stopped(fence, shutdown).await,
            Ran::Panicked => {
                return self
                    .fail_attempt(fence, "internal error: the simulation panicked")
                    .await;
            }
        };
        finish(storing.take()).await;
        let (workers, fence) = (Arc::clone(self), fence.clone());
        let store = async move {
            let started = Instant::now();
            let encoding = tokio::task::spawn_blocking(move || {
                let partial = partial_to_sql(&stats);
                (stats, partial)
            });
            let partial = match encoding.await {
                Ok((stats, Ok(partial))) => {
                    // Held before it is written, so that the merge this store makes claimable
                    // finds it: the same bits as any attempt's.
                    let (batch, bytes) = (fence.shard.batch, partial.len());
                    workers.held.keep(&fence.job, batch, group, bytes, stats);
                    partial
                }
                Ok((_, Err(error))) => {
                    let reason = format!("encoding the group's accumulators failed: {error}");
                    return workers.fail_attempt(&fence, &reason).await;
                }
                Err(_) => {
                    let reason = "internal error: encoding the group's accumulators panicked";
                    return workers.fail_attempt(&fence, reason).await;
                }
            };
            let complete = || workers.store.complete_encoded(&fence, partial.clone());
            if workers
                .stored(&fence, &lease, "the group's accumulators", complete)
                .await
            {
                record_shard_step("store", started);
                metrics::counter!("bouncewear_operations_simulated_total").increment(operations);
                tracing::debug!("group done");
            }
        };
        *storing = Some(tokio::spawn(store.in_current_span()));
    }

    /// Puts the done groups back in order: the Result, or the next batch of a precision target.
    async fn merge(&self, fence: &Fence, job: Job, started_at: UnixMs, lease: &KeptLease) {
        let mut clock = MergeClock::start();
        let last = fence.shard.batch;
        let read = clock.time(
            Part::Read,
            self.read_groups(fence, job, last, Holding::Use, lease),
        );
        let Some((_alone, partials)) = read.await else {
            return;
        };
        let wall_s = lease.wall_s_since(started_at);
        // A batch without groups stored is a job that entered the queue whole, at its first
        // batch or handed on after a step.
        let whole = !partials.read().iter().any(|shard| shard.batch == last);
        let job_here = partials.job().clone();
        let first_batch =
            Batch::of(&job_here, last).map_or(0, |b| b.size * job_here.spec().operations);
        let merge_planned = merge_plan(&job_here, last);
        let in_shards = groups_stay_in_shards(&job_here, last, whole);
        let (sharded_from, step) = (self.sharded_round_operations, self.whole_step);
        // A job run whole learns its total as its precision target adds batches.
        let work = if whole { Work::Growing } else { Work::Planned };
        let compute = self.compute(lease, work, move |observer| {
            let merged = if whole {
                partials
                    .finish_before_last()
                    .map_err(MergeError::from)
                    .and_then(|(job, ran)| {
                        run_whole(&job, ran, step, sharded_from, wall_s, observer)
                    })
            } else {
                merge(partials, sharded_from, wall_s, observer)
            };
            encoded(merged, in_shards)
        });
        let ran = clock.time(Part::Compute, compute).await;
        let simulated = simulated_in_step(&job_here, last, whole, &ran);
        // Its claim was charged what its shard planned: a whole step its first batch
        // (`first_shards`, `run_whole`), as its shard counts it (a step of one batch, any small
        // job without a precision target, is counted already, with no round trip to the
        // database for it); a batch's merge the rare event's budget on the last possible batch
        // ([`merge_plan`]). Beyond its charge, a step counts what it ran here (a target met
        // sooner counted nothing but what a heartbeat caught, a probe); its write then counts
        // what it ran, less than its plan too (a budget the estimate did not spend, or that
        // rounds of their own count as they run).
        let charged = if whole { first_batch } else { merge_planned };
        if simulated > charged
            && matches!(
                &ran,
                Ran::Done(Ok(Outcome::Result { .. } | Outcome::Next { .. }))
            )
        {
            self.counted(fence, simulated, charged).await;
        }
        let write = self.write(fence, ran, simulated, lease);
        clock.time(Part::Write, write).await;
        clock.record();
    }

    /// Counts the `operations` a merge step running a job whole (or a rare event's rounds) ran as
    /// its shard's own, all done, and charges its job for them
    /// ([`crate::store::Store::count_run`]), before it writes what it made: its heartbeats tell
    /// its progress at most every half second, and a step of a second ended with half of it
    /// counted (found from outside). A count the store does not take leaves the last one told.
    async fn counted(&self, fence: &Fence, operations: u64, charged: u64) {
        if let Err(error) = self.store.count_run(fence, operations, charged).await {
            tracing::warn!(%error, "the step's operations were not counted");
        }
    }

    /// Writes what a merge step made: the Result, the next batch, or a rare event's round; the
    /// devices' operations it `simulated` itself (a job run whole) are counted once it is stored.
    async fn write(
        &self,
        fence: &Fence,
        ran: Ran<Result<Outcome, MergeError>>,
        simulated: u64,
        lease: &KeptLease,
    ) {
        let count = || {
            metrics::counter!("bouncewear_operations_simulated_total").increment(simulated);
        };
        let next = match ran {
            Ran::Done(Ok(Outcome::Unencodable(reason))) => {
                return self.fail_attempt(fence, &reason).await;
            }
            Ran::Done(Ok(Outcome::Result { result, encoded })) => {
                if self
                    .succeed(fence, simulated, &result, &encoded, lease)
                    .await
                {
                    count();
                }
                return;
            }
            Ran::Done(Ok(Outcome::Next {
                shards,
                folded,
                folded_through,
                state,
                ..
            })) => (shards, folded, folded_through, state),
            Ran::Done(Err(failed @ (MergeError::RareEvent(_) | MergeError::OutOfRange(_)))) => {
                return self.fail(fence, lease, &failed.to_string()).await;
            }
            Ran::Done(Err(other)) => return self.fail_attempt(fence, &other.to_string()).await,
            Ran::Stopped { shutdown } => return self.stopped(fence, shutdown).await,
            Ran::Panicked => {
                return self
                    .fail_attempt(fence, "internal error: merging the groups panicked")
                    .await;
            }
        };
        let (shards, folded, folded_through, state) = next;
        let queue = || {
            self.store.add_batch(
                fence,
                simulated,
                &shards,
                &folded,
                folded_through,
                state.as_deref(),
            )
        };
        if self.stored(fence, lease, "the next step", queue).await {
            count();
            tracing::info!("next step queued (a precision target's batch or a rare event's round)");
        }
    }

    /// Writes what a shard made (`what`), trying again while the database cannot take it;
    /// whether it was written. A write the claim no longer holds is dropped; one that failed
    /// counts against the shard's retries.
    async fn stored<F>(
        &self,
        fence: &Fence,
        lease: &KeptLease,
        what: &str,
        write: impl FnMut() -> F,
    ) -> bool
    where
        F: Future<Output = StoreResult<bool>>,
    {
        match self.store_with_backoff(lease, write).await {
            Ok(written) => {
                if !written {
                    tracing::info!("{what} discarded: the job ended or the shard was taken over");
                }
                written
            }
            Err(error) => {
                self.database_failed(fence, lease, &format!("storing {what}"), error)
                    .await;
                false
            }
        }
    }

    /// Runs one task of a rare event's round and stores its outcome.
    async fn run_task(&self, fence: &Fence, job: Job, group: u64, lease: &KeptLease) {
        let rounds = match self.store.round(&fence.job, fence.shard.batch).await {
            Ok(rounds) => rounds,
            Err(error) => {
                let what = "reading the rare event's round";
                return self.database_failed(fence, lease, what, error).await;
            }
        };
        let Some(task) = rounds.task(group) else {
            let reason = format!("{} is not part of the job", fence.shard);
            return self.fail(fence, lease, &reason).await;
        };
        let operations = rounds.operations_of(&job, task);
        let running = Instant::now();
        let ran = self
            .compute(lease, Work::Planned, move |observer| {
                if observer.cancelled() {
                    return Err(Cancelled);
                }
                match rare::run_task(&job, &rounds.estimator, task) {
                    Ok(outcome) => Ok(Ok(encode("rare-event task outcome", &outcome))),
                    Err(RunError::Cancelled(cancelled)) => Err(cancelled),
                    Err(failed) => Ok(Err(failed)),
                }
            })
            .await;
        let outcome = match ran {
            Ran::Done(Ok(Ok(outcome))) => outcome,
            Ran::Done(Ok(Err(unencodable))) => {
                let reason = format!("encoding the task's outcome failed: {unencodable}");
                return self.fail_attempt(fence, &reason).await;
            }
            Ran::Done(Err(failed)) => return self.fail(fence, lease, &failed.to_string()).await,
            Ran::Stopped { shutdown } => return self.stopped(fence, shutdown).await,
            Ran::Panicked => {
                return self
                    .fail_attempt(fence, "internal error: the rare-event task panicked")
                    .await;
            }
        };
        record_shard_step("run", running);
        let storing = Instant::now();
        let complete = || self.store.complete_encoded(fence, outcome.clone());
        if self
            .stored(fence, lease, "the task's outcome", complete)
            .await
        {
            // As a group's store is (the counter and the step missed every round run as shards).
            record_shard_step("store", storing);
            metrics::counter!("bouncewear_operations_simulated_total").increment(operations);
            tracing::debug!("rare-event task done");
        }
    }

    /// A rare event's round's merge step: takes its tasks' outcomes, runs the next rounds while
    /// they are small, and queues the next large one or, the estimate made, stores the Result
    /// from the devices' groups.
    async fn merge_round(&self, fence: &Fence, job: Job, started_at: UnixMs, lease: &KeptLease) {
        let mut clock = MergeClock::start();
        let read = async {
            let rounds = self.store.round(&fence.job, fence.shard.batch).await?;
            let outcomes = self
                .store
                .round_outcomes(&fence.job, fence.shard.batch)
                .await?;
            StoreResult::Ok((rounds, outcomes))
        };
        let (rounds, outcomes) = match clock.time(Part::Read, read).await {
            Ok(read) => read,
            Err(error) => {
                let what = "reading the rare event's round";
                return self.database_failed(fence, lease, what, error).await;
            }
        };
        let devices_last = rounds.devices_last;
        let sharded_from = self.sharded_round_operations;
        let round_job = job.clone();
        let compute = self.compute(lease, Work::Planned, move |observer| {
            match merge_round(&round_job, rounds, outcomes, sharded_from, observer) {
                Err(MergeError::Cancelled(cancelled)) => Err(cancelled),
                Err(other) => Ok(Err(other)),
                Ok((RoundMerged::Next { rounds, shards }, ran)) => {
                    Ok(Ok(Ok((round_outcome(&rounds, shards, Vec::new()), ran))))
                }
                Ok((RoundMerged::Estimated(report), ran)) => Ok(Ok(Err((report, ran)))),
            }
        });
        // The rounds the step estimated itself count as it ran them, before what it made is
        // written (their progress reached the store at its heartbeats alone), and its write
        // counts them again as the step's own (it counted 0 there, and the probe's progress fell
        // by the rounds at each step's end).
        let (report, rounds_ran) = match clock.time(Part::Compute, compute).await {
            Ran::Done(Ok(Ok((next, ran)))) => {
                if ran > 0 {
                    self.counted(fence, ran, 0).await;
                }
                let write = self.write(fence, Ran::Done(Ok(next)), ran, lease);
                clock.time(Part::Write, write).await;
                return clock.record();
            }
            Ran::Done(Ok(Err((report, ran)))) => {
                if ran > 0 {
                    self.counted(fence, ran, 0).await;
                }
                (report, ran)
            }
            Ran::Done(Err(error)) => {
                let write = self.write(fence, Ran::Done(Err(error)), 0, lease);
                clock.time(Part::Write, write).await;
                return clock.record();
            }
            Ran::Stopped { shutdown } => return self.stopped(fence, shutdown).await,
            Ran::Panicked => {
                return self
                    .fail_attempt(fence, "internal error: merging the round panicked")
                    .await;
            }
        };
        // The estimate is made: the Result from the devices' groups.
        let read = clock.time(
            Part::Read,
            self.read_groups(fence, job, devices_last, Holding::Stale, lease),
        );
        let Some((_alone, devices)) = read.await else {
            return;
        };
        let wall_s = lease.wall_s_since(started_at);
        let compute = self.compute(lease, Work::Planned, move |_| {
            encoded(estimated(devices, report, wall_s), false)
        });
        let ran = clock.time(Part::Compute, compute).await;
        clock
            .time(Part::Write, self.write(fence, ran, rounds_ran, lease))
            .await;
        clock.record();
    }

    /// The job's groups up to batch `last`, read into a [`Folding`], with this instance's
    /// large-merge permit held for a merge beyond [`LARGE_MERGE_ACCUMULATORS`]; `None` once the
    /// attempt failed.
    async fn read_groups(
        &self,
        fence: &Fence,
        job: Job,
        last: u64,
        holding: Holding,
        lease: &KeptLease,
    ) -> Option<(Option<SemaphorePermit<'_>>, Folding)> {
        let alone = if merge_accumulators(&job) > LARGE_MERGE_ACCUMULATORS {
            match self.large_merges.acquire().await {
                Ok(permit) => Some(permit),
                Err(closed) => {
                    self.fail_attempt(fence, &closed.to_string()).await;
                    return None;
                }
            }
        } else {
            None
        };
        let held = self.held.take(&fence.job, last);
        let held = match holding {
            Holding::Use => held,
            Holding::Stale => Vec::new(),
        };
        match self
            .store
            .partials(&fence.job, Folding::new(job, last).holding(held))
            .await
        {
            Ok(partials) => Some((alone, partials)),
            Err(error) => {
                let what = "reading the groups' accumulators";
                self.database_failed(fence, lease, what, error).await;
                None
            }
        }
    }

    /// Heartbeats the shard's lease with its progress until the returned guard is dropped; stops
    /// the computation (through its observer) when the job ends, the lease is lost or the process
    /// is stopping.
    fn keep_lease(&self, fence: &Fence, mut shutdown: watch::Receiver<bool>) -> KeptLease {
        let cancel = Arc::new(AtomicBool::new(false));
        let stopping = Arc::new(AtomicBool::new(false));
        let done = Arc::new(AtomicU64::new(0));
        let total = Arc::new(AtomicU64::new(0));
        let period = (self.lease / 3).min(HEARTBEAT_MAX_PERIOD);
        let keeper = {
            let (store, fence) = (Arc::clone(&self.store), fence.clone());
            let (cancel, stopping, done, total) = (
                Arc::clone(&cancel),
                Arc::clone(&stopping),
                Arc::clone(&done),
                Arc::clone(&total),
            );
            let duration_ms = i64::try_from(self.lease.as_millis()).unwrap_or(i64::MAX);
            tokio::spawn(async move {
                let mut heartbeat = tokio::time::interval(period);
                heartbeat.tick().await; // the claim itself just set the lease
                loop {
                    tokio::select! {
                        _ = heartbeat.tick() => {
                            let terms = LeaseTerms::for_ms(duration_ms);
                            let progress = done.load(Ordering::Relaxed);
                            let total = total.load(Ordering::Relaxed);
                            match store.heartbeat(&fence, terms, progress, total).await {
                                Ok(Lease::Held) => {}
                                Ok(lease @ (Lease::Cancelled | Lease::Lost)) => {
                                    tracing::info!(?lease, "stopping: the shard is no longer ours to run");
                                    cancel.store(true, Ordering::Relaxed);
                                    return;
                                }
                                Err(error) => tracing::warn!(%error, "heartbeat failed; the lease may expire"),
                            }
                        }
                        _ = shutdown.changed() => {
                            stopping.store(true, Ordering::Relaxed);
                            cancel.store(true, Ordering::Relaxed);
                            return;
                        }
                    }
                }
            })
        };
        KeptLease {
            cancel,
            stopping,
            done,
            total,
            keeper,
            clock_offset_ms: 0,
        }
    }

    /// Runs `task` on the compute pool, reporting its progress to the lease (of the `work` it
    /// has) and stopping when the lease says so.
    async fn compute<T: Send + 'static>(
        &self,
        lease: &KeptLease,
        work: Work,
        task: impl FnOnce(&dyn Observer) -> Result<T, Cancelled> + Send + 'static,
    ) -> Ran<T> {
        let (sender, finished) = oneshot::channel();
        let (cancel, done) = (Arc::clone(&lease.cancel), Arc::clone(&lease.done));
        let total = Arc::clone(&lease.total);
        self.compute.spawn(move || {
            let observer = Watch {
                cancel: &cancel,
                on_progress: |d, t| {
                    done.store(d, Ordering::Relaxed);
                    if matches!(work, Work::Growing) {
                        total.store(t, Ordering::Relaxed);
                    }
                },
            };
            let _ = sender.send(std::panic::catch_unwind(AssertUnwindSafe(|| {
                task(&observer)
            })));
        });
        match finished.await {
            Ok(Ok(Ok(value))) => Ran::Done(value),
            Ok(Ok(Err(Cancelled))) => Ran::Stopped {
                shutdown: lease.stopping.load(Ordering::Relaxed),
            },
            Ok(Err(_)) | Err(_) => Ran::Panicked,
        }
    }

    /// After a stop: hands the shard back for a shutdown; otherwise there is nothing to write.
    async fn stopped(&self, fence: &Fence, shutdown: bool) {
        if !shutdown {
            return tracing::info!("shard stopped (the job ended or the shard was taken over)");
        }
        match self.store.release(fence).await {
            Ok(_) => tracing::info!("handed back to the queue for shutdown"),
            Err(error) => {
                tracing::error!(%error, "could not hand the shard back; its lease will expire")
            }
        }
    }

    /// Ends the job as failed, with the reason (no retry can mend it), counting what the shard ran
    /// of its total as its lease last heard; a failure to write it leaves the lease to expire, and
    /// the shard to be rerun.
    async fn fail(&self, fence: &Fence, lease: &KeptLease, reason: &str) {
        tracing::error!(reason, "job failed");
        let ran = lease.done.load(Ordering::Relaxed);
        let total = lease.total.load(Ordering::Relaxed);
        match self.store.fail(fence, None, [ran, total], reason).await {
            Ok(true) => {
                metrics::counter!("bouncewear_jobs_finished_total", "status" => "failed")
                    .increment(1);
                metrics::counter!("bouncewear_operations_simulated_total").increment(ran);
            }
            Ok(false) => {}
            Err(error) => {
                tracing::error!(%error, "could not mark the job failed; its lease will expire")
            }
        }
    }

    /// Hands a shard whose run failed back to the queue, counting the failure towards the limit.
    async fn fail_attempt(&self, fence: &Fence, reason: &str) {
        tracing::error!(reason, "shard failed");
        if let Err(error) = self
            .store
            .fail_attempt(fence, None, reason, self.budget.failures)
            .await
        {
            tracing::error!(%error, "could not record the failure; the shard's lease will expire");
        }
    }

    /// A shard's step the database could not serve (`what`: reading what it needs, or storing what
    /// it made): with no room on the disk, or no connection, the shard waits (nothing counted
    /// against it: the job is not at fault; a merge step's read that found no free PostgreSQL
    /// connection counted as a failed run, found from outside); any other error counts as a
    /// failed run.
    async fn database_failed(
        &self,
        fence: &Fence,
        lease: &KeptLease,
        what: &str,
        error: StoreError,
    ) {
        // No room on the disk (this store's check, or the database's own full disk), or no
        // connection to the database in all the write's tries (none free, unreachable): nothing
        // is wrong with the job, which waits rather than fail. Any other error the database
        // reports counts against the shard.
        let (awaited, reason) = match error {
            StoreError::NoRoom(room) => (Awaited::Room, format!("{what}: {room}")),
            error if error.is_out_of_space() => (Awaited::Room, format!("{what}: {error}")),
            error if error.is_unreachable() => (Awaited::Database, format!("{what}: {error}")),
            error => {
                return self
                    .fail_attempt(fence, &format!("{what} failed: {error}"))
                    .await;
            }
        };
        match awaited {
            Awaited::Database => match self.store.why_unreachable().await {
                Some(why) => tracing::warn!(reason, why, ?awaited, "shard waits"),
                None => tracing::warn!(reason, ?awaited, "shard waits"),
            },
            Awaited::Room => tracing::warn!(reason, ?awaited, "shard waits"),
        }
        // The hand-back is a write too, which the same full disk or outage can refuse (a probe:
        // PostgreSQL at 0 bytes free). It is tried again for as long as the database cannot
        // answer and nothing stopped the shard, not `--max-lost-leases` times: given up while
        // PostgreSQL was down, the shard sat "running" with nothing running it, `waiting` null,
        // until its lease expired (a whole lease after the outage, found from outside), and the
        // expiry counted against it. Once the database answers, the shard waits with its reason,
        // or the lease was lost meanwhile and the fence refuses the write.
        let hand_back = || self.store.wait_for(fence, None, awaited, &reason);
        let delay = STORE_RETRY_FIRST_DELAY;
        if let Err(error) = retry_unavailable(None, &lease.cancel, delay, hand_back).await {
            tracing::error!(%error, "could not hand the shard back; its lease will expire");
        }
    }

    /// Stores the Result; whether it was stored.
    async fn succeed(
        &self,
        fence: &Fence,
        ran: u64,
        result: &JobResult,
        encoded: &EncodedResult,
        lease: &KeptLease,
    ) -> bool {
        let stored = self
            .store_with_backoff(lease, || self.store.succeed(fence, None, ran, encoded))
            .await;
        match stored {
            Ok(Some(stored_bytes)) => {
                metrics::counter!("bouncewear_jobs_finished_total", "status" => "succeeded")
                    .increment(1);
                let operations = result.job.devices_run() * result.job.spec().operations;
                record_job_finished(result.timing.wall_s, operations, stored_bytes);
                tracing::info!(wall_s = result.timing.wall_s, stored_bytes, "job succeeded");
                true
            }
            Ok(None) => {
                tracing::info!(
                    "result discarded: the job ended or the merge was taken over meanwhile"
                );
                false
            }
            Err(error) => {
                self.database_failed(fence, lease, "storing the result", error)
                    .await;
                false
            }
        }
    }

    /// Runs a write of a shard's outcome, trying again with backoff while the database cannot
    /// take it (full, unreachable, busy) and the lease holds, at most `retries` times: the outcome
    /// is kept, not computed again. The error that remains goes to [`Workers::fail_attempt`], so
    /// it counts against the same limit as a failed run.
    async fn store_with_backoff<T, F>(
        &self,
        lease: &KeptLease,
        write: impl FnMut() -> F,
    ) -> StoreResult<T>
    where
        F: Future<Output = StoreResult<T>>,
    {
        let tries = Some(self.budget.lost_leases);
        retry_unavailable(tries, &lease.cancel, STORE_RETRY_FIRST_DELAY, write).await
    }
}

/// Runs `write`, trying again while the database cannot take it (unreachable, busy; not a full
/// disk, which the shard waits out) and nothing stopped the shard (`cancel`): after `delay`,
/// doubling up to [`STORE_RETRY_MAX_DELAY`], at most `tries` times, or for as long as that
/// holds with `None`.
async fn retry_unavailable<T, F>(
    tries: Option<u64>,
    cancel: &AtomicBool,
    mut delay: Duration,
    mut write: impl FnMut() -> F,
) -> StoreResult<T>
where
    F: Future<Output = StoreResult<T>>,
{
    let mut tried = 0;
    loop {
        match write().await {
            Err(error)
                if error.is_unavailable()
                    && !matches!(error, StoreError::NoRoom(_))
                    && tries.is_none_or(|tries| tried < tries)
                    && !cancel.load(Ordering::Relaxed) =>
            {
                tried += 1;
                metrics::counter!("bouncewear_store_retries_total").increment(1);
                tracing::warn!(%error, tries = tried, ?delay, "the database did not take the write; trying again");
                tokio::time::sleep(delay).await;
                delay = (delay * 2).min(STORE_RETRY_MAX_DELAY);
            }
            outcome => return outcome,
        }
    }
}

/// A claimed shard with its lease, kept from the claim on.
type Claimed = (Claim, KeptLease);

/// Waits for a store behind to end (it reports its own failure).
async fn finish(storing: Option<JoinHandle<()>>) {
    if let Some(storing) = storing
        && let Err(panicked) = storing.await
    {
        tracing::error!(%panicked, "storing a group panicked");
    }
}

/// Wakes idle workers when the database announces a queued job (from any instance), so that a
/// second machine starts at once rather than at its next poll.
async fn wake_on_announcements(
    mut events: broadcast::Receiver<QueueEvent>,
    wake: Arc<Notify>,
    mut shutdown: watch::Receiver<bool>,
) {
    loop {
        tokio::select! {
            event = events.recv() => match event {
                Ok(QueueEvent::Queued) | Err(broadcast::error::RecvError::Lagged(_)) => wake.notify_waiters(),
                Ok(QueueEvent::Changed(_)) => {}
                Err(broadcast::error::RecvError::Closed) => return,
            },
            _ = shutdown.changed() => return,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A write the database cannot take is tried again: `tries` times, or with `None` until it
    /// answers or the shard is stopped; any other error, and a full disk, at once.
    #[tokio::test]
    async fn a_write_is_tried_again_while_the_database_cannot_answer() {
        let calls = std::cell::Cell::new(0_u64);
        let cancel = AtomicBool::new(false);
        let delay = Duration::from_millis(1);
        // Unavailable `failing` times, then the write is taken; `stop_at` sets `cancel`.
        let write = |failing: u64, stop_at: Option<u64>| {
            let (calls, cancel) = (&calls, &cancel);
            move || {
                calls.set(calls.get() + 1);
                if stop_at == Some(calls.get()) {
                    cancel.store(true, Ordering::Relaxed);
                }
                let outcome = match calls.get() <= failing {
                    true => Err(StoreError::Database(sqlx::Error::PoolTimedOut)),
                    false => Ok(calls.get()),
                };
                std::future::ready(outcome)
            }
        };
        // Past any count of tries, until it answers.
        assert_eq!(
            retry_unavailable(None, &cancel, delay, write(9, None))
                .await
                .ok(),
            Some(10)
        );
        calls.set(0);
        let limited = retry_unavailable(Some(3), &cancel, delay, write(9, None)).await;
        assert!(limited.is_err_and(|error| error.is_unavailable()));
        assert_eq!(calls.get(), 4);
        calls.set(0);
        let stopped = retry_unavailable(None, &cancel, delay, write(u64::MAX, Some(5))).await;
        assert!(stopped.is_err() && calls.get() == 5);
        cancel.store(false, Ordering::Relaxed);
        for error in [
            StoreError::Conflict("no".into()),
            StoreError::NoRoom("full".into()),
        ] {
            calls.set(0);
            let error = std::cell::RefCell::new(Some(error));
            let once = || {
                calls.set(calls.get() + 1);
                std::future::ready(Err::<(), _>(error.borrow_mut().take().unwrap()))
            };
            assert!(retry_unavailable(None, &cancel, delay, once).await.is_err());
            assert_eq!(calls.get(), 1);
        }
    }
    use crate::telemetry::prometheus_builder;
    use bouncewear_model::montecarlo::Silent;

    /// Held groups go to their own batch's merge, once; the oldest go beyond the budget or past
    /// the age, and a group larger than the budget is not held.
    #[test]
    fn a_failing_claim_is_retried_less_often_up_to_eight_seconds() {
        let waits: Vec<f64> = (0..7).map(|n| claim_retry_delay(n).as_secs_f64()).collect();
        assert_eq!(waits, [0.5, 1.0, 2.0, 4.0, 8.0, 8.0, 8.0]);
        assert_eq!(claim_retry_delay(u32::MAX), Duration::from_secs(8));
    }

    #[test]
    fn held_groups_go_to_their_batchs_merge_and_the_oldest_beyond_the_budget() {
        let job = Job::from_json(r#"{"devices": 4, "operations": 2, "seed": 1}"#, || 0).unwrap();
        let batch = Batch::of(&job, 0).unwrap();
        let stats = || run_group(&job, batch, 0, &Silent).unwrap();
        let groups = |taken: Vec<(u64, GroupStats)>| -> Vec<u64> {
            taken.into_iter().map(|(group, _)| group).collect()
        };
        let held = HeldGroups::new(100);
        let (a, b) = (JobId::from("a"), JobId::from("b"));
        held.keep(&a, 0, 0, 40, stats());
        held.keep(&a, 1, 0, 40, stats());
        held.keep(&b, 0, 1, 40, stats());
        held.keep(&b, 0, 2, 101, stats());
        assert!(
            held.take(&a, 0).is_empty(),
            "the oldest went past the budget"
        );
        assert_eq!(groups(held.take(&a, 1)), [0]);
        assert_eq!(groups(held.take(&b, 0)), [1]);
        assert!(held.take(&b, 0).is_empty(), "taken once");
        assert_eq!(held.lock().bytes, 0);
        held.keep(&a, 2, 0, 40, stats());
        held.expire(Duration::from_secs(60));
        assert_eq!(held.lock().bytes, 40, "held less than the age");
        held.expire(Duration::ZERO);
        assert!(held.take(&a, 2).is_empty(), "given up past the age");
        assert_eq!(held.lock().bytes, 0);
    }

    /// The recorded `bouncewear_shard_step_seconds` of `step`: its count and sum.
    fn recorded(text: &str, step: &str) -> (u64, f64) {
        let value = |suffix: &str| {
            let name = format!("bouncewear_shard_step_seconds_{suffix}{{step=\"{step}\"}} ");
            let line = text.lines().find_map(|line| line.strip_prefix(&name));
            line.unwrap_or_else(|| panic!("{name} in {text}"))
        };
        (
            value("count").parse().unwrap(),
            value("sum").parse().unwrap(),
        )
    }

    #[test]
    fn a_merge_records_each_part_summed_over_its_returns_and_the_whole() {
        let recorder = prometheus_builder().build_recorder();
        let handle = recorder.handle();
        let pause = Duration::from_millis(30);
        metrics::with_local_recorder(&recorder, || {
            let runtime = tokio::runtime::Builder::new_current_thread()
                .enable_time()
                .build()
                .unwrap();
            runtime.block_on(async {
                // As a rare event's round once its estimate is made: read, compute, read again.
                let mut clock = MergeClock::start();
                clock.time(Part::Read, tokio::time::sleep(pause)).await;
                clock.time(Part::Compute, async {}).await;
                clock.time(Part::Read, tokio::time::sleep(pause)).await;
                clock.time(Part::Write, tokio::time::sleep(pause)).await;
                clock.record();
            });
        });
        let text = handle.render();
        let [read, compute, write, merge] =
            ["merge_read", "merge_compute", "merge_write", "merge"].map(|s| recorded(&text, s));
        assert!(
            [read, compute, write, merge]
                .iter()
                .all(|(count, _)| *count == 1)
        );
        // A sleep lasts at least its pause: lower bounds only, never a timing.
        assert!(read.1 >= 2.0 * pause.as_secs_f64(), "{text}");
        assert!(write.1 >= pause.as_secs_f64(), "{text}");
        assert!(read.1 + compute.1 + write.1 <= merge.1, "{text}");
    }
}
