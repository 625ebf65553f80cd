"""Driver for tests/test_fmu_boundaries.py: the FMU at the edges of what a host may do, through fmpy's low-level
calls, every status and logged message kept. Run in a process of its own:
python -m tests.fmu_boundaries FMI2.fmu FMI3.fmu NO_CONTACT_FMI2.fmu FAR_BERRY_FMI2.fmu"""
from __future__ import annotations

import io
import json
import ctypes
import math
import sys
from ctypes import byref

import numpy as np
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import (FMU2Slave, calloc, fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE,
                       fmi2CallbackFunctions, fmi2CallbackLoggerTYPE, free)
from fmpy.fmi3 import FMU3Slave
from fmpy.logging import addLoggerProxy

LOG: list[str] = []
_logger = fmi2CallbackLoggerTYPE(lambda env, name, status, cat, msg: LOG.append(msg.decode(errors="replace")))


def _callbacks():
    cb = fmi2CallbackFunctions()
    cb.logger = _logger
    cb.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
    cb.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
    addLoggerProxy(byref(cb))
    return cb


def call(fn, *args):
    """(status: 0 OK or the FMI error status, messages logged during the call, result)."""
    n = len(LOG)
    try:
        out = fn(*args)
    except FMICallException as e:
        return e.status, LOG[n:], None
    return 0, LOG[n:], out  # the messages read after the call: a call that returns may have logged too


class Fmu2:
    """An FMI 2 instance in a fresh extraction of `path` (as a host that extracts per instance does)."""

    def __init__(self, path, name, params=None, start=0.0, init=True):
        md = read_model_description(path)
        self.vr = {v.name: v.valueReference for v in md.modelVariables}
        self.type = {v.name: v.type for v in md.modelVariables}
        self.cb = _callbacks()
        self.f = FMU2Slave(guid=md.guid, unzipDirectory=extract(path), modelIdentifier=md.coSimulation.modelIdentifier,
                           instanceName=name)
        self.f.instantiate(loggingOn=True, callbacks=self.cb)
        self.t = start
        if init:
            self.f.setupExperiment(startTime=start)
            self.f.enterInitializationMode()
            for k, v in (params or {}).items():
                self.set(k, v)
            self.f.exitInitializationMode()

    def set(self, name, value):
        fn = {"Integer": self.f.setInteger, "Boolean": self.f.setBoolean}.get(self.type[name], self.f.setReal)
        return call(fn, [self.vr[name]], [value])

    def get(self, name):
        fn = {"Integer": self.f.getInteger, "Boolean": self.f.getBoolean}.get(self.type[name], self.f.getReal)
        return fn([self.vr[name]])[0]

    def step(self, dt, t=None):
        """(status: 0 or the error status, messages, the status doStep returned: 1 for Warning)."""
        r = call(self.f.fmi2DoStep, self.f.component, self.t if t is None else t, dt, 1)
        if r[0] == 0:
            self.t += dt
        return r

    def state(self) -> bytes:
        return bytes(self.f.serializeFMUstate(self.f.getFMUstate()))

    def restore(self, blob: bytes):
        st = call(self.f.deSerializeFMUstate, blob)
        return st if st[0] else call(self.f.setFMUstate, st[2])


def crafted(blob: bytes, name: str, value: float) -> bytes:
    """A serialized state with one stored value changed."""
    z = dict(np.load(io.BytesIO(blob), allow_pickle=False))
    data = z["value_data"].copy()
    data[list(z["value_names"]).index(name)] = value
    z["value_data"] = data
    out = io.BytesIO()
    np.savez(out, **z)
    return out.getvalue()


def in_initialization(path, name, params: dict) -> tuple:
    """An instance in Initialization Mode with `params` set: (it, the status and log of exitInitializationMode)."""
    c = Fmu2(path, name, init=False)
    c.f.setupExperiment(startTime=0.0)
    c.f.enterInitializationMode()
    for k, v in params.items():
        c.set(k, v)
    st, msgs, _ = call(c.f.exitInitializationMode)
    return c, (st, " ".join(msgs))


def fmi2(path, no_contact, far_berry) -> dict:
    r = {}
    # parameters that change which pairs can touch: refused, the outputs readable all along (an output of a pair the
    # parameters dropped raised IndexError: Fatal, and the host's next call crashed; one the build had dropped came
    # back and shifted the pair outputs by one)
    c = Fmu2(path, "reach", init=False)
    hinge = c.get("hinge_x_left")
    c.f.setupExperiment(startTime=0.0)
    c.f.enterInitializationMode()
    c.set("hinge_x_left", -1.0)
    r["reach dropped: read"] = call(c.f.getReal, [c.vr["contact_force_left_right"]])[:1]
    st, msgs, _ = call(c.f.exitInitializationMode)
    r["reach dropped: exit"] = (st, " ".join(msgs))
    r["reach dropped: read after"] = call(c.f.getReal, [c.vr["contact_force_left_right"]])[:1]
    c.set("hinge_x_left", hinge)
    r["reach dropped: exit again"] = call(c.f.exitInitializationMode)[0]
    r["reach dropped: step"] = c.step(1e-3)[0]
    r["reach added: exit"] = in_initialization(far_berry, "far", {"hinge_x_far": -0.045})[1]
    r["reach kept: exit"] = in_initialization(far_berry, "far kept", {"hinge_x_far": -0.11})[1][0]
    # calls out of FMI's order refused, the run going on as if never made; a refused set sets none of its values
    a, b = Fmu2(path, "order a"), Fmu2(path, "order b")
    for f in (a, b):
        f.set("base_ax", 2.0)
        for _ in range(20):
            f.step(1e-3)
    r["order: enter init"] = call(a.f.enterInitializationMode)[0]
    r["order: set a fixed parameter"] = a.set("mass_left", 0.02)[0]
    r["order: exit init"] = call(a.f.exitInitializationMode)[0]
    r["order: set two, one NaN"] = call(a.f.setReal, [a.vr["base_ax"], a.vr["base_az"]], [-5.0, math.nan])[0]
    r["order: base_ax"] = a.get("base_ax")
    r["order: steps"] = [a.step(1e-3)[0] for _ in range(20)] + [b.step(1e-3)[0] for _ in range(20)]
    r["order: same angle"] = (a.get("angle_left"), b.get("angle_left"))
    a.f.terminate()
    r["order: after terminate"] = (a.step(1e-3)[0], a.set("base_ax", 1.0)[0], a.get("angle_left"))
    # the same FMU extracted twice in one process: each instance's refusals are still its own call's status
    a = Fmu2(path, "a")
    b = Fmu2(path, "b")
    r["twice: a zero step"] = call(a.f.doStep, 0.0, 0.0)[0]
    r["twice: a NaN input"] = a.set("base_ax", math.nan)[0]
    r["twice: b zero step"] = call(b.f.doStep, 0.0, 0.0)[0]
    # start times and communication points the FMU cannot run from
    for label, start in (("NaN", math.nan), ("huge", 1e300)):
        c = Fmu2(path, f"start {label}", init=False)
        r[f"start {label}"] = call(lambda: c.f.setupExperiment(startTime=start))[0]
    c = Fmu2(path, "points")
    r["doStep at NaN"] = call(c.f.doStep, math.nan, 1e-3)[0]
    r["doStep at -inf"] = call(c.f.doStep, -math.inf, 1e-3)[0]
    # FMU states: crafted parameters refused; another instance's state brings its parameters
    a.set("base_ax", 3.0)
    for _ in range(20):
        a.step(1e-3)
    blob = a.state()
    fresh = Fmu2(path, "fresh")
    r["fresh"] = (fresh.get("mass_left"), fresh.get("restitution"), fresh.get("contact_law"))
    for label, name, value in (("mass", "mass_left", 0.5), ("restitution", "restitution", -3.0),
                               ("law 2.7", "contact_law", 2.7)):
        g = Fmu2(path, f"crafted {label}")
        st, msgs, _ = g.restore(crafted(blob, name, value))
        r[f"crafted {label}"] = (st, g.get("mass_left"), g.get("restitution"), g.get("contact_law"))
    yawed = Fmu2(path, "yawed", {"rachis_yaw": 0.5})
    plain = Fmu2(path, "plain")
    for f in (yawed, plain):
        f.set("base_ax", 2.0)
    for _ in range(5):
        yawed.step(1e-3)
    r["yaw state restored"] = plain.restore(yawed.state())[0]
    plain.t = yawed.t
    r["yaw reads"] = plain.get("rachis_yaw")
    r["yaw steps"] = (yawed.step(0.05)[0], plain.step(0.05)[0])
    r["yaw same angle"] = yawed.get("angle_left") == plain.get("angle_left")
    for f in (yawed, plain):  # a turn about the world's y axis: off the yawed rachis' y axis, for both
        f.set("base_omega_y", 1.0)
        f.set("base_alpha_y", 100.0)
    r["yaw turn about world y"] = (yawed.step(0.01)[0], plain.step(0.01)[0])
    # a state taken in Initialization Mode, restored after stepping: back in Initialization Mode
    c = Fmu2(path, "init state", init=False)
    c.f.setupExperiment(startTime=0.0)
    c.f.enterInitializationMode()
    c.set("initial_angle_left", -0.3)
    s0 = c.f.getFMUstate()
    c.f.exitInitializationMode()
    for _ in range(10):
        c.step(1e-3)
    r["init state restored"] = call(c.f.setFMUstate, s0)[0]
    r["init state: set parameter"] = c.set("initial_angle_left", 0.1)[0]
    r["init state: exit"] = call(c.f.exitInitializationMode)[0]
    c.t = 0.0
    r["init state: step"] = c.step(1e-3)[0]
    r["init state: angle"] = c.get("angle_left")
    # outputs in Initialization Mode: the start state the parameters set so far give, as after initialization
    c = Fmu2(path, "init outputs", init=False)
    c.f.setupExperiment(startTime=0.0)
    c.f.enterInitializationMode()
    c.set("initial_angle_left", -0.3)
    during = (c.get("angle_left"), c.get("pedicel_tension_left"))
    c.set("mass_left", -1.0)  # refused by the validator at exit: the outputs keep what they read
    refused = (c.get("angle_left"), c.get("pedicel_tension_left"))
    c.set("mass_left", 0.01)
    c.set("initial_angle_left", -0.2)
    again = (c.get("angle_left"), c.get("pedicel_tension_left"))
    c.f.exitInitializationMode()
    r["init outputs"] = (during, refused, again, (c.get("angle_left"), c.get("pedicel_tension_left")))
    # parameters named as the FMU names them; rtol's least value accepted
    for label, params in (("mass", {"mass_left": -1.0}), ("rtol", {"rtol": 1e-14})):
        r[f"param {label}"] = in_initialization(path, f"param {label}", params)[1]
    r["no contact restitution"] = in_initialization(no_contact, "no contact", {"restitution": 0.5})[1]
    # a pair pressed past the depth any contact law holds at: doStep says so with Warning, the step taken
    c = Fmu2(path, "deep", {"contact_stiffness": 1.0, "initial_angle_right": 0.8})
    bound = 0.2 * min(c.get("radius_left"), c.get("radius_right"))
    steps = []
    for k in range(600):
        st, msgs, status = c.step(1e-3)
        steps.append((st, status, " ".join(msgs), c.get("penetration_left_right"), c.get("angle_left")))
    r["deep"] = {"bound": bound, "steps": steps, "t": c.t}
    return r


def fmi3(path) -> dict:
    r = {}
    md = read_model_description(path)
    vr = {v.name: v.valueReference for v in md.modelVariables}

    def make(name, start=0.0):
        f = FMU3Slave(guid=md.guid, unzipDirectory=extract(path), modelIdentifier=md.coSimulation.modelIdentifier,
                      instanceName=name)
        f.instantiate(loggingOn=True, logMessage=lambda env, status, cat, msg: LOG.append(
            msg.decode(errors="replace") if isinstance(msg, bytes) else str(msg)))
        st = call(f.enterInitializationMode, None, start)[0]
        return f, st

    f, _ = make("five", start=5.0)
    f.exitInitializationMode()
    r["start 5: time"] = f.getFloat64([vr["time"]])[0]
    r["start 5: step"] = call(f.doStep, 5.0, 1e-3)[0]
    r["start 5: time after"] = f.getFloat64([vr["time"]])[0]
    r["start NaN"] = make("nan", start=math.nan)[1]
    a, _ = make("a")
    a.exitInitializationMode()
    b, _ = make("b")
    b.exitInitializationMode()
    r["twice: a zero step"] = call(a.doStep, 0.0, 0.0)[0]
    deep, _ = make("deep")
    deep.setFloat64([vr["contact_stiffness"], vr["initial_angle_right"]], [1.0, 0.8])
    deep.exitInitializationMode()
    said = []
    for k in range(600):
        st, msgs, _ = call(deep.doStep, k * 1e-3, 1e-3)
        said.append((st, " ".join(msgs)))
    r["deep"] = {"steps": said, "time": deep.getFloat64([vr["time"]])[0]}
    # what this FMU has not got (other variable types, event and configuration modes, clocks, derivatives): Error, the
    # host alive (pythonfmu3 threw a C++ exception from most: the host aborted) and the instance stepping on
    calls = {"getFloat32": ([vr["angle_left"]],), "setInt8": ([vr["base_ax"]], [1]), "getBinary": ([vr["angle_left"]],),
             "getClock": ([vr["angle_left"]],), "enterEventMode": (), "enterConfigurationMode": (),
             "updateDiscreteStates": (), "getAdjointDerivative": ([vr["angle_left"]], [vr["base_ax"]], [1.0])}
    r["unsupported"] = {name: call(getattr(a, name), *args)[0] for name, args in calls.items()}
    r["unsupported: empty get"] = call(a.getFloat32, [])[0]
    r["unsupported: step after"] = call(a.doStep, 0.0, 1e-3)[0]
    # doStep's output arguments, pre-filled with what a careless FMU would leave: an OK step, a Discard (too long
    # to integrate) and an Error (not from the FMU's time)
    raw = a.dll.fmi3DoStep
    raw.restype, raw.argtypes = ctypes.c_int, [ctypes.c_void_p, ctypes.c_double, ctypes.c_double, ctypes.c_int,
                                               *[ctypes.c_void_p] * 4]

    def step(t, h):
        flags, last = [ctypes.c_bool(True) for _ in range(3)], ctypes.c_double(-1.0)
        st = raw(a.component, t, h, 1, *map(ctypes.byref, flags), ctypes.byref(last))
        return st, [x.value for x in flags], last.value

    r["doStep outputs"] = [step(1e-3, 1e-3), step(2e-3, 1e6), step(1.0, 1e-3)]
    return r


def main(argv):
    out = {"fmi2": fmi2(argv[0], argv[2], argv[3]), "fmi3": fmi3(argv[1])}
    print("JSON:" + json.dumps(out), flush=True)
    sys.stdout.flush()


if __name__ == "__main__":
    main(sys.argv[1:])
