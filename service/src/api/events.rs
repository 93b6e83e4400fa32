//! The event streams: `/v1/events`, one stream for all of the caller's jobs, and
//! `/v1/jobs/{id}/events`, one job's. A page that shows many jobs holds one connection instead of
//! one per job: browsers open at most six per host over HTTP/1.1, and streams that take all six
//! leave every other request of the page waiting.

use super::AppState;
use super::Path;
use super::error::ApiError;
use super::error::responses::{NoSuchJob, TooManyStreams, Unauthorized};
use super::jobs::{JobResource, Progress, ServerSentEvent};
use super::watch::{Snapshot, Subscription};
use crate::domain::{JobId, JobStatus, Owner};
use crate::store::{JobRecord, StoreError};
use axum::Extension;
use axum::extract::State;
use axum::http::HeaderMap;
use axum::response::sse::{Event, KeepAlive, Sse};
use futures_util::stream::Stream;
use std::collections::{HashMap, HashSet, VecDeque};
use std::convert::Infallible;
use std::time::Duration;
use utoipa_axum::router::OpenApiRouter;
use utoipa_axum::routes;

pub fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new()
        .routes(routes!(events))
        .routes(routes!(job_events))
}

/// The comment an event stream sends after 15 s without an event: 8 KB. A client's end takes
/// what fits in its buffers whether it reads or not, and the server tells a stream unread only
/// once they are full (`connections::Delivery`): Linux's default buffers took about 150 KB, 19 of
/// these comments (about 5 minutes), where the empty comment took days (an outside probe: 64
/// unread streams held every place). 550 bytes a second for a client that reads.
fn keep_alive() -> KeepAlive {
    KeepAlive::new().text("keep-alive".to_owned() + &" ".repeat(8182))
}

/// How long a client waits before it reconnects a dropped stream (the first event's `retry`).
const RECONNECT: Duration = Duration::from_secs(2);

/// The `progress` event of a running or queued job.
pub(super) fn progress_event(record: &JobRecord, with_id: bool) -> Event {
    let progress = Progress::of(record);
    let mut data = serde_json::json!({
        "status": record.status,
        "operations_done": progress.operations_done,
        "operations_total": progress.operations_total,
    });
    if with_id {
        data["id"] = record.id.to_string().into();
    }
    // `data` right after `event`, as before ids: a client reading line pairs still finds it.
    Event::default()
        .event("progress")
        .data(data.to_string())
        .id(event_id(record))
}

/// The `status` event of a job that ended: the job resource.
pub(super) fn status_event(record: &JobRecord) -> Event {
    let data = serde_json::to_string(&JobResource::from_record(record)).unwrap_or_default();
    Event::default()
        .event("status")
        .data(data)
        .id(event_id(record))
}

/// The `deleted` event of a job the stream followed and the store no longer has, its end untold:
/// deleted by another server on the same database before this one saw it end (or deleted while
/// the stream was not read for over a minute).
fn deleted_event(id: &JobId) -> Event {
    Event::default()
        .event("deleted")
        .data(serde_json::json!({ "id": id }).to_string())
        .id(format!("{id}:deleted"))
}

/// An event's `id`: the job's state it tells, `JOB:STATUS:OPERATIONS_DONE`. A client that
/// reconnects sends the last one as `Last-Event-ID`, and a job's stream then does not tell that
/// state again.
fn event_id(record: &JobRecord) -> String {
    format!(
        "{}:{}:{}",
        record.id,
        record.status.as_str(),
        record.operations_done
    )
}

/// The job state a `Last-Event-ID` of [`event_id`]'s form names for job `id`, if it does.
fn last_seen(request: &HeaderMap, id: &JobId) -> Option<(JobStatus, u64)> {
    let text = request.get("last-event-id")?.to_str().ok()?;
    let mut parts = text.rsplitn(3, ':');
    let done = parts.next()?.parse().ok()?;
    let status = JobStatus::parse(parts.next()?)?;
    (parts.next()? == id.as_str()).then_some((status, done))
}

/// The stream's first event also tells the client how soon to reconnect.
fn first(event: Event, sent: &mut bool) -> Event {
    if std::mem::replace(sent, true) {
        event
    } else {
        event.retry(RECONNECT)
    }
}

/// What one caller's stream has told so far.
struct Follower {
    state: AppState,
    owner: Owner,
    subscription: Subscription,
    /// Queued and running jobs, with the status and count last sent.
    active: HashMap<JobId, (JobStatus, u64)>,
    /// The newest job (by `seq`) when the stream opened (the subscription's, or the first
    /// snapshot's store's): later ones were submitted since, and an end of one is told however
    /// soon it came.
    since: Option<i64>,
    /// The owner's jobs (by `seq`) in the last snapshot: a job later than `since` and not among
    /// them is new to the stream. By number alone, a job whose submission committed after a
    /// newer one's was read (PostgreSQL numbers at insert) was passed over.
    seen: HashSet<i64>,
    ready: VecDeque<Event>,
    /// Whether an event went out yet.
    sent: bool,
}

impl Follower {
    /// Queues an event for each of the owner's jobs that changed since the last snapshot:
    /// `progress` for a queued or running job whose status or count moved, `status` for a job
    /// that ended (one followed before, or one submitted since the stream began).
    async fn look(&mut self, snapshot: &Snapshot) {
        let since = *self.since.get_or_insert(snapshot.stored_newest);
        let mut gone: HashSet<JobId> = self.active.keys().cloned().collect();
        let mut seen = HashSet::new();
        let owner = self.owner.clone();
        for record in snapshot.of(&owner) {
            gone.remove(&record.id);
            let followed = self.active.contains_key(&record.id);
            let new = record.seq > since && !self.seen.contains(&record.seq);
            seen.insert(record.seq);
            if !record.status.is_terminal() || followed || new {
                self.tell(record);
            }
        }
        self.seen = seen;
        // Followed jobs gone from the snapshot: ended so long ago that the watcher forgot them
        // (this stream was not read meanwhile), or deleted. The store says which; on an error the
        // job stays followed and is asked about again.
        for id in gone {
            match self.state.store.job(&self.owner, &id).await {
                Ok(record) => self.tell(&record),
                Err(StoreError::NotFound { .. }) => {
                    self.active.remove(&id);
                    self.ready.push_back(deleted_event(&id));
                }
                Err(_) => {}
            }
        }
    }

    fn tell(&mut self, record: &JobRecord) {
        if record.status.is_terminal() {
            self.active.remove(&record.id);
            self.ready.push_back(status_event(record));
            return;
        }
        let seen = (record.status, record.operations_done);
        if self.active.insert(record.id.clone(), seen) != Some(seen) {
            self.ready.push_back(progress_event(record, true));
        }
    }
}

/// Server-Sent Events for all of your queued and running jobs, in one stream: first a `progress`
/// event for each, then one for every change, and a `status` event when one ends. Jobs submitted
/// later join the stream. Events carry the job's `id`.
///
/// Open it once for a page that shows many jobs: browsers hold at most six connections per host.
/// Each `progress` event's data is `{id, status, operations_done, operations_total}`; a `status`
/// event's data is the JobResource; a job that another server deleted before this one saw it end
/// gets a `deleted` event (data: `{id}`). The stream stays open until the client closes it or the
/// server shuts down; with API keys it shows only your jobs.
#[utoipa::path(
    get, path = "/v1/events", tag = "jobs",
    responses(
        (status = 200, description = "An event stream that stays open: `progress` events (data: id, status, operations_done, operations_total) for each queued or running job at the start and whenever it moves, and one `status` event (data: the JobResource) when a job ends (`deleted`, data: id, for a followed job another server deleted before this one saw its end)", content_type = "text/event-stream", body = ServerSentEvent),
        Unauthorized,
        TooManyStreams,
    ),
    security((), ("api_key" = []))
)]
pub async fn events(
    State(state): State<AppState>,
    Extension(owner): Extension<Owner>,
) -> Result<Sse<impl Stream<Item = Result<Event, Infallible>>>, ApiError> {
    let subscription = state.watch.subscribe(&owner)?;
    let follower = Follower {
        state,
        owner,
        since: subscription.newest,
        seen: HashSet::new(),
        subscription,
        active: HashMap::new(),
        ready: VecDeque::new(),
        sent: false,
    };
    let stream = futures_util::stream::unfold(follower, |mut f| async move {
        loop {
            if let Some(event) = f.ready.pop_front() {
                let event = first(event, &mut f.sent);
                return Some((Ok(event), f));
            }
            let mut shutdown = f.state.shutdown.clone();
            let snapshot = f.subscription.next(&mut shutdown).await?;
            f.look(&snapshot).await;
        }
    });
    Ok(Sse::new(stream).keep_alive(keep_alive()))
}

/// Server-Sent Events: `progress` events while the job runs, then one `status` event when it ends.
///
/// `progress` events (data: `{status, operations_done, operations_total}`) while the job is queued
/// or runs, then one `status` event (data: the JobResource) when it ends, and the stream closes. A
/// job that already ended gets its `status` event at once; one that another server deleted before
/// this one saw it end gets a `deleted` event (data: `{id}`).
#[utoipa::path(
    get, path = "/v1/jobs/{id}/events", tag = "jobs", params(("id" = String, Path, description = "Job id"), ("Last-Event-ID" = Option<String>, Header, description = "The last event's `id` a client that reconnects saw (`JOB:STATUS:OPERATIONS_DONE`): that state is not told again", example = "6f0d4e8a-2b1c-4d7e-9a3f-5c8b1e2d4f60:running:40000")),
    responses(
        (status = 200, description = "An event stream: `progress` events (data: status, operations_done, operations_total) while the job runs, then one `status` event (data: the JobResource) when it ends (`deleted`, data: id, if another server deleted it before this one saw its end)", content_type = "text/event-stream", body = ServerSentEvent),
        Unauthorized,
        TooManyStreams,
        NoSuchJob,
    ),
    security((), ("api_key" = []))
)]
pub async fn job_events(
    State(state): State<AppState>,
    Extension(owner): Extension<Owner>,
    Path(id): Path<JobId>,
    request: HeaderMap,
) -> Result<Sse<impl Stream<Item = Result<Event, Infallible>>>, ApiError> {
    let current = state.store.job(&owner, &id).await?;
    let last = last_seen(&request, &id);
    // Subscribed after the first read (a job is looked up before its stream takes a place); its
    // first snapshot is taken after this point.
    let subscription = state.watch.subscribe(&owner)?;
    struct Follower {
        state: AppState,
        subscription: Subscription,
        owner: Owner,
        id: JobId,
        last: Option<(JobStatus, u64)>,
        pending: Option<JobRecord>,
        ended: bool,
        sent: bool,
    }
    let follower = Follower {
        state,
        subscription,
        owner,
        id,
        last,
        pending: Some(current),
        ended: false,
        sent: false,
    };
    let stream = futures_util::stream::unfold(follower, |mut f| async move {
        loop {
            if f.ended {
                return None;
            }
            let record = match f.pending.take() {
                Some(record) => record,
                None => {
                    let mut shutdown = f.state.shutdown.clone();
                    let snapshot = f.subscription.next(&mut shutdown).await?;
                    match snapshot.get(&f.id) {
                        Some(record) => record.clone(),
                        // Neither live nor ended lately: ask the store (a stream not read for
                        // long, or the job deleted: then the stream says so and ends).
                        None => match f.state.store.job(&f.owner, &f.id).await {
                            Ok(record) => record,
                            Err(StoreError::NotFound { .. }) => {
                                f.ended = true;
                                let event = first(deleted_event(&f.id), &mut f.sent);
                                return Some((Ok(event), f));
                            }
                            Err(_) => continue,
                        },
                    }
                }
            };
            let seen = (record.status, record.operations_done);
            if record.status.is_terminal() {
                f.ended = true;
                let event = first(status_event(&record), &mut f.sent);
                return Some((Ok(event), f));
            }
            if f.last != Some(seen) {
                f.last = Some(seen);
                let event = first(progress_event(&record, false), &mut f.sent);
                return Some((Ok(event), f));
            }
        }
    });
    Ok(Sse::new(stream).keep_alive(keep_alive()))
}
