"""The stepping interface the FMU and the ROS node rely on."""
from __future__ import annotations

import numpy as np
import pytest

from grapefmu import Solver, SolverError, simulate
from grapefmu.solver.state import flatten

from .conftest import dual, scene


def test_steps_and_intervals_reproduce_a_whole_run(collision_scene):
    whole = Solver(collision_scene)
    whole.advance(1.0)
    stepped = Solver(collision_scene)
    while stepped.t < 0.5:
        stepped.step()
    stepped.advance(1.0 - stepped.t)
    assert stepped.t == 1.0
    np.testing.assert_allclose(stepped.y, whole.y, rtol=0, atol=1e-7)


def test_dense_output_matches_the_step_ends(collision_scene):
    s = Solver(collision_scene)
    for _ in range(30):
        y_start = s.y
        t_start = s.t
        s.step()
        f = s.dense_output()
        np.testing.assert_allclose(f(t_start), y_start, atol=1e-15)
        np.testing.assert_allclose(f(s.t), s.y, atol=1e-12)


def test_held_acceleration_is_independent_of_the_interval_and_matches_the_reference(tmp_path):
    """1 ms and 10 ms zero-order-hold intervals against scipy on a constant-acceleration CSV scene."""
    (tmp_path / "accel.csv").write_text("time,ax,ay\n0,4.0,-2.0\n1,4.0,-2.0\n")
    doc = dual(angles=(0.0, 0.3))
    results = []
    for dt in (1e-3, 1e-2):
        s = Solver(scene(doc))
        for _ in range(round(0.2 / dt)):
            s.advance(dt, base_accel=(4.0, -2.0))
        results.append(s.angles)
    doc["excitation"] = {"kind": "csv", "file": str(tmp_path / "accel.csv")}
    ref = simulate(scene(doc), 0.2, method="reference", rtol=1e-12, atol=1e-14)
    assert ref.collision_count > 0
    for angles in results:
        np.testing.assert_allclose(angles, ref.angles[-1], atol=1e-7)


def test_state_roundtrip_replays_bit_for_bit(collision_scene):
    s = Solver(collision_scene)
    s.advance(0.05)
    saved = s.get_state()
    s.advance(0.3, base_accel=(1.0, 0.5))
    first = s.y
    s.set_state(saved)
    s.advance(0.3, base_accel=(1.0, 0.5))
    assert np.array_equal(s.y, first)


@pytest.mark.parametrize("dt, accel, words", [
    (0.0, None, "dt"), (-1e-3, None, "dt"), (float("nan"), None, "dt"),
    (1e-3, (float("nan"), 0.0), "base_accel"), (1e-3, (0.0, float("inf")), "base_accel"),
])
def test_bad_advance_is_refused_and_leaves_the_state(collision_scene, dt, accel, words):
    s = Solver(collision_scene)
    s.advance(0.01)
    before = s.get_state()
    with pytest.raises(SolverError, match=words):
        s.advance(dt, base_accel=accel)
    assert same_state(before, s.state)


def test_a_step_the_solver_cannot_finish_leaves_the_state(collision_scene):
    s = Solver(collision_scene, max_steps=3)
    before = s.get_state()
    with pytest.raises(SolverError, match="step limit"):
        s.advance(0.5)
    assert same_state(before, s.state)


def test_held_csv_excitation_equals_held_advances(tmp_path):
    """A zero-order-hold CSV in a scene gives the same run as feeding the rows to advance()."""
    rng = np.random.default_rng(3)
    t = np.arange(0, 0.3, 0.01)
    acc = rng.uniform(-6, 6, (len(t), 2))
    rows = np.column_stack([t, acc])
    np.savetxt(tmp_path / "zoh.csv", rows, delimiter=",", header="time,ax,ay", comments="")
    doc = dual(angles=(0.0, 0.3), excitation={"kind": "csv", "file": str(tmp_path / "zoh.csv"), "hold": True})
    run = simulate(scene(doc), 0.29, rtol=1e-11, atol=1e-13)
    s = Solver(scene(dual(angles=(0.0, 0.3))), rtol=1e-11, atol=1e-13)
    for k in range(len(t) - 1):
        s.advance(0.01, base_accel=tuple(acc[k]))
    assert run.collision_count > 0
    np.testing.assert_allclose(s.angles, run.angles[-1], atol=1e-9)


def test_impacts_closed_while_stepping_match_a_whole_run(collision_scene):
    whole = simulate(collision_scene, 1.0)
    s = Solver(collision_scene)
    got = []
    for _ in range(1000):
        s.advance(1e-3)
        imp = s.take_impacts()
        got += list(zip(imp.onset, imp.peak_force))
    closed = ~whole.impacts.ongoing
    np.testing.assert_allclose([g[0] for g in got], whole.impacts.onset[closed], atol=1e-9)
    np.testing.assert_allclose([g[1] for g in got], whole.impacts.peak_force[closed], rtol=1e-6)


def same_state(a, b) -> bool:
    fa, fb = flatten(a), flatten(b)
    return fa.keys() == fb.keys() and all(np.array_equal(fa[k], fb[k]) for k in fa)
