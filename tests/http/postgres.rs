//! The same API on PostgreSQL: a job's life from submission to result (bit-identical to `run`),
//! listing, cancelling, life, and a schedule's trend, on a throwaway cluster.

use crate::support::app::{Service, Spawned, TestApp, WorkerProcess};
use crate::support::client::{agent, assert_problem, delete, get, post};
use crate::support::postgres::Postgres;
use crate::support::{
    run_job, scattered_job, send_signal, submit_concurrently, temp_dir, wearing_template,
};
use serde_json::json;
use std::io::{BufRead, BufReader};
use std::time::{Duration, Instant};

#[test]
fn jobs_results_and_schedules_work_the_same_on_postgres() {
    let Some(cluster) = Postgres::start(&temp_dir("http-postgres")) else {
        return;
    };
    let server = TestApp::on(&cluster.database("service"), &[]);

    let job = scattered_job(2000, 200, 5);
    let id = server.submit(&job);
    // The progress stream wakes on PostgreSQL's announcements and ends with the final status.
    let mut events = agent()
        .get(&server.url(&format!("/v1/jobs/{id}/events")))
        .call()
        .unwrap();
    let lines: Vec<String> = BufReader::new(events.body_mut().as_reader())
        .lines()
        .map(Result::unwrap)
        .collect();
    let status = lines
        .iter()
        .position(|l| l == "event: status")
        .expect("a status event");
    assert!(
        lines[status + 1].contains(r#""status":"succeeded""#),
        "{lines:?}"
    );
    let result = get(&server.url(&format!("/v1/jobs/{id}/result")), None).json();
    let local = run_job(&job, &[]);
    assert_eq!(result["operations"], local["operations"], "to the bit");
    assert_eq!(result["devices"], local["devices"]);
    let csv = get(
        &server.url(&format!(
            "/v1/jobs/{id}/distributions/total_bounce_s?format=csv"
        )),
        None,
    );
    assert_eq!(csv.body.lines().count(), 1 + 10);

    let long = server.submit(&scattered_job(200_000, 1000, 1));
    let cancelled = delete(&server.url(&format!("/v1/jobs/{long}")));
    assert_eq!(cancelled.status, 200, "{}", cancelled.body);
    assert_eq!(server.list_job_ids(1), [long.clone(), id.clone()]);
    let purged = delete(&server.url(&format!("/v1/jobs/{long}?purge=true")));
    assert_eq!(purged.status, 204, "{}", purged.body);
    assert_eq!(server.list_job_ids(1), std::slice::from_ref(&id));

    let wearing = server.submit(&wearing_template(48.0));
    // A request that waits wakes on PostgreSQL's announcement of the job's end.
    let ended = get(&server.url(&format!("/v1/jobs/{wearing}?wait_s=30")), None).json();
    assert_eq!(ended["status"], "succeeded", "{ended}");
    let lives = get(
        &server.url(&format!("/v1/jobs/{wearing}/life?format=csv")),
        None,
    );
    assert_eq!(lives.body.lines().count(), 1 + 60);

    let schedule = post(
        &server.url("/v1/schedules"),
        &json!({"name": "nightly", "cron": "0 3 * * *", "template": {"devices": 20, "operations": 20, "seed": 3}})
            .to_string(),
        None,
    );
    assert_eq!(schedule.status, 201, "{}", schedule.body);
    let schedule = schedule.json()["id"].as_str().unwrap().to_owned();
    for _ in 0..2 {
        let run = post(
            &server.url(&format!("/v1/schedules/{schedule}/run")),
            "",
            None,
        );
        assert_eq!(run.status, 202, "{}", run.body);
        server.wait_for(
            run.json()["id"].as_str().unwrap(),
            "succeeded",
            Duration::from_secs(60),
        );
    }
    let trend = get(&server.url(&format!("/v1/schedules/{schedule}/runs")), None).json();
    let runs = trend["runs"].as_array().unwrap();
    assert_eq!(runs.len(), 2);
    assert!(
        runs.iter()
            .all(|run| run["values"]["operations.total_bounce_s.p95"]["drift"] == false)
    );

    // U+0000, which PostgreSQL cannot hold, in a path or a name: refused as the client's (503
    // with Retry-After before: the database's "invalid byte sequence").
    for path in [
        "/v1/jobs/%00".to_owned(),
        format!("/v1/jobs/{id}/compare/a%00b"),
        "/v1/schedules/%00".to_owned(),
    ] {
        assert_problem(&get(&server.url(&path), None), 400);
    }
    assert_problem(&delete(&server.url("/v1/jobs/%00")), 400);
    let named = |name: &str| json!({"name": name, "devices": 2, "operations": 2}).to_string();
    let refused = assert_problem(&post(&server.url("/v1/jobs"), &named("a\0b"), None), 422);
    assert_eq!(refused["errors"][0]["pointer"], "/name", "{refused}");
    let schedule = json!({"name": "a\0b", "cron": "0 3 * * *", "template": {}}).to_string();
    let refused = assert_problem(&post(&server.url("/v1/schedules"), &schedule, None), 422);
    assert_eq!(refused["errors"][0]["pointer"], "/name", "{refused}");
}

#[test]
fn two_api_nodes_on_one_postgres_accept_or_refuse_every_submission_and_lose_none() {
    let Some(cluster) = Postgres::start(&temp_dir("http-postgres-burst")) else {
        return;
    };
    let database = cluster.database("burst");
    // Two API processes, each with its own workers, on one database.
    let nodes = [
        Spawned::on(&database, &["--max-queued", "150"]),
        Spawned::on(&database, &["--max-queued", "150"]),
    ];
    let urls: Vec<String> = nodes.iter().map(|node| node.url("/v1/jobs")).collect();
    let (mut accepted, unavailable) = submit_concurrently(&urls, 200);
    assert!(
        accepted.len() + unavailable >= 150,
        "{} accepted, {unavailable} unavailable",
        accepted.len()
    );
    let mut listed = nodes[1].list_job_ids(100);
    accepted.sort();
    listed.sort();
    assert_eq!(
        accepted, listed,
        "every accepted job is stored, nothing else"
    );
    for id in &accepted {
        nodes[0].wait_for(id, "succeeded", Duration::from_secs(120));
    }
}

/// PostgreSQL stopped under two workers running jobs, then started again: meanwhile every API
/// path and health check answers 503 with Retry-After within about 2 s (not after the pool's
/// 30 s) and names no address; an open event stream stays open; then the service recovers by
/// itself, and every job it acknowledged ends with the result `bouncewear run` gives, its end told
/// on the stream that was open through the outage.
#[test]
fn postgres_stopped_and_restarted_under_workers_fails_fast_and_loses_nothing() {
    let Some(cluster) = Postgres::start(&temp_dir("http-postgres-down")) else {
        return;
    };
    // Leases of 5 s: a shard whose worker lost the database keeps its lease until it expires, and
    // the default 30 s made the test wait 16 s for the second job after the restart.
    let server = TestApp::on(
        &cluster.database("down"),
        &["--workers", "2", "--lease-seconds", "5"],
    );
    assert_eq!(get(&server.url("/readyz"), None).status, 200);
    let jobs: Vec<_> = (0..2)
        .map(|seed| scattered_job(20_000, 500, seed))
        .collect();
    let ids: Vec<String> = jobs.iter().map(|job| server.submit(job)).collect();
    let stream_agent: ureq::Agent = ureq::Agent::config_builder()
        .http_status_as_error(false)
        .build()
        .into();
    let mut stream = stream_agent.get(&server.url("/v1/events")).call().unwrap();
    assert_eq!(stream.status(), 200);
    let (lines_sender, lines) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stream.body_mut().as_reader()).lines() {
            let Ok(line) = line else { break };
            if lines_sender.send(line).is_err() {
                break;
            }
        }
    });
    std::thread::sleep(Duration::from_millis(500));
    if !cluster.stop() {
        return;
    }
    for path in ["/healthz", "/readyz", "/v1/jobs"] {
        let started = Instant::now();
        let reply = get(&server.url(path), None);
        let took = started.elapsed();
        let problem = assert_problem(&reply, 503);
        assert!(reply.header("retry-after").is_some(), "{path}");
        assert!(
            !problem["detail"].as_str().unwrap().contains("127.0.0.1"),
            "the cause is logged, not sent: {problem}"
        );
        // 2 s of waiting for the database, and room for cores shared with other tests.
        assert!(
            took < Duration::from_secs(5),
            "{path} answered after {took:?}"
        );
    }
    std::thread::sleep(Duration::from_secs(3));
    cluster.restart();
    let back = Instant::now();
    while get(&server.url("/healthz"), None).status != 200 {
        assert!(back.elapsed() < Duration::from_secs(30), "no recovery");
        std::thread::sleep(Duration::from_millis(200));
    }
    for (id, job) in ids.iter().zip(&jobs) {
        server.wait_for(id, "succeeded", Duration::from_secs(180));
        let result = get(&server.url(&format!("/v1/jobs/{id}/result")), None).json();
        assert_eq!(
            result["operations"],
            run_job(job, &[])["operations"],
            "to the bit"
        );
    }
    // The stream open through the outage tells both jobs' ends.
    let mut ended = Vec::new();
    let mut status = false;
    while ended.len() < ids.len() {
        let line = lines
            .recv_timeout(Duration::from_secs(30))
            .expect("the stream stays open and tells every end");
        if line == "event: status" {
            status = true;
        } else if let Some(data) = line.strip_prefix("data: ").filter(|_| status) {
            let data: serde_json::Value = serde_json::from_str(data).unwrap();
            assert_eq!(data["status"], "succeeded", "{data}");
            ended.push(data["id"].as_str().unwrap().to_owned());
            status = false;
        }
    }
    ended.sort();
    let mut expected = ids.clone();
    expected.sort();
    assert_eq!(ended, expected);
}

/// A database server whose clock runs an hour ahead of the workers': a job's times are the
/// database's (started, finished, the Result's `timing`), as its leases are. The worker stamped
/// the end with its own clock: a job finished an hour before it was created, and its wall time
/// read 0 s (an hour behind, 3600 s).
#[test]
fn a_jobs_times_are_the_databases_whatever_the_workers_clock() {
    let Some(cluster) = Postgres::start_with_clock(&temp_dir("http-postgres-clock"), "+1h") else {
        return;
    };
    let server = TestApp::on(
        &cluster.database("clock"),
        &["--min-schedule-interval-seconds", "60"],
    );
    // 3e6 operations: sharded, the Result stored by a merge step.
    let id = server.submit(&scattered_job(3000, 1000, 3));
    let job = server.wait_for(&id, "succeeded", Duration::from_secs(120));
    let time = |field: &str| rfc3339_ms(&job[field]);
    let (created, started, finished) =
        (time("created_at"), time("started_at"), time("finished_at"));
    assert!(created <= started && started <= finished, "{job}");
    // The database's clock, an hour ahead of this machine's, stamped the start and the end; the
    // API stamped the creation with its own.
    let ahead = started - chrono::Utc::now().timestamp_millis();
    assert!((3_500_000..3_700_000).contains(&ahead), "{ahead} ms: {job}");
    let wall_s =
        get(&server.url(&format!("/v1/jobs/{id}/result")), None).json()["timing"]["wall_s"]
            .as_f64()
            .unwrap();
    let took = (finished - started) as f64 / 1000.0;
    assert!(
        wall_s > 0.0 && wall_s <= took + 0.05 && took < 60.0,
        "{wall_s} s, {took} s: {job}"
    );
    // A cancel's end too (the API node stamped it with its own clock).
    let long = server.submit(&scattered_job(200_000, 1000, 4));
    let cancelled = delete(&server.url(&format!("/v1/jobs/{long}"))).json();
    let ahead = rfc3339_ms(&cancelled["finished_at"]) - chrono::Utc::now().timestamp_millis();
    assert!(
        (3_500_000..3_700_000).contains(&ahead),
        "{ahead} ms: {cancelled}"
    );
    // A schedule's next run and a manual run's time are the database's too, as the scheduler
    // reads due times (a node 10 minutes fast ran each one 10 minutes early, a probe).
    let schedule = post(
        &server.url("/v1/schedules"),
        &json!({"name": "each minute", "cron": "* * * * *", "template": {"devices": 2, "operations": 2, "seed": 3}})
            .to_string(),
        None,
    );
    assert_eq!(schedule.status, 201, "{}", schedule.body);
    let schedule = schedule.json();
    let next = rfc3339_ms(&schedule["next_run_at"]);
    let ahead = next - chrono::Utc::now().timestamp_millis();
    assert!(
        (3_500_000..3_700_000).contains(&ahead),
        "{ahead} ms: {schedule}"
    );
    let id = schedule["id"].as_str().unwrap();
    let run = post(&server.url(&format!("/v1/schedules/{id}/run")), "", None);
    assert_eq!(run.status, 202, "{}", run.body);
    let runs = get(&server.url(&format!("/v1/schedules/{id}/runs")), None).json();
    let manual = rfc3339_ms(&runs["runs"][0]["scheduled_for"]);
    let ahead = manual - chrono::Utc::now().timestamp_millis();
    assert!(
        (3_500_000..3_700_000).contains(&ahead),
        "{ahead} ms: {runs}"
    );
}

/// A time of the API's, in milliseconds since the epoch.
fn rfc3339_ms(time: &serde_json::Value) -> i64 {
    chrono::DateTime::parse_from_rfc3339(time.as_str().unwrap())
        .unwrap()
        .timestamp_millis()
}

/// A worker frozen inside one of its transactions (stopped, or cut off from the database) kept
/// that transaction's row locks: every claim skipped its shard for as long as it stayed frozen,
/// long past its lease, and the job never ended (an outside check). PostgreSQL now ends a session
/// idle in a transaction after 5 s: another worker runs the shard once its lease expires, and the
/// job succeeds with `run`'s Result while the first worker is still stopped.
#[test]
fn a_worker_frozen_inside_a_transaction_holds_its_shard_no_longer_than_5_s() {
    let Some(cluster) = Postgres::start(&temp_dir("http-postgres-frozen")) else {
        return;
    };
    let url = cluster.database("frozen");
    let server = TestApp::on(&url, &["--workers", "0"]);
    let lease = ["--workers", "1", "--lease-seconds", "1"];
    let frozen = WorkerProcess::start(&url, &lease);
    let signal = |which: &str| send_signal(frozen.child.id(), which);
    // Stopped until caught with a write transaction open (a group's store, a claim, a
    // heartbeat), a few milliseconds in each shard's run: tried again job after job.
    let idle_in_transaction = "SELECT a.pid FROM pg_stat_activity a JOIN pg_locks l ON l.pid = a.pid \
         WHERE a.datname = current_database() AND a.pid <> pg_backend_pid() \
         AND a.state LIKE 'idle in transaction%' AND l.locktype = 'transactionid' LIMIT 1";
    let query = |sql: String| -> Option<i32> {
        let url = url.clone();
        crate::support::on_own_runtime(async move {
            use sqlx::Connection;
            let mut connection = sqlx::PgConnection::connect(&url).await.unwrap();
            sqlx::query_scalar(sqlx::AssertSqlSafe(sql))
                .fetch_optional(&mut connection)
                .await
                .unwrap()
        })
    };
    let mut held = None;
    for seed in 0..5 {
        let job = scattered_job(20_000, 1000, seed);
        let id = server.submit(&job);
        let job_status =
            || get(&server.url(&format!("/v1/jobs/{id}")), None).json()["status"].clone();
        while held.is_none() && job_status() != "succeeded" {
            signal("-STOP");
            held = query(idle_in_transaction.to_owned());
            if held.is_none() {
                signal("-CONT");
                std::thread::sleep(Duration::from_millis(3));
            }
        }
        if let Some(backend) = held {
            let other = WorkerProcess::start(&url, &lease);
            server.wait_for(&id, "succeeded", Duration::from_secs(120));
            let result = get(&server.url(&format!("/v1/jobs/{id}/result")), None).json();
            assert_eq!(result["operations"], run_job(&job, &[])["operations"]);
            let alive = format!("SELECT pid FROM pg_stat_activity WHERE pid = {backend}");
            assert_eq!(query(alive), None, "the frozen session ended by PostgreSQL");
            signal("-CONT");
            drop(other);
            return;
        }
    }
    panic!("no worker caught inside a transaction in five jobs");
}
