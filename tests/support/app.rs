//! The service under test: in-process ([`TestApp`], most tests) or as a child process
//! ([`Spawned`], for what only a process can show: SIGKILL, SIGTERM, start-up refusals).
//! Both take `bouncewear serve`'s flags, bind port 0 and use their own database.

use super::BIN;
use super::client::{get, post};
use bouncewear::app::Application;
use bouncewear::config::ServeConfig;
use clap::Parser;
use serde_json::Value;
use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::sync::mpsc::Receiver;
use std::time::{Duration, Instant};

/// A running service, however it runs.
pub trait Service {
    /// `http://127.0.0.1:PORT`.
    fn base(&self) -> &str;

    fn url(&self, path: &str) -> String {
        format!("{}{path}", self.base())
    }

    /// Submits a job, checks the 202 and its Location, and returns the job's id.
    fn submit(&self, job: &Value) -> String {
        let reply = post(&self.url("/v1/jobs"), &job.to_string(), None);
        assert_eq!(reply.status, 202, "{}", reply.body);
        let id = reply.json()["id"].as_str().unwrap().to_owned();
        assert_eq!(reply.header("location"), Some(&*format!("/v1/jobs/{id}")));
        id
    }

    /// Every job's id, newest first, read page by page through `next_cursor`.
    fn list_job_ids(&self, page_size: u32) -> Vec<String> {
        let mut ids = Vec::new();
        let mut cursor = String::new();
        loop {
            let url = self.url(&format!("/v1/jobs?limit={page_size}{cursor}"));
            let page = get(&url, None).json();
            let jobs = page["jobs"].as_array().unwrap();
            ids.extend(jobs.iter().map(|j| j["id"].as_str().unwrap().to_owned()));
            match page["next_cursor"].as_str() {
                Some(next) => cursor = format!("&cursor={next}"),
                None => return ids,
            }
        }
    }

    /// Asks for the job until it has `status`; returns the job resource. For an end, each
    /// request waits for it (`wait_s`).
    fn wait_for(&self, id: &str, status: &str, timeout: Duration) -> Value {
        let started = Instant::now();
        let ends = ["succeeded", "failed", "cancelled"].contains(&status);
        loop {
            let wait_s = if ends { 5.0 } else { 0.0 };
            let job = get(&self.url(&format!("/v1/jobs/{id}?wait_s={wait_s}")), None).json();
            if job["status"] == status {
                return job;
            }
            let ended = ["succeeded", "failed", "cancelled"]
                .contains(&job["status"].as_str().unwrap_or(""));
            assert!(
                !ended && started.elapsed() < timeout,
                "job {id} is {} after {:?}, waiting for {status}: {job}",
                job["status"],
                started.elapsed()
            );
            std::thread::sleep(Duration::from_millis(50));
        }
    }
}

/// The application on its own runtime in a thread of the test process; dropping it shuts it down
/// as SIGTERM would (running jobs go back to the queue) and waits for that.
pub struct TestApp {
    base: String,
    stop: Option<tokio::sync::oneshot::Sender<()>>,
    thread: Option<std::thread::JoinHandle<()>>,
}

/// `bouncewear serve`'s flags, parsed as the binary parses them.
#[derive(Parser)]
struct Serve {
    #[command(flatten)]
    config: ServeConfig,
}

impl TestApp {
    /// The service on a SQLite file of its own.
    pub fn start(database: &Path, args: &[&str]) -> Self {
        Self::on(&format!("sqlite://{}", database.display()), args)
    }

    /// Runs `job` to success on a service over the SQLite file `database`, then stops it as
    /// SIGTERM would: the job's id.
    pub fn ran(database: &Path, job: &Value) -> String {
        let server = Self::start(database, &[]);
        let id = server.submit(job);
        server.wait_for(&id, "succeeded", Duration::from_secs(60));
        id
    }

    /// The service on the database at `url`, any backend.
    pub fn on(url: &str, args: &[&str]) -> Self {
        let flags = ["serve", "--bind", "127.0.0.1:0", "--database", url];
        let config = Serve::try_parse_from(flags.iter().chain(args))
            .expect("valid flags")
            .config;
        let (address_sender, address) = std::sync::mpsc::channel();
        let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
        let thread = std::thread::spawn(move || {
            let runtime = tokio::runtime::Builder::new_multi_thread()
                .worker_threads(2)
                .enable_all()
                .build()
                .unwrap();
            runtime.block_on(async move {
                let application = Application::build(config)
                    .await
                    .expect("the service starts");
                address_sender.send(application.address()).unwrap();
                application
                    .run_until_stopped(async {
                        let _ = stopped.await;
                    })
                    .await
                    .expect("the service stops cleanly");
            });
        });
        let address = address.recv().expect("the service starts");
        Self {
            base: format!("http://{address}"),
            stop: Some(stop),
            thread: Some(thread),
        }
    }
}

impl Service for TestApp {
    fn base(&self) -> &str {
        &self.base
    }
}

impl Drop for TestApp {
    fn drop(&mut self) {
        if let Some(stop) = self.stop.take() {
            let _ = stop.send(());
        }
        if let Some(thread) = self.thread.take()
            && thread.join().is_err()
            && !std::thread::panicking()
        {
            panic!("the service's thread panicked");
        }
    }
}

fn sqlite_url(database: &Path) -> String {
    format!("sqlite://{}", database.display())
}

/// `bouncewear serve` as a child process; killed when dropped.
pub struct Spawned {
    pub child: Child,
    base: String,
}

impl Spawned {
    pub fn start(database: &Path, args: &[&str]) -> Self {
        Self::on(&sqlite_url(database), args)
    }

    /// A server on the database `url` names (SQLite or PostgreSQL).
    pub fn on(url: &str, args: &[&str]) -> Self {
        let mut command = Self::command(url, args);
        command.env("RUST_LOG", "warn").stderr(Stdio::null());
        Self::spawn(command)
    }

    /// The server logging at info to a pipe, whose lines arrive on the receiver as they are written.
    pub fn logging(database: &Path, args: &[&str]) -> (Self, Receiver<String>) {
        let mut command = Self::command(&sqlite_url(database), args);
        command.env_remove("RUST_LOG").stderr(Stdio::piped());
        let mut server = Self::spawn(command);
        let stderr = server.child.stderr.take().unwrap();
        let (sender, lines) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            for line in BufReader::new(stderr).lines().map_while(Result::ok) {
                let _ = sender.send(line);
            }
        });
        (server, lines)
    }

    fn command(url: &str, args: &[&str]) -> Command {
        let mut command = Command::new(BIN);
        command
            .args(["serve", "--bind", "127.0.0.1:0", "--database", url])
            .args(args)
            .stdout(Stdio::piped());
        command
    }

    fn spawn(mut command: Command) -> Self {
        let mut child = command.spawn().expect("server starts");
        let mut line = String::new();
        BufReader::new(child.stdout.take().unwrap())
            .read_line(&mut line)
            .unwrap();
        let base = line
            .trim()
            .rsplit(' ')
            .next()
            .expect("listening line")
            .to_owned();
        assert!(base.starts_with("http://127.0.0.1:"), "{line}");
        Self { child, base }
    }

    /// SIGKILL: no shutdown handler runs.
    pub fn kill(mut self) {
        self.child.kill().unwrap();
        self.child.wait().unwrap();
    }
}

/// `bouncewear worker` as a child process, running its shards; killed when dropped.
pub struct WorkerProcess {
    pub child: Child,
}

impl WorkerProcess {
    /// Starts a worker on the database `url` names and waits until it runs.
    pub fn start(url: &str, args: &[&str]) -> Self {
        let mut child = Command::new(BIN)
            .args(["worker", "--database", url])
            .args(args)
            .env("RUST_LOG", "warn")
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .expect("worker starts");
        let mut line = String::new();
        BufReader::new(child.stdout.take().unwrap())
            .read_line(&mut line)
            .unwrap();
        assert!(line.starts_with("bouncewear worker running"), "{line}");
        Self { child }
    }

    /// SIGKILL, mid-shard or not: no shutdown handler runs.
    pub fn kill(mut self) {
        self.child.kill().unwrap();
        self.child.wait().unwrap();
    }
}

impl Drop for WorkerProcess {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Service for Spawned {
    fn base(&self) -> &str {
        &self.base
    }
}

impl Drop for Spawned {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}
