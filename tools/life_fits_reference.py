#!/usr/bin/env python3
"""Independent reference for `model/src/life/fits.rs`: the candidate life distributions fitted by
maximum likelihood with right censoring, and their ranking.

    pip install scipy reliability==0.9.0
    python3 tools/life_fits_reference.py          # writes tests/data/life_fits_reference.json
    python3 tools/life_fits_reference.py -        # or prints it

For the data sets of `tools/weibull_reference.py` (the same splitmix64 draws as the Rust tests),
each distribution is fitted with scipy's own censored likelihood (logpdf of the failures plus
logsf of the suspensions), maximised by Nelder-Mead with tight
tolerances from scipy's own start, never from the Rust module's:

* `weibull`: `weibull_min(c=beta, scale=eta)`, location 0;
* `lognormal`: `lognorm(s=sigma, scale=exp(mu))`, location 0 (mu and sigma of ln t);
* `gamma`: `gamma(a=shape, scale=scale)`, location 0, from the failures' moments;
* `exponential`: `expon(scale=1/lambda)`, location 0; its maximum is also `failures / total time`;
* `weibull_3p`: `weibull_min(c=beta, loc=gamma, scale=eta)` (`weibull_3p`): the profile over gamma
  scanned for a local maximum inside (0, t_1) with beta > 1, polished by Nelder-Mead over all three
  parameters; null where there is none, with the reason. `reliability`'s `Fit_Weibull_3P` on the
  same lives is recorded beside it (`reliability_weibull_3p`): its bounded search ends at the
  boundary gamma -> t_1 where the likelihood grows without bound;
* the Weibull's likelihood-ratio 95 % bounds on B1 and B10 (`weibull_lr_bounds`);
* each fit's Anderson-Darling statistic by the `reliability` package's own plotting positions and
  formula (`reliability.Utils.anderson_darling`, as its fitters call it), at scipy's fit.

AICc = 2k - 2 lnL + 2k(k + 1)/(n - k - 1) and BIC = k ln n - 2 lnL, n the devices. Shares no code
with the Rust module: only the data generator.
"""
import json
import math
import os
import sys

import numpy as np
import scipy.optimize as so
import scipy.stats as ss

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from weibull_reference import DATASETS, SplitMix, versions  # noqa: E402  (the shared data sets)

DEFAULT_OUTPUT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests", "data",
                              "life_fits_reference.json")


def maximise(data, family, start, to_kwargs):
    """The maximum of scipy's censored log-likelihood: logpdf at the failures, logsf at the
    suspensions."""
    failures = np.array([t for t, failed in data if failed])
    suspensions = np.array([t for t, failed in data if not failed])

    def negative(x):
        kwargs = to_kwargs(x)
        value = -family.logpdf(failures, **kwargs).sum() - family.logsf(suspensions, **kwargs).sum()
        return value if math.isfinite(value) else 1e300

    best = so.fmin(negative, start, xtol=1e-12, ftol=1e-14, maxiter=100000, maxfun=200000, disp=0)
    best = so.fmin(negative, best, xtol=1e-13, ftol=1e-15, maxiter=100000, maxfun=200000, disp=0)
    return best, -negative(best)


def criteria(log_likelihood, k, n):
    aicc = 2 * k - 2 * log_likelihood + (2 * k * (k + 1) / (n - k - 1) if n - k - 1 > 0 else math.nan)
    return {"log_likelihood": log_likelihood, "aicc": aicc if math.isfinite(aicc) else None,
            "bic": k * math.log(n) - 2 * log_likelihood}


def weibull_lr_bounds(data, beta, eta, p):
    """Likelihood-ratio 95 % bounds on B_p = eta (-ln(1 - p))^(1/beta): the times t where the
    profile log-likelihood, maximised over beta with eta = t / (-ln(1 - p))^(1/beta), is
    chi2(0.95; 1) / 2 below the maximum. scipy's bounded scalar minimiser for the profile, brentq
    for the two crossings."""
    failures = np.array([t for t, failed in data if failed])
    suspensions = np.array([t for t, failed in data if not failed])
    k = -math.log1p(-p)

    def ll(b, e):
        return (ss.weibull_min.logpdf(failures, b, scale=e).sum()
                + ss.weibull_min.logsf(suspensions, b, scale=e).sum())

    top = ll(beta, eta)
    drop = ss.chi2.ppf(0.95, 1) / 2

    def profile(ln_t):
        res = so.minimize_scalar(lambda u: -ll(math.exp(u), math.exp(ln_t - math.log(k) / math.exp(u))),
                                 bounds=(math.log(beta) - 4, math.log(beta) + 4), method="bounded",
                                 options={"xatol": 1e-12, "maxiter": 2000})
        return -res.fun

    centre = math.log(eta) + math.log(k) / beta
    bounds = []
    for side in (-1.0, 1.0):
        step = 0.01
        while profile(centre + side * step) > top - drop:
            step *= 2
        far = centre + side * step
        lo, hi = sorted((centre, far))
        root = so.brentq(lambda x: profile(x) - (top - drop), lo, hi, xtol=1e-14, rtol=1e-14)
        bounds.append(math.exp(root))
    return bounds


def shifted(seed, n, gamma, beta, eta, end):
    """n devices with a failure-free life: floor(gamma + a Weibull(beta, eta) draw) + 1 operations,
    censored at `end` (the splitmix64 draws of `tools/weibull_reference.py`)."""
    rng = SplitMix(seed)
    data = []
    for _ in range(n):
        life = math.floor(gamma + eta * (-math.log1p(-rng.uniform())) ** (1.0 / beta)) + 1.0
        data.append((life, True) if life <= end else (end, False))
    return data


# Data sets of this table only, written into it with their lives: a failure-free life of 800
# operations under a Weibull(2, 400), censored at 1300.
LOCATION_DATASETS = {"shifted": shifted(6, 30, 800.0, 2.0, 400.0, 1300.0)}


def weibull_3p(data):
    """The three-parameter Weibull's maximum, or None and why. The profile log-likelihood over
    gamma (scipy's two-parameter censored fit of t - gamma) on a grid of t_1 - gamma, t_1 the
    earliest life, evenly in its logarithm from t_1 down to t_1 e^-14; the best grid point inside
    with a neighbour on each side lower and beta > 1 is refined by scipy's bounded scalar
    minimiser between its neighbours and polished by Nelder-Mead over (ln eta, ln beta, gamma)."""
    failures = np.array([t for t, failed in data if failed])
    suspensions = np.array([t for t, failed in data if not failed])
    first = min(t for t, _ in data)

    def ll(beta, eta, gamma):
        if not (0 <= gamma < first):
            return -math.inf
        return (ss.weibull_min.logpdf(failures, beta, loc=gamma, scale=eta).sum()
                + ss.weibull_min.logsf(suspensions, beta, loc=gamma, scale=eta).sum())

    def profile(gamma):
        def negative(x):
            value = -ll(math.exp(x[1]), math.exp(x[0]), gamma)
            return value if math.isfinite(value) else 1e300
        x = so.fmin(negative, [np.log(failures - gamma).mean(), 0.0], xtol=1e-10, ftol=1e-12,
                    maxiter=100000, maxfun=200000, disp=0)
        return -negative(x), math.exp(x[1]), math.exp(x[0])

    grid = [0.0] + [first - first * math.exp(-14.0 * j / 70) for j in range(1, 71)]
    values = [profile(g) for g in grid]
    peaks = [j for j in range(1, 70)
             if values[j][0] >= values[j - 1][0] and values[j][0] >= values[j + 1][0] and values[j][1] > 1]
    if not peaks:
        return None, "no local maximum inside (0, t_1) with beta > 1"
    j = max(peaks, key=lambda j: values[j][0])
    gamma = so.minimize_scalar(lambda g: -profile(g)[0], bounds=(grid[j - 1], grid[j + 1]),
                               method="bounded", options={"xatol": 1e-9 * first}).x
    _, beta, eta = profile(gamma)

    def negative(x):
        value = -ll(math.exp(x[1]), math.exp(x[0]), x[2])
        return value if math.isfinite(value) else 1e300

    x = [math.log(eta), math.log(beta), gamma]
    for _ in range(3):
        x = so.fmin(negative, x, xtol=1e-12, ftol=1e-15, maxiter=100000, maxfun=200000, disp=0)
    if not (x[2] > 0 and -negative(x) > values[0][0]):
        return None, "the best location is 0: the two-parameter Weibull"
    return {"beta": math.exp(x[1]), "eta": math.exp(x[0]), "gamma": x[2]}, -negative(x)


def reliability_weibull_3p(data):
    """`reliability`'s own three-parameter fit, for the record."""
    from reliability.Fitters import Fit_Weibull_3P
    fit = Fit_Weibull_3P(failures=[t for t, f in data if f],
                         right_censored=[t for t, f in data if not f] or None,
                         show_probability_plot=False, print_results=False)
    return {"beta": fit.beta, "eta": fit.alpha, "gamma": fit.gamma, "log_likelihood": fit.loglik}


def fits(data):
    n = len(data)
    failures = [t for t, failed in data if failed]
    logs = [math.log(t) for t in failures]
    mean = sum(logs) / len(logs)
    sd = math.sqrt(sum((x - mean) ** 2 for x in logs) / max(len(logs) - 1, 1)) or 1.0
    out = {}
    (ln_eta, ln_beta), ll = maximise(data, ss.weibull_min, [mean, 0.0],
                                     lambda x: {"c": math.exp(x[1]), "scale": math.exp(x[0])})
    out["weibull"] = {"beta": math.exp(ln_beta), "eta": math.exp(ln_eta), **criteria(ll, 2, n)}
    for p, name in ((0.01, "b1"), (0.1, "b10")):
        lower, upper = weibull_lr_bounds(data, math.exp(ln_beta), math.exp(ln_eta), p)
        out["weibull"][name + "_lr_lower"] = lower
        out["weibull"][name + "_lr_upper"] = upper
    (mu, ln_sigma), ll = maximise(data, ss.lognorm, [mean, math.log(sd)],
                                  lambda x: {"s": math.exp(x[1]), "scale": math.exp(x[0])})
    out["lognormal"] = {"mu": mu, "sigma": math.exp(ln_sigma), **criteria(ll, 2, n)}
    fm = sum(failures) / len(failures)
    fv = sum((t - fm) ** 2 for t in failures) / len(failures)
    (ln_shape, ln_theta), ll = maximise(data, ss.gamma, [math.log(fm * fm / fv), math.log(fv / fm)],
                                        lambda x: {"a": math.exp(x[0]), "scale": math.exp(x[1])})
    out["gamma"] = {"shape": math.exp(ln_shape), "scale": math.exp(ln_theta), **criteria(ll, 2, n)}
    (ln_scale,), ll = maximise(data, ss.expon, [math.log(sum(t for t, _ in data) / len(failures))],
                               lambda x: {"scale": math.exp(x[0])})
    out["exponential"] = {"lambda": math.exp(-ln_scale), **criteria(ll, 1, n)}
    location, ll = weibull_3p(data)
    if location is None:
        out["weibull_3p"] = None
        out["weibull_3p_absent"] = ll
    else:
        out["weibull_3p"] = {**location, **criteria(ll, 3, n)}
    out["reliability_weibull_3p"] = reliability_weibull_3p(data)
    # The Anderson-Darling statistic as the reliability package computes it: its own plotting
    # positions and its own formula, with scipy's CDF at scipy's fit.
    from reliability.Probability_plotting import plotting_positions
    from reliability.Utils import anderson_darling
    x, y = plotting_positions(failures=failures, right_censored=[t for t, f in data if not f] or None)
    cdfs = {
        "weibull": lambda t: ss.weibull_min.cdf(t, out["weibull"]["beta"], scale=out["weibull"]["eta"]),
        "lognormal": lambda t: ss.lognorm.cdf(t, out["lognormal"]["sigma"], scale=math.exp(out["lognormal"]["mu"])),
        "gamma": lambda t: ss.gamma.cdf(t, out["gamma"]["shape"], scale=out["gamma"]["scale"]),
        "exponential": lambda t: ss.expon.cdf(t, scale=1 / out["exponential"]["lambda"]),
    }
    if out["weibull_3p"] is not None:
        w = out["weibull_3p"]
        cdfs["weibull_3p"] = lambda t: ss.weibull_min.cdf(t, w["beta"], loc=w["gamma"], scale=w["eta"])
    for name, cdf in cdfs.items():
        out[name]["anderson_darling"] = float(anderson_darling(fitted_cdf=cdf(np.asarray(x)), empirical_cdf=y))
    candidates = [d for d in cdfs]
    out["best_by_aicc"] = min(candidates, key=lambda d: out[d]["aicc"] if out[d]["aicc"] is not None else math.inf)
    return out


def main():
    table = {"generator": "tools/life_fits_reference.py", "versions": versions(),
             "datasets": {name: {"n": len(data), "failures": sum(f for _, f in data), **fits(data),
                                 **({"data": data} if name in LOCATION_DATASETS else {})}
                          for name, data in {**DATASETS, **LOCATION_DATASETS}.items()}}
    text = json.dumps(table, indent=2, sort_keys=True) + "\n"
    if sys.argv[1:] == ["-"]:
        sys.stdout.write(text)
    else:
        with open(sys.argv[1] if sys.argv[1:] else DEFAULT_OUTPUT, "w") as f:
            f.write(text)


if __name__ == "__main__":
    main()
