//! Start-up: [`Application::build`] opens the store, binds the listener (port 0 picks a free one,
//! which tests use) and assembles every route in one router; [`Application::run_until_stopped`]
//! serves, runs the workers and the scheduler, and when the shutdown future resolves stops
//! accepting, hands running jobs back to the queue and returns.

use crate::api::watch::JobWatch;
use crate::api::{self, AppState};
use crate::compute::{PoolError, thread_pool};
use crate::config::{ServeConfig, WorkerConfig, WorkerProcess};
use crate::connections::{self, ConnectionLimits};
use crate::domain::Owner;
use crate::store::{Store, StoreError};
use crate::telemetry;
use crate::worker::{HELD_GROUP_BYTES, HeldGroups, Workers};
use metrics_exporter_prometheus::PrometheusHandle;
use std::collections::HashSet;
use std::future::Future;
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;
use tokio::net::TcpListener;
use tokio::sync::{Notify, watch};

/// Why the service could not start (or stopped serving).
#[derive(Debug, thiserror::Error)]
pub enum StartupError {
    #[error(
        "--bind {0} is not a loopback address: configure --api-key (or BOUNCEWEAR_API_KEYS) first"
    )]
    PublicWithoutKeys(SocketAddr),
    #[error("{}", prefixed("database", .0))]
    Database(#[from] StoreError),
    #[error("compute threads: {0}")]
    Compute(#[from] PoolError),
    #[error("bind {address}: {source}")]
    Bind {
        address: SocketAddr,
        source: std::io::Error,
    },
    #[error("--workers must be at least 1 for a worker process")]
    NoWorkers,
    #[error("{0}")]
    OpenFiles(String),
}

/// `error` after `what: `, unless it says so already (a database's own error begins
/// `database: `; "database: database: ... password authentication failed", found from outside).
fn prefixed(what: &str, error: &impl std::fmt::Display) -> String {
    let said = error.to_string();
    match said
        .strip_prefix(what)
        .is_some_and(|rest| rest.starts_with(": "))
    {
        true => said,
        false => format!("{what}: {said}"),
    }
}

impl StartupError {
    /// Whether the command line is at fault (a bad command line exits 2, docs/contract.md): a
    /// public bind without keys, no workers for a worker process, no compute threads, or a
    /// database URL no backend takes.
    pub fn is_bad_command_line(&self) -> bool {
        matches!(
            self,
            StartupError::PublicWithoutKeys(_)
                | StartupError::NoWorkers
                | StartupError::Compute(PoolError::NoThreads | PoolError::TooMany(_))
                | StartupError::Database(StoreError::UnsupportedUrl(_) | StoreError::NoFile(_))
        )
    }
}

/// A built service: bound, with its store open, not yet serving.
pub struct Application {
    listener: TcpListener,
    address: SocketAddr,
    router: axum::Router,
    state: AppState,
    workers: Arc<Workers>,
    shutdown_sender: watch::Sender<bool>,
}

impl Application {
    pub async fn build(config: ServeConfig) -> Result<Self, StartupError> {
        let key_owners: HashSet<Owner> = config
            .api_keys
            .iter()
            .map(|key| key.trim())
            .filter(|key| !key.is_empty())
            .map(Owner::of_key)
            .collect();
        if key_owners.is_empty() && !config.bind.ip().is_loopback() {
            return Err(StartupError::PublicWithoutKeys(config.bind));
        }
        connections::check_open_file_limit().map_err(StartupError::OpenFiles)?;
        // The address first: a port in use is refused before the database file is created.
        let listener =
            TcpListener::bind(config.bind)
                .await
                .map_err(|source| StartupError::Bind {
                    address: config.bind,
                    source,
                })?;
        let workers = Arc::new(start_workers(&config.queue).await?);
        let store = Arc::clone(&workers.store);
        let address = listener.local_addr().map_err(|source| StartupError::Bind {
            address: config.bind,
            source,
        })?;
        let (shutdown_sender, shutdown) = watch::channel(false);
        let watch = JobWatch::start(
            Arc::clone(&store),
            config.max_streams_per_key,
            config.max_waits(),
            shutdown.clone(),
        );
        let state = AppState {
            watch,
            store,
            config: Arc::new(config),
            key_owners: Arc::new(key_owners),
            wake: Arc::clone(&workers.wake),
            metrics: telemetry::prometheus(),
            shutdown,
            fits: api::calibrations::places_for_fits(),
            parsing: api::limits::places_per_core(),
        };
        Ok(Self {
            listener,
            address,
            router: api::router(state.clone()),
            state,
            workers,
            shutdown_sender,
        })
    }

    /// Where the service listens (the real port when the configuration asked for port 0).
    pub fn address(&self) -> SocketAddr {
        self.address
    }

    /// Serves until `shutdown` resolves, then drains: event streams end, the scheduler stops, and
    /// workers hand their running jobs back to the queue.
    pub async fn run_until_stopped(
        self,
        shutdown: impl Future<Output = ()> + Send + 'static,
    ) -> Result<(), StartupError> {
        let Self {
            listener,
            address,
            router,
            state,
            workers,
            shutdown_sender,
        } = self;
        let config = &state.config;
        let queue = &config.queue;
        let slots = workers.slots(queue.workers);
        let kernel = bouncewear_model::montecarlo::Kernel::active().name();
        tracing::info!(%address, database = %crate::config::shown_url(&queue.database), workers = slots, kernel, "serving");
        let stopping = state.shutdown.clone();
        let scheduler = tokio::spawn(crate::scheduler::run(
            Arc::clone(&state.store),
            crate::scheduler::RunLimits {
                queue: config.queue_bound(),
                schedule: config.schedule_limits(),
                key_owners: Arc::clone(&state.key_owners),
            },
            Arc::clone(&state.wake),
            stopping.clone(),
        ));
        if let Some(per_key) = config.max_queued_per_key.filter(|n| *n > config.max_queued) {
            let total = config.max_queued;
            tracing::warn!(
                "--max-queued-per-key {per_key} is above --max-queued {total}: a key holds at most {total} unfinished jobs, as the queue does"
            );
        }
        let retention = config.retain_days.map(|days| {
            if days == 0 {
                tracing::warn!("--retain-days 0: every job is deleted, with its Result, as soon as it ends (at the next hourly check); leave the flag out to keep jobs until deleted");
            }
            tokio::spawn(crate::retention::run(
                Arc::clone(&state.store),
                days,
                stopping.clone(),
            ))
        });
        // `--workers 0` makes an API-only instance that leaves the queue to others.
        let handles = workers.spawn(slots, stopping.clone());
        let reporter = tokio::spawn(report_queue_depth(
            Arc::clone(&state.store),
            state.metrics.clone(),
        ));
        tokio::spawn(async move {
            shutdown.await;
            tracing::info!("shutting down: no new requests, running jobs go back to the queue");
            let _ = shutdown_sender.send(true);
        });
        let limits = ConnectionLimits::new(
            config.max_connections,
            config.header_timeout(),
            config.body_timeout(),
        );
        tracing::info!(
            max_connections = limits.max_connections,
            header_timeout_s = limits.header_timeout.as_secs_f64(),
            "accepting connections"
        );
        // A stream holds its connection for as long as it is open (found from outside: 20
        // streams under `--max-connections 20`, and `/healthz` waited in the backlog).
        let streams = config.max_streams_per_key * config.api_keys.len().max(1);
        if streams >= limits.max_connections {
            tracing::warn!(
                "--max-streams-per-key {} for {} can hold {streams} event streams, every one of the {} connections (--max-connections): other requests, /healthz's too, would wait",
                config.max_streams_per_key,
                match config.api_keys.len() {
                    0 => "every client (no API keys)".to_owned(),
                    keys => format!("each of {keys} API keys"),
                },
                limits.max_connections
            );
        }
        connections::serve(listener, router, limits, stopping).await;
        reporter.abort();
        let _ = scheduler.await;
        if let Some(retention) = retention {
            let _ = retention.await;
        }
        join_workers(handles).await;
        checkpoint(state.store.as_ref()).await;
        Ok(())
    }
}

/// The store's log folded into its file as the process ends ([`crate::store::Store::checkpoint`]).
async fn checkpoint(store: &Store) {
    if let Err(error) = store.checkpoint().await {
        tracing::warn!(%error, "the database's log was not folded into its file");
    }
}

/// Opens the queue's store and readies the workers (not yet running) with their compute pool.
/// Shards whose lease expired while no worker ran are claimed again as workers start.
async fn start_workers(config: &WorkerConfig) -> Result<Workers, StartupError> {
    let store = crate::store::open_with(&config.database, config.database_connections).await?;
    Ok(Workers {
        store,
        compute: Arc::new(thread_pool(config.compute_threads)?),
        lease: config.lease(),
        budget: config.retry_budget(),
        instance: format!("{}-{}", std::process::id(), uuid::Uuid::new_v4().simple()),
        wake: Arc::new(Notify::new()),
        listed_lives: config.max_listed_lives,
        large_merges: tokio::sync::Semaphore::new(1),
        sharded_round_operations: crate::domain::rare::SHARDED_ROUND_OPERATIONS,
        whole_step: crate::domain::shards::WHOLE_STEP,
        held: HeldGroups::new(HELD_GROUP_BYTES),
    })
}

/// Waits for stopping workers, which hand their jobs back to the queue; one that takes too long
/// leaves its lease to expire.
async fn join_workers(handles: Vec<tokio::task::JoinHandle<()>>) {
    for handle in handles {
        if tokio::time::timeout(Duration::from_secs(30), handle)
            .await
            .is_err()
        {
            tracing::warn!("a worker did not stop in time; its lease will expire");
        }
    }
}

/// `bouncewear worker`: runs jobs from the queue until SIGINT or SIGTERM, without serving HTTP
/// (scale jobs out across machines with several of these on one PostgreSQL database).
pub async fn work(process: WorkerProcess) -> Result<(), StartupError> {
    let config = process.config;
    if config.workers == Some(0) {
        return Err(StartupError::NoWorkers);
    }
    no_transparent_huge_pages();
    // Before the store opens: its retries are counted too, and a bad address is said at once.
    if let Some(address) = process.metrics_bind {
        // Printed before the line below, for which tests and scripts wait.
        let bound = serve_metrics(address).await?;
        announce(format_args!(
            "bouncewear worker metrics on http://{bound}/metrics"
        ));
    }
    let workers = Arc::new(start_workers(&config).await?);
    let slots = workers.slots(config.workers);
    let (stop, stopping) = watch::channel(false);
    let handles = Arc::clone(&workers).spawn(slots, stopping);
    // Tests and scripts wait for this line.
    announce(format_args!(
        "bouncewear worker running {slots} shard(s) at a time from {}",
        crate::config::shown_url(&config.database)
    ));
    wait_for_signal().await;
    tracing::info!("shutting down: running shards go back to the queue");
    let _ = stop.send(true);
    join_workers(handles).await;
    checkpoint(workers.store.as_ref()).await;
    Ok(())
}

/// Serves this process's Prometheus metrics at `/metrics` on `address`, from now until the
/// process ends; the address bound.
async fn serve_metrics(address: SocketAddr) -> Result<SocketAddr, StartupError> {
    let bind_error = |source| StartupError::Bind { address, source };
    let listener = TcpListener::bind(address).await.map_err(bind_error)?;
    let bound = listener.local_addr().map_err(bind_error)?;
    let handle = telemetry::prometheus();
    let metrics = axum::routing::get(move || {
        let text = telemetry::render_metrics(&handle);
        async move {
            (
                [(
                    axum::http::header::CONTENT_TYPE,
                    telemetry::METRICS_CONTENT_TYPE,
                )],
                text,
            )
        }
    });
    let router = axum::Router::new().route("/metrics", metrics);
    tokio::spawn(async move {
        if let Err(error) = axum::serve(listener, router).await {
            tracing::error!(%error, "serving the worker's metrics failed");
        }
    });
    Ok(bound)
}

/// A line for the scripts that start a server or worker, on stdout; one that cannot be written
/// (stdout a full disk or a closed pipe) is logged, and the process runs on: `println!` panicked
/// there, and the server never served (found from outside).
fn announce(line: std::fmt::Arguments) {
    use std::io::Write;
    let mut stdout = std::io::stdout().lock();
    if let Err(error) = writeln!(stdout, "{line}").and_then(|()| stdout.flush()) {
        tracing::warn!(%error, "{line} (stdout could not take this line)");
    }
}

/// `bouncewear serve`: the application until SIGINT or SIGTERM.
pub async fn serve(config: ServeConfig) -> Result<(), StartupError> {
    no_transparent_huge_pages();
    let application = Application::build(config).await?;
    // Tests and scripts read the port from this line.
    announce(format_args!(
        "bouncewear listening on http://{}",
        application.address()
    ));
    application.run_until_stopped(wait_for_signal()).await
}

/// mimalloc asks for transparent huge pages on its arenas (`madvise`), and the kernel zeroes each
/// page of 2 MiB whole when it is first touched, again every time mimalloc has given it back. A
/// server's or worker's memory comes and goes with every group it encodes and every merge: with
/// huge pages, zeroing (`clear_page_erms`) took 4-5 % of a worker node's CPU running
/// 10^7-operation jobs on PostgreSQL; without, the merge step took 47 ms against 56 and the node
/// 491 ms of CPU a job against 518 (docs/performance-history.md, 4 December 2026). A `run` keeps
/// them: a short process touches its memory once, and huge pages spare it two thirds of its page
/// faults. The same as `MIMALLOC_ALLOW_THP=0`, from here on.
fn no_transparent_huge_pages() {
    #[cfg(target_os = "linux")]
    // SAFETY: PR_SET_THP_DISABLE only sets a flag of this process's memory; its arguments are
    // plain integers.
    unsafe {
        libc::prctl(libc::PR_SET_THP_DISABLE, 1, 0, 0, 0);
    }
}

async fn report_queue_depth(store: Arc<Store>, metrics: PrometheusHandle) {
    let mut tick = tokio::time::interval(Duration::from_secs(1));
    loop {
        tick.tick().await;
        // Without the exporter's own upkeep thread, histograms are drained here.
        metrics.run_upkeep();
        if let Ok((queued, running)) = store.queue_depth().await {
            metrics::gauge!("bouncewear_jobs_queued").set(queued as f64);
            metrics::gauge!("bouncewear_jobs_running").set(running as f64);
        }
    }
}

/// The first SIGINT, SIGTERM or SIGHUP, which starts a graceful stop (a hang-up, the terminal
/// that started it closed, ended the process at once: the default action); a second one then ends the process
/// at once, as an operator who sends it asks: the queue loses nothing by it (what was
/// acknowledged is in the database; running shards go back to the queue as their leases expire).
async fn wait_for_signal() {
    one_signal().await;
    tokio::spawn(async {
        one_signal().await;
        tracing::warn!(
            "a second signal: exiting now; running shards go back to the queue as their leases expire"
        );
        std::process::exit(1);
    });
}

async fn one_signal() {
    let interrupt = async {
        let _ = tokio::signal::ctrl_c().await;
    };
    #[cfg(unix)]
    let received = async |kind| match tokio::signal::unix::signal(kind) {
        Ok(mut signal) => {
            signal.recv().await;
        }
        Err(_) => std::future::pending::<()>().await,
    };
    #[cfg(unix)]
    let (terminate, hang_up) = (
        received(tokio::signal::unix::SignalKind::terminate()),
        received(tokio::signal::unix::SignalKind::hangup()),
    );
    #[cfg(not(unix))]
    let (terminate, hang_up) = (std::future::pending::<()>(), std::future::pending::<()>());
    tokio::select! {
        () = interrupt => {}
        () = terminate => {}
        () = hang_up => {}
    }
}

#[cfg(test)]
mod tests {
    use super::{StartupError, StoreError};

    /// A store's error is told after `database: ` once, whether or not it says so itself.
    #[test]
    fn a_database_error_at_start_up_says_database_once() {
        let said = |error: StoreError| StartupError::Database(error).to_string();
        let refused = said(StoreError::Database(sqlx::Error::RowNotFound));
        assert!(refused.starts_with("database: no rows"), "{refused}");
        let waited = said(StoreError::NotReady("no connection".to_owned()));
        assert_eq!(waited, "database: not ready: no connection");
    }

    #[test]
    fn a_database_url_is_logged_without_its_credentials() {
        use crate::config::shown_url;
        assert_eq!(
            shown_url("postgres://bouncewear:secret@db:5432/bouncewear"),
            "postgres://***@db:5432/bouncewear"
        );
        assert_eq!(
            shown_url("sqlite://bouncewear.db"),
            "sqlite://bouncewear.db"
        );
        // Too broken to parse, the password goes all the same.
        assert_eq!(shown_url("u:s3/cret@h:80"), "***@h:80");
    }
}
