//! `/v1/jobs`: submit, list, inspect, cancel, results, distributions and live progress.

use super::Path;
use super::cache::{
    NotModified, Tagged, immutable, immutable_identified, immutable_tagged, not_modified,
};
use super::error::{
    ApiError, Internal, PROBLEM, Problem,
    responses::{
        BadQuery, BodyRejected, NoSuchJob, NotSucceeded, OverQuota, QueueFull, Unauthorized,
    },
};
use super::watch::MAX_WAIT_S;
use super::{AppState, JsonText, idempotency_key, replayed};
use crate::domain::query::LARGE_DISTRIBUTION_BINS;
use crate::domain::{
    AfterRunQuery, CursorKey, JobId, JobStatus, Once, Owner, QueuedJob, UnixMs, draw_seed,
};
use crate::store::{JobRecord, Operations, Page, ShardRecord, StoreError};
use axum::body::{Body, Bytes};
use axum::extract::rejection::QueryRejection;
use axum::extract::{Query, State};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use axum::{Extension, Json};
use bouncewear_model::Pointer;
use bouncewear_model::life::weibayes::{WeibayesError, check_arguments, weibayes};
use bouncewear_model::montecarlo::rare::check_threshold;
use bouncewear_model::montecarlo::{Job, JobResult, JobSpec, Metric, query_metric};
use bouncewear_model::stats::{Accumulator, QUANTILES, QueryAnswer, Summary, Threshold, level_key};
use futures_util::stream::{Stream, StreamExt};
use serde::{Deserialize, Serialize};
use std::fmt::Write as _;
use utoipa::{IntoParams, ToSchema};
use utoipa_axum::router::OpenApiRouter;
use utoipa_axum::routes;

pub fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new()
        .routes(routes!(submit_job, list_jobs))
        .routes(routes!(get_job, cancel_job))
        .routes(routes!(cancel_only))
        .routes(routes!(get_shards))
        .routes(routes!(get_result))
        .routes(routes!(get_distribution))
        .routes(routes!(get_life))
        .routes(routes!(get_rare_event))
}

/// A job as the API shows it.
#[derive(Debug, Serialize, ToSchema)]
pub struct JobResource {
    /// The job's id (a UUID).
    #[schema(format = "uuid")]
    pub id: String,
    /// The job's `name`, if it had one.
    #[schema(required = true)]
    pub name: Option<String>,
    /// `queued`, `running`, `succeeded`, `failed` or `cancelled`.
    pub status: JobStatus,
    /// Operations done of the planned total.
    pub progress: Progress,
    /// RFC 3339.
    #[schema(format = DateTime)]
    pub created_at: String,
    /// RFC 3339; when a worker first started it.
    #[schema(format = DateTime, required = true)]
    pub started_at: Option<String>,
    /// RFC 3339; when it ended.
    #[schema(format = DateTime, required = true)]
    pub finished_at: Option<String>,
    /// Why it failed.
    #[schema(required = true)]
    pub error: Option<String>,
    /// While it runs, why its work waits, if it does (null otherwise): `waiting for room: ...`
    /// (no room on the disk for what it computed, kept until there is) or `waiting for the
    /// database: ...`; its shards (`links.shards`) say which.
    #[schema(required = true)]
    pub waiting: Option<String>,
    /// The seed the job runs with (drawn at submission when the job did not give one).
    pub seed: u64,
    /// Bytes stored for the job: its spec, its groups' accumulators while it runs, and once it
    /// succeeded its result, distributions and listed device lives (database overhead aside).
    /// `DELETE` frees them.
    pub stored_bytes: u64,
    /// URLs of the job and of what it has.
    pub links: Links,
    /// The job as it runs (as submitted, every default filled in, its seed fixed): in
    /// `GET /v1/jobs/{id}` only (not in the 202, a listing or an event).
    #[serde(skip_serializing_if = "Option::is_none")]
    #[schema(value_type = Option<Object>)]
    pub spec: Option<JobSpec>,
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, ToSchema)]
pub struct Progress {
    /// Operations simulated so far.
    pub operations_done: u64,
    /// Operations planned (a precision target may add batches).
    pub operations_total: u64,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct Links {
    /// The job's URL.
    #[serde(rename = "self")]
    pub this: String,
    /// Its result's URL (409 until it succeeded).
    pub result: String,
    /// Its event stream's URL.
    pub events: String,
    /// The shards it runs as.
    pub shards: String,
    /// Its distributions: the template of a metric's (`{metric}`, as the Result names it).
    pub distributions: String,
    /// Its life analysis (404 for a job without `failure` criteria).
    pub life: String,
    /// Its plots: the template of a plot's (`{kind}`: `bands.svg`, `histograms.svg`,
    /// `weibull.svg`, `sensitivity.svg`, `tail.svg`).
    pub plots: String,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct JobList {
    /// Newest first.
    pub jobs: Vec<JobResource>,
    /// Pass as `cursor` for the next page; absent on the last page.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub next_cursor: Option<String>,
}

impl Progress {
    /// A precision target can run more operations than first planned: the total never trails the count.
    pub fn of(record: &JobRecord) -> Self {
        Progress {
            operations_done: record.operations_done,
            operations_total: record.operations_total.max(record.operations_done),
        }
    }
}

impl JobResource {
    pub fn from_record(record: &JobRecord) -> Self {
        let this = format!("/v1/jobs/{}", record.id);
        JobResource {
            id: record.id.to_string(),
            name: record.name.clone(),
            status: record.status,
            progress: Progress::of(record),
            created_at: record.created_at.to_rfc3339(),
            started_at: record.started_at.map(UnixMs::to_rfc3339),
            finished_at: record.finished_at.map(UnixMs::to_rfc3339),
            error: record.error.clone(),
            waiting: record.waiting.clone(),
            seed: record.seed,
            stored_bytes: record.stored_bytes,
            links: Links {
                result: format!("{this}/result"),
                events: format!("{this}/events"),
                shards: format!("{this}/shards"),
                distributions: format!("{this}/distributions/{{metric}}"),
                life: format!("{this}/life"),
                plots: format!("{this}/plots/{{kind}}"),
                this,
            },
            spec: None,
        }
    }
}

/// Submit a Monte Carlo job; it is queued durably before the response is sent.
///
/// The body is a Job (docs/contract.md "Job"): every field is optional, the scenario defaults to
/// the paper's rig. The response is the queued JobResource, with its URL in `Location`; follow
/// `links.events` for live progress and `links.result` once it succeeded. A job larger than the
/// server's `--max-job-operations` is 422 naming `/devices` (or `/precision/max_devices`); a full
/// queue is 429 with `Retry-After`; a key whose jobs store `--max-stored-mb-per-key` or more gets
/// 403 until it deletes some. Send an `Idempotency-Key` to retry safely.
#[utoipa::path(
    post, path = "/v1/jobs", tag = "jobs",
    request_body(content = JobSpec, description = "The job of docs/contract.md", content_type = "application/json"),
    params(("Idempotency-Key" = Option<String>, Header, description = "Retries with the same key and body within 24 hours get the job the first created (422 for another body); 1 to 255 visible ASCII characters (400 otherwise)", pattern = "^[!-~]{1,255}$", example = "4f1c2b9e-nightly-2026-11-22")),
    responses(
        (status = 202, description = "Queued (or, for a retry with the same Idempotency-Key, queued before: then `Idempotent-Replayed: true`)", body = JobResource, headers(("Location" = String, description = "The job's URL"), ("Idempotent-Replayed" = String, description = "`true` when an earlier request with the same Idempotency-Key created it"))),
        BodyRejected,
        Unauthorized,
        QueueFull,
        OverQuota,
    ),
    security((), ("api_key" = []))
)]
pub async fn submit_job(
    State(state): State<AppState>,
    Extension(owner): Extension<Owner>,
    headers: HeaderMap,
    JsonText(body): JsonText,
) -> Result<Response, ApiError> {
    let key = idempotency_key(&headers, &body)?;
    let job = Job::from_json(&body, draw_seed)?;
    job.check_size(state.config.max_job_operations, &Pointer::root())?;
    if job.rare_event().is_some() {
        // One device run to the operation read: off the async threads, in a place among the
        // requests that compute, so that many submissions at once take no more cores than those.
        let _place = super::limits::take_place(&state.parsing).await?;
        let checked = job.clone();
        tokio::task::spawn_blocking(move || {
            check_threshold(&checked, &Pointer::root().child("rare_event"))
        })
        .await
        .map_err(|error| Internal(format!("checking the rare event's threshold: {error}")))??;
    }
    let now = UnixMs::now();
    let new = QueuedJob::new(&job, owner, job.spec().name.clone(), now);
    let bound = state.config.queue_bound();
    let once = match key {
        Some(key) => state.store.insert_job_once(new, bound, &key, None).await?,
        None => state.store.insert_job(new, bound).await?.map(Once::Created),
    };
    match once.ok_or(ApiError::QueueFull(bound))? {
        Once::Created(record) => {
            state.wake.notify_one();
            crate::telemetry::record_jobs_submitted(1);
            accepted(&record)
        }
        Once::Replayed(record) => accepted(&record).map(replayed),
        Once::KeyReused => Err(ApiError::KeyReused(header_text(&headers))),
    }
}

/// The `Idempotency-Key` a request sent, for the problem that names it.
pub fn header_text(headers: &HeaderMap) -> String {
    headers
        .get(super::IDEMPOTENCY_KEY)
        .and_then(|v| v.to_str().ok())
        .unwrap_or_default()
        .to_owned()
}

/// 202 for a job that entered the queue: the job resource, and its URL in `Location`.
pub fn accepted(record: &JobRecord) -> Result<Response, ApiError> {
    let resource = JobResource::from_record(record);
    let location =
        HeaderValue::from_str(&resource.links.this).map_err(|e| Internal(e.to_string()))?;
    Ok((
        StatusCode::ACCEPTED,
        [(header::LOCATION, location)],
        Json(resource),
    )
        .into_response())
}

#[derive(Debug, Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub struct ListQuery {
    /// Page size, 1 to 100 (default 20 jobs, 100 schedules).
    #[param(minimum = 1, maximum = 100, example = 20)]
    pub limit: Option<u32>,
    /// `next_cursor` of the previous page: opaque, as this database's instances give it.
    #[param(pattern = "^[0-9a-f]{24}$", example = "5d1e0c7a9b3f4e2a81c6d0b9")]
    pub cursor: Option<String>,
}

impl ListQuery {
    /// The page asked for: its size (`default` without `limit`) and the `seq` the cursor, opened
    /// with `key`, stands after.
    pub fn page(&self, default: u32, key: &CursorKey) -> Result<(u32, Option<i64>), ApiError> {
        let limit = self.limit.unwrap_or(default);
        if !(1..=100).contains(&limit) {
            return Err(ApiError::BadRequest(format!(
                "limit must be from 1 to 100, got {limit}"
            )));
        }
        let seq = self
            .cursor
            .as_deref()
            .map(|cursor| key.open(cursor).ok_or_else(|| not_given(cursor)));
        Ok((limit, seq.transpose()?))
    }

    /// `records`, read one more than the page (`limit + 1`), cut to the page; the cursor of the
    /// next page (the last record's `seq`, sealed with `key`), only where another page has
    /// records.
    pub fn cut<T>(
        records: &mut Vec<T>,
        limit: u32,
        key: &CursorKey,
        seq: impl Fn(&T) -> i64,
    ) -> Option<String> {
        last_of_page(records, limit).map(|last| key.seal(seq(last)))
    }
}

/// `records`, read one more than the page (`limit + 1`), cut to the page; its last record where
/// another page has records.
fn last_of_page<T>(records: &mut Vec<T>, limit: u32) -> Option<&T> {
    let more = records.len() > limit as usize;
    records.truncate(limit as usize);
    more.then(|| records.last()).flatten()
}

fn not_given(cursor: &str) -> ApiError {
    ApiError::BadRequest(format!("cursor `{cursor}` is not one this server gave"))
}

/// The place a shards cursor this server gave stands for: as the documented pattern, digits,
/// the first not 0 (`01` is no cursor this server gave).
fn shards_cursor(cursor: &str) -> Result<u64, ApiError> {
    (!cursor.starts_with('0') && cursor.bytes().all(|b| b.is_ascii_digit()))
        .then(|| cursor.parse::<u64>().ok())
        .flatten()
        .filter(|place| *place > 0 && *place <= i64::MAX as u64)
        .ok_or_else(|| not_given(cursor))
}

/// List your jobs, newest first, with cursor paging.
///
/// Pages of at most `limit` jobs (default 20); pass a page's `next_cursor` as `cursor` for the
/// next. With API keys, only your jobs.
#[utoipa::path(
    get, path = "/v1/jobs", tag = "jobs", params(ListQuery),
    responses(
        (status = 200, description = "A page of jobs", body = JobList),
        BadQuery,
        Unauthorized,
    ),
    security((), ("api_key" = []))
)]
pub async fn list_jobs(
    State(state): State<AppState>,
    Extension(owner): Extension<Owner>,
    query: Result<Query<ListQuery>, QueryRejection>,
) -> Result<Json<JobList>, ApiError> {
    let Query(query) = query?;
    let key = &state.store.cursor_key().of_list("jobs");
    let (limit, before) = query.page(20, key)?;
    // One more than the page: a cursor only where another page has jobs.
    let mut records = state
        .store
        .jobs(
            &owner,
            Page {
                before,
                limit: limit + 1,
            },
        )
        .await?;
    let next_cursor = ListQuery::cut(&mut records, limit, key, |r| r.seq);
    Ok(Json(JobList {
        jobs: records.iter().map(JobResource::from_record).collect(),
        next_cursor,
    }))
}

#[derive(Debug, Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub struct WaitQuery {
    /// Seconds to wait, at most 30 (and half the server's request timeout), for the job to end
    /// before answering: the answer comes the moment it succeeds, fails or is cancelled, or
    /// with the job as it is when the time passed. Without it (or 0), the answer is at once.
    #[param(minimum = 0, maximum = 30, example = 10)]
    pub wait_s: Option<f64>,
}

impl WaitQuery {
    /// How long to wait: `wait_s` checked, then cut to what the server allows.
    fn wait(
        query: Result<Query<WaitQuery>, QueryRejection>,
        state: &AppState,
    ) -> Result<std::time::Duration, ApiError> {
        let Query(query) = query?;
        let wait_s = query.wait_s.unwrap_or(0.0);
        if !(0.0..=MAX_WAIT_S).contains(&wait_s) {
            return Err(ApiError::BadRequest(format!(
                "wait_s must be from 0 to {MAX_WAIT_S} seconds, got {}",
                bouncewear_model::error::shown(wait_s)
            )));
        }
        Ok(std::time::Duration::from_secs_f64(wait_s).min(state.config.max_wait()))
    }
}

/// The job once it ended, or as it is after `wait` ([`super::watch::JobWatch::until_ended`]).
async fn ended_within(
    state: &AppState,
    owner: &Owner,
    id: &JobId,
    wait: std::time::Duration,
) -> Result<JobRecord, ApiError> {
    Ok(state
        .watch
        .until_ended(
            state.store.as_ref(),
            owner,
            id,
            wait,
            state.shutdown.clone(),
        )
        .await?)
}

/// A job's status and progress.
///
/// The JobResource: status (`queued`, `running`, `succeeded`, `failed`, `cancelled`), progress in
/// operations, times (RFC 3339), the seed, and links to the result and the event stream. With
/// `wait_s`, the answer waits for the job to end (for at most that long): one request instead of
/// asking again and again.
#[utoipa::path(
    get, path = "/v1/jobs/{id}", tag = "jobs",
    params(("id" = String, Path, description = "Job id"), WaitQuery),
    responses(
        (status = 200, description = "The job", body = JobResource),
        BadQuery,
        Unauthorized,
        NoSuchJob,
    ),
    security((), ("api_key" = []))
)]
pub async fn get_job(
    State(state): State<AppState>,
    Extension(owner): Extension<Owner>,
    Path(id): Path<JobId>,
    query: Result<Query<WaitQuery>, QueryRejection>,
) -> Result<Json<JobResource>, ApiError> {
    let wait = WaitQuery::wait(query, &state)?;
    if !wait.is_zero() {
        ended_within(&state, &owner, &id, wait).await?;
    }
    let (record, spec) = state.store.job_with_spec(&owner, &id).await?;
    Ok(Json(JobResource {
        spec: Some(spec),
        ..JobResource::from_record(&record)
    }))
}

/// One shard of a job: a group of devices of one batch (or the batch's merge step), as workers
/// claim it.
#[derive(Debug, Serialize, ToSchema)]
pub struct ShardResource {
    /// Batch of devices (0 unless a precision target added batches).
    pub batch: u64,
    /// Group within the batch; absent for the batch's merge step.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub group: Option<u64>,
    /// `queued`, `running` or `done`.
    pub status: String,
    /// Times it was claimed: 1 if it ran once; more after a worker died, stalled or failed.
    pub attempt: i64,
    /// Runs that failed (an error of the job itself), each retried after a backoff.
    pub failures: u64,
    /// Leases that expired before the run ended: its worker killed or stalled, or cut off from
    /// the database. Counted against a budget of their own.
    pub lost_leases: u64,
    /// The worker holding or last holding it (`PID-INSTANCE/SLOT`); null before its first claim.
    pub worker: Option<String>,
    /// Operations this shard has simulated.
    pub operations_done: u64,
    /// Operations in this shard.
    pub operations_total: u64,
    /// Why its last run did not finish (it failed, or waits for the database or for room); null
    /// while none has, and once the shard is done.
    pub error: Option<String>,
    /// One line per attempt that did not finish, oldest first: `attempt N (worker): failed: ...`,
    /// `attempt N (worker): lease lost`, or `attempt N (worker): stopped: job cancelled` (or
    /// `failed`) for a run its job's end stopped.
    pub history: Vec<String>,
}

impl ShardResource {
    fn from_record(record: ShardRecord) -> Self {
        Self {
            batch: record.shard.batch,
            group: record.shard.group,
            status: record.status,
            attempt: record.attempt.0,
            failures: record.failures,
            lost_leases: record.lost_leases,
            worker: record.worker,
            operations_done: record.operations_done,
            operations_total: record.operations_total,
            error: record.error,
            history: record.history,
        }
    }
}

/// A job's shards, a page of them.
#[derive(Debug, Serialize, ToSchema)]
pub struct ShardList {
    /// In batch order; in each batch its groups, then its merge step.
    pub shards: Vec<ShardResource>,
    /// Pass as `cursor` for the next page; absent on the last page.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub next_cursor: Option<String>,
}

/// Most shards in a page, and the default: a job of one batch has at most 33.
const SHARDS_PAGE: u32 = 1000;

#[derive(Debug, Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub struct ShardsQuery {
    /// Page size, 1 to 1000 (default 1000).
    #[param(minimum = 1, maximum = 1000, example = 1000)]
    pub limit: Option<u32>,
    /// `next_cursor` of the previous page.
    #[param(pattern = "^[1-9][0-9]{0,18}$", example = "1000")]
    pub cursor: Option<String>,
}

/// The shards a job runs as, on any worker of any machine: where each stands and how often it
/// ran. An operator's view: a shard with more than one attempt was rerun.
///
/// Each shard's status (`queued`, `running`, `done`), attempts, failures, the worker that holds or
/// held it, and its operations. Pages of at most `limit` shards (default and most 1000); pass a
/// page's `next_cursor` as `cursor` for the next.
#[utoipa::path(
    get, path = "/v1/jobs/{id}/shards", tag = "jobs",
    params(("id" = String, Path, description = "Job id"), ShardsQuery),
    responses(
        (status = 200, description = "A page of the job's shards", body = ShardList),
        BadQuery,
        Unauthorized,
        NoSuchJob,
    ),
    security((), ("api_key" = []))
)]
pub async fn get_shards(
    State(state): State<AppState>,
    Extension(owner): Extension<Owner>,
    Path(id): Path<JobId>,
    query: Result<Query<ShardsQuery>, QueryRejection>,
) -> Result<Json<ShardList>, ApiError> {
    let Query(query) = query?;
    let limit = query.limit.unwrap_or(SHARDS_PAGE);
    if !(1..=SHARDS_PAGE).contains(&limit) {
        return Err(ApiError::BadRequest(format!(
            "limit must be from 1 to {SHARDS_PAGE}, got {limit}"
        )));
    }
    // The cursor is the place of the next page's first shard in the list.
    let skip = query
        .cursor
        .as_deref()
        .map(shards_cursor)
        .transpose()?
        .unwrap_or(0);
    state.store.job(&owner, &id).await?;
    // One more than the page: a cursor only where another page has shards.
    let mut shards = state
        .store
        .shards_from(&id, skip, u64::from(limit) + 1)
        .await?;
    // The next page starts where this one ends, whatever its last shard.
    let next = skip + u64::from(limit);
    let next_cursor = last_of_page(&mut shards, limit).map(|_| next.to_string());
    Ok(Json(ShardList {
        shards: shards.into_iter().map(ShardResource::from_record).collect(),
        next_cursor,
    }))
}

#[derive(Debug, Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub struct DeleteQuery {
    /// `true`: delete a job that ended, a cancelled one included, with everything stored for it.
    /// Without it, a cancelled job is kept, so a retried cancel never destroys the record.
    #[param(example = false)]
    pub purge: Option<bool>,
}

/// Cancel a queued or running job; delete a job that succeeded or failed, with everything stored
/// for it.
///
/// A queued or running job is cancelled and its resource returned (200): workers stop at their next
/// check. A cancelled job is returned as it is (200): a retried cancel changes nothing. A job that
/// succeeded or failed is deleted with its result, distributions and device lives (204); a later
/// GET is 404. `purge=true` deletes any job that ended, a cancelled one too (204).
#[utoipa::path(
    delete, path = "/v1/jobs/{id}", tag = "jobs", params(("id" = String, Path, description = "Job id"), DeleteQuery),
    responses(
        (status = 200, description = "Cancelled, now or before", body = JobResource),
        (status = 204, description = "The job had ended: deleted, with its result, distributions and device lives"),
        (status = 400, description = "A malformed `purge`", body = Problem, content_type = PROBLEM),
        Unauthorized,
        NoSuchJob,
    ),
    security((), ("api_key" = []))
)]
pub async fn cancel_job(
    State(state): State<AppState>,
    Extension(owner): Extension<Owner>,
    Path(id): Path<JobId>,
    query: Result<Query<DeleteQuery>, QueryRejection>,
) -> Result<Response, ApiError> {
    let Query(query) = query?;
    let purge = query.purge.unwrap_or(false);
    let (record, had_ended) = cancel(&state, &owner, &id).await?;
    if !had_ended || (record.status == JobStatus::Cancelled && !purge) {
        return Ok(Json(JobResource::from_record(&record)).into_response());
    }
    // Told before it goes: a stream that has not read its end yet would find nothing.
    state.watch.deleting(record);
    state.store.delete_job(&owner, &id).await?;
    Ok(StatusCode::NO_CONTENT.into_response())
}

/// Cancels the job unless it has ended: its record then, and whether it had ended before.
async fn cancel(
    state: &AppState,
    owner: &Owner,
    id: &JobId,
) -> Result<(JobRecord, bool), ApiError> {
    match state.store.cancel(owner, id, None).await {
        Ok(record) => {
            metrics::counter!("bouncewear_jobs_finished_total", "status" => "cancelled")
                .increment(1);
            Ok((record, false))
        }
        Err(StoreError::Conflict(_)) => Ok((state.store.job(owner, id).await?, true)),
        Err(error) => Err(error.into()),
    }
}

/// Cancel a queued or running job; never delete one.
///
/// A queued or running job is cancelled and its resource returned: workers stop at their next
/// check. A job that had already ended (succeeded, failed or cancelled) is returned as it is:
/// unlike `DELETE`, this never deletes anything, so a client may call it on a job in any state.
#[utoipa::path(
    post, path = "/v1/jobs/{id}/cancel", tag = "jobs", params(("id" = String, Path, description = "Job id")),
    responses(
        (status = 200, description = "The job: cancelled now, or as it had ended", body = JobResource),
        BadQuery,
        Unauthorized,
        NoSuchJob,
    ),
    security((), ("api_key" = []))
)]
pub async fn cancel_only(
    State(state): State<AppState>,
    Extension(owner): Extension<Owner>,
    Path(id): Path<JobId>,
) -> Result<Json<JobResource>, ApiError> {
    let (record, _) = cancel(&state, &owner, &id).await?;
    Ok(Json(JobResource::from_record(&record)))
}

/// The job, if it succeeded: results exist only then (409 before).
pub async fn succeeded(state: &AppState, owner: &Owner, id: &JobId) -> Result<JobRecord, ApiError> {
    has_succeeded(state.store.job(owner, id).await?)
}

/// The job's record, if it succeeded (409 before).
pub fn has_succeeded(record: JobRecord) -> Result<JobRecord, ApiError> {
    let (id, status) = (&record.id, record.status.as_str());
    match record.status {
        JobStatus::Succeeded => {}
        JobStatus::Queued | JobStatus::Running => {
            return Err(ApiError::Conflict(format!(
                "job {id} is {status}; results exist once it succeeds"
            )));
        }
        JobStatus::Failed | JobStatus::Cancelled => {
            return Err(ApiError::Conflict(format!(
                "job {id} is {status}: it ended without results (only a succeeded job has them)"
            )));
        }
    }
    Ok(record)
}

/// The Result of docs/contract.md (409 until the job succeeded).
///
/// The whole Result: the resolved job, per-bin summaries of every operation metric, device
/// summaries, life analysis, precision, counts, diagnostics and timing. It never changes, so it
/// carries an `ETag` and `Cache-Control: immutable`; `If-None-Match` gets 304. With `wait_s`, the
/// answer waits for the job to end (for at most that long): the Result the moment it is stored.
#[utoipa::path(
    get, path = "/v1/jobs/{id}/result", tag = "jobs",
    params(("id" = String, Path, description = "Job id"), WaitQuery),
    responses(
        (status = 200, description = "The result", body = JobResult, headers(("ETag" = String, description = "A tag of the content, for If-None-Match"), ("Cache-Control" = String, description = "Immutable for a year"))),
        NotModified,
        BadQuery,
        Unauthorized,
        NoSuchJob,
        NotSucceeded,
    ),
    security((), ("api_key" = []))
)]
pub async fn get_result(
    State(state): State<AppState>,
    Extension(owner): Extension<Owner>,
    Path(id): Path<JobId>,
    query: Result<Query<WaitQuery>, QueryRejection>,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    let wait = WaitQuery::wait(query, &state)?;
    has_succeeded(ended_within(&state, &owner, &id, wait).await?)?;
    let identity = format!("{id}/result");
    if let Some(unchanged) = not_modified(&state, &headers, identity.as_bytes()) {
        return Ok(unchanged);
    }
    // A Result can be tens of MB once decompressed: one read at a time per core, so that many
    // clients asking at once neither build them all (100 took 3.3 GB) nor take every connection
    // to the database from the health check.
    let _place = super::limits::take_place(&state.parsing).await?;
    let result = state
        .store
        .result_json(&id)
        .await?
        .ok_or_else(|| without_result(&id))?;
    let body = Body::from(result);
    Ok(immutable_identified(
        &state,
        &headers,
        JSON,
        identity.as_bytes(),
        body,
    ))
}

#[derive(Debug, Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub struct DistributionQuery {
    /// First operation of interest (bins ending after it are returned).
    #[param(example = 0)]
    pub op_start: Option<u64>,
    /// End of the range, exclusive (bins starting before it are returned).
    #[param(example = 100)]
    pub op_end: Option<u64>,
    /// `json` (default) or `csv`.
    #[param(inline, example = "csv")]
    pub format: Option<Format>,
    /// Quantile levels to answer after the run, each bin gaining `query.quantiles` keyed by the
    /// level in shortest form: 1 to 20 comma-separated numbers strictly between 0 and 1 (with
    /// `format=csv`: columns `q{level}`, `q{level}_ci95_lo`, `q{level}_ci95_hi`).
    #[param(pattern = "^[-+0-9.eE]+(,[-+0-9.eE]+){0,19}$", example = "0.5,0.999")]
    pub quantiles: Option<String>,
    /// Thresholds to answer after the run, each bin gaining `query.exceedance` in this order:
    /// 1 to 20 comma-separated `above:X` or `below:X`, X a finite number (with `format=csv`:
    /// columns `above:X`, `above:X_ci95_lo`, `above:X_ci95_hi`).
    #[param(
        pattern = "^(above|below):[-+0-9.eE]+(,(above|below):[-+0-9.eE]+){0,19}$",
        example = "above:0.005,below:0.002"
    )]
    pub exceedance: Option<String>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum Format {
    Json,
    Csv,
}

impl Format {
    /// The representation to send: `format` when the query names one; otherwise CSV when the
    /// request's `Accept` prefers `text/csv` to `application/json` (by quality, RFC 9110 section
    /// 12.5.1; a client that names only CSV gets CSV); otherwise JSON.
    pub fn negotiate(asked: Option<Format>, request: &HeaderMap) -> Format {
        if let Some(format) = asked {
            return format;
        }
        let accept = request
            .get_all(header::ACCEPT)
            .iter()
            .filter_map(|value| value.to_str().ok())
            .collect::<Vec<_>>()
            .join(",");
        // A type's quality is that of the most specific range that matches it (RFC 9110,
        // section 12.5.1): `text/csv` before `text/*` before `*/*`.
        let quality = |wanted: &str| {
            let (kind, _) = wanted.split_once('/').expect("a media type");
            accept
                .split(',')
                .filter_map(|range| {
                    let mut parts = range.split(';');
                    let media = parts.next()?.trim().to_ascii_lowercase();
                    let specificity = match media.split_once('/')? {
                        _ if media == wanted => 2,
                        (k, "*") if k == kind => 1,
                        ("*", "*") => 0,
                        _ => return None,
                    };
                    let q = parts
                        .filter_map(|p| p.trim().strip_prefix("q="))
                        .find_map(|q| q.trim().parse::<f64>().ok())
                        .unwrap_or(1.0);
                    Some((specificity, q))
                })
                .max_by(|a, b| a.0.cmp(&b.0).then(a.1.total_cmp(&b.1)))
                .map(|(_, q)| q)
        };
        match (quality("text/csv"), quality("application/json")) {
            (Some(csv), json) if csv > 0.0 && json.is_none_or(|json| csv > json) => Format::Csv,
            _ => Format::Json,
        }
    }
}

/// One stored bin: its SUMMARY and the operations it covers.
#[derive(Debug, Serialize, ToSchema)]
pub struct DistributionBin {
    #[serde(flatten)]
    pub summary: Summary,
    /// First operation of the bin (0-based).
    pub op_start: u64,
    /// End of the bin, exclusive.
    pub op_end: u64,
    /// With `quantiles` or `exceedance`: their answers for this bin, with 95 % intervals.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub query: Option<QueryAnswer>,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct Distribution {
    /// The job's id.
    #[schema(format = "uuid")]
    pub job_id: String,
    /// The metric's name.
    pub metric: String,
    /// `operation` (one bin per `bin_operations`) or `device` (one summary at the end of the test).
    pub kind: String,
    /// The bins in the range, in operation order.
    pub bins: Vec<DistributionBin>,
}

/// One metric's bins, as JSON or CSV, optionally for a range of operations, optionally with any
/// quantile and any threshold answered after the run.
///
/// `format=json` (default) gives the bins as JSON, `format=csv` one CSV row per bin
/// (`op_start,op_end,n,mean,...`, every quantile with its interval). `op_start` and `op_end` select
/// the bins that overlap the range; an empty range has no bins (404). With `quantiles` or
/// `exceedance` (400 for a bad item, naming the parameter) each bin gains `query`: the asked
/// quantiles and exceedance probabilities, from the bin's stored groups with the summaries'
/// estimators and intervals (409 for a job stored before groups were kept); in CSV, columns after
/// the others, in the order asked.
#[utoipa::path(
    get, path = "/v1/jobs/{id}/distributions/{metric}", tag = "jobs",
    params(("id" = String, Path, description = "Job id"), ("metric" = String, Path, description = "An operation or device metric"), DistributionQuery),
    responses(
        (status = 200, description = "The bins: JSON, or with `format=csv` one CSV row per bin", content((Distribution = "application/json"), (String = "text/csv")), headers(("ETag" = String, description = "A tag of the content, for If-None-Match"), ("Cache-Control" = String, description = "Immutable for a year"))),
        NotModified,
        BadQuery,
        Unauthorized,
        (status = 404, description = "No such job, or the job has no such metric", body = Problem, content_type = PROBLEM),
        NotSucceeded,
    ),
    security((), ("api_key" = []))
)]
pub async fn get_distribution(
    State(state): State<AppState>,
    Extension(owner): Extension<Owner>,
    Path((id, metric)): Path<(JobId, String)>,
    query: Result<Query<DistributionQuery>, QueryRejection>,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    let Query(query) = query?;
    let after_run = AfterRunQuery::parse(query.quantiles.as_deref(), query.exceedance.as_deref())
        .map_err(|bad| ApiError::BadRequest(bad.to_string()))?;
    let format = Format::negotiate(query.format, &headers);
    let (op_start, op_end) = (
        query.op_start.unwrap_or(0),
        query.op_end.unwrap_or(u64::MAX),
    );
    // A metric the job does not compute is 404 whatever its status: it never will.
    let (record, spec) = state.store.job_with_spec(&owner, &id).await?;
    let Some(parsed) = Metric::parse(&metric) else {
        return Err(ApiError::NotFound(format!(
            "no metric `{metric}`; known: {}",
            Metric::all_names()
        )));
    };
    if !spec.computes(&metric) {
        return Err(ApiError::NotFound(format!(
            "job {id} does not compute `{metric}`: it was not among its `metrics`"
        )));
    }
    let record = has_succeeded(record)?;
    if op_start >= op_end {
        // Half-open: `[10, 10)` holds no operation, so no bin overlaps it (the store's overlap
        // test alone would take the bin around 10).
        return Err(ApiError::NotFound(format!(
            "operations {op_start} to {op_end} hold no operation, so no bin: op_end must exceed op_start"
        )));
    }
    let range = Operations {
        start: op_start,
        end: op_end,
    };
    let rows = state.store.distribution(&record.id, &metric, range).await?;
    let kind = rows.first().map(|r| r.kind.clone());
    let Some(kind) = kind else {
        return Err(ApiError::NotFound(format!(
            "job {id} has no bins of `{metric}` in that range"
        )));
    };
    let levels = after_run
        .as_ref()
        .map_or_else(Vec::new, |q| asked_levels(&q.levels));
    let mut answers = match after_run {
        Some(after_run) => {
            let groups = state
                .store
                .distribution_groups(&record.id, &metric, range)
                .await?;
            let ranges = rows.iter().map(|row| row.op_start..row.op_end).collect();
            answer(parsed, ranges, groups, after_run).await?
        }
        None => Vec::new(),
    }
    .into_iter();
    let bins: Vec<DistributionBin> = rows
        .into_iter()
        .map(|row| DistributionBin {
            summary: row.summary,
            op_start: row.op_start,
            op_end: row.op_end,
            query: answers.next(),
        })
        .collect();
    let large = bins.len() >= LARGE_DISTRIBUTION_BINS;
    let job_id = record.id.to_string();
    let represent = move || -> Result<_, ApiError> {
        Ok(match format {
            Format::Json => {
                let distribution = Distribution {
                    job_id,
                    metric,
                    kind,
                    bins,
                };
                (JSON, Tagged::new(to_json(&distribution)?))
            }
            Format::Csv => (CSV, Tagged::new(to_csv(&bins, &levels))),
        })
    };
    let (content_type, tagged) = if large {
        tokio::task::spawn_blocking(represent)
            .await
            .map_err(|e| Internal(format!("writing the distribution: {e}")))??
    } else {
        represent()?
    };
    Ok(immutable_tagged(&state, &headers, content_type, tagged))
}

/// Each bin's answer to `after_run`, from its stored groups, off the async threads (a wide range
/// of a large job decodes many accumulators); 409 for a bin stored before groups were kept.
async fn answer(
    metric: Metric,
    ranges: Vec<std::ops::Range<u64>>,
    groups: Vec<Option<Vec<Accumulator>>>,
    after_run: AfterRunQuery,
) -> Result<Vec<QueryAnswer>, ApiError> {
    let groups: Vec<Vec<Accumulator>> = groups.into_iter().collect::<Option<_>>().ok_or_else(|| {
        ApiError::Conflict(
            "this job was stored before its groups were kept: rerun it to ask `quantiles` or `exceedance`"
                .to_owned(),
        )
    })?;
    tokio::task::spawn_blocking(move || {
        groups
            .iter()
            .zip(ranges)
            .map(|(bin, operations)| {
                query_metric(
                    metric,
                    operations,
                    bin,
                    &after_run.levels,
                    &after_run.thresholds,
                )
            })
            .collect()
    })
    .await
    .map_err(|e| Internal(e.to_string()).into())
}

pub(super) const JSON: &str = "application/json";
const CSV: &str = "text/csv; charset=utf-8";

pub(super) fn to_json(value: &impl Serialize) -> Result<Vec<u8>, ApiError> {
    serde_json::to_vec(value).map_err(|e| Internal(e.to_string()).into())
}

/// One row per bin: range, moments, intervals and every quantile; after them, the answers to a
/// query after the run: per level `q{level}` with its interval, per threshold `above:{x}` (or
/// `below:{x}`) with its interval, in the order asked (`levels`: the answers' keys so,
/// [`asked_levels`]).
fn to_csv(bins: &[DistributionBin], levels: &[String]) -> String {
    let mut csv = String::from("op_start,op_end,n,mean,mean_ci95_lo,mean_ci95_hi,sd,min,max");
    for (name, _) in QUANTILES {
        let _ = write!(csv, ",{name},{name}_ci95_lo,{name}_ci95_hi");
    }
    csv.push_str(",exceedance_limit,exceedance_probability,exceedance_ci95_lo,exceedance_ci95_hi");
    // A job's list of limits on the metric: the same in every bin.
    let limits = bins
        .first()
        .map_or(&[][..], |bin| &bin.summary.exceedances[..]);
    for limit in limits {
        let name = format!("exceedance_{}", threshold_name(limit.threshold));
        let _ = write!(csv, ",{name},{name}_ci95_lo,{name}_ci95_hi");
    }
    let asked = bins.first().and_then(|bin| bin.query.as_ref());
    if let Some(answer) = asked {
        for level in levels.iter().filter(|l| answer.quantiles.contains_key(*l)) {
            let _ = write!(csv, ",q{level},q{level}_ci95_lo,q{level}_ci95_hi");
        }
        for item in &answer.exceedance {
            let name = threshold_name(item.threshold);
            let _ = write!(csv, ",{name},{name}_ci95_lo,{name}_ci95_hi");
        }
    }
    csv.push('\n');
    for bin in bins {
        let s = &bin.summary;
        let _ = write!(
            csv,
            "{},{},{},{},{},{},{},{},{}",
            bin.op_start,
            bin.op_end,
            s.n,
            s.mean,
            s.mean_ci95[0],
            s.mean_ci95[1],
            s.sd,
            s.min,
            s.max
        );
        for (name, _) in QUANTILES {
            let q = &s.quantiles[name];
            let _ = write!(csv, ",{},{},{}", q.value, q.ci95[0], q.ci95[1]);
        }
        match &s.exceedance {
            Some(e) => {
                let [lo, hi] = e.ci95;
                let _ = write!(csv, ",{},{},{lo},{hi}", e.limit, e.probability);
            }
            None => csv.push_str(",,,,"),
        }
        for e in &s.exceedances {
            let _ = write!(csv, ",{},{},{}", e.probability, e.ci95[0], e.ci95[1]);
        }
        if let Some(answer) = &bin.query {
            for q in levels.iter().filter_map(|l| answer.quantiles.get(l)) {
                // A level the data cannot bound leaves its three cells empty.
                match (q.value, q.ci95) {
                    (Some(value), Some([lo, hi])) => {
                        let _ = write!(csv, ",{value},{lo},{hi}");
                    }
                    _ => csv.push_str(",,,"),
                }
            }
            for e in &answer.exceedance {
                let _ = write!(csv, ",{},{},{}", e.probability, e.ci95[0], e.ci95[1]);
            }
        }
        csv.push('\n');
    }
    csv
}

/// The levels of a query as its answers key them ([`level_key`]), in the order asked, each once
/// (a level asked twice has one answer).
fn asked_levels(levels: &[f64]) -> Vec<String> {
    let mut keys: Vec<String> = Vec::with_capacity(levels.len());
    for key in levels.iter().map(|&level| level_key(level)) {
        if !keys.contains(&key) {
            keys.push(key);
        }
    }
    keys
}

/// A threshold as a CSV column names it: `above:0.011`, `below:0.3`.
fn threshold_name(threshold: Threshold) -> String {
    match threshold {
        Threshold::Above(x) => format!("above:{x}"),
        Threshold::Below(x) => format!("below:{x}"),
    }
}

/// One Server-Sent Event as a client parses it; `data` is a JSON document.
#[derive(Debug, Serialize, ToSchema)]
pub struct ServerSentEvent {
    /// `progress`, `status`, or `deleted` (a job whose end the stream can no longer read).
    pub event: Option<String>,
    /// The event's JSON document.
    pub data: String,
    /// The job's state the event tells, `JOB:STATUS:OPERATIONS_DONE` (`JOB:deleted`): sent back
    /// as `Last-Event-ID` on reconnecting, a job's stream does not tell that state again.
    pub id: Option<String>,
    /// On the stream's first event: milliseconds to wait before reconnecting (2000).
    pub retry: Option<u64>,
}

#[derive(Debug, Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub struct LifeQuery {
    /// `json` (default): the analysis; `csv`: one row per device, `device,operations_to_failure,censored`.
    #[param(inline, example = "json")]
    pub format: Option<Format>,
    /// A Weibull shape taken as known, 0.01 to 100: the JSON adds `weibayes`, the scale and the
    /// B1 and B10 lives' one-sided lower bounds demonstrated with it (with no failures too); 400
    /// with the CSV, which lists the devices' lives.
    #[param(minimum = 0.01, maximum = 100, example = 2.0)]
    pub weibayes_beta: Option<f64>,
    /// The one-sided confidence of `weibayes` (default 0.9), strictly between 0 and 1: given only
    /// with `weibayes_beta` (alone it is 400).
    #[param(exclusive_minimum = 0, exclusive_maximum = 1, example = 0.9)]
    pub confidence: Option<f64>,
}

/// Life analysis of a job with failure criteria: Weibull (maximum likelihood with right censoring,
/// Fisher-matrix bounds), B1 and B10 life, Kaplan-Meier reliability; or each device's life as CSV.
///
/// Needs a job with `failure` criteria (404 otherwise). `format=json` (default) gives the analysis;
/// `format=csv` gives one row per device: `device,operations_to_failure,censored`
/// (`operations_to_failure` empty for a censored device: it survived the whole test).
#[utoipa::path(
    get, path = "/v1/jobs/{id}/life", tag = "jobs", params(("id" = String, Path, description = "Job id"), LifeQuery),
    responses(
        (status = 200, description = "The life analysis (JSON), or with `format=csv` one row per device: `device,operations_to_failure,censored` (`operations_to_failure` empty for a censored device)", content((bouncewear_model::montecarlo::LifeReport = "application/json"), (String = "text/csv")), headers(("ETag" = String, description = "A tag of the content, for If-None-Match"), ("Cache-Control" = String, description = "Immutable for a year"))),
        NotModified,
        BadQuery,
        Unauthorized,
        (status = 404, description = "No such job, or it has no failure criteria", body = Problem, content_type = PROBLEM),
        NotSucceeded,
    ),
    security((), ("api_key" = []))
)]
pub async fn get_life(
    State(state): State<AppState>,
    Extension(owner): Extension<Owner>,
    Path(id): Path<JobId>,
    query: Result<Query<LifeQuery>, QueryRejection>,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    let Query(query) = query?;
    let format = Format::negotiate(query.format, &headers);
    if format == Format::Csv && (query.weibayes_beta, query.confidence) != (None, None) {
        // Computed and left out of the devices' rows, it was ignored in silence.
        return Err(ApiError::BadRequest(
            "query parameters `weibayes_beta` and `confidence` ask the JSON analysis for a \
             Weibayes demonstration; the CSV lists each device's life: leave them out"
                .to_owned(),
        ));
    }
    // The query's own faults first, whatever the job's state (a running job's bad shape was a
    // 409, an outside probe).
    let refused = |error: WeibayesError| {
        let parameter = match error {
            WeibayesError::Confidence(_) => "confidence",
            _ => "weibayes_beta",
        };
        ApiError::BadRequest(format!("query parameter `{parameter}`: {error}"))
    };
    let demonstration = match (query.weibayes_beta, query.confidence) {
        (Some(beta), confidence) => {
            let confidence = confidence.unwrap_or(0.9);
            check_arguments(beta, confidence).map_err(refused)?;
            Some((beta, confidence))
        }
        (None, Some(_)) => {
            return Err(ApiError::BadRequest(
                "query parameter `confidence` is the confidence of `weibayes_beta`: give both"
                    .to_owned(),
            ));
        }
        (None, None) => None,
    };
    let _place = super::limits::take_place(&state.parsing).await?;
    let no_life = || {
        ApiError::NotFound(format!(
            "job {id} has no failure criteria, so no life analysis"
        ))
    };
    let result = result_asking(&state, &owner, &id, |spec| {
        (!spec.failure.is_empty()).then_some(()).ok_or_else(no_life)
    })
    .await?;
    let Some(mut life) = result.life else {
        return Err(no_life());
    };
    if let Some((beta, confidence)) = demonstration {
        let lives = life.lives(result.job.spec().operations);
        life.weibayes = Some(weibayes(&lives, beta, confidence).map_err(refused)?);
    }
    match format {
        Format::Json => Ok(immutable(&state, &headers, JSON, to_json(&life)?)),
        Format::Csv => {
            let identity = format!("{id}/life.csv");
            let body = Body::from_stream(life_csv(state.clone(), owner, id));
            Ok(immutable_identified(
                &state,
                &headers,
                CSV,
                identity.as_bytes(),
                body,
            ))
        }
    }
}

#[derive(Debug, Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub struct RareEventQuery {
    /// `json` (default): the estimate; `csv`: its tail curve, `threshold,probability` per row.
    #[param(inline, example = "json")]
    pub format: Option<Format>,
}

/// A job's rare event: the probability beyond its threshold, the interval, the design point and
/// the tail curve; or the tail curve as CSV.
///
/// Needs a job submitted with `rare_event` (404 otherwise). `format=json` (default) gives the
/// Result's `rare_event`; `format=csv` gives the tail curve, one row per threshold from the bulk
/// to the one asked: `threshold,probability`.
#[utoipa::path(
    get, path = "/v1/jobs/{id}/rare_event", tag = "jobs", params(("id" = String, Path, description = "Job id"), RareEventQuery),
    responses(
        (status = 200, description = "The estimate (JSON), or with `format=csv` its tail curve: `threshold,probability`", content((bouncewear_model::montecarlo::RareEventReport = "application/json"), (String = "text/csv")), headers(("ETag" = String, description = "A tag of the content, for If-None-Match"), ("Cache-Control" = String, description = "Immutable for a year"))),
        NotModified,
        BadQuery,
        Unauthorized,
        (status = 404, description = "No such job, or it asks no rare event", body = Problem, content_type = PROBLEM),
        NotSucceeded,
    ),
    security((), ("api_key" = []))
)]
pub async fn get_rare_event(
    State(state): State<AppState>,
    Extension(owner): Extension<Owner>,
    Path(id): Path<JobId>,
    query: Result<Query<RareEventQuery>, QueryRejection>,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    let Query(query) = query?;
    let _place = super::limits::take_place(&state.parsing).await?;
    let no_rare_event = || {
        ApiError::NotFound(format!(
            "job {id} asks no rare event: submit it with `rare_event`"
        ))
    };
    let result = result_asking(&state, &owner, &id, |spec| {
        spec.rare_event
            .is_some()
            .then_some(())
            .ok_or_else(no_rare_event)
    })
    .await?;
    let Some(rare) = result.rare_event else {
        return Err(no_rare_event());
    };
    Ok(match Format::negotiate(query.format, &headers) {
        Format::Json => immutable(&state, &headers, JSON, to_json(&rare)?),
        Format::Csv => immutable(&state, &headers, CSV, tail_csv(&rare)),
    })
}

/// The tail curve as CSV, every number as Rust prints it (shortest round-trip).
fn tail_csv(report: &bouncewear_model::montecarlo::RareEventReport) -> String {
    let mut csv = String::from("threshold,probability\n");
    for point in &report.tail {
        let _ = writeln!(csv, "{},{}", point.threshold, point.probability);
    }
    csv
}

/// Devices a page of the life CSV reads from the store at a time.
const LIVES_PER_PAGE: u32 = 10_000;

/// The life CSV of a job, its header and then one page of listed devices at a time: what a
/// response holds in memory is one page, whatever the job's size. A store error ends the stream
/// (the client sees a truncated body: the status line is sent before the rows), and so does the
/// job's delete while it is read: the last page is served only if the job is still there once
/// it was read, since a page read after the delete is empty (a header alone came back as a
/// whole 200).
fn life_csv(
    state: AppState,
    owner: Owner,
    id: JobId,
) -> impl Stream<Item = Result<Bytes, crate::store::StoreError>> + Send {
    let header = Bytes::from_static(b"device,operations_to_failure,censored\n");
    let pages = futures_util::stream::try_unfold(Some(None), move |after| {
        let (state, owner, id) = (state.clone(), owner.clone(), id.clone());
        async move {
            let Some(after) = after else {
                return Ok(None);
            };
            let page = state.store.lives_page(&id, after, LIVES_PER_PAGE).await?;
            let last_page = page.len() < LIVES_PER_PAGE as usize;
            if last_page {
                state.store.job(&owner, &id).await?;
            }
            let Some(last) = page.last() else {
                return Ok(None);
            };
            let next = (!last_page).then_some(Some(last.device));
            let mut csv = String::with_capacity(page.len() * 16);
            for device in &page {
                // A censored device did not fail: it has no operations to failure.
                let _ = match device.censored {
                    true => writeln!(csv, "{},,true", device.device),
                    false => writeln!(
                        csv,
                        "{},{},false",
                        device.device, device.operations_to_failure
                    ),
                };
            }
            Ok(Some((Bytes::from(csv), next)))
        }
    });
    futures_util::stream::once(async move { Ok(header) }).chain(pages)
}

/// The Result of a succeeded job whose spec `asks` for a part of it: its error (a 404) when it
/// does not, whatever the job's status, since it never will; 409 before the job succeeds.
pub(super) async fn result_asking(
    state: &AppState,
    owner: &Owner,
    id: &JobId,
    asks: impl FnOnce(&JobSpec) -> Result<(), ApiError>,
) -> Result<JobResult, ApiError> {
    let (record, spec) = state.store.job_with_spec(owner, id).await?;
    asks(&spec)?;
    has_succeeded(record)?;
    stored_result(state, id).await
}

/// The stored Result of a succeeded job, parsed; one stored by an older build gets the life
/// fits it lacks ([`bouncewear_model::montecarlo::LifeReport::with_fits`]).
pub async fn stored_result(state: &AppState, id: &JobId) -> Result<JobResult, ApiError> {
    let mut result = state
        .store
        .result(id)
        .await?
        .ok_or_else(|| without_result(id))?;
    let operations = result.job.spec().operations;
    result.life = result.life.map(|life| life.with_fits(operations));
    Ok(result)
}

/// A succeeded job's result is stored with it and deleted with it: missing, the job was deleted
/// while the request ran (a DELETE racing this GET), so the job is not found.
fn without_result(id: &JobId) -> ApiError {
    ApiError::NotFound(format!("job {id} was deleted while this request ran"))
}
