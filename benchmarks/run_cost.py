"""Wall time of one `simulate` (rtol 1e-8, 1 ms output) of two benchmark scenes and the cost of one bare RHS
evaluation on their states: run it under two versions (PYTHONPATH=<other checkout>/src) one after the other,
several times, and compare minimums (the issue-14 note's before/after table for the 6-DoF rachis).
Run: .venv/bin/python benchmarks/run_cost.py"""
from __future__ import annotations

import time

import grapefmu
from grapefmu.bench.costs import rhs_seconds
from grapefmu.bench.scenes import bench_scenes, build


def main() -> None:
    for name in ("free swing", "paper collision"):
        sc = build(bench_scenes()[name])
        run = grapefmu.simulate(sc, rtol=1e-8, atol=1e-10, output_interval=1e-3)
        rhs = min(rhs_seconds(run) for _ in range(5))
        walls = []
        for _ in range(7):
            t0 = time.perf_counter()
            run = grapefmu.simulate(sc, rtol=1e-8, atol=1e-10, output_interval=1e-3)
            walls.append(time.perf_counter() - t0)
        print(f"{name}: simulate {min(walls) * 1e3:.2f} ms ({run.stats['steps']} steps, state of {run.y.shape[1]}), "
              f"one RHS {rhs * 1e9:.0f} ns")


if __name__ == "__main__":
    main()
