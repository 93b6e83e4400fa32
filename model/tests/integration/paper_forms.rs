//! The paper's closed forms (eq. 9, 10, 17, 19) and readings of e (eq. 14 through eq. 4, eq. 15)
//! against `tests/data/paper_forms.json`, computed at 50 digits by `tools/paper_forms_reference.py`
//! from docs/model.md alone, over the paper's Fig. 6/7 static-force sweep: to 1e-12 relative.

use bouncewear_model::paper_forms::{
    constant_restitution, e_from_bounce_times, e1_from_first_bounce, simplified_electrical,
};
use bouncewear_model::{Fidelity, Operation, Scenario};
use serde_json::Value;

fn cases() -> Vec<Value> {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../tests/data/paper_forms.json"
    );
    let text = std::fs::read_to_string(path).expect("paper forms reference");
    let data: Value = serde_json::from_str(&text).expect("JSON");
    data["cases"].as_array().expect("cases").clone()
}

fn close(name: &str, got: f64, want: &Value, failures: &mut Vec<String>) {
    let want = want
        .as_f64()
        .unwrap_or_else(|| panic!("{name}: no reference"));
    if (got - want).abs() > 1e-12 * want.abs() {
        failures.push(format!("{name}: {got} against {want}"));
    }
}

#[test]
fn every_form_and_reading_matches_the_50_digit_reference() {
    let cases = cases();
    assert_eq!(cases.len(), 10);
    let mut failures = Vec::new();
    for case in &cases {
        let scenario = Scenario::from_json(&case["scenario"].to_string()).expect("valid scenario");
        let label = case["scenario"].to_string();
        let op = Operation::nominal(&scenario, Fidelity::Exact);
        let e = case["constant_e"].as_f64().unwrap();
        let constant = constant_restitution(&op, e).expect("F_s > 0");
        close(
            &format!("{label} eq. 9"),
            constant.first_bounce_s,
            &case["eq9_first_bounce_s"],
            &mut failures,
        );
        close(
            &format!("{label} eq. 10"),
            constant.total_bounce_s,
            &case["eq10_total_bounce_s"],
            &mut failures,
        );
        match simplified_electrical(&op) {
            Some(simplified) => {
                close(
                    &format!("{label} eq. 17"),
                    simplified.first_bounce_s,
                    &case["eq17_first_bounce_s"],
                    &mut failures,
                );
                close(
                    &format!("{label} eq. 19"),
                    simplified.total_bounce_s,
                    &case["eq19_total_bounce_s"],
                    &mut failures,
                );
            }
            None => assert!(case.get("eq19_total_bounce_s").is_none(), "{label} arcs"),
        }
        let simulation = op.simulate();
        let bounces = &simulation.bounces;
        close(
            &format!("{label} eq. 14 through eq. 4"),
            e1_from_first_bounce(&op, simulation.outcome.first_bounce_s).unwrap(),
            &case["e1_eq14_from_exact_first_bounce"],
            &mut failures,
        );
        if bounces.len() >= 2 {
            close(
                &format!("{label} eq. 15"),
                e_from_bounce_times(bounces[0].duration_s, bounces[1].duration_s),
                &case["e2_eq15_from_exact_bounces"],
                &mut failures,
            );
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
