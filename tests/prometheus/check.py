"""/metrics of a live server, read by Prometheus' own text-format parser (prometheus_client): every
family has HELP and TYPE, request latency is a histogram, and the process and build are described.

    python3 tests/prometheus/check.py http://127.0.0.1:PORT

Submits one small job first, so the job counters exist too.
"""

import json
import sys
import time
import urllib.request

from prometheus_client.parser import text_string_to_metric_families


def fetch(url, body=None):
    request = urllib.request.Request(url, data=body, headers={"content-type": "application/json"})
    with urllib.request.urlopen(request, timeout=30) as response:
        return response.headers.get("content-type", ""), response.read().decode()


def main(base):
    _, job = fetch(f"{base}/v1/jobs", json.dumps({"devices": 2, "operations": 20, "seed": 1}).encode())
    job_id = json.loads(job)["id"]
    for _ in range(300):
        if json.loads(fetch(f"{base}/v1/jobs/{job_id}")[1])["status"] == "succeeded":
            break
        time.sleep(0.1)
    else:
        sys.exit(f"job {job_id} did not succeed")
    fetch(f"{base}/healthz")
    content_type, text = fetch(f"{base}/metrics")
    assert content_type.startswith("text/plain"), content_type

    families = {family.name: family for family in text_string_to_metric_families(text)}
    problems = [
        f"{name}: {what}"
        for name, family in families.items()
        for what, missing in (("no HELP", not family.documentation), ("no TYPE", family.type == "unknown"))
        if missing
    ]
    latency = families.get("bouncewear_http_request_duration_seconds")
    if latency is None or latency.type != "histogram":
        problems.append(f"request latency is {latency and latency.type}, not a histogram")
    elif not any(s.name.endswith("_bucket") and s.labels.get("le") == "+Inf" for s in latency.samples):
        problems.append("request latency has no +Inf bucket")
    for name in [
        "bouncewear_build_info",
        "bouncewear_http_requests",
        "bouncewear_jobs_submitted",
        "bouncewear_jobs_finished",
        "bouncewear_jobs_queued",
        "process_resident_memory_bytes",
        "process_cpu_seconds",
        "process_open_fds",
        "process_start_time_seconds",
    ]:
        if name not in families:
            problems.append(f"{name} is missing")
    if problems:
        sys.exit("/metrics:\n  " + "\n  ".join(problems))
    print(f"/metrics: {len(families)} families, each with HELP and TYPE; latency is a histogram")


if __name__ == "__main__":
    main(sys.argv[1].rstrip("/"))
