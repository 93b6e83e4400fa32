//! What every backend shares: the column lists, the mapping of each table's row to its record (one
//! place per table, whatever the database), and how values are stored (counts, seeds, times, JSON).

use super::sql::{AnyRow, Sql, Tx};
use super::{
    Claim, DistributionRow, Fence, JobRecord, Operations, RunRecord, ScheduleRecord, ShardRecord,
    StoreError, StoreResult,
};
use crate::domain::{
    Attempt, IdempotencyKey, JobId, JobStatus, Owner, QueuedJob, ScheduleDefinition, ScheduleId,
    ShardId, ShardPlan, UnixMs,
};
use bouncewear_model::montecarlo::engine::GroupStats;
use bouncewear_model::montecarlo::{DeviceLife, JobResult, JobSpec, RunGroups};
use bouncewear_model::stats::Accumulator;
use sqlx::migrate::Migrator;

/// SQL integers are signed 64-bit in both backends: counts saturate, seeds keep their bits (a seed
/// of 2^63 or more reads as negative in SQL).
pub(crate) fn count_to_sql(value: u64) -> i64 {
    i64::try_from(value).unwrap_or(i64::MAX)
}

pub(crate) fn count_from_sql(row: &AnyRow, column: &str) -> Result<u64, sqlx::Error> {
    Ok(row.int(column)?.max(0) as u64)
}

pub(crate) fn seed_to_sql(seed: u64) -> i64 {
    seed as i64
}

pub(crate) fn seed_from_sql(stored: i64) -> u64 {
    stored as u64
}

pub(crate) fn ms(row: &AnyRow, column: &str) -> Result<UnixMs, sqlx::Error> {
    row.int(column).map(UnixMs)
}

pub(crate) fn optional_ms(row: &AnyRow, column: &str) -> Result<Option<UnixMs>, sqlx::Error> {
    Ok(row.maybe_int(column)?.map(UnixMs))
}

pub(crate) fn status(row: &AnyRow) -> Result<JobStatus, sqlx::Error> {
    let text = row.text("status")?;
    JobStatus::parse(&text).ok_or_else(|| sqlx::Error::Decode(format!("status {text}").into()))
}

pub(crate) fn spec_from_json(text: &str) -> StoreResult<JobSpec> {
    serde_json::from_str(text).map_err(|e| corrupt("job spec", e))
}

pub(crate) fn to_json(what: &'static str, value: &impl serde::Serialize) -> StoreResult<String> {
    serde_json::to_string(value).map_err(|e| corrupt(what, e))
}

pub(crate) fn corrupt(what: &'static str, error: impl std::fmt::Display) -> StoreError {
    StoreError::Corrupt {
        what,
        detail: error.to_string(),
    }
}

// ---- deleting ended jobs -------------------------------------------------------------------
// A job's shards, result, distributions and device lives go with it (ON DELETE CASCADE); its
// schedule run row is deleted in the same transaction (its key is checked at commit).

/// Deletes job `$1` of owner `$2` if it ended.
pub(crate) const DELETE_ENDED_JOB: &str = "DELETE FROM jobs WHERE id = $1 AND owner = $2 \
     AND status IN ('succeeded', 'failed', 'cancelled')";

pub(crate) const DELETE_RUN_OF_JOB: &str = "DELETE FROM schedule_runs WHERE job_id = $1";

/// Deletes the jobs that ended before `$1`.
pub(crate) const PRUNE_JOBS: &str = "DELETE FROM jobs WHERE finished_at < $1 \
     AND status IN ('succeeded', 'failed', 'cancelled')";

pub(crate) const PRUNE_RUNS: &str = "DELETE FROM schedule_runs WHERE job_id IN \
     (SELECT id FROM jobs WHERE finished_at < $1 AND status IN ('succeeded', 'failed', 'cancelled'))";

/// Why an existing job cannot be deleted: it has not ended.
pub(crate) fn not_ended(job: &JobRecord) -> StoreError {
    StoreError::Conflict(format!(
        "job {} is {}: cancel it first",
        job.id,
        job.status.as_str()
    ))
}

// ---- idempotency keys ----------------------------------------------------------------------

/// Forgets key `$3` of owner `$1` in collection `$2` if it was used before `$4`.
pub(crate) const FORGET_EXPIRED_KEY: &str = "DELETE FROM idempotency_keys \
     WHERE owner = $1 AND collection = $2 AND key = $3 AND created_at < $4";

/// What key `$3` of owner `$1` in collection `$2` created: `fingerprint, resource`.
pub(crate) const REMEMBERED_KEY: &str = "SELECT fingerprint, COALESCE(job_id, schedule_id) AS resource \
     FROM idempotency_keys WHERE owner = $1 AND collection = $2 AND key = $3";

/// Remembers `owner, collection, key, fingerprint, job_id, schedule_id, created_at`.
pub(crate) const REMEMBER_KEY: &str = "INSERT INTO idempotency_keys \
     (owner, collection, key, fingerprint, job_id, schedule_id, created_at) \
     VALUES ($1, $2, $3, $4, $5, $6, $7)";

/// A remembered key: the fingerprint of its first body and the id of what that created.
pub(crate) fn remembered_from_row(row: &AnyRow) -> Result<(String, String), sqlx::Error> {
    Ok((row.text("fingerprint")?, row.text("resource")?))
}

/// Binds [`REMEMBER_KEY`]'s parameters: a job's or a schedule's key, used at `now`.
pub(crate) fn bind_key(
    query: Sql,
    owner: &Owner,
    created: Created<'_>,
    key: &IdempotencyKey,
    now: UnixMs,
) -> Sql {
    let (job, schedule) = match created {
        Created::Job(id) => (Some(id.to_string()), None),
        Created::Schedule(id) => (None, Some(id.to_string())),
    };
    query
        .bind(owner.as_str().to_owned())
        .bind(created.collection().to_owned())
        .bind(key.key.clone())
        .bind(key.fingerprint.clone())
        .bind(job)
        .bind(schedule)
        .bind(now.0)
}

/// What a POST with a key created.
#[derive(Debug, Clone, Copy)]
pub(crate) enum Created<'a> {
    Job(&'a JobId),
    Schedule(&'a ScheduleId),
}

impl Created<'_> {
    /// The collection it was POSTed to: keys are per owner and collection.
    pub(crate) fn collection(self) -> &'static str {
        match self {
            Created::Job(_) => "jobs",
            Created::Schedule(_) => "schedules",
        }
    }
}

// ---- readiness ------------------------------------------------------------------------------

/// The write readiness makes, `now` as parameter 1: the same in both backends' SQL.
pub(crate) const READINESS_WRITE: &str = "INSERT INTO readiness (id, checked_at) VALUES (1, $1) \
     ON CONFLICT (id) DO UPDATE SET checked_at = excluded.checked_at";

/// The newest migration applied to the database.
pub(crate) const LATEST_APPLIED_MIGRATION: &str =
    "SELECT MAX(version) AS version FROM _sqlx_migrations WHERE success";

/// Not ready when the database's schema is older than this build's (`applied`, the newest
/// migration applied): another version migrated it back, or it is another database.
pub(crate) fn schema_current(migrator: &Migrator, applied: Option<i64>) -> StoreResult<()> {
    let known = migrator.iter().map(|m| m.version).max().unwrap_or(0);
    let applied = applied.unwrap_or(0);
    if applied < known {
        return Err(StoreError::NotReady(format!(
            "the database's schema is at migration {applied}; this build needs {known}"
        )));
    }
    Ok(())
}

// ---- what the two databases say differently -------------------------------------------------

/// The statements whose text differs between the two databases (`sqlite::DIALECT`,
/// `postgres::DIALECT`); every other statement is the same text on both.
pub(crate) struct Dialect {
    /// The database's clock, in ms since the Unix epoch, as column `now`: one clock for every
    /// instance that shares the database.
    pub now: &'static str,
    /// Whether a claim still holds its shard, with the lock that keeps the job from ending
    /// meanwhile where the database has row locks.
    pub holds: &'static str,
    /// The claim of the next shard ([`claim_next`]).
    pub claim: &'static str,
    pub migrator: &'static Migrator,
}

// ---- jobs ----------------------------------------------------------------------------------

macro_rules! job_columns {
    () => {
        "seq, id, owner, name, seed, status, operations_done, operations_total, error, \
         created_at, started_at, finished_at, stored_bytes"
    };
}

pub(crate) use job_columns;

pub(crate) fn job_from_row(row: &AnyRow) -> Result<JobRecord, sqlx::Error> {
    Ok(JobRecord {
        seq: row.int("seq")?,
        id: JobId::from(row.text("id")?),
        owner: Owner::from_stored(row.text("owner")?),
        name: row.maybe_text("name")?,
        seed: seed_from_sql(row.int("seed")?),
        status: status(row)?,
        operations_done: count_from_sql(row, "operations_done")?,
        operations_total: count_from_sql(row, "operations_total")?,
        error: row.maybe_text("error")?,
        created_at: ms(row, "created_at")?,
        started_at: optional_ms(row, "started_at")?,
        finished_at: optional_ms(row, "finished_at")?,
        stored_bytes: count_from_sql(row, "stored_bytes")?,
    })
}

/// Why a job failed when one of its shards' lease kept expiring.
pub(crate) fn gave_up(retries: u64, shard: ShardId) -> String {
    format!(
        "gave up after {retries} retries: the lease of {shard} expired {} times (its worker stopped or stalled, or lost the database, each time)",
        retries + 1
    )
}

/// Why a job failed when one of its shards kept failing.
pub(crate) fn failed_too_often(retries: u64, shard: ShardId, failures: u64, error: &str) -> String {
    format!(
        "gave up after {retries} retries: {shard} failed {failures} times; the last time: {error}"
    )
}

/// Binds a new queued job's columns `id, owner, name, spec, seed, operations_total, created_at`
/// as parameters 1 to 7.
pub(crate) fn bind_queued_job(query: Sql, job: &QueuedJob) -> StoreResult<Sql> {
    Ok(query
        .bind(job.id.to_string())
        .bind(job.owner.as_str().to_owned())
        .bind(job.name.clone())
        .bind(to_json("job spec", &job.spec)?)
        .bind(seed_to_sql(job.seed))
        .bind(count_to_sql(job.operations_total))
        .bind(job.created_at.0))
}

/// The insert of a queued job, `$1` to `$7` bound by [`bind_queued_job`], with the condition
/// a backend adds.
///
/// [`bind_queued_job`]: super::rows::bind_queued_job
macro_rules! insert_job {
    ($condition:literal) => {
        concat!(
            "INSERT INTO jobs (id, owner, name, spec, seed, status, operations_total, created_at, stored_bytes, vtime) \
             SELECT $1, $2, $3, $4, $5, 'queued', $6, $7, octet_length($4), \
                    COALESCE((SELECT MAX(vstart) FROM jobs), 0)",
            $condition
        )
    };
}

pub(crate) use insert_job;

/// Inserts a batch's shards in one statement: one round trip whatever their number.
pub(crate) async fn insert_shards(
    tx: &mut Tx,
    job: &JobId,
    shards: &[ShardPlan],
) -> StoreResult<()> {
    if shards.is_empty() {
        return Ok(());
    }
    let rows: Vec<String> = (0..shards.len())
        .map(|i| {
            let n = 2 + 3 * i;
            format!("($1, ${n}, ${}, 'queued', ${})", n + 1, n + 2)
        })
        .collect();
    let insert = format!(
        "INSERT INTO shards (job_id, batch, grp, status, operations_total) VALUES {}",
        rows.join(", ")
    );
    let insert = shards
        .iter()
        .fold(Sql::built(insert).bind(job.as_str()), |insert, plan| {
            insert
                .bind(count_to_sql(plan.shard.batch))
                .bind(group_to_sql(plan.shard))
                .bind(count_to_sql(plan.operations))
        });
    insert.execute(&mut *tx).await?;
    Ok(())
}

// ---- shards --------------------------------------------------------------------------------

/// The condition of a write of one claim: only while its attempt still holds the running shard of
/// a running job. The fence is parameters 1 to 4.
macro_rules! fenced_shard {
    () => {
        "job_id = $1 AND batch = $2 AND grp = $3 AND attempt = $4 AND status = 'running' \
         AND (SELECT status FROM jobs WHERE id = $1) = 'running'"
    };
}

pub(crate) use fenced_shard;

/// Leases the next shard (see [`super::JobQueue::claim`]): the target picks the shard's row with the
/// lock the backend takes on it; `$jobs` names the jobs table, with the index that walks the open
/// ones in fair-share order where the backend must be told. `s.status <> 'done'`, implied by the
/// terms after it, is there for the partial index `shards_open_by_job`, which a planner uses only
/// where the query states its condition. `$1` the worker, `$2` now, `$3` the lease's duration.
macro_rules! claim_next {
    ($target:literal, $jobs:literal, $lock:literal) => {
        concat!(
            "UPDATE shards SET status = 'running', attempt = attempt + 1, lease_owner = $1, lease_until = $2 + $3, \
             operations_done = 0, retry_at = NULL, \
             lost_leases = lost_leases + CASE WHEN status = 'running' THEN 1 ELSE 0 END, \
             history = history || CASE WHEN status = 'running' \
                 THEN 'attempt ' || attempt || ' (' || COALESCE(lease_owner, '?') || '): lease lost\n' \
                 ELSE '' END \
             WHERE ",
            $target,
            " FROM ",
            $jobs,
            " CROSS JOIN shards s \
                            WHERE s.job_id = j.id AND j.status IN ('queued', 'running') AND s.status <> 'done' \
                            AND ((s.status = 'queued' AND COALESCE(s.retry_at, 0) <= $2) \
                                 OR (s.status = 'running' AND s.lease_until < $2)) \
                            AND (s.grp >= 0 OR NOT EXISTS (SELECT 1 FROM shards o WHERE o.job_id = s.job_id \
                                 AND o.batch = s.batch AND o.grp >= 0 AND o.status <> 'done')) \
                            ORDER BY j.vtime, j.seq, s.batch, s.grp LIMIT 1",
            $lock,
            ") RETURNING job_id, batch, grp, attempt, operations_total"
        )
    };
}

pub(crate) use claim_next;

/// The stored group of a shard: a merge step is group -1.
pub(crate) fn group_to_sql(shard: ShardId) -> i64 {
    shard.group.map_or(-1, count_to_sql)
}

pub(crate) fn shard_id_from_row(row: &AnyRow) -> Result<ShardId, sqlx::Error> {
    let batch = count_from_sql(row, "batch")?;
    let group = row.int("grp")?;
    Ok(ShardId {
        batch,
        group: u64::try_from(group).ok(),
    })
}

macro_rules! shard_columns {
    () => {
        "batch, grp, status, attempt, failures, lost_leases, lease_owner, operations_done, operations_total, error, history"
    };
}

pub(crate) use shard_columns;

pub(crate) fn shard_from_row(row: &AnyRow) -> Result<ShardRecord, sqlx::Error> {
    Ok(ShardRecord {
        shard: shard_id_from_row(row)?,
        status: row.text("status")?,
        attempt: Attempt(row.int("attempt")?),
        failures: count_from_sql(row, "failures")?,
        lost_leases: count_from_sql(row, "lost_leases")?,
        worker: row.maybe_text("lease_owner")?,
        operations_done: count_from_sql(row, "operations_done")?,
        operations_total: count_from_sql(row, "operations_total")?,
        error: row.maybe_text("error")?,
        history: row.text("history")?.lines().map(str::to_owned).collect(),
    })
}

/// Binds a claim's fence `job_id, batch, grp, attempt` as parameters 1 to 4.
pub(crate) fn bind_fence(query: Sql, fence: &Fence) -> Sql {
    query
        .bind(fence.job.to_string())
        .bind(count_to_sql(fence.shard.batch))
        .bind(group_to_sql(fence.shard))
        .bind(fence.attempt.0)
}

/// A claim, from a row of the claimed shard joined with its job: `job_id, batch, grp, attempt,
/// operations_total, spec, started_at`.
pub(crate) fn claim_from_row(row: &AnyRow) -> StoreResult<Claim> {
    Ok(Claim {
        fence: Fence {
            job: JobId::from(row.text("job_id")?),
            shard: shard_id_from_row(row)?,
            attempt: Attempt(row.int("attempt")?),
        },
        spec: spec_from_json(&row.text("spec")?)?,
        operations_total: count_from_sql(row, "operations_total")?,
        started_at: ms(row, "started_at")?,
    })
}

/// A done group's accumulators as stored: JSON (every float by its bits, so exact), gzipped, which
/// takes the dense histogram counts' runs of zeros and small numbers to under a third (45 kB for a
/// group of 10 bins x 14 metrics).
pub(crate) fn partial_to_sql(stats: &GroupStats) -> StoreResult<Vec<u8>> {
    gzip_json("group accumulators", stats)
}

/// The query that lists a job's done groups' accumulators, in batch and group order, as rows
/// `batch, grp, partial` (for [`collect_partials`]).
pub(crate) const SELECT_PARTIALS: &str = "SELECT batch, grp, partial FROM shards \
     WHERE job_id = $1 AND grp >= 0 AND status = 'done' AND partial IS NOT NULL ORDER BY batch, grp";

/// The done groups' accumulators from [`SELECT_PARTIALS`]' rows as they stream in: each row's
/// gzipped bytes are decoded (off the async threads) and dropped before the next row is read, so
/// a merge holds its groups once, decoded, and never all of them stored beside them (32 groups of
/// a 1000-bin job are about 185 MB gzipped).
pub(crate) async fn collect_partials(
    rows: impl futures_util::Stream<Item = Result<AnyRow, sqlx::Error>>,
) -> StoreResult<Vec<(ShardId, GroupStats)>> {
    use futures_util::TryStreamExt;
    let mut rows = std::pin::pin!(rows);
    let mut partials = Vec::new();
    while let Some(row) = rows.try_next().await? {
        let shard = shard_id_from_row(&row)?;
        let stored = row.bytes("partial")?;
        drop(row);
        let stats = tokio::task::spawn_blocking(move || {
            gunzip_json::<GroupStats>("group accumulators", &stored)
        })
        .await
        .map_err(|e| corrupt("group accumulators", e))??;
        partials.push((shard, stats));
    }
    Ok(partials)
}

/// Accumulators as stored: JSON, every float by its bits, gzipped. Written straight into the
/// compressor: the JSON text (several times the gzipped size) is never held whole, at no cost in
/// speed.
fn gzip_json(what: &'static str, value: &impl serde::Serialize) -> StoreResult<Vec<u8>> {
    let mut encoder = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    serde_json::to_writer(std::io::BufWriter::new(&mut encoder), value)
        .map_err(|e| corrupt(what, e))?;
    encoder.finish().map_err(|e| corrupt(what, e))
}

/// The inverse of [`gzip_json`]: decompressed whole, then parsed from the slice. Parsing as it
/// decompresses (`serde_json::from_reader`) held less at once but made a query over 1000 bins of
/// the largest job 1.6-2x slower (0.67-1.05 s against 1.42-1.46 s), and the merge's peak is its
/// decoded groups, read one at a time, not this text.
fn gunzip_json<T: serde::de::DeserializeOwned>(
    what: &'static str,
    stored: &[u8],
) -> StoreResult<T> {
    use std::io::Read;
    let mut text = Vec::with_capacity(stored.len() * 8);
    flate2::read::GzDecoder::new(stored)
        .read_to_end(&mut text)
        .map_err(|e| corrupt(what, e))?;
    serde_json::from_slice(&text).map_err(|e| corrupt(what, e))
}

// ---- results, distributions, device lives --------------------------------------------------

/// One `distributions` row per bin of every operation metric, and one per device metric.
/// Distribution rows a result writes per transaction: about 2 kB each.
pub(crate) const DISTRIBUTIONS_PER_WRITE: usize = 250;
/// Device lives a result writes per transaction.
pub(crate) const LIVES_PER_WRITE: usize = 5_000;
/// What a device life counts towards a job's stored bytes: its three numbers.
pub(crate) const LIFE_ROW_BYTES: u64 = 24;

pub(crate) fn distribution_rows(
    result: &JobResult,
) -> impl Iterator<Item = (&str, DistributionRow)> {
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

/// Inserts one `distributions` row (a merge step that reruns writes the same row again: kept).
pub(crate) const INSERT_DISTRIBUTION: &str = "INSERT INTO distributions (job_id, metric, kind, bin, \
     op_start, op_end, n, mean, sd, min, max, p05, p50, p95, exceedance, summary, groups) VALUES \
     ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10, $11, $12, $13, $14, $15, $16, $17) ON CONFLICT DO NOTHING";

/// Binds [`INSERT_DISTRIBUTION`]'s parameters: `groups` is [`row_groups_to_sql`].
pub(crate) fn bind_distribution(
    query: Sql,
    job: &JobId,
    metric: &str,
    row: &DistributionRow,
    groups: Vec<u8>,
) -> StoreResult<Sql> {
    let summary = &row.summary;
    let quantile = |key: &str| summary.quantiles.get(key).map_or(0.0, |q| q.value);
    Ok(query
        .bind(job.to_string())
        .bind(metric.to_owned())
        .bind(row.kind.clone())
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
        .bind(groups))
}

/// The groups' accumulators one distribution row summarises, as stored for queries after the run.
pub(crate) fn row_groups_to_sql(
    groups: &RunGroups,
    metric: &str,
    row: &DistributionRow,
) -> StoreResult<Vec<u8>> {
    let of_row = u64::try_from(row.bin)
        .ok()
        .and_then(|bin| groups.borrowed(metric, bin))
        .ok_or_else(|| corrupt(GROUPS, format!("the run has no {metric} bin {}", row.bin)))?;
    gzip_json(GROUPS, &of_row)
}

const GROUPS: &str = "groups of a distribution";

/// The bins of metric `$2` of job `$1` overlapping `[$3, $4)`, in bin order: their summaries.
pub(crate) const SELECT_DISTRIBUTION: &str = "SELECT kind, bin, op_start, op_end, summary \
     FROM distributions WHERE job_id = $1 AND metric = $2 AND op_end > $3 AND op_start < $4 ORDER BY bin";

/// The same bins' groups' accumulators.
pub(crate) const SELECT_DISTRIBUTION_GROUPS: &str = "SELECT groups FROM distributions \
     WHERE job_id = $1 AND metric = $2 AND op_end > $3 AND op_start < $4 ORDER BY bin";

/// Binds [`SELECT_DISTRIBUTION`]'s (or [`SELECT_DISTRIBUTION_GROUPS`]') parameters.
pub(crate) fn bind_bins(query: Sql, job: &JobId, metric: &str, range: Operations) -> Sql {
    query
        .bind(job.to_string())
        .bind(metric.to_owned())
        .bind(count_to_sql(range.start))
        .bind(count_to_sql(range.end))
}

/// A row's groups' accumulators; `None` for a row stored before they were kept.
pub(crate) fn groups_from_row(row: &AnyRow) -> StoreResult<Option<Vec<Accumulator>>> {
    row.maybe_bytes("groups")?
        .map(|stored| gunzip_json(GROUPS, &stored))
        .transpose()
}

/// Binds one `device_lives` row: `job_id, device, operations_to_failure, censored`.
pub(crate) fn bind_life(query: Sql, job: &JobId, life: &DeviceLife) -> Sql {
    query
        .bind(job.to_string())
        .bind(count_to_sql(life.device))
        .bind(count_to_sql(life.operations_to_failure))
        .bind(life.censored)
}

pub(crate) fn distribution_from_row(row: &AnyRow) -> StoreResult<DistributionRow> {
    Ok(DistributionRow {
        kind: row.text("kind")?,
        bin: row.int("bin")?,
        op_start: count_from_sql(row, "op_start")?,
        op_end: count_from_sql(row, "op_end")?,
        summary: serde_json::from_str(&row.text("summary")?).map_err(|e| corrupt("summary", e))?,
    })
}

pub(crate) fn life_from_row(row: &AnyRow) -> Result<DeviceLife, sqlx::Error> {
    Ok(DeviceLife {
        device: count_from_sql(row, "device")?,
        operations_to_failure: count_from_sql(row, "operations_to_failure")?,
        censored: row.flag("censored")?,
    })
}

// ---- schedules and their runs --------------------------------------------------------------

macro_rules! schedule_columns {
    () => {
        "id, owner, name, cron, time_zone, template, statistics, enabled, next_run_at, created_at, updated_at"
    };
}

pub(crate) use schedule_columns;

pub(crate) fn schedule_from_row(row: &AnyRow) -> StoreResult<ScheduleRecord> {
    Ok(ScheduleRecord {
        id: ScheduleId::from(row.text("id")?),
        owner: Owner::from_stored(row.text("owner")?),
        definition: ScheduleDefinition {
            name: row.text("name")?,
            cron: row.text("cron")?,
            time_zone: row.text("time_zone")?,
            template: spec_from_json(&row.text("template")?)?,
            statistics: serde_json::from_str(&row.text("statistics")?)
                .map_err(|e| corrupt("statistics", e))?,
            enabled: row.flag("enabled")?,
        },
        next_run_at: optional_ms(row, "next_run_at")?,
        created_at: ms(row, "created_at")?,
        updated_at: ms(row, "updated_at")?,
    })
}

/// Binds every column of [`schedule_columns`], in its order, as parameters 1 to 11.
pub(crate) fn bind_schedule(query: Sql, schedule: &ScheduleRecord) -> StoreResult<Sql> {
    let definition = &schedule.definition;
    Ok(query
        .bind(schedule.id.to_string())
        .bind(schedule.owner.as_str().to_owned())
        .bind(definition.name.clone())
        .bind(definition.cron.clone())
        .bind(definition.time_zone.clone())
        .bind(to_json("template", &definition.template)?)
        .bind(to_json("statistics", &definition.statistics)?)
        .bind(definition.enabled)
        .bind(schedule.next_run_at.map(|t| t.0))
        .bind(schedule.created_at.0)
        .bind(schedule.updated_at.0))
}

pub(crate) fn run_from_row(row: &AnyRow) -> Result<RunRecord, sqlx::Error> {
    Ok(RunRecord {
        scheduled_for: ms(row, "scheduled_for")?,
        job_id: JobId::from(row.text("job_id")?),
        manual: row.flag("manual")?,
        status: status(row)?,
    })
}
