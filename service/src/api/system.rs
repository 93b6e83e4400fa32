//! Health, Prometheus metrics, the OpenAPI document and its docs UI (RapiDoc, vendored).

use super::AppState;
use super::cache::OwnFile;
use super::error::{ApiError, Internal, Problem};
use crate::domain::UnixMs;
use crate::store::{DATABASE_WAIT, StoreResult};
use crate::telemetry;
use axum::Json;
use axum::extract::State;
use axum::http::{HeaderMap, header};
use axum::response::{Html, IntoResponse, Response};
use serde::Serialize;
use std::future::Future;
use std::sync::LazyLock;
use utoipa::ToSchema;
use utoipa_axum::router::OpenApiRouter;
use utoipa_axum::routes;

pub fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new()
        .routes(routes!(healthz))
        .routes(routes!(readyz))
        .routes(routes!(prometheus_metrics))
}

/// What `/healthz` and `/readyz` answer when all is well.
#[derive(Debug, Serialize, ToSchema)]
pub struct Health {
    /// `ok` (alive) or `ready`; anything else is a 503 problem.
    pub status: &'static str,
    /// `ok`: the database answered.
    pub database: &'static str,
    /// The server's version.
    pub version: &'static str,
}

impl Health {
    fn json(status: &'static str) -> Json<Self> {
        Json(Health {
            status,
            database: "ok",
            version: env!("CARGO_PKG_VERSION"),
        })
    }
}

/// Liveness and database reachability.
///
/// 200 while the process runs and its database answers; 503 with `Retry-After` otherwise. Needs no
/// API key.
#[utoipa::path(
    get, path = "/healthz", tag = "system",
    responses((status = 200, description = "Healthy", body = Health), (status = 503, description = "The database is unreachable", body = Problem, content_type = "application/problem+json", headers(("Retry-After" = u32, description = "Seconds to wait before asking again"))))
)]
pub async fn healthz(State(state): State<AppState>) -> Result<Json<Health>, ApiError> {
    within_wait(state.store.ping()).await?;
    Ok(Health::json("ok"))
}

/// A health check's answer within [`DATABASE_WAIT`]: a database that hangs (a network that drops
/// packets rather than refusing) is unavailable too.
async fn within_wait(check: impl Future<Output = StoreResult<()>>) -> Result<(), ApiError> {
    match tokio::time::timeout(DATABASE_WAIT, check).await {
        Ok(answer) => Ok(answer?),
        Err(_) => Err(ApiError::Unavailable(Internal(format!(
            "the database did not answer within {} s",
            DATABASE_WAIT.as_secs_f64()
        )))),
    }
}

/// Readiness: this instance can do its work. Its database takes a write, every migration this
/// build knows is applied, and, for SQLite, the file at the database's path is still the one it
/// opened, with at least `--min-free-disk-mb` free beside it.
///
/// 200 when ready, else 503 with a problem whose detail says why and `Retry-After`. For load
/// balancers; needs no API key.
#[utoipa::path(
    get, path = "/readyz", tag = "system",
    responses((status = 200, description = "Ready", body = Health), (status = 503, description = "Not ready; the detail says why", body = Problem, content_type = "application/problem+json", headers(("Retry-After" = u32, description = "Seconds to wait before asking again"))))
)]
pub async fn readyz(State(state): State<AppState>) -> Result<Json<Health>, ApiError> {
    let min_free = state.config.min_free_disk_bytes();
    within_wait(state.store.ready(min_free, UnixMs::now())).await?;
    Ok(Health::json("ready"))
}

/// Prometheus metrics: requests and their latency, queue depth, jobs, simulated operations, the
/// build and the process.
///
/// Prometheus text format 0.0.4: every family has HELP and TYPE, request latency is a histogram.
/// Needs no API key.
#[utoipa::path(
    get, path = "/metrics", tag = "system",
    responses((status = 200, description = "Prometheus text format", body = String, content_type = "text/plain"))
)]
pub async fn prometheus_metrics(State(state): State<AppState>) -> impl IntoResponse {
    (
        [(header::CONTENT_TYPE, telemetry::METRICS_CONTENT_TYPE)],
        telemetry::render_metrics(&state.metrics),
    )
}

const RAPIDOC: &str = include_str!("../../assets/rapidoc-min.js");

pub async fn docs() -> Html<&'static str> {
    Html(concat!(
        // No icon to fetch: the browser would ask for /favicon.ico and log its 404 as an error.
        "<!doctype html><html><head><meta charset=\"utf-8\"><title>bouncewear API</title>",
        "<link rel=\"icon\" href=\"data:,\">",
        "<script type=\"module\" src=\"/docs/rapidoc-min.js\"></script></head><body>",
        // `load-fonts="false"`: RapiDoc would fetch Open Sans from fonts.gstatic.com; the page
        // loads nothing from the internet, and system fonts serve.
        "<rapi-doc spec-url=\"/openapi.json\" render-style=\"read\" show-header=\"false\" allow-try=\"true\" load-fonts=\"false\"></rapi-doc>",
        "</body></html>"
    ))
}

pub async fn docs_script() -> impl IntoResponse {
    (
        [
            (
                header::CONTENT_TYPE,
                "application/javascript; charset=utf-8",
            ),
            (header::CACHE_CONTROL, "public, max-age=86400"),
        ],
        RAPIDOC,
    )
}

const DASHBOARD_PAGE: &str = include_str!("../../assets/dashboard/page.html");
const DASHBOARD_SCRIPT: &str = include_str!("../../assets/dashboard/app.js");
const DASHBOARD_STYLE: &str = include_str!("../../assets/dashboard/style.css");

/// A dashboard page: the one shell (head, top bar) around the page's own `<main>`.
fn page(title: &str, name: &str, main: &str) -> String {
    DASHBOARD_PAGE
        .replace("{{title}}", title)
        .replace("{{page}}", name)
        .replace("{{main}}", main)
}

static INDEX_PAGE: LazyLock<String> = LazyLock::new(|| {
    page(
        "dashboard",
        "index",
        include_str!("../../assets/dashboard/index-main.html"),
    )
});
static JOB_PAGE: LazyLock<String> = LazyLock::new(|| {
    page(
        "job",
        "job",
        include_str!("../../assets/dashboard/job-main.html"),
    )
});

const HTML: &str = "text/html; charset=utf-8";
static INDEX_FILE: LazyLock<OwnFile> = LazyLock::new(|| OwnFile::new(HTML, INDEX_PAGE.as_str()));
static JOB_FILE: LazyLock<OwnFile> = LazyLock::new(|| OwnFile::new(HTML, JOB_PAGE.as_str()));
static SCRIPT_FILE: LazyLock<OwnFile> =
    LazyLock::new(|| OwnFile::new("application/javascript; charset=utf-8", DASHBOARD_SCRIPT));
static STYLE_FILE: LazyLock<OwnFile> =
    LazyLock::new(|| OwnFile::new("text/css; charset=utf-8", DASHBOARD_STYLE));

/// The dashboard: jobs with live progress, the submit form and schedules.
pub async fn dashboard(request: HeaderMap) -> Response {
    INDEX_FILE.respond(&request)
}

/// A job's page: live progress, wear curves, histograms, the Weibull plot.
pub async fn job_page(request: HeaderMap) -> Response {
    JOB_FILE.respond(&request)
}

pub async fn dashboard_script(request: HeaderMap) -> Response {
    SCRIPT_FILE.respond(&request)
}

pub async fn dashboard_style(request: HeaderMap) -> Response {
    STYLE_FILE.respond(&request)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_page_is_the_shell_with_its_own_title_and_main() {
        for (page, title, name) in [
            (&*INDEX_PAGE, "dashboard", "index"),
            (&*JOB_PAGE, "job", "job"),
        ] {
            assert!(page.starts_with("<!doctype html>"));
            assert!(page.contains(&format!("<title>bouncewear · {title}</title>")));
            assert!(page.contains(&format!("<body data-page=\"{name}\">")));
            // Each page has one `h1` (the jobs page's read by screen readers alone).
            assert!(page.contains("<main>\n    <") && page.ends_with("</html>\n"));
            assert_eq!(page.matches("<h1").count(), 1, "{name}");
            assert!(!page.contains("{{"), "every placeholder filled");
        }
    }
}
