#!/usr/bin/env python3
"""The NumPy peer: the reference jobs of tests/data/reference_jobs.json, written as a user would write
them in NumPy, vectorised across devices, to measure what the Rust engine is worth against it.

    python3 tools/numpy_peer.py '<job JSON>'        # prints the statistics and the compute time

It follows docs/model.md sections 1-6 for the paper's rig (every scenario default), the paper's arc
law, roughening wear and the exact tier (eq. 7 by Newton's method, eq. 3 flights): one array per
quantity over the devices, one Python step per operation, the bounce loop masked per device until
every device has stopped. Draws come from NumPy's generator, not ChaCha8: the statistics agree with
the engine's within their sampling error, not to the bit. It reports, per bin of operations and per
metric, what a Result reports: n, mean, sd, min, max, the nine quantiles, a 20-bin histogram and the
batch-means 95 % interval of the mean over 32 groups; and the same for the device metrics.

Only what the reference jobs use is implemented; any other job is refused.
"""
import json
import sys
import time

import numpy as np

QUANTILES = [0.01, 0.05, 0.10, 0.25, 0.50, 0.75, 0.90, 0.95, 0.99]
GROUPS = 32
T_975_31 = 2.0395134463964077  # Student t, 0.975, 31 degrees of freedom


def restitution(u, kappa):
    """Eq. 7: e = eps0 sqrt(z), z^4 = (1 - a z)^3, a = 3 eps0^2 / 8; e = 1 at and above (8/5)^(3/8)."""
    eps0 = kappa / np.sqrt(np.sqrt(u))
    a = 0.375 * eps0 * eps0
    z = np.ones_like(a)
    for _ in range(6):
        c = 1.0 - a * z
        z2 = z * z
        z = z - (z2 * z2 - c * c * c) / (4.0 * z2 * z + 3.0 * a * c * c)
    return np.where(eps0 >= 1.6**0.375, 1.0, np.minimum(eps0 * np.sqrt(z), 1.0))


def truncated_normal(rng, mean, sd, low, size):
    x = rng.normal(mean, sd, size)
    while (bad := x < low).any():
        x[bad] = rng.normal(mean, sd, bad.sum())
    return x


def summary(values, groups):
    """A Result's SUMMARY of `values` (1-D), with `groups` the group of each value."""
    lo, hi = float(values.min()), float(values.max())
    counts, edges = np.histogram(values, bins=20, range=(lo, hi) if hi > lo else (lo, lo + 1))
    means = np.bincount(groups, weights=values, minlength=GROUPS) / np.bincount(groups, minlength=GROUPS)
    half = T_975_31 * means.std(ddof=1) / np.sqrt(GROUPS)
    mean = float(values.mean())
    return {
        "n": int(values.size), "mean": mean, "mean_ci95": [mean - half, mean + half],
        "sd": float(values.std(ddof=1)), "min": lo, "max": hi,
        "quantiles": {f"p{round(q * 100):02d}": float(v)
                      for q, v in zip(QUANTILES, np.quantile(values, QUANTILES, method="inverted_cdf"))},
        "histogram": {"edges": edges.tolist(), "counts": counts.tolist()},
    }


def run(job):
    assert {s["parameter"] for s in job["scatter"]} == {
        "contact_radius_m", "dynamic_yield_pressure_pa", "impact_velocity_m_s"}, "reference jobs only"
    circuit = job.get("scenario", {}).get("circuit", {"supply_voltage_v": 0, "current_a": 0})
    devices, operations = job["devices"], job["operations"]
    bin_operations = max(operations // 10, 1)
    rng = np.random.default_rng(job["seed"])
    by_name = {s["parameter"]: s["distribution"] for s in job["scatter"]}

    # The paper's rig (docs/model.md section 8), referred to the contact (eq. 1).
    m, k, fs = 1.593e-5 / 0.03**2, 200.0, 0.344
    r0, p0, youngs = 7.7e-3, 2e8, 1e11
    kappa_ref = 2.784 * p0**0.625 * r0**0.375 / (youngs**0.5 * m**0.125)
    omega = np.sqrt(k / m)
    loss_sq = 2.0 * 1e-6 / m
    g_min = 1e-7
    min_speed = np.sqrt(g_min) * np.sqrt((k * g_min + 2.0 * fs) / m)
    vs, current = circuit["supply_voltage_v"], circuit["current_a"]
    arc_current = current * (vs - 12.0) / vs if vs > 12.0 else 0.0
    arcs = vs > 12.0 and arc_current >= 0.4
    power, gap, softening = 12.0 * arc_current, vs / 1e8, 6.2e-4

    radius = by_name["contact_radius_m"]
    radius0 = truncated_normal(rng, radius["mean"], radius["sd"], radius["min"], devices)
    pressure = by_name["dynamic_yield_pressure_pa"]
    pressure0 = pressure["median"] * np.exp(pressure["sigma"] * rng.standard_normal(devices))
    speed = by_name["impact_velocity_m_s"]

    names = ["impact_velocity_m_s", "kappa", "e1", "first_bounce_s", "total_bounce_s", "bounce_count",
             "pre_arc_s", "arc_energy_j", "peak_force_n", "impact_duration_s", "first_impact_plastic_work_j"]
    out = {name: np.empty((operations, devices)) for name in names}
    energy = np.zeros(devices)
    work = np.zeros(devices)
    for op in range(operations):
        u = truncated_normal(rng, speed["mean"], speed["sd"], speed["min"], devices)
        r = np.where(energy > 0, 0.711e-3 + (radius0 - 0.711e-3) * np.exp(-energy / 500.0), radius0)
        kappa = kappa_ref * (r / r0) ** 0.375 * (pressure0 / p0) ** 0.625
        if arcs:
            pre_arc = gap / u
            arc_energy = power * pre_arc
            ratio = 1.0 / (1.0 + arc_energy / softening)
            kappa_1, p_1 = kappa * ratio**0.625, pressure0 * ratio
        else:
            pre_arc = arc_energy = np.zeros(devices)
            kappa_1, p_1 = kappa, pressure0
        e1 = restitution(u, kappa_1)
        kc = np.pi * r * p_1
        root_km = np.sqrt(kc * m)
        peak = fs + np.sqrt(fs * fs + (u * root_km) ** 2)
        duration = (np.pi / 2 + np.arctan(fs / (u * root_km))) * m / root_km + 1.8395 * m * e1 * u / peak
        plastic = 0.5 * m * u * u + fs * peak / kc
        v = np.sqrt(np.maximum((e1 * u) ** 2 - loss_sq, 0.0))
        count = np.zeros(devices)
        first = np.zeros(devices)
        total = np.zeros(devices)
        active = (v > 0) & (v >= min_speed)
        while (active := active & (count < 64)).any():
            t = 2.0 / omega * np.arctan(v * np.sqrt(k * m) / fs)
            count += active
            total += np.where(active, t, 0.0)
            first = np.where(active & (count == 1), t, first)
            if arcs:
                arc_energy = arc_energy + np.where(active, power * t, 0.0)
                linear = np.maximum(0.235 + 0.371 * v, 0.0)
                e = np.minimum(restitution(v, kappa_1), linear)
            else:
                e = restitution(v, kappa)
            v = np.where(active, np.sqrt(np.maximum((e * v) ** 2 - loss_sq, 0.0)), v)
            active &= (v > 0) & (v >= min_speed)
        for name, value in zip(names, [u, kappa, e1, first, total, count, pre_arc, arc_energy, peak,
                                       duration, plastic]):
            out[name][op] = value
        energy += arc_energy
        work += plastic

    group_of_device = np.arange(devices) * GROUPS // devices
    result = {"operations": {}, "devices": {}}
    for name in names:
        bins = []
        for start in range(0, operations, bin_operations):
            values = out[name][start:start + bin_operations]
            bins.append(summary(values.ravel(), np.broadcast_to(group_of_device, values.shape).ravel()))
        result["operations"][name] = bins
    final_radius = np.where(energy > 0, 0.711e-3 + (radius0 - 0.711e-3) * np.exp(-energy / 500.0), radius0)
    for name, value in [("cumulative_arc_energy_j", energy), ("eroded_mass_kg", 2e-9 * energy),
                        ("final_radius_m", final_radius),
                        ("final_kappa", kappa_ref * (final_radius / r0) ** 0.375 * (pressure0 / p0) ** 0.625),
                        ("cumulative_plastic_work_j", work)]:
        result["devices"][name] = summary(value, group_of_device)
    return result


def main():
    job = json.loads(sys.argv[1])
    started = time.perf_counter()
    # Stopped devices divide by a zero speed; their values are masked out.
    with np.errstate(divide="ignore", invalid="ignore"):
        result = run(job)
    result["compute_s"] = time.perf_counter() - started
    print(json.dumps(result))


if __name__ == "__main__":
    main()
