//! The migrations as databases that earlier builds migrated know them.

use sqlx::migrate::Migrator;
use std::path::Path;

/// Each landed migration's file and the first 16 hex digits of its SHA-384, the checksum sqlx
/// keeps in every database it migrated.
const LANDED: &[(&str, &str, &str)] = &[
    ("sqlite", "0001_jobs.sql", "8cce6b16608fd6e0"),
    ("sqlite", "0002_life_and_schedules.sql", "a8f3ee86dcb9b425"),
    ("sqlite", "0003_job_seed.sql", "43fd34981622b93a"),
    ("sqlite", "0004_lost_leases.sql", "d82763cae3e4b1ac"),
    ("sqlite", "0005_shards.sql", "eefc5e5b2d3c9ed4"),
    ("sqlite", "0006_readiness.sql", "a11bde5060be61ee"),
    ("sqlite", "0007_retention.sql", "ab201ab28155af38"),
    ("sqlite", "0008_idempotency.sql", "ffd3f0c4fc4b16ee"),
    ("sqlite", "0009_stored_bytes.sql", "6dfe24bc002c4c75"),
    ("sqlite", "0010_distribution_groups.sql", "920e994f748bc417"),
    (
        "sqlite",
        "0011_fair_share_and_retries.sql",
        "5a6f75ccbe17bc33",
    ),
    ("sqlite", "0012_claim_indexes.sql", "ba6a3a2da98cb158"),
    (
        "sqlite",
        "0013_results_without_summaries.sql",
        "4edb9d9e1644443b",
    ),
    ("sqlite", "0014_skipped_runs.sql", "3a77580360657193"),
    ("sqlite", "0015_cursor_secret.sql", "f694e94deb4368b1"),
    ("sqlite", "0016_schedule_revision.sql", "aa864b7ef66d47c9"),
    ("sqlite", "0017_groups_in_shards.sql", "cc57777068e4fb44"),
    ("postgres", "0001_schema.sql", "e6be58dc128a013f"),
    ("postgres", "0002_lost_leases.sql", "3f9e97de535e85cf"),
    ("postgres", "0003_job_events.sql", "4f2154e380d53591"),
    ("postgres", "0004_shards.sql", "0f906698527d0217"),
    ("postgres", "0005_readiness.sql", "f491644f740ed879"),
    ("postgres", "0006_retention.sql", "a27a70b8db8a1015"),
    ("postgres", "0007_idempotency.sql", "0488e3f532357e7e"),
    ("postgres", "0008_stored_bytes.sql", "9f9cdcd37019f18c"),
    (
        "postgres",
        "0009_distribution_groups.sql",
        "5b30097b942e8ca8",
    ),
    (
        "postgres",
        "0010_fair_share_and_retries.sql",
        "29d743bf48cbf516",
    ),
    ("postgres", "0011_claim_indexes.sql", "d0888bf726417740"),
    (
        "postgres",
        "0012_compressed_bytes_stored_as_they_are.sql",
        "f9c945e1638ffdf5",
    ),
    (
        "postgres",
        "0013_results_compressed_with_lz4.sql",
        "99f172e1d2eb101d",
    ),
    (
        "postgres",
        "0014_results_without_summaries.sql",
        "f43e8ed01ae690cf",
    ),
    (
        "postgres",
        "0015_job_end_announcements.sql",
        "b7b1cf8cda75a8e8",
    ),
    ("postgres", "0016_skipped_runs.sql", "956586cc8c8422ac"),
    ("postgres", "0017_cursor_secret.sql", "3bec3424dfb7ef62"),
    ("postgres", "0018_schedule_revision.sql", "a59bfa342a94d88a"),
    ("postgres", "0019_groups_in_shards.sql", "3952a135a9e60f1a"),
];

/// sqlx refuses to start against a database whose applied migration has changed since: an edit
/// to a landed migration would keep every existing database, and the jobs in it, from opening
/// (migrations/sqlite/README.md). A change goes in a new migration, whose checksum is added here
/// when it lands.
#[tokio::test]
async fn landed_migrations_are_never_edited() {
    let mut found = Vec::new();
    for dir in ["sqlite", "postgres"] {
        let path = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../migrations")
            .join(dir);
        let migrator = Migrator::new(path).await.expect("sqlx reads the directory");
        for migration in migrator.iter() {
            let hex: String = migration.checksum[..8]
                .iter()
                .map(|b| format!("{b:02x}"))
                .collect();
            let file = format!(
                "{:04}_{}.sql",
                migration.version,
                migration.description.replace(' ', "_")
            );
            found.push((dir, file, hex));
        }
    }
    for (landed, now) in LANDED.iter().zip(&found) {
        assert_eq!(
            (landed.0, landed.1, landed.2),
            (now.0, now.1.as_str(), now.2.as_str()),
            "a landed migration changed: put the change in a new one"
        );
    }
    assert_eq!(
        LANDED.len(),
        found.len(),
        "a new migration: add its checksum to LANDED"
    );
}

/// A database that a newer build migrated (a rollback after an upgrade) is not opened, and the
/// refusal says so and what to do, for a migration this build does not know and for one whose
/// checksum differs from its own.
#[tokio::test]
async fn a_database_a_newer_build_migrated_is_refused_saying_so() {
    use sqlx::Connection;
    let cases = [
        (
            9999,
            "INSERT INTO _sqlx_migrations \
             (version, description, installed_on, success, checksum, execution_time) \
             VALUES (9999, 'later', CURRENT_TIMESTAMP, 1, x'00', 1)",
            "a newer build migrated it",
        ),
        (
            1,
            "UPDATE _sqlx_migrations SET checksum = x'00' WHERE version = 1",
            "was edited",
        ),
    ];
    for (version, change, said) in cases {
        let path = crate::support::temp_dir(&format!("newer-{version}")).join("jobs.db");
        let url = format!("sqlite://{}", path.display());
        drop(bouncewear::store::open(&url).await.expect("a new database"));
        let mut connection = sqlx::SqliteConnection::connect(&url).await.unwrap();
        sqlx::query(change).execute(&mut connection).await.unwrap();
        connection.close().await.unwrap();
        let Err(refused) = bouncewear::store::open(&url).await else {
            panic!("migration {version}: opened");
        };
        let message = refused.to_string();
        assert!(
            message.contains(&format!("migration {version}")) && message.contains(said),
            "{message}"
        );
    }
}
