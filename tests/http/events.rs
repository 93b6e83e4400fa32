//! `/v1/events`: one stream for all of the caller's jobs, whatever their number.

use crate::support::app::{Service, TestApp};
use crate::support::client::{agent, authorized, post};
use crate::support::postgres::Postgres;
use crate::support::{scattered_job, temp_db, temp_dir};
use serde_json::Value;
use std::collections::{BTreeMap, BTreeSet};
use std::io::{BufRead, BufReader};

const KEYS_AND_ONE_WORKER: [&str; 4] = ["--api-key", "alpha,beta", "--workers", "1"];

#[test]
fn one_stream_carries_the_progress_and_end_of_every_job_of_its_key_and_no_other() {
    let server = TestApp::start(&temp_db("events"), &KEYS_AND_ONE_WORKER);
    the_stream_carries_every_job_of_its_key_and_no_other(&server);
}

/// On PostgreSQL the stream wakes on the database's announcements instead of polling.
#[test]
fn on_postgres_one_stream_carries_every_job_of_its_key_and_no_other() {
    let Some(cluster) = Postgres::start(&temp_dir("http-events-postgres")) else {
        return;
    };
    let server = TestApp::on(&cluster.database("service"), &KEYS_AND_ONE_WORKER);
    the_stream_carries_every_job_of_its_key_and_no_other(&server);
}

/// alpha's jobs, submitted before and after the stream opens, each show progress and then end on
/// alpha's stream; beta's job never appears on it.
fn the_stream_carries_every_job_of_its_key_and_no_other(server: &TestApp) {
    let submit = |key: &str, seed: u64| {
        let job = scattered_job(3000, 400, seed).to_string();
        let reply = post(&server.url("/v1/jobs"), &job, Some(key));
        assert_eq!(reply.status, 202, "{}", reply.body);
        reply.json()["id"].as_str().unwrap().to_owned()
    };
    let before = [submit("alpha", 1), submit("alpha", 2)];
    let others = submit("beta", 3);

    let mut stream = authorized(agent().get(&server.url("/v1/events")), Some("alpha"))
        .call()
        .unwrap();
    assert_eq!(stream.status(), 200);
    // A job submitted once the stream is open joins it.
    let after = submit("alpha", 4);
    let ours: BTreeSet<&str> = before.iter().chain([&after]).map(String::as_str).collect();

    // (event, data) in order, until each of alpha's jobs has ended.
    let mut events: Vec<(String, Value)> = Vec::new();
    let mut ended = BTreeMap::new();
    let mut name = String::new();
    for line in BufReader::new(stream.body_mut().as_reader()).lines() {
        let line = line.unwrap();
        if let Some(event) = line.strip_prefix("event: ") {
            name = event.to_owned();
        } else if let Some(data) = line.strip_prefix("data: ") {
            let data: Value = serde_json::from_str(data).unwrap();
            if name == "status" {
                ended.insert(data["id"].as_str().unwrap().to_owned(), data.clone());
            }
            events.push((name.clone(), data));
            if ended.len() == ours.len() {
                break;
            }
        }
    }

    assert!(
        events.iter().all(|(_, data)| data["id"] != others.as_str()),
        "another key's job on the stream: {events:?}"
    );
    for id in &ours {
        assert_eq!(ended[*id]["status"], "succeeded", "{events:?}");
        let first = events.iter().position(|(_, d)| d["id"] == *id).unwrap();
        assert_eq!(
            events[first].0, "progress",
            "job {id} shows progress before it ends: {events:?}"
        );
    }
}
