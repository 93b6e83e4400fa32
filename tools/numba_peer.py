#!/usr/bin/env python3
"""The Numba peer: the reference jobs of tests/data/reference_jobs.json as tools/numpy_peer.py runs
them, with the operations compiled by Numba, to measure the Rust engine against compiled Python.

    python3 -m pip install numba                    # PyPI; not needed by CI
    python3 tools/numba_peer.py '<job JSON>'        # prints the statistics and the compute time

The model, the draws and the statistics are tools/numpy_peer.py's (it imports that file, which must
sit beside it): the same seed gives the NumPy peer's statistics to rounding. What differs is how the
operations run. A bin's operations are one compiled loop over the devices, `prange` over
NUMBA_NUM_THREADS threads (default one per core), with `fastmath=False`: each device runs its
operations in order and each operation its bounces in scalar code, so a device stops bouncing when
it stops, and nothing is stored but the metrics. The statistics stay NumPy's (a sort per bin and
metric), on the threads too: NumPy releases the GIL while it sorts.

Numba compiles on the first call, and with cache=True keeps the machine code beside this file
(__pycache__): the first run of a new install pays the compilation (seconds), later runs load it.
The printed compute_s counts from the job's parsing to the statistics, compilation or loading
included.
"""
import math

import numpy_peer
from numba import get_num_threads, njit, prange
from numpy_peer import (ARC_A, ARC_B, CHEBYSHEV, ELASTIC_SQ, FLIGHT_PER_SPEED, FLIGHT_S, FS, LOSS_SQ,
                        LOWER_BOUND_SQ, M, MAX_BOUNCES, MIN_SPEED, ROUGHENING_J, SOFTENING_J, WORN_RADIUS)


@njit(cache=True, fastmath=False)
def restitution_sq(eps0_sq):
    """numpy_peer.restitution_sq of one impact."""
    x = min(eps0_sq, ELASTIC_SQ)
    a = 0.375 * x
    z = CHEBYSHEV[0]
    for i in range(1, len(CHEBYSHEV)):
        z = z * a + CHEBYSHEV[i]
    c = 1.0 - a * z
    z2 = z * z
    z -= (z2 * z2 - c * c * c) / (4.0 * z2 * z + 3.0 * a * c * c)
    return min(z * x, 1.0)


@njit(cache=True, fastmath=False)
def first_impact(u, e1, kc):
    """numpy_peer.first_impact of one impact: its peak force, duration and plastic work."""
    root_km = math.sqrt(kc * M)
    y = u * root_km
    peak = math.sqrt(y * y + FS * FS) + FS
    duration = (math.atan(FS / y) + math.pi / 2) * (M / root_km) + e1 * u * (1.8395 * M) / peak
    return peak, duration, u * u * (0.5 * M) + peak / kc * FS


@njit(cache=True, fastmath=False)
def bounces(v, kappa_sq, arcs):
    """numpy_peer.bounces of one operation: its bounce count, first and total bounce time."""
    count, first, total = 0, 0.0, 0.0
    while v >= MIN_SPEED and count < MAX_BOUNCES:
        t = FLIGHT_S * math.atan(v * FLIGHT_PER_SPEED)
        count += 1
        if count == 1:
            first = t
        total += t
        eps0_sq = kappa_sq / math.sqrt(v)
        if arcs:
            linear = max(ARC_A + ARC_B * v, 0.0)
            e_sq = linear * linear
            if e_sq > min(LOWER_BOUND_SQ * eps0_sq, 1.0):
                e_sq = min(e_sq, restitution_sq(eps0_sq))
        else:
            e_sq = restitution_sq(eps0_sq)
        v = math.sqrt(max(e_sq * v * v - LOSS_SQ, 0.0))
    return count, first, total


@njit(parallel=True, cache=True, fastmath=False)
def operations(u, radius0, pressure0, kappa_scale, arcs, power, gap, energy, out):
    """The operations `u` (operations x devices) of numpy_peer.Operations, one device per
    iteration: each device's operations in order, from its arc energy so far (`energy`, added to),
    into `out` (numpy_peer.OPERATION_METRICS but the first, each operations x devices)."""
    (kappa_out, e1_out, first_out, total_out, count_out, pre_arc_out, arc_energy_out, peak_out,
     duration_out, plastic_out) = out
    for d in prange(u.shape[1]):
        worn = energy[d]
        for op in range(u.shape[0]):
            ui = u[op, d]
            radius, pre_arc, arc_energy, ratio = radius0[d], 0.0, 0.0, 1.0
            if arcs:
                radius = WORN_RADIUS + (radius0[d] - WORN_RADIUS) * math.exp(worn / -ROUGHENING_J)
                pre_arc = gap / ui
                arc_energy = power * pre_arc
                ratio = 1.0 / (1.0 + arc_energy / SOFTENING_J)  # p_1 / p
            kappa = kappa_scale[d] * math.sqrt(math.sqrt(math.sqrt(radius * radius * radius)))
            kappa_sq = kappa * kappa * (ratio * math.sqrt(math.sqrt(ratio)))  # kappa_1^2
            e1 = math.sqrt(restitution_sq(kappa_sq / math.sqrt(ui)))
            kc = math.pi * radius * pressure0[d] * ratio  # eq. 12's k_c at the softened pressure
            peak_out[op, d], duration_out[op, d], plastic_out[op, d] = first_impact(ui, e1, kc)
            rebound = e1 * ui
            count, first, total = bounces(math.sqrt(max(rebound * rebound - LOSS_SQ, 0.0)), kappa_sq, arcs)
            arc_energy += power * total
            worn += arc_energy
            kappa_out[op, d], e1_out[op, d], pre_arc_out[op, d] = kappa, e1, pre_arc
            first_out[op, d], total_out[op, d], count_out[op, d] = first, total, count
            arc_energy_out[op, d] = arc_energy
        energy[d] = worn


def compiled(job):
    """The job's operations compiled, a bin at a time (numpy_peer.statistics calls it)."""
    def run(out, energy):
        operations(out["impact_velocity_m_s"], job.radius0, job.pressure0, job.kappa_scale, job.arcs,
                   job.power, job.gap, energy, tuple(out[name] for name in numpy_peer.OPERATION_METRICS[1:]))
    return run


if __name__ == "__main__":
    numpy_peer.main(compiled, get_num_threads())
