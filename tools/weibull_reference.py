#!/usr/bin/env python3
"""Independent reference for `model/src/life.rs`: two-parameter Weibull MLE with right censoring.

    pip install scipy reliability
    python3 tools/weibull_reference.py            # writes tests/data/weibull_reference.json
    python3 tools/weibull_reference.py -          # or prints it

For five fixed data sets (the same splitmix64 draws as the Rust tests in `life.rs`) writes the JSON
that those tests read, with

* `scipy`: `scipy.stats.weibull_min.fit` on `scipy.stats.CensoredData` (scipy's own censored
  likelihood, logpdf of failures + logsf of suspensions, location fixed at 0), maximised by
  Nelder-Mead with tight tolerances; the covariance of (ln eta, ln beta) is the inverse of a
  central-difference Hessian of that same likelihood; bounds are the log-transformed Wald (Fisher
  matrix) bounds and B-life bounds the delta method on ln B_p;
* `reliability` (the Rust tests need it; without the package it is `null`): `Fit_Weibull_2P(method='MLE', CI=0.95,
  optimizer='best')` (its default optimizer, TNC, stops 1.2e-3 short of the maximum in eta on
  `wide_span`), whose parameter bounds are Fisher-matrix bounds with se(ln x) = se(x)/x and whose
  bounds on time are the delta method on v = ln t = ln alpha + ln(-ln R)/beta: the same methods as
  `life.rs`.

Shares no code with the Rust module: the only shared thing is the data generator.
"""
import json
import math
import os
import sys

import numpy as np
import scipy.optimize as so
import scipy.stats as ss

os.environ.setdefault("MPLBACKEND", "Agg")  # reliability imports matplotlib; no display here

DEFAULT_OUTPUT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests", "data", "weibull_reference.json")
Z = 1.959963984540054
MASK = (1 << 64) - 1


class SplitMix:
    """splitmix64, bit-identical to `SplitMix` in the Rust tests."""

    def __init__(self, seed):
        self.state = seed & MASK

    def next_u64(self):
        self.state = (self.state + 0x9E3779B97F4A7C15) & MASK
        z = self.state
        z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & MASK
        z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & MASK
        return z ^ (z >> 31)

    def uniform(self):
        """In [0, 1): the top 53 bits."""
        return (self.next_u64() >> 11) * 2.0**-53

    def weibull_life(self, beta, eta):
        """Operations to failure: floor of a Weibull(beta, eta) draw, plus one."""
        u = self.uniform()
        return math.floor(eta * (-math.log1p(-u)) ** (1.0 / beta)) + 1.0


def type_one(seed, n, beta, eta, end):
    """n devices, each censored at `end` operations if it has not failed by then."""
    rng = SplitMix(seed)
    data = []
    for _ in range(n):
        life = rng.weibull_life(beta, eta)
        data.append((life, True) if life <= end else (end, False))
    return data


def random_withdrawal(seed, n, beta, eta, horizon):
    """n devices, each withdrawn at its own uniform time in 1..=horizon."""
    rng = SplitMix(seed)
    data = []
    for _ in range(n):
        life = rng.weibull_life(beta, eta)
        withdrawn = math.floor(rng.uniform() * horizon) + 1.0
        data.append((life, True) if life <= withdrawn else (withdrawn, False))
    return data


DATASETS = {
    "complete": type_one(1, 20, 2.5, 1000.0, math.inf),
    "heavy_censoring": type_one(2, 60, 1.5, 50000.0, 25000.0),
    "small": [(120.0, True), (190.0, True), (250.0, False), (310.0, True), (400.0, False)],
    "large": random_withdrawal(4, 500, 0.8, 2.0e5, 6.0e5),
    "wide_span": type_one(5, 40, 0.25, 4000.0, 1.0e6),
}


def log_likelihood(data, ln_eta, ln_beta):
    """scipy's log density at the failures plus its log survival at the suspensions."""
    failures = np.array([t for t, f in data if f])
    censored = np.array([t for t, f in data if not f])
    beta, eta = math.exp(ln_beta), math.exp(ln_eta)
    return float(
        np.sum(ss.weibull_min.logpdf(failures, beta, scale=eta))
        + np.sum(ss.weibull_min.logsf(censored, beta, scale=eta))
    )


def hessian(f, x, h=1e-4):
    """Central differences, step h in each (log) coordinate."""
    n = len(x)
    out = np.zeros((n, n))
    for i in range(n):
        for j in range(n):
            def at(di, dj):
                y = np.array(x, dtype=float)
                y[i] += di
                y[j] += dj
                return f(y)
            out[i, j] = (at(h, h) - at(h, -h) - at(-h, h) + at(-h, -h)) / (4 * h * h)
    return out


def tight_fmin(func, x0, args=(), disp=0):
    return so.fmin(func, x0, args=args, disp=disp, xtol=1e-13, ftol=1e-15, maxiter=20000, maxfun=40000)


def scipy_fit(data):
    failures = np.array([t for t, f in data if f])
    censored = np.array([t for t, f in data if not f])
    cens = ss.CensoredData(uncensored=failures, right=censored)
    beta, _, eta = ss.weibull_min.fit(cens, floc=0, optimizer=tight_fmin)
    x = np.array([math.log(eta), math.log(beta)])
    cov = np.linalg.inv(-hessian(lambda y: log_likelihood(data, y[0], y[1]), x))
    se_ln_eta, se_ln_beta = math.sqrt(cov[0, 0]), math.sqrt(cov[1, 1])
    out = {
        "beta": beta,
        "eta": eta,
        "log_likelihood": log_likelihood(data, x[0], x[1]),
        "covariance_ln": cov.tolist(),
        "beta_ci95": [beta * math.exp(-Z * se_ln_beta), beta * math.exp(Z * se_ln_beta)],
        "eta_ci95": [eta * math.exp(-Z * se_ln_eta), eta * math.exp(Z * se_ln_eta)],
    }
    for name, p in (("b1", 0.01), ("b10", 0.10)):
        k = math.log(-math.log1p(-p))
        value = eta * math.exp(k / beta)
        grad = np.array([1.0, -k / beta])
        se = math.sqrt(grad @ cov @ grad)
        out[name] = {"value": value, "ci95": [value * math.exp(-Z * se), value * math.exp(Z * se)]}
    return out


def reliability_fit(data):
    try:
        from reliability.Fitters import Fit_Weibull_2P
        from reliability.Utils import extract_CI
    except ImportError:
        return None
    fit = Fit_Weibull_2P(
        failures=[t for t, f in data if f],
        right_censored=[t for t, f in data if not f] or None,
        CI=0.95,
        method="MLE",
        optimizer="best",
        show_probability_plot=False,
        print_results=False,
    )
    out = {
        "beta": fit.beta,
        "eta": fit.alpha,
        "log_likelihood": fit.loglik,
        "beta_ci95": [fit.beta_lower, fit.beta_upper],
        "eta_ci95": [fit.alpha_lower, fit.alpha_upper],
        "cov_alpha_beta": fit.Cov_alpha_beta,
        "alpha_se": fit.alpha_SE,
        "beta_se": fit.beta_SE,
    }
    for name, p in (("b1", 0.01), ("b10", 0.10)):
        lower, upper = extract_CI(dist=fit.distribution, func="CDF", CI_type="time", CI=0.95, CI_y=[p])
        out[name] = {
            "value": float(fit.distribution.quantile(p)),
            "ci95": [float(np.asarray(lower).ravel()[0]), float(np.asarray(upper).ravel()[0])],
        }
    return out


def versions():
    out = {"scipy": __import__("scipy").__version__}
    try:
        from importlib.metadata import version

        out["reliability"] = version("reliability")
    except Exception:
        out["reliability"] = None
    return out


def main():
    result = {"versions": versions(), "datasets": {}}
    for name, data in DATASETS.items():
        result["datasets"][name] = {
            "n": len(data),
            "failures": sum(1 for _, f in data if f),
            "sum_times": sum(t for t, _ in data),
            "min_time": min(t for t, _ in data),
            "max_time": max(t for t, _ in data),
            "scipy": scipy_fit(data),
            "reliability": reliability_fit(data),
        }
    text = json.dumps(result, indent=2) + "\n"
    if len(sys.argv) > 1 and sys.argv[1] == "-":
        sys.stdout.write(text)
    else:
        path = sys.argv[1] if len(sys.argv) > 1 else DEFAULT_OUTPUT
        with open(path, "w") as out:
            out.write(text)


if __name__ == "__main__":
    main()
