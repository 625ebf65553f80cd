"""Runs a built FMU in a fresh process (never the one that built it) and prints JSON.

SIGNAL.csv: time and the inputs held from that row to the next, in the order of the FMU's INPUTS: the planar pair
(ax, az), the rachis acceleration (ax, ay, az, alpha_x, alpha_y, alpha_z), or that and its angular velocity
(omega_x, omega_y, omega_z), set at the start of each step (0 when the signal has none).

    python -m tests.fmu_driver fmpy FMU SIGNAL.csv STOP DT [--param NAME=VALUE ...]
    python -m tests.fmu_driver summary FMU SIGNAL.csv STOP DT     (a cluster FMU's summary outputs)
    python -m tests.fmu_driver named FMU SIGNAL.csv STOP DT NAME,NAME,... [NAME=VALUE ...]   (outputs after each step)
    python -m tests.fmu_driver cosim FMU SIGNAL.csv STOP DT
    python -m tests.fmu_driver ecos FMU SIGNAL.csv STOP DT     (needs LD_LIBRARY_PATH=<venv>/lib for tbb)
    python -m tests.fmu_driver cosim-named|ecos-named FMU SIGNAL.csv STOP DT NAME,NAME,... [NAME=VALUE ...]
    python -m tests.fmu_driver replay FMU SIGNAL.csv
    python -m tests.fmu_driver two FMU SIGNAL.csv
    python -m tests.fmu_driver bad FMU
"""
from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np

from grapefmu_fmu.core import INPUTS  # the FMU's inputs, from the output catalogue

OUTPUTS = ["angle_left", "angle_right", "angular_velocity_left", "angular_velocity_right", "contact_force_left_right",
           "pedicel_tension_left", "pedicel_tension_right", "peak_contact_force", "dissipated_energy"]


ROOT = Path(__file__).resolve().parents[1]


# --- for the tests: feed an FMU what simulate follows, and see what the hold leaves ----------------------------------
def fed_from(excitation, run, dt, stop) -> np.ndarray:
    """Rows (t_k, a, α, ω) that feed an FMU `excitation` in steps of dt: (a, α)(t_k) (physics.excitation.accel),
    held over each step, and ω(t_k), the rachis' angular velocity in `run` (simulate on that excitation, sampled
    on a grid that holds every t_k), set at each step's start."""
    from grapefmu.physics.excitation import accel
    t = np.round(np.arange(0.0, stop - 1e-9, dt), 12)
    k = np.rint((t - run.t[0]) / (run.t[1] - run.t[0])).astype(int)
    assert np.allclose(run.t[k], t, atol=1e-12), "the run's samples must hold every step's start"
    return np.column_stack([t, accel(excitation, t), run.base_angular_velocity[k]])


def named_outputs(fmu, rows, stop, dt, names, workdir, params=None) -> np.ndarray:
    """The FMU's outputs `names` after each step of dt, fed `rows` (held), in a fresh process: (steps, 1 + names)."""
    sig = Path(workdir) / f"signal_{dt:g}.csv"
    np.savetxt(sig, rows, delimiter=",", header=",".join(["time", *INPUTS][: rows.shape[1]]), comments="",
               fmt="%.17g")
    out = subprocess.run([sys.executable, "-m", "tests.fmu_driver", "named", str(fmu), str(sig), repr(stop), repr(dt),
                          ",".join(names), *(f"{k}={v!r}" for k, v in (params or {}).items())],
                         capture_output=True, text=True, cwd=ROOT, timeout=900)
    assert out.returncode == 0, out.stderr[-3000:]
    return np.array(json.loads(out.stdout.split("JSON:", 1)[1])["rows"])


def assert_hold_error(differences: dict) -> None:
    """`differences` {dt: FMU − simulate after each step}, for a step h and h/2: the difference is the hold's
    (zero-order, so first order in the step) and nothing else. It halves when the step halves, and the
    Richardson combination 2 d(h/2) − d(h), which cancels the first-order term, leaves a small fraction of it:
    the FMU's limit as the step shrinks is simulate's trajectory."""
    (h, d_h), (half, d_half) = sorted(differences.items(), reverse=True)
    assert abs(h / half - 2.0) < 1e-9
    d_half = d_half[1::2]  # at the coarse run's times
    e_h, e_half = np.abs(d_h).max(), np.abs(d_half).max()
    assert 0.4 < e_half / e_h < 0.6, (e_h, e_half)
    assert np.abs(2.0 * d_half - d_h).max() < 0.05 * e_half, (np.abs(2.0 * d_half - d_h).max(), e_half)


def signal(path):
    rows = np.loadtxt(path, delimiter=",", skiprows=1)
    return rows


def held(rows, t):
    """The zero-order-hold value of the signal at t (the row at or before t) as every input (INPUTS)."""
    k = max(np.searchsorted(rows[:, 0], t + 1e-12, side="right") - 1, 0)
    u = [float(x) for x in rows[k, 1:]]
    if len(u) == 2:  # the planar (ax, az)
        u = [u[0], 0.0, u[1], 0.0, 0.0, 0.0]
    return u + [0.0] * (len(INPUTS) - len(u))


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

    def step(self, dt, inputs=()):
        """Set the first len(inputs) of INPUTS (the others keep their values), then step."""
        self.fmu.setReal([self.vr[n] for n in INPUTS[: len(inputs)]], list(inputs))
        self.fmu.doStep(currentCommunicationPoint=self.t, communicationStepSize=dt)
        self.t += dt


def run_fmpy(path, rows, stop, dt, params=None):
    f = Fmu2(path, params=params)
    out = [[0.0] + f.get(OUTPUTS)]
    n = round(stop / dt)
    for k in range(n):
        f.step(dt, held(rows, k * dt))
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
        f.step(dt, held(rows, k * dt))
        out.append([(k + 1) * dt] + f.get(SUMMARY_REALS) + list(f.fmu.getInteger([f.vr[n] for n in SUMMARY_INTS])))
    return {"rows": out, "variables": len(f.md.modelVariables)}


def run_named(path, rows, stop, dt, names, params=None):
    """The named Real outputs after every step of a run (parameters set first)."""
    f = Fmu2(path, params=params)
    out = []
    for k in range(round(stop / dt)):
        f.step(dt, held(rows, k * dt))
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
        u = held(rows, k * dt)
        for s in (a, b):
            manip.slave_real_values(s, [vr[n] for n in INPUTS], u)
        ex.step()
        outs_a.append([(k + 1) * dt] + list(obs.last_real_values(a, [vr[n] for n in OUTPUTS])))
        outs_b.append([(k + 1) * dt] + list(obs.last_real_values(b, [vr[n] for n in OUTPUTS])))
    return {"a": outs_a, "b": outs_b}


def run_ecos(path, rows, stop, dt, names=OUTPUTS, params=None):
    """ecospy (Ecos co-simulation engine), a third importer none of us wrote: the named Real outputs after every
    step (parameters set before init)."""
    from ecospy import EcosSimulation, EcosSimulationStructure
    ss = EcosSimulationStructure()
    ss.add_model("a", path)
    sim = EcosSimulation(structure=ss, step_size=dt)
    for k, x in (params or {}).items():
        sim.set_real(f"a::{k}", x)
    sim.init()
    out = []
    for k in range(round(stop / dt)):
        for name, x in zip(INPUTS, held(rows, k * dt)):
            sim.set_real(f"a::{name}", x)
        sim.step()
        out.append([(k + 1) * dt] + [sim.get_real(f"a::{n}") for n in names])
    sim.terminate()
    return {"a": out}


def run_cosim_named(path, rows, stop, dt, names, params):
    """libcosimpy, one instance with its parameters' initial values: the named Real outputs after every step, and
    whether each step succeeded."""
    from fmpy import read_model_description
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimManipulator import CosimManipulator
    from libcosimpy.CosimObserver import CosimObserver
    from libcosimpy.CosimSlave import CosimLocalSlave
    vr = {v.name: v.valueReference for v in read_model_description(path).modelVariables}
    ex = CosimExecution.from_step_size(step_size=int(round(dt * 1e9)))
    a = ex.add_local_slave(CosimLocalSlave(fmu_path=path, instance_name="a"))
    for k, x in params.items():
        ex.real_initial_value(a, vr[k], x)
    manip = CosimManipulator.create_override()
    ex.add_manipulator(manip)
    obs = CosimObserver.create_last_value()
    ex.add_observer(obs)
    out, done = [], []
    for k in range(round(stop / dt)):
        manip.slave_real_values(a, [vr[n] for n in INPUTS], held(rows, k * dt))
        done.append(bool(ex.step()))
        out.append([(k + 1) * dt] + list(obs.last_real_values(a, [vr[n] for n in names])))
    return {"a": out, "done": done}


def replay(path, rows):
    """Save the state at 0.3 s, run to 0.6 s, restore (in memory and from bytes), run again."""
    f = Fmu2(path)
    dt = 1e-3
    for k in range(300):
        f.step(dt, held(rows, k * dt))
    state = f.fmu.getFMUstate()
    blob = f.fmu.serializeFMUstate(state)

    def run_on():
        f.t = 0.3
        traj = []
        for k in range(300, 600):
            f.step(dt, held(rows, k * dt))
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
        a.step(1e-3, u)
        b.step(1e-3, u)
        alone.step(1e-3, u)
    # pythonfmu's loader used to corrupt the script module after a few instances (see build.py)
    more = [Fmu2(path, f"m{k}") for k in range(10)]
    for m in more:
        m.step(1e-3, (1.0,))
    return {"a": a.get(OUTPUTS), "b": b.get(OUTPUTS), "alone": alone.get(OUTPUTS),
            "more_alike": all(m.get(OUTPUTS) == more[0].get(OUTPUTS) for m in more)}


def bad(path):
    """Each bad call must be refused with fmi2Error and a logged message, never Fatal, the state unchanged."""
    from fmpy.fmi1 import FMICallException
    results = {}
    f = Fmu2(path)
    f.step(1e-3)
    before = f.get(OUTPUTS)

    def attempt(label, call):
        try:
            call()
            results[label] = "ok"
        except FMICallException as e:
            results[label] = str(e)
        results[label + " unchanged"] = f.get(OUTPUTS) == before

    for label, name, x in (("nan input", "base_ax", math.nan), ("inf input", "base_az", math.inf),
                           ("huge input", "base_ax", 1e6), ("nan angular velocity", "base_omega_y", math.nan),
                           ("huge angular velocity", "base_omega_y", 1e3),
                           ("huge angular acceleration", "base_alpha_y", 1e6),
                           ("out-of-plane angular velocity", "base_omega_x", 0.5),  # the default scene is planar
                           ("out-of-plane angular acceleration", "base_alpha_z", -2.0)):
        attempt(label, lambda: f.fmu.setReal([f.vr["base_ay"], f.vr[name]], [0.0, x]))
    for label, dt in (("zero step", 0.0), ("negative step", -1e-3)):
        attempt(label, lambda: f.fmu.doStep(currentCommunicationPoint=f.t, communicationStepSize=dt))
    f.step(1e-3, (5.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 2.0, 0.0))  # and it goes on, turning about y
    results["recovers"] = f.get(OUTPUTS) != before
    for label, params in (("bad parameter", {"mass_left": -1.0}), ("bad orientation", {"rachis_pitch": 7.0}),
                          ("out-of-plane orientation", {"rachis_roll": 0.2})):
        try:
            Fmu2(path, label, params=params)
            results[label] = "ok"
        except FMICallException as e:
            results[label] = str(e)
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
            params = dict(p.split("=") for p in argv[6:])
            out = run_named(path, rows, float(argv[3]), float(argv[4]), argv[5].split(","),
                            {k: float(v) for k, v in params.items()})
        elif cmd == "cosim":
            out = run_cosim(path, rows, float(argv[3]), float(argv[4]))
        elif cmd == "ecos":
            out = run_ecos(path, rows, float(argv[3]), float(argv[4]))
        elif cmd in ("cosim-named", "ecos-named"):
            params = {k: float(v) for k, v in (p.split("=") for p in argv[6:])}
            run = run_cosim_named if cmd == "cosim-named" else run_ecos
            out = run(path, rows, float(argv[3]), float(argv[4]), argv[5].split(","), params)
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
