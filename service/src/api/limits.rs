//! What one request may take of the server: a slot among `--max-concurrent-requests`, and
//! `--request-timeout-seconds` until its response starts (the wait for a slot included), else 503.
//! A request's body arrives before it takes a slot, under a bound of its own (as many bodies
//! arriving at once as there are slots), so clients that stall mid-body hold up other uploads for
//! at most the body's deadline and never a request without a body (a probe, a read). An event
//! stream's response starts at once, so the timeout never cuts a stream; its body runs as long as
//! its job. The body's own deadline (`--body-timeout-seconds`, 408) is tower-http's
//! `RequestBodyDeadlineLayer`, around this layer.

use super::error::ApiError;
use axum::body::Body;
use axum::extract::{Request, State};
use axum::http::header;
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::{OwnedSemaphorePermit, Semaphore};

#[derive(Clone)]
pub struct Admission {
    slots: Arc<Semaphore>,
    /// Bodies arriving at once, before their requests take a slot.
    arriving: Arc<Semaphore>,
    timeout: Duration,
    max_body: usize,
    body_timeout: Duration,
}

impl Admission {
    pub fn new(
        max_concurrent_requests: usize,
        timeout: Duration,
        max_body: usize,
        body_timeout: Duration,
    ) -> Self {
        let slots = max_concurrent_requests.clamp(1, Semaphore::MAX_PERMITS);
        Self {
            slots: Arc::new(Semaphore::new(slots)),
            arriving: Arc::new(Semaphore::new(slots)),
            timeout,
            max_body,
            body_timeout,
        }
    }

    /// The request with its body read into memory, if it has one and declares no more than the
    /// limit (one that does is refused by its handler before any of it is read).
    async fn received(&self, request: Request) -> Result<Request, ApiError> {
        let declared = request
            .headers()
            .get(header::CONTENT_LENGTH)
            .and_then(|v| v.to_str().ok()?.parse::<u64>().ok());
        let chunked = request.headers().contains_key(header::TRANSFER_ENCODING);
        if !chunked && declared.is_none_or(|length| length == 0 || length > self.max_body as u64) {
            return Ok(request);
        }
        let _arriving = self.arriving.acquire().await;
        let (parts, body) = request.into_parts();
        let bytes = axum::body::to_bytes(body, self.max_body)
            .await
            .map_err(|error| self.body_error(&error))?;
        Ok(Request::from_parts(parts, Body::from(bytes)))
    }

    /// Why a body could not be read: too large (413), its deadline (408), or broken (400).
    fn body_error(&self, error: &(dyn std::error::Error + 'static)) -> ApiError {
        if is_body_timeout(error) {
            return ApiError::BodyTimeout(self.body_timeout);
        }
        let mut cause = Some(error);
        while let Some(error) = cause {
            if error.is::<http_body_util::LengthLimitError>() {
                return ApiError::TooLarge(self.max_body);
            }
            cause = error.source();
        }
        ApiError::BadRequest(format!("the request's body could not be read: {error}"))
    }
}

pub async fn admit(State(admission): State<Admission>, request: Request, next: Next) -> Response {
    let handled = async {
        let request = match admission.received(request).await {
            Ok(request) => request,
            Err(error) => return error.into_response(),
        };
        let _slot = admission.slots.acquire().await;
        next.run(request).await
    };
    tokio::time::timeout(admission.timeout, handled)
        .await
        .unwrap_or_else(|_| ApiError::Timeout(admission.timeout).into_response())
}

/// Places for a kind of costly request, one per core: each holds its place until its handler
/// ends, and the rest wait their turn within the request timeout (calibration fits; requests
/// that parse whole Results).
pub fn places_per_core() -> Arc<Semaphore> {
    Arc::new(Semaphore::new(
        std::thread::available_parallelism().map_or(1, |n| n.get()),
    ))
}

/// A place among `places`, held until it is dropped.
pub async fn take_place(places: &Arc<Semaphore>) -> Result<OwnedSemaphorePermit, ApiError> {
    Arc::clone(places)
        .acquire_owned()
        .await
        .map_err(|_| ApiError::Internal(super::error::Internal("the places are closed".into())))
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
