"""A step's start is booked once (solver/loop.py, `start_sampled`; docs/solver.md): within one call of the loop a step
that starts where a whole step ended, in the same modes on the same near list, copies that step's last samples
(force, dissipation power, mode class) instead of evaluating them again. The reference books every start anew: the
same steps taken one call each (`Solver.step`), where every call starts without the copy."""
from __future__ import annotations

import math

import numpy as np
import pytest

from grapefmu.bench.scenes import bench_scenes, build
from grapefmu.solver import session as ses
from grapefmu.solver.loop import IMPACTS_FULL, MAX_STEPS
from grapefmu.solver.solver import Solver


def _float_fields(a: np.ndarray) -> list[str]:
    return [n for n in a.dtype.names if a.dtype.fields[n][0].kind == "f"]


@pytest.mark.parametrize("name", ["paper collision", "pick and place", "shaken stiff pair"])
def test_one_call_books_what_the_same_steps_one_call_each_book(name):
    sc = build(bench_scenes()[name])
    steps = {"paper collision": 400, "pick and place": 400, "shaken stiff pair": 1500}[name]
    one, each = Solver(sc, rtol=1e-6, atol=1e-8), Solver(sc, rtol=1e-6, atol=1e-8)
    done = 0
    while done < steps:  # one compiled call for all the steps (emptying the impact list when it fills)
        before = int(one.state.book.counters["steps"][0])
        status = ses.resume(one._session, math.inf, steps - done)[0]
        one._closed_into(one._outputs[0])
        done += int(one.state.book.counters["steps"][0]) - before
        assert status in (MAX_STEPS, IMPACTS_FULL)
    for _ in range(steps):
        each.step()
    a, b = one.state, each.state
    # the same steps: booking never feeds back into the motion of an event-located run
    assert a.physical.t[0] == b.physical.t[0]
    np.testing.assert_array_equal(a.physical.y, b.physical.y)
    np.testing.assert_array_equal(a.physical.contacts["mode"], b.physical.contacts["mode"])
    assert int(a.book.totals["collision_count"][0]) > 0, "the run must hold impacts for the booking to be tested"
    # the booked integrals and peaks agree to rounding (a copied end is the dense output at θ = 1 of the last step,
    # an evaluated start the state the step committed: equal up to the last bits)
    for rec in ("pair", "totals"):
        x, y = getattr(a.book, rec), getattr(b.book, rec)
        for f in _float_fields(x):
            np.testing.assert_allclose(x[f], y[f], rtol=1e-11, atol=1e-14, err_msg=f"book.{rec}.{f}")
        for f in set(x.dtype.names) - set(_float_fields(x)):
            np.testing.assert_array_equal(x[f], y[f], err_msg=f"book.{rec}.{f}")
    np.testing.assert_allclose(a.book.peak_tension, b.book.peak_tension, rtol=1e-11, atol=1e-14)
    np.testing.assert_array_equal(a.book.ring, b.book.ring)
