//! The `bouncewear` binary through its outside contract (docs/contract.md "Build and binary",
//! "Scenario").

use crate::support::{bouncewear, run_job, temp_dir, without_timing};
use bouncewear_model::{Fidelity, Scenario, simulate};
use serde_json::Value;
use std::path::Path;

/// Runs the binary with `args`, its standard output a disk that is always full.
fn to_dev_full(args: &[&str]) -> std::process::Output {
    let full = std::fs::OpenOptions::new().write(true).open("/dev/full");
    std::process::Command::new(crate::support::BIN)
        .args(args)
        .stdout(full.unwrap())
        .output()
        .unwrap()
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
            let differences =
                crate::support::json_close::json_differences(&actual, &case[fidelity], 1e-12);
            assert!(
                differences.is_empty(),
                "{name} {fidelity}: {differences:#?}"
            );
        }
    }
}

#[test]
fn simulate_reads_a_file_and_defaults_to_exact() {
    let dir = temp_dir("simulate-file");
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
    // A bad command line is bad input too: one line, exit 2 (clap's own message spans five).
    let line = rejected(&["simulate", "--fidelity", "approximate"], "{}");
    assert!(
        line.contains("'approximate'") && line.contains("--fidelity"),
        "{line}"
    );
    let line = rejected(&["run", "--bogus", "job.json"], "");
    assert!(
        line.starts_with("bouncewear: unexpected argument '--bogus' found; ")
            && line.contains("Usage: bouncewear run"),
        "{line}"
    );
    let line = rejected(&["run"], "");
    assert!(line.contains("not provided: <FILE>; "), "{line}");
    let line = rejected(&[], "");
    assert!(line.contains("no command given"), "{line}");
}

#[test]
fn every_subcommand_has_help_and_a_version() {
    for args in [
        &["--help"][..],
        &["simulate", "--help"],
        &["run", "--help"],
        &["bench", "--help"],
        &["serve", "--help"],
        &["worker", "--help"],
        &["health", "--help"],
        &["calibrate", "--help"],
        &["submit", "--help"],
        &["status", "--help"],
        &["wait", "--help"],
        &["fetch", "--help"],
        &["cancel", "--help"],
    ] {
        let output = bouncewear(args, "");
        assert!(output.status.success(), "{args:?}");
        assert!(String::from_utf8(output.stdout).unwrap().contains("Usage"));
        // And its version: `bouncewear 0.1.0`, `bouncewear-run 0.1.0`, ...
        let version = [&args[..args.len() - 1], &["--version"]].concat();
        let output = bouncewear(&version, "");
        assert!(output.status.success(), "{version:?}");
        let expected = match &version[..] {
            [_] => "bouncewear".to_owned(),
            [command, _] => format!("bouncewear-{command}"),
            _ => unreachable!(),
        };
        assert_eq!(
            String::from_utf8(output.stdout).unwrap(),
            format!("{expected} {}\n", env!("CARGO_PKG_VERSION")),
        );
    }
    // Help never shows a secret the environment holds (it showed the database's password and
    // every API key of the server, found from outside).
    for command in ["serve", "worker", "status", "health"] {
        let output = std::process::Command::new(crate::support::BIN)
            .args([command, "--help"])
            .env("BOUNCEWEAR_DATABASE", "postgres://u:s3cret-db@h/x")
            .env("BOUNCEWEAR_API_KEYS", "s3cret-key1,s3cret-key2")
            .env("BOUNCEWEAR_API_KEY", "s3cret-key1")
            .env("BOUNCEWEAR_URL", "http://u:s3cret-url@h:1")
            .env("BOUNCEWEAR_HEALTH_URL", "http://u:s3cret-url@h:1/healthz")
            .output()
            .unwrap();
        let help = String::from_utf8(output.stdout).unwrap();
        assert!(help.contains("Usage") && !help.contains("s3cret"), "{help}");
    }
    // Help that cannot be written is a failure, as any output is.
    let output = to_dev_full(&["--help"]);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("No space left on device"), "{stderr}");
}

#[test]
fn run_is_bit_identical_for_threads_1_2_3_and_on_a_rerun() {
    let job = serde_json::json!({
        "devices": 40, "operations": 30, "seed": 2024,
        "scenario": {"circuit": {"supply_voltage_v": 48, "current_a": 15}},
        "scatter": [
            {"parameter": "contact_radius_m", "per": "device", "distribution": {"kind": "uniform", "min": 6e-3, "max": 9e-3}},
            {"parameter": "dynamic_yield_pressure_pa", "per": "device", "distribution": {"kind": "lognormal", "median": 2e8, "sigma": 0.1}},
            {"parameter": "impact_velocity_m_s", "per": "operation", "distribution": {"kind": "triangular", "min": 0.15, "mode": 0.22, "max": 0.3}}
        ]
    });
    let reference = run_job(&job, &["--threads", "1"]);
    for threads in ["2", "3", "1"] {
        let again = run_job(&job, &["--threads", threads]);
        assert_eq!(
            again["operations"], reference["operations"],
            "threads {threads}"
        );
        assert_eq!(again["devices"], reference["devices"], "threads {threads}");
    }
}

/// The kernels the binary runs on this CPU, as its refusal of an unknown `--kernel` lists them.
fn kernels() -> Vec<String> {
    let line = rejected(&["--kernel", "sse9", "simulate"], "{}");
    assert!(
        line.contains("--kernel (BOUNCEWEAR_KERNEL) `sse9`"),
        "{line}"
    );
    let names = line.trim_end().rsplit_once("one of ").unwrap().1;
    names.split(", ").map(str::to_owned).collect()
}

/// `--kernel NAME` (or `BOUNCEWEAR_KERNEL`) runs the process's jobs on that kernel, and every
/// kernel this CPU runs (one device at a time, then each instruction set's lockstep batches)
/// gives the same Result to the bit: both reference jobs at 37 devices, so that every batch width
/// leaves a remainder, and one with wear that softens, a failure criterion and a limit. The
/// model's own test (`model/tests/integration/kernels.rs`) compares more jobs in one process;
/// this is the switch a person or an outside check uses on the binary.
#[test]
fn every_kernel_gives_the_same_result_through_the_binary() {
    let names = kernels();
    assert_eq!(names[0], "scalar", "{names:?}");
    assert!(
        names.len() >= 2,
        "a lockstep kernel runs everywhere: {names:?}"
    );
    let reference: Value = serde_json::from_str(include_str!("data/reference_jobs.json")).unwrap();
    let mut jobs: Vec<Value> = ["48 V / 15 A", "mechanical"]
        .iter()
        .map(|name| {
            let mut job = reference[name].clone();
            job["devices"] = serde_json::json!(37);
            job["operations"] = serde_json::json!(40);
            job
        })
        .collect();
    let mut wearing = jobs[0].clone();
    wearing["scenario"]["material"] =
        serde_json::json!({"wear_law": {"law": "roughening_and_softening"}});
    wearing["scatter"].as_array_mut().unwrap().remove(1);
    wearing["failure"] = serde_json::json!({"total_bounce_s": {"above": 2e-3}});
    wearing["limits"] = serde_json::json!({"e1": 0.5});
    jobs.push(wearing);
    let on = |job: &Value, kernel: &str| {
        without_timing(&run_job(job, &["--kernel", kernel]).to_string())
    };
    let scalar: Vec<Value> = jobs.iter().map(|job| on(job, "scalar")).collect();
    for (job, scalar) in jobs.iter().zip(&scalar) {
        for name in &names[1..] {
            assert!(
                on(job, name) == *scalar,
                "{name} differs from scalar on {job}"
            );
        }
    }
    // The environment variable is the same switch; set empty, it is no choice (it was refused
    // as a kernel named ``).
    let dir = temp_dir("kernel-env");
    let path = dir.join("job.json");
    std::fs::write(&path, jobs[0].to_string()).unwrap();
    for kernel in [names.last().unwrap().as_str(), ""] {
        let output = std::process::Command::new(crate::support::BIN)
            .args(["run", "--quiet", path.to_str().unwrap()])
            .env("BOUNCEWEAR_KERNEL", kernel)
            .output()
            .unwrap();
        assert!(
            output.status.success(),
            "{kernel}: {}",
            String::from_utf8_lossy(&output.stderr)
        );
        let result = without_timing(std::str::from_utf8(&output.stdout).unwrap());
        assert!(result == scalar[0], "{kernel}");
    }
}

/// `--plots DIR` writes the dashboard's plots: per operation metric its bands and histograms, and
/// with a sensitivity analysis its chart per metric of the analysis.
#[test]
fn run_writes_the_dashboards_plots_sensitivity_included() {
    let mut job = crate::support::scattered_job(24, 20, 3);
    job["metrics"] = serde_json::json!(["total_bounce_s", "final_radius_m"]);
    job["sensitivity"] = serde_json::json!({"method": "sobol"});
    let dir = temp_dir("plots");
    let result = run_job(&job, &["--plots", dir.to_str().unwrap()]);
    assert!(result["sensitivity"]["total_bounce_s"].is_array());
    for name in [
        "bands-total_bounce_s.svg",
        "histograms-total_bounce_s.svg",
        "sensitivity-total_bounce_s.svg",
        "sensitivity-final_radius_m.svg",
    ] {
        let svg = std::fs::read_to_string(dir.join(name)).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert!(
            svg.starts_with("<svg") && svg.ends_with("</svg>\n"),
            "{name}"
        );
        assert!(!svg.contains("NaN"), "{name}");
    }
}

/// A one-device job without scatter is `simulate` repeated, with the radius of docs/model.md
/// section 6 worked out by hand from the arc energy of the operations before. Each operation is
/// simulated by the library, and the first, middle and last by the binary too, which must print
/// the same: a thousand processes took 13 of the test's seconds.
#[test]
fn one_device_job_equals_repeated_simulate_with_the_worn_radius() {
    let operations = 1000;
    let job = serde_json::json!({
        "devices": 1, "operations": operations, "bin_operations": 1, "seed": 1,
        "scenario": {"circuit": {"supply_voltage_v": 48, "current_a": 15}},
        "metrics": ["kappa", "e1", "total_bounce_s", "bounce_count", "arc_energy_j", "peak_force_n", "final_radius_m"]
    });
    let result = run_job(&job, &["--threads", "2"]);
    let (r0, r_inf, w_r) = (7.7e-3_f64, 0.711e-3_f64, 500.0_f64);
    let mut cumulative = 0.0;
    for op in 0..operations {
        let radius = r_inf + (r0 - r_inf) * (-cumulative / w_r).exp();
        let scenario = serde_json::json!({
            "circuit": {"supply_voltage_v": 48, "current_a": 15},
            "material": {"contact_radius_m": radius, "dynamic_yield_pressure_pa": 2e8}
        });
        let parsed = Scenario::from_json(&scenario.to_string()).unwrap();
        let expected = serde_json::to_value(simulate(&parsed, Fidelity::Exact)).unwrap();
        if [0, operations / 2, operations - 1].contains(&op) {
            let output = bouncewear(&["simulate"], &scenario.to_string());
            let printed: Value = serde_json::from_slice(&output.stdout).unwrap();
            assert_eq!(
                printed, expected,
                "operation {op}: the binary prints the library's"
            );
        }
        for metric in [
            "kappa",
            "e1",
            "total_bounce_s",
            "bounce_count",
            "arc_energy_j",
            "peak_force_n",
        ] {
            let bin = &result["operations"][metric][op];
            assert_eq!(bin["n"], 1);
            let (got, want) = (
                bin["mean"].as_f64().unwrap(),
                expected[metric].as_f64().unwrap(),
            );
            assert!(
                (got - want).abs() <= 1e-9 * want.abs(),
                "operation {op} {metric}: {got} vs {want}"
            );
        }
        cumulative += expected["arc_energy_j"].as_f64().unwrap();
    }
    let final_radius = r_inf + (r0 - r_inf) * (-cumulative / w_r).exp();
    let reported = result["devices"]["final_radius_m"]["mean"]
        .as_f64()
        .unwrap();
    assert!((reported - final_radius).abs() <= 1e-9 * final_radius);
}

#[test]
fn run_rejects_bad_jobs_naming_the_field() {
    for (job, pointer) in [
        (r#"{"devices": 0}"#, "/devices"),
        (
            r#"{"scatter": [{"parameter": "contact_radius_m", "per": "device", "distribution": {"kind": "normal", "mean": 7e-3, "sd": 1e-3}}]}"#,
            "/scatter/0/distribution/min",
        ),
        (
            r#"{"scenario": {"losses": {"max_bounces": 0}}}"#,
            "/scenario/losses/max_bounces",
        ),
        (r#"{"devices": "many"}"#, "/devices"),
        (r#"{"devices": 1"#, "malformed JSON"),
    ] {
        let path = temp_dir("bad-job").join("bad.json");
        std::fs::write(&path, job).unwrap();
        let line = rejected(&["run", path.to_str().unwrap()], "");
        assert!(line.contains(pointer), "{job}: {line}");
    }
    // A flag at fault is a bad command line, said as it is, not as a document's fault.
    let line = rejected(&["run", "-", "--threads", "0"], "{}");
    assert_eq!(
        line.trim_end(),
        "bouncewear: --threads must be from 1 to 1024, got 0"
    );
    // Thousands of threads on two cores: refused before one is started.
    let line = rejected(&["run", "-", "--threads", "100000"], "{}");
    assert_eq!(
        line.trim_end(),
        "bouncewear: --threads must be from 1 to 1024, got 100000"
    );
}

/// What a local command is given and where it writes, found wanting from outside: an output
/// directory that cannot be one is refused before the run (it threw the Result away after it),
/// an input is read up to 64 MB (`/dev/zero` took 9.4 GB), a byte-order mark is no part of the
/// text, a name with control characters stays on one inert line, and an output the machine
/// cannot write is a failure (1), not bad input (2).
#[test]
fn inputs_are_bounded_and_outputs_checked_before_the_work() {
    let dir = temp_dir("outputs");
    let file = dir.join("a-file");
    std::fs::write(&file, "").unwrap();
    let job = r#"{"devices": 2, "operations": 3, "seed": 1}"#;
    let line = rejected(&["run", "-q", "--plots", file.to_str().unwrap(), "-"], job);
    assert!(
        line.starts_with("bouncewear: --plots ") && line.contains("cannot be made a directory"),
        "{line}"
    );
    // A directory that is there but takes no file is refused before the run too (it failed
    // after it, the Result printed).
    let line = rejected(&["run", "-q", "--plots", "/proc/self", "-"], job);
    assert!(line.contains("--plots /proc/self: cannot"), "{line}");
    let huge = " ".repeat((64 << 20) + 1);
    let line = rejected(&["simulate", "-"], &huge);
    assert!(line.contains("more than 64 MB"), "{line}");
    let marked = bouncewear(&["simulate", "-"], "\u{feff}{}");
    assert!(marked.status.success(), "{marked:?}");
    let line = rejected(&["simulate", "-"], r#"{"a\nb\u001b[31m": 1}"#);
    assert!(line.contains(r"a\nb\u{1b}[31m"), "{line}");
    // Run to /dev/full: an empty job is bad input (2); a good one whose Result cannot be
    // written fails (1).
    let to_full = |job: &str| {
        std::fs::write(&file, job).unwrap();
        to_dev_full(&["run", "-q", file.to_str().unwrap()])
    };
    assert_eq!(to_full("").status.code(), Some(2));
    let full = to_full(job);
    let stderr = String::from_utf8_lossy(&full.stderr);
    assert_eq!(full.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("<stdout>: No space left on device"),
        "{stderr}"
    );
}

#[test]
fn a_reader_that_stops_early_is_not_an_error() {
    use std::process::{Command, Stdio};
    let dir = temp_dir("broken-pipe");
    let job = dir.join("job.json");
    std::fs::write(
        &job,
        r#"{"devices": 20, "operations": 1000, "bin_operations": 1, "seed": 1}"#,
    )
    .unwrap();
    let child = Command::new(crate::support::BIN)
        .args(["run", job.to_str().unwrap()])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // `| head -0`: the reader goes away before the first line arrives.
    let mut child = child;
    drop(child.stdout.take());
    let output = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "{:?}: {stderr}", output.status);
    assert!(!stderr.contains("Broken pipe"), "{stderr}");
}

/// A `--url` the remote commands cannot use, and an API key no header can carry, are a bad
/// command line (2) naming the flag, before any request: they were exit 1 with the HTTP
/// library's words, a query string sent every request to the dashboard, and port 99999 went to
/// another port (found from outside). The key is not repeated.
#[test]
fn a_remote_command_line_that_cannot_be_sent_is_refused_naming_the_flag() {
    for (url, rule) in [
        ("garbage", "no scheme"),
        ("ftp://127.0.0.1:8080", "http or https"),
        ("", "not a URL"),
        ("http://127.0.0.1:99999", "port must be from 1 to 65535"),
        ("http://127.0.0.1:0", "port must be from 1 to 65535"),
        ("http://127.0.0.1:8080?x=1", "no query or fragment"),
        ("http://127.0.0.1:8080#top", "no query or fragment"),
        (
            "http://user:pw@127.0.0.1:99999",
            "port must be from 1 to 65535",
        ),
        ("http://127.0.0.1:+8080", "port must be from 1 to 65535"),
        ("http://127.0.0.1:00", "port must be from 1 to 65535"),
    ] {
        let line = rejected(&["status", "some-id", "--url", url], "");
        assert!(
            line.contains("--url (BOUNCEWEAR_URL)") && line.contains(rule),
            "{url}: {line}"
        );
        assert!(!line.contains(":pw@"), "the password is not shown: {line}");
    }
    // An empty id is a bad command line before any request (`wait ""` asked for `/v1/jobs/`
    // and exited 1 with a 404, found from outside).
    for args in [
        &["wait", ""][..],
        &["compare", "a", ""],
        &["schedule", "show", ""],
    ] {
        let output = bouncewear(args, "");
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert_eq!(output.status.code(), Some(2), "{args:?}: {stderr}");
        assert!(stderr.contains("a value is required"), "{args:?}: {stderr}");
    }
    // URLs that are good, their server absent: no answer (1), never a bad command line; a
    // password is never shown (it was, in every message and log line, found from outside).
    for url in [
        "http://user:s3cret@127.0.0.1",
        "HTTP://[::1]:9/prefix/",
        "https://127.0.0.1:9",
    ] {
        let output = bouncewear(&["status", "some-id", "--retries", "0", "--url", url], "");
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert_eq!(output.status.code(), Some(1), "{url}: {stderr}");
        assert!(!stderr.contains("s3cret"), "{stderr}");
    }
    let health = bouncewear(
        &["health", "--url", "http://user:s3cret@127.0.0.1:9/healthz"],
        "",
    );
    let stderr = String::from_utf8_lossy(&health.stderr);
    assert!(
        stderr.contains("//***@") && !stderr.contains("s3cret"),
        "{stderr}"
    );
    // A URL too broken to parse, its password too: no scheme, a `/` in the password; health's
    // URL is held to the same rules.
    for url in ["u:s3cret@h:80", "http://u:s3/cret@h", "//u:s3cret@h"] {
        for command in [&["status", "some-id"][..], &["health"]] {
            let line = rejected(&[command, &["--url", url]].concat(), "");
            assert!(
                line.contains("--url") && !line.contains("s3"),
                "{url}: {line}"
            );
        }
    }
    let args = [
        "status",
        "some-id",
        "--retries",
        "0",
        "--url",
        "http://127.0.0.1:9",
    ];
    for key in ["k1\nX-Evil: 1", "caf\u{e9}", "a\tb", "", "   ", " k1"] {
        let line = rejected(&[&args[..], &["--api-key", key]].concat(), "");
        let repeated = !key.is_empty() && line.contains(key);
        assert!(line.contains("--api-key") && !repeated, "{line}");
    }
}

/// A stdout or stderr that cannot take a line never panics (exit 101): a message that cannot
/// be written leaves the exit status as it was, and a server whose stdout is a full disk says
/// where it listens in its log and serves (it panicked at start-up, found from outside).
#[test]
fn an_unwritable_stdout_or_stderr_never_panics() {
    use std::io::{BufRead, BufReader};
    use std::process::{Command, Stdio};
    let full = || {
        let file = std::fs::OpenOptions::new().write(true).open("/dev/full");
        Stdio::from(file.unwrap())
    };
    let mut refused = Command::new(crate::support::BIN)
        .args(["simulate", "-"])
        .stdin(Stdio::piped())
        .stdout(Stdio::null())
        .stderr(full())
        .spawn()
        .unwrap();
    drop(refused.stdin.take());
    assert_eq!(refused.wait().unwrap().code(), Some(2));
    let dir = temp_dir("unwritable");
    let database = format!("sqlite://{}", dir.join("a.db").display());
    let mut server = Command::new(crate::support::BIN)
        .args(["serve", "--bind", "127.0.0.1:0", "--workers", "0"])
        .args(["--database", &database])
        .env("RUST_LOG", "warn")
        .stdout(full())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut log = BufReader::new(server.stderr.take().unwrap());
    let mut line = String::new();
    let address = loop {
        line.clear();
        assert_ne!(log.read_line(&mut line).unwrap(), 0, "the server ended");
        if let Some(rest) = line.split("bouncewear listening on ").nth(1) {
            break rest.split_whitespace().next().unwrap().to_owned();
        }
    };
    let health = format!("{address}/healthz");
    let answered = bouncewear(&["health", "--url", &health], "");
    let to_full = Command::new(crate::support::BIN)
        .args(["health", "--url", &health])
        .stdout(full())
        .output()
        .unwrap();
    server.kill().unwrap();
    server.wait().unwrap();
    assert!(answered.status.success(), "{answered:?}");
    assert!(String::from_utf8_lossy(&answered.stdout).contains("\"ok\""));
    let stderr = String::from_utf8_lossy(&to_full.stderr);
    assert_eq!(to_full.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("<stdout>: No space left"), "{stderr}");
}

/// Runs the binary with `args` on a terminal (util-linux `script` gives it one), its stdout
/// thrown away: what the terminal showed.
fn on_a_terminal(args: &[&str]) -> String {
    let quoted: Vec<String> = std::iter::once(crate::support::BIN)
        .chain(args.iter().copied())
        .map(|arg| format!("'{arg}'"))
        .collect();
    let output = std::process::Command::new("script")
        .args(["--quiet", "--return", "--command"])
        .arg(format!("{} > /dev/null", quoted.join(" ")))
        .arg("/dev/null")
        .stdin(std::process::Stdio::null())
        .output()
        .expect("util-linux `script` runs");
    assert!(output.status.success(), "{args:?}: {output:?}");
    String::from_utf8_lossy(&output.stdout).into_owned()
}

#[test]
fn run_shows_progress_with_the_time_left_only_on_a_terminal_and_not_when_quiet() {
    let job = temp_dir("progress").join("job.json");
    std::fs::write(&job, r#"{"devices": 400, "operations": 2000, "seed": 1}"#).unwrap();
    let job = job.to_str().unwrap();
    let shown = on_a_terminal(&["run", job, "--threads", "1"]);
    assert!(
        shown.contains("/800,000 operations") && shown.contains("ETA"),
        "{shown}"
    );
    assert_eq!(
        on_a_terminal(&["run", job, "--threads", "1", "--quiet"]),
        ""
    );
    let piped = bouncewear(&["run", job, "--threads", "1"], "");
    assert!(piped.status.success());
    assert_eq!(
        String::from_utf8_lossy(&piped.stderr),
        "",
        "nothing on a pipe"
    );
}

#[test]
fn bench_quick_writes_the_report_in_all_three_forms_with_progress_on_a_terminal() {
    let out = temp_dir("bench");
    let shown = on_a_terminal(&[
        "bench",
        "--quick",
        "--coverage-seeds",
        "7",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(
        shown.contains("35/35 measurements") && shown.contains("ETA"),
        "{shown}"
    );
    let report: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    let tiers = report["tiers"].as_array().unwrap();
    assert_eq!(tiers.len(), 2);
    // Each rare-event method at 1e-3, 1e-6 and 1e-9 (crude at 1e-3 only), against the exact tail.
    let rare = report["rare_events"].as_array().unwrap();
    assert_eq!(rare.len(), 7);
    assert!(
        rare.iter()
            .all(|row| row["mean_evaluations"].as_f64().unwrap() > 0.0)
    );
    // Coverage of the 95 % intervals in three designs at two sizes, the Sobol' indices' among them.
    let coverage = report["coverage"].as_array().unwrap();
    for devices in [64, 512] {
        assert_eq!(
            coverage
                .iter()
                .filter(|row| row["devices"] == devices)
                .count(),
            coverage.len() / 2
        );
    }
    assert!(
        coverage
            .iter()
            .any(|row| row["statistic"] == "velocity: total index")
    );
    for row in coverage {
        assert!(
            (0.0..=1.0).contains(&row["coverage"].as_f64().unwrap()),
            "{row}"
        );
        assert_eq!(row["seeds"], 7, "{row}");
    }
    // Exceedance in the tail against the exact normal tail: counted as the job ran, and asked
    // after it, counted from the values each group keeps at its ends (about 31 per group beyond
    // P = 1e-3 of 1e6 values, within the 64 kept): both exact in every job.
    let tail = report["tail_coverage"].as_array().unwrap();
    assert_eq!(tail.len(), 2);
    for row in tail {
        assert_eq!(row["values"], 1_000_000, "{row}");
        assert_eq!(row["exact"], row["seeds"], "{row}");
        assert!(
            (0.0..=1.0).contains(&row["coverage"].as_f64().unwrap()),
            "{row}"
        );
    }
    // Calibration intervals over 20 noise draws of each study case: kappa from both bounce
    // times; kappa and the roughening energy from a wear curve. 20 draws of a true 0.95 fall
    // below 0.8 with probability 0.016: a fit that lost its interval would cover far less.
    let calibration = report["calibration_coverage"].as_array().unwrap();
    assert_eq!(calibration.len(), 3, "{calibration:?}");
    for row in calibration {
        assert_eq!(row["draws"], 20, "{row}");
        assert_eq!(row["first_seed"], 1000, "{row}");
        assert!(row["coverage"].as_f64().unwrap() >= 0.8, "{row}");
    }
    // The floor is measured on this CPU: square roots and divisions alone, which the engine runs
    // among everything else, so never above the engine's own time per operation.
    let engine = report["engine"].as_array().unwrap();
    assert_eq!(engine.len(), 2, "{engine:?}");
    for row in engine {
        for (floor, engine) in [
            ("floor_ns_per_op_scalar", "ns_per_op_one_device_at_a_time"),
            ("floor_ns_per_op_lockstep", "ns_per_op_lockstep"),
        ] {
            let (floor, engine) = (row[floor].as_f64().unwrap(), row[engine].as_f64().unwrap());
            assert!(floor > 0.0 && floor < engine, "{row}");
        }
    }
    let markdown = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(markdown.contains("## Calibration intervals"), "{markdown}");
    let refused = bouncewear(&["bench", "--coverage-seeds", "0"], "");
    assert!(!refused.status.success());
    assert!(
        String::from_utf8_lossy(&refused.stderr).contains("--coverage-seeds"),
        "{refused:?}"
    );
    for tier in tiers {
        assert!(tier["ns_per_op"].as_f64().unwrap() > 0.0);
        assert_eq!(tier["max_rel_error"].as_object().unwrap().len(), 10);
    }
    assert!(
        tiers[0]["max_rel_error"]["total_bounce_s"]
            .as_f64()
            .unwrap()
            < 1e-12,
        "exact tier is exact"
    );
    assert!(
        tiers[1]["median_rel_error"]["total_bounce_s"]
            .as_f64()
            .unwrap()
            > 1e-3,
        "closed form is not"
    );
    // The paper's closed forms: each applies to some of the scenarios, and costs accuracy.
    let forms = report["paper_forms"].as_array().unwrap();
    assert_eq!(forms.len(), 2);
    for form in forms {
        assert!(form["scenarios"].as_u64().unwrap() > 0, "{form}");
        assert!(
            form["median_rel_error"]["first_bounce_s"].as_f64().unwrap() > 1e-3,
            "{form}"
        );
    }
    let sampling = report["sampling"].as_array().unwrap();
    assert!(
        sampling.iter().any(|s| s["sampler"] == "lhs")
            && sampling.iter().any(|s| s["sampler"] == "random")
    );
    assert!(
        std::fs::read_to_string(out.join("report.svg"))
            .unwrap()
            .starts_with("<svg")
    );
    assert!(
        std::fs::read_to_string(out.join("report.md"))
            .unwrap()
            .contains("| exact |")
    );
    assert!(
        std::fs::read_to_string(out.join("report.md"))
            .unwrap()
            .contains("| paper eq. 9/10, e = 0.4 (")
    );
    measure_the_intervals_again(&out, &report);
}

/// `bench --only intervals` over the report [`bench_quick_writes_the_report_in_all_three_forms_with_progress_on_a_terminal`]
/// wrote: the coverage table over the seeds asked now, the seeded tail and calibration tables
/// the same to the bit, every timed figure as it was; a directory with no report, or one
/// measured with `--quick` asked again without it, is refused (exit 2) before any work.
fn measure_the_intervals_again(out: &Path, before: &Value) {
    let out_arg = out.to_str().unwrap();
    let again = bouncewear(
        &[
            "bench",
            "--quick",
            "--coverage-seeds",
            "5",
            "--only",
            "intervals",
            "--out",
            out_arg,
        ],
        "",
    );
    assert!(again.status.success(), "{again:?}");
    let after: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    for kept in [
        "tiers",
        "paper_forms",
        "sampling",
        "throughput",
        "skips",
        "engine",
        "rare_events",
        "tail_coverage",
        "calibration_coverage",
    ] {
        assert_eq!(after[kept], before[kept], "{kept}");
    }
    let coverage = after["coverage"].as_array().unwrap();
    assert_eq!(coverage.len(), before["coverage"].as_array().unwrap().len());
    assert!(coverage.iter().all(|row| row["seeds"] == 5), "{coverage:?}");
    assert_eq!(after["machine"]["coverage_seeds"], 5);
    let markdown = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(
        markdown.contains("measured again over it with `bouncewear bench --quick --coverage-seeds 5 --only intervals`"),
        "{markdown}"
    );
    let empty = temp_dir("bench-none");
    let refused = bouncewear(
        &[
            "bench",
            "--quick",
            "--only",
            "intervals",
            "--out",
            empty.to_str().unwrap(),
        ],
        "",
    );
    assert_eq!(refused.status.code(), Some(2), "{refused:?}");
    assert!(
        String::from_utf8_lossy(&refused.stderr).contains("report.json"),
        "{refused:?}"
    );
    let refused = bouncewear(&["bench", "--only", "intervals", "--out", out_arg], "");
    assert_eq!(refused.status.code(), Some(2), "{refused:?}");
    assert!(
        String::from_utf8_lossy(&refused.stderr).contains("measured with --quick"),
        "{refused:?}"
    );
}

/// Measurements made by `simulate` itself at kappa 0.3, at three impact velocities: `calibrate`
/// gives kappa back, and a scenario that `simulate` accepts; bad requests name their field.
#[test]
fn calibrate_fits_kappa_to_simulated_measurements() {
    let observations: Vec<Value> = [0.2, 0.4, 0.6]
        .iter()
        .map(|v| {
            let scenario = format!(
                r#"{{"material": {{"kappa": 0.3}}, "mechanism": {{"impact_velocity_m_s": {v}}}}}"#
            );
            let output = bouncewear(&["simulate"], &scenario);
            let outcome: Value = serde_json::from_slice(&output.stdout).unwrap();
            serde_json::json!({"impact_velocity_m_s": v, "first_bounce_s": outcome["first_bounce_s"],
                               "e1": outcome["e1"], "bounce_count": outcome["bounce_count"]})
        })
        .collect();
    let request = serde_json::json!({"fit": ["material.kappa"], "observations": observations});
    let output = bouncewear(&["calibrate"], &request.to_string());
    assert!(output.status.success(), "{output:?}");
    let fit: Value = serde_json::from_slice(&output.stdout).unwrap();
    let kappa = &fit["estimates"]["material.kappa"];
    assert!(
        (kappa["value"].as_f64().unwrap() / 0.3 - 1.0).abs() < 1e-6,
        "{kappa}"
    );
    assert_eq!(fit["residuals"]["bounce_count"]["rms_relative"], 0.0);
    let fitted = bouncewear(&["simulate"], &fit["scenario"].to_string());
    assert!(fitted.status.success(), "the fitted scenario simulates");
    // A plot that cannot be written fails the command (1), the fit printed first.
    let nowhere = temp_dir("calibrate-plot")
        .join("no-such-dir")
        .join("fit.svg");
    let plotted = bouncewear(
        &["calibrate", "--plot", nowhere.to_str().unwrap()],
        &request.to_string(),
    );
    assert_eq!(plotted.status.code(), Some(1), "{plotted:?}");
    assert_eq!(plotted.stdout, output.stdout);

    // The same measurements as CSV, a column per field, give the same fit to the byte.
    let dir = temp_dir("calibrate-csv");
    let mut csv = "impact_velocity_m_s,first_bounce_s,e1,bounce_count\n".to_owned();
    for o in &observations {
        let cells: Vec<String> = [
            "impact_velocity_m_s",
            "first_bounce_s",
            "e1",
            "bounce_count",
        ]
        .iter()
        .map(|field| o[field].to_string())
        .collect();
        csv += &(cells.join(",") + "\n");
    }
    let path = dir.join("measurements.csv");
    std::fs::write(&path, csv).unwrap();
    let from_csv = bouncewear(
        &["calibrate", "--observations", path.to_str().unwrap()],
        r#"{"fit": ["material.kappa"]}"#,
    );
    assert_eq!(
        String::from_utf8_lossy(&from_csv.stdout),
        String::from_utf8_lossy(&output.stdout)
    );
    std::fs::write(&path, "e1,first_bounce_s\n0.4,abc\n").unwrap();
    let line = rejected(
        &["calibrate", "--observations", path.to_str().unwrap()],
        r#"{"fit": ["material.kappa"]}"#,
    );
    assert!(
        line.contains("column `first_bounce_s`: `abc` is not a finite number"),
        "{line}"
    );
    // Observations in the file and in the CSV: one list too many (the file's were dropped).
    std::fs::write(&path, "e1\n0.4\n0.5\n").unwrap();
    let line = rejected(
        &["calibrate", "--observations", path.to_str().unwrap()],
        &request.to_string(),
    );
    assert!(
        line.contains("--observations") && line.contains("give them in one place"),
        "{line}"
    );

    let line = rejected(
        &["calibrate"],
        r#"{"fit": ["material.kappa", "material.contact_radius_m"], "scenario": {"material": {"kappa": 0.3}},
            "observations": [{"e1": 0.5}, {"e1": 0.45, "impact_velocity_m_s": 0.4}, {"e1": 0.4, "impact_velocity_m_s": 0.6}]}"#,
    );
    assert!(line.contains("/fit/1"), "{line}");
}
