//! Input that names its field: numbers beyond f64, members given twice and text over its length
//! limit are 422 with the JSON pointer at fault; a charset other than UTF-8 is 415.

use crate::support::app::{Service, TestApp};
use crate::support::client::{agent, assert_problem, post, reply};
use crate::support::temp_db;

/// The pointers of a 422 problem's `errors`.
fn rejected_pointers(server: &TestApp, path: &str, body: &str) -> Vec<String> {
    let problem = assert_problem(&post(&server.url(path), body, None), 422);
    problem["errors"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| e["pointer"].as_str().unwrap().to_owned())
        .collect()
}

const SCHEDULE: &str =
    r#"{"name": "nightly", "cron": "0 3 * * *", "template": {"devices": 2, "operations": 2}}"#;

#[test]
fn numbers_beyond_f64_name_their_pointer() {
    let server = TestApp::start(&temp_db("strict-range"), &[]);
    for (path, body, pointer) in [
        (
            "/v1/simulate",
            r#"{"circuit": {"current_a": 1e400}}"#,
            "/circuit/current_a",
        ),
        (
            "/v1/jobs",
            r#"{"scenario": {"mechanism": {"drop_height_m": -1e400}}}"#,
            "/scenario/mechanism/drop_height_m",
        ),
        (
            "/v1/jobs",
            r#"{"devices": 2, "operations": 2, "limits": {"e1": 1e999}}"#,
            "/limits/e1",
        ),
        ("/v1/jobs", r#"{"seed": 18446744073709551616}"#, "/seed"),
        ("/v1/jobs", r#"{"seed": -1}"#, "/seed"),
        (
            "/v1/simulate",
            r#"{"losses": {"max_bounces": 4294967296}}"#,
            "/losses/max_bounces",
        ),
    ] {
        assert_eq!(
            rejected_pointers(&server, path, body),
            [pointer],
            "{path} {body}"
        );
    }
}

/// A wrong type or an unknown member does not hide the other fields at fault: each is named, in a
/// job, a scenario and a schedule's template.
#[test]
fn every_field_at_fault_is_named_past_a_wrong_type() {
    let server = TestApp::start(&temp_db("strict-every"), &[]);
    let cases = [
        (
            "/v1/jobs",
            r#"{"devices": 0, "operations": 0, "foo": 1}"#,
            vec!["/foo", "/devices", "/operations"],
        ),
        (
            "/v1/simulate",
            r#"{"circuit": {"current_a": "15"}, "mechanism": {"static_force_n": -1}}"#,
            vec!["/circuit/current_a", "/mechanism/static_force_n"],
        ),
        (
            "/v1/schedules",
            r#"{"name": "n", "cron": "0 3 * * *", "enabled": "yes", "template": {"devices": 0}}"#,
            vec!["/enabled", "/template/devices"],
        ),
    ];
    for (path, body, pointers) in cases {
        assert_eq!(rejected_pointers(&server, path, body), pointers, "{body}");
    }
}

/// A name is text: serde's one-member object form of an enum's name (`{"exact": null}`) was
/// taken for the name, in a job, a scenario and a calibration, at every kind of name (a plain
/// name, a distribution's `kind` and a law's tag).
#[test]
fn a_name_written_as_an_object_is_named() {
    let server = TestApp::start(&temp_db("strict-names"), &[]);
    let cases = [
        (
            "/v1/jobs",
            r#"{"devices": 2, "operations": 2, "fidelity": {"exact": null}, "seed": "x"}"#,
            vec!["/seed", "/fidelity"],
        ),
        (
            "/v1/jobs",
            r#"{"devices": 2, "operations": 2, "sampler": {"lhs": {}},
                "scatter": [{"parameter": "kappa", "per": {"device": null},
                             "distribution": {"kind": {"fixed": null}, "value": 0.3}}]}"#,
            vec!["/sampler", "/scatter/0/distribution/kind", "/scatter/0/per"],
        ),
        (
            "/v1/simulate",
            r#"{"material": {"wear_law": {"law": {"constant": null}}}}"#,
            vec!["/material/wear_law/law"],
        ),
        // Read as the name, so a rule above it still stands (no parameter scattered).
        (
            "/v1/jobs",
            r#"{"devices": 20, "operations": 2, "sensitivity": {"method": {"sobol": null}}}"#,
            vec!["/sensitivity/method", "/sensitivity"],
        ),
    ];
    for (path, body, pointers) in cases {
        assert_eq!(rejected_pointers(&server, path, body), pointers, "{body}");
    }
    // The names themselves, as text, are taken.
    let taken = post(
        &server.url("/v1/jobs"),
        r#"{"devices": 2, "operations": 2, "fidelity": "exact", "sampler": "lhs"}"#,
        None,
    );
    assert_eq!(taken.status, 202, "{}", taken.body);
}

#[test]
fn a_member_given_twice_is_rejected_naming_it() {
    let server = TestApp::start(&temp_db("strict-duplicate"), &[]);
    assert_eq!(
        rejected_pointers(&server, "/v1/jobs", r#"{"devices": 2, "devices": 3}"#),
        ["/devices"]
    );
    assert_eq!(
        rejected_pointers(
            &server,
            "/v1/simulate",
            r#"{"circuit": {"current_a": 1, "supply_voltage_v": 2, "current_a": 1}}"#
        ),
        ["/circuit/current_a"]
    );
    let twice = SCHEDULE.replacen(r#""devices": 2"#, r#""devices": 2, "devices": 2"#, 1);
    assert_eq!(
        rejected_pointers(&server, "/v1/schedules", &twice),
        ["/template/devices"]
    );
}

#[test]
fn text_over_its_length_limit_is_rejected_naming_it() {
    let server = TestApp::start(&temp_db("strict-length"), &[]);
    let long = "x".repeat(201);
    let job = format!(r#"{{"devices": 2, "operations": 2, "name": "{long}"}}"#);
    assert_eq!(rejected_pointers(&server, "/v1/jobs", &job), ["/name"]);
    let schedule = SCHEDULE.replace("nightly", &long);
    assert_eq!(
        rejected_pointers(&server, "/v1/schedules", &schedule),
        ["/name"]
    );
    let metric = format!(r#"{{"devices": 2, "operations": 2, "metrics": ["{long}"]}}"#);
    assert_eq!(
        rejected_pointers(&server, "/v1/jobs", &metric),
        ["/metrics/0"]
    );
    let key = format!(r#"{{"devices": 2, "operations": 2, "limits": {{"{long}": 1}}}}"#);
    assert_eq!(
        rejected_pointers(&server, "/v1/jobs", &key),
        [format!("/limits/{long}")]
    );
    // The limit counts characters, not bytes: 200 two-byte characters fit.
    let wide = SCHEDULE.replace("nightly", &"é".repeat(200));
    assert_eq!(post(&server.url("/v1/schedules"), &wide, None).status, 201);
}

#[test]
fn a_charset_other_than_utf8_is_415_and_utf8_is_accepted() {
    let server = TestApp::start(&temp_db("strict-charset"), &[]);
    let send = |content_type: &str| {
        reply(
            agent()
                .post(&server.url("/v1/simulate"))
                .header("content-type", content_type)
                .send("{}"),
        )
    };
    for refused in [
        "application/json; charset=iso-8859-1",
        "application/json; charset=utf-16",
        "application/json;charset=\"latin1\"",
    ] {
        assert_problem(&send(refused), 415);
    }
    for accepted in [
        "application/json",
        "application/json; charset=utf-8",
        "application/json;charset=\"UTF-8\"",
    ] {
        assert_eq!(send(accepted).status, 200, "{accepted}");
    }
    // A byte-order mark before the JSON is no part of it (RFC 8259 8.1), as on the command line.
    let marked = reply(
        agent()
            .post(&server.url("/v1/simulate"))
            .header("content-type", "application/json")
            .send("\u{feff}{}"),
    );
    assert_eq!(marked.status, 200, "{}", marked.body);
}

#[test]
fn an_integral_number_fills_an_integer_field_as_json_schema_counts_it() {
    let server = TestApp::start(&temp_db("strict-integral"), &[]);
    let accepted = post(
        &server.url("/v1/jobs"),
        r#"{"devices": 2.0, "operations": 3e0, "seed": 7}"#,
        None,
    );
    assert_eq!(accepted.status, 202, "{}", accepted.body);
    assert_eq!(
        rejected_pointers(&server, "/v1/jobs", r#"{"devices": 2.5}"#),
        ["/devices"]
    );
}
