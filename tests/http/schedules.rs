//! `/v1/schedules`: runs, the trend with drift flags, and invalid schedules.

use crate::support::app::{Service, Spawned, TestApp};
use crate::support::client::{agent, assert_problem, get, post, put, reply};
use crate::support::{temp_db, wearing_template};
use serde_json::json;
use std::time::Duration;

#[test]
fn schedules_run_now_and_report_a_trend_with_drift_flags() {
    let server = TestApp::start(&temp_db("schedules"), &[]);
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

    let run_now = |server: &TestApp| {
        let reply = post(&server.url(&format!("/v1/schedules/{id}/run")), "", None);
        assert_eq!(reply.status, 202, "{}", reply.body);
        let job = reply.json()["id"].as_str().unwrap().to_owned();
        assert_eq!(reply.header("location"), Some(&*format!("/v1/jobs/{job}")));
        server.wait_for(&job, "succeeded", Duration::from_secs(60));
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
    // A run's flag is the run's, whatever the window: the drifting run alone in `?limit=1` is
    // still compared with the run before it (it read false as the oldest run shown).
    let alone = get(
        &server.url(&format!("/v1/schedules/{id}/runs?limit=1")),
        None,
    )
    .json();
    assert_eq!(alone["runs"].as_array().unwrap().len(), 1, "{alone}");
    assert_eq!(alone["runs"][0], last, "{alone}");
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
fn a_quantile_beyond_the_data_carries_its_reason_and_never_drifts() {
    // Four devices scattered per device, seedless: each run draws its own seed, and every
    // Result's p99 says the data cannot bound it. Its values move from run to run beyond each
    // other's (meaningless) intervals; the trend says why and raises no alarm (an outside probe
    // saw drift flagged on the fourth of five such runs).
    let server = TestApp::start(&temp_db("schedules-reason"), &[]);
    let template = json!({"devices": 4, "operations": 20, "scatter": [
        {"parameter": "impact_velocity_m_s", "per": "device",
         "distribution": {"kind": "normal", "mean": 0.3, "sd": 0.1, "min": 0.05}}]});
    let body = json!({"name": "four devices", "cron": "0 3 * * *", "time_zone": "UTC",
                      "template": template, "statistics": ["operations.total_bounce_s.p99", "operations.total_bounce_s.mean"]});
    let created = post(&server.url("/v1/schedules"), &body.to_string(), None);
    assert_eq!(created.status, 201, "{}", created.body);
    let id = created.json()["id"].as_str().unwrap().to_owned();
    for _ in 0..4 {
        let reply = post(&server.url(&format!("/v1/schedules/{id}/run")), "", None);
        assert_eq!(reply.status, 202, "{}", reply.body);
        let job = reply.json()["id"].as_str().unwrap().to_owned();
        server.wait_for(&job, "succeeded", Duration::from_secs(60));
    }
    let trend = get(&server.url(&format!("/v1/schedules/{id}/runs")), None).json();
    let runs = trend["runs"].as_array().unwrap();
    assert_eq!(runs.len(), 4);
    for run in runs {
        let p99 = &run["values"]["operations.total_bounce_s.p99"];
        assert!(
            p99["reason"].as_str().unwrap().contains("beyond the data"),
            "{p99}"
        );
        assert_eq!(p99["drift"], false, "{p99}");
        assert!(
            run["values"]["operations.total_bounce_s.mean"]
                .get("reason")
                .is_none()
        );
    }
}

/// A run's drift flag is the run's whatever `?limit=` shows: a window whose run before carries a
/// reason looks back past it to the last run whose value the data bound (an outside probe: a p99
/// flagged in the whole list read false under `?limit=7`, the look-back stopping at a value with a
/// reason, which no later run is judged by).
#[test]
fn a_runs_drift_flag_looks_back_past_values_that_carry_a_reason() {
    let server = TestApp::start(&temp_db("schedules-look-back"), &[]);
    let body = |devices: u64, velocity: f64| {
        let template = json!({"devices": devices, "operations": 2, "seed": 11, "scatter": [
            {"parameter": "impact_velocity_m_s", "per": "device",
             "distribution": {"kind": "normal", "mean": velocity, "sd": 0.05, "min": 0.05}}]});
        json!({"name": "look back", "cron": "0 3 * * *", "time_zone": "UTC", "template": template,
               "statistics": ["operations.total_bounce_s.p99"]})
        .to_string()
    };
    let created = post(&server.url("/v1/schedules"), &body(1024, 0.3), None);
    assert_eq!(created.status, 201, "{}", created.body);
    let id = created.json()["id"].as_str().unwrap().to_owned();
    let schedule = server.url(&format!("/v1/schedules/{id}"));
    // Bound, then four devices (a p99 beyond the data), then bound again at a faster closing.
    for (step, replacement) in [None, Some(body(4, 0.3)), Some(body(1024, 0.5))]
        .into_iter()
        .enumerate()
    {
        if let Some(replacement) = replacement {
            assert_eq!(put(&schedule, &replacement).status, 200, "step {step}");
        }
        let reply = post(&format!("{schedule}/run"), "", None);
        assert_eq!(reply.status, 202, "{}", reply.body);
        let job = reply.json()["id"].as_str().unwrap().to_owned();
        server.wait_for(&job, "succeeded", Duration::from_secs(60));
    }
    let p99 = |trend: &serde_json::Value, run: usize| {
        trend["runs"][run]["values"]["operations.total_bounce_s.p99"].clone()
    };
    let whole = get(&format!("{schedule}/runs"), None).json();
    assert_eq!(whole["runs"].as_array().unwrap().len(), 3, "{whole}");
    assert!(p99(&whole, 0).get("reason").is_none(), "{whole}");
    assert!(p99(&whole, 1)["reason"].is_string(), "{whole}");
    assert_eq!(p99(&whole, 2)["drift"], true, "{whole}");
    for limit in [1, 2] {
        let window = get(&format!("{schedule}/runs?limit={limit}"), None).json();
        assert_eq!(
            window["runs"].as_array().unwrap().last(),
            whole["runs"].as_array().unwrap().last(),
            "?limit={limit}: {window}"
        );
    }
}

#[test]
fn bad_schedules_name_their_field() {
    let server = TestApp::start(&temp_db("bad-schedules"), &[]);
    let schedules = server.url("/v1/schedules");
    for (body, pointer) in [
        (
            json!({"name": "x", "cron": "every night", "template": {}}),
            "/cron",
        ),
        (
            // A year as a seventh field: croner reads it, the API does not take it.
            json!({"name": "x", "cron": "0 0 3 * * * 2027", "template": {}}),
            "/cron",
        ),
        (
            json!({"name": "x", "cron": "0 3 * * *", "time_zone": "Mars/Olympus", "template": {}}),
            "/time_zone",
        ),
        (
            // Every 5 minutes: below the default minimum interval of an hour.
            json!({"name": "x", "cron": "*/5 * * * *", "template": {}}),
            "/cron",
        ),
        (
            json!({"name": "x", "cron": "0 3 * * *", "template": {"devices": 0}}),
            "/template/devices",
        ),
        (
            // A rule of a job being written: a precision target on batches of 16 or more.
            json!({"name": "x", "cron": "0 3 * * *", "template": {"devices": 4,
                   "precision": {"metric": "e1", "relative_half_width": 0.1, "max_devices": 100}}}),
            "/template/devices",
        ),
        (
            json!({"name": "x", "cron": "0 3 * * *", "template": {}, "statistics": ["operations.e1.p42"]}),
            "/statistics/0",
        ),
        (
            // A statistic the template's runs never give: no failure criteria, no life.
            json!({"name": "x", "cron": "0 3 * * *", "template": {}, "statistics": ["operations.e1.p50", "life.b1"]}),
            "/statistics/1",
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

/// A schedule's run is a job accepted into the queue, counted in `bouncewear_jobs_submitted_total`
/// as a submission is (a server of its own: the in-process servers share one recorder).
#[test]
fn a_schedules_run_counts_as_a_job_submitted() {
    let server = Spawned::start(&temp_db("schedule-counted"), &["--workers", "0"]);
    let submitted = || {
        let text = get(&server.url("/metrics"), None).body;
        let line = text
            .lines()
            .find(|l| l.starts_with("bouncewear_jobs_submitted_total "))
            .unwrap_or_else(|| panic!("no submitted count:\n{text}"));
        line.rsplit(' ').next().unwrap().parse::<f64>().unwrap()
    };
    let body =
        json!({"name": "n", "cron": "0 3 * * *", "template": {"devices": 2, "operations": 2}});
    let created = post(&server.url("/v1/schedules"), &body.to_string(), None);
    assert_eq!(created.status, 201, "{}", created.body);
    let id = created.json()["id"].as_str().unwrap().to_owned();
    assert_eq!(submitted(), 0.0);
    let run = post(&server.url(&format!("/v1/schedules/{id}/run")), "", None);
    assert_eq!(run.status, 202, "{}", run.body);
    let job = json!({"devices": 2, "operations": 2}).to_string();
    assert_eq!(post(&server.url("/v1/jobs"), &job, None).status, 202);
    assert_eq!(submitted(), 2.0);
}

/// A key holds at most `--max-schedules-per-key` schedules: the next is 403 naming the flag, a
/// retry of one it created still gets it, another key counts apart, and a delete makes room;
/// the list comes in pages.
#[test]
fn a_key_holds_at_most_its_share_of_schedules() {
    let server = TestApp::start(
        &temp_db("schedule-bound"),
        &["--api-key", "alpha,beta", "--max-schedules-per-key", "2"],
    );
    let schedules = server.url("/v1/schedules");
    let body = |name: &str| {
        json!({"name": name, "cron": "0 3 * * *", "template": {"devices": 2, "operations": 2}})
            .to_string()
    };
    let keyed = |key: &str, name: &str| {
        let request = agent()
            .post(&schedules)
            .header("content-type", "application/json")
            .header("authorization", "Bearer alpha")
            .header("idempotency-key", key);
        reply(request.send(body(name).as_str()))
    };
    let first = keyed("first", "one");
    assert_eq!(first.status, 201, "{}", first.body);
    assert_eq!(post(&schedules, &body("two"), Some("alpha")).status, 201);
    let problem = assert_problem(&post(&schedules, &body("three"), Some("alpha")), 403);
    assert_eq!(
        problem["detail"],
        "this API key (every client, where the server has no keys) holds 2 schedules, the most \
         it may (--max-schedules-per-key): delete one it no longer needs \
         (DELETE /v1/schedules/{id}) before creating another"
    );
    assert_problem(&keyed("third", "three"), 403);
    let retry = keyed("first", "one");
    assert_eq!(retry.status, 201, "{}", retry.body);
    assert_eq!(retry.json()["id"], first.json()["id"]);
    assert_eq!(post(&schedules, &body("theirs"), Some("beta")).status, 201);
    let id = first.json()["id"].as_str().unwrap().to_owned();
    let deleted = reply(
        agent()
            .delete(&server.url(&format!("/v1/schedules/{id}")))
            .header("authorization", "Bearer alpha")
            .call(),
    );
    assert_eq!(deleted.status, 204, "{}", deleted.body);
    assert_eq!(post(&schedules, &body("three"), Some("alpha")).status, 201);

    // The list comes in pages, oldest first; a key sees only its own.
    let page = get(&format!("{schedules}?limit=1"), Some("alpha")).json();
    assert_eq!(page["schedules"][0]["name"], "two", "{page}");
    let cursor = page["next_cursor"].as_str().unwrap();
    let next = get(
        &format!("{schedules}?limit=1&cursor={cursor}"),
        Some("alpha"),
    )
    .json();
    assert_eq!(next["schedules"][0]["name"], "three", "{next}");
    assert!(next.get("next_cursor").is_none(), "{next}");
    let whole = get(&schedules, Some("alpha")).json();
    assert_eq!(whole["schedules"].as_array().unwrap().len(), 2, "{whole}");
    assert_problem(&get(&format!("{schedules}?limit=101"), Some("alpha")), 400);
    assert_problem(&get(&format!("{schedules}?cursor=x"), Some("alpha")), 400);
    assert_problem(
        &get(&format!("{schedules}?cursor=0{cursor}"), Some("alpha")),
        400,
    );
    assert_problem(
        &get(&format!("{schedules}?cursor=%2B{cursor}"), Some("alpha")),
        400,
    );
}

/// A scheduler tick that keeps failing (here the disk is below `--min-free-disk-mb` while a
/// schedule is due every second) is logged as an error once, not every second.
#[test]
fn a_scheduler_tick_failing_every_second_is_logged_once() {
    let database = temp_db("schedules-failing-ticks");
    let every_second = ["--min-schedule-interval-seconds", "1"];
    {
        // Made while the disk had room (below the floor, a new schedule is refused).
        let server = Spawned::start(&database, &every_second);
        let body = json!({"name": "each second", "cron": "* * * * * *", "time_zone": "UTC",
                          "template": {"devices": 1, "operations": 1}});
        let created = post(&server.url("/v1/schedules"), &body.to_string(), None);
        assert_eq!(created.status, 201, "{}", created.body);
    }
    let (_server, lines) = Spawned::logging(
        &database,
        &[&every_second[..], &["--min-free-disk-mb", "100000000"]].concat(),
    );
    std::thread::sleep(Duration::from_millis(3500));
    let logged: Vec<String> = lines.try_iter().collect();
    let failed = logged
        .iter()
        .filter(|line| line.contains("scheduler tick failed"))
        .count();
    assert_eq!(failed, 1, "{logged:#?}");
}

/// A run now is refused, as a job submitted now would be, when the stored template is larger than
/// this server allows: another instance on the database, or this one restarted with a lower
/// `--max-job-operations`, ran it unbounded.
#[test]
fn a_run_larger_than_this_server_allows_is_refused() {
    let db = temp_db("schedule-size");
    let roomy = TestApp::start(&db, &["--workers", "0"]);
    let body = json!({"name": "n", "cron": "0 3 * * *",
                      "template": {"devices": 100, "operations": 100}});
    let created = post(&roomy.url("/v1/schedules"), &body.to_string(), None);
    assert_eq!(created.status, 201, "{}", created.body);
    let id = created.json()["id"].as_str().unwrap().to_owned();
    let strict = TestApp::start(&db, &["--workers", "0", "--max-job-operations", "1000"]);
    let refused = post(&strict.url(&format!("/v1/schedules/{id}/run")), "", None);
    let problem = assert_problem(&refused, 409);
    let detail = problem["detail"].as_str().unwrap();
    assert!(
        detail.contains("/template/devices") && detail.contains("1000"),
        "{problem}"
    );
    assert!(
        get(&strict.url("/v1/jobs"), None).json()["jobs"]
            .as_array()
            .unwrap()
            .is_empty()
    );
}

/// A schedule of `template` run every second, made on a server of `db` that is stopped at once;
/// its id.
fn every_second_schedule(db: &std::path::Path, template: serde_json::Value) -> String {
    let server = TestApp::start(db, &EVERY_SECOND);
    let body = json!({"name": "n", "cron": "* * * * * *", "template": template});
    let created = post(&server.url("/v1/schedules"), &body.to_string(), None);
    assert_eq!(created.status, 201, "{}", created.body);
    assert_eq!(created.json()["skipped_runs"], 0);
    assert!(created.json()["last_skipped"].is_null());
    created.json()["id"].as_str().unwrap().to_owned()
}

/// A scheduler of a server without workers that runs a schedule every second.
const EVERY_SECOND: [&str; 4] = ["--workers", "0", "--min-schedule-interval-seconds", "1"];

/// Schedule `id` on `server` once it has skipped two runs or more (5 s at most).
fn skipped_twice(server: &Spawned, id: &str) -> serde_json::Value {
    let url = server.url(&format!("/v1/schedules/{id}"));
    let mut schedule = get(&url, None).json();
    for _ in 0..100 {
        if schedule["skipped_runs"].as_u64().unwrap() >= 2 {
            break;
        }
        std::thread::sleep(Duration::from_millis(50));
        schedule = get(&url, None).json();
    }
    schedule
}

/// `bouncewear_scheduled_runs_skipped_total` on `server`'s `/metrics`.
fn skipped_on_metrics(server: &Spawned) -> u64 {
    let metrics = get(&server.url("/metrics"), None).body;
    let counted = metrics
        .lines()
        .find_map(|l| l.strip_prefix("bouncewear_scheduled_runs_skipped_total "));
    let counted = counted.unwrap_or_else(|| panic!("no skipped count:\n{metrics}"));
    counted.parse().unwrap()
}

/// A night the scheduler skips, its template refused by this server's limits now, shows on the
/// schedule (how many, the latest and why) and on `/metrics`, not only in the log.
#[test]
fn a_run_the_scheduler_skips_shows_on_the_schedule() {
    let db = temp_db("schedule-skipped");
    let id = every_second_schedule(&db, json!({"devices": 100, "operations": 100}));
    let strict = Spawned::start(
        &db,
        &[&EVERY_SECOND[..], &["--max-job-operations", "1000"]].concat(),
    );
    let schedule = skipped_twice(&strict, &id);
    assert!(
        schedule["skipped_runs"].as_u64().unwrap() >= 2,
        "{schedule}"
    );
    let reason = schedule["last_skipped"]["reason"].as_str().unwrap();
    assert!(
        reason.contains("/template/devices") && reason.contains("this server allows 1000"),
        "{schedule}"
    );
    let due = schedule["last_skipped"]["scheduled_for"].as_str().unwrap();
    assert!(due.ends_with(".000Z"), "a due time, whole seconds: {due}");
    assert!(skipped_on_metrics(&strict) >= 2);
}

/// Due times that passed while the server was down are skipped but the latest, and counted on
/// `/metrics` as the schedule counts them (they showed on the schedule alone, found from
/// outside).
#[test]
fn due_times_passed_while_the_server_was_down_count_on_metrics() {
    let db = temp_db("schedule-down");
    let id = every_second_schedule(&db, json!({"devices": 2, "operations": 2}));
    std::thread::sleep(Duration::from_millis(3500));
    let second = Spawned::start(&db, &EVERY_SECOND);
    let schedule = skipped_twice(&second, &id);
    let reason = schedule["last_skipped"]["reason"]
        .as_str()
        .unwrap_or_default();
    assert!(reason.starts_with("not run at its due time"), "{schedule}");
    // Every skip of this process is a catch-up's: the counter and the schedule's count grow
    // together (the metric read first: the schedule can only have counted more by then).
    let counted = skipped_on_metrics(&second);
    let url = second.url(&format!("/v1/schedules/{id}"));
    let on_schedule = get(&url, None).json()["skipped_runs"].as_u64().unwrap();
    assert!(
        (2..=on_schedule).contains(&counted),
        "{counted}: {schedule}"
    );
}

/// A schedule whose API key was taken off the server skips its runs (it ran on, and no key could
/// see or stop it); with the key back, its owner sees each night skipped and why.
#[test]
fn a_schedule_whose_key_was_removed_skips_its_runs() {
    let db = temp_db("schedule-key-gone");
    let both = [&EVERY_SECOND[..], &["--api-key", "alpha,beta"]].concat();
    let server = TestApp::start(&db, &both);
    let body = json!({"name": "n", "cron": "* * * * * *",
                      "template": {"devices": 2, "operations": 2}});
    let created = post(
        &server.url("/v1/schedules"),
        &body.to_string(),
        Some("beta"),
    );
    assert_eq!(created.status, 201, "{}", created.body);
    let id = created.json()["id"].as_str().unwrap().to_owned();
    drop(server);
    let alpha_only = [&EVERY_SECOND[..], &["--api-key", "alpha"]].concat();
    let server = TestApp::start(&db, &alpha_only);
    std::thread::sleep(Duration::from_millis(2500));
    drop(server);
    // Still allowing runs a second apart: under the default hour, a due run would be skipped for
    // its cron before the read below (the skip this test reads replaced, once in a CI run).
    let server = TestApp::start(&db, &both);
    let schedule = get(&server.url(&format!("/v1/schedules/{id}")), Some("beta")).json();
    assert!(
        schedule["skipped_runs"].as_u64().unwrap() >= 2,
        "{schedule}"
    );
    let reason = schedule["last_skipped"]["reason"].as_str().unwrap();
    assert!(reason.contains("API key"), "{schedule}");
    // The night skipped has no run (this server, with the key back, runs the next ones).
    let runs = get(
        &server.url(&format!("/v1/schedules/{id}/runs")),
        Some("beta"),
    )
    .json();
    let skipped_for = &schedule["last_skipped"]["scheduled_for"];
    assert!(
        runs["runs"]
            .as_array()
            .unwrap()
            .iter()
            .all(|run| &run["scheduled_for"] != skipped_for),
        "{runs}\n{schedule}"
    );
}
