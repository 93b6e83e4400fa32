//! PostgreSQL for tests, never a mock: the server at `BOUNCEWEAR_TEST_POSTGRES_URL` when that is set
//! (each test gets databases of its own there, dropped afterwards), or else a throwaway cluster:
//! `initdb` and `pg_ctl` in a temporary directory, on a free port on loopback, stopped when
//! dropped, run as the `postgres` user when the tests run as root (PostgreSQL refuses root).

use std::net::TcpListener;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

pub struct Postgres {
    /// A URL of the server with the right to create databases.
    admin: String,
    /// The throwaway cluster, when we started one.
    cluster: Option<Cluster>,
    created: std::sync::Mutex<Vec<String>>,
}

struct Cluster {
    dir: PathBuf,
    bin: PathBuf,
    /// The server's options (port, socket directory, no fsync).
    options: String,
    /// The server's environment beyond ours (a clock set apart by libfaketime).
    env: Vec<(&'static str, String)>,
}

/// libfaketime names the semaphore and shared memory its processes share after the process that
/// made them, and one killed leaves them in /dev/shm: a process of another user given that pid
/// later cannot make its own, and exits. Those of processes no longer running go.
fn remove_stale_faketime_files() {
    let Ok(entries) = std::fs::read_dir("/dev/shm") else {
        return;
    };
    for entry in entries.flatten() {
        let name = entry.file_name();
        let name = name.to_string_lossy();
        let pid = name
            .strip_prefix("sem.faketime_sem_")
            .or_else(|| name.strip_prefix("faketime_shm_"));
        if pid.is_some_and(|pid| !Path::new("/proc").join(pid).exists()) {
            let _ = std::fs::remove_file(entry.path());
        }
    }
}

/// Debian's libfaketime (package `faketime`), which sets a process's clock apart: in the
/// directory of this machine's multiarch triplet (`/usr/lib/x86_64-linux-gnu/faketime`, ...).
fn faketime() -> Option<PathBuf> {
    std::fs::read_dir("/usr/lib")
        .ok()?
        .flatten()
        .map(|entry| entry.path().join("faketime/libfaketime.so.1"))
        .find(|library| library.is_file())
}

/// The directory of PostgreSQL's programs: where `pg_ctl` really is (links followed, so that
/// `psql` and `initdb` beside it are the same version), found on the PATH or in Debian's
/// versioned directory.
fn binaries() -> Option<PathBuf> {
    let on_path = std::env::var_os("PATH")
        .into_iter()
        .flat_map(|path| std::env::split_paths(&path).collect::<Vec<_>>());
    let debian = std::fs::read_dir("/usr/lib/postgresql")
        .into_iter()
        .flatten()
        .flatten()
        .map(|entry| entry.path().join("bin"));
    on_path
        .chain(debian)
        .filter_map(|dir| dir.join("pg_ctl").canonicalize().ok())
        .filter_map(|pg_ctl| pg_ctl.parent().map(Path::to_owned))
        .find(|dir| dir.join("initdb").is_file() && dir.join("psql").is_file())
}

fn running_as_root() -> bool {
    Command::new("id")
        .arg("-u")
        .output()
        .is_ok_and(|out| out.stdout.starts_with(b"0\n"))
}

impl Postgres {
    /// The server to test against, or says why there is none: `None` when there is neither a
    /// `BOUNCEWEAR_TEST_POSTGRES_URL` nor an installed PostgreSQL, unless
    /// `BOUNCEWEAR_REQUIRE_POSTGRES=1` (CI) makes that a failure.
    pub fn start(dir: &Path) -> Option<Self> {
        Self::start_with(dir, Vec::new())
    }

    /// A throwaway cluster whose clock runs `offset` (libfaketime's form, e.g. `+1h`) from this
    /// machine's, as a database server's may from a worker's. `None`, saying why, without
    /// PostgreSQL or libfaketime (a failure with `BOUNCEWEAR_REQUIRE_POSTGRES=1`, as in CI).
    pub fn start_with_clock(dir: &Path, offset: &str) -> Option<Self> {
        let Some(library) = faketime() else {
            assert!(
                std::env::var("BOUNCEWEAR_REQUIRE_POSTGRES").as_deref() != Ok("1"),
                "BOUNCEWEAR_REQUIRE_POSTGRES=1 but libfaketime is not installed (apt install faketime)"
            );
            eprintln!("\n*** SKIPPED: no libfaketime (Debian: apt install faketime). ***\n");
            return None;
        };
        remove_stale_faketime_files();
        let env = vec![
            ("LD_PRELOAD", library.display().to_string()),
            ("FAKETIME", offset.to_owned()),
            ("FAKETIME_DONT_FAKE_MONOTONIC", "1".to_owned()),
        ];
        Self::start_with(dir, env).filter(|postgres| postgres.cluster.is_some())
    }

    fn start_with(dir: &Path, env: Vec<(&'static str, String)>) -> Option<Self> {
        if env.is_empty()
            && let Ok(admin) = std::env::var("BOUNCEWEAR_TEST_POSTGRES_URL")
        {
            return Some(Self {
                admin,
                cluster: None,
                created: Default::default(),
            });
        }
        let Some(bin) = binaries() else {
            assert!(
                std::env::var("BOUNCEWEAR_REQUIRE_POSTGRES").as_deref() != Ok("1"),
                "BOUNCEWEAR_REQUIRE_POSTGRES=1 but PostgreSQL is not installed"
            );
            eprintln!(
                "\n*** SKIPPED: no PostgreSQL for this test. Install it (Debian: apt install \
                 postgresql) or set BOUNCEWEAR_TEST_POSTGRES_URL. ***\n"
            );
            return None;
        };
        let port = TcpListener::bind("127.0.0.1:0")
            .and_then(|l| l.local_addr())
            .unwrap()
            .port();
        let cluster = Cluster {
            dir: dir.to_owned(),
            bin,
            options: format!(
                "-p {port} -k {} -c listen_addresses=127.0.0.1 -c fsync=off -c synchronous_commit=off -c full_page_writes=off",
                dir.display()
            ),
            env,
        };
        if running_as_root() {
            let status = Command::new("chown")
                .args(["-R", "postgres:postgres"])
                .arg(dir)
                .status()
                .unwrap();
            assert!(status.success(), "chown the cluster's directory");
        }
        let data = dir.join("data");
        cluster.run(
            "initdb",
            &[
                "-D",
                data.to_str().unwrap(),
                "-U",
                "postgres",
                "-A",
                "trust",
                "-E",
                "UTF8",
                "--no-sync",
            ],
        );
        cluster.start_server();
        Some(Self {
            admin: format!("postgres://postgres@127.0.0.1:{port}/postgres"),
            cluster: Some(cluster),
            created: Default::default(),
        })
    }

    /// Stops the throwaway cluster at once, as a crash or an outage would; `false` for a server
    /// given by URL, which is not ours to stop.
    pub fn stop(&self) -> bool {
        let Some(cluster) = &self.cluster else {
            return false;
        };
        let data = cluster.dir.join("data");
        let data = data.to_str().unwrap();
        cluster.run("pg_ctl", &["-D", data, "-m", "immediate", "-w", "stop"]);
        true
    }

    /// Starts the throwaway cluster again after [`Postgres::stop`], on the same port and data.
    pub fn restart(&self) {
        self.cluster
            .as_ref()
            .expect("only a throwaway cluster stops")
            .start_server();
    }

    /// A new, empty database on the server; its URL.
    pub fn database(&self, name: &str) -> String {
        let name = format!("bouncewear_test_{}_{name}", std::process::id());
        admin_sql(&self.admin, format!("CREATE DATABASE \"{name}\""))
            .expect("the test database is created");
        self.created.lock().unwrap().push(name.clone());
        let (server, _) = self.admin.rsplit_once('/').expect("a URL with a database");
        format!("{server}/{name}")
    }
}

/// One statement on the admin connection, from a thread of its own (callers may be inside an
/// async runtime, which cannot block on another).
fn admin_sql(admin: &str, statement: String) -> Result<(), sqlx::Error> {
    let admin = admin.to_owned();
    super::on_own_runtime(async move {
        use sqlx::Connection;
        let mut connection = sqlx::PgConnection::connect(&admin).await?;
        sqlx::query(sqlx::AssertSqlSafe(statement))
            .execute(&mut connection)
            .await
            .map(drop)
    })
}

impl Cluster {
    fn start_server(&self) {
        let data = self.dir.join("data");
        let log = self.dir.join("server.log");
        self.run(
            "pg_ctl",
            &[
                "-D",
                data.to_str().unwrap(),
                "-l",
                log.to_str().unwrap(),
                "-o",
                &self.options,
                "-w",
                "start",
            ],
        );
    }

    /// Runs one of PostgreSQL's programs, as the `postgres` user when we are root; it must succeed.
    fn run(&self, program: &str, args: &[&str]) {
        let output = self.output(program, args);
        assert!(
            output.status.success(),
            "{program} {args:?}: {}{}",
            String::from_utf8_lossy(&output.stdout),
            String::from_utf8_lossy(&output.stderr)
        );
    }

    /// The environment (libfaketime's) goes to the program alone, set by `env` once `runuser` has
    /// become `postgres`: given to `runuser`, root's libfaketime made the semaphore its children
    /// share, which `postgres` may not open ("sem_open failed ... Permission denied", a CI run).
    fn output(&self, program: &str, args: &[&str]) -> std::process::Output {
        let program = self.bin.join(program);
        let assignments = self
            .env
            .iter()
            .map(|(name, value)| format!("{name}={value}"));
        let mut command = if running_as_root() {
            let mut command = Command::new("runuser");
            command
                .args(["-u", "postgres", "--", "env"])
                .args(assignments);
            command.arg(&program);
            command
        } else {
            let mut command = Command::new("env");
            command.args(assignments).arg(&program);
            command
        };
        command
            .args(args)
            .stdin(Stdio::null())
            .output()
            .unwrap_or_else(|e| panic!("{}: {e}", program.display()))
    }
}

impl Drop for Postgres {
    fn drop(&mut self) {
        // Never panics: a failing test is already unwinding through here.
        match &self.cluster {
            Some(cluster) => {
                let data = cluster.dir.join("data");
                let data = data.to_str().unwrap();
                let _ = cluster.output("pg_ctl", &["-D", data, "-m", "immediate", "-w", "stop"]);
            }
            None => {
                for name in self.created.lock().unwrap().drain(..) {
                    let statement = format!("DROP DATABASE IF EXISTS \"{name}\" WITH (FORCE)");
                    let _ = admin_sql(&self.admin, statement);
                }
            }
        }
    }
}
