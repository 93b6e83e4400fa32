//! The command line against a server: `submit`, `status`, `wait`, `fetch` and `cancel` print what
//! the API answers and exit as the local commands do.

use crate::support::app::{Service, TestApp};
use crate::support::client::get;
use crate::support::tls;
use crate::support::{BIN, send_signal, temp_db, temp_dir};
use serde_json::{Value, json};
use std::io::{BufRead, BufReader, Read, Write};
use std::net::{TcpListener, TcpStream};
use std::process::{Command, Output, Stdio};

/// The binary with `args`, pointed at `server` through the environment, as a script would be.
pub(crate) fn remote(server: &TestApp, key: Option<&str>, args: &[&str]) -> Output {
    remote_at(server.base(), key, args)
        .output()
        .expect("bouncewear runs")
}

/// The command `remote` runs, pointed at the server (or proxy, or nothing) at `url`.
fn remote_at(url: &str, key: Option<&str>, args: &[&str]) -> Command {
    let mut command = Command::new(BIN);
    command.args(args).env("BOUNCEWEAR_URL", url);
    match key {
        Some(key) => command.env("BOUNCEWEAR_API_KEY", key),
        None => command.env_remove("BOUNCEWEAR_API_KEY"),
    };
    command
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

/// What `run` prints for the job in `file`.
fn run_locally(file: &str) -> String {
    stdout(
        &Command::new(BIN)
            .args(["run", "-q", file])
            .output()
            .unwrap(),
    )
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
    let local = run_locally(&file);
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
    // A part without a CSV form is a bad command line (exit 2), said as such.
    let shards = remote(&server, Some("k1"), &["fetch", id, "shards", "--csv"]);
    assert_eq!(shards.status.code(), Some(2));
    assert_eq!(
        String::from_utf8_lossy(&shards.stderr).trim_end(),
        "bouncewear: --csv: `shards` has no CSV form (`life` and `rare-event` have one)"
    );
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

/// No log level shows the API key: with `RUST_LOG=trace` the HTTP client's protocol layer dumped
/// each request's bytes, `Authorization: Bearer KEY` among them, sixteen characters a line.
#[test]
fn remote_commands_never_log_the_api_key() {
    const KEY: &str = "k0123456789abcdefghijklmnopqrstuvwxyz";
    let server = TestApp::start(&temp_db("remote-trace"), &["--api-key", KEY]);
    for filter in ["trace", "ureq_proto::util=trace,ureq=trace"] {
        let listed = remote_at(server.base(), Some(KEY), &["schedule", "list"])
            .env("RUST_LOG", filter)
            .output()
            .expect("bouncewear runs");
        let logged = String::from_utf8_lossy(&listed.stderr);
        assert!(
            listed.status.success() && logged.contains("ureq"),
            "{logged}"
        );
        let shown = (0..=KEY.len() - 8).find(|&at| logged.contains(&KEY[at..at + 8]));
        assert_eq!(shown, None, "RUST_LOG={filter}: {logged}");
    }
}

/// The remote commands speak https, as to a server behind a TLS terminator: trusting the CA that
/// `--ca-cert` (or `BOUNCEWEAR_CA_CERT`) names, a submission waited for prints what `run` prints;
/// without it the server's certificate is refused at once (exit 1, never sent again), the message
/// pointing at `--ca-cert`; a file with no certificate in it is a bad command line (exit 2).
#[test]
fn remote_commands_speak_https_trusting_the_ca_they_are_told() {
    let server = TestApp::start(&temp_db("remote-tls"), &["--api-key", "k1"]);
    let url = tls::terminate(server.base());
    let ca = tls::ca_file();
    let file = job_file(
        "remote-tls-job",
        &json!({"devices": 6, "operations": 20, "seed": 3}),
    );
    let mut served = remote_at(
        &url,
        Some("k1"),
        &["submit", &file, "--wait", "--ca-cert", &ca],
    );
    let served = stdout(&served.output().unwrap());
    let local = run_locally(&file);
    assert_eq!(without_timing(&served), without_timing(&local));

    let queued = remote_at(&url, Some("k1"), &["submit", &file])
        .env("BOUNCEWEAR_CA_CERT", &ca)
        .output()
        .unwrap();
    let queued: Value = serde_json::from_str(&stdout(&queued)).unwrap();
    let id = queued["id"].as_str().unwrap();

    let untrusted = remote_at(&url, Some("k1"), &["status", id])
        .output()
        .unwrap();
    assert_eq!(untrusted.status.code(), Some(1));
    let said = String::from_utf8_lossy(&untrusted.stderr);
    assert!(
        said.contains("UnknownIssuer") && said.contains("--ca-cert"),
        "{said}"
    );
    assert!(
        !said.contains("again in"),
        "a refused certificate is not tried again: {said}"
    );

    let key = tls::key_file();
    let no_certificate = remote_at(&url, Some("k1"), &["status", id, "--ca-cert", &key])
        .output()
        .unwrap();
    assert_eq!(no_certificate.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&no_certificate.stderr).contains("no PEM certificate"));
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

    // A body over the server's limit (1 MiB) is refused before it is sent, each time: writing
    // it all ended in a broken pipe (exit 1) at random once the server had answered and closed.
    let huge = job_file("remote-huge", &json!({"name": "x".repeat(3 << 20)}));
    for _ in 0..3 {
        let refused = remote(&server, None, &["submit", &huge]);
        let said = String::from_utf8_lossy(&refused.stderr);
        assert_eq!(refused.status.code(), Some(2), "{said}");
        assert!(
            said.contains("413: the request body is larger than"),
            "{said}"
        );
    }

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
    let nowhere = "http://127.0.0.1:1";
    let unreachable = remote_at(nowhere, None, &["status", id, "--retries", "2"])
        .output()
        .unwrap();
    assert_eq!(unreachable.status.code(), Some(1));
    let said = String::from_utf8_lossy(&unreachable.stderr);
    assert!(
        said.contains("again in 0.5 s (1 of 2)") && said.contains("again in 1.0 s (2 of 2)"),
        "{said}"
    );
    // `wait` does not pause past its timeout: after 0.5 s, a pause of 1 s would end past 1 s.
    let unreachable = remote_at(nowhere, None, &["wait", id, "--timeout-seconds", "1"])
        .output()
        .unwrap();
    assert_eq!(unreachable.status.code(), Some(1));
    let said = String::from_utf8_lossy(&unreachable.stderr);
    assert_eq!(said.matches("again in").count(), 1, "{said}");
    // Nor does `submit --wait`: its timeout counts from the submission, retries included.
    let unreachable = remote_at(
        nowhere,
        None,
        &[
            "submit",
            &file,
            "--wait",
            "--timeout-seconds",
            "1",
            "--retries",
            "5",
        ],
    )
    .output()
    .unwrap();
    assert_eq!(unreachable.status.code(), Some(1));
    let said = String::from_utf8_lossy(&unreachable.stderr);
    assert_eq!(said.matches("again in").count(), 1, "{said}");
}

/// Ctrl-C on `submit --wait` prints the job it queued (its id was lost: the interrupt ended the
/// command with nothing printed, an outside probe) and how to follow it, and exits 130; the job
/// goes on.
#[test]
fn an_interrupted_submit_wait_prints_the_job_it_queued() {
    let server = TestApp::start(&temp_db("remote-interrupt"), &["--workers", "0"]);
    let file = job_file(
        "remote-interrupt-job",
        &json!({"devices": 2, "operations": 2}),
    );
    // The submission's answer reaches the command a moment after the job is listed.
    let (queued, ended) = interrupted_once_queued(&server, server.base(), &file, 500);
    assert_eq!(ended.status.code(), Some(130));
    let job: Value = serde_json::from_slice(&ended.stdout).unwrap();
    assert_eq!(
        (job["id"].as_str(), &job["status"]),
        (Some(&queued[..]), &json!("queued"))
    );
    let said = String::from_utf8_lossy(&ended.stderr);
    assert!(
        said.contains(&format!("interrupted: job {queued} goes on")),
        "{said}"
    );
    let still = get(&server.url(&format!("/v1/jobs/{queued}")), None).json();
    assert_eq!(still["status"], "queued");
}

/// Ctrl-C while the submission's answer is still on its way (the job queued, its answer held
/// back) says the job may have been queued and the key that finds it, and exits 130: it ended the
/// command with nothing printed (an outside probe). The key named gives that job back.
#[test]
fn a_submit_interrupted_before_its_answer_names_its_key() {
    let server = TestApp::start(&temp_db("remote-interrupt-early"), &["--workers", "0"]);
    let proxy = losing_first_answer(server.base(), true);
    let body = json!({"devices": 2, "operations": 2});
    let file = job_file("remote-interrupt-early-job", &body);
    let (queued, ended) = interrupted_once_queued(&server, &proxy, &file, 300);
    assert_eq!(ended.status.code(), Some(130));
    assert!(ended.stdout.is_empty());
    let said = String::from_utf8_lossy(&ended.stderr).into_owned();
    assert!(
        said.contains("interrupted before the server answered: the job may have been queued"),
        "{said}"
    );
    let key = said
        .split("Idempotency-Key was ")
        .nth(1)
        .and_then(|rest| rest.split(';').next())
        .unwrap_or_else(|| panic!("no key in {said}"));
    let again = crate::support::client::agent()
        .post(&server.url("/v1/jobs"))
        .header("content-type", "application/json")
        .header("idempotency-key", key)
        .send(&body.to_string());
    let again = crate::support::client::reply(again);
    assert_eq!(
        again.header("idempotent-replayed"),
        Some("true"),
        "{}",
        again.body
    );
    assert_eq!(again.json()["id"], queued.as_str());
}

/// `submit FILE --wait` at `url` (the server or a proxy to it), interrupted `after_ms` after the
/// server lists the job it queued: the job's id and what the command did.
fn interrupted_once_queued(
    server: &TestApp,
    url: &str,
    file: &str,
    after_ms: u64,
) -> (String, Output) {
    let waiting = remote_at(url, None, &["submit", file, "--wait"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let started = std::time::Instant::now();
    let queued = loop {
        let jobs = get(&server.url("/v1/jobs"), None).json();
        if let Some(job) = jobs["jobs"].as_array().and_then(|jobs| jobs.first()) {
            break job["id"].as_str().unwrap().to_owned();
        }
        assert!(started.elapsed().as_secs() < 30, "no job queued");
        std::thread::sleep(std::time::Duration::from_millis(20));
    };
    std::thread::sleep(std::time::Duration::from_millis(after_ms));
    send_signal(waiting.id(), "-INT");
    (queued, waiting.wait_with_output().unwrap())
}

/// A full queue's 429 is asked again after its `Retry-After`: a submission made while the queue
/// is full is queued once there is room, not lost; with `--retries 0` it fails at once. A wait
/// of the queued job that times out says it is still queued.
#[test]
fn a_submission_to_a_full_queue_is_sent_again_once_there_is_room() {
    let server = TestApp::start(
        &temp_db("remote-full"),
        &["--workers", "0", "--max-queued", "1"],
    );
    let file = job_file("remote-full-job", &json!({"devices": 2, "operations": 2}));
    let first: Value =
        serde_json::from_str(&stdout(&remote(&server, None, &["submit", &file]))).unwrap();
    // A wait that times out says so: its last request's answer comes before the timeout (asked
    // to wait all the time left, the server answered past the request's deadline, and 1 wait in
    // 10 said "no answer within --request-timeout-seconds").
    let id = first["id"].as_str().unwrap();
    for timeout in ["0.5", "1", "1", "2"] {
        let waited = remote(&server, None, &["wait", id, "--timeout-seconds", timeout]);
        assert_eq!(waited.status.code(), Some(1));
        let said = String::from_utf8_lossy(&waited.stderr);
        assert!(
            said.contains(&format!("job {id} is still queued after")),
            "{said}"
        );
        // The job as it was goes to stdout, as a job that ended does: a script that submitted
        // it with `--wait` learns its id there (printed nothing before).
        let job: Value = serde_json::from_slice(&waited.stdout).unwrap();
        assert_eq!(
            (&job["id"], &job["status"]),
            (&first["id"], &json!("queued"))
        );
    }
    let refused = remote(&server, None, &["submit", &file, "--retries", "0"]);
    assert_eq!(refused.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&refused.stderr).contains("429"));
    // With `--wait`, no retry pauses past the timeout: the 429's 5 s would end past 2 s.
    let hurried = remote(
        &server,
        None,
        &["submit", &file, "--wait", "--timeout-seconds", "2"],
    );
    assert_eq!(hurried.status.code(), Some(1));
    let said = String::from_utf8_lossy(&hurried.stderr);
    assert!(said.contains("429") && !said.contains("again in"), "{said}");

    // The first job is cancelled once the second submission has had its 429 and waits.
    let mut waiting = remote_at(server.base(), None, &["submit", &file])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut said = String::new();
    let mut stderr = BufReader::new(waiting.stderr.take().unwrap());
    while !said.contains("again in") {
        assert_ne!(stderr.read_line(&mut said).unwrap(), 0, "{said}");
    }
    assert!(
        said.contains("429 from the server; again in 5.0 s (1 of 3)"),
        "{said}"
    );
    stdout(&remote(&server, None, &["cancel", id]));
    let second: Value =
        serde_json::from_str(&stdout(&waiting.wait_with_output().unwrap())).unwrap();
    assert_eq!(second["status"], "queued");
    assert_ne!(second["id"], first["id"]);
    let listed: Value = serde_json::from_str(&get(&server.url("/v1/jobs"), None).body).unwrap();
    assert_eq!(listed["jobs"].as_array().unwrap().len(), 2, "{listed}");
    // A job that ends just before the timeout is told as it ended: with its last request asked
    // to answer a quarter second early, one that ended then was told as still running.
    let second = second["id"].as_str().unwrap();
    let waited = std::thread::scope(|scope| {
        scope.spawn(|| {
            std::thread::sleep(std::time::Duration::from_millis(850));
            stdout(&remote(&server, None, &["cancel", second]));
        });
        remote(&server, None, &["wait", second, "--timeout-seconds", "1"])
    });
    assert_eq!(waited.status.code(), Some(1));
    let said = String::from_utf8_lossy(&waited.stderr);
    assert!(said.contains(&format!("job {second} cancelled")), "{said}");
}

/// A submission whose answer was lost (the connection closed after the server queued the job) is
/// sent again with the same `Idempotency-Key`, and the server answers with the job it queued: one
/// job, not two.
#[test]
fn a_submission_whose_answer_was_lost_queues_one_job() {
    let server = TestApp::start(&temp_db("remote-lost"), &["--workers", "0"]);
    let proxy = losing_first_answer(server.base(), false);
    let file = job_file("remote-lost-job", &json!({"devices": 2, "operations": 2}));
    let submitted = remote_at(&proxy, None, &["submit", &file])
        .output()
        .unwrap();
    let said = String::from_utf8_lossy(&submitted.stderr).into_owned();
    assert!(said.contains("again in 0.5 s (1 of 3)"), "{said}");
    let job: Value = serde_json::from_str(&stdout(&submitted)).unwrap();
    let listed: Value = serde_json::from_str(&get(&server.url("/v1/jobs"), None).body).unwrap();
    let ids: Vec<&Value> = listed["jobs"]
        .as_array()
        .unwrap()
        .iter()
        .map(|j| &j["id"])
        .collect();
    assert_eq!(ids, [&job["id"]], "{listed}");
}

/// A submission whose answer does not come within `--request-timeout-seconds` (the server queued
/// the job, its answer held back) is sent again with its key: one job, not two.
#[test]
fn a_submission_answered_too_late_queues_one_job() {
    let server = TestApp::start(&temp_db("remote-late"), &["--workers", "0"]);
    let proxy = losing_first_answer(server.base(), true);
    let file = job_file("remote-late-job", &json!({"devices": 2, "operations": 2}));
    let submitted = remote_at(
        &proxy,
        None,
        &["submit", &file, "--request-timeout-seconds", "2"],
    )
    .output()
    .unwrap();
    let said = String::from_utf8_lossy(&submitted.stderr).into_owned();
    assert!(said.contains("no answer within"), "{said}");
    let job: Value = serde_json::from_str(&stdout(&submitted)).unwrap();
    let listed: Value = serde_json::from_str(&get(&server.url("/v1/jobs"), None).body).unwrap();
    assert_eq!(listed["jobs"].as_array().unwrap().len(), 1, "{listed}");
    assert_eq!(listed["jobs"][0]["id"], job["id"]);
}

/// `wait --timeout-seconds` ends by then even where the server never answers, whatever
/// `--request-timeout-seconds` allows one request.
#[test]
fn wait_ends_at_its_timeout_against_a_server_that_never_answers() {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let url = format!("http://{}", listener.local_addr().unwrap());
    std::thread::spawn(move || {
        let held: Vec<TcpStream> = listener.incoming().map_while(Result::ok).collect();
        drop(held);
    });
    let started = std::time::Instant::now();
    let waited = remote_at(
        &url,
        None,
        &[
            "wait",
            "j-1",
            "--timeout-seconds",
            "1",
            "--request-timeout-seconds",
            "120",
        ],
    )
    .output()
    .unwrap();
    let took = started.elapsed();
    assert_eq!(waited.status.code(), Some(1));
    let said = String::from_utf8_lossy(&waited.stderr).into_owned();
    assert!(said.contains("no answer within"), "{said}");
    // Bounded by its own timeout, not by a request's 120 s (a generous margin for a busy host).
    assert!(took < std::time::Duration::from_secs(60), "{took:?}");
}

/// A sign-in page answered with 200 where JSON was expected is an error that shows what came
/// (it said only "expected value at line 1 column 1", an outside probe), exit 1.
#[test]
fn a_page_that_is_not_json_is_shown_not_parsed() {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let url = format!("http://{}", listener.local_addr().unwrap());
    std::thread::spawn(move || {
        for mut client in listener.incoming().map_while(Result::ok) {
            let mut head = [0; 4096];
            let _ = client.read(&mut head);
            let page = "<html>please sign in</html>";
            let _ = write!(
                client,
                "HTTP/1.1 200 OK\r\ncontent-type: text/html\r\ncontent-length: {}\r\n\
                 connection: close\r\n\r\n{page}",
                page.len()
            );
        }
    });
    let status = remote_at(&url, None, &["status", "j-1"]).output().unwrap();
    assert_eq!(status.status.code(), Some(1));
    let said = String::from_utf8_lossy(&status.stderr);
    assert!(
        said.contains("the server's answer is not the JSON expected")
            && said.contains("please sign in"),
        "{said}"
    );
}

/// A proxy to `base` that hands the first request on, lets the server handle it, and closes the
/// client's connection without its answer (or, with `hold`, keeps it open and silent); later
/// connections it relays both ways. Its base URL.
fn losing_first_answer(base: &str, hold: bool) -> String {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let proxy = format!("http://{}", listener.local_addr().unwrap());
    let upstream = base.trim_start_matches("http://").to_owned();
    std::thread::spawn(move || {
        for (n, client) in listener.incoming().enumerate() {
            let Ok(client) = client else { return };
            let server = TcpStream::connect(&upstream).unwrap();
            if n == 0 {
                let mut request = Vec::new();
                let mut reader = BufReader::new(client.try_clone().unwrap());
                let mut length = 0;
                loop {
                    let mut line = String::new();
                    reader.read_line(&mut line).unwrap();
                    if let Some(value) = line.to_ascii_lowercase().strip_prefix("content-length:") {
                        length = value.trim().parse().unwrap();
                    }
                    request.extend_from_slice(line.as_bytes());
                    if line == "\r\n" {
                        break;
                    }
                }
                let mut body = vec![0; length];
                reader.read_exact(&mut body).unwrap();
                request.extend_from_slice(&body);
                (&server).write_all(&request).unwrap();
                // The server's answer, read and dropped with the client's connection; held, the
                // server's connection is kept too, so that closing it does not end the handler
                // before the job is queued (its first byte may be a `100 Continue`).
                let mut answer = [0; 1];
                (&server).read_exact(&mut answer).unwrap();
                if hold {
                    std::thread::spawn(move || {
                        std::thread::sleep(std::time::Duration::from_secs(120));
                        drop((client, server));
                    });
                }
                continue;
            }
            for (mut from, mut to) in [
                (client.try_clone().unwrap(), server.try_clone().unwrap()),
                (server, client),
            ] {
                std::thread::spawn(move || {
                    let _ = std::io::copy(&mut from, &mut to);
                    let _ = to.shutdown(std::net::Shutdown::Write);
                });
            }
        }
    });
    proxy
}

/// With `--log-format json` every line a remote command writes to stderr is one JSON object: its
/// retry notes and its last word.
#[test]
fn a_remote_commands_stderr_is_json_lines_when_asked() {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let url = format!("http://{}", listener.local_addr().unwrap());
    drop(listener); // nothing listens there now: refused
    let output = remote_at(
        &url,
        None,
        &["--log-format", "json", "status", "j-1", "--retries", "1"],
    )
    .output()
    .unwrap();
    assert_eq!(output.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&output.stderr).into_owned();
    let lines: Vec<Value> = stderr
        .lines()
        .map(|line| serde_json::from_str(line).unwrap_or_else(|e| panic!("{e}: {line}")))
        .collect();
    assert_eq!(lines.len(), 2, "{stderr}");
    assert!(
        lines[0]["message"]
            .as_str()
            .unwrap()
            .contains("again in 0.5 s (1 of 1)")
    );
    assert_eq!(
        (lines[1]["level"].as_str(), lines[1]["exit_code"].as_u64()),
        (Some("ERROR"), Some(1))
    );
}

/// `schedule`: a schedule created from a file, listed, shown, run now, its trend printed,
/// replaced, deleted; the API's answers as printed JSON, a schedule gone exit 1.
#[test]
fn schedules_from_the_command_line() {
    let server = TestApp::start(&temp_db("remote-schedules"), &["--api-key", "k1"]);
    let spec = json!({"name": "nightly", "cron": "0 3 * * *", "time_zone": "Europe/Berlin",
                      "template": {"devices": 4, "operations": 20, "seed": 5}});
    let file = job_file("remote-schedule", &spec);
    let schedule = |args: &[&str]| remote(&server, Some("k1"), &[&["schedule"][..], args].concat());
    let created: Value = serde_json::from_str(&stdout(&schedule(&["create", &file]))).unwrap();
    let id = created["id"].as_str().unwrap().to_owned();
    assert_eq!(created["skipped_runs"], 0);
    let listed: Value = serde_json::from_str(&stdout(&schedule(&["list"]))).unwrap();
    assert_eq!(listed["schedules"][0]["id"], id.as_str(), "{listed}");
    let shown: Value = serde_json::from_str(&stdout(&schedule(&["show", &id]))).unwrap();
    assert_eq!(shown["next_run_at"], created["next_run_at"]);
    let job: Value = serde_json::from_str(&stdout(&schedule(&["run", &id]))).unwrap();
    let job_id = job["id"].as_str().unwrap();
    stdout(&remote(&server, Some("k1"), &["wait", job_id]));
    let runs: Value =
        serde_json::from_str(&stdout(&schedule(&["runs", &id, "--limit", "5"]))).unwrap();
    let run = &runs["runs"][0];
    assert_eq!(
        (run["job_id"].as_str(), run["manual"].as_bool()),
        (Some(job_id), Some(true))
    );
    assert!(
        run["values"]["operations.total_bounce_s.p95"]["value"]
            .as_f64()
            .unwrap()
            > 0.0
    );
    let mut off = spec.clone();
    off["enabled"] = json!(false);
    let off = job_file("remote-schedule-off", &off);
    let replaced: Value =
        serde_json::from_str(&stdout(&schedule(&["replace", &id, &off]))).unwrap();
    assert_eq!(
        (
            replaced["enabled"].as_bool(),
            replaced["next_run_at"].is_null()
        ),
        (Some(false), true)
    );
    let deleted = schedule(&["delete", &id]);
    assert!(stdout(&deleted).is_empty());
    let gone = schedule(&["show", &id]);
    let said = String::from_utf8_lossy(&gone.stderr);
    assert_eq!(gone.status.code(), Some(1), "{said}");
    assert!(said.contains("404"), "{said}");
}
