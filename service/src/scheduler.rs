//! The scheduler loop: every second, each enabled schedule whose next run is due gets one job for
//! its latest due time at or before now (so a server that was down for three nights runs the missed
//! night once, not three times), and its next run moves past now. The (schedule, due time) primary
//! key makes the job unique across restarts and across instances sharing the database.

use crate::domain::{Timetable, UnixMs};
use crate::store::{NewRun, RunSlot, Store, StoreResult};
use chrono::{DateTime, Utc};
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::{Notify, watch};

const TICK: Duration = Duration::from_secs(1);

pub async fn run(
    store: Arc<dyn Store>,
    max_queued: u64,
    wake: Arc<Notify>,
    mut shutdown: watch::Receiver<bool>,
) {
    while !*shutdown.borrow() {
        match tick(store.as_ref(), max_queued, Utc::now()).await {
            Ok(0) => {}
            Ok(created) => {
                tracing::info!(created, "scheduled jobs created");
                wake.notify_waiters();
            }
            Err(error) => tracing::error!(%error, "scheduler tick failed"),
        }
        tokio::select! {
            () = tokio::time::sleep(TICK) => {}
            _ = shutdown.changed() => {}
        }
    }
}

/// One pass over the due schedules at `now`; returns how many jobs it created.
pub async fn tick(store: &dyn Store, max_queued: u64, now: DateTime<Utc>) -> StoreResult<usize> {
    let mut created = 0;
    for schedule in store.due_schedules(UnixMs::from_datetime(now)).await? {
        let definition = &schedule.definition;
        let Ok(timetable) = Timetable::parse(&definition.cron, &definition.time_zone) else {
            tracing::error!(schedule = %schedule.id, "stored schedule no longer parses; skipped");
            continue;
        };
        let Some(due) = timetable
            .latest_at_or_before(now)
            .map(UnixMs::from_datetime)
        else {
            continue;
        };
        let job = match definition.job_at(schedule.owner.clone(), due, UnixMs::from_datetime(now)) {
            Ok(job) => job,
            Err(invalid) => {
                tracing::error!(schedule = %schedule.id, %invalid, "stored template no longer validates; skipped");
                continue;
            }
        };
        let slot = RunSlot {
            schedule: &schedule.id,
            scheduled_for: due,
            manual: false,
        };
        match store.create_run(slot, job, max_queued).await? {
            NewRun::Created(_) => created += 1,
            NewRun::AlreadyExists => {}
            NewRun::QueueFull => {
                tracing::warn!(schedule = %schedule.id, "queue full; the scheduled run waits for the next tick");
                continue;
            }
        }
        let next = timetable.next_after(now).map(UnixMs::from_datetime);
        store
            .advance_schedule(&schedule.id, schedule.next_run_at, next)
            .await?;
    }
    Ok(created)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::domain::utc;
    use crate::domain::{Owner, ScheduleDefinition, ScheduleId};
    use crate::store::sqlite::SqliteStore;
    use crate::store::{ScheduleRecord, Schedules};

    async fn store_at(path: &std::path::Path) -> SqliteStore {
        SqliteStore::open(&format!("sqlite://{}", path.display()))
            .await
            .unwrap()
    }

    fn temp_database(name: &str) -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!(
            "bouncewear-scheduler-{}-{name}",
            std::process::id()
        ));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir.join("schedules.db")
    }

    fn nightly(id: &str, next_run_at: DateTime<Utc>) -> ScheduleRecord {
        ScheduleRecord {
            id: ScheduleId::from(id),
            owner: Owner::anonymous(),
            definition: ScheduleDefinition {
                name: format!("nightly {id}"),
                cron: "0 3 * * *".to_owned(),
                time_zone: "UTC".to_owned(),
                template: serde_json::from_str(r#"{"devices": 2, "operations": 2, "seed": 1}"#)
                    .unwrap(),
                statistics: vec!["operations.total_bounce_s.p95".parse().unwrap()],
                enabled: true,
            },
            next_run_at: Some(UnixMs::from_datetime(next_run_at)),
            created_at: UnixMs(0),
            updated_at: UnixMs(0),
        }
    }

    fn schedule_id(id: &str) -> ScheduleId {
        ScheduleId::from(id)
    }

    #[tokio::test]
    async fn missed_nights_run_once_on_start_up_and_the_next_night_is_tomorrow() {
        let store = store_at(&temp_database("catch-up")).await;
        store
            .insert_schedule(&nightly("s1", utc("2026-11-19T03:00:00Z")))
            .await
            .unwrap();
        // The server was down for three nights; it starts at 08:00.
        let now = utc("2026-11-22T08:00:00Z");
        assert_eq!(tick(&store, 100, now).await.unwrap(), 1);
        assert_eq!(
            tick(&store, 100, now).await.unwrap(),
            0,
            "a restart the same morning adds nothing"
        );
        let runs = store.runs(&schedule_id("s1"), 10).await.unwrap();
        assert_eq!(runs.len(), 1);
        assert_eq!(
            runs[0].scheduled_for,
            UnixMs::from_datetime(utc("2026-11-22T03:00:00Z"))
        );
        let schedule = store
            .schedule(&Owner::anonymous(), &schedule_id("s1"))
            .await
            .unwrap();
        assert_eq!(
            schedule.next_run_at,
            Some(UnixMs::from_datetime(utc("2026-11-23T03:00:00Z")))
        );
        // the next night runs at its time, once
        assert_eq!(
            tick(&store, 100, utc("2026-11-23T03:00:01Z"))
                .await
                .unwrap(),
            1
        );
        assert_eq!(store.runs(&schedule_id("s1"), 10).await.unwrap().len(), 2);
    }

    #[tokio::test]
    async fn a_full_queue_leaves_the_night_due_for_the_next_tick() {
        let store = store_at(&temp_database("full")).await;
        store
            .insert_schedule(&nightly("s1", utc("2026-11-22T03:00:00Z")))
            .await
            .unwrap();
        let now = utc("2026-11-22T03:00:05Z");
        assert_eq!(tick(&store, 0, now).await.unwrap(), 0);
        assert_eq!(
            store
                .due_schedules(UnixMs::from_datetime(now))
                .await
                .unwrap()
                .len(),
            1,
            "still due"
        );
        assert_eq!(tick(&store, 10, now).await.unwrap(), 1);
    }
}
