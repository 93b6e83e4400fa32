//! The PostgreSQL store, for instances on several machines sharing one database: a connection pool,
//! row locks instead of SQLite's single writer (`FOR UPDATE SKIP LOCKED` lets workers claim jobs
//! side by side without waiting on each other), and an advisory lock around the queue bound, so that
//! concurrent submissions cannot overshoot it. Every change to a job is announced (LISTEN/NOTIFY),
//! so idle workers and progress streams on any machine wake at once. The schema is
//! `migrations/postgres/`; the row mapping is shared with SQLite (`rows.rs`).

use super::rows::{
    self, Created, DELETE_ENDED_JOB, DELETE_RUN_OF_JOB, FORGET_EXPIRED_KEY, INSERT_DISTRIBUTION,
    LATEST_APPLIED_MIGRATION, PRUNE_JOBS, PRUNE_RUNS, READINESS_WRITE, REMEMBER_KEY,
    REMEMBERED_KEY, SELECT_DISTRIBUTION, SELECT_DISTRIBUTION_GROUPS, SELECT_PARTIALS, bind_bins,
    bind_distribution, bind_fence, bind_key, bind_life, bind_queued_job, bind_schedule,
    claim_from_row, collect_partials, count_from_sql, count_to_sql, distribution_from_row,
    distribution_rows, failed_too_often, gave_up, group_to_sql, groups_from_row, job_columns,
    job_from_row, life_from_row, not_ended, partial_to_sql, remembered_from_row, row_groups_to_sql,
    run_from_row, schedule_columns, schedule_from_row, schema_current, shard_columns,
    shard_from_row, shard_id_from_row, spec_from_json, to_json,
};
use super::{
    Claim, DistributionRow, Fence, JobQueue, JobRecord, Lease, LeaseTerms, NewRun, Operations,
    Page, QueueEvent, Results, RunRecord, RunSlot, ScheduleRecord, Schedules, ShardRecord,
    StoreError, StoreResult,
};
use crate::domain::{
    IdempotencyKey, JobId, Once, Owner, QueueBound, QueuedJob, ScheduleId, ShardId, ShardPlan,
    UnixMs, first_shards,
};
use crate::domain::{RetryBudget, SHARD_OVERHEAD_OPERATIONS, retry_backoff_ms};
use async_trait::async_trait;
use bouncewear_model::Pointer;
use bouncewear_model::montecarlo::engine::GroupStats;
use bouncewear_model::montecarlo::{DeviceLife, Job, JobResult, RunGroups};
use bouncewear_model::stats::Accumulator;
use sqlx::migrate::Migrator;
use sqlx::postgres::{PgArguments, PgConnection, PgListener, PgPool, PgPoolOptions};
use sqlx::query::Query;
use sqlx::{Postgres, Row};
use std::time::Duration;
use tokio::sync::broadcast;

pub struct PgStore {
    pool: PgPool,
    events: broadcast::Sender<QueueEvent>,
}

static MIGRATOR: Migrator = sqlx::migrate!("../migrations/postgres");

/// The channel the schema's trigger announces every job change on (`migrations/postgres/0003`).
const JOB_CHANNEL: &str = "bouncewear_jobs";

/// The advisory lock every insert into the queue takes, so that counting the queued jobs and
/// inserting one cannot interleave with another submission.
const QUEUE_LOCK: i64 = 0x626f_756e_6365; // "bounce"

impl PgStore {
    /// Connects to the database at `url` and migrates it (concurrent instances wait for each
    /// other: sqlx takes an advisory lock around migrations).
    #[tracing::instrument(skip_all)]
    pub async fn open(url: &str) -> StoreResult<Self> {
        let pool = PgPoolOptions::new()
            .max_connections(8)
            // During an outage a request gets its 503 within this, not after the pool's 30 s.
            .acquire_timeout(super::DATABASE_WAIT)
            .connect(url)
            .await?;
        MIGRATOR.run(&pool).await?;
        backfill_shards(&pool).await?;
        let mut listener = PgListener::connect_with(&pool).await?;
        listener.listen(JOB_CHANNEL).await?;
        let (events, _) = broadcast::channel(1024);
        tokio::spawn(forward_announcements(listener, events.clone()));
        Ok(Self { pool, events })
    }
}

/// Passes the database's announcements on to this process's subscribers. A lost connection is
/// re-established by the listener; what was announced meanwhile is missed, which polling covers.
async fn forward_announcements(mut listener: PgListener, events: broadcast::Sender<QueueEvent>) {
    loop {
        match listener.recv().await {
            Ok(notification) => {
                let event = match notification.payload() {
                    "queued" => QueueEvent::Queued,
                    id => QueueEvent::Changed(JobId::from(id)),
                };
                // No subscriber right now is fine: nobody is waiting.
                let _ = events.send(event);
            }
            Err(error) => {
                tracing::warn!(%error, "listening for job announcements failed; polling meanwhile");
                tokio::time::sleep(Duration::from_secs(1)).await;
            }
        }
    }
}

/// Cuts jobs queued or running before shards existed (migration 0005) into their first batch's
/// shards; a job that was running starts again from its first shard.
async fn backfill_shards(writer: &PgPool) -> StoreResult<()> {
    let rows = sqlx::query(
        "SELECT id, spec FROM jobs j WHERE status IN ('queued', 'running') \
         AND NOT EXISTS (SELECT 1 FROM shards s WHERE s.job_id = j.id)",
    )
    .fetch_all(writer)
    .await?;
    for row in rows {
        let id = JobId::from(row.try_get::<String, _>("id")?);
        let spec = spec_from_json(&row.try_get::<String, _>("spec")?)?;
        let mut tx = writer.begin().await?;
        match Job::new(spec, || 0, &Pointer::root()) {
            Ok(job) => {
                sqlx::query("UPDATE jobs SET status = 'queued', operations_done = 0 WHERE id = $1")
                    .bind(id.as_str())
                    .execute(&mut *tx)
                    .await?;
                insert_shards(&mut tx, &id, &first_shards(&job)).await?;
            }
            Err(invalid) => {
                sqlx::query("UPDATE jobs SET status = 'failed', error = $2 WHERE id = $1")
                    .bind(id.as_str())
                    .bind(format!("the stored job no longer validates: {invalid}"))
                    .execute(&mut *tx)
                    .await?;
            }
        }
        tx.commit().await?;
    }
    Ok(())
}

// ---- idempotency keys ----------------------------------------------------------------------

/// In the caller's transaction, holding the key's advisory lock: forgets the key if it expired, then reads what it created (fingerprint, id).
async fn remembered(
    tx: &mut PgConnection,
    owner: &Owner,
    collection: &str,
    key: &IdempotencyKey,
    now: UnixMs,
) -> StoreResult<Option<(String, String)>> {
    // Two instances retrying at once: the second waits for the first's key.
    sqlx::query("SELECT pg_advisory_xact_lock(hashtextextended($1, 0))")
        .bind(format!("{}/{collection}/{}", owner.as_str(), key.key))
        .execute(&mut *tx)
        .await?;
    sqlx::query(FORGET_EXPIRED_KEY)
        .bind(owner.as_str())
        .bind(collection)
        .bind(key.key.as_str())
        .bind(IdempotencyKey::expired_before(now).0)
        .execute(&mut *tx)
        .await?;
    let row = sqlx::query(REMEMBERED_KEY)
        .bind(owner.as_str())
        .bind(collection)
        .bind(key.key.as_str())
        .fetch_optional(&mut *tx)
        .await?;
    Ok(row.as_ref().map(remembered_from_row).transpose()?)
}

async fn remember(
    tx: &mut PgConnection,
    owner: &Owner,
    created: Created<'_>,
    key: &IdempotencyKey,
    now: UnixMs,
) -> StoreResult<()> {
    bind_key(sqlx::query(REMEMBER_KEY), owner, created, key, now)
        .execute(&mut *tx)
        .await?;
    Ok(())
}

const SELECT_JOB: &str = concat!(
    "SELECT ",
    job_columns!(),
    " FROM jobs WHERE id = $1 AND owner = $2"
);

/// Inserts a queued job with its first shards unless the queue or the owner's share of it is
/// full ([`QueueBound`]), inside the caller's transaction. The rows go in first; the queue lock
/// is taken only to count, and held until the transaction ends, so that submissions wait on
/// each other for one count and a commit rather than for each other's inserts.
async fn insert_queued(
    tx: &mut PgConnection,
    job: &QueuedJob,
    bound: QueueBound,
) -> StoreResult<bool> {
    let insert = sqlx::query(
        "INSERT INTO jobs (id, owner, name, spec, seed, status, operations_total, created_at, stored_bytes, vtime) \
         SELECT $1, $2, $3, $4, $5, 'queued', $6, $7, octet_length($4), \
                COALESCE((SELECT MAX(vstart) FROM jobs), 0)",
    );
    bind_queued_job(insert, job)?.execute(&mut *tx).await?;
    insert_shards(tx, &job.id, &job.shards).await?;
    sqlx::query("SELECT pg_advisory_xact_lock($1)")
        .bind(QUEUE_LOCK)
        .execute(&mut *tx)
        .await?;
    // The counts include the job just inserted.
    let within: bool = sqlx::query_scalar(
        "SELECT (SELECT COUNT(*) FROM jobs WHERE status = 'queued') <= $1 \
            AND (SELECT COUNT(*) FROM jobs WHERE status = 'queued' AND owner = $2) <= $3",
    )
    .bind(count_to_sql(bound.total))
    .bind(job.owner.as_str())
    .bind(count_to_sql(bound.per_owner))
    .fetch_one(&mut *tx)
    .await?;
    Ok(within)
}

/// Inserts the shards in one statement: one round trip whatever their number.
async fn insert_shards(
    tx: &mut PgConnection,
    job: &JobId,
    shards: &[ShardPlan],
) -> StoreResult<()> {
    let batches: Vec<i64> = shards
        .iter()
        .map(|plan| count_to_sql(plan.shard.batch))
        .collect();
    let groups: Vec<i64> = shards.iter().map(|plan| group_to_sql(plan.shard)).collect();
    let operations: Vec<i64> = shards
        .iter()
        .map(|plan| count_to_sql(plan.operations))
        .collect();
    sqlx::query(
        "INSERT INTO shards (job_id, batch, grp, status, operations_total) \
         SELECT $1, batch, grp, 'queued', operations \
         FROM UNNEST($2::BIGINT[], $3::BIGINT[], $4::BIGINT[]) AS plan (batch, grp, operations)",
    )
    .bind(job.as_str())
    .bind(batches)
    .bind(groups)
    .bind(operations)
    .execute(&mut *tx)
    .await?;
    Ok(())
}

/// Sets the job's progress to the sum over its shards.
async fn sum_progress(tx: &mut PgConnection, job: &JobId) -> StoreResult<()> {
    sqlx::query(
        "UPDATE jobs SET operations_done = (SELECT COALESCE(SUM(operations_done), 0) FROM shards WHERE job_id = $1), \
         operations_total = GREATEST(operations_total, (SELECT COALESCE(SUM(operations_total), 0) FROM shards WHERE job_id = $1)) \
         WHERE id = $1",
    )
    .bind(job.as_str())
    .execute(&mut *tx)
    .await?;
    Ok(())
}

async fn select_job<'e, E>(executor: E, owner: &Owner, id: &JobId) -> StoreResult<JobRecord>
where
    E: sqlx::Executor<'e, Database = Postgres>,
{
    let row = sqlx::query(SELECT_JOB)
        .bind(id.as_str())
        .bind(owner.as_str())
        .fetch_optional(executor)
        .await?
        .ok_or_else(|| StoreError::job_not_found(id))?;
    Ok(job_from_row(&row)?)
}

/// The condition of a write of one claim: only while its attempt still holds the running shard of
/// a running job. The fence is parameters 1 to 4.
macro_rules! fenced_shard {
    () => {
        "job_id = $1 AND batch = $2 AND grp = $3 AND attempt = $4 AND status = 'running' \
         AND (SELECT status FROM jobs WHERE id = $1) = 'running'"
    };
}

fn fenced<'q>(sql: &'static str, fence: &Fence) -> Query<'q, Postgres, PgArguments> {
    bind_fence(sqlx::query(sql), fence)
}

/// Marks the claim's shard done, if the claim still holds it.
async fn finish_shard(tx: &mut PgConnection, fence: &Fence) -> StoreResult<bool> {
    let updated = fenced(
        concat!(
            "UPDATE shards SET status = 'done', lease_owner = NULL, lease_until = NULL WHERE ",
            fenced_shard!()
        ),
        fence,
    )
    .execute(&mut *tx)
    .await?;
    Ok(updated.rows_affected() == 1)
}

/// Ends a job that has not ended yet as failed, with the reason, dropping its groups' accumulators.
async fn end_job(tx: &mut PgConnection, job: &JobId, now: UnixMs, error: &str) -> StoreResult<()> {
    sqlx::query(
        "UPDATE jobs SET status = 'failed', finished_at = $2, error = $3 WHERE id = $1 AND status IN ('queued', 'running')",
    )
    .bind(job.as_str())
    .bind(now.0)
    .bind(error)
    .execute(&mut *tx)
    .await?;
    drop_unfinished(tx, job).await
}

/// Whether the claim still holds its shard, locking the job's row against ending for the rest of
/// the transaction.
async fn holds(tx: &mut PgConnection, fence: &Fence) -> StoreResult<bool> {
    Ok(fenced(
        concat!(
            "SELECT 1 FROM jobs WHERE id = $1 AND EXISTS (SELECT 1 FROM shards WHERE ",
            fenced_shard!(),
            ") FOR SHARE"
        ),
        fence,
    )
    .fetch_optional(&mut *tx)
    .await?
    .is_some())
}

impl PgStore {
    /// Writes a result's distribution rows and listed device lives in short transactions of
    /// bounded size ([`rows::DISTRIBUTIONS_PER_WRITE`], [`rows::LIVES_PER_WRITE`]), each only while
    /// the claim holds the merge step, so that no result holds the database for long. A merge that
    /// stops midway leaves rows that its rerun writes again, the same (the job is deterministic),
    /// or that ending the job drops. The bytes written (see [`JobRecord::stored_bytes`]); `None`
    /// once the claim no longer holds.
    async fn write_rows(
        &self,
        fence: &Fence,
        result: &JobResult,
        groups: &RunGroups,
    ) -> StoreResult<Option<u64>> {
        let distributions: Vec<_> = distribution_rows(result).collect();
        let mut bytes = 0;
        for chunk in distributions.chunks(rows::DISTRIBUTIONS_PER_WRITE) {
            let mut tx = self.pool.begin().await?;
            if !holds(&mut tx, fence).await? {
                tx.rollback().await?;
                return Ok(None);
            }
            for (metric, row) in chunk {
                bytes += to_json("summary", &row.summary)?.len() as u64;
                let stored = row_groups_to_sql(groups, metric, row)?;
                bytes += stored.len() as u64;
                bind_distribution(
                    sqlx::query(INSERT_DISTRIBUTION),
                    &fence.job,
                    metric,
                    row,
                    stored,
                )?
                .execute(&mut *tx)
                .await?;
            }
            tx.commit().await?;
        }
        let lives = result
            .life
            .as_ref()
            .map_or(&[][..], |life| &life.devices[..]);
        for chunk in lives.chunks(rows::LIVES_PER_WRITE) {
            let mut tx = self.pool.begin().await?;
            if !holds(&mut tx, fence).await? {
                tx.rollback().await?;
                return Ok(None);
            }
            bytes += chunk.len() as u64 * rows::LIFE_ROW_BYTES;
            for life in chunk {
                let insert = sqlx::query(
                    "INSERT INTO device_lives (job_id, device, operations_to_failure, censored) VALUES ($1, $2, $3, $4) ON CONFLICT DO NOTHING",
                );
                bind_life(insert, &fence.job, life)
                    .execute(&mut *tx)
                    .await?;
            }
            tx.commit().await?;
        }
        Ok(Some(bytes))
    }
}

/// Drops what an unfinished run of a job that ended left: its groups' accumulators, and the rows
/// of a merge step that stopped while it wrote them.
async fn drop_unfinished(tx: &mut PgConnection, job: &JobId) -> StoreResult<()> {
    drop_partials(tx, job).await?;
    for delete in [
        "UPDATE jobs SET stored_bytes = octet_length(spec) WHERE id = $1",
        "DELETE FROM distributions WHERE job_id = $1",
        "DELETE FROM device_lives WHERE job_id = $1",
    ] {
        sqlx::query(delete)
            .bind(job.as_str())
            .execute(&mut *tx)
            .await?;
    }
    Ok(())
}

/// Drops a job's groups' accumulators: it ended, and they will never be merged.
async fn drop_partials(tx: &mut PgConnection, job: &JobId) -> StoreResult<()> {
    sqlx::query("UPDATE shards SET partial = NULL WHERE job_id = $1 AND partial IS NOT NULL")
        .bind(job.as_str())
        .execute(&mut *tx)
        .await?;
    Ok(())
}

/// The database's clock, in ms since the Unix epoch: one clock for every worker on every machine.
async fn database_now(tx: &mut PgConnection) -> StoreResult<UnixMs> {
    let now: i64 =
        sqlx::query_scalar("SELECT (EXTRACT(EPOCH FROM clock_timestamp()) * 1000)::BIGINT")
            .fetch_one(&mut *tx)
            .await?;
    Ok(UnixMs(now))
}

/// `at`, or the database's clock.
async fn now_or(tx: &mut PgConnection, at: Option<UnixMs>) -> StoreResult<UnixMs> {
    match at {
        Some(at) => Ok(at),
        None => database_now(tx).await,
    }
}

/// Fails every job one of whose shards lost its lease once more than `retries` allow, with the
/// reason.
async fn give_up_on_exhausted(tx: &mut PgConnection, now: UnixMs, retries: u64) -> StoreResult<()> {
    let exhausted = sqlx::query(
        "SELECT s.job_id, s.batch, s.grp FROM shards s JOIN jobs j ON j.id = s.job_id \
         WHERE s.status = 'running' AND s.lease_until < $1 AND s.lost_leases >= $2 AND j.status IN ('queued', 'running')",
    )
    .bind(now.0)
    .bind(count_to_sql(retries))
    .fetch_all(&mut *tx)
    .await?;
    for row in exhausted {
        let job = JobId::from(row.try_get::<String, _>("job_id")?);
        let reason = gave_up(retries, shard_id_from_row(&row)?);
        end_job(tx, &job, now, &reason).await?;
    }
    Ok(())
}

#[async_trait]
impl JobQueue for PgStore {
    #[tracing::instrument(skip_all, fields(job = %job.id))]
    async fn insert_job(
        &self,
        job: QueuedJob,
        bound: QueueBound,
    ) -> StoreResult<Option<JobRecord>> {
        let mut tx = self.pool.begin().await?;
        if !insert_queued(&mut tx, &job, bound).await? {
            tx.rollback().await?;
            return Ok(None);
        }
        let record = select_job(&mut *tx, &job.owner, &job.id).await?;
        tx.commit().await?;
        Ok(Some(record))
    }

    #[tracing::instrument(skip_all, fields(job = %job.id))]
    async fn insert_job_once(
        &self,
        job: QueuedJob,
        bound: QueueBound,
        key: &IdempotencyKey,
        now: UnixMs,
    ) -> StoreResult<Option<Once<JobRecord>>> {
        let mut tx = self.pool.begin().await?;
        if let Some((fingerprint, id)) = remembered(&mut tx, &job.owner, "jobs", key, now).await? {
            let once = if fingerprint == key.fingerprint {
                Once::Replayed(select_job(&mut *tx, &job.owner, &JobId::from(id)).await?)
            } else {
                Once::KeyReused
            };
            tx.commit().await?;
            return Ok(Some(once));
        }
        if !insert_queued(&mut tx, &job, bound).await? {
            tx.rollback().await?;
            return Ok(None);
        }
        remember(&mut tx, &job.owner, Created::Job(&job.id), key, now).await?;
        let record = select_job(&mut *tx, &job.owner, &job.id).await?;
        tx.commit().await?;
        Ok(Some(Once::Created(record)))
    }

    #[tracing::instrument(skip_all, fields(job = %id))]
    async fn job(&self, owner: &Owner, id: &JobId) -> StoreResult<JobRecord> {
        select_job(&self.pool, owner, id).await
    }

    #[tracing::instrument(skip_all)]
    async fn jobs(&self, owner: &Owner, page: Page) -> StoreResult<Vec<JobRecord>> {
        let rows = sqlx::query(concat!(
            "SELECT ",
            job_columns!(),
            " FROM jobs WHERE owner = $1 AND seq < $2 ORDER BY seq DESC LIMIT $3"
        ))
        .bind(owner.as_str())
        .bind(page.before.unwrap_or(i64::MAX))
        .bind(i64::from(page.limit))
        .fetch_all(&self.pool)
        .await?;
        Ok(rows.iter().map(job_from_row).collect::<Result<_, _>>()?)
    }

    #[tracing::instrument(skip_all)]
    async fn live_jobs(&self, after: i64) -> StoreResult<(Vec<JobRecord>, i64)> {
        let mut connection = self.pool.acquire().await?;
        let newest: i64 = sqlx::query_scalar("SELECT COALESCE(MAX(seq), 0) FROM jobs")
            .fetch_one(&mut *connection)
            .await?;
        // Two arms, so that each reads an index: the active jobs by status, the new ones by seq.
        let rows = sqlx::query(concat!(
            "SELECT ",
            job_columns!(),
            " FROM jobs WHERE status IN ('queued', 'running') \
             UNION ALL SELECT ",
            job_columns!(),
            " FROM jobs WHERE seq > $1 AND status NOT IN ('queued', 'running') \
             ORDER BY seq"
        ))
        .bind(after)
        .fetch_all(&mut *connection)
        .await?;
        let jobs = rows.iter().map(job_from_row).collect::<Result<_, _>>()?;
        Ok((jobs, newest))
    }

    #[tracing::instrument(skip_all, fields(job = %id))]
    async fn cancel(&self, owner: &Owner, id: &JobId, now: UnixMs) -> StoreResult<JobRecord> {
        let row = sqlx::query(concat!(
            "UPDATE jobs SET status = 'cancelled', finished_at = $3 \
             WHERE id = $1 AND owner = $2 AND status IN ('queued', 'running') RETURNING ",
            job_columns!()
        ))
        .bind(id.as_str())
        .bind(owner.as_str())
        .bind(now.0)
        .fetch_optional(&self.pool)
        .await?;
        if let Some(row) = row {
            drop_unfinished(&mut *self.pool.acquire().await?, id).await?;
            return Ok(job_from_row(&row)?);
        }
        let ended = select_job(&self.pool, owner, id).await?;
        Err(StoreError::Conflict(format!(
            "job {id} already ended: {}",
            ended.status.as_str()
        )))
    }

    #[tracing::instrument(skip_all, fields(job = %id))]
    async fn delete_job(&self, owner: &Owner, id: &JobId) -> StoreResult<()> {
        let mut tx = self.pool.begin().await?;
        let deleted = sqlx::query(DELETE_ENDED_JOB)
            .bind(id.as_str())
            .bind(owner.as_str())
            .execute(&mut *tx)
            .await?;
        if deleted.rows_affected() == 0 {
            let job = select_job(&mut *tx, owner, id).await?;
            return Err(not_ended(&job));
        }
        sqlx::query(DELETE_RUN_OF_JOB)
            .bind(id.as_str())
            .execute(&mut *tx)
            .await?;
        tx.commit().await?;
        Ok(())
    }

    #[tracing::instrument(skip_all)]
    async fn prune_jobs(&self, ended_before: UnixMs) -> StoreResult<u64> {
        let mut tx = self.pool.begin().await?;
        sqlx::query(PRUNE_RUNS)
            .bind(ended_before.0)
            .execute(&mut *tx)
            .await?;
        let deleted = sqlx::query(PRUNE_JOBS)
            .bind(ended_before.0)
            .execute(&mut *tx)
            .await?;
        tx.commit().await?;
        Ok(deleted.rows_affected())
    }

    #[tracing::instrument(skip_all, fields(worker))]
    async fn claim(
        &self,
        worker: &str,
        terms: LeaseTerms,
        budget: RetryBudget,
    ) -> StoreResult<Option<Claim>> {
        let mut tx = self.pool.begin().await?;
        let now = now_or(&mut tx, terms.at).await?;
        give_up_on_exhausted(&mut tx, now, budget.lost_leases).await?;
        // Fair share: the job with the least virtual start time (docs/contract.md "Fair share");
        // in a job, shards in order.
        let claimed = sqlx::query(
            "UPDATE shards SET status = 'running', attempt = attempt + 1, lease_owner = $1, lease_until = $2 + $3, \
             operations_done = 0, retry_at = NULL, \
             lost_leases = lost_leases + CASE WHEN status = 'running' THEN 1 ELSE 0 END, \
             history = history || CASE WHEN status = 'running' \
                 THEN 'attempt ' || attempt || ' (' || COALESCE(lease_owner, '?') || '): lease lost' || chr(10) \
                 ELSE '' END \
             WHERE (job_id, batch, grp) = (SELECT s.job_id, s.batch, s.grp FROM shards s JOIN jobs j ON j.id = s.job_id \
                            WHERE j.status IN ('queued', 'running') \
                            AND ((s.status = 'queued' AND COALESCE(s.retry_at, 0) <= $2) \
                                 OR (s.status = 'running' AND s.lease_until < $2)) \
                            AND (s.grp >= 0 OR NOT EXISTS (SELECT 1 FROM shards o WHERE o.job_id = s.job_id \
                                 AND o.batch = s.batch AND o.grp >= 0 AND o.status <> 'done')) \
                            ORDER BY j.vtime, j.seq, s.batch, s.grp \
                            LIMIT 1 FOR UPDATE OF s SKIP LOCKED) \
             RETURNING job_id, batch, grp, attempt, operations_total",
        )
        .bind(worker)
        .bind(now.0)
        .bind(terms.duration_ms)
        .fetch_optional(&mut *tx)
        .await?;
        let Some(claimed) = claimed else {
            tx.commit().await?;
            return Ok(None);
        };
        let job = JobId::from(claimed.try_get::<String, _>("job_id")?);
        // The job runs from its first claim, and is charged its shard's cost at each (fair share).
        sqlx::query(
            "UPDATE jobs SET status = CASE WHEN status = 'queued' THEN 'running' ELSE status END, \
             started_at = COALESCE(started_at, $2), vstart = vtime, vtime = vtime + $3 WHERE id = $1",
        )
        .bind(job.as_str())
        .bind(now.0)
        .bind(claimed.try_get::<i64, _>("operations_total")? + SHARD_OVERHEAD_OPERATIONS)
        .execute(&mut *tx)
        .await?;
        sum_progress(&mut tx, &job).await?;
        let row = sqlx::query(
            "SELECT s.job_id, s.batch, s.grp, s.attempt, s.operations_total, j.spec, j.started_at \
             FROM shards s JOIN jobs j ON j.id = s.job_id WHERE s.job_id = $1 AND s.batch = $2 AND s.grp = $3",
        )
        .bind(job.as_str())
        .bind(claimed.try_get::<i64, _>("batch")?)
        .bind(claimed.try_get::<i64, _>("grp")?)
        .fetch_one(&mut *tx)
        .await?;
        tx.commit().await?;
        claim_from_row(&row).map(Some)
    }

    #[tracing::instrument(skip_all, fields(job = %fence.job, shard = %fence.shard))]
    async fn heartbeat(
        &self,
        fence: &Fence,
        terms: LeaseTerms,
        operations_done: u64,
    ) -> StoreResult<Lease> {
        let mut tx = self.pool.begin().await?;
        let now = now_or(&mut tx, terms.at).await?;
        let updated = fenced(
            concat!(
                "UPDATE shards SET lease_until = $5 + $6, operations_done = $7 WHERE ",
                fenced_shard!()
            ),
            fence,
        )
        .bind(now.0)
        .bind(terms.duration_ms)
        .bind(count_to_sql(operations_done))
        .execute(&mut *tx)
        .await?;
        if updated.rows_affected() == 1 {
            sum_progress(&mut tx, &fence.job).await?;
            tx.commit().await?;
            return Ok(Lease::Held);
        }
        let status: Option<String> = sqlx::query_scalar("SELECT status FROM jobs WHERE id = $1")
            .bind(fence.job.as_str())
            .fetch_optional(&mut *tx)
            .await?;
        tx.commit().await?;
        Ok(if status.as_deref() == Some("running") {
            Lease::Lost
        } else {
            Lease::Cancelled
        })
    }

    #[tracing::instrument(skip_all, fields(job = %fence.job, shard = %fence.shard))]
    async fn complete(&self, fence: &Fence, stats: &GroupStats) -> StoreResult<bool> {
        let partial = partial_to_sql(stats)?;
        let partial_bytes = partial.len() as u64;
        let mut tx = self.pool.begin().await?;
        let updated = fenced(
            concat!(
                "UPDATE shards SET status = 'done', partial = $5, operations_done = operations_total, \
                 lease_owner = NULL, lease_until = NULL WHERE ",
                fenced_shard!()
            ),
            fence,
        )
        .bind(partial)
        .execute(&mut *tx)
        .await?;
        if updated.rows_affected() == 0 {
            tx.rollback().await?;
            return Ok(false);
        }
        sqlx::query("UPDATE jobs SET stored_bytes = stored_bytes + $2 WHERE id = $1")
            .bind(fence.job.as_str())
            .bind(count_to_sql(partial_bytes))
            .execute(&mut *tx)
            .await?;
        sum_progress(&mut tx, &fence.job).await?;
        tx.commit().await?;
        Ok(true)
    }

    #[tracing::instrument(skip_all, fields(job = %fence.job, shard = %fence.shard))]
    async fn add_batch(
        &self,
        fence: &Fence,
        shards: &[ShardPlan],
        folded: &[GroupStats],
    ) -> StoreResult<bool> {
        let folded = folded
            .iter()
            .map(partial_to_sql)
            .collect::<StoreResult<Vec<_>>>()?;
        let mut tx = self.pool.begin().await?;
        if !finish_shard(&mut tx, fence).await? {
            tx.rollback().await?;
            return Ok(false);
        }
        let batch = count_to_sql(fence.shard.batch);
        for (group, partial) in folded.into_iter().enumerate() {
            sqlx::query(
                "UPDATE shards SET partial = $4 WHERE job_id = $1 AND batch = $2 AND grp = $3",
            )
            .bind(fence.job.as_str())
            .bind(batch)
            .bind(count_to_sql(group as u64))
            .bind(partial)
            .execute(&mut *tx)
            .await?;
        }
        sqlx::query("UPDATE shards SET partial = NULL WHERE job_id = $1 AND batch < $2 AND partial IS NOT NULL")
            .bind(fence.job.as_str())
            .bind(batch)
            .execute(&mut *tx)
            .await?;
        sqlx::query(
            "UPDATE jobs SET stored_bytes = octet_length(spec) + \
             (SELECT COALESCE(SUM(octet_length(partial)), 0) FROM shards WHERE job_id = $1) WHERE id = $1",
        )
        .bind(fence.job.as_str())
        .execute(&mut *tx)
        .await?;
        insert_shards(&mut tx, &fence.job, shards).await?;
        sum_progress(&mut tx, &fence.job).await?;
        tx.commit().await?;
        Ok(true)
    }

    #[tracing::instrument(skip_all, fields(job = %fence.job, shard = %fence.shard))]
    async fn fail(&self, fence: &Fence, now: UnixMs, error: &str) -> StoreResult<bool> {
        let mut tx = self.pool.begin().await?;
        if !finish_shard(&mut tx, fence).await? {
            tx.rollback().await?;
            return Ok(false);
        }
        end_job(&mut tx, &fence.job, now, error).await?;
        tx.commit().await?;
        Ok(true)
    }

    #[tracing::instrument(skip_all, fields(job = %fence.job, shard = %fence.shard))]
    async fn fail_attempt(
        &self,
        fence: &Fence,
        at: Option<UnixMs>,
        error: &str,
        retries: u64,
    ) -> StoreResult<bool> {
        let mut tx = self.pool.begin().await?;
        let now = now_or(&mut tx, at).await?;
        let failures: Option<i64> = fenced(
            concat!(
                "UPDATE shards SET status = 'queued', failures = failures + 1, error = $5, operations_done = 0, \
                 history = history || 'attempt ' || attempt || ' (' || COALESCE(lease_owner, '?') || '): failed: ' || $5 || chr(10), \
                 lease_owner = NULL, lease_until = NULL WHERE ",
                fenced_shard!(),
                " RETURNING failures"
            ),
            fence,
        )
        .bind(error)
        .fetch_optional(&mut *tx)
        .await?
        .map(|row| row.try_get("failures"))
        .transpose()?;
        let Some(failures) = failures else {
            tx.rollback().await?;
            return Ok(false);
        };
        let failures = failures.max(0) as u64;
        if failures > retries {
            let reason = failed_too_often(retries, fence.shard, failures, error);
            end_job(&mut tx, &fence.job, now, &reason).await?;
        } else {
            sqlx::query(
                "UPDATE shards SET retry_at = $4 WHERE job_id = $1 AND batch = $2 AND grp = $3",
            )
            .bind(fence.job.as_str())
            .bind(count_to_sql(fence.shard.batch))
            .bind(fence.shard.group.map_or(-1, count_to_sql))
            .bind(now.0 + retry_backoff_ms(failures))
            .execute(&mut *tx)
            .await?;
            sum_progress(&mut tx, &fence.job).await?;
        }
        tx.commit().await?;
        Ok(true)
    }

    #[tracing::instrument(skip_all, fields(job = %fence.job, shard = %fence.shard))]
    async fn release(&self, fence: &Fence) -> StoreResult<bool> {
        let mut tx = self.pool.begin().await?;
        let updated = fenced(
            concat!(
                "UPDATE shards SET status = 'queued', lease_owner = NULL, lease_until = NULL, operations_done = 0 WHERE ",
                fenced_shard!()
            ),
            fence,
        )
        .execute(&mut *tx)
        .await?;
        sum_progress(&mut tx, &fence.job).await?;
        tx.commit().await?;
        Ok(updated.rows_affected() == 1)
    }

    #[tracing::instrument(skip_all, fields(job = %id))]
    async fn shards(&self, id: &JobId) -> StoreResult<Vec<ShardRecord>> {
        let rows = sqlx::query(concat!(
            "SELECT ",
            shard_columns!(),
            " FROM shards WHERE job_id = $1 ORDER BY batch, grp < 0, grp"
        ))
        .bind(id.as_str())
        .fetch_all(&self.pool)
        .await?;
        Ok(rows.iter().map(shard_from_row).collect::<Result<_, _>>()?)
    }

    #[tracing::instrument(skip_all)]
    async fn queue_depth(&self) -> StoreResult<(u64, u64)> {
        let row = sqlx::query(
            "SELECT COUNT(*) FILTER (WHERE status = 'queued') AS queued, \
             COUNT(*) FILTER (WHERE status = 'running') AS running FROM jobs",
        )
        .fetch_one(&self.pool)
        .await?;
        Ok((
            count_from_sql(&row, "queued")?,
            count_from_sql(&row, "running")?,
        ))
    }

    #[tracing::instrument(skip_all)]
    async fn ping(&self) -> StoreResult<()> {
        sqlx::query("SELECT 1").execute(&self.pool).await?;
        Ok(())
    }

    /// PostgreSQL's disk is its server's to watch: readiness here is the write and the schema.
    #[tracing::instrument(skip_all)]
    async fn ready(&self, _min_free_disk_bytes: u64, now: UnixMs) -> StoreResult<()> {
        sqlx::query(READINESS_WRITE)
            .bind(now.0)
            .execute(&self.pool)
            .await?;
        let applied = sqlx::query_scalar(LATEST_APPLIED_MIGRATION)
            .fetch_one(&self.pool)
            .await?;
        schema_current(&MIGRATOR, applied)
    }

    fn events(&self) -> Option<broadcast::Receiver<QueueEvent>> {
        Some(self.events.subscribe())
    }
}

#[async_trait]
impl Results for PgStore {
    #[tracing::instrument(skip_all, fields(job = %fence.job))]
    async fn succeed(
        &self,
        fence: &Fence,
        finished_at: UnixMs,
        result: &JobResult,
        groups: &RunGroups,
    ) -> StoreResult<Option<u64>> {
        let text = to_json("result", result)?;
        let Some(row_bytes) = self.write_rows(fence, result, groups).await? else {
            return Ok(None);
        };
        let result_bytes = text.len() as u64 + row_bytes;
        let mut tx = self.pool.begin().await?;
        if !finish_shard(&mut tx, fence).await? {
            tx.rollback().await?;
            return Ok(None);
        }
        let stored = sqlx::query(
            "UPDATE jobs SET status = 'succeeded', finished_at = $2, operations_done = operations_total, \
             stored_bytes = octet_length(spec) + $3 WHERE id = $1 RETURNING stored_bytes",
        )
        .bind(fence.job.as_str())
        .bind(finished_at.0)
        .bind(count_to_sql(result_bytes))
        .fetch_one(&mut *tx)
        .await?;
        let stored_bytes = count_from_sql(&stored, "stored_bytes")?;
        drop_partials(&mut tx, &fence.job).await?;
        sqlx::query("INSERT INTO results (job_id, result) VALUES ($1, $2)")
            .bind(fence.job.as_str())
            .bind(text)
            .execute(&mut *tx)
            .await?;
        tx.commit().await?;
        Ok(Some(stored_bytes))
    }

    #[tracing::instrument(skip_all, fields(job = %id))]
    async fn partials(&self, id: &JobId) -> StoreResult<Vec<(ShardId, GroupStats)>> {
        collect_partials(
            sqlx::query(SELECT_PARTIALS)
                .bind(id.as_str())
                .fetch(&self.pool),
        )
        .await
    }

    #[tracing::instrument(skip_all, fields(job = %id))]
    async fn result_json(&self, id: &JobId) -> StoreResult<Option<String>> {
        Ok(
            sqlx::query_scalar("SELECT result FROM results WHERE job_id = $1")
                .bind(id.as_str())
                .fetch_optional(&self.pool)
                .await?,
        )
    }

    #[tracing::instrument(skip_all, fields(job = %id, metric))]
    async fn distribution(
        &self,
        id: &JobId,
        metric: &str,
        range: Operations,
    ) -> StoreResult<Vec<DistributionRow>> {
        let rows = bind_bins(sqlx::query(SELECT_DISTRIBUTION), id, metric, range)
            .fetch_all(&self.pool)
            .await?;
        rows.iter().map(distribution_from_row).collect()
    }

    #[tracing::instrument(skip_all, fields(job = %id, metric))]
    async fn distribution_groups(
        &self,
        id: &JobId,
        metric: &str,
        range: Operations,
    ) -> StoreResult<Vec<Option<Vec<Accumulator>>>> {
        let rows = bind_bins(sqlx::query(SELECT_DISTRIBUTION_GROUPS), id, metric, range)
            .fetch_all(&self.pool)
            .await?;
        rows.iter().map(groups_from_row).collect()
    }

    #[tracing::instrument(skip_all, fields(job = %id))]
    async fn lives_page(
        &self,
        id: &JobId,
        after: Option<u64>,
        limit: u32,
    ) -> StoreResult<Vec<DeviceLife>> {
        let rows = sqlx::query(
            "SELECT device, operations_to_failure, censored FROM device_lives \
             WHERE job_id = $1 AND device > $2 ORDER BY device LIMIT $3",
        )
        .bind(id.as_str())
        .bind(after.map_or(-1, count_to_sql))
        .bind(i64::from(limit))
        .fetch_all(&self.pool)
        .await?;
        Ok(rows.iter().map(life_from_row).collect::<Result<_, _>>()?)
    }
}

const INSERT_SCHEDULE: &str = concat!(
    "INSERT INTO schedules (",
    schedule_columns!(),
    ") VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10, $11)"
);

#[async_trait]
impl Schedules for PgStore {
    #[tracing::instrument(skip_all, fields(schedule = %schedule.id))]
    async fn insert_schedule(&self, schedule: &ScheduleRecord) -> StoreResult<()> {
        bind_schedule(sqlx::query(INSERT_SCHEDULE), schedule)?
            .execute(&self.pool)
            .await?;
        Ok(())
    }

    #[tracing::instrument(skip_all, fields(schedule = %schedule.id))]
    async fn insert_schedule_once(
        &self,
        schedule: &ScheduleRecord,
        key: &IdempotencyKey,
        now: UnixMs,
    ) -> StoreResult<Once<ScheduleRecord>> {
        let owner = &schedule.owner;
        let mut tx = self.pool.begin().await?;
        if let Some((fingerprint, id)) = remembered(&mut tx, owner, "schedules", key, now).await? {
            tx.commit().await?;
            if fingerprint != key.fingerprint {
                return Ok(Once::KeyReused);
            }
            return Ok(Once::Replayed(
                self.schedule(owner, &ScheduleId::from(id)).await?,
            ));
        }
        bind_schedule(sqlx::query(INSERT_SCHEDULE), schedule)?
            .execute(&mut *tx)
            .await?;
        remember(&mut tx, owner, Created::Schedule(&schedule.id), key, now).await?;
        tx.commit().await?;
        Ok(Once::Created(schedule.clone()))
    }

    #[tracing::instrument(skip_all, fields(schedule = %id))]
    async fn schedule(&self, owner: &Owner, id: &ScheduleId) -> StoreResult<ScheduleRecord> {
        let row = sqlx::query(concat!(
            "SELECT ",
            schedule_columns!(),
            " FROM schedules WHERE id = $1 AND owner = $2"
        ))
        .bind(id.as_str())
        .bind(owner.as_str())
        .fetch_optional(&self.pool)
        .await?
        .ok_or_else(|| StoreError::schedule_not_found(id))?;
        schedule_from_row(&row)
    }

    #[tracing::instrument(skip_all)]
    async fn schedules(&self, owner: &Owner) -> StoreResult<Vec<ScheduleRecord>> {
        let rows = sqlx::query(concat!(
            "SELECT ",
            schedule_columns!(),
            " FROM schedules WHERE owner = $1 ORDER BY seq"
        ))
        .bind(owner.as_str())
        .fetch_all(&self.pool)
        .await?;
        rows.iter().map(schedule_from_row).collect()
    }

    #[tracing::instrument(skip_all, fields(schedule = %schedule.id))]
    async fn update_schedule(&self, schedule: &ScheduleRecord) -> StoreResult<()> {
        let update = sqlx::query(
            "UPDATE schedules SET name = $3, cron = $4, time_zone = $5, template = $6, statistics = $7, \
             enabled = $8, next_run_at = $9, created_at = $10, updated_at = $11 WHERE id = $1 AND owner = $2",
        );
        let updated = bind_schedule(update, schedule)?.execute(&self.pool).await?;
        if updated.rows_affected() == 0 {
            return Err(StoreError::schedule_not_found(&schedule.id));
        }
        Ok(())
    }

    #[tracing::instrument(skip_all, fields(schedule = %id))]
    async fn delete_schedule(&self, owner: &Owner, id: &ScheduleId) -> StoreResult<()> {
        let deleted = sqlx::query("DELETE FROM schedules WHERE id = $1 AND owner = $2")
            .bind(id.as_str())
            .bind(owner.as_str())
            .execute(&self.pool)
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
            " FROM schedules WHERE enabled AND next_run_at <= $1 ORDER BY next_run_at"
        ))
        .bind(now.0)
        .fetch_all(&self.pool)
        .await?;
        rows.iter().map(schedule_from_row).collect()
    }

    #[tracing::instrument(skip_all, fields(schedule = %slot.schedule, job = %job.id))]
    async fn create_run(
        &self,
        slot: RunSlot<'_>,
        job: QueuedJob,
        bound: QueueBound,
    ) -> StoreResult<NewRun> {
        let mut tx = self.pool.begin().await?;
        // Claim the slot first: the primary key decides who runs this night (a concurrent claim of
        // the same slot waits for this transaction, then finds the slot taken).
        let claimed = sqlx::query(
            "INSERT INTO schedule_runs (schedule_id, scheduled_for, job_id, manual) VALUES ($1, $2, $3, $4) \
             ON CONFLICT DO NOTHING",
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
        if !insert_queued(&mut tx, &job, bound).await? {
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
            "UPDATE schedules SET next_run_at = $3 WHERE id = $1 AND next_run_at IS NOT DISTINCT FROM $2",
        )
        .bind(id.as_str())
        .bind(from.map(|t| t.0))
        .bind(to.map(|t| t.0))
        .execute(&self.pool)
        .await?;
        Ok(updated.rows_affected() == 1)
    }

    #[tracing::instrument(skip_all, fields(schedule = %schedule))]
    async fn runs(&self, schedule: &ScheduleId, limit: u32) -> StoreResult<Vec<RunRecord>> {
        let rows = sqlx::query(
            "SELECT r.scheduled_for, r.job_id, r.manual, j.status FROM schedule_runs r JOIN jobs j ON j.id = r.job_id \
             WHERE r.schedule_id = $1 ORDER BY r.scheduled_for DESC LIMIT $2",
        )
        .bind(schedule.as_str())
        .bind(i64::from(limit))
        .fetch_all(&self.pool)
        .await?;
        Ok(rows.iter().map(run_from_row).collect::<Result<_, _>>()?)
    }
}
