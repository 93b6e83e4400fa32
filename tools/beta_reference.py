#!/usr/bin/env python3
"""Independent references for model/src/stats/beta.rs and intervals.rs, by mpmath at 40 digits:

- the regularised incomplete beta function I_x(a, b) (mpmath's betainc, regularized=True);
- Clopper and Pearson's 95 % interval at a fractional count x out of n, Korn and Graubard's way:
  n* = n_eff (z / t)^2, x* = p n*; lower end solves I_L(x*, n* - x* + 1) = 0.025 (0 at x* = 0),
  upper end I_U(x* + 1, n* - x*) = 0.975, each by mpmath's root finder on the exact betainc
  (bisection of ln v, bracketed), not by the engine's Newton.

Prints the rows of beta.rs's REGULARIZED and intervals.rs's CLOPPER_PEARSON tables, each value the
f64 nearest the 40-digit one.
Usage: python3 tools/beta_reference.py   (pip install mpmath)"""

import mpmath as mp

mp.mp.dps = 40
Z_975 = mp.mpf("1.959963984540054")

REGULARIZED = [
    (0.3, 5.0, 0.1),
    (2.5, 7.5, 0.6),
    (50.0, 50.0, 0.5),
    (0.5, 0.5, 0.999),
    (1.0, 1e12, 1e-12),
    (3.0, 1e9, 3e-9),
    (3.0, 1e9, 1.2e-8),
    (101.0, 1e7, 1.1e-5),
    (101.0, 1e7, 0.8e-5),
    (0.001, 1000.0, 1e-5),
    (7.25, 2000.5, 0.01),
    (40.0, 1e15, 2e-14),
]

# (p, n_eff, t): t is Z_975 for independent values, or Student's t_{0.975, df}.
PROPORTIONS = [
    (0.0, 512.0, "2.0395134463964077"),
    (3.0 / 10240.0, 10240.0, None),
    (1.0 / 1e6, 1e6, None),
    (2.0 / 1e9, 1e9, None),
    (4.0 / 1e7, 2.5e6, "2.0395134463964077"),
    (0.3, 7.5, None),
    (0.995, 2000.0, None),
    (1.0, 40.0, None),
    (50.0 / 1e4, 1e4, "2.2621571627982053"),
    (0.137, 300.0, None),
]


def interval(p, n_eff, t):
    t = Z_975 if t is None else mp.mpf(t)
    n = mp.mpf(n_eff) * (Z_975 / t) ** 2
    x = mp.mpf(p) * n
    if x > n / 2:
        lo, hi = clopper_pearson(n - x, n)
        return 1 - hi, 1 - lo
    return clopper_pearson(x, n)


def solve(a, b, level, hint):
    """Bisection of ln v on the exact betainc, from a bracket around `hint`, to 1e-30."""
    f = lambda v: mp.betainc(a, b, 0, v, regularized=True) - level
    lo, hi = mp.log(hint) - 60, mp.log(min(hint * 1000, mp.mpf("0.999999")))
    assert f(mp.exp(lo)) < 0 < f(mp.exp(hi))
    while hi - lo > mp.mpf(10) ** -30:
        mid = (lo + hi) / 2
        if f(mp.exp(mid)) < 0:
            lo = mid
        else:
            hi = mid
    return mp.exp((lo + hi) / 2)


def clopper_pearson(x, n):
    centre = (x + 1) / n
    lo = 0 if x == 0 else solve(x, n - x + 1, mp.mpf("0.025"), centre)
    hi = solve(x + 1, n - x, mp.mpf("0.975"), centre)
    return lo, hi


def main():
    print("REGULARIZED: (a, b, x, I)")
    for a, b, x in REGULARIZED:
        value = mp.betainc(a, b, 0, x, regularized=True)
        print(f"    ({a!r}, {b!r}, {x!r}, {float(value)!r}),")
    print("CLOPPER_PEARSON: (p, n_eff, t, lo, hi)")
    for p, n_eff, t in PROPORTIONS:
        lo, hi = interval(p, n_eff, t)
        t_text = "Z_975" if t is None else t
        print(f"    ({p!r}, {n_eff!r}, {t_text}, {float(lo)!r}, {float(hi)!r}),")


if __name__ == "__main__":
    main()
