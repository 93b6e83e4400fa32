#!/usr/bin/env python3
"""Median-rank plotting positions, unit by unit, for the tests of `life::median_ranks`.

Johnson's adjusted rank as reliability texts give it: walk the units in time order (at a tie,
failures before suspensions); at each failure the increment is (N + 1 - previous rank) / (1 + the
units beyond the present suspended set, this one included). Bernard: F = (rank - 0.3) / (N + 0.4).
Prints (time, rank, F) for every failure of the datasets the Rust tests use.
"""


def median_ranks(data):
    units = sorted(data, key=lambda unit: (unit[0], not unit[1]))
    n = len(units)
    rank, out = 0.0, []
    for i, (time, failed) in enumerate(units):
        if failed:
            rank += (n + 1 - rank) / (1 + n - i)
            out.append((time, rank, (rank - 0.3) / (n + 0.4)))
    return out


DATASETS = {
    # ReliaSoft's textbook example: F S F S F gives adjusted ranks 1, 2.25, 4.125.
    "five units, two suspended": [(1, True), (2, False), (3, True), (4, False), (5, True)],
    "ten complete": [(t, True) for t in range(1, 11)],
    # The 6-MP arm of Freireich et al. (Klein & Moeschberger, table 1.1), as in life.rs's tests.
    "six-MP": [(t, True) for t in (6, 6, 6, 7, 10, 13, 16, 22, 23)]
    + [(t, False) for t in (6, 9, 10, 11, 17, 19, 20, 25, 32, 32, 34, 35)],
}

if __name__ == "__main__":
    for name, data in DATASETS.items():
        print(name)
        for time, rank, f in median_ranks(data):
            print(f"  t = {time}: rank {rank!r}, F = {f!r}")
