//! A bound on the bytes of responses held in memory until their clients read them. A response is
//! built whole (a Result of 1000 bins is tens of MB) and stays in memory until the client has read
//! it; clients that read slowly (at a byte a second, which no write-stall cut catches) each held
//! one, and 50 of them took a server to 2.6 GB (a probe). A response of [`HELD_FROM`] bytes or more
//! takes its size from a budget of `--max-response-mb` until its last chunk is handed to the
//! connection (hyper queues a few hundred KB of a connection's output beyond that, as for any
//! response) or it is dropped; when the budget is spent it waits up to [`WAIT`] for room, then is
//! 503 with Retry-After, its bytes freed. At most [`WAITING`] responses wait at a time, each
//! built whole: one more is 503 at once, its bytes freed (100 clients asking for a 44 MB Result
//! took a server to 3.3 GB, each response built and waiting: a probe). So the memory of responses
//! is at most the budget, [`WAITING`] responses and each connection's queue, besides those being
//! built (the handlers that build large ones take a place, one per core). One response larger
//! than the whole budget is served alone; a HEAD, whose body is never sent, takes nothing.

use super::error::ApiError;
use crate::telemetry::{RESPONSE_BYTES_HELD, RESPONSES_REFUSED, RESPONSES_WAITING};
use axum::body::{Body, Bytes};
use axum::extract::{Request, State};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use hyper::body::{Body as HttpBody, Frame, SizeHint};
use std::pin::Pin;
use std::sync::Arc;
use std::task::{Context, Poll};
use std::time::Duration;
use tokio::sync::{OwnedSemaphorePermit, Semaphore};

/// Responses of this many bytes or more count against the budget; smaller ones fit in a
/// connection's queue.
pub const HELD_FROM: u64 = 64 << 10;
/// How long a response waits for room in the budget.
pub const WAIT: Duration = Duration::from_secs(10);
/// How many built responses may wait for room at a time.
pub const WAITING: usize = 4;

/// The budget, in KiB, and the places to wait for it.
#[derive(Clone)]
pub struct Held {
    kib: Arc<Semaphore>,
    total_kib: u32,
    waiting: Arc<Semaphore>,
}

impl Held {
    pub fn new(max_mb: u64) -> Self {
        let total_kib = u32::try_from(max_mb.saturating_mul(1024))
            .unwrap_or(u32::MAX)
            .clamp(1, u32::try_from(Semaphore::MAX_PERMITS).unwrap_or(u32::MAX));
        Self {
            kib: Arc::new(Semaphore::new(total_kib as usize)),
            total_kib,
            waiting: Arc::new(Semaphore::new(WAITING)),
        }
    }
}

/// The middleware: a large response holds its bytes of the budget for as long as it lives.
pub async fn hold(State(held): State<Held>, request: Request, next: Next) -> Response {
    let head = request.method() == axum::http::Method::HEAD;
    let response = next.run(request).await;
    if head {
        return response;
    }
    let Some(bytes) = response.body().size_hint().exact() else {
        return response;
    };
    if bytes < HELD_FROM {
        return response;
    }
    let kib = u32::try_from(bytes.div_ceil(1024))
        .unwrap_or(u32::MAX)
        .min(held.total_kib);
    let permit = match Arc::clone(&held.kib).try_acquire_many_owned(kib) {
        Ok(permit) => Ok(permit),
        // No room now: wait for it in one of the few places to wait, or be refused at once.
        Err(_) => match Arc::clone(&held.waiting).try_acquire_owned() {
            Ok(_waiting) => {
                metrics::gauge!(RESPONSES_WAITING).increment(1.0);
                let waited =
                    tokio::time::timeout(WAIT, Arc::clone(&held.kib).acquire_many_owned(kib)).await;
                metrics::gauge!(RESPONSES_WAITING).decrement(1.0);
                match waited {
                    Ok(Ok(permit)) => Ok(permit),
                    _ => Err(()),
                }
            }
            Err(_) => Err(()),
        },
    };
    match permit {
        Ok(permit) => {
            metrics::gauge!(RESPONSE_BYTES_HELD).increment(bytes as f64);
            response.map(|body| {
                Body::new(Holding {
                    body,
                    pending: Bytes::new(),
                    bytes,
                    _permit: permit,
                })
            })
        }
        _ => {
            metrics::counter!(RESPONSES_REFUSED).increment(1);
            ApiError::ResponsesHeld(u64::from(held.total_kib) >> 10).into_response()
        }
    }
}

/// How much of a held response is handed to the connection at a time: hyper asks for more only
/// once it has written what it has, so the rest stays here, counted, until the client reads it
/// (given whole, the body would be dropped at once while hyper still held its bytes).
const CHUNK: usize = 64 << 10;

/// A response body with its share of the budget, given back when the body is dropped: after its
/// last chunk was taken, or with the connection.
struct Holding {
    body: Body,
    /// What the body gave and the connection has not taken yet.
    pending: Bytes,
    bytes: u64,
    _permit: OwnedSemaphorePermit,
}

impl Drop for Holding {
    fn drop(&mut self) {
        metrics::gauge!(RESPONSE_BYTES_HELD).decrement(self.bytes as f64);
    }
}

impl HttpBody for Holding {
    type Data = Bytes;
    type Error = axum::Error;

    fn poll_frame(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
    ) -> Poll<Option<Result<Frame<Bytes>, axum::Error>>> {
        loop {
            if !self.pending.is_empty() {
                let take = self.pending.len().min(CHUNK);
                let chunk = self.pending.split_to(take);
                return Poll::Ready(Some(Ok(Frame::data(chunk))));
            }
            match Pin::new(&mut self.body).poll_frame(cx) {
                Poll::Ready(Some(Ok(frame))) => match frame.into_data() {
                    Ok(data) => self.pending = data,
                    Err(frame) => return Poll::Ready(Some(Ok(frame))),
                },
                other => return other,
            }
        }
    }

    fn is_end_stream(&self) -> bool {
        self.pending.is_empty() && self.body.is_end_stream()
    }

    fn size_hint(&self) -> SizeHint {
        let rest = self.body.size_hint();
        let pending = self.pending.len() as u64;
        let mut hint = SizeHint::new();
        hint.set_lower(rest.lower() + pending);
        if let Some(upper) = rest.upper() {
            hint.set_upper(upper + pending);
        }
        hint
    }
}
