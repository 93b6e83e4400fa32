#!/usr/bin/env python3
"""Independent reference for the mean's interval (`stats::summary::mean_interval`).

Hall's transformation of Student's t (Hall, J. R. Statist. Soc. B 54, 1992) for the mean of G
independent groups' means x: with T = (mean - mu) / se, se = sd(x, ddof=1) / sqrt(G), the sample
skewness g = m3 / sd^3 (m3 the third central moment over G) and a = g / (3 sqrt(G)),

    T + a T^2 + a^2 T^3 / 3 + a / 2   lies within   +- t_{0.975, df},

df Satterthwaite's from the residuals r = x - mean: k = (sum r^2)^2 / sum r^4, df = 2 / (1/k -
1/G) rounded down, between 1 and G - 1 (G - 1 where 1/k - 1/G is not positive). So mu lies in
[mean - T(t) se, mean - T(-t) se], T(y) the cubic's real root, which numpy.roots finds here (the
engine writes the root in closed form). Prints:

1. the interval of a few fixed sets of group means, which `model/src/stats/summary.rs`'s tests
   hold to 1e-12;
2. the coverage of this interval, of Hall's transformation with t for G - 1, and of Student's t
   for G - 1 alone, over 20,000 samples each,
   of a lognormal (sigma 1.5, 1.0), an exponential, a normal and Student's t with 3 degrees of
   freedom (symmetric, heavy tails: there the transformation costs coverage), G values of one
   device each.

    python3 tools/skewed_mean_reference.py
"""
import math

import numpy as np
from scipy import stats


def satterthwaite_df(r):
    """Satterthwaite's degrees of freedom from residuals r (rows), as the engine's."""
    g = r.shape[-1]
    squares = (r**2).sum(axis=-1)
    fourths = (r**4).sum(axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        spread = fourths / squares**2 - 1 / g
        df = np.where(spread > 0, 2 / spread, g - 1)
    return np.floor(np.clip(df, 1, max(g - 1, 1)))


def interval(x):
    x = np.asarray(x, dtype=float)
    g = len(x)
    mean = x.mean()
    sd = x.std(ddof=1)
    se = sd / math.sqrt(g)
    t = stats.t.ppf(0.975, satterthwaite_df(x - mean))
    skew = ((x - mean) ** 3).mean() / sd**3
    a = skew / (3 * math.sqrt(g))

    def root(y):
        if a == 0:
            return y
        # a^2/3 T^3 + a T^2 + T + (a/2 - y) = 0: one real root (the cubic only rises).
        roots = np.roots([a * a / 3, a, 1.0, a / 2 - y])
        real = roots[np.abs(roots.imag) < 1e-9 * max(1.0, abs(y))].real
        return real[np.argmin(np.abs(real - y))]

    return float(mean - root(t) * se), float(mean - root(-t) * se)


def coverage(draw, mu, g, reps=20_000, seed=1):
    rng = np.random.default_rng(seed)
    x = draw(rng, (reps, g))
    mean = x.mean(axis=1)
    sd = x.std(axis=1, ddof=1)
    se = sd / math.sqrt(g)
    t_plain = stats.t.ppf(0.975, g - 1)
    t = stats.t.ppf(0.975, satterthwaite_df(x - mean[:, None]))
    plain = np.mean((mean - t_plain * se <= mu) & (mu <= mean + t_plain * se))
    skew = ((x - mean[:, None]) ** 3).mean(axis=1) / sd**3
    a = skew / (3 * math.sqrt(g))

    # The closed-form root, vectorised (checked against numpy.roots above).
    def root(y):
        z = y - a / 2
        c = np.cbrt(1 + 3 * a * z)
        return 3 * z / (c * c + c + 1)

    def covered(t):
        lo = np.minimum(mean - root(t) * se, mean)
        hi = np.maximum(mean - root(-t) * se, mean)
        return np.mean((lo <= mu) & (mu <= hi))

    return covered(t), covered(t_plain), plain


def main():
    fixed = (
        [1.0, 2.0, 3.0, 10.0],
        [0.5, 0.7, 0.6, 0.4, 3.0, 0.55, 0.45, 0.65],
        [-4.0, 1.0, 2.0, 1.5, 2.5],
    )
    for x in fixed:
        lo, hi = interval(x)
        print(f"{x}: [{lo!r}, {hi!r}]")
    cases = [
        ("lognormal sigma 1.5", lambda r, s: r.lognormal(0, 1.5, s), math.exp(1.5**2 / 2)),
        ("lognormal sigma 1.0", lambda r, s: r.lognormal(0, 1.0, s), math.exp(0.5)),
        ("exponential", lambda r, s: r.exponential(1.0, s), 1.0),
        ("normal", lambda r, s: r.normal(1.0, 1.0, s), 1.0),
        ("Student t, 3 df", lambda r, s: r.standard_t(3, s), 0.0),
    ]
    for name, draw, mu in cases:
        for g in (16, 64, 512):
            both, hall, plain = coverage(draw, mu, g)
            print(
                f"{name:22} G {g:4}: this interval {both:.3f}, Hall's with t for G - 1 {hall:.3f},"
                f" Student's t alone {plain:.3f}"
            )


if __name__ == "__main__":
    main()
