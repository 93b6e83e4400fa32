#!/usr/bin/env python3
"""Independent reference for `life::weibayes`'s chi-square quantiles, far in either tail.

    pip install mpmath
    python3 tools/chi_square_reference.py

`chi2(p; 2m)` is twice the `p` quantile of the gamma distribution of shape `m`. At 60 digits,
bisection in `ln y` (400 halvings) on mpmath's regularised incomplete gamma: the lower tail
`gammainc(m, 0, y)` against `p` at or below the median, the upper tail `gammainc(m, y, inf)`
against `1 - p` above it, `p` taken as the exact binary value of the f64. Prints the table that
`chi_square_quantiles_hold_far_in_both_tails` holds.
"""
import mpmath as mp

mp.mp.dps = 60

CASES = [
    (0.9999999999999999, 2),
    (0.999999999999, 2),
    (0.99999999, 4),
    (0.9999999999999999, 301),
    (1e-300, 2),
    (1e-300, 4),
    (1e-100, 4),
    (5e-324, 2),
    (0.5, 3),
    (0.75, 1000),
]


def quantile(p, m):
    p, m = mp.mpf(p), mp.mpf(m)
    lower = p <= mp.mpf(0.5)

    def below(ln_y):
        y = mp.e**ln_y
        if lower:
            return mp.gammainc(m, 0, y, regularized=True) < p
        return mp.gammainc(m, y, mp.inf, regularized=True) > 1 - p

    lo, hi = mp.mpf(-800), mp.mpf(10)
    while below(hi):
        hi += 1
    for _ in range(400):
        mid = (lo + hi) / 2
        lo, hi = (mid, hi) if below(mid) else (lo, mid)
    return 2 * mp.e ** ((lo + hi) / 2)


for p, m in CASES:
    print(f"({p!r}, {m}, {float(quantile(p, m))!r}),")
