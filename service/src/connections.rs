//! The accept loop: HTTP/1.1 connections served by hyper with a deadline for every request's
//! headers, and at most a bounded number of connections open, so that clients that connect and
//! stall (slowloris) are cut off and can never use up the process's file descriptors. When
//! `stopping` turns true, it stops accepting and waits for open connections to finish their
//! responses (each gets hyper's graceful shutdown).

use hyper::server::conn::http1;
use hyper_util::rt::{TokioIo, TokioTimer};
use hyper_util::service::TowerToHyperService;
use std::sync::Arc;
use std::time::Duration;
use tokio::net::TcpListener;
use tokio::sync::{Semaphore, watch};
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

/// Serves `router` on `listener` until `stopping` turns true, then drains.
pub async fn serve(
    listener: TcpListener,
    router: axum::Router,
    limits: ConnectionLimits,
    mut stopping: watch::Receiver<bool>,
) {
    let slots = Arc::new(Semaphore::new(limits.max_connections));
    let mut http = http1::Builder::new();
    http.timer(TokioTimer::new())
        .header_read_timeout(limits.header_timeout);
    let mut connections = JoinSet::new();
    loop {
        while connections.try_join_next().is_some() {}
        // A slot first: at the limit, new clients wait in the kernel's backlog, not in our memory.
        let slot = tokio::select! {
            slot = Arc::clone(&slots).acquire_owned() => slot.expect("the semaphore is never closed"),
            _ = stopping.wait_for(|stop| *stop) => break,
        };
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
        let _ = stream.set_nodelay(true);
        let connection = http.serve_connection(
            TokioIo::new(stream),
            TowerToHyperService::new(router.clone()),
        );
        let mut stop = stopping.clone();
        connections.spawn(async move {
            let _slot = slot;
            tokio::pin!(connection);
            tokio::select! {
                _ = connection.as_mut() => return,
                _ = stop.wait_for(|stop| *stop) => connection.as_mut().graceful_shutdown(),
            }
            let _ = connection.await;
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
