//! The OpenAPI document as served: utoipa's, built from the handlers and the types' doc comments,
//! with what its attributes cannot say added here, each part once: a working example of every
//! request body and of every success response (real answers of a server to those requests,
//! `assets/openapi_examples.json`, written by `tools/openapi_examples.py`), the links from a created resource to the operations on it (so a client, or
//! schemathesis' stateful phase, can follow them), the length limit on all text a client sends,
//! and descriptions of the simulation's output types, whose Rust docs are written for the physics.

use bouncewear_model::calibration::{
    FITTED, MAX_OBSERVATIONS, MAX_OPERATION, MAX_PARAMETERS, measured_range,
};
use bouncewear_model::error::MAX_TEXT_CHARS;
use bouncewear_model::montecarlo::distribution::POSITIVE_MEMBERS;
use bouncewear_model::montecarlo::job::{MAX_DEVICES, MAX_OPERATIONS, MAX_THRESHOLDS};
use bouncewear_model::montecarlo::rare::LIFE;
use bouncewear_model::montecarlo::{DeviceMetric, OperationMetric};
use bouncewear_model::scenario::{
    MAX_BOUNCES_LIMIT, MAX_MAGNITUDE, MIN_MAGNITUDE, NUMBER_RULES, Rule,
};
use bouncewear_model::stats::QUANTILES;
use serde_json::{Map, Value, json};
use std::collections::BTreeSet;

/// The document served at `/openapi.json`.
pub fn document(openapi: &utoipa::openapi::OpenApi) -> Value {
    let mut document = serde_json::to_value(openapi).expect("an OpenAPI document serialises");
    add_request_examples(&mut document);
    add_response_examples(&mut document);
    constrain_request_fields(&mut document);
    limit_request_text(&mut document);
    add_links(&mut document);
    declare_resolved_job(&mut document["components"]["schemas"]);
    describe_output_types(&mut document);
    hoist_optional_descriptions(&mut document);
    document
}

/// Example bodies, by operation: each valid, and accepted by a server with the default limits (the
/// OpenAPI check in CI sends every one of them).
fn request_examples() -> [(&'static str, Value); 5] {
    let template = json!({
        "name": "AgNi at 48 V, 15 A",
        "scenario": {"circuit": {"supply_voltage_v": 48, "current_a": 15}},
        "devices": 20,
        "operations": 200,
        "bin_operations": 20,
        "scatter": [{
            "parameter": "contact_radius_m",
            "per": "device",
            "distribution": {"kind": "uniform", "min": 0.0070, "max": 0.0085}
        }, {
            "parameter": "inertia_kg_m2",
            "per": "device",
            "distribution": {"kind": "lognormal", "median": 1.593e-5, "sigma": 0.1, "min": 1.3e-5}
        }],
        "correlation": {
            "parameters": ["contact_radius_m", "inertia_kg_m2"],
            "matrix": [[1, 0.4], [0.4, 1]]
        },
        "failure": {"cumulative_arc_energy_j": {"above": 2.0}}
    });
    let mut job = template.clone();
    job["seed"] = json!(42);
    let schedule = json!({
        "name": "nightly AgNi",
        "cron": "0 3 * * *",
        "time_zone": "Europe/London",
        "template": template,
        "statistics": ["operations.total_bounce_s.p95", "life.b10"]
    });
    let mut paused = schedule.clone();
    paused["enabled"] = json!(false);
    [
        ("submit_job", job),
        ("create_schedule", schedule),
        ("replace_schedule", paused),
        (
            "simulate_operation",
            json!({"circuit": {"supply_voltage_v": 48, "current_a": 15}}),
        ),
        ("create_calibration", calibration_example()),
    ]
}

/// Bounce traces of the paper's rig at three closing velocities (simulated at kappa 0.33 and 2 uJ
/// lost per impact, rounded to three digits as a measurement would be): kappa and the energy lost
/// per impact fitted to them.
pub fn calibration_example() -> Value {
    json!({
        "scenario": {},
        "fit": ["material.kappa", "losses.impact_energy_loss_j"],
        "observations": [
            {"impact_velocity_m_s": 0.2, "first_bounce_s": 0.00896, "second_bounce_s": 0.00515, "total_bounce_s": 0.0188, "bounce_count": 4},
            {"impact_velocity_m_s": 0.3, "first_bounce_s": 0.0116, "second_bounce_s": 0.00657, "total_bounce_s": 0.025, "bounce_count": 5},
            {"impact_velocity_m_s": 0.4, "first_bounce_s": 0.0136, "second_bounce_s": 0.00772, "total_bounce_s": 0.0297, "bounce_count": 5}
        ]
    })
}

fn operations_mut(document: &mut Value) -> impl Iterator<Item = (&String, &mut Value)> {
    document["paths"]
        .as_object_mut()
        .into_iter()
        .flat_map(|paths| paths.iter_mut())
        .flat_map(|(path, item)| {
            item.as_object_mut()
                .into_iter()
                .flat_map(|methods| methods.values_mut())
                .map(move |operation| (path, operation))
        })
}

fn add_request_examples(document: &mut Value) {
    let examples = request_examples();
    for (_, operation) in operations_mut(document) {
        let id = operation["operationId"].as_str().unwrap_or_default();
        if let Some((_, example)) = examples.iter().find(|(name, _)| *name == id)
            && let Some(media) = operation.pointer_mut("/requestBody/content/application~1json")
        {
            media["example"] = example.clone();
        }
    }
}

/// A live server's answers to the request examples, by operation, status and media type:
/// `tools/openapi_examples.py` writes them, `tests/openapi/check.py` validates each against its
/// response's schema.
const RESPONSE_EXAMPLES: &str = include_str!("../../assets/openapi_examples.json");

fn add_response_examples(document: &mut Value) {
    let examples: Value =
        serde_json::from_str(RESPONSE_EXAMPLES).expect("the response examples are JSON");
    for (_, operation) in operations_mut(document) {
        let id = operation["operationId"].as_str().unwrap_or_default();
        let Some(statuses) = examples.get(id).and_then(Value::as_object) else {
            continue;
        };
        for (status, media_types) in statuses {
            for (media, example) in media_types.as_object().into_iter().flatten() {
                let pointer = format!("/responses/{status}/content/{}", media.replace('/', "~1"));
                // A named Example with its `value`, not `example`: RapiDoc (the `/docs` page)
                // reads the members of an `example` object as Examples, and a `null` member
                // (a job's `error`, its `finished_at`) left eight operations without their
                // responses and the page with TypeErrors.
                if let Some(content) = operation.pointer_mut(&pointer) {
                    content["examples"] = json!({"answer": {"value": example}});
                }
            }
        }
    }
}

/// A number rule of docs/model.md section 9 as JSON Schema keywords.
fn range(rule: Rule) -> Value {
    match rule {
        Rule::Positive => json!({"minimum": MIN_MAGNITUDE, "maximum": MAX_MAGNITUDE}),
        Rule::NonNegative => json!({
            "minimum": 0, "maximum": MAX_MAGNITUDE,
            "not": {"type": "number", "exclusiveMinimum": 0, "exclusiveMaximum": MIN_MAGNITUDE}
        }),
        Rule::Finite => json!({"minimum": -MAX_MAGNITUDE, "maximum": MAX_MAGNITUDE}),
    }
}

/// What each field of a request body may hold on its own, as the model's validation has it: the
/// scenario's numbers from the model's own list (`NUMBER_RULES`, which `Scenario::new` applies),
/// the other fields as `Job::new`, `calibrate` and `ValidSchedule::parse` check them. Rules that
/// relate fields to each other (`worn_radius_m` at most `contact_radius_m`, `bin_operations` at
/// most `operations`, a job's size against the server's limit...) are in the descriptions: JSON
/// Schema cannot state them.
fn constrain_request_fields(document: &mut Value) {
    let mut fields: Vec<(&str, &str, Value)> = NUMBER_RULES
        .iter()
        .map(|number| (number.schema, number.field(), range(number.rule)))
        .collect();
    fields.extend(job_fields());
    fields.extend(calibration_fields());
    fields.extend(schedule_fields());
    let schemas = &mut document["components"]["schemas"];
    for (schema, field, rules) in fields {
        let pointer = format!("/{schema}/properties/{field}");
        if let (Some(Value::Object(members)), Value::Object(rules)) =
            (schemas.pointer_mut(&pointer), rules)
        {
            // A rule given as null takes the generated one away.
            members.extend(rules);
            members.retain(|_, rule| !rule.is_null());
        }
    }
    constrain_structure(schemas);
}

/// The operation metrics' names, and every metric's.
fn metric_names() -> (Vec<&'static str>, Vec<&'static str>) {
    let operation_metrics: Vec<&str> = OperationMetric::ALL.iter().map(|m| m.name()).collect();
    let metrics: Vec<&str> = operation_metrics
        .iter()
        .copied()
        .chain(DeviceMetric::ALL.iter().map(|m| m.name()))
        .collect();
    (operation_metrics, metrics)
}

/// A job's fields beyond its scenario's numbers, as `Job::new` checks them.
fn job_fields() -> Vec<(&'static str, &'static str, Value)> {
    let (operation_metrics, metrics) = metric_names();
    let names = json!({"type": "string", "enum": metrics});
    // Not `int64`, which the generated schema says of every whole number: a seed goes beyond it.
    let seed = json!({"minimum": 0, "maximum": u64::MAX, "format": null});
    let statistics: Vec<&str> = std::iter::once("mean")
        .chain(QUANTILES.iter().map(|(name, _)| *name))
        .collect();
    vec![
        // 0, or from the least magnitude to 1, as `Scenario::new` checks it: 1e-169 was
        // schema-valid and refused (schemathesis, another seed).
        (
            "MaterialSpec",
            "anode_erosion_fraction",
            json!({
                "minimum": 0, "maximum": 1,
                "not": {"type": "number", "exclusiveMinimum": 0, "exclusiveMaximum": MIN_MAGNITUDE}
            }),
        ),
        (
            "LossesSpec",
            "max_bounces",
            json!({"minimum": 1, "maximum": MAX_BOUNCES_LIMIT}),
        ),
        (
            "JobSpec",
            "bin_operations",
            json!({"minimum": 1, "maximum": MAX_OPERATIONS}),
        ),
        ("JobSpec", "seed", seed.clone()),
        // The seed a job runs with, as its resource tells it.
        ("JobResource", "seed", seed),
        (
            "JobSpec",
            "metrics",
            json!({"minItems": 1, "uniqueItems": true, "items": names}),
        ),
        ("JobSpec", "limits", json!({"propertyNames": names})),
        (
            "JobSpec",
            "failure",
            json!({"propertyNames": names, "minProperties": 1}),
        ),
        (
            "PrecisionSpec",
            "metric",
            json!({"enum": operation_metrics}),
        ),
        (
            "RareEventSpec",
            "metric",
            json!({"enum": metrics.iter().copied().chain([LIFE]).collect::<Vec<_>>()}),
        ),
        (
            "RareEventSpec",
            "operation",
            json!({"minimum": 1, "maximum": MAX_OPERATIONS}),
        ),
        (
            "RareEventSpec",
            "target_cov",
            json!({"exclusiveMinimum": 0, "maximum": 1}),
        ),
        ("PrecisionSpec", "statistic", json!({"enum": statistics})),
        (
            "PrecisionSpec",
            "relative_half_width",
            json!({"exclusiveMinimum": 0, "exclusiveMaximum": 1}),
        ),
        (
            "PrecisionSpec",
            "max_devices",
            json!({"minimum": 1, "maximum": MAX_DEVICES}),
        ),
        (
            "CorrelationSpec",
            "parameters",
            json!({"minItems": 2, "uniqueItems": true}),
        ),
        (
            "CorrelationSpec",
            "matrix",
            json!({"minItems": 2, "items": {"type": "array",
                   "items": {"type": "number", "minimum": -1, "maximum": 1}}}),
        ),
    ]
}

/// A calibration's fields, as `calibrate` checks them.
fn calibration_fields() -> Vec<(&'static str, &'static str, Value)> {
    let mut fields = vec![
        (
            "CalibrationSpec",
            "fit",
            json!({"minItems": 1, "maxItems": MAX_PARAMETERS, "uniqueItems": true}),
        ),
        (
            "CalibrationSpec",
            "observations",
            json!({"minItems": 1, "maxItems": MAX_OBSERVATIONS}),
        ),
        (
            "Observation",
            "impact_velocity_m_s",
            range(Rule::NonNegative),
        ),
        (
            "CalibrationSpec",
            "bounds",
            json!({"additionalProperties": {
                "type": "array", "minItems": 2, "maxItems": 2,
                "items": {"type": "number", "exclusiveMinimum": 0}
            }}),
        ),
        (
            "Observation",
            "operation",
            json!({"minimum": 0, "maximum": MAX_OPERATION}),
        ),
    ];
    // A measured quantity is a positive number within a scenario's magnitudes (`e1` at most 1).
    fields.extend(FITTED.map(|field| {
        let [least, most] = measured_range(field);
        (
            "Observation",
            field,
            json!({"minimum": least, "maximum": most}),
        )
    }));
    fields
}

/// A schedule's fields, as `ValidSchedule::parse` checks them.
fn schedule_fields() -> Vec<(&'static str, &'static str, Value)> {
    let (operation_metrics, metrics) = metric_names();
    let device_metrics = &metrics[operation_metrics.len()..];
    let quantiles: Vec<&str> = QUANTILES.iter().map(|(name, _)| *name).collect();
    let statistic = format!(
        "^((operations\\.({})|devices\\.({}))\\.(mean|{})|life\\.(b1|b10|beta|eta))$",
        operation_metrics.join("|"),
        device_metrics.join("|"),
        quantiles.join("|")
    );
    let mut time_zones: Vec<Value> = chrono_tz::TZ_VARIANTS
        .iter()
        .map(|tz| json!(tz.name()))
        .collect();
    time_zones.push(Value::Null);
    vec![
        // Not only white space, and (one pattern for both) no U+0000: `\S` alone left the name
        // of NUL and a letter schema-valid, and refused (schemathesis, stateful).
        (
            "ScheduleSpec",
            "name",
            json!({"pattern": "^[^\\u0000]*[^\\s\\u0000][^\\u0000]*$"}),
        ),
        ("ScheduleSpec", "time_zone", json!({"enum": time_zones})),
        (
            "ScheduleSpec",
            "statistics",
            json!({"minItems": 1, "uniqueItems": true, "items": {"type": "string", "pattern": statistic}}),
        ),
    ]
}

/// The rules of a schema's shape rather than one field's: a mechanism that can return the arm, a
/// distribution's members, a list of limits and its thresholds' sides.
fn constrain_structure(schemas: &mut Value) {
    // Without a spring, a static force of 0 would never return the arm.
    if let Some(Value::Object(mechanism)) = schemas.get_mut("MechanismSpec") {
        mechanism.insert(
            "not".to_owned(),
            json!({
                "required": ["static_force_n", "spring_stiffness_n_per_m"],
                "properties": {"static_force_n": {"const": 0}, "spring_stiffness_n_per_m": {"const": 0}}
            }),
        );
    }
    // A list of limits holds 1 to 20 thresholds, each exactly one of `above` or `below`; in an
    // answer (ThresholdExceedance) a threshold's probability and interval sit beside it.
    if let (Some(sides), Some(answer)) = (
        schemas.get("Threshold").cloned(),
        schemas.pointer_mut("/ThresholdExceedance/allOf/0"),
    ) {
        *answer = sides;
    }
    if let Some(Value::Object(list)) = schemas.pointer_mut("/LimitSpec/oneOf/1") {
        list.extend([
            ("minItems".to_owned(), json!(1)),
            ("maxItems".to_owned(), json!(MAX_THRESHOLDS)),
            // None listed twice (`job::check_written`): JSON Schema's equality is the rule's.
            ("uniqueItems".to_owned(), json!(true)),
        ]);
    }
    // A distribution's kind has only its own members, and those the model holds positive
    // whatever the parameter are so here too.
    for kind in variants(schemas, "DistributionSpec") {
        kind["additionalProperties"] = json!(false);
        for member in POSITIVE_MEMBERS {
            if let Some(Value::Object(rules)) = kind.pointer_mut(&format!("/properties/{member}")) {
                rules.insert("exclusiveMinimum".to_owned(), json!(0));
            }
        }
    }
    for side in variants(schemas, "Threshold") {
        side["additionalProperties"] = json!(false);
    }
}

/// The schemas of the variants (`oneOf`) of the schema `name`.
fn variants<'a>(schemas: &'a mut Value, name: &str) -> impl Iterator<Item = &'a mut Value> {
    (schemas.get_mut(name))
        .and_then(|schema| schema.get_mut("oneOf"))
        .and_then(Value::as_array_mut)
        .into_iter()
        .flatten()
}

/// `maxLength` and no U+0000 on every string a request body may hold, and on the names of its
/// maps' members: the rules `bouncewear_model::error::from_json` enforces on every document; no
/// U+0000 in a path's parameters, as `api::Path` refuses it.
fn limit_request_text(document: &mut Value) {
    for (_, operation) in operations_mut(document) {
        let parameters = operation
            .get_mut("parameters")
            .and_then(Value::as_array_mut);
        for parameter in parameters.into_iter().flatten() {
            let in_path = parameter["in"] == "path";
            let schema = &mut parameter["schema"];
            if in_path && schema["type"] == "string" && schema.get("pattern").is_none() {
                schema["pattern"] = json!(NO_NUL_PATTERN);
            }
        }
    }
    let mut names = BTreeSet::new();
    let bodies: Vec<Value> = operations_mut(document)
        .filter_map(|(_, operation)| {
            operation
                .pointer("/requestBody/content/application~1json/schema")
                .cloned()
        })
        .collect();
    let schemas = document["components"]["schemas"].clone();
    for body in &bodies {
        collect_refs(body, &schemas, &mut names);
    }
    for name in names {
        if let Some(schema) = document["components"]["schemas"].get_mut(&name) {
            limit_text(schema);
        }
    }
}

/// The names of the component schemas `schema` refers to, directly or through others.
fn collect_refs(schema: &Value, schemas: &Value, names: &mut BTreeSet<String>) {
    match schema {
        Value::Object(members) => {
            if let Some(name) = members
                .get("$ref")
                .and_then(Value::as_str)
                .and_then(|r| r.strip_prefix("#/components/schemas/"))
                && names.insert(name.to_owned())
            {
                collect_refs(&schemas[name], schemas, names);
            }
            members
                .values()
                .for_each(|member| collect_refs(member, schemas, names));
        }
        Value::Array(items) => items
            .iter()
            .for_each(|item| collect_refs(item, schemas, names)),
        _ => {}
    }
}

/// Text holding no U+0000 ([`bouncewear_model::error::NO_NUL`]), as a JSON Schema pattern.
const NO_NUL_PATTERN: &str = "^[^\\u0000]*$";

fn limit_text(schema: &mut Value) {
    let Value::Object(members) = schema else {
        return;
    };
    let is_string = match members.get("type") {
        Some(Value::String(kind)) => kind == "string",
        Some(Value::Array(kinds)) => kinds.iter().any(|k| k == "string"),
        _ => false,
    };
    if is_string && !members.contains_key("enum") && !members.contains_key("maxLength") {
        members.insert("maxLength".to_owned(), json!(MAX_TEXT_CHARS));
    }
    if is_string && !members.contains_key("enum") && !members.contains_key("pattern") {
        members.insert("pattern".to_owned(), json!(NO_NUL_PATTERN));
    }
    if members.contains_key("additionalProperties") {
        let names = members
            .entry("propertyNames")
            .or_insert_with(|| json!({"type": "string"}));
        names["maxLength"] = json!(MAX_TEXT_CHARS);
        names["pattern"] = json!(NO_NUL_PATTERN);
    }
    for (name, member) in members.iter_mut() {
        match name.as_str() {
            "properties" => member
                .as_object_mut()
                .into_iter()
                .flat_map(Map::values_mut)
                .for_each(limit_text),
            "items" | "additionalProperties" => limit_text(member),
            "oneOf" | "anyOf" | "allOf" => member
                .as_array_mut()
                .into_iter()
                .flatten()
                .for_each(limit_text),
            _ => {}
        }
    }
}

/// From the response that creates a job (or a schedule) to every operation on `/v1/jobs/{id}...`
/// (or `/v1/schedules/{id}...`), with the new resource's `id`.
fn add_links(document: &mut Value) {
    let targets = |prefix: &str, document: &Value| -> Map<String, Value> {
        let mut links = Map::new();
        for (path, item) in document["paths"].as_object().into_iter().flatten() {
            if !path.starts_with(prefix) {
                continue;
            }
            for operation in item.as_object().into_iter().flat_map(Map::values) {
                let Some(id) = operation["operationId"].as_str() else {
                    continue;
                };
                links.insert(
                    id.to_owned(),
                    json!({
                        "operationId": id,
                        "parameters": {"id": "$response.body#/id"},
                        "description": format!("`{id}` on the resource this response created"),
                    }),
                );
            }
        }
        links
    };
    let job_links = targets("/v1/jobs/{id}", document);
    let schedule_links = targets("/v1/schedules/{id}", document);
    for (_, operation) in operations_mut(document) {
        let (status, links) = match operation["operationId"].as_str() {
            Some("submit_job" | "run_schedule_now") => ("202", &job_links),
            Some("create_schedule") => ("201", &schedule_links),
            _ => continue,
        };
        if let Some(response) = operation["responses"].get_mut(status) {
            response["links"] = Value::Object(links.clone());
        }
    }
}

/// Descriptions of the properties of the `simulate` output and of a metric's summary, by schema.
const OUTPUT_DESCRIPTIONS: &[(&str, &[(&str, &str)])] = &[
    (
        "Outcome",
        &[
            (
                "impact_velocity_m_s",
                "Closing velocity of the moving contact at first impact, m/s (eq. 2, or the scenario's override)",
            ),
            (
                "first_bounce_s",
                "Duration of the first bounce (the first flight after a separation), s",
            ),
            (
                "total_bounce_s",
                "Time from first impact until the contacts stay closed, s",
            ),
            (
                "bounce_count",
                "Bounces (separations) before the contacts stay closed",
            ),
            (
                "pre_arc_s",
                "Duration of the pre-arc before first touch, s (0 when the circuit cannot arc)",
            ),
            (
                "arc_energy_j",
                "Arc energy over the operation (pre-arc and every bounce), J",
            ),
            (
                "peak_force_n",
                "Peak contact force of the first impact, N (eq. 12)",
            ),
            (
                "impact_duration_s",
                "Duration of the first impact, s (eq. 13)",
            ),
        ],
    ),
    (
        "Bounce",
        &[
            (
                "separation_velocity_m_s",
                "Velocity at which the contacts part at the start of this bounce, m/s",
            ),
            ("duration_s", "Time the contacts are apart, s"),
            ("peak_gap_m", "Largest gap between the contacts, m (eq. 4)"),
            ("arc_energy_j", "Arc energy during this bounce, J"),
        ],
    ),
    (
        "Simulation",
        &[("bounces", "Every bounce in order, the first first")],
    ),
    (
        "Summary",
        &[
            ("n", "Values summarised"),
            ("mean", "Mean of the values"),
            (
                "mean_ci95",
                "95 % confidence interval of the mean, [low, high]",
            ),
            ("min", "Smallest value (exact)"),
            ("max", "Largest value (exact)"),
            (
                "histogram",
                "Up to 20 equal-width bins over [min, max], none narrower than a sketch bucket, \
                 counts summing to n",
            ),
            (
                "exceedance",
                "Probability of exceeding the job's limit for the metric; only with a limit",
            ),
        ],
    ),
    (
        "DistributionBin",
        &[(
            "query",
            "With `quantiles` or `exceedance`: their answers for this bin, with 95 % intervals",
        )],
    ),
    (
        "QuantileSummary",
        &[
            ("value", "The quantile (within 0.2 %)"),
            (
                "ci95",
                "95 % confidence interval of the quantile, [low, high]",
            ),
            (
                "reason",
                "Present when the data cannot bound the level: why, and how many devices would",
            ),
        ],
    ),
    (
        "QueryQuantile",
        &[
            (
                "value",
                "The quantile (within 0.2 %); null when the data cannot bound the level",
            ),
            (
                "ci95",
                "95 % confidence interval of the quantile, [low, high]; null with the value",
            ),
            ("reason", "Why there is no value, and what would give one"),
        ],
    ),
    (
        "ThresholdExceedance",
        &[
            (
                "probability",
                "Share of values strictly beyond the threshold",
            ),
            (
                "ci95",
                "95 % confidence interval of the probability, [low, high]",
            ),
            (
                "resolution",
                "exact: every value compared with the threshold (counted as the job ran, from the extreme values each group keeps, or no value shares its bucket); bucket: some share its sketch bucket, and the interval holds the truth whatever they are",
            ),
            (
                "bucket",
                "Bucket-limited only: the value range [low, high] of the bucket holding the threshold",
            ),
        ],
    ),
    (
        "Exceedance",
        &[
            ("limit", "The job's limit for the metric"),
            ("probability", "Share of values strictly above the limit"),
            (
                "ci95",
                "95 % confidence interval of the probability, [low, high]",
            ),
        ],
    ),
    (
        "Histogram",
        &[
            (
                "edges",
                "Bin edges, one more than the bins: bin i is [edges[i], edges[i + 1]), the last closed",
            ),
            ("counts", "Values in each bin"),
        ],
    ),
];

/// The members every job as it ran has (docs/contract.md "Result": the contract's, and the
/// `metrics` the implementation records).
const RESOLVED_JOB_MEMBERS: [&str; 8] = [
    "seed",
    "devices",
    "operations",
    "bin_operations",
    "fidelity",
    "sampler",
    "scenario",
    "metrics",
];

/// A Result's `job` and a job's `spec` are a JobSpec with every default filled in: declared once,
/// as `JobSpecAsRun`, with JobSpec's members and their rules, requiring those every job as it ran
/// has. It cannot be JobSpec, which admits no other members (the Result's `job` has its own).
fn declare_resolved_job(schemas: &mut Value) {
    let Some(mut spec) = schemas.get("JobSpec").cloned() else {
        return;
    };
    let Some(members) = spec.as_object_mut() else {
        return;
    };
    members.remove("additionalProperties");
    members.insert("required".to_owned(), json!(RESOLVED_JOB_MEMBERS));
    members.insert(
        "description".to_owned(),
        json!(
            "The JobSpec with every default filled in: its seed, `bin_operations`, the whole \
             scenario and the list of metrics."
        ),
    );
    schemas["JobSpecAsRun"] = spec;
    let as_run = json!({"$ref": "#/components/schemas/JobSpecAsRun"});
    if let Some(part) = schemas.pointer_mut("/ResolvedJob/allOf/0") {
        *part = as_run.clone();
    }
    if let Some(Value::Object(spec)) = schemas.pointer_mut("/JobResource/properties/spec") {
        spec.remove("type");
        spec.insert("oneOf".to_owned(), json!([as_run, {"type": "null"}]));
    }
}

fn describe_output_types(document: &mut Value) {
    let schemas = &mut document["components"]["schemas"];
    for (schema, properties) in OUTPUT_DESCRIPTIONS {
        for (property, description) in *properties {
            if let Some(schema) = schemas.get_mut(*schema) {
                describe(schema, property, description);
            }
        }
    }
    // A distribution's tag, in each of its kinds.
    for kind in variants(schemas, "DistributionSpec") {
        describe(kind, "kind", "Which distribution; its parameters follow");
    }
}

/// Describes `property` of `schema`, or of the part of it (`allOf`) that has the property.
fn describe(schema: &mut Value, property: &str, description: &str) {
    let pointer = format!("/properties/{property}");
    let target = if schema.pointer(&pointer).is_some() {
        schema.pointer_mut(&pointer)
    } else {
        schema
            .get_mut("allOf")
            .and_then(Value::as_array_mut)
            .into_iter()
            .flatten()
            .find_map(|part| part.pointer_mut(&pointer))
    };
    if let Some(Value::Object(members)) = target {
        members
            .entry("description")
            .or_insert_with(|| json!(description));
    }
}

/// utoipa writes an optional reference's doc comment on the reference inside its `oneOf`, where
/// a reader (or the docs UI) does not look: it goes on the property itself.
fn hoist_optional_descriptions(document: &mut Value) {
    let schemas = document["components"]["schemas"].as_object_mut();
    for schema in schemas.into_iter().flat_map(Map::values_mut) {
        let properties = schema.get_mut("properties").and_then(Value::as_object_mut);
        for property in properties.into_iter().flat_map(Map::values_mut) {
            let description = property["oneOf"]
                .as_array()
                .into_iter()
                .flatten()
                .find_map(|part| part.get("description").cloned());
            if let (Some(description), Value::Object(members)) = (description, property) {
                members.entry("description").or_insert(description);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn strings_and_member_names_get_the_length_limit_and_enums_keep_theirs() {
        let mut schema = json!({
            "type": "object",
            "properties": {
                "name": {"type": ["string", "null"]},
                "law": {"type": "string", "enum": ["paper"]},
                "limits": {"type": "object", "additionalProperties": {"type": "number"}},
                "metrics": {"type": "array", "items": {"type": "string"}}
            }
        });
        limit_text(&mut schema);
        let properties = &schema["properties"];
        assert_eq!(properties["name"]["maxLength"], MAX_TEXT_CHARS);
        assert_eq!(properties["name"]["pattern"], NO_NUL_PATTERN);
        assert_eq!(
            properties["limits"]["propertyNames"]["pattern"],
            NO_NUL_PATTERN
        );
        assert!(properties["law"].get("maxLength").is_none());
        assert_eq!(
            properties["limits"]["propertyNames"]["maxLength"],
            MAX_TEXT_CHARS
        );
        assert_eq!(properties["metrics"]["items"]["maxLength"], MAX_TEXT_CHARS);
    }
}
