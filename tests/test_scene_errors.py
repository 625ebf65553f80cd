"""Every bad value gives one clear error naming the key and the allowed range."""
from __future__ import annotations

import math
import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest

from grapefmu import SceneError, Solver, SolverError, simulate
from grapefmu.model.model import ContactPair, Coupling, Obstacle
from grapefmu.scenefile import parse_scene

from .conftest import dual, scene


@pytest.mark.parametrize("mutate, key, words", [
    (lambda d: d["berries"][0].update(mass=-0.01), "berries[0].mass", "(0, 10] kg"),
    (lambda d: d["berries"][0].update(mass="heavy"), "berries[0].mass", "got str"),
    (lambda d: d["berries"][1].update(radius=0.05), "berries[1].radius", "smaller than twig_length"),
    (lambda d: d["berries"][0].update(angle=math.nan), "berries[0].angle", "[-3.14159, 3.14159] rad"),
    (lambda d: d["berries"][0].update(colour="red"), "berries[0].colour", "unknown key"),
    (lambda d: d["berries"][1].update(hinge_x=0.0), "berries[1].hinge_x", "overlap"),
    (lambda d: (d["berries"][0].update(angle=0.0), d["berries"][1].update(angle=-0.5)), "berries[1].angle", "overlap"),
    (lambda d: d["contact"].update(law="rubber"), "contact.law", "'kelvin-voigt'"),
    (lambda d: d["contact"].update(damping=1.0), "contact.restitution", "not both"),
    (lambda d: d["contact"].update(restitution=1.5), "contact.restitution", "(0, 1]"),
    (lambda d: d.update(solver={"rtol": 0.0}), "solver.rtol", "[1e-14, 0.1]"),
    (lambda d: d.update(solver={"method": "euler"}), "solver.method", "'event'"),
    (lambda d: d.update(excitation={"kind": "sine", "amplitude": [1.0, math.inf], "frequency": 5.0}),
     "excitation.amplitude[1]", "m/s²"),
    (lambda d: d.update(excitation={"kind": "csv", "file": "missing.csv"}), "excitation.file", "cannot read"),
    # a table's time out of order, or before 0 s, named by its row (they named none; an audit)
    (lambda d: d.update(excitation={"kind": "csv", "text": "0,0,0\n0.2,1,0\n0.1,0,0\n", "after": "zero"}),
     "excitation.text", "row 3 column time: 0.1 s is not after row 2's 0.2 s"),
    (lambda d: d.update(excitation={"kind": "csv", "text": "time,ax,az\n-0.5,0,0\n1,0,0\n", "after": "zero"}),
     "excitation.text", "row 1 column time: -0.5 s"),
    # a turn planar berries cannot follow, named by the key that gives it (both were refused as excitation.file)
    (lambda d: d.update(excitation={"kind": "pick-and-place", "moves": [
        {"displacement": [0.0, 0.05], "duration": 0.5}, {"duration": 0.5, "rotation": [0.2, 0.0, 0.0]}]}),
     "excitation.moves", "the angular acceleration at t = 0.5625 s turns the rachis about an axis other than its y"),
    (lambda d: d.update(excitation={"kind": "csv", "text": "0,0,0,0,0,0,0\n1,0,0,0,0,0,3\n", "after": "zero"}),
     "excitation.text", "the angular acceleration at t = 1 s turns the rachis about an axis other than its y"),
    (lambda d: d.update(gravity=-9.81), "gravity", "[0, 100]"),
    (lambda d: d.update(thresholds={"bruise_force": 0}), "thresholds.bruise_force", "(0, 10000] N"),
    (lambda d: d.update(berries=[]), "berries", "at least one"),
    (lambda d: d["berries"][0].update(kind="spherical", angle=[0.0, 0.0], rest_angles=[1.56, 0.0]),
     "berries[0].rest_angles[0]", "±80°"),
    (lambda d: d.update(solver={"max_steps": None}), "solver.max_steps", "leave a setting out"),  # no TOML null
    (lambda d: d["contact"].update(stiffness=None), "contact.stiffness", "got NoneType"),
    # names that combine into another's: one frame, column or topic for two (found by an audit: the CSV dropped a
    # pair's force, the MCAP put two pairs on one topic, and TF gave a frame two parents)
    (lambda d: d["berries"][1].update(name="left_hinge"), "berries[1].name", "frame name 'left_hinge', which 'left'"),
    (lambda d: d["berries"][1].update(name="rachis"), "berries[1].name", "names the rachis' frame"),
    (lambda d: (d["berries"][0].update(name="x", kind="spherical", angle=[0.0, 0.0]),
                d["berries"][1].update(name="x_swing", angle=0.0)), "berries[1].name", "angle name 'x_swing'"),
    (lambda d: d.update(berries=[{**d["berries"][0], "name": n, "hinge_x": x, "angle": 0.0}
                                 for n, x in (("a", -0.045), ("b_c", -0.015), ("a_b", 0.015), ("c", 0.045))]),
     "berries[3].name", "contact pair name 'a_b_c', which 'b_c' gives too"),
])
def test_bad_value_is_named(mutate, key, words):
    doc = dual()
    mutate(doc)
    with pytest.raises(SceneError) as ei:
        scene(doc)
    assert ei.value.key == key
    assert words in str(ei.value)


def _berry(k, **change):
    """A code change of the dual scene: berry k's fields replaced."""
    def apply(sc):
        berries = list(sc.model.berries)
        berries[k] = replace(berries[k], **change)
        return replace(sc, model=replace(sc.model, berries=tuple(berries)))
    return apply


def _law(**change):
    def apply(sc):
        pr = sc.model.pairs[0]
        return replace(sc, model=replace(sc.model, pairs=(replace(pr, law=replace(pr.law, **change)),)))
    return apply


def _plate(**change):
    """The dual scene with a floor plate (a box) under it, changed."""
    def apply(sc):
        box = Obstacle("plate", "box", (0.0, 0.0, -0.2), size=(0.2, 0.2, 0.02))
        touching = tuple(ContactPair(i, 2, sc.model.pairs[0].law) for i in range(2))
        return replace(sc, model=replace(sc.model, obstacles=(replace(box, **change),),
                                         pairs=sc.model.pairs + touching))
    return apply


SPHERICAL = {"kind": "spherical", "angle": [0.0, 0.0]}


@pytest.mark.parametrize("file_change, code_change, file_key, code_key, words", [
    (lambda d: d["berries"][0].update(mass=-0.01), _berry(0, mass=-0.01), "berries[0].mass", "berries[0].mass",
     "(0, 10] kg"),
    (lambda d: d["berries"][1].update(radius=0.05), _berry(1, radius=0.05), "berries[1].radius", "berries[1].radius",
     "smaller than twig_length"),
    (lambda d: d["berries"][0].update(hinge_damping=-1.0), _berry(0, hinge_damping=-1.0), "berries[0].hinge_damping",
     "berries[0].hinge_damping", "[0, 1000] N·m·s/rad"),
    (lambda d: d["berries"][0].update(hinge_stiffness=math.nan), _berry(0, hinge_stiffness=math.nan),
     "berries[0].hinge_stiffness", "berries[0].hinge_stiffness", "[0, 1000] N·m/rad"),
    (lambda d: d["berries"][0].update(SPHERICAL, rest_angles=[1.56, 0.0]), _berry(0, spherical=True, rest_angles=(1.56, 0.0)),
     "berries[0].rest_angles[0]", "berries[0].rest_angles[0]", "±80°"),
    (lambda d: d.update(gravity=-9.81), lambda sc: replace(sc, model=replace(sc.model, gravity=-9.81)), "gravity",
     "gravity", "[0, 100] m/s²"),
    (lambda d: d["contact"].update(restitution=1.5), _law(restitution=1.5), "contact.restitution",
     "contact[0].restitution", "(0, 1]"),
    (lambda d: d["contact"].update(stiffness=math.inf), _law(stiffness=math.inf), "contact.stiffness",
     "contact[0].stiffness", "(0, 1e+09] N/m"),
    (lambda d: d.update(contact={"law": "hunt-crossley", "damping": 2e3}), _law(kind="hunt-crossley", damping=2e3),
     "contact.damping", "contact[0].damping", "[0, 1000] (χ, dimensionless)"),
    (lambda d: d.update(coupling={"stiffness": -1.0}),
     lambda sc: replace(sc, model=replace(sc.model, couplings=(Coupling(0, 1, -1.0, 0.0),))),
     "coupling.stiffness", "couplings[0].stiffness", "[0, 1e+06] N/m"),
    (lambda d: d.update(obstacles=[{"name": "plate", "kind": "box", "centre": [0.0, 0.0, -0.2],
                                    "size": [0.2, 0.0, 0.02]}]), _plate(size=(0.2, 0.0, 0.02)),
     "obstacles[0].size[1]", "obstacles[0].size[1]", "expected a number in (0, 100] m, got 0.0"),
    (lambda d: d.update(obstacles=[{"name": "plate", "kind": "box", "centre": [0.0, 0.0, -0.2],
                                    "size": [0.2, 200.0, 0.02]}]), _plate(size=(0.2, 200.0, 0.02)),
     "obstacles[0].size[1]", "obstacles[0].size[1]", "expected a number in (0, 100] m, got 200"),
    (lambda d: d.update(obstacles=[{"name": "plate", "kind": "box", "centre": [0.0, 0.0, -0.2], "size": [0.2, 0.2, 0.02],
                                    "bruise_energy": -1.0}]), _plate(bruise_energy=-1.0),
     "obstacles[0].bruise_energy", "obstacles[0].bruise_energy", "(0, 1000] J"),
    (lambda d: d.update(solver={"rtol": 0.0}), lambda sc: replace(sc, solver=replace(sc.solver, rtol=0.0)),
     "solver.rtol", "solver.rtol", "[1e-14, 0.1]"),
    (lambda d: d.update(solver={"t_end": 0.5, "output_interval": 0.6}),
     lambda sc: replace(sc, solver=replace(sc.solver, t_end=0.5, output_interval=0.6)), "solver.output_interval",
     "solver.output_interval", "0.5"),
    (lambda d: d.update(solver={"method": "euler"}), lambda sc: replace(sc, solver=replace(sc.solver, method="euler")),
     "solver.method", "solver.method", "'event'"),
    (lambda d: d.update(solver={"integrator": "RK45"}),
     lambda sc: replace(sc, solver=replace(sc.solver, integrator="RK45")), "solver.integrator", "solver.integrator",
     "'DOP853'"),
    (lambda d: d.update(solver={"integrator": "DOP853", "method": "paper"}),
     lambda sc: replace(sc, solver=replace(sc.solver, integrator="DOP853", method="paper")), "solver.integrator",
     "solver.integrator", "for the 'event' method"),
    (lambda d: d.update(solver={"integrator": "DOP853", "fixed_step": 1e-3}),
     lambda sc: replace(sc, solver=replace(sc.solver, integrator="DOP853", fixed_step=1e-3)), "solver.integrator",
     "solver.integrator", "a fixed step (0.001 s) steps DOPRI5"),
    (lambda d: d.update(thresholds={"fatigue_fraction": 2.0}),
     lambda sc: replace(sc, thresholds=replace(sc.thresholds, fatigue_fraction=2.0)), "thresholds.fatigue_fraction",
     "thresholds.fatigue_fraction", "(0, 1]"),
    (lambda d: d["berries"][1].update(angular_velocity=math.nan),
     lambda sc: replace(sc, angular_velocities=(0.0, math.nan)), "berries[1].angular_velocity", "angular_velocities[1]",
     "[-1000, 1000] rad/s"),
    (lambda d: d["berries"][0].update(SPHERICAL, angle=[1.5, 0.0]),
     lambda sc: replace(sc, model=replace(sc.model, berries=(replace(sc.model.berries[0], spherical=True),
                                                             sc.model.berries[1])),
                        angles=(1.5, 0.0, sc.angles[1]), angular_velocities=(0.0,) * 3),
     "berries[0].angle[0]", "angles[0]", "±80°"),
])
def test_a_scene_built_in_code_meets_the_scene_files_ranges(file_change, code_change, file_key, code_key, words):
    """The ranges are declared once (model/bounds.py): a scene changed in code with `dataclasses.replace` skipped the
    scene file's checks (a NaN hinge stiffness stepped for minutes to the step limit; a negative mass, a restitution of
    1.5 or gravity −9.81 ran). Both ways are refused, with the same range in the message."""
    doc = dual()
    file_change(doc)
    with pytest.raises(SceneError) as by_file:
        scene(doc)
    with pytest.raises(SceneError) as by_code:
        code_change(scene(dual()))
    assert (by_file.value.key, by_code.value.key) == (file_key, code_key)
    assert words in str(by_file.value) and words in str(by_code.value)


@pytest.mark.parametrize("file_change, code_change, file_key, code_key, words", [
    (lambda d: (d["berries"][0].update(angle=0.0), d["berries"][1].update(angle=-0.5)),
     lambda sc: replace(sc, angles=(0.0, -0.5)), "berries[1].angle", "angles[1]", "overlap by"),
    (lambda d: (d["berries"][0].update(angle=0.0), d["berries"][1].update(SPHERICAL, angle=[-0.5, 0.0])),
     lambda sc: replace(sc, model=replace(sc.model, berries=(sc.model.berries[0],
                                                             replace(sc.model.berries[1], spherical=True))),
                        angles=(0.0, -0.5, 0.0), angular_velocities=(0.0,) * 3),
     "berries[1].angle", "angles[1]", "overlap by"),
    (lambda d: d.update(obstacles=[{"name": "plate", "kind": "box", "centre": [0.0, 0.0, -0.035], "size": [0.2, 0.2, 0.02]}]),
     _plate(point=(0.0, 0.0, -0.035)), "obstacles[0].centre", "obstacles[0].point", "in the initial state"),
])
def test_a_start_overlapping_too_deep_is_refused_however_the_scene_was_built(file_change, code_change, file_key,
                                                                             code_key, words):
    """A scene built in code used to skip the file's overlap check: the right berry started 6 mm into the left one
    and was flung to 137°. The file refuses such a start on its keys, a run (Solver, simulate) on the model's."""
    doc = dual()
    file_change(doc)
    with pytest.raises(SceneError) as by_file:
        scene(doc)
    with pytest.raises(SceneError) as by_code:
        Solver(code_change(scene(dual())))
    assert (by_file.value.key, by_code.value.key) == (file_key, code_key)
    assert words in by_file.value.why and words in by_code.value.why


def test_the_overlap_a_start_may_hold_is_a_fifth_of_the_smaller_radius_however_the_scene_is_built():
    """The bound against the geometry worked out here (centre = hinge + L (sin q, 0, −cos q)): a start 0.19 of the
    radius deep runs, 0.21 is refused by simulate, naming the angle and the allowed overlap."""
    from scipy.optimize import brentq

    sc = scene(dual())
    left, right = sc.model.berries
    cl = (left.hinge_x, -left.twig_length)  # the left berry hanging straight down

    def overlap(q):
        c = (right.hinge_x + right.twig_length * math.sin(q), -right.twig_length * math.cos(q))
        return left.radius + right.radius - math.dist(cl, c)

    for fraction, refused in ((0.19, False), (0.21, True)):
        q = brentq(lambda q: overlap(q) - fraction * right.radius, -1.0, 0.0)
        if not refused:
            assert simulate(replace(sc, angles=(0.0, q)), 0.01).t[-1] == pytest.approx(0.01)
            continue
        with pytest.raises(SceneError) as e:
            simulate(replace(sc, angles=(0.0, q)), 0.01)
        assert e.value.key == "angles[1]"
        assert f"overlap by {fraction * right.radius * 1e3:.3g} mm" in e.value.why
        assert f"at most {0.2 * right.radius * 1e3:.3g} mm" in e.value.why


def test_a_scene_built_in_code_refuses_a_wrong_length_list():
    sc = scene(dual())
    with pytest.raises(SceneError, match="one per angle, 2"):
        replace(sc, angles=(0.0,))
    with pytest.raises(SceneError, match="contact.0.: expected a berry and another body"):
        replace(sc, model=replace(sc.model, pairs=(ContactPair(0, 5, sc.model.pairs[0].law),)))


def test_hunt_crossley_restitution_whose_damping_is_out_of_range_is_refused():
    """χ(e) grows as 1/e: a restitution of 1e-4 asks for χ = 1e4, outside the law's damping range, which the scene
    file used to accept (a damping given as a number was refused there)."""
    with pytest.raises(SceneError, match=r"contact.restitution: 0.0001 needs χ = 1e\+04"):
        scene(dual(contact={"law": "hunt-crossley", "restitution": 1e-4}))
    assert scene(dual(contact={"law": "hunt-crossley", "restitution": 0.0011})).model.pairs[0].law.damping < 1e3


def test_invalid_toml_and_nan_in_toml():
    with pytest.raises(SceneError, match="not valid TOML"):
        parse_scene("berries = [")
    text = ('[[berries]]\nname="a"\nmass=nan\nradius=0.01\ntwig_length=0.03\nhinge_x=0.0\n')
    with pytest.raises(SceneError, match=r"berries\[0\]\.mass"):
        parse_scene(text)


def test_cli_reports_bad_scene_without_traceback(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text('[[berries]]\nname="a"\nmass=-1\nradius=0.01\ntwig_length=0.03\nhinge_x=0.0\n')
    out = tmp_path / "run.csv"
    r = subprocess.run([sys.executable, "-m", "grapefmu", "simulate", str(bad), "--out", str(out)],
                       capture_output=True, text=True)
    assert r.returncode == 2
    assert "berries[0].mass" in r.stderr and "Traceback" not in r.stderr
    assert not out.exists()


def test_scene_built_in_code_carries_toml_that_loads_back_to_the_same_model():
    sc = scene(dual(excitation={"kind": "pick-and-place", "moves": [{"displacement": [0.2, 0.1], "duration": 0.5}]},
                    coupling={"stiffness": 1.0}))
    again = parse_scene(sc.source)
    assert again.model == sc.model and again.angles == sc.angles
    assert (again.excitation.arrays.table == sc.excitation.arrays.table).all()


@pytest.mark.parametrize("times", [("0", "5e-324", "1e-323"), ("0", "1e160")])
def test_pose_table_times_no_spline_can_follow_are_refused(times):
    """Steps of 1e-323 s raised scipy's ValueError from the spline, and a table spanning 1e160 s one from the turn's
    rotation vectors: tracebacks (found by fuzzing scene files). Now the key and why."""
    rows = "".join(f"{t},{0.001 * k},0,0,0,0,0\n" for k, t in enumerate(times))
    doc = dual(excitation={"kind": "pose-table", "text": "time,x,y,z,roll,pitch,yaw\n" + rows})
    with pytest.raises(SceneError, match="too close together or too far apart to interpolate") as e:
        scene(doc)
    assert e.value.key == "excitation.text"


def test_a_mass_whose_inertia_underflows_is_refused_by_the_solver():
    """mass = 5e-324 kg is in (0, 10] kg, but m l² underflows to 0: ZeroDivisionError in the stiffness bound."""
    sc = scene(dual(left={"mass": 5e-324}))
    with pytest.raises(SolverError, match="too stiff"):
        simulate(sc, 0.01)


def test_a_csv_excitation_s_angular_accelerations_have_their_own_bound():
    """A 7-column CSV held α to the linear bound (1000) and said so in m/s²: 5000 rad/s², within the documented 1e4,
    was refused (found by fuzzing scene files)."""
    table = "time,ax,ay,az,alpha_x,alpha_y,alpha_z\n0,0,0,0,0,{a},0\n0.5,0,0,0,0,{a},0\n"
    spherical = {"kind": "spherical", "angle": [0.0, 0.0]}
    doc = dual(left=spherical, right=spherical, excitation={"kind": "csv", "text": table.format(a=5000.0),
                                                             "after": "zero"})
    scene(doc)
    doc["excitation"]["text"] = table.format(a=2e4)
    with pytest.raises(SceneError, match=r"angular accelerations must stay within ±10000 rad/s²") as e:
        scene(doc)
    assert e.value.key == "excitation.text"


@pytest.mark.parametrize("times, row, apart", [
    (("0", "5e-324", "1e-323"), 2, "1.6e-14 s"),
    (("0", "0.001", "0.001000000000000001", "0.002"), 3, "1.6e-14 s"),
    (("1e-300", "0.5"), 1, "1.6e-14 s"),  # the table is zero before its first row: a breakpoint 1e-300 s into the run
    (("0", "100", "100.0000000000001"), 3, "1.6e-12 s"),  # the floor grows with the time, as the solver's does
])
def test_csv_rows_closer_than_the_solver_steps_are_refused(times, row, apart):
    """A CSV whose time column steps by 5e-324 or 1e-300 s passed the scene and ran 10⁷ steps of 0 s at t = 0 (a
    starting step toward a row 1e-300 s away overflows the first step's probe to 0) before the step limit stopped it,
    minutes later (found by fuzzing scene files). Rows are now held at least the solver's shortest step apart, before
    a step."""
    text = "time,ax,az\n" + "".join(f"{t},{k % 2},0\n" for k, t in enumerate(times))
    doc = dual(excitation={"kind": "csv", "text": text, "after": "zero"})
    with pytest.raises(SceneError, match=rf"inline CSV row {row} column time: .* rows must be at least {apart} apart"
                                         r" \(1\.6e-14 s per second of max\(1 s, time\)") as e:
        scene(doc)
    assert e.value.key == "excitation.text"


def test_csv_file_rows_too_close_are_refused_naming_the_file(tmp_path):
    (tmp_path / "shake.csv").write_text("time,ax,az\n0,0,0\n1e-300,1,0\n2e-300,0,0\n")
    doc = dual(excitation={"kind": "csv", "file": "shake.csv", "after": "zero"})
    from grapefmu.scenefile import scene_from_dict
    with pytest.raises(SceneError, match=r"shake\.csv row 2 column time: 1e-300 s is 1e-300 s after row 1's 0\.0") as e:
        scene_from_dict(doc, tmp_path)
    assert e.value.key == "excitation.file"


def test_pose_table_rows_closer_than_the_solver_steps_are_refused():
    """Poses 1e-300 s apart that stand still: the spline follows them (no jump to refuse), and the run stalled as the
    CSV's did."""
    text = "time,x,y,z,roll,pitch,yaw\n0,0,0,0,0,0,0\n1e-300,0,0,0,0,0,0\n0.05,0.001,0,0,0,0,0\n"
    with pytest.raises(SceneError, match=r"inline CSV row 2 column time: 1e-300 s .* at least 1\.6e-14 s apart") as e:
        scene(dual(excitation={"kind": "pose-table", "text": text}))
    assert e.value.key == "excitation.text"


@pytest.mark.parametrize("rate, hold", [(1e3, False), (1e4, False), (1e4, True)])
def test_csv_sampled_at_1_and_10_khz_still_runs(rate, hold):
    """The floor on row spacing is ten orders of magnitude below a controller's or a sensor's sample interval."""
    t = [k / rate for k in range(int(0.05 * rate) + 1)]
    text = "time,ax,az\n" + "".join(f"{x!r},{20 * math.sin(2 * math.pi * 30 * x)!r},0\n" for x in t)
    run = simulate(scene(dual(excitation={"kind": "csv", "text": text, "hold": hold}, solver={"t_end": 0.05})))
    assert run.t[-1] == pytest.approx(0.05)


@pytest.mark.parametrize("rows, row", [
    ([[0.0, 0.0, 0.0], [1e-300, 1.0, 0.0], [2e-300, 0.0, 0.0]], 2),
    ([[0.0, 0.0, 0.0], [0.5, 1.0, 0.0], [0.5, 2.0, 0.0], [0.5 + 1e-16, 0.0, 0.0]], 4),  # after a staircase's knot
    ([[0.0, 0.0, 0.0], [0.5, 1.0, 0.0], [0.25, 0.0, 0.0]], 3),
])
def test_a_table_built_in_code_with_rows_closer_than_the_solver_steps_is_refused_naming_the_row(rows, row):
    """A table the file refuses, put in a scene in code (excitation.table, as fit/shooting.py does), skipped the file's
    check: its run stopped at t = 0 on "the step size fell below the resolution of time", a reason about stiffness
    that names no key. The scene refuses it as the file does, naming the excitation, the row and the spacing allowed.
    A time repeated on the next row (a staircase's doubled knot) is one breakpoint and runs."""
    from grapefmu.model import excitation as exc

    sc = scene(dual(solver={"t_end": 0.1}))
    with pytest.raises(SceneError) as e:
        replace(sc, excitation=exc.table("csv", np.array(rows)))
    assert e.value.key == "excitation"
    least = exc.TIME_RESOLUTION * max(1.0, rows[row - 2][0])
    assert f"row {row} column time" in e.value.why and f"rows must be at least {least:.3g} s apart" in e.value.why
    if rows[1][0] == 1e-300:
        text = "time,ax,az\n" + "".join(f"{t!r},{a!r},{b!r}\n" for t, a, b in rows)
        with pytest.raises(SceneError) as by_file:
            scene(dual(excitation={"kind": "csv", "text": text}))
        assert by_file.value.why.split("row", 1)[1] == e.value.why.split("row", 1)[1]  # the same words after the path
    stairs = exc.zero_order_hold(np.array([[0.0, 1.0, 0.0], [0.05, -1.0, 0.0], [0.1, 0.0, 0.0]]))
    assert Solver(replace(sc, excitation=exc.table("csv", stairs))).run().t[-1] == 0.1


@pytest.mark.parametrize("jf", [1e-16, 1e-20])
def test_a_jerk_fraction_too_small_to_keep_its_ramps_is_refused(jf):
    """Ramps shorter than 1e-15 s were merged away (pick_and_place drops a knot that close to the one before): the
    move's acceleration became a triangle, and a 0.1 m move of 0.1 s ended at 0.083 m still moving at 1 m/s
    (found by simulating it: the rachis was at 0.283 m at 0.3 s). A jerk_fraction below 0.001 is now refused."""
    doc = dual(excitation={"kind": "pick-and-place", "moves": [{"displacement": [0.1, 0.0], "duration": 0.1}],
                           "jerk_fraction": jf})
    with pytest.raises(SceneError) as e:
        scene(doc)
    assert e.value.key == "excitation.jerk_fraction" and "[0.001, 0.25]" in str(e.value)


@pytest.mark.parametrize("jf", [0.0, 1e-16, 0.3, -0.1, math.nan, True])
def test_pick_and_place_refuses_a_jerk_fraction_its_moves_cannot_keep(jf):
    """In code, pick_and_place took any jerk_fraction: 0 made each move's acceleration a triangle that ended the move
    off its displacement, 0.3 or -0.1 ramps that cross (times running backwards). It refuses them as a scene file
    does, naming the key."""
    from grapefmu.model.excitation import integrate_table, pick_and_place
    with pytest.raises(SceneError) as e:
        pick_and_place([((0.1, 0.0), 0.1)], jerk_fraction=jf)
    assert e.value.key == "excitation.jerk_fraction" and "[0.001, 0.25]" in str(e.value)
    for ok in (1e-3, 0.25):  # the ends of the range: the move ends at its displacement, at rest
        rows = pick_and_place([((0.1, 0.0), 0.1)], jerk_fraction=ok).arrays.table
        v, x = integrate_table(rows)
        assert np.diff(rows[:, 0]).min() > 0.0
        assert x[-1, 0] == pytest.approx(0.1, rel=1e-12) and abs(v[-1, 0]) < 1e-12
