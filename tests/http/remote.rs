//! The command line against a server: `submit`, `status`, `wait`, `fetch` and `cancel` print what
//! the API answers and exit as the local commands do.

use crate::support::app::{Service, TestApp};
use crate::support::{BIN, temp_db, temp_dir};
use serde_json::{Value, json};
use std::process::{Command, Output};

/// The binary with `args`, pointed at `server` through the environment, as a script would be.
pub(crate) fn remote(server: &TestApp, key: Option<&str>, args: &[&str]) -> Output {
    let mut command = Command::new(BIN);
    command.args(args).env("BOUNCEWEAR_URL", server.base());
    match key {
        Some(key) => command.env("BOUNCEWEAR_API_KEY", key),
        None => command.env_remove("BOUNCEWEAR_API_KEY"),
    };
    command.output().expect("bouncewear runs")
}

pub(crate) fn stdout(output: &Output) -> String {
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    String::from_utf8(output.stdout.clone()).unwrap()
}

/// A job file of its own.
pub(crate) fn job_file(name: &str, job: &Value) -> String {
    let path = temp_dir(name).join("job.json");
    std::fs::write(&path, job.to_string()).unwrap();
    path.display().to_string()
}

/// Every line of a printed Result but its timing, which differs between two runs.
fn without_timing(text: &str) -> Vec<&str> {
    text.lines()
        .filter(|line| !line.contains("wall_s") && !line.contains("operations_per_s"))
        .collect()
}

/// `submit --wait` prints the Result `run` prints for the same job and seed, line for line;
/// `status`, `wait` and `fetch` read the same job; `fetch life --csv` gives each device's life.
#[test]
fn submit_wait_prints_what_run_prints_and_fetch_reads_the_parts() {
    let server = TestApp::start(&temp_db("remote"), &["--api-key", "k1"]);
    let job = json!({"devices": 30, "operations": 60, "seed": 7,
        "scenario": {"circuit": {"supply_voltage_v": 48, "current_a": 15}},
        "failure": {"e1": {"below": 0.36}}});
    let file = job_file("remote-job", &job);
    let remote_result = stdout(&remote(&server, Some("k1"), &["submit", &file, "--wait"]));
    let local = stdout(
        &Command::new(BIN)
            .args(["run", "-q", &file])
            .output()
            .unwrap(),
    );
    assert_eq!(without_timing(&remote_result), without_timing(&local));

    let queued: Value =
        serde_json::from_str(&stdout(&remote(&server, Some("k1"), &["submit", &file]))).unwrap();
    let id = queued["id"].as_str().unwrap();
    let waited: Value =
        serde_json::from_str(&stdout(&remote(&server, Some("k1"), &["wait", id]))).unwrap();
    assert_eq!(waited["status"], "succeeded");
    let status: Value =
        serde_json::from_str(&stdout(&remote(&server, Some("k1"), &["status", id]))).unwrap();
    assert_eq!(status["spec"]["seed"], 7);
    let fetched = stdout(&remote(&server, Some("k1"), &["fetch", id]));
    assert_eq!(without_timing(&fetched), without_timing(&local));
    let lives = stdout(&remote(
        &server,
        Some("k1"),
        &["fetch", id, "life", "--csv"],
    ));
    assert_eq!(
        lives.lines().next(),
        Some("device,operations_to_failure,censored")
    );
    assert_eq!(lives.lines().count(), 31);
    // `cancel` of a job that ended prints it as it is and keeps it (it never deletes).
    let kept = remote(&server, Some("k1"), &["cancel", id]);
    assert_eq!(kept.status.code(), Some(0));
    let kept: Value = serde_json::from_str(&stdout(&kept)).unwrap();
    assert_eq!(kept["status"], "succeeded");
    let fetched = stdout(&remote(&server, Some("k1"), &["fetch", id]));
    assert_eq!(without_timing(&fetched), without_timing(&local));

    // Without the key: the server's 401, exit 1.
    let refused = remote(&server, None, &["status", id]);
    assert_eq!(refused.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&refused.stderr).contains("401"));
}

/// A job the server refuses exits 2 naming the field; an unknown job, a cancelled one waited for
/// and an unreachable server exit 1; `cancel` prints the cancelled job.
#[test]
fn refusals_and_failures_exit_as_the_local_commands_do() {
    let server = TestApp::start(&temp_db("remote-refusals"), &["--workers", "0"]);
    let bad = remote(
        &server,
        None,
        &["submit", &job_file("remote-bad", &json!({"devices": 0}))],
    );
    assert_eq!(bad.status.code(), Some(2));
    assert!(
        String::from_utf8_lossy(&bad.stderr).contains("/devices: must be from 1"),
        "{}",
        String::from_utf8_lossy(&bad.stderr)
    );

    let file = job_file("remote-queued", &json!({"devices": 2, "operations": 2}));
    let queued: Value =
        serde_json::from_str(&stdout(&remote(&server, None, &["submit", &file]))).unwrap();
    let id = queued["id"].as_str().unwrap();
    let cancelled: Value =
        serde_json::from_str(&stdout(&remote(&server, None, &["cancel", id]))).unwrap();
    assert_eq!(cancelled["status"], "cancelled");
    let waited = remote(&server, None, &["wait", id]);
    assert_eq!(waited.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&waited.stderr).contains("cancelled"));
    // The job as it ended is printed all the same.
    let printed: Value = serde_json::from_slice(&waited.stdout).unwrap();
    assert_eq!(
        (&printed["id"], &printed["status"]),
        (&json!(id), &json!("cancelled"))
    );
    let again: Value =
        serde_json::from_str(&stdout(&remote(&server, None, &["cancel", id]))).unwrap();
    assert_eq!(again["status"], "cancelled");

    let unknown = remote(&server, None, &["status", "no-such-job"]);
    assert_eq!(unknown.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&unknown.stderr).contains("404"));
    // An id is one path segment: what follows a slash in it does not reach another resource.
    let smuggled = remote(&server, None, &["status", &format!("{id}/shards")]);
    assert_eq!(smuggled.status.code(), Some(1));

    // A malformed document names the field the server's 400 names.
    let nan = job_file("remote-nan", &json!(null)).replace("job.json", "nan.json");
    std::fs::write(&nan, r#"{"devices": NaN}"#).unwrap();
    let malformed = remote(&server, None, &["submit", &nan]);
    assert_eq!(malformed.status.code(), Some(2));
    let said = String::from_utf8_lossy(&malformed.stderr);
    assert!(said.contains("invalid input: /devices: "), "{said}");

    // Seconds no clock holds, or none at all, are refused by name (exit 2), never a panic or a
    // wait without end; a timeout without --wait is refused too.
    for args in [
        vec!["status", id, "--request-timeout-seconds", "1e30"],
        vec!["status", id, "--request-timeout-seconds", "inf"],
        vec!["wait", id, "--timeout-seconds", "nan"],
        vec!["wait", id, "--timeout-seconds", "0"],
        vec!["submit", &file, "--timeout-seconds", "5"],
        vec!["health", "--timeout-seconds", "-1"],
    ] {
        let refused = remote(&server, None, &args);
        assert_eq!(refused.status.code(), Some(2), "{args:?}");
        let said = String::from_utf8_lossy(&refused.stderr);
        assert!(said.contains("--"), "{args:?}: {said}");
    }
    // No server there: tried again after 0.5 and 1 s, then exit 1.
    let unreachable = Command::new(BIN)
        .args([
            "status",
            id,
            "--url",
            "http://127.0.0.1:1",
            "--retries",
            "2",
        ])
        .output()
        .unwrap();
    assert_eq!(unreachable.status.code(), Some(1));
    let said = String::from_utf8_lossy(&unreachable.stderr);
    assert!(
        said.contains("again in 0.5 s (1 of 2)") && said.contains("again in 1.0 s (2 of 2)"),
        "{said}"
    );
}

/// A full queue's 429 is asked again after its `Retry-After`: a submission made while the queue
/// is full is queued once there is room, not lost; with `--retries 0` it fails at once.
#[test]
fn a_submission_to_a_full_queue_is_sent_again_once_there_is_room() {
    let server = TestApp::start(
        &temp_db("remote-full"),
        &["--workers", "0", "--max-queued", "1"],
    );
    let file = job_file("remote-full-job", &json!({"devices": 2, "operations": 2}));
    let first: Value =
        serde_json::from_str(&stdout(&remote(&server, None, &["submit", &file]))).unwrap();
    let refused = remote(&server, None, &["submit", &file, "--retries", "0"]);
    assert_eq!(refused.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&refused.stderr).contains("429"));

    let url = server.base().to_owned();
    let waiting = std::thread::spawn({
        let file = file.clone();
        move || {
            Command::new(BIN)
                .args(["submit", &file, "--url", &url])
                .env_remove("BOUNCEWEAR_API_KEY")
                .output()
                .unwrap()
        }
    });
    std::thread::sleep(std::time::Duration::from_secs(1));
    stdout(&remote(
        &server,
        None,
        &["cancel", first["id"].as_str().unwrap()],
    ));
    let second = waiting.join().unwrap();
    let said = String::from_utf8_lossy(&second.stderr);
    assert!(
        said.contains("429 from the server; again in 5.0 s (1 of 3)"),
        "{said}"
    );
    let second: Value = serde_json::from_str(&stdout(&second)).unwrap();
    assert_eq!(second["status"], "queued");
    assert_ne!(second["id"], first["id"]);
}
