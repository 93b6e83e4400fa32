//! `/v1/events`: one event stream for all of the caller's jobs. A page that shows many jobs holds
//! one connection instead of one per job: browsers open at most six per host over HTTP/1.1, and
//! streams that take all six leave every other request of the page waiting.

use super::AppState;
use super::error::{ApiError, responses::Unauthorized};
use super::jobs::{JobResource, Progress, ServerSentEvent};
use crate::domain::{JobId, JobStatus, Owner};
use crate::store::{JobRecord, Page, QueueEvent};
use axum::Extension;
use axum::extract::State;
use axum::response::sse::{Event, KeepAlive, Sse};
use futures_util::stream::Stream;
use std::collections::{HashMap, HashSet, VecDeque};
use std::convert::Infallible;
use std::time::Duration;
use tokio::sync::broadcast;
use utoipa_axum::router::OpenApiRouter;
use utoipa_axum::routes;

pub fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new().routes(routes!(events))
}

/// How often a stream looks at its jobs when the store announces nothing; with announcements, the
/// shortest time between two looks, however many jobs change.
const EVENT_POLL: Duration = Duration::from_millis(200);
/// With announcements (PostgreSQL), a stream looks when something it follows changed, and at least
/// this often in case an announcement was missed (a dropped listening connection).
const EVENT_FALLBACK_POLL: Duration = Duration::from_secs(2);

/// Waits until it is worth looking again: an announcement the stream `wants`, or the polling
/// interval. Without announcements (SQLite), or once they stopped for good, it polls.
pub(super) async fn next_look(
    events: &mut Option<broadcast::Receiver<QueueEvent>>,
    wants: impl Fn(&QueueEvent) -> bool,
) {
    let Some(receiver) = events else {
        return tokio::time::sleep(EVENT_POLL).await;
    };
    let changed = async {
        loop {
            match receiver.recv().await {
                Ok(event) if wants(&event) => return true,
                Ok(_) => {}
                Err(broadcast::error::RecvError::Lagged(_)) => return true,
                Err(broadcast::error::RecvError::Closed) => return false,
            }
        }
    };
    // The announcements stopped for good: poll from now on.
    if let Ok(false) = tokio::time::timeout(EVENT_FALLBACK_POLL, changed).await {
        *events = None;
    }
}

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
    Event::default().event("progress").data(data.to_string())
}

/// The `status` event of a job that ended: the job resource.
pub(super) fn status_event(record: &JobRecord) -> Event {
    let data = serde_json::to_string(&JobResource::from_record(record)).unwrap_or_default();
    Event::default().event("status").data(data)
}

/// What one caller's stream has told so far.
struct Follower {
    state: AppState,
    owner: Owner,
    /// Queued and running jobs, with the status and count last sent.
    active: HashMap<JobId, (JobStatus, u64)>,
    /// The newest job (by `seq`) looked at: later ones are new to the stream.
    newest: i64,
    events: Option<broadcast::Receiver<QueueEvent>>,
    ready: VecDeque<Event>,
}

impl Follower {
    /// Looks at the owner's jobs once and queues an event for each change since the last look:
    /// `progress` for a queued or running job whose status or count moved, `status` for a job
    /// that ended (one followed before, or one submitted since).
    async fn look(&mut self) -> Result<(), ApiError> {
        let live = self.state.store.live_jobs(&self.owner, self.newest).await?;
        let mut gone: HashSet<JobId> = self.active.keys().cloned().collect();
        for record in live {
            self.newest = self.newest.max(record.seq);
            gone.remove(&record.id);
            self.tell(&record);
        }
        // Followed jobs no longer queued or running: they ended since the last look.
        for id in gone {
            match self.state.store.job(&self.owner, &id).await {
                Ok(record) => self.tell(&record),
                Err(_) => {
                    self.active.remove(&id);
                }
            }
        }
        Ok(())
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
/// event's data is the JobResource. The stream stays open until the client closes it or the server
/// shuts down; with API keys it shows only your jobs.
#[utoipa::path(
    get, path = "/v1/events", tag = "jobs",
    responses(
        (status = 200, description = "An event stream that stays open: `progress` events (data: id, status, operations_done, operations_total) for each queued or running job at the start and whenever it moves, and one `status` event (data: the JobResource) when a job ends", content_type = "text/event-stream", body = ServerSentEvent),
        Unauthorized,
    ),
    security((), ("api_key" = []))
)]
pub async fn events(
    State(state): State<AppState>,
    Extension(owner): Extension<Owner>,
) -> Result<Sse<impl Stream<Item = Result<Event, Infallible>>>, ApiError> {
    // Subscribed before the first look, so no change after it goes unannounced.
    let events = state.store.events();
    let newest = state
        .store
        .jobs(
            &owner,
            Page {
                before: None,
                limit: 1,
            },
        )
        .await?
        .first()
        .map_or(0, |record| record.seq);
    let mut follower = Follower {
        state,
        owner,
        active: HashMap::new(),
        newest,
        events,
        ready: VecDeque::new(),
    };
    follower.look().await?;
    let stream = futures_util::stream::unfold(follower, |mut f| async move {
        loop {
            if *f.state.shutdown.borrow() {
                return None;
            }
            if let Some(event) = f.ready.pop_front() {
                return Some((Ok(event), f));
            }
            if f.events.is_some() {
                tokio::time::sleep(EVENT_POLL).await;
            }
            next_look(&mut f.events, |event| match event {
                QueueEvent::Queued => true,
                QueueEvent::Changed(id) => f.active.contains_key(id),
            })
            .await;
            if f.look().await.is_err() {
                return None;
            }
        }
    });
    Ok(Sse::new(stream).keep_alive(KeepAlive::default()))
}
