//! `POST /v1/simulate`: one operation, as the `simulate` command prints it.

use crate::support::app::{Service, TestApp};
use crate::support::client::post;
use crate::support::{bouncewear, temp_db};
use serde_json::Value;

#[test]
fn simulate_over_http_is_the_simulate_command() {
    let server = TestApp::start(&temp_db("simulate"), &[]);
    let scenario = r#"{"circuit": {"supply_voltage_v": 48, "current_a": 15}}"#;
    let simulated = post(
        &server.url("/v1/simulate?fidelity=closed_form"),
        scenario,
        None,
    );
    assert_eq!(simulated.status, 200);
    let output = bouncewear(&["simulate", "--fidelity", "closed_form"], scenario);
    let cli: Value = serde_json::from_slice(&output.stdout).unwrap();
    assert_eq!(simulated.json(), cli);
}
