#!/usr/bin/env python3
"""The NumPy peer: the reference jobs of tests/data/reference_jobs.json, written as a careful user
would write them in NumPy, vectorised across devices, to measure what the Rust engine is worth
against it.

    python3 tools/numpy_peer.py '<job JSON>'        # prints the statistics and the compute time

It follows docs/model.md sections 1-6 for the paper's rig (every scenario default), the paper's arc
law, roughening wear and the exact tier (eq. 7 to a few ulps, eq. 3 flights). Draws come from
NumPy's generator, not ChaCha8: the statistics agree with the engine's within their sampling error,
not to the bit (tools/peer_check.py checks that). It reports, per bin of operations and per metric,
what a Result reports: n, mean, sd, min, max, the nine quantiles, a 20-bin histogram and the
batch-means 95 % interval of the mean over 32 groups; and the same for the device metrics.

It does no work that the model does not need, and no Python step per operation where the model
does not need one:
- Without an arc nothing wears, so the operations of a device are independent: a block of
  operations of every device is one array per quantity (64k values, so that the arrays stay in the
  cache). With an arc the radius follows the arc energy so far, so each operation is one step over
  the devices, and only what depends on the wear runs in it: what the closing velocity alone
  decides (pre-arc, softening) is computed for a whole bin before.
- The bounce loop carries only the operations still bouncing (their positions, speeds, kappa^2 and
  time so far), and squared speeds as the engine does, so an impact needs no square root of its
  own; eq. 16 skips eq. 7 where the line lies below eq. 7's lower bound, as the engine does.
- Eq. 7's root is the engine's degree-6 Chebyshev start and one Newton step: e^2 within 2.3e-16
  relative of a 40-digit root over eps0^2 from 1e-6 to past the elastic limit (six Newton steps
  from 1 gave 6.3e-16 with twice the passes). Fractional powers are chains of square roots.
- A bin at a time, in arrays reused from bin to bin. Each bin is sorted once (NumPy's vectorised
  sort, in place): the quantiles (np.quantile's "inverted_cdf"), min, max and the histogram's counts
  (np.histogram's bins, by bisecting at the edges) all come from it.

The draws are those of the peer this one replaced (commit 43afae2, one Python step per operation,
masked bounces, six Newton steps), in its order: radius and pressure per device, then the closing
velocity per operation and device. With the same seed every statistic is that peer's within 5e-14
relative. Only what the reference jobs use is implemented; any other job is refused.
tools/numba_peer.py takes its rig, its draws and its statistics from this file.
"""
import json
import os
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from itertools import chain

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # one core, and no BLAS: its threads would only start
import numpy as np  # noqa: E402

QUANTILES = np.array([0.01, 0.05, 0.10, 0.25, 0.50, 0.75, 0.90, 0.95, 0.99])
GROUPS = 32
T_975_31 = 2.0395134463964077  # Student t, 0.975, 31 degrees of freedom
MAX_BOUNCES = 64
BLOCK_VALUES = 1 << 16  # how many operations of the mechanical job one array holds at a time

# The paper's rig (docs/model.md section 8), referred to the contact (eq. 1).
M, K, FS = 1.593e-5 / 0.03**2, 200.0, 0.344
R0, P0, YOUNGS = 7.7e-3, 2e8, 1e11
KAPPA_REF = 2.784 * P0**0.625 * R0**0.375 / (YOUNGS**0.5 * M**0.125)
FLIGHT_S = 2.0 / np.sqrt(K / M)  # eq. 3: T(v) = FLIGHT_S atan(v FLIGHT_PER_SPEED)
FLIGHT_PER_SPEED = np.sqrt(K * M) / FS
LOSS_SQ = 2.0 * 1e-6 / M  # section 3: each impact takes 2 eps / m from v^2
G_MIN = 1e-7
MIN_SPEED = np.sqrt(G_MIN) * np.sqrt((K * G_MIN + 2.0 * FS) / M)
WORN_RADIUS, ROUGHENING_J = 0.711e-3, 500.0
ARC_VOLTAGE, MIN_ARC_CURRENT, FIELD, SOFTENING_J = 12.0, 0.4, 1e8, 6.2e-4
ARC_A, ARC_B = 0.235, 0.371  # eq. 16
EROSION = 2e-9
ELASTIC_SQ = 1.6**0.75  # eps0^2 at and above which e = 1
LOWER_BOUND_SQ = 0.625**0.75  # e^2 >= min(1, LOWER_BOUND_SQ eps0^2) (eq. 7)
# The root of z^4 = (1 - a z)^3 on a in [0, 3/8 (8/5)^(3/4)], fitted (the engine's), highest degree first.
CHEBYSHEV = (0.008050232553153345, -0.03915618812370257, 0.1120694104495261, -0.2498606344542164,
             0.46873739565188555, -0.7499995753342589, 0.9999999976722691)
BOUNCES = ["first_bounce_s", "total_bounce_s", "bounce_count"]
OPERATION_METRICS = ["impact_velocity_m_s", "kappa", "e1", "first_bounce_s", "total_bounce_s",
                     "bounce_count", "pre_arc_s", "arc_energy_j", "peak_force_n", "impact_duration_s",
                     "first_impact_plastic_work_j"]


def restitution_sq(eps0_sq):
    """e^2 of eq. 7 from the squared scaled speed eps0^2 = kappa^2 / sqrt(u): with a = 3 eps0^2 / 8,
    e^2 = eps0^2 z where z^4 = (1 - a z)^3, and e = 1 at and above the elastic limit, where the
    root is e = 1 (so eps0^2 is held there)."""
    x = np.minimum(eps0_sq, ELASTIC_SQ)
    a = np.multiply(x, 0.375)
    z = a * CHEBYSHEV[0]
    for c in CHEBYSHEV[1:-1]:
        z += c
        z *= a
    z += CHEBYSHEV[-1]
    # One Newton step: z -= (z^4 - c^3) / (4 z^3 + 3 a c^2), c = 1 - a z.
    c = a * z
    np.subtract(1.0, c, out=c)
    c2 = c * c
    c *= c2
    f = z * z
    d = f * z
    f *= f
    f -= c
    d *= 4.0
    c2 *= a
    c2 *= 3.0
    d += c2
    f /= d
    z -= f
    z *= x
    return np.minimum(z, 1.0, out=z)


def power_3_8(x):
    """x^(3/8), as three square roots."""
    y = x * x
    y *= x
    return np.sqrt(np.sqrt(np.sqrt(y, out=y), out=y), out=y)


def worn_radius(radius0, energy):
    """Section 6: the radius after the arc energy `energy`."""
    r = np.exp(energy / -ROUGHENING_J)
    r *= radius0 - WORN_RADIUS
    r += WORN_RADIUS
    return r


def truncated_normal(rng, mean, sd, low, size):
    x = rng.normal(mean, sd, size)
    while (bad := x < low).any():
        x[bad] = rng.normal(mean, sd, bad.sum())
    return x


class Job:
    """A reference job: its circuit, its size and its draws."""

    def __init__(self, job):
        assert {s["parameter"] for s in job["scatter"]} == {
            "contact_radius_m", "dynamic_yield_pressure_pa", "impact_velocity_m_s"}, "reference jobs only"
        circuit = job.get("scenario", {}).get("circuit", {"supply_voltage_v": 0, "current_a": 0})
        self.devices, self.operations = job["devices"], job["operations"]
        self.bin_operations = max(self.operations // 10, 1)
        vs, current = circuit["supply_voltage_v"], circuit["current_a"]
        arc_current = current * (vs - ARC_VOLTAGE) / vs if vs > ARC_VOLTAGE else 0.0
        self.arcs = vs > ARC_VOLTAGE and arc_current >= MIN_ARC_CURRENT
        self.power, self.gap = ARC_VOLTAGE * arc_current, vs / FIELD
        rng = np.random.default_rng(job["seed"])
        by_name = {s["parameter"]: s["distribution"] for s in job["scatter"]}
        radius = by_name["contact_radius_m"]
        self.radius0 = truncated_normal(rng, radius["mean"], radius["sd"], radius["min"], self.devices)
        pressure = by_name["dynamic_yield_pressure_pa"]
        self.pressure0 = pressure["median"] * np.exp(pressure["sigma"] * rng.standard_normal(self.devices))
        speed = by_name["impact_velocity_m_s"]
        self.u = truncated_normal(rng, speed["mean"], speed["sd"], speed["min"],
                                  (self.operations, self.devices))
        # eq. 8: kappa = kappa_scale r^(3/8)
        self.kappa_scale = KAPPA_REF / R0**0.375 * (self.pressure0 / P0) ** 0.625


def first_impact(u, e1, kc, out):
    """Section 4: the first impact's peak force, duration and plastic work from its speed `u`, its
    restitution `e1` and its contact stiffness `kc`, into `out`'s arrays of u's shape."""
    root_km = np.multiply(kc, M, out=np.empty_like(u))
    np.sqrt(root_km, out=root_km)
    y = u * root_km
    peak = np.multiply(y, y, out=out["peak_force_n"])
    peak += FS * FS
    np.sqrt(peak, out=peak)
    peak += FS
    duration = np.divide(FS, y, out=out["impact_duration_s"])
    np.arctan(duration, out=duration)
    duration += np.pi / 2
    np.divide(M, root_km, out=root_km)
    duration *= root_km
    unload = np.multiply(e1, u, out=y)
    unload *= 1.8395 * M
    unload /= peak
    duration += unload
    plastic = np.multiply(u, u, out=out["first_impact_plastic_work_j"])
    plastic *= 0.5 * M
    np.divide(peak, kc, out=unload)
    unload *= FS
    plastic += unload


def separation_speed(u, e1):
    """Section 3: the flat speeds after the first impacts, sqrt(max(0, (e1 u)^2 - 2 eps / m))."""
    v = e1 * u
    v *= v
    v -= LOSS_SQ
    np.maximum(v, 0.0, out=v)
    return np.sqrt(v, out=v).reshape(-1)


def bounces(v, kappa_sq, first, total, count, arcs):
    """Section 3 (and eq. 16 after an arcing bounce): the bounces after the first impacts, whose
    separation speeds are the flat `v`, each at kappa^2 kappa_sq[i % kappa_sq.size]; writes the
    flat `first`, `total` and `count` of those that bounce."""
    at = np.flatnonzero(v >= MIN_SPEED)
    v, kappa_sq = v.take(at), kappa_sq.take(at % kappa_sq.size)
    elapsed = np.zeros(at.size)
    for n in range(1, MAX_BOUNCES + 1):
        if not at.size:
            return
        t = np.multiply(v, FLIGHT_PER_SPEED)
        np.arctan(t, out=t)
        t *= FLIGHT_S
        if n == 1:
            first[at] = t
        elapsed += t
        eps0_sq = np.sqrt(v)
        np.divide(kappa_sq, eps0_sq, out=eps0_sq)
        if arcs:
            # Eq. 16, without eq. 7's root where the line is below its bound e >= (5/8)^(3/8) eps0.
            e_sq = np.multiply(v, ARC_B, out=t)
            e_sq += ARC_A
            np.maximum(e_sq, 0.0, out=e_sq)
            e_sq *= e_sq
            bound = np.multiply(eps0_sq, LOWER_BOUND_SQ)
            np.minimum(bound, 1.0, out=bound)
            above = np.flatnonzero(e_sq > bound)
            if above.size:
                e_sq[above] = np.minimum(e_sq.take(above), restitution_sq(eps0_sq.take(above)))
        else:
            e_sq = restitution_sq(eps0_sq)
        v *= v
        v *= e_sq
        v -= LOSS_SQ
        np.maximum(v, 0.0, out=v)
        np.sqrt(v, out=v)
        bouncing = v >= MIN_SPEED
        done = np.flatnonzero(~bouncing)
        total[at.take(done)] = elapsed.take(done)
        count[at.take(done)] = n
        more = np.flatnonzero(bouncing)
        at, v, kappa_sq, elapsed = at.take(more), v.take(more), kappa_sq.take(more), elapsed.take(more)
    # The cap: the bounce after the last one allowed does not count.
    total[at] = elapsed
    count[at] = MAX_BOUNCES


class Operations:
    """The job's operations in NumPy, a bin at a time (`statistics` calls it): all the devices at
    once, and without an arc a block of operations at once."""

    def __init__(self, job):
        self.job = job
        self.kappa = job.kappa_scale * power_3_8(job.radius0)  # new, and without an arc for ever
        self.stiffness = np.pi * job.pressure0  # eq. 12's k_c = stiffness r p_1 / p

    def __call__(self, out, energy):
        u = out["impact_velocity_m_s"]
        for name in BOUNCES:
            out[name].fill(0.0)
        if self.job.arcs:
            self.arcing(u, out, energy)
            return
        out["kappa"][:] = self.kappa
        out["pre_arc_s"].fill(0.0)
        out["arc_energy_j"].fill(0.0)
        kappa_sq = self.kappa * self.kappa
        kc = self.stiffness * self.job.radius0
        rows = max(BLOCK_VALUES // self.job.devices, 1)
        for first in range(0, u.shape[0], rows):
            block = {name: values[first:first + rows] for name, values in out.items()}
            ub = block["impact_velocity_m_s"]
            eps0_sq = np.sqrt(ub)
            np.divide(kappa_sq, eps0_sq, out=eps0_sq)
            e1 = np.sqrt(restitution_sq(eps0_sq), out=block["e1"])
            first_impact(ub, e1, kc, block)
            bounces(separation_speed(ub, e1), kappa_sq, *(block[name].reshape(-1) for name in BOUNCES), False)

    def arcing(self, u, out, energy):
        """One operation at a time, each device's radius worn by its arc energy so far; only the
        chain from the arc energy to the next one (radius, kappa, e1, bounces) runs per operation."""
        job = self.job
        # Section 5: what the closing velocity alone decides, for the whole bin.
        pre_arc = np.divide(job.gap, u, out=out["pre_arc_s"])
        arc_energy = np.multiply(pre_arc, job.power, out=out["arc_energy_j"])
        ratio = arc_energy / SOFTENING_J
        ratio += 1.0
        np.divide(1.0, ratio, out=ratio)  # p_1 / p
        softening = np.sqrt(np.sqrt(ratio))
        softening *= ratio  # (kappa_1 / kappa)^2 = (p_1 / p)^(5/4)
        scaled = np.sqrt(u)
        np.divide(softening, scaled, out=scaled)  # (eps0 / kappa)^2 of the first impact
        kc = np.empty_like(u)
        for op in range(u.shape[0]):
            radius = worn_radius(job.radius0, energy)
            kc[op] = radius
            kappa = np.multiply(job.kappa_scale, power_3_8(radius), out=out["kappa"][op])
            kappa_sq = kappa * kappa
            eps0_sq = kappa_sq * scaled[op]
            kappa_sq *= softening[op]
            e1 = np.sqrt(restitution_sq(eps0_sq), out=out["e1"][op])
            bounces(separation_speed(u[op], e1), kappa_sq, *(out[name][op] for name in BOUNCES), True)
            bounce_energy = np.multiply(out["total_bounce_s"][op], job.power, out=radius)
            arc_energy[op] += bounce_energy
            energy += arc_energy[op]
        kc *= self.stiffness
        kc *= ratio  # k_c = pi r p_1
        first_impact(u, out["e1"], kc, out)


class Summary:
    """A Result's SUMMARY of one bin's values (operations x devices), sorted in a buffer of its own."""

    def __init__(self, job):
        self.group = np.arange(job.devices) * GROUPS // job.devices
        self.group_sizes = np.bincount(self.group, minlength=GROUPS)
        self.sorted = np.empty(job.bin_operations * job.devices)
        self.centred = np.empty_like(self.sorted)

    def __call__(self, values):
        rows, devices = values.shape
        n = rows * devices
        group_sums = np.bincount(self.group, weights=values.sum(axis=0), minlength=GROUPS)
        group_means = group_sums / (rows * self.group_sizes)
        half = T_975_31 * group_means.std(ddof=1) / np.sqrt(GROUPS)
        mean = group_sums.sum() / n
        flat = self.sorted[:n]
        flat.reshape(rows, devices)[...] = values
        centred = np.subtract(flat, mean, out=self.centred[:n])
        sd = np.sqrt(np.einsum("i,i", centred, centred) / (n - 1))
        flat.sort()
        lo, hi = flat[0], flat[-1]
        edges = np.linspace(lo, hi if hi > lo else lo + 1.0, 21)
        quantiles = flat[np.maximum(np.ceil(n * QUANTILES - 1).astype(np.intp), 0)]
        return {
            "n": n, "mean": float(mean), "mean_ci95": [float(mean - half), float(mean + half)],
            "sd": float(sd), "min": float(lo), "max": float(hi),
            "quantiles": {f"p{round(q * 100):02d}": float(v) for q, v in zip(QUANTILES, quantiles)},
            "histogram": {"edges": edges.tolist(),
                          "counts": np.diff(np.searchsorted(flat, edges[:20]), append=n).tolist()},
        }


def statistics(job, operations, threads=1):
    """The statistics a Result reports, per bin of operations and per metric, and per device metric.
    `operations(out, energy)` runs a bin of operations: it writes every metric but the closing
    velocity (already there) into `out` (by name, operations x devices) and adds each device's arc
    energy to `energy`. The bins' summaries are spread over `threads` threads."""
    summaries = [Summary(job) for _ in range(threads)]
    buffers = {name: np.empty((job.bin_operations, job.devices)) for name in OPERATION_METRICS}
    result = {"operations": {name: [] for name in OPERATION_METRICS}, "devices": {}}
    energy, work = np.zeros(job.devices), np.zeros(job.devices)
    with ThreadPoolExecutor(threads) as pool:
        for start in range(0, job.operations, job.bin_operations):
            rows = min(job.bin_operations, job.operations - start)
            out = {name: buffer[:rows] for name, buffer in buffers.items()}
            out["impact_velocity_m_s"] = job.u[start:start + rows]
            operations(out, energy)
            work += out["first_impact_plastic_work_j"].sum(axis=0)
            def share(i):
                return [(name, summaries[i](out[name])) for name in OPERATION_METRICS[i::threads]]
            for name, summary in chain.from_iterable(pool.map(share, range(threads))):
                result["operations"][name].append(summary)
    radius = worn_radius(job.radius0, energy) if job.arcs else job.radius0
    for name, value in [("cumulative_arc_energy_j", energy), ("eroded_mass_kg", EROSION * energy),
                        ("final_radius_m", radius), ("final_kappa", job.kappa_scale * power_3_8(radius)),
                        ("cumulative_plastic_work_j", work)]:
        result["devices"][name] = summaries[0](value[None])
    return result


def main(peer=Operations, threads=1):
    """Prints the statistics of the job in argv[1], run by `peer(job)` with its summaries on
    `threads` threads, and the compute time."""
    spec = json.loads(sys.argv[1])
    started = time.perf_counter()
    job = Job(spec)
    result = statistics(job, peer(job), threads)
    result["compute_s"] = time.perf_counter() - started
    print(json.dumps(result))


if __name__ == "__main__":
    main()
