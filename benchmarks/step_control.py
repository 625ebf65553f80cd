"""DOPRI5's step-size control with its PI term (Tableau.beta, docs/solver.md "Step-size control") against plain I
control (beta = 0) on the seven benchmark scenes: accepted steps, rejected trials, right-hand sides and the largest
angle error against the scene at rtol 1e-13 (1 ms grid); then, for the paper collision under each, where the
rejected trials fall (on steps that start with the pair apart or in contact), one `Solver.step` at a time.
Counts, not times: the same on every host.
Run: .venv/bin/python benchmarks/step_control.py [rtol ...]   (default 1e-4 1e-6)"""
from __future__ import annotations

import sys

import numpy as np

import grapefmu
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


def main(rtols: list[float]) -> None:
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
    finally:
        solver_module.DOPRI5 = DOPRI5


if __name__ == "__main__":
    main([float(a) for a in sys.argv[1:]] or [1e-4, 1e-6])
