//! The SQLite store: WAL, foreign keys, `synchronous = FULL` (a submitted job survives a crash or a
//! power cut once its 202 is sent), one writer connection (writes never race for the lock inside
//! the process, and every write transaction starts with a write, so instances sharing the file wait
//! on `busy_timeout` instead of failing with "database is locked"), and a pool of readers.

use super::{
    Cancel, Claim, DistributionRow, JobRecord, JobStatus, Lease, NewDistribution, NewJob, NewRun,
    RunRecord, ScheduleRecord, Store, StoreResult,
};
use crate::errors::Internal;
use async_trait::async_trait;
use bouncewear_model::montecarlo::DeviceLife;
use sqlx::Row;
use sqlx::sqlite::{
    SqliteConnectOptions, SqliteJournalMode, SqlitePool, SqlitePoolOptions, SqliteRow,
    SqliteSynchronous,
};
use std::str::FromStr;
use std::time::Duration;

pub struct SqliteStore {
    writer: SqlitePool,
    readers: SqlitePool,
}

impl SqliteStore {
    /// Opens (creating if missing) and migrates the database at `url`.
    pub async fn open(url: &str) -> Result<Self, Internal> {
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
        sqlx::migrate!("../migrations").run(&writer).await?;
        let readers = SqlitePoolOptions::new()
            .max_connections(4)
            .connect_with(options.read_only(true))
            .await?;
        Ok(Self { writer, readers })
    }
}

fn job_from_row(row: &SqliteRow) -> Result<JobRecord, sqlx::Error> {
    let status: String = row.try_get("status")?;
    Ok(JobRecord {
        seq: row.try_get("seq")?,
        id: row.try_get("id")?,
        owner: row.try_get("owner")?,
        name: row.try_get("name")?,
        spec: row.try_get("spec")?,
        status: JobStatus::parse(&status)
            .ok_or_else(|| sqlx::Error::Decode(format!("status {status}").into()))?,
        operations_done: row.try_get::<i64, _>("operations_done")?.max(0) as u64,
        operations_total: row.try_get::<i64, _>("operations_total")?.max(0) as u64,
        attempt: row.try_get("attempt")?,
        error: row.try_get("error")?,
        created_at: row.try_get("created_at")?,
        started_at: row.try_get("started_at")?,
        finished_at: row.try_get("finished_at")?,
    })
}

/// Inserts a queued job unless `max_queued` jobs are already queued. One statement: the queue
/// bound and the insert cannot race.
async fn insert_queued<'e, E>(
    executor: E,
    job: &NewJob,
    max_queued: u64,
) -> Result<bool, sqlx::Error>
where
    E: sqlx::Executor<'e, Database = sqlx::Sqlite>,
{
    let inserted = sqlx::query(
        "INSERT INTO jobs (id, owner, name, spec, status, operations_total, created_at) \
         SELECT ?1, ?2, ?3, ?4, 'queued', ?5, ?6 \
         WHERE (SELECT COUNT(*) FROM jobs WHERE status = 'queued') < ?7",
    )
    .bind(&job.id)
    .bind(&job.owner)
    .bind(&job.name)
    .bind(&job.spec)
    .bind(to_i64(job.operations_total))
    .bind(job.created_at)
    .bind(to_i64(max_queued))
    .execute(executor)
    .await?;
    Ok(inserted.rows_affected() == 1)
}

fn to_i64(value: u64) -> i64 {
    i64::try_from(value).unwrap_or(i64::MAX)
}

#[async_trait]
impl Store for SqliteStore {
    async fn insert_job(&self, job: NewJob, max_queued: u64) -> StoreResult<Option<JobRecord>> {
        if !insert_queued(&self.writer, &job, max_queued).await? {
            return Ok(None);
        }
        // Read back through the writer: a reader may not see the commit yet.
        let row = sqlx::query(SELECT_JOB)
            .bind(&job.id)
            .bind(&job.owner)
            .fetch_one(&self.writer)
            .await?;
        Ok(Some(job_from_row(&row)?))
    }

    async fn job(&self, owner: &str, id: &str) -> StoreResult<Option<JobRecord>> {
        let row = sqlx::query(SELECT_JOB)
            .bind(id)
            .bind(owner)
            .fetch_optional(&self.readers)
            .await?;
        Ok(row.as_ref().map(job_from_row).transpose()?)
    }

    async fn jobs(
        &self,
        owner: &str,
        before_seq: Option<i64>,
        limit: u32,
    ) -> StoreResult<Vec<JobRecord>> {
        let rows = sqlx::query(
            "SELECT seq, id, owner, name, spec, status, operations_done, operations_total, attempt, error, \
             created_at, started_at, finished_at FROM jobs \
             WHERE owner = ?1 AND seq < ?2 ORDER BY seq DESC LIMIT ?3",
        )
        .bind(owner)
        .bind(before_seq.unwrap_or(i64::MAX))
        .bind(i64::from(limit))
        .fetch_all(&self.readers)
        .await?;
        Ok(rows.iter().map(job_from_row).collect::<Result<_, _>>()?)
    }

    async fn cancel(&self, owner: &str, id: &str, now: i64) -> StoreResult<Cancel> {
        let row = sqlx::query(
            "UPDATE jobs SET status = 'cancelled', finished_at = ?3, lease_owner = NULL, lease_until = NULL \
             WHERE id = ?1 AND owner = ?2 AND status IN ('queued', 'running') \
             RETURNING seq, id, owner, name, spec, status, operations_done, operations_total, attempt, error, \
             created_at, started_at, finished_at",
        )
        .bind(id)
        .bind(owner)
        .bind(now)
        .fetch_optional(&self.writer)
        .await?;
        if let Some(row) = row {
            return Ok(Cancel::Cancelled(job_from_row(&row)?));
        }
        let row = sqlx::query(SELECT_JOB)
            .bind(id)
            .bind(owner)
            .fetch_optional(&self.writer)
            .await?;
        Ok(match row {
            Some(row) => Cancel::AlreadyFinished(job_from_row(&row)?),
            None => Cancel::NotFound,
        })
    }

    async fn claim(&self, worker: &str, now: i64, lease_ms: i64) -> StoreResult<Option<Claim>> {
        let row = sqlx::query(
            "UPDATE jobs SET status = 'running', attempt = attempt + 1, lease_owner = ?1, lease_until = ?2 + ?3, \
             operations_done = 0, started_at = COALESCE(started_at, ?2) \
             WHERE seq = (SELECT seq FROM jobs WHERE status = 'queued' \
                          OR (status = 'running' AND lease_until < ?2) ORDER BY seq LIMIT 1) \
             RETURNING id, spec, attempt, operations_total",
        )
        .bind(worker)
        .bind(now)
        .bind(lease_ms)
        .fetch_optional(&self.writer)
        .await?;
        Ok(match row {
            Some(row) => Some(Claim {
                id: row.try_get("id")?,
                spec: row.try_get("spec")?,
                attempt: row.try_get("attempt")?,
                operations_total: row.try_get::<i64, _>("operations_total")?.max(0) as u64,
            }),
            None => None,
        })
    }

    async fn heartbeat(
        &self,
        id: &str,
        attempt: i64,
        now: i64,
        lease_ms: i64,
        operations_done: u64,
    ) -> StoreResult<Lease> {
        let updated = sqlx::query(
            "UPDATE jobs SET lease_until = ?3 + ?4, operations_done = ?5 \
             WHERE id = ?1 AND attempt = ?2 AND status = 'running'",
        )
        .bind(id)
        .bind(attempt)
        .bind(now)
        .bind(lease_ms)
        .bind(to_i64(operations_done))
        .execute(&self.writer)
        .await?;
        if updated.rows_affected() == 1 {
            return Ok(Lease::Held);
        }
        let status: Option<String> = sqlx::query_scalar("SELECT status FROM jobs WHERE id = ?1")
            .bind(id)
            .fetch_optional(&self.writer)
            .await?;
        Ok(if status.as_deref() == Some("cancelled") {
            Lease::Cancelled
        } else {
            Lease::Lost
        })
    }

    async fn succeed(
        &self,
        id: &str,
        attempt: i64,
        now: i64,
        result: &str,
        rows: &[NewDistribution],
        lives: &[DeviceLife],
    ) -> StoreResult<bool> {
        let mut tx = self.writer.begin().await?;
        let updated = sqlx::query(
            "UPDATE jobs SET status = 'succeeded', finished_at = ?3, operations_done = operations_total, \
             lease_owner = NULL, lease_until = NULL WHERE id = ?1 AND attempt = ?2 AND status = 'running'",
        )
        .bind(id)
        .bind(attempt)
        .bind(now)
        .execute(&mut *tx)
        .await?;
        if updated.rows_affected() == 0 {
            tx.rollback().await?;
            return Ok(false);
        }
        sqlx::query("INSERT INTO results (job_id, result) VALUES (?1, ?2)")
            .bind(id)
            .bind(result)
            .execute(&mut *tx)
            .await?;
        for row in rows {
            let summary = &row.summary;
            let quantile = |key: &str| summary.quantiles.get(key).map_or(0.0, |q| q.value);
            sqlx::query(
                "INSERT INTO distributions (job_id, metric, kind, bin, op_start, op_end, n, mean, sd, min, max, \
                 p05, p50, p95, exceedance, summary) VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10, ?11, ?12, ?13, ?14, ?15, ?16)",
            )
            .bind(id)
            .bind(&row.metric)
            .bind(row.kind)
            .bind(row.bin)
            .bind(to_i64(row.op_start))
            .bind(to_i64(row.op_end))
            .bind(to_i64(summary.n))
            .bind(summary.mean)
            .bind(summary.sd)
            .bind(summary.min)
            .bind(summary.max)
            .bind(quantile("p05"))
            .bind(quantile("p50"))
            .bind(quantile("p95"))
            .bind(summary.exceedance.as_ref().map(|e| e.probability))
            .bind(serde_json::to_string(summary).map_err(|e| Internal(e.to_string()))?)
            .execute(&mut *tx)
            .await?;
        }
        for life in lives {
            sqlx::query("INSERT INTO device_lives (job_id, device, operations_to_failure, censored) VALUES (?1, ?2, ?3, ?4)")
                .bind(id)
                .bind(to_i64(life.device))
                .bind(to_i64(life.operations_to_failure))
                .bind(life.censored)
                .execute(&mut *tx)
                .await?;
        }
        tx.commit().await?;
        Ok(true)
    }

    async fn lives(&self, id: &str) -> StoreResult<Vec<DeviceLife>> {
        let rows = sqlx::query("SELECT device, operations_to_failure, censored FROM device_lives WHERE job_id = ?1 ORDER BY device")
            .bind(id)
            .fetch_all(&self.readers)
            .await?;
        rows.iter()
            .map(|row| {
                Ok(DeviceLife {
                    device: row.try_get::<i64, _>("device")?.max(0) as u64,
                    operations_to_failure: row.try_get::<i64, _>("operations_to_failure")?.max(0)
                        as u64,
                    censored: row.try_get("censored")?,
                })
            })
            .collect::<Result<_, sqlx::Error>>()
            .map_err(Internal::from)
    }

    async fn insert_schedule(&self, schedule: &ScheduleRecord) -> StoreResult<()> {
        sqlx::query(
            "INSERT INTO schedules (id, owner, name, cron, time_zone, template, statistics, enabled, next_run_at, created_at, updated_at) \
             VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10, ?11)",
        )
        .bind(&schedule.id)
        .bind(&schedule.owner)
        .bind(&schedule.name)
        .bind(&schedule.cron)
        .bind(&schedule.time_zone)
        .bind(&schedule.template)
        .bind(&schedule.statistics)
        .bind(schedule.enabled)
        .bind(schedule.next_run_at)
        .bind(schedule.created_at)
        .bind(schedule.updated_at)
        .execute(&self.writer)
        .await?;
        Ok(())
    }

    async fn schedule(&self, owner: &str, id: &str) -> StoreResult<Option<ScheduleRecord>> {
        let row = sqlx::query(SELECT_SCHEDULE_BY_ID)
            .bind(id)
            .bind(owner)
            .fetch_optional(&self.writer)
            .await?;
        Ok(row.as_ref().map(schedule_from_row).transpose()?)
    }

    async fn schedules(&self, owner: &str) -> StoreResult<Vec<ScheduleRecord>> {
        let rows = sqlx::query(
            "SELECT id, owner, name, cron, time_zone, template, statistics, enabled, next_run_at, created_at, updated_at \
             FROM schedules WHERE owner = ?1 ORDER BY seq",
        )
        .bind(owner)
        .fetch_all(&self.readers)
        .await?;
        Ok(rows
            .iter()
            .map(schedule_from_row)
            .collect::<Result<_, _>>()?)
    }

    async fn update_schedule(&self, schedule: &ScheduleRecord) -> StoreResult<bool> {
        let updated = sqlx::query(
            "UPDATE schedules SET name = ?3, cron = ?4, time_zone = ?5, template = ?6, statistics = ?7, enabled = ?8, \
             next_run_at = ?9, updated_at = ?10 WHERE id = ?1 AND owner = ?2",
        )
        .bind(&schedule.id)
        .bind(&schedule.owner)
        .bind(&schedule.name)
        .bind(&schedule.cron)
        .bind(&schedule.time_zone)
        .bind(&schedule.template)
        .bind(&schedule.statistics)
        .bind(schedule.enabled)
        .bind(schedule.next_run_at)
        .bind(schedule.updated_at)
        .execute(&self.writer)
        .await?;
        Ok(updated.rows_affected() == 1)
    }

    async fn delete_schedule(&self, owner: &str, id: &str) -> StoreResult<bool> {
        let deleted = sqlx::query("DELETE FROM schedules WHERE id = ?1 AND owner = ?2")
            .bind(id)
            .bind(owner)
            .execute(&self.writer)
            .await?;
        Ok(deleted.rows_affected() == 1)
    }

    async fn due_schedules(&self, now: i64) -> StoreResult<Vec<ScheduleRecord>> {
        let rows = sqlx::query(
            "SELECT id, owner, name, cron, time_zone, template, statistics, enabled, next_run_at, created_at, updated_at \
             FROM schedules WHERE enabled = 1 AND next_run_at <= ?1 ORDER BY next_run_at",
        )
        .bind(now)
        .fetch_all(&self.writer)
        .await?;
        Ok(rows
            .iter()
            .map(schedule_from_row)
            .collect::<Result<_, _>>()?)
    }

    async fn create_run(
        &self,
        schedule_id: &str,
        scheduled_for: i64,
        manual: bool,
        job: NewJob,
        max_queued: u64,
    ) -> StoreResult<NewRun> {
        let mut tx = self.writer.begin().await?;
        // Claim the (schedule, due time) slot first: the primary key decides who runs this night.
        let claimed = sqlx::query(
            "INSERT OR IGNORE INTO schedule_runs (schedule_id, scheduled_for, job_id, manual) VALUES (?1, ?2, ?3, ?4)",
        )
        .bind(schedule_id)
        .bind(scheduled_for)
        .bind(&job.id)
        .bind(manual)
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
        let row = sqlx::query(SELECT_JOB)
            .bind(&job.id)
            .bind(&job.owner)
            .fetch_one(&mut *tx)
            .await?;
        let record = job_from_row(&row)?;
        tx.commit().await?;
        Ok(NewRun::Created(record))
    }

    async fn advance_schedule(
        &self,
        id: &str,
        from: Option<i64>,
        to: Option<i64>,
    ) -> StoreResult<bool> {
        let updated = sqlx::query(
            "UPDATE schedules SET next_run_at = ?3 WHERE id = ?1 AND next_run_at IS ?2",
        )
        .bind(id)
        .bind(from)
        .bind(to)
        .execute(&self.writer)
        .await?;
        Ok(updated.rows_affected() == 1)
    }

    async fn runs(&self, schedule_id: &str, limit: u32) -> StoreResult<Vec<RunRecord>> {
        let rows = sqlx::query(
            "SELECT r.scheduled_for, r.job_id, r.manual, j.status FROM schedule_runs r JOIN jobs j ON j.id = r.job_id \
             WHERE r.schedule_id = ?1 ORDER BY r.scheduled_for DESC LIMIT ?2",
        )
        .bind(schedule_id)
        .bind(i64::from(limit))
        .fetch_all(&self.readers)
        .await?;
        rows.iter()
            .map(|row| {
                let status: String = row.try_get("status")?;
                Ok(RunRecord {
                    scheduled_for: row.try_get("scheduled_for")?,
                    job_id: row.try_get("job_id")?,
                    manual: row.try_get("manual")?,
                    status: JobStatus::parse(&status)
                        .ok_or_else(|| sqlx::Error::Decode(format!("status {status}").into()))?,
                })
            })
            .collect::<Result<_, sqlx::Error>>()
            .map_err(Internal::from)
    }

    async fn fail(&self, id: &str, attempt: i64, now: i64, error: &str) -> StoreResult<bool> {
        let updated = sqlx::query(
            "UPDATE jobs SET status = 'failed', error = ?4, finished_at = ?3, lease_owner = NULL, lease_until = NULL \
             WHERE id = ?1 AND attempt = ?2 AND status = 'running'",
        )
        .bind(id)
        .bind(attempt)
        .bind(now)
        .bind(error)
        .execute(&self.writer)
        .await?;
        Ok(updated.rows_affected() == 1)
    }

    async fn release(&self, id: &str, attempt: i64) -> StoreResult<bool> {
        let updated = sqlx::query(
            "UPDATE jobs SET status = 'queued', lease_owner = NULL, lease_until = NULL, operations_done = 0 \
             WHERE id = ?1 AND attempt = ?2 AND status = 'running'",
        )
        .bind(id)
        .bind(attempt)
        .execute(&self.writer)
        .await?;
        Ok(updated.rows_affected() == 1)
    }

    async fn reclaim_expired(&self, now: i64) -> StoreResult<u64> {
        let updated = sqlx::query(
            "UPDATE jobs SET status = 'queued', lease_owner = NULL, lease_until = NULL, operations_done = 0 \
             WHERE status = 'running' AND lease_until < ?1",
        )
        .bind(now)
        .execute(&self.writer)
        .await?;
        Ok(updated.rows_affected())
    }

    async fn result(&self, id: &str) -> StoreResult<Option<String>> {
        Ok(
            sqlx::query_scalar("SELECT result FROM results WHERE job_id = ?1")
                .bind(id)
                .fetch_optional(&self.readers)
                .await?,
        )
    }

    async fn distribution(
        &self,
        id: &str,
        metric: &str,
        op_start: u64,
        op_end: u64,
    ) -> StoreResult<Vec<DistributionRow>> {
        let rows = sqlx::query(
            "SELECT kind, bin, op_start, op_end, summary FROM distributions \
             WHERE job_id = ?1 AND metric = ?2 AND op_end > ?3 AND op_start < ?4 ORDER BY bin",
        )
        .bind(id)
        .bind(metric)
        .bind(to_i64(op_start))
        .bind(to_i64(op_end))
        .fetch_all(&self.readers)
        .await?;
        rows.iter()
            .map(|row| {
                Ok(DistributionRow {
                    kind: row.try_get("kind")?,
                    bin: row.try_get("bin")?,
                    op_start: row.try_get::<i64, _>("op_start")?.max(0) as u64,
                    op_end: row.try_get::<i64, _>("op_end")?.max(0) as u64,
                    summary: row.try_get("summary")?,
                })
            })
            .collect::<Result<_, sqlx::Error>>()
            .map_err(Internal::from)
    }

    async fn queue_depth(&self) -> StoreResult<(u64, u64)> {
        let row = sqlx::query(
            "SELECT COALESCE(SUM(status = 'queued'), 0) AS queued, COALESCE(SUM(status = 'running'), 0) AS running FROM jobs",
        )
        .fetch_one(&self.readers)
        .await?;
        Ok((
            row.try_get::<i64, _>("queued")?.max(0) as u64,
            row.try_get::<i64, _>("running")?.max(0) as u64,
        ))
    }

    async fn ping(&self) -> StoreResult<()> {
        sqlx::query("SELECT 1").execute(&self.readers).await?;
        Ok(())
    }
}

const SELECT_SCHEDULE_BY_ID: &str = "SELECT id, owner, name, cron, time_zone, template, statistics, enabled, next_run_at, \
     created_at, updated_at FROM schedules WHERE id = ?1 AND owner = ?2";

fn schedule_from_row(row: &SqliteRow) -> Result<ScheduleRecord, sqlx::Error> {
    Ok(ScheduleRecord {
        id: row.try_get("id")?,
        owner: row.try_get("owner")?,
        name: row.try_get("name")?,
        cron: row.try_get("cron")?,
        time_zone: row.try_get("time_zone")?,
        template: row.try_get("template")?,
        statistics: row.try_get("statistics")?,
        enabled: row.try_get("enabled")?,
        next_run_at: row.try_get("next_run_at")?,
        created_at: row.try_get("created_at")?,
        updated_at: row.try_get("updated_at")?,
    })
}

const SELECT_JOB: &str = "SELECT seq, id, owner, name, spec, status, operations_done, operations_total, attempt, error, \
     created_at, started_at, finished_at FROM jobs WHERE id = ?1 AND owner = ?2";
