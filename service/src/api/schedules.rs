//! `/v1/schedules`: nightly (or any cron) runs of a job template, and their trend.

use super::Path;
use super::error::{
    ApiError,
    responses::{
        BadQuery, BodyRejected, NoSuchSchedule, OverQuota, QueueFull, ReplacedMeanwhile,
        StaleTemplate, TooManySchedules, Unauthorized,
    },
};
use super::jobs::{JobResource, ListQuery, accepted, header_text};
use super::{AppState, JsonText, idempotency_key, replayed};
use crate::domain::trend::{RunValues, judges_later_runs, run_values, trend};
use crate::domain::{
    JobStatus, Once, Owner, ScheduleId, ScheduleSpec, TrendValue, UnixMs, ValidSchedule,
};
use crate::store::{NewRun, RunRecord, RunSlot, ScheduleRecord, Skipped};
use axum::extract::rejection::QueryRejection;
use axum::extract::{Query, State};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use axum::{Extension, Json};
use bouncewear_model::montecarlo::JobResult;
use chrono::Utc;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use utoipa::{IntoParams, ToSchema};
use utoipa_axum::router::OpenApiRouter;
use utoipa_axum::routes;

pub fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new()
        .routes(routes!(create_schedule, list_schedules))
        .routes(routes!(get_schedule, replace_schedule, delete_schedule))
        .routes(routes!(run_schedule_now))
        .routes(routes!(schedule_runs))
}

#[derive(Debug, Serialize, ToSchema)]
pub struct ScheduleResource {
    /// The schedule's id (a UUID).
    #[schema(format = "uuid")]
    pub id: String,
    /// The schedule's name.
    pub name: String,
    /// Its cron expression.
    pub cron: String,
    /// The IANA time zone its cron expression is read in.
    pub time_zone: String,
    /// Whether it runs on its timetable.
    pub enabled: bool,
    /// The job each run submits.
    #[schema(value_type = Object)]
    pub template: serde_json::Value,
    /// The statistics its trend follows.
    pub statistics: Vec<String>,
    /// RFC 3339; null when disabled, or when its timetable no longer parses (`last_skipped`
    /// says so) until a PUT.
    #[schema(format = DateTime)]
    pub next_run_at: Option<String>,
    /// RFC 3339; the due time of its latest run, if any.
    #[schema(format = DateTime)]
    pub last_run_at: Option<String>,
    /// How many of its runs were skipped at their due time (never run later): its template
    /// refused by the server's limits then, its key over its quota, or a later due time come first
    /// (a catch-up runs only the latest due time; counted up to 100,000 at a time).
    pub skipped_runs: u64,
    /// The latest skipped run, if any.
    pub last_skipped: Option<SkippedRun>,
    /// RFC 3339.
    #[schema(format = DateTime)]
    pub created_at: String,
    /// RFC 3339; when its definition last changed.
    #[schema(format = DateTime)]
    pub updated_at: String,
}

/// A run skipped at its due time.
#[derive(Debug, Serialize, ToSchema)]
pub struct SkippedRun {
    /// RFC 3339; its due time.
    #[schema(format = DateTime)]
    pub scheduled_for: String,
    /// Why it was skipped.
    pub reason: String,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct ScheduleList {
    /// Your schedules, oldest first.
    pub schedules: Vec<ScheduleResource>,
    /// Pass as `cursor` for the next page; absent on the last page.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub next_cursor: Option<String>,
}

/// The stored form of a valid schedule document, due next after `now`.
fn record(
    valid: ValidSchedule,
    id: ScheduleId,
    owner: Owner,
    created_at: UnixMs,
    now: UnixMs,
) -> ScheduleRecord {
    ScheduleRecord {
        next_run_at: valid.next_run_after(now),
        definition: valid.into_definition(),
        id,
        owner,
        created_at,
        updated_at: now,
        skipped: Skipped::default(),
        revision: 0,
    }
}

async fn resource(state: &AppState, record: &ScheduleRecord) -> Result<ScheduleResource, ApiError> {
    let last = state
        .store
        .runs(&record.id, 1)
        .await?
        .first()
        .map(|run| run.scheduled_for.to_rfc3339());
    let definition = &record.definition;
    Ok(ScheduleResource {
        id: record.id.to_string(),
        name: definition.name.clone(),
        cron: definition.cron.clone(),
        time_zone: definition.time_zone.clone(),
        enabled: definition.enabled,
        template: serde_json::to_value(&definition.template).unwrap_or_default(),
        statistics: definition
            .statistics
            .iter()
            .map(ToString::to_string)
            .collect(),
        next_run_at: record.next_run_at.map(UnixMs::to_rfc3339),
        last_run_at: last,
        skipped_runs: record.skipped.runs,
        last_skipped: record
            .skipped
            .last
            .as_ref()
            .map(|(due, reason)| SkippedRun {
                scheduled_for: due.to_rfc3339(),
                reason: reason.clone(),
            }),
        created_at: record.created_at.to_rfc3339(),
        updated_at: record.updated_at.to_rfc3339(),
    })
}

/// Create a schedule.
///
/// The body is a ScheduleSpec: a name, a cron expression in a time zone, the job template each run
/// submits and the statistics to follow. Returns 201 with the schedule and its URL in `Location`.
/// Send an `Idempotency-Key` to retry safely.
#[utoipa::path(
    post, path = "/v1/schedules", tag = "schedules",
    request_body(content = ScheduleSpec, content_type = "application/json"),
    params(("Idempotency-Key" = Option<String>, Header, description = "Retries with the same key and body within 24 hours get the schedule the first created (422 for another body); 1 to 255 visible ASCII characters (400 otherwise)", pattern = "^[!-~]{1,255}$", example = "4f1c2b9e-nightly-2026-11-22")),
    responses(
        (status = 201, description = "Created (or, for a retry with the same Idempotency-Key, created before: then `Idempotent-Replayed: true`)", body = ScheduleResource, headers(("Location" = String, description = "The schedule's URL"), ("Idempotent-Replayed" = String, description = "`true` when an earlier request with the same Idempotency-Key created it"))),
        BodyRejected,
        Unauthorized,
        TooManySchedules,
    ),
    security((), ("api_key" = []))
)]
pub async fn create_schedule(
    State(state): State<AppState>,
    Extension(owner): Extension<Owner>,
    headers: HeaderMap,
    JsonText(body): JsonText,
) -> Result<Response, ApiError> {
    let key = idempotency_key(&headers, &body)?;
    let valid = ValidSchedule::parse(&body, state.config.schedule_limits(), Utc::now())?;
    // Due times are the database's, as the scheduler reads them (`Store::now`).
    let now = state.store.now().await?;
    let record = record(valid, ScheduleId::generate(), owner, now, now);
    let bound = state.config.schedule_bound();
    let once = match key {
        Some(key) => {
            state
                .store
                .insert_schedule_once(&record, bound, &key, None)
                .await?
        }
        None => {
            state.store.insert_schedule(&record, bound).await?;
            Once::Created(record)
        }
    };
    match once {
        Once::Created(record) => created(&state, &record).await,
        Once::Replayed(record) => created(&state, &record).await.map(replayed),
        Once::KeyReused => Err(ApiError::KeyReused(header_text(&headers))),
    }
}

/// 201 for a schedule that was created: the resource, and its URL in `Location`.
async fn created(state: &AppState, record: &ScheduleRecord) -> Result<Response, ApiError> {
    let location = HeaderValue::from_str(&format!("/v1/schedules/{}", record.id))
        .map_err(|e| super::error::Internal(e.to_string()))?;
    Ok((
        StatusCode::CREATED,
        [(header::LOCATION, location)],
        Json(resource(state, record).await?),
    )
        .into_response())
}

/// Your schedules, oldest first, with cursor paging.
///
/// Pages of at most `limit` schedules (default 100, as many as a key holds by default); pass a
/// page's `next_cursor` as `cursor` for the next. With API keys, only your schedules.
#[utoipa::path(
    get, path = "/v1/schedules", tag = "schedules", params(ListQuery),
    responses(
        (status = 200, description = "A page of schedules", body = ScheduleList),
        BadQuery,
        Unauthorized,
    ),
    security((), ("api_key" = []))
)]
pub async fn list_schedules(
    State(state): State<AppState>,
    Extension(owner): Extension<Owner>,
    query: Result<Query<ListQuery>, QueryRejection>,
) -> Result<Json<ScheduleList>, ApiError> {
    let Query(query) = query?;
    let key = &state.store.cursor_key().of_list("schedules");
    let (limit, after) = query.page(100, key)?;
    // One more than the page: a cursor only where another page has schedules.
    let mut records = state.store.schedules(&owner, after, limit + 1).await?;
    let next_cursor = ListQuery::cut(&mut records, limit, key, |(seq, _)| *seq);
    let mut schedules = Vec::with_capacity(records.len());
    for (_, record) in &records {
        schedules.push(resource(&state, record).await?);
    }
    Ok(Json(ScheduleList {
        schedules,
        next_cursor,
    }))
}

/// One schedule.
///
/// Its definition, the next due time (null while disabled) and the due time of its latest run.
#[utoipa::path(
    get, path = "/v1/schedules/{id}", tag = "schedules", params(("id" = String, Path, description = "Schedule id")),
    responses(
        (status = 200, description = "The schedule", body = ScheduleResource),
        Unauthorized,
        NoSuchSchedule,
    ),
    security((), ("api_key" = []))
)]
pub async fn get_schedule(
    State(state): State<AppState>,
    Extension(owner): Extension<Owner>,
    Path(id): Path<ScheduleId>,
) -> Result<Json<ScheduleResource>, ApiError> {
    let record = state.store.schedule(&owner, &id).await?;
    Ok(Json(resource(&state, &record).await?))
}

/// Replace a schedule's definition (its runs stay).
///
/// The body is a whole ScheduleSpec, as for creation; the next due time is worked out again,
/// but a run already due and not yet made (waiting for room in the queue) stays due. Its runs and
/// their jobs stay.
#[utoipa::path(
    put, path = "/v1/schedules/{id}", tag = "schedules", params(("id" = String, Path, description = "Schedule id")),
    request_body(content = ScheduleSpec, content_type = "application/json"),
    responses(
        (status = 200, description = "Updated", body = ScheduleResource),
        BodyRejected,
        Unauthorized,
        NoSuchSchedule,
        ReplacedMeanwhile,
    ),
    security((), ("api_key" = []))
)]
pub async fn replace_schedule(
    State(state): State<AppState>,
    Extension(owner): Extension<Owner>,
    Path(id): Path<ScheduleId>,
    JsonText(body): JsonText,
) -> Result<Json<ScheduleResource>, ApiError> {
    let mut existing = state.store.schedule(&owner, &id).await?;
    // Worked out again from the schedule as it is if a run (or another PUT) moved it meanwhile:
    // a scheduler moves it once a due time.
    for _ in 0..REPLACE_TRIES {
        let valid = ValidSchedule::parse(&body, state.config.schedule_limits(), Utc::now())?;
        let now = state.store.now().await?;
        let next_run_at = valid.next_run_replacing(existing.next_run_at, now);
        let record = ScheduleRecord {
            next_run_at,
            skipped: existing.skipped.clone(),
            revision: existing.revision + 1,
            ..record(valid, id.clone(), owner.clone(), existing.created_at, now)
        };
        match state.store.update_schedule(&record, &existing).await? {
            None => return Ok(Json(resource(&state, &record).await?)),
            Some(moved) => existing = moved,
        }
    }
    Err(ApiError::Conflict(
        "the schedule kept changing while it was replaced (its runs, or other PUTs): send the \
         PUT again"
            .to_owned(),
    ))
}

/// Tries a PUT makes to replace a schedule that moves on meanwhile.
const REPLACE_TRIES: usize = 5;

/// Delete a schedule (its jobs stay).
///
/// Jobs it already submitted stay, with their results.
#[utoipa::path(
    delete, path = "/v1/schedules/{id}", tag = "schedules", params(("id" = String, Path, description = "Schedule id")),
    responses(
        (status = 204, description = "Deleted"),
        Unauthorized,
        NoSuchSchedule,
    ),
    security((), ("api_key" = []))
)]
pub async fn delete_schedule(
    State(state): State<AppState>,
    Extension(owner): Extension<Owner>,
    Path(id): Path<ScheduleId>,
) -> Result<StatusCode, ApiError> {
    state.store.delete_schedule(&owner, &id).await?;
    Ok(StatusCode::NO_CONTENT)
}

/// The milliseconds from its request on that a manual run may take as its key, each not taken yet
/// by another manual run nor a due time.
const MANUAL_RUN_SLOTS: i64 = 16;

/// Run a schedule now, outside its timetable.
///
/// Queues one job from the template now (202, the job's URL in `Location`); it counts in the trend
/// as a manual run. A full queue is 429 with `Retry-After`, as is a run when the schedule's manual
/// runs took each of the 16 milliseconds from the request on; a key whose jobs store its quota or
/// more, 403; a schedule whose stored template no longer validates, 409.
#[utoipa::path(
    post, path = "/v1/schedules/{id}/run", tag = "schedules", params(("id" = String, Path, description = "Schedule id")),
    responses(
        (status = 202, description = "The job it queued", body = JobResource, headers(("Location" = String, description = "The job's URL"))),
        Unauthorized,
        NoSuchSchedule,
        StaleTemplate,
        QueueFull,
        OverQuota,
    ),
    security((), ("api_key" = []))
)]
pub async fn run_schedule_now(
    State(state): State<AppState>,
    Extension(owner): Extension<Owner>,
    Path(id): Path<ScheduleId>,
) -> Result<Response, ApiError> {
    let schedule = state.store.schedule(&owner, &id).await?;
    let now = state.store.now().await?;
    // A manual run is keyed by its own time; two in the same millisecond take the next one, and
    // none takes a due time, its scheduled run's.
    for offset in 0..MANUAL_RUN_SLOTS {
        let at = now.plus_ms(offset);
        if schedule.definition.is_due_time(at) {
            continue;
        }
        let job = schedule
            .definition
            .job_at(owner.clone(), at, now, state.config.max_job_operations)
            .map_err(|invalid| {
                ApiError::Conflict(format!(
                    "the schedule's stored template no longer validates ({invalid}): PUT the \
                     schedule with a valid one"
                ))
            })?;
        let slot = RunSlot {
            schedule: &schedule.id,
            scheduled_for: at,
            manual: true,
            moves: None,
        };
        match state
            .store
            .create_run(slot, job, state.config.queue_bound())
            .await?
        {
            NewRun::Created(record) => {
                state.wake.notify_one();
                crate::telemetry::record_jobs_submitted(1);
                return accepted(&record);
            }
            // (`Moved` comes only of a due run's move, which a run asked for has not.)
            NewRun::AlreadyExists | NewRun::Moved => continue,
            NewRun::QueueFull => return Err(ApiError::QueueFull(state.config.queue_bound())),
        }
    }
    Err(ApiError::TooManyRuns)
}

#[derive(Debug, Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub struct RunsQuery {
    /// How many of the latest runs, 1 to 366 (default 60).
    #[param(minimum = 1, maximum = 366, example = 30)]
    pub limit: Option<u32>,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct Run {
    /// RFC 3339: the due time (or the request time of a manual run).
    #[schema(format = DateTime)]
    pub scheduled_for: String,
    /// The job the run submitted.
    #[schema(format = "uuid")]
    pub job_id: String,
    /// The job's status.
    pub status: JobStatus,
    /// Whether it was started by `POST /v1/schedules/{id}/run`.
    pub manual: bool,
    /// Each statistic's value, its 95 % interval, and whether it left the previous run's interval;
    /// null until the job succeeded or when the result lacks the statistic.
    #[schema(value_type = Object)]
    pub values: BTreeMap<String, Option<TrendValue>>,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct Trend {
    /// The schedule's id.
    #[schema(format = "uuid")]
    pub schedule_id: String,
    /// The statistics followed.
    pub statistics: Vec<String>,
    /// Oldest first.
    pub runs: Vec<Run>,
}

/// The run-by-run trend of the schedule's statistics, with drift flags.
///
/// The latest `limit` runs (default 60), oldest first, each with its job, status, and for every
/// statistic its value, its 95 % interval and whether it drifted out of the previous run's
/// interval.
#[utoipa::path(
    get, path = "/v1/schedules/{id}/runs", tag = "schedules", params(("id" = String, Path, description = "Schedule id"), RunsQuery),
    responses(
        (status = 200, description = "Runs, oldest first", body = Trend),
        BadQuery,
        Unauthorized,
        NoSuchSchedule,
    ),
    security((), ("api_key" = []))
)]
pub async fn schedule_runs(
    State(state): State<AppState>,
    Extension(owner): Extension<Owner>,
    Path(id): Path<ScheduleId>,
    query: Result<Query<RunsQuery>, QueryRejection>,
) -> Result<Json<Trend>, ApiError> {
    let Query(query) = query?;
    let limit = query.limit.unwrap_or(60);
    if !(1..=366).contains(&limit) {
        return Err(ApiError::BadRequest(format!(
            "limit must be from 1 to 366, got {limit}"
        )));
    }
    let schedule = state.store.schedule(&owner, &id).await?;
    Ok(Json(schedule_trend(&state, &schedule, limit).await?))
}

/// The most runs older than the asked window that the trend looks back over for the last run
/// with a Result, whose interval the window's oldest value is compared with.
pub const DRIFT_LOOKBACK: u32 = 30;

/// The trend of a schedule's `limit` latest runs, oldest first. Each value's drift flag compares
/// it with the run before that has a value of the same statistic, within the window or before it
/// (up to [`DRIFT_LOOKBACK`] runs older): a run's flag does not depend on the window asked. It
/// reads each run's end alone ([`Store::result_ends`](crate::store::Store::result_ends)), one at
/// a time, in a place of its own among the requests that parse stored Results.
pub async fn schedule_trend(
    state: &AppState,
    schedule: &ScheduleRecord,
    limit: u32,
) -> Result<Trend, ApiError> {
    let _place = super::limits::take_place(&state.parsing).await?;
    let mut runs = state
        .store
        .runs(&schedule.id, limit + DRIFT_LOOKBACK)
        .await?;
    let older = runs.split_off(runs.len().min(limit as usize));
    runs.reverse();
    let statistics = &schedule.definition.statistics;
    let mut window = Vec::with_capacity(runs.len());
    for run in &runs {
        window.push(run_values(
            statistics,
            run_result(state, run).await?.as_ref(),
        ));
    }
    // The runs before the window, newest first, until every statistic the window has a value
    // judged by the run before of has one such value among them too ([`judges_later_runs`]: a
    // life statistic may have none in a run of too few failures, a quantile may carry a reason):
    // put before the window, they give its oldest values the runs they are compared with. A
    // statistic without such a value in the window needs none, and costs no reading.
    let judges = |values: &RunValues, column: usize| judges_later_runs(values[column].as_ref());
    let mut unmet: Vec<usize> = (0..statistics.len())
        .filter(|&column| window.iter().any(|values| judges(values, column)))
        .collect();
    let mut looked_back = Vec::new();
    for run in &older {
        if unmet.is_empty() {
            break;
        }
        if let Some(result) = run_result(state, run).await? {
            let values = run_values(statistics, Some(&result));
            unmet.retain(|&column| !judges(&values, column));
            looked_back.push(values);
        }
    }
    looked_back.reverse();
    let skipped = looked_back.len();
    looked_back.extend(window);
    let runs = runs
        .iter()
        .zip(trend(statistics, &looked_back).into_iter().skip(skipped))
        .map(|(run, values)| Run {
            scheduled_for: run.scheduled_for.to_rfc3339(),
            job_id: run.job_id.to_string(),
            status: run.status,
            manual: run.manual,
            values,
        })
        .collect();
    Ok(Trend {
        schedule_id: schedule.id.to_string(),
        statistics: statistics.iter().map(ToString::to_string).collect(),
        runs,
    })
}

/// A run's Result with its last bins alone ([`run_values`] reads no other), once its job
/// succeeded; none before, for a failed run, or for one whose job was deleted meanwhile.
async fn run_result(state: &AppState, run: &RunRecord) -> Result<Option<JobResult>, ApiError> {
    if run.status != JobStatus::Succeeded {
        return Ok(None);
    }
    Ok(state.store.result_ends(&run.job_id).await?)
}
