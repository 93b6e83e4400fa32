//! What every backend shares: the column lists, the mapping of each table's row to its record (one
//! place per table, whatever the database), and how values are stored (counts, seeds, times, JSON).

use super::sql::{AnyRow, Sql, Tx};
use super::{
    Claim, DistributionRow, Fence, JobRecord, Operations, RunRecord, ScheduleRecord, ShardRecord,
    Skipped, StoreError, StoreResult,
};
use crate::domain::{
    Attempt, Folding, IdempotencyKey, JobId, JobStatus, Owner, QueuedJob, ScheduleDefinition,
    ScheduleId, ShardId, ShardPlan, UnixMs,
};
use bouncewear_model::montecarlo::engine::{self, GroupStats};
use bouncewear_model::montecarlo::{DeviceLife, JobResult, JobSpec, Metric, RunGroups};
use bouncewear_model::stats::Accumulator;
use sqlx::migrate::Migrator;
use std::sync::LazyLock;

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
/// migration applied): another version migrated it back, or it is another database; nor when it
/// is newer: a later build migrated it while this one ran, and may store what this one misreads.
pub(crate) fn schema_current(migrator: &Migrator, applied: Option<i64>) -> StoreResult<()> {
    let known = migrator.iter().map(|m| m.version).max().unwrap_or(0);
    let applied = applied.unwrap_or(0);
    if applied < known {
        return Err(StoreError::NotReady(format!(
            "the database's schema is at migration {applied}; this build needs {known}"
        )));
    }
    if applied > known {
        return Err(StoreError::NotReady(format!(
            "the database's schema is at migration {applied}, newer than this build's {known}: \
             a later build migrated it; run that one here too"
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
    /// Where one statement reads what others committed before it began (PostgreSQL): the lock
    /// on job `$1`'s row that a write of its progress takes first, so that the sum it writes
    /// reads every shard written before it (else a claim's or a heartbeat's sum, read before a
    /// group's completion committed, waited for that job's row and overwrote the larger sum:
    /// progress stepped back by a group).
    pub lock_job: Option<&'static str>,
    pub migrator: &'static LazyLock<Migrator>,
}

// ---- jobs ----------------------------------------------------------------------------------

/// A job's columns as read, with why its work waits while it does: the reason of a shard not done
/// that last waited ([`super::Store::wait_for`]), for room on the disk or for the database (kept
/// while it is claimed again and tries its write, until it is done).
macro_rules! job_columns {
    () => {
        "seq, id, owner, name, seed, status, operations_done, operations_total, error, \
         created_at, started_at, finished_at, stored_bytes, \
         CASE WHEN status = 'running' THEN (SELECT s.error FROM shards s \
         WHERE s.job_id = jobs.id AND s.status <> 'done' AND s.error LIKE 'waiting for %' \
         LIMIT 1) END AS waiting"
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
        waiting: row.maybe_text("waiting")?,
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
            let n = 1 + 4 * i;
            format!("(${n}, ${}, ${}, 'queued', ${})", n + 1, n + 2, n + 3)
        })
        .collect();
    let insert = format!(
        "INSERT INTO shards (job_id, batch, grp, status, operations_total) VALUES {}",
        rows.join(", ")
    );
    let insert = shards.iter().fold(Sql::in_order(insert), |insert, plan| {
        insert
            .bind(job.as_str())
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

/// A shard's history with the line of its attempt whose lease ran out appended.
macro_rules! history_lease_lost {
    () => {
        "history || 'attempt ' || attempt || ' (' || COALESCE(lease_owner, '?') || '): lease lost\n'"
    };
}

pub(crate) use history_lease_lost;

/// Leases the next shard (see [`super::Store::claim`]): the target picks the shard's row with the
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
             history = CASE WHEN status = 'running' THEN ",
            $crate::store::rows::history_lease_lost!(),
            " ELSE history END \
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

/// A claim, from the claimed shard's row (`job_id, batch, grp, attempt, operations_total`) and
/// its job's (`spec, started_at`), made at `claimed_at` on the database's clock.
pub(crate) fn claim_from_rows(
    shard: &AnyRow,
    job: &AnyRow,
    claimed_at: UnixMs,
) -> StoreResult<Claim> {
    Ok(Claim {
        fence: Fence {
            job: JobId::from(shard.text("job_id")?),
            shard: shard_id_from_row(shard)?,
            attempt: Attempt(shard.int("attempt")?),
        },
        spec: spec_from_json(&job.text("spec")?)?,
        operations_total: count_from_sql(shard, "operations_total")?,
        started_at: ms(job, "started_at")?,
        claimed_at,
    })
}

/// A done group's accumulators as stored ([`encode`]).
pub(crate) fn partial_to_sql(stats: &GroupStats) -> StoreResult<Vec<u8>> {
    encode("group accumulators", stats)
}

/// A precision target's folded groups ([`crate::domain::shards::Merged::Next`]) as stored, encoded on the
/// compute pool in parallel, each group dropped once encoded: never held both decoded and encoded.
pub struct EncodedGroups(pub(crate) Vec<Vec<u8>>);

impl EncodedGroups {
    pub fn new(groups: Vec<GroupStats>) -> StoreResult<Self> {
        use rayon::prelude::*;
        let groups = groups.into_par_iter().map(|group| partial_to_sql(&group));
        Ok(Self(groups.collect::<StoreResult<_>>()?))
    }

    /// How many groups.
    pub fn len(&self) -> usize {
        self.0.len()
    }

    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }
}

/// The query that lists a job's done groups' accumulators up to batch `$2`, in batch and group
/// order, as rows `batch, grp, stored` (for [`collect_partials`]); `stored` is NULL for a group
/// of batch `$2` that the merge holds: `$3` has a `1` at its place ([`held_mask`]).
pub(crate) const SELECT_PARTIALS: &str = "SELECT batch, grp, \
     CASE WHEN batch = $2 AND substr($3, CAST(grp AS INTEGER) + 1, 1) = '1' THEN NULL \
     ELSE partial END AS stored FROM shards \
     WHERE job_id = $1 AND batch <= $2 AND grp >= 0 AND status = 'done' AND partial IS NOT NULL \
     ORDER BY batch, grp";

/// The bytes of job `$1`'s groups' accumulators in its shards, for its stored bytes.
macro_rules! partial_bytes {
    () => {
        "(SELECT COALESCE(SUM(octet_length(partial)), 0) FROM shards WHERE job_id = $1)"
    };
}
pub(crate) use partial_bytes;

/// The groups `into` holds as [`SELECT_PARTIALS`] takes them: `1` at each held group's place
/// (its index from 0) up to the last held, `0` elsewhere. A batch has at most
/// [`engine::GROUPS`] groups.
pub(crate) fn held_mask(into: &Folding) -> String {
    let held: Vec<u64> = into.held().collect();
    let mask: String = (0..engine::GROUPS)
        .map(|group| if held.contains(&group) { '1' } else { '0' })
        .collect();
    mask.trim_end_matches('0').to_owned()
}

/// Stored bytes of done groups a merge reads before it decodes them, off the async threads, in
/// one go: a hop to the blocking pool and back for each group cost more than decoding it (a
/// 10^7-operation job's 32 groups, 2.4 MB: the merge's read 18-26 ms that way, 13-15 ms in one
/// go, on a 2-core VM whose idle vCPUs are slow to wake).
const PARTIAL_BYTES_PER_DECODE: usize = 8 << 20;

/// The done groups' accumulators from [`SELECT_PARTIALS`]' rows as they stream in, into `into`
/// ([`fold_stored`]).
pub(crate) async fn collect_partials(
    rows: impl futures_util::Stream<Item = Result<AnyRow, sqlx::Error>>,
    into: Folding,
) -> StoreResult<Folding> {
    use futures_util::TryStreamExt;
    let stored = rows
        .map_err(StoreError::from)
        .and_then(|row| async move { Ok((shard_id_from_row(&row)?, row.maybe_bytes("stored")?)) });
    fold_stored(stored, into, PARTIAL_BYTES_PER_DECODE).await
}

/// A group as [`SELECT_PARTIALS`] lists it: its stored bytes, or none for a group held.
type Listed = (ShardId, Option<Vec<u8>>);

/// Reads stored groups until `budget` bytes (or the last), then decodes and folds them into
/// `into` in order, off the async threads, and drops them: a merge holds one batch's groups
/// decoded and at most `budget` stored bytes (or one group's) beside them. A group listed
/// without its bytes is one `into` holds.
async fn fold_stored(
    stored: impl futures_util::Stream<Item = StoreResult<Listed>>,
    mut into: Folding,
    budget: usize,
) -> StoreResult<Folding> {
    use futures_util::TryStreamExt;
    let mut stored = std::pin::pin!(stored);
    let mut read: Vec<Listed> = Vec::new();
    let mut bytes = 0;
    loop {
        let next = stored.try_next().await?;
        let last = next.is_none();
        if let Some((shard, group)) = next {
            bytes += group.as_ref().map_or(0, Vec::len);
            read.push((shard, group));
        }
        if !read.is_empty() && (last || bytes >= budget) {
            let decoding = std::mem::take(&mut read);
            bytes = 0;
            into = off_async_threads("group accumulators", true, move || {
                for (shard, group) in decoding {
                    match group {
                        Some(group) => into.push(shard, decode("group accumulators", &group)?),
                        None => into.push_held(shard),
                    }
                }
                Ok(into)
            })
            .await?;
        }
        if last {
            return Ok(into);
        }
    }
}

/// The first bytes of accumulators as stored since the binary format: [`encode`].
const BINARY: &[u8; 4] = b"BWP1";
/// The first bytes of a gzip stream: accumulators stored before, as gzipped JSON.
const GZIP: &[u8; 2] = &[0x1f, 0x8b];
/// LZ4 expands no input more than 255-fold: a stated size beyond that is a corrupt header, refused
/// before it is allocated.
const LZ4_MAX_RATIO: usize = 255;

/// Accumulators as stored: `BINARY`, then their postcard encoding (serde's own shape of them,
/// every float its eight bytes, so exact, counts as varints) LZ4-compressed, its length first.
/// Against the gzipped JSON of before (every float its bits in decimal, written through deflate):
/// a 100 x 100 job's 115 rows took 12 ms of the server's 50 ms of CPU to encode that way, and
/// 2.9 MB of JSON became 65 kB; the same groups are 1.1 MB as postcard and 14 kB stored.
pub fn encode(what: &'static str, value: &impl serde::Serialize) -> StoreResult<Vec<u8>> {
    let plain = postcard::to_stdvec(value).map_err(|e| corrupt(what, e))?;
    if u32::try_from(plain.len()).is_err() {
        return Err(corrupt(
            what,
            format!("{} bytes, beyond 4 GiB", plain.len()),
        ));
    }
    let compressed = lz4_flex::block::compress_prepend_size(&plain);
    let mut stored = Vec::with_capacity(BINARY.len() + compressed.len());
    stored.extend_from_slice(BINARY);
    stored.extend_from_slice(&compressed);
    Ok(stored)
}

/// The inverse of [`encode`]; reads the gzipped JSON of rows stored before it as well.
pub(crate) fn decode<T: serde::de::DeserializeOwned>(
    what: &'static str,
    stored: &[u8],
) -> StoreResult<T> {
    if let Some(body) = stored.strip_prefix(BINARY) {
        let (size, compressed) =
            lz4_flex::block::uncompressed_size(body).map_err(|e| corrupt(what, e))?;
        if size > compressed.len().saturating_mul(LZ4_MAX_RATIO) {
            return Err(corrupt(
                what,
                format!("{size} bytes from {}", compressed.len()),
            ));
        }
        let mut plain = vec![0; size];
        let written = lz4_flex::block::decompress_into(compressed, &mut plain)
            .map_err(|e| corrupt(what, e))?;
        if written != size {
            return Err(corrupt(what, format!("{written} bytes of {size}")));
        }
        match postcard::take_from_bytes(&plain).map_err(|e| corrupt(what, e))? {
            (value, []) => Ok(value),
            (_, rest) => Err(corrupt(what, format!("{} bytes left over", rest.len()))),
        }
    } else if stored.starts_with(GZIP) {
        gunzip_json(what, stored)
    } else {
        Err(corrupt(what, "neither the binary format nor gzipped JSON"))
    }
}

/// Gzipped JSON, as accumulators were stored before [`encode`]: decompressed whole, then parsed
/// from the slice.
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

/// Distribution rows a result writes per transaction: about 2 kB each.
pub(crate) const DISTRIBUTIONS_PER_WRITE: usize = 250;
/// Device lives a result writes per transaction.
pub(crate) const LIVES_PER_WRITE: usize = 5_000;
/// What a device life counts towards a job's stored bytes: its three numbers.
pub(crate) const LIFE_ROW_BYTES: u64 = 24;

/// A Result as the store writes it, encoded before the first write: one `distributions` row per
/// bin of every operation metric and one per device metric (each with its summary's JSON and its
/// groups' accumulators [`encode`]d), the Result's JSON without those summaries (its
/// `operations` and `devices` empty: each summary is stored once, in its row, and
/// `result_from_row` puts them back), and the listed devices' lives. Made on the compute pool,
/// the rows in parallel ([`EncodedResult::new`]), so that the database's transactions bind bytes
/// and no async thread serialises.
pub struct EncodedResult {
    pub(crate) text: String,
    pub(crate) rows: Vec<EncodedRow>,
    pub(crate) lives: Vec<DeviceLife>,
    /// Whether the rows leave the groups' accumulators where the job's groups' shards stored
    /// them ([`EncodedResult::with_groups_in_shards`]): its shards' keep them.
    pub(crate) groups_in_shards: bool,
}

/// Rows [`EncodedResult::new`] encodes at a time, in parallel: the most bins' groups out of the
/// run's and not yet dropped.
const ROWS_PER_ENCODING: usize = 256;

/// The thread that encodes half of a Result's rows beside a compute pool of one thread
/// ([`EncodedResult::new`]): one for the process, kept, so that its allocations reuse its pages.
/// `None` if the system gave no thread: the compute thread encodes every row then.
static ENCODING: LazyLock<Option<rayon::ThreadPool>> = LazyLock::new(|| {
    rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .thread_name(|_| "bouncewear-encode".to_owned())
        // A panic drops the job's sender: its caller reads an error, the process goes on.
        .panic_handler(|_| ())
        .build()
        .ok()
});

/// One `distributions` row, ready to bind ([`insert_distributions`]).
pub(crate) struct EncodedRow {
    metric: String,
    kind: &'static str,
    bin: i64,
    op_start: u64,
    op_end: u64,
    n: u64,
    columns: [f64; 7],
    exceedance: Option<f64>,
    summary: String,
    /// Its groups' accumulators, [`encode`]d; none where they stay in the job's shards.
    groups: Option<Vec<u8>>,
}

impl EncodedRow {
    /// A row of `groups` bytes of groups and nothing else, for tests of how rows are written.
    #[cfg(test)]
    pub(crate) fn of_bytes(groups: usize) -> Self {
        Self {
            metric: "kappa".to_owned(),
            kind: "operation",
            bin: 0,
            op_start: 0,
            op_end: 1,
            n: 0,
            columns: [0.0; 7],
            exceedance: None,
            summary: String::new(),
            groups: Some(vec![0; groups]),
        }
    }

    /// The row of `metric`'s bin `bin` of `result` (bin 0 of a device metric), with its groups
    /// [`encode`]d, or none where they stay in the job's shards.
    fn new(
        result: &JobResult,
        metric: Metric,
        bin: u64,
        groups: Option<Vec<u8>>,
    ) -> StoreResult<Self> {
        let name = metric.name();
        let missing = || corrupt(GROUPS, format!("the Result has no {name} bin {bin}"));
        let (kind, op_start, op_end, summary) = match metric {
            Metric::Operation(_) => {
                let at = usize::try_from(bin).ok();
                let of_bin = result
                    .operations
                    .get(name)
                    .zip(at)
                    .and_then(|(bins, at)| bins.get(at));
                let of_bin = of_bin.ok_or_else(missing)?;
                ("operation", of_bin.op_start, of_bin.op_end, &of_bin.summary)
            }
            Metric::Device(_) => {
                let summary = result.devices.get(name).ok_or_else(missing)?;
                ("device", 0, result.job.spec().operations, summary)
            }
        };
        let quantile = |key: &str| summary.quantiles.get(key).map_or(0.0, |q| q.value);
        Ok(Self {
            metric: name.to_owned(),
            kind,
            bin: count_to_sql(bin),
            op_start,
            op_end,
            n: summary.n,
            columns: [
                summary.mean,
                summary.sd,
                summary.min,
                summary.max,
                quantile("p05"),
                quantile("p50"),
                quantile("p95"),
            ],
            exceedance: summary.exceedance.as_ref().map(|e| e.probability),
            summary: to_json("summary", summary)?,
            groups,
        })
    }
}

impl EncodedResult {
    /// Encodes `result` and the final `groups` of each of its (metric, bin), `ROWS_PER_ENCODING`
    /// rows at a time in parallel on the current rayon pool, each bin's groups dropped once
    /// encoded: the groups are never held both decoded and encoded. On a pool of one thread (a
    /// worker's `--compute-threads 1`) a second thread encodes the groups of half of each chunk,
    /// as a group's store encodes beside the compute thread: the scale-out job's 115 rows took
    /// 6.6-6.9 ms on one thread, 3.5-3.8 on two. `result` is as it was after.
    pub fn new(result: &mut JobResult, groups: RunGroups) -> StoreResult<Self> {
        Self::encode(result, groups, false)
    }

    /// As [`EncodedResult::new`], with rows that leave the groups' accumulators where the job's
    /// groups' shards stored them, for a query after the run to read there: the merge of a job
    /// of one batch, whose final groups are those ([`crate::domain::groups_stay_in_shards`]),
    /// neither encodes nor writes them a second time.
    pub fn with_groups_in_shards(result: &mut JobResult, groups: RunGroups) -> StoreResult<Self> {
        Self::encode(result, groups, true)
    }

    fn encode(result: &mut JobResult, groups: RunGroups, in_shards: bool) -> StoreResult<Self> {
        let shared = &*result;
        let mut bins = groups.into_bins().peekable();
        let mut rows = Vec::new();
        if in_shards {
            for (metric, bin, _) in bins.by_ref() {
                rows.push(EncodedRow::new(shared, metric, bin, None)?);
            }
        }
        while bins.peek().is_some() {
            let mut chunk: Vec<_> = bins.by_ref().take(ROWS_PER_ENCODING).collect();
            let alone = rayon::current_num_threads() == 1 && chunk.len() > 1;
            let Some(pool) = alone.then(|| ENCODING.as_ref()).flatten() else {
                rows.extend(encode_rows(shared, chunk)?);
                continue;
            };
            // The second half's groups encoded on the encoding thread, waited for on a channel:
            // a rayon scope would have this thread run other compute jobs while it waits.
            let second = chunk.split_off(chunk.len() / 2);
            let (sender, receiver) = std::sync::mpsc::sync_channel(1);
            pool.spawn(move || {
                let encoded: StoreResult<Vec<_>> = second
                    .into_iter()
                    .map(|(metric, bin, groups)| Ok((metric, bin, encode(GROUPS, &groups)?)))
                    .collect();
                let _ = sender.send(encoded);
            });
            rows.extend(encode_rows(shared, chunk)?);
            let beside = receiver.recv().map_err(|_| {
                corrupt(
                    GROUPS,
                    "the encoding thread stopped before its rows were done",
                )
            })??;
            for (metric, bin, groups) in beside {
                rows.push(EncodedRow::new(shared, metric, bin, Some(groups))?);
            }
        }
        let operations = std::mem::take(&mut result.operations);
        let devices = std::mem::take(&mut result.devices);
        let text = to_json("result", &*result);
        (result.operations, result.devices) = (operations, devices);
        let text = text?;
        let summaries =
            result.operations.values().map(Vec::len).sum::<usize>() + result.devices.len();
        if rows.len() != summaries {
            let detail = format!("{} bins' groups for {summaries} summaries", rows.len());
            return Err(corrupt(GROUPS, detail));
        }
        let lives = result
            .life
            .as_ref()
            .map_or_else(Vec::new, |life| life.devices.clone());
        Ok(Self {
            text,
            rows,
            lives,
            groups_in_shards: in_shards,
        })
    }

    /// What the result counts towards its job's stored bytes ([`super::JobRecord::stored_bytes`]):
    /// its JSON without the summaries, each row's summary and groups, each life's numbers.
    pub fn bytes(&self) -> u64 {
        let rows: usize = self
            .rows
            .iter()
            .map(|r| r.summary.len() + r.groups.as_ref().map_or(0, Vec::len))
            .sum();
        (self.text.len() + rows) as u64 + self.lives.len() as u64 * LIFE_ROW_BYTES
    }
}

/// The rows of `bins`, in order, in parallel on the current rayon pool.
fn encode_rows(
    result: &JobResult,
    bins: Vec<(Metric, u64, Vec<Accumulator>)>,
) -> StoreResult<Vec<EncodedRow>> {
    use rayon::prelude::*;
    bins.into_par_iter()
        .map(|(metric, bin, groups)| {
            let groups = encode(GROUPS, &groups)?;
            EncodedRow::new(result, metric, bin, Some(groups))
        })
        .collect()
}

/// `count` rows of `width` parameters each, in order: `($1, .., $w), ($w+1, ..)`.
fn rows_of_parameters(count: usize, width: usize) -> String {
    (0..count)
        .map(|row| {
            let first = 1 + row * width;
            let parameters: Vec<String> = (first..first + width).map(|n| format!("${n}")).collect();
            format!("({})", parameters.join(", "))
        })
        .collect::<Vec<_>>()
        .join(", ")
}

/// Rows one `INSERT` takes: a small job's 115 in one round trip to the database's thread, a large
/// job's in statements of a few thousand parameters (SQLite takes 32,766, PostgreSQL 65,535). Its
/// placeholders go in order ([`Sql::in_order`]): with the job's `$1` shared by every row, SQLite
/// found each parameter by a scan of the statement's names, and 16 rows a statement were the most
/// that kept that small.
const DISTRIBUTIONS_PER_STATEMENT: usize = 128;

/// Inserts a transaction's `distributions` rows, [`DISTRIBUTIONS_PER_STATEMENT`] a statement
/// (rather than one round trip to the database per row; a merge step that reruns writes the same
/// rows again: kept).
pub(crate) async fn insert_distributions(
    tx: &mut Tx,
    job: &JobId,
    rows: &[EncodedRow],
) -> StoreResult<()> {
    let into = "distributions (job_id, metric, kind, bin, op_start, op_end, n, mean, sd, min, max, \
                p05, p50, p95, exceedance, summary, groups, groups_in_shards)";
    insert_rows(
        tx,
        job,
        into,
        (17, DISTRIBUTIONS_PER_STATEMENT),
        rows,
        |insert, row| {
            let [mean, sd, min, max, p05, p50, p95] = row.columns;
            insert
                .bind(row.metric.as_str())
                .bind(row.kind)
                .bind(row.bin)
                .bind(count_to_sql(row.op_start))
                .bind(count_to_sql(row.op_end))
                .bind(count_to_sql(row.n))
                .bind(mean)
                .bind(sd)
                .bind(min)
                .bind(max)
                .bind(p05)
                .bind(p50)
                .bind(p95)
                .bind(row.exceedance)
                .bind(row.summary.as_str())
                .bind(row.groups.clone())
                .bind(row.groups.is_none())
        },
    )
    .await
}

/// Device lives one statement inserts: 4 parameters each (see [`DISTRIBUTIONS_PER_STATEMENT`]).
const LIVES_PER_STATEMENT: usize = 1000;

/// Inserts a transaction's `device_lives` rows, [`LIVES_PER_STATEMENT`] a statement.
pub(crate) async fn insert_lives(
    tx: &mut Tx,
    job: &JobId,
    lives: &[DeviceLife],
) -> StoreResult<()> {
    let into = "device_lives (job_id, device, operations_to_failure, censored)";
    insert_rows(
        tx,
        job,
        into,
        (3, LIVES_PER_STATEMENT),
        lives,
        |insert, life| {
            insert
                .bind(count_to_sql(life.device))
                .bind(count_to_sql(life.operations_to_failure))
                .bind(life.censored)
        },
    )
    .await
}

/// Inserts `rows` into `into` (a table and its columns, `job_id` first), `per_statement` rows a
/// statement, each row's job and then its `width` parameters bound by `bind`; a row already there
/// is kept.
async fn insert_rows<T>(
    tx: &mut Tx,
    job: &JobId,
    into: &str,
    (width, per_statement): (usize, usize),
    rows: &[T],
    bind: impl Fn(Sql, &T) -> Sql,
) -> StoreResult<()> {
    for chunk in rows.chunks(per_statement) {
        let insert = format!(
            "INSERT INTO {into} VALUES {} ON CONFLICT DO NOTHING",
            rows_of_parameters(chunk.len(), 1 + width)
        );
        let insert = chunk.iter().fold(Sql::in_order(insert), |insert, row| {
            bind(insert.bind(job.as_str()), row)
        });
        insert.execute(&mut *tx).await?;
    }
    Ok(())
}

pub(crate) const GROUPS: &str = "groups of a distribution";

/// The bins of metric `$2` of job `$1` overlapping `[$3, $4)`, in bin order: their summaries.
pub(crate) const SELECT_DISTRIBUTION: &str = "SELECT kind, bin, op_start, op_end, summary \
     FROM distributions WHERE job_id = $1 AND metric = $2 AND op_end > $3 AND op_start < $4 ORDER BY bin";

/// The same bins' groups' accumulators, or whether they are in the job's shards.
pub(crate) const SELECT_DISTRIBUTION_GROUPS: &str = "SELECT bin, groups, groups_in_shards \
     FROM distributions \
     WHERE job_id = $1 AND metric = $2 AND op_end > $3 AND op_start < $4 ORDER BY bin";

/// The groups' accumulators of job `$1` as its first batch's groups' shards stored them, in
/// group order: where a Result of one batch leaves them ([`EncodedResult::with_groups_in_shards`]).
pub(crate) const SELECT_GROUPS_IN_SHARDS: &str = "SELECT partial FROM shards \
     WHERE job_id = $1 AND batch = 0 AND grp >= 0 AND status = 'done' AND partial IS NOT NULL \
     ORDER BY grp";

/// Binds [`SELECT_DISTRIBUTION`]'s (or [`SELECT_DISTRIBUTION_GROUPS`]') parameters.
pub(crate) fn bind_bins(query: Sql, job: &JobId, metric: &str, range: Operations) -> Sql {
    query
        .bind(job.to_string())
        .bind(metric.to_owned())
        .bind(count_to_sql(range.start))
        .bind(count_to_sql(range.end))
}

/// The members of a Result stored apart, each as `{}` in its JSON ([`EncodedResult`]), with the
/// kind of the `distributions` rows that hold them: `devices` first, since it follows
/// `operations`, so that looking for it never scans `operations` put back. A Result stored whole
/// (before summaries were stored once) has neither empty, but a job's without device metrics,
/// whose rows are none: [`member_json`] gives it `{}` again (its rows are read for nothing).
pub(crate) const STORED_APART: [(&str, &str); 2] =
    [("devices", "device"), ("operations", "operation")];

/// One summary row as [`member_json`] reads it: metric, bin, first and end operation, summary.
pub(crate) type SummaryRow<'a> = (&'a str, i64, u64, u64, &'a str);

/// Job `$1`'s stored Result and the summary rows of it that `$rows` admits, the row's columns
/// joined by tabs and the rows by newlines (neither is ever raw in compact JSON nor in a metric's
/// name), in no particular order: one statement, so one snapshot of the database (a job deleted
/// meanwhile is wholly there or wholly gone), and one value to read however many rows.
macro_rules! select_result {
    ($rows:literal) => {
        concat!(
            "SELECT result, (SELECT string_agg(kind || '\t' || metric || '\t' || bin || '\t' \
             || op_start || '\t' || op_end || '\t' || summary, '\n') FROM distributions d \
             WHERE d.job_id = r.job_id",
            $rows,
            ") AS summaries FROM results r WHERE r.job_id = $1"
        )
    };
}

/// [`select_result!`] with every summary row: the whole Result.
pub(crate) const SELECT_RESULT: &str = select_result!("");

/// [`select_result!`] with the device metrics' rows and each operation metric's last bin alone:
/// what a schedule's trend reads of a run, a few rows where the whole Result can have 18,000.
/// The last bins are found once, by a subquery of the job's id alone: correlated with the row
/// (`e.job_id = r.job_id`), SQLite 3.51 ran it again for each of a 1000-bin job's 11,005 rows,
/// 12.7 s a run (a grouped subquery) and about as long as a subquery per row; uncorrelated 18 ms,
/// and 6 ms on PostgreSQL (a probe).
pub(crate) const SELECT_RESULT_ENDS: &str = select_result!(
    " AND (d.kind = 'device' OR (d.metric, d.bin) IN (SELECT e.metric, MAX(e.bin) \
     FROM distributions e WHERE e.job_id = $1 GROUP BY e.metric))"
);

/// Bytes of a stored Result from which it is put back together or parsed off the async threads
/// ([`off_async_threads`]): a 1000-bin job's 15.7 MB took several milliseconds of a thread that
/// answers requests to put together, tens to parse; a small job's 106 kB is quicker than a hop to
/// the blocking pool and back.
pub(crate) const LARGE_RESULT_BYTES: usize = 1 << 20;

/// `work` on what was stored (`what`, for the error should the work panic): on the blocking pool
/// when it is `large`, else here.
pub(crate) async fn off_async_threads<T: Send + 'static>(
    what: &'static str,
    large: bool,
    work: impl FnOnce() -> StoreResult<T> + Send + 'static,
) -> StoreResult<T> {
    if !large {
        return work();
    }
    tokio::task::spawn_blocking(work)
        .await
        .map_err(|e| corrupt(what, e))?
}

/// The Result's JSON from [`SELECT_RESULT`]'s row, its summaries put back ([`result_from_parts`]).
pub(crate) async fn result_from_row(row: AnyRow) -> StoreResult<String> {
    let text = row.text("result")?;
    let joined = row.maybe_text("summaries")?.unwrap_or_default();
    drop(row);
    let large = text.len() + joined.len() >= LARGE_RESULT_BYTES;
    off_async_threads("result", large, move || result_from_parts(text, &joined)).await
}

/// A stored Result's JSON (`text`) with its summary rows (`joined`, as [`SELECT_RESULT`] joins
/// them) put back.
fn result_from_parts(text: String, joined: &str) -> StoreResult<String> {
    let mut summaries: [Vec<SummaryRow>; 2] = Default::default();
    for line in joined.split('\n').filter(|line| !line.is_empty()) {
        let bad = || corrupt("summary", format!("a row read as {:.80}", line));
        let columns: Vec<&str> = line.splitn(6, '\t').collect();
        let &[kind, metric, bin, op_start, op_end, summary] = columns.as_slice() else {
            return Err(bad());
        };
        let at = STORED_APART.iter().position(|(_, apart)| *apart == kind);
        let at = at.ok_or_else(bad)?;
        let number = |text: &str| text.parse::<i64>().map_err(|_| bad());
        summaries[at].push((
            metric,
            number(bin)?,
            number(op_start)?.max(0) as u64,
            number(op_end)?.max(0) as u64,
            summary,
        ));
    }
    put_back(text, summaries)
}

/// `text`, a stored Result, with each member stored apart put back from its rows (`summaries`
/// in [`STORED_APART`]'s order). Each in one copy: `String::replace_range` moved a long member
/// in byte by byte, a fifth of a large Result's read.
fn put_back(mut text: String, summaries: [Vec<SummaryRow>; 2]) -> StoreResult<String> {
    for ((key, kind), rows) in STORED_APART.into_iter().zip(summaries) {
        if let Some(at) = empty_member(&text, key) {
            let member = member_json(kind, rows)?;
            text = [&text[..at.start], &member, &text[at.end..]].concat();
        }
    }
    Ok(text)
}

/// The JSON of a Result's member of `kind` from its rows, to the byte what `serde_json` writes
/// for the Result: its metrics in key order; a device metric's summary; an operation metric's
/// bins in order, each its summary's members followed by `op_start` and `op_end` (`Bin`'s
/// flattened summary).
fn member_json(kind: &str, mut rows: Vec<SummaryRow>) -> StoreResult<String> {
    use std::fmt::Write;
    rows.sort_unstable_by(|a, b| (a.0, a.1).cmp(&(b.0, b.1)));
    let mut member = String::with_capacity(rows.iter().map(|row| row.4.len() + 48).sum());
    member.push('{');
    for (m, bins) in rows.chunk_by(|a, b| a.0 == b.0).enumerate() {
        if m > 0 {
            member.push(',');
        }
        member.push_str(&to_json("metric name", &bins[0].0)?);
        member.push(':');
        if kind == "device" {
            member.push_str(bins[0].4);
            continue;
        }
        member.push('[');
        for (b, (metric, _, op_start, op_end, summary)) in bins.iter().enumerate() {
            let members = summary
                .strip_suffix('}')
                .ok_or_else(|| corrupt("summary", format!("{metric}'s is not an object")))?;
            if b > 0 {
                member.push(',');
            }
            member.push_str(members);
            // Writing to a String cannot fail.
            let _ = write!(member, r#","op_start":{op_start},"op_end":{op_end}}}"#);
        }
        member.push(']');
    }
    member.push('}');
    Ok(member)
}

/// Where the top-level member `key` of the JSON object `text` (compact, as `serde_json` writes
/// it) is `{}`: those two bytes. Strings are skipped whole, so a key inside one never matches;
/// the scan stops at the member, which a skeleton has early (after `job`).
fn empty_member(text: &str, key: &str) -> Option<std::ops::Range<usize>> {
    let bytes = text.as_bytes();
    let (mut depth, mut i) = (0_usize, 0);
    while i < bytes.len() {
        match bytes[i] {
            b'"' => {
                let start = i + 1;
                i += 1;
                while i < bytes.len() && bytes[i] != b'"' {
                    i += if bytes[i] == b'\\' { 2 } else { 1 };
                }
                let end = i.min(bytes.len());
                let after = end + 1;
                if depth == 1 && text.get(after..after + 1) == Some(":") && &text[start..end] == key
                {
                    // The member, empty or not: nothing after it can be it.
                    let empty = text.get(after + 1..after + 3) == Some("{}");
                    return empty.then_some(after + 1..after + 3);
                }
            }
            b'{' | b'[' => depth += 1,
            b'}' | b']' => depth = depth.saturating_sub(1),
            _ => {}
        }
        i += 1;
    }
    None
}

/// A row's groups' accumulators; `None` for a row stored before they were kept.
pub(crate) fn groups_from_row(row: &AnyRow) -> StoreResult<Option<Vec<Accumulator>>> {
    row.maybe_bytes("groups")?
        .map(|stored| decode(GROUPS, &stored))
        .transpose()
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

/// A schedule's columns as read: [`schedule_columns`], the runs it skipped, which only the
/// scheduler writes, and its revision, which the store counts.
macro_rules! schedule_read_columns {
    () => {
        concat!(
            $crate::store::rows::schedule_columns!(),
            ", skipped_runs, last_skipped_for, last_skip_reason, revision"
        )
    };
}

pub(crate) use schedule_read_columns;

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
        skipped: Skipped {
            runs: count_from_sql(row, "skipped_runs")?,
            last: match optional_ms(row, "last_skipped_for")? {
                Some(due) => Some((due, row.text("last_skip_reason")?)),
                None => None,
            },
        },
        revision: count_from_sql(row, "revision")?,
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

#[cfg(test)]
mod tests {
    use super::*;
    use bouncewear_model::Pointer;
    use bouncewear_model::montecarlo::engine::{Batch, run_group};
    use bouncewear_model::montecarlo::{Job, Silent};
    use bouncewear_model::stats::Threshold;

    /// Accumulators over hard values: signed zeros, a subnormal, the extremes of the doubles.
    fn accumulators() -> Vec<Accumulator> {
        let values = [0.0, -0.0, 5e-324, 1e-300, 2.5e-3, 1.0, 1e300, -7.25, 3.0e-3];
        (0..4)
            .map(|group| {
                let mut accumulator = Accumulator::new((group % 2 == 0).then_some(2.0e-3))
                    .keeping((group < 3).then_some(3))
                    .counting(&[Threshold::Above(2.6e-3), Threshold::Below(-1.0)]);
                values
                    .iter()
                    .cycle()
                    .skip(group)
                    .take(40 * group)
                    .for_each(|&x| accumulator.push(x));
                accumulator
            })
            .collect()
    }

    /// The JSON of a value: every float by its bits, so equal JSON is equal to the bit.
    fn json(value: &impl serde::Serialize) -> String {
        serde_json::to_string(value).unwrap()
    }

    /// As accumulators were stored before [`encode`].
    fn gzip_json(value: &impl serde::Serialize) -> Vec<u8> {
        let mut encoder = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
        serde_json::to_writer(&mut encoder, value).unwrap();
        encoder.finish().unwrap()
    }

    #[test]
    fn accumulators_come_back_to_the_bit() {
        let accumulators = accumulators();
        let stored = encode("test", &accumulators).unwrap();
        assert!(stored.starts_with(BINARY));
        let back: Vec<Accumulator> = decode("test", &stored).unwrap();
        assert_eq!(back, accumulators);
        assert_eq!(json(&back), json(&accumulators));
    }

    #[test]
    fn a_groups_stats_come_back_to_the_bit_smaller_than_gzipped_json() {
        let spec = serde_json::from_str(
            r#"{"devices": 64, "operations": 50, "seed": 7, "bin_operations": 10,
                "scatter": [{"parameter": "impact_velocity_m_s", "per": "operation",
                    "distribution": {"kind": "triangular", "min": 0.15, "mode": 0.22, "max": 0.3}}],
                "limits": {"total_bounce_s": [{"above": 0.0145}]}}"#,
        )
        .unwrap();
        let job = Job::new(spec, || 0, &Pointer::root()).unwrap();
        let batch = Batch::of(&job, 0).unwrap();
        let stats = run_group(&job, batch, 1, &Silent).unwrap();
        let stored = partial_to_sql(&stats).unwrap();
        let back: GroupStats = decode("test", &stored).unwrap();
        assert_eq!(json(&back), json(&stats));
        let before = gzip_json(&stats).len();
        assert!(
            stored.len() < before,
            "{} bytes against {before}",
            stored.len()
        );
    }

    /// The groups of a precision target's first two batches, stored, in the order a merge reads
    /// them, with the job.
    fn two_batches_stored() -> (Job, Vec<Listed>) {
        let job = Job::from_json(
            r#"{"devices": 40, "operations": 3, "seed": 8, "bin_operations": 1,
                "scatter": [{"parameter": "impact_velocity_m_s", "per": "device",
                    "distribution": {"kind": "normal", "mean": 0.3, "sd": 0.05, "min": 0.05}}],
                "precision": {"metric": "e1", "relative_half_width": 1e-6, "max_devices": 100}}"#,
            || 0,
        )
        .unwrap();
        let stored = (0..2)
            .flat_map(|index| {
                let batch = Batch::of(&job, index).unwrap();
                let job = &job;
                (0..batch.groups()).map(move |group| {
                    let stats = run_group(job, batch, group, &Silent).unwrap();
                    (
                        ShardId::group(index, group),
                        Some(partial_to_sql(&stats).unwrap()),
                    )
                })
            })
            .collect();
        (job, stored)
    }

    /// Whatever the bytes decoded at a time, the same groups are folded in the same order: the
    /// same merge, to the bit.
    #[tokio::test]
    async fn groups_decoded_a_few_at_a_time_or_all_at_once_merge_the_same() {
        let (job, stored) = two_batches_stored();
        let group_bytes = stored[0].1.as_ref().unwrap().len();
        let mut merged = Vec::new();
        for budget in [1, 3 * group_bytes, usize::MAX] {
            let rows = futures_util::stream::iter(stored.clone().into_iter().map(Ok));
            let folded = fold_stored(rows, Folding::new(job.clone(), 1), budget)
                .await
                .unwrap();
            let read: Vec<ShardId> = stored.iter().map(|(shard, _)| *shard).collect();
            assert_eq!(folded.read(), read, "budget {budget}");
            let merge = crate::domain::shards::merge(folded, u64::MAX, 0.0, &Silent).unwrap();
            merged.push(format!("{merge:?}"));
        }
        assert!(merged.iter().all(|m| *m == merged[0]));
    }

    /// Groups of the last batch held by the merge, listed without their bytes, merge as the
    /// stored ones do, to the bit, whichever are held and whatever the bytes decoded at a time;
    /// a group listed without its bytes that is not held fails the merge.
    #[tokio::test]
    async fn groups_held_merge_as_the_stored_ones() {
        let (job, stored) = two_batches_stored();
        let merged = |folded: Folding| {
            let merge = crate::domain::shards::merge(folded, u64::MAX, 0.0, &Silent);
            format!("{merge:?}")
        };
        let rows = futures_util::stream::iter(stored.clone().into_iter().map(Ok));
        let read = fold_stored(rows, Folding::new(job.clone(), 1), usize::MAX);
        let expected = merged(read.await.unwrap());
        let last: Vec<usize> = (0..stored.len())
            .filter(|&i| stored[i].0.batch == 1)
            .collect();
        assert!(last.len() >= 2, "{} groups in the last batch", last.len());
        for (holds, budget) in [(&last[..1], 1), (&last[1..], usize::MAX), (&last[..], 1)] {
            let mut rows = stored.clone();
            let mut held = Vec::new();
            for &i in holds {
                rows[i].1 = None;
                let group = rows[i].0.group.unwrap();
                let batch = Batch::of(&job, 1).unwrap();
                held.push((group, run_group(&job, batch, group, &Silent).unwrap()));
            }
            let into = Folding::new(job.clone(), 1).holding(held);
            assert_eq!(
                held_mask(&into).chars().filter(|&c| c == '1').count(),
                holds.len()
            );
            let read = fold_stored(
                futures_util::stream::iter(rows.into_iter().map(Ok)),
                into,
                budget,
            );
            assert_eq!(merged(read.await.unwrap()), expected, "held {holds:?}");
        }
        let mut rows = stored.clone();
        rows[last[0]].1 = None;
        let read = fold_stored(
            futures_util::stream::iter(rows.into_iter().map(Ok)),
            Folding::new(job.clone(), 1),
            usize::MAX,
        );
        let merge = crate::domain::shards::merge(read.await.unwrap(), u64::MAX, 0.0, &Silent);
        assert!(
            matches!(
                &merge,
                Err(crate::domain::shards::MergeError::Incomplete(_))
            ),
            "{merge:?}"
        );
    }

    #[test]
    fn the_held_mask_marks_each_held_group_at_its_place() {
        let (job, stored) = two_batches_stored();
        let stats = |i: usize| decode::<GroupStats>("held", stored[i].1.as_ref().unwrap()).unwrap();
        assert_eq!(held_mask(&Folding::new(job.clone(), 1)), "");
        let into = Folding::new(job, 1).holding([(3, stats(0)), (0, stats(1))]);
        assert_eq!(held_mask(&into), "1001");
    }

    /// A group that does not decode fails the read, wherever it is among those decoded together.
    #[tokio::test]
    async fn a_corrupt_group_fails_the_read() {
        let (job, mut stored) = two_batches_stored();
        stored[2].1.as_mut().unwrap().truncate(10);
        for budget in [1, usize::MAX] {
            let rows = futures_util::stream::iter(stored.clone().into_iter().map(Ok));
            let read = fold_stored(rows, Folding::new(job.clone(), 1), budget).await;
            assert!(
                matches!(read, Err(StoreError::Corrupt { .. })),
                "budget {budget}: {read:?}"
            );
        }
    }

    /// A rare event's estimator is stored as the build before stored it: the sign its messages
    /// read the event by is not among its bytes (postcard reads fields by position, and a field
    /// added at its end left a stored round unreadable, found in review).
    #[test]
    fn a_stored_estimator_keeps_its_bytes_whatever_its_events_sign() {
        let spec = serde_json::from_str(
            r#"{"devices": 2, "operations": 1, "seed": 3, "metrics": ["e1"],
                "scatter": [{"parameter": "impact_velocity_m_s", "per": "device",
                             "distribution": {"kind": "normal", "mean": 0.224, "sd": 0.02, "min": 0}}],
                "rare_event": {"metric": "e1", "below": 0.43}}"#,
        )
        .unwrap();
        let job = Job::new(spec, || 0, &Pointer::root()).unwrap();
        let below = bouncewear_model::montecarlo::rare::start(&job).unwrap();
        let mut above = below.clone();
        above.read_as(1.0);
        assert_ne!(below, above);
        let stored = encode("round", &below).unwrap();
        assert_eq!(stored, encode("round", &above).unwrap());
        let back: bouncewear_model::montecarlo::rare::Estimator = decode("round", &stored).unwrap();
        assert_eq!(back, above);
    }

    #[test]
    fn gzipped_json_stored_before_still_reads() {
        let accumulators = accumulators();
        let back: Vec<Accumulator> = decode("test", &gzip_json(&accumulators)).unwrap();
        assert_eq!(json(&back), json(&accumulators));
    }

    #[test]
    fn corrupt_bytes_are_an_error_not_a_panic_nor_a_huge_allocation() {
        let stored = encode("test", &accumulators()).unwrap();
        let mut trailing = stored.clone();
        trailing.extend_from_slice(&[0; 3]);
        let mut huge = BINARY.to_vec();
        huge.extend_from_slice(&u32::MAX.to_le_bytes());
        huge.extend_from_slice(&[0x10, 0x00]);
        let mut garbled = stored.clone();
        let middle = garbled.len() / 2;
        garbled[middle..].iter_mut().for_each(|b| *b ^= 0x5a);
        let cases: Vec<(&str, Vec<u8>)> = vec![
            ("empty", vec![]),
            ("magic alone", BINARY.to_vec()),
            ("truncated", stored[..stored.len() - 5].to_vec()),
            ("trailing bytes", trailing),
            ("a size beyond what LZ4 can expand to", huge),
            ("garbled", garbled),
            ("neither format", b"{\"min\": 0}".to_vec()),
            ("gzip magic alone", GZIP.to_vec()),
        ];
        for (case, bytes) in cases {
            let decoded = decode::<Vec<Accumulator>>("test", &bytes);
            assert!(
                matches!(decoded, Err(StoreError::Corrupt { .. })),
                "{case}: {decoded:?}"
            );
        }
    }

    /// The Result as the store reads it back: its stored text, and its rows' summaries joined
    /// as [`SELECT_RESULT`] joins them, in no particular order (here the reverse).
    fn stored_and_put_back(encoded: &EncodedResult) -> String {
        for (key, _) in STORED_APART {
            let empty = empty_member(&encoded.text, key);
            assert!(empty.is_some(), "stored without {key}");
        }
        let joined: Vec<String> = (encoded.rows.iter().rev())
            .map(|r| {
                let (metric, summary) = (&r.metric, &r.summary);
                let (bin, op_start, op_end) = (r.bin, r.op_start, r.op_end);
                format!(
                    "{}\t{metric}\t{bin}\t{op_start}\t{op_end}\t{summary}",
                    r.kind
                )
            })
            .collect();
        result_from_parts(encoded.text.clone(), &joined.join("\n")).unwrap()
    }

    #[test]
    fn a_result_is_stored_without_its_summaries_and_put_back_to_the_byte() {
        use crate::domain::shards::{Merged, run_whole};
        use bouncewear_model::montecarlo::Tally;
        use std::time::Duration;
        // Device and operation metrics, listed thresholds, a life analysis, a name that holds
        // the members' keys, and a metric ordered differently by name than by the job.
        let jobs = [
            r#"{"devices": 12, "operations": 30, "seed": 4, "name": "\"operations\":{}",
                "scenario": {"circuit": {"supply_voltage_v": 48, "current_a": 15}},
                "limits": {"total_bounce_s": [{"above": 0.002}]},
                "failure": {"e1": {"below": 0.4}}}"#,
            r#"{"devices": 40, "operations": 7, "seed": 5, "metrics": ["total_bounce_s", "e1"]}"#,
        ];
        for text in jobs {
            let job = Job::new(serde_json::from_str(text).unwrap(), || 0, &Pointer::root())
                .unwrap()
                .with_listed_lives(100);
            let Merged::Result { mut result, groups } =
                run_whole(&job, Tally::new(), Duration::MAX, u64::MAX, 0.0, &Silent).unwrap()
            else {
                panic!("a job without a rare event ends in its Result");
            };
            let whole = serde_json::to_string(&result).unwrap();
            let encoded = EncodedResult::new(&mut result, groups).unwrap();
            assert_eq!(serde_json::to_string(&result).unwrap(), whole, "{text}");
            assert!(encoded.text.len() < whole.len() / 4, "{}", encoded.text);
            assert_eq!(stored_and_put_back(&encoded), whole, "{text}");
        }
    }

    /// A Result's rows are the same, in the same order, whether its compute pool has one thread
    /// (half of each chunk encoded beside it) or several, over more than one chunk.
    #[test]
    fn a_result_encodes_the_same_rows_on_one_thread_as_on_several() {
        use crate::domain::shards::{Merged, run_whole};
        use bouncewear_model::montecarlo::Tally;
        use std::time::Duration;
        // 30 bins of 11 operation metrics and 5 device metrics: 335 rows, two chunks.
        let text = r#"{"devices": 40, "operations": 30, "seed": 8, "bin_operations": 1}"#;
        let job = Job::new(serde_json::from_str(text).unwrap(), || 0, &Pointer::root())
            .unwrap()
            .with_listed_lives(100);
        let encoded_on = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| {
                let Merged::Result { mut result, groups } =
                    run_whole(&job, Tally::new(), Duration::MAX, u64::MAX, 0.0, &Silent).unwrap()
                else {
                    panic!("a job without a rare event ends in its Result");
                };
                // The run's own clock apart, the same Result.
                (result.timing.wall_s, result.timing.operations_per_s) = (1.0, 1.0);
                EncodedResult::new(&mut result, groups).unwrap()
            })
        };
        let rows = |encoded: &EncodedResult| -> Vec<_> {
            let row =
                |r: &EncodedRow| (r.metric.clone(), r.bin, r.summary.clone(), r.groups.clone());
            encoded.rows.iter().map(row).collect()
        };
        let (alone, beside) = (encoded_on(3), encoded_on(1));
        assert!(
            alone.rows.len() > ROWS_PER_ENCODING,
            "{} rows",
            alone.rows.len()
        );
        assert_eq!(rows(&beside), rows(&alone));
        assert_eq!(beside.text, alone.text);
    }

    #[test]
    fn only_a_top_level_member_is_found() {
        let text = r#"{"job":{"name":"\"devices\":{}","x":{"devices":{}}},"operations":{"a":[]},"devices":{},"t":1}"#;
        let at = text.find(r#""devices":{},"t""#).unwrap() + r#""devices":"#.len();
        assert_eq!(empty_member(text, "devices"), Some(at..at + 2));
        // Not empty: stored whole, nothing to put back, and the scan ends there.
        assert_eq!(empty_member(text, "operations"), None);
        assert_eq!(empty_member(text, "absent"), None);
        assert_eq!(empty_member(r#"{"devices""#, "devices"), None);
        assert_eq!(empty_member(r#"{"devices":{"#, "devices"), None);
        assert_eq!(empty_member(r#"{"a":"\"#, "devices"), None);
    }

    #[test]
    fn a_summary_that_is_not_an_object_is_corrupt_not_a_panic() {
        let rows = vec![("e1", 0, 0, 1, "[]")];
        assert!(matches!(
            member_json("operation", rows),
            Err(StoreError::Corrupt { .. })
        ));
        assert_eq!(member_json("device", vec![]).unwrap(), "{}");
    }

    #[test]
    fn ready_only_at_the_schema_this_build_knows() {
        let migrator = &*super::super::migrations::SQLITE;
        let known = migrator.iter().map(|m| m.version).max().unwrap();
        assert!(schema_current(migrator, Some(known)).is_ok());
        for applied in [None, Some(known - 1), Some(known + 1)] {
            let checked = schema_current(migrator, applied);
            assert!(
                matches!(checked, Err(StoreError::NotReady(_))),
                "{applied:?}: {checked:?}"
            );
        }
    }
}
