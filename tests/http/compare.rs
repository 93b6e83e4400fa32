//! Two designs compared over the API and the command line: a job against itself is a comparison
//! whose answer is known exactly; two designs give both plots with both names; bad queries are
//! 400s naming their parameter.

use super::remote::{job_file, remote, stdout};
use crate::support::app::{Service, TestApp};
use crate::support::client::{assert_problem, get, post};
use crate::support::temp_db;
use serde_json::{Value, json};

/// A wearing design with scattered velocity and a failure criterion most devices meet.
fn design(name: &str, current_a: f64) -> Value {
    json!({"name": name, "devices": 60, "operations": 80, "bin_operations": 40, "seed": 11,
        "scenario": {"circuit": {"supply_voltage_v": 48, "current_a": current_a}},
        "scatter": [{"parameter": "impact_velocity_m_s", "per": "device",
                     "distribution": {"kind": "normal", "mean": 0.224, "sd": 0.03, "min": 0.05}}],
        "failure": {"e1": {"below": 0.37}}})
}

#[test]
fn a_job_against_itself_and_two_designs_over_api_and_cli() {
    let server = TestApp::start(&temp_db("compare"), &[]);
    let submit = |job: &Value, name: &str| -> String {
        let queued: Value = serde_json::from_str(&stdout(&remote(
            &server,
            None,
            &["submit", &job_file(name, job)],
        )))
        .unwrap();
        let id = queued["id"].as_str().unwrap().to_owned();
        stdout(&remote(&server, None, &["wait", &id]));
        id
    };
    let strong = submit(&design("15 A", 15.0), "compare-a");
    let weak = submit(&design("5 A", 5.0), "compare-b");

    // Itself: no difference, a ratio of one, each as likely to outlast the other.
    let same = get(
        &format!(
            "{}/v1/jobs/{strong}/compare/{strong}?statistics=mean,p50&b_lives=0.1",
            server.base()
        ),
        None,
    );
    assert_eq!(same.status, 200, "{}", same.body);
    let same = same.json();
    assert_eq!(same["a"], strong.as_str());
    assert_eq!(same["metric"], "total_bounce_s");
    assert_eq!(same["bins"].as_array().unwrap().len(), 2);
    let notes = same["notes"].to_string();
    assert!(notes.contains("are the same job"), "{notes}");
    for bin in same["bins"].as_array().unwrap() {
        for statistic in ["mean", "p50"] {
            let d = &bin["statistics"][statistic];
            assert_eq!(d["difference"], 0.0, "{d}");
            assert_eq!(d["ratio"], 1.0, "{d}");
            let [lo, hi] = [
                d["difference_ci95"][0].as_f64().unwrap(),
                d["difference_ci95"][1].as_f64().unwrap(),
            ];
            assert!(lo < 0.0 && hi > 0.0 && (lo + hi).abs() <= 1e-12 * hi, "{d}");
        }
    }
    let life = &same["life"];
    assert_eq!(life["b_lives"][0]["p"], 0.1);
    assert_eq!(life["b_lives"][0]["ratio"], 1.0);
    let p = life["outlasts"]["weibull"].as_f64().unwrap();
    assert!((p - 0.5).abs() < 1e-12, "{life}");
    let [lo, hi] = [
        life["outlasts"]["observed"][0].as_f64().unwrap(),
        life["outlasts"]["observed"][1].as_f64().unwrap(),
    ];
    assert!(lo <= 0.5 && 0.5 <= hi, "{life}");
    // A job against itself: the share's interval holds the bounds and is symmetric about 0.5.
    let [clo, chi] = [
        life["outlasts"]["observed_ci95"][0].as_f64().unwrap(),
        life["outlasts"]["observed_ci95"][1].as_f64().unwrap(),
    ];
    assert!(clo < lo && hi < chi, "{life}");
    assert!((clo + chi - 1.0).abs() < 1e-12, "{life}");

    // Two designs on the command line, with the plots.
    let dir = crate::support::temp_dir("compare-plots");
    let printed = stdout(&remote(
        &server,
        None,
        &[
            "compare",
            &strong,
            &weak,
            "--metric",
            "e1",
            "--plots",
            dir.to_str().unwrap(),
        ],
    ));
    let compared: Value = serde_json::from_str(&printed).unwrap();
    assert_eq!(compared["metric"], "e1");
    assert_eq!(compared["b"], weak.as_str());
    assert_eq!(
        compared["links"]["bands"],
        format!("/v1/jobs/{strong}/compare/{weak}/plots/bands.svg?metric=e1")
    );
    let bands = std::fs::read_to_string(dir.join("bands.svg")).unwrap();
    let weibull = std::fs::read_to_string(dir.join("weibull.svg")).unwrap();
    for svg in [&bands, &weibull] {
        assert!(svg.starts_with("<svg"), "{svg}");
        assert!(svg.contains(&format!("a: 15 A ({strong})")), "{svg}");
        assert!(svg.contains(&format!("b: 5 A ({weak})")), "{svg}");
    }
    assert!(bands.contains("e1: wear curves compared"));
    assert!(weibull.contains("Weibull probability plots compared"));
    // A device metric has no wear curve: its comparison is printed with the Weibull plots alone.
    let dir = crate::support::temp_dir("compare-device-plots");
    let (metric, plots) = ("eroded_mass_kg", dir.to_str().unwrap());
    let args = [
        "compare", &strong, &weak, "--metric", metric, "--plots", plots,
    ];
    let output = remote(&server, None, &args);
    let compared: Value = serde_json::from_str(&stdout(&output)).unwrap();
    assert_eq!(compared["metric"], metric);
    // Its comparison links to no wear curves.
    assert_eq!(compared["links"]["bands"], Value::Null);
    assert_eq!(
        compared["links"]["weibull"],
        format!("/v1/jobs/{strong}/compare/{weak}/plots/weibull.svg")
    );
    assert!(dir.join("weibull.svg").is_file());
    assert!(!dir.join("bands.svg").exists());
    // Said, not left out in silence.
    let said = String::from_utf8_lossy(&output.stderr);
    assert!(
        said.contains("no bands.svg: eroded_mass_kg is a device metric"),
        "{said}"
    );
    // A comparison that fails takes away the directory it made for its plots.
    let dir = crate::support::temp_dir("compare-failed-plots").join("new");
    let nobody = "00000000-0000-4000-8000-000000000000";
    let args = ["compare", &strong, nobody, "--plots", dir.to_str().unwrap()];
    let failed = remote(&server, None, &args);
    assert_eq!(failed.status.code(), Some(1));
    assert!(!dir.exists(), "{}", dir.display());
    // A flag the server refuses is said as the flag's fault, not a document's (exit 2).
    let refused = remote(
        &server,
        None,
        &["compare", &strong, &weak, "--statistics", "mean,p42"],
    );
    let said = String::from_utf8_lossy(&refused.stderr).into_owned();
    assert_eq!(refused.status.code(), Some(2), "{said}");
    assert!(
        said.contains("`statistics`") && !said.contains("(document)"),
        "{said}"
    );

    // Without failure criteria on a side, no Weibull plot to link to.
    let mut plain = design("plain", 15.0);
    plain.as_object_mut().unwrap().remove("failure");
    let plain = submit(&plain, "compare-c");
    let url = format!("{}/v1/jobs/{strong}/compare/{plain}", server.base());
    let compared = get(&url, None).json();
    assert_eq!(compared["links"]["weibull"], Value::Null, "{compared}");
    assert!(compared["links"]["bands"].is_string(), "{compared}");

    // Refusals name what is wrong.
    let base = format!("{}/v1/jobs/{strong}/compare/{weak}", server.base());
    let problem = assert_problem(&get(&format!("{base}?statistics=mean,median"), None), 400);
    assert!(
        problem["detail"].as_str().unwrap().contains("`statistics`"),
        "{problem}"
    );
    let problem = assert_problem(&get(&format!("{base}?b_lives=1.5"), None), 400);
    assert!(
        problem["detail"].as_str().unwrap().contains("`b_lives`"),
        "{problem}"
    );
    let problem = assert_problem(&get(&format!("{base}?metrc=e1"), None), 400);
    assert!(
        problem["detail"].as_str().unwrap().contains("metrc"),
        "{problem}"
    );
    let problem = assert_problem(&get(&format!("{base}?metric=no_such_metric"), None), 404);
    let detail = problem["detail"].as_str().unwrap();
    assert!(
        detail.contains("no metric `no_such_metric`; known: "),
        "{problem}"
    );
    assert_problem(&get(&format!("{base}/plots/histograms.svg"), None), 404);
    let missing = format!("{}/v1/jobs/{strong}/compare/no-such-job", server.base());
    assert_problem(&get(&missing, None), 404);
}

/// A job that does not exist is 404 whatever the other's status: the first job, still queued,
/// answered 409 and hid that the second never will be there.
#[test]
fn a_comparison_with_no_such_job_is_404_before_the_other_ends() {
    let server = TestApp::start(&temp_db("compare-missing"), &["--workers", "0"]);
    let body = json!({"devices": 2, "operations": 2}).to_string();
    let queued = post(&server.url("/v1/jobs"), &body, None).json()["id"]
        .as_str()
        .unwrap()
        .to_owned();
    let nobody = "00000000-0000-4000-8000-000000000000";
    for (a, b, status) in [
        (&*queued, nobody, 404),
        (nobody, &*queued, 404),
        (&*queued, &*queued, 409),
    ] {
        let url = server.url(&format!("/v1/jobs/{a}/compare/{b}"));
        assert_problem(&get(&url, None), status);
        assert_problem(&get(&format!("{url}/plots/bands.svg"), None), status);
    }
}
