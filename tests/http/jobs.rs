//! `/v1/jobs`: submission to result, listing, cancelling, the queue bound, life, and every 4xx.

use crate::support::app::{Service, TestApp};
use crate::support::client::{
    Reply, agent, assert_problem, assert_problem_saying, authorized, delete, get, post, reply,
};
use crate::support::{
    on_own_runtime, run_job, scattered_job, submit_concurrently, temp_db, wearing_template,
};
use serde_json::{Value, json};
use std::io::{BufRead, BufReader};
use std::time::{Duration, Instant};

#[test]
fn a_job_goes_from_submission_to_result_with_live_progress() {
    let server = TestApp::start(&temp_db("lifecycle"), &[]);
    let job = scattered_job(3000, 400, 77);
    let id = server.submit(&job);

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
    for field in ["error", "waiting"] {
        assert!(status.get(field).is_some_and(Value::is_null), "{field}");
    }
    // The job as it runs (as submitted, defaults filled in), and the URLs of what it has.
    let spec = &status["spec"];
    for field in ["name", "devices", "operations", "seed", "scatter", "limits"] {
        assert_eq!(spec[field], job[field], "{field}");
    }
    assert_eq!(spec["scenario"]["circuit"]["current_a"], 15.0);
    assert_eq!(spec["scenario"]["mechanism"]["static_force_n"], 0.344);
    let this = format!("/v1/jobs/{id}");
    assert_eq!(
        status["links"],
        json!({
            "self": this, "result": format!("{this}/result"), "events": format!("{this}/events"),
            "shards": format!("{this}/shards"),
            "distributions": format!("{this}/distributions/{{metric}}"),
            "life": format!("{this}/life"), "plots": format!("{this}/plots/{{kind}}"),
        })
    );
    let listed = get(&server.url("/v1/jobs"), None).json();
    assert!(
        listed["jobs"][0].get("spec").is_none(),
        "listings stay small"
    );

    let result = get(&server.url(&format!("/v1/jobs/{id}/result")), None);
    assert_eq!(result.status, 200);
    let (result, local) = (result.json(), run_job(&job, &[]));
    assert_eq!(
        result["operations"], local["operations"],
        "server and CLI agree to the bit"
    );
    assert_eq!(result["devices"], local["devices"]);
    // Every default filled in, the metrics too: the list the Result has.
    assert_eq!(status["spec"]["metrics"], result["job"]["metrics"]);
    assert!(status["spec"]["metrics"].as_array().unwrap().len() > 10);

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
    // A range that holds no operation has no bin, even inside one (the bin 80-120 overlapped
    // `[100, 100)` and `[110, 90)` by the ends alone).
    for empty in ["op_start=100&op_end=100", "op_start=110&op_end=90"] {
        for metric in ["total_bounce_s", "eroded_mass_kg"] {
            let url = format!("/v1/jobs/{id}/distributions/{metric}?{empty}");
            assert_problem(&get(&server.url(&url), None), 404);
        }
    }
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
    // The limit's exceedance with its interval, as the JSON has it.
    let whole = get(
        &server.url(&format!("/v1/jobs/{id}/distributions/total_bounce_s")),
        None,
    )
    .json();
    let header: Vec<&str> = rows[0].split(',').collect();
    let first: Vec<&str> = rows[1].split(',').collect();
    let cell = |name: &str| -> f64 {
        let at = header.iter().position(|h| *h == name).expect(name);
        first[at].parse().unwrap()
    };
    let exceedance = &whole["bins"][0]["exceedance"];
    assert_eq!(cell("exceedance_probability"), exceedance["probability"]);
    assert_eq!(cell("exceedance_ci95_lo"), exceedance["ci95"][0]);
    assert_eq!(cell("exceedance_ci95_hi"), exceedance["ci95"][1]);
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

/// A job of up to 2,000,000 operations runs whole, as one shard; one more operation per device
/// and it runs as its 32 groups and a merge step. Both give `bouncewear run`'s Result to the bit.
#[test]
fn a_small_job_runs_as_one_shard_and_a_larger_one_in_groups_with_the_same_bits() {
    let server = TestApp::start(&temp_db("whole"), &[]);
    for (operations, shards) in [(20_000, 1), (20_001, 33)] {
        let job = scattered_job(100, operations, 5);
        let id = server.submit(&job);
        server.wait_for(&id, "succeeded", Duration::from_secs(60));
        let listed = get(&server.url(&format!("/v1/jobs/{id}/shards")), None).json();
        let listed = listed["shards"].as_array().unwrap().clone();
        assert_eq!(listed.len(), shards, "{listed:?}");
        // Every shard names the worker that last held it, and has no error (null, present).
        for shard in &listed {
            let worker = shard["worker"].as_str().unwrap_or_default();
            assert!(worker.contains('/'), "{shard}");
            assert_eq!(shard.get("error"), Some(&Value::Null), "{shard}");
            assert_eq!(shard["status"], "done", "{shard}");
        }
        if shards == 33 {
            assert_pages_of_shards(&server, &id, &listed);
        }
        if shards == 1 {
            assert!(listed[0].get("group").is_none(), "{listed:?}");
            assert_eq!(listed[0]["operations_total"], 2_000_000);
            assert_eq!(listed[0]["operations_done"], 2_000_000);
        }
        let result = get(&server.url(&format!("/v1/jobs/{id}/result")), None).json();
        let local = run_job(&job, &[]);
        assert_eq!(result["operations"], local["operations"], "{operations}");
        assert_eq!(result["devices"], local["devices"], "{operations}");
    }
}

/// `/shards` in pages of 10 and of 33: the same shards in the same order as the whole list, a
/// cursor only where another page has shards; a bad page is a 400 naming what is wrong.
fn assert_pages_of_shards(server: &TestApp, id: &str, whole: &[Value]) {
    for limit in [10, 33] {
        let mut paged = Vec::new();
        let mut cursor: Option<String> = None;
        loop {
            let at = cursor.as_ref().map(|c| format!("&cursor={c}"));
            let path = format!(
                "/v1/jobs/{id}/shards?limit={limit}{}",
                at.unwrap_or_default()
            );
            let page = get(&server.url(&path), None).json();
            paged.extend(page["shards"].as_array().unwrap().iter().cloned());
            match page.get("next_cursor") {
                Some(next) => cursor = Some(next.as_str().unwrap().to_owned()),
                None => break,
            }
        }
        assert_eq!(paged, whole, "limit {limit}");
    }
    for (query, says) in [
        ("limit=0", "limit must be from 1 to 1000"),
        ("limit=1001", "limit must be from 1 to 1000"),
        ("cursor=0", "is not one this server gave"),
        ("cursor=x", "is not one this server gave"),
    ] {
        let reply = get(&server.url(&format!("/v1/jobs/{id}/shards?{query}")), None);
        assert_eq!(reply.status, 400, "{query}");
        let detail = reply.json()["detail"]
            .as_str()
            .unwrap_or_default()
            .to_owned();
        assert!(detail.contains(says), "{query}: {detail}");
    }
    // Past the end: an empty page, no cursor.
    let beyond = get(
        &server.url(&format!("/v1/jobs/{id}/shards?cursor=500")),
        None,
    )
    .json();
    assert_eq!(beyond, json!({"shards": []}));
}

#[test]
fn jobs_are_listed_newest_first_with_cursor_paging() {
    let server = TestApp::start(&temp_db("paging"), &[]);
    let ids: Vec<String> = (0..5)
        .map(|seed| server.submit(&json!({"devices": 1, "operations": 1, "seed": seed})))
        .collect();
    let seen = server.list_job_ids(2);
    let newest_first: Vec<String> = ids.into_iter().rev().collect();
    assert_eq!(seen, newest_first);
    // A page that ends the list has no cursor, however full it is: none leads to an empty page.
    for limit in [5, 6] {
        let page = get(&server.url(&format!("/v1/jobs?limit={limit}")), None).json();
        assert_eq!(page["jobs"].as_array().unwrap().len(), 5);
        assert!(page.get("next_cursor").is_none_or(Value::is_null), "{page}");
    }
    let first = get(&server.url("/v1/jobs?limit=4"), None).json();
    let cursor = first["next_cursor"].as_str().unwrap();
    let last = get(
        &server.url(&format!("/v1/jobs?limit=4&cursor={cursor}")),
        None,
    )
    .json();
    assert_eq!(last["jobs"].as_array().unwrap().len(), 1);
}

/// A key's listing cursor names its place and nothing else: not the row's number, whose gaps
/// would count other keys' jobs. It is sealed with the database's secret, so it opens on every
/// instance of that database and on no other.
#[test]
fn listing_cursors_are_sealed_with_the_databases_secret() {
    let database = temp_db("sealed-cursors");
    let keys = ["--api-key", "alpha,beta", "--workers", "0"];
    let (one, two) = (
        TestApp::start(&database, &keys),
        TestApp::start(&database, &keys),
    );
    let submit = |server: &TestApp, key: &str, seed: u64| {
        let job = json!({"devices": 1, "operations": 1, "seed": seed});
        let reply = post(&server.url("/v1/jobs"), &job.to_string(), Some(key));
        assert_eq!(reply.status, 202, "{}", reply.body);
        reply.json()["id"].as_str().unwrap().to_owned()
    };
    let older = submit(&one, "alpha", 1);
    for seed in 0..7 {
        submit(&two, "beta", seed);
    }
    let newer = submit(&two, "alpha", 2);
    let first = get(&one.url("/v1/jobs?limit=1"), Some("alpha")).json();
    assert_eq!(first["jobs"][0]["id"], newer.as_str());
    let cursor = first["next_cursor"].as_str().unwrap();
    assert!(
        cursor.len() == 24 && cursor.bytes().all(|b| b.is_ascii_hexdigit()),
        "{cursor}"
    );
    let next = get(
        &two.url(&format!("/v1/jobs?limit=1&cursor={cursor}")),
        Some("alpha"),
    )
    .json();
    assert_eq!(next["jobs"][0]["id"], older.as_str(), "{next}");
    assert!(next.get("next_cursor").is_none(), "{next}");
    // The row numbers the cursors stood for before are no cursors now.
    assert_problem(&get(&one.url("/v1/jobs?cursor=9"), Some("alpha")), 400);

    let elsewhere = TestApp::start(&temp_db("sealed-cursors-elsewhere"), &keys);
    let refused = get(
        &elsewhere.url(&format!("/v1/jobs?cursor={cursor}")),
        Some("alpha"),
    );
    let problem = assert_problem(&refused, 400);
    assert_eq!(
        problem["detail"],
        format!("cursor `{cursor}` is not one this server gave")
    );
}

#[test]
fn cancelling_stops_a_running_job_a_retried_cancel_keeps_it_and_a_purge_deletes_it() {
    let server = TestApp::start(&temp_db("cancel"), &[]);
    let id = server.submit(&scattered_job(200_000, 1000, 1));
    server.wait_for(&id, "running", Duration::from_secs(10));
    let cancelled = delete(&server.url(&format!("/v1/jobs/{id}")));
    assert_eq!(
        (cancelled.status, cancelled.json()["status"].as_str()),
        (200, Some("cancelled"))
    );
    assert_eq!(
        get(&server.url(&format!("/v1/jobs/{id}/result")), None).status,
        409
    );
    // the worker is free again: a small job runs to the end
    let next = server.submit(&json!({"devices": 2, "operations": 2, "seed": 1}));
    server.wait_for(&next, "succeeded", Duration::from_secs(20));
    assert_eq!(
        get(&server.url(&format!("/v1/jobs/{id}")), None).json()["status"],
        "cancelled"
    );
    // A retried cancel changes nothing: the record stays.
    let again = delete(&server.url(&format!("/v1/jobs/{id}")));
    assert_eq!(
        (again.status, again.json()["status"].as_str()),
        (200, Some("cancelled"))
    );
    assert_eq!(
        get(&server.url(&format!("/v1/jobs/{id}")), None).json()["status"],
        "cancelled"
    );
    let maybe = assert_problem(
        &delete(&server.url(&format!("/v1/jobs/{id}?purge=maybe"))),
        400,
    );
    assert_eq!(
        maybe["detail"],
        "the query string: purge: expected true or false"
    );
    assert_eq!(
        delete(&server.url(&format!("/v1/jobs/{id}?purge=true"))).status,
        204
    );
    assert_problem(&get(&server.url(&format!("/v1/jobs/{id}")), None), 404);
}

/// `POST /v1/jobs/{id}/cancel` cancels a running job and answers any job with itself: one that
/// ended, succeeded or cancelled, is left as it is, never deleted (a `DELETE` of a succeeded job
/// deletes it). An unknown job is 404, a query it does not take 400.
#[test]
fn a_cancel_only_request_never_deletes() {
    let server = TestApp::start(&temp_db("cancel-only"), &[]);
    let cancel = |id: &str| post(&server.url(&format!("/v1/jobs/{id}/cancel")), "", None);
    let running = server.submit(&scattered_job(200_000, 1000, 1));
    server.wait_for(&running, "running", Duration::from_secs(10));
    let cancelled = cancel(&running);
    assert_eq!(
        (cancelled.status, cancelled.json()["status"].as_str()),
        (200, Some("cancelled"))
    );
    assert_eq!(cancel(&running).json()["status"], "cancelled");
    let done = server.submit(&json!({"devices": 2, "operations": 2, "seed": 1}));
    server.wait_for(&done, "succeeded", Duration::from_secs(20));
    let kept = cancel(&done);
    assert_eq!(
        (kept.status, kept.json()["status"].as_str()),
        (200, Some("succeeded"))
    );
    assert_eq!(
        get(&server.url(&format!("/v1/jobs/{done}/result")), None).status,
        200
    );
    assert_problem(&cancel("no-such-job"), 404);
    assert_problem(
        &post(
            &server.url(&format!("/v1/jobs/{done}/cancel?purge=true")),
            "",
            None,
        ),
        400,
    );
}

/// A job of few devices with many operations each: its progress moves while they run, and a
/// cancel frees its compute threads at once. A sweep of the API found one of 20 devices x 10^8
/// operations at progress 0 throughout, and its groups running half a minute after the cancel:
/// a batch of devices told its progress, and looked for a cancel, only between batches. Here each
/// group is one device of 10^8 operations, so a group part done shows progress within a batch.
#[test]
fn a_job_of_few_long_devices_moves_and_stops_when_cancelled() {
    let server = TestApp::start(&temp_db("long-devices"), &[]);
    let id = server.submit(&json!({"devices": 2, "operations": 100_000_000, "seed": 1}));
    let started = Instant::now();
    loop {
        let shards = get(&server.url(&format!("/v1/jobs/{id}/shards")), None).json();
        let part_done = shards["shards"].as_array().unwrap().iter().any(|shard| {
            let done = shard["operations_done"].as_u64().unwrap();
            0 < done && done < shard["operations_total"].as_u64().unwrap()
        });
        if part_done {
            break;
        }
        assert!(
            started.elapsed() < Duration::from_secs(20),
            "no progress: {shards}"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    let cancelled = delete(&server.url(&format!("/v1/jobs/{id}")));
    assert_eq!(cancelled.json()["status"], "cancelled");
    // No shard of it reads as running: the one that was says it stopped.
    let shards = get(&server.url(&format!("/v1/jobs/{id}/shards")), None).json();
    let shards = shards["shards"].as_array().unwrap();
    assert!(
        shards.iter().all(|s| s["status"] != "running"),
        "{shards:?}"
    );
    assert!(
        shards.iter().any(|s| s["history"][0]
            .as_str()
            .is_some_and(|line| line.ends_with("stopped: job cancelled"))),
        "{shards:?}"
    );
    // The next job finds the compute threads free: no device of the cancelled one runs on.
    let next = server.submit(&json!({"devices": 64, "operations": 200, "seed": 2}));
    server.wait_for(&next, "succeeded", Duration::from_secs(5));
}

/// A job whose valid inputs combine past f64 fails at once with the metric named, on the
/// server as on the command line, instead of a Result of `null`s (on the server, a database that
/// refused them three times).
#[test]
fn a_job_beyond_f64_fails_once_with_the_metric_named() {
    let text = include_str!("../data/beyond_f64_job.json");
    let job: Value = serde_json::from_str(text).unwrap();
    let reason = "first_impact_plastic_work_j leaves the range of f64 (beyond 1.8e308)";
    let server = TestApp::start(&temp_db("beyond-f64"), &[]);
    let id = server.submit(&job);
    let failed = server.wait_for(&id, "failed", Duration::from_secs(30));
    let error = failed["error"].as_str().unwrap();
    assert!(error.contains(reason), "{error}");
    let shards = get(&server.url(&format!("/v1/jobs/{id}/shards")), None).json();
    assert_eq!(shards["shards"][0]["attempt"], 1, "not retried: {shards}");
    let ran = crate::support::bouncewear(&["run", "-"], &job.to_string());
    assert_eq!(ran.status.code(), Some(1), "{ran:?}");
    assert!(
        String::from_utf8_lossy(&ran.stderr).contains(reason),
        "{ran:?}"
    );
}

/// `wait_s`: one request answers the moment the job ends (its Result, the ended job, a cancel
/// seen by a request already waiting), or with the job as it is once the time passed; a wait out
/// of range is refused by name.
#[test]
fn a_request_with_wait_s_answers_when_the_job_ends() {
    let server = TestApp::start(&temp_db("wait"), &[]);
    let job = scattered_job(2000, 200, 5);
    let id = server.submit(&job);
    // Without the wait this would be 409: the job has only just been queued.
    let result = get(
        &server.url(&format!("/v1/jobs/{id}/result?wait_s=30")),
        None,
    );
    assert_eq!(result.status, 200, "{}", result.body);
    assert_eq!(
        result.json()["operations"],
        run_job(&job, &[])["operations"]
    );
    let ended = get(&server.url(&format!("/v1/jobs/{id}?wait_s=30")), None).json();
    assert_eq!(ended["status"], "succeeded");

    let long = server.submit(&scattered_job(200_000, 1000, 1));
    let job_url = server.url(&format!("/v1/jobs/{long}"));
    let started = Instant::now();
    let running = get(&format!("{job_url}?wait_s=0.3"), None).json();
    assert!(started.elapsed() >= Duration::from_millis(300), "it waited");
    assert!(
        ["queued", "running"].contains(&running["status"].as_str().unwrap()),
        "{running}"
    );
    assert_problem(&get(&format!("{job_url}/result?wait_s=0.1"), None), 409);
    let waiting = {
        let url = format!("{job_url}?wait_s=30");
        std::thread::spawn(move || get(&url, None).json())
    };
    std::thread::sleep(Duration::from_millis(200));
    assert_eq!(delete(&job_url).status, 200);
    assert_eq!(waiting.join().unwrap()["status"], "cancelled");

    for bad in ["31", "-1", "NaN", "soon"] {
        let problem = assert_problem(&get(&format!("{job_url}?wait_s={bad}"), None), 400);
        assert!(
            problem["detail"].as_str().unwrap().contains("wait_s"),
            "{bad}: {problem}"
        );
    }
}

/// One number from the database file, read beside the running server; `?1` is the job's id.
fn sql_number(database: &std::path::Path, sql: &'static str, job: &str) -> i64 {
    let url = format!("sqlite://{}", database.display());
    let job = job.to_owned();
    let binds_job = sql.contains("?1");
    on_own_runtime(async move {
        use sqlx::Connection;
        let mut connection = sqlx::SqliteConnection::connect(&url).await.unwrap();
        let query = sqlx::query_scalar(sql);
        let query = if binds_job { query.bind(job) } else { query };
        query.fetch_one(&mut connection).await.unwrap()
    })
}

/// The pages of the database file in use: freed pages are reused by later writes.
const USED_PAGES: &str = "SELECT (SELECT page_count FROM pragma_page_count()) \
     - (SELECT freelist_count FROM pragma_freelist_count())";

#[test]
fn deleting_a_finished_job_deletes_every_row_stored_for_it_and_frees_its_pages() {
    let database = temp_db("delete");
    let server = TestApp::start(&database, &[]);
    let id = server.submit(&wearing_template(48.0));
    server.wait_for(&id, "succeeded", Duration::from_secs(60));
    let tables: [&'static str; 5] = [
        "SELECT COUNT(*) FROM jobs WHERE id = ?1",
        "SELECT COUNT(*) FROM shards WHERE job_id = ?1",
        "SELECT COUNT(*) FROM results WHERE job_id = ?1",
        "SELECT COUNT(*) FROM distributions WHERE job_id = ?1",
        "SELECT COUNT(*) FROM device_lives WHERE job_id = ?1",
    ];
    for sql in tables {
        assert!(sql_number(&database, sql, &id) > 0, "{sql}");
    }
    let used = sql_number(&database, USED_PAGES, &id);
    assert_eq!(delete(&server.url(&format!("/v1/jobs/{id}"))).status, 204);
    for sql in tables {
        assert_eq!(sql_number(&database, sql, &id), 0, "{sql}");
    }
    let now_used = sql_number(&database, USED_PAGES, &id);
    assert!(now_used < used, "{now_used} pages in use, {used} before");
    assert_problem(
        &get(&server.url(&format!("/v1/jobs/{id}/result")), None),
        404,
    );
    assert_problem(&delete(&server.url(&format!("/v1/jobs/{id}"))), 404);
}

#[test]
fn jobs_that_ended_before_the_retention_are_deleted_at_start_up() {
    let database = temp_db("retention");
    let done = TestApp::ran(
        &database,
        &json!({"devices": 2, "operations": 2, "seed": 1}),
    );
    let server = TestApp::start(&database, &["--retain-days", "0", "--workers", "0"]);
    let queued = server.submit(&json!({"devices": 2, "operations": 2, "seed": 2}));
    let started = Instant::now();
    while get(&server.url(&format!("/v1/jobs/{done}")), None).status != 404 {
        assert!(
            started.elapsed() < Duration::from_secs(10),
            "{done} is still there"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    assert_eq!(
        get(&server.url(&format!("/v1/jobs/{queued}")), None).json()["status"],
        "queued",
        "a job that has not ended stays"
    );
}

#[test]
fn two_hundred_concurrent_submissions_are_all_accepted_or_refused_with_429() {
    let server = TestApp::start(&temp_db("concurrent"), &["--max-queued", "150"]);
    let (mut accepted, unavailable) = submit_concurrently(&[server.url("/v1/jobs")], 200);
    assert!(accepted.len() + unavailable >= 150);
    let mut listed = server.list_job_ids(100);
    accepted.sort();
    listed.sort();
    assert_eq!(
        accepted, listed,
        "every accepted job is stored, nothing else"
    );
}

/// One key that fills its share of the queue gets 429; another key still gets in.
#[test]
fn a_second_key_gets_in_when_the_first_has_filled_its_share_of_the_queue() {
    let server = TestApp::start(
        &temp_db("fair"),
        &[
            "--api-key",
            "alpha,beta",
            "--max-queued",
            "6",
            "--workers",
            "0",
        ],
    );
    let jobs = server.url("/v1/jobs");
    let job = r#"{"devices": 1, "operations": 1}"#;
    for _ in 0..3 {
        assert_eq!(post(&jobs, job, Some("alpha")).status, 202);
    }
    let refused = post(&jobs, job, Some("alpha"));
    let problem = assert_problem(&refused, 429);
    assert!(refused.header("retry-after").is_some());
    assert!(
        problem["detail"]
            .as_str()
            .unwrap()
            .contains("this API key's share of it, is full: at most 6 unfinished jobs in all and 3 unfinished jobs per API key"),
        "{problem}"
    );
    for _ in 0..3 {
        assert_eq!(post(&jobs, job, Some("beta")).status, 202);
    }
    assert_problem(&post(&jobs, job, Some("beta")), 429);
}

/// A key whose jobs store its quota or more gets 403 for a new job (or a schedule's run now),
/// naming the flag; another key still gets in, a retry with the same Idempotency-Key still gets
/// its job, and a purge frees the quota.
#[test]
fn a_key_whose_jobs_store_its_quota_gets_no_new_job_until_it_deletes_some() {
    let server = TestApp::start(
        &temp_db("stored-quota"),
        &["--api-key", "alpha,beta", "--max-stored-mb-per-key", "1"],
    );
    let jobs = server.url("/v1/jobs");
    let small = r#"{"devices": 1, "operations": 1}"#;
    // A summary a bin for 100 bins of 50 devices: about 2 MB stored.
    let large = r#"{"devices": 50, "operations": 100, "bin_operations": 1, "seed": 4}"#;
    let keyed = |key: &str| {
        let request = agent()
            .post(&jobs)
            .header("content-type", "application/json")
            .header("idempotency-key", key);
        reply(authorized(request, Some("alpha")).send(large))
    };
    let id = keyed("once").json()["id"].as_str().unwrap().to_owned();
    let this = server.url(&format!("/v1/jobs/{id}"));
    let started = Instant::now();
    let done = loop {
        let job = get(&format!("{this}?wait_s=5"), Some("alpha")).json();
        if job["status"] != "queued" && job["status"] != "running" {
            break job;
        }
        assert!(started.elapsed() < Duration::from_secs(120), "{job}");
    };
    assert_eq!(done["status"], "succeeded", "{done}");
    let stored = done["stored_bytes"].as_u64().unwrap();
    assert!(stored > 1 << 20, "{stored} bytes");

    let refused = post(&jobs, small, Some("alpha"));
    let problem = assert_problem(&refused, 403);
    assert_eq!(
        problem["detail"],
        format!(
            "the jobs of this API key (of every client, where the server has no keys) store \
             {stored} bytes, at or over its quota of 1048576 bytes (--max-stored-mb-per-key): \
             delete the jobs it no longer needs (DELETE /v1/jobs/{{id}}?purge=true) before \
             submitting more"
        )
    );
    assert_eq!(keyed("once").status, 202, "a retry gets the job it created");
    assert_eq!(keyed("twice").status, 403);
    // A schedule's run now is a job of the key too.
    let schedule = post(
        &server.url("/v1/schedules"),
        &json!({"name": "nightly", "cron": "0 3 * * *", "template": {"devices": 1, "operations": 1}})
            .to_string(),
        Some("alpha"),
    );
    assert_eq!(schedule.status, 201, "{}", schedule.body);
    let run = server.url(&format!(
        "/v1/schedules/{}/run",
        schedule.json()["id"].as_str().unwrap()
    ));
    assert_problem(&post(&run, "", Some("alpha")), 403);
    assert_eq!(post(&jobs, small, Some("beta")).status, 202);
    let purged =
        reply(authorized(agent().delete(&format!("{this}?purge=true")), Some("alpha")).call());
    assert_eq!(purged.status, 204, "{}", purged.body);
    assert_eq!(post(&jobs, small, Some("alpha")).status, 202);
    assert_eq!(post(&run, "", Some("alpha")).status, 202);
}

/// A query parameter the operation does not take is a 400 naming it and what it does take, on
/// every documented route, the document and its page too; the dashboard's pages are not the
/// API's and take any. The document declares the 400 on every operation.
#[test]
fn unknown_query_parameters_are_refused_by_name() {
    let server = TestApp::start(&temp_db("unknown-query"), &[]);
    let id = server.submit(&json!({"devices": 2, "operations": 2, "seed": 1}));
    server.wait_for(&id, "succeeded", Duration::from_secs(60));
    let refused = [
        (
            format!("/v1/jobs/{id}/distributions/total_bounce_s?quantiles=0.5&thresholds=0.011"),
            "unknown query parameter `thresholds`: GET /v1/jobs/{id}/distributions/{metric} \
             takes only `exceedance`, `format`, `op_end`, `op_start`, `quantiles`",
        ),
        (
            "/v1/jobs?status=cancelled&limit=2".to_owned(),
            "unknown query parameter `status`: GET /v1/jobs takes only `cursor`, `limit`",
        ),
        (
            format!("/v1/jobs/{id}?verbose=1&a=2"),
            "unknown query parameter `a`, `verbose`: GET /v1/jobs/{id} takes only `wait_s`",
        ),
    ];
    for (path, detail) in refused {
        let problem = assert_problem(&get(&server.url(&path), None), 400);
        assert_eq!(problem["detail"], detail, "{path}");
    }
    for path in [
        "/openapi.json",
        "/docs",
        "/docs/rapidoc-min.js",
        "/healthz",
        "/metrics",
    ] {
        let problem = assert_problem(&get(&server.url(&format!("{path}?foo=1")), None), 400);
        let detail = format!("unknown query parameter `foo`: GET {path} takes no query parameters");
        assert_eq!(problem["detail"], detail, "{path}");
    }
    let document = get(&server.url("/openapi.json"), None).json();
    for (path, item) in document["paths"].as_object().unwrap() {
        for (method, operation) in item.as_object().unwrap() {
            let bad = &operation["responses"]["400"];
            assert!(bad.is_object(), "{method} {path} declares no 400");
        }
    }
    let taken = format!("/v1/jobs/{id}/distributions/total_bounce_s?quantiles=0.5&op_start=0");
    assert_eq!(get(&server.url(&taken), None).status, 200);
    assert_eq!(get(&server.url("/v1/jobs?limit=2"), None).status, 200);
    assert_eq!(
        get(&server.url(&format!("/jobs/{id}?tab=1")), None).status,
        200
    );
}

#[test]
fn bad_requests_get_the_right_4xx_problem() {
    let server = TestApp::start(
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
    // A path segment that is not UTF-8 once percent-decoded: a problem, not axum's plain text.
    for path in [
        "/v1/jobs/%FF",
        "/v1/jobs/%C3%28/result",
        "/v1/schedules/%FF/runs",
    ] {
        let problem = assert_problem(&get(&server.url(path), None), 400);
        assert!(
            problem["detail"].as_str().unwrap().contains("UTF-8"),
            "{problem}"
        );
    }
    // Nor U+0000, on any database (PostgreSQL cannot compare it: a 503 there before).
    for path in [
        "/v1/jobs/%00",
        "/v1/jobs/a%00/result",
        "/v1/schedules/%00/runs",
    ] {
        assert_problem_saying(&get(&server.url(path), None), 400, "U+0000");
    }
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
    // Two Content-Types: the first won, whatever the second said.
    assert_problem(
        &reply(
            agent()
                .post(&jobs)
                .header("content-type", "application/json")
                .header("content-type", "text/plain")
                .send("{}"),
        ),
        415,
    );
    // A compressed body is not decoded: 415 naming its encoding, not "not UTF-8".
    let gzipped = assert_problem(
        &reply(
            agent()
                .post(&jobs)
                .header("content-type", "application/json")
                .header("content-encoding", "gzip")
                .send(&b"\x1f\x8b\x08\x00"[..]),
        ),
        415,
    );
    assert!(
        gzipped["detail"]
            .as_str()
            .unwrap()
            .contains("Content-Encoding: gzip"),
        "{gzipped}"
    );
    // Bytes that are not UTF-8: malformed, named at the value they fall in.
    let not_utf8 = assert_problem(
        &reply(
            agent()
                .post(&jobs)
                .header("content-type", "application/json")
                .send(&b"{\"devices\": 2, \"name\": \"ab\xff\"}"[..]),
        ),
        400,
    );
    assert_eq!(not_utf8["errors"][0]["pointer"], "/name", "{not_utf8}");
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
    // A parameter that does not parse is named in a query's words, not Rust's parser's
    // ("Failed to deserialize query string: limit: invalid digit found in string").
    for (query, said) in [
        (
            "/v1/jobs?limit=abc",
            "the query string: limit: expected a whole number",
        ),
        (
            "/v1/jobs?limit=99999999999999999999",
            "the query string: limit: a whole number too large",
        ),
        (
            "/v1/jobs/no-such-job?wait_s=",
            "the query string: wait_s: expected a number, got nothing",
        ),
    ] {
        let problem = assert_problem(&get(&server.url(query), None), 400);
        assert_eq!(problem["detail"], said, "{query}");
    }
    assert_problem(
        &reply(
            agent()
                .put(&jobs)
                .header("content-type", "application/json")
                .send("{}"),
        ),
        405,
    );
    let id = server.submit(&json!({"devices": 1, "operations": 1, "seed": 1}));
    server.wait_for(&id, "succeeded", Duration::from_secs(20));
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
        404,
    );
    let cancelled = server.submit(&json!({"devices": 1000, "operations": 1000, "seed": 1}));
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
fn life_analysis_is_served_as_json_and_per_device_csv() {
    let server = TestApp::start(&temp_db("life"), &[]);
    let id = server.submit(&wearing_template(48.0));
    server.wait_for(&id, "succeeded", Duration::from_secs(60));
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
    // A Weibayes demonstration is the JSON analysis': asked of the CSV, it is refused, not ignored.
    let weibayes = format!("/v1/jobs/{id}/life?format=csv&weibayes_beta=2");
    let problem = assert_problem(&get(&server.url(&weibayes), None), 400);
    assert!(
        problem["detail"]
            .as_str()
            .unwrap()
            .contains("`weibayes_beta`"),
        "{problem}"
    );
    assert_eq!(rows.len(), 61);
    assert!(rows[1].starts_with("0,"));
    // A failed device gives the operation it failed at; a censored one none.
    let (mut failed, mut censored) = (0, 0);
    for row in &rows[1..] {
        match row.split(',').collect::<Vec<_>>()[..] {
            [_, operations, "false"] => {
                assert!(operations.parse::<u64>().unwrap() <= 300, "{row}");
                failed += 1;
            }
            [_, "", "true"] => censored += 1,
            _ => panic!("{row}"),
        }
    }
    assert_eq!(
        (failed, censored),
        (
            life["failures"].as_u64().unwrap(),
            life["censored"].as_u64().unwrap()
        )
    );
    // `Accept: text/csv` asks for the same CSV; the query's `format` wins over it.
    let accept = |value: &str, query: &str| {
        reply(
            agent()
                .get(&server.url(&format!("/v1/jobs/{id}/life{query}")))
                .header("accept", value)
                .call(),
        )
    };
    assert_eq!(accept("text/csv", "").body, csv.body);
    assert_eq!(
        accept("application/json;q=0.5, text/csv", "").body,
        csv.body
    );
    assert_eq!(accept("text/csv;q=0.5, application/json", "").json(), life);
    assert_eq!(accept("text/csv", "?format=json").json(), life);
    assert_eq!(accept("*/*", "").json(), life);
    // A range counts for the types it covers, the most specific one deciding.
    assert_eq!(accept("text/*, application/json;q=0.5", "").body, csv.body);
    assert_eq!(accept("text/*", "").body, csv.body);
    assert_eq!(accept("text/csv;q=0.9, */*", "").json(), life);
    assert_eq!(accept("*/*;q=0.1, text/*;q=0.5", "").body, csv.body);
    assert_eq!(accept("text/*, text/csv;q=0", "").json(), life);
    let result = get(&server.url(&format!("/v1/jobs/{id}/result")), None).json();
    assert_eq!(result["life"], life, "the Result carries the same life");
    let plain = server.submit(&json!({"devices": 1, "operations": 1, "seed": 1}));
    server.wait_for(&plain, "succeeded", Duration::from_secs(20));
    assert_problem(
        &get(&server.url(&format!("/v1/jobs/{plain}/life")), None),
        404,
    );
}

/// A job whose devices never fail has no Weibull fit, but a Weibayes demonstration with a known
/// shape: 20 devices through 50 operations, beta 2, 90 % give `eta >= 50 sqrt(20 / ln 10)`, the
/// zero-failure test. The candidate fits are listed for a job whose devices fail.
#[test]
fn a_job_without_failures_demonstrates_life_by_weibayes() {
    let server = TestApp::start(&temp_db("weibayes"), &[]);
    let id = server.submit(&json!({"devices": 20, "operations": 50, "seed": 3,
        "failure": {"e1": {"below": 0.0001}}}));
    server.wait_for(&id, "succeeded", Duration::from_secs(60));
    let life = |query: &str| get(&server.url(&format!("/v1/jobs/{id}/life{query}")), None);
    let plain = life("").json();
    assert_eq!(
        (plain["failures"].as_u64(), plain["censored"].as_u64()),
        (Some(0), Some(20))
    );
    assert!(plain["analysis"]["weibull"].is_null());
    assert!(plain.get("weibayes").is_none());
    let demonstrated = life("?weibayes_beta=2").json()["weibayes"].clone();
    let eta_lower = 50.0 * (20.0 / 10f64.ln()).sqrt();
    let got = demonstrated["eta_lower"].as_f64().unwrap();
    assert!((got / eta_lower - 1.0).abs() < 1e-12, "{demonstrated}");
    assert_eq!(demonstrated["confidence"], 0.9);
    assert!(demonstrated["eta"].is_null());
    let stricter = life("?weibayes_beta=2&confidence=0.99").json()["weibayes"]["eta_lower"]
        .as_f64()
        .unwrap();
    assert!(stricter < got);
    for (query, named) in [
        ("?weibayes_beta=0", "weibayes_beta"),
        ("?weibayes_beta=2&confidence=1", "confidence"),
        ("?confidence=0.9", "confidence"),
    ] {
        let problem = assert_problem(&life(query), 400);
        assert!(
            problem["detail"].as_str().unwrap().contains(named),
            "{query}: {problem}"
        );
        // The query's fault whatever the job's state: a running job's was a 409 (an outside
        // probe), an unknown job's a 404.
        let unknown = format!("/v1/jobs/00000000-0000-0000-0000-000000000000/life{query}");
        assert_problem(&get(&server.url(&unknown), None), 400);
    }

    let wearing = server.submit(&wearing_template(48.0));
    server.wait_for(&wearing, "succeeded", Duration::from_secs(60));
    let analysis =
        get(&server.url(&format!("/v1/jobs/{wearing}/life")), None).json()["analysis"].clone();
    let fits: Vec<&str> = analysis["fits"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f["distribution"].as_str().unwrap())
        .collect();
    // The three-parameter Weibull is there only where its likelihood has a maximum inside.
    let location = usize::from(fits.contains(&"weibull_3p"));
    assert_eq!(fits.len(), 4 + location, "{analysis}");
    for name in ["weibull", "lognormal", "gamma", "exponential"] {
        assert!(fits.contains(&name), "{fits:?}");
    }
}

#[test]
fn a_sensitivity_job_has_a_sensitivity_plot_and_a_job_without_one_gets_404() {
    let server = TestApp::start(&temp_db("sensitivity-plot"), &[]);
    let mut job = scattered_job(64, 100, 5);
    job["bin_operations"] = json!(50);
    job["sensitivity"] = json!({"method": "sobol"});
    let id = server.submit(&job);
    server.wait_for(&id, "succeeded", Duration::from_secs(60));
    let plot = |id: &str, query: &str| {
        get(
            &server.url(&format!("/v1/jobs/{id}/plots/sensitivity.svg{query}")),
            None,
        )
    };
    let svg = plot(&id, "");
    assert_eq!(svg.status, 200, "{}", svg.body);
    assert_eq!(svg.content_type, "image/svg+xml");
    assert!(svg.body.starts_with("<svg") && svg.body.ends_with("</svg>\n"));
    assert!(svg.body.contains("total_bounce_s") && svg.body.contains("contact_radius_m"));
    assert!(
        svg.body.contains("operations 0\u{2013}49") && svg.body.contains("operations 50\u{2013}99")
    );
    assert!(!svg.body.contains("NaN"));
    // A device metric has its indices over the devices; a metric the analysis lacks is 404.
    let device = plot(&id, "?metric=final_radius_m");
    assert_eq!(device.status, 200, "{}", device.body);
    assert!(device.body.contains("devices at the end of the test"));
    assert_problem(&plot(&id, "?metric=no_such_metric"), 404);

    let plain = server.submit(&scattered_job(4, 20, 5));
    server.wait_for(&plain, "succeeded", Duration::from_secs(20));
    let problem = assert_problem(&plot(&plain, ""), 404);
    assert!(
        problem["detail"]
            .as_str()
            .unwrap()
            .contains("no sensitivity analysis"),
        "{problem}"
    );
}

/// A distribution of many bins is read and written off the async threads and of few bins on
/// them: the same bins either way, each representation with its tag.
#[test]
fn a_distribution_of_many_bins_reads_as_one_of_few() {
    let server = TestApp::start(&temp_db("many-bins"), &[]);
    let mut job = scattered_job(4, 100, 5);
    job["bin_operations"] = json!(1);
    let id = server.submit(&job);
    server.wait_for(&id, "succeeded", Duration::from_secs(60));
    let url = |query: &str| server.url(&format!("/v1/jobs/{id}/distributions/e1{query}"));
    let many = get(&url(""), None);
    assert_eq!(many.status, 200, "{}", many.body);
    let bins = many.json()["bins"].as_array().unwrap().clone();
    assert_eq!(bins.len(), 100);
    let few = get(&url("?op_end=10"), None).json();
    assert_eq!(few["bins"].as_array().unwrap()[..], bins[..10]);
    let csv = get(&url("?format=csv"), None);
    assert_eq!((csv.status, csv.body.lines().count()), (200, 101));
    let few_csv = get(&url("?format=csv&op_end=10"), None);
    assert!(
        csv.body.starts_with(&few_csv.body),
        "the first ten rows alike"
    );
    for reply in [&many, &csv] {
        let tag = reply.header("etag").unwrap();
        let url = if reply.content_type.starts_with("text/csv") {
            url("?format=csv")
        } else {
            url("")
        };
        assert_eq!(get_if_none_match(&url, tag, None).status, 304);
    }
}

/// A job whose result holds many rows is stored in short transactions: submissions meanwhile are
/// all accepted (or refused with 429 once the queue is full), never failed. Its device lives are
/// listed up to `--max-listed-lives` and streamed page by page, while the life analysis counts
/// every device.
#[test]
fn submissions_go_on_while_a_large_result_is_stored_and_its_lives_stream_in_pages() {
    let server = TestApp::start(
        &temp_db("large-result"),
        &["--workers", "1", "--max-listed-lives", "15000"],
    );
    let mut job = wearing_template(48.0);
    job["devices"] = json!(25_000);
    job["operations"] = json!(40);
    job["bin_operations"] = json!(1);
    job["failure"] = json!({"e1": {"below": 0.4}});
    let id = server.submit(&job);
    let jobs = [server.url("/v1/jobs")];
    let mut rounds = 0;
    let started = Instant::now();
    loop {
        let status = get(&server.url(&format!("/v1/jobs/{id}")), None).json()["status"].clone();
        if status == "succeeded" {
            break;
        }
        assert!(status == "queued" || status == "running", "{status}");
        assert!(
            started.elapsed() < Duration::from_secs(300),
            "the job did not end"
        );
        // Ten at a time for a while; fair share serves them beside the large job, which then
        // has the worker to itself.
        if rounds < 30 {
            let _ = submit_concurrently(&jobs, 10);
            rounds += 1;
        } else {
            std::thread::sleep(Duration::from_millis(50));
        }
    }
    assert!(rounds > 0, "submissions ran alongside the job");
    let resource = get(&server.url(&format!("/v1/jobs/{id}")), None).json();
    assert!(resource["stored_bytes"].as_u64().unwrap() > 15_000 * 24);
    let life = get(&server.url(&format!("/v1/jobs/{id}/life")), None).json();
    assert_eq!(
        life["failures"].as_u64().unwrap() + life["censored"].as_u64().unwrap(),
        25_000
    );
    let url = server.url(&format!("/v1/jobs/{id}/life?format=csv"));
    let csv = get(&url, None);
    assert_eq!(csv.status, 200);
    let rows: Vec<&str> = csv.body.lines().collect();
    assert_eq!(rows.len(), 15_001, "the header and the listed devices");
    assert!(rows[1].starts_with("0,") && rows[15_000].starts_with("14999,"));
    assert!(
        rows[1..].windows(2).all(|w| {
            let device = |row: &str| row.split(',').next().unwrap().parse::<u64>().unwrap();
            device(w[1]) == device(w[0]) + 1
        }),
        "every listed device once, in order, across pages"
    );
    let tag = csv.header("etag").unwrap().to_owned();
    let again = reply(agent().get(&url).header("if-none-match", &tag).call());
    assert_eq!(again.status, 304);
}

/// GET `url` with `accept-encoding`: the status, the `content-encoding` and the raw body.
fn get_encoded(url: &str, accept_encoding: &str) -> (u16, Option<String>, Vec<u8>) {
    let mut response = agent()
        .get(url)
        .header("accept-encoding", accept_encoding)
        .call()
        .unwrap();
    let encoding = response
        .headers()
        .get("content-encoding")
        .map(|v| v.to_str().unwrap().to_owned());
    let body = response
        .body_mut()
        .with_config()
        .limit(1 << 28)
        .read_to_vec()
        .unwrap();
    (response.status().as_u16(), encoding, body)
}

#[test]
fn a_result_comes_gzip_or_br_compressed_when_the_client_accepts_it() {
    use std::io::Read;
    let server = TestApp::start(&temp_db("compression"), &[]);
    let id = server.submit(&scattered_job(20, 50, 5));
    server.wait_for(&id, "succeeded", Duration::from_secs(60));
    let url = server.url(&format!("/v1/jobs/{id}/result"));
    let (status, encoding, plain) = get_encoded(&url, "identity");
    assert_eq!((status, encoding), (200, None));
    let plain: Value = serde_json::from_slice(&plain).unwrap();

    let (status, encoding, gzipped) = get_encoded(&url, "gzip");
    assert_eq!((status, encoding.as_deref()), (200, Some("gzip")));
    let mut text = Vec::new();
    flate2::read::GzDecoder::new(&gzipped[..])
        .read_to_end(&mut text)
        .unwrap();
    assert!(gzipped.len() * 3 < text.len(), "JSON compresses well");
    assert_eq!(serde_json::from_slice::<Value>(&text).unwrap(), plain);

    let (status, encoding, brotli) = get_encoded(&url, "br");
    assert_eq!((status, encoding.as_deref()), (200, Some("br")));
    let mut text = Vec::new();
    brotli_decompressor::Decompressor::new(&brotli[..], 4096)
        .read_to_end(&mut text)
        .unwrap();
    assert_eq!(serde_json::from_slice::<Value>(&text).unwrap(), plain);
}

/// GET `url` with `If-None-Match: tag`.
/// The names every `Vary` line of `reply` lists, lower case, sorted, once each.
fn varies(reply: &Reply) -> Vec<String> {
    let mut names: Vec<String> = (reply.headers.get_all("vary").iter())
        .flat_map(|v| v.to_str().unwrap().split(','))
        .map(|n| n.trim().to_lowercase())
        .collect();
    names.sort();
    names.dedup();
    names
}

fn get_if_none_match(url: &str, tag: &str, key: Option<&str>) -> Reply {
    reply(authorized(agent().get(url).header("if-none-match", tag), key).call())
}

#[test]
fn a_succeeded_jobs_results_are_immutable_with_an_etag_and_a_current_tag_gets_304() {
    let server = TestApp::start(&temp_db("etag"), &[]);
    let id = server.submit(&wearing_template(48.0));
    server.wait_for(&id, "succeeded", Duration::from_secs(60));
    let mut tags = Vec::new();
    for path in [
        "result",
        "distributions/e1",
        "distributions/e1?format=csv",
        "distributions/e1?op_start=100",
        "life",
        "life?format=csv",
    ] {
        let url = server.url(&format!("/v1/jobs/{id}/{path}"));
        let first = get(&url, None);
        assert_eq!(first.status, 200, "{path}: {}", first.body);
        assert_eq!(
            first.header("cache-control"),
            Some("public, max-age=31536000, immutable"),
            "{path}"
        );
        let tag = first.header("etag").expect("an ETag").to_owned();
        let again = get_if_none_match(&url, &tag, None);
        assert_eq!((again.status, again.body.as_str()), (304, ""), "{path}");
        assert_eq!(again.header("etag"), Some(tag.as_str()), "{path}");
        // A 304 carries the Vary its 200 would (RFC 9110 15.4.5): it lacked accept-encoding.
        assert_eq!(varies(&again), varies(&first), "{path}");
        assert!(
            varies(&again).contains(&"accept-encoding".to_owned()),
            "{path}"
        );
        let listed = get_if_none_match(&url, &format!("W/\"0\", {tag}"), None);
        assert_eq!(listed.status, 304, "{path}: a tag among others");
        let stale = get_if_none_match(&url, "W/\"0\"", None);
        assert_eq!((stale.status, &stale.body), (200, &first.body), "{path}");
        tags.push(tag);
    }
    tags.sort();
    tags.dedup();
    assert_eq!(tags.len(), 6, "each representation has its own tag");
}

#[test]
fn with_api_keys_results_are_cached_privately_and_unfinished_jobs_not_at_all() {
    let server = TestApp::start(&temp_db("etag-keys"), &["--api-key", "alpha"]);
    let jobs = server.url("/v1/jobs");
    let submit = |job: Value| {
        let reply = post(&jobs, &job.to_string(), Some("alpha"));
        assert_eq!(reply.status, 202, "{}", reply.body);
        reply.json()["id"].as_str().unwrap().to_owned()
    };
    let done = submit(json!({"devices": 2, "operations": 20, "seed": 3}));
    let result = server.url(&format!("/v1/jobs/{done}/result"));
    let deadline = std::time::Instant::now() + Duration::from_secs(60);
    let first = loop {
        let reply = get(&result, Some("alpha"));
        if reply.status == 200 || std::time::Instant::now() > deadline {
            break reply;
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    assert_eq!(
        (first.status, first.header("cache-control")),
        (200, Some("private, max-age=31536000, immutable"))
    );
    // A browser whose key changed must not answer from the last key's copy.
    let varies = varies(&first);
    assert!(varies.contains(&"authorization".to_owned()), "{varies:?}");
    let tag = first.header("etag").unwrap();
    assert_eq!(get_if_none_match(&result, tag, Some("alpha")).status, 304);
    assert_problem(&get_if_none_match(&result, tag, None), 401);

    let running = submit(json!({"devices": 1000, "operations": 1_000_000, "seed": 4}));
    let unfinished = get(
        &server.url(&format!("/v1/jobs/{running}/result")),
        Some("alpha"),
    );
    assert_problem(&unfinished, 409);
    assert_eq!(
        (
            unfinished.header("etag"),
            unfinished.header("cache-control")
        ),
        (None, None)
    );
    let cancel = agent().delete(&server.url(&format!("/v1/jobs/{running}")));
    assert_eq!(reply(authorized(cancel, Some("alpha")).call()).status, 200);
}

/// 422, a problem that names the header.
fn assert_key_reused(reply: &Reply) {
    let problem = assert_problem(reply, 422);
    let detail = problem["detail"].as_str().unwrap();
    assert!(detail.contains("Idempotency-Key"), "{problem}");
}

#[test]
fn a_retry_with_the_same_idempotency_key_gets_the_first_resource_and_another_body_422() {
    let server = TestApp::start(&temp_db("idempotency"), &["--workers", "0"]);
    let post_with = |path: &str, key: &str, body: &Value| {
        reply(
            agent()
                .post(&server.url(path))
                .header("content-type", "application/json")
                .header("idempotency-key", key)
                .send(&body.to_string()),
        )
    };
    // No seed: the server draws one, and a retry must not draw another.
    let job = json!({"devices": 1, "operations": 1});
    let first = post_with("/v1/jobs", "retry-1", &job);
    let again = post_with("/v1/jobs", "retry-1", &job);
    assert_eq!((first.status, again.status), (202, 202));
    assert_eq!(first.json(), again.json());
    assert_eq!(again.header("location"), first.header("location"));
    assert_eq!(again.header("idempotent-replayed"), Some("true"));
    assert_eq!(server.list_job_ids(10).len(), 1, "one job for two requests");
    let changed = post_with(
        "/v1/jobs",
        "retry-1",
        &json!({"devices": 2, "operations": 1}),
    );
    assert_key_reused(&changed);
    assert_problem(&post_with("/v1/jobs", "two words", &job), 400);
    // Two keys in one request: which one was meant is not the server's to guess (it keyed on
    // the first, and replayed it to a request that sent the first alone).
    let twice = reply(
        agent()
            .post(&server.url("/v1/jobs"))
            .header("content-type", "application/json")
            .header("idempotency-key", "retry-1")
            .header("idempotency-key", "retry-2")
            .send(&job.to_string()),
    );
    assert_problem_saying(&twice, 400, "more than once");

    // Keys are per collection: the same key makes one schedule.
    let schedule = json!({"name": "n", "cron": "0 3 * * *", "time_zone": "UTC",
                          "template": {"devices": 1, "operations": 1}});
    let first = post_with("/v1/schedules", "retry-1", &schedule);
    let again = post_with("/v1/schedules", "retry-1", &schedule);
    assert_eq!((first.status, again.status), (201, 201), "{}", first.body);
    assert_eq!(first.json()["id"], again.json()["id"]);
    let renamed = json!({"name": "m", "cron": "0 3 * * *", "time_zone": "UTC",
                         "template": {"devices": 1, "operations": 1}});
    assert_key_reused(&post_with("/v1/schedules", "retry-1", &renamed));
}

/// A correlated, truncated lognormal scatter of a scenario constant runs through the shards to a
/// Result that counts the rejected draws of its random truncated scatter; a matrix that is not
/// positive definite is refused by its pointer.
#[test]
fn a_correlated_truncated_scatter_runs_and_a_bad_matrix_is_refused_by_its_pointer() {
    let server = TestApp::start(&temp_db("correlated"), &[]);
    let mut job = json!({
        "devices": 40, "operations": 5, "seed": 8,
        "scenario": {"circuit": {"supply_voltage_v": 48.0, "current_a": 15.0}},
        "scatter": [
            {"parameter": "inertia_kg_m2", "per": "operation",
             "distribution": {"kind": "lognormal", "median": 1.6e-5, "sigma": 0.3, "min": 1.4e-5}},
            {"parameter": "impact_velocity_m_s", "per": "operation",
             "distribution": {"kind": "uniform", "min": 0.2, "max": 0.3}},
            {"parameter": "kappa", "per": "device",
             "distribution": {"kind": "lognormal", "median": 0.35, "sigma": 0.3, "min": 0.3}}],
        "correlation": {"parameters": ["inertia_kg_m2", "impact_velocity_m_s"],
                        "matrix": [[1.0, -0.5], [-0.5, 1.0]]}
    });
    let id = server.submit(&job);
    server.wait_for(&id, "succeeded", Duration::from_secs(60));
    let result = get(&server.url(&format!("/v1/jobs/{id}/result")), None).json();
    assert_eq!(result["job"]["correlation"], job["correlation"]);
    assert_eq!(result["counts"]["operations"], 200);
    // Correlated draws invert the truncated CDF; the random kappa draws reject below its min.
    let rejections = &result["counts"]["truncation_rejections"];
    assert_eq!(rejections[0], 0, "{result}");
    assert!(rejections[2].as_u64().unwrap() > 0, "{result}");
    let pointers: Vec<&str> = result["diagnostics"]
        .as_array()
        .unwrap()
        .iter()
        .map(|d| d["pointer"].as_str().unwrap())
        .collect();
    assert!(
        pointers.contains(&"/scatter/2/distribution"),
        "{pointers:?}"
    );

    job["correlation"]["matrix"] = json!([[1, 1], [1, 1]]);
    let refused = assert_problem(&post(&server.url("/v1/jobs"), &job.to_string(), None), 422);
    assert_eq!(refused["errors"][0]["pointer"], "/correlation/matrix/1");
}

/// Fair share: with one worker busy on a large job (2e8 operations, about a minute here), a small
/// job submitted behind it, by the same key or another, finishes in seconds rather than after the
/// large one; the large one is still running then.
#[test]
fn a_small_job_behind_a_large_one_finishes_in_seconds_for_any_key() {
    let server = TestApp::start(
        &temp_db("fair-share"),
        &["--api-key", "alpha,beta", "--workers", "1"],
    );
    let submit = |job: &Value, key: &str| {
        let reply = post(&server.url("/v1/jobs"), &job.to_string(), Some(key));
        assert_eq!(reply.status, 202, "{}", reply.body);
        reply.json()["id"].as_str().unwrap().to_owned()
    };
    let status = |id: &str, key: &str| {
        let job = get(&server.url(&format!("/v1/jobs/{id}")), Some(key)).json();
        job["status"].as_str().unwrap().to_owned()
    };
    let large = submit(&scattered_job(200_000, 1000, 1), "alpha");
    let started = Instant::now();
    while status(&large, "alpha") != "running" {
        assert!(started.elapsed() < Duration::from_secs(10));
        std::thread::sleep(Duration::from_millis(20));
    }
    let small = json!({"devices": 20, "operations": 100, "seed": 2});
    for key in ["alpha", "beta"] {
        let id = submit(&small, key);
        let submitted = Instant::now();
        while status(&id, key) != "succeeded" {
            assert!(
                submitted.elapsed() < Duration::from_secs(20),
                "{key}'s small job waits behind the large one"
            );
            std::thread::sleep(Duration::from_millis(20));
        }
        eprintln!(
            "{key}'s small job: {:?} from submission to its result",
            submitted.elapsed()
        );
        assert_eq!(status(&large, "alpha"), "running");
    }
    let cancel = authorized(
        agent().delete(&server.url(&format!("/v1/jobs/{large}"))),
        Some("alpha"),
    );
    assert_eq!(reply(cancel.call()).status, 200);
}

/// A job that asks no life analysis or rare event is 404 at those parts whatever its status: they
/// never come, so a client waiting out a 409 would wait in vain. One that asks is 409 until it
/// succeeds.
#[test]
fn parts_a_job_never_has_are_404_before_it_ends() {
    let server = TestApp::start(&temp_db("never-parts"), &["--workers", "0"]);
    let plain = post(
        &server.url("/v1/jobs"),
        r#"{"devices": 2, "operations": 2}"#,
        None,
    );
    assert_eq!(plain.status, 202, "{}", plain.body);
    let plain = plain.json()["id"].as_str().unwrap().to_owned();
    // A UUID is case-insensitive on input: the uppercase id names the same job.
    let upper = get(
        &server.url(&format!("/v1/jobs/{}", plain.to_uppercase())),
        None,
    );
    assert_eq!(upper.status, 200, "{}", upper.body);
    assert_eq!(upper.json()["id"], plain.as_str());
    for (part, why) in [
        ("life", "no failure criteria"),
        ("rare_event", "asks no rare event"),
    ] {
        let reply = get(&server.url(&format!("/v1/jobs/{plain}/{part}")), None);
        let problem = assert_problem(&reply, 404);
        assert!(
            problem["detail"].as_str().unwrap().contains(why),
            "{problem}"
        );
    }
    let failing = post(
        &server.url("/v1/jobs"),
        r#"{"devices": 2, "operations": 2, "failure": {"total_bounce_s": {"above": 0.001}}}"#,
        None,
    );
    assert_eq!(failing.status, 202, "{}", failing.body);
    let failing = failing.json()["id"].as_str().unwrap().to_owned();
    let life = get(&server.url(&format!("/v1/jobs/{failing}/life")), None);
    assert_problem(&life, 409);

    // So are the plots and the metrics it never has (they were 409 before it ended, 404 after).
    let one_metric = post(
        &server.url("/v1/jobs"),
        r#"{"devices": 2, "operations": 2, "metrics": ["e1"]}"#,
        None,
    );
    let one_metric = one_metric.json()["id"].as_str().unwrap().to_owned();
    for (job, part, status, why) in [
        (&plain, "plots/nosuch.svg", 404, "no plot `nosuch.svg`"),
        (&plain, "plots/weibull.svg", 404, "no failure criteria"),
        (&plain, "plots/sensitivity.svg", 404, "no sensitivity"),
        (&plain, "plots/tail.svg", 404, "asks no rare event"),
        (
            &plain,
            "plots/bands.svg?metric=final_kappa",
            404,
            "no operation metric",
        ),
        (
            &plain,
            "plots/bands.svg?metric=kappa",
            409,
            "results exist once",
        ),
        (&failing, "plots/weibull.svg", 409, "results exist once"),
        (&one_metric, "plots/histograms.svg", 404, "`total_bounce_s`"),
        (
            &plain,
            "distributions/nosuch",
            404,
            "no metric `nosuch`; known",
        ),
        (
            &one_metric,
            "distributions/kappa",
            404,
            "not among its `metrics`",
        ),
        (&one_metric, "distributions/e1", 409, "results exist once"),
    ] {
        let reply = get(&server.url(&format!("/v1/jobs/{job}/{part}")), None);
        let problem = assert_problem(&reply, status);
        let detail = problem["detail"].as_str().unwrap();
        assert!(detail.contains(why), "{part}: {problem}");
    }
    // A job that ended without results says so, not that they come once it succeeds.
    let cancelled = post(&server.url(&format!("/v1/jobs/{plain}/cancel")), "", None);
    assert_eq!(cancelled.status, 200, "{}", cancelled.body);
    let reply = get(&server.url(&format!("/v1/jobs/{plain}/result")), None);
    let problem = assert_problem(&reply, 409);
    let detail = problem["detail"].as_str().unwrap();
    assert!(
        detail.contains("is cancelled: it ended without results"),
        "{problem}"
    );
}
