//! Schedules and their runs, written once for both databases.

use super::backend::Store;
use super::queue::{remember, select_job};
use super::rows::{
    Created, bind_schedule, count_from_sql, count_to_sql, run_from_row, schedule_columns,
    schedule_from_row, schedule_read_columns,
};
use super::sql::{Conn, Sql, Tx};
use super::{NewRun, NextRun, RunRecord, RunSlot, ScheduleRecord, StoreError, StoreResult};
use crate::domain::{
    IdempotencyKey, MISSED_RUNS, Once, Owner, QueueBound, QueuedJob, ScheduleBound, ScheduleId,
    UnixMs,
};

/// Moves a schedule's next run from `$2` to `$3` if it is still at `$2` and at revision `$4`,
/// counting `$5` runs skipped, the latest due at `$6` for the reason `$7` ([`move_next_run`]).
const MOVE_NEXT_RUN: &str = "UPDATE schedules SET next_run_at = $3, \
     skipped_runs = skipped_runs + $5, last_skipped_for = COALESCE($6, last_skipped_for), \
     last_skip_reason = COALESCE($7, last_skip_reason) \
     WHERE id = $1 AND next_run_at IS NOT DISTINCT FROM $2 AND revision = $4";

/// [`MOVE_NEXT_RUN`] with its parameters: the runs `moves` missed, and the run due at `skipped`'s
/// time skipped for its reason (the latest skip then).
fn move_next_run(id: &ScheduleId, moves: NextRun, skipped: Option<(UnixMs, &str)>) -> Sql {
    let (count, last) = match skipped {
        Some(skipped) => (moves.missed + 1, Some(skipped)),
        None => (moves.missed, moves.last_missed.map(|at| (at, MISSED_RUNS))),
    };
    Sql::new(MOVE_NEXT_RUN)
        .bind(id.as_str())
        .bind(moves.from.map(|t| t.0))
        .bind(moves.to.map(|t| t.0))
        .bind(count_to_sql(moves.revision))
        .bind(count_to_sql(count))
        .bind(last.map(|(at, _)| at.0))
        .bind(last.map(|(_, reason)| reason.to_owned()))
}

const INSERT_SCHEDULE: &str = concat!(
    "INSERT INTO schedules (",
    schedule_columns!(),
    ") VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10, $11)"
);

impl Store {
    /// Inserts a schedule in `tx` unless the bound refuses it: the count and the insert in one
    /// transaction, under the owner's lock (SQLite's one writer; an advisory lock on PostgreSQL,
    /// whose inserts at the same moment would each see the count below the bound).
    async fn insert_bounded(
        &self,
        tx: &mut Tx,
        schedule: &ScheduleRecord,
        bound: ScheduleBound,
    ) -> StoreResult<()> {
        self.check_disk(bound.min_free_disk_bytes).await?;
        self.lock(tx, format!("{}/schedules", schedule.owner.as_str()))
            .await?;
        let held = Sql::new("SELECT COUNT(*) AS held FROM schedules WHERE owner = $1")
            .bind(schedule.owner.as_str())
            .fetch_one(&mut *tx)
            .await?;
        if count_from_sql(&held, "held")? >= bound.per_owner {
            return Err(StoreError::TooManySchedules {
                most: bound.per_owner,
            });
        }
        bind_schedule(Sql::new(INSERT_SCHEDULE), schedule)?
            .execute(&mut *tx)
            .await?;
        Ok(())
    }
}

/// Schedules and their runs.
impl Store {
    /// Inserts a schedule unless its owner holds the most the bound allows
    /// ([`StoreError::TooManySchedules`]); below the bound's free disk, the database is not
    /// ready (503).
    #[tracing::instrument(skip_all, fields(schedule = %schedule.id))]
    pub async fn insert_schedule(
        &self,
        schedule: &ScheduleRecord,
        bound: ScheduleBound,
    ) -> StoreResult<()> {
        let mut tx = self.begin_reading_first().await?;
        self.insert_bounded(&mut tx, schedule, bound).await?;
        tx.commit().await?;
        Ok(())
    }

    /// As [`Store::insert_schedule`], once per key of the schedule's owner (see
    /// [`Store::insert_job_once`]): a retry gets the schedule the first created, whatever
    /// the bound.
    #[tracing::instrument(skip_all, fields(schedule = %schedule.id))]
    pub async fn insert_schedule_once(
        &self,
        schedule: &ScheduleRecord,
        bound: ScheduleBound,
        key: &IdempotencyKey,
        at: Option<UnixMs>,
    ) -> StoreResult<Once<ScheduleRecord>> {
        let owner = &schedule.owner;
        let mut tx = self.begin_reading_first().await?;
        let now = super::queue::now_or(self.dialect(), &mut tx, at).await?;
        let read = async |tx: &mut Tx, id| select_schedule(tx, owner, &ScheduleId::from(id)).await;
        let replayed = self.replayed(&mut tx, (owner, "schedules"), key, now, read);
        if let Some(once) = replayed.await? {
            tx.commit().await?;
            return Ok(once);
        }
        self.insert_bounded(&mut tx, schedule, bound).await?;
        remember(&mut tx, owner, Created::Schedule(&schedule.id), key, now).await?;
        tx.commit().await?;
        Ok(Once::Created(schedule.clone()))
    }

    #[tracing::instrument(skip_all, fields(schedule = %id))]
    pub async fn schedule(&self, owner: &Owner, id: &ScheduleId) -> StoreResult<ScheduleRecord> {
        select_schedule(self.writer()?, owner, id).await
    }

    /// An owner's schedules after the one at `seq` `after` (from the first without it), oldest
    /// first, at most `limit`; each with its `seq`, the cursor of the next page.
    #[tracing::instrument(skip_all)]
    pub async fn schedules(
        &self,
        owner: &Owner,
        after: Option<i64>,
        limit: u32,
    ) -> StoreResult<Vec<(i64, ScheduleRecord)>> {
        let rows = Sql::new(concat!(
            "SELECT seq, ",
            schedule_read_columns!(),
            " FROM schedules WHERE owner = $1 AND seq > $2 ORDER BY seq LIMIT $3"
        ))
        .bind(owner.as_str())
        .bind(after.unwrap_or(0))
        .bind(i64::from(limit))
        .fetch_all(self.readers())
        .await?;
        rows.iter()
            .map(|row| Ok((row.int("seq")?, schedule_from_row(row)?)))
            .collect()
    }

    /// Replaces a schedule's definition and next run (its runs stay), if it is still as `read`
    /// (its revision and next run): `None` once written; the schedule as it is now if a PUT or a
    /// run moved it since, to work the replacement out again from ([`StoreError::NotFound`] if
    /// it is gone). A PUT that wrote back a
    /// next run read before a tick moved it put the schedule on a night already run, and the
    /// catch-up counted that night as skipped (a probe: 8 runs and 1 skipped of 8 due times).
    #[tracing::instrument(skip_all, fields(schedule = %schedule.id))]
    pub async fn update_schedule(
        &self,
        schedule: &ScheduleRecord,
        read: &ScheduleRecord,
    ) -> StoreResult<Option<ScheduleRecord>> {
        let update = Sql::new(
            "UPDATE schedules SET name = $3, cron = $4, time_zone = $5, template = $6, statistics = $7, \
             enabled = $8, next_run_at = $9, created_at = $10, updated_at = $11, \
             revision = revision + 1 WHERE id = $1 AND owner = $2 \
             AND revision = $12 AND next_run_at IS NOT DISTINCT FROM $13",
        );
        let updated = bind_schedule(update, schedule)?
            .bind(count_to_sql(read.revision))
            .bind(read.next_run_at.map(|t| t.0))
            .execute(self.writer()?)
            .await?;
        if updated == 0 {
            // Gone, or moved on since it was read.
            return self.schedule(&schedule.owner, &schedule.id).await.map(Some);
        }
        Ok(None)
    }

    #[tracing::instrument(skip_all, fields(schedule = %id))]
    pub async fn delete_schedule(&self, owner: &Owner, id: &ScheduleId) -> StoreResult<()> {
        let deleted = Sql::new("DELETE FROM schedules WHERE id = $1 AND owner = $2")
            .bind(id.as_str())
            .bind(owner.as_str())
            .execute(self.writer()?)
            .await?;
        if deleted == 0 {
            return Err(StoreError::schedule_not_found(id));
        }
        Ok(())
    }

    /// Enabled schedules of every owner whose next run is due at `now`.
    #[tracing::instrument(skip_all)]
    pub async fn due_schedules(&self, now: UnixMs) -> StoreResult<Vec<ScheduleRecord>> {
        let rows = Sql::new(concat!(
            "SELECT ",
            schedule_read_columns!(),
            " FROM schedules WHERE enabled = TRUE AND next_run_at <= $1 ORDER BY next_run_at"
        ))
        .bind(now.0)
        .fetch_all(self.writer()?)
        .await?;
        rows.iter().map(schedule_from_row).collect()
    }

    /// Creates the job of one slot unless the slot has one, and moves a due run's schedule on
    /// ([`RunSlot::moves`]), in one transaction.
    #[tracing::instrument(skip_all, fields(schedule = %slot.schedule, job = %job.id))]
    pub async fn create_run(
        &self,
        slot: RunSlot<'_>,
        job: QueuedJob,
        bound: QueueBound,
    ) -> StoreResult<NewRun> {
        let mut tx = self.begin().await?;
        // A due run first moves its schedule on, if the schedule is still as read.
        if let Some(moves) = slot.moves {
            let moved = move_next_run(slot.schedule, moves, None)
                .execute(&mut tx)
                .await?;
            if moved == 0 {
                tx.rollback().await?;
                return Ok(NewRun::Moved);
            }
        }
        // Claim the slot: the primary key decides who runs this night.
        let claimed = Sql::new(
            "INSERT INTO schedule_runs (schedule_id, scheduled_for, job_id, manual) VALUES ($1, $2, $3, $4) \
             ON CONFLICT DO NOTHING",
        )
        .bind(slot.schedule.as_str())
        .bind(slot.scheduled_for.0)
        .bind(job.id.as_str())
        .bind(slot.manual)
        .execute(&mut tx)
        .await
        .map_err(|error| match error {
            // The schedule was deleted since it was read (a run asked for beside its delete).
            StoreError::Database(sqlx::Error::Database(error))
                if error.kind() == sqlx::error::ErrorKind::ForeignKeyViolation =>
            {
                StoreError::schedule_not_found(slot.schedule)
            }
            error => error,
        })?;
        if claimed == 0 {
            // Its move stays: the schedule is past a night that has its job.
            tx.commit().await?;
            return Ok(NewRun::AlreadyExists);
        }
        if !self.insert_queued(&mut tx, &job, bound).await? {
            tx.rollback().await?;
            return Ok(NewRun::QueueFull);
        }
        let record = select_job(&mut tx, &job.owner, &job.id).await?;
        tx.commit().await?;
        Ok(NewRun::Created(Box::new(record)))
    }

    /// Moves the schedule's next run ([`NextRun`]), unless another loop moved it or a PUT
    /// replaced the schedule since it was read: false.
    #[tracing::instrument(skip_all, fields(schedule = %id))]
    pub async fn advance_schedule(&self, id: &ScheduleId, moves: NextRun) -> StoreResult<bool> {
        let updated = move_next_run(id, moves, None)
            .execute(self.writer()?)
            .await?;
        Ok(updated == 1)
    }

    /// Skips the run due at `due` with `reason` (and counts those `moves` missed before it) and
    /// moves the schedule's next run, as [`Store::advance_schedule`] would (else nothing is
    /// counted: false).
    #[tracing::instrument(skip_all, fields(schedule = %id))]
    pub async fn skip_run(
        &self,
        id: &ScheduleId,
        moves: NextRun,
        due: UnixMs,
        reason: &str,
    ) -> StoreResult<bool> {
        let updated = move_next_run(id, moves, Some((due, reason)))
            .execute(self.writer()?)
            .await?;
        Ok(updated == 1)
    }

    /// The latest runs, newest first.
    #[tracing::instrument(skip_all, fields(schedule = %schedule))]
    pub async fn runs(&self, schedule: &ScheduleId, limit: u32) -> StoreResult<Vec<RunRecord>> {
        let rows = Sql::new(
            "SELECT r.scheduled_for, r.job_id, r.manual, j.status FROM schedule_runs r JOIN jobs j ON j.id = r.job_id \
             WHERE r.schedule_id = $1 ORDER BY r.scheduled_for DESC LIMIT $2",
        )
        .bind(schedule.as_str())
        .bind(i64::from(limit))
        .fetch_all(self.readers())
        .await?;
        Ok(rows.iter().map(run_from_row).collect::<Result<_, _>>()?)
    }
}

/// Schedule `id` of `owner`, read on `on`.
async fn select_schedule(
    on: impl Into<Conn<'_>>,
    owner: &Owner,
    id: &ScheduleId,
) -> StoreResult<ScheduleRecord> {
    let row = Sql::new(concat!(
        "SELECT ",
        schedule_read_columns!(),
        " FROM schedules WHERE id = $1 AND owner = $2"
    ))
    .bind(id.as_str())
    .bind(owner.as_str())
    .fetch_optional(on)
    .await?
    .ok_or_else(|| StoreError::schedule_not_found(id))?;
    schedule_from_row(&row)
}
