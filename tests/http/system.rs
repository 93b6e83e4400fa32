//! The OpenAPI document, docs, health and metrics, and API keys.

use crate::support::app::{Service, TestApp};
use crate::support::client::{agent, assert_problem, get, post, reply};
use crate::support::temp_db;
use serde_json::json;

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
