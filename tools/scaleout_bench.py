#!/usr/bin/env python3
"""Scale-out benchmark (not a test): one 10^7-operation job on PostgreSQL run by 1, 2 and 4 worker
processes, and what sharding costs per shard.

    cargo build --release
    python3 tools/scaleout_bench.py [--bin target/release/bouncewear] [--database postgres://...]
                                    [--workers 1,2,4] [--rounds 3]

Without --database it starts a throwaway PostgreSQL cluster (Debian's `postgresql`: initdb and
pg_ctl in a temporary directory, as the `postgres` user when run as root) and removes it after.

Each worker process runs one shard at a time on one compute thread (`worker --workers 1
--compute-threads 1`), so N processes use N cores: on a 2-core machine expect a plateau at 2.
Throughput is operations over the wall time from submission to the stored Result, seen by a request
that waits for the job's end (`?wait_s=`), for the first job new processes run, the next, and the
median of the third to the sixth (a running service's). The workers do a little more than `run`:
their groups keep each bin's extreme values for queries after the run, which `run` leaves out (its
Result reads none; about 6 % of `run --threads 1` on this job, docs/performance.md). Each round
runs `run --threads 1` and `--threads 2` and then every worker count in turn, with `run --threads
1` again after each, and each wall is compared with the mean of the `run --threads 1` just before
and just after it (two workers with one through those ratios): this machine's speed drifts by a
quarter within minutes, so figures from different moments do not compare. The per-shard overhead comes from
the workers' own clocks, the `bouncewear_shard_step_seconds` histogram of a `serve --workers 1` node
running the same job twice: `claim` (finding and leasing a shard), `store` (encoding a group's
accumulators and writing them in the transaction that counts it done) and `merge` (reading every
group back, merging in order, summarising and storing the Result; its parts `merge_read`,
`merge_compute` and `merge_write`), beside `run` (the simulation itself).
"""

import argparse
import json
import os
import re
import shutil
import socket
import statistics
import subprocess
import sys
import tempfile
import time
import urllib.request

JOB = {
    "name": "scale-out benchmark",
    "devices": 1000,
    "operations": 10000,
    "seed": 2026,
    "scenario": {"circuit": {"supply_voltage_v": 48, "current_a": 15}},
    "scatter": [
        {"parameter": "contact_radius_m", "per": "device",
         "distribution": {"kind": "normal", "mean": 7.7e-3, "sd": 0.8e-3, "min": 1e-3}},
        {"parameter": "impact_velocity_m_s", "per": "operation",
         "distribution": {"kind": "normal", "mean": 0.224, "sd": 0.02, "min": 0.05}},
    ],
}


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def postgres_bin():
    for root in sorted(os.listdir("/usr/lib/postgresql"), reverse=True) if os.path.isdir("/usr/lib/postgresql") else []:
        path = os.path.join("/usr/lib/postgresql", root, "bin")
        if os.path.isfile(os.path.join(path, "initdb")):
            return path
    found = shutil.which("initdb")
    return os.path.dirname(found) if found else None


class Cluster:
    """A throwaway PostgreSQL cluster."""

    def __init__(self):
        self.bin = postgres_bin()
        if not self.bin:
            sys.exit("no PostgreSQL: install Debian's postgresql or pass --database")
        self.dir = tempfile.mkdtemp(prefix="bouncewear-scaleout-")
        self.root = os.geteuid() == 0
        if self.root:
            subprocess.run(["chown", "-R", "postgres:postgres", self.dir], check=True)
        self.port = free_port()
        data = os.path.join(self.dir, "data")
        self.run("initdb", "-D", data, "-U", "postgres", "-A", "trust", "-E", "UTF8", "--no-sync")
        options = f"-p {self.port} -k {self.dir} -c listen_addresses=127.0.0.1"
        self.run("pg_ctl", "-D", data, "-l", os.path.join(self.dir, "server.log"), "-o", options, "-w", "start")
        self.data = data

    def run(self, tool, *args):
        command = [os.path.join(self.bin, tool), *args]
        if self.root:
            command = ["runuser", "-u", "postgres", "--", *command]
        subprocess.run(command, check=True, stdout=subprocess.DEVNULL)

    def database(self, name):
        self.run("psql", "-h", "127.0.0.1", "-p", str(self.port), "-U", "postgres", "-c", f'CREATE DATABASE "{name}"')
        return f"postgres://postgres@127.0.0.1:{self.port}/{name}"

    def stop(self):
        self.run("pg_ctl", "-D", self.data, "-m", "immediate", "stop")
        shutil.rmtree(self.dir, ignore_errors=True)


def start(binary, args, first_line):
    process = subprocess.Popen([binary, *args], stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                               env={**os.environ, "RUST_LOG": "warn"}, text=True)
    line = process.stdout.readline()
    assert line.startswith(first_line), line
    return process, line


def serve(binary, database, workers):
    process, line = start(binary, ["serve", "--bind", "127.0.0.1:0", "--database", database,
                                   "--workers", str(workers), "--compute-threads", "1"], "bouncewear listening")
    return process, line.strip().rsplit(" ", 1)[-1]


def call(url, body=None):
    data = json.dumps(body).encode() if body is not None else None
    request = urllib.request.Request(url, data=data, headers={"Content-Type": "application/json"})
    with urllib.request.urlopen(request) as reply:
        text = reply.read().decode()
        return json.loads(text) if reply.headers.get_content_type().endswith("json") else text


def run_job(base, job):
    """Submits `job` and waits for its Result: (wall seconds, Result)."""
    started = time.perf_counter()
    job_id = call(f"{base}/v1/jobs", job)["id"]
    while True:
        # One request the API node answers when the job ends (PostgreSQL announces it).
        status = call(f"{base}/v1/jobs/{job_id}?wait_s=20")["status"]
        if status == "succeeded":
            return time.perf_counter() - started, call(f"{base}/v1/jobs/{job_id}/result"), job_id
        if status in ("failed", "cancelled"):
            sys.exit(f"job {job_id} {status}")


def step_means(metrics):
    """Mean seconds and count per step of `bouncewear_shard_step_seconds`."""
    sums, counts = {}, {}
    for line in metrics.splitlines():
        match = re.match(r'bouncewear_shard_step_seconds_(sum|count)\{step="(\w+)"\} (\S+)', line)
        if match:
            (sums if match[1] == "sum" else counts)[match[2]] = float(match[3])
    return {step: (sums[step] / counts[step], int(counts[step])) for step in sums if counts.get(step)}


def result_statistics(result):
    """A Result's statistics, without its timing, as text that compares equal to the bit."""
    return json.dumps([result["operations"], result["devices"]], sort_keys=True)


def run_baseline(binary, job_file, threads):
    """`bouncewear run` on `job_file`: (wall seconds of the whole process, its Result's statistics)."""
    started = time.perf_counter()
    output = subprocess.run([binary, "run", job_file, "--threads", str(threads)],
                            check=True, capture_output=True, text=True).stdout
    wall = time.perf_counter() - started
    result = json.loads(output)
    return wall, result_statistics(result)


# Jobs each worker count runs in a round, one after another: the first, the next and, from the
# third on, a running service's (their median).
JOBS_PER_ROUND = 6


def run_workers(binary, database, count):
    """The job JOBS_PER_ROUND times on an API node and `count` worker processes, new on a new
    database: the first time's wall seconds, the second's (warm: processes, connections and tables
    as a running service has them), the median of the rest (steady: the processes' memory and
    caches as they stay once they have run a few jobs), and the Results' statistics."""
    api, base = serve(binary, database, 0)
    workers = [start(binary, ["worker", "--database", database, "--workers", "1", "--compute-threads", "1"],
                     "bouncewear worker running")[0] for _ in range(count)]
    walls, results = [], set()
    try:
        for _ in range(JOBS_PER_ROUND):
            wall, result, _ = run_job(base, JOB)
            walls.append(wall)
            results.add(result_statistics(result))
    finally:
        for process in [*workers, api]:
            process.terminate()
            process.wait()
    return walls[0], walls[1], statistics.median(walls[2:]), results


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--bin", default="target/release/bouncewear")
    parser.add_argument("--database", help="a PostgreSQL server's admin URL (postgres://USER@HOST:PORT)")
    parser.add_argument("--workers", default="1,2,4")
    parser.add_argument("--rounds", type=int, default=3,
                        help="rounds, each running `run` and every worker count in turn (a machine whose "
                             "speed drifts is compared within a round)")
    args = parser.parse_args()
    cluster = None if args.database else Cluster()
    new_database = (lambda name: cluster.database(name)) if cluster else (lambda name: args.database)
    operations = JOB["devices"] * JOB["operations"]
    counts = [int(n) for n in args.workers.split(",")]
    kinds = ("first", "warm", "steady")
    configurations = ["run 1", "run 2", *[f"{kind} {count}" for count in counts for kind in kinds]]
    walls = {name: [] for name in configurations}
    # Each wall's `run --threads 1`: the mean of the one just before it and the one just after.
    references = {name: [] for name in configurations}
    results = set()
    try:
        with tempfile.NamedTemporaryFile("w", suffix=".json") as job_file:
            json.dump(JOB, job_file)
            job_file.flush()
            def baseline(threads):
                wall, result = run_baseline(args.bin, job_file.name, threads)
                results.add(result)
                return wall

            for round_ in range(args.rounds):
                before = baseline(1)
                walls["run 1"].append(before)
                references["run 1"].append(before)
                walls["run 2"].append(baseline(2))
                after = baseline(1)
                references["run 2"].append((before + after) / 2)
                for count in counts:
                    database = new_database(f"scaleout_{round_}_{count}")
                    first, warm, steady, result = run_workers(args.bin, database, count)
                    before, after = after, baseline(1)
                    for kind, wall in zip(kinds, (first, warm, steady)):
                        walls[f"{kind} {count}"].append(wall)
                        references[f"{kind} {count}"].append((before + after) / 2)
                    results |= result
        node, base = serve(args.bin, new_database("scaleout_steps"), 1)
        run_job(base, JOB)
        run_job(base, JOB)
        steps = step_means(call(f"{base}/metrics"))
        node.terminate()
        node.wait()
    finally:
        if cluster:
            cluster.stop()
    print(f"one job of {operations:.0e} operations (48 V / 15 A, radius and velocity scattered), "
          f"{os.cpu_count()} cores, PostgreSQL, {args.rounds} rounds\n")
    print("Wall time min and median over the rounds; the ratio is each wall over the mean of the "
          "`run --threads 1` just before and just after it (median, and min..max).\n")
    print("| run by | wall min (s) | wall median (s) | operations/s (median) | wall / `run --threads 1` |")
    print("|---|---|---|---|---|")
    for name in configurations:
        kind, number = name.split()
        label = (f"`bouncewear run --threads {number}` (no database)" if kind == "run"
                 else f"{number} worker process{'es' if int(number) > 1 else ''}, "
                 + {"first": "first job (new processes and database)", "warm": "next job",
                    "steady": f"jobs 3 to {JOBS_PER_ROUND} (median)"}[kind])
        ratios = sorted(wall / base for wall, base in zip(walls[name], references[name]))
        print(f"| {label} | {min(walls[name]):.2f} | {statistics.median(walls[name]):.2f} | "
              f"{operations / statistics.median(walls[name]) / 1e6:.2f} M | "
              f"{statistics.median(ratios):.2f}x ({ratios[0]:.2f}..{ratios[-1]:.2f}) |")
    if 1 in counts and 2 in counts:
        for kind in kinds:
            relative = {count: [wall / base for wall, base in zip(walls[f"{kind} {count}"],
                                                                  references[f"{kind} {count}"])]
                        for count in (1, 2)}
            ratios = sorted(two / one for two, one in zip(relative[2], relative[1]))
            what = {"first": "first job", "warm": "next job", "steady": f"jobs 3 to {JOBS_PER_ROUND}"}[kind]
            print(f"\nTwo workers over one, {what}, round by round: "
                  f"median {statistics.median(ratios):.2f}x ({ratios[0]:.2f}..{ratios[-1]:.2f})")
    print(f"\nResults identical to `run` for every worker count: {len(results) == 1}\n")
    print("| shard step | mean (ms) | count |")
    print("|---|---|---|")
    for step in ("claim", "run", "store", "merge", "merge_read", "merge_compute", "merge_write"):
        if step in steps:
            mean, count = steps[step]
            print(f"| {step} | {mean * 1e3:.2f} | {count} |")


if __name__ == "__main__":
    main()
