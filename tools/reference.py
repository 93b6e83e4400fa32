#!/usr/bin/env python3
"""Independent 50-digit evaluation of docs/model.md sections 1-5 (mpmath), for accuracy checks.

    python3 tools/reference.py check            # reproduce tests/data/validation_cases.json
    python3 tools/reference.py spread > tests/data/reference_spread.json

Written from the model's specification (docs/model.md) alone, sharing no code or algorithm with the
Rust model: eq. 7 is solved by bisection on s = e^2 in s^2 = q (1 - 3s/8)^(3/2), flights use atan2
and sqrt(d^2 + x^2) - d at 50 digits, where cancellation does not matter.
"""
import json
import random
import sys

from mpmath import atan2, mp, mpf, pi, sqrt

mp.dps = 50

DEFAULTS = {
    "mechanism": {"inertia_kg_m2": 1.593e-5, "spring_stiffness_n_per_m": 200, "spring_arm_m": 0.03,
                  "contact_arm_m": 0.03, "static_force_n": 0.344, "drop_height_m": 1e-3, "impact_velocity_m_s": None},
    "material": {"youngs_modulus_pa": 1.0e11, "dynamic_yield_pressure_pa": 2.0e8, "contact_radius_m": 7.7e-3,
                 "kappa": None, "min_arc_voltage_v": 12, "min_arc_current_a": 0.4, "breakdown_field_v_per_m": 1e8,
                 "softening_energy_j": 6.2e-4,
                 "arc_restitution": {"law": "continuous", "a": 0.235, "b_s_per_m": 0.371, "calibration_current_a": 15}},
    "circuit": {"supply_voltage_v": 0, "current_a": 0},
    "losses": {"impact_energy_loss_j": 1e-6, "min_separation_m": 1e-7, "max_bounces": 64},
}


def field(scenario, section, name):
    value = scenario.get(section, {}).get(name, DEFAULTS[section][name])
    return None if value is None else mpf(value)


def restitution_exact(u, kappa):
    if u == 0:
        return mpf(1)
    q = kappa ** 4 / u
    if q >= (mpf(8) / 5) ** mpf(1.5):
        return mpf(1)
    lo, hi = sqrt(q) / 2, min(mpf(1), sqrt(q))
    for _ in range(260):
        mid = (lo + hi) / 2
        if mid * mid - q * (1 - 3 * mid / 8) ** mpf(1.5) > 0:
            hi = mid
        else:
            lo = mid
    return sqrt((lo + hi) / 2)


def restitution_closed(u, kappa):
    return mpf(1) if u == 0 else min(mpf(1), kappa / u ** mpf(0.25))


def simulate(scenario, fidelity):
    """The `simulate` output of docs/contract.md "Scenario"."""
    return operation(scenario, fidelity)[0]


def operation(scenario, fidelity, radius=None, pressure=None):
    """One operation on a surface of the given radius and pressure (the scenario's when None): the
    `simulate` output and the first impact's plastic work (docs/model.md section 4)."""
    g = lambda section, name: field(scenario, section, name)
    m = g("mechanism", "inertia_kg_m2") / g("mechanism", "contact_arm_m") ** 2
    k = g("mechanism", "spring_stiffness_n_per_m") * g("mechanism", "spring_arm_m") ** 2 / g("mechanism", "contact_arm_m") ** 2
    fs = g("mechanism", "static_force_n")
    h = g("mechanism", "drop_height_m")
    u = g("mechanism", "impact_velocity_m_s")
    if u is None:
        u = sqrt((k * h * h + 2 * fs * h) / m)
    p0, r0, e_mod = g("material", "dynamic_yield_pressure_pa"), g("material", "contact_radius_m"), g("material", "youngs_modulus_pa")
    p = p0 if pressure is None else mpf(pressure)
    r = r0 if radius is None else mpf(radius)
    kappa = g("material", "kappa")
    if kappa is None:
        kappa = mpf("2.784") * (p ** 5 * r ** 3 / (e_mod ** 4 * m)) ** (mpf(1) / 8)
    else:
        kappa = kappa * (r / r0) ** (mpf(3) / 8) * (p / p0) ** (mpf(5) / 8)
    vs, i0 = g("circuit", "supply_voltage_v"), g("circuit", "current_a")
    vmin, imin = g("material", "min_arc_voltage_v"), g("material", "min_arc_current_a")
    i_arc = i0 * (vs - vmin) / vs if vs > 0 else mpf(0)
    arcs = vs > vmin and i_arc >= imin and i_arc > 0
    power = vmin * i_arc if arcs else mpf(0)
    law = dict(DEFAULTS["material"]["arc_restitution"], **scenario.get("material", {}).get("arc_restitution", {}))
    a, b = mpf(law["a"]), mpf(law["b_s_per_m"])
    # docs/model.md section 5: the continuous law weights the arc's effect on restitution by
    # w = (I_arc - I_min) / (I_arc at the calibration current - I_min), within [0, 1].
    weight = mpf(1)
    if law["law"] == "continuous" and arcs:
        i_cal = mpf(law["calibration_current_a"]) * (vs - vmin) / vs
        weight = min(mpf(1), max(mpf(0), (i_arc - imin) / (i_cal - imin)))
    eps = g("losses", "impact_energy_loss_j")
    gmin = g("losses", "min_separation_m")
    max_bounces = int(g("losses", "max_bounces"))
    closed = fidelity == "closed_form"
    e_of = restitution_closed if closed else restitution_exact

    out = {"impact_velocity_m_s": u, "kappa": kappa, "e1": mpf(0), "first_bounce_s": mpf(0), "total_bounce_s": mpf(0),
           "bounce_count": 0, "pre_arc_s": mpf(0), "arc_energy_j": mpf(0), "peak_force_n": mpf(0),
           "impact_duration_s": mpf(0), "truncated": False, "bounces": []}
    if u == 0:
        return out, mpf(0)
    kappa1, p1 = kappa, p
    if arcs:
        tp = vs / g("material", "breakdown_field_v_per_m") / u
        ep = power * tp
        p1 = p / (1 + weight * ep / g("material", "softening_energy_j"))
        kappa1 = kappa * (p1 / p) ** (mpf(5) / 8)
        out["pre_arc_s"], out["arc_energy_j"] = tp, ep
    e1 = e_of(u, kappa1)
    out["e1"] = e1
    kc = pi * r * p1
    fmax = fs + sqrt(fs * fs + kc * m * u * u)
    wc = sqrt(kc / m)
    out["peak_force_n"] = fmax
    out["impact_duration_s"] = (pi - atan2(u * wc * m, fs)) / wc + mpf("1.8395") * m * e1 * u / fmax
    # The work of the fully plastic loading, k_c d_max^2 / 2 with d_max = F_max / k_c.
    plastic_work = fmax * fmax / (2 * kc)

    constant_force = (closed and fs > 0) or k == 0
    w = sqrt(k / m)

    def flight(v):
        if constant_force:
            return 2 * v * m / fs, v * v * m / (2 * fs)
        d, x = fs / k, v / w
        return 2 / w * atan2(v * w * m, fs), sqrt(d * d + x * x) - d

    v = sqrt(max(mpf(0), e1 * e1 * u * u - 2 * eps / m))
    while v > 0:
        duration, gap = flight(v)
        if gap < gmin:
            break
        if out["bounce_count"] == max_bounces:
            out["truncated"] = True
            break
        out["bounce_count"] += 1
        out["total_bounce_s"] += duration
        if out["bounce_count"] == 1:
            out["first_bounce_s"] = duration
        energy = power * duration
        out["arc_energy_j"] += energy
        out["bounces"].append({"separation_velocity_m_s": v, "duration_s": duration, "peak_gap_m": gap, "arc_energy_j": energy})
        if arcs:
            mechanical = e_of(v, kappa1)
            e = (1 - weight) * mechanical + weight * min(mechanical, max(mpf(0), a + b * v))
        else:
            e = e_of(v, kappa)
        v = sqrt(max(mpf(0), e * e * v * v - 2 * eps / m))
    return out, plastic_work


def to_json(value):
    if isinstance(value, dict):
        return {key: to_json(item) for key, item in value.items()}
    if isinstance(value, list):
        return [to_json(item) for item in value]
    if isinstance(value, (bool, int)):
        return value
    return float(value)


def spread(count=80, seed=1992):
    """Scenarios spread over the rig's plausible range: mechanical and arcing, soft and stiff springs."""
    rng = random.Random(seed)
    log_uniform = lambda lo, hi: 10 ** rng.uniform(__import__("math").log10(lo), __import__("math").log10(hi))
    cases = []
    for i in range(count):
        scenario = {"mechanism": {"static_force_n": log_uniform(0.05, 5.0), "drop_height_m": log_uniform(2e-4, 3e-3),
                                  "spring_stiffness_n_per_m": 0 if i % 7 == 0 else log_uniform(20, 2000)},
                    "material": {"contact_radius_m": log_uniform(1e-3, 1e-2),
                                 "dynamic_yield_pressure_pa": log_uniform(5e7, 1e9)}}
        if i % 2 == 1:
            scenario["circuit"] = {"supply_voltage_v": log_uniform(20, 250), "current_a": log_uniform(1, 30)}
        if i % 5 == 0:
            scenario["material"]["kappa"] = log_uniform(0.1, 1.0)
        cases.append({"scenario": scenario,
                      "exact": to_json(simulate(scenario, "exact")),
                      "closed_form": to_json(simulate(scenario, "closed_form"))})
    return cases


def check():
    cases = json.load(open(__file__.rsplit("/", 2)[0] + "/tests/data/validation_cases.json"))
    worst = 0.0
    for name, case in cases.items():
        for fidelity in ("exact", "closed_form"):
            got = to_json(simulate(case["scenario"], fidelity))
            want = case[fidelity]
            assert got["bounce_count"] == want["bounce_count"] and got["truncated"] == want["truncated"], name
            for key, value in want.items():
                if isinstance(value, float) and value != 0:
                    worst = max(worst, abs(got[key] - value) / abs(value))
    print(f"validation cases reproduced; worst relative difference {worst:.2e}")


if __name__ == "__main__":
    if sys.argv[1:] == ["check"]:
        check()
    elif sys.argv[1:] == ["spread"]:
        json.dump(spread(), sys.stdout, indent=1)
    else:
        sys.exit(__doc__)
