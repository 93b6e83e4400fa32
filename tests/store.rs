//! The store's promises, kept by every backend: the same checks against SQLite and against a real
//! PostgreSQL (a throwaway cluster; skipped where PostgreSQL is not installed, required in CI).

use crate::support::postgres::Postgres;
use crate::support::{temp_dir, without_timing};
use bouncewear::compute::thread_pool;
use bouncewear::domain::idempotency::KEY_LIFETIME_MS;
use bouncewear::domain::rare::{RARE_ROUNDS, SHARDED_ROUND_OPERATIONS, is_round};
use bouncewear::domain::shards::{
    Folding, Merged, WHOLE_STEP, grouped_shards, groups_stay_in_shards, merge,
};
use bouncewear::domain::{
    Attempt, IdempotencyKey, JobId, JobStatus, Once, Owner, QueueBound, QueuedJob, ROOM_RETRY_MS,
    ScheduleBound, ScheduleDefinition, ScheduleId, ScheduleLimits, ShardId, UnixMs,
};
use bouncewear::scheduler::{RunLimits, Waiting, rebase, tick};
use bouncewear::store::{
    self, Awaited, EncodedGroups, EncodedResult, JobRecord, Lease, LeaseTerms, NewRun, Operations,
    RetryBudget, RunSlot, ScheduleRecord, Skipped, Store, StoreError,
};
use bouncewear::worker::{HELD_GROUP_BYTES, HeldGroups, Workers};
use bouncewear_model::Pointer;
use bouncewear_model::montecarlo::engine::{Batch, run_group};
use bouncewear_model::montecarlo::{Job, Metric, Silent, rare, run_job};
use bouncewear_model::stats::summarize;
use chrono::{DateTime, Utc};
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio::sync::{Notify, watch};

fn queued(seed: u64) -> QueuedJob {
    queued_job(r#"{"devices": 2, "operations": 3}"#, seed)
}

/// A job of one device: one group and its merge step.
fn single(seed: u64) -> QueuedJob {
    queued_job(r#"{"devices": 1, "operations": 3}"#, seed)
}

/// A job cut into its groups and merge step, however small: what these tests of the queue run.
fn queued_job(text: &str, seed: u64) -> QueuedJob {
    let job = Job::from_json(text, || seed).unwrap();
    let mut queued = QueuedJob::new(&job, Owner::anonymous(), None, UnixMs(1));
    queued.shards = grouped_shards(&job);
    queued
}

/// Three devices at 48 V / 15 A that fail when e1 falls below 0.36: a result with lives.
const WEARING: &str = r#"{"devices": 3, "operations": 40, "seed": 4,
    "scenario": {"circuit": {"supply_voltage_v": 48, "current_a": 15}},
    "failure": {"e1": {"below": 0.36}}}"#;

/// A lease of 1 s taken at `now` on a clock the test steps.
fn terms(now: i64) -> LeaseTerms {
    LeaseTerms {
        at: Some(UnixMs(now)),
        duration_ms: 1000,
    }
}

/// `retries` of each kind.
fn budget(retries: u64) -> RetryBudget {
    RetryBudget {
        failures: retries,
        lost_leases: retries,
    }
}

fn utc(text: &str) -> DateTime<Utc> {
    DateTime::parse_from_rfc3339(text)
        .unwrap()
        .with_timezone(&Utc)
}

/// Every check, on fresh databases that `database(name)` names by URL.
async fn every_promise(database: impl Fn(&str) -> String) {
    a_store_that_takes_writes_and_is_migrated_is_ready(&database("ready")).await;
    unknown_jobs_are_not_found_and_a_second_cancel_is_a_conflict(&database("cancel")).await;
    live_jobs_are_every_active_one_and_any_newer_than_the_mark(&database("live")).await;
    ended_jobs_are_deleted_with_everything_stored_for_them(&database("delete")).await;
    a_key_creates_once_and_refuses_another_body_for_24_hours(&database("keys")).await;
    a_claim_whose_lease_expired_is_fenced_out_by_its_successor(&database("fence")).await;
    a_job_runs_group_by_group_and_its_merge_gives_the_whole_result(&database("shards")).await;
    a_precision_target_queues_its_next_batch_from_the_merge(&database("batches")).await;
    a_job_run_whole_raises_its_total_as_its_batches_are_added(&database("growing")).await;
    a_job_run_whole_in_steps_gives_the_whole_result(&database("steps")).await;
    a_rare_events_rounds_run_as_shards_give_the_whole_result(&database("rounds")).await;
    a_rare_events_last_merge_reads_the_fold_not_a_held_group(&database("held-fold")).await;
    a_precision_target_and_a_rare_event_run_whole_give_the_whole_result(&database("whole-rare"))
        .await;
    a_poison_job_fails_after_the_retry_limit_with_the_reason(&database("poison")).await;
    a_shard_waiting_for_room_counts_nothing_and_is_claimed_again_later(&database("room")).await;
    a_cancelled_job_keeps_no_accumulators(&database("cancel-partials")).await;
    an_ended_jobs_running_shards_stop_with_it(&database("stop")).await;
    a_result_the_database_refuses_for_a_while_is_stored_without_running_again(&database("refused"))
        .await;
    a_result_the_database_keeps_refusing_fails_its_job_at_the_retry_limit(&database("refusing"))
        .await;
    a_result_the_databases_full_disk_refuses_waits_for_room(&database("disk-full")).await;
    retries_racing_a_schedules_delete_make_it_once(&database("schedule-race")).await;
    a_connection_postgresql_ended_is_unreachable(&database("ended")).await;
    a_finishing_merge_locks_its_job_before_its_groups(&database("lock-order")).await;
    lives_beyond_the_listing_cap_are_counted_not_listed(&database("listed")).await;
    a_result_is_stored_once_and_one_stored_whole_before_reads_as_it_was(&database("whole")).await;
    a_large_result_reads_back_whole(&database("large")).await;
    jobs_queued_before_shards_existed_get_theirs_on_open(&database("backfill")).await;
    concurrent_submissions_never_overshoot_the_queue_bound(&database("bound")).await;
    one_owner_fills_only_its_share_of_the_queue(&database("share")).await;
    an_owner_whose_jobs_store_its_quota_gets_no_new_job(&database("quota")).await;
    every_u64_seed_reads_back_exactly(&database("seeds")).await;
    a_job_whose_lease_keeps_expiring_fails_with_the_reason(&database("retries")).await;
    leases_run_on_the_database_clock(&database("db-clock")).await;
    a_job_behind_another_is_served_next(&database("fair")).await;
    two_scheduler_loops_never_duplicate_a_night(&database("race")).await;
    missed_nights_run_once_on_start_up_and_the_next_night_is_tomorrow(&database("catch-up")).await;
    a_full_queue_waits_and_a_key_over_its_quota_skips_the_night(&database("full")).await;
    a_template_that_no_longer_validates_skips_its_night_and_moves_on(&database("stale-template"))
        .await;
    a_clock_that_went_back_brings_the_next_runs_back(&database("clock-back")).await;
    a_schedule_whose_key_is_gone_skips_its_runs(&database("key-gone")).await;
    a_run_comes_only_of_the_schedule_as_the_scheduler_read_it(&database("replaced")).await;
}

async fn a_store_that_takes_writes_and_is_migrated_is_ready(url: &str) {
    let store = store::open(url).await.unwrap();
    store.ready(0, UnixMs(1)).await.unwrap();
    store
        .ready(0, UnixMs(2))
        .await
        .expect("the readiness row is updated");
}

async fn unknown_jobs_are_not_found_and_a_second_cancel_is_a_conflict(url: &str) {
    let store = store::open(url).await.unwrap();
    let owner = Owner::anonymous();
    let missing = store.job(&owner, &JobId::from("nope")).await.unwrap_err();
    assert!(
        matches!(missing, StoreError::NotFound { kind: "job", .. }),
        "{missing}"
    );
    let id = insert(&store, queued(1)).await;
    let cancelled = store.cancel(&owner, &id, Some(UnixMs(2))).await.unwrap();
    assert_eq!(cancelled.status, JobStatus::Cancelled);
    let again = store
        .cancel(&owner, &id, Some(UnixMs(3)))
        .await
        .unwrap_err();
    assert_eq!(
        again.to_string(),
        format!("job {id} already ended: cancelled")
    );
    let other = Owner::of_key("another key");
    assert!(matches!(
        store.cancel(&other, &id, Some(UnixMs(3))).await,
        Err(StoreError::NotFound { .. })
    ));
}

async fn live_jobs_are_every_active_one_and_any_newer_than_the_mark(url: &str) {
    let store = store::open(url).await.unwrap();
    let owner = Owner::anonymous();
    let insert = |seed| {
        let store = store.clone();
        async move {
            store
                .insert_job(queued(seed), QueueBound::total(10))
                .await
                .unwrap()
                .unwrap()
        }
    };
    let active = insert(1).await;
    let ended = insert(2).await;
    store
        .cancel(&owner, &ended.id, Some(UnixMs(2)))
        .await
        .unwrap();
    let newer = insert(3).await;
    store
        .cancel(&owner, &newer.id, Some(UnixMs(3)))
        .await
        .unwrap();
    let job = Job::from_json(r#"{"devices": 2, "operations": 3}"#, || 4).unwrap();
    let others = QueuedJob::new(&job, Owner::of_key("another key"), None, UnixMs(1));
    let others = store
        .insert_job(others, QueueBound::total(10))
        .await
        .unwrap()
        .unwrap();

    let ids = |(records, newest): (Vec<store::JobRecord>, i64)| {
        assert_eq!(newest, others.seq, "the newest seq of all owners");
        records.into_iter().map(|r| r.id).collect::<Vec<_>>()
    };
    // Every owner's: the live view is one for the whole server, each stream picks its own.
    assert_eq!(
        ids(store.live_jobs(ended.seq).await.unwrap()),
        [active.id.clone(), newer.id, others.id.clone()]
    );
    assert_eq!(
        ids(store.live_jobs(i64::MAX).await.unwrap()),
        [active.id, others.id]
    );
}

async fn a_key_creates_once_and_refuses_another_body_for_24_hours(url: &str) {
    let store = store::open(url).await.unwrap();
    let key = IdempotencyKey::new("retry-1", "body A").unwrap();
    let Some(Once::Created(job)) = store
        .insert_job_once(queued(1), QueueBound::total(10), &key, Some(UnixMs(1000)))
        .await
        .unwrap()
    else {
        panic!("the first use of a key creates");
    };
    let again = store
        .insert_job_once(queued(2), QueueBound::total(10), &key, Some(UnixMs(2000)))
        .await;
    assert_eq!(again.unwrap(), Some(Once::Replayed(job)));
    assert_eq!(store.queue_depth().await.unwrap(), (1, 0));
    let other_body = IdempotencyKey::new("retry-1", "body B").unwrap();
    let reused = store
        .insert_job_once(
            queued(3),
            QueueBound::total(10),
            &other_body,
            Some(UnixMs(3000)),
        )
        .await;
    assert_eq!(reused.unwrap(), Some(Once::KeyReused));
    let theirs = Job::from_json(r#"{"devices": 2, "operations": 3}"#, || 4).unwrap();
    let theirs = QueuedJob::new(&theirs, Owner::of_key("another key"), None, UnixMs(1));
    let created = store
        .insert_job_once(theirs, QueueBound::total(10), &key, Some(UnixMs(3000)))
        .await;
    assert!(
        matches!(created.unwrap(), Some(Once::Created(_))),
        "keys are per owner"
    );
    let a_day_later = UnixMs(1000 + KEY_LIFETIME_MS + 1);
    let fresh = store
        .insert_job_once(
            queued(4),
            QueueBound::total(10),
            &other_body,
            Some(a_day_later),
        )
        .await;
    assert!(
        matches!(fresh.unwrap(), Some(Once::Created(_))),
        "forgotten after 24 h"
    );

    let schedule = nightly("s1", "2026-11-22T03:00:00Z");
    let created = store
        .insert_schedule_once(&schedule, SCHEDULES, &key, Some(UnixMs(1)))
        .await;
    assert!(
        matches!(created.unwrap(), Once::Created(_)),
        "keys are per collection"
    );
    // One schedule is the most: a retry still gets the one it created, a new one is refused
    // (with a key or without), and another owner's counts apart.
    let one = ScheduleBound {
        per_owner: 1,
        ..SCHEDULES
    };
    let retry = nightly("s2", "2026-11-22T03:00:00Z");
    let replayed = store
        .insert_schedule_once(&retry, one, &key, Some(UnixMs(2)))
        .await
        .unwrap();
    assert!(matches!(replayed, Once::Replayed(s) if s.id == schedule.id));
    let new_key = IdempotencyKey::new("retry-2", "body C").unwrap();
    let refused = store
        .insert_schedule_once(&retry, one, &new_key, Some(UnixMs(3)))
        .await;
    assert!(matches!(
        refused,
        Err(StoreError::TooManySchedules { most: 1 })
    ));
    let refused = store.insert_schedule(&retry, one).await;
    assert!(matches!(
        refused,
        Err(StoreError::TooManySchedules { most: 1 })
    ));
    let anyone = Owner::anonymous();
    assert_eq!(store.schedules(&anyone, None, 10).await.unwrap().len(), 1);
    let mut theirs = nightly("s3", "2026-11-22T03:00:00Z");
    theirs.owner = Owner::of_key("another key");
    store.insert_schedule(&theirs, one).await.unwrap();

    // Pages, oldest first, each after the last one's seq.
    for id in ["s4", "s5", "s6"] {
        let schedule = nightly(id, "2026-11-22T03:00:00Z");
        store.insert_schedule(&schedule, SCHEDULES).await.unwrap();
    }
    let ids = |page: &[(i64, ScheduleRecord)]| -> Vec<String> {
        page.iter().map(|(_, s)| s.id.to_string()).collect()
    };
    let first = store.schedules(&anyone, None, 2).await.unwrap();
    assert_eq!(ids(&first), ["s1", "s4"]);
    let next = store.schedules(&anyone, Some(first[1].0), 2).await.unwrap();
    assert_eq!(ids(&next), ["s5", "s6"]);
    let last = store.schedules(&anyone, Some(next[1].0), 2).await.unwrap();
    assert!(last.is_empty());
}

/// Retries of a keyed schedule racing its delete make it at most once more, and never fail: a
/// retry that found the schedule deleted after reading its key created it outside the key's
/// lock, and racing retries met on the key's row (500s on PostgreSQL, found from outside).
async fn retries_racing_a_schedules_delete_make_it_once(url: &str) {
    let store = store::open(url).await.unwrap();
    for round in 0..20 {
        let key = IdempotencyKey::new(&format!("racing-{round}"), "body").unwrap();
        let first = nightly(&format!("r{round}"), "2026-11-22T03:00:00Z");
        let created = store.insert_schedule_once(&first, SCHEDULES, &key, Some(UnixMs(1)));
        assert!(matches!(created.await.unwrap(), Once::Created(_)));
        let retries: Vec<_> = (0..8)
            .map(|n| {
                let (store, key) = (Arc::clone(&store), key.clone());
                let retry = nightly(&format!("r{round}-{n}"), "2026-11-22T03:00:00Z");
                tokio::spawn(async move {
                    store
                        .insert_schedule_once(&retry, SCHEDULES, &key, Some(UnixMs(2)))
                        .await
                })
            })
            .collect();
        let anyone = Owner::anonymous();
        store.delete_schedule(&anyone, &first.id).await.unwrap();
        let mut made = 0;
        for retry in retries {
            match retry.await.unwrap() {
                Ok(Once::Created(_)) => made += 1,
                Ok(Once::Replayed(_)) => {}
                other => panic!("round {round}: {other:?}"),
            }
        }
        assert!(made <= 1, "round {round}: made {made} times");
    }
}

/// Room for every schedule a test makes.
const SCHEDULES: ScheduleBound = ScheduleBound {
    per_owner: 100,
    min_free_disk_bytes: 0,
};

async fn ended_jobs_are_deleted_with_everything_stored_for_them(url: &str) {
    let store = store::open(url).await.unwrap();
    let owner = Owner::anonymous();
    let id = insert(&store, queued_job(WEARING, 4)).await;
    let early = store.delete_job(&owner, &id).await.unwrap_err();
    assert_eq!(
        early.to_string(),
        format!("job {id} is queued: cancel it first")
    );
    run_every_shard(store.as_ref()).await;
    let other = Owner::of_key("another key");
    assert!(matches!(
        store.delete_job(&other, &id).await,
        Err(StoreError::NotFound { .. })
    ));
    store.delete_job(&owner, &id).await.unwrap();
    assert!(matches!(
        store.job(&owner, &id).await,
        Err(StoreError::NotFound { .. })
    ));
    assert!(store.result_json(&id).await.unwrap().is_none());
    assert!(store.shards(&id).await.unwrap().is_empty());
    assert!(store.lives(&id).await.unwrap().is_empty());
    assert!(
        store
            .distribution_groups(&id, "e1", every_operation())
            .await
            .unwrap()
            .is_empty()
    );

    // A schedule's run goes with its job; retention takes only what ended before its time.
    let schedule = nightly("s1", "2026-11-22T03:00:00Z");
    store.insert_schedule(&schedule, SCHEDULES).await.unwrap();
    let slot = RunSlot {
        schedule: &schedule.id,
        scheduled_for: UnixMs(5),
        manual: true,
        moves: None,
    };
    let NewRun::Created(run) = store
        .create_run(slot, queued(1), QueueBound::total(10))
        .await
        .unwrap()
    else {
        panic!("the run is created");
    };
    store
        .cancel(&owner, &run.id, Some(UnixMs(10)))
        .await
        .unwrap();
    let recent = insert(&store, queued(2)).await;
    store
        .cancel(&owner, &recent, Some(UnixMs(1000)))
        .await
        .unwrap();
    let waiting = insert(&store, queued(3)).await;
    assert_eq!(store.prune_jobs(0, Some(UnixMs(500))).await.unwrap(), 1);
    assert!(store.runs(&schedule.id, 10).await.unwrap().is_empty());
    assert!(store.job(&owner, &run.id).await.is_err());
    assert_eq!(
        store.job(&owner, &recent).await.unwrap().status,
        JobStatus::Cancelled
    );
    assert_eq!(
        store.job(&owner, &waiting).await.unwrap().status,
        JobStatus::Queued
    );

    // A run asked for as the schedule is deleted finds no schedule: 404, not a foreign key's
    // 500 (an audit met it in 53 of 200 runs raced with deletes).
    store.delete_schedule(&owner, &schedule.id).await.unwrap();
    let slot = RunSlot {
        schedule: &schedule.id,
        scheduled_for: UnixMs(6),
        manual: true,
        moves: None,
    };
    let created = store
        .create_run(slot, queued(4), QueueBound::total(10))
        .await;
    assert!(
        matches!(
            created,
            Err(StoreError::NotFound {
                kind: "schedule",
                ..
            })
        ),
        "{created:?}"
    );
}

async fn a_claim_whose_lease_expired_is_fenced_out_by_its_successor(url: &str) {
    let store = store::open(url).await.unwrap();
    store
        .insert_job(single(1), QueueBound::total(10))
        .await
        .unwrap();
    let first = store
        .claim("a", terms(0), budget(3))
        .await
        .unwrap()
        .unwrap();
    assert_eq!(first.fence.shard, ShardId::group(0, 0));
    assert!(
        store
            .claim("b", terms(500), budget(3))
            .await
            .unwrap()
            .is_none(),
        "the group is leased, and the merge waits for it"
    );
    let second = store
        .claim("b", terms(2000), budget(3))
        .await
        .unwrap()
        .unwrap();
    assert_eq!(second.fence.shard, ShardId::group(0, 0));
    assert_eq!(second.fence.attempt, Attempt(first.fence.attempt.0 + 1));
    assert_eq!(second.spec.seed, Some(1));
    let stats = run_group(
        &Job::new(second.spec.clone(), || 0, &Pointer::root()).unwrap(),
        Batch {
            index: 0,
            first: 0,
            size: 1,
        },
        0,
        &Silent,
    )
    .unwrap();
    assert!(
        !store.complete(&first.fence, &stats).await.unwrap(),
        "fenced out"
    );
    assert_eq!(
        store
            .heartbeat(&first.fence, terms(2100), 5, 5)
            .await
            .unwrap(),
        Lease::Lost
    );
    assert!(
        !store
            .fail(&first.fence, Some(UnixMs(2100)), [0, 0], "late")
            .await
            .unwrap()
    );
    assert_eq!(
        store
            .heartbeat(&second.fence, terms(2100), 5, 5)
            .await
            .unwrap(),
        Lease::Held
    );
}

async fn concurrent_submissions_never_overshoot_the_queue_bound(url: &str) {
    let store = store::open(url).await.unwrap();
    let submissions: Vec<_> = (0..40)
        .map(|seed| {
            let store = Arc::clone(&store);
            tokio::spawn(async move {
                store
                    .insert_job(queued(seed), QueueBound::total(15))
                    .await
                    .unwrap()
            })
        })
        .collect();
    let mut accepted = 0;
    for submission in submissions {
        accepted += usize::from(submission.await.unwrap().is_some());
    }
    assert_eq!(accepted, 15);
    assert_eq!(store.queue_depth().await.unwrap(), (15, 0));
}

async fn a_job_whose_lease_keeps_expiring_fails_with_the_reason(url: &str) {
    let store = store::open(url).await.unwrap();
    let id = insert(&store, single(1)).await;
    // Claimed at t = 0 s; every later claim finds the lease (1 s) expired: its worker died. Lost
    // leases have a budget of their own (2 here), apart from failed runs (0 here).
    let lost = RetryBudget {
        failures: 0,
        lost_leases: 2,
    };
    let mut attempts = 0;
    let mut now = 0;
    while store.claim("w", terms(now), lost).await.unwrap().is_some() {
        attempts += 1;
        now += 2000;
    }
    assert_eq!(attempts, 3, "the first run and two retries");
    let job = store.job(&Owner::anonymous(), &id).await.unwrap();
    assert_eq!(job.status, JobStatus::Failed);
    let reason = job.error.unwrap();
    assert_eq!(
        reason,
        "gave up after 2 retries: the lease of batch 0 group 0 expired 3 times (its worker stopped or stalled, or lost the database, each time)"
    );
    // Its last attempt, whose lease ran out too, reads so, as the job's error tells: a lease
    // lost, the reason its error (as a run that failed its job reads).
    let shards = store.shards(&id).await.unwrap();
    assert_eq!((shards[0].failures, shards[0].lost_leases), (0, 3));
    assert_eq!(shards[0].status, "queued");
    assert_eq!(shards[0].error.as_deref(), Some(reason.as_str()));
    assert_eq!(shards[0].operations_done, 0);
    assert_eq!(
        shards[0].history,
        [
            "attempt 1 (w): lease lost",
            "attempt 2 (w): lease lost",
            "attempt 3 (w): lease lost"
        ],
        "one line per attempt that did not finish"
    );

    // A run that fails counts against the other budget, is claimed again only after its backoff
    // (1 s, then 2 s), and the last reason is kept.
    let id = insert(&store, single(2)).await;
    for attempt in 1..=2 {
        let claim = store
            .claim("w", terms(now), budget(1))
            .await
            .unwrap()
            .unwrap();
        assert_eq!(claim.fence.attempt, Attempt(attempt));
        let reason = format!("boom {attempt}");
        assert!(
            store
                .fail_attempt(&claim.fence, Some(UnixMs(now)), &reason, 1)
                .await
                .unwrap()
        );
        if attempt == 1 {
            assert!(
                store
                    .claim("w", terms(now + 999), budget(1))
                    .await
                    .unwrap()
                    .is_none(),
                "claimed again within its backoff"
            );
            let shards = store.shards(&id).await.unwrap();
            assert_eq!((shards[0].failures, shards[0].lost_leases), (1, 0));
            assert_eq!(shards[0].history, ["attempt 1 (w): failed: boom 1"]);
        }
        now += 1000;
    }
    assert!(
        store
            .claim("w", terms(now + 5000), budget(1))
            .await
            .unwrap()
            .is_none()
    );
    let job = store.job(&Owner::anonymous(), &id).await.unwrap();
    assert_eq!(job.status, JobStatus::Failed);
    assert_eq!(
        job.error.unwrap(),
        "gave up after 1 retries: batch 0 group 0 failed 2 times; the last time: boom 2"
    );
    let shards = store.shards(&id).await.unwrap();
    assert_eq!((shards[0].attempt, shards[0].failures), (Attempt(2), 2));
}

/// Leases run on the database's clock when the worker names no instant (as real workers do):
/// held for their duration, then free for another worker, whatever the workers' own clocks say.
async fn leases_run_on_the_database_clock(url: &str) {
    let store = store::open(url).await.unwrap();
    insert(&store, single(4)).await;
    let lease = LeaseTerms::for_ms(300);
    let first = store.claim("a", lease, budget(3)).await.unwrap().unwrap();
    assert!(
        store.claim("b", lease, budget(3)).await.unwrap().is_none(),
        "held on the database's clock"
    );
    tokio::time::sleep(Duration::from_millis(400)).await;
    let second = store.claim("b", lease, budget(3)).await.unwrap().unwrap();
    assert_eq!(second.fence.shard, first.fence.shard);
    assert_eq!(
        store.heartbeat(&first.fence, lease, 1, 1).await.unwrap(),
        Lease::Lost
    );
    assert_eq!(
        store.heartbeat(&second.fence, lease, 1, 1).await.unwrap(),
        Lease::Held
    );
}

/// Fair share (start-time fair queuing): a job is charged each shard's operations plus 10,000 as
/// it is claimed, a free worker claims for the job with the least virtual start time, and a job
/// joins at the latest start time served. So jobs submitted behind a large one, by the same owner
/// or another, are claimed before its next shard, and the large one still gets its turns.
async fn a_job_behind_another_is_served_next(url: &str) {
    let store = store::open(url).await.unwrap();
    // 64 devices: 32 groups of 6 operations; the others 2 groups of 3.
    let large = insert(&store, queued_job(r#"{"devices": 64, "operations": 3}"#, 1)).await;
    let first = store
        .claim("w", terms(1), budget(3))
        .await
        .unwrap()
        .unwrap();
    assert_eq!(first.fence.job, large);
    let small = insert(&store, queued(2)).await;
    let theirs = QueuedJob {
        owner: Owner::of_key("another key"),
        ..queued(3)
    };
    let theirs = store
        .insert_job(theirs, QueueBound::total(10))
        .await
        .unwrap()
        .unwrap()
        .id;
    let mut order = Vec::new();
    for now in 2..=7 {
        let claim = store
            .claim("w", terms(now), budget(3))
            .await
            .unwrap()
            .unwrap();
        order.push(claim.fence.job.clone());
    }
    // Both joined at 0, where the large job's first group started; it stands at 10,006. After a
    // group of 3 operations each, they stand at 10,003: below it still.
    assert_eq!(
        order,
        [
            small.clone(),
            theirs.clone(),
            small,
            theirs,
            large.clone(),
            large
        ],
        "the least virtual start time, the oldest job at a tie"
    );
}

/// The shards whose accumulators `store` keeps for `job`, in the order a merge reads them.
async fn stored_groups(store: &Store, id: &JobId, job: &Job) -> Vec<ShardId> {
    let read = store.partials(id, Folding::new(job.clone(), u64::MAX));
    read.await.unwrap().read().to_vec()
}

/// Runs every claimable shard of the store's jobs the way workers do, in claim order, until none
/// is left; returns the shards each claim ran. A merge holds the odd groups of its batch, as a
/// worker holds those it ran, and reads the others back.
async fn run_every_shard(store: &Store) -> Vec<ShardId> {
    run_every_shard_keeping(store, groups_stay_in_shards).await
}

/// [`run_every_shard`], a Result leaving its groups in the shards where `in_shards` says, as the
/// workers do by [`groups_stay_in_shards`].
async fn run_every_shard_keeping(
    store: &Store,
    in_shards: fn(&Job, u64, bool) -> bool,
) -> Vec<ShardId> {
    let mut ran = Vec::new();
    let mut odd_groups = Vec::new();
    while let Some(claim) = store.claim("w", terms(0), budget(3)).await.unwrap() {
        let job = Job::new(claim.spec.clone(), || 0, &Pointer::root()).unwrap();
        let fence = &claim.fence;
        ran.push(fence.shard);
        match fence.shard.group {
            Some(group) => {
                let batch = Batch::of(&job, fence.shard.batch).unwrap();
                let stats = run_group(&job, batch, group, &Silent).unwrap();
                assert!(store.complete(fence, &stats).await.unwrap());
                if group % 2 == 1 {
                    odd_groups.push((fence.job.clone(), fence.shard, stats));
                }
            }
            None => {
                let held: Vec<_> = odd_groups
                    .extract_if(.., |(job, shard, _)| {
                        *job == fence.job && shard.batch == fence.shard.batch
                    })
                    .map(|(_, shard, stats)| (shard.group.unwrap(), stats))
                    .collect();
                let partials = Folding::new(job.clone(), fence.shard.batch).holding(held);
                let partials = store.partials(&fence.job, partials).await.unwrap();
                assert_eq!(partials.held().count(), 0, "held groups come without bytes");
                let merged = merge(partials, SHARDED_ROUND_OPERATIONS, 1.0, &Silent).unwrap();
                let through = merged.folded_through();
                let encoding = match in_shards(&job, fence.shard.batch, false) {
                    true => EncodedResult::with_groups_in_shards,
                    false => EncodedResult::new,
                };
                match merged {
                    Merged::Result { mut result, groups } => {
                        // The step ran the rare event's evaluations, if any; the groups the rest.
                        let evaluations = result.rare_event.as_ref().map_or(0, |r| r.evaluations);
                        let ran = evaluations * rare::operations_per_evaluation(&job);
                        let encoded = encoding(&mut result, groups).unwrap();
                        assert!(
                            store
                                .succeed(fence, Some(UnixMs(5)), ran, &encoded)
                                .await
                                .unwrap()
                                .is_some()
                        )
                    }
                    Merged::Next { shards, folded } => {
                        let folded = EncodedGroups::new(folded).unwrap();
                        assert!(
                            store
                                .add_batch(fence, 0, &shards, &folded, through.unwrap(), None)
                                .await
                                .unwrap()
                        );
                        // Only the merged batch keeps accumulators: the fold of all so far.
                        let kept = stored_groups(store, &fence.job, &job).await;
                        assert!(kept.iter().all(|shard| shard.batch == fence.shard.batch));
                        assert_eq!(kept.len(), folded.len());
                    }
                    round @ Merged::Round { .. } => panic!("no rare event asked: {round:?}"),
                }
            }
        }
    }
    ran
}

/// The shards of job `id`, in order.
async fn shard_ids(store: &Store, id: &JobId) -> Vec<ShardId> {
    let shards = store.shards(id).await.unwrap();
    shards.iter().map(|s| s.shard).collect()
}

fn every_operation() -> Operations {
    Operations {
        start: 0,
        end: u64::MAX,
    }
}

async fn a_job_runs_group_by_group_and_its_merge_gives_the_whole_result(url: &str) {
    let store = store::open(url).await.unwrap();
    let text = WEARING;
    let id = insert(&store, queued_job(text, 4)).await;
    let ran = run_every_shard(store.as_ref()).await;
    assert_eq!(
        ran,
        [
            ShardId::group(0, 0),
            ShardId::group(0, 1),
            ShardId::group(0, 2),
            ShardId::merge(0)
        ]
    );
    let job = store.job(&Owner::anonymous(), &id).await.unwrap();
    assert_eq!(job.status, JobStatus::Succeeded);
    assert_eq!((job.operations_done, job.operations_total), (120, 120));
    let whole = run_job(&Job::from_json(text, || 0).unwrap(), &Silent).unwrap();
    assert_eq!(
        without_timing(&store.result_json(&id).await.unwrap().unwrap()),
        without_timing(&serde_json::to_string(&whole).unwrap())
    );
    assert_eq!(store.lives(&id).await.unwrap(), whole.life.unwrap().devices);
    let job = Job::from_json(text, || 0).unwrap();
    assert_eq!(
        stored_groups(store.as_ref(), &id, &job).await.len(),
        3,
        "a job of one batch leaves its groups in its shards, for queries after the run"
    );
    // The same job with its groups in its distribution rows, as a larger job keeps them: its
    // shards keep none, and the two give each bin the same groups, to the bit.
    let in_rows = insert(&store, queued_job(text, 4)).await;
    run_every_shard_keeping(store.as_ref(), |_, _, _| false).await;
    assert!(
        stored_groups(store.as_ref(), &in_rows, &job)
            .await
            .is_empty(),
        "the running accumulators go with the Result"
    );
    // Each distribution has the final groups it summarises, for queries after the run.
    for metric in ["e1", "eroded_mass_kg"] {
        let bins = store
            .distribution(&id, metric, every_operation())
            .await
            .unwrap();
        let groups = store
            .distribution_groups(&id, metric, every_operation())
            .await
            .unwrap();
        let of_rows = store.distribution_groups(&in_rows, metric, every_operation());
        assert_eq!(of_rows.await.unwrap(), groups, "{metric}");
        assert_eq!(groups.len(), bins.len());
        for (bin, groups) in bins.iter().zip(groups) {
            let per_device = Metric::parse(metric)
                .unwrap()
                .values_per_device(bin.op_start..bin.op_end);
            assert_eq!(
                summarize(&groups.unwrap(), per_device),
                bin.summary,
                "{metric}"
            );
        }
    }
    let shards = store.shards(&id).await.unwrap();
    assert!(
        shards
            .iter()
            .all(|s| s.status == "done" && s.attempt == Attempt(1))
    );
    // A query whose job went between its reads (a DELETE takes the job, its rows and its
    // shards at once) finds no job, as a query after the delete: it was a 500 (found from
    // outside). Here the shards alone go, as a read would see them after the rows' read.
    let gone = format!("DELETE FROM shards WHERE job_id = '{id}'");
    match url.starts_with("sqlite:") {
        true => sqlx::raw_sql(sqlx::AssertSqlSafe(gone))
            .execute(&sqlx::SqlitePool::connect(url).await.unwrap())
            .await
            .unwrap(),
        false => sqlx::raw_sql(sqlx::AssertSqlSafe(gone))
            .execute(&sqlx::PgPool::connect(url).await.unwrap())
            .await
            .map(|_| Default::default())
            .unwrap(),
    };
    let read = store
        .distribution_groups(&id, "e1", every_operation())
        .await;
    assert!(matches!(read, Err(StoreError::NotFound { .. })), "{read:?}");
}

/// A Result of over a megabyte (a thousand bins' summaries), which the store puts back together
/// and parses off the async threads, reads back as the job run whole gives it; its ends (what a
/// schedule's trend reads) are the whole Result with each operation metric's last bin alone.
async fn a_large_result_reads_back_whole(url: &str) {
    let store = store::open(url).await.unwrap();
    let text = r#"{"devices": 2, "operations": 100, "seed": 6, "bin_operations": 1}"#;
    let id = insert(&store, queued_job(text, 6)).await;
    run_every_shard(store.as_ref()).await;
    let stored = store.result_json(&id).await.unwrap().unwrap();
    assert!(stored.len() > 1 << 20, "{} bytes", stored.len());
    let parsed = store.result(&id).await.unwrap().unwrap();
    assert_eq!(serde_json::to_string(&parsed).unwrap(), stored);
    let mut whole = run_job(&Job::from_json(text, || 0).unwrap(), &Silent).unwrap();
    assert_eq!(
        without_timing(&stored),
        without_timing(&serde_json::to_string(&whole).unwrap())
    );
    let ends = store.result_ends(&id).await.unwrap().unwrap();
    for bins in whole.operations.values_mut() {
        assert_eq!(bins.len(), 100);
        bins.drain(..99);
    }
    let ends = serde_json::to_string(&ends).unwrap();
    assert!(ends.len() < 1 << 17, "{} bytes", ends.len());
    assert_eq!(
        without_timing(&ends),
        without_timing(&serde_json::to_string(&whole).unwrap())
    );
    let gone = JobId::generate();
    assert!(store.result_ends(&gone).await.unwrap().is_none());
}

async fn a_precision_target_queues_its_next_batch_from_the_merge(url: &str) {
    let store = store::open(url).await.unwrap();
    let text = r#"{"devices": 40, "operations": 2, "seed": 8,
        "scatter": [{"parameter": "impact_velocity_m_s", "per": "device",
                     "distribution": {"kind": "normal", "mean": 0.3, "sd": 0.05, "min": 0.05}}],
        "precision": {"metric": "e1", "relative_half_width": 1e-6, "max_devices": 100}}"#;
    let id = insert(&store, queued_job(text, 8)).await;
    let ran = run_every_shard(store.as_ref()).await;
    let whole = run_job(&Job::from_json(text, || 0).unwrap(), &Silent).unwrap();
    assert_eq!(
        whole.job.devices_run(),
        100,
        "out of reach: every batch runs"
    );
    let mut expected = Vec::new();
    for (batch, groups) in [(0, 32), (1, 32), (2, 20)] {
        expected.extend((0..groups).map(|g| ShardId::group(batch, g)));
        expected.push(ShardId::merge(batch));
    }
    assert_eq!(ran, expected);
    let job = store.job(&Owner::anonymous(), &id).await.unwrap();
    assert_eq!(
        (job.status, job.operations_done, job.operations_total),
        (JobStatus::Succeeded, 200, 200)
    );
    assert_eq!(
        without_timing(&store.result_json(&id).await.unwrap().unwrap()),
        without_timing(&serde_json::to_string(&whole).unwrap())
    );
    // Entered as a submission enters it, the job's batches are too small to shard: one worker
    // runs them all in its one merge step, to the same Result and the same count of operations.
    let queued = QueuedJob::new(
        &Job::from_json(text, || 8).unwrap(),
        Owner::anonymous(),
        None,
        UnixMs(1),
    );
    assert_eq!(queued.shards.len(), 1, "batches of 80 operations run whole");
    let id = insert(&store, queued).await;
    let ended = run_until_ended(&store, workers(&store, 1, u64::MAX), &id, async || {}).await;
    assert_eq!(
        (ended.status, ended.operations_done, ended.operations_total),
        (JobStatus::Succeeded, 200, 200)
    );
    let shards = shard_ids(store.as_ref(), &id).await;
    assert_eq!(shards, [ShardId::merge(0)]);
    assert_eq!(
        without_timing(&store.result_json(&id).await.unwrap().unwrap()),
        without_timing(&serde_json::to_string(&whole).unwrap())
    );
}

/// A rare event's rounds, each run as shards by two real workers (every round sharded), give the
/// Result of the job run whole, whether its devices ran as groups or whole; nothing of them is
/// kept once the Result is stored, and every shard listed was claimed (a job that ran whole keeps
/// its devices' groups in rows of their own during the rounds, which are no shards).
async fn a_rare_events_rounds_run_as_shards_give_the_whole_result(url: &str) {
    let store = store::open(url).await.unwrap();
    let text = r#"{"devices": 3, "operations": 2, "seed": 9,
        "scenario": {"circuit": {"supply_voltage_v": 48, "current_a": 15}},
        "scatter": [{"parameter": "impact_velocity_m_s", "per": "operation",
                     "distribution": {"kind": "normal", "mean": 0.224, "sd": 0.02, "min": 0.01}}],
        "rare_event": {"metric": "total_bounce_s", "above": 0.014, "operation": 2,
                       "method": "subset", "target_cov": 0.5}}"#;
    let job = Job::from_json(text, || 0).unwrap();
    let whole = run_job(&job, &Silent).unwrap();
    assert!(whole.rare_event.is_some());
    let grouped = queued_job(text, 9);
    let ran_whole = QueuedJob::new(&job, Owner::anonymous(), None, UnixMs(1));
    assert_eq!(ran_whole.shards.len(), 1, "a job this small runs whole");
    for (queued, devices) in [
        (
            grouped,
            (0..3).map(|g| ShardId::group(0, g)).collect::<Vec<_>>(),
        ),
        (ran_whole, vec![]),
    ] {
        let id = insert(&store, queued).await;
        let ended = run_rounds(&store, &id, 1).await;
        assert_eq!(ended.status, JobStatus::Succeeded, "{ended:?}");
        let shards = store.shards(&id).await.unwrap();
        let rounds: Vec<ShardId> = shards
            .iter()
            .map(|s| s.shard)
            .filter(|s| is_round(s.batch))
            .collect();
        // A first level, then levels of chains: each round two tasks and a merge step.
        assert!(rounds.len() >= 9, "{rounds:?}");
        for round in [RARE_ROUNDS, RARE_ROUNDS + 1] {
            assert!(rounds.contains(&ShardId::group(round, 1)), "{rounds:?}");
        }
        let of_devices: Vec<ShardId> = shards
            .iter()
            .map(|s| s.shard)
            .filter(|s| !is_round(s.batch))
            .collect();
        assert_eq!(of_devices, [devices, vec![ShardId::merge(0)]].concat());
        // Progress counts the devices' operations and the rounds' (a job run whole counted
        // 2^40 times its operations: the round's batch number taken for a batch of devices).
        let step = shards
            .iter()
            .find(|s| s.shard == ShardId::merge(0))
            .unwrap();
        assert_eq!(step.operations_done, step.operations_total, "{step:?}");
        assert!(step.operations_total < 1 << 30, "{step:?}");
        // Each operation once: the step that queued the first round counts the devices it ran,
        // not the rare event's budget it planned, which the rounds count as they run (it counted
        // both, a probe: 3,870,000 for 1,870,000 run).
        let evaluations = whole.rare_event.as_ref().unwrap().evaluations;
        let ran = 3 * 2 + evaluations * rare::operations_per_evaluation(&job);
        let counted: u64 = shards.iter().map(|s| s.operations_done).sum();
        assert_eq!(counted, ran, "{shards:?}");
        assert_eq!((ended.operations_done, ended.operations_total), (ran, ran));
        assert!(
            shards
                .iter()
                .all(|s| s.status == "done" && s.attempt.0 >= 1),
            "{shards:?}"
        );
        assert_eq!(
            without_timing(&store.result_json(&id).await.unwrap().unwrap()),
            without_timing(&serde_json::to_string(&whole).unwrap())
        );
        assert!(stored_groups(store.as_ref(), &id, &job).await.is_empty());
    }
    // The first level's 1000 evaluations (2000 operations) queued, the chains' 900 run by the
    // merge step that reaches them: each counted once, by its task or by the step (the step's
    // end counted 0, and progress fell by its rounds: a probe).
    let id = insert(&store, queued_job(text, 9)).await;
    let ended = run_rounds(&store, &id, 1900).await;
    assert_eq!(ended.status, JobStatus::Succeeded, "{ended:?}");
    let shards = store.shards(&id).await.unwrap();
    let step_ran = |s: &&store::ShardRecord| is_round(s.shard.batch) && s.shard.group.is_none();
    assert!(
        shards
            .iter()
            .filter(step_ran)
            .any(|s| s.operations_done > 0),
        "a round's step ran rounds itself: {shards:?}"
    );
    let evaluations = whole.rare_event.as_ref().unwrap().evaluations;
    let ran = 3 * 2 + evaluations * rare::operations_per_evaluation(&job);
    let counted: u64 = shards.iter().map(|s| s.operations_done).sum();
    assert_eq!(counted, ran, "{shards:?}");
    assert_eq!((ended.operations_done, ended.operations_total), (ran, ran));
}

/// Runs the queue with two real workers that shard every rare event's round of at least
/// `sharded_from` operations until job `id` ends.
async fn run_rounds(store: &Arc<Store>, id: &JobId, sharded_from: u64) -> JobRecord {
    let mut workers = Arc::into_inner(workers(store, 3, u64::MAX)).unwrap();
    workers.sharded_round_operations = sharded_from;
    let ended = async || ended(store, id).await;
    work_until(
        Arc::new(workers),
        2,
        Duration::from_secs(120),
        async || {},
        ended,
    )
    .await
}

/// Job `id` once it ended, else as it is.
async fn ended(store: &Store, id: &JobId) -> Result<JobRecord, JobRecord> {
    let job = store.job(&Owner::anonymous(), id).await.unwrap();
    if job.status.is_terminal() {
        Ok(job)
    } else {
        Err(job)
    }
}

/// Runs `workers`, `slots` shards at a time, and `meanwhile` beside them, until `done` gives a
/// value (within `limit`, else the test fails with what it gave last); stops them; the value.
async fn work_until<T, U: std::fmt::Debug>(
    workers: Arc<Workers>,
    slots: usize,
    limit: Duration,
    meanwhile: impl AsyncFnOnce(),
    mut done: impl AsyncFnMut() -> Result<T, U>,
) -> T {
    let (stop, stopping) = watch::channel(false);
    let handles = workers.spawn(slots, stopping);
    meanwhile().await;
    let started = Instant::now();
    let value = loop {
        match done().await {
            Ok(value) => break value,
            Err(last) => assert!(started.elapsed() < limit, "{last:?}"),
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
    };
    stop.send(true).unwrap();
    for handle in handles {
        handle.await.unwrap();
    }
    value
}

/// A job run whole with a precision target hands itself on after each step of `whole_step`
/// (here every batch), so that it never holds its worker long: each step is a merge step
/// of its own, the fold of its batches stored at the last one it ran, and the Result is the
/// job's to the bit, its last batch cut short by `max_devices` included.
async fn a_job_run_whole_in_steps_gives_the_whole_result(url: &str) {
    let store = store::open(url).await.unwrap();
    let text = r#"{"devices": 16, "operations": 2, "seed": 9,
        "scatter": [{"parameter": "impact_velocity_m_s", "per": "operation",
                     "distribution": {"kind": "normal", "mean": 0.224, "sd": 0.02, "min": 0.01}}],
        "precision": {"metric": "total_bounce_s", "relative_half_width": 1e-9, "max_devices": 88}}"#;
    let job = Job::from_json(text, || 9).unwrap();
    let whole = run_job(&job, &Silent).unwrap();
    assert_eq!(
        whole.job.devices_run(),
        88,
        "five batches of 16 and one of 8"
    );
    // A batch a step, and all of them in one: each step counts the operations it ran (a step
    // of a second was counted by its last heartbeat, about half of it).
    for (step, last_batches) in [
        (Duration::ZERO, vec![0, 1, 2, 3, 4, 5]),
        (Duration::MAX, vec![0]),
    ] {
        let queued = QueuedJob::new(&job, Owner::anonymous(), None, UnixMs(1));
        let (id, ended) = run_queued(&store, queued, step, SHARDED_ROUND_OPERATIONS).await;
        assert_eq!(ended.status, JobStatus::Succeeded, "{ended:?}");
        assert_eq!((ended.operations_done, ended.operations_total), (176, 176));
        let shards = store.shards(&id).await.unwrap();
        let steps: Vec<(ShardId, u64, u64)> = shards
            .iter()
            .filter(|s| s.shard.group.is_none())
            .map(|s| (s.shard, s.operations_done, s.operations_total))
            .collect();
        let ran = |batch: u64| if batch == 5 { 16 } else { 32 };
        let expected: Vec<_> = last_batches
            .iter()
            .zip(last_batches.iter().skip(1).chain([&6]))
            .map(|(&from, &to)| {
                let operations = (from..to).map(ran).sum();
                (ShardId::merge(from), operations, operations)
            })
            .collect();
        assert_eq!(steps, expected, "steps from batches {last_batches:?}");
        assert!(shards.iter().all(|s| s.status == "done"), "{shards:?}");
        assert_eq!(
            without_timing(&store.result_json(&id).await.unwrap().unwrap()),
            without_timing(&serde_json::to_string(&whole).unwrap())
        );
        assert!(stored_groups(store.as_ref(), &id, &job).await.is_empty());
    }
}

/// A precision target of batches of 16 devices (the last cut to 8 by `max_devices`), then a rare
/// event.
const PRECISION_THEN_RARE_EVENT: &str = r#"{"devices": 16, "operations": 2, "seed": 9,
    "scenario": {"circuit": {"supply_voltage_v": 48, "current_a": 15}},
    "scatter": [{"parameter": "impact_velocity_m_s", "per": "operation",
                 "distribution": {"kind": "normal", "mean": 0.224, "sd": 0.02, "min": 0.01}}],
    "precision": {"metric": "total_bounce_s", "relative_half_width": 1e-9, "max_devices": 40},
    "rare_event": {"metric": "total_bounce_s", "above": 0.014, "operation": 2,
                   "method": "subset", "target_cov": 0.5}}"#;

/// A worker process that ran a group of a precision target's last batch, but not the batch's
/// merge, still holds that group when it later makes the rare event's last merge, which reads the
/// devices' groups back at that batch: their rows hold the fold of every batch then, and the
/// group held is its batch's alone. Taken in place of its row, it left the earlier batches out of
/// the Result (PostgreSQL with two worker processes, found from outside: bins of 3200 values
/// where 4800 ran). Here the batches and merges run by hand, the last batch's group 0 held by the
/// worker that then runs the rounds: the Result is the job's, to the bit. The last batch is cut
/// short by `max_devices` (8 of 16 devices), whose fold of 16 groups failed every last merge.
async fn a_rare_events_last_merge_reads_the_fold_not_a_held_group(url: &str) {
    let store = store::open(url).await.unwrap();
    let text = PRECISION_THEN_RARE_EVENT;
    let job = Job::from_json(text, || 9).unwrap();
    let whole = run_job(&job, &Silent).unwrap();
    assert_eq!(whole.job.devices_run(), 40);
    let id = insert(&store, queued_job(text, 9)).await;
    let mut held = None;
    // The devices' batches, group by group, each merged here; the rounds are left to the worker.
    while let Some(claim) = store.claim("hand", terms(0), budget(3)).await.unwrap() {
        let fence = &claim.fence;
        if is_round(fence.shard.batch) {
            break;
        }
        match fence.shard.group {
            Some(group) => {
                let batch = Batch::of(&job, fence.shard.batch).unwrap();
                let stats = run_group(&job, batch, group, &Silent).unwrap();
                assert!(store.complete(fence, &stats).await.unwrap());
                if fence.shard.batch == 2 && group == 0 {
                    held = Some(stats);
                }
            }
            None => {
                let partials = Folding::new(job.clone(), fence.shard.batch);
                let partials = store.partials(&fence.job, partials).await.unwrap();
                let merged = merge(partials, 1, 1.0, &Silent).unwrap();
                let through = merged.folded_through().unwrap();
                let (shards, folded, state) = match merged {
                    Merged::Next { shards, folded } => (shards, folded, None),
                    Merged::Round {
                        rounds,
                        shards,
                        folded,
                    } => (
                        shards,
                        folded,
                        Some(store::encode("round", &rounds).unwrap()),
                    ),
                    result @ Merged::Result { .. } => {
                        panic!("a rare event comes first: {result:?}")
                    }
                };
                let folded = EncodedGroups::new(folded).unwrap();
                let added = store.add_batch(fence, 0, &shards, &folded, through, state.as_deref());
                assert!(added.await.unwrap());
            }
        }
    }
    let mut workers = Arc::into_inner(workers(&store, 3, u64::MAX)).unwrap();
    workers.sharded_round_operations = 1;
    workers
        .held
        .keep(&id, 2, 0, 1, held.expect("batch 2 ran its group 0 here"));
    let ended = run_until_ended(&store, Arc::new(workers), &id, async || {}).await;
    assert_eq!(ended.status, JobStatus::Succeeded, "{ended:?}");
    assert_eq!(
        without_timing(&store.result_json(&id).await.unwrap().unwrap()),
        without_timing(&serde_json::to_string(&whole).unwrap())
    );
}

/// A precision target followed by a rare event runs whole too, in steps, its rounds after the
/// last step reading the devices' fold from the last batch it ran (cut short by `max_devices`):
/// kept sharded, such a job of 16 devices a batch slowed to 31 devices a second as its shards'
/// rows grew (a probe). The Result is the job's to the bit and progress counts what ran, whether
/// each batch is a step of its own or all are one, and whether the rare event's rounds are run
/// by the last step or sharded.
async fn a_precision_target_and_a_rare_event_run_whole_give_the_whole_result(url: &str) {
    let store = store::open(url).await.unwrap();
    let text = PRECISION_THEN_RARE_EVENT;
    let job = Job::from_json(text, || 9).unwrap();
    let whole = run_job(&job, &Silent).unwrap();
    assert_eq!(
        whole.job.devices_run(),
        40,
        "two batches of 16 and one of 8"
    );
    let queued = QueuedJob::new(&job, Owner::anonymous(), None, UnixMs(1));
    assert_eq!(queued.shards.len(), 1, "it runs whole");
    for (step, sharded_from) in [
        (Duration::ZERO, 1),
        (Duration::MAX, 1),
        (Duration::ZERO, SHARDED_ROUND_OPERATIONS),
    ] {
        let queued = QueuedJob::new(&job, Owner::anonymous(), None, UnixMs(1));
        let (id, ended) = run_queued(&store, queued, step, sharded_from).await;
        assert_eq!(ended.status, JobStatus::Succeeded, "{ended:?}");
        // Every operation run counted once: 40 devices of 2 and each of the estimate's
        // evaluations of 2 (the budget's 400,000, or the estimate's rounds again, before).
        let estimated = whole.rare_event.as_ref().unwrap().evaluations;
        let ran = 80 + 2 * estimated;
        assert_eq!((ended.operations_done, ended.operations_total), (ran, ran));
        let shards = store.shards(&id).await.unwrap();
        let rounds = shards.iter().filter(|s| is_round(s.shard.batch)).count();
        assert_eq!(rounds > 0, sharded_from == 1, "{step:?}: {shards:?}");
        let devices: u64 = shards
            .iter()
            .filter(|s| !is_round(s.shard.batch))
            .map(|s| s.operations_done)
            .sum();
        if sharded_from == 1 {
            // Every round is sharded: the steps ran the devices alone.
            assert_eq!(
                devices, 80,
                "{step:?}: 40 devices of 2 operations: {shards:?}"
            );
        }
        assert_eq!(
            without_timing(&store.result_json(&id).await.unwrap().unwrap()),
            without_timing(&serde_json::to_string(&whole).unwrap()),
            "{step:?}, rounds sharded from {sharded_from}"
        );
        assert!(stored_groups(store.as_ref(), &id, &job).await.is_empty());
    }
    // Cut into groups (as batches beyond WHOLE_JOB_OPERATIONS are): the last batch's merge
    // counts the estimate as it ran, not the budget it planned, whether the target stopped the
    // devices at `max_devices` or sooner, and in the merge or in rounds of their own (a sooner
    // stop counted what a heartbeat caught, often nothing: a probe).
    let early = PRECISION_THEN_RARE_EVENT.replace(
        r#""relative_half_width": 1e-9"#,
        r#""statistic": "mean", "relative_half_width": 0.5"#,
    );
    let early_job = Job::from_json(&early, || 9).unwrap();
    let early_whole = run_job(&early_job, &Silent).unwrap();
    let stopped = early_whole.job.devices_run();
    assert!(stopped < 40, "the target stops it early: {stopped}");
    let evaluations = early_whole.rare_event.as_ref().unwrap().evaluations;
    let estimated = whole.rare_event.as_ref().unwrap().evaluations;
    assert!(2 * estimated < job.rare_event().unwrap().max_operations());
    for (text, result, sharded_from, ran) in [
        (
            PRECISION_THEN_RARE_EVENT,
            &whole,
            SHARDED_ROUND_OPERATIONS,
            80 + 2 * estimated,
        ),
        (
            early.as_str(),
            &early_whole,
            SHARDED_ROUND_OPERATIONS,
            2 * (stopped + evaluations),
        ),
        (early.as_str(), &early_whole, 1, 2 * (stopped + evaluations)),
    ] {
        let queued = queued_job(text, 9);
        let (id, ended) = run_queued(&store, queued, WHOLE_STEP, sharded_from).await;
        assert_eq!(ended.status, JobStatus::Succeeded, "{ended:?}");
        let progress = (ended.operations_done, ended.operations_total);
        assert_eq!(
            progress,
            (ran, ran),
            "{text}, rounds sharded from {sharded_from}"
        );
        assert_eq!(
            without_timing(&store.result_json(&id).await.unwrap().unwrap()),
            without_timing(&serde_json::to_string(result).unwrap())
        );
    }
}

/// Runs one statement on the database behind a store, as an operator (or a failing disk) could:
/// `sqlite` on SQLite, `postgres` on PostgreSQL.
async fn execute(url: &str, sqlite: &'static str, postgres: &'static str) {
    if url.starts_with("sqlite:") {
        let pool = sqlx::SqlitePool::connect(url).await.unwrap();
        sqlx::query(sqlite).execute(&pool).await.unwrap();
    } else {
        let pool = sqlx::PgPool::connect(url).await.unwrap();
        sqlx::query(postgres).execute(&pool).await.unwrap();
    }
}

/// A shard whose outcome the disk had no room for goes back to the queue, its failures and its
/// job untouched, with the reason, and is claimed again only after the room wait; waiting again
/// adds no line to its history.
async fn a_shard_waiting_for_room_counts_nothing_and_is_claimed_again_later(url: &str) {
    let store = store::open(url).await.unwrap();
    let id = insert(&store, single(3)).await;
    let claim = store
        .claim("w", terms(0), budget(0))
        .await
        .unwrap()
        .unwrap();
    let waits = store.wait_for(
        &claim.fence,
        Some(UnixMs(100)),
        Awaited::Room,
        "no room: 2 MB",
    );
    assert!(waits.await.unwrap());
    let shard = store.shards(&id).await.unwrap().remove(0);
    assert_eq!((shard.status.as_str(), shard.failures), ("queued", 0));
    assert_eq!(
        shard.error.as_deref(),
        Some("waiting for room: no room: 2 MB")
    );
    assert_eq!(
        shard.history,
        ["attempt 1 (w): waiting for room: no room: 2 MB"]
    );
    let owner = Owner::anonymous();
    let job = store.job(&owner, &id).await.unwrap();
    assert_eq!(job.status, JobStatus::Running);
    assert_eq!(
        job.waiting.as_deref(),
        Some("waiting for room: no room: 2 MB"),
        "the job says why it waits"
    );
    let early = store.claim("w", terms(100 + ROOM_RETRY_MS - 1), budget(0));
    assert!(early.await.unwrap().is_none(), "claimed before the wait");
    let later = store.claim("w", terms(100 + ROOM_RETRY_MS), budget(0));
    let again = later.await.unwrap().unwrap();
    assert_eq!(again.fence.job, id);
    assert_eq!(
        store.job(&owner, &id).await.unwrap().waiting.as_deref(),
        Some("waiting for room: no room: 2 MB"),
        "claimed again, it says why until it is done: its write may wait again"
    );
    // Waiting again adds no line, for room or for the database.
    let at = Some(UnixMs(200 + ROOM_RETRY_MS));
    let waits = store.wait_for(&again.fence, at, Awaited::Database, "pool timed out");
    assert!(waits.await.unwrap());
    let shard = store.shards(&id).await.unwrap().remove(0);
    assert_eq!(shard.history.len(), 1, "{:?}", shard.history);
    assert_eq!(
        shard.error.as_deref(),
        Some("waiting for the database: pool timed out")
    );
    assert_eq!(shard.failures, 0);
    // Done at last: no error stays, the history keeps the wait.
    let last = store.claim("w", terms(300 + 2 * ROOM_RETRY_MS), budget(0));
    let last = last.await.unwrap().unwrap();
    let job = Job::new(last.spec.clone(), || 0, &Pointer::root()).unwrap();
    let stats = run_group(&job, Batch::of(&job, 0).unwrap(), 0, &Silent).unwrap();
    assert!(store.complete(&last.fence, &stats).await.unwrap());
    let shard = store.shards(&id).await.unwrap().remove(0);
    assert_eq!((shard.status.as_str(), shard.error), ("done", None));
    assert_eq!(shard.history.len(), 1, "{:?}", shard.history);
    assert_eq!(store.job(&owner, &id).await.unwrap().waiting, None);
}

/// A job whose stored accumulators are damaged makes every merge fail: real workers retry it the
/// configured number of times, then the job fails with the reason, instead of looping forever.
async fn a_poison_job_fails_after_the_retry_limit_with_the_reason(url: &str) {
    let store = store::open(url).await.unwrap();
    let id = insert(&store, single(3)).await;
    let claim = store
        .claim("w", terms(0), budget(2))
        .await
        .unwrap()
        .unwrap();
    let job = Job::new(claim.spec.clone(), || 0, &Pointer::root()).unwrap();
    let batch = Batch::of(&job, 0).unwrap();
    let stats = run_group(&job, batch, 0, &Silent).unwrap();
    assert!(store.complete(&claim.fence, &stats).await.unwrap());
    // A gzip header cut short.
    execute(
        url,
        "UPDATE shards SET partial = X'1f8b0800'",
        "UPDATE shards SET partial = '\\x1f8b0800'::bytea",
    )
    .await;

    let failed = run_until_ended(&store, workers(&store, 2, u64::MAX), &id, async || {}).await;
    assert_eq!(failed.status, JobStatus::Failed);
    let reason = failed.error.unwrap();
    assert!(
        reason.starts_with("gave up after 2 retries: batch 0 merge failed 3 times; the last time: reading the groups' accumulators failed: stored group accumulators cannot be read"),
        "{reason}"
    );
    let merge = store.shards(&id).await.unwrap().pop().unwrap();
    assert_eq!(
        (merge.shard, merge.attempt, merge.failures),
        (ShardId::merge(0), Attempt(3), 3)
    );
}

/// A trigger that refuses every Result as a full disk would: a real failure of the database, on
/// the write that stores a job's outcome.
const REFUSE_RESULTS: (&str, &str) = (
    "CREATE TRIGGER refuse_results BEFORE INSERT ON results BEGIN SELECT RAISE(ABORT, 'injected: refused'); END",
    "CREATE FUNCTION refuse_results() RETURNS trigger LANGUAGE plpgsql AS $$ BEGIN \
     RAISE EXCEPTION 'injected: refused'; END $$",
);
/// PostgreSQL's own full disk, as it reports it.
const DISK_FULL: &str = "CREATE FUNCTION refuse_results() RETURNS trigger LANGUAGE plpgsql AS $$ BEGIN \
     RAISE EXCEPTION 'injected: could not extend file: No space left on device' \
     USING ERRCODE = 'disk_full'; END $$";
const REFUSE_RESULTS_ON_INSERT: &str = "CREATE TRIGGER refuse_results BEFORE INSERT ON results FOR EACH ROW EXECUTE FUNCTION refuse_results()";
const ACCEPT_RESULTS: (&str, &str) = (
    "DROP TRIGGER refuse_results",
    "DROP TRIGGER refuse_results ON results",
);

async fn refuse_results(url: &str) {
    execute(url, REFUSE_RESULTS.0, REFUSE_RESULTS.1).await;
    if !url.starts_with("sqlite:") {
        execute(url, "SELECT 1", REFUSE_RESULTS_ON_INSERT).await;
    }
}

/// Inserts a queued job into a queue of ten; its id.
/// A job run whole with a precision target enters the queue with its first batch's operations
/// and learns the rest as its batches are added: each heartbeat raises its total to the end of
/// the batch running, so its progress reads the work still to do (it read done of done).
async fn a_job_run_whole_raises_its_total_as_its_batches_are_added(url: &str) {
    let store = store::open(url).await.unwrap();
    let owner = Owner::anonymous();
    let text = r#"{"devices": 16, "operations": 3, "precision":
        {"metric": "e1", "relative_half_width": 1e-9, "max_devices": 64}}"#;
    let job = Job::from_json(text, || 1).unwrap();
    let id = insert(&store, QueuedJob::new(&job, owner.clone(), None, UnixMs(1))).await;
    let claim = store.claim("w", terms(0), budget(2));
    let claim = claim.await.unwrap().expect("the job's one shard");
    let progress = async || {
        let record = store.job(&owner, &id).await.unwrap();
        (record.operations_done, record.operations_total)
    };
    assert_eq!(progress().await, (0, 48), "the first batch, run whole");
    let beat = async |at: i64, done: u64, total: u64| {
        let lease = store.heartbeat(&claim.fence, terms(at), done, total);
        assert_eq!(lease.await.unwrap(), Lease::Held);
    };
    beat(100, 30, 48).await;
    assert_eq!(progress().await, (30, 48));
    beat(200, 60, 96).await;
    assert_eq!(progress().await, (60, 96), "the second batch's end");
    beat(300, 70, 0).await;
    assert_eq!(progress().await, (70, 96), "a total is never lowered");
    beat(400, 150, 144).await;
    assert_eq!(progress().await, (150, 150), "never below what is done");
    // The step's end counts what it ran, all done, and charges the job (fair share) what it
    // ran beyond the first batch of 48 operations its claim was charged for.
    let vtime = async || -> i64 {
        let sql = "SELECT vtime FROM jobs WHERE id = $1";
        if url.starts_with("sqlite:") {
            let pool = sqlx::SqlitePool::connect(url).await.unwrap();
            sqlx::query_scalar(sql)
                .bind(id.as_str())
                .fetch_one(&pool)
                .await
                .unwrap()
        } else {
            let pool = sqlx::PgPool::connect(url).await.unwrap();
            sqlx::query_scalar(sql)
                .bind(id.as_str())
                .fetch_one(&pool)
                .await
                .unwrap()
        }
    };
    let claimed = vtime().await;
    store.count_run(&claim.fence, 1000, 48).await.unwrap();
    assert_eq!(progress().await, (1000, 1000));
    assert_eq!(vtime().await - claimed, 1000 - 48);
}

async fn insert(store: &Arc<Store>, job: QueuedJob) -> JobId {
    let bound = QueueBound::total(10);
    store.insert_job(job, bound).await.unwrap().unwrap().id
}

/// Real workers with `retries` of each kind, on `store`.
fn workers(store: &Arc<Store>, retries: u64, listed_lives: u64) -> Arc<Workers> {
    Arc::new(Workers {
        store: Arc::clone(store),
        compute: Arc::new(thread_pool(Some(1)).unwrap()),
        lease: Duration::from_secs(30),
        budget: budget(retries),
        instance: "store-test".to_owned(),
        wake: Arc::new(Notify::new()),
        listed_lives,
        large_merges: tokio::sync::Semaphore::new(1),
        sharded_round_operations: SHARDED_ROUND_OPERATIONS,
        whole_step: WHOLE_STEP,
        held: HeldGroups::new(HELD_GROUP_BYTES),
    })
}

/// Inserts `queued` and runs it with three workers whose whole-run steps take `step` and whose
/// rare events shard rounds of `sharded_from` operations or more, until it ends: its id, and the
/// job as it ended.
async fn run_queued(
    store: &Arc<Store>,
    queued: QueuedJob,
    step: Duration,
    sharded_from: u64,
) -> (JobId, JobRecord) {
    let id = insert(store, queued).await;
    let mut workers = Arc::into_inner(workers(store, 3, u64::MAX)).unwrap();
    workers.whole_step = step;
    workers.sharded_round_operations = sharded_from;
    let ended = run_until_ended(store, Arc::new(workers), &id, async || {}).await;
    (id, ended)
}

/// Runs `workers` until job `id` ends, and stops them; the job as it ended.
async fn run_until_ended(
    store: &Arc<Store>,
    workers: Arc<Workers>,
    id: &JobId,
    meanwhile: impl AsyncFnOnce(),
) -> JobRecord {
    let check = async || ended(store, id).await;
    work_until(workers, 1, Duration::from_secs(60), meanwhile, check).await
}

/// A Result the database refuses (for a moment) is written again after a backoff, with the lease
/// kept: once the database takes writes again, the job succeeds without its merge running twice.
async fn a_result_the_database_refuses_for_a_while_is_stored_without_running_again(url: &str) {
    let store = store::open(url).await.unwrap();
    let id = insert(&store, single(6)).await;
    refuse_results(url).await;
    let ended = run_until_ended(&store, workers(&store, 3, u64::MAX), &id, async || {
        // The merge runs, and its first write is refused at once; the retries come after 250 ms
        // and 750 ms, so the database takes writes again before the third.
        let started = Instant::now();
        while store.shards(&id).await.unwrap().last().unwrap().status != "running" {
            assert!(started.elapsed() < Duration::from_secs(30));
            tokio::time::sleep(Duration::from_millis(5)).await;
        }
        tokio::time::sleep(Duration::from_millis(400)).await;
        execute(url, ACCEPT_RESULTS.0, ACCEPT_RESULTS.1).await;
    })
    .await;
    assert_eq!(ended.status, JobStatus::Succeeded, "{ended:?}");
    let merge = store.shards(&id).await.unwrap().pop().unwrap();
    assert_eq!(
        (merge.shard, merge.attempt, merge.failures),
        (ShardId::merge(0), Attempt(1), 0),
        "stored on a retry of the write, not by running the merge again"
    );
    assert!(store.result(&id).await.unwrap().is_some());
}

/// A Result the database never takes counts against the retry limit like a failed run: the job
/// fails with the reason instead of being computed again forever.
async fn a_result_the_database_keeps_refusing_fails_its_job_at_the_retry_limit(url: &str) {
    let store = store::open(url).await.unwrap();
    let id = insert(&store, single(7)).await;
    let spec_only = store
        .job(&Owner::anonymous(), &id)
        .await
        .unwrap()
        .stored_bytes;
    refuse_results(url).await;
    let ended = run_until_ended(&store, workers(&store, 1, u64::MAX), &id, async || {}).await;
    assert_eq!(ended.status, JobStatus::Failed);
    let reason = ended.error.unwrap();
    assert!(
        reason.starts_with("gave up after 1 retries: batch 0 merge failed 2 times; the last time: storing the result failed: ")
            && reason.contains("injected"),
        "{reason}"
    );
    let merge = store.shards(&id).await.unwrap().pop().unwrap();
    assert_eq!((merge.attempt, merge.failures), (Attempt(2), 2));
    assert!(store.result(&id).await.unwrap().is_none());
    assert_eq!(ended.stored_bytes, spec_only, "only the spec stays");
}

/// A Result that PostgreSQL's own full disk refuses (beyond the store's tries) waits for room,
/// as one that the store's free-space check refuses: it failed its job at the retry limit (a
/// probe: three jobs acknowledged, then `failed`, "could not extend file"). SQLite's full file
/// reads the same ([`a_full_sqlite_file_is_out_of_space`]); the wait itself is
/// [`a_shard_waiting_for_room_counts_nothing_and_is_claimed_again_later`]. The hand-back that
/// says so, refused once by the same full disk, is tried again: it left the shard running until
/// its lease expired, counted as lost (a probe at 0 bytes free).
async fn a_result_the_databases_full_disk_refuses_waits_for_room(url: &str) {
    if url.starts_with("sqlite:") {
        return;
    }
    let store = store::open(url).await.unwrap();
    let id = insert(&store, single(8)).await;
    execute(url, "SELECT 1", DISK_FULL).await;
    execute(url, "SELECT 1", REFUSE_RESULTS_ON_INSERT).await;
    execute(url, "SELECT 1", REFUSE_ONE_HAND_BACK.0).await;
    execute(url, "SELECT 1", REFUSE_ONE_HAND_BACK.1).await;
    execute(url, "SELECT 1", REFUSE_ONE_HAND_BACK.2).await;
    let waits = async || {
        let merge = store.shards(&id).await.unwrap().pop().unwrap();
        if merge.error.is_some() {
            Ok(merge)
        } else {
            Err(merge)
        }
    };
    // One try again for a write the disk refuses: the Result's twice, the hand-back's once.
    let workers = workers(&store, 1, u64::MAX);
    let merge = work_until(workers, 1, Duration::from_secs(20), async || {}, waits).await;
    let error = merge.error.unwrap();
    assert!(
        error.starts_with("waiting for room: storing the result: ")
            && error.ends_with("No space left on device (code 53100)"),
        "in PostgreSQL's words and code, not its source's line: {error}"
    );
    let counted = (merge.failures, merge.lost_leases);
    assert_eq!((merge.status.as_str(), counted), ("queued", (0, 0)));
    let refused: (i64,) = sqlx::query_as("SELECT last_value FROM hand_backs_refused")
        .fetch_one(&sqlx::PgPool::connect(url).await.unwrap())
        .await
        .unwrap();
    assert!(
        refused.0 >= 2,
        "the first hand-back was refused and another made"
    );
    let job = store.job(&Owner::anonymous(), &id).await.unwrap();
    assert_eq!(job.status, JobStatus::Running);
    assert_eq!(job.waiting, Some(error));
    execute(url, ACCEPT_RESULTS.0, ACCEPT_RESULTS.1).await;
}

/// A trigger that refuses the first hand-back of a shard waiting for room as a full disk would.
const REFUSE_ONE_HAND_BACK: (&str, &str, &str) = (
    "CREATE SEQUENCE hand_backs_refused",
    "CREATE FUNCTION refuse_a_hand_back() RETURNS trigger LANGUAGE plpgsql AS $$ BEGIN \
     IF nextval('hand_backs_refused') = 1 THEN RAISE EXCEPTION \
     'injected: could not extend file: No space left on device' USING ERRCODE = 'disk_full'; \
     END IF; RETURN NEW; END $$",
    "CREATE TRIGGER refuse_a_hand_back BEFORE UPDATE ON shards FOR EACH ROW \
     WHEN (NEW.error LIKE 'waiting for %') EXECUTE FUNCTION refuse_a_hand_back()",
);

/// A connection PostgreSQL ended (a restart's `terminating connection due to administrator
/// command`, SQLSTATE 57P01) is the database out of reach, not a fault of the statement, also
/// where a migration met it: a process started as PostgreSQL restarted exited at once (found
/// from outside), where it waits for a database that does not answer yet.
async fn a_connection_postgresql_ended_is_unreachable(url: &str) {
    use sqlx::Connection;
    if url.starts_with("sqlite:") {
        return;
    }
    let mut ended = sqlx::PgConnection::connect(url).await.unwrap();
    let (pid,): (i32,) = sqlx::query_as("SELECT pg_backend_pid()")
        .fetch_one(&mut ended)
        .await
        .unwrap();
    let mut admin = sqlx::PgConnection::connect(url).await.unwrap();
    sqlx::query("SELECT pg_terminate_backend($1)")
        .bind(pid)
        .execute(&mut admin)
        .await
        .unwrap();
    let error = sqlx::query("SELECT 1")
        .execute(&mut ended)
        .await
        .unwrap_err();
    let code = error
        .as_database_error()
        .and_then(|e| e.code())
        .map(|code| code.into_owned());
    let unreachable = StoreError::from(error);
    assert!(unreachable.is_unreachable(), "{unreachable}");
    if let Some(code) = code {
        assert_eq!(code, "57P01", "{unreachable}");
    }
    let migrating = StoreError::Migration(sqlx::migrate::MigrateError::Execute(
        sqlx::query("SELECT 1")
            .execute(&mut ended)
            .await
            .unwrap_err(),
    ));
    assert!(migrating.is_unreachable(), "{migrating}");
    let refused = sqlx::query("SELECT * FROM nowhere")
        .execute(&mut admin)
        .await;
    assert!(!StoreError::from(refused.unwrap_err()).is_unreachable());
    // A statement timeout (57014, class 57 as a shutdown is) fails the same way next time: a
    // shard whose Result's write always met one waited for the database for ever (found from
    // a review), where it counts as a failed run and fails its job at the retry limit.
    sqlx::query("SET statement_timeout = 1")
        .execute(&mut admin)
        .await
        .unwrap();
    let timed_out = sqlx::query("SELECT pg_sleep(1)")
        .execute(&mut admin)
        .await
        .unwrap_err();
    let code = timed_out.as_database_error().and_then(|e| e.code());
    assert_eq!(code.as_deref(), Some("57014"), "{timed_out}");
    assert!(!StoreError::from(timed_out).is_unreachable());
    let unsendable = sqlx::Error::Protocol("too many arguments for query: 65536".into());
    assert!(!StoreError::from(unsendable).is_unreachable());
}

/// SQLite's full file (here its page limit) is the disk's state, as PostgreSQL's `disk_full`.
#[tokio::test]
async fn a_full_sqlite_file_is_out_of_space() {
    use sqlx::Connection;
    let path = temp_dir("full-file").join("full.db");
    let url = format!("sqlite://{}?mode=rwc", path.display());
    let mut connection = sqlx::SqliteConnection::connect(&url).await.unwrap();
    for statement in ["CREATE TABLE t (b BLOB)", "PRAGMA max_page_count = 4"] {
        sqlx::query(statement)
            .execute(&mut connection)
            .await
            .unwrap();
    }
    let full = sqlx::query("INSERT INTO t VALUES (zeroblob(100000))")
        .execute(&mut connection)
        .await
        .unwrap_err();
    let full = StoreError::from(full);
    assert!(full.is_out_of_space(), "{full}");
    let refused = sqlx::query("INSERT INTO nowhere VALUES (1)")
        .execute(&mut connection)
        .await
        .unwrap_err();
    assert!(!StoreError::from(refused).is_out_of_space());
}

/// Each device's life is listed up to the workers' cap, across groups, and read back page by page;
/// the life analysis still counts every device.
async fn lives_beyond_the_listing_cap_are_counted_not_listed(url: &str) {
    let store = store::open(url).await.unwrap();
    let text = r#"{"devices": 80, "operations": 30, "seed": 9,
        "scenario": {"circuit": {"supply_voltage_v": 48, "current_a": 15}},
        "failure": {"e1": {"below": 0.4}}}"#;
    let id = insert(&store, queued_job(text, 9)).await;
    let ended = run_until_ended(&store, workers(&store, 1, 25), &id, async || {}).await;
    assert_eq!(ended.status, JobStatus::Succeeded, "{ended:?}");
    let whole = run_job(&Job::from_json(text, || 9).unwrap(), &Silent).unwrap();
    let whole_life = whole.life.unwrap();
    let stored = store.result(&id).await.unwrap().unwrap().life.unwrap();
    assert_eq!(stored.analysis, whole_life.analysis);
    assert_eq!(stored.failures + stored.censored, 80);
    let listed = store.lives(&id).await.unwrap();
    assert_eq!(listed, whole_life.devices[..25]);
    let page = store.lives_page(&id, Some(9), 4).await.unwrap();
    assert_eq!(page, whole_life.devices[10..14]);
    // The spec, the Result, its distributions and 24 bytes per listed life.
    let result_bytes = store.result_json(&id).await.unwrap().unwrap().len() as u64;
    assert!(
        ended.stored_bytes > result_bytes + 25 * 24 && ended.stored_bytes < 3 * result_bytes,
        "{} bytes stored for a result of {result_bytes}",
        ended.stored_bytes
    );
}

/// The Result is stored without its summaries, each kept once in its distribution's row, and read
/// back whole; one stored whole, as builds before that wrote it, reads as it was (here a job
/// without device metrics, whose `devices` is empty either way).
async fn a_result_is_stored_once_and_one_stored_whole_before_reads_as_it_was(url: &str) {
    let store = store::open(url).await.unwrap();
    let text =
        r#"{"devices": 20, "operations": 12, "seed": 3, "metrics": ["total_bounce_s", "e1"]}"#;
    let id = insert(&store, queued_job(text, 3)).await;
    let ended = run_until_ended(&store, workers(&store, 1, 25), &id, async || {}).await;
    assert_eq!(ended.status, JobStatus::Succeeded, "{ended:?}");
    let whole = store.result_json(&id).await.unwrap().unwrap();
    let expected = run_job(&Job::from_json(text, || 3).unwrap(), &Silent).unwrap();
    assert_eq!(
        without_timing(&whole),
        without_timing(&serde_json::to_string(&expected).unwrap())
    );
    // The row as stored, then put back whole as before (SQLite numbers `$N` in order too).
    macro_rules! stored_then_whole {
        ($pool:expr) => {{
            let pool = $pool.unwrap();
            let select = "SELECT result FROM results WHERE job_id = $1";
            let stored: String = sqlx::query_scalar(select)
                .bind(id.as_str())
                .fetch_one(&pool)
                .await
                .unwrap();
            let update = "UPDATE results SET result = $1 WHERE job_id = $2";
            let query = sqlx::query(update).bind(&whole).bind(id.as_str());
            query.execute(&pool).await.unwrap();
            stored
        }};
    }
    let stored = if url.starts_with("sqlite:") {
        stored_then_whole!(sqlx::SqlitePool::connect(url).await)
    } else {
        stored_then_whole!(sqlx::PgPool::connect(url).await)
    };
    assert!(
        stored.contains(r#""operations":{},"devices":{}"#),
        "{stored}"
    );
    assert!(
        stored.len() * 4 < whole.len(),
        "{} of {} bytes",
        stored.len(),
        whole.len()
    );
    assert_eq!(store.result_json(&id).await.unwrap().unwrap(), whole);
}

/// A job of one device and one operation of `owner`.
fn of(owner: &Owner, seed: u64) -> QueuedJob {
    let job = Job::from_json(r#"{"devices": 1, "operations": 1}"#, || seed).unwrap();
    QueuedJob::new(&job, owner.clone(), None, UnixMs(1))
}

async fn one_owner_fills_only_its_share_of_the_queue(url: &str) {
    let store = store::open(url).await.unwrap();
    let bound = QueueBound {
        total: 3,
        per_owner: 2,
        min_free_disk_bytes: 0,
        stored_per_owner: None,
    };
    let (greedy, other) = (Owner::of_key("greedy"), Owner::of_key("other"));
    let mut accepted = Vec::new();
    for (seed, owner) in [&greedy, &greedy, &greedy, &other, &other]
        .into_iter()
        .enumerate()
    {
        let inserted = store
            .insert_job(of(owner, seed as u64), bound)
            .await
            .unwrap();
        accepted.push(inserted.is_some());
    }
    // The greedy key's third is past its share, the other key's second past the whole queue.
    assert_eq!(accepted, [true, true, false, true, false]);
}

async fn an_owner_whose_jobs_store_its_quota_gets_no_new_job(url: &str) {
    let store = store::open(url).await.unwrap();
    let (greedy, other) = (Owner::of_key("greedy"), Owner::of_key("other"));
    let first = store
        .insert_job(of(&greedy, 1), QueueBound::total(10))
        .await
        .unwrap()
        .unwrap();
    // A quota of the first job's spec: it is reached, and only by that owner.
    let bound = QueueBound {
        stored_per_owner: Some(first.stored_bytes),
        ..QueueBound::total(10)
    };
    match store.insert_job(of(&greedy, 2), bound).await {
        Err(StoreError::OverQuota { used, quota }) => {
            assert_eq!((used, quota), (first.stored_bytes, first.stored_bytes));
        }
        other => panic!("expected the quota, got {other:?}"),
    }
    let admitted = |job| async { store.insert_job(job, bound).await.unwrap().is_some() };
    assert!(admitted(of(&other, 3)).await);
    store
        .cancel(&greedy, &first.id, Some(UnixMs(2)))
        .await
        .unwrap();
    store.delete_job(&greedy, &first.id).await.unwrap();
    assert!(admitted(of(&greedy, 4)).await);
}

/// A merge that ends its job locks the job's row before its groups' rows, as a cancel and a
/// claim that fails a job do: it dropped the groups' accumulators first, and a cancel racing it
/// on PostgreSQL deadlocked (the cancel, rolled back, a 503; found from a review). Here another
/// transaction holds the job's row: the ending waits for it with the groups' rows still free.
async fn a_finishing_merge_locks_its_job_before_its_groups(url: &str) {
    if url.starts_with("sqlite:") {
        return; // One writer at a time: no two transactions hold rows at once.
    }
    let store = store::open(url).await.unwrap();
    let id = insert(&store, queued(5)).await;
    let mut merge_claim = None;
    while let Some(claim) = store.claim("w", terms(0), budget(2)).await.unwrap() {
        let job = Job::new(claim.spec.clone(), || 0, &Pointer::root()).unwrap();
        match claim.fence.shard.group {
            Some(group) => {
                let stats = run_group(&job, Batch::of(&job, 0).unwrap(), group, &Silent).unwrap();
                assert!(store.complete(&claim.fence, &stats).await.unwrap());
            }
            None => merge_claim = Some((job, claim.fence)),
        }
    }
    let (job, fence) = merge_claim.expect("the merge step, once its groups are done");
    let partials = store.partials(&id, Folding::new(job, 0)).await.unwrap();
    let merged = merge(partials, SHARDED_ROUND_OPERATIONS, 1.0, &Silent).unwrap();
    let Merged::Result { mut result, groups } = merged else {
        panic!("one batch: {merged:?}");
    };
    let encoded = EncodedResult::new(&mut result, groups).unwrap();
    let holder = sqlx::PgPool::connect(url).await.unwrap();
    let mut holding = holder.begin().await.unwrap();
    sqlx::query("SELECT 1 FROM jobs WHERE id = $1 FOR UPDATE")
        .bind(id.as_str())
        .execute(&mut *holding)
        .await
        .unwrap();
    let ending = tokio::spawn({
        let store = Arc::clone(&store);
        async move { store.succeed(&fence, Some(UnixMs(5)), 0, &encoded).await }
    });
    tokio::time::sleep(Duration::from_millis(300)).await;
    assert!(!ending.is_finished(), "the ending waits for the job's row");
    let mut probe = holder.begin().await.unwrap();
    let groups =
        sqlx::query("SELECT grp FROM shards WHERE job_id = $1 AND grp >= 0 FOR UPDATE NOWAIT")
            .bind(id.as_str())
            .fetch_all(&mut *probe)
            .await;
    assert_eq!(
        groups.map(|rows| rows.len()).map_err(|e| e.to_string()),
        Ok(2)
    );
    probe.rollback().await.unwrap();
    holding.commit().await.unwrap();
    assert!(ending.await.unwrap().unwrap().is_some(), "the job succeeds");
}

async fn a_cancelled_job_keeps_no_accumulators(url: &str) {
    let store = store::open(url).await.unwrap();
    let id = insert(&store, queued(5)).await;
    let claim = store
        .claim("w", terms(0), budget(2))
        .await
        .unwrap()
        .unwrap();
    let job = Job::new(claim.spec.clone(), || 0, &Pointer::root()).unwrap();
    let stats = run_group(&job, Batch::of(&job, 0).unwrap(), 0, &Silent).unwrap();
    assert!(store.complete(&claim.fence, &stats).await.unwrap());
    assert_eq!(stored_groups(store.as_ref(), &id, &job).await.len(), 1);
    let owner = Owner::anonymous();
    let with_group = store.job(&owner, &id).await.unwrap().stored_bytes;
    let cancelled = store.cancel(&owner, &id, Some(UnixMs(9))).await.unwrap();
    assert!(stored_groups(store.as_ref(), &id, &job).await.is_empty());
    // The answer is the job as the cancel left it: its spec alone, the group dropped.
    let spec_only = store.job(&owner, &id).await.unwrap().stored_bytes;
    assert!(spec_only < with_group, "{spec_only} < {with_group}");
    assert_eq!(cancelled.stored_bytes, spec_only);
    assert!(
        store
            .claim("w", terms(0), budget(2))
            .await
            .unwrap()
            .is_none(),
        "a cancelled job's shards are never claimed"
    );
}

/// A job that ends stops its running shards: none reads as running afterwards, each says in its
/// history that the end stopped it, and its worker's claim is gone.
async fn an_ended_jobs_running_shards_stop_with_it(url: &str) {
    let store = store::open(url).await.unwrap();
    let owner = Owner::anonymous();
    let shard_lines = |shards: &[store::ShardRecord]| -> Vec<(String, u64, Vec<String>)> {
        let lines = shards
            .iter()
            .map(|s| (s.status.clone(), s.lost_leases, s.history.clone()));
        lines.collect()
    };
    let line = |text: &str| vec![text.to_owned()];

    // Cancelled with both groups claimed at 0 s: `a` renewed its lease, `b`'s ran out at 1 s (its
    // worker gone); both read as stopped by the end.
    // Both groups of a new job, claimed at 0 s by `a` and `b`.
    let claim_both = async |seed: u64, retries: u64| {
        let id = insert(&store, queued(seed)).await;
        let claim = async |worker: &str| {
            let claimed = store.claim(worker, terms(0), budget(retries)).await;
            claimed.unwrap().unwrap()
        };
        let (a, b) = (claim("a").await, claim("b").await);
        assert_ne!(a.fence.shard, b.fence.shard);
        (id, a, b)
    };
    let (id, a, _) = claim_both(6, 2).await;
    let renewed = store.heartbeat(&a.fence, terms(900), 2, 2).await.unwrap();
    assert_eq!(renewed, Lease::Held);
    store.cancel(&owner, &id, Some(UnixMs(1500))).await.unwrap();
    assert_eq!(
        shard_lines(&store.shards(&id).await.unwrap()),
        [
            (
                "queued".into(),
                0,
                line("attempt 1 (a): stopped: job cancelled")
            ),
            (
                "queued".into(),
                0,
                line("attempt 1 (b): stopped: job cancelled")
            ),
            ("queued".into(), 0, vec![]),
        ]
    );
    assert_eq!(
        store.heartbeat(&a.fence, terms(1600), 3, 3).await.unwrap(),
        Lease::Cancelled
    );
    let job = Job::new(a.spec.clone(), || 0, &Pointer::root()).unwrap();
    let stats = run_group(&job, Batch::of(&job, 0).unwrap(), 0, &Silent).unwrap();
    assert!(
        !store.complete(&a.fence, &stats).await.unwrap(),
        "fenced out"
    );
    assert_eq!(store.job(&owner, &id).await.unwrap().operations_done, 2);

    // Failed by its other group's run: the group still running stops with it.
    let (id, a, b) = claim_both(7, 0).await;
    let failed = store.fail_attempt(&b.fence, Some(UnixMs(500)), "boom", 0);
    assert!(failed.await.unwrap());
    assert_eq!(
        store.job(&owner, &id).await.unwrap().status,
        JobStatus::Failed
    );
    assert_eq!(
        shard_lines(&store.shards(&id).await.unwrap()),
        [
            (
                "queued".into(),
                0,
                line("attempt 1 (a): stopped: job failed")
            ),
            ("queued".into(), 0, line("attempt 1 (b): failed: boom")),
            ("queued".into(), 0, vec![]),
        ]
    );
    assert_eq!(
        store.heartbeat(&a.fence, terms(600), 1, 1).await.unwrap(),
        Lease::Cancelled
    );

    // Failed at once by a run that no retry mends, after 3 operations of it of the 7 it had
    // learnt of (no heartbeat told them) and 2 of the other group's: the run reads as failed, and
    // the job keeps all 5.
    let (id, a, b) = claim_both(8, 2).await;
    let renewed = store.heartbeat(&a.fence, terms(400), 2, 2).await.unwrap();
    assert_eq!(renewed, Lease::Held);
    assert!(
        store
            .fail(&b.fence, Some(UnixMs(500)), [3, 7], "no answer")
            .await
            .unwrap()
    );
    let job = store.job(&owner, &id).await.unwrap();
    assert_eq!(
        (job.status, job.operations_done, job.error.as_deref()),
        (JobStatus::Failed, 5, Some("no answer"))
    );
    let shards = store.shards(&id).await.unwrap();
    assert_eq!(
        shard_lines(&shards),
        [
            (
                "queued".into(),
                0,
                line("attempt 1 (a): stopped: job failed")
            ),
            ("queued".into(), 0, line("attempt 1 (b): failed: no answer")),
            ("queued".into(), 0, vec![]),
        ]
    );
    let failed = &shards[1];
    assert_eq!(
        (
            failed.failures,
            failed.operations_done,
            failed.operations_total,
            failed.error.as_deref()
        ),
        (1, 3, 7, Some("no answer"))
    );
}

/// Rows written before migration 0005 have no shards: opening the store cuts them as a
/// submission does.
async fn jobs_queued_before_shards_existed_get_theirs_on_open(url: &str) {
    let store = store::open(url).await.unwrap();
    let id = insert(&store, queued(6)).await;
    execute(url, "DELETE FROM shards", "DELETE FROM shards").await;
    assert!(
        store
            .claim("w", terms(0), budget(2))
            .await
            .unwrap()
            .is_none()
    );
    drop(store);
    let store = store::open(url).await.unwrap();
    let shards = shard_ids(store.as_ref(), &id).await;
    // Cut as a submission cuts it: a job this small runs whole, as its first merge step.
    assert_eq!(shards, [ShardId::merge(0)]);
    let claim = store
        .claim("w", terms(0), budget(2))
        .await
        .unwrap()
        .unwrap();
    assert_eq!(
        (claim.fence.job, claim.fence.shard, claim.operations_total),
        (id, ShardId::merge(0), 6)
    );
}

async fn every_u64_seed_reads_back_exactly(url: &str) {
    let store = store::open(url).await.unwrap();
    for seed in [0, 1 << 53, i64::MAX as u64 + 1, u64::MAX] {
        let id = store
            .insert_job(queued(seed), QueueBound::total(10))
            .await
            .unwrap()
            .unwrap()
            .id;
        assert_eq!(
            store.job(&Owner::anonymous(), &id).await.unwrap().seed,
            seed
        );
        // The job and its spec in one read, as GET /v1/jobs/{id} shows them.
        let (record, spec) = store.job_with_spec(&Owner::anonymous(), &id).await.unwrap();
        assert_eq!(record, store.job(&Owner::anonymous(), &id).await.unwrap());
        assert_eq!(
            (spec.seed, spec.devices, spec.operations),
            (Some(seed), 2, 3)
        );
    }
    let missing = store
        .job_with_spec(&Owner::anonymous(), &JobId::from("nope"))
        .await;
    assert!(matches!(
        missing,
        Err(StoreError::NotFound { kind: "job", .. })
    ));
}

/// A nightly schedule (03:00 UTC) of a tiny job, next due at `next_run_at`.
fn nightly(id: &str, next_run_at: &str) -> ScheduleRecord {
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
        next_run_at: Some(UnixMs::from_datetime(utc(next_run_at))),
        created_at: UnixMs(0),
        updated_at: UnixMs(0),
        skipped: Skipped::default(),
        revision: 0,
    }
}

/// The reason of `schedule`'s one skipped run, which was due at `due`.
async fn one_skip_at(store: &Store, schedule: &ScheduleRecord, due: &str) -> String {
    let (runs, last) = skipped(store, schedule).await;
    let (skipped_due, reason) = last.expect("the skipped run");
    assert_eq!((runs, skipped_due.as_str()), (1, due));
    reason
}

/// The runs `schedule` skipped as stored: how many, the latest one's due time and its reason.
async fn skipped(store: &Store, schedule: &ScheduleRecord) -> (u64, Option<(String, String)>) {
    let stored = store.schedule(&schedule.owner, &schedule.id).await.unwrap();
    let last = stored
        .skipped
        .last
        .map(|(due, reason)| (due.to_rfc3339(), reason));
    (stored.skipped.runs, last)
}

async fn two_scheduler_loops_never_duplicate_a_night(url: &str) {
    let (first, second): (Arc<Store>, Arc<Store>) = (
        store::open(url).await.unwrap(),
        store::open(url).await.unwrap(),
    );
    for i in 0..10 {
        let schedule = nightly(&format!("s{i}"), "2026-11-21T03:00:00Z");
        first.insert_schedule(&schedule, SCHEDULES).await.unwrap();
    }
    let now = utc("2026-11-22T04:00:00Z");
    let mut created = 0;
    let (mut waiting_a, mut waiting_b) = (Waiting::default(), Waiting::default());
    for _ in 0..5 {
        let (a, b) = tokio::join!(
            tick(
                first.as_ref(),
                queue(QueueBound::total(1000)),
                now,
                &mut waiting_a
            ),
            tick(
                second.as_ref(),
                queue(QueueBound::total(1000)),
                now,
                &mut waiting_b
            )
        );
        created += a.unwrap() + b.unwrap();
    }
    assert_eq!(
        created, 10,
        "one job per schedule and night, whichever loop made it"
    );
    assert_eq!(
        first.queue_depth().await.unwrap(),
        (10, 0),
        "no job without its run row"
    );
    for i in 0..10 {
        let runs = first
            .runs(&ScheduleId::from(format!("s{i}")), 10)
            .await
            .unwrap();
        assert_eq!(runs.len(), 1);
    }
}

async fn missed_nights_run_once_on_start_up_and_the_next_night_is_tomorrow(url: &str) {
    let store = store::open(url).await.unwrap();
    let id = ScheduleId::from("s1");
    store
        .insert_schedule(&nightly("s1", "2026-11-19T03:00:00Z"), SCHEDULES)
        .await
        .unwrap();
    // The server was down for three nights; it starts at 08:00.
    let now = utc("2026-11-22T08:00:00Z");
    let tick_at = async |now| tick_now(&store, 100, now, &mut Waiting::default()).await;
    assert_eq!(tick_at(now).await, 1);
    assert_eq!(
        tick_at(now).await,
        0,
        "a restart the same morning adds nothing"
    );
    let runs = store.runs(&id, 10).await.unwrap();
    assert_eq!(runs.len(), 1);
    assert_eq!(
        runs[0].scheduled_for,
        UnixMs::from_datetime(utc("2026-11-22T03:00:00Z"))
    );
    let schedule = store.schedule(&Owner::anonymous(), &id).await.unwrap();
    assert_eq!(
        schedule.next_run_at,
        Some(UnixMs::from_datetime(utc("2026-11-23T03:00:00Z")))
    );
    // The nights before the one run are skipped, and the schedule says so.
    let (runs, last) = skipped(&store, &schedule).await;
    let (at, reason) = last.unwrap();
    assert_eq!((runs, at.as_str()), (3, "2026-11-21T03:00:00.000Z"));
    assert!(reason.starts_with("not run at its due time"), "{reason}");
    // The next night runs at its time, once.
    let next_night = utc("2026-11-23T03:00:01Z");
    assert_eq!(tick_at(next_night).await, 1);
    assert_eq!(store.runs(&id, 10).await.unwrap().len(), 2);
}

/// One scheduler tick at `now` with room for `room` jobs in the queue; the jobs it created.
async fn tick_now(store: &Store, room: u64, now: DateTime<Utc>, waiting: &mut Waiting) -> usize {
    tick(store, queue(QueueBound::total(room)), now, waiting)
        .await
        .unwrap()
}

/// The scheduler's limits with room for every run and no bound on a job's size.
fn queue(bound: QueueBound) -> RunLimits {
    RunLimits {
        queue: bound,
        schedule: ScheduleLimits {
            max_job_operations: u64::MAX,
            min_interval: chrono::TimeDelta::zero(),
        },
        key_owners: Arc::default(),
    }
}

/// The scheduler's limits with room for 100 jobs, bounding each run's size and how often it runs.
fn allowing(max_job_operations: u64, min_interval: chrono::TimeDelta) -> RunLimits {
    RunLimits {
        schedule: ScheduleLimits {
            max_job_operations,
            min_interval,
        },
        ..queue(QueueBound::total(100))
    }
}

/// A schedule whose stored template no longer validates (a rule made since) skips its run and
/// moves on to the next night: it stayed due, skipped and logged again at every tick (a second).
async fn a_template_that_no_longer_validates_skips_its_night_and_moves_on(url: &str) {
    let store = store::open(url).await.unwrap();
    let mut schedule = nightly("s1", "2026-11-22T03:00:00Z");
    schedule.definition.template = serde_json::from_str(r#"{"devices": 0}"#).unwrap();
    store.insert_schedule(&schedule, SCHEDULES).await.unwrap();
    let now = utc("2026-11-22T03:00:05Z");
    let mut waiting = Waiting::default();
    assert_eq!(tick_now(&store, 100, now, &mut waiting).await, 0);
    assert!(store.runs(&schedule.id, 10).await.unwrap().is_empty());
    let stored = store
        .schedule(&Owner::anonymous(), &schedule.id)
        .await
        .unwrap();
    assert_eq!(
        stored.next_run_at,
        Some(UnixMs::from_datetime(utc("2026-11-23T03:00:00Z")))
    );
    // The lost night shows on the schedule, with why: it was in the log only.
    let (runs, last) = skipped(&store, &schedule).await;
    assert_eq!(runs, 1);
    let (due, reason) = last.expect("the skipped run");
    assert_eq!(due, "2026-11-22T03:00:00.000Z");
    assert!(
        reason.starts_with("the template is refused by this server now: ")
            && reason.contains("/devices"),
        "{reason}"
    );
    // A timetable this build no longer reads (written by another): skipped, and stopped until a
    // PUT, rather than due and logged again every second.
    let mut unreadable = nightly("s3", "2026-11-22T03:00:00Z");
    unreadable.definition.time_zone = "Europe/Atlantis".to_owned();
    store.insert_schedule(&unreadable, SCHEDULES).await.unwrap();
    assert_eq!(tick_now(&store, 100, now, &mut waiting).await, 0);
    let reason = one_skip_at(&store, &unreadable, "2026-11-22T03:00:00.000Z").await;
    assert!(
        reason.contains("Europe/Atlantis") && reason.contains("PUT"),
        "{reason}"
    );
    let stored = store
        .schedule(&unreadable.owner, &unreadable.id)
        .await
        .unwrap();
    assert_eq!(stored.next_run_at, None);
    // A template larger than the server now allows (a limit lowered since it was written, or
    // another instance's) skips its run the same way: it ran, unbounded.
    let mut large = nightly("s2", "2026-11-22T03:00:00Z");
    large.definition.template =
        serde_json::from_str(r#"{"devices": 100, "operations": 100}"#).unwrap();
    store.insert_schedule(&large, SCHEDULES).await.unwrap();
    let any_interval = chrono::TimeDelta::zero();
    let created = tick(
        store.as_ref(),
        allowing(9_999, any_interval),
        now,
        &mut waiting,
    );
    assert_eq!(created.await.unwrap(), 0);
    assert!(store.runs(&large.id, 10).await.unwrap().is_empty());
    let next_night = utc("2026-11-23T03:00:05Z");
    let limits = allowing(10_000, any_interval);
    let created = tick(store.as_ref(), limits, next_night, &mut waiting);
    let (runs, last) = skipped(&store, &large).await;
    assert_eq!(runs, 1);
    let reason = last.unwrap().1;
    assert!(reason.contains("this server allows 9999"), "{reason}");
    assert_eq!(
        created.await.unwrap(),
        1,
        "within the limit, the next night runs"
    );
    let (runs, last) = skipped(&store, &large).await;
    assert_eq!(runs, 1, "a run made is no skip");
    assert_eq!(last.unwrap().0, "2026-11-22T03:00:00.000Z");
    // The first schedule's template is still refused: its next night is skipped too.
    let (runs, last) = skipped(&store, &schedule).await;
    assert_eq!(
        (runs, last.unwrap().0.as_str()),
        (2, "2026-11-23T03:00:00.000Z")
    );
    // A timetable that runs more often than the server now allows (a limit raised since it was
    // written, or another instance's) skips its runs the same way: they ran every hour under a
    // limit of a day. Within the limit, the next one runs.
    let mut hourly = nightly("s4", "2026-11-23T04:00:00Z");
    hourly.definition.cron = "0 * * * *".to_owned();
    store.insert_schedule(&hourly, SCHEDULES).await.unwrap();
    let every = |hours| allowing(10_000, chrono::TimeDelta::hours(hours));
    let at_four = utc("2026-11-23T04:00:05Z");
    let created = tick(store.as_ref(), every(24), at_four, &mut waiting);
    assert_eq!(created.await.unwrap(), 0);
    let reason = one_skip_at(&store, &hourly, "2026-11-23T04:00:00.000Z").await;
    assert!(
        reason.contains("runs 1 h apart") && reason.contains("--min-schedule-interval-seconds"),
        "{reason}"
    );
    let at_five = utc("2026-11-23T05:00:05Z");
    let created = tick(store.as_ref(), every(1), at_five, &mut waiting);
    assert_eq!(created.await.unwrap(), 1);
    assert_eq!(store.runs(&hourly.id, 10).await.unwrap().len(), 1);
    // A second loop (another instance) that read the schedule before the first skipped its run
    // moves nothing and counts nothing.
    assert!(
        !store
            .skip_run(
                &schedule.id,
                schedule.moving_to(None),
                UnixMs::from_datetime(now),
                "again"
            )
            .await
            .unwrap()
    );
    assert_eq!(skipped(&store, &schedule).await.0, 2);
}

/// A PUT that lands between the scheduler's read of a due schedule and its run stops that run: a
/// probe with three nodes saw runs of a disabled schedule's old definition committed up to 1.5 s
/// after the PUT's 200, and a cron replaced under a kept due time run at a past time of the new
/// one. The run, and the move of the next run, are made only of the schedule as read.
async fn a_run_comes_only_of_the_schedule_as_the_scheduler_read_it(url: &str) {
    let store = store::open(url).await.unwrap();
    let schedule = nightly("s1", "2026-11-22T03:00:00Z");
    store.insert_schedule(&schedule, SCHEDULES).await.unwrap();
    let now = utc("2026-11-22T03:00:01Z");
    let read = store
        .due_schedules(UnixMs::from_datetime(now))
        .await
        .unwrap();
    let read = read.into_iter().next().unwrap();
    let tomorrow = Some(UnixMs::from_datetime(utc("2026-11-23T03:00:00Z")));
    // Replaced meanwhile: the same due time kept, another template.
    let mut replaced = read.clone();
    replaced.definition.template =
        serde_json::from_str(r#"{"devices": 3, "operations": 2, "seed": 2}"#).unwrap();
    assert_eq!(store.update_schedule(&replaced, &read).await.unwrap(), None);
    let slot = RunSlot {
        schedule: &read.id,
        scheduled_for: read.next_run_at.unwrap(),
        manual: false,
        moves: Some(read.moving_to(tomorrow)),
    };
    let made = store.create_run(slot, queued(1), QueueBound::total(10));
    assert!(matches!(made.await.unwrap(), NewRun::Moved));
    assert!(store.runs(&read.id, 10).await.unwrap().is_empty());
    assert!(
        !store
            .skip_run(
                &read.id,
                read.moving_to(tomorrow),
                slot.scheduled_for,
                "stale"
            )
            .await
            .unwrap()
    );
    // The next tick reads the schedule as replaced and runs its template.
    assert_eq!(tick_now(&store, 10, now, &mut Waiting::default()).await, 1);
    let runs = store.runs(&read.id, 10).await.unwrap();
    let job = store.job(&read.owner, &runs[0].job_id).await.unwrap();
    assert_eq!(job.operations_total, 6, "3 devices of 2 operations");
    let stored = store.schedule(&read.owner, &read.id).await.unwrap();
    assert_eq!(stored.next_run_at, tomorrow);
    assert_eq!(stored.revision, 1);
    // A PUT worked out from a read the run has moved on from writes nothing: it would put the
    // schedule back on the night just run.
    let moved = store.update_schedule(&replaced, &replaced).await.unwrap();
    assert_eq!(
        moved,
        Some(stored.clone()),
        "nothing written: the schedule as it is"
    );
    assert_eq!(store.schedule(&read.owner, &read.id).await.unwrap(), stored);

    // Disabled after the read: no run, and it stays disabled.
    let disabled = nightly("s2", "2026-11-22T03:00:00Z");
    store.insert_schedule(&disabled, SCHEDULES).await.unwrap();
    let read = store.schedule(&disabled.owner, &disabled.id).await.unwrap();
    let off = ScheduleRecord {
        next_run_at: None,
        definition: ScheduleDefinition {
            enabled: false,
            ..read.definition.clone()
        },
        ..read.clone()
    };
    assert_eq!(store.update_schedule(&off, &read).await.unwrap(), None);
    let slot = RunSlot {
        schedule: &read.id,
        ..slot
    };
    let made = store.create_run(slot, queued(2), QueueBound::total(10));
    assert!(matches!(made.await.unwrap(), NewRun::Moved));
    assert!(store.runs(&read.id, 10).await.unwrap().is_empty());
    let stored = store.schedule(&read.owner, &read.id).await.unwrap();
    assert_eq!(stored.next_run_at, None);

    // A due time its timetable does not give (stored before a replaced cron moved it): the latest
    // time the timetable gives is before it, so nothing is owed; the schedule moves on.
    let moved = nightly("s3", "2026-11-22T05:00:00Z");
    store.insert_schedule(&moved, SCHEDULES).await.unwrap();
    let later = utc("2026-11-22T05:30:00Z");
    assert_eq!(
        tick_now(&store, 10, later, &mut Waiting::default()).await,
        0
    );
    assert!(store.runs(&moved.id, 10).await.unwrap().is_empty());
    let stored = store.schedule(&moved.owner, &moved.id).await.unwrap();
    assert_eq!(stored.next_run_at, tomorrow);
}

/// A clock that went back (between ticks, or while the server was down) left each next run where
/// the later clock put it: a day back, a night was missed, as a probe with libfaketime saw. The
/// next runs later than the timetable gives from now come back to it; the others stay.
async fn a_clock_that_went_back_brings_the_next_runs_back(url: &str) {
    let store = store::open(url).await.unwrap();
    // Worked out on a clock two days ahead, on time, and disabled.
    let ahead = nightly("ahead", "2026-11-24T03:00:00Z");
    let on_time = nightly("on-time", "2026-11-23T03:00:00Z");
    let mut disabled = nightly("disabled", "2026-11-24T03:00:00Z");
    disabled.definition.enabled = false;
    disabled.next_run_at = None;
    for schedule in [&ahead, &on_time, &disabled] {
        store.insert_schedule(schedule, SCHEDULES).await.unwrap();
    }
    let now = utc("2026-11-22T12:00:00Z");
    assert_eq!(rebase(store.as_ref(), now).await.unwrap(), 1);
    for (schedule, next) in [
        (&ahead, Some("2026-11-23T03:00:00.000Z")),
        (&on_time, Some("2026-11-23T03:00:00.000Z")),
        (&disabled, None),
    ] {
        let stored = store.schedule(&schedule.owner, &schedule.id).await.unwrap();
        assert_eq!(
            stored.next_run_at.map(UnixMs::to_rfc3339).as_deref(),
            next,
            "{}",
            schedule.id
        );
    }
    assert_eq!(rebase(store.as_ref(), now).await.unwrap(), 0, "once");
    // The night comes: both run.
    let mut waiting = Waiting::default();
    let night = utc("2026-11-23T03:00:01Z");
    assert_eq!(tick_now(&store, 10, night, &mut waiting).await, 2);
}

/// On a server with API keys, a schedule whose key was removed from them skips its runs: no
/// caller could see, pause or delete it, and it ran on (a probe: a revoked key's `* * * * *`
/// schedule made a job a minute). The keys' own schedules run.
async fn a_schedule_whose_key_is_gone_skips_its_runs(url: &str) {
    let store = store::open(url).await.unwrap();
    let mut kept = nightly("kept", "2026-11-22T03:00:00Z");
    kept.owner = Owner::of_key("alpha");
    let mut gone = nightly("gone", "2026-11-22T03:00:00Z");
    gone.owner = Owner::of_key("beta");
    for schedule in [&kept, &gone] {
        store.insert_schedule(schedule, SCHEDULES).await.unwrap();
    }
    let limits = RunLimits {
        key_owners: Arc::new([Owner::of_key("alpha")].into()),
        ..queue(QueueBound::total(10))
    };
    let mut waiting = Waiting::default();
    let created = tick(
        store.as_ref(),
        limits,
        utc("2026-11-22T03:00:01Z"),
        &mut waiting,
    );
    assert_eq!(created.await.unwrap(), 1);
    assert_eq!(store.runs(&kept.id, 10).await.unwrap().len(), 1);
    assert!(store.runs(&gone.id, 10).await.unwrap().is_empty());
    let (runs, last) = skipped(&store, &gone).await;
    let (due, reason) = last.expect("the skipped run");
    assert_eq!((runs, due.as_str()), (1, "2026-11-22T03:00:00.000Z"));
    assert!(reason.contains("API key"), "{reason}");
    assert_eq!(skipped(&store, &kept).await, (0, None));
}

async fn a_full_queue_waits_and_a_key_over_its_quota_skips_the_night(url: &str) {
    let store = store::open(url).await.unwrap();
    store
        .insert_schedule(&nightly("s1", "2026-11-22T03:00:00Z"), SCHEDULES)
        .await
        .unwrap();
    let now = utc("2026-11-22T03:00:05Z");
    let mut waiting = Waiting::default();
    for _ in 0..2 {
        assert_eq!(tick_now(&store, 0, now, &mut waiting).await, 0);
        assert!(waiting.contains(&ScheduleId::from("s1")), "warned of once");
    }
    let due = store
        .due_schedules(UnixMs::from_datetime(now))
        .await
        .unwrap();
    assert_eq!(due.len(), 1, "still due");
    // A key whose jobs store its quota skips the run (it would stay over until it deletes some),
    // and the tick goes on to the other schedules: another key's runs.
    insert(&store, queued(7)).await;
    let mut other = nightly("s2", "2026-11-22T03:00:00Z");
    other.owner = Owner::of_key("other");
    store.insert_schedule(&other, SCHEDULES).await.unwrap();
    let over_quota = QueueBound {
        stored_per_owner: Some(1),
        ..QueueBound::total(10)
    };
    let created = tick(store.as_ref(), queue(over_quota), now, &mut waiting);
    assert_eq!(created.await.unwrap(), 1);
    assert!(
        !waiting.contains(&ScheduleId::from("s1")),
        "no longer waiting: skipped"
    );
    let due = store
        .due_schedules(UnixMs::from_datetime(now))
        .await
        .unwrap();
    assert!(due.is_empty(), "both moved on: {due:?}");
    for (schedule, runs) in [("s1", 0), ("s2", 1)] {
        let made = store.runs(&ScheduleId::from(schedule), 10).await.unwrap();
        assert_eq!(made.len(), runs, "{schedule}");
    }
    let (runs, last) = skipped(&store, &nightly("s1", "2026-11-22T03:00:00Z")).await;
    let (due, reason) = last.expect("the skipped run");
    assert_eq!((runs, due.as_str()), (1, "2026-11-22T03:00:00.000Z"));
    assert!(reason.contains("quota"), "{reason}");
    assert_eq!(skipped(&store, &other).await, (0, None));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sqlite_keeps_every_promise() {
    let dir = temp_dir("store-sqlite");
    every_promise(|name| format!("sqlite://{}", dir.join(format!("{name}.db")).display())).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn postgres_keeps_every_promise() {
    let Some(cluster) = Postgres::start(&temp_dir("store-postgres")) else {
        return;
    };
    every_promise(|name| cluster.database(name)).await;
    postgres_announces_queued_jobs_and_their_progress(&cluster.database("events")).await;
    a_dropped_store_closes_every_connection(&cluster.database("dropped")).await;
    compressed_accumulators_are_stored_without_pglz(&cluster.database("storage")).await;
    postgres_says_why_it_gives_no_connection(&cluster.database("why")).await;
    a_heartbeat_that_outlives_its_jobs_end_leaves_its_progress(&cluster.database("late")).await;
}

/// A heartbeat begun while its job ran and finished after the job was cancelled (its worker
/// frozen between its statements: an outside check) changed the ended job's progress. Here the
/// test holds the job's row, so the heartbeat waits between its shard's update and the job's
/// sum, and cancels the job meanwhile: the progress stays what the cancel left.
async fn a_heartbeat_that_outlives_its_jobs_end_leaves_its_progress(url: &str) {
    use sqlx::Connection;
    let store = store::open(url).await.unwrap();
    let id = insert(&store, queued(1)).await;
    let claim = store
        .claim("w", terms(0), budget(3))
        .await
        .unwrap()
        .unwrap();
    let mut holder = sqlx::PgConnection::connect(url).await.unwrap();
    sqlx::query("BEGIN").execute(&mut holder).await.unwrap();
    sqlx::query("SELECT id FROM jobs WHERE id = $1 FOR UPDATE")
        .bind(id.as_str())
        .execute(&mut holder)
        .await
        .unwrap();
    let late = tokio::spawn({
        let (store, fence) = (store.clone(), claim.fence.clone());
        async move { store.heartbeat(&fence, terms(100), 7, 7).await }
    });
    // The heartbeat has updated its shard and waits for the job's row.
    let waiting = "SELECT count(*) FROM pg_stat_activity WHERE wait_event_type = 'Lock' \
                   AND datname = current_database()";
    let started = std::time::Instant::now();
    while sqlx::query_scalar::<_, i64>(waiting)
        .fetch_one(&mut holder)
        .await
        .unwrap()
        == 0
    {
        assert!(
            started.elapsed().as_secs() < 10,
            "the heartbeat never waited"
        );
        tokio::time::sleep(std::time::Duration::from_millis(10)).await;
    }
    sqlx::query("UPDATE jobs SET status = 'cancelled', finished_at = 9 WHERE id = $1")
        .bind(id.as_str())
        .execute(&mut holder)
        .await
        .unwrap();
    sqlx::query("COMMIT").execute(&mut holder).await.unwrap();
    late.await.unwrap().unwrap();
    let job = store.job(&Owner::anonymous(), &id).await.unwrap();
    assert_eq!(job.status, JobStatus::Cancelled);
    assert_eq!(
        job.operations_done, 0,
        "the ended job's progress as its end left it"
    );
}

/// A database whose clock runs an hour ahead of this machine's judges an idempotency key's age
/// and the schedules' due times by its own clock, which every instance shares. Each instance's
/// own clock did: a key stored by a node 10 minutes slow was forgotten by one 23 h 55 min ahead
/// (its retry made a second job), and a node 10 minutes fast ran each due time 10 minutes early
/// (a probe with libfaketime).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn postgres_judges_keys_and_due_times_on_its_own_clock() {
    let Some(cluster) = Postgres::start_with_clock(&temp_dir("store-clock"), "+1h") else {
        return;
    };
    let store = store::open(&cluster.database("clock")).await.unwrap();
    let machine = UnixMs::now();
    let database = store.now().await.unwrap();
    let ahead = database.0 - machine.0;
    assert!((3_500_000..3_700_000).contains(&ahead), "{ahead} ms");

    // Stamped on the database's clock: 23 h 30 min old by a clock 24 h 30 min past this machine's.
    let key = IdempotencyKey::new("clock", r#"{"devices": 2}"#).unwrap();
    let bound = QueueBound::total(10);
    let first = store.insert_job_once(queued(1), bound, &key, None).await;
    let Some(Once::Created(first)) = first.unwrap() else {
        panic!("the key's first job");
    };
    let retried_at = machine.plus_ms(KEY_LIFETIME_MS + 30 * 60 * 1000);
    let retry = store
        .insert_job_once(queued(2), bound, &key, Some(retried_at))
        .await;
    match retry.unwrap() {
        Some(Once::Replayed(job)) => assert_eq!(job.id, first.id),
        other => panic!("the first job, replayed: {other:?}"),
    }

    // Due this minute by the database's clock, an hour from now by this machine's: the
    // scheduler runs it at once, for the database's due time (with 10 s to spare in the minute).
    let mut database = store.now().await.unwrap();
    if database.0 % 60_000 > 50_000 {
        let rest = 60_000 - database.0 % 60_000 + 500;
        tokio::time::sleep(Duration::from_millis(rest as u64)).await;
        database = store.now().await.unwrap();
    }
    let minute = UnixMs(database.0 / 60_000 * 60_000);
    let mut every_minute = nightly("every-minute", &minute.to_rfc3339());
    every_minute.definition.cron = "* * * * *".to_owned();
    store
        .insert_schedule(&every_minute, SCHEDULES)
        .await
        .unwrap();
    let (stop, stopped) = watch::channel(false);
    let scheduler = tokio::spawn(bouncewear::scheduler::run(
        Arc::clone(&store),
        queue(QueueBound::total(10)),
        Arc::new(Notify::new()),
        stopped,
    ));
    let started = std::time::Instant::now();
    let runs = loop {
        let runs = store.runs(&every_minute.id, 10).await.unwrap();
        if !runs.is_empty() || started.elapsed() > Duration::from_secs(10) {
            break runs;
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    };
    stop.send(true).unwrap();
    scheduler.await.unwrap();
    assert_eq!(runs.len(), 1, "one run, within 10 s: {runs:?}");
    assert_eq!(runs[0].scheduled_for, minute, "the database's due time");
    assert_eq!(skipped(&store, &every_minute).await.0, 0, "nothing skipped");
}

/// A pool that gets no connection says only that it timed out: the store asks PostgreSQL itself
/// why, for the log (a node out of slots logged `pool timed out` 190 times, never PostgreSQL's
/// `remaining connection slots are reserved`, found from outside), at most once every ten
/// seconds. Here the database stops taking new connections under a store that has its own.
async fn postgres_says_why_it_gives_no_connection(url: &str) {
    let (server, database) = url.rsplit_once('/').unwrap();
    let store = store::open(url).await.unwrap();
    let admin = sqlx::PgPool::connect(&format!("{server}/postgres"))
        .await
        .unwrap();
    let allow = |allowed: bool| {
        let statement = format!("ALTER DATABASE {database} ALLOW_CONNECTIONS {allowed}");
        sqlx::query(sqlx::AssertSqlSafe(statement))
    };
    allow(false).execute(&admin).await.unwrap();
    let why = store.why_unreachable().await.expect("asked");
    assert!(why.contains("not currently accepting connections"), "{why}");
    assert_eq!(store.why_unreachable().await, None, "asked again at once");
    allow(true).execute(&admin).await.unwrap();
}

/// The accumulators are LZ4-compressed before they are stored: PostgreSQL keeps them out of line
/// as they are (`EXTERNAL`), without its default attempt at pglz, which could not shrink them and
/// cost a third of its CPU time on a sharded job (`migrations/postgres/0012`). The Result's JSON,
/// which compresses, goes through lz4 rather than pglz (`migrations/postgres/0013`).
async fn compressed_accumulators_are_stored_without_pglz(url: &str) {
    use sqlx::Connection;
    let store = store::open(url).await.unwrap();
    let mut connection = sqlx::PgConnection::connect(url).await.unwrap();
    for (table, column) in [("shards", "partial"), ("distributions", "groups")] {
        let storage: i8 = sqlx::query_scalar(
            "SELECT attstorage FROM pg_attribute WHERE attrelid = $1::regclass AND attname = $2",
        )
        .bind(table)
        .bind(column)
        .fetch_one(&mut connection)
        .await
        .unwrap();
        assert_eq!(storage as u8, b'e', "{table}.{column}");
    }
    // The Result's JSON is compressed with lz4 wherever the server has it (migration 0013).
    let lz4 = sqlx::query("CREATE TEMPORARY TABLE lz4_here (x text COMPRESSION lz4)")
        .execute(&mut connection)
        .await
        .is_ok();
    let compression: i8 = sqlx::query_scalar(
        "SELECT attcompression FROM pg_attribute \
         WHERE attrelid = 'results'::regclass AND attname = 'result'",
    )
    .fetch_one(&mut connection)
    .await
    .unwrap();
    // Without it the column keeps the server's default (no method of its own).
    let expected = if lz4 { b'l' } else { 0 };
    assert_eq!(compression as u8, expected, "results.result");
    drop(store);
}

/// A store that is dropped leaves no connection open: its pool and the connection that listens
/// for announcements close with it (they once lived on, so the tests' many stores on one server
/// ran out of connections when the machine was busy).
async fn a_dropped_store_closes_every_connection(url: &str) {
    use sqlx::Connection;
    let store = store::open(url).await.unwrap();
    insert(&store, queued(1)).await;
    let database = url.rsplit_once('/').unwrap().1.to_owned();
    let mut watcher = sqlx::PgConnection::connect(url).await.unwrap();
    let mut open = async || -> i64 {
        sqlx::query_scalar(
            "SELECT COUNT(*) FROM pg_stat_activity WHERE datname = $1 AND pid <> pg_backend_pid()",
        )
        .bind(&database)
        .fetch_one(&mut watcher)
        .await
        .unwrap()
    };
    assert!(open().await >= 2, "the pool and the listener are connected");
    drop(store);
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(10);
    while open().await > 0 {
        assert!(
            std::time::Instant::now() < deadline,
            "a dropped store still holds connections after 10 s"
        );
        tokio::time::sleep(std::time::Duration::from_millis(50)).await;
    }
}

/// PostgreSQL announces every change to a job: idle workers and progress streams need not poll.
/// Its end is announced apart as well, so that a request waiting for it wakes once, not at every
/// claim and store.
async fn postgres_announces_queued_jobs_and_their_progress(url: &str) {
    use bouncewear::store::QueueEvent;
    let store = store::open(url).await.unwrap();
    let mut events = store.events().expect("PostgreSQL announces changes");
    let mut ends = store.ends();
    let id = insert(&store, queued(1)).await;
    let mut next = async || {
        tokio::time::timeout(std::time::Duration::from_secs(10), events.recv())
            .await
            .expect("announced within 10 s")
            .unwrap()
    };
    assert_eq!(next().await, QueueEvent::Queued);
    assert_eq!(next().await, QueueEvent::Changed(id.clone()));
    let claim = store
        .claim("w", terms(0), budget(3))
        .await
        .unwrap()
        .unwrap();
    assert_eq!(next().await, QueueEvent::Changed(id.clone()));
    store
        .heartbeat(&claim.fence, terms(100), 7, 7)
        .await
        .unwrap();
    assert_eq!(next().await, QueueEvent::Changed(id.clone()));
    // Announced in order: had the submission, the claim or the heartbeat announced an end, it
    // would have been passed on before the heartbeat's change.
    assert!(matches!(
        ends.try_recv(),
        Err(tokio::sync::broadcast::error::TryRecvError::Empty)
    ));
    store
        .cancel(&Owner::anonymous(), &id, Some(UnixMs(9)))
        .await
        .unwrap();
    let end = tokio::time::timeout(std::time::Duration::from_secs(10), ends.recv());
    let end = end.await.expect("the end announced within 10 s").unwrap();
    assert_eq!(end, QueueEvent::Changed(id.clone()));
    assert_eq!(next().await, QueueEvent::Changed(id));
}

#[tokio::test]
async fn sqlite_announces_nothing_so_its_readers_poll() {
    let dir = temp_dir("store-sqlite-events");
    let store = store::open(&format!("sqlite://{}", dir.join("events.db").display()))
        .await
        .unwrap();
    assert!(store.events().is_none());
}

/// A stopping process's checkpoint that another process's lock cuts short is an error, not a
/// checkpoint done (SQLite answers it with a row saying so, which passed for done, found from
/// outside).
#[tokio::test]
async fn sqlite_says_when_a_lock_cuts_its_checkpoint_short() {
    use sqlx::Connection;
    let dir = temp_dir("store-sqlite-checkpoint");
    let url = format!("sqlite://{}", dir.join("checkpoint.db").display());
    let store = store::open(&url).await.unwrap();
    insert(&store, queued(1)).await;
    store.checkpoint().await.expect("nothing in the way");
    insert(&store, queued(2)).await;
    let mut lock = sqlx::SqliteConnection::connect(&url).await.unwrap();
    sqlx::query("BEGIN EXCLUSIVE")
        .execute(&mut lock)
        .await
        .unwrap();
    assert!(store.checkpoint().await.is_err(), "cut short by the lock");
    sqlx::query("ROLLBACK").execute(&mut lock).await.unwrap();
    store.checkpoint().await.expect("the lock is gone");
}

#[tokio::test]
async fn an_unknown_url_scheme_names_the_supported_ones_and_never_the_password() {
    let Err(error) = store::open("mysql://user:secret@host/db").await else {
        panic!("mysql is not a backend");
    };
    let message = error.to_string();
    assert!(
        message.contains("`mysql`")
            && message.contains("sqlite://")
            && message.contains("postgres://"),
        "{message}"
    );
    assert!(!message.contains("secret"), "{message}");
}
