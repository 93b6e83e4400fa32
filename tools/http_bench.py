#!/usr/bin/env python3
"""HTTP benchmarks of `bouncewear serve` (standard library only).

    target/release/bouncewear serve --bind 127.0.0.1:8080 --database sqlite:///tmp/bench.db &
    python3 tools/http_bench.py http://127.0.0.1:8080

1. Submit to result: a 100 devices x 100 operations job, POST until the Result is fetched, 50 times:
   asking for the Result every millisecond until it is there, and with one request that waits for
   it (`?wait_s=`), alternately.
2. Throughput of small jobs: 4 clients each submit 50 such jobs one after another, each fetching
   its Result before the next (a waiting request); jobs per second from the first POST to the last
   Result.
3. GET latency under load: 16 client threads GET /v1/jobs/{id} for 10 s while a 500-million-operation
   job keeps the compute threads busy.
"""
import http.client
import json
import statistics
import sys
import threading
import time
from urllib.parse import urlparse


def connection(base):
    url = urlparse(base)
    return http.client.HTTPConnection(url.hostname, url.port, timeout=60)


def request(conn, method, path, body=None):
    headers = {"content-type": "application/json"} if body is not None else {}
    conn.request(method, path, body=None if body is None else json.dumps(body), headers=headers)
    response = conn.getresponse()
    return response.status, response.read()


def submit_to_result(base, runs=50, first_seed=0, wait=False):
    """Seconds from each POST to its Result: polled every millisecond, or with `wait` one request
    that the server answers once the job ended."""
    conn = connection(base)
    times = []
    for seed in range(first_seed, first_seed + runs):
        started = time.perf_counter()
        status, body = request(conn, "POST", "/v1/jobs", {"devices": 100, "operations": 100, "seed": seed})
        assert status == 202, body
        job = json.loads(body)["id"]
        while True:
            status, body = request(conn, "GET", f"/v1/jobs/{job}/result" + ("?wait_s=10" if wait else ""))
            if status == 200:
                break
            assert status == 409, body
            time.sleep(0.001)
        times.append(time.perf_counter() - started)
    return times


def small_jobs_throughput(base, clients=4, jobs=50):
    errors = []

    def client(index):
        try:
            submit_to_result(base, runs=jobs, first_seed=1000 * (index + 1), wait=True)
        except AssertionError as error:
            errors.append(error)

    threads = [threading.Thread(target=client, args=(i,)) for i in range(clients)]
    started = time.perf_counter()
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors, errors
    return clients * jobs / (time.perf_counter() - started)


def get_under_load(base, seconds=10.0, clients=16):
    conn = connection(base)
    status, body = request(conn, "POST", "/v1/jobs", {"devices": 20000, "operations": 25000, "seed": 1,
                                                      "scenario": {"circuit": {"supply_voltage_v": 48, "current_a": 15}}})
    assert status == 202, body
    job = json.loads(body)["id"]
    while json.loads(request(conn, "GET", f"/v1/jobs/{job}")[1])["status"] != "running":
        time.sleep(0.01)
    latencies, errors, stop = [], [], time.perf_counter() + seconds
    lock = threading.Lock()

    def client():
        own, c = [], connection(base)
        while time.perf_counter() < stop:
            started = time.perf_counter()
            status, _ = request(c, "GET", f"/v1/jobs/{job}")
            own.append(time.perf_counter() - started)
            if status != 200:
                errors.append(status)
        with lock:
            latencies.extend(own)

    threads = [threading.Thread(target=client) for _ in range(clients)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    # A new connection: the server closes one left idle through the load (slow-client rules).
    conn = connection(base)
    still_running = json.loads(request(conn, "GET", f"/v1/jobs/{job}")[1])["status"] == "running"
    request(conn, "DELETE", f"/v1/jobs/{job}")
    return latencies, errors, still_running


def quantile(values, q):
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))]


def main():
    if any(arg in ("-h", "--help") for arg in sys.argv[1:]):
        print(__doc__)
        return
    base = sys.argv[1] if len(sys.argv) > 1 else "http://127.0.0.1:8080"
    if urlparse(base).hostname is None:
        sys.exit(f"http_bench.py: {base!r} is not a server's URL (http://HOST:PORT)")
    polled, waited = [], []
    for block in range(5):
        polled += submit_to_result(base, runs=10, first_seed=100 * block)
        waited += submit_to_result(base, runs=10, first_seed=100 * block + 50, wait=True)
    for how, times in (("polled every ms", polled), ("one waiting GET", waited)):
        print(f"submit to result, 100 x 100 job, {how}, {len(times)} runs: median {1e3 * statistics.median(times):.1f} ms, "
              f"p90 {1e3 * quantile(times, 0.9):.1f} ms, max {1e3 * max(times):.1f} ms")
    print(f"small jobs, 4 clients x 50 jobs of 100 x 100: {small_jobs_throughput(base):.1f} jobs/s")
    latencies, errors, busy = get_under_load(base)
    print(f"GET /v1/jobs/{{id}} under load (16 clients, 10 s, a 500 M-operation job still running at the end: {busy}): "
          f"{len(latencies) / 10:.0f} requests/s, p50 {1e3 * quantile(latencies, 0.5):.2f} ms, "
          f"p99 {1e3 * quantile(latencies, 0.99):.2f} ms, max {1e3 * max(latencies):.1f} ms, errors {len(errors)}")


if __name__ == "__main__":
    main()
