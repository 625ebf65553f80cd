"""One benchmark run of a scene's FMU through fmpy at 1 ms communication steps (used by grapefmu bench).

`python -m grapefmu_fmu.bench_run SCENE.toml` builds the FMU in a separate process, then steps it here
with the scene's excitation sampled and held every 1 ms (core.held_inputs), and prints JSON: the angles on
the 1 ms grid and the wall time of the stepping loop (best of 3)."""
from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def main(scene_path: str) -> None:
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    from grapefmu import load_scene
    from grapefmu_fmu.core import INPUTS, held_inputs
    scene = load_scene(scene_path)
    with tempfile.TemporaryDirectory() as d:
        fmu = Path(d) / "bench.fmu"
        subprocess.run([sys.executable, "-m", "grapefmu", "build-fmu", scene_path, "-o", str(fmu)], check=True,
                       capture_output=True)
        md = read_model_description(str(fmu))
        vr = {v.name: v.valueReference for v in md.modelVariables}
        outs = [vr[f"angle_{b}"] for b in scene.model.names]
        unzip = extract(str(fmu), Path(d) / "unzipped")  # fmpy's default, a fresh temporary directory, is never removed
        dt, steps = 1e-3, int(round(scene.solver.t_end / 1e-3))
        inputs = [vr[n] for n in INPUTS]
        u = held_inputs(scene.excitation, np.arange(steps) * dt).tolist()
        best, angles = float("inf"), None
        for rep in range(3):
            f = FMU2Slave(guid=md.guid, unzipDirectory=unzip, modelIdentifier=md.coSimulation.modelIdentifier,
                          instanceName=f"b{rep}")
            f.instantiate()
            f.setupExperiment(startTime=0.0)
            f.enterInitializationMode()
            f.exitInitializationMode()
            rows = [f.getReal(outs)]
            w = time.perf_counter()
            for k in range(steps):
                f.setReal(inputs, u[k])
                f.doStep(currentCommunicationPoint=k * dt, communicationStepSize=dt)
                rows.append(f.getReal(outs))
            best = min(best, time.perf_counter() - w)
            angles = rows
            f.terminate()
            f.freeInstance()
    print("JSON:" + json.dumps({"angles": angles, "wall": best}), flush=True)


if __name__ == "__main__":
    main(sys.argv[1])
