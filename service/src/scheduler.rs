//! The scheduler loop: every second, each enabled schedule whose next run is due gets one job for
//! its latest due time at or before now (so a server that was down for three nights runs the missed
//! night once, not three times), and its next run moves past now. The (schedule, due time) primary
//! key makes the job unique across restarts and across instances sharing the database.

use crate::api::jobs::rfc3339;
use crate::schedule::Timetable;
use crate::store::{NewJob, NewRun, ScheduleRecord, Store, StoreResult};
use bouncewear_model::InvalidInput;
use bouncewear_model::montecarlo::Job;
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
    for schedule in store.due_schedules(now.timestamp_millis()).await? {
        let Ok(timetable) = Timetable::parse(&schedule.cron, &schedule.time_zone) else {
            tracing::error!(schedule = %schedule.id, "stored schedule no longer parses; skipped");
            continue;
        };
        let Some(due) = timetable.latest_at_or_before(now) else {
            continue;
        };
        let job = match job_from_template(&schedule, due, now) {
            Ok(job) => job,
            Err(invalid) => {
                tracing::error!(schedule = %schedule.id, %invalid, "stored template no longer validates; skipped");
                continue;
            }
        };
        match store
            .create_run(&schedule.id, due.timestamp_millis(), false, job, max_queued)
            .await?
        {
            NewRun::Created(_) => created += 1,
            NewRun::AlreadyExists => {}
            NewRun::QueueFull => {
                tracing::warn!(schedule = %schedule.id, "queue full; the scheduled run waits for the next tick");
                continue;
            }
        }
        let next = timetable.next_after(now).map(|t| t.timestamp_millis());
        store
            .advance_schedule(&schedule.id, schedule.next_run_at, next)
            .await?;
    }
    Ok(created)
}

/// The job a schedule runs at `due`: its template (a seed is drawn for each run when the template has
/// none), named after the schedule and the due time.
pub fn job_from_template(
    schedule: &ScheduleRecord,
    due: DateTime<Utc>,
    now: DateTime<Utc>,
) -> Result<NewJob, InvalidInput> {
    let job = Job::from_json(&schedule.template, crate::cli::draw_seed)?;
    let spec = serde_json::to_string(job.spec())
        .map_err(|e| InvalidInput::single(&bouncewear_model::Pointer::root(), e.to_string()))?;
    Ok(NewJob {
        id: uuid::Uuid::new_v4().to_string(),
        owner: schedule.owner.clone(),
        name: Some(format!(
            "{} @ {}",
            schedule.name,
            rfc3339(due.timestamp_millis())
        )),
        spec,
        operations_total: job.spec().devices.saturating_mul(job.spec().operations),
        created_at: now.timestamp_millis(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::store::sqlite::SqliteStore;

    fn utc(text: &str) -> DateTime<Utc> {
        DateTime::parse_from_rfc3339(text)
            .unwrap()
            .with_timezone(&Utc)
    }

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
            id: id.to_owned(),
            owner: String::new(),
            name: format!("nightly {id}"),
            cron: "0 3 * * *".to_owned(),
            time_zone: "UTC".to_owned(),
            template: r#"{"devices": 2, "operations": 2, "seed": 1}"#.to_owned(),
            statistics: r#"["operations.total_bounce_s.p95"]"#.to_owned(),
            enabled: true,
            next_run_at: Some(next_run_at.timestamp_millis()),
            created_at: 0,
            updated_at: 0,
        }
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
        let runs = store.runs("s1", 10).await.unwrap();
        assert_eq!(runs.len(), 1);
        assert_eq!(
            runs[0].scheduled_for,
            utc("2026-11-22T03:00:00Z").timestamp_millis()
        );
        let schedule = store.schedule("", "s1").await.unwrap().unwrap();
        assert_eq!(
            schedule.next_run_at,
            Some(utc("2026-11-23T03:00:00Z").timestamp_millis())
        );
        // the next night runs at its time, once
        assert_eq!(
            tick(&store, 100, utc("2026-11-23T03:00:01Z"))
                .await
                .unwrap(),
            1
        );
        assert_eq!(store.runs("s1", 10).await.unwrap().len(), 2);
    }

    #[tokio::test]
    async fn two_scheduler_loops_racing_on_one_database_never_duplicate_a_night() {
        let path = temp_database("race");
        let (first, second) = (store_at(&path).await, store_at(&path).await);
        for i in 0..10 {
            first
                .insert_schedule(&nightly(&format!("s{i}"), utc("2026-11-21T03:00:00Z")))
                .await
                .unwrap();
        }
        let now = utc("2026-11-22T04:00:00Z");
        let mut created = 0;
        for _ in 0..5 {
            let (a, b) = tokio::join!(tick(&first, 1000, now), tick(&second, 1000, now));
            created += a.unwrap() + b.unwrap();
        }
        assert_eq!(
            created, 10,
            "one job per schedule and night, whichever loop made it"
        );
        let (queued, _) = first.queue_depth().await.unwrap();
        assert_eq!(queued, 10, "no job without its run row either");
        for i in 0..10 {
            assert_eq!(first.runs(&format!("s{i}"), 10).await.unwrap().len(), 1);
        }
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
                .due_schedules(now.timestamp_millis())
                .await
                .unwrap()
                .len(),
            1,
            "still due"
        );
        assert_eq!(tick(&store, 10, now).await.unwrap(), 1);
    }
}
