//! The SQLite backend: WAL, foreign keys, `synchronous = FULL` (a submitted job survives a crash or
//! a power cut once its 202 is sent; only writes the queue can redo do not wait for the disk, see
//! [`super::Store::begin_redoable`]), one writer connection (writes never race for the lock
//! inside the process, and every write transaction starts with a write, so instances sharing the
//! file wait on `busy_timeout` instead of failing with "database is locked"), and a pool of
//! readers. The SQL is the store's one body; what is SQLite's own is here.

use super::rows::{
    Dialect, bind_queued_job, claim_next, count_to_sql, fenced_shard, insert_job, insert_shards,
    seed_to_sql, spec_from_json,
};
use super::sql::{Sql, Tx};
use super::{SQLITE_BUSY, SQLITE_NOTADB, StoreError, StoreResult, migrations, sqlite_code};
use crate::domain::{QueueBound, QueuedJob};
use sqlx::sqlite::{
    SqliteConnectOptions, SqliteJournalMode, SqlitePool, SqlitePoolOptions, SqliteSynchronous,
};
use sqlx::{Connection, Row};
use std::ffi::CString;
use std::mem::MaybeUninit;
use std::os::unix::ffi::OsStrExt;
use std::os::unix::fs::MetadataExt;
use std::path::{Path, PathBuf};
use std::str::FromStr;
use std::time::Duration;

pub(crate) struct SqliteBackend {
    writer: SqlitePool,
    pub(crate) readers: SqlitePool,
    /// The file opened; none for an in-memory database.
    file: Option<DatabaseFile>,
    /// The ends of jobs this process wrote ([`super::Store::ended`]): SQLite announces
    /// nothing itself.
    pub(crate) ends: tokio::sync::broadcast::Sender<super::QueueEvent>,
}

/// Connects as `connect` does, again while SQLite answers busy, for ten seconds at most: two
/// processes opening a new file together both turn it to WAL, and SQLite refuses one at once
/// rather than wait for it (no busy handler runs there): "database is locked" stopped one worker
/// of 13 pairs in 100 started together (found from outside).
async fn unbusy<F>(connect: impl Fn() -> F) -> Result<SqlitePool, sqlx::Error>
where
    F: Future<Output = Result<SqlitePool, sqlx::Error>>,
{
    let started = std::time::Instant::now();
    loop {
        match connect().await {
            Err(sqlx::Error::Database(error))
                if sqlite_code(error.as_ref()) == Some(SQLITE_BUSY)
                    && started.elapsed() < Duration::from_secs(10) =>
            {
                tokio::time::sleep(Duration::from_millis(20)).await;
            }
            done => return done,
        }
    }
}

/// Runs the migrations the database lacks. SQLite's migrator takes no lock: two processes
/// opening a new database together (`serve` and `worker` started at once) both ran a migration,
/// and the later one failed on what the earlier had made ("table jobs already exists", found from
/// outside). Its transaction rolled back; while another process has recorded a migration since
/// the run began, the run is tried again, and finds that migration made. A migration that fails
/// while nobody else migrates fails at once.
async fn migrate(writer: &SqlitePool) -> Result<(), sqlx::migrate::MigrateError> {
    let applied = async || -> i64 {
        let count = sqlx::query_scalar("SELECT COUNT(*) FROM _sqlx_migrations");
        count.fetch_one(writer).await.unwrap_or(0)
    };
    loop {
        let before = applied().await;
        match migrations::SQLITE.run(writer).await {
            // A migration's statements, or its row in `_sqlx_migrations` (a statement that
            // changed nothing, then "UNIQUE constraint failed").
            Err(
                error @ (sqlx::migrate::MigrateError::ExecuteMigration(..)
                | sqlx::migrate::MigrateError::Execute(_)),
            ) if applied().await > before => {
                tracing::info!(%error, "another process migrated the database meanwhile: trying again");
                tokio::time::sleep(Duration::from_millis(50)).await;
            }
            done => return done,
        }
    }
}

/// Refuses a file with tables and no record of bouncewear's migrations (no `_sqlx_migrations`, or
/// one that records other migrations than bouncewear's first): an operator's slip
/// (`--database sqlite://app.db`) added bouncewear's tables to another application's file
/// without a word (a probe). Read on a connection of its own, read-only, that leaves the file
/// as it was. Processes opening a new file together see `_sqlx_migrations` before any table the
/// migrations make: sqlx creates it first. A file that is no database is left to the writer to
/// name.
async fn others_tables(options: SqliteConnectOptions, file: &str) -> StoreResult<()> {
    use sqlx::Connection;
    let Ok(mut connection) = sqlx::SqliteConnection::connect_with(&options).await else {
        return Ok(());
    };
    let tables: Result<Vec<String>, _> = sqlx::query_scalar(
        "SELECT name FROM sqlite_master WHERE type = 'table' \
         AND name NOT LIKE 'sqlite!_%' ESCAPE '!' ORDER BY name",
    )
    .fetch_all(&mut connection)
    .await;
    // Another application's sqlx migrations record other versions: ours start with `1 jobs`
    // (none recorded yet: a process migrating the new file right now).
    let ours = sqlx::query_scalar(
        "SELECT COUNT(*) = 0 OR SUM(version = 1 AND description = 'jobs') > 0 \
         FROM _sqlx_migrations",
    )
    .fetch_one(&mut connection)
    .await
    .unwrap_or(false);
    let _ = connection.close().await;
    match tables {
        Ok(tables) if !tables.is_empty() && !ours => Err(StoreError::Foreign {
            file: file.to_owned(),
            tables: tables.join(", "),
        }),
        _ => Ok(()),
    }
}

impl SqliteBackend {
    /// Opens (creating if missing) and migrates the database at `url`.
    #[tracing::instrument(skip_all)]
    pub(crate) async fn open(url: &str) -> StoreResult<Self> {
        let options = SqliteConnectOptions::from_str(url)?;
        if options.get_filename().as_os_str().is_empty() {
            return Err(StoreError::NoFile(url.to_owned()));
        }
        let name = options.get_filename().display().to_string();
        // Read before the writer opens it: WAL mode rewrites the file's header.
        if options.get_filename().exists() {
            others_tables(options.clone().read_only(true), &name).await?;
        }
        let options = options
            .create_if_missing(true)
            .journal_mode(SqliteJournalMode::Wal)
            .synchronous(SqliteSynchronous::Full)
            .foreign_keys(true)
            .busy_timeout(Duration::from_secs(30));
        let writer = unbusy(|| {
            SqlitePoolOptions::new()
                .max_connections(1)
                .connect_with(options.clone())
        })
        .await
        .map_err(|source| StoreError::Unopened {
            file: name.clone(),
            source,
        })?;
        migrate(&writer).await.map_err(|error| match error {
            sqlx::migrate::MigrateError::Execute(sqlx::Error::Database(source))
                if sqlite_code(source.as_ref()) == Some(SQLITE_NOTADB) =>
            {
                StoreError::Unopened {
                    file: name.clone(),
                    source: sqlx::Error::Database(source),
                }
            }
            error => StoreError::Migration(error),
        })?;
        backfill_seeds(&writer).await?;
        let file = DatabaseFile::opened(options.get_filename());
        let writer = match &file {
            Some(_) => {
                writer.close().await;
                recovering_writer(options.clone().create_if_missing(false)).await?
            }
            // An in-memory database lives in its one connection: never closed, never reopened.
            None => writer,
        };
        // No ping before a connection is handed out (here and for the writer): an embedded
        // connection cannot drop, and each ping was a round trip through its thread, about a
        // tenth of a small job's 12 ms from submission to Result.
        let readers = unbusy(|| {
            SqlitePoolOptions::new()
                .max_connections(4)
                .test_before_acquire(false)
                .connect_with(options.clone().read_only(true))
        })
        .await?;
        Ok(Self {
            writer,
            readers,
            file,
            ends: tokio::sync::broadcast::channel(1024).0,
        })
    }

    /// Refuses to acknowledge a write that went into a file no longer at the database's path
    /// (deleted or replaced while serving): what it wrote is out of every later reader's reach.
    pub(crate) fn acknowledge(&self) -> StoreResult<()> {
        match &self.file {
            Some(file) => file.still_there(),
            None => Ok(()),
        }
    }

    /// The writer, once the database's path still leads to the file the server opened: writes to
    /// a deleted or replaced file are refused (503 with Retry-After), never acknowledged.
    pub(crate) fn writer(&self) -> StoreResult<&SqlitePool> {
        self.acknowledge()?;
        Ok(&self.writer)
    }

    /// The writer as opened, whatever its file now, for what only asks whether the database
    /// answers (`SELECT 1`: [`super::Store::ping`]).
    pub(crate) fn writer_as_opened(&self) -> &SqlitePool {
        &self.writer
    }

    /// The file is still the one opened, with at least `min_free_bytes` of room beside it
    /// ([`SqliteBackend::short_of`]).
    pub(crate) async fn check_disk(&self, min_free_bytes: u64) -> StoreResult<()> {
        let Some(file) = &self.file else {
            return Ok(());
        };
        file.still_there()?;
        if let Some(room) = self.short_of(file, min_free_bytes).await? {
            return Err(StoreError::NotReady(format!(
                "{}, below the {} MB required (--min-free-disk-mb)",
                room,
                min_free_bytes >> 20
            )));
        }
        Ok(())
    }

    /// What the database can still write: the disk's free bytes beside it and its own free pages
    /// (the pages of deleted jobs, which it reuses before it grows its file). Without the pages, a
    /// disk that filled stayed full to the queue however many jobs an operator deleted.
    ///
    /// That room when it is less than `needed`, else `None`. The free pages are read only when the
    /// disk alone falls short: every store of a group checks, and the disk's figure is a system
    /// call where the pages' are a round trip to a reader.
    async fn short_of(&self, file: &DatabaseFile, needed: u64) -> StoreResult<Option<Room>> {
        let disk = disk_free(file)?;
        if disk >= needed {
            return Ok(None);
        }
        let room = Room {
            disk,
            pages: self.free_pages().await?,
        };
        Ok((room.bytes() < needed).then_some(room))
    }

    /// The bytes of the database's free pages.
    async fn free_pages(&self) -> StoreResult<u64> {
        let pages: i64 = sqlx::query_scalar(
            "SELECT (SELECT freelist_count FROM pragma_freelist_count()) * \
             (SELECT page_size FROM pragma_page_size())",
        )
        .fetch_one(&self.readers)
        .await?;
        Ok(u64::try_from(pages).unwrap_or(0))
    }

    /// Room beside the database for a write of `bytes`: twice them (the write-ahead log, then the
    /// database's pages) and [`KEPT_FOR_DELETES`], so that a write the disk cannot hold is refused
    /// before it starts (503-like, tried again later) instead of filling the disk half-way, where
    /// even ending the job could not be written, nor a job deleted to make room.
    pub(crate) async fn check_room(&self, bytes: u64) -> StoreResult<()> {
        let Some(file) = &self.file else {
            return Ok(());
        };
        let needed = bytes.saturating_mul(2).saturating_add(KEPT_FOR_DELETES);
        if let Some(room) = self.short_of(file, needed).await? {
            return Err(StoreError::NoRoom(format!(
                "a write of {} MB needs {} MB of room beside the database (the write-ahead log, \
                 the pages, and {} MB kept for deletes); {}",
                bytes >> 20,
                needed >> 20,
                KEPT_FOR_DELETES >> 20,
                room
            )));
        }
        Ok(())
    }
}

/// Room a Result or a group's accumulators leave free beside a SQLite database: a `DELETE` of a
/// job writes its freed pages' list and the tables' pages to the write-ahead log first (for a
/// Result of 40 MB, ten pages of the list and a few of each table: well under a megabyte), so jobs
/// can still be deleted to make room once the queue's writes have taken what they may. Found from
/// outside: accepted jobs filled a disk to its last bytes, and then `DELETE` was 503 (SQLite could
/// not write its log).
pub(crate) const KEPT_FOR_DELETES: u64 = 4 << 20;

/// The room [`SqliteBackend::short_of`] finds.
struct Room {
    disk: u64,
    pages: u64,
}

impl Room {
    fn bytes(&self) -> u64 {
        self.disk.saturating_add(self.pages)
    }
}

impl std::fmt::Display for Room {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} MB free beside the database and {} MB of its free pages",
            self.disk >> 20,
            self.pages >> 20
        )
    }
}

/// The one writer connection of a database file, which recovers from any failed statement: it is
/// closed when it comes back to the pool still inside a transaction. A COMMIT that fails (a full
/// disk) can leave SQLite's transaction rolled back and sqlx's count of open transactions at one;
/// every later BEGIN would then be a savepoint inside a transaction that never commits,
/// acknowledging writes that vanish. A fresh connection starts clean, and never creates a missing
/// file (the store checks the file before each write: [`SqliteBackend::writer`]).
///
/// Released, the writer is back at `synchronous = FULL`, whatever its last transaction was
/// ([`super::Store::begin_redoable`] sets `NORMAL`), so every other commit reaches the disk
/// before it is acknowledged; a writer that cannot be set back is closed.
///
/// A write waits [`LOCK_WAIT`] for a lock another process holds on the file: then it answers 503
/// with Retry-After, or a worker tries again later (a lock held for 50 s made a submission wait
/// 49 s, found from outside). For the writer itself it waits as long as the pool lets it (30
/// s): writes queued behind others of this process under load are not refused (with 2 s, a
/// submission during CI's API fuzzing on two busy cores got 503).
///
/// A writer opened while the file could not be written stays read-only (SQLite opens such a
/// file read-only, silently, and reuses that descriptor for any connection of this process
/// while another is open): writes answer 503 until the process is restarted once the file can
/// be written (docs/manual.md, "Operating it").
async fn recovering_writer(options: SqliteConnectOptions) -> StoreResult<SqlitePool> {
    let pool = SqlitePoolOptions::new()
        .max_connections(1)
        .test_before_acquire(false)
        .after_release(|connection, _| {
            Box::pin(async move {
                // The statement runs behind any rollback a dropped transaction queued, so the
                // count of open transactions is settled when it answers (and SQLite refuses to
                // change `synchronous` inside a transaction).
                let durable = sqlx::query("PRAGMA synchronous = FULL");
                if durable.execute(&mut *connection).await.is_err() {
                    return Ok(false);
                }
                Ok(!connection.is_in_transaction())
            })
        })
        .connect_with(options.busy_timeout(LOCK_WAIT))
        .await?;
    Ok(pool)
}

/// How long a write waits for a lock another process holds on the file before it gives up (503
/// with Retry-After; a worker tries again later).
const LOCK_WAIT: Duration = Duration::from_secs(1);

/// The database file as the store opened it: connections keep writing to the file they opened,
/// so a file deleted or replaced under a running server would take its writes into nowhere.
/// Readiness checks that the path still leads to it, and that its disk has room.
struct DatabaseFile {
    path: PathBuf,
    device: u64,
    inode: u64,
}

impl DatabaseFile {
    fn opened(path: &Path) -> Option<Self> {
        let metadata = std::fs::metadata(path).ok()?;
        Some(Self {
            path: path.to_owned(),
            device: metadata.dev(),
            inode: metadata.ino(),
        })
    }

    /// Whether the path still leads to the file opened.
    fn still_there(&self) -> StoreResult<()> {
        let now = std::fs::metadata(&self.path).map_err(|error| {
            StoreError::NotReady(format!("the database file is gone from its path ({error})"))
        })?;
        if (now.dev(), now.ino()) != (self.device, self.inode) {
            return Err(StoreError::NotReady(
                "the database file at its path is not the one this server opened (replaced)"
                    .to_owned(),
            ));
        }
        Ok(())
    }

    /// The directory holding the database file.
    fn directory(&self) -> &Path {
        match self.path.parent() {
            Some(parent) if !parent.as_os_str().is_empty() => parent,
            _ => Path::new("."),
        }
    }
}

/// [`free_bytes`] beside the database `file`.
fn disk_free(file: &DatabaseFile) -> StoreResult<u64> {
    free_bytes(file.directory())
        .map_err(|error| StoreError::NotReady(format!("free disk space cannot be read ({error})")))
}

/// Bytes an unprivileged process may still write on the file system of `directory` (statvfs).
fn free_bytes(directory: &Path) -> std::io::Result<u64> {
    let path = CString::new(directory.as_os_str().as_bytes())?;
    let mut stats = MaybeUninit::<libc::statvfs>::uninit();
    // SAFETY: `path` is a NUL-terminated string and `stats` has room for one `statvfs`, which
    // the call fills when it returns 0.
    if unsafe { libc::statvfs(path.as_ptr(), stats.as_mut_ptr()) } != 0 {
        return Err(std::io::Error::last_os_error());
    }
    // SAFETY: filled by the successful call above.
    let stats = unsafe { stats.assume_init() };
    let (blocks, block_size): (u64, u64) = (stats.f_bavail, stats.f_frsize);
    Ok(blocks.saturating_mul(block_size))
}

/// Gives jobs stored before the `seed` column their seed, read from their spec (migration 0003).
async fn backfill_seeds(writer: &SqlitePool) -> StoreResult<()> {
    let rows = sqlx::query("SELECT seq, spec FROM jobs WHERE seed IS NULL")
        .fetch_all(writer)
        .await?;
    for row in rows {
        let spec = spec_from_json(&row.try_get::<String, _>("spec")?)?;
        sqlx::query("UPDATE jobs SET seed = ?2 WHERE seq = ?1")
            .bind(row.try_get::<i64, _>("seq")?)
            .bind(seed_to_sql(spec.seed.unwrap_or(0)))
            .execute(writer)
            .await?;
    }
    Ok(())
}

pub(crate) static DIALECT: Dialect = Dialect {
    now: "SELECT CAST((julianday('now') - 2440587.5) * 86400000.0 AS INTEGER) AS now",
    holds: concat!(
        "SELECT 1 AS held FROM jobs WHERE id = $1 AND status = 'running' AND EXISTS (SELECT 1 FROM shards WHERE ",
        fenced_shard!(),
        ")"
    ),
    // Open jobs in fair-share order, each one's open shards in order (migration 0012): named,
    // since without statistics the planner takes `jobs_by_status` and sorts the whole queue.
    claim: claim_next!(
        "rowid = (SELECT s.rowid",
        "jobs j INDEXED BY jobs_open_by_vtime",
        ""
    ),
    // One writer at a time: a transaction's statements see every write committed before it.
    lock_job: None,
    migrator: &migrations::SQLITE,
};

/// Inserts a queued job with its first shards unless the queue or the owner's share of it is
/// full: one statement counts and inserts, under the one writer's lock.
pub(crate) async fn insert_queued(
    tx: &mut Tx,
    job: &QueuedJob,
    bound: QueueBound,
) -> StoreResult<bool> {
    let insert = Sql::new(insert_job!(
        " WHERE (SELECT COUNT(*) FROM jobs WHERE status IN ('queued', 'running')) < $8 \
           AND (SELECT COUNT(*) FROM jobs WHERE status IN ('queued', 'running') AND owner = $2) < $9"
    ));
    let inserted = bind_queued_job(insert, job)?
        .bind(count_to_sql(bound.total))
        .bind(count_to_sql(bound.per_owner))
        .execute(&mut *tx)
        .await?;
    if inserted == 0 {
        return Ok(false);
    }
    insert_shards(tx, &job.id, &job.shards).await?;
    Ok(true)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::domain::{Owner, UnixMs};
    use crate::store::Store;
    use bouncewear_model::montecarlo::Job;

    /// A store in a fresh directory of its own, and the directory (to remove at the test's end).
    async fn open_named(name: &str) -> (Store, String, std::path::PathBuf) {
        let dir =
            std::env::temp_dir().join(format!("bouncewear-store-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let url = format!("sqlite://{}", dir.join("store.db").display());
        (
            Store::open(&url, crate::store::DEFAULT_CONNECTIONS)
                .await
                .unwrap(),
            url,
            dir,
        )
    }

    fn queued(seed: u64) -> QueuedJob {
        let job = Job::from_json(r#"{"devices": 2, "operations": 3}"#, || seed).unwrap();
        QueuedJob::new(&job, Owner::anonymous(), None, UnixMs(1))
    }

    /// Every reading connection held by long reads, the database still answers a health check:
    /// the writer does (with the readers' answer alone, 200 clients reading a large CSV failed 7
    /// of 11 checks of `/healthz` while every read succeeded, found from outside).
    #[tokio::test]
    async fn a_ping_is_answered_while_every_reader_is_busy() {
        let (store, _, dir) = open_named("busy-readers").await;
        let mut held = Vec::new();
        while let Ok(Ok(reader)) =
            tokio::time::timeout(std::time::Duration::from_millis(200), store.reader()).await
        {
            held.push(reader);
        }
        assert_eq!(held.len(), 4, "the readers are all held");
        let answer = tokio::time::timeout(std::time::Duration::from_secs(2), store.ping()).await;
        assert!(matches!(answer, Ok(Ok(()))), "{answer:?}");
        drop(held);
        std::fs::remove_dir_all(dir).unwrap();
    }

    /// SQLite's `synchronous` on the writer: 1 is `NORMAL`, 2 `FULL`.
    async fn synchronous<'c>(on: impl Into<crate::store::sql::Conn<'c>>) -> i64 {
        let row = Sql::new("PRAGMA synchronous").fetch_one(on).await.unwrap();
        row.int("synchronous").unwrap()
    }

    /// Only a redoable transaction commits without waiting for the disk: the writer is back at
    /// `FULL` after it, whether it committed, rolled back or was dropped unfinished, and after a
    /// claim, which is one.
    #[tokio::test]
    async fn only_redoable_transactions_commit_without_waiting_for_the_disk() {
        let (store, _, dir) = open_named("synchronous").await;
        assert_eq!(synchronous(store.writer().unwrap()).await, 2);
        let mut tx = store.begin().await.unwrap();
        assert_eq!(synchronous(&mut tx).await, 2);
        tx.commit().await.unwrap();
        for end in ["commit", "rollback", "drop"] {
            let mut tx = store.begin_redoable().await.unwrap();
            assert_eq!(synchronous(&mut tx).await, 1, "{end}");
            match end {
                "commit" => tx.commit().await.unwrap(),
                "rollback" => tx.rollback().await.unwrap(),
                _ => drop(tx),
            }
            assert_eq!(synchronous(store.writer().unwrap()).await, 2, "after {end}");
            let mut tx = store.begin().await.unwrap();
            assert_eq!(synchronous(&mut tx).await, 2, "a transaction after {end}");
            tx.rollback().await.unwrap();
        }
        store
            .insert_job(queued(1), QueueBound::total(10))
            .await
            .unwrap()
            .unwrap();
        let terms = crate::store::LeaseTerms {
            at: None,
            duration_ms: 60_000,
        };
        let budget = crate::domain::shards::RetryBudget {
            failures: 0,
            lost_leases: 0,
        };
        assert!(store.claim("w", terms, budget).await.unwrap().is_some());
        assert_eq!(synchronous(store.writer().unwrap()).await, 2);
        drop(store);
        std::fs::remove_dir_all(dir).unwrap();
    }

    /// The room a write finds counts the pages of what was deleted, which the database reuses:
    /// 8 MB written and deleted are 8 MB more room, though the disk's free bytes are no more.
    /// A write needs twice its bytes and the 4 MB kept for deletes.
    #[tokio::test]
    async fn deleted_pages_are_room_and_a_write_keeps_room_for_deletes() {
        let (store, _, dir) = open_named("room").await;
        let crate::store::backend::Backend::Sqlite(sqlite) = &store.backend else {
            unreachable!("a SQLite URL")
        };
        let file = sqlite.file.as_ref().unwrap();
        // Short of everything: the room as it is.
        let room = async || sqlite.short_of(file, u64::MAX).await.unwrap().unwrap();
        let before = room().await;
        for statement in [
            "CREATE TABLE scratch (b BLOB)",
            "INSERT INTO scratch VALUES (zeroblob(8388608))",
            "DELETE FROM scratch",
        ] {
            sqlx::query(statement)
                .execute(&sqlite.writer)
                .await
                .unwrap();
        }
        let after = room().await;
        assert!(
            after.pages >= before.pages + (8 << 20) - (64 << 10),
            "{before} then {after}"
        );
        assert!(sqlite.check_room(1 << 20).await.is_ok());
        // Past the room by 256 MB, whatever else on the machine frees meanwhile.
        let huge = after.bytes() / 2 - KEPT_FOR_DELETES / 2 + (256 << 20);
        let refused = sqlite.check_room(huge).await.unwrap_err().to_string();
        assert!(
            refused.contains("4 MB kept for deletes") && refused.contains("MB of its free pages"),
            "{refused}"
        );
        drop(store);
        std::fs::remove_dir_all(dir).unwrap();
    }

    #[tokio::test]
    async fn every_u64_seed_reads_back_exactly_even_for_rows_older_than_the_seed_column() {
        let (store, url, dir) = open_named("seeds").await;
        let seeds = [0, 1 << 53, i64::MAX as u64 + 1, u64::MAX];
        let mut ids = Vec::new();
        for seed in seeds {
            ids.push(
                store
                    .insert_job(queued(seed), QueueBound::total(10))
                    .await
                    .unwrap()
                    .unwrap()
                    .id,
            );
        }
        // Rows written before migration 0003 have no seed: the next open reads it from the spec.
        Sql::new("UPDATE jobs SET seed = NULL")
            .execute(store.writer().unwrap())
            .await
            .unwrap();
        drop(store);
        let store = Store::open(&url, crate::store::DEFAULT_CONNECTIONS)
            .await
            .unwrap();
        for (id, seed) in ids.iter().zip(seeds) {
            let record = store.job(&Owner::anonymous(), id).await.unwrap();
            assert_eq!(record.seed, seed);
        }
        drop(store);
        std::fs::remove_dir_all(dir).unwrap();
    }
}
