//! Rare events over HTTP: the estimate in the Result and on its own, the tail as CSV and SVG, and
//! the refusals that name their field.

use crate::support::app::{Service, TestApp};
use crate::support::client::{assert_problem, get, post};
use crate::support::temp_db;
use serde_json::{Value, json};
use std::time::Duration;

/// P(total bounce time of the first operation above 14 ms), the velocity per operation.
fn rare_job(above: f64) -> Value {
    json!({
        "devices": 20, "operations": 5, "seed": 3,
        "scenario": {"circuit": {"supply_voltage_v": 48, "current_a": 15}},
        "scatter": [{"parameter": "impact_velocity_m_s", "per": "operation",
                     "distribution": {"kind": "normal", "mean": 0.224, "sd": 0.02, "min": 0.01}}],
        "rare_event": {"metric": "total_bounce_s", "above": above, "method": "subset",
                       "target_cov": 0.5}
    })
}

#[test]
fn a_rare_event_is_estimated_served_as_json_csv_and_a_plot() {
    let server = TestApp::start(&temp_db("rare"), &[]);
    let id = server.submit(&rare_job(0.014));
    server.wait_for(&id, "succeeded", Duration::from_secs(120));
    let rare = get(&server.url(&format!("/v1/jobs/{id}/rare_event")), None);
    assert_eq!(rare.status, 200, "{}", rare.body);
    let rare = rare.json();
    let p = rare["probability"].as_f64().unwrap();
    assert!(p > 1e-8 && p < 1e-3, "{rare}");
    let [lo, hi] = [
        rare["ci95"][0].as_f64().unwrap(),
        rare["ci95"][1].as_f64().unwrap(),
    ];
    assert!(lo < p && p < hi, "{rare}");
    assert_eq!(rare["method"], "subset");
    assert!(
        rare["design_point"]["impact_velocity_m_s@1"]
            .as_f64()
            .unwrap()
            > 0.224
    );
    let result = get(&server.url(&format!("/v1/jobs/{id}/result")), None).json();
    assert_eq!(
        result["rare_event"], rare,
        "the Result carries the same estimate"
    );
    assert_eq!(result["job"]["rare_event"]["metric"], "total_bounce_s");

    let csv = get(
        &server.url(&format!("/v1/jobs/{id}/rare_event?format=csv")),
        None,
    );
    let rows: Vec<&str> = csv.body.lines().collect();
    assert_eq!(rows[0], "threshold,probability");
    assert_eq!(rows.len(), 1 + rare["tail"].as_array().unwrap().len());
    assert!(rows.last().unwrap().starts_with("0.014,"));

    let svg = get(&server.url(&format!("/v1/jobs/{id}/plots/tail.svg")), None);
    assert_eq!(svg.status, 200, "{}", svg.body);
    assert!(svg.body.starts_with("<svg") && svg.body.contains("P(total_bounce_s above t)"));

    let plain = server.submit(&json!({"devices": 1, "operations": 1, "seed": 1}));
    server.wait_for(&plain, "succeeded", Duration::from_secs(20));
    assert_problem(
        &get(&server.url(&format!("/v1/jobs/{plain}/rare_event")), None),
        404,
    );
    assert_problem(
        &get(
            &server.url(&format!("/v1/jobs/{plain}/plots/tail.svg")),
            None,
        ),
        404,
    );
}

#[test]
fn a_rare_event_that_is_not_rare_or_ill_posed_is_refused_naming_its_field() {
    let server = TestApp::start(&temp_db("rare-refused"), &[]);
    let url = server.url("/v1/jobs");
    // The median device already bounces longer than 1 ms.
    let refused = post(&url, &rare_job(0.001).to_string(), None);
    let problem = assert_problem(&refused, 422);
    assert_eq!(
        problem["errors"][0]["pointer"], "/rare_event/above",
        "{problem}"
    );
    // No velocity within 11.5 standard deviations of the median bounces for a second: never.
    let never = post(&url, &rare_job(1.0).to_string(), None);
    let problem = assert_problem(&never, 422);
    assert_eq!(
        problem["errors"][0]["pointer"], "/rare_event/above",
        "{problem}"
    );
    let detail = problem["errors"][0]["detail"].as_str().unwrap();
    assert!(detail.contains("never reaches above 1"), "{detail}");
    let mut no_scatter = rare_job(0.014);
    no_scatter["scatter"] = json!([]);
    let problem = assert_problem(&post(&url, &no_scatter.to_string(), None), 422);
    assert_eq!(problem["errors"][0]["pointer"], "/rare_event", "{problem}");
}
