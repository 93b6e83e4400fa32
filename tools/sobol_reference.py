#!/usr/bin/env python3
"""SALib's Sobol' indices of the Ishigami function on SALib's own samples, for
tests/data/sobol_reference.json:

    python3 -m pip install SALib
    python3 tools/sobol_reference.py > tests/data/sobol_reference.json

With `--job SAMPLES` it reads instead the outputs of a bouncewear job's own samples, which
`model/tests/integration/sensitivity.rs` evaluates outside the engine from the engine's draws, and writes
SALib's indices of them, for tests/data/sobol_job_reference.json:

    BOUNCEWEAR_WRITE_SOBOL_SAMPLES=/tmp/samples.json \
        cargo test -p bouncewear-model --test integration sensitivity::the_indices_of_a_job_are_salibs
    python3 tools/sobol_reference.py --job /tmp/samples.json > tests/data/sobol_job_reference.json

The file holds the model's outputs in SALib's order (per base sample: A, AB_1 .. AB_D, B) and
`SALib.analyze.sobol`'s first-order and total indices. `model/src/stats/sobol.rs` must give the same
indices from the same outputs to 1e-10 (`model/tests/integration/sobol_reference.rs`): the estimators are the
same (Saltelli 2010 first order, Jansen total), computed independently.
"""
import json
import sys
from importlib.metadata import version

import numpy as np
from SALib.analyze import sobol as analyze
from SALib.sample import sobol as sample

PROBLEM = {"num_vars": 3, "names": ["x1", "x2", "x3"], "bounds": [[-np.pi, np.pi]] * 3}
N = 1024


def ishigami(x):
    return np.sin(x[:, 0]) + 7 * np.sin(x[:, 1]) ** 2 + 0.1 * x[:, 2] ** 4 * np.sin(x[:, 0])


def job_reference(path):
    """SALib's indices of each metric of a job's samples (SALib's order per device: A, AB_i, B)."""
    with open(path) as f:
        samples = json.load(f)
    names = samples["parameters"]
    problem = {"num_vars": len(names), "names": names, "bounds": [[0.0, 1.0]] * len(names)}
    salib = {}
    for metric, outputs in zip(samples["metrics"], samples["outputs"]):
        indices = analyze.analyze(
            problem, np.array(outputs), calc_second_order=False, print_to_console=False, seed=1992
        )
        salib[metric] = {
            "first": [float(v) for v in indices["S1"]],
            "total": [float(v) for v in indices["ST"]],
        }
    samples["salib"] = salib
    samples["salib_version"] = version("SALib")
    return samples


def main():
    if len(sys.argv) == 3 and sys.argv[1] == "--job":
        json.dump(job_reference(sys.argv[2]), sys.stdout)
        sys.stdout.write("\n")
        return
    x = sample.sample(PROBLEM, N, calc_second_order=False, seed=1992)
    y = ishigami(x)
    indices = analyze.analyze(PROBLEM, y, calc_second_order=False, print_to_console=False, seed=1992)
    json.dump(
        {
            "salib": version("SALib"),
            "inputs": PROBLEM["num_vars"],
            "base_samples": N,
            "outputs": [float(v) for v in y],
            "first": [float(v) for v in indices["S1"]],
            "total": [float(v) for v in indices["ST"]],
        },
        sys.stdout,
    )
    sys.stdout.write("\n")


if __name__ == "__main__":
    main()
