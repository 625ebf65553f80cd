"""Plays hostile FMI call sequences on a built FMU, in a process of its own (a crash is then a failed test,
not a dead test run):

    python -m tests.fmu_fuzz FMU PROGRAMS.json   -> JSON on the last line

Each program runs on a fresh instance A while a twin B, made the same way, receives only the calls A
accepted. After every refusal A's outputs must equal what they were; at the end A and B must agree exactly
and nothing may be NaN: a refused call changed nothing."""
from __future__ import annotations

import io
import json
import math
import sys
import zlib

import numpy as np
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException

STOP = 1.0


class Instance:
    def __init__(self, path, unzipped, md, name):
        self.md = md
        fmi3 = md.fmiVersion.startswith("3")
        if fmi3:
            from fmpy.fmi3 import FMU3Slave as Slave
        else:
            from fmpy.fmi2 import FMU2Slave as Slave
        self.fmi3 = fmi3
        self.f = Slave(guid=md.guid, unzipDirectory=unzipped, modelIdentifier=md.coSimulation.modelIdentifier,
                       instanceName=name)
        self.f.instantiate(loggingOn=False)
        if fmi3:
            self.f.enterInitializationMode(startTime=0.0, stopTime=STOP)
        else:
            self.f.setupExperiment(startTime=0.0, stopTime=STOP)
            self.f.enterInitializationMode()
        self.f.exitInitializationMode()
        self.t = 0.0

    def call(self, name, *args):
        """(status, result): the FMI status as the host sees it."""
        try:
            return 0, getattr(self.f, name)(*args)
        except FMICallException as e:
            return e.status, None

    def get_real(self, vrs):
        return self.call("getFloat64" if self.fmi3 else "getReal", vrs)

    def set_real(self, vrs, values):
        return self.call("setFloat64" if self.fmi3 else "setReal", vrs, values)

    def step(self, t, dt):
        return self.call("doStep", t, dt)

    def get_state_bytes(self):
        if self.fmi3:
            s = self.f.getFMUState()
            b = self.f.serializeFMUState(s)
            self.f.freeFMUState(s)
        else:
            s = self.f.getFMUstate()
            b = self.f.serializeFMUstate(s)
            self.f.freeFMUstate(s)
        return bytes(b)

    def restore(self, data: bytes):
        """(status of deserialize, status of set or None)."""
        name = "deserializeFMUState" if self.fmi3 else "deSerializeFMUstate"
        st, state = self.call(name, data)
        if st > 1:
            return st, None
        st2, _ = self.call("setFMUState" if self.fmi3 else "setFMUstate", state)
        self.call("freeFMUState" if self.fmi3 else "freeFMUstate", state)
        return st, st2


def crafted(data: bytes, field: str, how: str) -> bytes:
    """A well-formed npz state with one solver array made nonsensical (what a hostile host could craft)."""
    z = dict(np.load(io.BytesIO(data), allow_pickle=False))
    keys = sorted(k for k in z if k.startswith("solver.")) or sorted(z)
    key = keys[zlib.crc32(field.encode()) % len(keys)]
    a = z[key]
    if how == "huge" and a.dtype.kind in "iuf":
        z[key] = a + np.array(10 ** 9).astype(a.dtype)
    elif how == "nan" and a.dtype.kind == "f":
        z[key] = np.full_like(a, np.nan)
    elif how == "truncate" and a.ndim:
        z[key] = a[: a.shape[0] // 2]
    else:
        z[key] = np.zeros(3, dtype=np.int8)
    buf = io.BytesIO()
    np.savez(buf, **z)
    return buf.getvalue()


def corrupt(data: bytes, how: str, k: int) -> bytes:
    if how == "random":
        return np.random.default_rng(k).integers(0, 256, size=(k % 4000) + 1, dtype=np.uint8).tobytes()
    if how == "truncate":
        return data[: k % max(len(data), 1)]
    if how == "empty":
        return b""
    b = bytearray(data)
    b[k % len(b)] ^= 1 << (k % 8)
    return bytes(b)


def play(path, unzipped, md, program, index):
    vr = {v.name: v.valueReference for v in md.modelVariables}
    outputs = [v.valueReference for v in md.modelVariables if v.causality == "output" and v.type in ("Real", "Float64")]
    a = Instance(path, unzipped, md, f"a{index}")
    b = Instance(path, unzipped, md, f"b{index}")
    refused = accepted = 0
    problems = []
    for op in program:
        before = a.get_real(outputs)[1]
        kind = op[0]
        if kind == "set":
            _, target, value = op
            ref = vr.get(target, target if isinstance(target, int) else 99999)
            st, _ = a.set_real([ref], [value])
            twin = lambda: b.set_real([ref], [value])  # noqa: E731
        elif kind == "get":
            st, _ = a.get_real([op[1]])
            twin = None
        elif kind == "step":
            _, dt, offset = op
            st, _ = a.step(a.t + offset, dt)
            if st <= 1:
                a.t += dt
            twin = lambda t=b.t: b.step(t + offset, dt)  # noqa: E731 - B's time before the step below adds dt
        elif kind in ("corrupt", "crafted"):
            good = a.get_state_bytes()
            data = corrupt(good, op[1], op[2]) if kind == "corrupt" else crafted(good, op[1], op[2])
            st, st2 = a.restore(data)
            st = max(st, st2 or 0)
            twin = lambda: b.restore(data)  # noqa: E731
        else:  # a round trip through serialized bytes, which must be accepted
            data = a.get_state_bytes()
            st, st2 = a.restore(data)
            st = max(st, st2 or 0)
            if st > 1:
                problems.append(f"{op}: a state the FMU wrote was refused (status {st})")
            twin = lambda: b.restore(b.get_state_bytes())  # noqa: E731
        if st > 3:
            problems.append(f"{op}: status {st} (Fatal)")
        if st > 1:
            refused += 1
            after = a.get_real(outputs)[1]
            if after != before:
                problems.append(f"{op}: refused (status {st}) but the outputs changed")
        else:
            accepted += 1
            if kind == "step":
                b.t += op[1]
            if twin and max(x for x in twin() if isinstance(x, int)) > 1:  # (status, result or a 2nd status)
                problems.append(f"{op}: accepted by A, refused by its twin B (the twin must follow A)")
    st, _ = a.step(a.t, 1e-3) if a.t + 1e-3 <= STOP else (0, None)
    if st > 1:
        problems.append(f"a normal step after the program was refused (status {st})")
    else:
        b.step(b.t, 1e-3)
    ya, yb = a.get_real(outputs)[1], b.get_real(outputs)[1]
    if ya != yb:
        problems.append("A and its twin B disagree: a refused call left a trace")
    if any(not math.isfinite(x) for x in ya):
        problems.append("NaN or infinite output")
    for x in (a, b):
        x.f.terminate()
        x.f.freeInstance()
    return {"refused": refused, "accepted": accepted, "problems": problems}


def main():
    path, programs = sys.argv[1], json.loads(open(sys.argv[2]).read())
    md = read_model_description(path)
    unzipped = extract(path)
    results = [play(path, unzipped, md, p, k) for k, p in enumerate(programs)]
    print("JSON:" + json.dumps(results), flush=True)


if __name__ == "__main__":
    main()
