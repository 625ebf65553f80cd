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

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import minimize_scalar

from ..errors import SolverError
from ..model.model import Scene
from ..physics.dynamics import HC_MIN_APPROACH_SPEED, base_accel, pair_force, rhs
from ..physics.layout import layout
from . import core

# new mode after (old mode, function, direction of sign·function turning positive)
TRANSITION = {(0, core.EV_DELTA): 1, (1, core.EV_DELTA): 0, (1, core.EV_PHI): 2, (2, core.EV_DELTA): 0,
              (2, core.EV_PHI): 1}
MAX_SEGMENTS = 200_000
MAX_STEP = 5e-4  # s: every switch that lasts longer than this is seen


class _State:
    """The discrete state carried between segments: each pair's mode and Hunt–Crossley onset speed."""

    def __init__(self, npair: int):
        self.mode = np.zeros(npair, dtype=np.int64)
        self.v_onset = np.full(npair, HC_MIN_APPROACH_SPEED)
        self.smooth = np.zeros(npair, dtype=np.bool_)


def simulate_reference(scene: Scene, t_end: float | None = None, *, rtol: float | None = None,
                       atol: float | None = None, output_interval: float | None = None,
                       integrator: str = "DOP853", max_step: float = MAX_STEP):
    from ..results.run import Impacts, Run

    s = scene.solver
    t_end = s.t_end if t_end is None else float(t_end)
    rtol = s.rtol if rtol is None else rtol
    atol = s.atol if atol is None else atol
    dt_out = s.output_interval if output_interval is None else output_interval
    m = scene.model
    M = m.arrays
    X = scene.excitation.arrays
    lay = layout(m.n_berries, m.n_dof, len(m.couplings))
    npair = len(m.pairs)
    ny = lay.size
    st = _State(npair)
    rows, open_imp = [], {}
    # the reference integrates each pair's impulse and dissipation as extra ODE components, which
    # rhs fills when dy has room for them (the event solver uses quadrature), so the two check each other
    y = np.zeros(ny + 2 * npair)
    y[: 2 * lay.d] = scene.initial_state
    for p in range(npair):
        st.mode[p], ddot = core.classify(p, y, M, st.v_onset, 0)
        if st.mode[p] != 0:
            open_imp[p] = [0.0, ddot, 0.0, 0.0, 0.0, 0.0]
    breaks = [b for b in X.breaks if 0 < b < t_end] + [t_end]
    grid = np.linspace(0.0, t_end, int(round(t_end / dt_out)) + 1)
    out_t, out_y, out_mode, out_acc, out_vo = [], [], [], [], []
    peak_force = np.zeros(npair)
    dy = np.zeros(ny + 2 * npair)
    nfev = 0
    t = 0.0
    seg_start_piece = 0.0
    wall = time.perf_counter()
    segments = 0

    def f(tt, yy):
        rhs(tt, seg_start_piece, yy, dy, st.mode, st.v_onset, st.smooth, M, X.kind, X.par, X.table)
        return dy.copy()

    def make_event(p, fn, sign, t_seg):
        def ev(tt, yy):
            v = core.event_value(fn, sign, p, yy, M, st.v_onset)
            return min(v, -1e-300) if tt - t_seg < 1e-12 else v
        ev.terminal = True
        ev.direction = 1.0
        return ev

    while t < t_end:
        segments += 1
        if segments > MAX_SEGMENTS:
            raise SolverError(f"reference: more than {MAX_SEGMENTS} contact switches before t = {t:.6g} s")
        t_stop = next(b for b in breaks if b > t)
        seg_start_piece = t
        events, labels = [], []
        for p in range(npair):
            na, f1, s1, f2, s2 = core.active_events(st.mode[p], M.pair_law[p], M.pair_par[p])
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
            out_mode.append(np.repeat(st.mode[None, :], len(seg_grid), axis=0))
            out_vo.append(np.repeat(st.v_onset[None, :], len(seg_grid), axis=0))
            out_acc.append(np.array([base_accel(X.kind, X.par, X.table, tg, t) for tg in seg_grid]).reshape(-1, 2))
        for p in range(npair):
            if st.mode[p] == 1 and t_new > t:
                def neg_force(tt, p=p):
                    return -pair_force(p, sol.sol(tt), st.mode, st.v_onset, st.smooth, M)[0]
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
                if p in open_imp and best > open_imp[p][core.O_PEAK]:
                    open_imp[p][core.O_PEAK] = best
                    open_imp[p][core.O_TPEAK] = tbest
        y = sol.sol(t_new) if hit else sol.y[:, -1]
        t = t_new
        if hit:
            p, fn = labels[hit[0]]
            old = int(st.mode[p])
            new = TRANSITION[(old, fn)]
            _, ddot, _, _ = _kin(y, M, p)
            o_j, o_d = ny + p, ny + npair + p
            if old == 0:
                st.v_onset[p] = max(ddot, HC_MIN_APPROACH_SPEED)
                open_imp[p] = [t, ddot, 0.0, t, y[o_j], y[o_d]]
            elif new == 0:
                o = open_imp.pop(p)
                rows.append([p, o[0], t, o[1], o[2], o[3], y[o_j] - o[4], y[o_d] - o[5], -ddot])
            st.mode[p] = new
    wall = time.perf_counter() - wall
    for p, o in open_imp.items():
        rows.append([p, o[0], t, o[1], o[2], o[3], y[ny + p] - o[4], y[ny + npair + p] - o[5], math.nan])
    ongoing = np.r_[np.zeros(len(rows) - len(open_imp), bool), np.ones(len(open_imp), bool)]
    tt = np.concatenate(out_t)
    run = Run(scene, tt, np.concatenate(out_y)[:, :ny], np.concatenate(out_mode).reshape(len(tt), -1)[:, :npair],
              np.concatenate(out_acc), np.concatenate(out_vo).reshape(len(tt), -1)[:, :npair],
              np.zeros((len(tt), npair), dtype=bool), Impacts.from_rows(np.array(rows).reshape(-1, 9), ongoing),
              peak_force, np.zeros(m.n_berries),
              {"method": f"reference ({integrator})", "rhs_evaluations": nfev, "segments": segments, "wall_time": wall})
    run.peak_tension = run.pedicel_force.max(axis=0)
    return run


def _kin(y, M, p):
    from ..physics.dynamics import pair_kinematics
    return pair_kinematics(y, M, M.pair_idx[p, 0], M.pair_idx[p, 1], M.dof[M.berry.shape[0]])[:4]
