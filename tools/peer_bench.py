#!/usr/bin/env python3
"""The engine against its peers (not a test): whole processes side by side, interleaved rounds,
the fastest and the median of each, and the ratio against the faster peer.

    cargo build --release
    pip install numpy numba          # Numba is optional: without it, NumPy alone
    python3 tools/peer_bench.py [--bin target/release/bouncewear] [--python python3]
                                [--rounds 6] [--threads 2]

For each reference job (`tests/data/reference_jobs.json`: 2000 devices x 500 operations, every
metric) each round runs `bouncewear run --quiet --threads N`, `tools/numpy_peer.py` (one core) and
`tools/numba_peer.py` (`NUMBA_NUM_THREADS=N`) one after another, so that a drift of the machine's
speed, a quarter within minutes on some VMs, falls on all three alike. The Numba peer runs once
before the rounds, so that its machine code is compiled and cached and the rounds time loading it,
as a user's second run would. Times are wall clock of the whole process: start-up, reading the
job, the simulation, the statistics and writing the Result.

The ratio is the faster peer's time over the engine's, for the fastest runs and for the medians
(issue 33 asks 20x at 48 V / 15 A and 50x mechanical on a quiet machine); docs/performance.md
says what each figure means and where they stand. `bouncewear bench` gives the same comparison
best of three, in its report.
"""

import argparse
import json
import os
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def cpu_name():
    """The CPU's model name, as /proc/cpuinfo gives it (the machine, where there is none)."""
    try:
        with open("/proc/cpuinfo") as info:
            for line in info:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.machine()


def wall(command, env):
    """Seconds the command takes, its output discarded; a failure ends the benchmark."""
    start = time.perf_counter()
    subprocess.run(command, stdout=subprocess.DEVNULL, check=True, env=env)
    return time.perf_counter() - start


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--bin", default=os.path.join(ROOT, "target/release/bouncewear"))
    parser.add_argument("--python", default=sys.executable, help="the Python that runs the peers")
    parser.add_argument("--rounds", type=int, default=6)
    parser.add_argument("--threads", type=int, default=2)
    args = parser.parse_args()
    if args.rounds < 1 or args.threads < 1:
        parser.error("--rounds and --threads must be at least 1")
    if not shutil.which(args.bin) and not os.access(args.bin, os.X_OK):
        parser.error(f"no bouncewear at {args.bin}: cargo build --release, or --bin PATH")

    def imports(module):
        probe = [args.python, "-c", f"import {module}"]
        return subprocess.run(probe, capture_output=True).returncode == 0

    if not imports("numpy"):
        parser.error(f"{args.python} cannot import NumPy: pip install numpy (and numba)")
    peers = {"numpy": os.path.join(ROOT, "tools/numpy_peer.py")}
    if imports("numba"):
        peers["numba"] = os.path.join(ROOT, "tools/numba_peer.py")
    env = dict(os.environ, NUMBA_NUM_THREADS=str(args.threads), OPENBLAS_NUM_THREADS="1")

    with open(os.path.join(ROOT, "tests/data/reference_jobs.json")) as f:
        jobs = json.load(f)
    print(f"{cpu_name()}, {os.cpu_count()} cores; `run --threads {args.threads}`, "
          f"{args.rounds} interleaved rounds; peers: {', '.join(peers)}")
    print("| job | process | fastest s | median s |")
    print("|---|---|---|---|")
    ratios = []
    with tempfile.TemporaryDirectory() as scratch:
        for name, job in jobs.items():
            text = json.dumps(job)
            path = os.path.join(scratch, "job.json")
            with open(path, "w") as f:
                f.write(text)
            commands = {"bouncewear run": [args.bin, "run", "--quiet", "--threads",
                                           str(args.threads), path]}
            commands.update({peer: [args.python, script, text] for peer, script in peers.items()})
            if "numba" in peers:
                wall(commands["numba"], env)
            times = {process: [] for process in commands}
            for _ in range(args.rounds):
                for process, command in commands.items():
                    times[process].append(wall(command, env))
            for process, seen in times.items():
                print(f"| {name} | {process} | {min(seen):.3f} | {statistics.median(seen):.3f} |")
            engine = times.pop("bouncewear run")
            fastest = min(times, key=lambda peer: min(times[peer]))
            by_median = min(times, key=lambda peer: statistics.median(times[peer]))
            ratios.append((name, fastest, min(times[fastest]) / min(engine), by_median,
                           statistics.median(times[by_median]) / statistics.median(engine)))
    print()
    for name, fastest, best, by_median, median in ratios:
        print(f"{name}: {best:.1f}x the faster peer ({fastest}) fastest against fastest, "
              f"{median:.1f}x ({by_median}) median against median")


if __name__ == "__main__":
    main()
