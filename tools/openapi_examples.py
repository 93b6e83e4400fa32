#!/usr/bin/env python3
"""The success examples of the OpenAPI document: real answers of a live server to the document's
own request examples, written to `service/assets/openapi_examples.json`, which
`service/src/api/openapi.rs` puts under each operation's 2xx response (and `tests/openapi/check.py`
validates against the response schemas).

    target/debug/bouncewear serve --bind 127.0.0.1:18931 --database sqlite:///tmp/x.sqlite &
    python3 tools/openapi_examples.py http://127.0.0.1:18931

The server must be fresh (its listings become the examples) and use the default limits. Every call
is one a user would make: the documented job submitted, waited for and read (its result, a
distribution, its life, shards, plots are SVG and not examples); a second design compared with it;
a rare-event job; the documented schedule created, replaced, run; a calibration and a simulated
operation. Arrays longer than three items keep their first three and a Result keeps two metrics
of each kind (an example is read, not computed with); numbers keep their value. Text answers (CSV, the event stream, metrics) keep
their first lines.
"""
import copy
import http.client
import json
import os
import sys
import threading
import urllib.parse
import urllib.request
import xml.etree.ElementTree as ElementTree

OUTPUT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "service", "assets",
                      "openapi_examples.json")
KEEP = 3
TEXT_LINES = 6


def call(base, method, path, body=None, accept="application/json"):
    data = None if body is None else json.dumps(body).encode()
    request = urllib.request.Request(base + path, data=data, method=method)
    request.add_header("Accept", accept)
    if data is not None:
        request.add_header("Content-Type", "application/json")
    with urllib.request.urlopen(request, timeout=120) as response:
        text = response.read().decode()
        return response.status, text


def trim(value):
    if isinstance(value, dict):
        # A Result's metrics (maps by name): two of each kind show the shape.
        return {k: trim(dict(list(v.items())[:2]) if k in ("operations", "devices") and isinstance(v, dict) else v)
                for k, v in value.items()}
    if isinstance(value, list):
        return [trim(v) for v in value[:KEEP]]
    return value


def svg_head(text):
    """The drawing's first elements, closed: its size, title and frame show what the plot is."""
    lines = text.splitlines()
    for keep in range(min(len(lines) - 1, 8), 0, -1):
        head = "\n".join(lines[:keep] + ["</svg>"]) + "\n"
        try:
            ElementTree.fromstring(head)
            return head
        except ElementTree.ParseError:
            continue
    raise ValueError("no well-formed head")


def first_events(base, then):
    """The first events of `/v1/events` while `then()` submits a job, up to its `status` event."""
    url = urllib.parse.urlparse(base)
    connection = http.client.HTTPConnection(url.hostname, url.port, timeout=60)
    connection.request("GET", "/v1/events", headers={"Accept": "text/event-stream"})
    response = connection.getresponse()
    assert response.status == 200, response.status
    threading.Timer(0.5, then).start()
    lines = []
    # Up to the end of the first job's `status` event.
    while not ("event: status" in lines and lines[-1] == ""):
        lines.append(response.readline().decode().rstrip("\n"))
    connection.close()
    return "\n".join(lines) + "\n"


def request_example(document, operation_id):
    for item in document["paths"].values():
        for operation in item.values():
            if operation.get("operationId") == operation_id:
                return copy.deepcopy(operation["requestBody"]["content"]["application/json"]["example"])
    raise KeyError(operation_id)


def main():
    base = sys.argv[1].rstrip("/")
    examples = {}

    def record(operation_id, status, media, value):
        examples.setdefault(operation_id, {}).setdefault(str(status), {})[media] = value

    def json_call(operation_id, method, path, body=None, want=200, example=True):
        status, text = call(base, method, path, body)
        assert status == want, f"{operation_id}: {status} {text[:300]}"
        value = json.loads(text)
        if example:
            record(operation_id, status, "application/json", trim(value))
        return value

    def submit(job):
        return json_call("submit_job", "POST", "/v1/jobs", job, want=202, example=False)["id"]

    def text_call(operation_id, path, media, method="GET", body=None):
        status, text = call(base, method, path, body, accept=media)
        assert status == 200, f"{operation_id}: {status}"
        if media == "image/svg+xml":
            record(operation_id, 200, media, svg_head(text))
        else:
            record(operation_id, 200, media, "\n".join(text.splitlines()[:TEXT_LINES]) + "\n")

    document = json.loads(call(base, "GET", "/openapi.json")[1])
    json_call("healthz", "GET", "/healthz")
    json_call("readyz", "GET", "/readyz")

    job = request_example(document, "submit_job")
    submitted = json_call("submit_job", "POST", "/v1/jobs", job, want=202)
    job_id = submitted["id"]
    # Its events while it runs, then the job once it has ended.
    _, stream = call(base, "GET", f"/v1/jobs/{job_id}/events", accept="text/event-stream")
    record("job_events", 200, "text/event-stream",
           "\n".join(stream.splitlines()[:2 * TEXT_LINES]) + "\n")
    json_call("get_job", "GET", f"/v1/jobs/{job_id}")
    json_call("get_result", "GET", f"/v1/jobs/{job_id}/result")
    json_call("get_distribution", "GET", f"/v1/jobs/{job_id}/distributions/total_bounce_s")
    text_call("get_distribution", f"/v1/jobs/{job_id}/distributions/total_bounce_s?format=csv", "text/csv")
    json_call("get_shards", "GET", f"/v1/jobs/{job_id}/shards")

    # Two designs with a failure criterion (the manual's wear job, and one with larger contacts):
    # the life analysis of the first, and the two compared.
    wear = {"name": "7.7 mm contacts, 2 ug worn away", "devices": 300, "operations": 1000, "seed": 1,
            "scenario": {"circuit": {"supply_voltage_v": 48, "current_a": 15}},
            "scatter": [{"parameter": "contact_radius_m", "per": "device",
                         "distribution": {"kind": "normal", "mean": 7.7e-3, "sd": 0.8e-3, "min": 1e-3}}],
            "failure": {"eroded_mass_kg": {"above": 2e-6}}}
    larger = copy.deepcopy(wear)
    larger["name"] = "8.5 mm contacts, 2 ug worn away"
    larger["scatter"][0]["distribution"]["mean"] = 8.5e-3
    wear_id = submit(wear)
    larger_id = submit(larger)
    for id in (wear_id, larger_id):
        call(base, "GET", f"/v1/jobs/{id}/events", accept="text/event-stream")
    json_call("get_life", "GET", f"/v1/jobs/{wear_id}/life")
    text_call("get_life", f"/v1/jobs/{wear_id}/life?format=csv", "text/csv")
    json_call("get_comparison", "GET", f"/v1/jobs/{larger_id}/compare/{wear_id}")
    text_call("job_plot", f"/v1/jobs/{wear_id}/plots/weibull.svg", "image/svg+xml")
    text_call("comparison_plot", f"/v1/jobs/{larger_id}/compare/{wear_id}/plots/weibull.svg", "image/svg+xml")

    # A rare event: total bounce time above 14.755 ms at the first operation.
    rare = {"name": "P(total bounce > 14.755 ms)", "devices": 100, "operations": 1, "seed": 7,
            "scenario": {"circuit": {"supply_voltage_v": 48, "current_a": 15}},
            "scatter": [{"parameter": "impact_velocity_m_s", "per": "operation",
                         "distribution": {"kind": "normal", "mean": 0.224, "sd": 0.02, "min": 0.05}}],
            "rare_event": {"metric": "total_bounce_s", "above": 0.014755, "operation": 1,
                           "method": "subset", "target_cov": 0.3, "max_evaluations": 20000}}
    rare_id = submit(rare)
    call(base, "GET", f"/v1/jobs/{rare_id}/events", accept="text/event-stream")
    json_call("get_rare_event", "GET", f"/v1/jobs/{rare_id}/rare_event")
    text_call("get_rare_event", f"/v1/jobs/{rare_id}/rare_event?format=csv", "text/csv")

    # A job cancelled while it waits or runs.
    long = submit({"devices": 1000, "operations": 20000, "seed": 7})
    json_call("cancel_job", "DELETE", f"/v1/jobs/{long}")
    # The same with the request that never deletes.
    other = submit({"devices": 1000, "operations": 20000, "seed": 8})
    json_call("cancel_only", "POST", f"/v1/jobs/{other}/cancel")
    json_call("list_jobs", "GET", "/v1/jobs?limit=3")

    schedule = json_call("create_schedule", "POST", "/v1/schedules",
                         request_example(document, "create_schedule"), want=201)
    schedule_id = schedule["id"]
    json_call("get_schedule", "GET", f"/v1/schedules/{schedule_id}")
    json_call("replace_schedule", "PUT", f"/v1/schedules/{schedule_id}",
              request_example(document, "replace_schedule"))
    run = json_call("run_schedule_now", "POST", f"/v1/schedules/{schedule_id}/run", want=202)
    call(base, "GET", f"/v1/jobs/{run['id']}/events", accept="text/event-stream")
    json_call("schedule_runs", "GET", f"/v1/schedules/{schedule_id}/runs")
    text_call("schedule_trend_plot", f"/v1/schedules/{schedule_id}/plots/trend.svg", "image/svg+xml")
    json_call("list_schedules", "GET", "/v1/schedules")

    calibration = request_example(document, "create_calibration")
    json_call("create_calibration", "POST", "/v1/calibrations", calibration)
    text_call("create_calibration", "/v1/calibrations?format=svg", "image/svg+xml", "POST", calibration)
    record("events", 200, "text/event-stream",
           first_events(base, lambda: submit({"devices": 10, "operations": 10, "seed": 1})))
    json_call("simulate_operation", "POST", "/v1/simulate", request_example(document, "simulate_operation"))
    text_call("prometheus_metrics", "/metrics", "text/plain")

    text = json.dumps(examples, indent=1, sort_keys=True) + "\n"
    with open(OUTPUT, "w") as f:
        f.write(text)
    print(f"{OUTPUT}: {sum(len(m) for s in examples.values() for m in s.values())} examples, {len(text)} bytes")


if __name__ == "__main__":
    main()
