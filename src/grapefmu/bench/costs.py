"""What a run cannot cost less than, and what stepping from a face adds (issue 14).

- **RHS floor**: a bare compiled right-hand-side evaluation (inlined into a compiled loop, as the solver's
  stage loop has it), timed on the states of a run with their contact modes; a method's floor is its RHS
  evaluations × that cost. Wall / floor says how much a method spends beyond its physics.
- **advance loop**: the collision scene stepped by `Solver.advance(dt)` n times against one `Solver.run` of
  the same span, and against a compiled loop that integrates to the same n communication points (so it takes
  exactly the same solver steps): advance − compiled loop, per call, is advance's fixed cost.

Timings are the minimum of several repeats, interleaved.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..physics.compiled import jit
from ..physics.dynamics import rhs_inline
from ..physics.excitation import held
from ..physics.kinematics import workspace
from ..solver.loop import DONE, integrate
from ..solver.solver import Solver


@jit
def _rhs_loop(ts, ys, contacts, M, X, inp, W, pairs, dy, repeats):
    for _ in range(repeats):
        for k in range(ts.shape[0]):
            rhs_inline(ts[k], ts[k], ys[k], dy, contacts[k], M, X, inp, W, pairs, pairs.shape[0])
    return dy[0]


def rhs_seconds(run, repeats: int = 7, min_wall: float = 0.02) -> float:
    """Seconds per bare RHS evaluation on the run's samples (every pair listed: a two-berry scene's near
    list), the minimum of `repeats` timings of a compiled loop over all of them."""
    M, X = run.scene.arrays, run.scene.excitation.arrays
    W = workspace(M)
    pairs = np.arange(M.pair.shape[0])
    ys = np.ascontiguousarray(run.y)
    contacts = np.ascontiguousarray(run.contacts)
    dy = np.zeros(ys.shape[1])
    inp = held(on=False)[0]
    args = (run.t, ys, contacts, M, X, inp, W, pairs, dy)
    _rhs_loop(*args, 1)
    n = len(run.t)
    loops = 1
    while True:  # enough loops over the samples for a timing well above the clock's resolution
        t0 = time.perf_counter()
        _rhs_loop(*args, loops)
        if time.perf_counter() - t0 >= min_wall:
            break
        loops *= 4
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        _rhs_loop(*args, loops)
        best = min(best, time.perf_counter() - t0)
    return best / (loops * n)


@jit
def compiled_steps(s, dt, n, hold, ax, az):
    """The communication points of n calls of advance(dt) (held input (ax, 0, az) if hold, else the scene's
    excitation), without leaving compiled code: the same solver steps, none of the call's costs."""
    S = s.state
    inp = S.input[0]
    inp.held, inp.ax, inp.az = hold, ax, az
    inp.ay, inp.alpha_x, inp.alpha_y, inp.alpha_z = 0.0, 0.0, 0.0, 0.0
    for _ in range(n):
        if integrate(s.model, s.excitation, s.tableau, S, s.config, s.scratch, s.buffers, S.physical.t[0] + dt,
                     10_000_000) != DONE:
            return False
        s.scratch.cursor[0].n_impacts = 0
    return True


@dataclass
class AdvanceCost:
    dt: float
    calls: int
    advance: float        # wall s per simulated s, n calls of advance(dt)
    compiled: float       # the same communication points in one compiled loop
    run: float            # one Solver.run over the same span (1 ms output grid)
    steps_advance: int    # solver steps taken by the advance loop (communication points truncate steps)
    steps_run: int

    @property
    def fixed(self) -> float:
        """advance's fixed cost per call, s: what the call adds to the steps it integrates."""
        return (self.advance - self.compiled) * self.dt

    @property
    def over_run(self) -> float:
        """What each call costs beyond one run of the same span, s (the extra steps the points force included)."""
        return (self.advance - self.run) * self.dt


def advance_cost(scene, dt: float = 1e-3, calls: int = 2000, rtol: float = 1e-6, atol: float = 1e-8,
                 repeats: int = 7) -> AdvanceCost:
    """`calls` × Solver.advance(dt) (the scene's excitation, no held input), the compiled loop over the same
    points and one Solver.run of calls × dt, interleaved, the minimum of `repeats` each."""
    s = Solver(scene, rtol=rtol, atol=atol)
    start = s.get_state()
    span = calls * dt

    def by_advance():
        for _ in range(calls):
            s.advance(dt)
        s.take_impacts()

    def compiled():
        assert compiled_steps(s._session, dt, calls, False, 0.0, 0.0)

    def one_run():
        s.run(span, output_interval=1e-3)

    times = {by_advance: [], compiled: [], one_run: []}
    ends, steps = {}, {}
    for _ in range(repeats + 1):  # the first round warms up
        for fn in times:
            s.set_state(start)
            t0 = time.perf_counter()
            fn()
            times[fn].append(time.perf_counter() - t0)
            ends[fn], steps[fn] = s.y, s.stats["steps"]
    if not np.array_equal(ends[by_advance], ends[compiled]):
        raise AssertionError("the advance loop and the compiled loop must take the same steps")
    adv, comp, run = (min(times[f][1:]) / span for f in (by_advance, compiled, one_run))
    return AdvanceCost(dt, calls, adv, comp, run, steps[by_advance], steps[one_run])


__all__ = ["AdvanceCost", "advance_cost", "compiled_steps", "rhs_seconds"]
