#!/usr/bin/env python3
"""Independent 50-digit trajectories of one device through an endurance test (docs/model.md
section 6), one per wear law, for tests/data/wear_reference.json.

    python3 tools/wear_reference.py > tests/data/wear_reference.json

Each operation is `tools/reference.py`'s 50-digit operation (written from docs/model.md alone,
sharing no code with the Rust model) on the surface the wear law gives for the arc energy of the
operations before it. Nothing is scattered, so the trajectory is deterministic: it is what a
one-device job with one operation per bin must report, operation by operation.
"""
import json
import re
import sys

from mpmath import exp, mpf

from reference import operation, to_json

OPERATIONS = 1000
ARCING = {"supply_voltage_v": 48, "current_a": 15}

# docs/model.md section 8: the wear defaults.
WORN_RADIUS_M, ROUGHENING_ENERGY_J, EROSION_KG_PER_J = mpf("0.711e-3"), mpf(500), mpf("2e-9")
WORN_PRESSURE_PA, ANNEALING_ENERGY_J = mpf("1e8"), mpf(500)

CASES = {
    "roughening": {"circuit": ARCING},
    "constant": {"circuit": ARCING, "material": {"wear_law": {"law": "constant"}}},
    "roughening_and_softening": {
        "circuit": ARCING,
        "material": {"wear_law": {"law": "roughening_and_softening"}, "anode_erosion_fraction": 0.7},
    },
    "continuous_arc_law_at_5_a": {
        "circuit": {"supply_voltage_v": 48, "current_a": 5},
        "material": {"arc_restitution": {"law": "continuous"}},
    },
}

OPERATION_METRICS = ["kappa", "e1", "first_bounce_s", "total_bounce_s", "bounce_count", "arc_energy_j",
                     "first_impact_plastic_work_j"]


def relax(new, worn, scaled_energy):
    """A surface property relaxing from new to worn: worn + (new - worn) exp(-W / W_scale)."""
    return worn + (new - worn) * exp(-scaled_energy)


def trajectory(scenario):
    material = scenario.get("material", {})
    law = material.get("wear_law", {}).get("law", "roughening")
    r0, p0 = mpf("7.7e-3"), mpf("2e8")

    def surface(energy):
        radius = r0 if law == "constant" else relax(r0, WORN_RADIUS_M, energy / ROUGHENING_ENERGY_J)
        pressure = relax(p0, WORN_PRESSURE_PA, energy / ANNEALING_ENERGY_J) if law == "roughening_and_softening" else p0
        return radius, pressure

    arc_energy, plastic_work = mpf(0), mpf(0)
    rows = {metric: [] for metric in OPERATION_METRICS}
    for _ in range(OPERATIONS):
        radius, pressure = surface(arc_energy)
        out, work = operation(scenario, "exact", radius, pressure)
        out["first_impact_plastic_work_j"] = work
        for metric in OPERATION_METRICS:
            rows[metric].append(out[metric])
        arc_energy += out["arc_energy_j"]
        plastic_work += work
    radius, pressure = surface(arc_energy)
    kappa_at = operation(scenario, "exact", radius, pressure)[0]["kappa"]
    eroded = EROSION_KG_PER_J * arc_energy
    devices = {"cumulative_arc_energy_j": arc_energy, "eroded_mass_kg": eroded, "final_radius_m": radius,
               "final_kappa": kappa_at, "cumulative_plastic_work_j": plastic_work}
    if "anode_erosion_fraction" in material:
        fraction = mpf(material["anode_erosion_fraction"])
        devices["anode_eroded_mass_kg"] = fraction * eroded
        devices["cathode_eroded_mass_kg"] = (1 - fraction) * eroded
    return {"scenario": scenario, "operations": to_json(rows), "devices": to_json(devices)}


if __name__ == "__main__":
    if sys.argv[1:]:
        sys.exit(__doc__)
    text = json.dumps({name: trajectory(scenario) for name, scenario in CASES.items()}, indent=1)
    # One line per list of numbers.
    print(re.sub(r"\[\s+([^\[\]{}]*?)\s+\]", lambda m: "[" + " ".join(m.group(1).split()) + "]", text))
