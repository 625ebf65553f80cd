"""Observed order through collisions: fifth order with event location, about first without."""
from __future__ import annotations

import numpy as np

from grapefmu import simulate
from grapefmu.solver.solver import Solver

from .conftest import dual, scene


def _final_error(sc, ref, h, locate):
    s = Solver(sc, fixed_step=h, locate=locate)
    s.advance(0.4)
    return np.abs(s.angles - ref).max()


def test_order_holds_through_collisions_only_with_event_location():
    sc = scene(dual(left={"hinge_damping": 0.0}, right={"hinge_damping": 0.0}))
    ref = simulate(sc, 0.4, method="reference", rtol=1e-13, atol=1e-15).angles[-1]
    hs = np.array([1e-3, 5e-4, 2.5e-4, 1.25e-4])
    with_ev = np.array([_final_error(sc, ref, h, True) for h in hs])
    without = np.array([_final_error(sc, ref, h, False) for h in hs])
    order_ev = np.polyfit(np.log(hs), np.log(with_ev), 1)[0]
    order_no = np.polyfit(np.log(hs), np.log(without), 1)[0]
    print(f"observed order: {order_ev:.2f} with event location, {order_no:.2f} without; "
          f"errors {with_ev} vs {without}")
    assert 4.5 < order_ev < 6.0
    assert order_no < 2.0
    assert with_ev[-1] < 1e-3 * without[-1]
