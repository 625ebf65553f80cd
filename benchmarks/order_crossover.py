"""Where DOP853 starts to pay: both Dormand–Prince pairs forced on the benchmark scenes, work against error.

For each scene and rtol in 1e-4..1e-12 (atol = rtol·1e-2, output every 1 ms) each pair runs `simulate`;
error = max |angles − reference| over the run, the reference being the same scene at rtol 1e-13
(DOP853, atol 1e-15); cost = the fastest of REPEATS wall times, the runs of both pairs interleaved. Printed
per scene: the cost at 1e-6 and 1e-10 rad (log-log interpolation between rtols), steps and RHS evaluations,
and per rtol the ratio of DOP853's cost to DOPRI5's at the error DOP853 reached (< 1: DOP853 pays).
solver.DOP853_BELOW and DOP853_BELOW_FEW are set from these ratios (DOP853 steps at solver.DOP853_TOLERANCE
times the rtol and atol given, as it does by default). `clusters N ...` instead: the Scale section's pick-and-place cluster
of N berries at rtol 1e-6 under each pair as `simulate` runs it (islands from 100 berries), wall time (the fastest of
3, interleaved) and error against the scene at rtol 1e-10 (bench/scale.error). `advance` instead: the paper
collision advanced 1 ms at a time for 2 s by a face's solver (driven, a held input that changes every call) under
each pair at rtol 1e-6, wall time (the fastest of 5, interleaved), steps and right-hand sides.

    PYTHONPATH=src python benchmarks/order_crossover.py [scene ... | clusters N ... | advance]
"""
from __future__ import annotations

import math
import sys
import time

import numpy as np

from grapefmu import simulate
from grapefmu.bench.scenes import bench_scenes, build
from grapefmu.solver import solver as sv

RTOLS = [10.0 ** -k for k in range(4, 13)]
REPEATS = 5
PAIRS = {"DOPRI5": 0.0, "DOP853": math.inf}  # DOP853_BELOW and DOP853_BELOW_FEW that force each pair
SCENES = ("paper collision", "free swing", "shaken stiff pair")


def force(pair):
    sv.DOP853_BELOW = sv.DOP853_BELOW_FEW = PAIRS[pair]


def run(scene, pair, rtol, atol):
    force(pair)
    t = time.perf_counter()
    r = simulate(scene, rtol=rtol, atol=atol, output_interval=1e-3)
    return time.perf_counter() - t, r


def at_error(errors, costs, target):
    """Cost at `target` error, interpolated in log-log between the runs that bracket it (nan outside)."""
    le, lc = np.log10(errors), np.log10(costs)
    for i in range(len(le) - 1):
        lo, hi = sorted((le[i], le[i + 1]))
        if lo <= math.log10(target) <= hi and hi > lo:
            w = (math.log10(target) - le[i]) / (le[i + 1] - le[i])
            return 10.0 ** (lc[i] + w * (lc[i + 1] - lc[i]))
    return math.nan


def clusters(sizes, rtol=1e-6):
    from grapefmu.bench.scale import error, scene
    kept = sv.DOP853_BELOW, sv.DOP853_BELOW_FEW
    try:
        for n in sizes:
            sc, best, err = scene("cluster", n, rtol), {}, {}
            for rep in range(4):
                for p in PAIRS:
                    w, _ = run(sc, p, rtol, rtol * 1e-3)  # the Scale section's atol
                    if rep:
                        best[p] = min(best.get(p, math.inf), w)
            for p in PAIRS:
                force(p)
                err[p] = error("cluster", n, rtol)
            print(f"cluster of {n}, rtol {rtol:g}: " + ", ".join(
                f"{p} {1e3 * best[p]:.1f} ms per simulated s, error {err[p]:.1e} rad" for p in PAIRS))
    finally:
        sv.DOP853_BELOW, sv.DOP853_BELOW_FEW = kept


def advance(rtol=1e-6, repeats=5):
    from grapefmu.solver.solver import Solver
    sc = build(bench_scenes()["paper collision"])
    kept = sv.DOP853_BELOW, sv.DOP853_BELOW_FEW
    best, work = {}, {}
    try:
        for _ in range(repeats):
            for p in PAIRS:
                force(p)
                s = Solver(sc, rtol=rtol, atol=rtol * 1e-2, driven=True)
                t = time.perf_counter()
                for k in range(2000):
                    s.advance(1e-3, (0.5 * math.sin(0.01 * k), 0.0, 0.3, 0.0, 0.0, 0.0))
                best[p] = min(best.get(p, math.inf), time.perf_counter() - t)
                work[p] = (s.stats["steps"], s.stats["rhs_evaluations"])
    finally:
        sv.DOP853_BELOW, sv.DOP853_BELOW_FEW = kept
    print(f"paper collision, 2000 advance(1 ms), driven, rtol {rtol:g}: " + ", ".join(
        f"{p} {1e3 * best[p]:.2f} ms ({work[p][0]} steps, {work[p][1]} RHS)" for p in PAIRS)
        + f"; DOP853/DOPRI5 {best['DOP853'] / best['DOPRI5']:.2f}")


def main(names):
    scenes = bench_scenes()
    kept = sv.DOP853_BELOW, sv.DOP853_BELOW_FEW
    try:
        for name in names:
            sc = build(scenes[name])
            _, ref = run(sc, "DOP853", 1e-13, 1e-15)
            rows = {p: [] for p in PAIRS}
            for rtol in RTOLS:
                best = {p: math.inf for p in PAIRS}
                last = {}
                for _ in range(REPEATS):
                    for p in PAIRS:
                        w, r = run(sc, p, rtol, rtol * 1e-2)
                        best[p], last[p] = min(best[p], w), r
                for p in PAIRS:
                    err = float(np.abs(last[p].angles - ref.angles).max())
                    rows[p].append((rtol, max(err, 1e-16), best[p], last[p].stats["steps"],
                                    last[p].stats["rhs_evaluations"]))
            print(f"\n## {name}")
            print(f"{'rtol':>7} | {'DOPRI5 err':>10} {'ms':>8} {'steps':>7} {'rhs':>8} | "
                  f"{'DOP853 err':>10} {'ms':>8} {'steps':>7} {'rhs':>8} | ratio")
            e5, c5 = np.array([r[1] for r in rows["DOPRI5"]]), np.array([r[2] for r in rows["DOPRI5"]])
            for a, b in zip(rows["DOPRI5"], rows["DOP853"]):
                ratio = b[2] / at_error(e5, c5, b[1])
                print(f"{a[0]:7.0e} | {a[1]:10.2e} {a[2] * 1e3:8.2f} {a[3]:7d} {a[4]:8d} | "
                      f"{b[1]:10.2e} {b[2] * 1e3:8.2f} {b[3]:7d} {b[4]:8d} | {ratio:5.2f}")
            for target in (1e-6, 1e-10):
                cells = []
                for p in PAIRS:
                    e, c = np.array([r[1] for r in rows[p]]), np.array([r[2] for r in rows[p]])
                    cells.append(f"{p} {at_error(e, c, target) * 1e3:8.2f} ms")
                print(f"cost at {target:.0e} rad: " + ", ".join(cells))
    finally:
        sv.DOP853_BELOW, sv.DOP853_BELOW_FEW = kept


if __name__ == "__main__":
    if sys.argv[1:2] == ["clusters"]:
        clusters([int(n) for n in sys.argv[2:]])
    elif sys.argv[1:2] == ["advance"]:
        advance()
    else:
        main(sys.argv[1:] or SCENES)
