"""The scipy reference: solve_ivp (DOP853 by default) with its own event location, restarted at
every contact switch. It shares only the right-hand side with the event-driven solver, so the
two disagree if our stepping, event location or mode logic is wrong.

scipy only sees an event function change sign between its step ends, so a contact (or a
separation) shorter than a step goes unseen; the reference therefore caps its step at
MAX_STEP. Restart rules that keep it from stalling (research notes): the new mode comes from which
function crossed and in which direction, never from the sign of a gap that is ~0 at the
restart, and each event function ignores the first 1e-12 s of a segment.
"""
from __future__ import annotations

import math
import time
from collections.abc import Callable

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import minimize_scalar

from ..errors import SolverError
from ..model.contact import HC_MIN_APPROACH_SPEED
from ..model.model import Scene
from ..physics.damage import bruising, detaching, pair_bruise_thresholds
from ..physics.dynamics import rhs
from ..physics.excitation import base_accel, held
from ..physics.compiled import jit
from ..physics.forces import CONTACT, pair_force
from ..physics.kinematics import pair_state, workspace
from ..physics.layout import initial, layout_of
from ..physics.observe import empty, observe
from ..results.contacts import ContactLog
from ..results.impacts import IMPACT, Impacts
from ..results.records import TOTALS
from ..results.run import Run
from .events import EV_DELTA, EV_PHI, classify, value_at, watched
from .loop import grid_last
from .sampling import PEAK_GAIN

# new mode after (old mode, function, direction of sign·function turning positive)
TRANSITION = {(0, EV_DELTA): 1, (1, EV_DELTA): 0, (1, EV_PHI): 2, (2, EV_DELTA): 0, (2, EV_PHI): 1}
MAX_SEGMENTS = 200_000
MAX_STEP = 5e-4  # s: every switch that lasts longer than this is seen


def simulate_reference(scene: Scene, t_end: float | None = None, *, rtol: float | None = None,
                       atol: float | None = None, output_interval: float | None = None,
                       integrator: str = "DOP853", max_step: float = MAX_STEP,
                       progress: Callable[[float, float], None] | None = None):
    s = scene.solver
    t_end = s.t_end if t_end is None else float(t_end)
    rtol = s.rtol if rtol is None else rtol
    atol = s.atol if atol is None else atol
    dt_out = s.output_interval if output_interval is None else output_interval
    m = scene.model
    M = scene.arrays
    X = scene.excitation.arrays
    lay = layout_of(scene)
    npair = len(m.pairs)
    ny = lay.size
    st = np.zeros(npair, dtype=CONTACT)
    st["v_onset"] = HC_MIN_APPROACH_SPEED
    W = workspace(M)
    kin = W.berry
    every = np.arange(npair)
    scene_input = held(on=False)[0]
    rows, open_imp = [], {}
    # the reference integrates each pair's impulse and dissipation as extra ODE components, which
    # rhs fills when dy has room for them (the event solver uses quadrature), so the two check each other
    y = initial(lay, scene, 2 * npair)
    for p in range(npair):
        st["mode"][p], ddot = classify(p, y, M, st, kin, 0)
        if st["mode"][p] != 0:
            open_imp[p] = [0.0, ddot, 0.0, 0.0, 0.0, 0.0]
    breaks = [b for b in X.breaks if 0 < b < t_end] + [t_end]
    grid = np.minimum(np.arange(grid_last(0.0, t_end, dt_out, True) + 1) * dt_out, t_end)  # the event solver's samples
    out_t, out_y, out_contacts, out_acc = [], [], [], []
    peak_force = np.zeros(npair)
    dy = np.zeros(ny + 2 * npair)
    nfev = 0
    t = 0.0
    seg_start_piece = 0.0
    wall = time.perf_counter()
    segments = 0
    peak_tension = np.full(m.n_berries, -np.inf)
    seg_end, seg_force, seg_tension = [], [], []  # each segment's end and its refined peaks, for the running columns

    def f(tt, yy):
        rhs(tt, seg_start_piece, yy, dy, st, M, X, scene_input, W, every, npair)
        return dy.copy()

    def make_event(p, fn, sign, t_seg):
        def ev(tt, yy):
            v = value_at(fn, sign, p, yy, M, st, kin)
            return min(v, -1e-300) if tt - t_seg < 1e-12 else v
        ev.terminal = True
        ev.direction = 1.0
        return ev

    while t < t_end:
        if progress:
            progress(t, t_end)
        segments += 1
        if segments > MAX_SEGMENTS:
            raise SolverError(f"reference: more than {MAX_SEGMENTS} contact switches before t = {t:.6g} s")
        t_stop = next(b for b in breaks if b > t)
        seg_start_piece = t
        events, labels = [], []
        for p in range(npair):
            na, f1, s1, f2, s2 = watched(st["mode"][p], M.pair["law"][p], M.pair["clamp"][p])
            for a in range(na):
                fn, sg = (f1, s1) if a == 0 else (f2, s2)
                events.append(make_event(p, fn, sg, t))
                labels.append((p, fn))
        sol = solve_ivp(f, (t, t_stop), y, method=integrator, rtol=rtol, atol=atol, dense_output=True,
                        events=events or None, max_step=max_step)
        nfev += sol.nfev
        if sol.status < 0:
            raise SolverError(f"reference: solve_ivp failed at t = {sol.t[-1]:.6g} s: {sol.message}")
        t_new = sol.t[-1]
        hit = None
        if sol.status == 1:
            for k, te in enumerate(sol.t_events):
                if len(te) and (hit is None or te[0] < hit[1]):
                    hit = (k, te[0])
            t_new = hit[1]
        seg_grid = grid[(grid > t - 1e-15 if not out_t else grid > t) & (grid <= t_new)]
        if len(seg_grid):
            yy = sol.sol(seg_grid).T
            out_t.append(seg_grid)
            out_y.append(yy)
            out_contacts.append(np.repeat(st[None, :], len(seg_grid), axis=0))
            out_acc.append(_accels(X, seg_grid, t))
        force_best = 0.0
        for p in range(npair):
            if st["mode"][p] == 1 and t_new > t:
                def neg_force(tt, p=p):
                    return -_force(sol.sol(tt), M, p, st, kin)
                ts = np.linspace(t, t_new, 65)
                fs = -np.array([neg_force(tt) for tt in ts])
                k = int(np.argmax(fs))
                best, tbest = fs[k], ts[k]
                if 0 < k < 64:
                    r = minimize_scalar(neg_force, bounds=(ts[k - 1], ts[k + 1]), method="bounded",
                                        options={"xatol": 1e-13})
                    if -r.fun > best:
                        best, tbest = -r.fun, r.x
                peak_force[p] = max(peak_force[p], best)
                force_best = max(force_best, best)
                if p in open_imp and best > open_imp[p][2]:
                    open_imp[p][2] = best
                    open_imp[p][3] = tbest
        if t_new > t:
            seg_end.append(t_new)
            seg_force.append(force_best)
            seg_tension.append(_largest_tensions(sol.sol, t, t_new, st, X, M, ny, peak_tension))
            np.maximum(peak_tension, seg_tension[-1], out=peak_tension)
        y = sol.sol(t_new) if hit else sol.y[:, -1]
        t = t_new
        if hit:
            p, fn = labels[hit[0]]
            old = int(st["mode"][p])
            new = TRANSITION[(old, fn)]
            ddot = _delta_dot(y, M, p, kin)
            o_j, o_d = ny + p, ny + npair + p
            if old == 0:
                st["v_onset"][p] = max(ddot, HC_MIN_APPROACH_SPEED)
                open_imp[p] = [t, ddot, 0.0, t, y[o_j], y[o_d]]
            elif new == 0:
                o = open_imp.pop(p)
                rows.append([p, o[0], t, o[1], o[2], o[3], y[o_j] - o[4], y[o_d] - o[5], -ddot])
            st["mode"][p] = new
    wall = time.perf_counter() - wall
    if progress:
        progress(t_end, t_end)
    for p, o in open_imp.items():
        rows.append([p, o[0], t, o[1], o[2], o[3], y[ny + p] - o[4], y[ny + npair + p] - o[5], math.nan])
    th = scene.thresholds
    limits = pair_bruise_thresholds(M, th.bruise_force, th.bruise_energy)
    table = np.zeros(len(rows), dtype=IMPACT)
    for k, r in enumerate(rows):
        table[k] = (*r, bruising(r[4], r[7], *limits[int(r[0])]))
    n_open = len(open_imp)
    impacts = Impacts.from_records(table[: len(rows) - n_open], table[len(rows) - n_open:])
    tt = np.concatenate(out_t)
    run = Run(scene, tt, np.concatenate(out_y)[:, :ny], ContactLog.of(np.concatenate(out_contacts).reshape(len(tt), npair)),
              np.concatenate(out_acc), np.zeros(len(tt), dtype=TOTALS),
              impacts, peak_force, np.zeros(m.n_berries),
              {"method": "reference", "integrator": integrator, "rhs_evaluations": nfev, "segments": segments,
               "wall_time": wall})
    # totals from the impact book, each segment's refined peaks (as of the segment before a sample, as the
    # event solver's are as of its step before) and the samples themselves
    tension = np.maximum.accumulate(run.pedicel_tension, axis=0)
    force = np.maximum.accumulate(run.contact_force.max(axis=1, initial=0.0))
    if seg_end:
        before = np.searchsorted(np.array(seg_end), tt, side="right") - 1  # the last segment ended by each sample
        ended = before >= 0
        tension[ended] = np.maximum(tension[ended], np.maximum.accumulate(np.array(seg_tension), axis=0)[before[ended]])
        force[ended] = np.maximum(force[ended], np.maximum.accumulate(np.array(seg_force))[before[ended]])
    run.peak_tension = np.maximum(peak_tension, tension[-1])
    run.totals["collision_count"] = np.searchsorted(np.sort(impacts.onset), tt, side="right")
    run.totals["bruising_impacts"] = [np.count_nonzero(impacts.bruising & (impacts.onset <= x)) for x in tt]
    run.totals["berries_over_detachment_force"] = detaching(tension, th.detachment_force).sum(axis=1)
    run.totals["peak_pedicel_tension"] = tension.max(axis=1)
    run.totals["peak_contact_force"] = force
    return run


def _accels(X, ts, t_ref):
    """The rachis acceleration (len(ts), 6) at the times ts of a segment whose excitation piece holds t_ref."""
    return np.array([base_accel(X, x, t_ref) for x in ts]).reshape(-1, 6)


def _tensions(sol, ts, contacts, X, t_ref, M, ny):
    """Every berry's pedicel tension (len(ts), N) at the times ts of a segment's dense output (the observation's)."""
    ys = np.ascontiguousarray(sol(ts).T[:, :ny])
    out = empty(len(ts), M.berry.shape[0], M.n_dof, M.pair.shape[0])
    observe(ys, np.repeat(contacts[None, :], len(ts), axis=0), _accels(X, ts, t_ref), M, out)
    return out.pedicel_tension


def _largest_tensions(sol, t0, t1, contacts, X, M, ny, peak):
    """Each berry's largest pedicel tension on one segment [t0, t1], on its dense output: sampled at the quarter
    points of scipy's steps, then, around each sampled maximum (the ends included) whose bracket could hold more
    than the berry's peak so far (peak) or the segment's best sample (2·largest − the lower neighbour bounds it),
    a bounded scalar search. The samples alone miss a peak between them by up to a quarter of their curvature,
    so the reference's peak would depend on its step, not its tolerance (as the event solver's did:
    docs/solver.md, "Peaks")."""
    edges = np.concatenate(([t0], sol.ts[(sol.ts > t0) & (sol.ts < t1)], [t1]))
    pts = np.append((edges[:-1, None] + np.diff(edges)[:, None] * np.arange(4) / 4).ravel(), t1)
    tens = _tensions(sol, pts, contacts, X, t0, M, ny)
    best = tens.max(axis=0)
    lo = np.maximum(np.arange(len(pts)) - 1, 0)
    hi = np.minimum(np.arange(len(pts)) + 1, len(pts) - 1)
    for i in range(tens.shape[1]):
        f = tens[:, i]
        bound = 2.0 * f - np.minimum(f[lo], f[hi])
        cand = np.flatnonzero((f >= f[lo]) & (f >= f[hi]) & (bound > best[i]))
        for k in cand[np.argsort(-f[cand], kind="stable")]:  # the largest first: its search bounds the rest
            ref = max(best[i], peak[i])
            if not bound[k] - ref > PEAK_GAIN * abs(ref):
                continue  # the bracket cannot hold more than what is found (ripples of round-off, too)
            r = minimize_scalar(lambda x: -_tensions(sol, np.array([x]), contacts, X, t0, M, ny)[0, i],
                                bounds=(pts[lo[k]], pts[hi[k]]), method="bounded", options={"xatol": 1e-13})
            best[i] = max(best[i], -r.fun)
    return best


@jit
def _force(y, M, p, contacts, kin):
    pr = M.pair[p]
    delta, delta_dot, _, _, _ = pair_state(y, M, pr, kin)
    return pair_force(pr, contacts[p], delta, delta_dot)[0]


@jit
def _delta_dot(y, M, p, kin):
    return pair_state(y, M, M.pair[p], kin)[1]
