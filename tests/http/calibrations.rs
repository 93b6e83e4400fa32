//! `POST /v1/calibrations`: a scenario fitted to measured operations, as `bouncewear calibrate`
//! prints it, or its plot.

use crate::support::app::{Service, TestApp};
use crate::support::client::{assert_problem, get, post};
use crate::support::{bouncewear, temp_db};
use serde_json::{Value, json};

/// Bounce traces of the paper's rig, simulated by the binary at kappa 0.33 and 2 uJ lost per
/// impact and rounded to three digits.
fn measurements() -> Value {
    let observations: Vec<Value> = [0.2, 0.3, 0.4]
        .into_iter()
        .map(|v| {
            let scenario = json!({
                "mechanism": {"impact_velocity_m_s": v},
                "material": {"kappa": 0.33},
                "losses": {"impact_energy_loss_j": 2e-6}
            });
            let output = bouncewear(&["simulate"], &scenario.to_string());
            let simulated: Value = serde_json::from_slice(&output.stdout).unwrap();
            let round = |x: &Value| {
                format!("{:.3e}", x.as_f64().unwrap())
                    .parse::<f64>()
                    .unwrap()
            };
            json!({
                "impact_velocity_m_s": v,
                "first_bounce_s": round(&simulated["first_bounce_s"]),
                "second_bounce_s": round(&simulated["bounces"][1]["duration_s"]),
                "total_bounce_s": round(&simulated["total_bounce_s"]),
                "bounce_count": simulated["bounce_count"],
            })
        })
        .collect();
    json!({
        "fit": ["material.kappa", "losses.impact_energy_loss_j"],
        "observations": observations
    })
}

#[test]
fn a_calibration_over_http_is_the_calibrate_command_and_recovers_the_parameters() {
    let server = TestApp::start(&temp_db("calibrations"), &[]);
    let request = measurements().to_string();
    let fitted = post(&server.url("/v1/calibrations"), &request, None);
    assert_eq!(fitted.status, 200, "{}", fitted.body);
    let fit = fitted.json();
    let output = bouncewear(&["calibrate"], &request);
    let cli: Value = serde_json::from_slice(&output.stdout).unwrap();
    assert_eq!(fit, cli);
    for (name, truth) in [
        ("material.kappa", 0.33),
        ("losses.impact_energy_loss_j", 2e-6),
    ] {
        let estimate = &fit["estimates"][name];
        let [lo, hi] = [0, 1].map(|i| estimate["ci95"][i].as_f64().unwrap());
        assert!(lo < truth && truth < hi, "{name}: {estimate}");
    }
    // The fitted scenario is one a job accepts.
    let job = json!({"scenario": fit["scenario"], "devices": 2, "operations": 2, "seed": 1});
    assert_eq!(
        post(&server.url("/v1/jobs"), &job.to_string(), None).status,
        202
    );
    // The paper's readings of e2 off the bounce times, with their bias.
    let e2 = &fit["restitution_from_bounce_times"]["e2"];
    assert_eq!(e2["observations"], json!([0, 1, 2]));
    assert!(e2["bias"].as_f64().unwrap() > 0.01, "{e2}");

    let plot = post(&server.url("/v1/calibrations?format=svg"), &request, None);
    assert_eq!(plot.status, 200);
    assert_eq!(plot.content_type, "image/svg+xml");
    assert!(plot.body.starts_with("<svg") && plot.body.contains("total_bounce_s"));
}

#[test]
fn an_ill_posed_calibration_is_refused_naming_the_field() {
    let server = TestApp::start(&temp_db("calibrations-bad"), &[]);
    let url = server.url("/v1/calibrations");
    // With kappa given, the contact radius changes nothing the data measure.
    let mut request = measurements();
    request["scenario"] = json!({"material": {"kappa": 0.33}});
    request["fit"] = json!(["material.kappa", "material.contact_radius_m"]);
    let problem = assert_problem(&post(&url, &request.to_string(), None), 422);
    assert_eq!(problem["errors"][0]["pointer"], "/fit/1", "{problem}");
    // A field that is not a positive number of the scenario, and an observation measuring nothing.
    let bad = json!({"fit": ["material.arc_restitution.law"], "observations": [{"impact_velocity_m_s": 0.3}]});
    let problem = assert_problem(&post(&url, &bad.to_string(), None), 422);
    let pointers: Vec<&str> = problem["errors"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| e["pointer"].as_str().unwrap())
        .collect();
    assert_eq!(pointers, ["/fit/0", "/observations/0"], "{problem}");
    assert_problem(
        &post(&format!("{url}?format=png"), &bad.to_string(), None),
        400,
    );
}

/// A fit whose request has gone is stopped and gives its place back: a client cannot pile up
/// fits beyond the cores by letting requests time out, nor keep the cores busy with requests it
/// abandoned. Each fit here follows a wear curve to 90,000 operations (7.6 s alone on a 2-core
/// Xeon VM, release build); before fits could be stopped, each went on after its request's 503
/// and held its place to the end. The timeout leaves the quick fit (5 ms alone) room to answer on
/// a machine loaded by other tests: at 0.25 s it once timed out itself for the 1.5 s the test
/// waited, under CI's load.
#[test]
fn a_fit_whose_request_timed_out_is_stopped_and_frees_its_place() {
    let server = TestApp::start(&temp_db("fit-places"), &["--request-timeout-seconds", "1"]);
    let url = server.url("/v1/calibrations");
    let observations: Vec<Value> = (0..6)
        .map(|i| json!({"operation": 15_000 * (i + 1), "first_bounce_s": 0.009 - 0.0005 * f64::from(i)}))
        .collect();
    let slow = json!({
        "scenario": {"circuit": {"supply_voltage_v": 48, "current_a": 15}},
        "fit": ["material.kappa", "material.roughening_energy_j"],
        "observations": observations
    })
    .to_string();
    let quick = measurements().to_string();
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let gave_up: Vec<u16> = (0..cores)
        .map(|_| {
            let (url, slow) = (url.clone(), slow.clone());
            std::thread::spawn(move || post(&url, &slow, None).status)
        })
        .collect::<Vec<_>>()
        .into_iter()
        .map(|request| request.join().unwrap())
        .collect();
    assert_eq!(gave_up, vec![503; cores]);
    // The stopped fits gave their places back: a fit runs again at once, seconds before any of
    // them would have ended on its own.
    let started = std::time::Instant::now();
    loop {
        match post(&url, &quick, None).status {
            503 => assert!(
                started.elapsed() < std::time::Duration::from_secs(3),
                "the places are still held"
            ),
            status => break assert_eq!(status, 200),
        }
    }
    // Each was stopped, not ended: however fast the CPU, the count says so (the quick fit
    // needed one place; the others are counted as they give theirs back).
    loop {
        let metrics = get(&server.url("/metrics"), None).body;
        let stopped = metrics
            .lines()
            .find_map(|line| line.strip_prefix("bouncewear_fits_stopped_total "))
            .and_then(|count| count.trim().parse::<usize>().ok());
        if stopped >= Some(cores) {
            break;
        }
        assert!(
            started.elapsed() < std::time::Duration::from_secs(3),
            "{stopped:?} of {cores} fits stopped"
        );
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
}
