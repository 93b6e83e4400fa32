//! The service as a process: what only a real process shows (SIGKILL, SIGTERM, refusing to
//! start, its log on stderr), through the binary.

use crate::support::app::{Service, Spawned, WorkerProcess};
use crate::support::client::{agent, delete, get, reply};
use crate::support::postgres::Postgres;
use crate::support::{BIN, run_job, scattered_job, send_signal, temp_db, temp_dir};
use serde_json::{Value, json};
use std::process::Command;
use std::sync::mpsc::Receiver;
use std::time::{Duration, Instant};

#[test]
fn a_job_killed_mid_run_finishes_after_restart_with_the_identical_result() {
    let database = temp_db("crash");
    let job = scattered_job(20_000, 300, 4242);
    let server = Spawned::start(&database, &["--lease-seconds", "1"]);
    let id = server.submit(&job);
    let queued = server.submit(&json!({"devices": 3, "operations": 3, "seed": 5}));
    let started = Instant::now();
    loop {
        let status = get(&server.url(&format!("/v1/jobs/{id}")), None).json();
        if status["progress"]["operations_done"].as_u64().unwrap() > 0 {
            assert_eq!(status["status"], "running");
            break;
        }
        assert!(
            started.elapsed() < Duration::from_secs(20),
            "never started: {status}"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    server.kill(); // SIGKILL: no shutdown handler runs

    let server = Spawned::start(&database, &["--lease-seconds", "1"]);
    server.wait_for(&id, "succeeded", Duration::from_secs(60));
    server.wait_for(&queued, "succeeded", Duration::from_secs(60));
    let result = get(&server.url(&format!("/v1/jobs/{id}/result")), None).json();
    let local = run_job(&job, &[]);
    assert_eq!(result["operations"], local["operations"]);
    assert_eq!(result["devices"], local["devices"]);
}

/// A client that reads a large Result slowly no longer holds a SIGTERM for its body timeout:
/// with 120 s of it, the server stopped only when it ran out (a probe saw 30 s with the default,
/// past a container's grace period); it now cuts the response off after 10 s and exits.
#[test]
fn sigterm_cuts_off_a_response_its_client_reads_too_slowly() {
    use std::io::{Read, Write};
    let server = Spawned::start(&temp_db("slow-reader"), &["--body-timeout-seconds", "120"]);
    // 1000 bins: a Result of about 18 MB, far beyond what the sockets' buffers hold.
    let job = json!({"devices": 64, "operations": 1000, "seed": 3, "bin_operations": 1});
    let id = server.submit(&job);
    server.wait_for(&id, "succeeded", Duration::from_secs(60));
    let address = server
        .url("")
        .trim_start_matches("http://")
        .trim_end_matches('/')
        .to_owned();
    let mut reader = std::net::TcpStream::connect(&address).unwrap();
    write!(
        reader,
        "GET /v1/jobs/{id}/result HTTP/1.1\r\nHost: localhost\r\n\r\n"
    )
    .unwrap();
    let mut first = [0_u8; 4096];
    reader.read_exact(&mut first).unwrap();
    let mut server = server;
    let signalled = Instant::now();
    send_signal(server.child.id(), "-TERM");
    let exit = server.child.wait().unwrap();
    let took = signalled.elapsed();
    assert!(exit.success(), "{exit:?}");
    assert!(took < Duration::from_secs(60), "stopped after {took:?}");
    drop(reader);
}

/// A second SIGTERM ends the process at once, where the first waits for a request in flight
/// (here a body that never comes, for up to the 10 s drain).
#[test]
fn a_second_sigterm_ends_a_graceful_stop_at_once() {
    use std::io::Write;
    let server = Spawned::start(&temp_db("second-sigterm"), &["--workers", "0"]);
    let address = server.url("");
    let address = address.trim_start_matches("http://").trim_end_matches('/');
    let mut writer = std::net::TcpStream::connect(address).unwrap();
    write!(
        writer,
        "POST /v1/jobs HTTP/1.1\r\nHost: localhost\r\nContent-Type: application/json\r\n\
         Content-Length: 100\r\n\r\n{{"
    )
    .unwrap();
    writer.flush().unwrap();
    std::thread::sleep(Duration::from_millis(300));
    let mut server = server;
    let pid = server.child.id();
    let terminate = || send_signal(pid, "-TERM");
    terminate();
    std::thread::sleep(Duration::from_secs(1));
    assert!(
        server.child.try_wait().unwrap().is_none(),
        "the first SIGTERM waits for the request in flight"
    );
    let signalled = Instant::now();
    terminate();
    let exit = server.child.wait().unwrap();
    let took = signalled.elapsed();
    assert_eq!(exit.code(), Some(1), "{exit:?}");
    assert!(
        took < Duration::from_secs(3),
        "ended {took:?} after the second"
    );
    drop(writer);
}

/// SIGTERM, and SIGHUP as it (a hang-up ended the process at once, its default action; found
/// from outside).
#[test]
fn sigterm_hands_a_running_job_back_to_the_queue() {
    for signal in ["-TERM", "-HUP"] {
        stopping_hands_a_running_job_back_to_the_queue(signal);
    }
}

fn stopping_hands_a_running_job_back_to_the_queue(signal: &str) {
    let database = temp_db(&format!("stopped-by{signal}"));
    let server = Spawned::start(&database, &[]);
    let id = server.submit(&scattered_job(200_000, 1000, 3));
    server.wait_for(&id, "running", Duration::from_secs(10));
    send_signal(server.child.id(), signal);
    let mut server = server;
    let exit = server.child.wait().unwrap();
    assert!(exit.success(), "{exit:?}");
    let server = Spawned::start(&database, &["--workers", "0"]);
    let job = get(&server.url(&format!("/v1/jobs/{id}")), None).json();
    assert!(
        job["status"] == "queued" || job["status"] == "running",
        "{job}"
    );
    // The attempt handed back is in its shard's history (one line per attempt that did not
    // finish; it had none).
    let shards = get(&server.url(&format!("/v1/jobs/{id}/shards")), None).json();
    let handed_back = shards["shards"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|shard| {
            shard["history"].as_array().is_some_and(|lines| {
                lines
                    .iter()
                    .any(|line| line.as_str().unwrap().ends_with("handed back at shutdown"))
            })
        })
        .count();
    assert!(handed_back >= 1, "{shards}");
    delete(&server.url(&format!("/v1/jobs/{id}")));
}

#[test]
fn serve_refuses_a_public_bind_without_keys() {
    let output = Command::new(BIN)
        .args([
            "serve",
            "--bind",
            "0.0.0.0:0",
            "--database",
            "sqlite::memory:",
        ])
        .env_remove("BOUNCEWEAR_API_KEYS")
        .output()
        .unwrap();
    assert_eq!(output.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&output.stderr).contains("--api-key"));
}

/// A server whose open-file limit leaves no room for connections beside the descriptors it keeps
/// refuses to start, saying which limit and how much: under `ulimit -n 16` it said it listened
/// and accepted no connection at all, and under 12 it blamed the database's file (found from
/// outside).
#[test]
fn serve_refuses_an_open_file_limit_without_room_for_connections() {
    for limit in [12, 64] {
        let output = Command::new("sh")
            .arg("-c")
            .arg(format!(
                "ulimit -n {limit} && exec {BIN} serve --bind 127.0.0.1:0 --database sqlite::memory:"
            ))
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert_eq!(output.status.code(), Some(1), "{stderr}");
        let said = format!("open-file limit (RLIMIT_NOFILE, `ulimit -n`) is {limit}");
        assert!(stderr.contains(&said), "{stderr}");
        assert!(stderr.contains("raise it to at least 136"), "{stderr}");
    }
}

/// A database URL of a scheme no backend takes is a bad command line (exit 2, the contract's
/// "Exit codes"), as a public bind without keys is; it exited 1.
#[test]
fn serve_and_worker_refuse_an_unsupported_database_scheme_as_a_bad_command_line() {
    for command in [&["serve", "--bind", "127.0.0.1:0"][..], &["worker"]] {
        let output = Command::new(BIN)
            .args(command)
            .args(["--database", "mysql://x/y"])
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert_eq!(output.status.code(), Some(2), "{command:?}: {stderr}");
        assert!(
            stderr.contains("unsupported database URL scheme `mysql`"),
            "{stderr}"
        );
    }
}

/// A SQLite URL that names no file (`sqlite://$DB` with DB unset) is a bad command line too: it
/// served, SQLite gave each connection a private temporary database, and a job acknowledged with
/// 202 was lost (a probe). Nothing is created.
#[test]
fn serve_and_worker_refuse_a_sqlite_url_without_a_file() {
    let dir = temp_dir("no-file");
    for url in ["sqlite://", "sqlite:", "sqlite://?mode=rwc"] {
        for command in [&["serve", "--bind", "127.0.0.1:0"][..], &["worker"]] {
            let output = Command::new(BIN)
                .args(command)
                .args(["--database", url])
                .current_dir(&dir)
                .output()
                .unwrap();
            let stderr = String::from_utf8_lossy(&output.stderr);
            assert_eq!(output.status.code(), Some(2), "{command:?} {url}: {stderr}");
            assert!(stderr.contains("names no file"), "{stderr}");
        }
    }
    assert_eq!(
        std::fs::read_dir(&dir).unwrap().count(),
        0,
        "nothing created"
    );
}

/// A SQLite file that cannot be opened is named, with what to check: the error was "database:
/// database: error returned from database: (code: 14) unable to open database file".
#[test]
fn a_sqlite_file_that_cannot_be_opened_is_named() {
    let dir = temp_dir("unopened");
    let not_a_database = dir.join("notes.db");
    std::fs::write(&not_a_database, "not a database, but notes\n".repeat(100)).unwrap();
    let missing_dir = dir.join("no-such-dir").join("x.db");
    for file in [&not_a_database, &missing_dir] {
        let output = Command::new(BIN)
            .args(["serve", "--bind", "127.0.0.1:0", "--database"])
            .arg(format!("sqlite://{}", file.display()))
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert_eq!(output.status.code(), Some(1), "{stderr}");
        let named = format!("cannot open {}", file.display());
        assert!(
            stderr.contains(&named) && !stderr.contains("database: database"),
            "{stderr}"
        );
    }
}

/// A SQLite file of another application (tables, and no record of bouncewear's migrations) is
/// refused, naming its tables, and left as it was: the server added its own tables to it.
#[test]
fn another_applications_sqlite_file_is_refused_and_left_alone() {
    use sqlx::{Connection, Executor};
    let dir = temp_dir("foreign");
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    // A plain application's file, and one whose own sqlx migrations are recorded.
    for (name, sql) in [
        ("app.db", ""),
        (
            "sqlx-app.db",
            "CREATE TABLE _sqlx_migrations (version BIGINT PRIMARY KEY, description TEXT); \
             INSERT INTO _sqlx_migrations VALUES (20240101, 'init');",
        ),
    ] {
        let file = dir.join(name);
        let url = format!("sqlite://{}?mode=rwc", file.display());
        runtime.block_on(async {
            let mut connection = sqlx::SqliteConnection::connect(&url).await.unwrap();
            let made = "CREATE TABLE customers (id INTEGER PRIMARY KEY, name TEXT)";
            connection.execute(made).await.unwrap();
            if !sql.is_empty() {
                connection.execute(sql).await.unwrap();
            }
            connection.close().await.unwrap();
        });
        refused_and_left_alone(&file);
    }
}

fn refused_and_left_alone(file: &std::path::Path) {
    let before = std::fs::read(file).unwrap();
    for command in [&["serve", "--bind", "127.0.0.1:0"][..], &["worker"]] {
        let output = Command::new(BIN)
            .args(command)
            .arg("--database")
            .arg(format!("sqlite://{}", file.display()))
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert_eq!(output.status.code(), Some(1), "{command:?}: {stderr}");
        assert!(
            stderr.contains("customers") && stderr.contains("a file of its own"),
            "{stderr}"
        );
    }
    assert_eq!(
        std::fs::read(file).unwrap(),
        before,
        "the file is left as it was"
    );
}

/// A count or a time outside what the server can honour is a bad command line naming the flag,
/// before anything is created: `--workers 100000` started and logged 108,731 warnings of its
/// pool in 12 s, `--header-timeout-seconds 0` became 1 ms and cut off every keep-alive,
/// `--max-connections 0` became 1, and `--lease-seconds 1e20` panicked where 0, -1 and NaN became
/// half a second (probes).
#[test]
fn serve_refuses_counts_and_times_out_of_range_by_name() {
    let dir = temp_dir("flag-ranges");
    for (flag, value) in [
        ("--workers", "100000"),
        ("--compute-threads", "0"),
        ("--max-queued", "0"),
        ("--max-queued-per-key", "0"),
        ("--max-job-operations", "0"),
        ("--max-body-bytes", "0"),
        ("--header-timeout-seconds", "0"),
        ("--body-timeout-seconds", "0"),
        ("--request-timeout-seconds", "NaN"),
        ("--header-timeout-seconds", "1e-9"),
        ("--lease-seconds", "99999999999999999999"),
        ("--lease-seconds", "inf"),
        ("--lease-seconds", "0"),
        ("--lease-seconds", "0.25"),
        ("--lease-seconds", "NaN"),
        ("--max-concurrent-requests", "0"),
        ("--max-connections", "0"),
        ("--max-streams-per-key", "0"),
        ("--min-free-disk-mb", "18446744073709551615"),
        ("--retain-days", "100000"),
    ] {
        let output = Command::new(BIN)
            .args(["serve", "--bind", "127.0.0.1:0", flag, value])
            .current_dir(&dir)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert_eq!(output.status.code(), Some(2), "{flag} {value}: {stderr}");
        assert!(stderr.contains(flag), "{flag} {value}: {stderr}");
    }
    assert_eq!(
        std::fs::read_dir(&dir).unwrap().count(),
        0,
        "nothing created"
    );
}

#[test]
fn a_worker_process_runs_what_an_api_only_server_queued_and_stops_cleanly_on_sigterm() {
    use std::io::{BufRead, BufReader};
    use std::process::Stdio;
    let database = temp_db("worker");
    let server = Spawned::start(&database, &["--workers", "0"]);
    // Killed when dropped, should an assertion fail before its SIGTERM.
    let mut worker = WorkerProcess {
        child: Command::new(BIN)
            .args([
                "worker",
                "--workers",
                "2",
                "--metrics-bind",
                "127.0.0.1:0",
                "--database",
            ])
            .arg(format!("sqlite://{}", database.display()))
            .env("RUST_LOG", "warn")
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .unwrap(),
    };
    let mut stdout = BufReader::new(worker.child.stdout.take().unwrap());
    let (mut metrics, mut line) = (String::new(), String::new());
    stdout.read_line(&mut metrics).unwrap();
    stdout.read_line(&mut line).unwrap();
    let metrics = metrics
        .trim()
        .strip_prefix("bouncewear worker metrics on ")
        .unwrap_or_else(|| panic!("{metrics}"))
        .to_owned();
    assert!(
        line.starts_with("bouncewear worker running 2 shard(s) at a time"),
        "{line}"
    );
    for pid in [server.child.id(), worker.child.id()] {
        assert_ne!(huge_pages(pid), Some(true), "process {pid}");
    }
    let job = json!({"devices": 50, "operations": 40, "seed": 8});
    let id = server.submit(&job);
    server.wait_for(&id, "succeeded", Duration::from_secs(60));
    let result = get(&server.url(&format!("/v1/jobs/{id}/result")), None).json();
    assert_eq!(result["operations"], run_job(&job, &[])["operations"]);
    // A rare event whose round (10,000 evaluations of 100 operations) runs as shards: its tasks
    // count their operations as groups do (the counter missed them, found from outside).
    let rare = json!({"devices": 4, "operations": 100, "seed": 9, "metrics": ["total_bounce_s"],
        "scatter": [{"parameter": "impact_velocity_m_s", "per": "operation",
            "distribution": {"kind": "normal", "mean": 0.224, "sd": 0.02, "min": 0.05}}],
        "rare_event": {"metric": "total_bounce_s", "above": 0.0305, "operation": 100,
            "method": "crude", "target_cov": 0.3, "max_evaluations": 10000}});
    let id = server.submit(&rare);
    server.wait_for(&id, "succeeded", Duration::from_secs(120));
    let ended = get(&server.url(&format!("/v1/jobs/{id}")), None).json();
    assert_eq!(ended["progress"]["operations_done"], 1_000_400, "{ended}");
    // A subset simulation out of its budget: its first level (1000 evaluations of 500
    // operations) runs as a round's shards, and the round's merge, which runs the second level
    // (900) and finds no budget for a third, fails the job. The job keeps what it ran (it read
    // the devices' 2,000 and the first level's alone), the counter counts it too, and that merge
    // is timed as every other merge step is (it was not, found from outside).
    let failing = json!({"devices": 4, "operations": 500, "seed": 9, "metrics": ["total_bounce_s"],
        "scatter": [{"parameter": "impact_velocity_m_s", "per": "operation",
            "distribution": {"kind": "normal", "mean": 0.224, "sd": 0.02, "min": 0.05}}],
        "rare_event": {"metric": "total_bounce_s", "above": 0.04, "operation": 500,
            "method": "subset", "max_evaluations": 2000}});
    let failed = server.submit(&failing);
    server.wait_for(&failed, "failed", Duration::from_secs(120));
    let ended = get(&server.url(&format!("/v1/jobs/{failed}")), None).json();
    let ran = 2_000 + 1_900 * 500;
    assert_eq!(ended["progress"]["operations_done"], ran, "{ended}");
    // The job's metrics are the worker's, which ran it: an API-only node has none of them.
    let scraped = get(&metrics, None);
    assert_eq!(scraped.status, 200);
    let merge_steps: usize = [&id, &failed]
        .iter()
        .map(|job| {
            let shards = get(&server.url(&format!("/v1/jobs/{job}/shards")), None).json();
            let shards = shards["shards"].as_array().unwrap().clone();
            // No shard has done more than its total (the failed round's merge read 450,000 of 0).
            let within =
                |s: &&Value| s["operations_done"].as_u64() <= s["operations_total"].as_u64();
            assert!(shards.iter().all(|s| within(&s)), "{shards:?}");
            shards.iter().filter(|s| s.get("group").is_none()).count()
        })
        .sum::<usize>()
        + 1;
    let merges = format!("bouncewear_shard_step_seconds_count{{step=\"merge\"}} {merge_steps}");
    for line in [
        "bouncewear_jobs_finished_total{status=\"succeeded\"} 2",
        "bouncewear_jobs_finished_total{status=\"failed\"} 1",
        "bouncewear_operations_simulated_total 1954400",
        &merges,
    ] {
        assert!(
            scraped.body.lines().any(|l| l == line),
            "{line}: {}",
            scraped.body
        );
    }
    send_signal(worker.child.id(), "-TERM");
    assert!(worker.child.wait().unwrap().success());
}

/// A server and two workers started together on a new SQLite database all run: SQLite's
/// migrator takes no lock, and the later of two processes failed on a migration the other had
/// made ("table jobs already exists", 4 starts in 5); and two processes turning a new file to
/// WAL together saw "database is locked" at once (3 pairs of workers in 40; found from outside).
#[test]
fn a_server_and_workers_started_together_on_a_new_database_all_run() {
    use std::io::{BufRead, BufReader, Read};
    use std::process::Stdio;
    for round in 0..4 {
        let database = temp_db(&format!("together-{round}"));
        let url = format!("sqlite://{}", database.display());
        // Killed when dropped, as the server is.
        let mut workers: Vec<WorkerProcess> = (0..2)
            .map(|_| WorkerProcess {
                child: Command::new(BIN)
                    .args(["worker", "--compute-threads", "1", "--database", &url])
                    .env("RUST_LOG", "warn")
                    .stdout(Stdio::piped())
                    .stderr(Stdio::piped())
                    .spawn()
                    .unwrap(),
            })
            .collect();
        let server = Spawned::start(&database, &["--workers", "0"]);
        for worker in &mut workers {
            let mut line = String::new();
            BufReader::new(worker.child.stdout.take().unwrap())
                .read_line(&mut line)
                .unwrap();
            let mut stderr = String::new();
            if line.is_empty() {
                let mut log = worker.child.stderr.take().unwrap();
                log.read_to_string(&mut stderr).unwrap();
            }
            assert!(
                line.starts_with("bouncewear worker running"),
                "round {round}: {line}{stderr}"
            );
        }
        assert_eq!(get(&server.url("/healthz"), None).status, 200);
    }
}

/// Whether the kernel may back process `pid`'s memory with transparent huge pages (its
/// `THP_enabled` line); `None` where /proc does not tell. `serve` and `worker` turn them off.
fn huge_pages(pid: u32) -> Option<bool> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    let line = status.lines().find(|l| l.starts_with("THP_enabled:"))?;
    Some(line.split_whitespace().nth(1)? == "1")
}

#[test]
fn a_worker_needs_at_least_one_slot_and_a_known_database_scheme() {
    for (args, message) in [
        (&["worker", "--workers", "0"][..], "--workers"),
        (
            &["worker", "--lease-seconds", "1e30"][..],
            "--lease-seconds",
        ),
        (
            &["worker", "--database", "mysql://u:secret@h/db"][..],
            "postgres://",
        ),
    ] {
        let output = Command::new(BIN).args(args).output().unwrap();
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert_ne!(output.status.code(), Some(0), "{args:?}");
        assert!(
            stderr.contains(message) && !stderr.contains("secret"),
            "{args:?}: {stderr}"
        );
    }
}

/// The shards of a job, as `GET /v1/jobs/{id}/shards` lists them.
fn shards(server: &impl Service, id: &str) -> Vec<serde_json::Value> {
    let reply = get(&server.url(&format!("/v1/jobs/{id}/shards")), None).json();
    reply["shards"].as_array().unwrap().clone()
}

/// The process id in a shard's worker name (`PID-INSTANCE/SLOT`).
fn worker_pid(shard: &serde_json::Value) -> Option<u32> {
    shard["worker"].as_str()?.split('-').next()?.parse().ok()
}

/// The Result's `operations` and `devices`, as the bytes a client receives.
fn numbers(result: &serde_json::Value) -> (String, String) {
    (
        result["operations"].to_string(),
        result["devices"].to_string(),
    )
}

#[test]
fn three_worker_processes_on_postgres_survive_kill_9_and_give_the_bits_of_one_machine() {
    let Some(cluster) = Postgres::start(&temp_dir("process-shards")) else {
        return;
    };
    // 32 groups of 10 devices x 60,000 operations: a few tenths of a second each.
    let job = scattered_job(320, 60_000, 77);
    let local = numbers(&run_job(&job, &[]));

    // One worker on SQLite and one on PostgreSQL, side by side.
    let single: Vec<(Spawned, String)> = [
        format!("sqlite://{}", temp_db("shards-sqlite").display()),
        cluster.database("single"),
    ]
    .iter()
    .map(|url| {
        let server = Spawned::on(url, &["--workers", "1"]);
        let id = server.submit(&job);
        (server, id)
    })
    .collect();
    for (server, id) in &single {
        server.wait_for(id, "succeeded", Duration::from_secs(120));
        let result = get(&server.url(&format!("/v1/jobs/{id}/result")), None).json();
        assert_eq!(numbers(&result), local, "one worker, to the bit");
    }
    drop(single);

    // An API-only node and three worker processes, one shard at a time each; kill -9 a worker
    // mid-shard, twice, starting a new one each time.
    let url = cluster.database("sharded");
    let api = Spawned::on(&url, &["--workers", "0"]);
    let worker_args = [
        "--workers",
        "1",
        "--compute-threads",
        "1",
        "--lease-seconds",
        "2",
    ];
    let mut workers: Vec<WorkerProcess> = (0..3)
        .map(|_| WorkerProcess::start(&url, &worker_args))
        .collect();
    let id = api.submit(&job);
    let mut killed = Vec::new();
    let started = Instant::now();
    while killed.len() < 2 {
        assert!(
            started.elapsed() < Duration::from_secs(60),
            "no shard ever ran"
        );
        let running = shards(&api, &id).into_iter().find_map(|shard| {
            let pid = worker_pid(&shard).filter(|_| shard["status"] == "running")?;
            let index = workers.iter().position(|w| w.child.id() == pid)?;
            shard["group"].is_u64().then_some((index, shard))
        });
        let Some((index, _)) = running else {
            std::thread::sleep(Duration::from_millis(20));
            continue;
        };
        let worker = workers.swap_remove(index);
        let pid = worker.child.id();
        worker.kill();
        // What the worker held when it died: the group it ran, the next shard it had claimed
        // meanwhile and the last group still being stored. Their leases outlive it by two seconds;
        // a statement it sent before it died is done within the pause.
        std::thread::sleep(Duration::from_millis(200));
        let held: Vec<_> = shards(&api, &id)
            .into_iter()
            .filter(|s| s["status"] == "running" && worker_pid(s) == Some(pid))
            .map(|s| (s["batch"].clone(), s["group"].clone()))
            .collect();
        assert!(!held.is_empty(), "the killed worker held no shard");
        killed.push(held);
        workers.push(WorkerProcess::start(&url, &worker_args));
        std::thread::sleep(Duration::from_millis(300));
    }
    api.wait_for(&id, "succeeded", Duration::from_secs(180));
    let result = get(&api.url(&format!("/v1/jobs/{id}/result")), None).json();
    assert_eq!(
        numbers(&result),
        local,
        "three workers and two kills, to the bit"
    );

    // Only the shards the killed workers held ran again; every other shard ran once.
    let shards = shards(&api, &id);
    assert_eq!(shards.len(), 33, "32 groups and the merge");
    let rerun: Vec<_> = shards
        .iter()
        .filter(|s| s["attempt"].as_u64().unwrap() > 1)
        .map(|s| (s["batch"].clone(), s["group"].clone()))
        .collect();
    assert!(!rerun.is_empty(), "a killed shard reran: {shards:#?}");
    let killed: Vec<_> = killed.concat();
    for shard in &rerun {
        assert!(
            killed.contains(shard),
            "{shard:?} reran but was never killed ({killed:?}): {shards:#?}"
        );
    }
    for shard in &shards {
        assert_eq!(shard["status"], "done");
        assert!(shard["attempt"].as_u64().unwrap() <= 2, "{shard}");
    }
}
/// The log's lines up to the first that mentions `needle` (the last one), waiting for it at
/// most ten seconds.
fn log_until(lines: &Receiver<String>, needle: &str) -> Vec<String> {
    let deadline = Instant::now() + Duration::from_secs(10);
    let mut read = Vec::new();
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        match lines.recv_timeout(left) {
            Ok(line) if line.contains(needle) => {
                read.push(line);
                return read;
            }
            Ok(line) => read.push(line),
            Err(error) => panic!("no log line with {needle} after {read:?}: {error}"),
        }
    }
}

/// GET `path` with `request_id` as its `x-request-id`; the status.
fn tagged_get(server: &Spawned, path: &str, request_id: &str) -> u16 {
    let request = agent()
        .get(&server.url(path))
        .header("x-request-id", request_id);
    reply(request.call()).status
}

#[test]
fn each_request_is_one_json_log_line_with_its_route_status_latency_and_request_id() {
    let (server, lines) = Spawned::logging(&temp_db("json-log"), &["--log-format", "json"]);
    assert_eq!(
        tagged_get(&server, "/v1/jobs/no-such-job", "json-log-test-1"),
        404
    );
    let line = log_until(&lines, "json-log-test-1").pop().unwrap();
    assert!(!line.contains('\u{1b}'), "no colour codes: {line}");
    let event: Value = serde_json::from_str(&line).expect("one JSON object a line");
    assert_eq!(event["level"], "INFO");
    assert_eq!(event["status"], 404);
    assert!(event["latency_ms"].as_f64().unwrap() >= 0.0, "{event}");
    let request = &event["span"];
    assert_eq!(
        (
            &request["method"],
            &request["route"],
            &request["request_id"]
        ),
        (
            &json!("GET"),
            &json!("/v1/jobs/{id}"),
            &json!("json-log-test-1")
        ),
        "{event}"
    );
    get(&server.url("/healthz"), None);
    let later = log_until(&lines, r#""route":"/healthz""#);
    assert!(
        later.iter().all(|l| !l.contains("json-log-test-1")),
        "one line per request: {later:?}"
    );
}

/// A `RUST_LOG` that does not parse is said on stderr (it was dropped in silence, logging at
/// info as if it were not set).
#[test]
fn a_rust_log_that_does_not_parse_is_said() {
    use std::io::Write;
    let mut simulate = Command::new(BIN)
        .args(["simulate", "-"])
        .env("RUST_LOG", "x=y=z")
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    simulate.stdin.take().unwrap().write_all(b"{}").unwrap();
    let output = simulate.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "{stderr}");
    assert!(stderr.contains("RUST_LOG does not parse"), "{stderr}");
}

#[test]
fn text_logs_on_a_pipe_have_no_colour_and_name_the_request() {
    let (server, lines) = Spawned::logging(&temp_db("text-log"), &[]);
    assert_eq!(tagged_get(&server, "/healthz", "text-log-test-1"), 200);
    let line = log_until(&lines, "text-log-test-1").pop().unwrap();
    assert!(
        !line.contains('\u{1b}'),
        "no colour codes on a pipe: {line}"
    );
    for field in [
        "INFO",
        "method=GET",
        "route=/healthz",
        "status=200",
        "latency_ms=",
    ] {
        assert!(line.contains(field), "{field} in {line}");
    }
}

/// Flags that the server honours otherwise than they read are warned of at start-up.
#[test]
fn flags_honoured_otherwise_than_they_read_are_warned_of() {
    let flags = [
        "--max-queued",
        "5",
        "--max-queued-per-key",
        "8",
        "--retain-days",
        "0",
        "--max-connections",
        "20",
        "--max-streams-per-key",
        "20",
    ];
    let (_server, lines) = Spawned::logging(&temp_db("flag-warnings"), &flags);
    let logged = log_until(&lines, "--max-streams-per-key").join("\n");
    assert!(
        logged.contains("--max-queued-per-key 8 is above --max-queued 5: a key holds at most 5"),
        "{logged}"
    );
    assert!(logged.contains("--retain-days 0"), "{logged}");
    assert!(
        logged.contains("--max-streams-per-key 20 for every client (no API keys) can hold 20"),
        "{logged}"
    );
}

/// The command of the Dockerfile's `HEALTHCHECK ... CMD [...]`, without the binary's name.
fn dockerfile_health_check() -> Vec<String> {
    let dockerfile = include_str!("../Dockerfile");
    let line = dockerfile
        .lines()
        .find(|l| l.starts_with("HEALTHCHECK"))
        .expect("the Dockerfile has a HEALTHCHECK");
    let (_, command) = line.split_once(" CMD ").expect("HEALTHCHECK ... CMD [...]");
    let mut command: Vec<String> = serde_json::from_str(command).expect("the exec form");
    assert_eq!(command.remove(0), "bouncewear", "{line}");
    command
}

#[test]
fn the_images_health_check_passes_against_a_healthy_server_and_fails_without_one() {
    let server = Spawned::start(&temp_db("health"), &[]);
    let check = dockerfile_health_check();
    let healthy = Command::new(BIN)
        .args(&check)
        .env("BOUNCEWEAR_HEALTH_URL", server.url("/healthz"))
        .output()
        .unwrap();
    assert!(healthy.status.success(), "{healthy:?}");
    let health: Value = serde_json::from_slice(&healthy.stdout).unwrap();
    assert_eq!(health["status"], "ok");

    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let nobody = format!("http://127.0.0.1:{port}/healthz");
    let refused = Command::new(BIN)
        .args(&check)
        .env("BOUNCEWEAR_HEALTH_URL", &nobody)
        .output()
        .unwrap();
    assert_eq!(refused.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&refused.stderr).contains(&nobody));

    let not_health = Command::new(BIN)
        .args(&check)
        .env("BOUNCEWEAR_HEALTH_URL", server.url("/no-such/healthz"))
        .output()
        .unwrap();
    assert_eq!(not_health.status.code(), Some(1), "only a 200 is healthy");

    // A server's address, as the remote commands take it, asks its /healthz (it answered the
    // dashboard's page, which passed, printing its HTML); /readyz is asked as given.
    for base in [server.url(""), server.url("/"), server.url("/readyz")] {
        let answered = Command::new(BIN)
            .args(["health", "--url", &base])
            .output()
            .unwrap();
        assert!(answered.status.success(), "{base}: {answered:?}");
        let health: Value = serde_json::from_slice(&answered.stdout).unwrap();
        assert!(
            ["ok", "ready"].contains(&health["status"].as_str().unwrap()),
            "{base}"
        );
    }
}
