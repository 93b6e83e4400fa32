//! The store, written once ([`Store`]), and the few things its two databases do differently
//! ([`Backend`]): how connections are pooled and transactions begun, the locks each takes, the
//! clock, and what readiness checks beyond a write. Everything else (the queue, results,
//! schedules) is one body of SQL in `queue.rs`, `results.rs` and `schedules.rs`.

use super::postgres::PgBackend;
use super::rows::{Dialect, count_from_sql};
use super::sql::{Conn, Pooled, Sql, Tx};
use super::sqlite::SqliteBackend;
use super::{QueueEvent, StoreError, StoreResult};
use crate::domain::{CursorKey, JobId, QueueBound, QueuedJob};
use tokio::sync::broadcast;

/// The store over either database.
pub struct Store {
    pub(crate) backend: Backend,
    /// Seals listing cursors: from the secret the database's migration drew.
    cursor_key: CursorKey,
}

/// SQLite (embedded, one writer connection) or PostgreSQL (a pool shared by many instances).
pub(crate) enum Backend {
    Sqlite(SqliteBackend),
    Postgres(PgBackend),
}

impl Backend {
    fn readers(&self) -> Conn<'_> {
        match self {
            Backend::Sqlite(sqlite) => Conn::SqlitePool(&sqlite.readers),
            Backend::Postgres(postgres) => Conn::PostgresPool(&postgres.pool),
        }
    }

    /// Every pool, to ask whether the database answers at all: SQLite's readers and its writer
    /// (as opened, whatever its file now), PostgreSQL's one pool.
    fn pools(&self) -> Vec<Conn<'_>> {
        match self {
            Backend::Sqlite(sqlite) => vec![
                Conn::SqlitePool(&sqlite.readers),
                Conn::SqlitePool(sqlite.writer_as_opened()),
            ],
            Backend::Postgres(postgres) => vec![Conn::PostgresPool(&postgres.pool)],
        }
    }
}

impl Store {
    /// Opens the database a URL names, migrating it: `sqlite:` or `postgres:` (`postgresql:`).
    pub async fn open(url: &str, connections: u32) -> StoreResult<Self> {
        // Only the scheme is ever repeated back: the rest of a URL may hold a password.
        let scheme = url.split_once(':').map_or(url, |(scheme, _)| scheme);
        match scheme {
            "sqlite" => Self::on(Backend::Sqlite(SqliteBackend::open(url).await?)).await,
            "postgres" | "postgresql" => {
                super::postgres::while_starting(url, || async {
                    Self::on(Backend::Postgres(PgBackend::open(url, connections).await?)).await
                })
                .await
            }
            _ => {
                let scheme = scheme.chars().take(32).collect();
                Err(StoreError::UnsupportedUrl(scheme))
            }
        }
    }

    /// The store on `backend`, opened and migrated: its cursors' key read, shards filled in for
    /// jobs queued before there were any.
    async fn on(backend: Backend) -> StoreResult<Self> {
        let secret = Sql::new("SELECT value FROM secrets WHERE name = 'cursor'")
            .fetch_one(backend.readers())
            .await?
            .text("value")?;
        let store = Store {
            backend,
            cursor_key: CursorKey::from_secret(&secret),
        };
        store.backfill_shards().await?;
        Ok(store)
    }

    /// The key that seals this database's listing cursors, the same on every instance.
    pub fn cursor_key(&self) -> &CursorKey {
        &self.cursor_key
    }

    pub(crate) fn dialect(&self) -> &'static Dialect {
        match &self.backend {
            Backend::Sqlite(_) => &super::sqlite::DIALECT,
            Backend::Postgres(_) => &super::postgres::DIALECT,
        }
    }

    /// Where writes go, once SQLite's file is still the one opened (a write to a deleted or
    /// replaced file is refused, never acknowledged).
    pub(crate) fn writer(&self) -> StoreResult<Conn<'_>> {
        Ok(match &self.backend {
            Backend::Sqlite(sqlite) => Conn::SqlitePool(sqlite.writer()?),
            Backend::Postgres(postgres) => Conn::PostgresPool(&postgres.pool),
        })
    }

    /// SQLite's write-ahead log checkpointed whole into the database's file
    /// ([`super::Store::checkpoint`]). A checkpoint that another process's lock cut short
    /// answers, rather than fails: that is an error here (it passed for done, found from outside).
    pub(crate) async fn fold_log(&self) -> StoreResult<()> {
        if let Backend::Sqlite(sqlite) = &self.backend {
            let row = sqlx::query("PRAGMA wal_checkpoint(FULL)")
                .fetch_one(sqlite.writer()?)
                .await?;
            let busy: i64 = sqlx::Row::try_get(&row, 0)?;
            if busy != 0 {
                return Err(StoreError::NotReady(
                    "another process holds the database: its log is not folded whole".to_owned(),
                ));
            }
        }
        Ok(())
    }

    /// PostgreSQL's own reason it gives no connection ([`super::Store::why_unreachable`]);
    /// SQLite, embedded, has none to give.
    pub(crate) async fn why_no_connection(&self) -> Option<String> {
        match &self.backend {
            Backend::Postgres(postgres) => postgres.why_unreachable().await,
            Backend::Sqlite(_) => None,
        }
    }

    /// Where reads go: SQLite's read-only connections, which never wait for the writer.
    pub(crate) fn readers(&self) -> Conn<'_> {
        self.backend.readers()
    }

    pub(crate) fn pools(&self) -> Vec<Conn<'_>> {
        self.backend.pools()
    }

    /// One reading connection, for statements that must see the same database.
    pub(crate) async fn reader(&self) -> StoreResult<Pooled> {
        Ok(match &self.backend {
            Backend::Sqlite(sqlite) => Pooled::Sqlite(sqlite.readers.acquire().await?),
            Backend::Postgres(postgres) => Pooled::Postgres(postgres.pool.acquire().await?),
        })
    }

    /// A write transaction.
    pub(crate) async fn begin(&self) -> StoreResult<Tx> {
        Ok(match &self.backend {
            Backend::Sqlite(sqlite) => Tx::Sqlite(sqlite.writer()?.begin().await?),
            Backend::Postgres(postgres) => Tx::Postgres(postgres.pool.begin().await?),
        })
    }

    /// A write transaction that reads before it writes. SQLite takes the write lock first, so
    /// that instances sharing the file wait on `busy_timeout` rather than fail to upgrade a read;
    /// PostgreSQL locks the rows it reads ([`Dialect::claim`]).
    pub(crate) async fn begin_reading_first(&self) -> StoreResult<Tx> {
        Ok(match &self.backend {
            Backend::Sqlite(sqlite) => {
                Tx::Sqlite(sqlite.writer()?.begin_with("BEGIN IMMEDIATE").await?)
            }
            Backend::Postgres(postgres) => Tx::Postgres(postgres.pool.begin().await?),
        })
    }

    /// A write transaction, reading first, whose commit does not wait for the disk: for writes a
    /// power cut may undo without losing anything acknowledged, because the queue does their work
    /// again to the same bits (a claim, a lease renewed, a group's accumulators). The next commit
    /// that does wait for the disk takes them with it: both databases write their log in order.
    /// A crash of the process alone loses nothing, as the operating system holds what was written.
    /// SQLite sets `synchronous = NORMAL` for it; its writer goes back to `FULL` when released
    /// ([`super::sqlite`]). PostgreSQL turns `synchronous_commit` off for the transaction alone.
    pub(crate) async fn begin_redoable(&self) -> StoreResult<Tx> {
        Ok(match &self.backend {
            Backend::Sqlite(sqlite) => Tx::Sqlite(
                sqlite
                    .writer()?
                    .begin_with("PRAGMA synchronous = NORMAL; BEGIN IMMEDIATE")
                    .await?,
            ),
            Backend::Postgres(postgres) => Tx::Postgres(
                postgres
                    .pool
                    .begin_with("BEGIN; SET LOCAL synchronous_commit = off")
                    .await?,
            ),
        })
    }

    /// Whether the database runs write transactions side by side (PostgreSQL), not one after
    /// another (SQLite's one writer).
    pub(crate) fn writes_side_by_side(&self) -> bool {
        matches!(self.backend, Backend::Postgres(_))
    }

    /// Refuses to acknowledge a write that went into a SQLite file no longer at the database's
    /// path: what it wrote is out of every later reader's reach.
    pub(crate) fn acknowledge(&self) -> StoreResult<()> {
        match &self.backend {
            Backend::Sqlite(sqlite) => sqlite.acknowledge(),
            Backend::Postgres(_) => Ok(()),
        }
    }

    /// Serialises, until the transaction ends, every transaction that names the same `key`:
    /// two instances retrying one request at once. SQLite's one writer already does.
    pub(crate) async fn lock(&self, tx: &mut Tx, key: String) -> StoreResult<()> {
        if let Backend::Postgres(_) = &self.backend {
            Sql::new("SELECT pg_advisory_xact_lock(hashtextextended($1, 0))")
                .bind(key)
                .execute(tx)
                .await?;
        }
        Ok(())
    }

    /// Inserts a queued job with its first shards unless the queue or the owner's share of it
    /// is full ([`QueueBound`]), in `tx`: the count and the insert cannot race. Below the
    /// bound's free disk, the job is refused as the database not being ready (503); an owner
    /// whose jobs store its quota or more gets [`StoreError::OverQuota`]. The quota is read
    /// before the insert, unlocked: submissions at the same moment may all pass it, and jobs
    /// already queued store their Results after it, so an owner goes over by at most what its
    /// share of the queue stores.
    pub(crate) async fn insert_queued(
        &self,
        tx: &mut Tx,
        job: &QueuedJob,
        bound: QueueBound,
    ) -> StoreResult<bool> {
        self.check_disk(bound.min_free_disk_bytes).await?;
        if let Some(quota) = bound.stored_per_owner {
            let used = Sql::new(
                "SELECT CAST(COALESCE(SUM(stored_bytes), 0) AS BIGINT) AS used \
                 FROM jobs WHERE owner = $1",
            )
            .bind(job.owner.as_str())
            .fetch_one(&mut *tx)
            .await?;
            let used = count_from_sql(&used, "used")?;
            if used >= quota {
                return Err(StoreError::OverQuota { used, quota });
            }
        }
        match &self.backend {
            Backend::Sqlite(_) => super::sqlite::insert_queued(tx, job, bound).await,
            Backend::Postgres(_) => super::postgres::insert_queued(tx, job, bound).await,
        }
    }

    /// Room for a write of `bytes` (SQLite's disk; PostgreSQL's is its server's to watch).
    pub(crate) async fn check_room(&self, bytes: u64) -> StoreResult<()> {
        match &self.backend {
            Backend::Sqlite(sqlite) => sqlite.check_room(bytes).await,
            Backend::Postgres(_) => Ok(()),
        }
    }

    /// What readiness checks before its write: SQLite's file and the disk beside it.
    pub(crate) async fn check_disk(&self, min_free_bytes: u64) -> StoreResult<()> {
        match &self.backend {
            Backend::Sqlite(sqlite) => sqlite.check_disk(min_free_bytes).await,
            // PostgreSQL's disk is its server's to watch.
            Backend::Postgres(_) => Ok(()),
        }
    }

    pub(crate) fn subscribe(&self) -> Option<broadcast::Receiver<QueueEvent>> {
        match &self.backend {
            Backend::Sqlite(_) => None,
            Backend::Postgres(postgres) => Some(postgres.events.subscribe()),
        }
    }

    /// [`super::Store::ends`]: PostgreSQL's announcements of every instance's ends, or the ends
    /// of jobs this process wrote to SQLite.
    pub(crate) fn subscribe_ends(&self) -> broadcast::Receiver<QueueEvent> {
        match &self.backend {
            Backend::Sqlite(sqlite) => sqlite.ends.subscribe(),
            Backend::Postgres(postgres) => postgres.ends.subscribe(),
        }
    }

    /// Tells this process's waiters that job `id` ended (or is gone), once its transaction
    /// committed. PostgreSQL's trigger announces it to every instance already.
    pub(crate) fn ended(&self, id: &JobId) {
        if let Backend::Sqlite(sqlite) = &self.backend {
            // No receiver is no waiter: nothing to tell.
            let _ = sqlite.ends.send(QueueEvent::Changed(id.clone()));
        }
    }
}
