//! Compares two JSON documents: same shape, same strings, booleans and integers, and floating-point
//! numbers equal to a relative tolerance (an exact zero must be matched exactly).

use serde_json::Value;

/// Every difference between `actual` and `expected`, each with the JSON pointer where it is.
pub fn json_differences(actual: &Value, expected: &Value, max_relative: f64) -> Vec<String> {
    let mut differences = Vec::new();
    compare(
        actual,
        expected,
        max_relative,
        String::new(),
        &mut differences,
    );
    differences
}

fn compare(actual: &Value, expected: &Value, max_relative: f64, at: String, out: &mut Vec<String>) {
    match (actual, expected) {
        (Value::Number(a), Value::Number(e)) if e.is_f64() || a.is_f64() => {
            let (a, e) = (
                a.as_f64().unwrap_or(f64::NAN),
                e.as_f64().unwrap_or(f64::NAN),
            );
            let close = a == e || (a - e).abs() <= max_relative * a.abs().max(e.abs());
            if !close {
                out.push(format!(
                    "{at}: {a:e} != {e:e} (relative {:e})",
                    (a - e).abs() / e.abs()
                ));
            }
        }
        (Value::Object(a), Value::Object(e)) => {
            for (key, expected_value) in e {
                match a.get(key) {
                    Some(actual_value) => compare(
                        actual_value,
                        expected_value,
                        max_relative,
                        format!("{at}/{key}"),
                        out,
                    ),
                    None => out.push(format!("{at}/{key}: missing")),
                }
            }
            for key in a.keys().filter(|key| !e.contains_key(*key)) {
                out.push(format!("{at}/{key}: unexpected"));
            }
        }
        (Value::Array(a), Value::Array(e)) if a.len() == e.len() => {
            for (i, (a, e)) in a.iter().zip(e).enumerate() {
                compare(a, e, max_relative, format!("{at}/{i}"), out);
            }
        }
        (a, e) if a == e => {}
        (a, e) => out.push(format!("{at}: {a} != {e}")),
    }
}
