"""DOPRI5's step-size control with its PI term (Tableau.beta, docs/solver.md "Step-size control") against plain I
control (beta = 0) on the seven benchmark scenes: accepted steps, rejected trials, right-hand sides and the largest
angle error against the scene at rtol 1e-13 (1 ms grid); then, for the paper collision under each, where the
rejected trials fall (on steps that start with the pair apart or in contact), one `Solver.step` at a time.
Counts, not times: the same on every host. --clusters N ...: the Scale section's pick-and-place cluster of N berries
at its rtol 1e-6 as `simulate` runs it, wall time under each controller, interleaved, the minimum of 3.
Run: .venv/bin/python benchmarks/step_control.py [rtol ...] [--clusters 10 30 100 300]   (default rtol 1e-4 1e-6)"""
from __future__ import annotations

import argparse
import time

import numpy as np

import grapefmu
from grapefmu.bench.scale import scene as scale_scene
from grapefmu.bench.scenes import bench_scenes, build
from grapefmu.solver import solver as solver_module
from grapefmu.solver.solver import Solver
from grapefmu.solver.tableau import DOPRI5

BETAS = (DOPRI5.beta, 0.0)


def where_rejected(sc, rtol: float) -> tuple[int, int]:
    """Rejected trials on steps that start with every pair apart, and with a pair in contact."""
    s = Solver(sc, rtol=rtol, atol=rtol / 100)
    counters, contacts = s.state.book.counters, s.state.physical.contacts
    apart = touching = 0
    while s.t < sc.solver.t_end:
        before, in_contact = int(counters["rejected"][0]), bool((contacts["mode"] != 0).any())
        s.step()
        n = int(counters["rejected"][0]) - before
        touching, apart = (touching + n, apart) if in_contact else (touching, apart + n)
    return apart, touching


def clusters(sizes: list[int]) -> None:
    """Wall time of the Scale section's cluster under each controller, interleaved, the minimum of 3 after a warm-up."""
    for n in sizes:
        sc = scale_scene("cluster", n)
        best = dict.fromkeys(BETAS, np.inf)
        for rep in range(4):
            for beta in BETAS:
                solver_module.DOPRI5 = DOPRI5._replace(beta=beta)
                t = time.perf_counter()
                grapefmu.simulate(sc)
                if rep:
                    best[beta] = min(best[beta], time.perf_counter() - t)
        print(f"cluster of {n}: {1e3 * best[BETAS[0]]:.1f} ms (β {BETAS[0]:g}) against {1e3 * best[0.0]:.1f} ms (β 0) "
              f"per simulated second: {best[BETAS[0]] / best[0.0]:.3f}")


def main(rtols: list[float], sizes: list[int]) -> None:
    print("| scene | rtol | β | steps | rejected | RHS | error (rad) |\n|---|---|---|---|---|---|---|")
    try:
        for name, spec in bench_scenes().items():
            sc = build(spec)
            ref = grapefmu.simulate(sc, rtol=1e-13, atol=1e-15, output_interval=1e-3)
            for rtol in rtols:
                for beta in BETAS:
                    solver_module.DOPRI5 = DOPRI5._replace(beta=beta)
                    run = grapefmu.simulate(sc, rtol=rtol, atol=rtol / 100, output_interval=1e-3)
                    s, err = run.stats, float(np.abs(run.angles - ref.angles).max())
                    print(f"| {name} | {rtol:g} | {beta:g} | {s['steps']} | {s['rejected']} | {s['rhs_evaluations']} "
                          f"| {err:.2e} |")
        sc = build(bench_scenes()["paper collision"])
        for rtol in rtols:
            for beta in BETAS:
                solver_module.DOPRI5 = DOPRI5._replace(beta=beta)
                apart, touching = where_rejected(sc, rtol)
                print(f"paper collision, rtol {rtol:g}, β {beta:g}: {apart} rejected trials on steps that start with "
                      f"the pair apart, {touching} in contact")
        clusters(sizes)
    finally:
        solver_module.DOPRI5 = DOPRI5


if __name__ == "__main__":
    p = argparse.ArgumentParser()
    p.add_argument("rtol", type=float, nargs="*", default=[1e-4, 1e-6])
    p.add_argument("--clusters", type=int, nargs="*", default=[])
    a = p.parse_args()
    main(a.rtol, a.clusters)
