#!/usr/bin/env python3
"""Independent reference for `life::observed_b_life`: B-lives read off the Kaplan-Meier curve.

The curve and Greenwood's variance written here from the formulas; at each failure time the
bounds on `F = 1 - R` are Clopper and Pearson's (scipy's beta quantiles) at Greenwood's effective
sample size `n* = F (1 - F) / var(F)` with `F n*` events (Korn & Graubard 1998; Wilson's score
interval where both counts are 100 or more, as the engine's `proportion_interval`), and the
B-life's bounds are the first failure times at which the upper and the lower bound reach `p`
(Brookmeyer & Crowley 1982), the lower one 0 where the bound before any failure reaches it.
Where all at risk fail (R = 0), the bounds are those of n of n at the effective size before. Prints the values that `model/src/life.rs`'s tests hold, for the
6-MP arm of Freireich et al. (1963) as Klein & Moeschberger give it.

    python3 tools/km_quantile_reference.py
"""
import math

from scipy.stats import beta

Z = 1.959963984540054


def proportion_bounds(f, n):
    events = f * n
    if min(events, n - events) >= 100:
        z2n = Z * Z / n
        centre = (f + z2n / 2) / (1 + z2n)
        half = Z / (1 + z2n) * math.sqrt(f * (1 - f) / n + z2n / (4 * n))
        return max(centre - half, 0.0), min(centre + half, 1.0)
    lower = 0.0 if events <= 0 else beta.ppf(0.025, events, n - events + 1)
    upper = 1.0 if events >= n else beta.ppf(0.975, events + 1, n - events)
    return min(lower, f), max(upper, f)


def curve(lives):
    """`(time, F, F's upper bound, F's lower bound)` at 0 and each distinct failure time."""
    times = sorted({t for t, failed in lives if failed})
    # Before the first failure: none of the devices then at risk has failed.
    first_at_risk = sum(1 for s, _ in lives if s >= times[0])
    effective = first_at_risk
    points, reliability, greenwood = [(0.0, 0.0, proportion_bounds(0.0, effective)[1], 0.0)], 1.0, 0.0
    for t in times:
        at_risk = sum(1 for s, _ in lives if s >= t)
        deaths = sum(1 for s, failed in lives if s == t and failed)
        reliability *= 1 - deaths / at_risk
        greenwood += deaths / (at_risk * (at_risk - deaths)) if at_risk > deaths else math.inf
        f = 1 - reliability
        variance = reliability ** 2 * greenwood
        if 0 < variance < math.inf:
            effective = f * reliability / variance
        # All at risk failed (R = 0): n of n of the effective devices before.
        lower, upper = proportion_bounds(f, effective)
        points.append((t, f, upper, lower))
    return points


def b_life(lives, p):
    points = curve(lives)

    def first(column):
        return next((pt[0] for pt in points if pt[column] >= p * (1 - 1e-12)), None)

    return first(1), [first(2), first(3)]


SIX_MP = [(t, True) for t in (6, 6, 6, 7, 10, 13, 16, 22, 23)] + [
    (t, False) for t in (6, 9, 10, 11, 17, 19, 20, 25, 32, 32, 34, 35)]

if __name__ == "__main__":
    for p in (0.1, 0.25, 0.4, 0.5, 0.7):
        print(p, *b_life(SIX_MP, p))
