//! What the integration tests share: the binary, temporary files, an HTTP client, the service run
//! in-process or as a child process, and the jobs the tests submit. Each test module uses a part
//! of it.
#![allow(dead_code)]

pub mod app;
pub mod client;
pub mod json_close;
pub mod postgres;
pub mod tls;

use serde_json::{Value, json};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::sync::OnceLock;
use std::sync::atomic::{AtomicUsize, Ordering};

pub const BIN: &str = env!("CARGO_BIN_EXE_bouncewear");

/// Runs `work` to its end on a runtime of its own, in a thread of its own: callers may be inside
/// an async runtime, which cannot block on another.
pub fn on_own_runtime<T: Send + 'static>(
    work: impl std::future::Future<Output = T> + Send + 'static,
) -> T {
    std::thread::spawn(move || {
        tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .unwrap()
            .block_on(work)
    })
    .join()
    .expect("the thread finishes")
}

/// A fresh directory for one test, named after it, inside the test binary's own directory.
pub fn temp_dir(name: &str) -> PathBuf {
    let dir = binary_dir().join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// The test binary's directory, `bouncewear-test-PID` in the system's temporary one, removed when
/// the binary exits (each run left a hundred directories behind before), unless
/// `BOUNCEWEAR_KEEP_TEST_DIRS` is set, to look at what a failing test left. The servers and
/// PostgreSQL clusters the tests start are stopped when their tests end, before it goes.
fn binary_dir() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    extern "C" fn remove() {
        if let Some(dir) = DIR.get() {
            let _ = std::fs::remove_dir_all(dir);
        }
    }
    DIR.get_or_init(|| {
        if std::env::var_os("BOUNCEWEAR_KEEP_TEST_DIRS").is_none() {
            // SAFETY: `remove` is a plain function that runs once, when the process exits.
            unsafe { libc::atexit(remove) };
        }
        std::env::temp_dir().join(format!("bouncewear-test-{}", std::process::id()))
    })
}

/// Sends `signal` (`-TERM`, `-INT`, `-STOP`, ...) to the process `pid`, as `kill` does.
pub fn send_signal(pid: u32, signal: &str) {
    let sent = Command::new("kill")
        .args([signal, &pid.to_string()])
        .status()
        .unwrap();
    assert!(sent.success(), "kill {signal} {pid}");
}

/// A database file of its own for one test.
pub fn temp_db(name: &str) -> PathBuf {
    temp_dir(name).join("bouncewear.db")
}

/// Runs the binary with `args`, `stdin` on its standard input.
pub fn bouncewear(args: &[&str], stdin: &str) -> Output {
    let mut child = Command::new(BIN)
        .args(args)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("bouncewear runs");
    let written = child.stdin.take().unwrap().write_all(stdin.as_bytes());
    // A command that refuses its arguments may exit before it reads its input.
    if let Err(error) = written {
        assert_eq!(error.kind(), std::io::ErrorKind::BrokenPipe, "{error}");
    }
    child.wait_with_output().unwrap()
}

/// A Result's JSON without its timing: every other number is the same bits however it ran.
pub fn without_timing(result: &str) -> Value {
    let mut result: Value = serde_json::from_str(result).unwrap();
    result.as_object_mut().unwrap().remove("timing");
    result
}

/// `bouncewear run` of a job (from a file) with extra arguments: the Result, which must come.
pub fn run_job(job: &Value, args: &[&str]) -> Value {
    static RUNS: AtomicUsize = AtomicUsize::new(0);
    let path = temp_dir(&format!("run-{}", RUNS.fetch_add(1, Ordering::Relaxed))).join("job.json");
    std::fs::write(&path, job.to_string()).unwrap();
    let output = bouncewear(&[&["run", path.to_str().unwrap()], args].concat(), "");
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    serde_json::from_slice(&output.stdout).unwrap()
}

/// A job at 48 V / 15 A with the radius scattered per device and the velocity per operation.
pub fn scattered_job(devices: u64, operations: u64, seed: u64) -> Value {
    json!({
        "name": "lifecycle", "devices": devices, "operations": operations, "seed": seed,
        "scenario": {"circuit": {"supply_voltage_v": 48, "current_a": 15}},
        "scatter": [
            {"parameter": "contact_radius_m", "per": "device", "distribution": {"kind": "normal", "mean": 7.7e-3, "sd": 0.8e-3, "min": 1e-3}},
            {"parameter": "impact_velocity_m_s", "per": "operation", "distribution": {"kind": "normal", "mean": 0.224, "sd": 0.02, "min": 0.05}}
        ],
        "limits": {"total_bounce_s": 0.011}
    })
}

/// A job whose devices wear out: they fail when e1 falls below 0.33 (a life analysis follows).
pub fn wearing_template(supply_voltage_v: f64) -> Value {
    json!({
        "devices": 60, "operations": 300, "seed": 11,
        "scenario": {"circuit": {"supply_voltage_v": supply_voltage_v, "current_a": 15}},
        "scatter": [{"parameter": "contact_radius_m", "per": "device", "distribution": {"kind": "normal", "mean": 7.7e-3, "sd": 1.5e-3, "min": 1e-3}}],
        "failure": {"e1": {"below": 0.33}}
    })
}

/// Submits `count` small jobs at once, spread over the `urls` (each a `/v1/jobs`), checks that
/// each was accepted (202) or refused with `Retry-After`: the queue full (429), or the database
/// not answering in time (503, as the contract allows; seen once with the two cores starved by
/// other work), and returns the accepted ids and how many got 503. The callers check that
/// exactly those ids were stored.
pub fn submit_concurrently(urls: &[String], count: u64) -> (Vec<String>, usize) {
    let threads: Vec<_> = (0..count)
        .map(|seed| {
            let url = urls[seed as usize % urls.len()].clone();
            std::thread::spawn(move || {
                let job = json!({"devices": 1, "operations": 2000, "seed": seed});
                let reply = client::post(&url, &job.to_string(), None);
                let retry_after = reply.headers.get("retry-after").is_some();
                let id = reply.json()["id"].as_str().map(str::to_owned);
                (reply.status, retry_after, id)
            })
        })
        .collect();
    let replies: Vec<(u16, bool, Option<String>)> =
        threads.into_iter().map(|t| t.join().unwrap()).collect();
    let statuses: Vec<u16> = replies.iter().map(|r| r.0).collect();
    assert!(
        statuses.iter().all(|s| matches!(s, 202 | 429 | 503)),
        "{statuses:?}"
    );
    assert!(
        replies.iter().filter(|r| r.0 != 202).all(|r| r.1),
        "a refusal carries Retry-After"
    );
    let unavailable = statuses.iter().filter(|&&s| s == 503).count();
    (
        replies.into_iter().filter_map(|r| r.2).collect(),
        unavailable,
    )
}
