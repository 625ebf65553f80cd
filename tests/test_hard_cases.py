"""Numerically hard scenes: each must finish, at every tolerance, and agree with the reference."""
from __future__ import annotations

import math

import numpy as np
import pytest

from grapefmu import simulate
from grapefmu.physics.kinematics import penetrations

from .conftest import dual, scene

HARD = {
    "stiff contact k=2e5": dual(contact={"law": "kelvin-voigt", "stiffness": 2e5, "restitution": 0.5},
                                solver={"t_end": 1.0}),
    # hinges 26 mm apart, berries 27 mm wide: squeezed at rest, shaken at 5 Hz
    "pre-compressed resting contact": dual(d0=0.026, angles=(0.0, 0.0),
                                           excitation={"kind": "sine", "amplitude": [3.0, 2.0], "frequency": 5.0},
                                           solver={"t_end": 1.0}),
    "large angles near pi": dual(angles=(-3.1, 3.1), solver={"t_end": 1.0}),
    "50 Hz base excitation": dual(angles=(0.0, 0.0), d0=0.0275,
                                  excitation={"kind": "sine", "amplitude": [20.0, 10.0], "frequency": 50.0},
                                  solver={"t_end": 0.5}),
    # pressed together by a steady sideways acceleration: bounces shrink into resting contact
    # a stiff left hinge makes a wall; the right berry is thrown at it and pressed against it
    "impact accumulation": dual(angles=(0.0, 0.6), right={"hinge_stiffness": 0.0, "hinge_damping": 0.0},
                                left={"hinge_stiffness": 1.0, "hinge_damping": 0.0},
                                contact={"law": "kelvin-voigt", "stiffness": 2e5, "restitution": 0.3},
                                excitation={"kind": "impulse", "peak": [15.0, 0.0], "start": 0.0, "duration": 1.0},
                                solver={"t_end": 0.6}),
}


@pytest.mark.parametrize("name", list(HARD))
@pytest.mark.parametrize("rtol", [1e-3, 1e-6, 1e-10])
def test_hard_case_finishes_and_agrees(name, rtol):
    sc = scene(HARD[name])
    run = simulate(sc, rtol=rtol, atol=rtol * 1e-2)
    assert np.isfinite(run.y).all()
    ref = simulate(sc, method="reference", rtol=1e-11, atol=1e-13)
    err = np.abs(run.angles - ref.angles).max()
    # loose tolerances are allowed to be loose, but not wrong in kind
    assert err < max(1e3 * rtol, 1e-6), f"{name} at rtol {rtol}: angle error {err:.3g} rad"
    if rtol <= 1e-6:
        assert run.collision_count == ref.collision_count


def test_pre_compressed_start_is_in_contact_without_stalling():
    sc = scene(HARD["pre-compressed resting contact"])
    run = simulate(sc)
    assert run.mode[0, 0] == 1 and run.contact_force[0, 0] > 0
    assert run.stats["steps"] < 20000


def test_restart_exactly_at_zero_gap_does_not_stall():
    """Berries released exactly touching (g = 0) with the neighbour pushing in."""
    sc0 = scene(dual(angles=(0.0, 0.0), d0=0.027, excitation={"kind": "sine", "amplitude": [5.0, 0.0],
                                                                  "frequency": 3.0}, solver={"t_end": 0.5}))
    delta = np.zeros(1)
    penetrations(np.zeros(4), sc0.model.arrays, delta)
    assert delta[0] == pytest.approx(0.0, abs=1e-15)
    run = simulate(sc0)
    ref = simulate(sc0, method="reference", rtol=1e-11, atol=1e-13)
    assert np.abs(run.angles - ref.angles).max() < 1e-6


def test_grazing_contact_inside_one_step_is_found():
    """The right berry swings into its resting neighbour by only 1e-7 m and back: a contact far
    shorter than one step at rtol 1e-6. Only sampling inside the step can see it."""
    d0, r, length = 0.03, 0.0135, 0.03
    pen = 1e-7
    # far turning point of the right berry where it overlaps the hanging left berry by `pen`
    from scipy.optimize import brentq

    def overlap(q):
        dx = d0 + length * math.sin(q)
        dy = length * (1 - math.cos(q))
        return 2 * r - math.hypot(dx, dy) - pen
    q_turn = brentq(overlap, -0.5, 0.0)
    doc = dual(angles=(0.0, -q_turn), left={"hinge_damping": 0.0}, right={"hinge_damping": 0.0},
               contact={"law": "kelvin-voigt", "stiffness": 2000.0, "damping": 0.0}, solver={"t_end": 0.2})
    run = simulate(scene(doc), rtol=1e-6, atol=1e-8)
    steps_per_second = run.stats["steps"] / 0.2
    assert run.collision_count == 1
    assert run.impacts.duration[0] < 0.2 / steps_per_second  # far shorter than a typical step
    ref = simulate(scene(doc), method="reference", rtol=1e-12, atol=1e-14, output_interval=1e-4)
    assert ref.collision_count == 1
    assert abs(run.impacts.onset[0] - ref.impacts.onset[0]) < 1e-5


@pytest.mark.parametrize("rtol", [1e-6, 1e-7])
def test_a_graze_just_after_a_steps_start_is_found(rtol):
    """The grazing scene's third touch is 0.5 µm deep and peaks 6.5 ms after the start of a 56 ms DOP853 step, whose
    start is its largest sample of δ: the samples' rates (events.graze_possible) must find it, against the
    reference's three impacts. The run asks rtol / DOP853_TOLERANCE, so that DOP853 steps at rtol 1e-6 and 1e-7,
    where it used to book two."""
    from grapefmu.bench.scenes import bench_scenes, build
    from grapefmu.solver import solver as solver_module
    from grapefmu.solver.tableau import DOP853

    sc = build(bench_scenes()["grazing"])
    asked = rtol / solver_module.DOP853_TOLERANCE
    solver = solver_module.Solver(sc, rtol=asked, atol=asked / 100)
    assert solver.tableau is DOP853 and solver.config["rtol"][0] == pytest.approx(rtol)
    run = simulate(sc, rtol=asked, atol=asked / 100)
    ref = simulate(sc, method="reference", rtol=1e-11, atol=1e-13)
    assert ref.collision_count == 3
    assert run.collision_count == 3
    np.testing.assert_allclose(run.impacts.onset, ref.impacts.onset, atol=1e-5)
    assert np.abs(run.angles - ref.angles).max() < 1e-4


def test_zeno_guard_stops_an_accumulation_cleanly():
    doc = dict(HARD["impact accumulation"])
    doc["solver"] = {"t_end": 0.6, "zeno_max_events": 4, "zeno_window": 0.05}
    sc = scene(doc)
    run = simulate(sc, rtol=1e-8, atol=1e-10)
    assert run.stats["zeno_guard_activations"] >= 1
    # inside the guard the clamped law's kinks are stepped over, not located: the ledger
    # closes only to the local first-order accuracy (docs/solver.md)
    assert run.ledger_error() < 1e-3
    ref = simulate(sc, method="reference", rtol=1e-11, atol=1e-13)
    # the guard changes how kinks are integrated, not the physics
    assert np.abs(run.angles - ref.angles).max() < 1e-4


def _stable_reach(T) -> float:
    """How far along the negative real axis the Runge–Kutta pair T is stable: the largest x with |R(−x)| ≤ 1,
    R(z) = 1 + z bᵀ (I − zA)⁻¹ 1 from the tableau alone."""
    A, b, one = np.asarray(T.a), np.asarray(T.b), np.ones(len(T.b))

    def R(x):
        return 1.0 - x * b @ np.linalg.solve(np.eye(len(b)) + x * A, one)
    xs = np.linspace(0.01, 10.0, 4000)
    stable = np.array([abs(R(x)) <= 1.0 for x in xs])
    return float(xs[np.argmin(stable)])  # the first x where it is not


@pytest.mark.parametrize("rtol", [1e-4, 1e-6])
def test_a_stiff_hinge_damping_ends_at_the_step_limit_saying_why(rtol):
    """A hinge damping c far beyond the twig's inertia m l² decays in 1/λ = m l²/c = 40 ns: an explicit pair can
    only step it at its stability limit (hλ at the edge of its real stability interval), millions of steps per
    simulated second. Over a span whose bound on the steps (solver/stiffness.py: half the eigenvalue, the region's
    farthest point) stays under max_steps, so that it is not refused before a step (tests/test_stiffness.py), the run
    stops at the step limit with a SolverError that gives that step size and names max_steps, and the state is as it
    was."""
    import re

    from grapefmu.errors import SolverError
    from grapefmu.solver.solver import Solver
    from grapefmu.solver.stiffness import least_steps
    from grapefmu.solver.tableau import DOP853, DOPRI5

    m, l, c = 0.01, 0.02, 100.0
    sc = scene({"berries": [{"name": "b", "mass": m, "radius": 0.005, "twig_length": l, "hinge_x": 0.0,
                             "hinge_damping": c, "angle": 0.5}], "solver": {"t_end": 1.0}})
    s = Solver(sc, rtol=rtol, max_steps=20_000)
    span = 0.75 * s.max_steps / least_steps(sc.model, s.tableau, 1.0, s.layout.turning)[0]
    with pytest.raises(SolverError, match="step limit was reached.*max_steps") as e:
        s.run(span)
    h = float(re.search(r"the step size was ([0-9.e+-]+) s", str(e.value))[1])
    reach = _stable_reach({"DOPRI5": DOPRI5, "DOP853": DOP853}[s.integrator])
    assert 0.9 * reach < h * c / (m * l * l) < 1.1 * reach
    assert s.t == 0.0 and s.y[0] == 0.5


@pytest.mark.parametrize("tilt_rate", [1e-3, 1e-9])
def test_a_swing_over_the_spherical_charts_pole(tilt_rate):
    """A spherical berry with no forces swinging at ṡ = 10 rad/s with a little tilt momentum p_t = m l² cos² s ṫ:
    energy and p_t hold, so it turns back where cos² s = p_t² / (2 m l² E), cos s_min = ṫ₀/ṡ₀ (docs/model.md §1).
    With ṫ₀ = 1e-3 rad/s it turns at cos s = 1e-4 and the run goes on, never nearer the pole than that; with 1e-9
    it would turn at 1e-10, and the chart cannot follow it: the run stops at the step floor (this berry) or once
    |cos s| has stayed below loop.POLE_STOP (1e-4, 1e-5 s before s reaches 90° at t = π/20 s) for 1024 steps, with an
    error naming the berry, not at the step limit."""
    import re
    from dataclasses import replace

    from grapefmu.errors import SolverError
    from grapefmu.solver.solver import Solver

    w0 = 10.0
    sc = scene({"gravity": 0.0, "berries": [{"name": "b", "mass": 0.01, "radius": 0.005, "twig_length": 0.03,
                                             "hinge_x": 0.0, "kind": "spherical", "angle": [0.0, 0.0],
                                             "angular_velocity": [w0, tilt_rate]}], "solver": {"t_end": 0.5}})
    s = Solver(sc)
    if tilt_rate > 1e-6:
        run = s.run()
        assert run.t[-1] == pytest.approx(0.5)
        assert np.abs(np.cos(run.angles[:, 0])).min() > 0.999 * tilt_rate / w0
        return
    in_islands = replace(sc, solver=replace(sc.solver, islands=True))
    for run in (s.run, lambda: simulate(in_islands)):  # one step size, and in islands
        with pytest.raises(SolverError, match=r"spherical berry 'b' swung to (89\.99\d\d|90\.0000)°, at the pole of") as e:
            run()
        t = float(re.match(r"integration stopped at t = ([0-9.]+) s", str(e.value))[1])
        assert math.pi / 2 / w0 - 1.01e-5 < t < math.pi / 2 / w0 + 1e-9  # t is printed to 9 digits
    assert s.t == 0.0


def test_a_spherical_berry_carried_into_its_charts_pole_stops_near_it():
    """Swung at the documented limits (80°, −1000 rad/s) on a damped hinge: the damping's torque on the tilt stays as
    the tilt's inertia m l² cos² s vanishes, draining its momentum, and the berry is carried into the pole at −90°.
    Its accepted steps crept down unchecked (a rejected step's retry alone was held to the resolution of time): to
    3.6e-16 s at 300 000 steps and 3.4e-19 s at the default 10⁷, 35 s later; then the run stopped when the steps the
    error control asked for fell below 1.6e-14 s, which took a 300-berry cluster shaken at 4.1 Hz 200 s (800 000
    steps from |cos s| = 1e-4). Now it stops once |cos s| has stayed below loop.POLE_STOP = 1e-4 for 1024 steps, at
    steps far above that floor, in one step size and in islands, naming the berry."""
    import re
    from dataclasses import replace

    from grapefmu.errors import SolverError
    from grapefmu.solver.solver import Solver

    sc = scene({"berries": [{"name": "b", "kind": "spherical", "mass": 0.011, "radius": 0.0135, "twig_length": 0.03,
                             "hinge_x": 0.0, "hinge_damping": 1e-3, "angle": [1.396, 0.2],
                             "angular_velocity": [-1000.0, 0.0]}], "solver": {"t_end": 0.1}})
    s = Solver(sc, max_steps=300_000)
    in_islands = replace(sc, solver=replace(sc.solver, islands=True, max_steps=300_000))
    for run in (s.run, lambda: simulate(in_islands)):
        with pytest.raises(SolverError, match=r"spherical berry 'b' swung to -89\.99\d\d°, at the pole of its") as e:
            run()
        h = float(re.search(r"the steps shrank to ([0-9.e+-]+) s", str(e.value))[1])
        assert h > 1e-12  # the control's last proposal: over a hundred times the floor
    assert s.t == 0.0


@pytest.mark.parametrize("angle, rates", [([1.396, 0.0], [-1000.0, 0.01]), ([-1.396, 0.3], [-1000.0, 0.0])])
def test_a_hard_swing_at_80_degrees_that_passes_the_pole_still_runs(angle, rates):
    """As hard a start without hinge damping keeps its tilt momentum: it passes the pole every turn (as near as
    |cos s| = 3e-7 and 6e-6 on the first, in under 60 steps below 1e-4) and runs, so no start in the documented ranges
    can be refused for the pole before the run, nor the run for a pass (loop.POLE_STOP stops a berry that stays)."""
    sc = scene({"berries": [{"name": "b", "kind": "spherical", "mass": 0.011, "radius": 0.0135, "twig_length": 0.03,
                             "hinge_x": 0.0, "angle": angle, "angular_velocity": rates}], "solver": {"t_end": 1.0}})
    run = simulate(sc)
    assert run.t[-1] == pytest.approx(1.0)
    assert np.abs(np.cos(run.angles[:, 0])).min() < 2e-2  # it did swing past the pole's neighbourhood


@pytest.mark.parametrize("excitation", [{"kind": "impulse", "peak": [10.0, 0.0], "start": 1e-200, "duration": 0.01},
                                        {"kind": "sine", "amplitude": [10.0, 0.0], "frequency": 5.0, "start": 1e-300}])
def test_an_excitation_starting_a_hair_after_zero_runs(excitation):
    """The first step toward a breakpoint 1e-300 s away is about that long, and grows tenfold a step from there; at
    1e-158 s DOP853's error estimate squared underflowed (0.01 ‖e3‖² to 0 with ‖e5‖² = 0: 0/0) and the valid
    run stopped, 'the state became NaN or infinite'."""
    run = simulate(scene(dual(excitation=excitation, solver={"t_end": 0.1})))
    assert run.t[-1] == pytest.approx(0.1) and np.isfinite(run.y).all()
