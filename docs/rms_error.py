#!/usr/bin/env python3
"""Per-triangle rms error of a solve against a path-traced reference, the reference's own
noise removed, from two references of the same spp and different seeds.

Usage: python3 docs/rms_error.py estimate.csv reference_seed_a.csv reference_seed_b.csv

Two-sided results (the CSVs of `--two-sided` runs, with `back_r,back_g,back_b`) count both
faces: six channels per triangle instead of three. The reference is the mean of the two, B* = (a + b) / 2; its per-triangle variance is estimated
as se^2 = (a - b)^2 / 4. Over the non-emissive triangles and the three channels, area-weighted:

    rms^2      = sum A (B - B*)^2 / sum A B*^2
    rms_true^2 = rms^2 - sum A se^2 / sum A B*^2        (the solver's own error)
    pt^2       = sum A (a - b)^2 / 2 / sum A B*^2       (one reference run's own error)

A path tracer of N spp has error pt * sqrt(spp / N), so it reaches the solver's rms_true at
N = spp * (pt / rms_true)^2, printed with the spp given by --spp (default 0: not printed).
"""

import csv
import math
import sys


def load(path):
    with open(path) as f:
        return list(csv.DictReader(f))


def main(argv):
    spp = 0
    if "--spp" in argv:
        i = argv.index("--spp")
        spp = int(argv[i + 1])
        argv = argv[:i] + argv[i + 2:]
    est, ra, rb = (load(p) for p in argv[:3])
    num = noise = one_run = den = 0.0
    channels = ["r", "g", "b"]
    if est and all("back_r" in rows[0] for rows in (est, ra, rb) if rows):
        channels += ["back_r", "back_g", "back_b"]
    for e, a, b in zip(est, ra, rb):
        if a["emissive"] == "1":
            continue
        area = float(a["area"])
        for c in channels:
            x, ya, yb = float(e[c]), float(a[c]), float(b[c])
            ref = 0.5 * (ya + yb)
            num += area * (x - ref) ** 2
            noise += area * (ya - yb) ** 2 / 4.0
            one_run += area * (ya - yb) ** 2 / 2.0
            den += area * ref * ref
    rms = math.sqrt(num / den)
    true_sq = (num - noise) / den
    rms_true = math.sqrt(max(true_sq, 0.0))
    pt = math.sqrt(one_run / den)
    print(f"rms {100 * rms:.3f}%  reference noise {100 * math.sqrt(noise / den):.3f}%  "
          f"rms without it {100 * rms_true:.3f}%  one reference run {100 * pt:.3f}%")
    if spp and rms_true > 0:
        print(f"path tracer spp for the same rms: {spp * (pt / rms_true) ** 2:.0f}")


if __name__ == "__main__":
    main(sys.argv[1:])
