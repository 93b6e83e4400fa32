//! The scheduler loop: every second, each enabled schedule whose next run is due gets one job for
//! its latest due time at or before now (so a server that was down for three nights runs the missed
//! night once, not three times), and its next run moves past now. The (schedule, due time) primary
//! key makes the job unique across restarts and across instances sharing the database. "Now" is
//! the database's clock, which those instances share. At start-up and when that clock steps back,
//! next runs the later clock put too far are brought back.

use crate::domain::{
    MISSED_RUNS_COUNTED, Owner, QueueBound, ScheduleId, ScheduleLimits, Timetable, UnixMs,
    too_often,
};
use crate::store::{NewRun, NextRun, RunSlot, ScheduleRecord, Store, StoreError, StoreResult};
use chrono::{DateTime, Utc};
use std::collections::HashSet;
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::{Notify, watch};

const TICK: Duration = Duration::from_secs(1);

pub async fn run(
    store: Arc<Store>,
    limits: RunLimits,
    wake: Arc<Notify>,
    mut shutdown: watch::Receiver<bool>,
) {
    let mut waiting = Waiting::default();
    // Ticks failed in a row: the first is logged as an error and the end of the run as news,
    // not every tick (a second) between, as when the disk stays below --min-free-disk-mb.
    let mut failing = 0_u64;
    let mut last_tick: Option<DateTime<Utc>> = None;
    // Every second on the second from the start, not a second after each tick's work: a tick
    // period that drifted to 1.02-1.2 s skipped one due time of a cron every second in 13 (a
    // probe, with --min-schedule-interval-seconds 1).
    let mut ticker = tokio::time::interval(TICK);
    ticker.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
    while !*shutdown.borrow() {
        tokio::select! {
            _ = ticker.tick() => {}
            // Told to stop (or the server gone): the loop's condition says which.
            changed = shutdown.changed() => {
                if changed.is_err() {
                    break;
                }
                continue;
            }
        }
        // The database's clock, which every instance shares: on their own, one 10 minutes fast
        // ran each due time 10 minutes early and counted the rest as skipped, and one two days
        // ahead, once stopped, left the others nothing due for two days (a probe).
        let now = match store.now().await {
            Ok(now) => now.to_datetime(),
            Err(error) => {
                failed(&mut failing, &error);
                continue;
            }
        };
        // At start-up, and when the clock stepped back since the last tick.
        if last_tick.is_none_or(|last| now + TICK < last) {
            match rebase(store.as_ref(), now).await {
                Ok(0) => {}
                Ok(rebased) => {
                    tracing::warn!(
                        rebased,
                        "schedules' next runs were later than their timetables give from now (the clock went back); moved to the next due time from now"
                    );
                }
                Err(error) => {
                    tracing::error!(%error, "the schedules' next runs could not be checked against the clock")
                }
            }
        }
        last_tick = Some(now);
        let ticked = tick(store.as_ref(), limits.clone(), now, &mut waiting).await;
        if ticked.is_ok() && failing > 0 {
            tracing::info!(
                failed_ticks = failing,
                "the scheduler's ticks succeed again"
            );
            failing = 0;
        }
        match ticked {
            Ok(0) => {}
            Ok(created) => {
                tracing::info!(created, "scheduled jobs created");
                crate::telemetry::record_jobs_submitted(created as u64);
                wake.notify_waiters();
            }
            Err(error) => failed(&mut failing, &error),
        }
    }
}

/// Counts a failed tick, logged as an error the first time in a row.
fn failed(failing: &mut u64, error: &StoreError) {
    if *failing == 0 {
        tracing::error!(%error, "scheduler tick failed; it is tried every second, and logged again once it succeeds");
    } else {
        tracing::debug!(%error, "scheduler tick failed again");
    }
    *failing += 1;
}

/// The schedules whose run waits for room in a full queue. Each is warned of once, when it starts
/// waiting, and noted when its run is queued, rather than warned of at every tick (a second) in
/// between.
#[derive(Debug, Default)]
pub struct Waiting(HashSet<ScheduleId>);

impl Waiting {
    /// Notes what creating `schedule`'s run did, saying once when its run starts and stops
    /// waiting for room in the queue; whether it made a job.
    fn note(&mut self, schedule: &ScheduleId, made: &NewRun) -> bool {
        match made {
            NewRun::QueueFull => {
                if self.0.insert(schedule.clone()) {
                    tracing::warn!(%schedule, "queue full; the scheduled run waits for room");
                }
                return false;
            }
            // Replaced, disabled, deleted or run by another loop since it was read: the next
            // tick reads it as it is now.
            NewRun::Moved => {
                self.0.remove(schedule);
                return false;
            }
            NewRun::Created(_) | NewRun::AlreadyExists => {}
        }
        if self.0.remove(schedule) {
            tracing::info!(%schedule, "the scheduled run no longer waits for room");
        }
        matches!(made, NewRun::Created(_))
    }

    pub fn contains(&self, schedule: &ScheduleId) -> bool {
        self.0.contains(schedule)
    }
}

/// What the server allows the jobs its schedules make: room in the queue, each one's size and
/// how often they run (a run larger than the schedule limits' `max_job_operations`, or of a
/// timetable that runs more often than their `min_interval`, is skipped, as the schedule
/// written now would be refused) and whose they may be (with API keys, a schedule whose key is
/// not among them is skipped: no caller could see, pause or delete it).
#[derive(Debug, Clone)]
pub struct RunLimits {
    pub queue: QueueBound,
    pub schedule: ScheduleLimits,
    /// The owners of the server's API keys; empty without keys, when every schedule runs.
    pub key_owners: Arc<HashSet<Owner>>,
}

/// One pass over the due schedules at `now`; returns how many jobs it created. `waiting` carries
/// the schedules waiting for room in the queue from one tick to the next.
pub async fn tick(
    store: &Store,
    limits: RunLimits,
    now: DateTime<Utc>,
    waiting: &mut Waiting,
) -> StoreResult<usize> {
    let mut created = 0;
    for schedule in store.due_schedules(UnixMs::from_datetime(now)).await? {
        let definition = &schedule.definition;
        let Some(timetable) = timetable_or_stop(store, &schedule, now).await? else {
            continue;
        };
        let next = timetable.next_after(now).map(UnixMs::from_datetime);
        // No time of the timetable from the run planned to now owes nothing: a timetable
        // replaced under a kept due time (before the revision that stops it) made runs at past
        // times of the new one.
        let planned = schedule.next_run_at.map_or(now, UnixMs::to_datetime);
        let Some(catch_up) = timetable.catch_up(planned, now, MISSED_RUNS_COUNTED) else {
            store
                .advance_schedule(&schedule.id, schedule.moving_to(next))
                .await?;
            continue;
        };
        let due = UnixMs::from_datetime(catch_up.due);
        let moves = NextRun {
            missed: catch_up.missed,
            last_missed: catch_up.last_missed.map(UnixMs::from_datetime),
            ..schedule.moving_to(next)
        };
        if !limits.key_owners.is_empty() && !limits.key_owners.contains(&schedule.owner) {
            tracing::warn!(schedule = %schedule.id, "the schedule's API key is no longer among this server's keys; this run is skipped");
            let reason = "its API key is no longer among this server's keys: configure the key \
                          again to run it, or to see and delete it";
            skip(store, &schedule, moves, due, reason).await?;
            continue;
        }
        // A limit raised since the schedule was written (or another instance's) holds for its
        // runs too: they ran every minute under an hour's limit, unthrottled (found from outside).
        let min_interval = limits.schedule.min_interval;
        if let Some(why) = too_often(&timetable, &definition.time_zone, min_interval, now) {
            tracing::warn!(schedule = %schedule.id, why, "the schedule runs more often than this server allows; this run is skipped");
            let reason = format!("its cron {why}: replace it (PUT) with one that runs less often");
            skip(store, &schedule, moves, due, &reason).await?;
            continue;
        }
        let job = match definition.job_at(
            schedule.owner.clone(),
            due,
            UnixMs::from_datetime(now),
            limits.schedule.max_job_operations,
        ) {
            Ok(job) => job,
            Err(invalid) => {
                // Moved past this run, so that it is said once a run, not at every tick.
                tracing::error!(schedule = %schedule.id, %invalid, "stored template no longer validates; this run is skipped");
                let reason = format!("the template is refused by this server now: {invalid}");
                skip(store, &schedule, moves, due, &reason).await?;
                continue;
            }
        };
        let missed = moves.missed;
        let slot = RunSlot {
            schedule: &schedule.id,
            scheduled_for: due,
            manual: false,
            moves: Some(moves),
        };
        let made = match store.create_run(slot, job, limits.queue).await {
            // Deleted since it was read: the other schedules still run this tick.
            Err(StoreError::NotFound { .. }) => {
                waiting.0.remove(&schedule.id);
                continue;
            }
            // Skipped, not retried: the key stays over until it deletes some, which a retry every
            // tick would wait for with a writer's transaction and a warning a second. The
            // schedule moves on as past a run that exists.
            Err(StoreError::OverQuota { used, quota }) => {
                tracing::warn!(schedule = %schedule.id, used, quota, "the schedule's key stores its quota; this run is skipped");
                waiting.0.remove(&schedule.id);
                let reason = format!(
                    "its key's jobs store {used} bytes, its quota is {quota}: delete some jobs"
                );
                skip(store, &schedule, moves, due, &reason).await?;
                continue;
            }
            made => made?,
        };
        // The schedule moved past the due times missed with either (a night that had its job
        // keeps the move): the count is this instance's.
        if matches!(made, NewRun::Created(_) | NewRun::AlreadyExists) {
            passed_over(&schedule.id, missed);
        }
        created += usize::from(waiting.note(&schedule.id, &made));
    }
    Ok(created)
}

/// Moves each enabled schedule whose next run is later than its timetable's next due time after
/// `now` back to that time; returns how many it moved. Only a clock that went back (between two
/// ticks, or while the server was down) leaves one so: its next run was worked out on the later
/// clock, and it would wait that long again, its nights between never run (a day back, a night
/// missed; a year back, a year). A run made on the later clock keeps its slot: the new clock's
/// nights are made unless one of them was made already.
pub async fn rebase(store: &Store, now: DateTime<Utc>) -> StoreResult<usize> {
    let mut rebased = 0;
    for schedule in store.due_schedules(UnixMs(i64::MAX)).await? {
        let definition = &schedule.definition;
        let Ok(timetable) = Timetable::parse(&definition.cron, &definition.time_zone) else {
            continue;
        };
        let next = timetable.next_after(now).map(UnixMs::from_datetime);
        if next.is_some_and(|next| schedule.next_run_at.is_some_and(|at| at > next))
            && store
                .advance_schedule(&schedule.id, schedule.moving_to(next))
                .await?
        {
            rebased += 1;
        }
    }
    Ok(rebased)
}

/// The schedule's timetable; none when this build cannot read it (one that reads cron or time
/// zones otherwise than the build that wrote it): then its run is skipped and the schedule stops
/// (no next run: it stayed due and was logged again every second) until a PUT writes it anew.
async fn timetable_or_stop(
    store: &Store,
    schedule: &ScheduleRecord,
    now: DateTime<Utc>,
) -> StoreResult<Option<Timetable>> {
    let definition = &schedule.definition;
    let faults = match Timetable::parse(&definition.cron, &definition.time_zone) {
        Ok(timetable) => return Ok(Some(timetable)),
        Err(faults) => faults,
    };
    let faults: Vec<String> = faults
        .iter()
        .map(|(field, fault)| format!("{field}: {fault}"))
        .collect();
    let reason = format!(
        "its timetable no longer parses ({}); it runs again once replaced (PUT)",
        faults.join("; ")
    );
    tracing::error!(schedule = %schedule.id, %reason, "this run is skipped");
    let due = schedule.next_run_at.unwrap_or(UnixMs::from_datetime(now));
    skip(store, schedule, schedule.moving_to(None), due, &reason).await?;
    Ok(None)
}

/// Skips `schedule`'s run due at `due` for `reason`: counted on the schedule (shown with it) and on
/// `/metrics`, and its next run moved to `next`.
async fn skip(
    store: &Store,
    schedule: &ScheduleRecord,
    moves: NextRun,
    due: UnixMs,
    reason: &str,
) -> StoreResult<()> {
    let missed = moves.missed;
    if store.skip_run(&schedule.id, moves, due, reason).await? {
        crate::telemetry::record_scheduled_runs_skipped(1);
        passed_over(&schedule.id, missed);
    }
    Ok(())
}

/// Says in the log and on `/metrics` the `missed` due times a catch-up passed over (the server
/// down or late) once the schedule has recorded them: they showed on the schedule alone (found
/// from outside).
fn passed_over(schedule: &ScheduleId, missed: u64) {
    if missed > 0 {
        tracing::warn!(%schedule, missed, "due times passed while the server was down or late are skipped; only the latest is made");
        crate::telemetry::record_scheduled_runs_skipped(missed);
    }
}
