"""Step-size control (docs/solver.md, "Step-size control"): DOPRI5's PI term, against plain I control on the same
scenes, and against the reference solution."""
from __future__ import annotations

import numpy as np
import pytest

import grapefmu
from grapefmu.bench.scenes import bench_scenes, build
from grapefmu.solver import solver as solver_module
from grapefmu.solver.tableau import DOPRI5


@pytest.mark.parametrize("name", ["free swing", "paper collision", "pick and place"])
def test_pi_control_rejects_fewer_trials_for_no_larger_error(name, monkeypatch):
    sc = build(bench_scenes()[name])
    ref = grapefmu.simulate(sc, rtol=1e-13, atol=1e-15, output_interval=1e-3)
    monkeypatch.setattr(solver_module, "DOP853_BELOW_FEW", 0.0)  # these scenes of few berries: DOPRI5 at 1e-6 too
    runs = {}
    for beta in (DOPRI5.beta, 0.0):
        monkeypatch.setattr(solver_module, "DOPRI5", DOPRI5._replace(beta=beta))
        run = grapefmu.simulate(sc, rtol=1e-6, atol=1e-8, output_interval=1e-3)
        runs[beta] = (run.stats, float(np.abs(run.angles - ref.angles).max()))
    (pi, e_pi), (i, e_i) = runs[DOPRI5.beta], runs[0.0]
    assert DOPRI5.beta > 0.0
    # plain I control overshoots every few steps (a limit cycle, docs/bench_notes.md "Stop 40"); PI damps it
    assert pi["rejected"] < 0.7 * i["rejected"]
    assert pi["steps"] + pi["rejected"] <= 1.05 * (i["steps"] + i["rejected"])  # no more trials in all
    assert e_pi <= 1.1 * e_i  # and no larger an error (smaller, in fact, on these scenes)
    assert pi["impacts"] == i["impacts"] == ref.stats["impacts"]
