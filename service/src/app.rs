//! `bouncewear serve`: builds the store, the workers and the router, serves until SIGINT or SIGTERM,
//! then stops accepting, hands running jobs back to the queue and exits.

use crate::api::{self, AppState};
use crate::cli::CliError;
use crate::config::ServeConfig;
use crate::errors::ApiError;
use crate::store::sqlite::SqliteStore;
use crate::store::{Store, now_ms};
use crate::telemetry;
use crate::worker::Workers;
use axum::extract::DefaultBodyLimit;
use axum::http::Request;
use axum::routing::get;
use metrics_exporter_prometheus::PrometheusBuilder;
use std::collections::HashSet;
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::{Notify, watch};
use tower_http::catch_panic::CatchPanicLayer;
use tower_http::request_id::{MakeRequestUuid, PropagateRequestIdLayer, SetRequestIdLayer};
use tower_http::trace::TraceLayer;

pub async fn serve(config: ServeConfig) -> Result<(), CliError> {
    telemetry::init_logging();
    let api_keys: Vec<&String> = config
        .api_keys
        .iter()
        .filter(|k| !k.trim().is_empty())
        .collect();
    if api_keys.is_empty() && !config.bind.ip().is_loopback() {
        return Err(CliError::Invalid(bouncewear_model::InvalidInput::single(
            &bouncewear_model::Pointer::root(),
            format!(
                "--bind {} is not a loopback address: configure --api-key (or BOUNCEWEAR_API_KEYS) first",
                config.bind
            ),
        )));
    }
    let failed = |what: &str| {
        let what = what.to_owned();
        move |error: &dyn std::fmt::Display| CliError::Failed(format!("{what}: {error}"))
    };
    let metrics = PrometheusBuilder::new()
        .install_recorder()
        .map_err(|e| failed("metrics")(&e))?;
    let store: Arc<dyn Store> = Arc::new(
        SqliteStore::open(&config.database)
            .await
            .map_err(|e| failed("database")(&e))?,
    );
    let reclaimed = store
        .reclaim_expired(now_ms())
        .await
        .map_err(|e| failed("database")(&e))?;
    if reclaimed > 0 {
        tracing::info!(reclaimed, "jobs whose lease expired are back in the queue");
    }
    let compute = Arc::new(crate::cli::thread_pool(config.compute_threads)?);
    let (shutdown_sender, shutdown) = watch::channel(false);
    let wake = Arc::new(Notify::new());
    let state = AppState {
        store: Arc::clone(&store),
        config: Arc::new(config.clone()),
        key_hashes: Arc::new(
            api_keys
                .iter()
                .map(|k| api::hash_key(k.trim()))
                .collect::<HashSet<_>>(),
        ),
        wake: Arc::clone(&wake),
        metrics,
        shutdown: shutdown.clone(),
    };
    let router = build_router(state);

    let listener = tokio::net::TcpListener::bind(config.bind)
        .await
        .map_err(|e| failed("bind")(&e))?;
    let address = listener.local_addr().map_err(|e| failed("bind")(&e))?;
    // Tests and scripts read the port from this line.
    println!("bouncewear listening on http://{address}");
    tracing::info!(%address, database = %config.database, workers = config.workers, "serving");

    let workers = Arc::new(Workers {
        store: Arc::clone(&store),
        compute,
        lease: config.lease(),
        instance: format!("{}-{}", std::process::id(), uuid::Uuid::new_v4().simple()),
        wake,
    });
    let scheduler = tokio::spawn(crate::scheduler::run(
        Arc::clone(&store),
        config.max_queued,
        Arc::clone(&workers.wake),
        shutdown.clone(),
    ));
    // `--workers 0` makes an API-only instance that leaves the queue to others.
    let handles = workers.spawn(config.workers, shutdown.clone());
    tokio::spawn(report_queue_depth(Arc::clone(&store)));
    tokio::spawn(async move {
        wait_for_signal().await;
        tracing::info!("shutting down: no new requests, running jobs go back to the queue");
        let _ = shutdown_sender.send(true);
    });
    let mut stopped = shutdown.clone();
    axum::serve(listener, router)
        .with_graceful_shutdown(async move {
            let _ = stopped.wait_for(|stop| *stop).await;
        })
        .await
        .map_err(|e| failed("server")(&e))?;
    let _ = scheduler.await;
    for handle in handles {
        if tokio::time::timeout(Duration::from_secs(30), handle)
            .await
            .is_err()
        {
            tracing::warn!("a worker did not stop in time; its lease will expire");
        }
    }
    Ok(())
}

/// The API router with the docs, fallbacks and the cross-cutting layers.
pub fn build_router(state: AppState) -> axum::Router {
    let max_body = state.config.max_body_bytes;
    let (router, openapi) = api::router(state);
    let openapi = Arc::new(openapi);
    router
        .route("/openapi.json", get(move || async move { axum::Json(openapi.as_ref().clone()) }))
        .route("/docs", get(api::system::docs))
        .route("/docs/rapidoc-min.js", get(api::system::docs_script))
        .route("/", get(api::system::dashboard))
        .route("/jobs/{id}", get(api::system::job_page))
        .route("/dashboard/app.js", get(api::system::dashboard_script))
        .route("/dashboard/style.css", get(api::system::dashboard_style))
        .fallback(|| async { ApiError::NotFound("no such resource".to_owned()) })
        .method_not_allowed_fallback(|| async { ApiError::MethodNotAllowed })
        .layer(DefaultBodyLimit::max(max_body))
        .layer(axum::middleware::from_fn(telemetry::record_request))
        .layer(CatchPanicLayer::custom(|_| {
            axum::response::IntoResponse::into_response(ApiError::Internal(crate::errors::Internal("a handler panicked".into())))
        }))
        .layer(TraceLayer::new_for_http().make_span_with(|request: &Request<_>| {
            let request_id = request.headers().get("x-request-id").and_then(|v| v.to_str().ok()).unwrap_or("-");
            tracing::info_span!("request", method = %request.method(), uri = %request.uri(), request_id)
        }))
        .layer(PropagateRequestIdLayer::x_request_id())
        .layer(SetRequestIdLayer::x_request_id(MakeRequestUuid))
}

async fn report_queue_depth(store: Arc<dyn Store>) {
    let mut tick = tokio::time::interval(Duration::from_secs(1));
    loop {
        tick.tick().await;
        if let Ok((queued, running)) = store.queue_depth().await {
            metrics::gauge!("bouncewear_jobs_queued").set(queued as f64);
            metrics::gauge!("bouncewear_jobs_running").set(running as f64);
        }
    }
}

async fn wait_for_signal() {
    let interrupt = async {
        let _ = tokio::signal::ctrl_c().await;
    };
    #[cfg(unix)]
    let terminate = async {
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(mut signal) => {
                signal.recv().await;
            }
            Err(_) => std::future::pending::<()>().await,
        }
    };
    #[cfg(not(unix))]
    let terminate = std::future::pending::<()>();
    tokio::select! {
        () = interrupt => {}
        () = terminate => {}
    }
}
