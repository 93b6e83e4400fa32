//! Storage behind a trait, so that a second backend can be added without touching handlers or
//! workers. [`sqlite::SqliteStore`] is the one backend today.

pub mod sqlite;

use crate::errors::Internal;
use async_trait::async_trait;
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

pub type StoreResult<T> = Result<T, Internal>;

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
        [
            Self::Queued,
            Self::Running,
            Self::Succeeded,
            Self::Failed,
            Self::Cancelled,
        ]
        .into_iter()
        .find(|s| s.as_str() == text)
    }

    pub fn is_terminal(self) -> bool {
        matches!(
            self,
            JobStatus::Succeeded | JobStatus::Failed | JobStatus::Cancelled
        )
    }
}

/// A job as stored. Times are Unix milliseconds.
#[derive(Debug, Clone, PartialEq)]
pub struct JobRecord {
    pub seq: i64,
    pub id: String,
    pub owner: String,
    pub name: Option<String>,
    /// The validated job, seed fixed, as JSON.
    pub spec: String,
    pub status: JobStatus,
    pub operations_done: u64,
    pub operations_total: u64,
    pub attempt: i64,
    pub error: Option<String>,
    pub created_at: i64,
    pub started_at: Option<i64>,
    pub finished_at: Option<i64>,
}

#[derive(Debug, Clone)]
pub struct NewJob {
    pub id: String,
    pub owner: String,
    pub name: Option<String>,
    pub spec: String,
    pub operations_total: u64,
    pub created_at: i64,
}

/// A job a worker has leased, with the fencing attempt number every later write must carry.
#[derive(Debug, Clone)]
pub struct Claim {
    pub id: String,
    pub spec: String,
    pub attempt: i64,
    pub operations_total: u64,
}

/// What a heartbeat found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Lease {
    /// The lease is still ours and was extended.
    Held,
    /// The job was cancelled (by any instance): stop.
    Cancelled,
    /// Another worker took the job over (our lease expired): stop and write nothing.
    Lost,
}

#[derive(Debug, Clone)]
pub enum Cancel {
    Cancelled(JobRecord),
    AlreadyFinished(JobRecord),
    NotFound,
}

/// One stored bin of one metric.
#[derive(Debug, Clone)]
pub struct DistributionRow {
    pub kind: String,
    pub bin: i64,
    pub op_start: u64,
    pub op_end: u64,
    /// The SUMMARY JSON.
    pub summary: String,
}

/// Rows for the `distributions` table, from a result.
#[derive(Debug, Clone)]
pub struct NewDistribution {
    pub metric: String,
    pub kind: &'static str,
    pub bin: i64,
    pub op_start: u64,
    pub op_end: u64,
    pub summary: bouncewear_model::stats::Summary,
}

/// A schedule as stored.
#[derive(Debug, Clone, PartialEq)]
pub struct ScheduleRecord {
    pub id: String,
    pub owner: String,
    pub name: String,
    pub cron: String,
    pub time_zone: String,
    /// The job template, as JSON.
    pub template: String,
    /// The statistics the trend follows, as a JSON list.
    pub statistics: String,
    pub enabled: bool,
    pub next_run_at: Option<i64>,
    pub created_at: i64,
    pub updated_at: i64,
}

/// One run of a schedule, with its job's status.
#[derive(Debug, Clone, PartialEq)]
pub struct RunRecord {
    pub scheduled_for: i64,
    pub job_id: String,
    pub manual: bool,
    pub status: JobStatus,
}

/// What creating a scheduled run did.
#[derive(Debug, Clone)]
pub enum NewRun {
    Created(JobRecord),
    /// That (schedule, due time) already has its job: another loop or instance made it.
    AlreadyExists,
    QueueFull,
}

#[async_trait]
pub trait Store: Send + Sync + 'static {
    /// Inserts a queued job unless `max_queued` jobs are already queued (then `None`).
    async fn insert_job(&self, job: NewJob, max_queued: u64) -> StoreResult<Option<JobRecord>>;
    async fn job(&self, owner: &str, id: &str) -> StoreResult<Option<JobRecord>>;
    /// Newest first, below the cursor `before_seq`.
    async fn jobs(
        &self,
        owner: &str,
        before_seq: Option<i64>,
        limit: u32,
    ) -> StoreResult<Vec<JobRecord>>;
    async fn cancel(&self, owner: &str, id: &str, now: i64) -> StoreResult<Cancel>;
    /// Leases the oldest queued job, or a running one whose lease expired, bumping its attempt.
    async fn claim(&self, worker: &str, now: i64, lease_ms: i64) -> StoreResult<Option<Claim>>;
    /// Extends the lease and records progress, if the attempt still holds the job.
    async fn heartbeat(
        &self,
        id: &str,
        attempt: i64,
        now: i64,
        lease_ms: i64,
        operations_done: u64,
    ) -> StoreResult<Lease>;
    /// Stores the result and its distributions and marks the job succeeded, if the attempt still
    /// holds it; `false` otherwise (nothing written).
    async fn succeed(
        &self,
        id: &str,
        attempt: i64,
        now: i64,
        result: &str,
        rows: &[NewDistribution],
        lives: &[bouncewear_model::montecarlo::DeviceLife],
    ) -> StoreResult<bool>;
    /// Each device's life, in device order.
    async fn lives(&self, id: &str) -> StoreResult<Vec<bouncewear_model::montecarlo::DeviceLife>>;
    async fn insert_schedule(&self, schedule: &ScheduleRecord) -> StoreResult<()>;
    async fn schedule(&self, owner: &str, id: &str) -> StoreResult<Option<ScheduleRecord>>;
    async fn schedules(&self, owner: &str) -> StoreResult<Vec<ScheduleRecord>>;
    /// Replaces a schedule's definition; `false` if there is no such schedule.
    async fn update_schedule(&self, schedule: &ScheduleRecord) -> StoreResult<bool>;
    async fn delete_schedule(&self, owner: &str, id: &str) -> StoreResult<bool>;
    /// Enabled schedules of every owner whose next run is due at `now`.
    async fn due_schedules(&self, now: i64) -> StoreResult<Vec<ScheduleRecord>>;
    /// Creates the job of one (schedule, due time) unless it exists, in one transaction.
    async fn create_run(
        &self,
        schedule_id: &str,
        scheduled_for: i64,
        manual: bool,
        job: NewJob,
        max_queued: u64,
    ) -> StoreResult<NewRun>;
    /// Moves `next_run_at` from `from` to `to`, unless another loop already moved it.
    async fn advance_schedule(
        &self,
        id: &str,
        from: Option<i64>,
        to: Option<i64>,
    ) -> StoreResult<bool>;
    /// The latest runs, newest first.
    async fn runs(&self, schedule_id: &str, limit: u32) -> StoreResult<Vec<RunRecord>>;
    async fn fail(&self, id: &str, attempt: i64, now: i64, error: &str) -> StoreResult<bool>;
    /// Hands a running job back to the queue (graceful shutdown).
    async fn release(&self, id: &str, attempt: i64) -> StoreResult<bool>;
    /// Puts every running job whose lease expired back in the queue; returns how many.
    async fn reclaim_expired(&self, now: i64) -> StoreResult<u64>;
    async fn result(&self, id: &str) -> StoreResult<Option<String>>;
    async fn distribution(
        &self,
        id: &str,
        metric: &str,
        op_start: u64,
        op_end: u64,
    ) -> StoreResult<Vec<DistributionRow>>;
    /// `(queued, running)` job counts, for metrics.
    async fn queue_depth(&self) -> StoreResult<(u64, u64)>;
    async fn ping(&self) -> StoreResult<()>;
}

/// Milliseconds since the Unix epoch.
pub fn now_ms() -> i64 {
    chrono::Utc::now().timestamp_millis()
}
