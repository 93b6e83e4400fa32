//! Logs (tracing, to stderr, `RUST_LOG` to filter; text or JSON) and Prometheus metrics: every
//! metric the service records is named, described and given its buckets here.

use axum::extract::MatchedPath;
use axum::http::Method;
use axum::http::Request;
use axum::middleware::Next;
use axum::response::Response;
use clap::ValueEnum;
use metrics_exporter_prometheus::{Matcher, PrometheusBuilder, PrometheusHandle};
use std::io::IsTerminal;
use std::sync::OnceLock;
use std::time::{Duration, Instant};
use tracing_subscriber::layer::SubscriberExt;
use tracing_subscriber::util::SubscriberInitExt;

/// How log lines are written (`--log-format`, `BOUNCEWEAR_LOG_FORMAT`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum LogFormat {
    /// One line per event, coloured only when stderr is a terminal.
    Text,
    /// One JSON object per line, for log collectors.
    Json,
}

/// Logs to stderr, filtered by `RUST_LOG` (default: info, and warnings from sqlx).
pub fn init_logging(format: LogFormat) {
    // A RUST_LOG that does not parse is said once logging runs, not dropped in silence.
    let mut refused = None;
    let filter = match tracing_subscriber::EnvFilter::try_from_default_env() {
        Ok(filter) => filter,
        Err(error) => {
            if std::env::var_os("RUST_LOG").is_some_and(|value| !value.is_empty()) {
                refused = Some(error.to_string());
            }
            tracing_subscriber::EnvFilter::new("info,sqlx=warn")
        }
    };
    let builder = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr);
    let _ = match format {
        LogFormat::Text => builder
            .with_ansi(colour(
                std::io::stderr().is_terminal(),
                std::env::var_os("NO_COLOR"),
            ))
            .finish()
            .with(no_request_bytes())
            .try_init(),
        // The request's fields (method, route, request id) sit beside the event's own.
        LogFormat::Json => builder
            .json()
            .flatten_event(true)
            .with_current_span(true)
            .with_span_list(false)
            .finish()
            .with(no_request_bytes())
            .try_init(),
    };
    if let Some(error) = refused {
        tracing::warn!(%error, "RUST_LOG does not parse; logging at info (and sqlx at warn)");
    }
}

/// ureq's protocol layer dumps every request's bytes at trace, the remote commands'
/// `Authorization: Bearer KEY` among them (at debug it names headers, not their values): no
/// `RUST_LOG` lets those lines through.
fn no_request_bytes<S: tracing::Subscriber>() -> impl tracing_subscriber::Layer<S> {
    tracing_subscriber::filter::filter_fn(|event| {
        !(*event.level() == tracing::Level::TRACE && event.target().starts_with("ureq_proto"))
    })
}

/// Whether text logs are coloured: on a terminal, unless `NO_COLOR` is set to anything but the
/// empty string (no-color.org).
fn colour(terminal: bool, no_color: Option<std::ffi::OsString>) -> bool {
    terminal && no_color.is_none_or(|value| value.is_empty())
}

/// The span every request runs in: its method, route template, URI and request id.
pub fn request_span<B>(request: &Request<B>) -> tracing::Span {
    let request_id = request
        .headers()
        .get("x-request-id")
        .and_then(|v| v.to_str().ok())
        .unwrap_or("-");
    tracing::info_span!(
        "request",
        method = %request.method(),
        route = %route_label(request),
        uri = %LoggedUri(request.uri()),
        request_id,
    )
}

/// A request's URI as logged: a query parameter whose name says it holds a secret (`api_key=`,
/// `token=`, ...) has its value replaced. The API takes none, but a client that sends its key
/// in the query instead of `Authorization` (refused, 401) put it in the log as written.
struct LoggedUri<'a>(&'a axum::http::Uri);

impl std::fmt::Display for LoggedUri<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.0.path())?;
        let Some(query) = self.0.query() else {
            return Ok(());
        };
        for (index, pair) in query.split('&').enumerate() {
            f.write_str(if index == 0 { "?" } else { "&" })?;
            match pair.split_once('=') {
                Some((name, _)) if secret_name(name) => write!(f, "{name}=REDACTED")?,
                _ => f.write_str(pair)?,
            }
        }
        Ok(())
    }
}

fn secret_name(name: &str) -> bool {
    let name = name.to_ascii_lowercase();
    ["key", "token", "secret", "password", "auth", "bearer"]
        .iter()
        .any(|word| name.contains(word))
}

/// The one log line of a request, at info: its status and latency, in the request's span.
pub fn log_response<B>(response: &axum::http::Response<B>, latency: Duration, _: &tracing::Span) {
    tracing::info!(
        status = response.status().as_u16(),
        latency_ms = latency.as_secs_f64() * 1e3,
        "answered"
    );
}

const HTTP_REQUESTS: &str = "bouncewear_http_requests_total";
const HTTP_DURATION: &str = "bouncewear_http_request_duration_seconds";
const BUILD_INFO: &str = "bouncewear_build_info";
const JOB_DURATION: &str = "bouncewear_job_duration_seconds";
const JOB_RATE: &str = "bouncewear_job_operations_per_second";
const JOB_STORED_BYTES: &str = "bouncewear_job_stored_bytes";
const SHARD_STEP: &str = "bouncewear_shard_step_seconds";

/// Request latency: from a cached health check to a result of many megabytes.
const HTTP_BUCKETS: &[f64] = &[
    0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0,
];
/// A job's wall time: a hundredth of a second to a day.
const JOB_DURATION_BUCKETS: &[f64] = &[
    0.01, 0.03, 0.1, 0.3, 1.0, 3.0, 10.0, 30.0, 100.0, 300.0, 1000.0, 3000.0, 10000.0, 86400.0,
];
/// Simulated operations per second of wall time: a tiny job's start-up to a large machine's speed.
const JOB_RATE_BUCKETS: &[f64] = &[
    1e3, 3e3, 1e4, 3e4, 1e5, 3e5, 1e6, 2e6, 5e6, 1e7, 2e7, 5e7, 1e8,
];
/// From a job of one bin to one of a thousand bins with a full listing of device lives.
const JOB_STORED_BYTES_BUCKETS: &[f64] = &[1e4, 3e4, 1e5, 3e5, 1e6, 3e6, 1e7, 3e7, 1e8, 3e8, 1e9];

/// One step of a shard's life: a millisecond's claim to a long group's run.
const SHARD_STEP_BUCKETS: &[f64] = &[
    0.0005, 0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 10.0, 60.0, 600.0,
];

/// The metrics recorder's configuration: which histograms have which buckets (the others would
/// be summaries, which cannot be aggregated across instances).
pub(crate) fn prometheus_builder() -> PrometheusBuilder {
    [
        (HTTP_DURATION, HTTP_BUCKETS),
        (JOB_DURATION, JOB_DURATION_BUCKETS),
        (JOB_RATE, JOB_RATE_BUCKETS),
        (JOB_STORED_BYTES, JOB_STORED_BYTES_BUCKETS),
        (SHARD_STEP, SHARD_STEP_BUCKETS),
    ]
    .into_iter()
    .fold(PrometheusBuilder::new(), |builder, (name, buckets)| {
        builder
            .set_buckets_for_metric(Matcher::Full(name.to_owned()), buckets)
            .expect("bucket lists are not empty")
    })
}

/// Connections closed for a new client at the connection limit (`connections`).
/// The bytes of large responses held until their clients read them (a gauge).
pub const RESPONSE_BYTES_HELD: &str = "bouncewear_response_bytes_held";
/// Large responses built and waiting for room among the bytes held (a gauge).
pub const RESPONSES_WAITING: &str = "bouncewear_responses_waiting";
/// Large responses refused while the bytes held were at their limit (`api::held`).
pub const RESPONSES_REFUSED: &str = "bouncewear_responses_refused_total";
pub const CONNECTIONS_SHED: &str = "bouncewear_connections_shed_total";

/// Connections closed because their client read none of a response for the body timeout
/// (`connections`).
pub const CONNECTIONS_STALLED: &str = "bouncewear_connections_stalled_total";

/// Reads of the job queue by the watcher behind every event stream (`api::watch`).
pub const EVENT_WATCH_LOOKS: &str = "bouncewear_event_watch_looks_total";

/// Calibration fits stopped because their request ended first (`api::calibrations`).
pub const FITS_STOPPED: &str = "bouncewear_fits_stopped_total";

/// Jobs accepted into the queue, schedules' runs included ([`record_jobs_submitted`]).
const JOBS_SUBMITTED: &str = "bouncewear_jobs_submitted_total";

/// Schedules' runs skipped at their due time ([`record_scheduled_runs_skipped`]).
const SCHEDULED_RUNS_SKIPPED: &str = "bouncewear_scheduled_runs_skipped_total";

/// The HELP text of every metric the service records, wherever it records it.
fn describe_metrics() {
    metrics::describe_counter!(
        HTTP_REQUESTS,
        "HTTP requests answered, by method, route template and status."
    );
    metrics::describe_histogram!(
        HTTP_DURATION,
        metrics::Unit::Seconds,
        "Time from a request's arrival to its response's headers, by method, route template and status."
    );
    metrics::describe_gauge!(BUILD_INFO, "Always 1; its labels name the running build.");
    metrics::describe_gauge!("bouncewear_jobs_queued", "Jobs waiting in the queue.");
    metrics::describe_gauge!(
        RESPONSE_BYTES_HELD,
        "Bytes of large responses held until their clients read them (--max-response-mb)."
    );
    metrics::describe_gauge!(
        RESPONSES_WAITING,
        "Large responses built and waiting for room among the bytes held (at most 4)."
    );
    metrics::describe_counter!(
        RESPONSES_REFUSED,
        "Large responses refused (503) while --max-response-mb was held for unread ones."
    );
    metrics::describe_gauge!(
        "bouncewear_jobs_running",
        "Jobs claimed by a worker and not yet finished."
    );
    metrics::describe_counter!(
        JOBS_SUBMITTED,
        "Jobs accepted into the queue by this instance, schedules' runs included."
    );
    metrics::describe_counter!(
        SCHEDULED_RUNS_SKIPPED,
        "Schedules' runs this instance skipped at their due time: a template the server's limits refuse now, a key over its quota, or due times passed while the server was down or late (only the latest is made)."
    );
    metrics::describe_counter!(
        "bouncewear_jobs_finished_total",
        "Jobs that ended on this instance, by status (succeeded, failed, cancelled)."
    );
    metrics::describe_counter!(
        "bouncewear_operations_simulated_total",
        "Make operations simulated by this instance's workers, counted as each group of devices, rare-event task or merge step is stored or fails its job (a job's progress counts them the same way)."
    );
    metrics::describe_counter!(
        CONNECTIONS_SHED,
        "Connections waiting for a request's headers that were closed to make room for a new client at the connection limit."
    );
    metrics::describe_counter!(
        CONNECTIONS_STALLED,
        "Connections closed because their client read none of a response for the body timeout."
    );
    metrics::describe_counter!(
        FITS_STOPPED,
        "Calibration fits stopped, their place given back, because their request timed out before they ended."
    );
    metrics::describe_counter!(
        EVENT_WATCH_LOOKS,
        "Reads of the job queue by the one watcher behind every event stream (none while no stream is open)."
    );
    metrics::describe_counter!(
        "bouncewear_store_retries_total",
        "Writes of a shard's outcome the database did not take and that were tried again after a backoff."
    );
    metrics::describe_histogram!(
        JOB_DURATION,
        metrics::Unit::Seconds,
        "Wall time of a succeeded job's run, from its claim to its result."
    );
    metrics::describe_histogram!(
        JOB_STORED_BYTES,
        metrics::Unit::Bytes,
        "Bytes stored for a succeeded job (spec, result, distributions, listed device lives), one observation per job."
    );
    metrics::describe_histogram!(
        JOB_RATE,
        "Simulated operations per second of wall time, one observation per succeeded job."
    );
    metrics::describe_histogram!(
        SHARD_STEP,
        metrics::Unit::Seconds,
        "One step of a shard on this instance's workers, by step: claim (finding and leasing it), run (simulating a group), store (writing its accumulators), merge (reading them back, merging, storing the Result)."
    );
}

/// Counters and gauges that would appear only once something happened, there from the start at
/// 0: a scrape shows every family with its HELP and TYPE, and a rate over a series that is still
/// 0 is 0, not absent.
fn counters_from_zero() {
    for name in [
        CONNECTIONS_SHED,
        CONNECTIONS_STALLED,
        EVENT_WATCH_LOOKS,
        FITS_STOPPED,
        "bouncewear_store_retries_total",
        JOBS_SUBMITTED,
        SCHEDULED_RUNS_SKIPPED,
        "bouncewear_operations_simulated_total",
        RESPONSES_REFUSED,
    ] {
        metrics::counter!(name).increment(0);
    }
    for name in [RESPONSE_BYTES_HELD, RESPONSES_WAITING] {
        metrics::gauge!(name).increment(0.0);
    }
    for status in ["succeeded", "failed", "cancelled"] {
        metrics::counter!("bouncewear_jobs_finished_total", "status" => status).increment(0);
    }
}

fn process_metrics() -> &'static metrics_process::Collector {
    static COLLECTOR: OnceLock<metrics_process::Collector> = OnceLock::new();
    COLLECTOR.get_or_init(metrics_process::Collector::default)
}

/// The Prometheus registry, installed once per process with every metric described. `metrics`'
/// macros record into one process-wide recorder, so every application in a process (several, in
/// tests) shares this one handle to it.
pub fn prometheus() -> PrometheusHandle {
    static HANDLE: OnceLock<PrometheusHandle> = OnceLock::new();
    HANDLE
        .get_or_init(|| {
            let recorder = prometheus_builder().build_recorder();
            let handle = recorder.handle();
            if metrics::set_global_recorder(recorder).is_err() {
                tracing::warn!("another metrics recorder is installed; /metrics will be empty");
            }
            describe_metrics();
            counters_from_zero();
            process_metrics().describe();
            metrics::gauge!(
                BUILD_INFO,
                "version" => env!("CARGO_PKG_VERSION"),
                "profile" => if cfg!(debug_assertions) { "debug" } else { "release" },
                "os" => std::env::consts::OS,
                "arch" => std::env::consts::ARCH,
            )
            .set(1.0);
            handle
        })
        .clone()
}

/// The content type of [`render_metrics`]' text: Prometheus' text format.
pub const METRICS_CONTENT_TYPE: &str = "text/plain; version=0.0.4";

/// The text a scrape gets, with the process metrics read at this moment.
pub fn render_metrics(handle: &PrometheusHandle) -> String {
    process_metrics().collect();
    handle.render()
}

/// Counts `jobs` accepted into the queue: submitted, or a schedule's runs (on its timetable or
/// run now), whether or not they go on to succeed.
pub fn record_jobs_submitted(jobs: u64) {
    metrics::counter!(JOBS_SUBMITTED).increment(jobs);
}

/// Counts a schedule's run skipped at its due time (shown on the schedule as well).
pub fn record_scheduled_runs_skipped(runs: u64) {
    metrics::counter!(SCHEDULED_RUNS_SKIPPED).increment(runs);
}

/// Records a succeeded job's wall time and speed. `operations` is what the job simulated.
pub fn record_job_finished(wall_s: f64, operations: u64, stored_bytes: u64) {
    metrics::histogram!(JOB_DURATION).record(wall_s);
    metrics::histogram!(JOB_STORED_BYTES).record(stored_bytes as f64);
    if wall_s > 0.0 {
        metrics::histogram!(JOB_RATE).record(operations as f64 / wall_s);
    }
}

/// Records how long one step of a shard took, from `since`: `claim`, `run`, `store` or `merge`,
/// and a merge step in parts, `merge_read` (the groups, or a rare event's round, read back),
/// `merge_compute` (merged, summarised and encoded; a job run whole runs here) and `merge_write`
/// (the Result, the next batch or the next round stored). What sharding costs is all but `run`.
pub fn record_shard_step(step: &'static str, since: std::time::Instant) {
    record_shard_time(step, since.elapsed());
}

/// Records `took` as the time of shard step `step` ([`record_shard_step`]).
pub fn record_shard_time(step: &'static str, took: std::time::Duration) {
    metrics::histogram!(SHARD_STEP, "step" => step).record(took.as_secs_f64());
}

/// A label value for a request's method: the standard ones by name, any other `other`, so a
/// client cannot grow the number of series.
fn method_label(method: &Method) -> &'static str {
    ["GET", "HEAD", "POST", "PUT", "DELETE", "PATCH", "OPTIONS"]
        .into_iter()
        .find(|known| *known == method.as_str())
        .unwrap_or("other")
}

/// The route template a request matched (`/v1/jobs/{id}`), or `other` for anything the router
/// does not know: label values come only from the router's own table.
fn route_label<B>(request: &Request<B>) -> String {
    request
        .extensions()
        .get::<MatchedPath>()
        .map_or_else(|| "other".to_owned(), |p| p.as_str().to_owned())
}

/// Counts requests and their latency by method, route template and status.
pub async fn record_request(request: axum::extract::Request, next: Next) -> Response {
    let started = Instant::now();
    let method = method_label(request.method());
    let route = route_label(&request);
    let response = next.run(request).await;
    let status = response.status().as_u16().to_string();
    let labels = [
        ("method", method.to_owned()),
        ("route", route),
        ("status", status),
    ];
    metrics::counter!(HTTP_REQUESTS, &labels).increment(1);
    metrics::histogram!(HTTP_DURATION, &labels).record(started.elapsed().as_secs_f64());
    response
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_secret_in_the_query_is_not_logged() {
        let logged = |uri: &str| LoggedUri(&uri.parse().unwrap()).to_string();
        assert_eq!(
            logged("/v1/jobs?api_key=k1&limit=2&Access_Token=t&cursor=9"),
            "/v1/jobs?api_key=REDACTED&limit=2&Access_Token=REDACTED&cursor=9"
        );
        assert_eq!(logged("/v1/jobs?wait_s=3&flag"), "/v1/jobs?wait_s=3&flag");
        assert_eq!(logged("/v1/jobs"), "/v1/jobs");
        assert_eq!(logged("/v1/jobs?"), "/v1/jobs?");
    }

    #[test]
    fn text_logs_are_coloured_on_a_terminal_unless_no_color_is_set() {
        let set = |v: &str| Some(std::ffi::OsString::from(v));
        assert!(colour(true, None));
        assert!(colour(true, set("")));
        assert!(!colour(true, set("1")));
        assert!(!colour(false, None));
    }

    #[test]
    fn a_finished_job_is_one_observation_of_its_duration_its_speed_and_its_bytes() {
        let recorder = prometheus_builder().build_recorder();
        let handle = recorder.handle();
        metrics::with_local_recorder(&recorder, || {
            describe_metrics();
            record_job_finished(2.0, 10_000_000, 250_000);
        });
        let text = handle.render();
        for line in [
            "# TYPE bouncewear_job_duration_seconds histogram",
            "bouncewear_job_duration_seconds_bucket{le=\"1\"} 0",
            "bouncewear_job_duration_seconds_bucket{le=\"3\"} 1",
            "bouncewear_job_duration_seconds_sum 2",
            "bouncewear_job_duration_seconds_count 1",
            "# TYPE bouncewear_job_operations_per_second histogram",
            "bouncewear_job_operations_per_second_bucket{le=\"2000000\"} 0",
            "bouncewear_job_operations_per_second_bucket{le=\"5000000\"} 1",
            "bouncewear_job_operations_per_second_sum 5000000",
            "# TYPE bouncewear_job_stored_bytes histogram",
            "bouncewear_job_stored_bytes_bucket{le=\"100000\"} 0",
            "bouncewear_job_stored_bytes_bucket{le=\"300000\"} 1",
            "bouncewear_job_stored_bytes_sum 250000",
        ] {
            assert!(text.lines().any(|l| l == line), "{line} in\n{text}");
        }
        for name in [JOB_DURATION, JOB_RATE, JOB_STORED_BYTES] {
            assert!(text.contains(&format!("# HELP {name} ")), "{text}");
        }
    }

    #[test]
    fn a_job_of_no_measurable_time_records_its_duration_but_no_speed() {
        let recorder = prometheus_builder().build_recorder();
        let handle = recorder.handle();
        metrics::with_local_recorder(&recorder, || record_job_finished(0.0, 5, 1));
        let text = handle.render();
        assert!(
            text.contains("bouncewear_job_duration_seconds_count 1"),
            "{text}"
        );
        assert!(!text.contains(JOB_RATE), "{text}");
    }

    #[test]
    fn methods_outside_the_standard_ones_share_one_label() {
        assert_eq!(method_label(&Method::GET), "GET");
        assert_eq!(method_label(&Method::from_bytes(b"BREW").unwrap()), "other");
    }
}
