#!/usr/bin/env python3
"""P(T_a > T_b) of two Weibull lives by scipy's adaptive quadrature, independent of the engine's
trapezoid on ln w (model/src/life/compare.rs): int_0^inf f_b(t) R_a(t) dt, split at b's quantiles so
that quad sees every peak. Prints the rows of compare.rs's REFERENCE table."""

import numpy as np
from scipy import integrate
from scipy.stats import weibull_min

CASES = [
    (1000.0, 2.0, 800.0, 3.5),
    (866.0, 26.4, 900.0, 1.3),
    (1.0, 0.5, 1.0, 8.0),
    (5e4, 12.0, 1e4, 12.0),
    (1e3, 1.0, 2e3, 40.0),
    (1e6, 3.0, 1.0, 0.3),
]


def outlasts(eta_a, beta_a, eta_b, beta_b):
    fb = weibull_min(beta_b, scale=eta_b)
    ra = weibull_min(beta_a, scale=eta_a)
    # Integrate over u = F_b(t) in pieces: P = int_0^1 R_a(F_b^-1(u)) du.
    f = lambda u: ra.sf(fb.isf(1.0 - u)) if 0.0 < u < 1.0 else (1.0 if u <= 0.0 else 0.0)
    edges = np.concatenate([[0.0], np.logspace(-12, -1, 12), np.linspace(0.2, 0.9, 8), 1.0 - np.logspace(-2, -12, 11), [1.0]])
    total = 0.0
    for lo, hi in zip(edges[:-1], edges[1:]):
        value, _ = integrate.quad(f, lo, hi, epsabs=0.0, epsrel=1e-11, limit=500)
        total += value
    return total


if __name__ == "__main__":
    for case in CASES:
        print("({!r}, {!r}, {!r}, {!r}, {!r}),".format(*case, outlasts(*case)))
