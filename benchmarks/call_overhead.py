"""Fixed costs around the integration itself: numba unboxing the model and state on a compiled call,
Solver.advance's cost per call beyond the physics it integrates, and a whole simulate() of a very short run
(Python set-up and result assembly).

advance's fixed cost is measured as (N calls of advance(dt) − one compiled loop that integrates to the same N
communication points with the same held input) / N: both take exactly the same solver steps, so what is left
is the call itself (checks, boxing, saving the state for rollback). Of that, Python's part (advance with its
compiled call stubbed out) and the call of a compiled function that does nothing with advance's arguments: through
numba's dispatcher, which types every argument, and straight to its compiled entry (physics/compiled.entry), as
advance calls it.
Interleaved, best of 7. Run: .venv/bin/python benchmarks/call_overhead.py [scene.toml]"""
from __future__ import annotations

import sys
import time

import numba
import numpy as np

import grapefmu
from grapefmu import Solver
from grapefmu.bench.costs import compiled_steps
from grapefmu.physics.compiled import entry
from grapefmu.scenefile import default_scene_path
from grapefmu.solver import session as ses
from grapefmu.solver.loop import DONE

N, DT = 2000, 1e-3
#: the held input as the faces pass it (ACCEL_COMPONENTS: six floats); the planar pair (a_x, a_z) is accepted too,
#: converted on a slower path
ACCEL = (0.5, 0.0, 0.0, 0.0, 0.0, 0.0)
OMEGA = (0.0, 0.0, 0.0)


@numba.njit
def nothing(s, dt, held, a, omega_set, omega, max_steps):
    """session.advance's arguments and result, nothing done: what numba's dispatch alone costs."""
    return DONE, dt, 0


def main(path: str) -> None:
    scene = grapefmu.load_scene(path)
    s = Solver(scene)
    s.advance(DT, ACCEL)
    start = s.get_state()

    def by_advance():
        for _ in range(N):
            s.advance(DT, ACCEL)
        s.take_impacts()

    def compiled():
        assert compiled_steps(s._session, DT, N, True, ACCEL[0], ACCEL[2])

    def noop():
        for _ in range(N):
            s._integrate(s.t, s._outputs[0], 1)

    def python_part():
        compiled_advance = s._advance
        s._advance = lambda *args: (DONE, 0.0, 0)
        try:
            for _ in range(N):
                s.advance(DT, ACCEL)
        finally:
            s._advance = compiled_advance

    def dispatch():
        for _ in range(N):
            nothing(s._session, DT, True, ACCEL, False, OMEGA, s.max_steps)

    direct = entry(nothing, s._session, DT, True, ACCEL, False, OMEGA, s.max_steps)

    def straight():
        for _ in range(N):
            direct(s._session, DT, True, ACCEL, False, OMEGA, s.max_steps)

    def snapshots():  # what a face reads its outputs from after each step
        for _ in range(N):
            s.snapshot()

    times = {by_advance: [], compiled: [], noop: [], python_part: [], dispatch: [], straight: [], snapshots: []}
    ends = {}
    for _ in range(7):
        for fn in times:
            s.set_state(start)
            w = time.perf_counter()
            fn()
            times[fn].append((time.perf_counter() - w) / N)
            ends[fn] = s.y
    assert np.array_equal(ends[by_advance], ends[compiled]), "the two loops must take the same steps"
    adv, comp, nop, py, disp, ent, snap = (min(times[f]) for f in (by_advance, compiled, noop, python_part, dispatch,
                                                                    straight, snapshots))
    sim = min(_timed(lambda: grapefmu.simulate(scene, 1e-3)) for _ in range(200))
    print(f"scene {path}, {N} steps of {DT * 1e3:g} ms, best of 7 (µs per call)")
    print(f"compiled call that integrates nothing (integrate(), ~40 arrays unboxed): {nop * 1e6:7.2f}")
    print(f"Solver.advance(1 ms), held input:                                       {adv * 1e6:7.2f}")
    print(f"the same communication points in one compiled loop:                     {comp * 1e6:7.2f}")
    print(f"advance fixed cost (the difference):                                    {(adv - comp) * 1e6:7.2f}")
    print(f"  of which Python (advance, its compiled call stubbed out):             {py * 1e6:7.2f}")
    print(f"  of which the compiled call (advance's arguments, nothing done):       {ent * 1e6:7.2f}")
    print(f"  (the same through numba's dispatcher, which advance skips):           {disp * 1e6:7.2f}")
    print(f"Solver.snapshot():                                                      {snap * 1e6:7.2f}")
    print(f"simulate(scene, t_end = 1 ms), set-up and result assembly:              {sim * 1e6:7.1f}")


def _timed(fn) -> float:
    w = time.perf_counter()
    fn()
    return time.perf_counter() - w


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else str(default_scene_path()))
