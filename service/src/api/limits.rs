//! What one request may take of the server: a slot among `--max-concurrent-requests`, and
//! `--request-timeout-seconds` until its response starts (the wait for a slot included), else 503.
//! The body of an API request whose key is valid arrives before the request takes a slot, under a
//! bound of its own (as many bodies arriving, or read and waiting for a slot, as there are slots,
//! and never more than half the connections),
//! each within `--body-timeout-seconds` from when its turn to arrive came, and never behind 4 KB/s
//! after its first 2 s (408): clients that stall
//! mid-body hold up other uploads for at most that long, and never a request without a body (a
//! probe, a read). A body the server would refuse without reading (no valid key, no API route, a
//! declared length over the limit) is not read. An event stream's response starts at once, so the
//! timeout never cuts a stream; its body runs as long as its job.

use super::error::ApiError;
use crate::connections::{self, RequestConnection};
use crate::domain::Owner;
use axum::body::Body;
use axum::extract::{Request, State};
use axum::http::header;
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use http_body_util::BodyExt;
use std::collections::HashSet;
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::{OwnedSemaphorePermit, Semaphore};

#[derive(Clone)]
pub struct Admission {
    slots: Arc<Semaphore>,
    /// Bodies arriving, or read and waiting for a slot.
    arriving: Arc<Semaphore>,
    timeout: Duration,
    max_body: usize,
    body_timeout: Duration,
    /// The API keys' owners ([`super::AppState::key_owners`]): only a valid key's body is read.
    key_owners: Arc<HashSet<Owner>>,
}

impl Admission {
    pub fn new(state: &super::AppState) -> Self {
        let config = &state.config;
        let slots = config
            .max_concurrent_requests
            .clamp(1, Semaphore::MAX_PERMITS);
        // Uploads arriving hold their connections: half of them at most, so that uploads that
        // stall leave room for others. With as many places as slots, 200 connections and 256
        // slots, stalled uploads took every connection until their body timeout (a probe).
        let connections = connections::max_connections(config.max_connections);
        Self {
            slots: Arc::new(Semaphore::new(slots)),
            arriving: Arc::new(Semaphore::new(slots.min(connections / 2).max(1))),
            timeout: config.request_timeout(),
            max_body: config.max_body_bytes,
            body_timeout: config.body_timeout(),
            key_owners: Arc::clone(&state.key_owners),
        }
    }

    /// The request with its body read into memory and the place that lets it wait for a slot
    /// holding it; or as it came, without a place, when it has no body or one the server refuses
    /// unread.
    async fn received(
        &self,
        request: Request,
    ) -> Result<(Request, Option<OwnedSemaphorePermit>), ApiError> {
        let headers = request.headers();
        let declared = declared_length(headers);
        let chunked = headers.contains_key(header::TRANSFER_ENCODING);
        let has_body = chunked || declared.is_some_and(|length| length > 0);
        let refused_unread = declared_over(headers, self.max_body)
            || !request.uri().path().starts_with("/v1/")
            || super::owner_of(headers, &self.key_owners).is_err();
        if !has_body || refused_unread {
            return Ok((request, None));
        }
        let waiting =
            (request.extensions().get::<RequestConnection>()).map(RequestConnection::waiting_turn);
        let place = take_place(&self.arriving).await?;
        drop(waiting);
        let (parts, body) = request.into_parts();
        let bytes = self.arrived(body, declared).await?;
        Ok((Request::from_parts(parts, Body::from(bytes)), Some(place)))
    }

    /// The body, read as it arrives: whole within [`arrival_deadline`], and at no moment after
    /// [`ARRIVAL_GRACE`] behind [`MIN_ARRIVAL_BYTES_PER_S`] (else 408). A chunked body that
    /// stalled after a byte held its place for the whole body timeout, so that reconnecting
    /// clients kept others' uploads waiting their turn 30 s at a time (a probe).
    async fn arrived(&self, body: Body, declared: Option<u64>) -> Result<Vec<u8>, ApiError> {
        let started = tokio::time::Instant::now();
        let end = started + arrival_deadline(declared, self.body_timeout);
        let mut body = http_body_util::Limited::new(body, self.max_body);
        let mut bytes = Vec::new();
        loop {
            let behind = ARRIVAL_GRACE
                + Duration::from_secs_f64(bytes.len() as f64 / MIN_ARRIVAL_BYTES_PER_S);
            let until = end.min(started + behind);
            let frame = tokio::time::timeout_at(until, body.frame())
                .await
                .map_err(|_| ApiError::BodyTimeout(until - started))?;
            match frame {
                None => return Ok(bytes),
                Some(Err(error)) => return Err(self.body_error(&*error)),
                Some(Ok(frame)) => {
                    if let Ok(data) = frame.into_data() {
                        bytes.extend_from_slice(&data);
                    }
                }
            }
        }
    }

    /// Why a body could not be read: too large (413), or broken (400).
    fn body_error(&self, error: &(dyn std::error::Error + 'static)) -> ApiError {
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

/// The slowest a body may arrive, after its first [`ARRIVAL_GRACE`].
pub const MIN_ARRIVAL_BYTES_PER_S: f64 = 4096.0;
pub const ARRIVAL_GRACE: Duration = Duration::from_secs(2);

/// How long a body may take to arrive: `body_timeout`, or less for a body whose length is
/// declared, [`ARRIVAL_GRACE`] and [`MIN_ARRIVAL_BYTES_PER_S`]. A hundred bytes that stall held
/// an arriving body's place for the whole body timeout: 300 such connections delayed another
/// client's small submission by 26 s (a probe); now they hold one for about 2 s.
fn arrival_deadline(declared: Option<u64>, body_timeout: Duration) -> Duration {
    declared.map_or(body_timeout, |bytes| {
        let arriving = Duration::from_secs_f64(bytes as f64 / MIN_ARRIVAL_BYTES_PER_S);
        body_timeout.min(ARRIVAL_GRACE + arriving)
    })
}

/// The body's length as its `Content-Length` declares it, if it does.
fn declared_length(headers: &axum::http::HeaderMap) -> Option<u64> {
    headers
        .get(header::CONTENT_LENGTH)
        .and_then(|v| v.to_str().ok()?.parse::<u64>().ok())
}

/// Whether the request declares a body longer than `limit`: refused (413) before any of it is
/// read, not after waiting for bytes a client may never send.
pub fn declared_over(headers: &axum::http::HeaderMap, limit: usize) -> bool {
    declared_length(headers).is_some_and(|length| length > limit as u64)
}

pub async fn admit(State(admission): State<Admission>, request: Request, next: Next) -> Response {
    let handled = async {
        let (request, _arrived) = match admission.received(request).await {
            Ok(received) => received,
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
