//! What a succeeded job leaves, written once for both databases: one row per (metric, bin) with
//! its summary and its groups' accumulators, its Result without those summaries (each is stored
//! once, and put back when the Result is read), and each listed device's life.

use super::backend::Store;
use super::queue::{done_over_shards, drop_partials};
use super::rows::{
    self, EncodedResult, SELECT_DISTRIBUTION, SELECT_DISTRIBUTION_GROUPS, SELECT_GROUPS_IN_SHARDS,
    SELECT_PARTIALS, SELECT_RESULT, SELECT_RESULT_ENDS, bind_bins, collect_partials,
    count_from_sql, count_to_sql, distribution_from_row, groups_from_row, held_mask,
    insert_distributions, insert_lives, life_from_row, result_from_row, spec_from_json,
};
use super::sql::Sql;
use super::{DistributionRow, Fence, Operations, StoreError, StoreResult};
use crate::domain::query::LARGE_DISTRIBUTION_BINS;
use crate::domain::rare::Rounds;
use crate::domain::{Folding, JobId, UnixMs};
use bouncewear_model::Pointer;
use bouncewear_model::montecarlo::engine::GroupStats;
use bouncewear_model::montecarlo::rare::Outcome;
use bouncewear_model::montecarlo::{DeviceLife, Job, JobResult, RunGroups};
use bouncewear_model::stats::Accumulator;

/// Transactions that write a large Result's rows side by side where the database runs writers
/// side by side (PostgreSQL; SQLite's one writer would take them in turn). Two took the merge's
/// write of the scale-out job's Result (115 rows, 2.5 MB of groups) from 56 to 38-39 ms, means
/// of two alternating series (24 and 12 merges each) on a 2-core VM (docs/performance.md).
const SIDE_BY_SIDE_WRITES: usize = 2;

/// The stored bytes from which a Result's rows are written side by side before the transaction
/// that ends the job, where the database takes writers so: below, the transactions of their own
/// cost more than they save.
const SIDE_BY_SIDE_BYTES: u64 = 256 << 10;

impl Store {
    /// Writes a result's distribution rows and listed device lives in short transactions of
    /// bounded size ([`rows::DISTRIBUTIONS_PER_WRITE`], [`rows::LIVES_PER_WRITE`]), each only while
    /// the claim holds the merge step, so that no result holds the database for long; the rows
    /// in [`SIDE_BY_SIDE_WRITES`] transactions at a time where the database runs them side by
    /// side, cut into at least as many. A merge that stops midway leaves rows that its rerun
    /// writes again, the same (the job is deterministic), or that ending the job drops. `None`
    /// once the claim no longer holds.
    async fn write_rows(&self, fence: &Fence, result: &EncodedResult) -> StoreResult<Option<()>> {
        use futures_util::StreamExt;
        let writers = if self.writes_side_by_side() {
            SIDE_BY_SIDE_WRITES
        } else {
            1
        };
        let per_write = result
            .rows
            .len()
            .div_ceil(writers)
            .clamp(1, rows::DISTRIBUTIONS_PER_WRITE);
        let mut chunks = result.rows.chunks(per_write);
        let mut writes = futures_util::stream::FuturesUnordered::new();
        loop {
            while writes.len() < writers
                && let Some(chunk) = chunks.next()
            {
                writes.push(self.write_distributions(fence, chunk));
            }
            let Some(written) = writes.next().await else {
                break;
            };
            if written?.is_none() {
                return Ok(None);
            }
        }
        for chunk in result.lives.chunks(rows::LIVES_PER_WRITE) {
            let Some(mut tx) = self.begin_holding(fence).await? else {
                return Ok(None);
            };
            insert_lives(&mut tx, &fence.job, chunk).await?;
            tx.commit().await?;
        }
        Ok(Some(()))
    }

    /// Writes `rows` of a Result in a transaction of their own while the claim holds.
    async fn write_distributions(
        &self,
        fence: &Fence,
        rows: &[rows::EncodedRow],
    ) -> StoreResult<Option<()>> {
        let Some(mut tx) = self.begin_holding(fence).await? else {
            return Ok(None);
        };
        insert_distributions(&mut tx, &fence.job, rows).await?;
        tx.commit().await?;
        Ok(Some(()))
    }
}

/// Where a bin's groups' accumulators are: its own, decoded (none if stored before they were
/// kept), or its job's shards', for bin `.0`.
enum Kept {
    Own(Option<Vec<Accumulator>>),
    InShards(u64),
}

impl Kept {
    fn own(self) -> Option<Vec<Accumulator>> {
        match self {
            Kept::Own(groups) => groups,
            Kept::InShards(_) => None,
        }
    }
}

/// Whether `result`'s rows go in the transaction that ends the job, rather than in transactions
/// of their own before it ([`Store::write_rows`]): when they fit in one write, and unless
/// `side_by_side` (the database runs writers side by side) and there are rows enough to share
/// out, large enough to gain.
fn with_the_end(result: &EncodedResult, side_by_side: bool) -> bool {
    let shared_out = side_by_side
        && result.rows.len() >= SIDE_BY_SIDE_WRITES
        && result.bytes() >= SIDE_BY_SIDE_BYTES;
    result.rows.len() <= rows::DISTRIBUTIONS_PER_WRITE
        && result.lives.len() <= rows::LIVES_PER_WRITE
        && !shared_out
}

/// What a succeeded job leaves: its Result, one row per (metric, bin), each device's life.
impl Store {
    /// Stores the result, marks the merge step done and the job succeeded, and drops the groups'
    /// accumulators, if the claim still holds the merge step: the distributions (each with the
    /// final groups' accumulators of its (metric, bin), for queries after the run) and device
    /// lives first, in short transactions, then the rest in one. The job's stored bytes
    /// ([`super::JobRecord::stored_bytes`]); `None` if the claim no longer holds (the job stays
    /// unsucceeded; rows already written go when it ends, or its next merge writes them again).
    /// The job's end is stamped `at`, or on the database's clock. The merge step counts the
    /// operations it `ran` itself (a job's devices run whole, a rare event estimated there), and
    /// the job's progress ends as the sum over its shards, each operation run counted once.
    #[tracing::instrument(skip_all, fields(job = %fence.job))]
    pub async fn succeed(
        &self,
        fence: &Fence,
        at: Option<UnixMs>,
        ran: u64,
        result: &EncodedResult,
    ) -> StoreResult<Option<u64>> {
        // A Result that fits in one write goes in the transaction that ends the job, one commit,
        // unless it is large and the database writes its rows faster side by side before.
        self.check_room(result.bytes()).await?;
        let with_the_end = with_the_end(result, self.writes_side_by_side());
        if !with_the_end && self.write_rows(fence, result).await?.is_none() {
            return Ok(None);
        }
        let Some(mut tx) = self.begin_finishing(fence, ran).await? else {
            return Ok(None);
        };
        let finished_at = super::queue::now_or(self.dialect(), &mut tx, at).await?;
        // The job's row before its groups' rows, in the order a cancel and a claim that fails
        // the job take them: dropping the groups first deadlocked with a cancel (a review).
        super::queue::lock_job(self.dialect(), &mut tx, fence.job.as_str()).await?;
        // The groups' accumulators go, unless the rows leave them in the shards; those left
        // count towards the job's stored bytes.
        if !result.groups_in_shards {
            drop_partials(&mut tx, &fence.job).await?;
        }
        // Only a job still running: a cancel that committed after the shard's fence was read
        // has ended it (and dropped the rows written before), and stands.
        let Some(stored) = Sql::new(concat!(
            "UPDATE jobs SET status = 'succeeded', finished_at = $2, operations_total = ",
            done_over_shards!(),
            ", operations_done = ",
            done_over_shards!(),
            ", stored_bytes = octet_length(spec) + $3 + ",
            rows::partial_bytes!(),
            " WHERE id = $1 AND status = 'running' RETURNING stored_bytes"
        ))
        .bind(fence.job.as_str())
        .bind(finished_at.0)
        .bind(count_to_sql(result.bytes()))
        .fetch_optional(&mut tx)
        .await?
        else {
            tx.rollback().await?;
            return Ok(None);
        };
        let stored_bytes = count_from_sql(&stored, "stored_bytes")?;
        if with_the_end {
            insert_distributions(&mut tx, &fence.job, &result.rows).await?;
            insert_lives(&mut tx, &fence.job, &result.lives).await?;
        }
        Sql::new("INSERT INTO results (job_id, result) VALUES ($1, $2)")
            .bind(fence.job.as_str())
            .bind(result.text.clone())
            .execute(&mut tx)
            .await?;
        tx.commit().await?;
        self.ended(&fence.job);
        Ok(Some(stored_bytes))
    }

    /// The accumulators of the job's done groups, in batch and group order, read into `into`
    /// one at a time; those of the groups `into` holds are not sent ([`Folding::holding`]).
    #[tracing::instrument(skip_all, fields(job = %id))]
    pub async fn partials(&self, id: &JobId, into: Folding) -> StoreResult<Folding> {
        collect_partials(
            Sql::new(SELECT_PARTIALS)
                .bind(id.as_str())
                .bind(count_to_sql(into.last()))
                .bind(held_mask(&into))
                .fetch(self.readers()),
            into,
        )
        .await
    }

    /// The state a rare event's round `batch` starts from, its merge step's partial.
    #[tracing::instrument(skip_all, fields(job = %id, batch))]
    pub async fn round(&self, id: &JobId, batch: u64) -> StoreResult<Rounds> {
        let stored = Sql::new(
            "SELECT partial FROM shards WHERE job_id = $1 AND batch = $2 AND grp = -1 \
             AND partial IS NOT NULL",
        )
        .bind(id.as_str())
        .bind(count_to_sql(batch))
        .fetch_optional(self.readers())
        .await?
        .map(|row| row.bytes("partial"))
        .transpose()?
        .ok_or_else(|| rows::corrupt("rare-event round", format!("batch {batch} has no state")))?;
        decoded("rare-event round", stored).await
    }

    /// The outcomes of round `batch`'s done tasks, in task order.
    #[tracing::instrument(skip_all, fields(job = %id, batch))]
    pub async fn round_outcomes(&self, id: &JobId, batch: u64) -> StoreResult<Vec<Outcome>> {
        let rows = Sql::new(
            "SELECT partial FROM shards WHERE job_id = $1 AND batch = $2 AND grp >= 0 \
             AND status = 'done' AND partial IS NOT NULL ORDER BY grp",
        )
        .bind(id.as_str())
        .bind(count_to_sql(batch))
        .fetch_all(self.readers())
        .await?;
        let mut outcomes = Vec::with_capacity(rows.len());
        for row in rows {
            outcomes.push(decoded("rare-event task outcome", row.bytes("partial")?).await?);
        }
        Ok(outcomes)
    }

    /// The Result JSON as stored, to be served as it is.
    #[tracing::instrument(skip_all, fields(job = %id))]
    pub async fn result_json(&self, id: &JobId) -> StoreResult<Option<String>> {
        self.result_text(id, SELECT_RESULT).await
    }

    /// The Result JSON that `statement` ([`SELECT_RESULT`] or [`SELECT_RESULT_ENDS`]) reads.
    async fn result_text(
        &self,
        id: &JobId,
        statement: &'static str,
    ) -> StoreResult<Option<String>> {
        let row = Sql::new(statement)
            .bind(id.as_str())
            .fetch_optional(self.readers())
            .await?;
        match row {
            Some(row) => result_from_row(row).await.map(Some),
            None => Ok(None),
        }
    }

    /// The bins of `metric` that overlap `range`, in bin order.
    #[tracing::instrument(skip_all, fields(job = %id, metric))]
    pub async fn distribution(
        &self,
        id: &JobId,
        metric: &str,
        range: Operations,
    ) -> StoreResult<Vec<DistributionRow>> {
        let rows = bind_bins(Sql::new(SELECT_DISTRIBUTION), id, metric, range)
            .fetch_all(self.readers())
            .await?;
        let large = rows.len() >= LARGE_DISTRIBUTION_BINS;
        let parse = move || rows.iter().map(distribution_from_row).collect();
        rows::off_async_threads("distribution", large, parse).await
    }

    /// The groups' accumulators of the bins [`Store::distribution`] gives, in the same order:
    /// what a query after the run reads. `None` for a bin stored before they were kept. Where
    /// the bins leave them in the job's shards, every group is read from there, decoded off the
    /// async threads, and each bin's taken out.
    #[tracing::instrument(skip_all, fields(job = %id, metric))]
    pub async fn distribution_groups(
        &self,
        id: &JobId,
        metric: &str,
        range: Operations,
    ) -> StoreResult<Vec<Option<Vec<Accumulator>>>> {
        let rows = bind_bins(Sql::new(SELECT_DISTRIBUTION_GROUPS), id, metric, range)
            .fetch_all(self.readers())
            .await?;
        // Decoded on the blocking pool: a wide job's bins are megabytes each, and decoded here
        // eight such queries held the threads that answer requests (`/healthz` took up to 7 s;
        // found from outside).
        let bins = rows::off_async_threads(rows::GROUPS, true, move || {
            (rows.iter())
                .map(|row| match row.flag("groups_in_shards")? {
                    true => Ok(Kept::InShards(count_from_sql(row, "bin")?)),
                    false => Ok(Kept::Own(groups_from_row(row)?)),
                })
                .collect::<StoreResult<Vec<Kept>>>()
        })
        .await?;
        if !bins.iter().any(|bin| matches!(bin, Kept::InShards(_))) {
            return Ok(bins.into_iter().map(Kept::own).collect());
        }
        // A job deleted since its rows were read has neither (a DELETE takes them together): it
        // is not found, as a read after the delete finds it (a query racing the delete was a 500).
        let spec = Sql::new("SELECT spec FROM jobs WHERE id = $1")
            .bind(id.as_str())
            .fetch_optional(self.readers())
            .await?
            .ok_or_else(|| StoreError::job_not_found(id))?
            .text("spec")?;
        let stored = Sql::new(SELECT_GROUPS_IN_SHARDS)
            .bind(id.as_str())
            .fetch_all(self.readers())
            .await?;
        if stored.is_empty() {
            return Err(StoreError::job_not_found(id));
        }
        let metric = metric.to_owned();
        rows::off_async_threads("groups in shards", true, move || {
            let what = "group accumulators";
            // The job as it ran: which metrics its groups hold, in what order.
            let job = Job::new(spec_from_json(&spec)?, || 0, &Pointer::root())
                .map_err(|e| rows::corrupt("job", e))?;
            let groups: Vec<GroupStats> = stored
                .iter()
                .map(|row| rows::decode(what, &row.bytes("partial")?))
                .collect::<StoreResult<_>>()?;
            let run = RunGroups::from_groups(&job, groups);
            let of_bin = |bin| match bin {
                Kept::Own(groups) => Ok(groups),
                Kept::InShards(bin) => run.of(&metric, bin).map(Some).ok_or_else(|| {
                    rows::corrupt(what, format!("the job's shards have no {metric} bin {bin}"))
                }),
            };
            bins.into_iter().map(of_bin).collect()
        })
        .await
    }

    /// The listed devices' lives after device `after` (from the first without), in device order,
    /// at most `limit`: one page of a keyset walk, whatever the job's size.
    #[tracing::instrument(skip_all, fields(job = %id))]
    pub async fn lives_page(
        &self,
        id: &JobId,
        after: Option<u64>,
        limit: u32,
    ) -> StoreResult<Vec<DeviceLife>> {
        let rows = Sql::new(
            "SELECT device, operations_to_failure, censored FROM device_lives \
             WHERE job_id = $1 AND device > $2 ORDER BY device LIMIT $3",
        )
        .bind(id.as_str())
        .bind(after.map_or(-1, count_to_sql))
        .bind(i64::from(limit))
        .fetch_all(self.readers())
        .await?;
        Ok(rows.iter().map(life_from_row).collect::<Result<_, _>>()?)
    }

    /// The Result, parsed (off the async threads when it is large).
    pub async fn result(&self, id: &JobId) -> StoreResult<Option<JobResult>> {
        self.parsed_result(id, SELECT_RESULT).await
    }

    /// The Result with each operation metric's last bin alone (its other bins left out), for
    /// what reads only the job's end: a schedule's trend. A few kilobytes where the whole Result
    /// of a 1000-bin job is tens of megabytes.
    pub async fn result_ends(&self, id: &JobId) -> StoreResult<Option<JobResult>> {
        self.parsed_result(id, SELECT_RESULT_ENDS).await
    }

    async fn parsed_result(
        &self,
        id: &JobId,
        statement: &'static str,
    ) -> StoreResult<Option<JobResult>> {
        let Some(text) = self.result_text(id, statement).await? else {
            return Ok(None);
        };
        let large = text.len() >= rows::LARGE_RESULT_BYTES;
        let parse = move || serde_json::from_str(&text).map_err(|e| rows::corrupt("result", e));
        rows::off_async_threads("result", large, parse)
            .await
            .map(Some)
    }

    /// Every listed device's life, in device order (page by page; for tests and small jobs).
    pub async fn lives(&self, id: &JobId) -> StoreResult<Vec<DeviceLife>> {
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

/// `stored` decoded off the async threads.
async fn decoded<T: serde::de::DeserializeOwned + Send + 'static>(
    what: &'static str,
    stored: Vec<u8>,
) -> StoreResult<T> {
    rows::off_async_threads(what, true, move || rows::decode(what, &stored)).await
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A Result of `rows` rows of `bytes` bytes in all and `lives` listed lives.
    fn result(rows: usize, bytes: usize, lives: usize) -> EncodedResult {
        let life = DeviceLife {
            device: 0,
            operations_to_failure: 1,
            censored: false,
        };
        EncodedResult {
            text: String::new(),
            rows: (0..rows)
                .map(|i| rows::EncodedRow::of_bytes(bytes / rows + usize::from(i < bytes % rows)))
                .collect(),
            lives: vec![life; lives],
            groups_in_shards: false,
        }
    }

    /// A small Result ends its job in one transaction on either database; one of 256 KB or more
    /// in two rows or more goes first, side by side, where the database writes so; one beyond a
    /// write's bounds goes first on either.
    #[test]
    fn only_a_large_result_is_written_before_its_end() {
        let bytes = usize::try_from(SIDE_BY_SIDE_BYTES).unwrap();
        for side_by_side in [false, true] {
            assert!(with_the_end(&result(115, bytes - 1, 0), side_by_side));
            assert!(with_the_end(&result(1, bytes, 0), side_by_side));
            let many_lives = result(1, 0, rows::LIVES_PER_WRITE + 1);
            assert!(!with_the_end(&many_lives, side_by_side));
            let many_rows = result(rows::DISTRIBUTIONS_PER_WRITE + 1, 0, 0);
            assert!(!with_the_end(&many_rows, side_by_side));
        }
        assert_eq!(result(115, bytes, 0).bytes(), SIDE_BY_SIDE_BYTES);
        assert!(with_the_end(&result(115, bytes, 0), false));
        assert!(!with_the_end(&result(115, bytes, 0), true));
    }
}
