"""The event-driven solver against scipy's DOP853 with its own event location (shared RHS only)."""
from __future__ import annotations

import numpy as np
import pytest

from grapefmu import simulate

from .conftest import dual, scene

SCENES = {
    "kelvin-voigt": dual(solver={"t_end": 2.0}),
    "hertz": dual(contact={"law": "hertz", "effective_modulus": 1e6}, solver={"t_end": 1.0}),
    "hunt-crossley": dual(angles=(-0.3, 0.6), contact={"law": "hunt-crossley", "stiffness": 1.1e5, "restitution": 0.5},
                          solver={"t_end": 1.5}),
    "paper literal (tension allowed)": dual(contact={"law": "kelvin-voigt", "stiffness": 2000.0, "damping": 1.0,
                                                     "allow_tension": True}, solver={"t_end": 1.0}),
    "sine base": dual(angles=(0.0, 0.0), right={"twig_length": 0.035},
                      excitation={"kind": "sine", "amplitude": [8.0, 0.0], "frequency": 4.0}, solver={"t_end": 1.5}),
}


@pytest.mark.parametrize("name", list(SCENES))
def test_matches_scipy_reference(name):
    sc = scene(SCENES[name])
    ours = simulate(sc, rtol=1e-12, atol=1e-14)
    ref = simulate(sc, method="reference", rtol=1e-12, atol=1e-14)
    assert ours.collision_count == ref.collision_count > 0
    np.testing.assert_allclose(ours.t, ref.t, atol=1e-12)
    assert np.abs(ours.angles - ref.angles).max() < 1e-9
    np.testing.assert_allclose(ours.impacts.onset, ref.impacts.onset, atol=1e-10)
    np.testing.assert_allclose(ours.impacts.end[~ours.impacts.ongoing], ref.impacts.end[~ref.impacts.ongoing], atol=1e-10)
    np.testing.assert_allclose(ours.impacts.peak_force, ref.impacts.peak_force, rtol=1e-7)
    np.testing.assert_allclose(ours.impacts.impulse, ref.impacts.impulse, rtol=1e-7, atol=1e-12)
