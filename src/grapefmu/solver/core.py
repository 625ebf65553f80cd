"""The compiled event-driven integration loop (docs/solver.md).

One accepted Runge–Kutta step at a time: sample the contact functions on the step's
dense output (so a contact that opens and closes inside one step is still seen),
locate the earliest switch to ~1e-13 s, truncate the step there, restart just past
the switching surface in the mode the state is now in, and never straddle an
excitation breakpoint. Impacts, peaks and the Zeno guard are booked here, in the
same pass, so nothing is recomputed afterwards.
"""
from __future__ import annotations

import math

import numba as nb
import numpy as np

from ..physics.dynamics import (HC_MIN_APPROACH_SPEED, base_accel, centres, contact_law, coupling_loads, jit,
                                pair_force, pair_kinematics, pedicel_tension, push_pair, rhs)

#: the right-hand side inlined into the stage loop only: a compiled call passing a dozen arrays costs
#: more in reference counting than two berries' arithmetic, and inlining it everywhere doubles compile time
rhs_stage = nb.njit(cache=True, error_model="numpy", inline="always")(rhs.py_func)

# float slots of S.fl
T, H, T_PREV, H_LAST, GRID_T0, GRID_DT, HELD_AX, HELD_AY = range(8)
# int slots of S.it
(N_STEPS, N_REJECTED, N_RHS, N_SWITCHES, N_IMPACTS, N_ZENO, BREAK_IDX, GRID_K, N_OUT, N_IMP, STATUS, HELD,
 N_NEAR, N_REBUILDS, NEAR_SUM) = range(15)
# slots of cfg
RTOL, ATOL, FIXED, ZENO_WIN, LOCATE, HMAX, SKIN, STEP_CONTROL = range(8)
# statuses
DONE, OUT_FULL, IMP_FULL, MAX_STEPS, STEP_UNDERFLOW, NOT_FINITE = range(6)
# columns of an impact row
I_PAIR, I_ONSET, I_END, I_SPEED, I_PEAK, I_TPEAK, I_IMPULSE, I_DISS, I_SEP_SPEED = range(9)
IMPACT_COLUMNS = 9
# columns of an open impact
O_ONSET, O_SPEED, O_PEAK, O_TPEAK, O_J, O_D = range(6)
# contact event functions
EV_DELTA, EV_PHI = 0, 1
N_SAMPLES = 4          # sub-intervals per step searched for a sign change (plus local-maximum refinement)
#: Boole's rule on the N_SAMPLES + 1 equally spaced samples: the per-pair impulse and dissipation
#: integrals, exact for quintics like the step's dense output
BOOLE = np.array([7.0, 32.0, 12.0, 32.0, 7.0]) / 90.0
ROOT_TOL = 1e-13       # s, absolute tolerance of event times


@jit
def dense(theta, y0, q, h, out):
    """y(t0 + θh) = y0 + h Σ_j Q[:, j] θ^(j+1)."""
    for r in range(y0.shape[0]):
        acc = 0.0
        for j in range(q.shape[1] - 1, -1, -1):
            acc = (acc + q[r, j]) * theta
        out[r] = y0[r] + h * acc


@jit
def dense_head(theta, y0, q, h, out, m):
    """dense() for the first m components only (the angles and rates that events and forces need)."""
    for r in range(m):
        acc = 0.0
        for j in range(q.shape[1] - 1, -1, -1):
            acc = (acc + q[r, j]) * theta
        out[r] = y0[r] + h * acc


@jit
def combine(coef, stages, count, out):
    """out = Σ_{m < count} coef[m] · stages[m], summed in m order for every element."""
    out[:] = 0.0
    for m in range(count):
        c = coef[m]
        row = stages[m]
        for r in range(out.shape[0]):
            out[r] += c * row[r]


@jit
def rms_norm(x, scale):
    s = 0.0
    for i in range(x.shape[0]):
        s += (x[i] / scale[i]) ** 2
    return math.sqrt(s / x.shape[0])


@jit
def event_value(fn, sign, p, y, M, v_onset):
    i, j = M.pair_idx[p, 0], M.pair_idx[p, 1]
    delta, delta_dot, _, _, _ = pair_kinematics(y, M, i, j, M.dof[M.berry.shape[0]])
    if fn == EV_DELTA:
        return sign * delta
    _, _, phi = contact_law(M.pair_law[p], M.pair_par[p], delta, delta_dot, v_onset[p])
    return sign * phi


@jit
def active_events(mode, law, par):
    """(fn, sign) pairs watched in a mode: an event is where sign·fn turns positive."""
    clamped = par[2] > 0.5 and law != 1
    if mode == 0:
        return 1, EV_DELTA, 1.0, EV_PHI, 0.0
    if mode == 1:
        return (2 if clamped else 1), EV_DELTA, -1.0, EV_PHI, -1.0
    return 2, EV_DELTA, -1.0, EV_PHI, 1.0


@jit
def classify(p, y, M, v_onset, old_mode):
    """The mode the state is in: 0 apart, 1 loaded, 2 overlapping but unloaded."""
    i, j = M.pair_idx[p, 0], M.pair_idx[p, 1]
    delta, delta_dot, _, _, _ = pair_kinematics(y, M, i, j, M.dof[M.berry.shape[0]])
    if delta <= 0.0:
        return 0, delta_dot
    vo = v_onset[p] if old_mode != 0 else max(delta_dot, HC_MIN_APPROACH_SPEED)
    vsave = v_onset[p]
    v_onset[p] = vo
    _, _, phi = contact_law(M.pair_law[p], M.pair_par[p], delta, delta_dot, vo)
    v_onset[p] = vsave
    return (1 if phi > 0.0 else 2), delta_dot


@jit
def locate_root(fn, sign, p, ta, tb, y0, q, h, M, v_onset, work, tol):
    """Illinois iteration on θ ∈ [ta, tb] with v(ta) ≤ 0 < v(tb); returns the right end."""
    m = 2 * M.dof[M.berry.shape[0]]
    dense_head(ta, y0, q, h, work, m)
    va = event_value(fn, sign, p, work, M, v_onset)
    dense_head(tb, y0, q, h, work, m)
    vb = event_value(fn, sign, p, work, M, v_onset)
    side = 0
    for _ in range(200):
        if (tb - ta) * h <= tol:
            break
        if va < vb and va <= 0.0 < vb:
            tm = (ta * vb - tb * va) / (vb - va)
        else:
            tm = 0.5 * (ta + tb)
        if not (ta < tm < tb):
            tm = 0.5 * (ta + tb)
        # keep the bracket shrinking from both sides
        if (tb - ta) * h < 64 * tol:
            tm = 0.5 * (ta + tb)
        dense_head(tm, y0, q, h, work, m)
        vm = event_value(fn, sign, p, work, M, v_onset)
        if vm > 0.0:
            tb, vb = tm, vm
            if side == 1:
                va *= 0.5
            side = 1
        else:
            ta, va = tm, vm
            if side == -1:
                vb *= 0.5
            side = -1
    return tb


@jit
def switch_pair(p, new_mode, t, delta_dot, S, B, cfg):
    """Change a pair's mode and keep the impact book and the Zeno guard."""
    old = S.mode[p]
    if old == new_mode:
        return
    if old == 0:
        S.v_onset[p] = max(delta_dot, HC_MIN_APPROACH_SPEED)
        S.imp_open[p, O_ONSET] = t
        S.imp_open[p, O_SPEED] = delta_dot
        S.imp_open[p, O_PEAK] = 0.0
        S.imp_open[p, O_TPEAK] = t
        S.imp_open[p, O_J] = S.pair_int[p, 0]
        S.imp_open[p, O_D] = S.pair_int[p, 1]
        S.it[N_IMPACTS] += 1
    elif new_mode == 0:
        k = S.it[N_IMP]
        row = B.imp[k]
        row[I_PAIR] = p
        row[I_ONSET] = S.imp_open[p, O_ONSET]
        row[I_END] = t
        row[I_SPEED] = S.imp_open[p, O_SPEED]
        row[I_PEAK] = S.imp_open[p, O_PEAK]
        row[I_TPEAK] = S.imp_open[p, O_TPEAK]
        row[I_IMPULSE] = S.pair_int[p, 0] - S.imp_open[p, O_J]
        row[I_DISS] = S.pair_int[p, 1] - S.imp_open[p, O_D]
        row[I_SEP_SPEED] = -delta_dot
        S.it[N_IMP] = k + 1
    S.mode[p] = new_mode
    S.it[N_SWITCHES] += 1
    if S.smooth_until[p] == np.inf:
        return  # a smooth law under step-size control: no events, so no Zeno guard either
    kz = S.ring.shape[1]
    pos = S.ring_pos[p]
    S.ring[p, pos] = t
    pos = (pos + 1) % kz
    S.ring_pos[p] = pos
    if t - S.ring[p, pos] < cfg[ZENO_WIN]:
        S.smooth[p] = True
        S.smooth_until[p] = t + cfg[ZENO_WIN]
        S.it[N_ZENO] += 1


@jit
def initial_step(t0, y0, f0, M, X, S, cfg, order, t_stop):
    ny = y0.shape[0]
    scale = cfg[ATOL] + cfg[RTOL] * np.abs(y0)
    d0 = rms_norm(y0, scale)
    d1 = rms_norm(f0, scale)
    h0 = 1e-6 if (d0 < 1e-5 or d1 < 1e-5) else 0.01 * d0 / d1
    h0 = min(h0, t_stop - t0)
    y1 = y0 + h0 * f0
    f1 = np.empty(ny)
    rhs(t0 + h0, t0, y1, f1, S.mode, S.v_onset, S.smooth, M, X.kind, X.par, X.table)
    d2 = rms_norm(f1 - f0, scale) / h0
    if d1 <= 1e-15 and d2 <= 1e-15:
        h1 = max(1e-6, h0 * 1e-3)
    else:
        h1 = (0.01 / max(d1, d2)) ** (1.0 / (order + 1))
    return min(100 * h0, h1, cfg[HMAX])


@jit
def sample_step(t0, h, theta_end, y0, q, M, X, S, work, fbuf, pwbuf, fext, tens, cls):
    """On the committed part of the step: peaks of contact force and pedicel tension (the force
    refined around an interior maximum), each near pair's mode class at every sample, and the
    per-pair impulse and dissipation integrals (Boole's rule on the samples)."""
    n = M.berry.shape[0]
    nd = M.dof[n]
    nnear = S.it[N_NEAR]
    for k in range(N_SAMPLES + 1):
        th = theta_end * k / N_SAMPLES
        dense_head(th, y0, q, h, work, 2 * nd)
        coupling_loads(work, M, fext)
        for kk in range(nnear):
            p = S.near[kk]
            if S.mode[p] == 0 and not S.smooth[p]:
                fbuf[k, kk] = 0.0
                pwbuf[k, kk] = 0.0
                continue
            f, power, _, _, nx, ny, nz = pair_force(p, work, S.mode, S.v_onset, S.smooth, M)
            fbuf[k, kk] = f
            pwbuf[k, kk] = power
            push_pair(fext, M.pair_idx[p, 0], M.pair_idx[p, 1], f, nx, ny, nz)
            if S.smooth[p]:
                cls[k, kk] = classify(p, work, M, S.v_onset, S.mode[p])[0]
        ax, az = base_accel(X.kind, X.par, X.table, t0 + th * h, t0)
        pedicel_tension(work, ax, az, fext, M, tens)
        for i in range(n):
            if tens[i] > S.peak_tension[i]:
                S.peak_tension[i] = tens[i]
    span = theta_end * h
    for kk in range(nnear):
        p = S.near[kk]
        if S.mode[p] == 0 and not S.smooth[p]:
            continue
        fi = 0.0
        pi = 0.0
        for k in range(N_SAMPLES + 1):
            fi += BOOLE[k] * fbuf[k, kk]
            pi += BOOLE[k] * pwbuf[k, kk]
        S.pair_int[p, 0] += span * fi
        S.pair_int[p, 1] += span * pi
        kbest = 0
        for k in range(1, N_SAMPLES + 1):
            if fbuf[k, kk] > fbuf[kbest, kk]:
                kbest = k
        fbest = fbuf[kbest, kk]
        tbest = theta_end * kbest / N_SAMPLES
        turning = 0 < kbest < N_SAMPLES
        if not turning and fbest > 0.0 and fbest >= S.imp_open[p, O_PEAK]:
            # a maximum at a step end is a peak only if the force already falls there
            eps = 1e-3 / N_SAMPLES
            th_in = theta_end * (1.0 - eps) if kbest == N_SAMPLES else theta_end * eps
            dense_head(th_in, y0, q, h, work, 2 * nd)
            turning = pair_force(p, work, S.mode, S.v_onset, S.smooth, M)[0] > fbest
        if turning and fbest > 0.0 and fbest >= S.imp_open[p, O_PEAK]:
            # golden-section search between the neighbouring samples (one-sided at the step's ends,
            # where the peak may sit just inside this step)
            a = theta_end * max(kbest - 1, 0) / N_SAMPLES
            b = theta_end * min(kbest + 1, N_SAMPLES) / N_SAMPLES
            gr = 0.6180339887498949
            for _ in range(40):
                c1 = b - gr * (b - a)
                c2 = a + gr * (b - a)
                dense_head(c1, y0, q, h, work, 2 * nd)
                f1 = pair_force(p, work, S.mode, S.v_onset, S.smooth, M)[0]
                dense_head(c2, y0, q, h, work, 2 * nd)
                f2 = pair_force(p, work, S.mode, S.v_onset, S.smooth, M)[0]
                if f1 > f2:
                    b = c2
                else:
                    a = c1
                if (b - a) * h < 1e-12:
                    break
            tm = 0.5 * (a + b)
            dense_head(tm, y0, q, h, work, 2 * nd)
            fm = pair_force(p, work, S.mode, S.v_onset, S.smooth, M)[0]
            if fm > fbest:
                fbest, tbest = fm, tm
        if fbest > S.peak_force[p]:
            S.peak_force[p] = fbest
        if fbest > S.imp_open[p, O_PEAK]:
            S.imp_open[p, O_PEAK] = fbest
            S.imp_open[p, O_TPEAK] = t0 + tbest * h


@jit
def _max_on(fn, sign, p, a, b, y0, q, h, M, v_onset, work):
    """Golden-section search for the largest sign·fn on [a, b] (θ units); returns (θ, value)."""
    m = 2 * M.dof[M.berry.shape[0]]
    gr = 0.6180339887498949
    c1 = b - gr * (b - a)
    c2 = a + gr * (b - a)
    dense_head(c1, y0, q, h, work, m)
    f1 = event_value(fn, sign, p, work, M, v_onset)
    dense_head(c2, y0, q, h, work, m)
    f2 = event_value(fn, sign, p, work, M, v_onset)
    for _ in range(60):
        if f1 > 0.0 or f2 > 0.0 or (b - a) * h < ROOT_TOL:
            break
        if f1 > f2:
            b, c2, f2 = c2, c1, f1
            c1 = b - gr * (b - a)
            dense_head(c1, y0, q, h, work, m)
            f1 = event_value(fn, sign, p, work, M, v_onset)
        else:
            a, c1, f1 = c1, c2, f2
            c2 = a + gr * (b - a)
            dense_head(c2, y0, q, h, work, m)
            f2 = event_value(fn, sign, p, work, M, v_onset)
    return (c1, f1) if f1 > f2 else (c2, f2)


@jit
def find_event(y0, q, h, t0, M, S, vbuf, ytmp, work, pos):
    """Earliest θ in (0, 1] where a watched contact function of a near pair turns positive, or (1, False).

    Each function is sampled at N_SAMPLES + 1 points. A sign change gives a bracket at once;
    a sampled local maximum that is still ≤ 0 but close to zero is refined by a golden-section
    search, so a graze that opens and closes between two samples is not missed. A pair apart only
    watches δ, read from the berry centres the broad phase already sampled (pos); no trigonometry."""
    nnear = S.it[N_NEAR]
    m = 2 * M.dof[M.berry.shape[0]]
    b = M.berry
    tol = max(ROOT_TOL, 8 * 2.2e-16 * abs(t0))
    for k in range(N_SAMPLES + 1):
        dense_head(k / N_SAMPLES, y0, q, h, work, m)
        for kk in range(nnear):
            p = S.near[kk]
            if S.mode[p] == 0:
                i, j = M.pair_idx[p, 0], M.pair_idx[p, 1]
                dx = pos[k, j, 0] - pos[k, i, 0]
                dy = pos[k, j, 1] - pos[k, i, 1]
                dz = pos[k, j, 2] - pos[k, i, 2]
                vbuf[k, 2 * kk] = b[i, 1] + b[j, 1] - math.sqrt(dx * dx + dy * dy + dz * dz)
                vbuf[k, 2 * kk + 1] = -1.0
                continue
            na, f1, s1, f2, s2 = active_events(S.mode[p], M.pair_law[p], M.pair_par[p])
            vbuf[k, 2 * kk] = event_value(f1, s1, p, work, M, S.v_onset)
            vbuf[k, 2 * kk + 1] = event_value(f2, s2, p, work, M, S.v_onset) if na == 2 else -1.0
    best = 2.0
    for kk in range(nnear):
        p = S.near[kk]
        if S.smooth[p]:
            continue
        na, f1, s1, f2, s2 = active_events(S.mode[p], M.pair_law[p], M.pair_par[p])
        for a in range(na):
            fn = f1 if a == 0 else f2
            sg = s1 if a == 0 else s2
            col = 2 * kk + a
            if vbuf[0, col] > 0.0:
                best = 0.0  # inconsistent start: switch at once, no advance
                continue
            for k in range(1, N_SAMPLES + 1):
                th_a = (k - 1) / N_SAMPLES
                if th_a >= best:
                    break
                if vbuf[k, col] > 0.0:
                    root = locate_root(fn, sg, p, th_a, k / N_SAMPLES, y0, q, h, M, S.v_onset, ytmp, tol)
                    best = min(best, root)
                    break
            for k in range(N_SAMPLES + 1):
                lo = max(k - 1, 0)
                hi = min(k + 1, N_SAMPLES)
                if lo / N_SAMPLES >= best:
                    break
                v = vbuf[k, col]
                if v > 0.0 or v < vbuf[lo, col] or v < vbuf[hi, col]:
                    continue
                rise = (v - vbuf[lo, col]) + (v - vbuf[hi, col])
                if v + 2.0 * rise <= 0.0:
                    continue  # a local maximum far below zero: no graze here
                th_m, vm = _max_on(fn, sg, p, lo / N_SAMPLES, hi / N_SAMPLES, y0, q, h, M, S.v_onset, work)
                if vm > 0.0:
                    root = locate_root(fn, sg, p, lo / N_SAMPLES, th_m, y0, q, h, M, S.v_onset, ytmp, tol)
                    best = min(best, root)
    if best <= 1.0:
        return best, True
    return 1.0, False


@jit
def rebuild_near(S, M, pos, skin):
    """The broad phase (a Verlet list): keep the candidate pairs closer than `skin` at the berry
    centres pos, and every pair in contact. It stays valid while no berry moves skin/2 from pos.
    A smooth law under step-size control is evaluated inline exactly for its near pairs."""
    nn = 0
    for p in range(S.mode.shape[0]):
        i, j = M.pair_idx[p, 0], M.pair_idx[p, 1]
        d = math.sqrt((pos[j, 0] - pos[i, 0]) ** 2 + (pos[j, 1] - pos[i, 1]) ** 2 + (pos[j, 2] - pos[i, 2]) ** 2)
        near = d - M.berry[i, 1] - M.berry[j, 1] < skin or S.mode[p] != 0
        if S.smooth_until[p] == np.inf:
            S.smooth[p] = near
        if near or S.smooth[p]:
            S.near[nn] = p
            nn += 1
    S.it[N_NEAR] = nn
    S.ref[:, :] = pos
    S.it[N_REBUILDS] += 1


@jit
def travel(y0, q, h, M, ref, work, pos):
    """How far any berry gets from ref over the step (its samples, plus half the largest chord
    between samples for the stretch in between); fills pos with the centres at the samples."""
    n = M.berry.shape[0]
    m = 2 * M.dof[n]
    for k in range(N_SAMPLES + 1):
        dense_head(k / N_SAMPLES, y0, q, h, work, m)
        centres(work, M, pos[k])
    worst = 0.0
    for i in range(n):
        for k in range(N_SAMPLES + 1):
            d = math.sqrt((pos[k, i, 0] - ref[i, 0]) ** 2 + (pos[k, i, 1] - ref[i, 1]) ** 2
                          + (pos[k, i, 2] - ref[i, 2]) ** 2)
            if k > 0:
                d += 0.5 * math.sqrt((pos[k, i, 0] - pos[k - 1, i, 0]) ** 2 + (pos[k, i, 1] - pos[k - 1, i, 1]) ** 2
                                     + (pos[k, i, 2] - pos[k - 1, i, 2]) ** 2)
            worst = max(worst, d)
    return worst


@jit
def keep_near_valid(y0, q, h, M, S, skin, work, pos, step_control):
    """Keep the near list valid over this step. Returns how far a berry got from the list's
    reference (the caller rebuilds after the step once that passes skin/4), or −1: retry shorter.

    Up to skin/2 the list holds for the whole step. Beyond, a pair outside the list could have
    touched inside this step: with event location the list is rebuilt from the step's start (wide
    enough for the step) and the events search it; under step-size control the forces of such a
    pair were missing from the stages, so the step is refused."""
    if S.mode.shape[0] == 0:
        return 0.0
    reach = travel(y0, q, h, M, S.ref, work, pos)  # also fills pos, which the event search reads
    if not math.isfinite(skin):
        return 0.0
    if reach <= 0.5 * skin:
        return reach
    if step_control:
        return -1.0
    rebuild_near(S, M, pos[0], skin)
    reach = travel(y0, q, h, M, S.ref, work, pos)
    if reach > 0.5 * skin:
        rebuild_near(S, M, pos[0], 2.0 * reach * 1.001)
    return math.inf  # rebuild again from the committed state


@jit
def integrate(M, X, TB, S, cfg, B, t_target, max_steps):
    """Advance S to t_target (or until a buffer fills or max_steps). Returns a status code."""
    n = M.berry.shape[0]
    npair = S.mode.shape[0]
    ny = S.y.shape[0]
    ns = TB.b.shape[0]
    kd = TB.p.shape[1]
    locate = cfg[LOCATE] > 0.5
    fixed = cfg[FIXED] > 0.0
    err_exp = -1.0 / (TB.error_order + 1.0)
    stages = S.k
    ytmp = np.empty(ny)
    acc_row = np.empty(ny)
    ynew = np.empty(ny)
    err = np.empty(ny)
    scale = np.empty(ny)
    work = np.empty(ny)
    q = S.q
    fbuf = np.zeros((N_SAMPLES + 1, max(npair, 1)))
    pwbuf = np.zeros((N_SAMPLES + 1, max(npair, 1)))
    fext = np.zeros((n, 3))
    pos = np.zeros((N_SAMPLES + 1, n, 3))
    tens = np.zeros(n)
    cls = np.zeros((N_SAMPLES + 1, max(npair, 1)), dtype=np.int64)
    vbuf = np.zeros((N_SAMPLES + 1, 2 * max(npair, 1)))
    nbreak = X.breaks.shape[0]
    cap_out = B.t.shape[0]
    cap_imp = B.imp.shape[0]
    steps = 0
    while S.fl[T] < t_target:
        if steps >= max_steps:
            return MAX_STEPS
        if S.it[N_IMP] + npair > cap_imp:
            return IMP_FULL
        t0 = S.fl[T]
        bi = S.it[BREAK_IDX]
        while bi < nbreak and X.breaks[bi] <= t0:
            bi += 1
        S.it[BREAK_IDX] = bi
        t_stop = t_target
        if bi < nbreak and X.breaks[bi] < t_stop:
            t_stop = X.breaks[bi]
        if fixed:
            h_prop = cfg[FIXED]
        else:
            if S.fl[H] <= 0.0:
                S.fl[H] = initial_step(t0, S.y, S.f, M, X, S, cfg, TB.order, t_stop)
                S.it[N_RHS] += 1
            h_prop = min(S.fl[H], cfg[HMAX])
        h = h_prop
        clipped = False
        if t0 + h >= t_stop or t_stop - (t0 + h) < 1e-9 * h:
            h = t_stop - t0
            clipped = True
        t_new = t_stop if clipped else t0 + h
        # --- one Runge–Kutta trial step
        # the linear combinations run stage by stage over the whole vector (contiguous, so they
        # vectorise); each element still sums its terms in the same order as a per-element loop
        stages[0, :] = S.f
        for st in range(1, ns):
            combine(TB.a[st], stages, st, acc_row)
            for r in range(ny):
                ytmp[r] = S.y[r] + h * acc_row[r]
            rhs_stage(t0 + TB.c[st] * h, t0, ytmp, stages[st], S.mode, S.v_onset, S.smooth, M, X.kind, X.par, X.table)
        combine(TB.b, stages, ns, acc_row)
        for r in range(ny):
            ynew[r] = S.y[r] + h * acc_row[r]
        rhs_stage(t_new, t0, ynew, stages[ns], S.mode, S.v_onset, S.smooth, M, X.kind, X.par, X.table)
        S.it[N_RHS] += ns
        finite = True
        for r in range(ny):
            if not math.isfinite(ynew[r]):
                finite = False
                break
        if fixed:
            if not finite:
                return NOT_FINITE
            en = 0.0
        else:
            combine(TB.e, stages, ns + 1, acc_row)
            for r in range(ny):
                err[r] = h * acc_row[r]
                scale[r] = cfg[ATOL] + cfg[RTOL] * max(abs(S.y[r]), abs(ynew[r]))
            en = rms_norm(err, scale) if finite else np.inf
            if not (en <= 1.0):
                fac = 0.2 if not math.isfinite(en) else max(0.2, 0.9 * en ** err_exp)
                S.fl[H] = h * fac
                S.it[N_REJECTED] += 1
                if S.fl[H] < 1e-15 * max(1.0, abs(t0)) * 16:
                    return STEP_UNDERFLOW if finite else NOT_FINITE
                continue
        # --- accepted: dense-output coefficients
        for j in range(kd):
            combine(TB.p[:, j], stages, ns + 1, acc_row)
            for r in range(ny):
                q[r, j] = acc_row[r]
        # --- broad phase, then the earliest contact switch inside the step
        reach = keep_near_valid(S.y, q, h, M, S, cfg[SKIN], work, pos, cfg[STEP_CONTROL] > 0.5)
        if reach < 0.0:
            S.fl[H] = 0.5 * h
            S.it[N_REJECTED] += 1
            continue
        S.it[NEAR_SUM] += S.it[N_NEAR]
        theta_e = 1.0
        event = False
        if locate:
            theta_e, event = find_event(S.y, q, h, t0, M, S, vbuf, ytmp, work, pos)
        t_commit = t_new if not event or theta_e >= 1.0 else t0 + theta_e * h
        # --- grid output in (t0, t_commit]
        dt_out = S.fl[GRID_DT]
        if dt_out > 0.0:
            kg = S.it[GRID_K]
            last = int(math.floor((t_commit - S.fl[GRID_T0]) / dt_out + 1e-9))
            if last - kg + 1 > cap_out - S.it[N_OUT]:
                return OUT_FULL
            while kg <= last:
                tg = min(S.fl[GRID_T0] + kg * dt_out, t_commit)
                th = (tg - t0) / h
                o = S.it[N_OUT]
                dense(th, S.y, q, h, B.y[o])
                B.t[o] = tg
                ax, ay = base_accel(X.kind, X.par, X.table, tg, t0)
                B.acc[o, 0] = ax
                B.acc[o, 1] = ay
                for p in range(npair):
                    B.mode[o, p] = S.mode[p]
                    B.v_onset[o, p] = S.v_onset[p]
                    B.smooth[o, p] = S.smooth[p]
                S.it[N_OUT] = o + 1
                kg += 1
            S.it[GRID_K] = kg
        # --- peaks and classes on the committed part of the step
        sample_step(t0, h, theta_e, S.y, q, M, X, S, work, fbuf, pwbuf, fext, tens, cls)
        # --- commit
        S.y_prev[:] = S.y
        if event:
            dense(theta_e, S.y_prev, q, h, S.y)
        else:
            S.y[:] = ynew
        S.fl[T_PREV] = t0
        S.fl[H_LAST] = h
        S.fl[T] = t_commit
        S.it[N_STEPS] += 1
        steps += 1
        changed = False
        for kk in range(S.it[N_NEAR]):
            p = S.near[kk]
            if S.smooth[p] and S.smooth_until[p] == np.inf:
                new, dd = classify(p, S.y, M, S.v_onset, S.mode[p])  # impacts booked at step ends
                switch_pair(p, new, t_commit, dd, S, B, cfg)
                continue
            if S.smooth[p]:
                if t_commit >= S.smooth_until[p]:
                    c0 = cls[0, kk]
                    same = True
                    for k in range(1, N_SAMPLES + 1):
                        if cls[k, kk] != c0:
                            same = False
                    if same:
                        S.smooth[p] = False
                        new, dd = classify(p, S.y, M, S.v_onset, S.mode[p])
                        switch_pair(p, new, t_commit, dd, S, B, cfg)
                        changed = True
                continue
            if event or not locate:
                new, dd = classify(p, S.y, M, S.v_onset, S.mode[p])
                if new != S.mode[p]:
                    switch_pair(p, new, t_commit, dd, S, B, cfg)
                    changed = True
        if reach > 0.25 * cfg[SKIN]:
            # rebuild early, from where the step ended, so the list stays valid for the next steps
            centres(S.y, M, pos[0])
            rebuild_near(S, M, pos[0], cfg[SKIN])
            changed = changed or cfg[STEP_CONTROL] > 0.5  # only step control ties smooth flags to the list
        if changed or event or (bi < nbreak and t_commit >= X.breaks[bi]):
            rhs(t_commit, t_commit, S.y, S.f, S.mode, S.v_onset, S.smooth, M, X.kind, X.par, X.table)
            S.it[N_RHS] += 1
        else:
            S.f[:] = stages[ns]
        if not fixed:
            fac = 10.0 if en == 0.0 else min(10.0, max(0.2, 0.9 * en ** err_exp))
            S.fl[H] = h_prop if (clipped or event) and fac * h < h_prop else h * fac
    return DONE

