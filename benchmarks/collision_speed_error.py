"""Speed against error on the paper's collision scene (±45°, 2 s): grapefmu's event solver over rtol,
the paper's method (ode23-like, contact checked at step ends) and the scipy reference.
Run: .venv/bin/python benchmarks/collision_speed_error.py   (issue 5 grows this into `grapefmu bench`)."""
from __future__ import annotations

import math
import time

import numpy as np

import grapefmu
from grapefmu.model.scene import scene_from_dict
from pathlib import Path

KYOHO = {"mass": 0.011, "radius": 0.0135, "twig_length": 0.03, "hinge_stiffness": 1e-3, "hinge_damping": 2e-5}
SCENE = scene_from_dict({
    "berries": [{"name": "left", **KYOHO, "hinge_x": -0.015, "angle": -math.pi / 4},
                {"name": "right", **KYOHO, "hinge_x": 0.015, "angle": math.pi / 4}],
    "contact": {"law": "kelvin-voigt", "stiffness": 2000.0, "restitution": 0.5},
    "solver": {"t_end": 2.0}}, Path.cwd())


def best_of(fn, n=5):
    fn()
    runs = []
    for _ in range(n):
        t = time.perf_counter()
        r = fn()
        runs.append(time.perf_counter() - t)
    return r, min(runs)


def main():
    ref = grapefmu.simulate(SCENE, method="reference", rtol=1e-13, atol=1e-15)
    check = grapefmu.simulate(SCENE, rtol=1e-13, atol=1e-15)
    agree = np.abs(ref.angles - check.angles).max()
    print(f"reference agreement (grapefmu 1e-13 vs scipy DOP853 1e-13): {agree:.2e} rad")
    print(f"{'method':<28}{'tol':>8}{'max angle err (rad)':>22}{'impacts':>9}{'wall ms / sim s':>17}{'RHS evals':>11}")
    for method, tols in (("event", [1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-10]), ("paper", [1e-3, 1e-4, 1e-5, 1e-6])):
        for tol in tols:
            r, wall = best_of(lambda: grapefmu.simulate(SCENE, method=method, rtol=tol, atol=tol * 1e-2))
            err = np.abs(r.angles - ref.angles).max()
            print(f"{method:<28}{tol:>8.0e}{err:>22.2e}{r.collision_count:>9}{1e3 * wall / 2.0:>17.3f}"
                  f"{r.stats['rhs_evaluations']:>11}")
    for tol in (1e-6, 1e-8):
        r, wall = best_of(lambda: grapefmu.simulate(SCENE, method="reference", rtol=tol, atol=tol * 1e-2), n=2)
        err = np.abs(r.angles - ref.angles).max()
        print(f"{'scipy DOP853 + events':<28}{tol:>8.0e}{err:>22.2e}{r.collision_count:>9}{1e3 * wall / 2.0:>17.3f}"
              f"{r.stats['rhs_evaluations']:>11}")


if __name__ == "__main__":
    main()
