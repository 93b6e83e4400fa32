//! Storage in its own language: typed ids and times in, typed records and [`StoreError`] out, no
//! JSON strings for callers to parse again. The traits are split by concern (the job queue, results,
//! schedules); [`Store`] is all three, so that the handlers, workers and scheduler never see SQL.
//!
//! One body of SQL serves both databases ([`SqlStore`]): `queue.rs`, `results.rs` and
//! `schedules.rs` implement the traits once, with `$N` placeholders; `rows.rs` maps each table's
//! rows; `sql.rs` runs a statement on either database. What truly differs (pools, locks, the
//! clock, SQLite's file checks, PostgreSQL's announcements) is `backend.rs` with `sqlite.rs`
//! (embedded, the default) and `postgres.rs` (several instances on several machines). Each keeps
//! its migrations (`migrations/sqlite/`, `migrations/postgres/`). [`open`] picks one from the
//! database URL.

mod backend;
mod migrations;
mod postgres;
mod queue;
mod results;
mod rows;
mod schedules;
mod sql;
mod sqlite;

pub use backend::SqlStore;
pub(crate) use rows::partial_to_sql;
pub use rows::{EncodedGroups, EncodedResult, encode};

use crate::domain::rare::Rounds;
use crate::domain::{
    Attempt, Folding, IdempotencyKey, JobId, JobStatus, Once, Owner, QueueBound, QueuedJob,
    ScheduleBound, ScheduleDefinition, ScheduleId, ShardId, ShardPlan, UnixMs,
};
use async_trait::async_trait;
use bouncewear_model::montecarlo::engine::GroupStats;
use bouncewear_model::montecarlo::rare::Outcome;
use bouncewear_model::montecarlo::{DeviceLife, JobResult, JobSpec};
use bouncewear_model::stats::{Accumulator, Summary};
use std::sync::Arc;

pub type StoreResult<T> = Result<T, StoreError>;

#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    /// No such thing for this owner (another owner's things do not exist for the caller).
    #[error("no {kind} {id}")]
    NotFound { kind: &'static str, id: String },
    /// The request contradicts the stored state, e.g. cancelling a job that already ended.
    #[error("{0}")]
    Conflict(String),
    #[error("database: {0}")]
    Database(#[from] sqlx::Error),
    #[error("migration: {0}")]
    Migration(#[from] sqlx::migrate::MigrateError),
    /// The database URL names no backend this build has.
    #[error(
        "unsupported database URL scheme `{0}`: use sqlite://FILE (embedded, the default) or postgres://USER@HOST/DATABASE"
    )]
    UnsupportedUrl(String),
    /// A stored document no longer reads as its type (written by another version, or damaged).
    #[error("stored {what} cannot be read: {detail}")]
    Corrupt { what: &'static str, detail: String },
    /// This instance cannot do its work now, and why (see [`JobQueue::ready`]).
    #[error("not ready: {0}")]
    NotReady(String),
    /// A write the disk beside a SQLite database has no room for now, and what it needs.
    #[error("no room: {0}")]
    NoRoom(String),
    /// The owner's jobs store `used` bytes, at or over the `quota` a new job needs below it
    /// ([`crate::domain::QueueBound::stored_per_owner`]).
    #[error(
        "the jobs of this API key (of every client, where the server has no keys) store {used} \
         bytes, at or over its quota of {quota} bytes (--max-stored-mb-per-key): delete the \
         jobs it no longer needs (DELETE /v1/jobs/{{id}}?purge=true) before submitting more"
    )]
    OverQuota { used: u64, quota: u64 },
    /// The owner holds `most` schedules, as many as [`crate::domain::ScheduleBound::per_owner`]
    /// allows.
    #[error(
        "this API key (every client, where the server has no keys) holds {most} schedules, the \
         most it may (--max-schedules-per-key): delete one it no longer needs \
         (DELETE /v1/schedules/{{id}}) before creating another"
    )]
    TooManySchedules { most: u64 },
}

impl StoreError {
    pub(crate) fn job_not_found(id: &JobId) -> Self {
        Self::NotFound {
            kind: "job",
            id: id.to_string(),
        }
    }

    /// Whether the database rolled the transaction back to break a deadlock between it and
    /// another (PostgreSQL's `40P01`): run again, it goes through.
    pub(crate) fn is_deadlock(&self) -> bool {
        matches!(self, StoreError::Database(sqlx::Error::Database(error))
            if error.code().as_deref() == Some("40P01"))
    }

    /// Whether the database failed to answer for now (unreachable, busy, out of space, read-only,
    /// not ready): a retry later may succeed. Any other failure is the stored data's or ours.
    pub fn is_unavailable(&self) -> bool {
        match self {
            StoreError::NotReady(_) | StoreError::NoRoom(_) => true,
            StoreError::Database(sqlx::Error::Database(error)) => {
                matches!(error.kind(), sqlx::error::ErrorKind::Other)
            }
            StoreError::Database(error) => matches!(
                error,
                sqlx::Error::Io(_)
                    | sqlx::Error::Tls(_)
                    | sqlx::Error::Protocol(_)
                    | sqlx::Error::PoolTimedOut
                    | sqlx::Error::PoolClosed
                    | sqlx::Error::WorkerCrashed
            ),
            _ => false,
        }
    }

    /// Whether no connection reached the database (none free in the pool in time, refused,
    /// reset), or SQLite's file stayed locked by another process for all of `busy_timeout`:
    /// unlike an error the database itself reports (a full disk, a refused statement), nothing
    /// says the write would fail once one does.
    pub fn is_unreachable(&self) -> bool {
        match self {
            StoreError::Database(
                sqlx::Error::PoolTimedOut | sqlx::Error::PoolClosed | sqlx::Error::Io(_),
            ) => true,
            StoreError::Database(sqlx::Error::Database(error)) => error
                .try_downcast_ref::<sqlx::sqlite::SqliteError>()
                .and_then(|sqlite| {
                    sqlx::error::DatabaseError::code(sqlite)?
                        .parse::<i32>()
                        .ok()
                })
                // SQLITE_BUSY and its extended codes.
                .is_some_and(|code| code & 0xff == 5),
            _ => false,
        }
    }

    pub(crate) fn schedule_not_found(id: &ScheduleId) -> Self {
        Self::NotFound {
            kind: "schedule",
            id: id.to_string(),
        }
    }
}

/// A job as stored.
#[derive(Debug, Clone, PartialEq)]
pub struct JobRecord {
    /// Submission order: the paging cursor.
    pub seq: i64,
    pub id: JobId,
    pub owner: Owner,
    pub name: Option<String>,
    /// The seed the job runs with, fixed at submission.
    pub seed: u64,
    pub status: JobStatus,
    /// Summed over the job's shards.
    pub operations_done: u64,
    pub operations_total: u64,
    pub error: Option<String>,
    pub created_at: UnixMs,
    pub started_at: Option<UnixMs>,
    pub finished_at: Option<UnixMs>,
    /// Bytes stored for the job: its spec, its groups' accumulators while it runs, and once it
    /// succeeded its Result, distributions (with their final groups' accumulators) and listed
    /// device lives (not the database's own
    /// overhead: indexes, free pages).
    pub stored_bytes: u64,
}

/// One page of a newest-first listing: the rows below the cursor `before` (a `seq`).
#[derive(Debug, Clone, Copy)]
pub struct Page {
    pub before: Option<i64>,
    pub limit: u32,
}

/// The claim a worker holds on one shard of a job: every write of that claim carries it, and is
/// refused once another claim replaced it (fencing) or the job ended.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Fence {
    pub job: JobId,
    pub shard: ShardId,
    pub attempt: Attempt,
}

/// A lease's terms: taken or renewed now, held for `duration_ms`.
#[derive(Debug, Clone, Copy)]
pub struct LeaseTerms {
    /// The instant "now" is: `None` reads the database's clock, which is what workers do, so that
    /// machines whose clocks disagree still agree on when every lease ends; `Some` fixes it (tests
    /// that step time).
    pub at: Option<UnixMs>,
    pub duration_ms: i64,
}

impl LeaseTerms {
    /// Terms on the database's clock.
    pub fn for_ms(duration_ms: i64) -> Self {
        Self {
            at: None,
            duration_ms,
        }
    }
}

/// A shard a worker has leased.
#[derive(Debug, Clone)]
pub struct Claim {
    pub fence: Fence,
    /// The job as validated at submission, seed fixed.
    pub spec: JobSpec,
    /// The shard's operations (none for a merge step).
    pub operations_total: u64,
    /// When the job's first shard was claimed: a merge step reports the run's wall time from it.
    pub started_at: UnixMs,
    /// When this claim was made, on the database's clock (as `started_at`): a worker whose own
    /// clock differs reads the database's time from it.
    pub claimed_at: UnixMs,
}

/// A shard as stored: where it stands, and how often it ran.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ShardRecord {
    pub shard: ShardId,
    /// `queued`, `running` or `done`.
    pub status: String,
    /// Claims so far (the fencing attempt): 1 for a shard that ran once.
    pub attempt: Attempt,
    /// Runs that failed.
    pub failures: u64,
    /// Leases that expired before the run ended (a worker killed or stalled, an outage).
    pub lost_leases: u64,
    pub worker: Option<String>,
    pub operations_done: u64,
    pub operations_total: u64,
    pub error: Option<String>,
    /// One line per attempt that did not finish: which, by whom, and why.
    pub history: Vec<String>,
}

impl ShardRecord {
    /// The shard as its job, of status `job`, leaves it: a job that ended cancelled or failed runs
    /// nothing more, so a shard still stored as running (its worker stops at its next heartbeat
    /// or store, or was gone) reads as `queued`, never to be claimed, its history ending with the
    /// attempt the end stopped. Decided when read rather than written by the end, so that ending
    /// a job locks none of its shards: ends, claims and heartbeats lock a shard and then its job.
    pub fn as_ended_by(mut self, job: &str) -> Self {
        if self.status == "running" && matches!(job, "cancelled" | "failed") {
            let worker = self.worker.as_deref().unwrap_or("?");
            let attempt = self.attempt.0;
            let line = format!("attempt {attempt} ({worker}): stopped: job {job}");
            self.history.push(line);
            self.status = "queued".to_owned();
        }
        self
    }
}

/// What a heartbeat found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Lease {
    /// The lease is still ours and was extended.
    Held,
    /// The job ended (cancelled by any instance, or failed by another shard): stop.
    Cancelled,
    /// Another worker took the shard over (our lease expired): stop and write nothing.
    Lost,
}

/// One stored bin of one metric.
#[derive(Debug, Clone)]
pub struct DistributionRow {
    /// `operation` (one bin of operations) or `device` (at the end of the test).
    pub kind: String,
    pub bin: i64,
    pub op_start: u64,
    pub op_end: u64,
    pub summary: Summary,
}

/// A half-open range of operations, `[start, end)`.
#[derive(Debug, Clone, Copy)]
pub struct Operations {
    pub start: u64,
    pub end: u64,
}

/// A schedule as stored.
#[derive(Debug, Clone, PartialEq)]
pub struct ScheduleRecord {
    pub id: ScheduleId,
    pub owner: Owner,
    pub definition: ScheduleDefinition,
    /// The next due time; none while disabled.
    pub next_run_at: Option<UnixMs>,
    pub created_at: UnixMs,
    pub updated_at: UnixMs,
}

/// One run of a schedule, with its job's status.
#[derive(Debug, Clone, PartialEq)]
pub struct RunRecord {
    /// The due time, or the request time of a manual run.
    pub scheduled_for: UnixMs,
    pub job_id: JobId,
    pub manual: bool,
    pub status: JobStatus,
}

/// The (schedule, due time) slot a run takes: at most one job per slot, ever.
#[derive(Debug, Clone, Copy)]
pub struct RunSlot<'a> {
    pub schedule: &'a ScheduleId,
    pub scheduled_for: UnixMs,
    pub manual: bool,
}

/// What creating a scheduled run did.
#[derive(Debug, Clone)]
pub enum NewRun {
    Created(JobRecord),
    /// That slot already has its job: another loop or instance made it.
    AlreadyExists,
    QueueFull,
}

/// A change to the queue, as the database announces it to every instance.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum QueueEvent {
    /// A job entered the queue: idle workers should look.
    Queued,
    /// Something about this job changed: its progress or its status.
    Changed(JobId),
}

/// How long a request waits for a PostgreSQL connection before it answers 503 with Retry-After:
/// while the database is unreachable, every request and health check fails fast and frees its
/// slot, and recovers by itself when the database is back.
pub const DATABASE_WAIT: std::time::Duration = std::time::Duration::from_secs(2);

pub use crate::domain::RetryBudget;

/// The durable job queue: submissions, leases with fencing, and the end of every job.
#[async_trait]
pub trait JobQueue: Send + Sync + 'static {
    /// Inserts a queued job unless the queue or its owner's share of it is full (then `None`).
    async fn insert_job(&self, job: QueuedJob, bound: QueueBound)
    -> StoreResult<Option<JobRecord>>;
    /// As [`JobQueue::insert_job`], once per key of the job's owner: a key used within 24 hours
    /// (before `now`) gives the job it created, or [`Once::KeyReused`] for another body. The key
    /// is remembered only with a job (a full queue leaves it unused).
    async fn insert_job_once(
        &self,
        job: QueuedJob,
        bound: QueueBound,
        key: &IdempotencyKey,
        now: UnixMs,
    ) -> StoreResult<Option<Once<JobRecord>>>;
    async fn job(&self, owner: &Owner, id: &JobId) -> StoreResult<JobRecord>;
    /// The job and the job as submitted, seed fixed, in one read.
    async fn job_with_spec(&self, owner: &Owner, id: &JobId) -> StoreResult<(JobRecord, JobSpec)>;
    /// Newest first.
    async fn jobs(&self, owner: &Owner, page: Page) -> StoreResult<Vec<JobRecord>>;
    /// Every owner's queued and running jobs, and the other jobs submitted after `after` (a
    /// `seq`), oldest first, with the newest `seq` of all (read first, so a job submitted
    /// meanwhile is newer than it): what the live view of jobs looks at.
    async fn live_jobs(&self, after: i64) -> StoreResult<(Vec<JobRecord>, i64)>;
    /// Cancels a queued or running job; [`StoreError::Conflict`] if it already ended.
    /// The job's end is stamped `at`, or on the database's clock.
    async fn cancel(&self, owner: &Owner, id: &JobId, at: Option<UnixMs>)
    -> StoreResult<JobRecord>;
    /// Deletes a job that ended, with everything stored for it (its shards, result,
    /// distributions, device lives, its place among a schedule's runs), in one transaction;
    /// [`StoreError::Conflict`] while it is queued or running.
    async fn delete_job(&self, owner: &Owner, id: &JobId) -> StoreResult<()>;
    /// Deletes every owner's jobs that ended `age_ms` or more before `at` (or the database's
    /// clock, on which their ends are stamped) as [`JobQueue::delete_job`] does, in one
    /// transaction; how many.
    async fn prune_jobs(&self, age_ms: i64, at: Option<UnixMs>) -> StoreResult<u64>;
    /// Folds what the database keeps beside its main file into it, as the process ends: SQLite's
    /// write-ahead log, checkpointed whole, so that a copy of the file alone (a stopped server's
    /// backup) holds every write it acknowledged (it lacked the last ones, found from outside).
    /// The log's file keeps its size: emptied, a file the next start may not write could not be
    /// opened at all (SQLite needs a log to read one read-only). Nothing for PostgreSQL.
    async fn checkpoint(&self) -> StoreResult<()> {
        Ok(())
    }
    /// Why no connection reached the database, in the database's own words where it gave them
    /// (PostgreSQL refuses a connection with its reason, `remaining connection slots are
    /// reserved ...`, which the pool's time-out drops): for a log line, asked at most once every
    /// ten seconds; `None` otherwise, or for a database that gives none.
    async fn why_unreachable(&self) -> Option<String> {
        None
    }
    /// Leases the next shard to run: a queued shard past its backoff or a running one whose lease
    /// expired (bumping its attempt), a merge step only once its batch's groups are done. Fair
    /// share: of the job with the least virtual start time (then the oldest job; in a job, shards
    /// in order), which is charged the shard's cost (docs/contract.md "Fair share"). A shard whose
    /// lease has expired `budget.lost_leases + 1` times fails its job instead, with the reason.
    async fn claim(
        &self,
        worker: &str,
        terms: LeaseTerms,
        budget: RetryBudget,
    ) -> StoreResult<Option<Claim>>;
    /// Counts `operations`, run by a merge step that runs its job whole, as all its shard's, done,
    /// if the claim still holds it and the job still runs; fair share charges the job what they
    /// exceed of the `charged` operations its claim was charged (the step's first batch), so that
    /// a job run a second at a time is charged its seconds (docs/contract.md "Fair share").
    async fn count_run(&self, fence: &Fence, operations: u64, charged: u64) -> StoreResult<()>;
    /// Extends the shard's lease and records its progress (the job's is the sum over its
    /// shards), if the claim still holds it and the job still runs: its operations done, and
    /// `operations_total` where that is more than the shard's total (a job run whole learns its
    /// next batch as it goes).
    async fn heartbeat(
        &self,
        fence: &Fence,
        terms: LeaseTerms,
        operations_done: u64,
        operations_total: u64,
    ) -> StoreResult<Lease>;
    /// Marks a group done with its accumulators, encoded here, in one transaction, if the claim
    /// still holds it. A worker encodes them off the async threads and calls
    /// [`JobQueue::complete_encoded`].
    async fn complete(&self, fence: &Fence, stats: &GroupStats) -> StoreResult<bool> {
        self.complete_encoded(fence, rows::partial_to_sql(stats)?)
            .await
    }
    /// Marks a group done with what it made, encoded: a group's accumulators
    /// (`partial_to_sql`) or a rare event's task's outcome ([`encode`]).
    async fn complete_encoded(&self, fence: &Fence, partial: Vec<u8>) -> StoreResult<bool>;
    /// Marks a merge step done and queues the next step's shards, in one transaction, if the claim
    /// still holds it: a precision target's next batch, or a rare event's round with `state`,
    /// encoded ([`encode`]), as its merge step's partial. `folded` (the groups of every batch so
    /// far, folded) replaces the accumulators of batch `folded_through`'s groups, the last batch
    /// run (inserted, for a job that ran whole;
    /// [`crate::domain::shards::Merged::folded_through`]), and what the next step no longer
    /// reads is dropped: the groups of earlier batches, or a round's outcomes and state (the
    /// devices' groups are kept for the Result).
    async fn add_batch(
        &self,
        fence: &Fence,
        shards: &[ShardPlan],
        folded: &EncodedGroups,
        folded_through: u64,
        state: Option<&[u8]>,
    ) -> StoreResult<bool>;
    /// Marks the job failed with `error` at once (a failure no retry can mend), if the claim still
    /// holds its shard.
    /// The job's end is stamped `at`, or on the database's clock.
    async fn fail(&self, fence: &Fence, at: Option<UnixMs>, error: &str) -> StoreResult<bool>;
    /// Hands a shard whose run failed back to the queue, counting the failure, to be claimed again
    /// after [`crate::domain::retry_backoff_ms`] on the database's clock (or from `at`, as [`LeaseTerms::at`]);
    /// once it failed more than `retries` times, its job fails instead, with the reason.
    async fn fail_attempt(
        &self,
        fence: &Fence,
        at: Option<UnixMs>,
        error: &str,
        retries: u64,
    ) -> StoreResult<bool>;
    /// Hands a shard whose outcome could not be stored back to the queue, counting nothing
    /// against it, to be claimed again after [`crate::domain::ROOM_RETRY_MS`] on the database's
    /// clock (or from `at`): its job waits (an operator makes room or connections, or cancels
    /// it) rather than fail. Its `error` is `waiting for room: REASON` (or `waiting for the
    /// database: REASON`) meanwhile, and its history has one line of it however often it waits.
    async fn wait_for(
        &self,
        fence: &Fence,
        at: Option<UnixMs>,
        awaited: Awaited,
        reason: &str,
    ) -> StoreResult<bool>;
    /// Hands a running shard back to the queue (graceful shutdown), without counting a failure.
    async fn release(&self, fence: &Fence) -> StoreResult<bool>;
    /// The job's shards, in order: at most `limit` of them, after the first `skip`. Shards are
    /// only ever added after those already there, so pages read one after another miss none.
    async fn shards_from(&self, id: &JobId, skip: u64, limit: u64)
    -> StoreResult<Vec<ShardRecord>>;
    /// The job's shards, in order, all of them.
    async fn shards(&self, id: &JobId) -> StoreResult<Vec<ShardRecord>> {
        self.shards_from(id, 0, u64::MAX).await
    }
    /// `(queued, running)` job counts, for metrics.
    async fn queue_depth(&self) -> StoreResult<(u64, u64)>;
    /// Announcements of changes to the queue, where the backend makes them (PostgreSQL's
    /// LISTEN/NOTIFY); `None` means the caller polls.
    fn events(&self) -> Option<tokio::sync::broadcast::Receiver<QueueEvent>> {
        None
    }
    /// Jobs that ended, as soon as the store knows: [`QueueEvent::Changed`] with the job's id
    /// (PostgreSQL announces the ends of every instance's jobs, SQLite those of jobs this process
    /// wrote); a job's progress is not announced here. Not every end reaches it (another process
    /// on the same SQLite file, an announcement missed while PostgreSQL's listener reconnected): a
    /// waiter reads the job again now and then.
    fn ends(&self) -> tokio::sync::broadcast::Receiver<QueueEvent>;
    async fn ping(&self) -> StoreResult<()>;
    /// Whether this instance can do its work (`/readyz`): the database takes a write (recorded at
    /// `now`), every migration this build knows is applied, and, for SQLite, the file at the
    /// database's path is still the one opened, with at least `min_free_disk_bytes` free beside
    /// it. [`StoreError::NotReady`] says what is wrong.
    async fn ready(&self, min_free_disk_bytes: u64, now: UnixMs) -> StoreResult<()>;
}

/// What a succeeded job leaves: its Result, one row per (metric, bin), each device's life.
#[async_trait]
pub trait Results: Send + Sync + 'static {
    /// Stores the result, marks the merge step done and the job succeeded, and drops the groups'
    /// accumulators, if the claim still holds the merge step: the distributions (each with the
    /// final groups' accumulators of its (metric, bin), for queries after the run) and device
    /// lives first, in short transactions, then the rest in one. The job's stored bytes
    /// ([`JobRecord::stored_bytes`]); `None` if the claim no longer holds (the job stays
    /// unsucceeded; rows already written go when it ends, or its next merge writes them again).
    /// The job's end is stamped `at`, or on the database's clock.
    async fn succeed(
        &self,
        fence: &Fence,
        at: Option<UnixMs>,
        result: &EncodedResult,
    ) -> StoreResult<Option<u64>>;
    /// The accumulators of the job's done groups, in batch and group order, read into `into`
    /// one at a time; those of the groups `into` holds are not sent ([`Folding::holding`]).
    async fn partials(&self, id: &JobId, into: Folding) -> StoreResult<Folding>;
    /// The state a rare event's round `batch` starts from, its merge step's partial.
    async fn round(&self, id: &JobId, batch: u64) -> StoreResult<Rounds>;
    /// The outcomes of round `batch`'s done tasks, in task order.
    async fn round_outcomes(&self, id: &JobId, batch: u64) -> StoreResult<Vec<Outcome>>;
    /// The Result JSON as stored, to be served as it is.
    async fn result_json(&self, id: &JobId) -> StoreResult<Option<String>>;

    /// The Result, parsed (off the async threads when it is large).
    async fn result(&self, id: &JobId) -> StoreResult<Option<JobResult>> {
        let Some(text) = self.result_json(id).await? else {
            return Ok(None);
        };
        let large = text.len() >= rows::LARGE_RESULT_BYTES;
        let parse = move || serde_json::from_str(&text).map_err(|e| rows::corrupt("result", e));
        rows::off_async_threads("result", large, parse)
            .await
            .map(Some)
    }
    /// The bins of `metric` that overlap `range`, in bin order.
    async fn distribution(
        &self,
        id: &JobId,
        metric: &str,
        range: Operations,
    ) -> StoreResult<Vec<DistributionRow>>;
    /// The groups' accumulators of the bins [`Results::distribution`] gives, in the same order:
    /// what a query after the run reads. `None` for a bin stored before they were kept.
    async fn distribution_groups(
        &self,
        id: &JobId,
        metric: &str,
        range: Operations,
    ) -> StoreResult<Vec<Option<Vec<Accumulator>>>>;
    /// The listed devices' lives after device `after` (from the first without), in device order,
    /// at most `limit`: one page of a keyset walk, whatever the job's size.
    async fn lives_page(
        &self,
        id: &JobId,
        after: Option<u64>,
        limit: u32,
    ) -> StoreResult<Vec<DeviceLife>>;

    /// Every listed device's life, in device order (page by page; for tests and small jobs).
    async fn lives(&self, id: &JobId) -> StoreResult<Vec<DeviceLife>> {
        let mut lives: Vec<DeviceLife> = Vec::new();
        loop {
            let page = self
                .lives_page(id, lives.last().map(|l| l.device), 10_000)
                .await?;
            if page.is_empty() {
                return Ok(lives);
            }
            lives.extend(page);
        }
    }
}

/// Schedules and their runs.
#[async_trait]
pub trait Schedules: Send + Sync + 'static {
    /// Inserts a schedule unless its owner holds the most the bound allows
    /// ([`StoreError::TooManySchedules`]); below the bound's free disk, the database is not
    /// ready (503).
    async fn insert_schedule(
        &self,
        schedule: &ScheduleRecord,
        bound: ScheduleBound,
    ) -> StoreResult<()>;
    /// As [`Schedules::insert_schedule`], once per key of the schedule's owner (see
    /// [`JobQueue::insert_job_once`]): a retry gets the schedule the first created, whatever
    /// the bound.
    async fn insert_schedule_once(
        &self,
        schedule: &ScheduleRecord,
        bound: ScheduleBound,
        key: &IdempotencyKey,
        now: UnixMs,
    ) -> StoreResult<Once<ScheduleRecord>>;
    async fn schedule(&self, owner: &Owner, id: &ScheduleId) -> StoreResult<ScheduleRecord>;
    /// An owner's schedules after the one at `seq` `after` (from the first without it), oldest
    /// first, at most `limit`; each with its `seq`, the cursor of the next page.
    async fn schedules(
        &self,
        owner: &Owner,
        after: Option<i64>,
        limit: u32,
    ) -> StoreResult<Vec<(i64, ScheduleRecord)>>;
    /// Replaces a schedule's definition and next run (its runs stay).
    async fn update_schedule(&self, schedule: &ScheduleRecord) -> StoreResult<()>;
    async fn delete_schedule(&self, owner: &Owner, id: &ScheduleId) -> StoreResult<()>;
    /// Enabled schedules of every owner whose next run is due at `now`.
    async fn due_schedules(&self, now: UnixMs) -> StoreResult<Vec<ScheduleRecord>>;
    /// Creates the job of one slot unless the slot has one, in one transaction.
    async fn create_run(
        &self,
        slot: RunSlot<'_>,
        job: QueuedJob,
        bound: QueueBound,
    ) -> StoreResult<NewRun>;
    /// Moves `next_run_at` from `from` to `to`, unless another loop already moved it.
    async fn advance_schedule(
        &self,
        id: &ScheduleId,
        from: Option<UnixMs>,
        to: Option<UnixMs>,
    ) -> StoreResult<bool>;
    /// The latest runs, newest first.
    async fn runs(&self, schedule: &ScheduleId, limit: u32) -> StoreResult<Vec<RunRecord>>;
}

/// Opens the store a database URL names, migrating it: `sqlite:` or `postgres:` (`postgresql:`).
pub async fn open(url: &str) -> StoreResult<Arc<dyn Store>> {
    open_with(url, DEFAULT_CONNECTIONS).await
}

/// [`open`], with at most `connections` pooled connections to PostgreSQL.
pub async fn open_with(url: &str, connections: u32) -> StoreResult<Arc<dyn Store>> {
    Ok(Arc::new(SqlStore::open(url, connections).await?))
}

/// PostgreSQL's pooled connections per process unless told (`--database-connections`).
pub const DEFAULT_CONNECTIONS: u32 = 8;

/// What a shard handed back to the queue waits for ([`JobQueue::wait_for`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Awaited {
    /// Room on the disk beside the database ([`StoreError::NoRoom`]).
    Room,
    /// The database, which did not take the write in all its tries (unreachable, no connection
    /// free).
    Database,
}

impl Awaited {
    fn as_str(self) -> &'static str {
        match self {
            Awaited::Room => "room",
            Awaited::Database => "the database",
        }
    }
}

/// Everything the service stores.
pub trait Store: JobQueue + Results + Schedules {}

impl<T: JobQueue + Results + Schedules> Store for T {}
