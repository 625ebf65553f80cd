"""The energy ledger (stored + dissipated − base work = constant) closes, and a conservative
system with repeated collisions does not drift."""
from __future__ import annotations

import math

import numpy as np
import pytest

from grapefmu import simulate

from .conftest import dual, scene

CASES = {
    "dissipative": dual(solver={"t_end": 2.0}),
    "conservative": dual(left={"hinge_damping": 0.0}, right={"hinge_damping": 0.0},
                         contact={"law": "kelvin-voigt", "stiffness": 2000.0, "damping": 0.0}, solver={"t_end": 2.0}),
    "base-excited": dual(angles=(0.0, 0.2), coupling={"stiffness": 0.5, "damping": 0.002},
                         excitation={"kind": "sweep", "amplitude": [6.0, 3.0], "f_start": 2.0, "f_stop": 12.0},
                         solver={"t_end": 2.0}),
    "hunt-crossley pick-and-place": dual(angles=(0.0, 0.0), right={"twig_length": 0.04, "mass": 0.012},
                                         contact={"law": "hunt-crossley", "stiffness": 1.1e5, "restitution": 0.4},
                                         excitation={"kind": "pick-and-place", "moves": [
                                             {"displacement": [0.3, 0.1], "duration": 0.6}]},
                                         solver={"t_end": 1.5}),
}


@pytest.mark.parametrize("name", list(CASES))
def test_ledger_closes_at_tight_tolerance(name):
    run = simulate(scene(CASES[name]), rtol=1e-11, atol=1e-13)
    assert run.collision_count > 0
    assert run.ledger_error() < 1e-8


def test_contact_dissipation_is_what_the_impacts_book():
    run = simulate(scene(CASES["dissipative"]), rtol=1e-11, atol=1e-13)
    assert run.impacts.dissipated.sum() == pytest.approx(run.energy["dissipated_contact"][-1], rel=1e-9)
    assert np.all(run.impacts.dissipated > 0)


def test_no_drift_over_100_s_of_collisions_without_damping():
    doc = dual(left={"hinge_damping": 0.0}, right={"hinge_damping": 0.0},
               contact={"law": "kelvin-voigt", "stiffness": 2000.0, "damping": 0.0}, solver={"t_end": 100.0,
                                                                                          "output_interval": 0.01})
    run = simulate(scene(doc), rtol=1e-10, atol=1e-12)
    assert run.collision_count > 100
    e = run.energy
    total = e["stored"]
    assert np.max(np.abs(total - total[0])) / total[0] < 1e-6
    assert math.isclose(e["dissipated_contact"][-1], 0.0, abs_tol=1e-15)
