//! `bouncewear serve` and `bouncewear worker` configuration: flags, each with an environment variable.

use crate::domain::{QueueBound, RetryBudget, ScheduleBound, ScheduleLimits};
use clap::Args;
use std::net::SocketAddr;
use std::time::Duration;

/// `bouncewear worker`: a process that runs shards from the queue's database, with no API.
#[derive(Debug, Clone, Args)]
pub struct WorkerProcess {
    #[command(flatten)]
    pub config: WorkerConfig,
    /// Serve this process's Prometheus metrics at `http://ADDRESS/metrics` (port 0 picks a free
    /// one, printed at start-up): the jobs it ran, its shards' steps, its process. Without it
    /// they are not served; an API-only `serve --workers 0` has none of them.
    #[arg(long, env = "BOUNCEWEAR_METRICS_BIND")]
    pub metrics_bind: Option<SocketAddr>,
}

/// What every process that runs jobs needs: the queue's database and how to run its jobs. The
/// settings of how shards run (`--max-retries`, `--max-lost-leases`, `--max-listed-lives`) are
/// those of the process that runs each shard: on a shared database, give every worker the same
/// (a `serve --workers 0` runs none, and its own settings of them change nothing).
#[derive(Debug, Clone, Args)]
pub struct WorkerConfig {
    /// Database URL: `sqlite://FILE` (embedded; the file is created if missing) or
    /// `postgres://USER:PASSWORD@HOST/DATABASE` (shared by instances on several machines).
    #[arg(
        long,
        env = "BOUNCEWEAR_DATABASE",
        default_value = "sqlite://bouncewear.db",
        hide_env_values = true
    )]
    pub database: String,
    /// Connections this process keeps to a PostgreSQL database at most, besides one that listens
    /// for announcements. One idle for a minute closes, but a node that polls the queue reuses
    /// its connections in turn and keeps them: count on all of them. PostgreSQL's
    /// `max_connections` must cover every process: (this + 1) for each `serve` and `worker`, plus
    /// whatever else connects (superuser slots aside). SQLite keeps its own (one writer, four
    /// readers).
    #[arg(long, env = "BOUNCEWEAR_DATABASE_CONNECTIONS", default_value_t = 8,
          value_parser = clap::value_parser!(u32).range(2..=1000))]
    pub database_connections: u32,
    /// Shards run at the same time, each on one compute thread (default: one per compute thread);
    /// with `serve`, 0 serves the API without running jobs.
    #[arg(long, env = "BOUNCEWEAR_WORKERS", value_parser = at_most(1024, 0))]
    pub workers: Option<usize>,
    /// Compute threads (default: one per core). Compute never runs on the async runtime. With one,
    /// a merge encodes half its Result's rows on a second thread, as stores encode beside it.
    #[arg(long, env = "BOUNCEWEAR_COMPUTE_THREADS", value_parser = at_most(1024, 1))]
    pub compute_threads: Option<usize>,
    /// How long a claimed job stays leased without a heartbeat before another worker may take it
    /// (from half a second to a year).
    #[arg(long, env = "BOUNCEWEAR_LEASE_SECONDS", default_value_t = 30.0,
          value_parser = lease_seconds_flag)]
    pub lease_seconds: f64,
    /// Times a shard may be run again after its run failed (an error of the job itself), each
    /// after a backoff (1 s, doubling, at most a minute); once more and its job fails with the reason.
    #[arg(long, env = "BOUNCEWEAR_MAX_RETRIES", default_value_t = 3)]
    pub max_retries: u64,
    /// Times a shard may be run again after its lease expired (its worker killed or stalled, or cut
    /// off from the database): counted apart from failed runs, since nothing need be wrong with the
    /// job; once more and it fails with the reason. Also the writes a worker tries again while the
    /// database cannot take them.
    #[arg(long, env = "BOUNCEWEAR_MAX_LOST_LEASES", default_value_t = 10)]
    pub max_lost_leases: u64,
    /// Devices of a job whose own life is kept and listed (`/v1/jobs/{id}/life?format=csv`): the
    /// first ones, in device order. The life analysis counts every device whatever this is. The
    /// worker that runs a job's last merge applies it (with `serve --workers 0`, the workers').
    #[arg(long, env = "BOUNCEWEAR_MAX_LISTED_LIVES", default_value_t = 100_000)]
    pub max_listed_lives: u64,
}

/// The most seconds any flag's time may be: a year.
const MAX_SECONDS: f64 = 365.0 * 24.0 * 3600.0;

/// The fewest seconds a flag's time may be: a millisecond (a zero timeout would refuse everything).
const MIN_SECONDS: f64 = 0.001;

/// The shortest lease: a worker's heartbeat comes every third of one (or every 500 ms, if that
/// is sooner), and each is a database round trip that must land before the lease runs out.
const MIN_LEASE_SECONDS: f64 = 0.5;

/// `url` with its user part, if it has one, written `***`: a message or log line shows a server's
/// or a database's URL (a log collector keeps it), never a password (the remote commands showed
/// it, found from outside). Whatever comes before the last `@` and after the scheme's `//` goes,
/// so that a URL too broken to parse (no scheme, a `/` in the password) loses it too.
pub fn shown_url(url: &str) -> String {
    let Some(at) = url.rfind('@') else {
        return url.to_owned();
    };
    let start = url.find("//").map_or(0, |slashes| slashes + 2).min(at);
    format!("{}***{}", &url[..start], &url[at..])
}

/// Parses a flag's seconds: a number from a millisecond to a year (so that NaN, infinities and
/// values no `Duration` holds are refused by name, exit 2, rather than panicking or never ending;
/// a server's `--header-timeout-seconds 0` read as 1 ms cut off every keep-alive, and 1e-9 was
/// raised to 1 ms without a word).
pub fn seconds_flag(text: &str) -> Result<f64, String> {
    seconds_within(text, MIN_SECONDS)
}

/// Parses `--lease-seconds`: from [`MIN_LEASE_SECONDS`] to a year (a probe's 1e20 panicked, and
/// 0, -1 and NaN became half a second without a word).
fn lease_seconds_flag(text: &str) -> Result<f64, String> {
    seconds_within(text, MIN_LEASE_SECONDS)
}

fn seconds_within(text: &str, least: f64) -> Result<f64, String> {
    let seconds: f64 = text.trim().parse().map_err(|e| format!("{e}"))?;
    if (least..=MAX_SECONDS).contains(&seconds) {
        Ok(seconds)
    } else {
        Err(format!(
            "must be from {least} to {MAX_SECONDS} seconds (a year)"
        ))
    }
}

/// A count flag's parser: from `least` to `most`, else a refusal naming the range (exit 2). A
/// flag with no upper bound took `--workers 100000` and logged 108,731 warnings of its pool in
/// 12 s; one with no lower bound read 0 as 1, or as no bound.
fn at_most(most: u64, least: u64) -> clap::builder::RangedU64ValueParser<usize> {
    clap::builder::RangedU64ValueParser::<usize>::new().range(least..=most)
}

impl WorkerConfig {
    pub fn retry_budget(&self) -> RetryBudget {
        RetryBudget {
            failures: self.max_retries,
            lost_leases: self.max_lost_leases,
        }
    }

    pub fn lease(&self) -> Duration {
        seconds(self.lease_seconds, MIN_LEASE_SECONDS)
    }
}

#[derive(Debug, Clone, Args)]
pub struct ServeConfig {
    /// Address to listen on; port 0 picks a free port (printed at start-up).
    #[arg(long, env = "BOUNCEWEAR_BIND", default_value = "127.0.0.1:8080")]
    pub bind: SocketAddr,
    /// API keys, comma-separated; with keys, every /v1 call needs `Authorization: Bearer KEY`.
    #[arg(
        long = "api-key",
        env = "BOUNCEWEAR_API_KEYS",
        value_delimiter = ',',
        hide_env_values = true
    )]
    pub api_keys: Vec<String>,
    /// Unfinished (queued or running) jobs at most; further submissions get 429 with Retry-After.
    #[arg(long, env = "BOUNCEWEAR_MAX_QUEUED", default_value_t = 1000,
          value_parser = clap::value_parser!(u64).range(1..))]
    pub max_queued: u64,
    /// Unfinished jobs at most per API key (and per schedule's key), so that one key cannot fill the
    /// queue for all (default: half of --max-queued with two keys or more, else all of it).
    #[arg(long, env = "BOUNCEWEAR_MAX_QUEUED_PER_KEY",
          value_parser = clap::value_parser!(u64).range(1..))]
    pub max_queued_per_key: Option<u64>,
    /// Shortest interval between two runs of a schedule, in seconds: a cron expression that fires
    /// more often is refused (422).
    #[arg(
        long,
        env = "BOUNCEWEAR_MIN_SCHEDULE_INTERVAL_SECONDS",
        default_value_t = 3600
    )]
    pub min_schedule_interval_seconds: u64,
    /// Largest job, in operations (devices x operations, with max_devices for a precision target).
    #[arg(
        long,
        env = "BOUNCEWEAR_MAX_JOB_OPERATIONS",
        default_value_t = 2_000_000_000,
        value_parser = clap::value_parser!(u64).range(1..)
    )]
    pub max_job_operations: u64,
    /// Largest request body, in bytes.
    #[arg(long, env = "BOUNCEWEAR_MAX_BODY_BYTES", default_value_t = 1 << 20,
          value_parser = at_most(1 << 30, 1))]
    pub max_body_bytes: usize,
    /// Seconds a connection may take to send a request's headers (and may stay idle between
    /// requests); a client that stalls is disconnected.
    #[arg(
        long,
        env = "BOUNCEWEAR_HEADER_TIMEOUT_SECONDS",
        default_value_t = 10.0,
        value_parser = seconds_flag
    )]
    pub header_timeout_seconds: f64,
    /// Seconds a request may take to send its whole body; later, 408.
    #[arg(long, env = "BOUNCEWEAR_BODY_TIMEOUT_SECONDS", default_value_t = 30.0,
          value_parser = seconds_flag)]
    pub body_timeout_seconds: f64,
    /// Seconds a request may take until its response starts (waiting for a slot included);
    /// later, 503. An event stream, once started, runs as long as its job.
    #[arg(
        long,
        env = "BOUNCEWEAR_REQUEST_TIMEOUT_SECONDS",
        default_value_t = 60.0,
        value_parser = seconds_flag
    )]
    pub request_timeout_seconds: f64,
    /// Requests handled at the same time; more wait for a slot (within the request timeout).
    #[arg(
        long,
        env = "BOUNCEWEAR_MAX_CONCURRENT_REQUESTS",
        default_value_t = 256,
        value_parser = at_most(1 << 20, 1)
    )]
    pub max_concurrent_requests: usize,
    /// Open connections at most; more wait in the listen backlog. Never more than the process's
    /// open-file limit (RLIMIT_NOFILE) less what the database and the process need (default: that).
    #[arg(long, env = "BOUNCEWEAR_MAX_CONNECTIONS", value_parser = at_most(1 << 20, 1))]
    pub max_connections: Option<usize>,
    /// Event streams (`/v1/events`, `/v1/jobs/{id}/events`) one API key may hold open at once
    /// (without API keys: all clients together); more get 429 with Retry-After.
    #[arg(long, env = "BOUNCEWEAR_MAX_STREAMS_PER_KEY", default_value_t = 64,
          value_parser = at_most(1 << 20, 1))]
    pub max_streams_per_key: usize,
    /// Schedules one API key may hold (without API keys: all clients together); another gets 403
    /// until one is deleted.
    #[arg(
        long,
        env = "BOUNCEWEAR_MAX_SCHEDULES_PER_KEY",
        default_value_t = 100,
        value_parser = clap::value_parser!(u64).range(1..)
    )]
    pub max_schedules_per_key: u64,
    /// Bytes, in MB, of responses of 64 KB or more held in memory at once until their clients
    /// read them; another waits up to 10 s for room, then gets 503 with Retry-After (one larger
    /// than this is served alone).
    #[arg(
        long,
        env = "BOUNCEWEAR_MAX_RESPONSE_MB",
        default_value_t = 512,
        value_parser = clap::value_parser!(u64).range(1..)
    )]
    pub max_response_mb: u64,
    /// Free disk space, in MB, beside a SQLite database below which the server reports itself not
    /// ready (`/readyz` answers 503).
    #[arg(long, env = "BOUNCEWEAR_MIN_FREE_DISK_MB", default_value_t = 100,
          value_parser = clap::value_parser!(u64).range(..=1_000_000_000_000))]
    pub min_free_disk_mb: u64,
    /// Bytes, in MB, that the jobs of one API key (and of its schedules) may store: a key whose
    /// jobs store this much or more gets 403 for a new job until it deletes some (a job's
    /// `stored_bytes`). Without it, no bound but the disk's.
    #[arg(
        long,
        env = "BOUNCEWEAR_MAX_STORED_MB_PER_KEY",
        value_parser = clap::value_parser!(u64).range(1..)
    )]
    pub max_stored_mb_per_key: Option<u64>,
    /// Delete finished jobs, with everything stored for them, this many days after they ended
    /// (checked at start-up and every hour). Without it, they stay until deleted.
    #[arg(long, env = "BOUNCEWEAR_RETAIN_DAYS",
          value_parser = clap::value_parser!(u32).range(..=36_500))]
    pub retain_days: Option<u32>,
    #[command(flatten)]
    pub queue: WorkerConfig,
}

/// Seconds from a flag, at least `least` and at most a year (later deadlines overflow the clock):
/// the parsers refuse what lies outside, and a configuration built in code is held to it too.
fn seconds(value: f64, least: f64) -> Duration {
    const YEAR: Duration = Duration::from_secs(365 * 86_400);
    Duration::try_from_secs_f64(value.max(least)).map_or(YEAR, |d| d.min(YEAR))
}

impl ServeConfig {
    pub fn header_timeout(&self) -> Duration {
        seconds(self.header_timeout_seconds, MIN_SECONDS)
    }

    pub fn body_timeout(&self) -> Duration {
        seconds(self.body_timeout_seconds, MIN_SECONDS)
    }

    pub fn request_timeout(&self) -> Duration {
        seconds(self.request_timeout_seconds, MIN_SECONDS)
    }

    /// Requests that may wait for a job's end at once (`wait_s`): a quarter of the request slots,
    /// so that waiting never takes the slots other requests need.
    pub fn max_waits(&self) -> usize {
        (self.max_concurrent_requests / 4).max(1)
    }

    /// The longest a request waits for a job's end: half the request timeout, so that a wait
    /// ends with the job as it is rather than a 503.
    pub fn max_wait(&self) -> Duration {
        self.request_timeout() / 2
    }

    /// What a schedule may ask for: each run's size, and how often it runs.
    pub fn schedule_limits(&self) -> ScheduleLimits {
        ScheduleLimits {
            max_job_operations: self.max_job_operations,
            min_interval: i64::try_from(self.min_schedule_interval_seconds)
                .ok()
                .and_then(chrono::TimeDelta::try_seconds)
                .unwrap_or(chrono::TimeDelta::MAX),
        }
    }

    /// The queue's bound: `--max-queued` in all, and each key's share.
    /// How many schedules one owner may hold, and the free disk a new one needs.
    pub fn schedule_bound(&self) -> ScheduleBound {
        ScheduleBound {
            per_owner: self.max_schedules_per_key,
            min_free_disk_bytes: self.min_free_disk_bytes(),
        }
    }

    pub fn queue_bound(&self) -> QueueBound {
        let share = if self.api_keys.len() >= 2 {
            self.max_queued.div_ceil(2)
        } else {
            self.max_queued
        };
        QueueBound {
            total: self.max_queued,
            per_owner: self
                .max_queued_per_key
                .unwrap_or(share)
                .min(self.max_queued),
            min_free_disk_bytes: self.min_free_disk_bytes(),
            stored_per_owner: self.max_stored_mb_per_key.map(bytes_of_mb),
        }
    }

    pub fn min_free_disk_bytes(&self) -> u64 {
        bytes_of_mb(self.min_free_disk_mb)
    }
}

/// The bytes of a flag given in MB (MiB), saturating.
fn bytes_of_mb(mb: u64) -> u64 {
    mb.saturating_mul(1 << 20)
}
