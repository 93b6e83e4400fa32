#!/usr/bin/env python3
"""Where a quantile read within a sketch bucket to first order holds the exact quantile.

`stats::Sketch::interpolated` spreads a bucket's values evenly and allows twice the first-order
error of that reading, `w rho s (1 - s)` (`rho` the density's change across the bucket from its
neighbours, `s` the share of its values below the quantile); where the logarithm of the density
bends by more than `BENT` = 0.5 across the three buckets it takes the whole bucket instead. For a
normal of standard deviation `sd` read through buckets of width `w`, the bend is `(w / sd)^2`
wherever the buckets lie. This prints, per `w / sd`, at how many of the nine levels x 100 offsets
of the bucket grid the exact quantile lies outside the first-order range, and how many of those
the bend catches: none missed, and none taken whole below `w / sd = 0.7`.

Usage: python3 tools/sketch_reading.py   (numpy, scipy)
"""

import numpy as np
from scipy.stats import norm

BENT = 0.5
LEVELS = [0.01, 0.05, 0.1, 0.25, 0.5, 0.75, 0.9, 0.95, 0.99]


def mass(a, b):
    return norm.cdf(b) - norm.cdf(a)


for k in [0.1, 0.3, 0.5, 0.7, 0.85, 1.0, 1.5, 2.0, 4.0]:
    outside = whole = missed = total = 0
    for offset in np.linspace(0.0, 1.0, 100, endpoint=False):
        for q in LEVELS:
            z = norm.ppf(q)
            lo = offset * k + np.floor((z - offset * k) / k) * k
            here, below, above = mass(lo, lo + k), mass(lo - k, lo), mass(lo + k, lo + 2 * k)
            s = (q - norm.cdf(lo)) / here
            rho = abs(above - below) / (2 * here)
            off = abs(lo + s * k - z) > k * rho * s * (1 - s)
            bent = abs(np.log(above) - 2 * np.log(here) + np.log(below)) > BENT
            total += 1
            outside += off
            whole += bent
            missed += off and not bent
    print(f"w/sd {k:4}: outside the first-order range {outside:3}/{total}, "
          f"taken whole {whole:3}, outside and not taken whole {missed}")
