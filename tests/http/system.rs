//! The OpenAPI document, docs, health and metrics (every family described), and API keys.

use crate::support::app::{Service, TestApp};
use crate::support::client::{
    Reply, agent, assert_problem, assert_problem_saying, delete, get, post, reply,
};
use crate::support::temp_db;
use bouncewear_model::calibration::FITTED;
use bouncewear_model::montecarlo::distribution::POSITIVE_MEMBERS;
use bouncewear_model::scenario::{MAX_MAGNITUDE, MIN_MAGNITUDE, NUMBER_RULES, Rule};
use serde_json::json;
use std::collections::{BTreeMap, BTreeSet};
use std::io::{Read, Write};
use std::net::TcpStream;
use std::time::Duration;

#[test]
fn openapi_docs_health_and_metrics_are_served() {
    let server = TestApp::start(&temp_db("system"), &[]);
    let openapi = get(&server.url("/openapi.json"), None).json();
    assert_eq!(openapi["openapi"], "3.1.0");
    for path in [
        "/v1/jobs",
        "/v1/jobs/{id}",
        "/v1/jobs/{id}/result",
        "/v1/jobs/{id}/distributions/{metric}",
        "/v1/jobs/{id}/events",
        "/v1/events",
        "/v1/simulate",
        "/healthz",
        "/readyz",
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

/// A comma-separated query parameter takes at most `MAX_ITEMS` items, and its pattern in the
/// document says so: `b_lives` and `statistics` had no bound there, so a schema-valid request of
/// 25 items was refused.
#[test]
fn the_dashboards_files_are_revalidated_and_every_answer_forbids_framing() {
    let server = TestApp::start(&temp_db("pages"), &[]);
    for (path, kind) in [
        ("/", "text/html"),
        ("/jobs/anything", "text/html"),
        ("/dashboard/app.js", "application/javascript"),
        ("/dashboard/style.css", "text/css"),
    ] {
        let first = get(&server.url(path), None);
        assert!(
            first.content_type.starts_with(kind),
            "{path}: {}",
            first.content_type
        );
        assert_eq!(first.header("cache-control"), Some("no-cache"), "{path}");
        let tag = first.header("etag").expect("an ETag").to_owned();
        // A reload of the same build moves no body.
        let again = reply(
            agent()
                .get(&server.url(path))
                .header("if-none-match", &tag)
                .call(),
        );
        assert_eq!((again.status, again.body.as_str()), (304, ""), "{path}");
        let stale = reply(
            agent()
                .get(&server.url(path))
                .header("if-none-match", "W/\"0\"")
                .call(),
        );
        assert_eq!((stale.status, &stale.body), (200, &first.body), "{path}");
    }
    // Pages, the API and its errors alike (a page framed by another site, a "Run now" clicked).
    for path in ["/", "/v1/jobs", "/v1/jobs/nosuch", "/openapi.json"] {
        let answer = get(&server.url(path), None);
        assert_eq!(answer.header("x-frame-options"), Some("DENY"), "{path}");
        assert_eq!(
            answer.header("x-content-type-options"),
            Some("nosniff"),
            "{path}"
        );
        assert_eq!(
            answer.header("referrer-policy"),
            Some("no-referrer"),
            "{path}"
        );
        let policy = answer.header("content-security-policy").expect(path);
        for rule in [
            "default-src 'none'",
            "script-src 'self';",
            "frame-ancestors 'none'",
        ] {
            assert!(policy.contains(rule), "{path}: {policy}");
        }
    }
}

#[test]
fn a_browser_on_another_site_is_refused_before_any_handler_runs() {
    let server = TestApp::start(&temp_db("cross-site"), &[]);
    let address = server.base().trim_start_matches("http://").to_owned();
    // A GET of the jobs to `target` with a `Host` field for each of `hosts`.
    let raw_to = |target: &str, hosts: &[&str]| {
        let mut stream = TcpStream::connect(&address).unwrap();
        let fields: String = hosts.iter().map(|h| format!("host: {h}\r\n")).collect();
        let request = format!("GET {target} HTTP/1.1\r\n{fields}connection: close\r\n\r\n");
        stream.write_all(request.as_bytes()).unwrap();
        let mut answer = String::new();
        stream.read_to_string(&mut answer).unwrap();
        answer
    };
    let raw = |host: &str| raw_to("/v1/jobs", &[host]);
    // Without keys a server answers to loopback names only: another name pointing at 127.0.0.1
    // is how a web page would reach it (DNS rebinding).
    let port = address.rsplit_once(':').unwrap().1;
    for host in [
        format!("localhost:{port}"),
        address.clone(),
        format!("[::1]:{port}"),
        "a.localhost".into(),
        format!("LOCALHOST.:{port}"),
        // As `inet_aton` reads them, and a client may send them as typed.
        format!("127.1:{port}"),
        format!("2130706433:{port}"),
        format!("0x7f.0.0.1:{port}"),
    ] {
        assert!(raw(&host).starts_with("HTTP/1.1 200"), "{host}");
    }
    for host in [
        format!("attacker.example:{port}"),
        format!("localhost:{port}@attacker.example"),
        "[::1]attacker.example".into(),
        "localhost.attacker.example".into(),
        "128.0.0.1".into(),
    ] {
        let rebound = raw(&host);
        assert!(rebound.starts_with("HTTP/1.1 403"), "{host}: {rebound}");
        assert!(rebound.contains("loopback names only"), "{rebound}");
    }
    // Every name counts: a second `Host` field, and a target in absolute form (both were
    // answered as the first `Host` said, found from outside).
    let local = format!("localhost:{port}");
    for (target, hosts) in [
        ("/v1/jobs".to_owned(), vec![&local[..], "attacker.example"]),
        (
            "http://attacker.example/v1/jobs".to_owned(),
            vec![&local[..]],
        ),
    ] {
        let rebound = raw_to(&target, &hosts);
        assert!(
            rebound.starts_with("HTTP/1.1 403"),
            "{target} {hosts:?}: {rebound}"
        );
    }
    let absolute = format!("http://localhost:{port}/v1/jobs");
    assert!(raw_to(&absolute, &[&local]).starts_with("HTTP/1.1 200"));
    // A change sent by a page of another site (a form, a fetch without preflight) is refused; the
    // server's own pages, and clients that are no browser, send their own origin or none.
    let jobs = server.url("/v1/jobs");
    let job = json!({"devices": 2, "operations": 2}).to_string();
    let send = |origin: &str| {
        let request = agent()
            .post(&jobs)
            .header("content-type", "application/json");
        let request = if origin.is_empty() {
            request
        } else {
            request.header("origin", origin)
        };
        reply(request.send(job.as_str()))
    };
    let refused = send("https://evil.example");
    assert_problem_saying(&refused, 403, "another site");
    assert_eq!(send("null").status, 403);
    assert_eq!(send(server.base()).status, 202);
    assert_eq!(send(&format!("http://localhost:{port}")).status, 202);
    assert_eq!(send("").status, 202);
    // Reading is not changing: a GET with a foreign origin is answered (CORS keeps its body from
    // the page).
    let read = reply(
        agent()
            .get(&jobs)
            .header("origin", "https://evil.example")
            .call(),
    );
    assert_eq!(read.status, 200);

    // With keys neither rule applies: a key is no credential a browser attaches for another
    // site, and a proxy in front may name the server as it likes.
    let keyed = TestApp::start(&temp_db("cross-site-keys"), &["--api-key", "alpha"]);
    let keyed_post = |key: Option<&str>| {
        let request = agent()
            .post(&keyed.url("/v1/jobs"))
            .header("content-type", "application/json")
            .header("origin", "https://bouncewear.example");
        let request = match key {
            Some(key) => request.header("authorization", &format!("Bearer {key}")),
            None => request,
        };
        reply(request.send(job.as_str()))
    };
    assert_eq!(keyed_post(Some("alpha")).status, 202);
    assert_eq!(keyed_post(None).status, 401);
}

#[test]
fn every_list_parameters_pattern_bounds_its_items() {
    let server = TestApp::start(&temp_db("patterns"), &[]);
    let openapi = get(&server.url("/openapi.json"), None).json();
    let bound = format!("){{0,{}}}$", bouncewear::domain::query::MAX_ITEMS - 1);
    let mut lists = BTreeSet::new();
    for operation in openapi["paths"].as_object().unwrap().values() {
        for parameter in operation["get"]["parameters"]
            .as_array()
            .into_iter()
            .flatten()
        {
            let Some(pattern) = parameter["schema"]["pattern"].as_str() else {
                continue;
            };
            if pattern.contains('(') && pattern.contains(",") {
                let name = parameter["name"].as_str().unwrap();
                assert!(pattern.ends_with(&bound), "{name}: {pattern}");
                lists.insert(name.to_owned());
            }
        }
    }
    let expected = ["b_lives", "exceedance", "quantiles", "statistics"];
    assert_eq!(lists, BTreeSet::from(expected.map(String::from)));
}

/// The scenario's number rules have one home, `NUMBER_RULES` in the model: validation applies
/// them and the document states each as its field's range. A number of a scenario section with
/// no rule, or a rule whose field the document does not have, fails here.
#[test]
fn every_number_of_a_scenario_has_its_one_rule_in_the_document() {
    let server = TestApp::start(&temp_db("rules"), &[]);
    let openapi = get(&server.url("/openapi.json"), None).json();
    let schemas = &openapi["components"]["schemas"];
    for number in &NUMBER_RULES {
        let property = &schemas[number.schema]["properties"][number.field()];
        let bound = |key: &str| property[key].as_f64();
        let expected = match number.rule {
            Rule::Positive => (MIN_MAGNITUDE, MAX_MAGNITUDE),
            Rule::NonNegative => (0.0, MAX_MAGNITUDE),
            Rule::Finite => (-MAX_MAGNITUDE, MAX_MAGNITUDE),
        };
        assert_eq!(
            (bound("minimum"), bound("maximum")),
            (Some(expected.0), Some(expected.1)),
            "{}.{}: {property}",
            number.schema,
            number.field()
        );
    }
    // A calibration's measured quantities: a scenario's positive magnitudes, as `calibrate`
    // checks them (it refuses 1e-31 and 2e30), `e1` at most 1.
    for field in FITTED {
        let property = &schemas["Observation"]["properties"][field];
        let most = if field == "e1" { 1.0 } else { MAX_MAGNITUDE };
        assert_eq!(
            (property["minimum"].as_f64(), property["maximum"].as_f64()),
            (Some(MIN_MAGNITUDE), Some(most)),
            "Observation.{field}: {property}"
        );
    }
    let sections: BTreeSet<&str> = NUMBER_RULES.iter().map(|n| n.schema).collect();
    for section in sections {
        let properties = schemas[section]["properties"].as_object().unwrap();
        for (field, property) in properties {
            let types = &property["type"];
            let number = types == "number"
                || types
                    .as_array()
                    .is_some_and(|t| t.contains(&json!("number")));
            assert!(
                !number || property.get("minimum").is_some(),
                "{section}.{field} is a number with no rule: {property}"
            );
        }
    }
    // No whole number's range goes beyond the format it is said to have: a seed is any u64,
    // which `int64` would not hold.
    for (name, schema) in schemas.as_object().unwrap() {
        let properties = schema["properties"].as_object().into_iter().flatten();
        for (field, property) in properties {
            let beyond_int64 = property["maximum"].as_f64() > Some(i64::MAX as f64);
            assert!(
                !(beyond_int64 && property["format"] == "int64"),
                "{name}.{field}: {property}"
            );
        }
    }
    // A schedule's name is not only white space and holds no U+0000, in one pattern (its own
    // rule had taken the place of the one every text gets, and schemathesis sent a NUL).
    let name = schemas["ScheduleSpec"]["properties"]["name"]["pattern"]
        .as_str()
        .unwrap();
    assert_eq!(name, r"^[^\u0000]*[^\s\u0000][^\u0000]*$");
    // A seed is any u64 wherever it is told: in a job asked for and in the job's resource.
    for schema in ["JobSpec", "JobResource"] {
        let seed = &schemas[schema]["properties"]["seed"];
        assert_eq!(seed["maximum"].as_u64(), Some(u64::MAX), "{schema}: {seed}");
        assert!(seed["format"].is_null(), "{schema}: {seed}");
    }
}

/// What the document says a request may send and get matches what the server does: a
/// distribution's kind takes its own members only, those the model holds positive are so, a
/// truncation bound may be `null` (a client that writes absent members as `null` was refused),
/// every operation may get the keyless server's 403, and one that answers 304 reads
/// `If-None-Match` (a probe against the contract found each missing).
#[test]
fn the_document_declares_what_every_request_may_send_and_get() {
    let server = TestApp::start(&temp_db("declared"), &[]);
    let openapi = get(&server.url("/openapi.json"), None).json();
    let kinds = openapi["components"]["schemas"]["DistributionSpec"]["oneOf"]
        .as_array()
        .unwrap();
    let mut positive = BTreeSet::new();
    for kind in kinds {
        assert_eq!(kind["additionalProperties"], json!(false), "{kind}");
        for (member, rules) in kind["properties"].as_object().unwrap() {
            if rules["exclusiveMinimum"] == json!(0) {
                positive.insert(member.as_str());
            }
        }
    }
    assert_eq!(positive, BTreeSet::from(POSITIVE_MEMBERS));
    let (mut operations, mut conditional) = (0, 0);
    for (path, item) in openapi["paths"].as_object().unwrap() {
        for (method, operation) in item.as_object().unwrap() {
            let responses = &operation["responses"];
            assert!(responses.get("403").is_some(), "{method} {path}");
            let headers: Vec<&str> = operation["parameters"]
                .as_array()
                .into_iter()
                .flatten()
                .filter(|p| p["in"] == "header")
                .map(|p| p["name"].as_str().unwrap())
                .collect();
            let not_modified = responses.get("304").is_some();
            assert_eq!(
                not_modified,
                headers.contains(&"If-None-Match"),
                "{method} {path}"
            );
            operations += 1;
            conditional += usize::from(not_modified);
        }
    }
    assert!(
        operations > 20 && conditional >= 5,
        "{operations} {conditional}"
    );
    let quota = &openapi["paths"]["/v1/jobs"]["post"]["responses"]["403"]["description"];
    assert!(
        quota.as_str().unwrap().contains("quota") && quota.as_str().unwrap().contains("Origin"),
        "{quota}"
    );
    let job = r#"{"devices": 2, "operations": 2, "scatter": [{"parameter": "kappa",
        "per": "device", "distribution": {"kind": "normal", "mean": 0.3, "sd": 0.01,
        "min": 0.1, "max": null}}]}"#;
    let accepted = post(&server.url("/v1/jobs"), job, None);
    assert_eq!(accepted.status, 202, "{}", accepted.body);
    let unbounded = job.replace(r#""min": 0.1"#, r#""min": null"#);
    let refused = assert_problem(&post(&server.url("/v1/jobs"), &unbounded, None), 422);
    let errors = refused["errors"].as_array().unwrap();
    assert_eq!(errors.len(), 1, "{refused}");
    assert_eq!(
        errors[0]["pointer"], "/scatter/0/distribution/min",
        "{refused}"
    );
}

/// A client's `X-Request-Id` is echoed (and logged) when it is an id; one of 9,000 characters,
/// or with a space, is replaced by one of the server's (a UUID) rather than echoed whole.
#[test]
fn a_request_id_is_echoed_only_when_it_is_an_id() {
    let server = TestApp::start(&temp_db("request-id"), &[]);
    let echoed = |id: &str| {
        let asked = agent()
            .get(&server.url("/healthz"))
            .header("x-request-id", id);
        reply(asked.call())
            .header("x-request-id")
            .unwrap()
            .to_owned()
    };
    assert_eq!(echoed("build-42.step-7"), "build-42.step-7");
    for unusable in ["x".repeat(9000), "a b".to_owned(), "x".repeat(129)] {
        let ours = echoed(&unusable);
        assert!(ours.len() == 36 && ours.matches('-').count() == 4, "{ours}");
    }
}

#[test]
fn api_keys_are_required_and_isolate_jobs() {
    let server = TestApp::start(&temp_db("keys"), &["--api-key", "alpha,beta"]);
    let jobs = server.url("/v1/jobs");
    assert_problem(&get(&jobs, None), 401);
    assert_problem(&get(&jobs, Some("gamma")), 401);
    for scheme in ["bearer", "BEARER", "Bearer"] {
        let reply = reply(
            agent()
                .get(&jobs)
                .header("authorization", &format!("{scheme} alpha"))
                .call(),
        );
        assert_eq!(
            reply.status, 200,
            "the scheme `{scheme}` is case-insensitive"
        );
    }
    let basic = reply(
        agent()
            .get(&jobs)
            .header("authorization", "Basic alpha")
            .call(),
    );
    assert_problem(&basic, 401);
    // No route under /v1 is told apart without a key: an unknown path or method is 401 too, and
    // 404 or 405 with one.
    let nowhere = server.url("/v1/no-such-route");
    assert_problem(&get(&nowhere, None), 401);
    assert_problem(&get(&nowhere, Some("alpha")), 404);
    let put = |key: Option<&str>| {
        let request = agent().put(&jobs);
        let request = match key {
            Some(key) => request.header("authorization", &format!("Bearer {key}")),
            None => request,
        };
        reply(request.send_empty())
    };
    assert_problem(&put(None), 401);
    assert_problem(&put(Some("alpha")), 405);
    assert_problem(&get(&server.url("/no-such-page"), None), 404);
    // Nor by the query parameters a route takes: 400 for an unknown one only with a key.
    for listing in [jobs.clone(), server.url("/v1/schedules")] {
        let asked = format!("{listing}?bogus=1");
        assert_problem(&get(&asked, None), 401);
        let problem = assert_problem(&get(&asked, Some("alpha")), 400);
        assert!(
            problem["detail"].as_str().unwrap().contains("`bogus`"),
            "{problem}"
        );
    }
    // Authorization twice is refused, whichever key comes first: taking the first let a
    // client's header win over one a proxy added after it.
    for (first, second) in [("alpha", "beta"), ("beta", "alpha"), ("alpha", "alpha")] {
        let twice = reply(
            agent()
                .get(&jobs)
                .header("authorization", &format!("Bearer {first}"))
                .header("authorization", &format!("Bearer {second}"))
                .call(),
        );
        assert_problem_saying(&twice, 400, "more than once");
    }
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

/// One `/metrics` scrape: the type and help of each family, and each sample's name and labels.
struct Scrape {
    types: BTreeMap<String, String>,
    helps: BTreeSet<String>,
    samples: Vec<(String, String)>,
}

impl Scrape {
    fn of(text: &str) -> Self {
        let mut scrape = Scrape {
            types: BTreeMap::new(),
            helps: BTreeSet::new(),
            samples: Vec::new(),
        };
        for line in text.lines().filter(|l| !l.is_empty()) {
            if let Some(rest) = line.strip_prefix("# TYPE ") {
                let (name, kind) = rest.split_once(' ').unwrap();
                scrape.types.insert(name.to_owned(), kind.to_owned());
            } else if let Some(rest) = line.strip_prefix("# HELP ") {
                scrape
                    .helps
                    .insert(rest.split_once(' ').unwrap().0.to_owned());
            } else {
                let end = line.find(['{', ' ']).unwrap();
                let labels = line[end..].rsplit_once(' ').unwrap().0.to_owned();
                scrape.samples.push((line[..end].to_owned(), labels));
            }
        }
        scrape
    }

    /// The family a sample belongs to: its own name, or a histogram's or summary's.
    fn family(&self, sample: &str) -> String {
        ["_bucket", "_sum", "_count"]
            .into_iter()
            .filter_map(|suffix| sample.strip_suffix(suffix))
            .find(|base| {
                matches!(
                    self.types.get(*base).map(String::as_str),
                    Some("histogram" | "summary")
                )
            })
            .unwrap_or(sample)
            .to_owned()
    }

    fn labels_of(&self, name: &str) -> Vec<&str> {
        self.samples
            .iter()
            .filter(|(sample, _)| sample == name)
            .map(|(_, labels)| labels.as_str())
            .collect()
    }
}

#[test]
fn every_metric_family_has_help_and_type_and_latency_is_a_histogram() {
    let server = TestApp::start(&temp_db("metrics"), &[]);
    let done = server.submit(&json!({"devices": 2, "operations": 50, "seed": 1}));
    server.wait_for(&done, "succeeded", Duration::from_secs(60));
    let long = server.submit(&json!({"devices": 1000, "operations": 1_000_000, "seed": 2}));
    assert_eq!(delete(&server.url(&format!("/v1/jobs/{long}"))).status, 200);
    get(&server.url("/healthz"), None);
    get(&server.url("/no/such/page/12345"), None);
    // A method no client library sends, so written by hand.
    let mut raw = TcpStream::connect(server.base().trim_start_matches("http://")).unwrap();
    raw.write_all(b"BREW /healthz HTTP/1.1\r\nhost: localhost\r\nconnection: close\r\n\r\n")
        .unwrap();
    let mut answer = String::new();
    raw.read_to_string(&mut answer).unwrap();
    assert!(answer.starts_with("HTTP/1.1 405"), "{answer}");
    // The queue gauges are reported once a second.
    std::thread::sleep(Duration::from_millis(1100));

    let text = get(&server.url("/metrics"), None).body;
    let scrape = Scrape::of(&text);
    for (sample, _) in &scrape.samples {
        let family = scrape.family(sample);
        assert!(
            scrape.types.contains_key(&family),
            "TYPE of {family}:\n{text}"
        );
        assert!(scrape.helps.contains(&family), "HELP of {family}:\n{text}");
    }
    for family in [
        "bouncewear_http_requests_total",
        "bouncewear_jobs_submitted_total",
        "bouncewear_jobs_finished_total",
        "bouncewear_operations_simulated_total",
        // Counters of what has not happened here, there from the start at 0.
        "bouncewear_store_retries_total",
        "bouncewear_connections_shed_total",
        "bouncewear_connections_stalled_total",
        "bouncewear_event_watch_looks_total",
        "bouncewear_fits_stopped_total",
        "bouncewear_responses_refused_total",
        "bouncewear_scheduled_runs_skipped_total",
        "bouncewear_responses_waiting",
        "bouncewear_response_bytes_held",
        "bouncewear_jobs_queued",
        "bouncewear_jobs_running",
        "bouncewear_build_info",
        "process_resident_memory_bytes",
        "process_cpu_seconds_total",
        "process_open_fds",
        "process_start_time_seconds",
    ] {
        assert!(
            scrape.types.contains_key(family),
            "{family} is exported:\n{text}"
        );
    }
    let latency = "bouncewear_http_request_duration_seconds";
    assert_eq!(scrape.types[latency], "histogram");
    let buckets = scrape.labels_of(&format!("{latency}_bucket"));
    assert!(
        buckets
            .iter()
            .any(|l| l.contains(r#"route="/healthz""#) && l.contains(r#"le="+Inf""#))
    );
    // The small job ran whole, as its batch's merge step: claimed, its (no) groups read, run,
    // summarised and encoded, then written; each part on the workers' own clock.
    let steps = scrape.labels_of("bouncewear_shard_step_seconds_count");
    for step in [
        "claim",
        "merge",
        "merge_read",
        "merge_compute",
        "merge_write",
    ] {
        let label = format!(r#"step="{step}""#);
        assert!(
            steps.iter().any(|l| l.contains(&label)),
            "{step}: {steps:?}"
        );
    }
    let version = format!(r#"version="{}""#, env!("CARGO_PKG_VERSION"));
    assert!(
        scrape
            .labels_of("bouncewear_build_info")
            .iter()
            .any(|l| l.contains(&version))
    );

    // Label values come from the router's table and the standard methods, never from the client.
    let requests = scrape.labels_of("bouncewear_http_requests_total");
    assert!(
        requests.iter().all(|l| !l.contains("no/such")),
        "{requests:?}"
    );
    assert!(
        requests.iter().any(|l| l.contains(r#"route="other""#)),
        "{requests:?}"
    );
    assert!(
        requests.iter().any(|l| l.contains(r#"method="other""#)),
        "{requests:?}"
    );
    assert!(requests.iter().all(|l| !l.contains("BREW")), "{requests:?}");
}

#[test]
fn readiness_turns_503_when_the_database_file_is_replaced_or_deleted() {
    let database = temp_db("ready-file");
    let server = TestApp::start(&database, &[]);
    let ready = get(&server.url("/readyz"), None);
    assert_eq!(
        (ready.status, ready.json()["status"].clone()),
        (200, json!("ready"))
    );
    // Another file moved over it: the server would go on writing into the one it opened.
    let copy = database.with_extension("copy");
    std::fs::copy(&database, &copy).unwrap();
    std::fs::rename(&copy, &database).unwrap();
    let replaced = get(&server.url("/readyz"), None);
    let problem = assert_problem(&replaced, 503);
    assert!(replaced.header("retry-after").is_some());
    assert!(
        problem["detail"].as_str().unwrap().contains("replaced"),
        "{problem}"
    );
    std::fs::remove_file(&database).unwrap();
    let problem = assert_problem(&get(&server.url("/readyz"), None), 503);
    assert!(
        problem["detail"].as_str().unwrap().contains("gone"),
        "{problem}"
    );
}

/// A database that takes no writes (here SQLite's `?mode=ro`, as a file without write permission
/// or a read-only mount would be, or a PostgreSQL standby) is said to be read-only by `/readyz`
/// and by a submission's 503: both said "the database is unavailable", naming no cause (a probe).
/// Reads go on.
#[test]
fn a_read_only_database_is_said_to_be_read_only() {
    let database = temp_db("read-only");
    let id = TestApp::ran(
        &database,
        &json!({"devices": 2, "operations": 3, "seed": 1}),
    );
    let server = TestApp::on(&format!("sqlite://{}?mode=ro", database.display()), &[]);
    let ready = get(&server.url("/readyz"), None);
    let problem = assert_problem(&ready, 503);
    assert!(ready.header("retry-after").is_some());
    assert!(
        problem["detail"].as_str().unwrap().contains("read-only"),
        "{problem}"
    );
    let submitted = post(
        &server.url("/v1/jobs"),
        r#"{"devices": 2, "operations": 3, "seed": 2}"#,
        None,
    );
    let problem = assert_problem(&submitted, 503);
    assert!(
        problem["detail"].as_str().unwrap().contains("read-only"),
        "{problem}"
    );
    let job = get(&server.url(&format!("/v1/jobs/{id}")), None);
    assert_eq!(job.json()["status"], json!("succeeded"));
}

/// A lock another process holds on the SQLite file (a backup, a tool) makes a submission answer
/// 503 with Retry-After within the database's wait, not wait for the lock (it waited 49 s for a
/// lock held 50 s, found from outside); reads go on, and once the lock is gone the submission is
/// taken.
#[test]
fn a_submission_behind_another_processs_lock_answers_503_at_once() {
    use sqlx::Connection;
    let database = temp_db("locked");
    let server = TestApp::start(&database, &[]);
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    let url = format!("sqlite://{}", database.display());
    let mut lock = runtime.block_on(async {
        let mut connection = sqlx::SqliteConnection::connect(&url).await.unwrap();
        let exclusive = sqlx::query("BEGIN EXCLUSIVE").execute(&mut connection);
        exclusive.await.unwrap();
        connection
    });
    let job = r#"{"devices": 2, "operations": 3, "seed": 1}"#;
    let started = std::time::Instant::now();
    let refused = post(&server.url("/v1/jobs"), job, None);
    let waited = started.elapsed();
    assert_problem(&refused, 503);
    assert!(refused.header("retry-after").is_some());
    // The lock is never let go meanwhile: before, the wait was SQLite's 30 s busy timeout.
    assert!(waited < Duration::from_secs(10), "{waited:?}");
    assert_eq!(get(&server.url("/v1/jobs"), None).status, 200);
    runtime
        .block_on(sqlx::query("ROLLBACK").execute(&mut lock))
        .unwrap();
    assert_eq!(post(&server.url("/v1/jobs"), job, None).status, 202);
}

/// A stopped server's database file holds every write it acknowledged without its log beside
/// it: the write-ahead log is checkpointed into the file as the server stops (a copy of the
/// file alone, a stopped server's backup, lacked the last jobs, found from outside).
#[test]
fn a_stopped_servers_file_holds_every_write_without_its_log() {
    let database = temp_db("stopped");
    let id = TestApp::ran(
        &database,
        &json!({"devices": 2, "operations": 3, "seed": 1}),
    );
    let copy = temp_db("stopped-copy");
    std::fs::copy(&database, &copy).unwrap();
    let server = TestApp::start(&copy, &[]);
    let job = get(&server.url(&format!("/v1/jobs/{id}")), None);
    assert_eq!(job.json()["status"], "succeeded", "{}", job.body);
}

#[test]
fn readiness_turns_503_below_the_free_disk_threshold() {
    let server = TestApp::start(
        &temp_db("ready-disk"),
        &["--min-free-disk-mb", "1000000000000"],
    );
    let says_why = |reply: &Reply| {
        let problem = assert_problem(reply, 503);
        let detail = problem["detail"].as_str().unwrap();
        assert!(detail.contains("--min-free-disk-mb"), "{problem}");
    };
    says_why(&get(&server.url("/readyz"), None));
    assert_eq!(
        get(&server.url("/healthz"), None).status,
        200,
        "alive all the same"
    );
    // Nor does it take a job (tiny legal jobs of large Results once filled the disk from a
    // single client); what it holds still reads.
    let refused = post(
        &server.url("/v1/jobs"),
        r#"{"devices": 2, "operations": 2}"#,
        None,
    );
    says_why(&refused);
    assert_eq!(refused.headers["retry-after"], "5");
    // Nor a schedule (one was written whatever the free disk).
    let schedule = r#"{"name": "n", "cron": "0 3 * * *", "template": {"devices": 2}}"#;
    says_why(&post(&server.url("/v1/schedules"), schedule, None));
    assert_eq!(get(&server.url("/v1/jobs"), None).status, 200);
}

#[test]
fn a_deleted_database_file_refuses_writes_and_acknowledges_nothing() {
    let database = temp_db("deleted-writes");
    let server = TestApp::start(&database, &[]);
    let job = json!({"devices": 2, "operations": 2, "seed": 1}).to_string();
    assert_eq!(post(&server.url("/v1/jobs"), &job, None).status, 202);
    std::fs::remove_file(&database).unwrap();
    for _ in 0..5 {
        let refused = post(&server.url("/v1/jobs"), &job, None);
        let problem = assert_problem(&refused, 503);
        assert!(refused.header("retry-after").is_some());
        assert!(
            problem["detail"].as_str().unwrap().contains("gone"),
            "{problem}"
        );
    }
    assert_problem(&get(&server.url("/readyz"), None), 503);
    assert_eq!(get(&server.url("/healthz"), None).status, 200);
}

/// A tmpfs of `size` mounted at a fresh directory for one test, unmounted when dropped; `None`
/// (after a loud notice) where this process may not mount one (not root, or no `mount`).
struct SmallDisk(std::path::PathBuf);

impl SmallDisk {
    fn mount(name: &str, size: &str) -> Option<Self> {
        let dir = crate::support::temp_dir(name);
        let mounted = std::process::Command::new("mount")
            .args(["-t", "tmpfs", "-o", &format!("size={size}"), "tmpfs"])
            .arg(&dir)
            .status()
            .is_ok_and(|status| status.success());
        if !mounted {
            eprintln!("SKIPPED: {name} needs to mount a tmpfs (root and `mount`)");
            return None;
        }
        Some(Self(dir))
    }

    /// Writes a file until the disk is full, then gives back `room` bytes.
    fn fill(&self, room: u64) -> std::path::PathBuf {
        let path = self.0.join("filler");
        let mut file = std::fs::File::create(&path).unwrap();
        let chunk = vec![0_u8; 64 * 1024];
        while file.write_all(&chunk).is_ok() {}
        let _ = file.sync_all();
        let written = std::fs::metadata(&path).unwrap().len();
        file.set_len(written.saturating_sub(room)).unwrap();
        path
    }
}

impl Drop for SmallDisk {
    /// Unmounted, trying again while something still holds it busy, then detached lazily (it goes
    /// once its last file closes): a single try left 128 MB tmpfs mounts behind after runs of the
    /// suite on this VM.
    fn drop(&mut self) {
        let umount = |lazy: bool| {
            let mut command = std::process::Command::new("umount");
            if lazy {
                command.arg("-l");
            }
            command.arg(&self.0).status().is_ok_and(|s| s.success())
        };
        for _ in 0..20 {
            if umount(false) {
                return;
            }
            std::thread::sleep(Duration::from_millis(100));
        }
        umount(true);
    }
}

/// Issue 30's fault: submissions while the database's disk is full. Some are refused (503), and
/// every one acknowledged (202) is there, runs to the end once room is made, and is still there
/// after a restart; the queue recovers without one.
#[test]
fn a_full_disk_loses_no_acknowledged_job_and_the_queue_recovers_by_itself() {
    let Some(disk) = SmallDisk::mount("full-disk", "20m") else {
        return;
    };
    let database = disk.0.join("bouncewear.db");
    // No free-space threshold: the writes themselves meet the full disk.
    let args = [
        "--min-free-disk-mb",
        "0",
        "--max-retries",
        "1000",
        "--max-lost-leases",
        "1000",
    ];
    let mut acknowledged = Vec::new();
    {
        let server = TestApp::start(&database, &args);
        let filler = disk.fill(64 * 1024);
        let mut refused = 0;
        for seed in 0..60 {
            let job = json!({"devices": 2, "operations": 20, "seed": seed}).to_string();
            let reply = post(&server.url("/v1/jobs"), &job, None);
            match reply.status {
                202 => acknowledged.push(reply.json()["id"].as_str().unwrap().to_owned()),
                503 => refused += 1,
                status => panic!("{status}: {}", reply.body),
            }
        }
        eprintln!(
            "disk full: {} acknowledged, {refused} refused",
            acknowledged.len()
        );
        std::fs::remove_file(filler).unwrap();
        // Room again: the queue goes on by itself, and new work is taken.
        let after = server.submit(&json!({"devices": 2, "operations": 20, "seed": 99}));
        acknowledged.push(after);
        for id in &acknowledged {
            server.wait_for(id, "succeeded", Duration::from_secs(60));
        }
        assert_eq!(get(&server.url("/readyz"), None).status, 200);
    }
    let server = TestApp::start(&database, &args);
    for id in &acknowledged {
        let job = get(&server.url(&format!("/v1/jobs/{id}")), None);
        assert_eq!(job.json()["status"], "succeeded", "{id}: {}", job.body);
    }
}

/// One accepted job whose Result the disk cannot hold (16 MB on a disk with about 12 MB free): it
/// filled the disk half-way, and then no claim, heartbeat or end could be written, nor the job
/// failed or cancelled, until an operator made room (a probe). Its write is now refused before it
/// starts, and the job waits for room, saying why, without counting a failure (it had failed for
/// good after its retries, and stayed failed once the disk grew: a later probe); the queue goes
/// on, and once the disk has room the job succeeds.
#[test]
fn a_result_the_disk_cannot_hold_waits_for_room_and_the_queue_goes_on() {
    let Some(disk) = SmallDisk::mount("result-too-large", "16m") else {
        return;
    };
    let database = disk.0.join("bouncewear.db");
    let args = [
        "--min-free-disk-mb",
        "1",
        "--max-retries",
        "0",
        "--max-lost-leases",
        "0",
    ];
    let server = TestApp::start(&database, &args);
    let large = json!({"devices": 64, "operations": 1000, "bin_operations": 1, "seed": 1,
                       "scenario": {"circuit": {"supply_voltage_v": 48, "current_a": 15}}});
    let id = server.submit(&large);
    let shards = server.url(&format!("/v1/jobs/{id}/shards"));
    let started = std::time::Instant::now();
    let waiting = loop {
        let listed = get(&shards, None).json();
        let waiting = listed["shards"].as_array().unwrap().iter().find(|shard| {
            shard["error"]
                .as_str()
                .is_some_and(|error| error.starts_with("waiting for room: storing"))
        });
        if let Some(shard) = waiting {
            break shard.clone();
        }
        assert!(started.elapsed() < Duration::from_secs(120), "{listed}");
        std::thread::sleep(Duration::from_millis(200));
    };
    let error = waiting["error"].as_str().unwrap();
    assert!(
        error.contains("needs") && error.contains("free beside the database"),
        "{error}"
    );
    assert_eq!(waiting["failures"], 0, "{waiting}");
    let small = server.submit(&json!({"devices": 2, "operations": 20, "seed": 2}));
    server.wait_for(&small, "succeeded", Duration::from_secs(60));
    let job = get(&server.url(&format!("/v1/jobs/{id}")), None).json();
    assert!(
        job["status"] == "running" || job["status"] == "queued",
        "{job}"
    );
    // Room: the job goes on by itself.
    let grown = std::process::Command::new("mount")
        .args(["-o", "remount,size=128m"])
        .arg(&disk.0)
        .status()
        .unwrap();
    assert!(grown.success());
    server.wait_for(&id, "succeeded", Duration::from_secs(120));
    assert_eq!(get(&server.url("/readyz"), None).status, 200);
}
