"""Cost per 1 ms communication step: the raw core, the FMU through fmpy, libcosimpy and ecospy, and a
do-nothing pythonfmu FMU with the same variables through the same importers (the importer's and
pythonfmu's own overhead). Wrapper overhead = FMU − null FMU − raw core. Each step sets every input (the
rachis' acceleration, angular acceleration and angular velocity: nine), steps and reads every Real output
("fmpy-angles": only the two angles a controller would read).
Run: .venv/bin/python benchmarks/fmu_step_cost.py   (builds into a temporary directory)."""
from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

import numpy as np

N_STEPS = 2000
IMPORTERS = ("fmpy", "fmpy-angles", "libcosimpy", "ecospy")
DT = 1e-3
ROOT = Path(__file__).resolve().parents[1]

NULL_SLAVE = textwrap.dedent('''
    from pythonfmu import Boolean, Fmi2Causality, Fmi2Initial, Fmi2Slave, Fmi2Variability, Integer, Real
    from grapefmu_fmu.variables import variables
    from grapefmu import load_scene
    from grapefmu.scenefile import default_scene_path

    class NullFmu(Fmi2Slave):
        """The same variables as the grapefmu FMU, and a do_step that does nothing."""
        def __init__(self, **kw):
            super().__init__(**kw)
            self.v = {}
            for var in variables(load_scene(default_scene_path()).model):
                self.v[var.name] = 0 if var.type == "integer" else (False if var.type == "boolean" else 0.0)
                cls = {"real": Real, "integer": Integer, "boolean": Boolean}[var.type]
                kw2 = dict(getter=lambda n=var.name: self.v[n], setter=lambda x, n=var.name: self.v.__setitem__(n, x))
                if var.causality == "input":
                    kw2.update(causality=Fmi2Causality.input, variability=Fmi2Variability.continuous if var.type == "real" else Fmi2Variability.discrete)
                elif var.causality == "output":
                    kw2.update(causality=Fmi2Causality.output, initial=Fmi2Initial.exact, variability=Fmi2Variability.continuous if var.type == "real" else Fmi2Variability.discrete)
                else:
                    kw2.update(causality=Fmi2Causality.parameter, variability=Fmi2Variability.fixed, initial=Fmi2Initial.exact)
                self.register_variable(cls(var.name, **kw2))

        def do_step(self, t, dt):
            return True
''')

WORKER = textwrap.dedent('''
    import sys, time, json
    import numpy as np
    path, importer, n, dt = sys.argv[1], sys.argv[2], int(sys.argv[3]), float(sys.argv[4])
    from fmpy import read_model_description, extract
    md = read_model_description(path)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    outs = [v.valueReference for v in md.modelVariables if v.causality == "output" and v.type == "Real"]
    ins = [v.valueReference for v in md.modelVariables if v.causality == "input"]
    in_names = [v.name for v in md.modelVariables if v.causality == "input"]
    if importer.endswith("-angles"):  # a master that reads only what its controller needs
        importer, outs = importer.split("-")[0], [vr["angle_left"], vr["angle_right"]]
    acc = np.sin(np.arange(n) * 0.01) * 3.0
    best = 1e9
    for rep in range(3):
        if importer == "fmpy":
            from fmpy.fmi2 import FMU2Slave
            f = FMU2Slave(guid=md.guid, unzipDirectory=extract(path), modelIdentifier=md.coSimulation.modelIdentifier, instanceName="a")
            f.instantiate(); f.setupExperiment(startTime=0); f.enterInitializationMode(); f.exitInitializationMode()
            f.doStep(currentCommunicationPoint=0.0, communicationStepSize=dt)
            t = dt
            w = time.perf_counter()
            for k in range(n):
                f.setReal(ins, [acc[k]] + [0.0] * (len(ins) - 1))
                f.doStep(currentCommunicationPoint=t, communicationStepSize=dt)
                f.getReal(outs)
                t += dt
            best = min(best, (time.perf_counter() - w) / n)
            f.terminate(); f.freeInstance()
        elif importer == "ecospy":
            from ecospy import EcosSimulation, EcosSimulationStructure
            ss = EcosSimulationStructure()
            ss.add_model(f"a{rep}", path)
            sim = EcosSimulation(structure=ss, step_size=dt)
            sim.init()
            sim.step()
            names = [f"a{rep}::{v.name}" for v in md.modelVariables if v.valueReference in outs and v.causality == "output" and v.type == "Real"]
            w = time.perf_counter()
            for k in range(n):
                for j, name in enumerate(in_names):
                    sim.set_real(f"a{rep}::{name}", acc[k] if j == 0 else 0.0)
                sim.step()
                [sim.get_real(x) for x in names]
            best = min(best, (time.perf_counter() - w) / n)
            sim.terminate()
        else:
            from libcosimpy.CosimExecution import CosimExecution
            from libcosimpy.CosimManipulator import CosimManipulator
            from libcosimpy.CosimObserver import CosimObserver
            from libcosimpy.CosimSlave import CosimLocalSlave
            ex = CosimExecution.from_step_size(step_size=int(dt * 1e9))
            a = ex.add_local_slave(CosimLocalSlave(fmu_path=path, instance_name=f"a{rep}"))
            m = CosimManipulator.create_override(); ex.add_manipulator(m)
            o = CosimObserver.create_last_value(); ex.add_observer(o)
            ex.step()
            w = time.perf_counter()
            for k in range(n):
                m.slave_real_values(a, ins, [acc[k]] + [0.0] * (len(ins) - 1))
                ex.step()
                o.last_real_values(a, outs)
            best = min(best, (time.perf_counter() - w) / n)
    print("JSON:" + json.dumps(best), flush=True)
    import os
    os._exit(0)  # pythonfmu's own binary (the null FMU) may abort in Python's teardown: the figure is out
''')


def core_cost() -> float:
    from grapefmu import Solver, load_scene
    from grapefmu.scenefile import default_scene_path
    acc = np.sin(np.arange(N_STEPS) * 0.01) * 3.0
    best = 1e9
    still = (0.0, 0.0, 0.0)
    for _ in range(3):
        s = Solver(load_scene(default_scene_path()), driven=True)  # the FMU's: its inputs may turn the rachis
        w = time.perf_counter()
        for k in range(N_STEPS):
            s.advance(DT, (float(acc[k]), 0.0, 0.0, 0.0, 0.0, 0.0), still)  # what the FMU's step calls
        best = min(best, (time.perf_counter() - w) / N_STEPS)
    return best


def main() -> None:
    import json
    with tempfile.TemporaryDirectory() as d:
        os.environ["TMPDIR"] = d  # fmpy's extract makes a directory per FMU and never removes it: here, it goes with d
        d = Path(d)
        subprocess.run([sys.executable, "-m", "grapefmu", "build-fmu", "-o", str(d / "g.fmu")], check=True,
                       capture_output=True)
        (d / "nullfmu.py").write_text(NULL_SLAVE)
        subprocess.run([sys.executable, "-m", "pythonfmu", "build", "-f", str(d / "nullfmu.py"), "-d", str(d)],
                       check=True, capture_output=True, cwd=d)
        (d / "worker.py").write_text(WORKER)
        res = {}
        for fmu in ("g.fmu", "NullFmu.fmu"):
            for importer in IMPORTERS:
                env = {**os.environ, "LD_LIBRARY_PATH": str(Path(sys.prefix) / "lib")}  # ecospy's tbb
                out = subprocess.run([sys.executable, str(d / "worker.py"), str(d / fmu), importer, str(N_STEPS),
                                      str(DT)], capture_output=True, text=True, check=True, env=env).stdout
                res[(fmu, importer)] = json.loads(out.split("JSON:")[1].splitlines()[0])
    core = core_cost()
    print(f"raw core Solver.advance(1 ms), default scene, pick-and-place-like input: {core * 1e6:8.1f} µs/step")
    for importer in IMPORTERS:
        g, null = res[("g.fmu", importer)], res[("NullFmu.fmu", importer)]
        print(f"{importer:<12} grapefmu FMU {g * 1e6:8.1f} µs/step, null FMU {null * 1e6:6.1f} µs/step, "
              f"wrapper overhead {1e6 * (g - null - core):6.1f} µs/step")


if __name__ == "__main__":
    main()
