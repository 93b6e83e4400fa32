//! The accept loop: HTTP/1.1 connections served by hyper with a deadline for every request's
//! headers, and at most a bounded number of connections open, so that clients that connect and
//! stall (slowloris) are cut off and can never use up the process's file descriptors; at the limit,
//! the oldest connection waiting on its client for a request's headers is closed to make room for a
//! new client. When
//! `stopping` turns true, it stops accepting and waits for open connections to finish their
//! responses (each gets hyper's graceful shutdown).

use hyper::body::{Body as HttpBody, Frame, SizeHint};
use hyper::server::conn::http1;
use hyper::service::{Service, service_fn};
use hyper_util::rt::{TokioIo, TokioTimer};
use hyper_util::service::TowerToHyperService;
use std::collections::BTreeMap;
use std::pin::Pin;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::task::{Context, Poll};
use std::time::Duration;
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{Notify, OwnedSemaphorePermit, Semaphore, watch};
use tokio::task::JoinSet;

/// File descriptors kept back from connections: the database's connections, SQLite's WAL and
/// shared memory, the log, `/proc` reads for the process metrics.
const RESERVED_FDS: u64 = 128;

/// The fewest connections a server starts with: one event stream must not leave `/healthz` and
/// every other request waiting in the backlog.
const MIN_CONNECTIONS: u64 = 8;

/// Refuses an open-file limit that leaves no room for connections beside `RESERVED_FDS`: under
/// `ulimit -n 16` the server said it listened and accepted no connection at all, its 17
/// descriptors at rest already over the limit, and under 12 it blamed the database's file (found
/// from outside). The soft limit stays as it is: the default `--max-connections` follows it.
pub fn check_open_file_limit() -> Result<(), String> {
    match open_file_limit() {
        Some(limit) if limit < RESERVED_FDS + MIN_CONNECTIONS => Err(format!(
            "the open-file limit (RLIMIT_NOFILE, `ulimit -n`) is {limit}: the server keeps \
             {RESERVED_FDS} descriptors for the database, the log and the process metrics and \
             needs room for {MIN_CONNECTIONS} connections or more beside them; raise it to at \
             least {}",
            RESERVED_FDS + MIN_CONNECTIONS
        )),
        _ => Ok(()),
    }
}

/// What each connection may take.
#[derive(Debug, Clone, Copy)]
pub struct ConnectionLimits {
    /// Open connections at most; further clients wait in the listen backlog.
    pub max_connections: usize,
    /// From the connection's start, or the end of its previous response, to the end of a
    /// request's headers.
    pub header_timeout: Duration,
    /// How long a response may wait for its client to read any of it: a client that stops
    /// reading is disconnected, and the response it pinned in memory is dropped.
    pub write_stall: Duration,
}

impl ConnectionLimits {
    /// `wanted` connections (or as many as there are descriptors for), never more than the
    /// open-file limit allows.
    pub fn new(wanted: Option<usize>, header_timeout: Duration, write_stall: Duration) -> Self {
        let max_connections = max_connections(wanted);
        if wanted.is_some_and(|wanted| wanted > max_connections) {
            tracing::warn!(
                max_connections,
                "--max-connections is above what the open-file limit (RLIMIT_NOFILE) leaves; lowered"
            );
        }
        Self {
            max_connections,
            header_timeout,
            write_stall,
        }
    }
}

/// The connections a server keeps open at most for `wanted` (`--max-connections`): as many as
/// asked, or as the open-file limit leaves room for, whichever is fewer.
pub fn max_connections(wanted: Option<usize>) -> usize {
    let available = open_file_limit().map_or(usize::MAX, |limit| {
        usize::try_from(limit.saturating_sub(RESERVED_FDS).max(1)).unwrap_or(usize::MAX)
    });
    let max_connections = wanted.map_or(available, |wanted| wanted.clamp(1, available));
    max_connections.min(Semaphore::MAX_PERMITS)
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

/// The most a connection buffers of what its client sends: a request's line and headers must fit
/// (more is 431). Hyper's default, about 400 KB, let 6,000 clients that stall in one long header
/// each keep that much in memory until their header timeout: 1.4 GB (a probe).
pub const MAX_REQUEST_HEAD_BYTES: usize = 16 * 1024;

/// How often a new client waiting for a slot looks again for a connection to close, while none can
/// be: every open one is busy, or new.
const SHED_RETRY: Duration = Duration::from_millis(5);

/// How long a connection whose client has sent nothing yet is kept from being closed for a new
/// client: the time a client that has just connected has to send its request, however many
/// others connect.
const FIRST_BYTES_WITHIN: Duration = Duration::from_millis(100);

/// One open connection: how many of its requests are in progress (a response counts until its
/// body is sent), whether the server is waiting on its client (its last read found nothing to
/// read), and the signal that closes it.
struct Connection {
    in_progress: AtomicUsize,
    /// Of those, how many wait their turn to send a body ([`Waiting`]).
    waiting_turn: AtomicUsize,
    waiting: AtomicBool,
    /// Whether its client has sent any bytes.
    heard: AtomicBool,
    /// Whether a response's bytes were written and not yet flushed to the socket.
    writing: AtomicBool,
    /// When the connection started.
    started: std::time::Instant,
    shed: Notify,
    /// Chosen to be closed: not chosen again for the next client.
    shedding: AtomicBool,
}

/// The open connections, oldest first: when every slot is taken, the oldest that is waiting on
/// its client (its last read found nothing) with no request in progress and no response still
/// being written is closed for the new one, so clients that hold connections without using them
/// (slow or idle clients) cannot lock out the others. A client that has sent nothing yet keeps its
/// connection for [`FIRST_BYTES_WITHIN`] whatever else connects: a client that has just connected
/// may not have sent its request yet. (Among hundreds of stalling clients that reconnect, a health
/// check's connection was closed with its response written but not yet flushed, or before its
/// request had arrived, while both counted as waiting.)
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
            waiting_turn: AtomicUsize::new(0),
            waiting: AtomicBool::new(false),
            heard: AtomicBool::new(false),
            writing: AtomicBool::new(false),
            started: std::time::Instant::now(),
            shed: Notify::new(),
            shedding: AtomicBool::new(false),
        });
        self.lock().insert(id, Arc::clone(&connection));
        (id, connection)
    }

    fn remove(&self, id: u64) {
        self.lock().remove(&id);
    }

    /// Closes the oldest connection that is idle ([`Connection::idle`]), or else the oldest whose
    /// request waits its turn to send a body (the newest first kept none: each upload coming in
    /// was the newest when the next client came, 0 of 40 submissions got through a flood of
    /// reconnecting stalled uploads, a probe); whether one was chosen. None is while a slot is
    /// free, or while another chosen is still closing (or finds it may not: then the next look
    /// chooses again): one at a time, for one newcomer. A closing connection frees its slot
    /// before it is unlisted, under this lock.
    fn shed_one(&self, slots: &Semaphore) -> bool {
        let open = self.lock();
        if slots.available_permits() > 0
            || open.values().any(|c| c.shedding.load(Ordering::Acquire))
        {
            return false;
        }
        let chosen = (open.values().find(|c| c.idle()))
            .or_else(|| open.values().find(|c| c.waiting_turn_only()));
        if let Some(connection) = chosen {
            connection.shedding.store(true, Ordering::Release);
            connection.shed.notify_one();
        }
        chosen.is_some()
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, BTreeMap<u64, Arc<Connection>>> {
        self.connections.lock().unwrap_or_else(|e| e.into_inner())
    }
}

impl Connection {
    /// Waiting on its client, with no request in progress and nothing left to write, and it has
    /// heard from it or is older than [`FIRST_BYTES_WITHIN`].
    fn idle(&self) -> bool {
        self.in_progress.load(Ordering::Acquire) == 0
            && !self.writing.load(Ordering::Acquire)
            && self.waiting.load(Ordering::Acquire)
            && (self.heard.load(Ordering::Acquire) || self.started.elapsed() >= FIRST_BYTES_WITHIN)
    }

    /// Its request waits its turn to send a body ([`Waiting`]): nothing of it was read or done.
    fn waiting_turn_only(&self) -> bool {
        let waiting_turn = self.waiting_turn.load(Ordering::Acquire);
        waiting_turn > 0
            && waiting_turn == self.in_progress.load(Ordering::Acquire)
            && !self.writing.load(Ordering::Acquire)
    }
}

/// A request's connection, in the request's extensions: while the request waits its turn to send
/// its body, the connection may be closed for a new client as an idle one is. Uploads that stall
/// hold their connections until their body timeout, and those waiting behind them until their
/// turn: 20,000 of them kept every other client in the backlog (a probe).
#[derive(Clone)]
pub struct RequestConnection(Arc<Connection>);

impl RequestConnection {
    /// The request waits its turn until the guard is dropped.
    pub fn waiting_turn(&self) -> Waiting {
        self.0.waiting_turn.fetch_add(1, Ordering::AcqRel);
        Waiting(Arc::clone(&self.0))
    }
}

/// A request waiting its turn to send its body ([`RequestConnection::waiting_turn`]).
pub struct Waiting(Arc<Connection>);

impl Drop for Waiting {
    fn drop(&mut self) {
        self.0.waiting_turn.fetch_sub(1, Ordering::AcqRel);
    }
}

/// A connection's slot and its listing in [`Open`], given back when its task ends, however it
/// ends, after its socket is closed (the connection, pinned later in the task, is dropped
/// first): the slot before the listing, so that while it still counts as closing no other
/// connection is chosen for the newcomer, who takes the slot.
struct Place {
    open: Arc<Open>,
    id: u64,
    slot: Option<OwnedSemaphorePermit>,
}

impl Drop for Place {
    fn drop(&mut self) {
        drop(self.slot.take());
        self.open.remove(self.id);
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
    /// The response's last bytes may still be in hyper's buffer: the connection counts as writing
    /// until its next flush, so that it is not closed under them.
    fn drop(&mut self) {
        self.0.writing.store(true, Ordering::Release);
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

/// A connection's socket, recording for [`Open`] whether the server waits on its client (a read
/// that found nothing to read sets it, one that read bytes or the end clears it), whether the
/// client has sent anything, and whether written bytes wait for a flush; and failing a write
/// once the client has read none of the response for `write_stall` (hyper then drops the
/// connection): a write that has waited that long while the client took none of the bytes
/// before it ([`Delivery::took_more`]), or one of a trickle the kernel still takes
/// (an event stream's, a few bytes a minute) while none of what it took before has reached the
/// client ([`Delivery`]).
struct Watched {
    stream: TcpStream,
    connection: Arc<Connection>,
    write_stall: Duration,
    /// Runs while a write waits for the client; none while writes go through.
    stalled: Option<Pin<Box<tokio::time::Sleep>>>,
    delivery: Delivery,
}

/// What of the bytes written has reached the client: the kernel takes an event stream's few
/// bytes a minute for as long as its buffers last (about 4 MB on Linux), so a stream whose client
/// read nothing held its place for hours, writes never waiting (found from outside: 64 streams
/// that never read shut every other client out of event streams). The bytes the client's end
/// has taken are those written less those the socket still holds unacknowledged (`SIOCOUTQ`); a
/// client whose buffer is full because it reads nothing takes no more.
struct Delivery {
    /// Bytes written to the socket.
    written: u64,
    /// Bytes the client's end had taken when last looked at.
    taken: u64,
    /// When those bytes last grew, or bytes began to wait (the socket held none when last asked).
    since: tokio::time::Instant,
    /// Whether the socket held bytes unacknowledged when last asked.
    waiting: bool,
    /// When the socket was last asked: at most once a second.
    asked: tokio::time::Instant,
}

impl Delivery {
    fn new() -> Self {
        let now = tokio::time::Instant::now();
        Self {
            written: 0,
            taken: 0,
            since: now,
            waiting: false,
            asked: now,
        }
    }

    /// Whether the client has taken none of the bytes written to `stream` for `stall`, with
    /// some waiting for it (looked at once a second at most; `false` where the platform cannot
    /// tell).
    fn stalled(&mut self, stream: &TcpStream, stall: Duration) -> bool {
        let now = tokio::time::Instant::now();
        if now.duration_since(self.asked) < Duration::from_secs(1) {
            return false;
        }
        self.asked = now;
        let Some(held) = unacknowledged(stream) else {
            return false;
        };
        let taken = self.written.saturating_sub(held);
        let waited_before = std::mem::replace(&mut self.waiting, held > 0);
        // A new wait (after an idle keep-alive, say) starts its own clock.
        if held == 0 || taken > self.taken || !waited_before {
            (self.taken, self.since) = (taken, now);
            return false;
        }
        now.duration_since(self.since) >= stall
    }

    /// Whether the client's end has taken bytes since they were last looked at: a client reading
    /// slowly and steadily. A write that waits for room wakes only once a third of the kernel's
    /// buffer is free (about a megabyte), so at 1 KB/s a write waited far past the body timeout
    /// while the client read all along, and a 17 MB Result was cut after 3-4 MB (an outside
    /// probe). `false` where the platform cannot tell.
    fn took_more(&mut self, stream: &TcpStream) -> bool {
        let Some(held) = unacknowledged(stream) else {
            return false;
        };
        let taken = self.written.saturating_sub(held);
        if taken <= self.taken {
            return false;
        }
        (self.taken, self.since) = (taken, tokio::time::Instant::now());
        true
    }
}

/// The bytes written to `stream` that its peer has not acknowledged yet (`SIOCOUTQ`).
#[cfg(target_os = "linux")]
fn unacknowledged(stream: &TcpStream) -> Option<u64> {
    use std::os::fd::AsRawFd;
    let mut held: libc::c_int = 0;
    // SAFETY: `SIOCOUTQ` (`TIOCOUTQ`) writes one `int` through the pointer, which lives for
    // the call; the descriptor is the stream's own, open while it is borrowed.
    let done = unsafe { libc::ioctl(stream.as_raw_fd(), libc::TIOCOUTQ, &raw mut held) };
    (done == 0).then(|| u64::try_from(held).unwrap_or(0))
}

#[cfg(not(target_os = "linux"))]
fn unacknowledged(_stream: &TcpStream) -> Option<u64> {
    None
}

impl Watched {
    /// `written`, or the error that ends the connection once the client has read none of the
    /// response for `write_stall`.
    fn unless_stalled<T>(
        &mut self,
        cx: &mut Context<'_>,
        written: Poll<std::io::Result<T>>,
    ) -> Poll<std::io::Result<T>> {
        let stall = self.write_stall;
        if written.is_ready() {
            self.stalled = None;
            if !self.delivery.stalled(&self.stream, stall) {
                return written;
            }
        } else {
            loop {
                let stalled = self
                    .stalled
                    .get_or_insert_with(|| Box::pin(tokio::time::sleep(stall)));
                if stalled.as_mut().poll(cx).is_pending() {
                    return Poll::Pending;
                }
                // The wait outlasted the body timeout: a client still reading gets another.
                if !self.delivery.took_more(&self.stream) {
                    break;
                }
                self.stalled = None;
            }
        }
        metrics::counter!(crate::telemetry::CONNECTIONS_STALLED).increment(1);
        Poll::Ready(Err(std::io::Error::new(
            std::io::ErrorKind::TimedOut,
            format!("the client read none of the response for {stall:?}"),
        )))
    }
}

impl AsyncRead for Watched {
    fn poll_read(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<std::io::Result<()>> {
        let before = buf.filled().len();
        let read = Pin::new(&mut self.stream).poll_read(cx, buf);
        if buf.filled().len() > before {
            self.connection.heard.store(true, Ordering::Release);
        }
        let waiting = read.is_pending();
        self.connection.waiting.store(waiting, Ordering::Release);
        read
    }
}

impl AsyncWrite for Watched {
    fn poll_write(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<std::io::Result<usize>> {
        self.connection.writing.store(true, Ordering::Release);
        let written = Pin::new(&mut self.stream).poll_write(cx, buf);
        if let Poll::Ready(Ok(n)) = written {
            self.delivery.written += n as u64;
        }
        self.unless_stalled(cx, written)
    }

    fn poll_write_vectored(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        bufs: &[std::io::IoSlice<'_>],
    ) -> Poll<std::io::Result<usize>> {
        self.connection.writing.store(true, Ordering::Release);
        let written = Pin::new(&mut self.stream).poll_write_vectored(cx, bufs);
        if let Poll::Ready(Ok(n)) = written {
            self.delivery.written += n as u64;
        }
        self.unless_stalled(cx, written)
    }

    fn is_write_vectored(&self) -> bool {
        self.stream.is_write_vectored()
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<std::io::Result<()>> {
        let flushed = Pin::new(&mut self.stream).poll_flush(cx);
        if flushed.is_ready() {
            self.connection.writing.store(false, Ordering::Release);
        }
        self.unless_stalled(cx, flushed)
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<std::io::Result<()>> {
        Pin::new(&mut self.stream).poll_shutdown(cx)
    }
}

/// At the limit: closes a connection that waits on its client ([`Open`]) and takes the slot that
/// frees. While none can be closed (every open connection busy, or not read from yet),
/// the new client waits for a slot, looking again every [`SHED_RETRY`]. `None` once `stopping`.
async fn make_room(
    open: &Open,
    slots: &Arc<Semaphore>,
    stopping: &mut watch::Receiver<bool>,
) -> Option<OwnedSemaphorePermit> {
    loop {
        if let Ok(slot) = Arc::clone(slots).try_acquire_owned() {
            return Some(slot);
        }
        if open.shed_one(slots) {
            metrics::counter!(crate::telemetry::CONNECTIONS_SHED).increment(1);
        }
        tokio::select! {
            // A slot handed over is taken, not dropped for the sleep's turn (and another closed).
            biased;
            slot = Arc::clone(slots).acquire_owned() => {
                return Some(slot.expect("the semaphore is never closed"));
            }
            () = tokio::time::sleep(SHED_RETRY) => {}
            _ = stopping.wait_for(|stop| *stop) => return None,
        }
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
        .header_read_timeout(limits.header_timeout)
        .max_buf_size(MAX_REQUEST_HEAD_BYTES);
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
        // At the limit, the oldest connection waiting on its client makes room; while none can,
        // the new client waits for a slot (and later ones in the kernel's backlog, not in our
        // memory: one accepted socket at most is held beyond the limit).
        let slot = match Arc::clone(&slots).try_acquire_owned() {
            Ok(slot) => slot,
            Err(_) => match make_room(&open, &slots, &mut stopping).await {
                Some(slot) => slot,
                None => break,
            },
        };
        let _ = stream.set_nodelay(true);
        let (id, state) = open.add();
        let inner = TowerToHyperService::new(router.clone());
        let counting = Arc::clone(&state);
        let service = service_fn(move |mut request: hyper::Request<hyper::body::Incoming>| {
            let in_progress = InProgress::enter(&counting);
            let on = RequestConnection(Arc::clone(&counting));
            request.extensions_mut().insert(on);
            let response = inner.call(request);
            async move {
                let response = response.await?;
                Ok::<_, std::convert::Infallible>(response.map(|body| Counted {
                    body,
                    _in_progress: in_progress,
                }))
            }
        });
        let watched = Watched {
            stream,
            connection: Arc::clone(&state),
            write_stall: limits.write_stall,
            stalled: None,
            delivery: Delivery::new(),
        };
        let connection = http.serve_connection(TokioIo::new(watched), service);
        let mut stop = stopping.clone();
        let place = Place {
            open: Arc::clone(&open),
            id,
            slot: Some(slot),
        };
        connections.spawn(async move {
            let _place = place;
            tokio::pin!(connection);
            let drain = loop {
                tokio::select! {
                    // The connection first: a request whose bytes or turn came is seen to move
                    // on (they move on only in this task) before a choice to close is looked at.
                    biased;
                    _ = connection.as_mut() => break false,
                    // Dropping the connection closes its socket; not once a request came, or an
                    // upload's turn, after it was chosen.
                    () = state.shed.notified() => {
                        if state.idle() || state.waiting_turn_only() {
                            break false;
                        }
                        state.shedding.store(false, Ordering::Release);
                    }
                    _ = stop.wait_for(|stop| *stop) => break true,
                }
            };
            if drain {
                connection.as_mut().graceful_shutdown();
                let _ = connection.await;
            }
        });
    }
    drop(listener);
    drain(connections).await;
}

/// Responses still being sent get DRAIN to end, then are cut off: a client reading a large
/// Result at 300 kB/s held a SIGTERM for its whole body timeout (30 s, silently), past the 30 s
/// a container manager grants before it kills the process, workers' hand-back and all.
async fn drain(mut connections: JoinSet<()>) {
    let sending = connections.len();
    if sending > 0 {
        tracing::info!(
            connections = sending,
            "waiting at most {} s for the responses still being sent",
            DRAIN.as_secs()
        );
    }
    let drained = tokio::time::timeout(DRAIN, async {
        while connections.join_next().await.is_some() {}
    });
    if drained.await.is_err() {
        tracing::warn!(
            connections = connections.len(),
            "responses still being sent were cut off at shutdown"
        );
        connections.shutdown().await;
    }
}

/// How long a stopping server lets the responses it is sending end.
const DRAIN: Duration = Duration::from_secs(10);

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

    /// At the limit the oldest connection that waits on its client goes, once, and one at a time:
    /// not one the server has not read from yet, nor one with a request in progress or a response
    /// not yet flushed, nor a new one whose client has sent nothing yet; after them, the oldest
    /// whose upload waits its turn, not once its turn came; and none while a slot is free.
    #[test]
    fn the_oldest_connection_waiting_on_its_client_is_shed_once() {
        let open = Arc::new(Open::default());
        let full = Semaphore::new(0);
        let (_, unread) = open.add();
        let (_, busy) = open.add();
        let (_, queued) = open.add();
        let (_, queued_later) = open.add();
        let (_, flushing) = open.add();
        let (silent_id, silent) = open.add();
        let (stalled_id, stalled) = open.add();
        let (newer_id, newer) = open.add();
        for c in [
            &busy,
            &queued,
            &queued_later,
            &flushing,
            &silent,
            &stalled,
            &newer,
        ] {
            c.waiting.store(true, Ordering::Release);
        }
        for c in [&busy, &queued, &queued_later, &flushing, &stalled, &newer] {
            c.heard.store(true, Ordering::Release);
        }
        let _request = InProgress::enter(&busy);
        let _upload = InProgress::enter(&queued);
        let turn = RequestConnection(Arc::clone(&queued)).waiting_turn();
        let _later = InProgress::enter(&queued_later);
        let later_turn = RequestConnection(Arc::clone(&queued_later)).waiting_turn();
        flushing.writing.store(true, Ordering::Release);
        assert!(!open.shed_one(&Semaphore::new(1)), "a slot is free");
        assert!(open.shed_one(&full));
        assert!(stalled.shedding.load(Ordering::Acquire));
        assert!(!open.shed_one(&full), "one at a time");
        open.remove(stalled_id);
        assert!(open.shed_one(&full), "the next client gets the next one");
        assert!(newer.shedding.load(Ordering::Acquire));
        open.remove(newer_id);
        assert!(open.shed_one(&full), "the first upload waiting its turn");
        assert!(queued.shedding.load(Ordering::Acquire));
        queued.shedding.store(false, Ordering::Release);
        drop(turn);
        assert!(open.shed_one(&full), "then the one after it");
        assert!(queued_later.shedding.load(Ordering::Acquire));
        assert!(
            !silent.shedding.load(Ordering::Acquire),
            "a new client has a moment to send"
        );
        queued_later.shedding.store(false, Ordering::Release);
        drop(later_turn);
        assert!(!queued.waiting_turn_only(), "its turn came: it stays");
        assert!(!open.shed_one(&full));
        std::thread::sleep(FIRST_BYTES_WITHIN + Duration::from_millis(10));
        assert!(open.shed_one(&full));
        assert!(silent.shedding.load(Ordering::Acquire));
        open.remove(silent_id);
        assert!(!open.shed_one(&full));
        for c in [&unread, &busy, &queued, &queued_later, &flushing] {
            assert!(!c.shedding.load(Ordering::Acquire));
        }
    }

    #[test]
    fn connections_stay_below_the_open_file_limit() {
        let limits = ConnectionLimits::new(
            Some(usize::MAX),
            Duration::from_secs(1),
            Duration::from_secs(1),
        );
        if let Some(limit) = open_file_limit() {
            assert!((limits.max_connections as u64) < limit.max(2));
        }
        let asked = ConnectionLimits::new(Some(5), Duration::from_secs(1), Duration::from_secs(1));
        assert_eq!(asked.max_connections, 5);
    }
}
