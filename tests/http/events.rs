//! `/v1/events`: one stream for all of the caller's jobs, whatever their number.

use crate::support::app::{Service, Spawned, TestApp};
use crate::support::client::{agent, assert_problem, authorized, delete, get, post};
use crate::support::postgres::Postgres;
use crate::support::{scattered_job, temp_db, temp_dir};
use serde_json::Value;
use std::collections::{BTreeMap, BTreeSet};
use std::io::{BufRead, BufReader};
use std::sync::mpsc::RecvTimeoutError;

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

/// On PostgreSQL, announcements queued while no stream was open (a sharded job's progress) cost
/// one look when a stream opens, then looks come when a job changes and every 2 s: the watcher
/// took them one a look, five looks a second for as long as they lasted.
#[test]
fn on_postgres_announcements_queued_while_nobody_listened_cost_one_look() {
    let Some(cluster) = Postgres::start(&temp_dir("http-events-backlog")) else {
        return;
    };
    let server = Spawned::on(&cluster.database("service"), &["--workers", "1"]);
    let id = server.submit(&scattered_job(3000, 1000, 5));
    server.wait_for(&id, "succeeded", std::time::Duration::from_secs(120));
    let stream = agent().get(&server.url("/v1/events")).call().unwrap();
    assert_eq!(stream.status(), 200);
    std::thread::sleep(std::time::Duration::from_millis(500));
    let before = counter(&server, "bouncewear_event_watch_looks_total");
    std::thread::sleep(std::time::Duration::from_secs(3));
    let looks = counter(&server, "bouncewear_event_watch_looks_total") - before;
    assert!(looks <= 3.0, "{looks} looks in 3 s with no job changing");
    drop(stream);
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

/// The value of a counter on the server's `/metrics` (0 before its first increment).
fn counter(server: &impl Service, name: &str) -> f64 {
    let metrics = crate::support::client::get(&server.url("/metrics"), None).body;
    metrics
        .lines()
        .find_map(|line| line.strip_prefix(name)?.strip_prefix(' ')?.parse().ok())
        .unwrap_or(0.0)
}

/// Idle streams cost no database reads of their own: one watcher reads for all of them, about
/// five times a second however many are open. And one key holds at most
/// `--max-streams-per-key`: the next gets 429 with Retry-After, while another key still gets its
/// own. A process of its own, so that its metrics are its alone.
#[test]
fn idle_streams_share_one_reader_and_each_key_has_a_cap() {
    let server = Spawned::start(
        &temp_db("events-cap"),
        &[
            "--api-key",
            "alpha,beta",
            "--workers",
            "0",
            "--max-streams-per-key",
            "6",
        ],
    );
    let open = |key: &str| {
        let reply = authorized(agent().get(&server.url("/v1/events")), Some(key)).call();
        reply.unwrap()
    };
    let streams: Vec<_> = (0..6).map(|_| open("alpha")).collect();
    assert!(streams.iter().all(|s| s.status() == 200));
    let refused = crate::support::client::reply(
        authorized(agent().get(&server.url("/v1/events")), Some("alpha")).call(),
    );
    let problem = assert_problem(&refused, 429);
    assert!(refused.header("retry-after").is_some(), "{problem}");
    assert!(
        problem["detail"]
            .as_str()
            .unwrap()
            .contains("6 event streams"),
        "{problem}"
    );
    let job = crate::support::client::reply(
        authorized(
            agent().get(&server.url("/v1/jobs/nope/events")),
            Some("alpha"),
        )
        .call(),
    );
    assert_eq!(
        job.status, 404,
        "a job is looked up before its stream takes a place"
    );
    let beta = open("beta");
    assert_eq!(beta.status(), 200, "another key has its own streams");

    // Seven streams open for 3 s: each polling on its own would read about 7 x 15 = 105 times.
    std::thread::sleep(std::time::Duration::from_millis(500));
    let before = counter(&server, "bouncewear_event_watch_looks_total");
    std::thread::sleep(std::time::Duration::from_secs(3));
    let looks = counter(&server, "bouncewear_event_watch_looks_total") - before;
    assert!(
        (5.0..=20.0).contains(&looks),
        "{looks} reads in 3 s for seven streams"
    );
    drop(streams);
    drop(beta);
}

/// Each event has an `id` naming the job's state it tells, and the first a `retry`; a client that
/// reconnects with `Last-Event-ID` is not told that state again. A queued job (no workers) stays
/// `queued` with 0 done: a fresh stream tells it at once, a resumed one only its cancellation.
#[test]
fn events_have_ids_and_a_resumed_stream_does_not_repeat_the_last() {
    let server = TestApp::start(&temp_db("events-resume"), &["--workers", "0"]);
    let reply = post(
        &server.url("/v1/jobs"),
        r#"{"devices": 2, "operations": 2}"#,
        None,
    );
    let id = reply.json()["id"].as_str().unwrap().to_owned();
    let events = server.url(&format!("/v1/jobs/{id}/events"));
    // The first event's fields, until the blank line that ends it.
    let first_event = |last_event_id: Option<&str>| {
        let mut request = agent().get(&events);
        if let Some(last) = last_event_id {
            request = request.header("last-event-id", last);
        }
        let mut stream = request.call().unwrap();
        BufReader::new(stream.body_mut().as_reader())
            .lines()
            .map(Result::unwrap)
            .take_while(|line| !line.is_empty())
            .collect::<Vec<String>>()
    };
    let fresh = first_event(None);
    let state = format!("{id}:queued:0");
    assert_eq!(fresh[0], "event: progress", "{fresh:?}");
    assert!(fresh.contains(&format!("id: {state}")), "{fresh:?}");
    assert!(fresh.contains(&"retry: 2000".to_owned()), "{fresh:?}");
    let cancel = {
        let url = server.url(&format!("/v1/jobs/{id}"));
        std::thread::spawn(move || {
            std::thread::sleep(std::time::Duration::from_millis(500));
            agent().delete(&url).call().unwrap();
        })
    };
    let resumed = first_event(Some(&state));
    cancel.join().unwrap();
    assert_eq!(resumed[0], "event: status", "{resumed:?}");
    assert!(
        resumed.contains(&format!("id: {id}:cancelled:0")),
        "{resumed:?}"
    );
}

/// A job deleted right after its end, before the watcher's next read, has its end told on both
/// kinds of stream (found from outside: 6 of 10 such jobs stayed "running" on `/v1/events`, and
/// a job's stream closed with no word when its job was cancelled and at once purged).
#[test]
fn a_job_deleted_right_after_its_end_has_its_end_told() {
    let server = TestApp::start(&temp_db("events-deleted"), &["--workers", "1"]);
    let all = follow(&server, "/v1/events");
    let mut told = ran_and_deleted(&server, &server, 0..10);
    let long = server.submit(&scattered_job(200_000, 1000, 1));
    let one = follow(&server, &format!("/v1/jobs/{long}/events"));
    let url = server.url(&format!("/v1/jobs/{long}"));
    assert_eq!(delete(&url).status, 200);
    assert_eq!(delete(&format!("{url}?purge=true")).status, 204);
    told.insert(long.clone(), "cancelled");

    let mut last = None;
    let closed = loop {
        match one.recv_timeout(TOLD_WITHIN) {
            Ok(event) => last = Some(event),
            Err(closed) => break closed,
        }
    };
    assert_eq!(
        closed,
        RecvTimeoutError::Disconnected,
        "the job's stream closes"
    );
    let last = last.expect("the job's stream tells something");
    assert_eq!(last.0, "status", "{last:?}");
    assert_eq!(last.1["status"], "cancelled", "{last:?}");
    assert_eq!(ends_told_once(&all, told.len()), told);

    // A stream opened while another is followed tells the jobs submitted after it opened, ended
    // and deleted before the watcher's next read (the re-probe: missed, 4 rounds in 4 on
    // PostgreSQL), and nothing of those before.
    let second = follow(&server, "/v1/events");
    let later = ran_and_deleted(&server, &server, 10..13);
    assert_eq!(ends_told_once(&second, later.len()), later);
    assert_eq!(ends_told_once(&all, later.len()), later);
}

/// A job another process on the same database ran, that this server deletes before its watcher
/// saw it (the newest job: gone, it no longer counted among the jobs the stream had seen), has
/// its end told once (the re-probe: told at every read of the watcher, every 2 s on PostgreSQL).
#[test]
fn a_job_this_server_never_saw_and_deleted_has_its_end_told_once() {
    let database = temp_db("events-deleted-elsewhere");
    let runner = TestApp::start(&database, &["--workers", "1"]);
    let server = TestApp::start(&database, &["--workers", "0"]);
    let all = follow(&server, "/v1/events");
    let told = ran_and_deleted(&runner, &server, 0..5);
    assert_eq!(ends_told_once(&all, told.len()), told);
}

/// How soon a stream tells an end.
const TOLD_WITHIN: std::time::Duration = std::time::Duration::from_secs(20);

/// A stream's (event, data) pairs, as they come, read on a thread of its own.
fn follow(server: &TestApp, path: &str) -> std::sync::mpsc::Receiver<(String, Value)> {
    let mut stream = agent().get(&server.url(path)).call().unwrap();
    let (sender, events) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let mut name = String::new();
        for line in BufReader::new(stream.body_mut().as_reader()).lines() {
            let Ok(line) = line else { return };
            if let Some(event) = line.strip_prefix("event: ") {
                name = event.to_owned();
            } else if let Some(data) = line.strip_prefix("data: ") {
                let data: Value = serde_json::from_str(data).unwrap();
                if sender.send((name.clone(), data)).is_err() {
                    return;
                }
            }
        }
    });
    events
}

/// A small job of each seed, submitted to `runner` and waited for there until it succeeded, then
/// deleted at once through `deleter`: their ids and statuses.
fn ran_and_deleted(
    runner: &TestApp,
    deleter: &TestApp,
    seeds: std::ops::Range<u64>,
) -> BTreeMap<String, &'static str> {
    let ran = |seed| {
        let id = runner.submit(&scattered_job(20, 20, seed));
        let ended = get(&runner.url(&format!("/v1/jobs/{id}?wait_s=10")), None).json();
        assert_eq!(ended["status"], "succeeded", "{ended}");
        assert_eq!(delete(&deleter.url(&format!("/v1/jobs/{id}"))).status, 204);
        (id, "succeeded")
    };
    seeds.map(ran).collect()
}

/// The status each of `count` jobs ended with, as `/v1/events` told it, once each: the stream is
/// read on for 1.5 s after the last, over several of the watcher's reads.
fn ends_told_once(
    all: &std::sync::mpsc::Receiver<(String, Value)>,
    count: usize,
) -> BTreeMap<String, &'static str> {
    let mut ended = BTreeMap::new();
    let later = std::time::Duration::from_millis(1500);
    let wait = |ended: &BTreeMap<_, _>| {
        if ended.len() < count {
            TOLD_WITHIN
        } else {
            later
        }
    };
    while let Ok((name, data)) = all.recv_timeout(wait(&ended)) {
        if name == "status" {
            let id = data["id"].as_str().unwrap().to_owned();
            let status = match data["status"].as_str().unwrap() {
                "succeeded" => "succeeded",
                "cancelled" => "cancelled",
                other => panic!("{other} told for {id}"),
            };
            assert_eq!(ended.insert(id, status), None, "an end told twice: {data}");
        }
    }
    assert_eq!(ended.len(), count, "every end told in time: {ended:?}");
    ended
}
