//! The same API on PostgreSQL: a job's life from submission to result (bit-identical to `run`),
//! listing, cancelling, life, and a schedule's trend, on a throwaway cluster.

use crate::support::app::{Service, Spawned, TestApp};
use crate::support::client::{agent, assert_problem, delete, get, post};
use crate::support::postgres::Postgres;
use crate::support::{run_job, scattered_job, submit_concurrently, temp_dir, wearing_template};
use serde_json::json;
use std::io::{BufRead, BufReader};
use std::time::Duration;

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
    assert_eq!(delete(&server.url(&format!("/v1/jobs/{long}"))).status, 200);
    assert_eq!(server.list_job_ids(1), [long.clone(), id.clone()]);
    assert_eq!(
        delete(&server.url(&format!("/v1/jobs/{long}?purge=true"))).status,
        204
    );
    assert_eq!(server.list_job_ids(1), std::slice::from_ref(&id));

    let wearing = server.submit(&wearing_template(48.0));
    server.wait_for(&wearing, "succeeded", Duration::from_secs(60));
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
    let mut accepted = submit_concurrently(&urls, 200);
    assert!(accepted.len() >= 150, "{} accepted", accepted.len());
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

#[test]
fn a_database_that_goes_away_gets_503_with_retry_after_and_not_ready() {
    let Some(cluster) = Postgres::start(&temp_dir("http-postgres-down")) else {
        return;
    };
    let server = TestApp::on(
        &cluster.database("down"),
        &["--workers", "0", "--request-timeout-seconds", "5"],
    );
    assert_eq!(get(&server.url("/readyz"), None).status, 200);
    if !cluster.stop() {
        return;
    }
    let jobs = get(&server.url("/v1/jobs"), None);
    let problem = assert_problem(&jobs, 503);
    assert!(jobs.header("retry-after").is_some());
    assert!(
        !problem["detail"].as_str().unwrap().contains("127.0.0.1"),
        "the cause is logged, not sent: {problem}"
    );
    assert_problem(&get(&server.url("/readyz"), None), 503);
}
