#!/usr/bin/env python3
"""The peers checked against the engine, statistically: `bouncewear run` and each peer
(tools/numpy_peer.py, and tools/numba_peer.py where Numba imports) run each reference job of
tests/data/reference_jobs.json with different seeds, and every bin's statistics must agree within
their sampling error.

    python3 tools/peer_check.py [--bouncewear target/release/bouncewear] [--rounds 2]

Per job, peer, round, bin and metric (operation metrics per bin, device metrics once):
- the means: |peer - engine| < 4.5 combined standard errors. Each side's standard error is its
  batch-means interval (`mean_ci95`, t over 32 groups of devices) divided by t: the operations of
  one device are correlated, so sd / sqrt(n) would understate it. The engine clips its interval to
  [min, max]; the wider side is the unclipped one. Where both errors are 0 (a metric that does not
  vary, such as the mechanical job's arc energy) the means must be equal.
- the nine quantiles: |peer - engine| < 4.5 sqrt(2) s + 0.002 |engine|, where s is the engine's
  quantile interval (Woodruff's, over the same groups) divided by 2 t and stands for the peer's
  too (same design, same n), and 0.2 % is the resolution of the engine's sketch.
With about 2300 such comparisons per round, a true model fails one by chance rarely (4.5 standard
errors on 31 degrees of freedom is p ~ 1e-4 per comparison, and the quantiles of a bin are
correlated); a real mismatch in the peer's model fails many, in the bins and metrics it touches.

The Numba peer is also run with the NumPy peer's seed: it takes the same draws, so every statistic
must be the NumPy peer's to 1e-9 relative. Exits 1 if any check fails.
"""
import argparse
import json
import os
import subprocess
import sys

TOOLS = os.path.dirname(os.path.abspath(__file__))
JOBS = os.path.join(TOOLS, "..", "tests", "data", "reference_jobs.json")
T_975_31 = 2.0395134463964077
Z_MAX = 4.5
SKETCH = 0.002


def engine(binary, job):
    text = subprocess.run([binary, "run", "--quiet", "--threads", "2", "-"], input=json.dumps(job),
                          capture_output=True, text=True, check=True).stdout
    return json.loads(text)


def peer(name, job):
    text = subprocess.run([sys.executable, os.path.join(TOOLS, f"{name}_peer.py"), json.dumps(job)],
                          capture_output=True, text=True, check=True).stdout
    return json.loads(text)


def summaries(result):
    """Every (metric, bin) summary of a Result or a peer's output, keyed by (metric, bin)."""
    for metric, bins in result["operations"].items():
        for i, summary in enumerate(bins):
            yield (metric, i), summary
    for metric, summary in result["devices"].items():
        yield (metric, "device"), summary


def mean_error(summary):
    """The standard error of the mean, from the batch-means interval's wider (unclipped) side."""
    lo, hi = summary["mean_ci95"]
    return max(summary["mean"] - lo, hi - summary["mean"]) / T_975_31


def compare(ours, theirs):
    """The failures of `theirs` (a peer's output) against `ours` (the engine's Result), and the
    largest ratio of a difference to its tolerance, for the means and for the quantiles."""
    failures, worst = [], {"mean": 0.0, "quantile": 0.0}
    theirs = dict(summaries(theirs))
    for key, engine_summary in summaries(ours):
        peer_summary = theirs[key]
        assert engine_summary["n"] == peer_summary["n"], key
        se = (mean_error(engine_summary) ** 2 + mean_error(peer_summary) ** 2) ** 0.5
        diff = abs(peer_summary["mean"] - engine_summary["mean"])
        ratio = diff / (Z_MAX * se) if se > 0 else (0.0 if diff == 0 else float("inf"))
        worst["mean"] = max(worst["mean"], ratio)
        if ratio >= 1:
            failures.append(f"{key} mean: engine {engine_summary['mean']:.6g} peer {peer_summary['mean']:.6g}"
                            f" ({diff / se if se else float('inf'):.1f} standard errors)")
        for level, quantile in engine_summary["quantiles"].items():
            value, (lo, hi) = quantile["value"], quantile["ci95"]
            tolerance = Z_MAX * 2**0.5 * (hi - lo) / (2 * T_975_31) + SKETCH * abs(value)
            diff = abs(peer_summary["quantiles"][level] - value)
            ratio = diff / tolerance if tolerance > 0 else (0.0 if diff == 0 else float("inf"))
            worst["quantile"] = max(worst["quantile"], ratio)
            if ratio >= 1:
                failures.append(f"{key} {level}: engine {value:.6g} [{lo:.6g}, {hi:.6g}]"
                                f" peer {peer_summary['quantiles'][level]:.6g}")
    return failures, worst


def same_to_rounding(a, b, path=()):
    """The paths where two peers' outputs differ by more than 1e-9 relative (timing aside)."""
    if isinstance(a, dict):
        return [p for k in a if k != "compute_s" for p in same_to_rounding(a[k], b[k], path + (k,))]
    if isinstance(a, list):
        return [p for i, (x, y) in enumerate(zip(a, b)) for p in same_to_rounding(x, y, path + (i,))]
    return [] if abs(a - b) <= 1e-9 * max(abs(a), abs(b)) else [path]


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--bouncewear", default=os.path.join(TOOLS, "..", "target", "release", "bouncewear"))
    parser.add_argument("--rounds", type=int, default=2, help="seeds per job and peer")
    args = parser.parse_args()
    try:
        import numba  # noqa: F401
        peers = ["numpy", "numba"]
    except ImportError:
        print("numba does not import: the Numba peer is not checked")
        peers = ["numpy"]
    failed = False
    for name, job in json.load(open(JOBS)).items():
        for round_ in range(args.rounds):
            ours = engine(args.bouncewear, dict(job, seed=job["seed"] + round_))
            outputs = {}
            for i, peer_name in enumerate(peers):
                outputs[peer_name] = peer(peer_name, dict(job, seed=job["seed"] + 1000 * (i + 1) + round_))
                failures, worst = compare(ours, outputs[peer_name])
                print(f"{name}, round {round_}, {peer_name}: {len(failures)} failures; largest share of its"
                      f" tolerance: means {worst['mean']:.2f}, quantiles {worst['quantile']:.2f}")
                for failure in failures:
                    print("   ", failure)
                failed |= bool(failures)
            if "numba" in outputs:
                twin = peer("numba", dict(job, seed=job["seed"] + 1000 + round_))
                differ = same_to_rounding(outputs["numpy"], twin)
                print(f"{name}, round {round_}, numba with numpy's seed: {len(differ)} statistics differ"
                      f" by more than 1e-9")
                failed |= bool(differ)
    sys.exit(1 if failed else 0)


if __name__ == "__main__":
    main()
