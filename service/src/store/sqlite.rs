//! The SQLite store: WAL, foreign keys, `synchronous = FULL` (a submitted job survives a crash or a
//! power cut once its 202 is sent), one writer connection (writes never race for the lock inside
//! the process, and every write transaction starts with a write, so instances sharing the file wait
//! on `busy_timeout` instead of failing with "database is locked"), and a pool of readers.
//!
//! Each table's columns and row mapping are written once, below its section heading.

use super::{
    Claim, DistributionRow, Fence, JobQueue, JobRecord, Lease, LeaseTerms, NewRun, Operations,
    Page, Results, RunRecord, RunSlot, ScheduleRecord, Schedules, StoreError, StoreResult,
};
use crate::domain::{
    Attempt, JobId, JobStatus, Owner, QueuedJob, ScheduleDefinition, ScheduleId, UnixMs,
};
use async_trait::async_trait;
use bouncewear_model::montecarlo::{DeviceLife, JobResult, JobSpec};
use sqlx::query::Query;
use sqlx::sqlite::{
    SqliteArguments, SqliteConnectOptions, SqliteJournalMode, SqlitePool, SqlitePoolOptions,
    SqliteRow, SqliteSynchronous,
};
use sqlx::{Row, Sqlite};
use std::str::FromStr;
use std::time::Duration;

pub struct SqliteStore {
    writer: SqlitePool,
    readers: SqlitePool,
}

impl SqliteStore {
    /// Opens (creating if missing) and migrates the database at `url`.
    #[tracing::instrument(skip_all)]
    pub async fn open(url: &str) -> StoreResult<Self> {
        let options = SqliteConnectOptions::from_str(url)?
            .create_if_missing(true)
            .journal_mode(SqliteJournalMode::Wal)
            .synchronous(SqliteSynchronous::Full)
            .foreign_keys(true)
            .busy_timeout(Duration::from_secs(30));
        let writer = SqlitePoolOptions::new()
            .max_connections(1)
            .connect_with(options.clone())
            .await?;
        sqlx::migrate!("../migrations/sqlite").run(&writer).await?;
        backfill_seeds(&writer).await?;
        let readers = SqlitePoolOptions::new()
            .max_connections(4)
            .connect_with(options.read_only(true))
            .await?;
        Ok(Self { writer, readers })
    }
}

/// Gives jobs stored before the `seed` column their seed, read from their spec (migration 0003).
async fn backfill_seeds(writer: &SqlitePool) -> StoreResult<()> {
    let rows = sqlx::query("SELECT seq, spec FROM jobs WHERE seed IS NULL")
        .fetch_all(writer)
        .await?;
    for row in rows {
        let spec = spec_from_json(&row.try_get::<String, _>("spec")?)?;
        sqlx::query("UPDATE jobs SET seed = ?2 WHERE seq = ?1")
            .bind(row.try_get::<i64, _>("seq")?)
            .bind(seed_to_sql(spec.seed.unwrap_or(0)))
            .execute(writer)
            .await?;
    }
    Ok(())
}

/// SQLite integers are signed: counts saturate, seeds keep their bits.
fn count_to_sql(value: u64) -> i64 {
    i64::try_from(value).unwrap_or(i64::MAX)
}

fn count_from_sql(row: &SqliteRow, column: &str) -> Result<u64, sqlx::Error> {
    Ok(row.try_get::<i64, _>(column)?.max(0) as u64)
}

fn seed_to_sql(seed: u64) -> i64 {
    seed as i64
}

fn seed_from_sql(stored: i64) -> u64 {
    stored as u64
}

fn ms(row: &SqliteRow, column: &str) -> Result<UnixMs, sqlx::Error> {
    row.try_get(column).map(UnixMs)
}

fn optional_ms(row: &SqliteRow, column: &str) -> Result<Option<UnixMs>, sqlx::Error> {
    Ok(row.try_get::<Option<i64>, _>(column)?.map(UnixMs))
}

fn status(row: &SqliteRow) -> Result<JobStatus, sqlx::Error> {
    let text: String = row.try_get("status")?;
    JobStatus::parse(&text).ok_or_else(|| sqlx::Error::Decode(format!("status {text}").into()))
}

fn spec_from_json(text: &str) -> StoreResult<JobSpec> {
    serde_json::from_str(text).map_err(|e| corrupt("job spec", e))
}

fn to_json(what: &'static str, value: &impl serde::Serialize) -> StoreResult<String> {
    serde_json::to_string(value).map_err(|e| corrupt(what, e))
}

fn corrupt(what: &'static str, error: impl std::fmt::Display) -> StoreError {
    StoreError::Corrupt {
        what,
        detail: error.to_string(),
    }
}

// ---- jobs ----------------------------------------------------------------------------------

macro_rules! job_columns {
    () => {
        "seq, id, owner, name, seed, status, operations_done, operations_total, attempt, error, \
         created_at, started_at, finished_at"
    };
}

const SELECT_JOB: &str = concat!(
    "SELECT ",
    job_columns!(),
    " FROM jobs WHERE id = ?1 AND owner = ?2"
);

fn job_from_row(row: &SqliteRow) -> Result<JobRecord, sqlx::Error> {
    Ok(JobRecord {
        seq: row.try_get("seq")?,
        id: JobId::from(row.try_get::<String, _>("id")?),
        owner: Owner::from_stored(row.try_get("owner")?),
        name: row.try_get("name")?,
        seed: seed_from_sql(row.try_get("seed")?),
        status: status(row)?,
        operations_done: count_from_sql(row, "operations_done")?,
        operations_total: count_from_sql(row, "operations_total")?,
        attempt: Attempt(row.try_get("attempt")?),
        error: row.try_get("error")?,
        created_at: ms(row, "created_at")?,
        started_at: optional_ms(row, "started_at")?,
        finished_at: optional_ms(row, "finished_at")?,
    })
}

/// Inserts a queued job unless `max_queued` jobs are already queued. One statement: the queue
/// bound and the insert cannot race.
async fn insert_queued<'e, E>(executor: E, job: &QueuedJob, max_queued: u64) -> StoreResult<bool>
where
    E: sqlx::Executor<'e, Database = Sqlite>,
{
    let inserted = sqlx::query(
        "INSERT INTO jobs (id, owner, name, spec, seed, status, operations_total, created_at) \
         SELECT ?1, ?2, ?3, ?4, ?5, 'queued', ?6, ?7 \
         WHERE (SELECT COUNT(*) FROM jobs WHERE status = 'queued') < ?8",
    )
    .bind(job.id.as_str())
    .bind(job.owner.as_str())
    .bind(&job.name)
    .bind(to_json("job spec", &job.spec)?)
    .bind(seed_to_sql(job.seed))
    .bind(count_to_sql(job.operations_total))
    .bind(job.created_at.0)
    .bind(count_to_sql(max_queued))
    .execute(executor)
    .await?;
    Ok(inserted.rows_affected() == 1)
}

async fn select_job<'e, E>(executor: E, owner: &Owner, id: &JobId) -> StoreResult<JobRecord>
where
    E: sqlx::Executor<'e, Database = Sqlite>,
{
    let row = sqlx::query(SELECT_JOB)
        .bind(id.as_str())
        .bind(owner.as_str())
        .fetch_optional(executor)
        .await?
        .ok_or_else(|| StoreError::job_not_found(id))?;
    Ok(job_from_row(&row)?)
}

/// A write of one claim: only while its attempt still holds the running job.
fn fenced<'q>(sql: &'static str, fence: &Fence) -> Query<'q, Sqlite, SqliteArguments> {
    sqlx::query(sql)
        .bind(fence.job.as_str())
        .bind(fence.attempt.0)
}

#[async_trait]
impl JobQueue for SqliteStore {
    #[tracing::instrument(skip_all, fields(job = %job.id))]
    async fn insert_job(&self, job: QueuedJob, max_queued: u64) -> StoreResult<Option<JobRecord>> {
        if !insert_queued(&self.writer, &job, max_queued).await? {
            return Ok(None);
        }
        // Read back through the writer: a reader may not see the commit yet.
        select_job(&self.writer, &job.owner, &job.id)
            .await
            .map(Some)
    }

    #[tracing::instrument(skip_all, fields(job = %id))]
    async fn job(&self, owner: &Owner, id: &JobId) -> StoreResult<JobRecord> {
        select_job(&self.readers, owner, id).await
    }

    #[tracing::instrument(skip_all)]
    async fn jobs(&self, owner: &Owner, page: Page) -> StoreResult<Vec<JobRecord>> {
        let rows = sqlx::query(concat!(
            "SELECT ",
            job_columns!(),
            " FROM jobs WHERE owner = ?1 AND seq < ?2 ORDER BY seq DESC LIMIT ?3"
        ))
        .bind(owner.as_str())
        .bind(page.before.unwrap_or(i64::MAX))
        .bind(i64::from(page.limit))
        .fetch_all(&self.readers)
        .await?;
        Ok(rows.iter().map(job_from_row).collect::<Result<_, _>>()?)
    }

    #[tracing::instrument(skip_all, fields(job = %id))]
    async fn cancel(&self, owner: &Owner, id: &JobId, now: UnixMs) -> StoreResult<JobRecord> {
        let row = sqlx::query(concat!(
            "UPDATE jobs SET status = 'cancelled', finished_at = ?3, lease_owner = NULL, lease_until = NULL \
             WHERE id = ?1 AND owner = ?2 AND status IN ('queued', 'running') RETURNING ",
            job_columns!()
        ))
        .bind(id.as_str())
        .bind(owner.as_str())
        .bind(now.0)
        .fetch_optional(&self.writer)
        .await?;
        if let Some(row) = row {
            return Ok(job_from_row(&row)?);
        }
        let ended = select_job(&self.writer, owner, id).await?;
        Err(StoreError::Conflict(format!(
            "job {id} already ended: {}",
            ended.status.as_str()
        )))
    }

    #[tracing::instrument(skip_all, fields(worker))]
    async fn claim(&self, worker: &str, terms: LeaseTerms) -> StoreResult<Option<Claim>> {
        let row = sqlx::query(
            "UPDATE jobs SET status = 'running', attempt = attempt + 1, lease_owner = ?1, lease_until = ?2 + ?3, \
             operations_done = 0, started_at = COALESCE(started_at, ?2) \
             WHERE seq = (SELECT seq FROM jobs WHERE status = 'queued' \
                          OR (status = 'running' AND lease_until < ?2) ORDER BY seq LIMIT 1) \
             RETURNING id, spec, attempt, operations_total",
        )
        .bind(worker)
        .bind(terms.now.0)
        .bind(terms.duration_ms)
        .fetch_optional(&self.writer)
        .await?;
        let Some(row) = row else {
            return Ok(None);
        };
        Ok(Some(Claim {
            fence: Fence {
                job: JobId::from(row.try_get::<String, _>("id")?),
                attempt: Attempt(row.try_get("attempt")?),
            },
            spec: spec_from_json(&row.try_get::<String, _>("spec")?)?,
            operations_total: count_from_sql(&row, "operations_total")?,
        }))
    }

    #[tracing::instrument(skip_all, fields(job = %fence.job))]
    async fn heartbeat(
        &self,
        fence: &Fence,
        terms: LeaseTerms,
        operations_done: u64,
    ) -> StoreResult<Lease> {
        let updated = fenced(
            "UPDATE jobs SET lease_until = ?3 + ?4, operations_done = ?5 \
             WHERE id = ?1 AND attempt = ?2 AND status = 'running'",
            fence,
        )
        .bind(terms.now.0)
        .bind(terms.duration_ms)
        .bind(count_to_sql(operations_done))
        .execute(&self.writer)
        .await?;
        if updated.rows_affected() == 1 {
            return Ok(Lease::Held);
        }
        let status: Option<String> = sqlx::query_scalar("SELECT status FROM jobs WHERE id = ?1")
            .bind(fence.job.as_str())
            .fetch_optional(&self.writer)
            .await?;
        Ok(if status.as_deref() == Some("cancelled") {
            Lease::Cancelled
        } else {
            Lease::Lost
        })
    }

    #[tracing::instrument(skip_all, fields(job = %fence.job))]
    async fn fail(&self, fence: &Fence, now: UnixMs, error: &str) -> StoreResult<bool> {
        let updated = fenced(
            "UPDATE jobs SET status = 'failed', finished_at = ?3, error = ?4, lease_owner = NULL, lease_until = NULL \
             WHERE id = ?1 AND attempt = ?2 AND status = 'running'",
            fence,
        )
        .bind(now.0)
        .bind(error)
        .execute(&self.writer)
        .await?;
        Ok(updated.rows_affected() == 1)
    }

    #[tracing::instrument(skip_all, fields(job = %fence.job))]
    async fn release(&self, fence: &Fence) -> StoreResult<bool> {
        let updated = fenced(
            "UPDATE jobs SET status = 'queued', lease_owner = NULL, lease_until = NULL, operations_done = 0 \
             WHERE id = ?1 AND attempt = ?2 AND status = 'running'",
            fence,
        )
        .execute(&self.writer)
        .await?;
        Ok(updated.rows_affected() == 1)
    }

    #[tracing::instrument(skip_all)]
    async fn reclaim_expired(&self, now: UnixMs) -> StoreResult<u64> {
        let updated = sqlx::query(
            "UPDATE jobs SET status = 'queued', lease_owner = NULL, lease_until = NULL, operations_done = 0 \
             WHERE status = 'running' AND lease_until < ?1",
        )
        .bind(now.0)
        .execute(&self.writer)
        .await?;
        Ok(updated.rows_affected())
    }

    #[tracing::instrument(skip_all)]
    async fn queue_depth(&self) -> StoreResult<(u64, u64)> {
        let row = sqlx::query(
            "SELECT COALESCE(SUM(status = 'queued'), 0) AS queued, COALESCE(SUM(status = 'running'), 0) AS running FROM jobs",
        )
        .fetch_one(&self.readers)
        .await?;
        Ok((
            count_from_sql(&row, "queued")?,
            count_from_sql(&row, "running")?,
        ))
    }

    #[tracing::instrument(skip_all)]
    async fn ping(&self) -> StoreResult<()> {
        sqlx::query("SELECT 1").execute(&self.readers).await?;
        Ok(())
    }
}

// ---- results, distributions, device lives --------------------------------------------------

/// One `distributions` row per bin of every operation metric, and one per device metric.
fn distribution_rows(result: &JobResult) -> impl Iterator<Item = (&str, DistributionRow)> {
    let operations = result.job.spec().operations;
    let bins = result.operations.iter().flat_map(|(metric, bins)| {
        bins.iter().enumerate().map(move |(index, bin)| {
            let row = DistributionRow {
                kind: "operation".to_owned(),
                bin: i64::try_from(index).unwrap_or(i64::MAX),
                op_start: bin.op_start,
                op_end: bin.op_end,
                summary: bin.summary.clone(),
            };
            (metric.as_str(), row)
        })
    });
    let devices = result.devices.iter().map(move |(metric, summary)| {
        let row = DistributionRow {
            kind: "device".to_owned(),
            bin: 0,
            op_start: 0,
            op_end: operations,
            summary: summary.clone(),
        };
        (metric.as_str(), row)
    });
    bins.chain(devices)
}

fn distribution_from_row(row: &SqliteRow) -> StoreResult<DistributionRow> {
    Ok(DistributionRow {
        kind: row.try_get("kind")?,
        bin: row.try_get("bin")?,
        op_start: count_from_sql(row, "op_start")?,
        op_end: count_from_sql(row, "op_end")?,
        summary: serde_json::from_str(&row.try_get::<String, _>("summary")?)
            .map_err(|e| corrupt("summary", e))?,
    })
}

fn life_from_row(row: &SqliteRow) -> Result<DeviceLife, sqlx::Error> {
    Ok(DeviceLife {
        device: count_from_sql(row, "device")?,
        operations_to_failure: count_from_sql(row, "operations_to_failure")?,
        censored: row.try_get("censored")?,
    })
}

#[async_trait]
impl Results for SqliteStore {
    #[tracing::instrument(skip_all, fields(job = %fence.job))]
    async fn succeed(
        &self,
        fence: &Fence,
        finished_at: UnixMs,
        result: &JobResult,
    ) -> StoreResult<bool> {
        let text = to_json("result", result)?;
        let mut tx = self.writer.begin().await?;
        let updated = fenced(
            "UPDATE jobs SET status = 'succeeded', finished_at = ?3, operations_done = operations_total, \
             lease_owner = NULL, lease_until = NULL WHERE id = ?1 AND attempt = ?2 AND status = 'running'",
            fence,
        )
        .bind(finished_at.0)
        .execute(&mut *tx)
        .await?;
        if updated.rows_affected() == 0 {
            tx.rollback().await?;
            return Ok(false);
        }
        let id = fence.job.as_str();
        sqlx::query("INSERT INTO results (job_id, result) VALUES (?1, ?2)")
            .bind(id)
            .bind(text)
            .execute(&mut *tx)
            .await?;
        for (metric, row) in distribution_rows(result) {
            let summary = &row.summary;
            let quantile = |key: &str| summary.quantiles.get(key).map_or(0.0, |q| q.value);
            sqlx::query(
                "INSERT INTO distributions (job_id, metric, kind, bin, op_start, op_end, n, mean, sd, min, max, \
                 p05, p50, p95, exceedance, summary) VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10, ?11, ?12, ?13, ?14, ?15, ?16)",
            )
            .bind(id)
            .bind(metric)
            .bind(&row.kind)
            .bind(row.bin)
            .bind(count_to_sql(row.op_start))
            .bind(count_to_sql(row.op_end))
            .bind(count_to_sql(summary.n))
            .bind(summary.mean)
            .bind(summary.sd)
            .bind(summary.min)
            .bind(summary.max)
            .bind(quantile("p05"))
            .bind(quantile("p50"))
            .bind(quantile("p95"))
            .bind(summary.exceedance.as_ref().map(|e| e.probability))
            .bind(to_json("summary", summary)?)
            .execute(&mut *tx)
            .await?;
        }
        for life in result.life.iter().flat_map(|life| &life.devices) {
            sqlx::query("INSERT INTO device_lives (job_id, device, operations_to_failure, censored) VALUES (?1, ?2, ?3, ?4)")
                .bind(id)
                .bind(count_to_sql(life.device))
                .bind(count_to_sql(life.operations_to_failure))
                .bind(life.censored)
                .execute(&mut *tx)
                .await?;
        }
        tx.commit().await?;
        Ok(true)
    }

    #[tracing::instrument(skip_all, fields(job = %id))]
    async fn result_json(&self, id: &JobId) -> StoreResult<Option<String>> {
        Ok(
            sqlx::query_scalar("SELECT result FROM results WHERE job_id = ?1")
                .bind(id.as_str())
                .fetch_optional(&self.readers)
                .await?,
        )
    }

    #[tracing::instrument(skip_all, fields(job = %id))]
    async fn result(&self, id: &JobId) -> StoreResult<Option<JobResult>> {
        self.result_json(id)
            .await?
            .map(|text| serde_json::from_str(&text).map_err(|e| corrupt("result", e)))
            .transpose()
    }

    #[tracing::instrument(skip_all, fields(job = %id, metric))]
    async fn distribution(
        &self,
        id: &JobId,
        metric: &str,
        range: Operations,
    ) -> StoreResult<Vec<DistributionRow>> {
        let rows = sqlx::query(
            "SELECT kind, bin, op_start, op_end, summary FROM distributions \
             WHERE job_id = ?1 AND metric = ?2 AND op_end > ?3 AND op_start < ?4 ORDER BY bin",
        )
        .bind(id.as_str())
        .bind(metric)
        .bind(count_to_sql(range.start))
        .bind(count_to_sql(range.end))
        .fetch_all(&self.readers)
        .await?;
        rows.iter().map(distribution_from_row).collect()
    }

    #[tracing::instrument(skip_all, fields(job = %id))]
    async fn lives(&self, id: &JobId) -> StoreResult<Vec<DeviceLife>> {
        let rows = sqlx::query(
            "SELECT device, operations_to_failure, censored FROM device_lives WHERE job_id = ?1 ORDER BY device",
        )
        .bind(id.as_str())
        .fetch_all(&self.readers)
        .await?;
        Ok(rows.iter().map(life_from_row).collect::<Result<_, _>>()?)
    }
}

// ---- schedules and their runs --------------------------------------------------------------

macro_rules! schedule_columns {
    () => {
        "id, owner, name, cron, time_zone, template, statistics, enabled, next_run_at, created_at, updated_at"
    };
}

fn schedule_from_row(row: &SqliteRow) -> StoreResult<ScheduleRecord> {
    Ok(ScheduleRecord {
        id: ScheduleId::from(row.try_get::<String, _>("id")?),
        owner: Owner::from_stored(row.try_get("owner")?),
        definition: ScheduleDefinition {
            name: row.try_get("name")?,
            cron: row.try_get("cron")?,
            time_zone: row.try_get("time_zone")?,
            template: spec_from_json(&row.try_get::<String, _>("template")?)?,
            statistics: serde_json::from_str(&row.try_get::<String, _>("statistics")?)
                .map_err(|e| corrupt("statistics", e))?,
            enabled: row.try_get("enabled")?,
        },
        next_run_at: optional_ms(row, "next_run_at")?,
        created_at: ms(row, "created_at")?,
        updated_at: ms(row, "updated_at")?,
    })
}

/// Binds every column of [`schedule_columns`], in its order, as `?1` to `?11`.
fn bind_schedule<'q>(
    query: Query<'q, Sqlite, SqliteArguments>,
    schedule: &ScheduleRecord,
) -> StoreResult<Query<'q, Sqlite, SqliteArguments>> {
    let definition = &schedule.definition;
    Ok(query
        .bind(schedule.id.as_str())
        .bind(schedule.owner.as_str())
        .bind(&definition.name)
        .bind(&definition.cron)
        .bind(&definition.time_zone)
        .bind(to_json("template", &definition.template)?)
        .bind(to_json("statistics", &definition.statistics)?)
        .bind(definition.enabled)
        .bind(schedule.next_run_at.map(|t| t.0))
        .bind(schedule.created_at.0)
        .bind(schedule.updated_at.0))
}

fn run_from_row(row: &SqliteRow) -> Result<RunRecord, sqlx::Error> {
    Ok(RunRecord {
        scheduled_for: ms(row, "scheduled_for")?,
        job_id: JobId::from(row.try_get::<String, _>("job_id")?),
        manual: row.try_get("manual")?,
        status: status(row)?,
    })
}

#[async_trait]
impl Schedules for SqliteStore {
    #[tracing::instrument(skip_all, fields(schedule = %schedule.id))]
    async fn insert_schedule(&self, schedule: &ScheduleRecord) -> StoreResult<()> {
        let insert = sqlx::query(concat!(
            "INSERT INTO schedules (",
            schedule_columns!(),
            ") VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10, ?11)"
        ));
        bind_schedule(insert, schedule)?
            .execute(&self.writer)
            .await?;
        Ok(())
    }

    #[tracing::instrument(skip_all, fields(schedule = %id))]
    async fn schedule(&self, owner: &Owner, id: &ScheduleId) -> StoreResult<ScheduleRecord> {
        let row = sqlx::query(concat!(
            "SELECT ",
            schedule_columns!(),
            " FROM schedules WHERE id = ?1 AND owner = ?2"
        ))
        .bind(id.as_str())
        .bind(owner.as_str())
        .fetch_optional(&self.writer)
        .await?
        .ok_or_else(|| StoreError::schedule_not_found(id))?;
        schedule_from_row(&row)
    }

    #[tracing::instrument(skip_all)]
    async fn schedules(&self, owner: &Owner) -> StoreResult<Vec<ScheduleRecord>> {
        let rows = sqlx::query(concat!(
            "SELECT ",
            schedule_columns!(),
            " FROM schedules WHERE owner = ?1 ORDER BY seq"
        ))
        .bind(owner.as_str())
        .fetch_all(&self.readers)
        .await?;
        rows.iter().map(schedule_from_row).collect()
    }

    #[tracing::instrument(skip_all, fields(schedule = %schedule.id))]
    async fn update_schedule(&self, schedule: &ScheduleRecord) -> StoreResult<()> {
        // The creation time is bound as ?10 but never written: a schedule keeps it.
        let update = sqlx::query(
            "UPDATE schedules SET name = ?3, cron = ?4, time_zone = ?5, template = ?6, statistics = ?7, \
             enabled = ?8, next_run_at = ?9, updated_at = ?11 WHERE id = ?1 AND owner = ?2",
        );
        let updated = bind_schedule(update, schedule)?
            .execute(&self.writer)
            .await?;
        if updated.rows_affected() == 0 {
            return Err(StoreError::schedule_not_found(&schedule.id));
        }
        Ok(())
    }

    #[tracing::instrument(skip_all, fields(schedule = %id))]
    async fn delete_schedule(&self, owner: &Owner, id: &ScheduleId) -> StoreResult<()> {
        let deleted = sqlx::query("DELETE FROM schedules WHERE id = ?1 AND owner = ?2")
            .bind(id.as_str())
            .bind(owner.as_str())
            .execute(&self.writer)
            .await?;
        if deleted.rows_affected() == 0 {
            return Err(StoreError::schedule_not_found(id));
        }
        Ok(())
    }

    #[tracing::instrument(skip_all)]
    async fn due_schedules(&self, now: UnixMs) -> StoreResult<Vec<ScheduleRecord>> {
        let rows = sqlx::query(concat!(
            "SELECT ",
            schedule_columns!(),
            " FROM schedules WHERE enabled = 1 AND next_run_at <= ?1 ORDER BY next_run_at"
        ))
        .bind(now.0)
        .fetch_all(&self.writer)
        .await?;
        rows.iter().map(schedule_from_row).collect()
    }

    #[tracing::instrument(skip_all, fields(schedule = %slot.schedule, job = %job.id))]
    async fn create_run(
        &self,
        slot: RunSlot<'_>,
        job: QueuedJob,
        max_queued: u64,
    ) -> StoreResult<NewRun> {
        let mut tx = self.writer.begin().await?;
        // Claim the slot first: the primary key decides who runs this night.
        let claimed = sqlx::query(
            "INSERT OR IGNORE INTO schedule_runs (schedule_id, scheduled_for, job_id, manual) VALUES (?1, ?2, ?3, ?4)",
        )
        .bind(slot.schedule.as_str())
        .bind(slot.scheduled_for.0)
        .bind(job.id.as_str())
        .bind(slot.manual)
        .execute(&mut *tx)
        .await?;
        if claimed.rows_affected() == 0 {
            tx.rollback().await?;
            return Ok(NewRun::AlreadyExists);
        }
        if !insert_queued(&mut *tx, &job, max_queued).await? {
            tx.rollback().await?;
            return Ok(NewRun::QueueFull);
        }
        let record = select_job(&mut *tx, &job.owner, &job.id).await?;
        tx.commit().await?;
        Ok(NewRun::Created(record))
    }

    #[tracing::instrument(skip_all, fields(schedule = %id))]
    async fn advance_schedule(
        &self,
        id: &ScheduleId,
        from: Option<UnixMs>,
        to: Option<UnixMs>,
    ) -> StoreResult<bool> {
        let updated = sqlx::query(
            "UPDATE schedules SET next_run_at = ?3 WHERE id = ?1 AND next_run_at IS ?2",
        )
        .bind(id.as_str())
        .bind(from.map(|t| t.0))
        .bind(to.map(|t| t.0))
        .execute(&self.writer)
        .await?;
        Ok(updated.rows_affected() == 1)
    }

    #[tracing::instrument(skip_all, fields(schedule = %schedule))]
    async fn runs(&self, schedule: &ScheduleId, limit: u32) -> StoreResult<Vec<RunRecord>> {
        let rows = sqlx::query(
            "SELECT r.scheduled_for, r.job_id, r.manual, j.status FROM schedule_runs r JOIN jobs j ON j.id = r.job_id \
             WHERE r.schedule_id = ?1 ORDER BY r.scheduled_for DESC LIMIT ?2",
        )
        .bind(schedule.as_str())
        .bind(i64::from(limit))
        .fetch_all(&self.readers)
        .await?;
        Ok(rows.iter().map(run_from_row).collect::<Result<_, _>>()?)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use bouncewear_model::montecarlo::Job;

    async fn open(name: &str) -> (SqliteStore, String) {
        let dir =
            std::env::temp_dir().join(format!("bouncewear-store-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let url = format!("sqlite://{}", dir.join("store.db").display());
        (SqliteStore::open(&url).await.unwrap(), url)
    }

    fn queued(seed: u64) -> QueuedJob {
        let job = Job::from_json(r#"{"devices": 2, "operations": 3}"#, || seed).unwrap();
        QueuedJob::new(&job, Owner::anonymous(), None, UnixMs(1))
    }

    fn terms(now: i64) -> LeaseTerms {
        LeaseTerms {
            now: UnixMs(now),
            duration_ms: 1000,
        }
    }

    #[tokio::test]
    async fn every_u64_seed_reads_back_exactly_even_for_rows_older_than_the_seed_column() {
        let (store, url) = open("seeds").await;
        let seeds = [0, 1 << 53, i64::MAX as u64 + 1, u64::MAX];
        let mut ids = Vec::new();
        for seed in seeds {
            ids.push(
                store
                    .insert_job(queued(seed), 10)
                    .await
                    .unwrap()
                    .unwrap()
                    .id,
            );
        }
        // Rows written before migration 0003 have no seed: the next open reads it from the spec.
        sqlx::query("UPDATE jobs SET seed = NULL")
            .execute(&store.writer)
            .await
            .unwrap();
        drop(store);
        let store = SqliteStore::open(&url).await.unwrap();
        for (id, seed) in ids.iter().zip(seeds) {
            let record = store.job(&Owner::anonymous(), id).await.unwrap();
            assert_eq!(record.seed, seed);
        }
    }

    #[tokio::test]
    async fn an_unknown_job_is_not_found_and_a_second_cancel_is_a_conflict() {
        let (store, _) = open("cancel").await;
        let owner = Owner::anonymous();
        let missing = store.job(&owner, &JobId::from("nope")).await.unwrap_err();
        assert!(
            matches!(missing, StoreError::NotFound { kind: "job", .. }),
            "{missing}"
        );
        let id = store.insert_job(queued(1), 10).await.unwrap().unwrap().id;
        let cancelled = store.cancel(&owner, &id, UnixMs(2)).await.unwrap();
        assert_eq!(cancelled.status, JobStatus::Cancelled);
        let again = store.cancel(&owner, &id, UnixMs(3)).await.unwrap_err();
        assert_eq!(
            again.to_string(),
            format!("job {id} already ended: cancelled")
        );
        let other = Owner::of_key("another key");
        assert!(matches!(
            store.cancel(&other, &id, UnixMs(3)).await,
            Err(StoreError::NotFound { .. })
        ));
    }

    #[tokio::test]
    async fn a_claim_whose_lease_expired_is_fenced_out_by_its_successor() {
        let (store, _) = open("fence").await;
        store.insert_job(queued(1), 10).await.unwrap();
        let first = store.claim("a", terms(0)).await.unwrap().unwrap();
        assert!(
            store.claim("b", terms(500)).await.unwrap().is_none(),
            "leased"
        );
        let second = store.claim("b", terms(2000)).await.unwrap().unwrap();
        assert_eq!(second.fence.attempt, Attempt(first.fence.attempt.0 + 1));
        assert_eq!(second.spec.seed, Some(1));
        assert_eq!(
            store.heartbeat(&first.fence, terms(2100), 5).await.unwrap(),
            Lease::Lost
        );
        assert!(
            !store
                .fail(&first.fence, UnixMs(2100), "late")
                .await
                .unwrap()
        );
        assert_eq!(
            store
                .heartbeat(&second.fence, terms(2100), 5)
                .await
                .unwrap(),
            Lease::Held
        );
    }

    #[tokio::test]
    async fn the_queue_bound_refuses_the_job_past_it() {
        let (store, _) = open("bound").await;
        assert!(store.insert_job(queued(1), 1).await.unwrap().is_some());
        assert!(store.insert_job(queued(2), 1).await.unwrap().is_none());
        assert_eq!(store.queue_depth().await.unwrap(), (1, 0));
    }
}
