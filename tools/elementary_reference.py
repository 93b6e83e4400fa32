#!/usr/bin/env python3
"""50-digit reference points for the model's own atan and exp (model/src/elementary.rs).

Each point is [x, hi, lo]: hi is the true value rounded to f64 and lo the f64 nearest to what is
left, so hi + lo is the true value to about 1e-32 relative and a test can measure an error in
fractions of an ulp. The points cover each function's whole input range: atan log-uniformly from
1e-12 to 1e18 (odd symmetry covers the negatives; below 1e-12 atan(x) rounds to x, above 1e18 to
pi/2), densely across its reduction thresholds 0.66 and tan(3 pi/8); exp uniformly over the
arguments whose value is a positive f64, densely near 0 and through the subnormal results.

The draws use a fixed seed, so this regenerates tests/data/elementary_reference.json byte for byte:

    python3 tools/elementary_reference.py > tests/data/elementary_reference.json
"""
import json
import random

import mpmath

mpmath.mp.dps = 50


def point(x, f):
    value = f(mpmath.mpf(x))
    hi = float(value)
    return [x, hi, float(value - hi)]


def atan_points(rng):
    xs = [10 ** rng.uniform(-12, 18) for _ in range(2500)]
    xs += [rng.uniform(0, 3) for _ in range(1500)]
    xs += [t * (1 + rng.uniform(-1e-6, 1e-6)) for t in (0.66, 2.414213562373095) for _ in range(100)]
    return [point(x, mpmath.atan) for x in xs]


def exp_points(rng):
    xs = [rng.uniform(-745.0, 709.7) for _ in range(2500)]
    xs += [rng.uniform(-1, 1) for _ in range(1000)]
    xs += [rng.choice((-1, 1)) * 10 ** rng.uniform(-20, 0) for _ in range(500)]
    xs += [rng.uniform(-745.0, -708.4) for _ in range(300)]
    return [point(x, mpmath.exp) for x in xs]


def main():
    rng = random.Random(1992)
    print(json.dumps({"atan": atan_points(rng), "exp": exp_points(rng)}))


if __name__ == "__main__":
    main()
