//! Plots as SVG, rendered by the server (`crate::plots`): a job's wear curves, histograms, Weibull
//! plot and sensitivity indices, and a schedule's trend. The dashboard and `bouncewear run --plots` show the same pictures.

use super::AppState;
use super::Path;
use super::error::{
    ApiError, PROBLEM, Problem,
    responses::{BadQuery, NotSucceeded, Unauthorized},
};
use super::jobs::result_asking;
use super::schedules::schedule_trend;
use crate::domain::{JobId, Owner, ScheduleId};
use crate::plots::{self, TrendPoint};
use axum::Extension;
use axum::extract::rejection::QueryRejection;
use axum::extract::{Query, State};
use axum::http::header;
use axum::response::{IntoResponse, Response};
use serde::Deserialize;
use utoipa::IntoParams;
use utoipa_axum::router::OpenApiRouter;
use utoipa_axum::routes;

pub fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new()
        .routes(routes!(job_plot))
        .routes(routes!(schedule_trend_plot))
}

const SVG: &str = "image/svg+xml";

#[derive(Debug, Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub struct PlotQuery {
    /// The metric to draw (default `total_bounce_s`): an operation metric for `bands.svg` and
    /// `histograms.svg`, any metric of the sensitivity analysis for `sensitivity.svg`; ignored by
    /// `weibull.svg`.
    #[param(example = "total_bounce_s")]
    pub metric: Option<String>,
}

/// A plot of a succeeded job: `bands.svg` (p05/p50/p95 across operations: the wear curve),
/// `histograms.svg` (per bin), `weibull.svg` (life, with bounds), `sensitivity.svg` (which
/// parameters drive a metric) or `tail.svg` (a rare event's tail curve).
///
/// SVG, as the dashboard shows it. `bands.svg` and `histograms.svg` draw `metric` (an operation
/// metric of the job, default `total_bounce_s`); `weibull.svg` needs failure criteria and plots
/// median-rank positions with the fitted line and its bounds; `sensitivity.svg` needs a job
/// submitted with `sensitivity` and draws, for `metric` (an operation or device metric), the
/// first-order and total Sobol' indices of each scattered parameter with their 95 % intervals in
/// the first and the last bin (method `regression`: the absolute standardised regression
/// coefficients); `tail.svg` needs a job submitted with `rare_event` and draws `P(metric beyond
/// t)` on a log axis, from the bulk to the threshold asked, with the estimate's 95 % interval.
#[utoipa::path(
    get, path = "/v1/jobs/{id}/plots/{kind}", tag = "jobs",
    params(("id" = String, Path, description = "Job id"), ("kind" = String, Path, description = "bands.svg, histograms.svg, weibull.svg, sensitivity.svg or tail.svg"), PlotQuery),
    responses(
        (status = 200, description = "The plot", body = String, content_type = SVG),
        BadQuery,
        Unauthorized,
        (status = 404, description = "No such job, plot or metric, or no sensitivity analysis or rare event", body = Problem, content_type = PROBLEM),
        NotSucceeded,
    ),
    security((), ("api_key" = []))
)]
pub async fn job_plot(
    State(state): State<AppState>,
    Extension(owner): Extension<Owner>,
    Path((id, kind)): Path<(JobId, String)>,
    query: Result<Query<PlotQuery>, QueryRejection>,
) -> Result<Response, ApiError> {
    let Query(query) = query?;
    let _place = super::limits::take_place(&state.parsing).await?;
    let metric = query.metric.as_deref().unwrap_or("total_bounce_s");
    let result = result_asking(&state, &owner, &id, |spec| {
        Ok(plots::job_has_plot(spec, &kind, metric)?)
    })
    .await?;
    let svg = plots::job_plot(&result, &kind, metric)?;
    Ok(([(header::CONTENT_TYPE, SVG)], svg).into_response())
}

#[derive(Debug, Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub struct TrendQuery {
    /// One of the schedule's statistics (default: its first).
    #[param(example = "operations.total_bounce_s.p95")]
    pub statistic: Option<String>,
}

/// A schedule's trend of one statistic, with 95 % intervals and drift flags.
///
/// SVG: one point per succeeded run with its 95 % interval, runs whose value left the previous
/// run's interval flagged, labelled on the schedule's clock.
#[utoipa::path(
    get, path = "/v1/schedules/{id}/plots/trend.svg", tag = "schedules",
    params(("id" = String, Path, description = "Schedule id"), TrendQuery),
    responses(
        (status = 200, description = "The trend", body = String, content_type = SVG),
        BadQuery,
        Unauthorized,
        (status = 404, description = "No such schedule or statistic", body = Problem, content_type = PROBLEM),
    ),
    security((), ("api_key" = []))
)]
pub async fn schedule_trend_plot(
    State(state): State<AppState>,
    Extension(owner): Extension<Owner>,
    Path(id): Path<ScheduleId>,
    query: Result<Query<TrendQuery>, QueryRejection>,
) -> Result<Response, ApiError> {
    let Query(query) = query?;
    let schedule = state.store.schedule(&owner, &id).await?;
    let followed = &schedule.definition.statistics;
    let statistic = match query.statistic {
        Some(statistic) if followed.iter().any(|s| s.to_string() == statistic) => statistic,
        Some(statistic) => {
            return Err(ApiError::NotFound(format!(
                "the schedule does not follow `{statistic}`"
            )));
        }
        None => followed
            .first()
            .map(ToString::to_string)
            .unwrap_or_default(),
    };
    let trend = schedule_trend(&state, &schedule, 60).await?;
    let shown: Vec<_> = trend
        .runs
        .iter()
        .filter_map(|run| {
            Some((
                run.scheduled_for.as_str(),
                run.values.get(&statistic)?.as_ref()?,
            ))
        })
        .collect();
    let times: Vec<&str> = shown.iter().map(|(time, _)| *time).collect();
    let points: Vec<TrendPoint> = (schedule.definition.wall_clock(&times).into_iter())
        .zip(&shown)
        .map(|(label, (_, value))| TrendPoint {
            label,
            value: value.value,
            ci95: Some(value.ci95),
            flagged: value.drift,
        })
        .collect();
    let svg = plots::trend_svg(
        &format!("{}: {statistic}", schedule.definition.name),
        &format!("run (time in {})", schedule.definition.time_zone),
        &statistic,
        &points,
    );
    Ok(([(header::CONTENT_TYPE, SVG)], svg).into_response())
}
