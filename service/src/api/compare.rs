//! Two succeeded jobs compared, design against design (docs/contract.md "Comparing designs"): the
//! numbers as JSON and the wear curves and Weibull plots overlaid, all read from the two stored
//! Results by `bouncewear_model::montecarlo::compare` and `crate::plots`.

use super::AppState;
use super::Path;
use super::cache::{NotModified, immutable};
use super::error::{
    ApiError, PROBLEM, Problem,
    responses::{BadQuery, NotSucceeded, Unauthorized},
};
use super::jobs::{JSON, has_succeeded, stored_result, to_json};
use crate::domain::query::{fraction, items};
use crate::domain::{JobId, Owner};
use crate::plots;
use axum::Extension;
use axum::extract::rejection::QueryRejection;
use axum::extract::{Query, State};
use axum::http::{HeaderMap, header};
use axum::response::{IntoResponse, Response};
use bouncewear_model::montecarlo::JobResult;
use bouncewear_model::montecarlo::compare::{
    Comparison, DEFAULT_B_LIVES, DEFAULT_STATISTICS, Statistic, compare,
};
use serde::{Deserialize, Serialize};
use tokio::sync::OwnedSemaphorePermit;
use utoipa::{IntoParams, ToSchema};
use utoipa_axum::router::OpenApiRouter;
use utoipa_axum::routes;

pub fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new()
        .routes(routes!(get_comparison))
        .routes(routes!(comparison_plot))
}

#[derive(Debug, Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub struct ComparisonQuery {
    /// The metric compared (default `total_bounce_s`): an operation metric, compared per bin both
    /// jobs have, or a device metric, compared over the whole test.
    #[param(example = "total_bounce_s")]
    pub metric: Option<String>,
    /// Comma-separated statistics (default `mean,p50,p95`), at most 20: `mean`, `p01` ... `p99`
    /// (the reported quantiles) or `exceedance` (the probability beyond the metric's limit).
    #[param(
        pattern = "^(mean|p01|p05|p10|p25|p50|p75|p90|p95|p99|exceedance)(,(mean|p01|p05|p10|p25|p50|p75|p90|p95|p99|exceedance)){0,19}$",
        example = "mean,p50,p99"
    )]
    pub statistics: Option<String>,
    /// Comma-separated fractions failed of the B-lives compared (default `0.01,0.1`), at most 20,
    /// each at least 1e-9 and below 1, written as a decimal (`0.001`) or with an exponent
    /// (`1e-3`).
    #[param(
        pattern = "^(0?\\.0{0,8}[1-9][0-9]*|[1-9](\\.[0-9]+)?[eE]-0*[1-9])(,(0?\\.0{0,8}[1-9][0-9]*|[1-9](\\.[0-9]+)?[eE]-0*[1-9])){0,19}$",
        example = "0.01,0.1"
    )]
    pub b_lives: Option<String>,
}

/// The comparison of job `a` against job `b`.
#[derive(Debug, Serialize, ToSchema)]
pub struct JobComparison {
    /// The first job (the path's `id`).
    pub a: String,
    /// The second job (the path's `other`).
    pub b: String,
    #[serde(flatten)]
    pub comparison: Comparison,
    /// The plots of the comparison.
    pub links: ComparisonLinks,
}

/// Each `null` where the comparison has no such plot.
#[derive(Debug, Serialize, ToSchema)]
pub struct ComparisonLinks {
    /// The wear curves of the metric overlaid; `null` for a device metric (one value a device,
    /// no wear curve).
    pub bands: Option<String>,
    /// The Weibull plots overlaid; `null` unless both jobs have failure criteria.
    pub weibull: Option<String>,
}

/// Job `id` (design a) compared with job `other` (design b): any statistic of a metric, B-lives,
/// and who outlasts whom.
///
/// Both jobs must have succeeded. Per bin of operations both jobs have (the same `op_start` and
/// `op_end`; a device metric: the whole test), each statistic asked with `a`, `b` and their 95 %
/// intervals, `a - b` and `a / b` with theirs (MOVER: each side's interval keeps its shape; the
/// jobs are independent samples). With failure criteria in both: each B-life asked from the two
/// Weibull fits, compared the same way, and `outlasts`: `P(a device of a outlasts one of b)` from
/// the fits with its interval (delta method on the logit), and the share of pairs of simulated
/// devices in which it does, bounded as censoring allows, with its 95 % interval (DeLong's
/// variance of the two-sample U-statistic). `notes` says what limits the comparison.
#[utoipa::path(
    get, path = "/v1/jobs/{id}/compare/{other}", tag = "jobs",
    params(("id" = String, Path, description = "The first job (design a)"), ("other" = String, Path, description = "The second job (design b)"), ComparisonQuery),
    responses(
        (status = 200, description = "The comparison", body = JobComparison, headers(("ETag" = String, description = "A tag of the content, for If-None-Match"), ("Cache-Control" = String, description = "Immutable for a year"))),
        NotModified,
        BadQuery,
        Unauthorized,
        (status = 404, description = "No such job, or a job without the metric", body = Problem, content_type = PROBLEM),
        NotSucceeded,
    ),
    security((), ("api_key" = []))
)]
pub async fn get_comparison(
    State(state): State<AppState>,
    Extension(owner): Extension<Owner>,
    Path((id, other)): Path<(JobId, JobId)>,
    query: Result<Query<ComparisonQuery>, QueryRejection>,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    let Query(query) = query?;
    let statistics = statistics(query.statistics.as_deref())?;
    let b_lives = b_lives(query.b_lives.as_deref())?;
    let metric = query.metric.unwrap_or_else(|| "total_bounce_s".to_owned());
    let (a, b, _place) = results(&state, &owner, &id, &other).await?;
    let comparison = compare(&a, &b, &metric, &statistics, &b_lives)
        .map_err(|error| ApiError::NotFound(error.to_string()))?;
    let this = format!("/v1/jobs/{id}/compare/{other}");
    let body = JobComparison {
        a: id.to_string(),
        b: other.to_string(),
        links: ComparisonLinks {
            bands: plots::has_wear_curve(&metric)
                .then(|| format!("{this}/plots/bands.svg?metric={metric}")),
            weibull: (comparison.life.is_some()).then(|| format!("{this}/plots/weibull.svg")),
        },
        comparison,
    };
    Ok(immutable(&state, &headers, JSON, to_json(&body)?))
}

#[derive(Debug, Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub struct ComparisonPlotQuery {
    /// The operation metric of `bands.svg` (default `total_bounce_s`); ignored by `weibull.svg`.
    #[param(example = "total_bounce_s")]
    pub metric: Option<String>,
}

/// Two jobs' plots overlaid, as the dashboard's comparison shows them.
///
/// SVG: `bands.svg` draws the wear curves of `metric` (an operation metric of both jobs, default
/// `total_bounce_s`): each job's p05-p95 band, median and mean in its colour; `weibull.svg` draws
/// both Weibull probability plots with their fits and bounds, annotated with each job's beta, eta
/// and B10 (both jobs need failure criteria). Each job is named in the legend by its name and id.
#[utoipa::path(
    get, path = "/v1/jobs/{id}/compare/{other}/plots/{kind}", tag = "jobs",
    params(("id" = String, Path, description = "The first job (design a)"), ("other" = String, Path, description = "The second job (design b)"), ("kind" = String, Path, description = "bands.svg or weibull.svg"), ComparisonPlotQuery),
    responses(
        (status = 200, description = "The plot", body = String, content_type = "image/svg+xml"),
        BadQuery,
        Unauthorized,
        (status = 404, description = "No such job, plot or metric, or a job without failure criteria", body = Problem, content_type = PROBLEM),
        NotSucceeded,
    ),
    security((), ("api_key" = []))
)]
pub async fn comparison_plot(
    State(state): State<AppState>,
    Extension(owner): Extension<Owner>,
    Path((id, other, kind)): Path<(JobId, JobId, String)>,
    query: Result<Query<ComparisonPlotQuery>, QueryRejection>,
) -> Result<Response, ApiError> {
    let Query(query) = query?;
    let (a, b, _place) = results(&state, &owner, &id, &other).await?;
    let (name_a, name_b) = (legend_name("a", &id, &a), legend_name("b", &other, &b));
    let svg = plots::compared_plot(
        [(&name_a, &a), (&name_b, &b)],
        &kind,
        query.metric.as_deref().unwrap_or("total_bounce_s"),
    )?;
    Ok(([(header::CONTENT_TYPE, "image/svg+xml")], svg).into_response())
}

/// The two jobs' Results, each of which must have succeeded, with the place that lets the
/// request hold them ([`AppState::parsing`]): one place for both.
async fn results(
    state: &AppState,
    owner: &Owner,
    a: &JobId,
    b: &JobId,
) -> Result<(JobResult, JobResult, OwnedSemaphorePermit), ApiError> {
    // Both jobs read before either's status is judged: a job that does not exist is 404
    // whatever the other's status (a 409 for the first, not yet succeeded, hid that the second
    // will never be there).
    let (job_a, job_b) = (
        state.store.job(owner, a).await?,
        state.store.job(owner, b).await?,
    );
    has_succeeded(job_a)?;
    has_succeeded(job_b)?;
    let place = super::limits::take_place(&state.parsing).await?;
    Ok((
        stored_result(state, a).await?,
        stored_result(state, b).await?,
        place,
    ))
}

/// A design in a legend: `a: its name (its id)`, or `a: its id` without a name.
fn legend_name(letter: &str, id: &JobId, result: &JobResult) -> String {
    match &result.job.spec().name {
        Some(name) => format!("{letter}: {name} ({id})"),
        None => format!("{letter}: {id}"),
    }
}

/// The statistics asked, or the defaults.
fn statistics(text: Option<&str>) -> Result<Vec<Statistic>, ApiError> {
    let Some(text) = text else {
        return Ok(DEFAULT_STATISTICS
            .iter()
            .map(|name| Statistic::parse(name).expect("a default statistic"))
            .collect());
    };
    items("statistics", Some(text), |name| {
        Statistic::parse(name.trim())
    })
    .map_err(|bad| ApiError::BadRequest(bad.to_string()))
}

/// The smallest B-life fraction compared: the likelihood-ratio bounds were checked against an
/// independent profile down to it; at 1e-100 they collapsed to a width of 2e-11 where the delta
/// method gives a factor of e^28 either way (a probe), and at 1e-310 the interval was `null`.
pub const SMALLEST_B_LIFE: f64 = 1e-9;

/// The B-life fractions asked, or the defaults.
fn b_lives(text: Option<&str>) -> Result<Vec<f64>, ApiError> {
    let b_life = |item: &str| {
        fraction(item).and_then(|p| {
            (p >= SMALLEST_B_LIFE)
                .then_some(p)
                .ok_or_else(|| format!("a B-life fraction must be at least {SMALLEST_B_LIFE}"))
        })
    };
    match text {
        None => Ok(DEFAULT_B_LIVES.to_vec()),
        Some(text) => items("b_lives", Some(text), b_life)
            .map_err(|bad| ApiError::BadRequest(bad.to_string())),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn statistics_and_fractions_parse_or_name_their_parameter() {
        assert_eq!(statistics(None).unwrap().len(), DEFAULT_STATISTICS.len());
        assert_eq!(
            statistics(Some("mean, p99")).unwrap(),
            vec![Statistic::Mean, Statistic::Quantile("p99")]
        );
        let error = statistics(Some("mean,median")).unwrap_err().to_string();
        assert!(
            error.contains("`statistics`") && error.contains("`median`"),
            "{error}"
        );
        assert_eq!(b_lives(None).unwrap(), DEFAULT_B_LIVES.to_vec());
        assert_eq!(b_lives(Some("0.05")).unwrap(), vec![0.05]);
        assert_eq!(b_lives(Some("0.1,0.05,0.1")).unwrap(), vec![0.1, 0.05]);
        let many = vec!["mean"; 21].join(",");
        let error = statistics(Some(&many)).unwrap_err().to_string();
        assert!(error.contains("at most 20"), "{error}");
        assert_eq!(b_lives(Some("1e-9")).unwrap(), vec![1e-9]);
        for bad in ["1", "0", "x", "nan", "", "1e-100", "5e-324"] {
            let error = b_lives(Some(bad)).unwrap_err().to_string();
            assert!(error.contains("`b_lives`"), "{error}");
        }
    }
}
