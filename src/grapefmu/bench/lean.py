"""The best scipy driver we can write: the peer grapefmu's speed is measured against (issue 14).

`solve_ivp` (DOP853, RK45, LSODA, …) integrates only the head of the state (angles, rates, rachis motion: no
energy integrals, no per-pair components), in the same contact modes as the event solver, and restarts at every
mode switch, with nothing of grapefmu's but the compiled right-hand side and the mode logic (events.classify,
events.watched, the event functions' values, reference.TRANSITION: which function crossed gives the new mode,
and every function ignores the first 1e-12 s of a segment). It differs from solver/reference.py, the
reference that checks grapefmu, in what it leaves out to be fast:

- every call into compiled code takes one argument for the model, state and scratch (a numba StructRef of
  the same type as the Solver's Session) instead of a dozen arrays: a right-hand side costs 1.5 µs from
  Python (its result array included) instead of 4.4, an event function 0.7 µs instead of 1.8;
- no step cap, no peak-force search, no impact book: it records the grid, the onsets and the modes;
- terminal events only for the functions a pair watches in its mode, and only for pairs near contact:
  pairs apart by more than a skin share one event (the nearest of them closing to the skin), which
  restarts the segment with that pair watched;
- the grid (1 ms) is sampled by solve_ivp's t_eval, so a dense output is built only on steps that hold
  a grid point or an event (DOP853's costs three more evaluations).

Starting each segment with the step size the previous one ended with (first_step) was measured on the paper
collision scene: no gain at any tolerance (a step size from before a switch is rejected after it), so scipy
chooses it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba.experimental import structref
from numba.extending import overload
from scipy.integrate import solve_ivp

from ..errors import SolverError
from ..model.contact import HC_MIN_APPROACH_SPEED
from ..model.model import Scene
from ..physics.compiled import jit
from ..physics.dynamics import rhs
from ..physics.excitation import held
from ..physics.forces import CONTACT, active
from ..physics.kinematics import pair_state, workspace
from ..physics.layout import initial, model_head, layout_of
from ..solver.events import classify, event_value, watched
from ..solver.reference import MAX_SEGMENTS, TRANSITION
from ..solver.session import Session, SessionType

IGNORE = 1e-12  # s: a segment's event functions are not looked at before this
#: with at most this many pairs every pair is watched (one event per pair is as cheap as the shared one)
WATCH_ALL = 4
T_SEG, T_REF, SKIN = range(3)          # the driver's floats
N_ACTIVE, N_EVENTS, N_FAR = range(3)   # and counts


def _new(model, excitation, inp, work, contacts, pairs, events, signs, far, floats, counts, dy):
    raise NotImplementedError  # compiled only (the overload below)


@overload(_new)
def _new_impl(model, excitation, inp, work, contacts, pairs, events, signs, far, floats, counts, dy):
    kind = SessionType([("model", model), ("excitation", excitation), ("inp", inp), ("work", work),
                        ("contacts", contacts), ("pairs", pairs), ("events", events), ("signs", signs),
                        ("far", far), ("floats", floats), ("counts", counts), ("dy", dy)])

    def impl(model, excitation, inp, work, contacts, pairs, events, signs, far, floats, counts, dy):
        s = structref.new(kind)
        s.model, s.excitation, s.inp, s.work, s.contacts, s.pairs = model, excitation, inp, work, contacts, pairs
        s.events, s.signs, s.far, s.floats, s.counts, s.dy = events, signs, far, floats, counts, dy
        return s

    return impl


@jit
def _session(model, excitation, inp, work, contacts, pairs, events, signs, far, floats, counts, dy):
    return _new(model, excitation, inp, work, contacts, pairs, events, signs, far, floats, counts, dy)


@jit
def f_head(s, t, y):
    """dy/dt of the head y (angles, rates, rachis motion) with the pairs that push in their modes."""
    rhs(t, s.floats[T_REF], y, s.dy, s.contacts, s.model, s.excitation, s.inp[0], s.work, s.pairs,
        s.counts[N_ACTIVE])
    return s.dy[: y.shape[0]].copy()


@jit
def event(s, k, t, y):
    """Event k of the segment: a watched function of a near pair (< 0 until it switches)."""
    if t - s.floats[T_SEG] < IGNORE:
        return -1e-300
    p = s.events[k, 0]
    M = s.model
    pr = M.pair[p]
    delta, delta_dot, _, _, _ = pair_state(y, M, pr, s.work.berry)
    return event_value(s.events[k, 1], s.signs[k], pr, s.contacts[p], delta, delta_dot)


@jit
def far_event(s, t, y):
    """The shared event of the pairs apart by more than the skin: the largest δ + skin among them."""
    if t - s.floats[T_SEG] < IGNORE:
        return -1e-300
    M = s.model
    best = -math.inf
    for kk in range(s.counts[N_FAR]):
        best = max(best, pair_state(y, M, M.pair[s.far[kk]], s.work.berry)[0] + s.floats[SKIN])
    return best


@jit
def plan(s, t, y, watch_all):
    """A segment from t: which pairs push (the RHS evaluates only those), which functions are events, and
    which pairs are far enough apart to share one (a pair within 1.5 skins is watched: hysteresis)."""
    M, C = s.model, s.contacts
    s.floats[T_SEG] = t
    s.floats[T_REF] = t
    na = ne = nf = 0
    for p in range(C.shape[0]):
        c = C[p]
        pr = M.pair[p]
        if active(c):
            s.pairs[na] = p
            na += 1
        if c.mode == 0 and not watch_all and -pair_state(y, M, pr, s.work.berry)[0] > 1.5 * s.floats[SKIN]:
            s.far[nf] = p
            nf += 1
            continue
        n, f1, s1, f2, s2 = watched(c.mode, pr.law, pr.clamp)
        for a in range(n):
            s.events[ne, 0], s.events[ne, 1] = p, (f1 if a == 0 else f2)
            s.signs[ne] = s1 if a == 0 else s2
            ne += 1
    s.counts[N_ACTIVE], s.counts[N_EVENTS], s.counts[N_FAR] = na, ne, nf
    return ne, nf


@dataclass
class LeanRun:
    t: np.ndarray          # the output grid, s
    y: np.ndarray          # (S, m) the head of the state on it
    final: np.ndarray      # the head at t_end
    onsets: np.ndarray     # impact onsets, s
    modes: np.ndarray      # (P,) the modes at t_end
    rhs_evaluations: int
    segments: int


def simulate_lean(scene: Scene, *, rtol: float, atol: float, integrator: str = "DOP853",
                  output_interval: float = 1e-3, t_end: float | None = None, skin: float | None = None) -> LeanRun:
    """The scene from its initial state to t_end (scene.solver.t_end) with scipy's `integrator` ("DOP853",
    "RK45", "LSODA", …). Pairs apart by more than `skin` (m) share one event; without it every pair is watched
    one by one in a scene of at most WATCH_ALL pairs, and the skin is the mean berry radius in a larger one."""
    t_end = scene.solver.t_end if t_end is None else float(t_end)
    m = scene.model
    M, X = scene.arrays, scene.excitation.arrays
    npair = len(m.pairs)
    head = model_head.py_func(M)
    W = workspace(M)
    C = np.zeros(npair, dtype=CONTACT)
    C["v_onset"] = HC_MIN_APPROACH_SPEED
    floats = np.zeros(3)
    floats[SKIN] = m.mean_radius if skin is None else skin
    watch_all = skin is None and npair <= WATCH_ALL
    counts = np.zeros(3, dtype=np.int64)
    y = initial(layout_of(scene), scene)
    events = np.zeros((2 * npair, 2), np.int64)  # (pair, function) of each event; the session shares the arrays
    s: Session = _session(M, X, held(on=False), W, C, np.zeros(npair, np.int64), events, np.zeros(2 * npair),
                          np.zeros(npair, np.int64), floats, counts, np.zeros_like(y))
    y = y[:head].copy()
    kin = W.berry
    onsets = []
    for p in range(npair):
        C["mode"][p] = classify(p, y, M, C, kin, 0)[0]
        if C["mode"][p]:  # in contact from the start: an impact that starts now, as the event solver books it
            onsets.append(0.0)
    grid = np.linspace(0.0, t_end, int(round(t_end / output_interval)) + 1)
    breaks = [b for b in X.breaks if 0 < b < t_end] + [t_end]

    def fun(t, yy):
        return f_head(s, t, yy)

    def make(k):
        def ev(t, yy):
            return event(s, k, t, yy)
        ev.terminal, ev.direction = True, 1.0
        return ev

    def far(t, yy):
        return far_event(s, t, yy)
    far.terminal, far.direction = True, 1.0

    makers: list = []
    out_y = [y[None, :]]
    t, nfev, segments, gi = 0.0, 0, 0, 1
    while t < t_end:
        segments += 1
        if segments > MAX_SEGMENTS:
            raise SolverError(f"lean scipy driver: more than {MAX_SEGMENTS} segments before t = {t:.6g} s")
        t_stop = next(b for b in breaks if b > t)
        ne, nf = plan(s, t, y, watch_all)
        while len(makers) < ne:
            makers.append(make(len(makers)))
        watching = makers[:ne] + ([far] if nf else [])
        gj = int(np.searchsorted(grid, t_stop, side="right"))
        t_eval = grid[gi:gj] if grid[gj - 1] == t_stop else np.r_[grid[gi:gj], t_stop]
        sol = solve_ivp(fun, (t, t_stop), y, method=integrator, rtol=rtol, atol=atol, t_eval=t_eval,
                        events=watching or None)
        nfev += sol.nfev
        if sol.status < 0:
            raise SolverError(f"lean scipy driver: {integrator} failed at t = {sol.t[-1]:.6g} s: {sol.message}")
        hit = None
        if sol.status == 1:
            for k, te in enumerate(sol.t_events):
                if len(te) and (hit is None or te[0] < sol.t_events[hit][0]):
                    hit = k
        if hit is None:
            t_new, y = t_stop, sol.y[:, -1].copy()  # t_eval ends with t_stop
        else:
            t_new, y = float(sol.t_events[hit][0]), sol.y_events[hit][0].copy()
        ts = np.asarray(sol.t, dtype=float)  # a list when no t_eval point came before the event
        n_grid = int(np.count_nonzero((ts <= grid[gj - 1]) & (ts <= t_new)))
        if n_grid:
            out_y.append(sol.y[:, :n_grid].T)
            gi += n_grid
        t = t_new
        if hit is None or hit == ne:  # the end of the piece, or a far pair came within the skin: watch it now
            continue
        p, fn = events[hit]
        old = int(C["mode"][p])
        new = TRANSITION[(old, int(fn))]
        if old == 0:
            C["v_onset"][p] = max(classify(p, y, M, C, kin, old)[1], HC_MIN_APPROACH_SPEED)
            onsets.append(t)
        C["mode"][p] = new
    ys = np.concatenate(out_y)
    return LeanRun(grid[: len(ys)], ys, y, np.array(onsets), C["mode"].copy(), nfev, segments)


__all__ = ["LeanRun", "simulate_lean"]

