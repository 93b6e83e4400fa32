#!/usr/bin/env python3
"""Independent 50-digit values of the paper's closed forms of the bounce times (eq. 9, 10, 17, 19)
and of its readings of e off bounce times (eq. 14 through eq. 4, eq. 15), for
tests/data/paper_forms.json:

    python3 tools/paper_forms_reference.py > tests/data/paper_forms.json

Written from docs/model.md section 7 alone; the exact bounce times the readings are applied to
come from `tools/reference.py`'s 50-digit operation. The scenarios are the paper's Fig. 6 and 7
sweep (static force 0.344 to 4.33 N at H = 1 mm), mechanical and at 48 V / 15 A.
"""
import json
import sys

from mpmath import mpf, sqrt

from reference import field, restitution_closed, simulate, to_json

CONSTANT_E = mpf("0.4")
FORCES = ["0.344", "1", "2", "3.2", "4.33"]


def forms(scenario):
    g = lambda section, name: field(scenario, section, name)
    m = g("mechanism", "inertia_kg_m2") / g("mechanism", "contact_arm_m") ** 2
    k = g("mechanism", "spring_stiffness_n_per_m") * g("mechanism", "spring_arm_m") ** 2 / g("mechanism", "contact_arm_m") ** 2
    fs, h = g("mechanism", "static_force_n"), g("mechanism", "drop_height_m")
    u = sqrt((k * h * h + 2 * fs * h) / m)
    kappa = mpf("2.784") * (g("material", "dynamic_yield_pressure_pa") ** 5 * g("material", "contact_radius_m") ** 3
                            / (g("material", "youngs_modulus_pa") ** 4 * m)) ** (mpf(1) / 8)
    per_speed = 2 * m / fs  # eq. 4: T = 2 m v / F_s
    out = {
        "eq9_first_bounce_s": per_speed * u * CONSTANT_E,
        "eq10_total_bounce_s": per_speed * u * CONSTANT_E / (1 - CONSTANT_E),
    }
    vs, i0 = g("circuit", "supply_voltage_v"), g("circuit", "current_a")
    vmin, imin = g("material", "min_arc_voltage_v"), g("material", "min_arc_current_a")
    arcs = vs > vmin and i0 * (vs - vmin) / vs >= imin
    if arcs:
        v1 = u * restitution_closed(u, kappa)
        e2 = min(mpf(1), max(mpf(0), mpf("0.235") + mpf("0.371") * v1))
        out["eq17_first_bounce_s"] = per_speed * v1
        out["eq19_total_bounce_s"] = per_speed * v1 * (1 + e2)
    exact = simulate(scenario, "exact")
    bounces = exact["bounces"]
    out["exact_first_bounce_s"] = exact["first_bounce_s"]
    out["exact_total_bounce_s"] = exact["total_bounce_s"]
    out["e1_eq14_from_exact_first_bounce"] = exact["first_bounce_s"] / (per_speed * u)
    out["exact_e1_effective"] = bounces[0]["separation_velocity_m_s"] / u
    if len(bounces) >= 2:
        out["e2_eq15_from_exact_bounces"] = bounces[1]["duration_s"] / bounces[0]["duration_s"]
        out["exact_e2_effective"] = bounces[1]["separation_velocity_m_s"] / bounces[0]["separation_velocity_m_s"]
    return out


def main():
    cases = []
    for circuit in [{}, {"supply_voltage_v": 48, "current_a": 15}]:
        for force in FORCES:
            scenario = {"mechanism": {"static_force_n": float(force)}}
            if circuit:
                scenario["circuit"] = circuit
            cases.append({"scenario": scenario, "constant_e": float(CONSTANT_E), **to_json(forms(scenario))})
    json.dump({"cases": cases}, sys.stdout, indent=1)
    sys.stdout.write("\n")


if __name__ == "__main__":
    main()
