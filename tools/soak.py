#!/usr/bin/env python3
"""Soak benchmark of `bouncewear serve` under mixed load (standard library only; not a test).

    cargo build --release
    python3 tools/soak.py [--minutes 10] [--binary target/release/bouncewear]

Starts a release server on a fresh SQLite database in a temporary directory, then for the given
time runs, all at once:

- submitters: small jobs (50 devices x 200 operations, a failure criterion), a few per second,
  some with an Idempotency-Key sent twice;
- readers: GET of job resources, listings, results, a distribution as CSV and the life CSV of
  finished jobs;
- event listeners: `GET /v1/events`, each held open for 5-20 s, then reopened;
- a large job at the start and every 3 minutes: 200,000 devices x 50 operations with 50 bins, all
  operation metrics and a failure criterion (a result with 100,000 listed lives to store);
- a flood of requests with made-up methods and paths (the metrics' labels must stay bounded).

Reports, per kind of request, count, p50 / p99 / max latency and answers by status; the server's
peak RSS (VmHWM) and the database's size (with its WAL) at the end; whether `/metrics` stayed small.
Any 5xx other than a 503 with Retry-After is an error.
"""
import argparse
import http.client
import json
import os
import random
import re
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from collections import defaultdict


class Stats:
    def __init__(self):
        self.lock = threading.Lock()
        self.latency = defaultdict(list)
        self.status = defaultdict(lambda: defaultdict(int))

    def record(self, kind, seconds, status):
        with self.lock:
            self.latency[kind].append(seconds)
            self.status[kind][status] += 1


def quantile(values, q):
    values = sorted(values)
    return values[min(len(values) - 1, int(q * len(values)))] if values else float("nan")


class Client:
    def __init__(self, host, port, stats):
        self.host, self.port, self.stats = host, port, stats
        self.conn = None

    def call(self, kind, method, path, body=None, headers=None, read=True):
        headers = dict(headers or {})
        data = None
        if body is not None:
            data = json.dumps(body)
            headers["content-type"] = "application/json"
        started = time.perf_counter()
        # A kept-alive connection idle past the server's header timeout is closed by the server
        # (as documented); one such stale connection is reopened once, like any HTTP client does.
        for attempt in range(2):
            reused = self.conn is not None
            try:
                if self.conn is None:
                    self.conn = http.client.HTTPConnection(self.host, self.port, timeout=120)
                self.conn.request(method, path, body=data, headers=headers)
                response = self.conn.getresponse()
                payload = response.read() if read else b""
                status = response.status
                if response.getheader("connection", "").lower() == "close":
                    self.conn.close()
                    self.conn = None
                break
            except (OSError, http.client.HTTPException) as error:
                self.conn = None
                payload, status = str(error).encode(), f"error: {type(error).__name__}"
                if not (reused and attempt == 0):
                    break
        self.stats.record(kind, time.perf_counter() - started, status)
        return status, payload


def small_job(seed):
    return {"devices": 50, "operations": 200, "seed": seed,
            "scenario": {"circuit": {"supply_voltage_v": 48, "current_a": 15}},
            "failure": {"e1": {"below": 0.36}}}


def large_job(seed):
    return {"devices": 200_000, "operations": 50, "bin_operations": 1, "seed": seed,
            "scenario": {"circuit": {"supply_voltage_v": 48, "current_a": 15}},
            "failure": {"e1": {"below": 0.4}}}


def submitter(client, stop, finished, rng):
    seed = 0
    while not stop.is_set():
        seed += 1
        key = {"idempotency-key": f"soak-{id(client)}-{seed}"} if seed % 5 == 0 else None
        for _ in range(2 if key else 1):
            status, body = client.call("POST /v1/jobs", "POST", "/v1/jobs", small_job(seed), key)
        if status == 202:
            finished.append(json.loads(body)["id"])
        time.sleep(rng.uniform(0.2, 0.6))


def reader(client, stop, finished, rng):
    while not stop.is_set():
        if not finished:
            time.sleep(0.2)
            continue
        job = rng.choice(finished[-200:])
        kind = rng.random()
        if kind < 0.4:
            client.call("GET /v1/jobs/{id}", "GET", f"/v1/jobs/{job}")
        elif kind < 0.55:
            client.call("GET /v1/jobs", "GET", "/v1/jobs?limit=50")
        elif kind < 0.75:
            client.call("GET result", "GET", f"/v1/jobs/{job}/result")
        elif kind < 0.9:
            client.call("GET distribution csv", "GET", f"/v1/jobs/{job}/distributions/e1?format=csv")
        else:
            client.call("GET life csv", "GET", f"/v1/jobs/{job}/life?format=csv")
        time.sleep(rng.uniform(0.01, 0.05))


def listener(host, port, stats, stop, rng):
    while not stop.is_set():
        started = time.perf_counter()
        try:
            conn = http.client.HTTPConnection(host, port, timeout=30)
            conn.request("GET", "/v1/events", headers={"accept": "text/event-stream"})
            response = conn.getresponse()
            stats.record("GET /v1/events (open)", time.perf_counter() - started, response.status)
            until = time.perf_counter() + rng.uniform(5, 20)
            while time.perf_counter() < until and not stop.is_set():
                if not response.fp.readline():
                    break
            conn.close()
        except (OSError, http.client.HTTPException) as error:
            stats.record("GET /v1/events (open)", time.perf_counter() - started,
                         f"error: {type(error).__name__}")
            time.sleep(1)


def large_jobs(client, stop, large, seconds_apart=180):
    seed = 0
    while not stop.is_set():
        seed += 1
        status, body = client.call("POST large job", "POST", "/v1/jobs", large_job(seed))
        if status == 202:
            large.append(json.loads(body)["id"])
        stop.wait(seconds_apart)


def flood(client, stop, rng):
    while not stop.is_set():
        method = "".join(rng.choice("ABCDEFGHIJKLMNOPQRSTUVWXYZ") for _ in range(rng.randint(3, 12)))
        client.call("made-up method", method, f"/{rng.getrandbits(64):x}")
        time.sleep(0.005)


def peak_rss_mb(pid):
    with open(f"/proc/{pid}/status") as status:
        for line in status:
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024
    return float("nan")


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--minutes", type=float, default=10.0)
    parser.add_argument("--binary", default="target/release/bouncewear")
    parser.add_argument("--seed", type=int, default=1992)
    args = parser.parse_args()

    work = tempfile.mkdtemp(prefix="bouncewear-soak-")
    database = os.path.join(work, "soak.db")
    server = subprocess.Popen(
        [args.binary, "serve", "--bind", "127.0.0.1:0", "--database", f"sqlite://{database}",
         "--max-queued", "300", "--log-format", "json"],
        stdout=subprocess.PIPE, stderr=open(os.path.join(work, "server.log"), "w"), text=True)
    line = server.stdout.readline()
    match = re.search(r"http://([\d.]+):(\d+)", line)
    if not match:
        sys.exit(f"the server did not start: {line!r}")
    host, port = match.group(1), int(match.group(2))
    stats, stop, finished, large = Stats(), threading.Event(), [], []
    rng = random.Random(args.seed)
    threads = [threading.Thread(target=large_jobs, args=(Client(host, port, stats), stop, large))]
    threads += [threading.Thread(target=submitter, args=(Client(host, port, stats), stop, finished,
                                                          random.Random(rng.random()))) for _ in range(4)]
    threads += [threading.Thread(target=reader, args=(Client(host, port, stats), stop, finished,
                                                       random.Random(rng.random()))) for _ in range(6)]
    threads += [threading.Thread(target=listener, args=(host, port, stats, stop, random.Random(rng.random())))
                for _ in range(4)]
    threads += [threading.Thread(target=flood, args=(Client(host, port, stats), stop, random.Random(rng.random())))]
    started = time.time()
    for thread in threads:
        thread.daemon = True
        thread.start()
    try:
        while time.time() - started < args.minutes * 60:
            time.sleep(5)
            print(f"{time.time() - started:6.0f} s  requests {sum(len(v) for v in stats.latency.values())}"
                  f"  peak RSS {peak_rss_mb(server.pid):.0f} MB", file=sys.stderr)
    finally:
        stop.set()
    for thread in threads:
        thread.join(timeout=40)
    probe = Client(host, port, stats)
    _, metrics = probe.call("GET /metrics", "GET", "/metrics")
    large_status = [json.loads(probe.call("GET /v1/jobs/{id}", "GET", f"/v1/jobs/{job}")[1])
                    for job in large]
    rss = peak_rss_mb(server.pid)
    db_bytes = sum(os.path.getsize(os.path.join(work, name)) for name in os.listdir(work)
                   if name.startswith("soak.db"))
    server.terminate()
    server.wait(timeout=30)

    print(f"\nbouncewear soak: {args.minutes:g} min, {os.cpu_count()} cores\n")
    print(f"{'request':28} {'count':>7} {'p50 ms':>8} {'p99 ms':>8} {'max ms':>8}  statuses")
    errors = 0
    for kind in sorted(stats.latency):
        values = stats.latency[kind]
        statuses = dict(sorted(stats.status[kind].items(), key=lambda item: str(item[0])))
        # The flood's made-up methods are meant to be refused; elsewhere a 5xx other than a 503 (with
        # Retry-After, asked to come back) or a broken connection is an error.
        bad = sum(n for s, n in statuses.items()
                  if isinstance(s, str) or (s >= 500 and s != 503))
        errors += bad
        print(f"{kind:28} {len(values):7d} {1e3 * quantile(values, 0.5):8.1f} "
              f"{1e3 * quantile(values, 0.99):8.1f} {1e3 * max(values):8.1f}  {statuses}")
    print(f"\npeak RSS {rss:.0f} MB; database {db_bytes / 1e6:.1f} MB; /metrics {len(metrics) / 1e3:.0f} kB")
    for job in large_status:
        print(f"large job {job.get('id')}: {job.get('status')}, {job.get('stored_bytes', 0) / 1e6:.1f} MB stored")
    print(f"errors: {errors}")
    shutil.rmtree(work, ignore_errors=True)
    sys.exit(1 if errors else 0)


if __name__ == "__main__":
    main()
