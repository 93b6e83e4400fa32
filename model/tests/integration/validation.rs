//! The worked validation cases in `tests/data/validation_cases.json`, computed independently at 50
//! digits (see `tests/data/README.md`): every field of every case at both fidelities, to 1e-12
//! relative.

#[path = "../../../tests/support/json_close.rs"]
mod json_close;

use bouncewear_model::{Fidelity, Scenario, simulate};
use serde_json::Value;

fn cases() -> serde_json::Map<String, Value> {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../tests/data/validation_cases.json"
    );
    let text = std::fs::read_to_string(path).expect("validation cases");
    serde_json::from_str(&text).expect("validation cases are JSON")
}

#[test]
fn every_validation_case_matches_to_1e_12_at_both_fidelities() {
    let cases = cases();
    assert_eq!(cases.len(), 6);
    let mut failures = Vec::new();
    for (name, case) in &cases {
        let scenario = Scenario::from_json(&case["scenario"].to_string()).expect("valid scenario");
        for fidelity in Fidelity::ALL {
            let actual = serde_json::to_value(simulate(&scenario, fidelity)).unwrap();
            for difference in json_close::json_differences(&actual, &case[fidelity.as_str()], 1e-12)
            {
                failures.push(format!("{name} {}: {difference}", fidelity.as_str()));
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// 80 scenarios spread over the rig's range (mechanical and arcing, with and without spring, kappa
/// overrides), evaluated at 50 digits by `tools/reference.py`, an independent implementation.
/// Tolerance 1e-11: four cases run to the 64-bounce cap near the elastic limit, where each bounce
/// carries the last one's rounding forward (1.6e-12 on the 50th bounce of case 78); every other
/// number agrees to a few ulps.
#[test]
fn a_spread_of_80_scenarios_matches_the_50_digit_reference_to_1e_11() {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../tests/data/reference_spread.json"
    );
    let cases: Vec<Value> = serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    assert_eq!(cases.len(), 80);
    let mut failures = Vec::new();
    for (i, case) in cases.iter().enumerate() {
        let scenario = Scenario::from_json(&case["scenario"].to_string()).expect("valid scenario");
        for fidelity in Fidelity::ALL {
            let actual = serde_json::to_value(simulate(&scenario, fidelity)).unwrap();
            for difference in json_close::json_differences(&actual, &case[fidelity.as_str()], 1e-11)
            {
                failures.push(format!("case {i} {}: {difference}", fidelity.as_str()));
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
