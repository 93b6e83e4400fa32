//! The `bouncewear` binary through its outside contract (CONTRACT.md "Build and binary", "Scenario").

#[path = "support/json_close.rs"]
mod json_close;

use serde_json::Value;
use std::io::Write;
use std::process::{Command, Output, Stdio};

const BIN: &str = env!("CARGO_BIN_EXE_bouncewear");

fn bouncewear(args: &[&str], stdin: &str) -> Output {
    let mut child = Command::new(BIN)
        .args(args)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("bouncewear runs");
    child
        .stdin
        .take()
        .unwrap()
        .write_all(stdin.as_bytes())
        .unwrap();
    child.wait_with_output().unwrap()
}

/// Runs a command that must fail with exit code 2 and one stderr line; returns that line.
fn rejected(args: &[&str], stdin: &str) -> String {
    let output = bouncewear(args, stdin);
    let stderr = String::from_utf8(output.stderr).unwrap();
    assert_eq!(output.status.code(), Some(2), "{args:?} {stdin}: {stderr}");
    assert!(output.stdout.is_empty());
    assert_eq!(stderr.trim_end().lines().count(), 1, "one line: {stderr}");
    stderr
}

#[test]
fn simulate_reproduces_every_validation_case_through_the_binary() {
    let text = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../tests/data/validation_cases.json"
    ))
    .unwrap();
    let cases: serde_json::Map<String, Value> = serde_json::from_str(&text).unwrap();
    for (name, case) in &cases {
        for fidelity in ["exact", "closed_form"] {
            let output = bouncewear(
                &["simulate", "--fidelity", fidelity, "-"],
                &case["scenario"].to_string(),
            );
            assert!(
                output.status.success(),
                "{name}: {}",
                String::from_utf8_lossy(&output.stderr)
            );
            let actual: Value = serde_json::from_slice(&output.stdout).unwrap();
            let differences = json_close::json_differences(&actual, &case[fidelity], 1e-12);
            assert!(
                differences.is_empty(),
                "{name} {fidelity}: {differences:#?}"
            );
        }
    }
}

#[test]
fn simulate_reads_a_file_and_defaults_to_exact() {
    let dir = std::env::temp_dir().join(format!("bouncewear-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("scenario.json");
    std::fs::write(&path, "{}").unwrap();
    let from_file = bouncewear(&["simulate", path.to_str().unwrap()], "");
    let from_stdin = bouncewear(&["simulate", "--fidelity", "exact"], "{}");
    assert!(from_file.status.success());
    assert_eq!(from_file.stdout, from_stdin.stdout);
    let output: Value = serde_json::from_slice(&from_file.stdout).unwrap();
    assert_eq!(output["bounce_count"], 7);
}

#[test]
fn simulate_rejects_a_rule_violation_naming_the_field() {
    let line = rejected(&["simulate"], r#"{"mechanism":{"static_force_n":-0.3}}"#);
    assert!(
        line.contains("/mechanism/static_force_n") && line.contains("non-negative"),
        "{line}"
    );
}

#[test]
fn simulate_rejects_malformed_json_wrong_types_and_unknown_fields() {
    for (input, expected) in [
        (r#"{"mechanism":{"static_force_n":0.3}"#, "malformed JSON"),
        ("", "malformed JSON"),
        (
            r#"{"mechanism":{"static_force_n":"0.3"}}"#,
            "/mechanism/static_force_n",
        ),
        (r#"{"losses":{"max_bounces":-1}}"#, "/losses/max_bounces"),
        (r#"{"material":{"radius":1}}"#, "/material/radius"),
        (r#"{"circuit":[48,15]}"#, "/circuit"),
        (
            r#"{"mechanism":{"static_force_n":0,"spring_stiffness_n_per_m":0}}"#,
            "/mechanism/static_force_n",
        ),
    ] {
        let line = rejected(&["simulate"], input);
        assert!(line.contains(expected), "{input}: {line}");
    }
}

#[test]
fn simulate_rejects_a_missing_file_and_an_unknown_fidelity() {
    let line = rejected(&["simulate", "/nonexistent/scenario.json"], "");
    assert!(line.contains("/nonexistent/scenario.json"), "{line}");
    let output = bouncewear(&["simulate", "--fidelity", "approximate"], "{}");
    assert_eq!(output.status.code(), Some(2));
}

#[test]
fn every_subcommand_has_help() {
    for args in [&["--help"][..], &["simulate", "--help"]] {
        let output = bouncewear(args, "");
        assert!(output.status.success(), "{args:?}");
        assert!(String::from_utf8(output.stdout).unwrap().contains("Usage"));
    }
}
