//! What one request may take of the server: a slot among `--max-concurrent-requests`, and
//! `--request-timeout-seconds` until its response starts (the wait for a slot included), else 503.
//! An event stream's response starts at once, so the timeout never cuts a stream; its body runs as
//! long as its job. The body's own deadline (`--body-timeout-seconds`, 408) is tower-http's
//! `RequestBodyDeadlineLayer`, read where bodies are read ([`super::JsonText`]).

use super::error::ApiError;
use axum::extract::{Request, State};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::Semaphore;

#[derive(Clone)]
pub struct Admission {
    slots: Arc<Semaphore>,
    timeout: Duration,
}

impl Admission {
    pub fn new(max_concurrent_requests: usize, timeout: Duration) -> Self {
        let slots = max_concurrent_requests.clamp(1, Semaphore::MAX_PERMITS);
        Self {
            slots: Arc::new(Semaphore::new(slots)),
            timeout,
        }
    }
}

pub async fn admit(State(admission): State<Admission>, request: Request, next: Next) -> Response {
    let handled = async {
        let _slot = admission.slots.acquire().await;
        next.run(request).await
    };
    tokio::time::timeout(admission.timeout, handled)
        .await
        .unwrap_or_else(|_| ApiError::Timeout(admission.timeout).into_response())
}

/// Whether a failure to read a body was its deadline running out.
pub fn is_body_timeout(error: &(dyn std::error::Error + 'static)) -> bool {
    let mut cause = Some(error);
    while let Some(error) = cause {
        if error.is::<tower_http::timeout::TimeoutError>() {
            return true;
        }
        cause = error.source();
    }
    false
}
