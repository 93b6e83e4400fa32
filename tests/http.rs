//! The HTTP API through the real server: `bouncewear serve` on port 0 with a temporary database file.

use serde_json::{Value, json};
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

const BIN: &str = env!("CARGO_BIN_EXE_bouncewear");

struct Server {
    child: Child,
    base: String,
}

impl Server {
    fn start(database: &Path, args: &[&str]) -> Server {
        let url = format!("sqlite://{}", database.display());
        let mut child = Command::new(BIN)
            .args(["serve", "--bind", "127.0.0.1:0", "--database", &url])
            .args(args)
            .env("RUST_LOG", "warn")
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .expect("server starts");
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
        Server { child, base }
    }

    fn url(&self, path: &str) -> String {
        format!("{}{path}", self.base)
    }

    fn kill(mut self) {
        self.child.kill().unwrap();
        self.child.wait().unwrap();
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn temp_db(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("bouncewear-http-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir.join("bouncewear.db")
}

fn agent() -> ureq::Agent {
    ureq::Agent::config_builder()
        .http_status_as_error(false)
        .timeout_global(Some(Duration::from_secs(60)))
        .build()
        .into()
}

struct Reply {
    status: u16,
    content_type: String,
    headers: ureq::http::HeaderMap,
    body: String,
}

impl Reply {
    fn json(&self) -> Value {
        serde_json::from_str(&self.body).unwrap_or_else(|e| panic!("{e}: {}", self.body))
    }
}

fn reply(response: Result<ureq::http::Response<ureq::Body>, ureq::Error>) -> Reply {
    let mut response = response.expect("the server answers");
    let content_type = response
        .headers()
        .get("content-type")
        .and_then(|v| v.to_str().ok())
        .unwrap_or("")
        .to_owned();
    Reply {
        status: response.status().as_u16(),
        content_type,
        headers: response.headers().clone(),
        body: response
            .body_mut()
            .with_config()
            .limit(1 << 28)
            .read_to_string()
            .unwrap(),
    }
}

fn get(url: &str, key: Option<&str>) -> Reply {
    let mut request = agent().get(url);
    if let Some(key) = key {
        request = request.header("authorization", &format!("Bearer {key}"));
    }
    reply(request.call())
}

fn post(url: &str, body: &str, key: Option<&str>) -> Reply {
    let mut request = agent().post(url).header("content-type", "application/json");
    if let Some(key) = key {
        request = request.header("authorization", &format!("Bearer {key}"));
    }
    reply(request.send(body))
}

fn delete(url: &str) -> Reply {
    reply(agent().delete(url).call())
}

fn submit(server: &Server, job: &Value) -> String {
    let reply = post(&server.url("/v1/jobs"), &job.to_string(), None);
    assert_eq!(reply.status, 202, "{}", reply.body);
    let location = reply
        .headers
        .get("location")
        .unwrap()
        .to_str()
        .unwrap()
        .to_owned();
    assert_eq!(
        location,
        format!("/v1/jobs/{}", reply.json()["id"].as_str().unwrap())
    );
    reply.json()["id"].as_str().unwrap().to_owned()
}

fn wait_for(server: &Server, id: &str, status: &str, timeout: Duration) -> Value {
    let started = Instant::now();
    loop {
        let job = get(&server.url(&format!("/v1/jobs/{id}")), None).json();
        if job["status"] == status {
            return job;
        }
        assert!(
            started.elapsed() < timeout,
            "job {id} is {} after {timeout:?}",
            job["status"]
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}

fn scattered_job(devices: u64, operations: u64, seed: u64) -> Value {
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

/// `bouncewear run` on the same job: the reference for the server's result.
fn run_locally(job: &Value) -> Value {
    let path = temp_db(&format!("job-{}", job["seed"])).with_file_name("job.json");
    std::fs::write(&path, job.to_string()).unwrap();
    let output = Command::new(BIN)
        .args(["run", path.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(output.status.success());
    serde_json::from_slice(&output.stdout).unwrap()
}

#[test]
fn a_job_goes_from_submission_to_result_with_live_progress() {
    let server = Server::start(&temp_db("lifecycle"), &[]);
    let job = scattered_job(3000, 400, 77);
    let id = submit(&server, &job);

    // Server-Sent Events: progress while it runs, then the final status.
    let mut events = agent()
        .get(&server.url(&format!("/v1/jobs/{id}/events")))
        .call()
        .unwrap();
    assert!(
        events
            .headers()
            .get("content-type")
            .unwrap()
            .to_str()
            .unwrap()
            .starts_with("text/event-stream")
    );
    let lines: Vec<String> = BufReader::new(events.body_mut().as_reader())
        .lines()
        .map(Result::unwrap)
        .collect();
    let progress: Vec<Value> = lines
        .windows(2)
        .filter(|w| w[0] == "event: progress")
        .map(|w| serde_json::from_str(w[1].trim_start_matches("data: ")).unwrap())
        .collect();
    assert!(!progress.is_empty(), "{lines:?}");
    let done: Vec<u64> = progress
        .iter()
        .map(|p| p["operations_done"].as_u64().unwrap())
        .collect();
    assert!(
        done.windows(2).all(|w| w[0] <= w[1]),
        "progress never goes back: {done:?}"
    );
    let last = lines
        .iter()
        .position(|l| l == "event: status")
        .expect("a final status event");
    let final_status: Value =
        serde_json::from_str(lines[last + 1].trim_start_matches("data: ")).unwrap();
    assert_eq!(final_status["status"], "succeeded");

    let status = get(&server.url(&format!("/v1/jobs/{id}")), None).json();
    assert_eq!(status["progress"]["operations_done"], 3000 * 400);
    assert_eq!(
        (status["seed"].as_u64(), status["name"].as_str()),
        (Some(77), Some("lifecycle"))
    );
    for field in ["created_at", "started_at", "finished_at"] {
        assert!(status[field].is_string(), "{field}");
    }

    let result = get(&server.url(&format!("/v1/jobs/{id}/result")), None);
    assert_eq!(result.status, 200);
    let (result, local) = (result.json(), run_locally(&job));
    assert_eq!(
        result["operations"], local["operations"],
        "server and CLI agree to the bit"
    );
    assert_eq!(result["devices"], local["devices"]);

    let distribution = get(
        &server.url(&format!(
            "/v1/jobs/{id}/distributions/total_bounce_s?op_start=100&op_end=200"
        )),
        None,
    );
    assert_eq!(distribution.status, 200);
    let bins = distribution.json()["bins"].as_array().unwrap().clone();
    assert_eq!(
        bins.len(),
        3,
        "bins of 40 operations overlapping [100, 200): 80-120, 120-160, 160-200"
    );
    assert_eq!(bins[0]["op_start"], 80);
    assert_eq!(bins[0]["exceedance"]["limit"], 0.011);
    let csv = get(
        &server.url(&format!(
            "/v1/jobs/{id}/distributions/total_bounce_s?format=csv"
        )),
        None,
    );
    assert!(csv.content_type.starts_with("text/csv"));
    let rows: Vec<&str> = csv.body.lines().collect();
    assert_eq!(rows.len(), 1 + 10);
    assert!(rows[0].starts_with("op_start,op_end,n,mean"));
    assert!(rows[1].starts_with("0,40,120000,"));
    let device = get(
        &server.url(&format!("/v1/jobs/{id}/distributions/final_radius_m")),
        None,
    )
    .json();
    assert_eq!(
        (device["kind"].as_str(), device["bins"][0]["n"].as_u64()),
        (Some("device"), Some(3000))
    );
}

#[test]
fn jobs_are_listed_newest_first_with_cursor_paging() {
    let server = Server::start(&temp_db("paging"), &[]);
    let ids: Vec<String> = (0..5)
        .map(|seed| {
            submit(
                &server,
                &json!({"devices": 1, "operations": 1, "seed": seed}),
            )
        })
        .collect();
    let mut seen = Vec::new();
    let mut cursor: Option<String> = None;
    loop {
        let query = cursor
            .as_ref()
            .map_or(String::new(), |c| format!("&cursor={c}"));
        let page = get(&server.url(&format!("/v1/jobs?limit=2{query}")), None).json();
        seen.extend(
            page["jobs"]
                .as_array()
                .unwrap()
                .iter()
                .map(|j| j["id"].as_str().unwrap().to_owned()),
        );
        match page["next_cursor"].as_str() {
            Some(next) => cursor = Some(next.to_owned()),
            None => break,
        }
    }
    let newest_first: Vec<String> = ids.into_iter().rev().collect();
    assert_eq!(seen, newest_first);
}

#[test]
fn cancelling_stops_a_running_job_and_only_once() {
    let server = Server::start(&temp_db("cancel"), &[]);
    let id = submit(&server, &scattered_job(200_000, 1000, 1));
    wait_for(&server, &id, "running", Duration::from_secs(10));
    let cancelled = delete(&server.url(&format!("/v1/jobs/{id}")));
    assert_eq!(
        (cancelled.status, cancelled.json()["status"].as_str()),
        (200, Some("cancelled"))
    );
    assert_eq!(delete(&server.url(&format!("/v1/jobs/{id}"))).status, 409);
    assert_eq!(
        get(&server.url(&format!("/v1/jobs/{id}/result")), None).status,
        409
    );
    // the worker is free again: a small job runs to the end
    let next = submit(&server, &json!({"devices": 2, "operations": 2, "seed": 1}));
    wait_for(&server, &next, "succeeded", Duration::from_secs(20));
    assert_eq!(
        get(&server.url(&format!("/v1/jobs/{id}")), None).json()["status"],
        "cancelled"
    );
}

#[test]
fn a_job_killed_mid_run_finishes_after_restart_with_the_identical_result() {
    let database = temp_db("crash");
    let job = scattered_job(20_000, 300, 4242);
    let server = Server::start(&database, &["--lease-seconds", "1"]);
    let id = submit(&server, &job);
    let queued = submit(&server, &json!({"devices": 3, "operations": 3, "seed": 5}));
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

    let server = Server::start(&database, &["--lease-seconds", "1"]);
    wait_for(&server, &id, "succeeded", Duration::from_secs(60));
    wait_for(&server, &queued, "succeeded", Duration::from_secs(60));
    let result = get(&server.url(&format!("/v1/jobs/{id}/result")), None).json();
    let local = run_locally(&job);
    assert_eq!(result["operations"], local["operations"]);
    assert_eq!(result["devices"], local["devices"]);
}

#[test]
fn two_hundred_concurrent_submissions_are_all_accepted_or_refused_with_429() {
    let server = Server::start(&temp_db("concurrent"), &["--max-queued", "150"]);
    let url = server.url("/v1/jobs");
    let threads: Vec<_> = (0..200)
        .map(|seed| {
            let url = url.clone();
            std::thread::spawn(move || {
                let reply = post(
                    &url,
                    &json!({"devices": 1, "operations": 2000, "seed": seed}).to_string(),
                    None,
                );
                let retry_after = reply.headers.get("retry-after").is_some();
                (
                    reply.status,
                    retry_after,
                    reply.json()["id"].as_str().map(str::to_owned),
                )
            })
        })
        .collect();
    let replies: Vec<_> = threads.into_iter().map(|t| t.join().unwrap()).collect();
    assert!(
        replies
            .iter()
            .all(|(status, ..)| *status == 202 || *status == 429),
        "{:?}",
        replies.iter().map(|r| r.0).collect::<Vec<_>>()
    );
    assert!(
        replies.iter().filter(|r| r.0 == 429).all(|r| r.1),
        "429 carries Retry-After"
    );
    let mut accepted: Vec<String> = replies
        .into_iter()
        .filter(|r| r.0 == 202)
        .filter_map(|r| r.2)
        .collect();
    assert!(accepted.len() >= 150);
    let mut listed = Vec::new();
    let mut cursor = String::new();
    loop {
        let page = get(&server.url(&format!("/v1/jobs?limit=100{cursor}")), None).json();
        listed.extend(
            page["jobs"]
                .as_array()
                .unwrap()
                .iter()
                .map(|j| j["id"].as_str().unwrap().to_owned()),
        );
        match page["next_cursor"].as_str() {
            Some(next) => cursor = format!("&cursor={next}"),
            None => break,
        }
    }
    accepted.sort();
    listed.sort();
    assert_eq!(
        accepted, listed,
        "every accepted job is stored, nothing else"
    );
}

fn assert_problem(reply: &Reply, status: u16) -> Value {
    assert_eq!(reply.status, status, "{}", reply.body);
    assert_eq!(
        reply.content_type, "application/problem+json",
        "{}",
        reply.body
    );
    let problem = reply.json();
    assert_eq!(problem["status"], status);
    assert!(problem["title"].is_string() && problem["detail"].is_string());
    problem
}

#[test]
fn bad_requests_get_the_right_4xx_problem() {
    let server = Server::start(
        &temp_db("bad"),
        &[
            "--max-body-bytes",
            "4096",
            "--max-job-operations",
            "1000000",
        ],
    );
    let jobs = server.url("/v1/jobs");
    assert_problem(&post(&jobs, "{\"devices\": 1", None), 400);
    assert_problem(&post(&jobs, "[1, 2]", None), 422);
    assert_problem(
        &reply(
            agent()
                .post(&jobs)
                .header("content-type", "text/plain")
                .send("{}"),
        ),
        415,
    );
    assert_problem(&reply(agent().post(&jobs).send("{}")), 415);
    assert_problem(
        &post(
            &jobs,
            &format!("{{\"name\": \"{}\"}}", "x".repeat(5000)),
            None,
        ),
        413,
    );
    let invalid = assert_problem(
        &post(
            &jobs,
            r#"{"devices": 0, "scenario": {"mechanism": {"static_force_n": -1}}}"#,
            None,
        ),
        422,
    );
    let pointers: Vec<&str> = invalid["errors"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| e["pointer"].as_str().unwrap())
        .collect();
    assert!(
        pointers.contains(&"/devices") && pointers.contains(&"/scenario/mechanism/static_force_n"),
        "{pointers:?}"
    );
    let too_big = assert_problem(
        &post(&jobs, r#"{"devices": 10000, "operations": 1000}"#, None),
        422,
    );
    assert_eq!(too_big["errors"][0]["pointer"], "/devices");
    assert_problem(
        &post(
            &server.url("/v1/simulate"),
            r#"{"losses": {"max_bounces": 0}}"#,
            None,
        ),
        422,
    );
    assert_problem(
        &post(&server.url("/v1/simulate?fidelity=fast"), "{}", None),
        400,
    );
    assert_problem(&get(&server.url("/v1/jobs/no-such-job"), None), 404);
    assert_problem(&get(&server.url("/v1/jobs/no-such-job/result"), None), 404);
    assert_problem(&delete(&server.url("/v1/jobs/no-such-job")), 404);
    assert_problem(&get(&server.url("/v1/nothing-here"), None), 404);
    assert_problem(&get(&server.url("/v1/jobs?limit=0"), None), 400);
    assert_problem(&get(&server.url("/v1/jobs?cursor=abc"), None), 400);
    assert_problem(
        &reply(
            agent()
                .put(&jobs)
                .header("content-type", "application/json")
                .send("{}"),
        ),
        405,
    );
    let id = submit(&server, &json!({"devices": 1, "operations": 1, "seed": 1}));
    wait_for(&server, &id, "succeeded", Duration::from_secs(20));
    assert_problem(
        &get(
            &server.url(&format!("/v1/jobs/{id}/distributions/bogus")),
            None,
        ),
        404,
    );
    assert_problem(
        &get(
            &server.url(&format!(
                "/v1/jobs/{id}/distributions/e1?op_start=5&op_end=2"
            )),
            None,
        ),
        400,
    );
    let cancelled = submit(
        &server,
        &json!({"devices": 1000, "operations": 1000, "seed": 1}),
    );
    delete(&server.url(&format!("/v1/jobs/{cancelled}")));
    assert_problem(
        &get(&server.url(&format!("/v1/jobs/{cancelled}/result")), None),
        409,
    );
    assert_problem(
        &get(
            &server.url(&format!("/v1/jobs/{cancelled}/distributions/e1")),
            None,
        ),
        409,
    );
}

#[test]
fn simulate_over_http_is_the_simulate_command() {
    let server = Server::start(&temp_db("simulate"), &[]);
    let scenario = r#"{"circuit": {"supply_voltage_v": 48, "current_a": 15}}"#;
    let simulated = post(
        &server.url("/v1/simulate?fidelity=closed_form"),
        scenario,
        None,
    );
    assert_eq!(simulated.status, 200);
    let mut child = Command::new(BIN)
        .args(["simulate", "--fidelity", "closed_form"])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    std::io::Write::write_all(&mut child.stdin.take().unwrap(), scenario.as_bytes()).unwrap();
    let cli: Value = serde_json::from_slice(&child.wait_with_output().unwrap().stdout).unwrap();
    assert_eq!(simulated.json(), cli);
}

#[test]
fn api_keys_are_required_and_isolate_jobs() {
    let server = Server::start(&temp_db("keys"), &["--api-key", "alpha,beta"]);
    let jobs = server.url("/v1/jobs");
    assert_problem(&get(&jobs, None), 401);
    assert_problem(&get(&jobs, Some("gamma")), 401);
    let reply = post(
        &jobs,
        &json!({"devices": 1, "operations": 1, "seed": 9}).to_string(),
        Some("alpha"),
    );
    assert_eq!(reply.status, 202);
    let id = reply.json()["id"].as_str().unwrap().to_owned();
    assert_eq!(
        get(&server.url(&format!("/v1/jobs/{id}")), Some("alpha")).status,
        200
    );
    assert_problem(
        &get(&server.url(&format!("/v1/jobs/{id}")), Some("beta")),
        404,
    );
    assert_eq!(
        get(&jobs, Some("beta")).json()["jobs"]
            .as_array()
            .unwrap()
            .len(),
        0
    );
    assert_eq!(
        get(&jobs, Some("alpha")).json()["jobs"]
            .as_array()
            .unwrap()
            .len(),
        1
    );
    assert_eq!(
        get(&server.url("/healthz"), None).status,
        200,
        "health needs no key"
    );
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

#[test]
fn openapi_docs_health_and_metrics_are_served() {
    let server = Server::start(&temp_db("system"), &[]);
    let openapi = get(&server.url("/openapi.json"), None).json();
    assert_eq!(openapi["openapi"], "3.1.0");
    for path in [
        "/v1/jobs",
        "/v1/jobs/{id}",
        "/v1/jobs/{id}/result",
        "/v1/jobs/{id}/distributions/{metric}",
        "/v1/jobs/{id}/events",
        "/v1/simulate",
        "/healthz",
        "/metrics",
    ] {
        assert!(openapi["paths"][path].is_object(), "{path} documented");
    }
    let docs = get(&server.url("/docs"), None);
    assert!(docs.body.contains("rapi-doc") && docs.content_type.starts_with("text/html"));
    assert!(get(&server.url("/docs/rapidoc-min.js"), None).body.len() > 100_000);
    assert_eq!(get(&server.url("/healthz"), None).json()["status"], "ok");
    let metrics = get(&server.url("/metrics"), None).body;
    assert!(
        metrics.contains("bouncewear_http_requests_total"),
        "{metrics}"
    );
}

#[test]
fn sigterm_hands_a_running_job_back_to_the_queue() {
    let database = temp_db("sigterm");
    let server = Server::start(&database, &[]);
    let id = submit(&server, &scattered_job(200_000, 1000, 3));
    wait_for(&server, &id, "running", Duration::from_secs(10));
    let pid = server.child.id();
    let status = Command::new("kill")
        .args(["-TERM", &pid.to_string()])
        .status()
        .unwrap();
    assert!(status.success());
    let mut server = server;
    let exit = server.child.wait().unwrap();
    assert!(exit.success(), "{exit:?}");
    let server = Server::start(&database, &["--workers", "0"]);
    let job = get(&server.url(&format!("/v1/jobs/{id}")), None).json();
    assert!(
        job["status"] == "queued" || job["status"] == "running",
        "{job}"
    );
    delete(&server.url(&format!("/v1/jobs/{id}")));
}

fn put(url: &str, body: &str) -> Reply {
    reply(
        agent()
            .put(url)
            .header("content-type", "application/json")
            .send(body),
    )
}

fn wearing_template(supply_voltage_v: f64) -> Value {
    json!({
        "devices": 60, "operations": 300, "seed": 11,
        "scenario": {"circuit": {"supply_voltage_v": supply_voltage_v, "current_a": 15}},
        "scatter": [{"parameter": "contact_radius_m", "per": "device", "distribution": {"kind": "normal", "mean": 7.7e-3, "sd": 1.5e-3, "min": 1e-3}}],
        "failure": {"e1": {"below": 0.33}}
    })
}

#[test]
fn schedules_run_now_and_report_a_trend_with_drift_flags() {
    let server = Server::start(&temp_db("schedules"), &[]);
    let schedules = server.url("/v1/schedules");
    let body = json!({"name": "nightly wear", "cron": "0 3 * * *", "time_zone": "Europe/Berlin",
                      "template": wearing_template(48.0), "statistics": ["operations.total_bounce_s.p95", "life.b10"]});
    let created = post(&schedules, &body.to_string(), None);
    assert_eq!(created.status, 201, "{}", created.body);
    let schedule = created.json();
    let id = schedule["id"].as_str().unwrap().to_owned();
    assert_eq!(
        created.headers.get("location").unwrap().to_str().unwrap(),
        format!("/v1/schedules/{id}")
    );
    assert!(schedule["next_run_at"].as_str().unwrap().ends_with('Z'));
    assert_eq!(
        get(&schedules, None).json()["schedules"]
            .as_array()
            .unwrap()
            .len(),
        1
    );

    let run_now = |server: &Server| {
        let reply = post(&server.url(&format!("/v1/schedules/{id}/run")), "", None);
        assert_eq!(reply.status, 202, "{}", reply.body);
        let job = reply.json()["id"].as_str().unwrap().to_owned();
        wait_for(server, &job, "succeeded", Duration::from_secs(60));
    };
    run_now(&server);
    run_now(&server);
    // The same template and seed: the same numbers, so no drift.
    let trend = get(&server.url(&format!("/v1/schedules/{id}/runs")), None).json();
    let runs = trend["runs"].as_array().unwrap();
    assert_eq!(runs.len(), 2);
    for run in runs {
        assert_eq!(run["manual"], true);
        for statistic in ["operations.total_bounce_s.p95", "life.b10"] {
            let value = &run["values"][statistic];
            assert!(value["value"].as_f64().unwrap() > 0.0, "{statistic}: {run}");
            assert_eq!(value["drift"], false);
        }
    }
    // A much higher supply voltage changes the wear: the next night leaves the interval.
    let changed = json!({"name": "nightly wear", "cron": "0 3 * * *", "time_zone": "Europe/Berlin",
                         "template": wearing_template(120.0), "statistics": ["operations.total_bounce_s.p95", "life.b10"]});
    assert_eq!(
        put(
            &server.url(&format!("/v1/schedules/{id}")),
            &changed.to_string()
        )
        .status,
        200
    );
    run_now(&server);
    let trend = get(&server.url(&format!("/v1/schedules/{id}/runs")), None).json();
    let last = trend["runs"].as_array().unwrap().last().unwrap().clone();
    assert_eq!(
        last["values"]["operations.total_bounce_s.p95"]["drift"], true,
        "{last}"
    );
    let svg = get(
        &server.url(&format!("/v1/schedules/{id}/plots/trend.svg")),
        None,
    );
    assert_eq!(svg.status, 200);
    assert!(svg.body.starts_with("<svg"));

    assert_eq!(
        reply(
            agent()
                .delete(&server.url(&format!("/v1/schedules/{id}")))
                .call()
        )
        .status,
        204
    );
    assert_problem(&get(&server.url(&format!("/v1/schedules/{id}")), None), 404);
}

#[test]
fn bad_schedules_name_their_field() {
    let server = Server::start(&temp_db("bad-schedules"), &[]);
    let schedules = server.url("/v1/schedules");
    for (body, pointer) in [
        (
            json!({"name": "x", "cron": "every night", "template": {}}),
            "/cron",
        ),
        (
            json!({"name": "x", "cron": "0 3 * * *", "time_zone": "Mars/Olympus", "template": {}}),
            "/time_zone",
        ),
        (
            json!({"name": "x", "cron": "0 3 * * *", "template": {"devices": 0}}),
            "/template/devices",
        ),
        (
            json!({"name": "x", "cron": "0 3 * * *", "template": {}, "statistics": ["operations.e1.p42"]}),
            "/statistics/0",
        ),
        (
            json!({"name": "", "cron": "0 3 * * *", "template": {}}),
            "/name",
        ),
        (json!({"cron": "0 3 * * *", "template": {}}), "malformed"),
    ] {
        let reply = post(&schedules, &body.to_string(), None);
        assert!(
            reply.status == 422 || reply.status == 400,
            "{body}: {}",
            reply.body
        );
        assert!(
            reply.body.contains(pointer) || reply.status == 422,
            "{body}: {}",
            reply.body
        );
        if reply.status == 422 && pointer.starts_with('/') {
            let problem = reply.json();
            assert!(
                problem["errors"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .any(|e| e["pointer"] == pointer),
                "{body}: {problem}"
            );
        }
    }
}

#[test]
fn life_analysis_is_served_as_json_and_per_device_csv() {
    let server = Server::start(&temp_db("life"), &[]);
    let id = submit(&server, &wearing_template(48.0));
    wait_for(&server, &id, "succeeded", Duration::from_secs(60));
    let life = get(&server.url(&format!("/v1/jobs/{id}/life")), None);
    assert_eq!(life.status, 200, "{}", life.body);
    let life = life.json();
    assert_eq!(
        life["failures"].as_u64().unwrap() + life["censored"].as_u64().unwrap(),
        60
    );
    assert!(life["analysis"]["weibull"]["beta"].as_f64().unwrap() > 0.0);
    assert!(life["analysis"]["b10"]["ci95"].is_array());
    let csv = get(&server.url(&format!("/v1/jobs/{id}/life?format=csv")), None);
    let rows: Vec<&str> = csv.body.lines().collect();
    assert_eq!(rows[0], "device,operations_to_failure,censored");
    assert_eq!(rows.len(), 61);
    assert!(rows[1].starts_with("0,"));
    let result = get(&server.url(&format!("/v1/jobs/{id}/result")), None).json();
    assert_eq!(result["life"], life, "the Result carries the same life");
    let plain = submit(&server, &json!({"devices": 1, "operations": 1, "seed": 1}));
    wait_for(&server, &plain, "succeeded", Duration::from_secs(20));
    assert_problem(
        &get(&server.url(&format!("/v1/jobs/{plain}/life")), None),
        404,
    );
}
