//! `/v1/schedules`: nightly (or any cron) runs of a job template, and their trend.

use super::jobs::{JobResource, rfc3339};
use super::{AppState, JsonText, Owner};
use crate::errors::{ApiError, Problem};
use crate::schedule::{Statistic, Timetable, TrendValue, flag_drift};
use crate::store::{NewRun, ScheduleRecord, now_ms};
use axum::extract::rejection::QueryRejection;
use axum::extract::{Path, Query, State};
use axum::http::{HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use axum::{Extension, Json};
use bouncewear_model::montecarlo::{Job, JobSpec};
use bouncewear_model::{FieldError, InvalidInput, Pointer};
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

const PROBLEM: &str = "application/problem+json";
const DEFAULT_STATISTIC: &str = "operations.total_bounce_s.p95";

/// A schedule as a client writes it.
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct ScheduleSpec {
    pub name: String,
    /// Cron expression: 5 fields (minute hour day month weekday), or 6 with seconds first.
    pub cron: String,
    /// IANA time zone the cron expression is read in (default `UTC`).
    #[serde(default)]
    pub time_zone: Option<String>,
    /// The job each run submits (CONTRACT.md "Job"). Without a `seed`, every run draws its own.
    pub template: JobSpec,
    /// Statistics the trend follows, e.g. `operations.total_bounce_s.p95` (last bin),
    /// `devices.eroded_mass_kg.mean`, `life.b10` (default: `operations.total_bounce_s.p95`).
    #[serde(default)]
    pub statistics: Option<Vec<String>>,
    #[serde(default)]
    pub enabled: Option<bool>,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct ScheduleResource {
    pub id: String,
    pub name: String,
    pub cron: String,
    pub time_zone: String,
    pub enabled: bool,
    #[schema(value_type = Object)]
    pub template: serde_json::Value,
    pub statistics: Vec<String>,
    /// RFC 3339; null when disabled.
    pub next_run_at: Option<String>,
    pub last_run_at: Option<String>,
    pub created_at: String,
    pub updated_at: String,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct ScheduleList {
    pub schedules: Vec<ScheduleResource>,
}

/// A schedule document that passed every rule: the parts of a [`ScheduleRecord`] a client sets.
struct ValidSchedule {
    name: String,
    cron: String,
    time_zone: String,
    template: String,
    statistics: String,
    enabled: bool,
    next_run_at: Option<i64>,
}

impl ValidSchedule {
    fn into_record(
        self,
        id: String,
        owner: String,
        created_at: i64,
        updated_at: i64,
    ) -> ScheduleRecord {
        ScheduleRecord {
            id,
            owner,
            name: self.name,
            cron: self.cron,
            time_zone: self.time_zone,
            template: self.template,
            statistics: self.statistics,
            enabled: self.enabled,
            next_run_at: self.next_run_at,
            created_at,
            updated_at,
        }
    }
}

/// Validates a schedule document, naming every field at fault.
fn validate(body: &str, max_job_operations: u64) -> Result<ValidSchedule, ApiError> {
    let spec: ScheduleSpec = bouncewear_model::error::from_json(
        body,
        &["/statistics", "/template/scatter", "/template/metrics"],
    )?;
    let root = Pointer::root();
    let mut errors = Vec::new();
    if spec.name.trim().is_empty() || spec.name.len() > 200 {
        errors.push(FieldError {
            pointer: "/name".into(),
            detail: "must be 1 to 200 characters".into(),
        });
    }
    let time_zone = spec.time_zone.clone().unwrap_or_else(|| "UTC".to_owned());
    let timetable = Timetable::parse(&spec.cron, &time_zone)
        .map_err(|(field, detail)| {
            errors.push(FieldError {
                pointer: root.child(field).to_string(),
                detail,
            })
        })
        .ok();
    let template = serde_json::to_string(&spec.template)
        .map_err(|e| crate::errors::Internal(e.to_string()))?;
    let at = root.child("template");
    if let Err(invalid) = Job::new(spec.template.clone(), || 0, &at)
        .and_then(|job| job.check_size(max_job_operations, &at))
    {
        errors.extend_from_slice(invalid.errors());
    }
    let statistics = spec
        .statistics
        .clone()
        .unwrap_or_else(|| vec![DEFAULT_STATISTIC.to_owned()]);
    if statistics.is_empty() {
        errors.push(FieldError {
            pointer: "/statistics".into(),
            detail: "must name at least one statistic".into(),
        });
    }
    for (i, statistic) in statistics.iter().enumerate() {
        if let Err(detail) = Statistic::check(statistic) {
            errors.push(FieldError {
                pointer: root.child("statistics").child(i).to_string(),
                detail,
            });
        }
    }
    if !errors.is_empty() {
        return Err(ApiError::Invalid(InvalidInput::new(errors)));
    }
    let enabled = spec.enabled.unwrap_or(true);
    let next_run_at = match (enabled, timetable) {
        (true, Some(timetable)) => timetable
            .next_after(chrono::Utc::now())
            .map(|t| t.timestamp_millis()),
        _ => None,
    };
    Ok(ValidSchedule {
        name: spec.name.trim().to_owned(),
        cron: spec.cron,
        time_zone,
        template,
        statistics: serde_json::to_string(&statistics)
            .map_err(|e| crate::errors::Internal(e.to_string()))?,
        enabled,
        next_run_at,
    })
}

async fn resource(state: &AppState, record: &ScheduleRecord) -> Result<ScheduleResource, ApiError> {
    let last = state
        .store
        .runs(&record.id, 1)
        .await?
        .first()
        .map(|run| rfc3339(run.scheduled_for));
    Ok(ScheduleResource {
        id: record.id.clone(),
        name: record.name.clone(),
        cron: record.cron.clone(),
        time_zone: record.time_zone.clone(),
        enabled: record.enabled,
        template: serde_json::from_str(&record.template).unwrap_or_default(),
        statistics: serde_json::from_str(&record.statistics).unwrap_or_default(),
        next_run_at: record.next_run_at.map(rfc3339),
        last_run_at: last,
        created_at: rfc3339(record.created_at),
        updated_at: rfc3339(record.updated_at),
    })
}

async fn find(state: &AppState, owner: &str, id: &str) -> Result<ScheduleRecord, ApiError> {
    state
        .store
        .schedule(owner, id)
        .await?
        .ok_or_else(|| ApiError::NotFound(format!("no schedule {id}")))
}

/// Create a schedule.
#[utoipa::path(
    post, path = "/v1/schedules", tag = "schedules",
    request_body(content = ScheduleSpec, content_type = "application/json"),
    responses(
        (status = 201, description = "Created", body = ScheduleResource, headers(("Location" = String, description = "The schedule's URL"))),
        (status = 400, description = "Malformed JSON", body = Problem, content_type = PROBLEM),
        (status = 401, description = "Missing or unknown API key", body = Problem, content_type = PROBLEM),
        (status = 413, description = "Body too large", body = Problem, content_type = PROBLEM),
        (status = 415, description = "Body is not JSON", body = Problem, content_type = PROBLEM),
        (status = 422, description = "A field breaks a rule", body = Problem, content_type = PROBLEM),
    ),
    security((), ("api_key" = []))
)]
pub async fn create_schedule(
    State(state): State<AppState>,
    Extension(Owner(owner)): Extension<Owner>,
    JsonText(body): JsonText,
) -> Result<Response, ApiError> {
    let now = now_ms();
    let record = validate(&body, state.config.max_job_operations)?.into_record(
        uuid::Uuid::new_v4().to_string(),
        owner,
        now,
        now,
    );
    state.store.insert_schedule(&record).await?;
    let location = HeaderValue::from_str(&format!("/v1/schedules/{}", record.id))
        .map_err(|e| crate::errors::Internal(e.to_string()))?;
    Ok((
        StatusCode::CREATED,
        [(header::LOCATION, location)],
        Json(resource(&state, &record).await?),
    )
        .into_response())
}

/// Your schedules, oldest first.
#[utoipa::path(
    get, path = "/v1/schedules", tag = "schedules",
    responses(
        (status = 200, description = "Schedules", body = ScheduleList),
        (status = 401, description = "Missing or unknown API key", body = Problem, content_type = PROBLEM),
    ),
    security((), ("api_key" = []))
)]
pub async fn list_schedules(
    State(state): State<AppState>,
    Extension(Owner(owner)): Extension<Owner>,
) -> Result<Json<ScheduleList>, ApiError> {
    let mut schedules = Vec::new();
    for record in state.store.schedules(&owner).await? {
        schedules.push(resource(&state, &record).await?);
    }
    Ok(Json(ScheduleList { schedules }))
}

/// One schedule.
#[utoipa::path(
    get, path = "/v1/schedules/{id}", tag = "schedules", params(("id" = String, Path, description = "Schedule id")),
    responses(
        (status = 200, description = "The schedule", body = ScheduleResource),
        (status = 401, description = "Missing or unknown API key", body = Problem, content_type = PROBLEM),
        (status = 404, description = "No such schedule (for this key)", body = Problem, content_type = PROBLEM),
    ),
    security((), ("api_key" = []))
)]
pub async fn get_schedule(
    State(state): State<AppState>,
    Extension(Owner(owner)): Extension<Owner>,
    Path(id): Path<String>,
) -> Result<Json<ScheduleResource>, ApiError> {
    let record = find(&state, &owner, &id).await?;
    Ok(Json(resource(&state, &record).await?))
}

/// Replace a schedule's definition (its runs stay).
#[utoipa::path(
    put, path = "/v1/schedules/{id}", tag = "schedules", params(("id" = String, Path, description = "Schedule id")),
    request_body(content = ScheduleSpec, content_type = "application/json"),
    responses(
        (status = 200, description = "Updated", body = ScheduleResource),
        (status = 400, description = "Malformed JSON", body = Problem, content_type = PROBLEM),
        (status = 401, description = "Missing or unknown API key", body = Problem, content_type = PROBLEM),
        (status = 404, description = "No such schedule (for this key)", body = Problem, content_type = PROBLEM),
        (status = 413, description = "Body too large", body = Problem, content_type = PROBLEM),
        (status = 415, description = "Body is not JSON", body = Problem, content_type = PROBLEM),
        (status = 422, description = "A field breaks a rule", body = Problem, content_type = PROBLEM),
    ),
    security((), ("api_key" = []))
)]
pub async fn replace_schedule(
    State(state): State<AppState>,
    Extension(Owner(owner)): Extension<Owner>,
    Path(id): Path<String>,
    JsonText(body): JsonText,
) -> Result<Json<ScheduleResource>, ApiError> {
    let existing = find(&state, &owner, &id).await?;
    let record = validate(&body, state.config.max_job_operations)?.into_record(
        existing.id,
        existing.owner,
        existing.created_at,
        now_ms(),
    );
    if !state.store.update_schedule(&record).await? {
        return Err(ApiError::NotFound(format!("no schedule {id}")));
    }
    Ok(Json(resource(&state, &record).await?))
}

/// Delete a schedule (its jobs stay).
#[utoipa::path(
    delete, path = "/v1/schedules/{id}", tag = "schedules", params(("id" = String, Path, description = "Schedule id")),
    responses(
        (status = 204, description = "Deleted"),
        (status = 401, description = "Missing or unknown API key", body = Problem, content_type = PROBLEM),
        (status = 404, description = "No such schedule (for this key)", body = Problem, content_type = PROBLEM),
    ),
    security((), ("api_key" = []))
)]
pub async fn delete_schedule(
    State(state): State<AppState>,
    Extension(Owner(owner)): Extension<Owner>,
    Path(id): Path<String>,
) -> Result<StatusCode, ApiError> {
    if state.store.delete_schedule(&owner, &id).await? {
        Ok(StatusCode::NO_CONTENT)
    } else {
        Err(ApiError::NotFound(format!("no schedule {id}")))
    }
}

/// Run a schedule now, outside its timetable.
#[utoipa::path(
    post, path = "/v1/schedules/{id}/run", tag = "schedules", params(("id" = String, Path, description = "Schedule id")),
    responses(
        (status = 202, description = "The job it queued", body = JobResource),
        (status = 401, description = "Missing or unknown API key", body = Problem, content_type = PROBLEM),
        (status = 404, description = "No such schedule (for this key)", body = Problem, content_type = PROBLEM),
        (status = 429, description = "The queue is full; see Retry-After", body = Problem, content_type = PROBLEM),
    ),
    security((), ("api_key" = []))
)]
pub async fn run_schedule_now(
    State(state): State<AppState>,
    Extension(Owner(owner)): Extension<Owner>,
    Path(id): Path<String>,
) -> Result<Response, ApiError> {
    let schedule = find(&state, &owner, &id).await?;
    let now = chrono::Utc::now();
    // A manual run is keyed by its own time; two in the same millisecond take the next one.
    for offset in 0..16 {
        let at = now + chrono::Duration::milliseconds(offset);
        let job = crate::scheduler::job_from_template(&schedule, at, now)
            .map_err(|e| crate::errors::Internal(e.to_string()))?;
        match state
            .store
            .create_run(
                &schedule.id,
                at.timestamp_millis(),
                true,
                job,
                state.config.max_queued,
            )
            .await?
        {
            NewRun::Created(record) => {
                state.wake.notify_one();
                return Ok((
                    StatusCode::ACCEPTED,
                    Json(JobResource::from_record(&record)),
                )
                    .into_response());
            }
            NewRun::AlreadyExists => continue,
            NewRun::QueueFull => return Err(ApiError::QueueFull(state.config.max_queued)),
        }
    }
    Err(ApiError::Conflict(
        "too many manual runs at once; retry".into(),
    ))
}

#[derive(Debug, Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub struct RunsQuery {
    /// How many of the latest runs, 1 to 366 (default 60).
    #[param(minimum = 1, maximum = 366)]
    pub limit: Option<u32>,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct Run {
    /// RFC 3339: the due time (or the request time of a manual run).
    pub scheduled_for: String,
    pub job_id: String,
    pub status: crate::store::JobStatus,
    pub manual: bool,
    /// Each statistic's value, its 95 % interval, and whether it left the previous run's interval;
    /// null until the job succeeded or when the result lacks the statistic.
    #[schema(value_type = Object)]
    pub values: BTreeMap<String, Option<TrendValue>>,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct Trend {
    pub schedule_id: String,
    pub statistics: Vec<String>,
    /// Oldest first.
    pub runs: Vec<Run>,
}

/// The run-by-run trend of the schedule's statistics, with drift flags.
#[utoipa::path(
    get, path = "/v1/schedules/{id}/runs", tag = "schedules", params(("id" = String, Path, description = "Schedule id"), RunsQuery),
    responses(
        (status = 200, description = "Runs, oldest first", body = Trend),
        (status = 400, description = "Bad query", body = Problem, content_type = PROBLEM),
        (status = 401, description = "Missing or unknown API key", body = Problem, content_type = PROBLEM),
        (status = 404, description = "No such schedule (for this key)", body = Problem, content_type = PROBLEM),
    ),
    security((), ("api_key" = []))
)]
pub async fn schedule_runs(
    State(state): State<AppState>,
    Extension(Owner(owner)): Extension<Owner>,
    Path(id): Path<String>,
    query: Result<Query<RunsQuery>, QueryRejection>,
) -> Result<Json<Trend>, ApiError> {
    let Query(query) = query.map_err(|rejection| ApiError::BadRequest(rejection.body_text()))?;
    let limit = query.limit.unwrap_or(60);
    if !(1..=366).contains(&limit) {
        return Err(ApiError::BadRequest(format!(
            "limit must be from 1 to 366, got {limit}"
        )));
    }
    Ok(Json(
        trend(&state, &find(&state, &owner, &id).await?, limit).await?,
    ))
}

/// The trend of a schedule's runs, oldest first.
pub async fn trend(
    state: &AppState,
    schedule: &ScheduleRecord,
    limit: u32,
) -> Result<Trend, ApiError> {
    let statistics: Vec<String> = serde_json::from_str(&schedule.statistics).unwrap_or_default();
    let mut runs = state.store.runs(&schedule.id, limit).await?;
    runs.reverse();
    let mut results = Vec::with_capacity(runs.len());
    for run in &runs {
        results.push(match run.status {
            crate::store::JobStatus::Succeeded => {
                Some(super::jobs::stored_result(state, &run.job_id).await?)
            }
            _ => None,
        });
    }
    let columns: Vec<Vec<Option<TrendValue>>> = statistics
        .iter()
        .map(|name| {
            let statistic = Statistic(name.clone());
            flag_drift(
                &results
                    .iter()
                    .map(|r| r.as_ref().and_then(|r| statistic.read(r)))
                    .collect::<Vec<_>>(),
            )
        })
        .collect();
    let runs = runs
        .iter()
        .enumerate()
        .map(|(i, run)| Run {
            scheduled_for: rfc3339(run.scheduled_for),
            job_id: run.job_id.clone(),
            status: run.status,
            manual: run.manual,
            values: statistics
                .iter()
                .zip(&columns)
                .map(|(name, column)| (name.clone(), column[i].clone()))
                .collect(),
        })
        .collect();
    Ok(Trend {
        schedule_id: schedule.id.clone(),
        statistics,
        runs,
    })
}
