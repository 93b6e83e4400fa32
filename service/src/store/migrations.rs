//! Each database's migrations, embedded in the binary as `sqlx::migrate!` would embed them: the
//! version and description from the file name, the SQL's SHA-384 as its checksum (what a database
//! migrated by an older build has recorded). Written out rather than expanded by sqlx's macros,
//! which compile SQLite and both drivers a second time for the compiler's host: about 90 s of a
//! clean build's CPU on two cores, in `cargo clippy` once more. The test below holds the lists to
//! the directories, as sqlx's own resolver reads them.

use sqlx::SqlStr;
use sqlx::migrate::{Migration, MigrationType, Migrator};
use std::sync::LazyLock;

/// `(file name, its SQL)` for each named file of `migrations/$dir/`.
macro_rules! embed {
    ($dir:literal: $($file:literal),+ $(,)?) => {
        &[$((
            $file,
            include_str!(concat!(env!("CARGO_MANIFEST_DIR"), "/../migrations/", $dir, "/", $file)),
        )),+]
    };
}

const SQLITE_FILES: &[(&str, &str)] = embed!("sqlite":
    "0001_jobs.sql",
    "0002_life_and_schedules.sql",
    "0003_job_seed.sql",
    "0004_lost_leases.sql",
    "0005_shards.sql",
    "0006_readiness.sql",
    "0007_retention.sql",
    "0008_idempotency.sql",
    "0009_stored_bytes.sql",
    "0010_distribution_groups.sql",
    "0011_fair_share_and_retries.sql",
    "0012_claim_indexes.sql",
    "0013_results_without_summaries.sql",
    "0014_skipped_runs.sql",
    "0015_cursor_secret.sql",
    "0016_schedule_revision.sql",
    "0017_groups_in_shards.sql",
);

const POSTGRES_FILES: &[(&str, &str)] = embed!("postgres":
    "0001_schema.sql",
    "0002_lost_leases.sql",
    "0003_job_events.sql",
    "0004_shards.sql",
    "0005_readiness.sql",
    "0006_retention.sql",
    "0007_idempotency.sql",
    "0008_stored_bytes.sql",
    "0009_distribution_groups.sql",
    "0010_fair_share_and_retries.sql",
    "0011_claim_indexes.sql",
    "0012_compressed_bytes_stored_as_they_are.sql",
    "0013_results_compressed_with_lz4.sql",
    "0014_results_without_summaries.sql",
    "0015_job_end_announcements.sql",
    "0016_skipped_runs.sql",
    "0017_cursor_secret.sql",
    "0018_schedule_revision.sql",
    "0019_groups_in_shards.sql",
);

/// `migrations/sqlite/`.
pub(crate) static SQLITE: LazyLock<Migrator> = LazyLock::new(|| migrator(SQLITE_FILES));
/// `migrations/postgres/`.
pub(crate) static POSTGRES: LazyLock<Migrator> = LazyLock::new(|| migrator(POSTGRES_FILES));

fn migrator(files: &[(&str, &'static str)]) -> Migrator {
    Migrator::with_migrations(
        files
            .iter()
            .map(|&(file, sql)| migration(file, sql))
            .collect(),
    )
}

/// A migration as sqlx's resolver reads `VERSION_DESCRIPTION.sql`: `_` in the description read as
/// spaces, no transaction when the SQL starts with `-- no-transaction`.
fn migration(file: &str, sql: &'static str) -> Migration {
    let (version, description) = file
        .strip_suffix(".sql")
        .and_then(|stem| stem.split_once('_'))
        .expect("a migration's file is VERSION_DESCRIPTION.sql");
    Migration::new(
        version
            .parse()
            .expect("a migration's version is an integer"),
        description.replace('_', " ").into(),
        MigrationType::Simple,
        SqlStr::from_static(sql),
        sql.starts_with("-- no-transaction"),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    /// Every migration of each directory, read by sqlx at run time, is embedded with the same
    /// version, description, checksum and transaction mode, and nothing else is.
    #[tokio::test]
    async fn the_embedded_migrations_are_the_directories_as_sqlx_reads_them() {
        for (dir, embedded) in [("sqlite", &*SQLITE), ("postgres", &*POSTGRES)] {
            let path = Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("../migrations")
                .join(dir);
            let resolved = Migrator::new(path).await.expect("sqlx reads the directory");
            let shape = |m: &Migration| {
                (
                    m.version,
                    m.description.to_string(),
                    m.checksum.to_vec(),
                    m.no_tx,
                )
            };
            let ours: Vec<_> = embedded.iter().map(shape).collect();
            let theirs: Vec<_> = resolved.iter().map(shape).collect();
            assert_eq!(
                ours, theirs,
                "migrations/{dir}/ and its embedded list differ"
            );
            assert!(!ours.is_empty());
        }
    }
}
