"""A single impact returns the restitution its law was calibrated for."""
from __future__ import annotations

import pytest

from grapefmu import simulate
from grapefmu.model.contact import hunt_crossley_restitution, hunt_crossley_chi

from .conftest import scene


def head_on(contact: dict, speed=0.3):
    """Two berries on long, free twigs meeting head on at the bottom of their swing:
    the normal is horizontal and the twigs barely turn during the ~1 ms contact."""
    b = {"mass": 0.011, "radius": 0.0135, "twig_length": 1.0, "hinge_stiffness": 0.0, "hinge_damping": 0.0}
    return scene({"gravity": 0.0,
                  "berries": [{"name": "a", **b, "hinge_x": -0.0145, "angular_velocity": speed / 2},
                              {"name": "b", **b, "hinge_x": 0.0145, "angular_velocity": -speed / 2}],
                  "contact": contact, "solver": {"t_end": 0.02}})


@pytest.mark.parametrize("e", [0.3, 0.5, 0.7, 0.9])
def test_hunt_crossley_impact_returns_target_restitution(e):
    run = simulate(head_on({"law": "hunt-crossley", "stiffness": 1.1e5, "restitution": e}), rtol=1e-11, atol=1e-14)
    assert run.collision_count == 1
    realised = run.impacts.separation_speed[0] / run.impacts.approach_speed[0]
    assert realised == pytest.approx(e, abs=0.01)


def test_closed_forms_miss_and_the_root_find_does_not():
    for e in (0.3, 0.5):
        assert abs(hunt_crossley_restitution(1.5 * (1 - e)) - e) > 0.15  # Hunt–Crossley's own formula
        assert hunt_crossley_restitution(hunt_crossley_chi(e)) == pytest.approx(e, abs=1e-9)


def test_kelvin_voigt_calibration_exact_with_tension_and_biased_under_clamp():
    e = 0.5
    free = simulate(head_on({"law": "kelvin-voigt", "stiffness": 2000.0, "restitution": e, "allow_tension": True}),
                    rtol=1e-11, atol=1e-14)
    clamped = simulate(head_on({"law": "kelvin-voigt", "stiffness": 2000.0, "restitution": e}), rtol=1e-11, atol=1e-14)
    e_free = free.impacts.separation_speed[0] / free.impacts.approach_speed[0]
    e_clamped = clamped.impacts.separation_speed[0] / clamped.impacts.approach_speed[0]
    assert e_free == pytest.approx(e, abs=0.01)
    # the documented bias: the clamp forbids the pulling dashpot, so more energy comes back
    assert 0.52 < e_clamped < 0.60
