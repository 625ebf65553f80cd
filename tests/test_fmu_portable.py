"""The FMU runs from the file alone: a fresh Python 3.11 environment with only fmpy, then the FMU's own
requirements from its resources (what a co-simulation user has), simulates it and matches `grapefmu
simulate` on the same scene and held input."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
STOP, DT, ACCEL = 1.0, 1e-3, (1.5, -0.5)

DRIVER = """
import json, sys, time
t0 = time.perf_counter()
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave
path = sys.argv[1]
md = read_model_description(path)
vr = {v.name: v.valueReference for v in md.modelVariables}
f = FMU2Slave(guid=md.guid, unzipDirectory=extract(path), modelIdentifier=md.coSimulation.modelIdentifier,
              instanceName="a")
f.instantiate()
f.setupExperiment(startTime=0.0)
f.enterInitializationMode()
f.exitInitializationMode()
f.setReal([vr["base_ax"], vr["base_az"]], [%r, %r])
angles = []
for k in range(%d):
    f.doStep(k * %r, %r)
    angles.append(f.getReal([vr["angle_left"], vr["angle_right"]]))
f.terminate()
f.freeInstance()
print("JSON:" + json.dumps({"angles": angles, "seconds": time.perf_counter() - t0}), flush=True)
"""


@pytest.fixture(scope="module")
def clean_env(tmp_path_factory):
    """A venv with fmpy and nothing of ours."""
    d = tmp_path_factory.mktemp("clean")
    subprocess.run([sys.executable, "-m", "venv", str(d / "venv")], check=True)
    py = d / "venv" / "bin" / "python"
    subprocess.run([str(py), "-m", "pip", "install", "--quiet", "fmpy"], check=True, capture_output=True)
    return d, py


def test_a_clean_python_with_the_fmus_own_requirements_runs_it(clean_env, tmp_path):
    d, py = clean_env
    fmu = tmp_path / "default.fmu"
    subprocess.run([sys.executable, "-m", "grapefmu", "build-fmu", "-o", str(fmu)], check=True, cwd=ROOT,
                   capture_output=True)
    env = {**os.environ, "GRAPEFMU_CACHE": str(tmp_path / "cache")}
    env.pop("PYTHONPATH", None)
    driver = tmp_path / "drive.py"
    driver.write_text(DRIVER % (*ACCEL, round(STOP / DT), DT, DT))

    # without the requirements, instantiation fails saying what is missing and how to install it
    r = subprocess.run([str(py), str(driver), str(fmu)], capture_output=True, text=True, env=env, timeout=300)
    assert r.returncode != 0
    assert "lacks" in r.stdout + r.stderr and "pip install -r" in r.stdout + r.stderr

    req = tmp_path / "requirements.txt"
    req.write_bytes(zipfile.ZipFile(fmu).read("resources/requirements.txt"))
    assert "grapefmu" not in req.read_text()  # no package index serves it: it is bundled
    subprocess.run([str(py), "-m", "pip", "install", "--quiet", "-r", str(req)], check=True, capture_output=True)
    r = subprocess.run([str(py), str(driver), str(fmu)], capture_output=True, text=True, env=env, timeout=900)
    assert r.returncode == 0, r.stderr[-3000:]
    got = np.array(json.loads(r.stdout.split("JSON:", 1)[1])["angles"])

    from grapefmu import Solver
    from grapefmu.scenefile import load_scene
    s = Solver(load_scene(ROOT / "scenes" / "default.toml"), driven=True)  # as the FMU's: its inputs may turn
    ref = []
    for _ in range(round(STOP / DT)):
        s.advance(DT, ACCEL)
        ref.append(s.angles[:2].copy())
    assert np.max(np.abs(got - np.array(ref))) < 1e-6
    assert np.max(np.abs(got)) > 1e-2
