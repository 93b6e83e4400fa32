//! One watcher of the job queue for every event stream of this process. Each stream used to read
//! the database every 200 ms on its own, so 1000 idle streams were 5000 queries a second; now one
//! task reads every owner's live jobs once per look and hands each stream the same snapshot, from
//! which it takes its owner's jobs. The watcher reads only while some stream listens, keeps its
//! last snapshot through a database outage (the streams stay open and resume), and caps how many
//! streams one API key may hold.

use super::error::ApiError;
use crate::domain::{JobId, Owner};
use crate::store::{JobRecord, QueueEvent, Store, StoreError, StoreResult};
use crate::telemetry::EVENT_WATCH_LOOKS;
use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tokio::sync::{Notify, Semaphore, broadcast, watch};

/// The shortest time between two looks, however many jobs change; without announcements
/// (SQLite), how often the watcher looks, unless a job of this process ended sooner.
const LOOK_INTERVAL: Duration = Duration::from_millis(200);
/// Without announcements, the shortest time between two looks when jobs of this process end
/// ([`Store::ends`](crate::store::Store::ends)): a stream hears of an end at once, and many
/// ends cost at most 50 looks a second.
const END_LOOK_INTERVAL: Duration = Duration::from_millis(20);
/// With announcements (PostgreSQL), the watcher looks when a job changed, and at least this often
/// in case an announcement was missed (a dropped listening connection).
const FALLBACK_INTERVAL: Duration = Duration::from_secs(2);
/// After a failed look, the wait doubles from [`LOOK_INTERVAL`] up to this.
const MAX_BACKOFF: Duration = Duration::from_secs(5);
/// How long a job that ended stays in the snapshots: a stream that was not read for longer (a
/// stalled client) asks the store for the jobs it still follows.
const REMEMBER_ENDED: Duration = Duration::from_secs(60);
/// How far below the newest job of the last look each look reads the jobs that ended: a job
/// numbered below it whose submission committed after it was read (PostgreSQL numbers a row at
/// insert, not at commit; clients submitting at once) and that ended before this look is found
/// (9 of 216 such jobs were told on no stream). More submissions than this in flight at once
/// across every server could still pass one over.
const LOOK_BACK: i64 = 64;
/// The most jobs being deleted the watcher remembers between two looks: beyond them, a stream
/// that followed one tells it `deleted`.
const MAX_DELETING: usize = 10_000;

/// What the watcher saw at one look.
#[derive(Debug, Default)]
pub struct Snapshot {
    /// Counts the looks that succeeded since the watcher last started reading; 0 before.
    generation: u64,
    /// Every queued or running job and every job that ended within [`REMEMBER_ENDED`], oldest
    /// first.
    jobs: Vec<Arc<JobRecord>>,
    /// Positions in `jobs`.
    by_id: HashMap<JobId, usize>,
    /// The newest `seq` of all jobs at this look, those this process deleted since included:
    /// every job at most as new that ended since the previous look is in `jobs`.
    pub newest: i64,
    /// The store's newest `seq` at this look: the starting point of a stream that opened while
    /// the watcher was idle, where its last look, long before, would take the ends read back
    /// (`LOOK_BACK`) as new.
    pub stored_newest: i64,
}

impl Snapshot {
    /// `owner`'s jobs, oldest first.
    pub fn of<'a>(&'a self, owner: &'a Owner) -> impl Iterator<Item = &'a JobRecord> + 'a {
        self.jobs
            .iter()
            .map(|job| job.as_ref())
            .filter(move |job| job.owner == *owner)
    }

    /// The job if it is live or ended recently, whoever owns it.
    pub fn get(&self, id: &JobId) -> Option<&JobRecord> {
        self.by_id.get(id).map(|&i| self.jobs[i].as_ref())
    }
}

/// The shared watcher: start it with [`JobWatch::start`], open streams with
/// [`JobWatch::subscribe`].
pub struct JobWatch {
    snapshots: watch::Sender<Arc<Snapshot>>,
    streams: Mutex<HashMap<Owner, usize>>,
    per_key: usize,
    /// Places of the requests waiting for a job's end ([`JobWatch::until_ended`]).
    waits: Semaphore,
    /// Told of each new stream, so that an idle watcher looks at once.
    listening: Notify,
    /// Jobs that ended and that this process deletes, as they ended, since the watcher last
    /// looked: their end is told as any other's, though the store may no longer have them.
    deleted: Mutex<Vec<Arc<JobRecord>>>,
}

/// The longest a request may wait for a job's end (`wait_s`): within the request timeout's
/// default of 60 s, so that a wait always ends with the job as it is, never a 503.
pub const MAX_WAIT_S: f64 = 30.0;

/// How often a waiting request reads its job again when nothing was announced: another process
/// on the same SQLite file, or PostgreSQL's listener reconnecting, announces nothing here.
const RECHECK: Duration = Duration::from_millis(500);

impl JobWatch {
    /// Starts the watcher over `store`; it runs until `shutdown` turns true. At most `per_key`
    /// streams per owner, and at most `waits` requests waiting for a job's end at once.
    pub fn start(
        store: Arc<Store>,
        per_key: usize,
        waits: usize,
        shutdown: watch::Receiver<bool>,
    ) -> Arc<Self> {
        let (snapshots, _) = watch::channel(Arc::new(Snapshot::default()));
        let watch = Arc::new(Self {
            snapshots,
            streams: Mutex::new(HashMap::new()),
            per_key,
            waits: Semaphore::new(waits),
            listening: Notify::new(),
            deleted: Mutex::new(Vec::new()),
        });
        tokio::spawn(Arc::clone(&watch).run(store, shutdown));
        watch
    }

    /// A stream's place: refused (429) when `owner` already holds as many as allowed. Its first
    /// snapshot is one taken after this call began waiting.
    pub fn subscribe(self: &Arc<Self>, owner: &Owner) -> Result<Subscription, ApiError> {
        let mut streams = self.streams.lock().unwrap_or_else(|e| e.into_inner());
        let held = streams.entry(owner.clone()).or_default();
        if *held >= self.per_key {
            return Err(ApiError::TooManyStreams(self.per_key));
        }
        *held += 1;
        let receiver = self.snapshots.subscribe();
        let newest = {
            let last = receiver.borrow();
            (last.generation > 0).then_some(last.newest)
        };
        // After the receiver counts: the watcher that wakes sees a listener.
        self.listening.notify_one();
        Ok(Subscription {
            newest,
            receiver,
            owner: owner.clone(),
            watch: Arc::clone(self),
        })
    }

    /// Tells the streams of this process the end of `ended`, a job about to be deleted: each that
    /// has not told its end yet tells it (deleted before the watcher looked, it was gone from
    /// the store, its end untold). Kept only while some stream listens, and only for a job whose
    /// end a snapshot may not hold yet: live at the last look, or newer than its newest less
    /// `LOOK_BACK` (one numbered below it may have committed since); a job that ended long ago
    /// costs nothing, however many are deleted; at most `MAX_DELETING` between two looks.
    pub fn deleting(&self, ended: JobRecord) {
        if self.snapshots.receiver_count() == 0 {
            return;
        }
        let untold = {
            let last = self.snapshots.borrow();
            let recent = ended.seq > last.newest.saturating_sub(LOOK_BACK);
            recent
                || last
                    .get(&ended.id)
                    .is_some_and(|job| !job.status.is_terminal())
        };
        let mut deleted = self.deleted.lock().unwrap_or_else(|e| e.into_inner());
        if untold && deleted.len() < MAX_DELETING {
            deleted.push(Arc::new(ended));
        }
    }

    /// `owner`'s job `id` once it ended, or as it is when `wait` passed: a request that waits
    /// instead of asking again and again. The store's announcements
    /// ([`Store::ends`](crate::store::Store::ends)) wake it the moment the job ends, and it
    /// reads the job again every `RECHECK` in case one was missed. With every place taken, at
    /// shutdown, or for a job that already ended it answers at once.
    pub async fn until_ended(
        &self,
        store: &Store,
        owner: &Owner,
        id: &JobId,
        wait: Duration,
        mut shutdown: watch::Receiver<bool>,
    ) -> StoreResult<JobRecord> {
        let deadline = Instant::now() + wait;
        // Listening before the first read: an end between the two is not missed.
        let mut ends = store.ends();
        let mut record = store.job(owner, id).await?;
        if record.status.is_terminal() || wait.is_zero() {
            return Ok(record);
        }
        let Ok(_place) = self.waits.try_acquire() else {
            return Ok(record);
        };
        while !record.status.is_terminal() && Instant::now() < deadline && !*shutdown.borrow() {
            let recheck = tokio::time::sleep_until((deadline.min(Instant::now() + RECHECK)).into());
            tokio::pin!(recheck);
            loop {
                tokio::select! {
                    () = &mut recheck => break,
                    // Shutting down (or its sender gone): the job as it is, so the server drains.
                    _ = shutdown.changed() => return store.job(owner, id).await,
                    event = ends.recv() => match event {
                        Ok(QueueEvent::Changed(changed)) if changed == *id => break,
                        Ok(_) => {}
                        // Ends passed over, perhaps this one's (never closed: the store holds
                        // the sender).
                        Err(_) => break,
                    },
                }
            }
            record = store.job(owner, id).await?;
        }
        Ok(record)
    }

    async fn run(self: Arc<Self>, store: Arc<Store>, mut shutdown: watch::Receiver<bool>) {
        let mut announcements = store.events();
        let mut ends = announcements.is_none().then(|| store.ends());
        let mut tracked = Tracked::default();
        let mut failures = 0_u32;
        loop {
            if *shutdown.borrow() {
                return;
            }
            if self.snapshots.receiver_count() == 0 {
                // Nobody listens: read nothing, and start afresh as soon as somebody does (from
                // an empty snapshot: its last look's is no stream's starting point).
                if tracked.generation > 0 {
                    self.snapshots.send_replace(Arc::new(Snapshot::default()));
                }
                tracked = Tracked::default();
                self.deleted
                    .lock()
                    .unwrap_or_else(|e| e.into_inner())
                    .clear();
                failures = 0;
                tokio::select! {
                    () = self.listening.notified() => {}
                    paused = pause(LOOK_INTERVAL, &mut shutdown) => if !paused {
                        return;
                    },
                }
                continue;
            }
            metrics::counter!(EVENT_WATCH_LOOKS).increment(1);
            let wait = match tracked.look(store.as_ref(), &self.deleted).await {
                Ok(()) => {
                    if failures > 0 {
                        tracing::info!("the event watcher reads the database again");
                    }
                    failures = 0;
                    self.snapshots.send_replace(Arc::new(tracked.snapshot()));
                    LOOK_INTERVAL
                }
                Err(error) => {
                    if failures == 0 {
                        tracing::warn!(%error, "the event watcher cannot read the database; streams stay open and wait");
                    }
                    failures = failures.saturating_add(1);
                    LOOK_INTERVAL
                        .saturating_mul(1 << failures.min(5))
                        .min(MAX_BACKOFF)
                }
            };
            let paused = match (failures, &mut ends) {
                (0, Some(ends)) => pause_until_end(wait, ends, &mut shutdown).await,
                _ => pause(wait, &mut shutdown).await,
            };
            if !paused {
                return;
            }
            if failures == 0 && !*shutdown.borrow() {
                next_announcement(&mut announcements).await;
            }
        }
    }
}

/// Sleeps for `wait`, or less if `shutdown` changes; `false` once its sender is gone.
async fn pause(wait: Duration, shutdown: &mut watch::Receiver<bool>) -> bool {
    tokio::select! {
        () = tokio::time::sleep(wait) => true,
        changed = shutdown.changed() => changed.is_ok(),
    }
}

/// [`pause`], or less when a job of this process ends: then [`END_LOOK_INTERVAL`] after the
/// pause began.
async fn pause_until_end(
    wait: Duration,
    ends: &mut broadcast::Receiver<QueueEvent>,
    shutdown: &mut watch::Receiver<bool>,
) -> bool {
    let began = Instant::now();
    tokio::select! {
        () = tokio::time::sleep(wait) => return true,
        changed = shutdown.changed() => return changed.is_ok(),
        // An end, or ends passed over (never closed: this task holds the store).
        _ = ends.recv() => {}
    }
    pause(END_LOOK_INTERVAL.saturating_sub(began.elapsed()), shutdown).await
}

/// With announcements, waits for one or [`FALLBACK_INTERVAL`]; without, returns at once. Once
/// the announcements stop for good, it returns at once from then on (the caller polls).
async fn next_announcement(events: &mut Option<broadcast::Receiver<QueueEvent>>) {
    let Some(receiver) = events else {
        return;
    };
    let changed = async {
        match receiver.recv().await {
            Ok(_) | Err(broadcast::error::RecvError::Lagged(_)) => {
                // One look answers every announcement queued so far: taken one a look, those
                // queued while nobody listened (up to the channel's 1024) kept the watcher
                // reading five times a second for minutes.
                while let Ok(_) | Err(broadcast::error::TryRecvError::Lagged(_)) =
                    receiver.try_recv()
                {}
                true
            }
            Err(broadcast::error::RecvError::Closed) => false,
        }
    };
    if let Ok(false) = tokio::time::timeout(FALLBACK_INTERVAL, changed).await {
        *events = None;
    }
}

/// The watcher's memory between looks.
#[derive(Default)]
struct Tracked {
    generation: u64,
    /// `None` before the first look.
    newest: Option<i64>,
    live: HashMap<JobId, Arc<JobRecord>>,
    ended: HashMap<JobId, (Instant, Arc<JobRecord>)>,
    /// The store's newest `seq` at the last look.
    stored_newest: i64,
}

impl Tracked {
    /// One look at the store; the jobs being `deleted` meanwhile are remembered as ended once it
    /// read (each is handed over before its delete: one the read missed is there). On an error
    /// nothing else changes.
    async fn look(
        &mut self,
        store: &Store,
        deleted: &Mutex<Vec<Arc<JobRecord>>>,
    ) -> StoreResult<()> {
        let after = self
            .newest
            .map_or(i64::MAX, |newest| newest.saturating_sub(LOOK_BACK));
        let (rows, newest) = store.live_jobs(after).await?;
        self.stored_newest = newest;
        let now = Instant::now();
        self.ended
            .retain(|_, (at, _)| now.duration_since(*at) < REMEMBER_ENDED);
        let deleted = std::mem::take(&mut *deleted.lock().unwrap_or_else(|e| e.into_inner()));
        for record in deleted {
            self.ended.insert(record.id.clone(), (now, record));
        }
        let mut live = HashMap::new();
        let mut ended = Vec::new();
        for record in rows {
            let record = Arc::new(record);
            if record.status.is_terminal() {
                ended.push(record);
            } else {
                live.insert(record.id.clone(), record);
            }
        }
        // Live at the last look, not now: ended since, or deleted.
        for (id, before) in &self.live {
            let told = ended.iter().any(|r| r.id == *id) || self.ended.contains_key(id);
            if live.contains_key(id) || told {
                continue;
            }
            match store.job(&before.owner, id).await {
                Ok(record) if record.status.is_terminal() => ended.push(Arc::new(record)),
                Ok(record) => {
                    live.insert(id.clone(), Arc::new(record));
                }
                Err(StoreError::NotFound { .. }) => {}
                Err(error) => return Err(error),
            }
        }
        for record in ended {
            self.ended.insert(record.id.clone(), (now, record));
        }
        self.live = live;
        // The store's newest, or a deleted job's that is newer: a stream that opens now takes the
        // jobs above it as new, and a job deleted now is remembered if it is above it.
        let remembered = self.ended.values().map(|(_, record)| record.seq);
        self.newest = Some(remembered.fold(newest, i64::max));
        self.generation += 1;
        Ok(())
    }

    fn snapshot(&self) -> Snapshot {
        let mut jobs: Vec<Arc<JobRecord>> = self
            .live
            .values()
            .chain(self.ended.values().map(|(_, record)| record))
            .cloned()
            .collect();
        jobs.sort_by_key(|job| job.seq);
        let by_id = jobs
            .iter()
            .enumerate()
            .map(|(i, job)| (job.id.clone(), i))
            .collect();
        Snapshot {
            generation: self.generation,
            jobs,
            by_id,
            newest: self.newest.unwrap_or(0),
            stored_newest: self.stored_newest,
        }
    }
}

/// One stream's place at the watcher; gives it back when dropped.
pub struct Subscription {
    /// The newest job (by `seq`) of the watcher's last look before the stream opened (`None`
    /// while it was idle: then the first snapshot's store's newest): the jobs after it are new
    /// to the stream, even those its first snapshot holds as ended (or deleted) already.
    pub newest: Option<i64>,
    receiver: watch::Receiver<Arc<Snapshot>>,
    owner: Owner,
    watch: Arc<JobWatch>,
}

impl Subscription {
    /// The next snapshot the stream has not seen (the first: one taken after it subscribed),
    /// or `None` once `shutdown` turns true.
    pub async fn next(&mut self, shutdown: &mut watch::Receiver<bool>) -> Option<Arc<Snapshot>> {
        loop {
            if *shutdown.borrow() {
                return None;
            }
            tokio::select! {
                changed = self.receiver.changed() => {
                    changed.ok()?;
                    let snapshot = Arc::clone(&self.receiver.borrow_and_update());
                    // A generation of 0 is the empty value a restarted watcher begins with.
                    if snapshot.generation > 0 {
                        return Some(snapshot);
                    }
                }
                // The server is gone with its shutdown signal: nothing more to tell.
                changed = shutdown.changed() => changed.ok()?,
            }
        }
    }
}

impl Drop for Subscription {
    fn drop(&mut self) {
        let mut streams = self.watch.streams.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(held) = streams.get_mut(&self.owner) {
            *held -= 1;
            if *held == 0 {
                streams.remove(&self.owner);
            }
        }
    }
}
