//! The PostgreSQL backend, for instances on several machines sharing one database: a connection
//! pool, row locks instead of SQLite's single writer (`FOR UPDATE SKIP LOCKED` lets workers claim
//! shards side by side without waiting on each other), and an advisory lock around the queue bound,
//! so that concurrent submissions cannot overshoot it. Every change to a job is announced
//! (LISTEN/NOTIFY), so idle workers and progress streams on any machine wake at once. The SQL is the
//! store's one body; what is PostgreSQL's own is here.

use super::StoreError;
use super::rows::{
    Dialect, bind_queued_job, claim_next, count_to_sql, fenced_shard, insert_job, insert_shards,
};
use super::sql::{Sql, Tx};
use super::{QueueEvent, StoreResult, migrations};
use crate::domain::{JobId, QueueBound, QueuedJob};
use sqlx::Connection;
use sqlx::postgres::{PgConnectOptions, PgConnection, PgListener, PgPool, PgPoolOptions};
use std::str::FromStr;
use std::time::Duration;
use tokio::sync::broadcast;
use tokio::task::AbortHandle;

pub(crate) struct PgBackend {
    pub(crate) pool: PgPool,
    /// Every announcement but ends (`queued`, a job's id).
    pub(crate) events: broadcast::Sender<QueueEvent>,
    /// Ends alone (`ended <id>`, `migrations/postgres/0015`), as [`QueueEvent::Changed`].
    pub(crate) ends: broadcast::Sender<QueueEvent>,
    /// The task that passes announcements on: it holds a connection of the pool and the pool
    /// itself, so it ends with the store, or neither would ever be closed.
    announcements: AbortHandle,
    /// Where the database is, to ask it why the pool reaches it not ([`PgBackend::why_unreachable`]).
    url: String,
    /// When that was last asked.
    asked_why: std::sync::Mutex<Option<std::time::Instant>>,
}

impl Drop for PgBackend {
    fn drop(&mut self) {
        self.announcements.abort();
        let pool = self.pool.clone();
        if let Ok(runtime) = tokio::runtime::Handle::try_current() {
            runtime.spawn(async move { pool.close().await });
        }
    }
}

/// The channel the schema's trigger announces every job change on (`migrations/postgres/0003`).
const JOB_CHANNEL: &str = "bouncewear_jobs";

/// How long opening the store waits for the database's first connection.
const STARTUP_WAIT: Duration = Duration::from_secs(30);

/// A pooled connection idle this long is closed: a node that stopped working hands its slots
/// back to PostgreSQL for the others.
const IDLE_CONNECTION: Duration = Duration::from_secs(60);

/// A session idle inside a transaction this long is ended by PostgreSQL, and its row locks with
/// it. Between its statements every transaction of the store waits on nothing but the database
/// (no computing, no other lock of the process), so such a session is a process frozen or cut off
/// from the database. Its locks made every claim skip its shard for as long as it stayed so, long
/// past its lease (an outside check: a worker stopped mid-store held its group 30 s and more past
/// a 3 s lease, and one cut off until TCP gave up, two hours by default), and a cancel waited on
/// them until its 503. Now its shard is claimed again once the lease expires, or after this.
pub(crate) const IDLE_IN_TRANSACTION: &str = "5s";

/// The advisory lock every insert into the queue takes, so that counting the queued jobs and
/// inserting one cannot interleave with another submission.
const QUEUE_LOCK: i64 = 0x626f_756e_6365; // "bounce"

/// Why the pool has no connection to the database at `url`, which it does not say (refused, no
/// slots left, a wrong password): a connection of its own, tried once.
async fn why_no_connection(url: &str) -> String {
    match tokio::time::timeout(super::DATABASE_WAIT, PgConnection::connect(url)).await {
        Ok(Ok(_)) => "it answers now".to_owned(),
        Ok(Err(error)) => error.to_string(),
        Err(_) => format!("no answer within {} s", super::DATABASE_WAIT.as_secs_f64()),
    }
}

/// The pause between two tries to open the store while the database does not answer.
const STARTUP_RETRY: Duration = Duration::from_millis(500);

/// Opens the store on the database at `url` by `attempt`, tried again for up to
/// [`STARTUP_WAIT`] while the database does not answer yet or goes away meanwhile (restarted:
/// its connections reset or ended by its administrator, [`StoreError::is_unreachable`]): a
/// process started as PostgreSQL restarted exited within 2 s (found from outside), at its
/// migrations or at its first reads after them. Any other error ends it at once (a wrong
/// password, a database that does not exist).
pub(crate) async fn while_starting<T, F>(
    url: &str,
    mut attempt: impl FnMut() -> F,
) -> StoreResult<T>
where
    F: Future<Output = StoreResult<T>>,
{
    let started = std::time::Instant::now();
    loop {
        let error = match attempt().await {
            Ok(opened) => return Ok(opened),
            Err(error) if error.is_unreachable() => error,
            Err(error) => return Err(error),
        };
        let why = match error {
            StoreError::Database(sqlx::Error::PoolTimedOut) => why_no_connection(url).await,
            other => other.to_string(),
        };
        if started.elapsed() >= STARTUP_WAIT {
            return Err(StoreError::NotReady(format!(
                "no connection to the database within {} s: {why}",
                STARTUP_WAIT.as_secs()
            )));
        }
        let server = PgConnectOptions::from_str(url)
            .map(|o| format!("{}:{}", o.get_host(), o.get_port()))
            .unwrap_or_default();
        tracing::warn!(%why, %server, "the database has not answered yet; trying again");
        // A refused connection comes back at once: not a busy loop meanwhile.
        tokio::time::sleep(STARTUP_RETRY).await;
    }
}

/// The pool's first connection, the database migrated on it, and a listener to the queue's
/// announcements: what opening the store needs of the database.
async fn migrated_listener(pool: &PgPool) -> StoreResult<PgListener> {
    let mut connection = pool.acquire().await?;
    // On the connection just had: on a server at max_connections another might not come.
    migrations::POSTGRES.run(&mut *connection).await?;
    drop(connection);
    let mut listener = PgListener::connect_with(pool).await?;
    listener.listen(JOB_CHANNEL).await?;
    Ok(listener)
}

impl PgBackend {
    /// Connects to the database at `url` and migrates it (concurrent instances wait for each
    /// other: sqlx takes an advisory lock around migrations), once: [`while_starting`] tries
    /// again while the database is out of reach.
    #[tracing::instrument(skip_all)]
    pub(crate) async fn open(url: &str, connections: u32) -> StoreResult<Self> {
        let options = PgConnectOptions::from_str(url)?
            .options([("idle_in_transaction_session_timeout", IDLE_IN_TRANSACTION)]);
        let pool = PgPoolOptions::new()
            .max_connections(connections)
            .idle_timeout(IDLE_CONNECTION)
            // During an outage a request gets its 503 within this, not after the pool's 30 s.
            .acquire_timeout(super::DATABASE_WAIT)
            .connect_lazy_with(options);
        let listener = migrated_listener(&pool).await?;
        let (events, ends) = (broadcast::channel(1024).0, broadcast::channel(1024).0);
        let announcements = tokio::spawn(forward_announcements(
            listener,
            events.clone(),
            ends.clone(),
        ));
        Ok(Self {
            pool,
            events,
            ends,
            announcements: announcements.abort_handle(),
            url: url.to_owned(),
            asked_why: std::sync::Mutex::new(None),
        })
    }

    /// Why the pool reaches the database not, from a connection of its own ([`why_no_connection`]),
    /// at most once every [`WHY_INTERVAL`]: while the database refuses, every request and claim
    /// would otherwise knock too.
    pub(crate) async fn why_unreachable(&self) -> Option<String> {
        {
            let mut asked = self.asked_why.lock().unwrap_or_else(|e| e.into_inner());
            if asked.is_some_and(|at| at.elapsed() < WHY_INTERVAL) {
                return None;
            }
            *asked = Some(std::time::Instant::now());
        }
        Some(why_no_connection(&self.url).await)
    }
}

/// How often [`PgBackend::why_unreachable`] asks the database.
const WHY_INTERVAL: Duration = Duration::from_secs(10);

/// Passes the database's announcements on to this process's subscribers: a job's end to `ends`,
/// the rest to `events`. A lost connection is re-established by the listener; what was announced
/// meanwhile is missed, which polling covers.
async fn forward_announcements(
    mut listener: PgListener,
    events: broadcast::Sender<QueueEvent>,
    ends: broadcast::Sender<QueueEvent>,
) {
    loop {
        match listener.recv().await {
            Ok(notification) => {
                let (to, event) = match notification.payload() {
                    "queued" => (&events, QueueEvent::Queued),
                    payload => match payload.strip_prefix("ended ") {
                        Some(id) => (&ends, QueueEvent::Changed(JobId::from(id))),
                        None => (&events, QueueEvent::Changed(JobId::from(payload))),
                    },
                };
                // No subscriber right now is fine: nobody is waiting.
                let _ = to.send(event);
            }
            Err(error) => {
                tracing::warn!(%error, "listening for job announcements failed; polling meanwhile");
                tokio::time::sleep(Duration::from_secs(1)).await;
            }
        }
    }
}

pub(crate) static DIALECT: Dialect = Dialect {
    now: "SELECT (EXTRACT(EPOCH FROM clock_timestamp()) * 1000)::BIGINT AS now",
    holds: concat!(
        "SELECT 1 AS held FROM jobs WHERE id = $1 AND status = 'running' AND EXISTS (SELECT 1 FROM shards WHERE ",
        fenced_shard!(),
        ") FOR SHARE"
    ),
    claim: claim_next!(
        "(job_id, batch, grp) = (SELECT s.job_id, s.batch, s.grp",
        "jobs j",
        " FOR UPDATE OF s SKIP LOCKED"
    ),
    lock_job: Some("SELECT 1 AS locked FROM jobs WHERE id = $1 FOR NO KEY UPDATE"),
    migrator: &migrations::POSTGRES,
};

/// Inserts a queued job with its first shards unless the queue or the owner's share of it is
/// full. The rows go in first; the queue lock is taken only to count, and held until the
/// transaction ends, so that submissions wait on each other for one count and a commit rather
/// than for each other's inserts.
pub(crate) async fn insert_queued(
    tx: &mut Tx,
    job: &QueuedJob,
    bound: QueueBound,
) -> StoreResult<bool> {
    bind_queued_job(Sql::new(insert_job!("")), job)?
        .execute(&mut *tx)
        .await?;
    insert_shards(tx, &job.id, &job.shards).await?;
    Sql::new("SELECT pg_advisory_xact_lock($1)")
        .bind(QUEUE_LOCK)
        .execute(&mut *tx)
        .await?;
    // The counts include the job just inserted.
    let within = Sql::new(
        "SELECT (SELECT COUNT(*) FROM jobs WHERE status IN ('queued', 'running')) <= $1 \
            AND (SELECT COUNT(*) FROM jobs WHERE status IN ('queued', 'running') AND owner = $2) <= $3 AS within",
    )
    .bind(count_to_sql(bound.total))
    .bind(job.owner.as_str())
    .bind(count_to_sql(bound.per_owner))
    .fetch_one(&mut *tx)
    .await?;
    Ok(within.flag("within")?)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::{AtomicU32, Ordering};

    /// Opening goes on through the database being out of reach (its connections reset while it
    /// restarts) and stops at once at any other error, which waiting would not mend.
    #[tokio::test]
    async fn opening_tries_again_only_while_the_database_is_out_of_reach() {
        let tries = AtomicU32::new(0);
        let url = "postgres://127.0.0.1:1/none";
        let opened = while_starting(url, || async {
            match tries.fetch_add(1, Ordering::Relaxed) {
                0 | 1 => Err(StoreError::Database(sqlx::Error::Io(
                    std::io::ErrorKind::ConnectionReset.into(),
                ))),
                _ => Ok("open"),
            }
        });
        assert_eq!(opened.await.unwrap(), "open");
        assert_eq!(tries.load(Ordering::Relaxed), 3);
        let refused = while_starting(url, || async {
            tries.fetch_add(1, Ordering::Relaxed);
            Err::<(), _>(StoreError::Database(sqlx::Error::RowNotFound))
        });
        assert!(matches!(
            refused.await,
            Err(StoreError::Database(sqlx::Error::RowNotFound))
        ));
        assert_eq!(tries.load(Ordering::Relaxed), 4, "tried once");
    }
}
