//! Storage in its own language: typed ids and times in, typed records and [`StoreError`] out, no
//! JSON strings for callers to parse again: [`Store`]'s methods, split by concern (the job queue,
//! results, schedules), so that the handlers, workers and scheduler never see SQL.
//!
//! One body of SQL serves both databases ([`Store`]): `queue.rs`, `results.rs` and
//! `schedules.rs` implement them once, with `$N` placeholders; `rows.rs` maps each table's
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

pub use backend::Store;
pub(crate) use rows::partial_to_sql;
pub use rows::{EncodedGroups, EncodedResult, encode};

use crate::domain::{
    Attempt, JobId, JobStatus, Owner, ScheduleDefinition, ScheduleId, ShardId, UnixMs,
};
use bouncewear_model::montecarlo::JobSpec;
use bouncewear_model::stats::Summary;
use std::sync::Arc;

pub type StoreResult<T> = Result<T, StoreError>;

/// Why the database's migrations stop this build, in words that say what to do: a database
/// that another build migrated further (a rollback after an upgrade), or one whose applied
/// migration was edited since, is never migrated over.
fn migration_failed(error: &sqlx::migrate::MigrateError) -> String {
    use sqlx::migrate::MigrateError::{VersionMismatch, VersionMissing};
    match error {
        VersionMissing(version) => format!(
            "the database has migration {version}, which this build does not know: a newer build \
             migrated it; run that build (or this one on a copy taken before the upgrade)"
        ),
        VersionMismatch(version) => format!(
            "the database's migration {version} is not this build's migration {version} (a landed \
             migration was edited): run the build that migrated it"
        ),
        other => format!("migration: {other}"),
    }
}

/// What the database said, in its own words and code: PostgreSQL's errors read without the line
/// of PostgreSQL's own source that sqlx adds ("... No space left on device at line 3891").
fn said(error: &sqlx::Error) -> String {
    match error {
        sqlx::Error::Database(error) => match error.code() {
            Some(code) => format!("{} (code {code})", error.message()),
            None => error.message().to_owned(),
        },
        other => other.to_string(),
    }
}

#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    /// No such thing for this owner (another owner's things do not exist for the caller).
    #[error("no {kind} {id}")]
    NotFound { kind: &'static str, id: String },
    /// The request contradicts the stored state, e.g. cancelling a job that already ended.
    #[error("{0}")]
    Conflict(String),
    #[error("database: {}", said(.0))]
    Database(#[from] sqlx::Error),
    #[error("{}", migration_failed(.0))]
    Migration(#[from] sqlx::migrate::MigrateError),
    /// The database URL names no backend this build has.
    #[error(
        "unsupported database URL scheme `{0}`: use sqlite://FILE (embedded, the default) or postgres://USER@HOST/DATABASE"
    )]
    UnsupportedUrl(String),
    /// A SQLite URL that names no file (`sqlite://`, an unset variable in `sqlite://$DB`):
    /// SQLite would give each connection a private temporary database, and lose what they wrote.
    #[error(
        "the database URL `{0}` names no file: use sqlite://FILE (sqlite::memory: for a database that lives as long as the process)"
    )]
    NoFile(String),
    /// The SQLite file could not be opened (or created), and why.
    #[error(
        "cannot open {file}: {source} (does its directory exist, may this user write there, and is it a SQLite database?)"
    )]
    Unopened { file: String, source: sqlx::Error },
    /// A SQLite file with tables and no record of bouncewear's migrations: another
    /// application's, which migrating would fill with bouncewear's tables.
    #[error(
        "{file} holds tables that are not bouncewear's ({tables}) and no record of its \
         migrations: point --database at a file of its own"
    )]
    Foreign { file: String, tables: String },
    /// A stored document no longer reads as its type (written by another version, or damaged).
    #[error("stored {what} cannot be read: {detail}")]
    Corrupt { what: &'static str, detail: String },
    /// This instance cannot do its work now, and why (see [`Store::ready`]).
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

/// SQLite's primary result codes this store tells apart: a lock held past `busy_timeout` (or
/// refused at once), a full disk, and a file that is no database.
pub(crate) const SQLITE_BUSY: i32 = 5;
const SQLITE_READONLY: i32 = 8;
const SQLITE_FULL: i32 = 13;
pub(crate) const SQLITE_NOTADB: i32 = 26;

/// The primary result code of a SQLite `error` (its extended code's low byte: SQLITE_BUSY for
/// SQLITE_BUSY_SNAPSHOT too); none for another database's.
pub(crate) fn sqlite_code(error: &dyn sqlx::error::DatabaseError) -> Option<i32> {
    let sqlite = error.try_downcast_ref::<sqlx::sqlite::SqliteError>()?;
    let code = sqlx::error::DatabaseError::code(sqlite)?
        .parse::<i32>()
        .ok()?;
    Some(code & 0xff)
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

    /// Whether the database reported that its disk is full: SQLite's `SQLITE_FULL` (code 13),
    /// PostgreSQL's `disk_full` (SQLSTATE 53100, "could not extend file"). Like a write this
    /// store refuses for want of room ([`StoreError::NoRoom`]), it is the disk's state, not the
    /// job's: what waits for room is written once there is some.
    pub fn is_out_of_space(&self) -> bool {
        self.is_database_error(SQLITE_FULL, "53100")
    }

    /// Whether the database takes no writes at all: SQLite's `SQLITE_READONLY` (code 8: a file or
    /// directory without write permission, a read-only mount or `?mode=ro`), PostgreSQL's
    /// `read_only_sql_transaction` (SQLSTATE 25006: a standby, or `default_transaction_read_only`).
    /// The server's state, which an operator mends: said as it is, not as "unavailable".
    pub fn is_read_only(&self) -> bool {
        self.is_database_error(SQLITE_READONLY, "25006")
    }

    /// Whether the database itself reported SQLite's primary result code `sqlite`, or
    /// PostgreSQL's SQLSTATE `postgres`.
    fn is_database_error(&self, sqlite: i32, postgres: &str) -> bool {
        let StoreError::Database(sqlx::Error::Database(error)) = self else {
            return false;
        };
        match sqlite_code(error.as_ref()) {
            Some(code) => code == sqlite,
            None => error.code().as_deref() == Some(postgres),
        }
    }

    /// Whether no connection reached the database (none free in the pool in time, refused,
    /// reset, cut short, its name not found yet), PostgreSQL ended it or does not take one yet
    /// (SQLSTATE class 08, connection exceptions, but for a protocol violation; 57P01-57P03 and
    /// 57P05: a shutdown, a crash, a server starting, an idle session ended), or SQLite's file
    /// stayed locked by another process for all of `busy_timeout`: unlike an error the database
    /// itself reports (a full disk, a refused statement, a statement timeout, 57014), nothing
    /// says the write would fail once one does. Also met migrating the database at start-up.
    /// Not sqlx's protocol errors: a message it cannot read, or a query it cannot send (too
    /// many arguments), fails the same way every time, and waiting for it would never end.
    pub fn is_unreachable(&self) -> bool {
        let error = match self {
            StoreError::Database(error)
            | StoreError::Migration(
                sqlx::migrate::MigrateError::Execute(error)
                | sqlx::migrate::MigrateError::ExecuteMigration(error, _),
            ) => error,
            _ => return false,
        };
        match error {
            sqlx::Error::PoolTimedOut
            | sqlx::Error::PoolClosed
            | sqlx::Error::Io(_)
            | sqlx::Error::WorkerCrashed => true,
            sqlx::Error::Database(error) => match sqlite_code(error.as_ref()) {
                Some(code) => code == SQLITE_BUSY,
                None => error.code().is_some_and(|code| {
                    (code.starts_with("08") && code != "08P01")
                        || ["57P01", "57P02", "57P03", "57P05"].contains(&code.as_ref())
                }),
            },
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
    /// While it runs, why its work waits, if it does: `waiting for room: ...` (the disk) or
    /// `waiting for the database: ...`, as its shard says.
    pub waiting: Option<String>,
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
    /// The runs it skipped; kept by a PUT, which replaces only the definition.
    pub skipped: Skipped,
    /// How often it was replaced: each [`Store::update_schedule`] adds one.
    pub revision: u64,
}

impl ScheduleRecord {
    /// The move of its next run to `to` from where it was read ([`NextRun`]).
    pub fn moving_to(&self, to: Option<UnixMs>) -> NextRun {
        NextRun {
            from: self.next_run_at,
            to,
            revision: self.revision,
            missed: 0,
            last_missed: None,
        }
    }
}

/// The runs a schedule skipped at their due time: its template refused by the server's limits
/// then, or its key over its quota. A skipped night is not run later.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Skipped {
    pub runs: u64,
    /// The latest skipped run's due time and why it was skipped.
    pub last: Option<(UnixMs, String)>,
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
    /// A due run's move of the schedule's next run, made in the run's transaction; none for a
    /// run asked for.
    pub moves: Option<NextRun>,
}

/// Where a due run moves its schedule's next run: from `from` to `to`, only if the schedule is
/// still at `from` and at `revision` (not replaced, disabled or run by another loop since the
/// scheduler read it); with the runs it missed since `from`, counted as skipped.
#[derive(Debug, Clone, Copy)]
pub struct NextRun {
    pub from: Option<UnixMs>,
    pub to: Option<UnixMs>,
    pub revision: u64,
    /// Due times before the one run that no run was made for ([`crate::domain::CatchUp`]).
    pub missed: u64,
    pub last_missed: Option<UnixMs>,
}

/// What creating a scheduled run did.
#[derive(Debug, Clone)]
pub enum NewRun {
    Created(Box<JobRecord>),
    /// That slot already has its job: another loop or instance made it.
    AlreadyExists,
    QueueFull,
    /// The schedule is no longer as read ([`NextRun`]): nothing was made or moved.
    Moved,
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

/// Opens the store a database URL names, migrating it: `sqlite:` or `postgres:` (`postgresql:`).
pub async fn open(url: &str) -> StoreResult<Arc<Store>> {
    open_with(url, DEFAULT_CONNECTIONS).await
}

/// [`open`], with at most `connections` pooled connections to PostgreSQL.
pub async fn open_with(url: &str, connections: u32) -> StoreResult<Arc<Store>> {
    Ok(Arc::new(Store::open(url, connections).await?))
}

/// PostgreSQL's pooled connections per process unless told (`--database-connections`).
pub const DEFAULT_CONNECTIONS: u32 = 8;

/// What a shard handed back to the queue waits for ([`Store::wait_for`]).
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
