"""The stiffness bound (solver/stiffness.py, docs/reliability.md "Known limits"): each pair's stability radius
r_max, and on the paper collision's pair with the right berry's hinge made stiff, the fewest steps the bound allows
against the steps a run takes (DOP853 at rtol 1e-6, as simulate steps a two-berry scene), and how long a scene the
bound refuses takes to say so.
Run: .venv/bin/python benchmarks/stiff_bound.py"""
from __future__ import annotations

import math
import time

import grapefmu
from grapefmu.bench.scenes import _dual, build
from grapefmu.errors import SolverError
from grapefmu.solver.stiffness import least_steps, stability_radius
from grapefmu.solver.tableau import BOGACKI_SHAMPINE, DOP853, DOPRI5

#: (hinge_damping N·m·s/rad, hinge_stiffness N·m/rad, span s)
HINGES = [(1.0, 1e-3, 0.1), (10.0, 1e-3, 0.02), (100.0, 1e-3, 0.002), (0.0, 1000.0, 0.2), (0.0, 100.0, 0.5)]


def scene(damping: float, stiffness: float, t_end: float):
    return build(_dual((0.0, math.pi / 4), right={"hinge_damping": damping, "hinge_stiffness": stiffness},
                       t_end=t_end))


def main() -> None:
    for name, tb in (("DOPRI5", DOPRI5), ("DOP853", DOP853), ("ode23", BOGACKI_SHAMPINE)):
        print(f"r_max {name}: {stability_radius(tb):.3f}")
    print("| hinge_damping | hinge_stiffness | span (s) | bound (steps) | steps taken | taken / bound |")
    print("|---|---|---|---|---|---|")
    for c, k, span in HINGES:
        sc = scene(c, k, span)
        s = grapefmu.Solver(sc, rtol=1e-6)
        bound = least_steps(sc.model, s.tableau, span, s.layout.turning)[0]
        s.run()
        steps = s.stats["steps"]
        print(f"| {c:g} | {k:g} | {span:g} | {bound:.0f} | {steps} | {steps / bound:.2f} |")
    sc = scene(1000.0, 1e-3, 2.0)
    t = time.perf_counter()
    try:
        grapefmu.simulate(sc)
    except SolverError as e:
        print(f"hinge_damping 1000 over 2 s: refused in {1e3 * (time.perf_counter() - t):.2f} ms: {str(e)[:90]}...")


if __name__ == "__main__":
    main()
