//! `/v1/jobs/{id}/distributions/{metric}?quantiles=&exceedance=`: any quantile and any threshold,
//! answered after the run from the stored groups, with intervals.

use crate::support::app::{Service, TestApp};
use crate::support::client::{assert_problem, get};
use crate::support::{scattered_job, temp_db};
use serde_json::{Value, json};
use std::time::Duration;

fn pair(value: &Value) -> [f64; 2] {
    [value[0].as_f64().unwrap(), value[1].as_f64().unwrap()]
}

#[test]
fn any_quantile_and_threshold_are_answered_after_the_run_with_intervals() {
    let server = TestApp::start(&temp_db("query"), &[]);
    let mut job = scattered_job(64, 40, 5);
    job["limits"]["e1"] = json!([{"above": 0.3}, {"below": 0.3}]);
    let id = server.submit(&job);
    server.wait_for(&id, "succeeded", Duration::from_secs(60));
    let url = |query: &str| server.url(&format!("/v1/jobs/{id}/distributions/e1{query}"));
    let plain = get(&url(""), None).json();
    assert!(
        plain["bins"][0].get("query").is_none(),
        "unchanged without a query"
    );
    let median = plain["bins"][0]["quantiles"]["p50"]["value"]
        .as_f64()
        .unwrap();

    let asked = get(
        &url(&format!(
            "?quantiles=0.5,0.999&exceedance=above:{median},below:{median}"
        )),
        None,
    );
    assert_eq!(asked.status, 200, "{}", asked.body);
    let asked = asked.json();
    let bins = asked["bins"].as_array().unwrap();
    assert_eq!(bins.len(), plain["bins"].as_array().unwrap().len());
    for bin in bins {
        let (min, max) = (bin["min"].as_f64().unwrap(), bin["max"].as_f64().unwrap());
        let query = &bin["query"];
        assert_eq!(
            query["quantiles"]["0.5"], bin["quantiles"]["p50"],
            "level 0.5 is the job's own p50"
        );
        let value = query["quantiles"]["0.5"]["value"].as_f64().unwrap();
        let [lo, hi] = pair(&query["quantiles"]["0.5"]["ci95"]);
        assert!(
            min <= lo && lo <= value && value <= hi && hi <= max,
            "0.5: {query}"
        );
        // 64 devices of 40 operations are at most 2560 values, 2.6 beyond a level of 0.999: the
        // data cannot bound it, and the answer says so instead of ending at the maximum.
        let extreme = &query["quantiles"]["0.999"];
        assert!(
            extreme["value"].is_null() && extreme["ci95"].is_null(),
            "{extreme}"
        );
        assert!(
            extreme["reason"]
                .as_str()
                .unwrap()
                .contains("beyond the data"),
            "{extreme}"
        );
        let exceedance = query["exceedance"].as_array().unwrap();
        assert_eq!(exceedance.len(), 2);
        assert_eq!(exceedance[0]["above"].as_f64(), Some(median));
        assert_eq!(exceedance[1]["below"].as_f64(), Some(median));
        for item in exceedance {
            let probability = item["probability"].as_f64().unwrap();
            let [lo, hi] = pair(&item["ci95"]);
            assert!(
                0.0 <= lo && lo <= probability && probability <= hi && hi <= 1.0,
                "{item}"
            );
        }
        let total = exceedance[0]["probability"].as_f64().unwrap()
            + exceedance[1]["probability"].as_f64().unwrap();
        assert!(total <= 1.0, "above and below the same threshold: {total}");
    }

    // The job's list of limits is answered as the same query answers it.
    let limits = get(&url("?exceedance=above:0.3,below:0.3"), None).json();
    for (bin, stored) in limits["bins"]
        .as_array()
        .unwrap()
        .iter()
        .zip(plain["bins"].as_array().unwrap())
    {
        assert_eq!(bin["query"]["exceedance"], stored["exceedances"]);
    }
    // In CSV, each limit of the list has its columns, with the JSON's numbers.
    let csv = get(&url("?format=csv"), None).body;
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    for (line, bin) in lines.zip(plain["bins"].as_array().unwrap()) {
        let cells: Vec<&str> = line.split(',').collect();
        for (k, name) in ["above:0.3", "below:0.3"].iter().enumerate() {
            let column = |suffix: &str| -> f64 {
                let name = format!("exceedance_{name}{suffix}");
                let at = header.iter().position(|h| *h == name).expect("a column");
                cells[at].parse().unwrap()
            };
            let stored = &bin["exceedances"][k];
            assert_eq!(column(""), stored["probability"]);
            assert_eq!(column("_ci95_lo"), stored["ci95"][0]);
            assert_eq!(column("_ci95_hi"), stored["ci95"][1]);
        }
    }
}

/// In CSV the answers are columns after the others, in the order asked (a level asked twice
/// once), with the numbers of the JSON answer.
#[test]
fn a_query_after_the_run_in_csv_has_a_column_per_answer() {
    let server = TestApp::start(&temp_db("query-csv"), &[]);
    let id = server.submit(&scattered_job(16, 20, 5));
    server.wait_for(&id, "succeeded", Duration::from_secs(60));
    let query = "quantiles=0.999,0.5,0.999&exceedance=above:0.3,below:0.25";
    let url = |format: &str| server.url(&format!("/v1/jobs/{id}/distributions/e1?{query}{format}"));
    let json = get(&url(""), None).json();
    let csv = get(&url("&format=csv"), None);
    assert_eq!(csv.status, 200, "{}", csv.body);
    let mut lines = csv.body.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let asked = [
        "q0.999",
        "q0.999_ci95_lo",
        "q0.999_ci95_hi",
        "q0.5",
        "q0.5_ci95_lo",
        "q0.5_ci95_hi",
        "above:0.3",
        "above:0.3_ci95_lo",
        "above:0.3_ci95_hi",
        "below:0.25",
        "below:0.25_ci95_lo",
        "below:0.25_ci95_hi",
    ];
    assert_eq!(header[header.len() - asked.len()..], asked);
    let bins = json["bins"].as_array().unwrap();
    for (line, bin) in lines.zip(bins) {
        let cells: Vec<f64> = line
            .split(',')
            .map(|c| c.parse().unwrap_or(f64::NAN))
            .collect();
        let answers = &cells[cells.len() - asked.len()..];
        let q = &bin["query"];
        let expected = [
            &q["quantiles"]["0.999"]["value"],
            &q["quantiles"]["0.999"]["ci95"][0],
            &q["quantiles"]["0.999"]["ci95"][1],
            &q["quantiles"]["0.5"]["value"],
            &q["quantiles"]["0.5"]["ci95"][0],
            &q["quantiles"]["0.5"]["ci95"][1],
            &q["exceedance"][0]["probability"],
            &q["exceedance"][0]["ci95"][0],
            &q["exceedance"][0]["ci95"][1],
            &q["exceedance"][1]["probability"],
            &q["exceedance"][1]["ci95"][0],
            &q["exceedance"][1]["ci95"][1],
        ];
        for (got, want) in answers.iter().zip(expected) {
            // A level the data cannot bound has no value: empty cells.
            match want.as_f64() {
                Some(want) => assert_eq!(*got, want, "{line}"),
                None => assert!(want.is_null() && got.is_nan(), "{line}"),
            }
        }
    }
}

#[test]
fn a_bad_query_is_400_naming_its_parameter() {
    let server = TestApp::start(&temp_db("bad-query"), &[]);
    let id = server.submit(&scattered_job(4, 4, 5));
    server.wait_for(&id, "succeeded", Duration::from_secs(60));
    for (query, parameter) in [
        ("quantiles=1", "quantiles"),
        ("quantiles=0.5,,0.9", "quantiles"),
        ("quantiles=NaN", "quantiles"),
        ("exceedance=over:1", "exceedance"),
        ("exceedance=above:1e999", "exceedance"),
    ] {
        let url = server.url(&format!("/v1/jobs/{id}/distributions/e1?{query}"));
        let problem = assert_problem(&get(&url, None), 400);
        let detail = problem["detail"].as_str().unwrap();
        assert!(detail.contains(parameter), "{query}: {detail}");
    }
}
