"""`grapefmu bench --quick` runs end to end, so the benchmark cannot rot. Correctness of the harness only:
no assertion here is about time."""
from __future__ import annotations

import math
import re
import subprocess
import sys

import numpy as np
import pytest

import grapefmu
from grapefmu.bench.harness import Row, cost_at
from grapefmu.bench.lean import simulate_lean
from grapefmu.bench.scale import SIZES, markdown as scale_markdown, slope
from grapefmu.bench.scenes import bench_scenes, build
from grapefmu.model.model import ISLANDS_FROM


def test_quick_bench_reports_every_method_against_agreeing_references(tmp_path):
    out = tmp_path / "benchmarks.md"
    r = subprocess.run([sys.executable, "-m", "grapefmu", "bench", "--quick", "--out", str(out), "--plots",
                        str(tmp_path / "plots")], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    text = out.read_text()
    assert "grapefmu bench --quick" in text and "cores" in text
    for scene in ("paper collision", "grazing"):
        assert f"## {scene}" in text
        assert (tmp_path / "plots" / f"{scene.replace(' ', '_')}.png").stat().st_size > 5000
        agree = float(re.search(rf"## {scene}.*?\| reference check \| [^|]* \| — \| ([0-9.e+-]+)", text, re.S).group(1))
        assert agree <= 1e-10
        rows = re.findall(rf"\| grapefmu event \| rtol ([0-9.e-]+) \| [0-9.]+ \| ([0-9.e+-]+) \|",
                          text.split(f"## {scene}")[1].split("## ")[0])
        errors = [float(e) for _, e in rows]
        assert len(errors) == 4 and errors[0] > errors[1] > errors[2] > errors[3]  # tighter tolerance, smaller error
        assert errors[1] < 1e-4
    for method in ("paper (ode23 check at step ends)", "scipy DOP853+events", "scipy DOP853 lean"):
        assert method in text
    # the RHS floor and wall / floor columns: positive wherever the method evaluates grapefmu's right-hand side
    collision = text.split("## paper collision")[1].split("## ")[0]
    cells = re.findall(r"\| (grapefmu event|scipy DOP853 lean|paper[^|]*) \| [^|]* \| ([0-9.]+) \|(?: [^|]* \|){6} "
                       r"([0-9.]+) \| ([0-9.]+) \|", collision)
    assert {c[0] for c in cells} >= {"grapefmu event", "scipy DOP853 lean"} and len(cells) >= 9
    for _, wall, floor, ratio in cells:
        assert float(floor) > 0 and float(ratio) > 0
        assert math.isclose(float(wall) / float(floor), float(ratio), rel_tol=0.06, abs_tol=0.06)
    assert re.search(r"\| paper collision \| [1-9][0-9]* \| 1e-6 \| [0-9.]+ \| [0-9.]+ \| [0-9.]+ \| scipy", text)
    fixed = re.search(r"advance's fixed cost \(advance − compiled loop, per call\): \*\*([0-9.]+) µs", text)
    assert fixed and float(fixed.group(1)) > 0
    per_s = re.findall(r"\| ([0-9.]+) \| ([0-9]+) \|\n", text.split("## Stepping from a face")[1].split("## ")[0])
    assert len(per_s) == 3 and all(float(c) > 0 and int(n) > 0 for c, n in per_s)
    for target in ("0.2 ms per simulated second", "RHS floor at 1e-6", "best scipy driver at 1e-6",
                   "best scipy driver at 1e-10", "fixed cost at most 2 µs"):
        assert target in text


def test_cost_interpolation_and_failures():
    rows = [Row("s", "m", "a", 1e-3, 1e-4, 0, 1, 1, 0, 0, 10), Row("s", "m", "b", 1e-2, 1e-8, 0, 1, 1, 0, 0, 10),
            Row("s", "m", "c", math.nan, math.nan, math.nan, None, 1, math.nan, math.nan, None, failure="x")]
    c = cost_at(rows, 1e-6)
    assert math.isclose(c, math.sqrt(1e-3 * 1e-2), rel_tol=1e-12)  # halfway in log error, halfway in log cost
    assert math.isnan(cost_at(rows, 1e-10))  # never reached: not extrapolated


def test_methods_are_timed_in_rounds_that_run_each_once_and_keep_its_fastest(monkeypatch):
    """The harness interleaves: each round runs every method once, in turn; a method keeps its fastest round, sits
    out the rounds after its runs took more than the budget, and one that fails says so and runs no more. Each run
    advances a clock of the test's own by its time, so a loaded host cannot move the budget's verdicts."""
    from grapefmu.bench import methods
    from grapefmu.bench.methods import Outcome, interleaved
    from grapefmu.errors import GrapefmuError

    now = [0.0]
    monkeypatch.setattr(methods.time, "perf_counter", lambda: now[0])
    calls = []

    def method(name, sleeps=(), fail_at=None):
        def fn():
            k = sum(c == name for c in calls)
            calls.append(name)
            if k == fail_at:
                raise GrapefmuError("gave up")
            now[0] += sleeps[k] if k < len(sleeps) else 0.0
            return Outcome(rhs=k)
        return fn

    # times in 1/1024 s, so that the clock's differences are exact
    fast_late = method("a", sleeps=(48 / 1024, 32 / 1024, 16 / 1024, 32 / 1024))
    slow = method("b", sleeps=(104 / 1024,) * 5)
    failing = method("c", fail_at=1)
    out = interleaved([fast_late, slow, failing], repeats=3, budget=0.25)
    assert calls == ["a", "b", "c", "a", "b", "c", "a", "b", "a"]  # b sits out once its runs took 0.3 s > 0.25
    (oa, ta), (ob, tb), (oc, tc) = out
    assert 0.01 <= ta < 0.03 and oa.failure is None  # its second round, not its warm-up or the others
    assert 0.1 <= tb < 0.15 and ob.failure is None
    assert oc.failure and "gave up" in oc.failure and math.isnan(tc)


def test_cost_is_not_interpolated_across_a_setting_that_missed_a_contact():
    """The pick-and-place scene's scipy DOP853 lean ladder in the report of 2026-11-29: rtol 1e-7 caught all five
    impacts (6.7e-6 rad), 1e-8 and 1e-9 missed one (1.6e-2 rad), 1e-10 caught them (2.5e-10 rad). Sorted by error,
    1e-7 and 1e-10 bracketed 1e-6 rad (7.76 ms), a cost its neighbours in between do not reach it at; the cheapest
    setting that reaches it is 1e-10."""
    def row(rtol, cost, err, impacts):
        return Row("pick and place", "scipy DOP853 lean", f"rtol {rtol:g}", cost, err, 0.0, impacts, 5, 0.0, 0.0, 100)
    rows = [row(1e-10, 10.423e-3, 2.52e-10, 5), row(1e-6, 6.057e-3, 1.58e-2, 4), row(1e-7, 7.256e-3, 6.67e-6, 5),
            row(1e-8, 7.563e-3, 1.58e-2, 4), row(1e-9, 8.426e-3, 1.58e-2, 4), row(1e-11, 11.849e-3, 2.37e-11, 5)]
    assert cost_at(rows, 1e-6) == 10.423e-3
    # grazing, scipy RK45 lean: two runs that missed all three impacts tie on error; neither is a point of the curve
    graze = [Row("grazing", "m", f"rtol {r:g}", c, e, 0.0, n, 3, 0.0, 0.0, 100) for r, c, e, n in
             ((1e-4, 1.974e-3, 8.085e-4, 0), (1e-6, 4.833e-3, 8.085e-4, 0), (1e-8, 14.478e-3, 5.17e-8, 3),
              (1e-10, 31.531e-3, 4.97e-10, 3))]
    assert cost_at(graze, 1e-6) == 14.478e-3
    w = math.log(1e-9 / 4.97e-10) / math.log(5.17e-8 / 4.97e-10)  # between two good neighbours: log-log as before
    assert math.isclose(cost_at(graze, 1e-9), 31.531e-3 * (14.478e-3 / 31.531e-3) ** w, rel_tol=1e-12)
    # a tighter setting that is cheaper than the interpolation (a non-monotone curve): its measured cost
    bumpy = [Row("s", "m", f"rtol {r:g}", c, e, 0.0, 1, 1, 0.0, 0.0, 10) for r, c, e in
             ((1e-5, 0.195e-3, 5.31e-6), (1e-6, 0.180e-3, 9.12e-7))]
    assert cost_at(bumpy, 1e-6) == 0.180e-3
    # a method whose every setting beats the target reaches it at its cheapest one: the committed report said "not
    # reached" for MuJoCo RK4 on the free swing (3.1e-7 rad at dt 1e-3) and for the FMU (one setting) everywhere
    rk4 = [Row("free swing", "MuJoCo RK4", f"dt {h:g}", c, e, 0.0, None, 0, 0.0, 0.0, 8) for h, c, e in
           ((1e-3, 6.067e-3, 3.06e-7), (1e-4, 50.07e-3, 2.97e-7))]
    assert cost_at(rk4, 1e-6) == 6.067e-3 and math.isnan(cost_at(rk4, 1e-10))
    fmu = [Row("paper collision", "FMU via fmpy", "1 ms steps", 15.8e-3, 7.2e-10, math.nan, None, 3, 0.0, 0.0, None)]
    assert cost_at(fmu, 1e-6) == 15.8e-3
    # a floor or a ratio is read where the cost is cheapest, not at its own least: the report of 2026-12-01 gave the
    # scipy driver's wall / floor at 1e-6 rad as its tightest setting's (the same figure as at 1e-10 rad)
    ladder = [Row("s", "scipy", f"rtol {r:g}", c, e, 0.0, 1, 1, 0.0, 0.0, 100, floor=fl) for r, c, e, fl in
              ((1e-5, 4e-3, 1e-7, 0.02e-3), (1e-12, 14e-3, 1e-12, 0.09e-3))]
    assert cost_at(ladder, 1e-6, key=lambda r: r.over_floor) == 4e-3 / 0.02e-3
    assert cost_at(ladder, 1e-6, key=lambda r: r.floor) == 0.02e-3
    w = math.log(1e-10 / 1e-12) / math.log(1e-7 / 1e-12)
    assert math.isclose(cost_at(ladder, 1e-10, key=lambda r: r.floor), 0.09e-3 * (0.02 / 0.09) ** w, rel_tol=1e-12)


@pytest.fixture(scope="module")
def collision():
    """The paper collision scene and grapefmu's event solver on it at rtol 1e-12 (the independent check's other side)."""
    sc = build(bench_scenes()["paper collision"])
    return sc, grapefmu.simulate(sc, rtol=1e-12, atol=1e-14, output_interval=1e-3)


@pytest.mark.parametrize("integrator, rtol, skin",
                         [("DOP853", 1e-9, None), ("DOP853", 1e-9, 1e-3), ("RK45", 1e-8, None)])
def test_lean_scipy_driver_agrees_with_the_event_solver(collision, integrator, rtol, skin):
    """The lean scipy driver shares only the RHS and the mode rules with grapefmu: the same impacts and the same
    angles to its tolerance, every pair watched one by one or (skin) apart pairs sharing one event. Its error norm
    is scipy's RMS over the head of the state, angles and rates (2D) and the rachis' pose and twist (13, idle
    here), so at a given rtol its angles are √((2D + 13)/2D) times looser than over the angles alone: the bound."""
    sc, ours = collision
    r = simulate_lean(sc, rtol=rtol, atol=rtol * 1e-2, integrator=integrator, skin=skin)
    bound = 10 * rtol * math.sqrt((2 * sc.model.n_dof + 13) / (2 * sc.model.n_dof))
    assert len(r.onsets) == len(ours.impacts) == 3
    assert np.abs(r.onsets - np.sort(ours.impacts.onset)).max() < bound
    assert r.t.shape == ours.t.shape and np.allclose(r.t, ours.t, rtol=0, atol=1e-12)
    assert np.abs(r.y[:, : sc.model.n_dof] - ours.angles).max() < bound
    final = np.r_[ours.angles[-1], ours.angular_velocities[-1]]
    assert np.abs(r.final[: 2 * sc.model.n_dof] - final).max() < bound
    assert np.array_equal(r.modes, ours.contacts[-1]["mode"])
    assert r.rhs_evaluations > 0 and r.segments == 1 + 3 * 3 + (skin is not None)  # onset, unload, release


def test_scale_reports_the_fitted_exponent():
    """cost ∝ N^1.5 exactly, in islands ∝ N^1.1 (equal at N = 100): the report says k = 1.50, 1.10 for islands, fits
    the default path (one step size below ISLANDS_FROM berries, islands from there) and judges the targets by it."""
    sizes = [{"kind": kind, "n": n, "cost": 2e-4 * n ** 1.5, "dof": n, "candidates": n, "pruned": 0, "near": 1.0,
              "active_max": 1, "active_mean": 0.5, "impacts": 1, "steps": 10, "groups": 1, "error": 1e-7,
              "islands": 2e-4 * 100 ** 0.4 * n ** 1.1, "islands_error": 1e-7, "islands_formed": n, "rollbacks": 0}
             for kind in ("row", "cluster") for n in SIZES]
    text = scale_markdown({"sizes": sizes, "smooth": [], "skin": []}, "scale.png")
    assert "**k = 1.50** (row), **k = 1.50** (cluster)" in text
    assert "k = 1.10 (row), 1.10 (cluster)" in text
    assert ISLANDS_FROM == 100
    default = slope([{"n": n, "cost": n ** 1.5 if n < 100 else 100 ** 0.4 * n ** 1.1} for n in SIZES])
    assert 1.1 < default < 1.5
    assert f"at most 1.2: **1.50** (row), **1.50** (cluster); as `simulate` runs them by default: " \
           f"**{default:.2f}**, **{default:.2f}**; {'met' if default <= 1.2 else 'missed'}." in text
    assert ("as `simulate` runs it by default (in islands): **0.2 s** (5.0× real time); with one step size "
            "(`solver.islands = false`) **0.2 s** (5.0×); missed.") in text
    sizes = [r | {"islands": r["islands"] / 4} if r["n"] == 100 and r["kind"] == "cluster" else r for r in sizes]
    text = scale_markdown({"sizes": sizes, "smooth": [], "skin": []}, "scale.png")
    assert ("as `simulate` runs it by default (in islands): **0.05 s** (20.0× real time); with one step size "
            "(`solver.islands = false`) **0.2 s** (5.0×); met.") in text


def test_the_mujoco_target_names_each_scene_where_mujoco_reaches_the_error():
    """The report said 'MuJoCo never reaches 1e-6 rad' while its RK4 did on the free swing (2026-12-01): the target is
    judged on every scene where one does, against grapefmu's cost there."""
    from grapefmu.bench.harness import mujoco_target

    def row(scene, method, setting, cost, err):
        return Row(scene, method, setting, cost, err, 0.0, None, 0, 0.0, 0.0, None)
    rows = [row("free swing", "grapefmu event", "rtol 1e-6", 0.5e-3, 7e-7),
            row("free swing", "MuJoCo RK4", "dt 0.001", 7.7e-3, 3e-7),
            row("free swing", "MuJoCo Euler", "dt 0.001", 1e-3, 1e-2),
            row("paper collision", "grapefmu event", "rtol 1e-6", 0.25e-3, 9e-7),
            row("paper collision", "MuJoCo RK4", "dt 0.001", 5e-3, 1e-3)]
    text = mujoco_target(rows)
    assert text.startswith("free swing: MuJoCo RK4 7.7 ms against ours 0.5 ms") and text.endswith("met.")
    assert "paper collision" not in text
    rows[1] = row("free swing", "MuJoCo RK4", "dt 0.001", 0.4e-3, 3e-7)
    assert mujoco_target(rows).endswith("missed.")
    assert "no scene" in mujoco_target(rows[2:])
