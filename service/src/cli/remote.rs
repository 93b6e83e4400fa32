//! The commands that talk to a running server: `submit`, `status`, `wait`, `fetch`, `compare`,
//! `cancel`. They print what the API answers as it is (JSON, or CSV where asked) on stdout, and
//! exit as the local commands do: 0 when done, 2 when the server refuses the input (its problem's
//! errors, each with its JSON pointer, on stderr), 1 for anything else (unreachable, a job that
//! failed, 5xx).

use super::{CliError, read_input};
use bouncewear_model::{FieldError, InvalidInput};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};
use ureq::tls::{PemItem, RootCerts, TlsConfig};

/// The server a remote command talks to.
#[derive(Debug, Clone, clap::Args)]
pub struct Server {
    /// The server's base URL.
    #[arg(
        long,
        env = "BOUNCEWEAR_URL",
        default_value = "http://127.0.0.1:8080",
        global = true,
        hide_env_values = true
    )]
    pub url: String,
    /// The API key, when the server has keys.
    #[arg(
        long,
        env = "BOUNCEWEAR_API_KEY",
        hide_env_values = true,
        global = true
    )]
    pub api_key: Option<String>,
    /// Seconds one request may take.
    #[arg(long, default_value_t = 60.0, global = true, value_parser = seconds)]
    pub request_timeout_seconds: f64,
    /// Times a request is sent again after a 429 or 503 (after the server's `Retry-After`, at
    /// most a minute) or a connection refused, reset or cut short (after 0.5, 1, 2, ... s); 0
    /// sends it once. `submit` sends an `Idempotency-Key`, so a retry never queues the job twice.
    #[arg(long, default_value_t = 3, global = true, value_parser = clap::value_parser!(u32).range(..=100))]
    pub retries: u32,
    /// For an `https` URL: a PEM file of the CA certificates to trust instead of the Mozilla
    /// roots built in (a company's own CA, say).
    #[arg(long, env = "BOUNCEWEAR_CA_CERT", global = true, value_name = "PEM")]
    pub ca_cert: Option<PathBuf>,
    /// `--ca-cert`'s certificates, read at the first request (`wait` sends one every 10 s).
    #[arg(skip)]
    pub roots: std::sync::OnceLock<RootCerts>,
}

/// A server's base URL as `--url` takes it, the API's paths added to it: `http` or `https`, a
/// host, a port from 1 to 65535, and no query or fragment. A bad one is a bad command line
/// (exit 2) naming the flag, checked before the first request rather than by clap, whose
/// message repeats the value, password and all; it was exit 1 with "http: invalid format", or
/// a query string that sent every request to the dashboard (found from outside).
pub(super) fn check_base_url(text: &str) -> Result<(), String> {
    let uri: ureq::http::Uri = text
        .parse()
        .map_err(|error| format!("not a URL such as http://127.0.0.1:8080 ({error})"))?;
    match uri.scheme_str() {
        Some("http" | "https") => {}
        Some(other) => return Err(format!("the scheme must be http or https, got {other}")),
        None => return Err("no scheme: write http://HOST:PORT (or https://)".to_owned()),
    }
    if uri.host().is_none_or(str::is_empty) {
        return Err("no host: write http://HOST:PORT (or https://)".to_owned());
    }
    // The port as written: `Uri` takes 99999 and the request went to another port.
    let authority = uri.authority().map_or("", |a| a.as_str());
    let host_and_port = authority
        .rsplit_once('@')
        .map_or(authority, |(_, rest)| rest);
    let port = host_and_port
        .rsplit_once(':')
        .filter(|(host, _)| !host.starts_with('[') || host.ends_with(']'))
        .map(|(_, port)| port);
    let in_range = |port: &str| {
        port.bytes().all(|b| b.is_ascii_digit()) && port.parse::<u16>().is_ok_and(|p| p > 0)
    };
    if port.is_some_and(|port| !in_range(port)) {
        return Err("the port must be from 1 to 65535".to_owned());
    }
    if uri.query().is_some() || text.contains('#') {
        return Err(
            "a base URL has no query or fragment: the API's paths are added to it".to_owned(),
        );
    }
    Ok(())
}

/// The longest pause before a retry, whatever `Retry-After` asks.
const MAX_RETRY_PAUSE: Duration = Duration::from_secs(60);

/// What `fetch` gets of a job.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Part {
    /// The Result (409 until the job succeeded).
    Result,
    /// The life analysis (JSON) or each device's life (CSV).
    Life,
    /// The rare event's estimate (JSON) or its tail curve (CSV).
    RareEvent,
    /// The shards the job runs as.
    Shards,
}

/// The longest one of `wait`'s requests waits for the job's end (`wait_s`): well within the
/// server's and the client's request timeouts.
const WAIT_PER_REQUEST: f64 = 10.0;
/// The least time between two of `wait`'s requests, should a server answer at once anyway.
const POLL: Duration = Duration::from_millis(200);
/// How long past a deadline (`wait`'s timeout) the answer to a request is awaited: a server
/// asked to wait all the time left answers just after it. With the deadline as the request's
/// own, 1 wait in 10 read as "no answer within --request-timeout-seconds"; with the last
/// request asked to answer a quarter second early, a job that ended in that quarter second was
/// told as still running (both found from outside).
const ANSWER_GRACE: Duration = Duration::from_secs(1);

pub use crate::config::seconds_flag as seconds;

/// An HTTP client whose every request ends within `timeout_seconds`, and which hands any status
/// back to the caller (a 4xx or 5xx is an answer, not an error of the client). It speaks `http`
/// and `https`, trusting `roots` (else the Mozilla roots built in).
pub fn agent(timeout_seconds: f64, roots: Option<RootCerts>) -> ureq::Agent {
    let tls = TlsConfig::builder().root_certs(roots.unwrap_or(RootCerts::WebPki));
    ureq::Agent::config_builder()
        .http_status_as_error(false)
        .timeout_global(Some(Duration::from_secs_f64(timeout_seconds.max(0.001))))
        .tls_config(tls.build())
        .build()
        .into()
}

/// The certificates of a PEM file, for `--ca-cert`: exit 2 for a file that cannot be read or
/// holds none.
pub fn trusted(path: &Path) -> Result<RootCerts, CliError> {
    let text = read_input(path).map_err(|e| CliError::Usage(format!("--ca-cert {e}")))?;
    let certificates = ureq::tls::parse_pem(text.as_bytes())
        .filter_map(|item| match item {
            Ok(PemItem::Certificate(certificate)) => Some(Ok(certificate)),
            Ok(_) => None,
            Err(error) => Some(Err(error)),
        })
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| CliError::Usage(format!("--ca-cert {}: {e}", path.display())))?;
    if certificates.is_empty() {
        return Err(CliError::Usage(format!(
            "--ca-cert {}: no PEM certificate (-----BEGIN CERTIFICATE-----) in it",
            path.display()
        )));
    }
    Ok(RootCerts::new_with_certs(&certificates))
}

impl Server {
    /// The request with the key, when there is one, asking for a gzipped answer: a 1000-bin
    /// Result is 9.9 MB as JSON and about 110 kB gzipped.
    fn prepare<B>(&self, request: ureq::RequestBuilder<B>) -> ureq::RequestBuilder<B> {
        let request = request.header("accept-encoding", "gzip");
        match &self.api_key {
            Some(key) => request.header("authorization", &format!("Bearer {key}")),
            None => request,
        }
    }

    fn url(&self, path: &str) -> String {
        format!("{}{path}", self.url.trim_end_matches('/'))
    }

    /// Sends a request, again up to `--retries` times while the server is busy (429, 503), the
    /// connection fails or no answer came within `--request-timeout-seconds`; the body of a 2xx,
    /// or the failure the answer means. Every request of
    /// the remote commands may be sent again: reads and cancels change nothing the second time,
    /// and a submission carries an `Idempotency-Key`, the same on every try.
    fn send(&self, method: &str, path: &str, body: Option<&str>) -> Result<String, CliError> {
        self.send_by(method, path, body, None)
    }

    /// [`Server::send`], giving up rather than pausing past `deadline`.
    fn send_by(
        &self,
        method: &str,
        path: &str,
        body: Option<&str>,
        deadline: Option<Instant>,
    ) -> Result<String, CliError> {
        let key = (method == "POST" && ["/v1/jobs", "/v1/schedules"].contains(&path))
            .then(submission_key);
        self.send_keyed(method, path, body, deadline, key)
    }

    /// [`Server::send_by`] with the submission's `Idempotency-Key`, if it is one.
    fn send_keyed(
        &self,
        method: &str,
        path: &str,
        body: Option<&str>,
        deadline: Option<Instant>,
        key: Option<String>,
    ) -> Result<String, CliError> {
        let mut retried = 0;
        loop {
            let failure = match self.send_once(method, path, body, key.as_deref(), deadline) {
                Ok(text) => return Ok(text),
                Err(failure) => failure,
            };
            let (pause, why) = match &failure {
                Failure::Final(_) => return Err(failure.into_error()),
                Failure::Busy {
                    status,
                    retry_after,
                    ..
                } => (
                    retry_after.unwrap_or(Duration::from_secs(1)),
                    format!("{status} from the server"),
                ),
                Failure::Broken(error) => (
                    Duration::from_millis(500) * 2u32.pow(retried.min(7)),
                    error.clone(),
                ),
            };
            let pause = pause.min(MAX_RETRY_PAUSE);
            let past_deadline = deadline.is_some_and(|end| Instant::now() + pause > end);
            if retried == self.retries || past_deadline {
                return Err(match (failure, &key) {
                    // The server may have queued it: the key gives that job back to a retry.
                    (Failure::Broken(error), Some(key)) => CliError::Failed(format!(
                        "{error} (the submission's Idempotency-Key was {key}: it may have been \
                         created; `GET {path}` lists it)"
                    )),
                    (failure, _) => failure.into_error(),
                });
            }
            retried += 1;
            // A log line, in the process's `--log-format`.
            tracing::warn!(
                "{why}; again in {:.1} s ({retried} of {})",
                pause.as_secs_f64(),
                self.retries
            );
            std::thread::sleep(pause);
        }
    }

    /// The roots `--ca-cert` names, read once; none without it (the Mozilla roots then).
    fn trusted_roots(&self) -> Result<Option<RootCerts>, CliError> {
        let Some(path) = self.ca_cert.as_deref() else {
            return Ok(None);
        };
        if let Some(roots) = self.roots.get() {
            return Ok(Some(roots.clone()));
        }
        let roots = trusted(path)?;
        Ok(Some(self.roots.get_or_init(|| roots).clone()))
    }

    /// Sends a request once, to be answered within `--request-timeout-seconds` and
    /// [`ANSWER_GRACE`] after `deadline`: the body of a 2xx, or why not.
    fn send_once(
        &self,
        method: &str,
        path: &str,
        body: Option<&str>,
        idempotency_key: Option<&str>,
        deadline: Option<Instant>,
    ) -> Result<String, Failure> {
        // A key that no header can carry (a newline, a letter beyond ASCII) is the command
        // line's fault; the key is not repeated (it failed each request with the HTTP
        // library's "failed to parse header value").
        if let Some(key) = &self.api_key
            && (key.trim() != key
                || key.is_empty()
                || key.chars().any(|c| !(c == ' ' || c.is_ascii_graphic())))
        {
            return Err(Failure::Final(CliError::Usage(
                "--api-key (BOUNCEWEAR_API_KEY): a key is printable ASCII, not empty and with \
                 no space at either end, and the one given is not"
                    .to_owned(),
            )));
        }
        check_base_url(&self.url).map_err(|rule| {
            let url = crate::config::shown_url(&self.url);
            Failure::Final(CliError::Usage(format!(
                "--url (BOUNCEWEAR_URL) {url}: {rule}"
            )))
        })?;
        let url = self.url(path);
        let shown = crate::config::shown_url(&url);
        let left = deadline.map_or(f64::INFINITY, |end| {
            (end + ANSWER_GRACE)
                .saturating_duration_since(Instant::now())
                .as_secs_f64()
        });
        let agent = agent(
            self.request_timeout_seconds.min(left),
            self.trusted_roots().map_err(Failure::Final)?,
        );
        // A body waits for the server's 100 Continue: a body over its limit is refused (413)
        // before any of it is sent, where writing it all gave a broken pipe instead of the answer
        // (once the server had answered and closed), at random, past about a megabyte.
        let json = |request: ureq::RequestBuilder<ureq::typestate::WithBody>| {
            self.prepare(request)
                .header("content-type", "application/json")
                .header("expect", "100-continue")
        };
        let sent = match (method, body) {
            ("POST", Some(body)) => {
                let request = json(agent.post(&url));
                match idempotency_key {
                    Some(key) => request.header("idempotency-key", key).send(body),
                    None => request.send(body),
                }
            }
            ("POST", None) => self.prepare(agent.post(&url)).send_empty(),
            ("PUT", Some(body)) => json(agent.put(&url)).send(body),
            ("DELETE", _) => self.prepare(agent.delete(&url)).call(),
            _ => self.prepare(agent.get(&url)).call(),
        };
        let failed = |error: &ureq::Error| Failure::of(&shown, error);
        let mut response = sent.map_err(|e| failed(&e))?;
        let status = response.status().as_u16();
        let header = |name: &str| {
            let value = response.headers().get(name)?;
            value.to_str().ok().map(str::to_owned)
        };
        let retry_after = header("retry-after").and_then(|value| seconds_to_wait(&value));
        let gzipped = header("content-encoding").is_some_and(|c| c.eq_ignore_ascii_case("gzip"));
        let bytes = response
            .body_mut()
            .with_config()
            .limit(u64::MAX)
            .read_to_vec()
            .map_err(|e| failed(&e))?;
        let unreadable = |e: String| Failure::Final(CliError::Failed(format!("{shown}: {e}")));
        let text = if gzipped {
            let mut text = String::new();
            std::io::Read::read_to_string(&mut flate2::read::GzDecoder::new(&bytes[..]), &mut text)
                .map_err(|e| unreadable(format!("the gzipped answer: {e}")))?;
            text
        } else {
            String::from_utf8(bytes).map_err(|e| unreadable(format!("the answer: {e}")))?
        };
        match status {
            200..=299 => Ok(text),
            429 | 503 => Err(Failure::Busy {
                retry_after,
                refused: refused(status, &shown, &text),
                status,
            }),
            _ => Err(Failure::Final(refused(status, &shown, &text))),
        }
    }

    fn job(&self, id: &str) -> Result<serde_json::Value, CliError> {
        parse(&self.send("GET", &format!("/v1/jobs/{}", encode(id)), None)?)
    }

    /// The job once it ended, or as it is after `wait_s` seconds (the server's `wait_s`), asked
    /// again while the server is busy but not past `deadline`.
    fn job_within(
        &self,
        id: &str,
        wait_s: f64,
        deadline: Option<Instant>,
    ) -> Result<serde_json::Value, CliError> {
        let path = format!("/v1/jobs/{}?wait_s={wait_s}", encode(id));
        parse(&self.send_by("GET", &path, None, deadline)?)
    }
}

/// Why a request has no answer to print.
enum Failure {
    /// The server is busy (429, 503): worth asking again after `retry_after`, its `Retry-After`
    /// in seconds where it gave one; `refused` is the failure should it stay busy.
    Busy {
        status: u16,
        retry_after: Option<Duration>,
        refused: CliError,
    },
    /// No connection, or one the server closed or reset before the whole answer: worth trying
    /// again.
    Broken(String),
    /// An answer, or a fault, that another try would not change.
    Final(CliError),
}

impl Failure {
    /// What `error` of a request to `url` means. A pipe broken while the request is written is
    /// final: the server closed it having answered already (a 413 for a body over its limit),
    /// and writing the body again would end the same way.
    fn of(url: &str, error: &ureq::Error) -> Self {
        use std::io::ErrorKind::{
            ConnectionAborted, ConnectionRefused, ConnectionReset, NotConnected, UnexpectedEof,
        };
        let broken = match error {
            // No answer in time: a read asks again, a submission sends its key again.
            ureq::Error::ConnectionFailed | ureq::Error::Timeout(_) => true,
            ureq::Error::Io(io) => matches!(
                io.kind(),
                ConnectionRefused
                    | ConnectionReset
                    | ConnectionAborted
                    | NotConnected
                    | UnexpectedEof
            ),
            _ => false,
        };
        let said = match error {
            ureq::Error::Timeout(_) => format!(
                "{url}: no answer within --request-timeout-seconds (or what --timeout-seconds left)"
            ),
            _ if error.to_string().contains("invalid peer certificate") => format!(
                "{url}: {error} (a server whose certificate a CA of your own signed: --ca-cert)"
            ),
            _ => format!("{url}: {error}"),
        };
        if broken {
            Failure::Broken(said)
        } else {
            Failure::Final(CliError::Failed(said))
        }
    }

    fn into_error(self) -> CliError {
        match self {
            Failure::Busy { refused, .. } => refused,
            Failure::Broken(error) => CliError::Failed(error),
            Failure::Final(error) => error,
        }
    }
}

/// A `Retry-After` value as a pause: seconds, or an HTTP date (RFC 9110 10.2.3, as some proxies
/// send it) counted from now, never below 0.
fn seconds_to_wait(value: &str) -> Option<Duration> {
    let value = value.trim();
    if let Ok(seconds) = value.parse::<u64>() {
        return Some(Duration::from_secs(seconds));
    }
    let when = chrono::DateTime::parse_from_rfc2822(value).ok()?;
    let left = when.with_timezone(&chrono::Utc) - chrono::Utc::now();
    Some(left.to_std().unwrap_or(Duration::ZERO))
}

/// The failure a non-2xx answer means: the input's (exit 2) for 400, 413, 415 and 422, each error
/// of a 400 or 422 with its pointer; anything else exit 1, with the problem's detail.
fn refused(status: u16, url: &str, body: &str) -> CliError {
    let problem: serde_json::Value = serde_json::from_str(body).unwrap_or_default();
    let detail = problem["detail"].as_str().unwrap_or(body).to_owned();
    let errors: Vec<FieldError> = problem["errors"]
        .as_array()
        .into_iter()
        .flatten()
        .filter_map(|e| {
            Some(FieldError {
                pointer: e["pointer"].as_str()?.to_owned(),
                detail: e["detail"].as_str()?.to_owned(),
            })
        })
        .collect();
    match status {
        400 | 422 if !errors.is_empty() => CliError::Invalid(InvalidInput::new(errors)),
        // A fault of no field: a query parameter the command's flags made (`--statistics`).
        400 => CliError::Usage(format!("{status}: {detail}")),
        413 | 415 | 422 => CliError::Invalid(InvalidInput::single(
            &bouncewear_model::Pointer::root(),
            format!("{status}: {detail}"),
        )),
        _ => CliError::Failed(format!("{url}: {status} {detail}")),
    }
}

fn parse(text: &str) -> Result<serde_json::Value, CliError> {
    serde_json::from_str(text).map_err(|e| {
        // What came instead, a proxy's or a sign-in page perhaps (it said only "expected value
        // at line 1 column 1", an outside probe).
        let start: String = text.chars().take(120).collect();
        CliError::Failed(format!(
            "the server's answer is not the JSON expected ({e}): {start:?}"
        ))
    })
}

fn id_of(job: &serde_json::Value) -> Result<String, CliError> {
    job["id"]
        .as_str()
        .map(str::to_owned)
        .ok_or_else(|| CliError::Failed(format!("the server's answer names no job: {job}")))
}

/// `submit`: queues the job in `file`; prints the job resource, or with `wait` the Result once it
/// succeeded. `timeout` counts from the start: the submission's retries, the wait and the
/// Result's fetch pause no later than it.
pub fn submit(
    server: &Server,
    file: &std::path::Path,
    wait: bool,
    timeout: Option<f64>,
) -> Result<String, CliError> {
    let deadline = deadline_after(timeout);
    let body = read_input(file)?;
    let key = submission_key();
    let interrupt = OnInterrupt::listen(format!(
        "interrupted before the server answered: the job may have been queued (the submission's \
         Idempotency-Key was {key}; `GET /v1/jobs` lists your jobs)"
    ));
    let sent = server.send_keyed("POST", "/v1/jobs", Some(&body), deadline, Some(key))?;
    let job = parse(&sent)?;
    if !wait {
        return Ok(job.to_string());
    }
    let id = id_of(&job)?;
    if let Some(interrupt) = &interrupt {
        interrupt.tell(
            job.to_string(),
            format!(
                "interrupted: job {id} goes on; `bouncewear wait {id}` waits for it, \
                 `bouncewear cancel {id}` cancels it"
            ),
        );
    }
    wait_until(server, &id, deadline)?;
    let text = server.send_by("GET", &part_path(&id, Part::Result, ""), None, deadline)?;
    Ok(text.trim_end().to_owned())
}

/// A fresh `Idempotency-Key` for one submission, the same on every try of it.
fn submission_key() -> String {
    format!("cli-{}", uuid::Uuid::new_v4().simple())
}

/// What an interrupt (Ctrl-C) says from [`OnInterrupt::listen`] until the process ends: the job
/// resource `submit` queued on stdout once it is known, and on stderr what became of the job and
/// how to follow it; then exit 130, as an interrupted command does. Without, the interrupt ended
/// the command with nothing printed, and a script lost the id of the job it had queued (an
/// outside probe), or, before the server answered, the key that finds it.
struct OnInterrupt(std::sync::Arc<std::sync::Mutex<(Option<String>, String)>>);

impl OnInterrupt {
    /// Listening before this returns, so that an interrupt from here on is ours (telling
    /// `stderr`); waited for on a thread of its own while this one waits on the server.
    fn listen(stderr: String) -> Option<Self> {
        let runtime = tokio::runtime::Builder::new_current_thread()
            .enable_io()
            .build()
            .ok()?;
        #[cfg(unix)]
        let mut interrupts = {
            let _entered = runtime.enter();
            tokio::signal::unix::signal(tokio::signal::unix::SignalKind::interrupt()).ok()?
        };
        let told = std::sync::Arc::new(std::sync::Mutex::new((None::<String>, stderr)));
        let tell = std::sync::Arc::clone(&told);
        std::thread::spawn(move || {
            #[cfg(unix)]
            runtime.block_on(interrupts.recv());
            #[cfg(not(unix))]
            if runtime.block_on(tokio::signal::ctrl_c()).is_err() {
                return;
            }
            let (stdout, stderr) = &*tell.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
            if let Some(stdout) = stdout {
                let _ = super::print_text(stdout.clone());
            }
            super::stderr_line(format_args!("{stderr}"));
            std::process::exit(130);
        });
        Some(Self(told))
    }

    /// From now on, an interrupt prints `stdout` and tells `stderr`.
    fn tell(&self, stdout: String, stderr: String) {
        *self
            .0
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner()) = (Some(stdout), stderr);
    }
}

/// The moment `timeout` seconds from now, if given.
fn deadline_after(timeout: Option<f64>) -> Option<Instant> {
    let now = Instant::now();
    timeout.map(|t| now + Duration::from_secs_f64(t.clamp(0.0, 1e9)))
}

/// `status`: the job resource.
pub fn status(server: &Server, id: &str) -> Result<String, CliError> {
    Ok(server.job(id)?.to_string())
}

/// `wait`: asks until the job ended; the final job resource when it succeeded; when it failed or
/// was cancelled, the job resource too, and exit 1 with its error; when `timeout` seconds passed
/// first, the job resource as it was then, and exit 1.
pub fn wait_for(server: &Server, id: &str, timeout: Option<f64>) -> Result<String, CliError> {
    wait_until(server, id, deadline_after(timeout))
}

/// [`wait_for`] until `deadline` rather than for a number of seconds.
fn wait_until(server: &Server, id: &str, deadline: Option<Instant>) -> Result<String, CliError> {
    let started = Instant::now();
    loop {
        let left = deadline.map_or(WAIT_PER_REQUEST, |end| {
            end.saturating_duration_since(Instant::now()).as_secs_f64()
        });
        let wait_s = left
            .min(WAIT_PER_REQUEST)
            .min(server.request_timeout_seconds / 2.0)
            .max(0.0);
        let asked = Instant::now();
        let job = server.job_within(id, wait_s, deadline)?;
        match job["status"].as_str() {
            Some("succeeded") => return Ok(job.to_string()),
            Some(ended @ ("failed" | "cancelled")) => {
                let error = job["error"].as_str().unwrap_or("no reason given");
                return Err(CliError::Ended {
                    reason: format!("job {id} {ended}: {error}"),
                    job: job.to_string(),
                });
            }
            _ => {}
        }
        // The job as read at the timeout or after: the last request waits until then.
        if deadline.is_some_and(|end| Instant::now() >= end) {
            return Err(CliError::Ended {
                reason: format!(
                    "job {id} is still {} after {:.1} s",
                    job["status"].as_str().unwrap_or("?"),
                    started.elapsed().as_secs_f64()
                ),
                job: job.to_string(),
            });
        }
        // A server that did not wait (all its places taken) is asked again after a pause, never
        // past the timeout.
        let left = deadline.map_or(POLL, |end| end.saturating_duration_since(Instant::now()));
        std::thread::sleep(POLL.saturating_sub(asked.elapsed()).min(left));
    }
}

/// `fetch`: a part of a job, as the API serves it (`csv` where the part has a CSV form).
pub fn fetch(server: &Server, id: &str, part: Part, csv: bool) -> Result<String, CliError> {
    let path = part_name(part);
    let format = match (csv, part) {
        (false, _) => "",
        (true, Part::Life | Part::RareEvent) => "?format=csv",
        (true, _) => {
            return Err(CliError::Usage(format!(
                "--csv: `{path}` has no CSV form (`life` and `rare-event` have one)"
            )));
        }
    };
    if matches!(part, Part::Shards) {
        return all_shards(server, id);
    }
    let text = server.send("GET", &part_path(id, part, format), None)?;
    Ok(text.trim_end().to_owned())
}

/// Every shard of job `id`, read page by page (the API serves at most 1000 a page) and printed as
/// one list: a job of one page as the API answers, the pages of a larger one joined.
fn all_shards(server: &Server, id: &str) -> Result<String, CliError> {
    let mut shards = Vec::new();
    let mut query = String::new();
    loop {
        let text = server.send("GET", &part_path(id, Part::Shards, &query), None)?;
        let mut page = parse(&text)?;
        if query.is_empty() && page.get("next_cursor").is_none() {
            return Ok(text.trim_end().to_owned());
        }
        match page["shards"].take() {
            serde_json::Value::Array(page) => shards.extend(page),
            _ => return Err(CliError::Failed(format!("the server's answer: {text}"))),
        }
        match page["next_cursor"].as_str() {
            Some(cursor) => query = format!("?cursor={}", encode(cursor)),
            None => break,
        }
    }
    Ok(serde_json::json!({ "shards": shards }).to_string())
}

/// The path of `part` of job `id`, with `format` (a query string, or empty) after it.
fn part_path(id: &str, part: Part, format: &str) -> String {
    format!("/v1/jobs/{}/{}{format}", encode(id), part_name(part))
}

/// The last segment of `part`'s path.
fn part_name(part: Part) -> &'static str {
    match part {
        Part::Result => "result",
        Part::Life => "life",
        Part::RareEvent => "rare_event",
        Part::Shards => "shards",
    }
}

/// What `compare` asks of the comparison; `None` takes the server's default.
pub struct Compared {
    pub metric: Option<String>,
    pub statistics: Option<String>,
    pub b_lives: Option<String>,
}

/// `compare`: job `a` against job `b`, the comparison as the API serves it; with `plots`, the
/// overlaid wear curves (and Weibull plots, when both jobs have failure criteria) written there.
pub fn compare(
    server: &Server,
    [a, b]: [&str; 2],
    asked: &Compared,
    plots: Option<&Path>,
) -> Result<String, CliError> {
    let mut query: Vec<String> = Vec::new();
    for (name, value) in [
        ("metric", &asked.metric),
        ("statistics", &asked.statistics),
        ("b_lives", &asked.b_lives),
    ] {
        if let Some(value) = value {
            query.push(format!("{name}={}", encode(value)));
        }
    }
    let query = if query.is_empty() {
        String::new()
    } else {
        format!("?{}", query.join("&"))
    };
    let this = format!("/v1/jobs/{}/compare/{}", encode(a), encode(b));
    let text = server.send("GET", &format!("{this}{query}"), None)?;
    // The directory is made and tried before the request (`--plots`, exit 2).
    if let Some(dir) = plots {
        // The plots the comparison links to: `null` where it has none.
        let comparison = parse(&text)?;
        let links = &comparison["links"];
        if links["bands"].is_null() {
            tracing::warn!(
                "--plots: no bands.svg: {} is a device metric, one value a device, with no wear \
                 curve",
                asked.metric.as_deref().unwrap_or_default()
            );
        }
        for kind in ["bands", "weibull"] {
            let Some(link) = links[kind].as_str() else {
                continue;
            };
            let svg = server.send("GET", link, None)?;
            let path = dir.join(format!("{kind}.svg"));
            std::fs::write(&path, svg).map_err(|source| CliError::Write {
                path: path.display().to_string(),
                source,
            })?;
        }
    }
    Ok(text.trim_end().to_owned())
}

/// `text` with everything but unreserved characters and commas percent-encoded, for a path
/// segment or a query value.
fn encode(text: &str) -> String {
    text.bytes()
        .map(|byte| match byte {
            b'A'..=b'Z' | b'a'..=b'z' | b'0'..=b'9' | b'-' | b'.' | b'_' | b'~' | b',' => {
                (byte as char).to_string()
            }
            _ => format!("%{byte:02X}"),
        })
        .collect()
}

/// `cancel`: cancels a queued or running job; the job resource. A job that had ended is printed
/// as it is, never deleted (`POST /v1/jobs/{id}/cancel`, not `DELETE`).
pub fn cancel(server: &Server, id: &str) -> Result<String, CliError> {
    server.send("POST", &format!("/v1/jobs/{}/cancel", encode(id)), None)
}

/// `schedule`: nightly runs on a server.
#[derive(Debug, Clone, clap::Subcommand)]
pub enum ScheduleCommand {
    /// Create a schedule from a JSON file (`{"name", "cron", "time_zone", "template": JOB,
    /// "statistics", "enabled"}`; `-` or nothing reads standard input); print it.
    Create {
        /// The schedule JSON file; `-` or nothing reads standard input.
        #[arg(default_value = "-")]
        file: PathBuf,
    },
    /// Print your schedules, oldest first: `{"schedules": [...]}`, every page.
    List,
    /// Print a schedule: its timetable, next and last run, and the runs it skipped.
    Show {
        /// The schedule's id.
        #[arg(value_parser = clap::builder::NonEmptyStringValueParser::new())]
        id: String,
    },
    /// Replace a schedule's definition with a JSON file's (its runs stay); print it.
    Replace {
        /// The schedule's id.
        #[arg(value_parser = clap::builder::NonEmptyStringValueParser::new())]
        id: String,
        /// The schedule JSON file; `-` or nothing reads standard input.
        #[arg(default_value = "-")]
        file: PathBuf,
    },
    /// Delete a schedule (the jobs it submitted stay).
    Delete {
        /// The schedule's id.
        #[arg(value_parser = clap::builder::NonEmptyStringValueParser::new())]
        id: String,
    },
    /// Run a schedule's template now, outside its timetable; print the job. Sent once: a
    /// request sent again after a lost answer would run it twice.
    Run {
        /// The schedule's id.
        #[arg(value_parser = clap::builder::NonEmptyStringValueParser::new())]
        id: String,
    },
    /// Print a schedule's latest runs, oldest first, with each statistic's value, 95 % interval
    /// and drift flag.
    Runs {
        /// The schedule's id.
        #[arg(value_parser = clap::builder::NonEmptyStringValueParser::new())]
        id: String,
        /// How many of the latest runs, 1 to 366 (the server's default 60).
        #[arg(long, value_parser = clap::value_parser!(u32).range(1..=366))]
        limit: Option<u32>,
    },
}

/// Runs a `schedule` command; what it prints (nothing for a delete).
pub fn schedule(server: &Server, command: &ScheduleCommand) -> Result<String, CliError> {
    let path = |id: &str, tail: &str| format!("/v1/schedules/{}{tail}", encode(id));
    match command {
        ScheduleCommand::Create { file } => {
            server.send("POST", "/v1/schedules", Some(&read_input(file)?))
        }
        ScheduleCommand::List => {
            let mut schedules = Vec::new();
            let mut cursor: Option<String> = None;
            loop {
                let page = match &cursor {
                    Some(cursor) => format!("/v1/schedules?cursor={}", encode(cursor)),
                    None => "/v1/schedules".to_owned(),
                };
                let mut body = parse(&server.send("GET", &page, None)?)?;
                if let Some(serde_json::Value::Array(items)) = body.get_mut("schedules") {
                    schedules.append(items);
                }
                cursor = body["next_cursor"].as_str().map(str::to_owned);
                if cursor.is_none() {
                    return Ok(serde_json::json!({ "schedules": schedules }).to_string());
                }
            }
        }
        ScheduleCommand::Show { id } => server.send("GET", &path(id, ""), None),
        ScheduleCommand::Replace { id, file } => {
            server.send("PUT", &path(id, ""), Some(&read_input(file)?))
        }
        ScheduleCommand::Delete { id } => server.send("DELETE", &path(id, ""), None),
        ScheduleCommand::Run { id } => {
            let once = Server {
                retries: 0,
                ..server.clone()
            };
            once.send("POST", &path(id, "/run"), None)
        }
        ScheduleCommand::Runs { id, limit } => {
            let query = limit.map_or(String::new(), |limit| format!("?limit={limit}"));
            server.send("GET", &path(id, &format!("/runs{query}")), None)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `Retry-After` as seconds or as an HTTP date, counted from now and never below 0.
    #[test]
    fn retry_after_is_seconds_or_a_date() {
        assert_eq!(seconds_to_wait(" 120 "), Some(Duration::from_secs(120)));
        let later = (chrono::Utc::now() + chrono::TimeDelta::seconds(100)).to_rfc2822();
        let pause = seconds_to_wait(&later.replace("+0000", "GMT")).unwrap();
        assert!(
            (Duration::from_secs(98)..=Duration::from_secs(100)).contains(&pause),
            "{pause:?}"
        );
        assert_eq!(
            seconds_to_wait("Wed, 21 Oct 2015 07:28:00 GMT"),
            Some(Duration::ZERO)
        );
        assert_eq!(seconds_to_wait("soon"), None);
        assert_eq!(seconds_to_wait("-5"), None);
    }
}
