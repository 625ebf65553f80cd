"""Runs a built FMU in a fresh process (never the one that built it) and prints JSON.

    python -m tests.fmu_driver fmpy FMU SIGNAL.csv STOP DT [--param NAME=VALUE ...]
    python -m tests.fmu_driver summary FMU SIGNAL.csv STOP DT     (a cluster FMU's summary outputs)
    python -m tests.fmu_driver cosim FMU SIGNAL.csv STOP DT
    python -m tests.fmu_driver ecos FMU SIGNAL.csv STOP DT     (needs LD_LIBRARY_PATH=<venv>/lib for tbb)
    python -m tests.fmu_driver replay FMU SIGNAL.csv
    python -m tests.fmu_driver two FMU SIGNAL.csv
    python -m tests.fmu_driver bad FMU
"""
from __future__ import annotations

import json
import math
import os
import sys

import numpy as np

OUTPUTS = ["angle_left", "angle_right", "angular_velocity_left", "angular_velocity_right", "contact_force_left_right",
           "pedicel_tension_left", "pedicel_tension_right", "peak_contact_force", "dissipated_energy"]


def signal(path):
    rows = np.loadtxt(path, delimiter=",", skiprows=1)
    return rows


def held(rows, t):
    """The zero-order-hold value of the signal at t (the row at or before t)."""
    k = max(np.searchsorted(rows[:, 0], t + 1e-12, side="right") - 1, 0)
    return rows[k, 1], rows[k, 2]


_EXTRACTED = {}


def extracted(path):
    """One extraction per FMU and process, as importers do; instances share it."""
    from fmpy import extract
    if path not in _EXTRACTED:
        _EXTRACTED[path] = extract(path)
    return _EXTRACTED[path]


class Fmu2:
    """fmpy's low-level FMI 2 interface, so every call and status is visible."""

    def __init__(self, path, name="a", params=None):
        from fmpy import read_model_description
        from fmpy.fmi2 import FMU2Slave
        self.md = read_model_description(path)
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.types = {v.name: v.type for v in self.md.modelVariables}
        self.log = []
        self.fmu = FMU2Slave(guid=self.md.guid, unzipDirectory=extracted(path),
                             modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName=name)
        self.fmu.instantiate(loggingOn=True, callbacks=None)
        self.fmu.setupExperiment(startTime=0.0)
        self.fmu.enterInitializationMode()
        for k, val in (params or {}).items():
            self.set(k, val)
        self.fmu.exitInitializationMode()
        self.t = 0.0

    def set(self, name, value):
        if self.types[name] == "Integer":
            self.fmu.setInteger([self.vr[name]], [int(value)])
        else:
            self.fmu.setReal([self.vr[name]], [float(value)])

    def get(self, names):
        return list(self.fmu.getReal([self.vr[n] for n in names]))

    def step(self, dt, ax, ay):
        self.fmu.setReal([self.vr["base_ax"], self.vr["base_az"]], [ax, ay])
        self.fmu.doStep(currentCommunicationPoint=self.t, communicationStepSize=dt)
        self.t += dt


def run_fmpy(path, rows, stop, dt, params=None):
    f = Fmu2(path, params=params)
    out = [[0.0] + f.get(OUTPUTS)]
    n = round(stop / dt)
    for k in range(n):
        f.step(dt, *held(rows, k * dt))
        out.append([(k + 1) * dt] + f.get(OUTPUTS))
    count = f.fmu.getInteger([f.vr["collision_count"]])[0]
    return {"t_y": out, "collision_count": count}


SUMMARY_REALS = ["peak_contact_force", "dissipated_energy", "max_contact_force", "max_pedicel_tension"]
SUMMARY_INTS = ["collision_count", "active_pairs", "berries_over_detachment_force", "bruising_impacts"]


def run_summary(path, rows, stop, dt):
    """A cluster FMU's summary outputs over a run."""
    f = Fmu2(path)
    out = []
    for k in range(round(stop / dt)):
        f.step(dt, *held(rows, k * dt))
        out.append([(k + 1) * dt] + f.get(SUMMARY_REALS) + list(f.fmu.getInteger([f.vr[n] for n in SUMMARY_INTS])))
    return {"rows": out, "variables": len(f.md.modelVariables)}


def run_named(path, rows, stop, dt, names):
    """The named Real outputs after every step of a run."""
    f = Fmu2(path)
    out = []
    for k in range(round(stop / dt)):
        f.step(dt, *held(rows, k * dt))
        out.append([(k + 1) * dt] + f.get(names))
    return {"rows": out}


def run_cosim(path, rows, stop, dt):
    from fmpy import read_model_description
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimManipulator import CosimManipulator
    from libcosimpy.CosimObserver import CosimObserver
    from libcosimpy.CosimSlave import CosimLocalSlave
    md = read_model_description(path)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    ex = CosimExecution.from_step_size(step_size=int(round(dt * 1e9)))
    a = ex.add_local_slave(CosimLocalSlave(fmu_path=path, instance_name="a"))
    b = ex.add_local_slave(CosimLocalSlave(fmu_path=path, instance_name="b"))
    ex.real_initial_value(b, vr["mass_right"], 0.02)  # a second, different instance side by side
    manip = CosimManipulator.create_override()
    ex.add_manipulator(manip)
    obs = CosimObserver.create_last_value()
    ex.add_observer(obs)
    outs_a, outs_b = [], []
    for k in range(round(stop / dt)):
        ax, ay = held(rows, k * dt)
        for s in (a, b):
            manip.slave_real_values(s, [vr["base_ax"], vr["base_az"]], [ax, ay])
        ex.step()
        outs_a.append([(k + 1) * dt] + list(obs.last_real_values(a, [vr[n] for n in OUTPUTS])))
        outs_b.append([(k + 1) * dt] + list(obs.last_real_values(b, [vr[n] for n in OUTPUTS])))
    return {"a": outs_a, "b": outs_b}


def run_ecos(path, rows, stop, dt):
    """ecospy (Ecos co-simulation engine), a third importer none of us wrote."""
    from ecospy import EcosSimulation, EcosSimulationStructure
    ss = EcosSimulationStructure()
    ss.add_model("a", path)
    sim = EcosSimulation(structure=ss, step_size=dt)
    sim.init()
    out = []
    for k in range(round(stop / dt)):
        ax, ay = held(rows, k * dt)
        sim.set_real("a::base_ax", ax)
        sim.set_real("a::base_az", ay)
        sim.step()
        out.append([(k + 1) * dt] + [sim.get_real(f"a::{n}") for n in OUTPUTS])
    sim.terminate()
    return {"a": out}


def replay(path, rows):
    """Save the state at 0.3 s, run to 0.6 s, restore (in memory and from bytes), run again."""
    f = Fmu2(path)
    dt = 1e-3
    for k in range(300):
        f.step(dt, *held(rows, k * dt))
    state = f.fmu.getFMUstate()
    blob = f.fmu.serializeFMUstate(state)

    def run_on():
        f.t = 0.3
        traj = []
        for k in range(300, 600):
            f.step(dt, *held(rows, k * dt))
            traj.append(f.get(OUTPUTS))
        return traj
    first = run_on()
    f.fmu.setFMUstate(state)
    second = run_on()
    f.fmu.setFMUstate(f.fmu.deSerializeFMUstate(blob))
    third = run_on()
    return {"same_in_memory": first == second, "same_from_bytes": first == third,
            "moved": first[0] != first[-1], "bytes": len(blob)}


def two(path, rows):
    a = Fmu2(path, "a")
    b = Fmu2(path, "b", params={"mass_right": 0.02, "twig_length_right": 0.04})
    alone = Fmu2(path, "c")
    for k in range(500):
        u = held(rows, k * 1e-3)
        a.step(1e-3, *u)
        b.step(1e-3, *u)
        alone.step(1e-3, *u)
    # pythonfmu's loader used to corrupt the script module after a few instances (see build.py)
    more = [Fmu2(path, f"m{k}") for k in range(10)]
    for m in more:
        m.step(1e-3, 1.0, 0.0)
    return {"a": a.get(OUTPUTS), "b": b.get(OUTPUTS), "alone": alone.get(OUTPUTS),
            "more_alike": all(m.get(OUTPUTS) == more[0].get(OUTPUTS) for m in more)}


def bad(path):
    """Each bad call must be refused with fmi2Error and a logged message, never Fatal, the state unchanged."""
    from fmpy.fmi1 import FMICallException
    results = {}
    f = Fmu2(path)
    f.step(1e-3, 0.0, 0.0)
    before = f.get(OUTPUTS)

    def attempt(label, call):
        try:
            call()
            results[label] = "ok"
        except FMICallException as e:
            results[label] = str(e)
        results[label + " unchanged"] = f.get(OUTPUTS) == before

    for label, ax in (("nan input", math.nan), ("inf input", math.inf), ("huge input", 1e6)):
        attempt(label, lambda: f.fmu.setReal([f.vr["base_ax"], f.vr["base_az"]], [ax, 0.0]))
    for label, dt in (("zero step", 0.0), ("negative step", -1e-3)):
        attempt(label, lambda: f.fmu.doStep(currentCommunicationPoint=f.t, communicationStepSize=dt))
    f.step(1e-3, 5.0, 0.0)  # and it goes on
    results["recovers"] = f.get(OUTPUTS) != before
    try:
        Fmu2(path, "g", params={"mass_left": -1.0})
        results["bad parameter"] = "ok"
    except FMICallException as e:
        results["bad parameter"] = str(e)
    return results


def main(argv):
    cmd, path = argv[0], argv[1]
    if cmd == "bad":
        out = bad(path)
    else:
        rows = signal(argv[2])
        if cmd == "fmpy":
            params = dict(p.split("=") for p in argv[5:])
            out = run_fmpy(path, rows, float(argv[3]), float(argv[4]), {k: float(v) for k, v in params.items()})
        elif cmd == "summary":
            out = run_summary(path, rows, float(argv[3]), float(argv[4]))
        elif cmd == "named":
            out = run_named(path, rows, float(argv[3]), float(argv[4]), argv[5].split(","))
        elif cmd == "cosim":
            out = run_cosim(path, rows, float(argv[3]), float(argv[4]))
        elif cmd == "ecos":
            out = run_ecos(path, rows, float(argv[3]), float(argv[4]))
        elif cmd == "replay":
            out = replay(path, rows)
        else:
            out = two(path, rows)
    print("JSON:" + json.dumps(out), flush=True)


def release_all():
    """Terminate and free every instance while Python is fully alive: pythonfmu's loader keeps global
    state whose teardown at interpreter exit can hit freed Python objects (seen as an occasional
    'corrupted double-linked list' abort after all work was done)."""
    import gc
    for obj in gc.get_objects():
        if type(obj).__name__ == "Fmu2":
            try:
                obj.fmu.terminate()
                obj.fmu.freeInstance()
            except Exception:  # noqa: BLE001 - an instance that refused initialization
                pass


if __name__ == "__main__":
    main(sys.argv[1:])
    release_all()
    sys.stdout.flush()
    os._exit(0)
