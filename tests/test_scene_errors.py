"""Every bad value gives one clear error naming the key and the allowed range."""
from __future__ import annotations

import math
import subprocess
import sys
from dataclasses import replace

import pytest

from grapefmu import SceneError
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
    (lambda d: d.update(gravity=-9.81), "gravity", "[0, 100]"),
    (lambda d: d.update(thresholds={"bruise_force": 0}), "thresholds.bruise_force", "(0, 10000] N"),
    (lambda d: d.update(berries=[]), "berries", "at least one"),
    (lambda d: d["berries"][0].update(kind="spherical", angle=[0.0, 0.0], rest_angles=[1.56, 0.0]),
     "berries[0].rest_angles[0]", "±80°"),
])
def test_bad_value_is_named(mutate, key, words):
    doc = dual()
    mutate(doc)
    with pytest.raises(SceneError) as ei:
        scene(doc)
    assert ei.value.key == key
    assert words in str(ei.value)


@pytest.mark.parametrize("change, key", [
    (lambda sc: replace(sc, model=replace(sc.model, berries=(replace(sc.model.berries[0], hinge_stiffness=math.nan),
                                                              sc.model.berries[1]))), "berries[0].hinge_stiffness"),
    (lambda sc: replace(sc, model=replace(sc.model, pairs=(replace(sc.model.pairs[0], law=replace(
        sc.model.pairs[0].law, stiffness=math.inf)),))), "contact[0].stiffness"),
    (lambda sc: replace(sc, angular_velocities=(0.0, math.nan)), "angular_velocities[1]"),
    (lambda sc: replace(sc, angles=(0.0,)), "angles"),
])
def test_scene_built_in_code_refuses_a_number_the_core_cannot_read(change, key):
    """A scene changed in code skips the scene file's checks: with a NaN hinge stiffness `simulate` stepped for
    minutes to its step limit, and a short angle list failed in numpy's broadcasting. Refused where it is built,
    naming the field."""
    with pytest.raises(SceneError) as ei:
        change(scene(dual()))
    assert ei.value.key == key
    assert "finite" in str(ei.value) or "one per angle" in str(ei.value)


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
