"""The built FMU (not the source module), run in fresh processes through fmpy and libcosimpy,
against `grapefmu simulate` on the same scene and inputs."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import zipfile
from pathlib import Path
from xml.etree import ElementTree as ET

import numpy as np
import pytest

from grapefmu import simulate
from grapefmu.physics.excitation import ACCEL_COMPONENTS, accel
from grapefmu.scenefile import default_scene_path
from grapefmu.model.excitation import pick_and_place
from grapefmu.scenefile import scene_from_dict

pytest.importorskip("fmpy")
ROOT = Path(__file__).resolve().parents[1]
STOP = 1.5


def run(*args, timeout=600, env=None):
    r = subprocess.run([sys.executable, *args], capture_output=True, text=True, cwd=ROOT, timeout=timeout, env=env)
    assert r.returncode == 0, r.stderr[-3000:]
    return r


def drive(*args, env=None, log=False):
    """The driver's JSON (and with log=True what the FMU logged)."""
    r = run("-m", "tests.fmu_driver", *map(str, args), env=env)
    head, tail = r.stdout.split("JSON:", 1)
    return (json.loads(tail), head + r.stderr) if log else json.loads(tail)


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    d = tmp_path_factory.mktemp("fmu")
    for fmi in (2, 3):
        run("-m", "grapefmu", "build-fmu", "-o", str(d / f"default{fmi}.fmu"), "--fmi", str(fmi))
    # a pick-and-place acceleration, sampled every 10 ms and held (what a controller sends)
    t = np.round(np.arange(0, STOP + 1e-9, 1e-2), 10)
    ex = pick_and_place([((0.0, 0.1), 0.3), ((0.3, 0.0), 0.5), ((0.0, -0.1), 0.3)], start=0.05)
    np.savetxt(d / "signal.csv", np.column_stack([t, accel(ex, t)]), delimiter=",",
               header=",".join(["time", *ACCEL_COMPONENTS]), comments="")
    return d


@pytest.fixture(scope="module")
def reference(fmus):
    """grapefmu simulate on the same scene, driven by the same held signal."""
    import tomllib
    doc = tomllib.loads(default_scene_path().read_text())
    doc["excitation"] = {"kind": "csv", "file": str(fmus / "signal.csv"), "hold": True}
    return simulate(scene_from_dict(doc, ROOT), STOP)


def test_validator_reports_no_problems(fmus):
    from fmpy.validation import validate_fmu
    for fmi in (2, 3):
        assert validate_fmu(str(fmus / f"default{fmi}.fmu")) == []


def test_description_units_version_and_capabilities(fmus):
    from grapefmu import __version__
    for fmi in (2, 3):
        with zipfile.ZipFile(fmus / f"default{fmi}.fmu") as z:
            root = ET.fromstring(z.read("modelDescription.xml"))
            names = z.namelist()
        assert f"grapefmu {__version__}" in root.get("description")
        assert "resources/scene.toml" in names and "resources/bundle/grapefmu/__init__.py" in names
        cs = root.find("CoSimulation")
        assert cs.get("canGetAndSetFMUstate" if fmi == 2 else "canGetAndSetFMUState") == "true"
        units = {u.get("name") for u in root.iter("Unit")}
        assert {"rad", "rad/s", "N", "m/s2", "kg", "J"} <= units
    with zipfile.ZipFile(fmus / "default2.fmu") as z:
        root = ET.fromstring(z.read("modelDescription.xml"))
    reals = {sv.get("name"): sv.find("Real") for sv in root.iter("ScalarVariable") if sv.find("Real") is not None}
    assert reals["angle_left"].get("unit") == "rad" and reals["contact_force_left_right"].get("unit") == "N"
    assert all(r.get("unit") for n, r in reals.items() if n not in ("restitution", "rtol"))
    assert all(sv.get("description") for sv in root.iter("ScalarVariable"))


def test_description_tells_the_truth(fmus):
    """Outputs are calculated (no start value), depend on no input, the scene gives the default experiment,
    and both versions say the step may vary (results do not depend on it: test below)."""
    import tomllib
    sv = tomllib.loads(default_scene_path().read_text(encoding="utf-8"))["solver"]
    for fmi in (2, 3):
        with zipfile.ZipFile(fmus / f"default{fmi}.fmu") as z:
            root = ET.fromstring(z.read("modelDescription.xml"))
        assert root.find("CoSimulation").get("canHandleVariableCommunicationStepSize") == "true"
        ex = root.find("DefaultExperiment")
        assert float(ex.get("stopTime")) == sv["t_end"] and float(ex.get("tolerance")) == sv["rtol"]
        if fmi == 2:
            outs = [sv_ for sv_ in root.iter("ScalarVariable") if sv_.get("causality") == "output"]
            assert all(o.get("initial") == "calculated" and o[0].get("start") is None for o in outs)
            unknowns = root.find("ModelStructure/Outputs")
            assert len(unknowns) == len(outs) and all(u.get("dependencies") == "" for u in unknowns)
            assert len(root.find("ModelStructure/InitialUnknowns")) == len(outs)
        else:
            outs = [v for v in root.find("ModelVariables") if v.get("causality") == "output"]
            assert all(o.get("initial") == "calculated" and o.get("start") is None for o in outs)
            deps = root.find("ModelStructure").findall("Output")
            assert len(deps) == len(outs) and all(d.get("dependencies") == "" for d in deps)


def test_initial_state_is_set_by_parameters_and_damping_has_one_setting(fmus):
    code = f"""
import sys
sys.path.insert(0, {str(ROOT)!r})
from tests.fmu_driver import Fmu2
from fmpy.fmi1 import FMICallException
path = {str(fmus / 'default2.fmu')!r}
f = Fmu2(path, params={{"initial_angle_left": 0.2, "initial_angular_velocity_right": -1.0}})
print("START", f.get(["angle_left", "angular_velocity_right"]) + Fmu2(path, "rest").get(["pedicel_tension_left"]))
for name, params in (("both", {{"restitution": 0.5, "contact_damping": 1.0}}),
                     ("hertz", {{"contact_law": 1, "restitution": 0.5}})):
    try:
        Fmu2(path, name, params=params)
        print("RESULT", name, "ok")
    except FMICallException as e:
        print("RESULT", name, e)
sys.stdout.flush()
"""
    out = run("-c", code)
    start = eval(out.stdout.split("START", 1)[1].splitlines()[0])
    assert start[:2] == [0.2, -1.0]
    assert abs(start[2] - 0.011 * 9.81) < 1e-9  # a berry at rest hangs on its pedicel, read right after initialization
    assert "RESULT both fmi2ExitInitializationMode failed with status 3" in out.stdout
    assert "RESULT hertz fmi2ExitInitializationMode failed with status 3" in out.stdout
    assert "set one of them" in out.stdout + out.stderr and "has no damping" in out.stdout + out.stderr


def test_fmpy_matches_grapefmu_simulate(fmus, reference):
    res = drive("fmpy", fmus / "default2.fmu", fmus / "signal.csv", STOP, 1e-3)
    ty = np.array(res["t_y"])
    assert res["collision_count"] == reference.collision_count > 0
    np.testing.assert_allclose(ty[:, 0], reference.t, atol=1e-9)
    np.testing.assert_allclose(ty[:, 1:3], reference.angles, atol=1e-6)
    np.testing.assert_allclose(ty[:, 5], reference.contact_force[:, 0], atol=1e-4)


def test_result_does_not_depend_on_the_communication_step(fmus):
    runs = {dt: np.array(drive("fmpy", fmus / "default2.fmu", fmus / "signal.csv", 0.6, dt)["t_y"])
            for dt in (1e-4, 1e-3, 1e-2)}
    coarse = runs[1e-2]
    for dt in (1e-4, 1e-3):
        common = runs[dt][:: round(1e-2 / dt)]
        np.testing.assert_allclose(common[:, 1:5], coarse[:, 1:5], atol=1e-6)


def test_state_roll_back_replays_bit_for_bit(fmus):
    r = drive("replay", fmus / "default2.fmu", fmus / "signal.csv")
    assert r == {**r, "same_in_memory": True, "same_from_bytes": True, "moved": True}


def test_two_instances_in_one_process_are_independent(fmus):
    r = drive("two", fmus / "default2.fmu", fmus / "signal.csv")
    assert r["a"] == r["alone"]
    assert r["b"] != r["a"]
    assert r["more_alike"]


def test_bad_input_is_refused_not_fatal_and_leaves_the_state(fmus):
    """Every input is checked when it is set, against the solver's bounds; the default scene is planar, so the
    rachis may turn about y only: its x and z angular inputs and an initial roll are refused, saying why."""
    r, log = drive("bad", fmus / "default2.fmu", log=True)
    parameters = ("bad parameter", "bad orientation", "out-of-plane orientation")
    for label in ("nan input", "inf input", "huge input", "nan angular velocity", "huge angular velocity",
                  "huge angular acceleration", "out-of-plane angular velocity", "out-of-plane angular acceleration",
                  "zero step", "negative step", *parameters):
        assert "status 3 (error)" in r[label], (label, r[label])
        if label not in parameters:
            assert r[label + " unchanged"], label
    assert r["recovers"]
    for message in ("input base_omega_y = 1000.0: expected an angular velocity within ±100 rad/s",
                    "input base_alpha_y = 1000000.0: expected an angular acceleration within ±10000 rad/s²",
                    "input base_omega_x = 0.5: this scene has planar berries",
                    "input base_alpha_z = -2.0: this scene has planar berries",
                    "rachis_pitch: expected a number in [-6.28319, 6.28319] rad, got 7.0",
                    "rachis_roll = 0.2, rachis_pitch = 0.0, rachis_yaw = 0.0: the initial orientation tilts",
                    "for planar berries rachis_roll must be 0"):
        assert message in log, message


def test_fmi3_refuses_bad_input_with_fmi3_error(fmus):
    code = f"""
import math
from fmpy import extract, read_model_description
from fmpy.fmi3 import FMU3Slave
from fmpy.fmi1 import FMICallException
path = {str(fmus / 'default3.fmu')!r}
md = read_model_description(path)
vr = {{v.name: v.valueReference for v in md.modelVariables}}
f = FMU3Slave(guid=md.guid, unzipDirectory=extract(path), modelIdentifier=md.coSimulation.modelIdentifier, instanceName='a')
f.instantiate(loggingOn=True)
f.enterInitializationMode(); f.exitInitializationMode()
try:
    f.setFloat64([vr['base_ax']], [math.nan])
    print('RESULT ok')
except FMICallException as e:
    print('RESULT', e)
f.setFloat64([vr['base_ax']], [2.0])
f.doStep(currentCommunicationPoint=0.0, communicationStepSize=1e-3)
print('TIME', f.getFloat64([vr['time']])[0], flush=True)
"""
    out = run("-c", code).stdout
    assert "RESULT fmi3SetFloat64 failed with status 3 (error)" in out
    assert "TIME 0.001" in out


def test_libcosimpy_runs_two_instances_and_matches(fmus, reference):
    pytest.importorskip("libcosimpy")
    r = drive("cosim", fmus / "default2.fmu", fmus / "signal.csv", STOP, 1e-3)
    a, b = np.array(r["a"]), np.array(r["b"])
    np.testing.assert_allclose(a[:, 1:3], reference.angles[1:], atol=1e-6)
    heavy = np.array(drive("fmpy", fmus / "default2.fmu", fmus / "signal.csv", STOP, 1e-3, "mass_right=0.02")["t_y"])
    np.testing.assert_allclose(b[:, 1:3], heavy[1:, 1:3], atol=1e-9)
    assert np.abs(b[:, 2] - a[:, 2]).max() > 1e-3


def test_ecospy_matches(fmus, reference):
    import os
    env = {**os.environ, "LD_LIBRARY_PATH": str(Path(sys.prefix) / "lib")}
    r = drive("ecos", fmus / "default2.fmu", fmus / "signal.csv", STOP, 1e-3, env=env)
    a = np.array(r["a"])
    np.testing.assert_allclose(a[:, 1:3], reference.angles[1:], atol=1e-6)


def test_libcosimpy_and_ecospy_take_the_fmus_warning_as_a_step_done(fmus):
    """doStep's Warning (a pair pressed past any contact law, docs/fmu.md) is a step done for every importer: on a
    1 N/m law the raised berry swings into the other past the bound, and libcosimpy and ecospy step on to the end,
    their outputs after every step those fmpy reads (which tests/test_fmu_boundaries.py checks warns)."""
    import os
    pytest.importorskip("libcosimpy")
    args = (fmus / "default2.fmu", fmus / "signal.csv", 0.6, 1e-3, "penetration_left_right,angle_left",
            "contact_stiffness=1.0", "initial_angle_right=0.8")
    ref = np.array(drive("named", *args[:5], *args[5:])["rows"])
    cosim = drive("cosim-named", *args)
    ecos = drive("ecos-named", *args, env={**os.environ, "LD_LIBRARY_PATH": str(Path(sys.prefix) / "lib")})
    assert ref[:, 1].max() > 0.2 * 0.0135 and len(ref) == 600  # past the bound: the FMU warned
    assert all(cosim["done"]) and len(cosim["done"]) == 600
    np.testing.assert_allclose(np.array(cosim["a"]), ref, rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.array(ecos["a"]), ref, rtol=0, atol=1e-12)


def test_build_rejects_a_bad_scene(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text('[[berries]]\nname="a"\nmass=-1\nradius=0.01\ntwig_length=0.03\nhinge_x=0.0\n')
    r = subprocess.run([sys.executable, "-m", "grapefmu", "build-fmu", str(bad), "-o", str(tmp_path / "x.fmu")],
                       capture_output=True, text=True)
    assert r.returncode == 2 and "berries[0].mass" in r.stderr
    assert not (tmp_path / "x.fmu").exists()


def test_cluster_fmu_has_summary_outputs_that_match_the_core(fmus):
    """A 30-berry spherical cluster: the FMU exposes the cluster totals (not one variable per idle
    pair), passes fmpy's validator and agrees with grapefmu simulate under the same held input."""
    import tomllib

    from fmpy.validation import validate_fmu

    scene = fmus / "cluster.toml"
    run("-m", "grapefmu", "cluster", "--berries", "30", "--seed", "2", "-o", str(scene))
    run("-m", "grapefmu", "build-fmu", str(scene), "-o", str(fmus / "cluster.fmu"))
    assert validate_fmu(str(fmus / "cluster.fmu")) == []
    stop = 1.0
    res = drive("summary", fmus / "cluster.fmu", fmus / "signal.csv", stop, 1e-2)
    assert res["variables"] < 40
    rows = np.array(res["rows"])
    doc = tomllib.loads(scene.read_text())
    doc["excitation"] = {"kind": "csv", "file": str(fmus / "signal.csv"), "hold": True}
    ref = simulate(scene_from_dict(doc, ROOT), stop, output_interval=1e-2)
    assert rows[-1, 5] == ref.collision_count > 5
    assert rows[-1, 1] == pytest.approx(ref.peak_force.max(), rel=1e-5)
    assert rows[-1, 2] == pytest.approx(ref.energy["dissipated_hinge"][-1] + ref.energy["dissipated_contact"][-1],
                                        rel=1e-5)
    np.testing.assert_allclose(rows[:, 3], ref.contact_force[1:].max(axis=1), atol=1e-4)
    np.testing.assert_allclose(rows[:, 4], ref.pedicel_tension[1:].max(axis=1), atol=1e-4)
    np.testing.assert_array_equal(rows[:, 6], ref.active_pairs[1:])


def test_the_benchmarks_fmu_run_leaves_no_temporary_files(tmp_path):
    """`grapefmu bench` steps each scene's FMU through fmpy (grapefmu_fmu.bench_run): it built and unpacked 37 MB per
    scene into temporary directories it never removed."""
    text = default_scene_path().read_text()
    assert "t_end = 2.5" in text
    scene = tmp_path / "short.toml"
    scene.write_text(text.replace("t_end = 2.5", "t_end = 0.01"))
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    r = subprocess.run([sys.executable, "-m", "grapefmu_fmu.bench_run", str(scene)], capture_output=True, text=True,
                       timeout=600, env={**os.environ, "TMPDIR": str(tmp)})
    assert r.returncode == 0, r.stderr[-2000:]
    out = json.loads(r.stdout.split("JSON:", 1)[1])
    assert len(out["angles"]) == 11 and np.isfinite(out["angles"]).all()
    assert list(tmp.iterdir()) == []
