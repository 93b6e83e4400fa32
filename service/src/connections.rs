//! The accept loop: HTTP/1.1 connections served by hyper with a deadline for every request's
//! headers, and at most a bounded number of connections open, so that clients that connect and
//! stall (slowloris) are cut off and can never use up the process's file descriptors; at the limit,
//! the oldest connection waiting for a request's headers is closed to make room for a new client. When
//! `stopping` turns true, it stops accepting and waits for open connections to finish their
//! responses (each gets hyper's graceful shutdown).

use hyper::body::{Body as HttpBody, Frame, SizeHint};
use hyper::server::conn::http1;
use hyper::service::{Service, service_fn};
use hyper_util::rt::{TokioIo, TokioTimer};
use hyper_util::service::TowerToHyperService;
use std::collections::BTreeMap;
use std::pin::Pin;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::task::{Context, Poll};
use std::time::Duration;
use tokio::net::TcpListener;
use tokio::sync::{Notify, Semaphore, watch};
use tokio::task::JoinSet;

/// File descriptors kept back from connections: the database's connections, SQLite's WAL and
/// shared memory, the log, `/proc` reads for the process metrics.
const RESERVED_FDS: u64 = 128;

/// What each connection may take.
#[derive(Debug, Clone, Copy)]
pub struct ConnectionLimits {
    /// Open connections at most; further clients wait in the listen backlog.
    pub max_connections: usize,
    /// From the connection's start, or the end of its previous response, to the end of a
    /// request's headers.
    pub header_timeout: Duration,
}

impl ConnectionLimits {
    /// `wanted` connections (or as many as there are descriptors for), never more than the
    /// open-file limit allows.
    pub fn new(wanted: Option<usize>, header_timeout: Duration) -> Self {
        let available = open_file_limit().map_or(usize::MAX, |limit| {
            usize::try_from(limit.saturating_sub(RESERVED_FDS).max(1)).unwrap_or(usize::MAX)
        });
        let max_connections = wanted.map_or(available, |wanted| wanted.clamp(1, available));
        if wanted.is_some_and(|wanted| wanted > max_connections) {
            tracing::warn!(
                max_connections,
                "--max-connections is above what the open-file limit (RLIMIT_NOFILE) leaves; lowered"
            );
        }
        Self {
            max_connections: max_connections.min(Semaphore::MAX_PERMITS),
            header_timeout,
        }
    }
}

/// The soft limit on open files (RLIMIT_NOFILE); `None` where there is none or it cannot be read.
fn open_file_limit() -> Option<u64> {
    let mut limit = libc::rlimit {
        rlim_cur: 0,
        rlim_max: 0,
    };
    // SAFETY: getrlimit writes one `rlimit` into the struct it is given, which lives on our stack.
    let read = unsafe { libc::getrlimit(libc::RLIMIT_NOFILE, &raw mut limit) };
    (read == 0 && limit.rlim_cur != libc::RLIM_INFINITY).then_some(limit.rlim_cur)
}

/// One open connection: how many of its requests are in progress (a response counts until its
/// body is sent), and the signal that closes it.
struct Connection {
    in_progress: AtomicUsize,
    shed: Notify,
}

/// The open connections, oldest first: when every slot is taken, the oldest that has no request in
/// progress (it is waiting for a request's headers: a slow or idle client) is closed for the new
/// one, so clients that hold connections without using them cannot lock out the others.
#[derive(Default)]
struct Open {
    next: AtomicU64,
    connections: Mutex<BTreeMap<u64, Arc<Connection>>>,
}

impl Open {
    fn add(self: &Arc<Self>) -> (u64, Arc<Connection>) {
        let id = self.next.fetch_add(1, Ordering::Relaxed);
        let connection = Arc::new(Connection {
            in_progress: AtomicUsize::new(0),
            shed: Notify::new(),
        });
        self.lock().insert(id, Arc::clone(&connection));
        (id, connection)
    }

    fn remove(&self, id: u64) {
        self.lock().remove(&id);
    }

    /// Closes the oldest connection without a request in progress; whether there was one.
    fn shed_oldest_idle(&self) -> bool {
        let open = self.lock();
        let idle = open
            .values()
            .find(|c| c.in_progress.load(Ordering::Acquire) == 0);
        if let Some(connection) = idle {
            connection.shed.notify_one();
        }
        idle.is_some()
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, BTreeMap<u64, Arc<Connection>>> {
        self.connections.lock().unwrap_or_else(|e| e.into_inner())
    }
}

/// Counts a request in progress from its arrival until its response's body is sent or dropped.
struct InProgress(Arc<Connection>);

impl InProgress {
    fn enter(connection: &Arc<Connection>) -> Self {
        connection.in_progress.fetch_add(1, Ordering::AcqRel);
        Self(Arc::clone(connection))
    }
}

impl Drop for InProgress {
    fn drop(&mut self) {
        self.0.in_progress.fetch_sub(1, Ordering::AcqRel);
    }
}

/// A response body that keeps its request counted as in progress until it is dropped.
struct Counted<B> {
    body: B,
    _in_progress: InProgress,
}

impl<B: HttpBody + Unpin> HttpBody for Counted<B> {
    type Data = B::Data;
    type Error = B::Error;

    fn poll_frame(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
    ) -> Poll<Option<Result<Frame<Self::Data>, Self::Error>>> {
        Pin::new(&mut self.body).poll_frame(cx)
    }

    fn is_end_stream(&self) -> bool {
        self.body.is_end_stream()
    }

    fn size_hint(&self) -> SizeHint {
        self.body.size_hint()
    }
}

/// Serves `router` on `listener` until `stopping` turns true, then drains.
pub async fn serve(
    listener: TcpListener,
    router: axum::Router,
    limits: ConnectionLimits,
    mut stopping: watch::Receiver<bool>,
) {
    let slots = Arc::new(Semaphore::new(limits.max_connections));
    let open = Arc::new(Open::default());
    let mut http = http1::Builder::new();
    http.timer(TokioTimer::new())
        .header_read_timeout(limits.header_timeout);
    let mut connections = JoinSet::new();
    loop {
        while connections.try_join_next().is_some() {}
        let stream = tokio::select! {
            accepted = listener.accept() => match accepted {
                Ok((stream, _)) => stream,
                Err(error) => {
                    pause_after(&error).await;
                    continue;
                }
            },
            _ = stopping.wait_for(|stop| *stop) => break,
        };
        // At the limit, the oldest connection waiting for a request's headers makes room; if
        // every one is busy, the new client waits for a slot (and later ones in the kernel's
        // backlog, not in our memory: one accepted socket at most is held beyond the limit).
        let slot = match Arc::clone(&slots).try_acquire_owned() {
            Ok(slot) => slot,
            Err(_) => {
                if open.shed_oldest_idle() {
                    metrics::counter!(crate::telemetry::CONNECTIONS_SHED).increment(1);
                }
                tokio::select! {
                    slot = Arc::clone(&slots).acquire_owned() => slot.expect("the semaphore is never closed"),
                    _ = stopping.wait_for(|stop| *stop) => break,
                }
            }
        };
        let _ = stream.set_nodelay(true);
        let (id, state) = open.add();
        let inner = TowerToHyperService::new(router.clone());
        let counting = Arc::clone(&state);
        let service = service_fn(move |request| {
            let in_progress = InProgress::enter(&counting);
            let response = inner.call(request);
            async move {
                let response = response.await?;
                Ok::<_, std::convert::Infallible>(response.map(|body| Counted {
                    body,
                    _in_progress: in_progress,
                }))
            }
        });
        let connection = http.serve_connection(TokioIo::new(stream), service);
        let mut stop = stopping.clone();
        let open = Arc::clone(&open);
        connections.spawn(async move {
            let _slot = slot;
            tokio::pin!(connection);
            let drain = tokio::select! {
                _ = connection.as_mut() => false,
                // Dropping the connection closes its socket.
                () = state.shed.notified() => false,
                _ = stop.wait_for(|stop| *stop) => true,
            };
            if drain {
                connection.as_mut().graceful_shutdown();
                let _ = connection.await;
            }
            open.remove(id);
        });
    }
    drop(listener);
    while connections.join_next().await.is_some() {}
}

/// After a failed accept: a client that gave up is nothing; anything else (out of descriptors,
/// most likely) gets a second's pause, as accept loops do, instead of a busy loop.
async fn pause_after(error: &std::io::Error) {
    use std::io::ErrorKind::{ConnectionAborted, ConnectionRefused, ConnectionReset};
    if !matches!(
        error.kind(),
        ConnectionAborted | ConnectionRefused | ConnectionReset
    ) {
        tracing::warn!(%error, "accepting a connection failed");
        tokio::time::sleep(Duration::from_secs(1)).await;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn connections_stay_below_the_open_file_limit() {
        let limits = ConnectionLimits::new(Some(usize::MAX), Duration::from_secs(1));
        if let Some(limit) = open_file_limit() {
            assert!((limits.max_connections as u64) < limit.max(2));
        }
        let asked = ConnectionLimits::new(Some(5), Duration::from_secs(1));
        assert_eq!(asked.max_connections, 5);
    }
}
