//! The job queue, written once for both databases: submissions with their shards, leases with
//! fencing, and the end of every job. What the two databases say differently is their
//! [`Dialect`](super::rows::Dialect) and a few steps of [`Store`]'s.

use super::backend::Store;
use super::rows::{
    self, Created, DELETE_ENDED_JOB, DELETE_RUN_OF_JOB, Dialect, FORGET_EXPIRED_KEY,
    LATEST_APPLIED_MIGRATION, PRUNE_JOBS, PRUNE_RUNS, READINESS_WRITE, REMEMBER_KEY,
    REMEMBERED_KEY, bind_fence, bind_key, claim_from_rows, count_from_sql, count_to_sql,
    failed_too_often, fenced_shard, gave_up, group_to_sql, history_lease_lost, insert_shards,
    job_columns, job_from_row, not_ended, partial_bytes, remembered_from_row, schema_current,
    shard_columns, shard_from_row, shard_id_from_row, spec_from_json,
};
use super::sql::{AnyRow, Conn, Sql, Tx};
use super::{
    Awaited, Claim, EncodedGroups, Fence, JobRecord, Lease, LeaseTerms, Page, QueueEvent,
    ShardRecord, StoreError, StoreResult,
};
use crate::domain::rare::{RARE_ROUNDS, is_round};
use crate::domain::{
    IdempotencyKey, JobId, Once, Owner, QueueBound, QueuedJob, ROOM_RETRY_MS, RetryBudget,
    SHARD_OVERHEAD_OPERATIONS, ShardId, ShardPlan, UnixMs, first_shards, retry_backoff_ms,
};
use bouncewear_model::Pointer;
use bouncewear_model::montecarlo::engine::GroupStats;
use bouncewear_model::montecarlo::{Job, JobSpec};
use tokio::sync::broadcast;

/// How often a job's delete is tried when the database broke a deadlock by rolling it back.
const DELETE_ATTEMPTS: u32 = 3;

impl Store {
    /// Deletes a job that ended, and its schedule run, in one transaction.
    async fn delete_ended_job(&self, owner: &Owner, id: &JobId) -> StoreResult<()> {
        let mut tx = self.begin().await?;
        let deleted = Sql::new(DELETE_ENDED_JOB)
            .bind(id.as_str())
            .bind(owner.as_str())
            .execute(&mut tx)
            .await?;
        if deleted == 0 {
            let job = select_job(&mut tx, owner, id).await?;
            return Err(not_ended(&job));
        }
        Sql::new(DELETE_RUN_OF_JOB)
            .bind(id.as_str())
            .execute(&mut tx)
            .await?;
        tx.commit().await?;
        self.ended(id);
        Ok(())
    }
}

// ---- idempotency keys ----------------------------------------------------------------------

impl Store {
    /// In the caller's transaction, first (two retries of one request never both miss the key):
    /// forgets the key if it expired, then gives what its first use created, read by `read` from
    /// its id in the same transaction, under the key's lock; [`Once::KeyReused`] for another
    /// body; `None` for the caller to create: the key unused, or its resource deleted since
    /// (a delete takes its keys in its transaction), as a retry after the delete. A schedule
    /// read after the lock, found deleted, was created anew without it, and racing retries met
    /// on the key's row (500s, found from outside).
    pub(crate) async fn replayed<T>(
        &self,
        tx: &mut Tx,
        (owner, collection): (&Owner, &str),
        key: &IdempotencyKey,
        now: UnixMs,
        read: impl AsyncFnOnce(&mut Tx, String) -> StoreResult<T>,
    ) -> StoreResult<Option<Once<T>>> {
        self.lock(tx, format!("{}/{collection}/{}", owner.as_str(), key.key))
            .await?;
        Sql::new(FORGET_EXPIRED_KEY)
            .bind(owner.as_str())
            .bind(collection)
            .bind(key.key.as_str())
            .bind(IdempotencyKey::expired_before(now).0)
            .execute(&mut *tx)
            .await?;
        let row = Sql::new(REMEMBERED_KEY)
            .bind(owner.as_str())
            .bind(collection)
            .bind(key.key.as_str())
            .fetch_optional(&mut *tx)
            .await?;
        let Some((fingerprint, id)) = row.as_ref().map(remembered_from_row).transpose()? else {
            return Ok(None);
        };
        if fingerprint != key.fingerprint {
            return Ok(Some(Once::KeyReused));
        }
        match read(tx, id).await {
            Ok(replayed) => Ok(Some(Once::Replayed(replayed))),
            Err(StoreError::NotFound { .. }) => Ok(None),
            Err(error) => Err(error),
        }
    }

    /// A write transaction in which the claim's shard is marked done, its operations `ran`;
    /// `None` (rolled back) once the claim no longer holds it.
    pub(crate) async fn begin_finishing(&self, fence: &Fence, ran: u64) -> StoreResult<Option<Tx>> {
        let mut tx = self.begin().await?;
        if finish_shard(&mut tx, fence, ran).await? {
            return Ok(Some(tx));
        }
        tx.rollback().await?;
        Ok(None)
    }

    /// A write transaction while the claim still holds its shard, the job's row locked against
    /// ending; `None` (rolled back) once it does not. It is redoable ([`Self::begin_redoable`]):
    /// what it writes is part of a Result whose job ends in a later commit that waits for the
    /// disk and takes it along, and which its merge step's rerun writes again until then.
    pub(crate) async fn begin_holding(&self, fence: &Fence) -> StoreResult<Option<Tx>> {
        let mut tx = self.begin_redoable().await?;
        if holds(self.dialect(), &mut tx, fence).await? {
            return Ok(Some(tx));
        }
        tx.rollback().await?;
        Ok(None)
    }

    /// Cuts jobs queued or running before shards existed (migration 0005) into their first
    /// batch's shards; a job that was running starts again from its first shard.
    pub(crate) async fn backfill_shards(&self) -> StoreResult<()> {
        let rows = Sql::new(
            "SELECT id, spec FROM jobs j WHERE status IN ('queued', 'running') \
             AND NOT EXISTS (SELECT 1 FROM shards s WHERE s.job_id = j.id)",
        )
        .fetch_all(self.writer()?)
        .await?;
        for row in rows {
            let id = JobId::from(row.text("id")?);
            let spec = spec_from_json(&row.text("spec")?)?;
            let mut tx = self.begin().await?;
            match Job::new(spec, || 0, &Pointer::root()) {
                Ok(job) => {
                    Sql::new(
                        "UPDATE jobs SET status = 'queued', operations_done = 0 WHERE id = $1",
                    )
                    .bind(id.as_str())
                    .execute(&mut tx)
                    .await?;
                    insert_shards(&mut tx, &id, &first_shards(&job)).await?;
                }
                Err(invalid) => {
                    Sql::new("UPDATE jobs SET status = 'failed', error = $2 WHERE id = $1")
                        .bind(id.as_str())
                        .bind(format!("the stored job no longer validates: {invalid}"))
                        .execute(&mut tx)
                        .await?;
                }
            }
            tx.commit().await?;
        }
        Ok(())
    }
}

pub(crate) async fn remember(
    tx: &mut Tx,
    owner: &Owner,
    created: Created<'_>,
    key: &IdempotencyKey,
    now: UnixMs,
) -> StoreResult<()> {
    bind_key(Sql::new(REMEMBER_KEY), owner, created, key, now)
        .execute(&mut *tx)
        .await?;
    Ok(())
}

// ---- jobs ----------------------------------------------------------------------------------

/// The operations done over job `$1`'s shards.
macro_rules! done_over_shards {
    () => {
        "(SELECT COALESCE(SUM(operations_done), 0) FROM shards WHERE job_id = $1)"
    };
}
pub(super) use done_over_shards;

/// The assignments of an `UPDATE jobs ... WHERE id = $1` that set the job's progress to the sum
/// over its shards.
macro_rules! progress_sums {
    () => {
        concat!(
            "operations_done = ",
            done_over_shards!(),
            ", operations_total = (SELECT CASE WHEN COALESCE(SUM(operations_total), 0) > \
             jobs.operations_total THEN SUM(operations_total) ELSE jobs.operations_total END \
             FROM shards WHERE job_id = $1)"
        )
    };
}

/// Locks job `job`'s row where the database asks it ([`Dialect::lock_job`]), before a statement
/// that writes [`progress_sums!`]: that statement then reads every shard committed before it.
pub(super) async fn lock_job(dialect: &Dialect, tx: &mut Tx, job: &str) -> StoreResult<()> {
    if let Some(lock) = dialect.lock_job {
        Sql::new(lock).bind(job).fetch_optional(&mut *tx).await?;
    }
    Ok(())
}

/// Sets the job's progress to the sum over its shards, its row locked first ([`lock_job`]).
async fn sum_progress(dialect: &Dialect, tx: &mut Tx, job: &JobId) -> StoreResult<()> {
    lock_job(dialect, tx, job.as_str()).await?;
    // Only while the job runs: a transaction that waited for the row while the job ended (its
    // shard's update made before) leaves the progress the end left.
    Sql::new(concat!(
        "UPDATE jobs SET ",
        progress_sums!(),
        " WHERE id = $1 AND status IN ('queued', 'running')"
    ))
    .bind(job.as_str())
    .execute(&mut *tx)
    .await?;
    Ok(())
}

/// Job `$1` of owner `$2`: its columns, then what follows `$rest` (more columns).
macro_rules! select_job {
    ($($rest:literal)?) => {
        concat!("SELECT ", job_columns!(), $($rest,)? " FROM jobs WHERE id = $1 AND owner = $2")
    };
}

pub(crate) async fn select_job(
    on: impl Into<Conn<'_>>,
    owner: &Owner,
    id: &JobId,
) -> StoreResult<JobRecord> {
    Ok(job_from_row(&job_row(on, select_job!(), owner, id).await?)?)
}

/// The row `sql` ([`select_job!`]) reads of job `id` of `owner`, or that there is none.
async fn job_row(
    on: impl Into<Conn<'_>>,
    sql: &'static str,
    owner: &Owner,
    id: &JobId,
) -> StoreResult<AnyRow> {
    Sql::new(sql)
        .bind(id.as_str())
        .bind(owner.as_str())
        .fetch_optional(on)
        .await?
        .ok_or_else(|| StoreError::job_not_found(id))
}

fn fenced(sql: &'static str, fence: &Fence) -> Sql {
    bind_fence(Sql::new(sql), fence)
}

/// Marks the claim's shard done, if the claim still holds it, with the operations it `ran` as
/// its total. Its `error` goes: its last run did not fail (a shard
/// that waited for the database kept "waiting for the database" once done, found from outside);
/// the history keeps every attempt's.
async fn finish_shard(tx: &mut Tx, fence: &Fence, ran: u64) -> StoreResult<bool> {
    let updated = fenced(
        concat!(
            "UPDATE shards SET status = 'done', lease_until = NULL, error = NULL, \
             operations_total = $5, operations_done = $5 WHERE ",
            fenced_shard!()
        ),
        fence,
    )
    .bind(count_to_sql(ran))
    .execute(&mut *tx)
    .await?;
    Ok(updated == 1)
}

/// Records the claim's run as failed with `error`, if the claim still holds its shard: queued
/// (claimed again only while its job runs), its failures counted, the `error` and a history line,
/// with the operations it `ran` done (0 for a run to be made again) of a total of at least
/// `ran` and the `total` its run had learnt (as a heartbeat tells it); its failures so far.
async fn failed_run(
    tx: &mut Tx,
    fence: &Fence,
    error: &str,
    [ran, total]: [u64; 2],
) -> StoreResult<Option<u64>> {
    let total = total.max(ran);
    let failures = fenced(
        concat!(
            "UPDATE shards SET status = 'queued', failures = failures + 1, error = $5, operations_done = $6, \
             operations_total = CASE WHEN $7 > operations_total THEN $7 ELSE operations_total END, \
             history = history || 'attempt ' || attempt || ' (' || COALESCE(lease_owner, '?') || '): failed: ' || $5 || '\n', \
             lease_until = NULL WHERE ",
            fenced_shard!(),
            " RETURNING failures"
        ),
        fence,
    )
    .bind(error)
    .bind(count_to_sql(ran))
    .bind(count_to_sql(total))
    .fetch_optional(&mut *tx)
    .await?
    .map(|row| row.int("failures"))
    .transpose()?;
    Ok(failures.map(|failures| failures.max(0) as u64))
}

/// Ends a job that has not ended yet as failed, with the reason, dropping its groups' accumulators.
async fn end_job(tx: &mut Tx, job: &JobId, now: UnixMs, error: &str) -> StoreResult<()> {
    Sql::new(
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
async fn holds(dialect: &Dialect, tx: &mut Tx, fence: &Fence) -> StoreResult<bool> {
    Ok(fenced(dialect.holds, fence)
        .fetch_optional(&mut *tx)
        .await?
        .is_some())
}

/// Drops what an unfinished run of a job that ended left: its groups' accumulators, and the rows
/// of a merge step that stopped while it wrote them.
async fn drop_unfinished(tx: &mut Tx, job: &JobId) -> StoreResult<()> {
    drop_partials(tx, job).await?;
    for delete in [
        "UPDATE jobs SET stored_bytes = octet_length(spec) WHERE id = $1",
        "DELETE FROM distributions WHERE job_id = $1",
        "DELETE FROM device_lives WHERE job_id = $1",
    ] {
        Sql::new(delete)
            .bind(job.as_str())
            .execute(&mut *tx)
            .await?;
    }
    Ok(())
}

/// Drops a job's groups' accumulators: it ended, and they will never be merged.
pub(crate) async fn drop_partials(tx: &mut Tx, job: &JobId) -> StoreResult<()> {
    Sql::new("UPDATE shards SET partial = NULL WHERE job_id = $1 AND partial IS NOT NULL")
        .bind(job.as_str())
        .execute(&mut *tx)
        .await?;
    Ok(())
}

/// `at`, or the database's clock.
pub(super) async fn now_or(
    dialect: &Dialect,
    tx: &mut Tx,
    at: Option<UnixMs>,
) -> StoreResult<UnixMs> {
    match at {
        Some(at) => Ok(at),
        None => Ok(UnixMs(
            Sql::new(dialect.now)
                .fetch_one(&mut *tx)
                .await?
                .int("now")?,
        )),
    }
}

/// The jobs to fail, each with the shard and the reason: one of their running shards lost its
/// lease once more than `retries` allow.
async fn exhausted(
    tx: &mut Tx,
    now: UnixMs,
    retries: u64,
) -> StoreResult<Vec<(JobId, ShardId, String)>> {
    let rows = Sql::new(
        // From the running shards (`shards_open`, whose condition `s.status <> 'done'` is stated
        // for the planner to use it), not from every open job's: 16 ms a claim with 1000 jobs
        // queued, when SQLite started from the jobs.
        "SELECT s.job_id, s.batch, s.grp FROM shards s CROSS JOIN jobs j \
         WHERE j.id = s.job_id AND s.status <> 'done' AND s.status = 'running' AND s.lease_until < $1 \
         AND s.lost_leases >= $2 AND j.status IN ('queued', 'running')",
    )
    .bind(now.0)
    .bind(count_to_sql(retries))
    .fetch_all(&mut *tx)
    .await?;
    rows.iter()
        .map(|row| {
            let (job, shard) = (JobId::from(row.text("job_id")?), shard_id_from_row(row)?);
            Ok((job, shard, gave_up(retries, shard)))
        })
        .collect()
}

/// The durable job queue: submissions, leases with fencing, and the end of every job.
impl Store {
    /// Why no connection reached the database, in the database's own words where it gave them
    /// (PostgreSQL refuses a connection with its reason, `remaining connection slots are
    /// reserved ...`, which the pool's time-out drops): for a log line, asked at most once every
    /// ten seconds; `None` otherwise, or for a database that gives none.
    pub async fn why_unreachable(&self) -> Option<String> {
        self.why_no_connection().await
    }

    /// Folds what the database keeps beside its main file into it, as the process ends: SQLite's
    /// write-ahead log, checkpointed whole, so that a copy of the file alone (a stopped server's
    /// backup) holds every write it acknowledged (it lacked the last ones, found from outside).
    /// The log's file keeps its size: emptied, a file the next start may not write could not be
    /// opened at all (SQLite needs a log to read one read-only). Nothing for PostgreSQL.
    pub async fn checkpoint(&self) -> StoreResult<()> {
        self.fold_log().await
    }

    /// Inserts a queued job unless the queue or its owner's share of it is full (then `None`).
    #[tracing::instrument(skip_all, fields(job = %job.id))]
    pub async fn insert_job(
        &self,
        job: QueuedJob,
        bound: QueueBound,
    ) -> StoreResult<Option<JobRecord>> {
        let mut tx = self.begin().await?;
        if !self.insert_queued(&mut tx, &job, bound).await? {
            tx.rollback().await?;
            return Ok(None);
        }
        let record = select_job(&mut tx, &job.owner, &job.id).await?;
        tx.commit().await?;
        self.acknowledge()?;
        Ok(Some(record))
    }

    /// As [`Store::insert_job`], once per key of the job's owner: a key used within 24 hours
    /// (before `at`, or the database's clock) gives the job it created, or [`Once::KeyReused`]
    /// for another body. The key is remembered only with a job (a full queue leaves it unused).
    /// Its age is the database's to judge: stored and read on each instance's own clock, a key
    /// stored by a node 10 minutes slow was forgotten by one 23 h 55 min ahead, and its retry
    /// made a second job (a probe).
    #[tracing::instrument(skip_all, fields(job = %job.id))]
    pub async fn insert_job_once(
        &self,
        job: QueuedJob,
        bound: QueueBound,
        key: &IdempotencyKey,
        at: Option<UnixMs>,
    ) -> StoreResult<Option<Once<JobRecord>>> {
        let mut tx = self.begin().await?;
        let now = now_or(self.dialect(), &mut tx, at).await?;
        let owner = &job.owner;
        let read = async |tx: &mut Tx, id| select_job(tx, owner, &JobId::from(id)).await;
        let replayed = self.replayed(&mut tx, (owner, "jobs"), key, now, read);
        if let Some(once) = replayed.await? {
            tx.commit().await?;
            return Ok(Some(once));
        }
        if !self.insert_queued(&mut tx, &job, bound).await? {
            tx.rollback().await?;
            return Ok(None);
        }
        remember(&mut tx, &job.owner, Created::Job(&job.id), key, now).await?;
        let record = select_job(&mut tx, &job.owner, &job.id).await?;
        tx.commit().await?;
        self.acknowledge()?;
        Ok(Some(Once::Created(record)))
    }

    #[tracing::instrument(skip_all, fields(job = %id))]
    pub async fn job(&self, owner: &Owner, id: &JobId) -> StoreResult<JobRecord> {
        select_job(self.readers(), owner, id).await
    }

    /// The job and the job as submitted, seed fixed, in one read.
    #[tracing::instrument(skip_all, fields(job = %id))]
    pub async fn job_with_spec(
        &self,
        owner: &Owner,
        id: &JobId,
    ) -> StoreResult<(JobRecord, JobSpec)> {
        let row = job_row(self.readers(), select_job!(", spec"), owner, id).await?;
        Ok((job_from_row(&row)?, spec_from_json(&row.text("spec")?)?))
    }

    /// Newest first.
    #[tracing::instrument(skip_all)]
    pub async fn jobs(&self, owner: &Owner, page: Page) -> StoreResult<Vec<JobRecord>> {
        let rows = Sql::new(concat!(
            "SELECT ",
            job_columns!(),
            " FROM jobs WHERE owner = $1 AND seq < $2 ORDER BY seq DESC LIMIT $3"
        ))
        .bind(owner.as_str())
        .bind(page.before.unwrap_or(i64::MAX))
        .bind(i64::from(page.limit))
        .fetch_all(self.readers())
        .await?;
        Ok(rows.iter().map(job_from_row).collect::<Result<_, _>>()?)
    }

    /// Every owner's queued and running jobs, and the other jobs submitted after `after` (a
    /// `seq`), oldest first, with the newest `seq` of all (read first, so a job submitted
    /// meanwhile is newer than it): what the live view of jobs looks at.
    #[tracing::instrument(skip_all)]
    pub async fn live_jobs(&self, after: i64) -> StoreResult<(Vec<JobRecord>, i64)> {
        let mut connection = self.reader().await?;
        let newest = Sql::new("SELECT COALESCE(MAX(seq), 0) AS newest FROM jobs")
            .fetch_one(&mut connection)
            .await?
            .int("newest")?;
        // Two arms, so that each reads an index: the active jobs by status, the new ones by seq.
        let rows = Sql::new(concat!(
            "SELECT ",
            job_columns!(),
            " FROM jobs WHERE status IN ('queued', 'running') \
             UNION ALL SELECT ",
            job_columns!(),
            " FROM jobs WHERE seq > $1 AND status NOT IN ('queued', 'running') \
             ORDER BY seq"
        ))
        .bind(after)
        .fetch_all(&mut connection)
        .await?;
        let jobs = rows.iter().map(job_from_row).collect::<Result<_, _>>()?;
        Ok((jobs, newest))
    }

    /// Cancels a queued or running job; [`StoreError::Conflict`] if it already ended.
    /// The job's end is stamped `at`, or on the database's clock.
    #[tracing::instrument(skip_all, fields(job = %id))]
    pub async fn cancel(
        &self,
        owner: &Owner,
        id: &JobId,
        at: Option<UnixMs>,
    ) -> StoreResult<JobRecord> {
        // The job ends and what its run left goes in one transaction: a crash between the two
        // would have left a cancelled job's accumulators counted in its stored bytes.
        let mut tx = self.begin().await?;
        let now = now_or(self.dialect(), &mut tx, at).await?;
        let cancelled = Sql::new(
            "UPDATE jobs SET status = 'cancelled', finished_at = $3 \
             WHERE id = $1 AND owner = $2 AND status IN ('queued', 'running')",
        )
        .bind(id.as_str())
        .bind(owner.as_str())
        .bind(now.0)
        .execute(&mut tx)
        .await?;
        if cancelled == 1 {
            drop_unfinished(&mut tx, id).await?;
            // Read once the run's leftovers are dropped: its stored bytes without them.
            let cancelled = select_job(&mut tx, owner, id).await?;
            tx.commit().await?;
            self.ended(id);
            return Ok(cancelled);
        }
        let ended = select_job(&mut tx, owner, id).await?;
        tx.rollback().await?;
        Err(StoreError::Conflict(format!(
            "job {id} already ended: {}",
            ended.status.as_str()
        )))
    }

    /// Deletes a job that ended, with everything stored for it (its shards, result,
    /// distributions, device lives, its place among a schedule's runs), in one transaction;
    /// [`StoreError::Conflict`] while it is queued or running.
    #[tracing::instrument(skip_all, fields(job = %id))]
    pub async fn delete_job(&self, owner: &Owner, id: &JobId) -> StoreResult<()> {
        // The delete locks the job, then its shards; a worker's heartbeat locks its shard, then
        // the job (its progress): deleting a job just cancelled while a heartbeat of it is under
        // way can deadlock, and PostgreSQL then rolls one of the two back (a 503 for the delete,
        // seen once in CI). Run again, the heartbeat has ended.
        let mut attempt = 1;
        loop {
            match self.delete_ended_job(owner, id).await {
                Err(error) if error.is_deadlock() && attempt < DELETE_ATTEMPTS => {
                    tracing::warn!(%error, attempt, "deleting the job met a heartbeat's locks");
                    attempt += 1;
                }
                done => return done,
            }
        }
    }

    /// Deletes every owner's jobs that ended `age_ms` or more before `at` (or the database's
    /// clock, on which their ends are stamped) as [`Store::delete_job`] does, in one
    /// transaction; how many.
    #[tracing::instrument(skip_all)]
    pub async fn prune_jobs(&self, age_ms: i64, at: Option<UnixMs>) -> StoreResult<u64> {
        let mut tx = self.begin().await?;
        let ended_before = UnixMs(now_or(self.dialect(), &mut tx, at).await?.0 - age_ms);
        Sql::new(PRUNE_RUNS)
            .bind(ended_before.0)
            .execute(&mut tx)
            .await?;
        let deleted = Sql::new(PRUNE_JOBS)
            .bind(ended_before.0)
            .execute(&mut tx)
            .await?;
        tx.commit().await?;
        Ok(deleted)
    }

    /// Leases the next shard to run: a queued shard past its backoff or a running one whose lease
    /// expired (bumping its attempt), a merge step only once its batch's groups are done. Fair
    /// share: of the job with the least virtual start time (then the oldest job; in a job, shards
    /// in order), which is charged the shard's cost (docs/contract.md "Fair share"). A shard whose
    /// lease has expired `budget.lost_leases + 1` times fails its job instead, with the reason.
    #[tracing::instrument(skip_all, fields(worker))]
    pub async fn claim(
        &self,
        worker: &str,
        terms: LeaseTerms,
        budget: RetryBudget,
    ) -> StoreResult<Option<Claim>> {
        // A claim that a power cut undoes is claimed again, so its commit does not wait for the
        // disk; unless it also fails a job whose shard ran out of retries (an end is acknowledged
        // to whoever asks), which is rare: then the claim starts again, durable.
        let mut tx = self.begin_redoable().await?;
        let mut now = now_or(self.dialect(), &mut tx, terms.at).await?;
        let mut ending = exhausted(&mut tx, now, budget.lost_leases).await?;
        if !ending.is_empty() {
            tx.rollback().await?;
            tx = self.begin_reading_first().await?;
            now = now_or(self.dialect(), &mut tx, terms.at).await?;
            ending = exhausted(&mut tx, now, budget.lost_leases).await?;
        }
        for (job, shard, reason) in ending {
            // The lease that ran out is counted and said, as a run that failed its job is: the
            // shard then reads as the job's error tells (it read one lease short, its last
            // attempt "stopped: job failed").
            Sql::new(concat!(
                "UPDATE shards SET status = 'queued', lost_leases = lost_leases + 1, \
                 operations_done = 0, error = $4, history = ",
                history_lease_lost!(),
                " WHERE job_id = $1 AND batch = $2 AND grp = $3 AND status = 'running'",
            ))
            .bind(job.as_str())
            .bind(count_to_sql(shard.batch))
            .bind(group_to_sql(shard))
            .bind(reason.as_str())
            .execute(&mut tx)
            .await?;
            end_job(&mut tx, &job, now, &reason).await?;
        }
        // Fair share: the job with the least virtual start time (docs/contract.md "Fair share");
        // in a job, shards in order.
        let claimed = Sql::new(self.dialect().claim)
            .bind(worker)
            .bind(now.0)
            .bind(terms.duration_ms)
            .fetch_optional(&mut tx)
            .await?;
        let Some(claimed) = claimed else {
            tx.commit().await?;
            return Ok(None);
        };
        // The job runs from its first claim, is charged its shard's cost at each (fair share), and
        // counts the claimed shard's progress afresh; the statement returns what the worker needs
        // of the job (one round trip where three were).
        lock_job(self.dialect(), &mut tx, &claimed.text("job_id")?).await?;
        let job = Sql::new(concat!(
            "UPDATE jobs SET status = CASE WHEN status = 'queued' THEN 'running' ELSE status END, \
             started_at = COALESCE(started_at, $2), vstart = vtime, vtime = vtime + $3, ",
            progress_sums!(),
            " WHERE id = $1 RETURNING spec, started_at"
        ))
        .bind(claimed.text("job_id")?)
        .bind(now.0)
        .bind(claimed.int("operations_total")? + SHARD_OVERHEAD_OPERATIONS)
        .fetch_one(&mut tx)
        .await?;
        tx.commit().await?;
        claim_from_rows(&claimed, &job, now).map(Some)
    }

    /// Counts `operations`, run by a merge step that runs its job whole, as all its shard's, done,
    /// if the claim still holds it and the job still runs; fair share charges the job what they
    /// exceed of the `charged` operations its claim was charged (the step's first batch), so that
    /// a job run a second at a time is charged its seconds (docs/contract.md "Fair share").
    #[tracing::instrument(skip_all, fields(job = %fence.job, shard = %fence.shard))]
    pub async fn count_run(&self, fence: &Fence, operations: u64, charged: u64) -> StoreResult<()> {
        let mut tx = self.begin_redoable().await?;
        let ran = count_to_sql(operations);
        let counted = fenced(
            concat!(
                "UPDATE shards SET operations_done = $5, \
                 operations_total = CASE WHEN $5 > operations_total THEN $5 ELSE operations_total END \
                 WHERE ",
                fenced_shard!()
            ),
            fence,
        )
        .bind(ran)
        .execute(&mut tx)
        .await?;
        if counted != 1 {
            tx.rollback().await?;
            return Ok(());
        }
        Sql::new("UPDATE jobs SET vtime = vtime + $2 WHERE id = $1")
            .bind(fence.job.as_str())
            .bind(count_to_sql(operations.saturating_sub(charged)))
            .execute(&mut tx)
            .await?;
        sum_progress(self.dialect(), &mut tx, &fence.job).await?;
        tx.commit().await?;
        Ok(())
    }

    /// Extends the shard's lease and records its progress (the job's is the sum over its
    /// shards), if the claim still holds it and the job still runs: its operations done, and
    /// `operations_total` where that is more than the shard's total (a job run whole learns its
    /// next batch as it goes).
    #[tracing::instrument(skip_all, fields(job = %fence.job, shard = %fence.shard))]
    pub async fn heartbeat(
        &self,
        fence: &Fence,
        terms: LeaseTerms,
        operations_done: u64,
        operations_total: u64,
    ) -> StoreResult<Lease> {
        // A renewal that a power cut undoes leaves a lease that runs out: the shard runs again.
        let mut tx = self.begin_redoable().await?;
        let now = now_or(self.dialect(), &mut tx, terms.at).await?;
        let updated = fenced(
            concat!(
                // A job run whole with a precision target runs more than its first batch.
                "UPDATE shards SET lease_until = $5 + $6, operations_done = $7, \
                 operations_total = CASE WHEN $8 > operations_total THEN $8 ELSE operations_total END \
                 WHERE ",
                fenced_shard!()
            ),
            fence,
        )
        .bind(now.0)
        .bind(terms.duration_ms)
        .bind(count_to_sql(operations_done))
        .bind(count_to_sql(operations_total.max(operations_done)))
        .execute(&mut tx)
        .await?;
        if updated == 1 {
            sum_progress(self.dialect(), &mut tx, &fence.job).await?;
            tx.commit().await?;
            return Ok(Lease::Held);
        }
        let status = Sql::new("SELECT status FROM jobs WHERE id = $1")
            .bind(fence.job.as_str())
            .fetch_optional(&mut tx)
            .await?
            .map(|row| row.text("status"))
            .transpose()?;
        tx.commit().await?;
        Ok(if status.as_deref() == Some("running") {
            Lease::Lost
        } else {
            Lease::Cancelled
        })
    }

    /// Marks a group done with what it made, encoded: a group's accumulators
    /// (`partial_to_sql`) or a rare event's task's outcome ([`rows::encode`]).
    #[tracing::instrument(skip_all, fields(job = %fence.job, shard = %fence.shard))]
    pub async fn complete_encoded(&self, fence: &Fence, partial: Vec<u8>) -> StoreResult<bool> {
        let partial_bytes = partial.len() as u64;
        self.check_room(partial_bytes).await?;
        // Accumulators that a power cut undoes are computed again, to the same bits.
        let mut tx = self.begin_redoable().await?;
        let updated = fenced(
            concat!(
                "UPDATE shards SET status = 'done', partial = $5, operations_done = operations_total, error = NULL, \
                 lease_until = NULL WHERE ",
                fenced_shard!()
            ),
            fence,
        )
        .bind(partial)
        .execute(&mut tx)
        .await?;
        if updated == 0 {
            tx.rollback().await?;
            return Ok(false);
        }
        // Only a job still running (as in `succeed`): a cancel committed since the fence was read
        // dropped the accumulators, and these would be counted in a job that ended.
        lock_job(self.dialect(), &mut tx, fence.job.as_str()).await?;
        let counted = Sql::new(concat!(
            "UPDATE jobs SET stored_bytes = stored_bytes + $2, ",
            progress_sums!(),
            " WHERE id = $1 AND status = 'running'"
        ))
        .bind(fence.job.as_str())
        .bind(count_to_sql(partial_bytes))
        .execute(&mut tx)
        .await?;
        if counted == 0 {
            tx.rollback().await?;
            return Ok(false);
        }
        tx.commit().await?;
        Ok(true)
    }

    /// Marks a merge step done and queues the next step's shards, in one transaction, if the claim
    /// still holds it: a precision target's next batch, or a rare event's round with `state`,
    /// encoded ([`rows::encode`]), as its merge step's partial. `folded` (the groups of every batch so
    /// far, folded) replaces the accumulators of batch `folded_through`'s groups, the last batch
    /// run (inserted, for a job that ran whole;
    /// [`crate::domain::shards::Merged::folded_through`]), and what the next step no longer
    /// reads is dropped: the groups of earlier batches, or a round's outcomes and state (the
    /// devices' groups are kept for the Result). The step counts the operations it `ran` itself:
    /// what it planned beyond them (a rare event's budget) is the queued shards' to count.
    #[tracing::instrument(skip_all, fields(job = %fence.job, shard = %fence.shard))]
    pub async fn add_batch(
        &self,
        fence: &Fence,
        ran: u64,
        shards: &[ShardPlan],
        folded: &EncodedGroups,
        last_run: u64,
        state: Option<&[u8]>,
    ) -> StoreResult<bool> {
        self.check_room(folded.0.iter().map(|partial| partial.len() as u64).sum())
            .await?;
        let Some(mut tx) = self.begin_finishing(fence, ran).await? else {
            return Ok(false);
        };
        let batch = count_to_sql(last_run);
        for (group, partial) in folded.0.iter().enumerate() {
            Sql::new(
                "INSERT INTO shards (job_id, batch, grp, status, operations_total, partial) \
                 VALUES ($1, $2, $3, 'done', 0, $4) \
                 ON CONFLICT (job_id, batch, grp) DO UPDATE SET partial = excluded.partial",
            )
            .bind(fence.job.as_str())
            .bind(batch)
            .bind(count_to_sql(group as u64))
            .bind(partial.clone())
            .execute(&mut tx)
            .await?;
        }
        // A batch of devices holds the fold of every batch before it; a round's next round holds
        // all its merge step needs, and the devices' fold is kept for the Result.
        let dropped = if is_round(fence.shard.batch) {
            RARE_ROUNDS..fence.shard.batch + 1
        } else {
            0..last_run
        };
        Sql::new(
            "UPDATE shards SET partial = NULL \
             WHERE job_id = $1 AND batch >= $2 AND batch < $3 AND partial IS NOT NULL",
        )
        .bind(fence.job.as_str())
        .bind(count_to_sql(dropped.start))
        .bind(count_to_sql(dropped.end))
        .execute(&mut tx)
        .await?;
        insert_shards(&mut tx, &fence.job, shards).await?;
        if let (Some(state), Some(merge)) = (state, shards.last()) {
            Sql::new(
                "UPDATE shards SET partial = $4 WHERE job_id = $1 AND batch = $2 AND grp = $3",
            )
            .bind(fence.job.as_str())
            .bind(count_to_sql(merge.shard.batch))
            .bind(group_to_sql(merge.shard))
            .bind(state.to_vec())
            .execute(&mut tx)
            .await?;
        }
        let counted = Sql::new(concat!(
            "UPDATE jobs SET stored_bytes = octet_length(spec) + ",
            partial_bytes!(),
            " WHERE id = $1 AND status = 'running'"
        ))
        .bind(fence.job.as_str())
        .execute(&mut tx)
        .await?;
        if counted == 0 {
            // Cancelled since the fence was read (see `complete_encoded`).
            tx.rollback().await?;
            return Ok(false);
        }
        sum_progress(self.dialect(), &mut tx, &fence.job).await?;
        tx.commit().await?;
        Ok(true)
    }

    /// Marks the job failed with `error` at once (a failure no retry can mend), if the claim still
    /// holds its shard: the shard reads as a failed run (as [`Store::fail_attempt`] leaves one),
    /// the operations it `ran`, of the total it learnt, counted in the job's progress (a step
    /// that failed read 0 of what it had run where no heartbeat had told it, found from outside).
    /// The job's end is stamped `at`, or on the database's clock.
    #[tracing::instrument(skip_all, fields(job = %fence.job, shard = %fence.shard))]
    pub async fn fail(
        &self,
        fence: &Fence,
        at: Option<UnixMs>,
        ran: [u64; 2],
        error: &str,
    ) -> StoreResult<bool> {
        let mut tx = self.begin().await?;
        let now = now_or(self.dialect(), &mut tx, at).await?;
        if failed_run(&mut tx, fence, error, ran).await?.is_none() {
            tx.rollback().await?;
            return Ok(false);
        }
        sum_progress(self.dialect(), &mut tx, &fence.job).await?;
        end_job(&mut tx, &fence.job, now, error).await?;
        tx.commit().await?;
        self.ended(&fence.job);
        Ok(true)
    }

    /// Hands a shard whose run failed back to the queue, counting the failure, to be claimed again
    /// after [`crate::domain::retry_backoff_ms`] on the database's clock (or from `at`, as [`LeaseTerms::at`]);
    /// once it failed more than `retries` times, its job fails instead, with the reason.
    #[tracing::instrument(skip_all, fields(job = %fence.job, shard = %fence.shard))]
    pub async fn fail_attempt(
        &self,
        fence: &Fence,
        at: Option<UnixMs>,
        error: &str,
        retries: u64,
    ) -> StoreResult<bool> {
        let mut tx = self.begin().await?;
        let now = now_or(self.dialect(), &mut tx, at).await?;
        let Some(failures) = failed_run(&mut tx, fence, error, [0, 0]).await? else {
            tx.rollback().await?;
            return Ok(false);
        };
        let ends = failures > retries;
        if ends {
            let reason = failed_too_often(retries, fence.shard, failures, error);
            end_job(&mut tx, &fence.job, now, &reason).await?;
        } else {
            Sql::new(
                "UPDATE shards SET retry_at = $4 WHERE job_id = $1 AND batch = $2 AND grp = $3",
            )
            .bind(fence.job.as_str())
            .bind(count_to_sql(fence.shard.batch))
            .bind(group_to_sql(fence.shard))
            .bind(now.0 + retry_backoff_ms(failures))
            .execute(&mut tx)
            .await?;
            sum_progress(self.dialect(), &mut tx, &fence.job).await?;
        }
        tx.commit().await?;
        if ends {
            self.ended(&fence.job);
        }
        Ok(true)
    }

    /// Hands a shard whose outcome could not be stored back to the queue, counting nothing
    /// against it, to be claimed again after [`crate::domain::ROOM_RETRY_MS`] on the database's
    /// clock (or from `at`): its job waits (an operator makes room or connections, or cancels
    /// it) rather than fail. Its `error` is `waiting for room: REASON` (or `waiting for the
    /// database: REASON`) meanwhile, and its history has one line of it however often it waits.
    #[tracing::instrument(skip_all, fields(job = %fence.job, shard = %fence.shard))]
    pub async fn wait_for(
        &self,
        fence: &Fence,
        at: Option<UnixMs>,
        awaited: Awaited,
        reason: &str,
    ) -> StoreResult<bool> {
        let mut tx = self.begin().await?;
        let now = now_or(self.dialect(), &mut tx, at).await?;
        let updated = fenced(
            concat!(
                // One line however long it waits (its error says it waits already): a shard's
                // history would grow every 15 s.
                "UPDATE shards SET status = 'queued', operations_done = 0, retry_at = $6, \
                 history = CASE WHEN error LIKE 'waiting for %' THEN history \
                 ELSE history || 'attempt ' || attempt || ' (' || COALESCE(lease_owner, '?') || '): ' || $5 || '\n' END, \
                 error = $5, \
                 lease_until = NULL WHERE ",
                fenced_shard!()
            ),
            fence,
        )
        .bind(format!("waiting for {}: {reason}", awaited.as_str()))
        .bind(now.0 + ROOM_RETRY_MS)
        .execute(&mut tx)
        .await?;
        sum_progress(self.dialect(), &mut tx, &fence.job).await?;
        tx.commit().await?;
        Ok(updated == 1)
    }

    /// Hands a running shard back to the queue (graceful shutdown), without counting a failure.
    #[tracing::instrument(skip_all, fields(job = %fence.job, shard = %fence.shard))]
    pub async fn release(&self, fence: &Fence) -> StoreResult<bool> {
        let mut tx = self.begin().await?;
        let updated = fenced(
            concat!(
                "UPDATE shards SET status = 'queued', lease_until = NULL, operations_done = 0, \
                 history = history || 'attempt ' || attempt || ' (' || \
                 COALESCE(lease_owner, '?') || '): handed back at shutdown\n' WHERE ",
                fenced_shard!()
            ),
            fence,
        )
        .execute(&mut tx)
        .await?;
        sum_progress(self.dialect(), &mut tx, &fence.job).await?;
        tx.commit().await?;
        Ok(updated == 1)
    }

    /// The job's shards, in order: at most `limit` of them, after the first `skip`. Shards are
    /// only ever added after those already there, so pages read one after another miss none.
    #[tracing::instrument(skip_all, fields(job = %id))]
    pub async fn shards_from(
        &self,
        id: &JobId,
        skip: u64,
        limit: u64,
    ) -> StoreResult<Vec<ShardRecord>> {
        let rows = Sql::new(concat!(
            "SELECT ",
            shard_columns!(),
            ", (SELECT status FROM jobs WHERE id = $1) AS job_status",
            // A job that ran whole keeps its devices' groups in rows of their own while its
            // rare event's rounds run (`add_batch`): stored, never claimed, so no shard of it.
            " FROM shards WHERE job_id = $1 AND (attempt > 0 OR status <> 'done') \
              ORDER BY batch, grp < 0, grp LIMIT $2 OFFSET $3"
        ))
        .bind(id.as_str())
        .bind(count_to_sql(limit))
        .bind(count_to_sql(skip))
        .fetch_all(self.readers())
        .await?;
        let shards = rows.iter().map(|row| {
            let shard = shard_from_row(row)?;
            let job = row.maybe_text("job_status")?.unwrap_or_default();
            Ok::<_, sqlx::Error>(shard.as_ended_by(&job))
        });
        Ok(shards.collect::<Result<_, _>>()?)
    }

    /// `(queued, running)` job counts, for metrics.
    #[tracing::instrument(skip_all)]
    pub async fn queue_depth(&self) -> StoreResult<(u64, u64)> {
        let row = Sql::new(
            "SELECT COUNT(*) FILTER (WHERE status = 'queued') AS queued, \
             COUNT(*) FILTER (WHERE status = 'running') AS running FROM jobs",
        )
        .fetch_one(self.readers())
        .await?;
        Ok((
            count_from_sql(&row, "queued")?,
            count_from_sql(&row, "running")?,
        ))
    }

    /// The database's clock, which leases, a job's start and end, idempotency keys and the
    /// schedules' due times are judged by: instances whose clocks disagree agree on them.
    pub async fn now(&self) -> StoreResult<UnixMs> {
        let row = Sql::new(self.dialect().now)
            .fetch_one(self.readers())
            .await?;
        Ok(UnixMs(row.int("now")?))
    }

    /// Whether the database answers (`/healthz`): `SELECT 1` on each pool at once, the first
    /// answer taken. SQLite's readers all serving long reads are busy, not unavailable: 200
    /// clients reading a large CSV failed 7 of 11 health checks while every read succeeded (found
    /// from outside); the writer answers then.
    #[tracing::instrument(skip_all)]
    pub async fn ping(&self) -> StoreResult<()> {
        let pings = self
            .pools()
            .into_iter()
            .map(|pool| Box::pin(Sql::new("SELECT 1").execute(pool)));
        futures_util::future::select_ok(pings).await?;
        Ok(())
    }

    /// Whether this instance can do its work (`/readyz`): the database takes a write (recorded at
    /// `now`), every migration this build knows is applied, and, for SQLite, the file at the
    /// database's path is still the one opened, with at least `min_free_disk_bytes` free beside
    /// it. [`StoreError::NotReady`] says what is wrong.
    #[tracing::instrument(skip_all)]
    pub async fn ready(&self, min_free_disk_bytes: u64, now: UnixMs) -> StoreResult<()> {
        self.check_disk(min_free_disk_bytes).await?;
        Sql::new(READINESS_WRITE)
            .bind(now.0)
            .execute(self.writer()?)
            .await?;
        let applied = Sql::new(LATEST_APPLIED_MIGRATION)
            .fetch_one(self.readers())
            .await?
            .maybe_int("version")?;
        schema_current(self.dialect().migrator, applied)
    }

    /// Announcements of changes to the queue, where the backend makes them (PostgreSQL's
    /// LISTEN/NOTIFY); `None` means the caller polls.
    pub fn events(&self) -> Option<broadcast::Receiver<QueueEvent>> {
        self.subscribe()
    }

    /// Jobs that ended, as soon as the store knows: [`QueueEvent::Changed`] with the job's id
    /// (PostgreSQL announces the ends of every instance's jobs, SQLite those of jobs this process
    /// wrote); a job's progress is not announced here. Not every end reaches it (another process
    /// on the same SQLite file, an announcement missed while PostgreSQL's listener reconnected): a
    /// waiter reads the job again now and then.
    pub fn ends(&self) -> broadcast::Receiver<QueueEvent> {
        self.subscribe_ends()
    }

    /// Marks a group done with its accumulators, encoded here, in one transaction, if the claim
    /// still holds it. A worker encodes them off the async threads and calls
    /// [`Store::complete_encoded`].
    pub async fn complete(&self, fence: &Fence, stats: &GroupStats) -> StoreResult<bool> {
        self.complete_encoded(fence, rows::partial_to_sql(stats)?)
            .await
    }

    /// The job's shards, in order, all of them.
    pub async fn shards(&self, id: &JobId) -> StoreResult<Vec<ShardRecord>> {
        self.shards_from(id, 0, u64::MAX).await
    }
}
