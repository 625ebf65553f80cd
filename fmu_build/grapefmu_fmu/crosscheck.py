"""An FMI cross-check package for a scene's FMU (https://github.com/modelica/fmi-cross-check layout):

    DIR/fmus/<2.0|3.0>/cs/<platform>/grapefmu/<version>/<Name>/
        <Name>.fmu  <Name>_in.csv  <Name>_ref.csv  <Name>_ref.opt  ReadMe.txt

The input is the scene's own excitation sampled every 10 ms and held (the time repeats at each change, so
an importer that interpolates inputs linearly still applies a step), with the rachis' angular velocity that
held angular acceleration gives (continuous: linear between samples, so an importer that interpolates sets
the exact ω at any step); the reference is grapefmu's own run of the scene driven by the same held signal."""
from __future__ import annotations

import re
import tempfile
import tomllib
from pathlib import Path

import numpy as np

import grapefmu
from grapefmu.physics.excitation import ACCEL_COMPONENTS
from grapefmu.scenefile import load_scene, scene_from_dict
from grapefmu.solver.api import simulate

from .build import build_fmu
from .core import ACCEL_INPUTS, INPUTS, OMEGA_INPUTS, held_inputs

SAMPLE = 1e-2        # s: the controller period of the input signal
PLATFORM = {2: "linux64", 3: "x86_64-linux"}


def write_cross_check(scene_path: str | Path, out: str | Path, fmi: int = 2) -> Path:
    """Build the FMU of the scene and its cross-check files under `out`; returns the model's folder."""
    scene = load_scene(scene_path)
    name = re.sub(r"[^A-Za-z0-9_]", "_", scene.name)
    folder = Path(out) / "fmus" / f"{fmi}.0" / "cs" / PLATFORM[fmi] / "grapefmu" / grapefmu.__version__ / name
    folder.mkdir(parents=True, exist_ok=True)
    build_fmu(scene_path, folder / f"{name}.fmu", fmi)

    sv = scene.solver
    t = np.round(np.arange(0.0, sv.t_end + 1e-12, SAMPLE), 12)
    u = held_inputs(scene.excitation, t)
    steps = np.column_stack([t, u])
    na = len(ACCEL_INPUTS)
    # each acceleration holds until the next sample: repeat the time at every change (FMI cross-check rules)
    rows = [steps[0]] + [r for k in range(1, len(t)) for r in ((t[k], *u[k - 1, :na], *u[k, na:]), steps[k])]
    header = ",".join(["time", *INPUTS])
    np.savetxt(folder / f"{name}_in.csv", np.array(rows), delimiter=",", header=header, comments="", fmt="%.17g")

    with tempfile.TemporaryDirectory() as tmp:
        signal = Path(tmp) / "signal.csv"
        np.savetxt(signal, steps[:, : 1 + na], delimiter=",", header=",".join(["time", *ACCEL_COMPONENTS]),
                   comments="", fmt="%.17g")
        doc = tomllib.loads(scene.source)
        start = {k: doc["excitation"][k] for k in ("orientation", "angular_velocity") if k in doc.get("excitation", {})}
        doc["excitation"] = {"kind": "csv", "file": str(signal), "hold": True, "after": "hold", **start}
        run = simulate(scene_from_dict(doc, Path(scene_path).parent, name=scene.name), sv.t_end,
                       output_interval=sv.output_interval)
    m = scene.model
    names = [f"angle_{d}" for d in m.dof_names] + [f"angular_velocity_{d}" for d in m.dof_names]
    ref = np.column_stack([run.t, run.y[:, : 2 * m.n_dof]])
    np.savetxt(folder / f"{name}_ref.csv", ref, delimiter=",", header=",".join(["time", *names]), comments="",
               fmt="%.17g")
    (folder / f"{name}_ref.opt").write_text(
        f"StartTime,0.0\nStopTime,{sv.t_end!r}\nStepSize,{sv.output_interval!r}\nRelTol,{sv.rtol!r}\n")
    (folder / "ReadMe.txt").write_text(
        f"{name}: {m.n_berries} table-grape berries on hinged twigs swinging and colliding while a gripper moves the "
        f"rachis (grapefmu {grapefmu.__version__}, https://doi.org/10.3390/agriculture15020154).\n"
        f"Inputs {', '.join(ACCEL_INPUTS)} (m/s2, rad/s2): the scene's excitation sampled every {SAMPLE} s and "
        f"held; {', '.join(OMEGA_INPUTS)} (rad/s): the rachis' angular velocity that gives (linear between "
        "samples), set at the start of each communication step.\n"
        f"Reference: grapefmu's event-driven solver on the same scene and held input (rtol {sv.rtol}), "
        f"outputs every {sv.output_interval} s. Results do not depend on the communication step.\n"
        f"Reproduce: grapefmu build-fmu SCENE.toml --fmi {fmi} --cross-check DIR\n")
    return folder
