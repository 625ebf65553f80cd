"""The compiled event-driven integration loop (docs/solver.md): step, broad phase, events, recording,
sampling and commit, in that order, one accepted step at a time.

A step is truncated at the earliest contact switch (located to ~1e-13 s) and restarted just past the
switching surface in the mode the state is now in; no step straddles an excitation breakpoint.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..model.excitation import TIME_RESOLUTION
from ..physics.compiled import inline, jit
from ..physics.dynamics import rhs
from ..physics.excitation import applied_accel
from ..physics.kinematics import Workspace, kinematics, workspace
from .broadphase import keep_valid, quiet, rebuild, samples_for
from .drift import drift
from .events import N_SAMPLES, classify, find_event, switch_pair
from .sampling import sample_step
from .step import dense, dense_coefficients, dense_rows, error_norm, initial_step, rk_step

#: output samples record_grid evaluates at a time (its scratch's length: Buffers.grid_theta, .grid_sum)
GRID_CHUNK = 64
# statuses
DONE, OUT_FULL, IMPACTS_FULL, MAX_STEPS, STEP_UNDERFLOW, NOT_FINITE, REFUSED, AT_POLE = range(8)  # REFUSED: advance's
#: A spherical berry's swing–tilt chart is singular at cos s = 0 (docs/model.md §1). One carried towards the pole
#: crawls there in steps ∝ |cos s| (a 300-berry cluster shaken at 4.1 Hz: 256 steps from |cos s| = 1.3e-4 to 1e-4,
#: 16 000 to 6.6e-6, 800 000 and 200 s to 1.4e-7, where the step floor stopped it); one that swings past it goes
#: nearer (3e-7 in tests/test_hard_cases.py) but within 60 steps. So the run stops (AT_POLE) where a berry is within
#: |cos s| < POLE_STOP at POLE_CHECKS looks in a row, one every POLE_EVERY accepted steps of a call.
POLE_STOP = 1e-4
POLE_EVERY = 64
POLE_CHECKS = 16


class Buffers(NamedTuple):
    """What the loop works in, allocated once per solver rather than on every call (a face calls it every
    millisecond): the stages' temporaries, the step's samples and the evaluation stages' workspace, each written
    before it is read within one step; and an island's path, drift and scene indices, which hold for its window
    (drift.anchor) or its life (handover.form)."""

    tmp: np.ndarray      # (ny,) each
    acc: np.ndarray
    ynew: np.ndarray
    err: np.ndarray
    scale: np.ndarray
    work: np.ndarray
    fbuf: np.ndarray     # (N_SAMPLES + 1, P) force of each near pair at each sample
    pwbuf: np.ndarray    # (N_SAMPLES + 1, P) its dissipation power
    cls: np.ndarray      # (N_SAMPLES + 1, P) its mode class (smooth pairs)
    tension: np.ndarray  # (N_SAMPLES + 1, N) each berry's pedicel tension at each sample
    pushing: np.ndarray  # (P,) the near pairs in contact (sampling.refine_tensions)
    values: np.ndarray   # (N_SAMPLES + 1, 2P) each near pair's event functions
    rates: np.ndarray    # (N_SAMPLES + 1, 2P) their slopes (δ's; per sample spacing)
    W: Workspace
    samples: np.ndarray  # (N_SAMPLES + 1, N) KINEMATICS: the berries at the step's samples
    travel: np.ndarray   # (N, 2) how far each berry can get in the step, rachis and world frame (broadphase.quiet)
    suspect: np.ndarray  # (P,) whether the k-th near pair can switch in the step (broadphase.quiet)
    reach: np.ndarray    # (N, 3) each berry's travel, |u̇| and |F| bounds on the step (sampling.tensions_bounded)
    path: np.ndarray     # (D + 1, 3) or (0, 3): an island's window's extrapolated angles (drift.anchor)
    drifted: np.ndarray  # (N,) or (0,): how far each berry got from them (drift.drift)
    members: np.ndarray  # (N,) or (0,): an island's berries in the scene (handover.form)
    pairs: np.ndarray    # (P,) or (0,): its pairs in the scene
    rows: np.ndarray     # (ny,) or (0,): the scene's component of each of its own (handover.scene_rows)
    grid_theta: np.ndarray  # (GRID_CHUNK,) θ of the output samples record_grid evaluates at once
    grid_sum: np.ndarray    # (GRID_CHUNK,) their Horner sums (step.dense_rows)


@jit
def buffers(M, ny, island):
    p = max(M.pair.shape[0], 1)
    return Buffers(np.empty(ny), np.empty(ny), np.empty(ny), np.empty(ny), np.empty(ny), np.empty(ny),
                   np.zeros((N_SAMPLES + 1, p)), np.zeros((N_SAMPLES + 1, p)),
                   np.zeros((N_SAMPLES + 1, p), dtype=np.int64), np.zeros((N_SAMPLES + 1, M.berry.shape[0])),
                   np.zeros(p, dtype=np.int64), np.zeros((N_SAMPLES + 1, 2 * p)),
                   np.zeros((N_SAMPLES + 1, 2 * p)), workspace(M),
                   samples_for(M), np.zeros((M.berry.shape[0], 2)), np.ones(p, dtype=np.bool_),
                   np.zeros((M.berry.shape[0], 3)),
                   np.zeros((M.n_dof + 1 if island else 0, 3)), np.zeros(M.berry.shape[0] if island else 0),
                   np.zeros(M.berry.shape[0] if island else 0, np.int64),
                   np.zeros(M.pair.shape[0] if island else 0, np.int64), np.zeros(ny if island else 0, np.int64),
                   np.zeros(GRID_CHUNK), np.zeros(GRID_CHUNK))


@inline
def differs(c, d):
    """Whether two CONTACT records differ."""
    return c.mode != d.mode or c.v_onset != d.v_onset or c.smooth != d.smooth


@jit
def grid_last(t0, t, dt, at_end):
    """The index of the last sample at or before t on the output grid t0 + k dt; at the run's end (at_end) past its
    last grid point, one more: the end's own sample (record_grid clamps its time to the end). Why: a run to
    0.0995 s sampled every 0.01 s ended its samples at 0.09 s, and its summary read its end and its energy there.
    An end within 1e-9 dt past a grid point is sampled at that point (no sample a rounding apart), but not when that
    point is the start, t0: a run shorter than 1e-9 dt (to 1e-300 s) would have only its start's sample."""
    k = int(math.floor((t - t0) / dt + 1e-9))
    if at_end and (t0 + k * dt < t - 1e-9 * dt or (k == 0 and t > t0)):
        k += 1
    return k


@jit
def record_grid(t0, t_commit, h, y0, q, X, inp, contacts, totals, R, theta, acc):
    """Samples on the output grid in (t0, t_commit], and each pair whose contact record the samples hold differs
    from the one logged before (results/contacts.py), at the first new sample's index on the grid (grid_k: the run's
    sample, whatever the recorder handed over before); GRID_CHUNK samples at a time (theta, acc: scratch,
    step.dense_rows). Returns False when the recorder is full."""
    cur = R.cursor[0]
    dt_out = cur.grid_dt
    kg = cur.grid_k
    last = grid_last(cur.grid_t0, t_commit, dt_out, t_commit >= cur.grid_end)
    if last < kg:
        return True
    if last - kg + 1 > R.t.shape[0] - cur.n_out:
        return False
    logged = R.logged
    new = 0
    for p in range(contacts.shape[0]):
        if differs(contacts[p], logged[p]):
            new += 1
    if new > R.changes.shape[0] - cur.n_changes:
        return False
    o = cur.n_out
    if new > 0:
        n = cur.n_changes
        for p in range(contacts.shape[0]):
            c, d = contacts[p], logged[p]
            if differs(c, d):
                row = R.changes[n]
                row.sample, row.pair, row.mode, row.v_onset, row.smooth = kg, p, c.mode, c.v_onset, c.smooth
                d.mode, d.v_onset, d.smooth = c.mode, c.v_onset, c.smooth
                n += 1
        cur.n_changes = n
    ts, accels, tots = R.t, R.accel, R.totals
    while kg <= last:
        n = min(last - kg + 1, GRID_CHUNK)
        for k in range(n):
            tg = min(cur.grid_t0 + (kg + k) * dt_out, t_commit)
            theta[k] = (tg - t0) / h
            ts[o + k] = tg
            accels[o + k, 0], accels[o + k, 1], accels[o + k, 2], accels[o + k, 3], accels[o + k, 4], \
                accels[o + k, 5] = applied_accel(X, inp, tg, t0)
            tots[o + k] = totals[0]
        dense_rows(theta, n, y0, q, h, acc, R.y, o)
        o += n
        kg += n
    cur.n_out = o
    cur.grid_k = kg
    return True


@jit
def integrate(M, X, TB, S, config, R, Z, t_target, max_steps):
    """Advance S to t_target (or until the recorder fills or max_steps), working in Z (Buffers). Returns a
    status code."""
    cfg = config[0]
    P = S.physical
    C = P.contacts
    I = S.integrator
    clk = I.clock[0]
    Bk = S.book
    cnt = Bk.counters[0]
    B = S.broad_phase
    inp = S.input[0]
    npair = C.shape[0]
    ny = P.y.shape[0]
    ns = TB.b.shape[0]
    err_exp = -(1.0 / (TB.error_order + 1.0) - 0.75 * TB.beta)  # Hairer's exponent with his PI gain β
    fixed = cfg.fixed_step > 0.0
    W, samples = Z.W, Z.samples
    tmp, acc, ynew, err, scale, work = Z.tmp, Z.acc, Z.ynew, Z.err, Z.scale, Z.work
    fbuf, pwbuf, cls, values = Z.fbuf, Z.pwbuf, Z.cls, Z.values
    nbreak = 0 if inp.held else X.breaks.shape[0]  # a held input has no breakpoints
    steps = 0
    start_known = False  # whether samples[0] holds the berries at P.y (a whole step's end: the step's FSAL stage)
    start_sampled = False  # whether sample_step booked P.y as the last step's end, in the modes and near list now
    at_pole_for = 0  # looks in a row that found a berry at its pole (POLE_CHECKS)
    while P.t[0] < t_target:
        if steps >= max_steps:
            return MAX_STEPS
        if R.cursor[0].n_impacts + npair > R.impacts.shape[0]:
            return IMPACTS_FULL
        t0 = P.t[0]
        bi = clk.break_index
        while bi < nbreak and X.breaks[bi] <= t0:
            bi += 1
        clk.break_index = bi
        t_stop = t_target
        if bi < nbreak and X.breaks[bi] < t_stop:
            t_stop = X.breaks[bi]
        args = (C, M, X, inp, W, B.near, B.count[0])
        if fixed:
            h_prop = cfg.fixed_step
        else:
            if clk.h <= 0.0:
                clk.h = initial_step(t0, P.y, I.f, args, cfg, TB.order, t_stop)
                cnt.rhs_evaluations += 1
            h_prop = min(clk.h, cfg.h_max)
        h = h_prop
        clipped = False
        if t0 + h >= t_stop or t_stop - (t0 + h) < 1e-9 * h:
            h = t_stop - t0
            clipped = True
        t_new = t_stop if clipped else t0 + h
        # --- one Runge–Kutta trial step
        rk_step(t0, h, t_new, P.y, I.f, args, TB, I.stages, ynew, tmp, acc)
        cnt.rhs_evaluations += ns
        if fixed:
            en = 0.0
            for r in range(ny):
                if not math.isfinite(ynew[r]):
                    return NOT_FINITE
        else:
            en = error_norm(h, P.y, ynew, TB, I.stages, cfg, err, scale, acc)
            if not (en <= 1.0):
                fac = 0.2 if not math.isfinite(en) else max(0.2, 0.9 * en ** err_exp)
                clk.h = h * fac
                cnt.rejected += 1
                if not clk.h >= TIME_RESOLUTION * max(1.0, abs(t0)):  # NaN too: rejections are not counted as steps
                    return STEP_UNDERFLOW if math.isfinite(en) else NOT_FINITE
                continue
        # the berries at the step's end are the FSAL stage's: kept before DOP853's extra stages overwrite them
        copy_kinematics(W.berry, samples[N_SAMPLES])
        dense_coefficients(t0, h, P.y, args, TB, I.stages, I.dense, tmp, acc)
        cnt.rhs_evaluations += TB.c_extra.shape[0]
        q = I.dense
        if not start_known:
            kinematics(P.y, M, samples[0])
            start_known = True
        # --- broad phase, then the earliest contact switch inside the step: none to look for on a quiet step
        far = quiet(P.y, q, h, M, C, B, cfg, samples[0], Z.travel, Z.suspect) if npair > 0 else 0.0
        sampled = far < 0.0
        if sampled:
            far = keep_valid(P.y, q, h, M, C, Bk, B, cfg, work, samples)
            if far < 0.0:
                clk.h = 0.5 * h
                cnt.rejected += 1
                continue
            if far == np.inf:  # the list was rebuilt: quiet() screened another one
                Z.suspect[:] = True
                start_sampled = False
        else:
            cnt.quiet_steps += 1
        cnt.near_pairs_sum += B.count[0]
        theta_e = 1.0
        event = False
        if sampled and cfg.locate and B.count[0] > 0:
            theta_e, event = find_event(P.y, q, h, t0, M, C, B.near, B.count[0], Z.suspect, W.berry, samples,
                                        values, Z.rates, work)
        t_commit = t_new if not event or theta_e >= 1.0 else t0 + theta_e * h
        if R.cursor[0].grid_dt > 0.0 and not record_grid(t0, t_commit, h, P.y, q, X, inp, C, Bk.totals, R,
                                                      Z.grid_theta, Z.grid_sum):
            return OUT_FULL
        ended = sample_step(t0, h, theta_e, P.y, q, M, X, inp, C, B.near, B.count[0], Bk.totals, Bk.pair,
                            Bk.peak_tension, cfg, W, work, fbuf, pwbuf, cls, Z.tension, Z.pushing, samples, sampled,
                            start_sampled, Z.reach)
        if not ended:
            cnt.spared_steps += 1
        # --- commit
        I.y_prev[:] = P.y
        if event:
            dense(theta_e, I.y_prev, q, h, P.y)
        else:
            P.y[:] = ynew
            copy_kinematics(samples[N_SAMPLES], samples[0])
        start_known = not event
        clk.t_prev = t0
        clk.h_last = h
        P.t[0] = t_commit
        if Z.drifted.shape[0] > 0:
            drift(I.y_prev, q, h, t0, M, Z.path, Z.drifted)
        cnt.steps += 1
        steps += 1
        if steps % POLE_EVERY == 0:
            at_pole_for = at_pole_for + 1 if at_pole(P.y, M) else 0
            if at_pole_for >= POLE_CHECKS:
                return AT_POLE
        opened = Bk.totals[0].collision_count
        changed = B.count[0] > 0 and switch_modes(t_commit, event, P.y, M, C, Bk, B, cfg, R.impacts, R.cursor,
                                                  W.berry, cls, Z.suspect)
        # a whole step's end was sampled (sample_step); the next step's start is it while nothing switched, the list
        # was not rebuilt and no breakpoint moved the acceleration (step control switches smooth pairs silently)
        start_sampled = ended and not event and not cfg.step_control
        if far > 0.25 * cfg.skin:
            # rebuild early, from where the step ended, so the list stays valid for the next steps
            kinematics(P.y, M, W.berry)
            rebuild(M, C, Bk, B, W.berry, cfg.skin)
            changed = changed or cfg.step_control  # only step control ties smooth flags to the list
            start_sampled = False
        if changed or event or (bi < nbreak and t_commit >= X.breaks[bi]):
            rhs(t_commit, t_commit, P.y, I.f, C, M, X, inp, W, B.near, B.count[0])
            cnt.rhs_evaluations += 1
            if not start_known:  # after an event: the berries at the next step's start are this evaluation's
                copy_kinematics(W.berry, samples[0])
                start_known = True
            start_sampled = False
        else:
            I.f[:] = I.stages[ns]
        if not fixed:
            # PI control (docs/solver.md, "Step-size control"): the last accepted step's error damps the growth
            if en == 0.0:
                fac = 10.0
            elif TB.beta > 0.0:
                fac = min(10.0, max(0.2, 0.9 * en ** err_exp * max(clk.err_last, 1e-4) ** TB.beta))
            else:  # plain I control (DOP853, ode23): the same factor without the power of 1
                fac = min(10.0, max(0.2, 0.9 * en ** err_exp))
            clk.err_last = en
            clk.h = h_prop if (clipped or event) and fac * h < h_prop else h * fac
            # An accepted step is held to the floor a rejected one is: a next step the error control shrinks (or keeps)
            # below the resolution of time ends the run now. Without this the steps crept down unchecked while they
            # passed, 1e-19 s after minutes at the step limit: a spherical berry carried into its chart's pole (solver
            # POLE), or a step of 0 s from a breakpoint 1e-300 s ahead (initial_step's probe overflows), which never
            # moved. A step clipped to a breakpoint or an event is the table's or the contact's size, not the
            # control's, and a step growing from a short one (a breakpoint close to the start) is let grow.
            if not (clipped or event) and clk.h <= h and clk.h < TIME_RESOLUTION * max(1.0, abs(t0)):
                return STEP_UNDERFLOW
            # A contact that opens stiffens the system at once, and the step size from before it was often rejected:
            # the next onset starts no longer than the last contact's first step proposed (docs/solver.md).
            if clk.after_onset:
                clk.h_contact = clk.h
                clk.after_onset = False
            if Bk.totals[0].collision_count > opened:
                if clk.h_contact > 0.0:
                    clk.h = min(clk.h, clk.h_contact)
                clk.after_onset = True
    return DONE


@inline
def at_pole(y, M):
    """Whether a spherical berry's swing s (y at its first angle) is within POLE_STOP of its chart's pole."""
    for i in range(M.berry.shape[0]):
        if M.berry[i].n_angles == 2 and abs(math.cos(y[M.berry[i].dof])) < POLE_STOP:
            return True
    return False


@inline
def copy_kinematics(source, target):
    """target[:] = source, record by record ((N,) KINEMATICS)."""
    for i in range(source.shape[0]):
        target[i] = source[i]


@jit
def switch_modes(t_commit, event, y, M, contacts, Bk, B, cfg, impacts, cursor, kin, cls, suspect):
    """After a commit: each near pair takes the mode its state is in (at a located event, for every
    pair without location, at the end of a Zeno window, or at every step for a smooth law under step
    control). Returns whether any mode changed. A pair the broad phase ruled out for the step (suspect) stayed
    apart: at an event it is not classified again."""
    changed = False
    for kk in range(B.count[0]):
        p = B.near[kk]
        c = contacts[p]
        until = Bk.pair[p].smooth_until
        if c.smooth and until == np.inf:
            new, dd = classify(p, y, M, contacts, kin, c.mode)  # impacts booked at step ends
            switch_pair(p, new, t_commit, dd, M, contacts, Bk, cfg, impacts, cursor)
            continue
        if c.smooth:
            if t_commit >= until:
                same = True
                for k in range(1, N_SAMPLES + 1):
                    if cls[k, kk] != cls[0, kk]:
                        same = False
                if same:
                    c.smooth = False
                    new, dd = classify(p, y, M, contacts, kin, c.mode)
                    switch_pair(p, new, t_commit, dd, M, contacts, Bk, cfg, impacts, cursor)
                    changed = True
            continue
        if (event and suspect[kk]) or not cfg.locate:
            new, dd = classify(p, y, M, contacts, kin, c.mode)
            if new != c.mode:
                switch_pair(p, new, t_commit, dd, M, contacts, Bk, cfg, impacts, cursor)
                changed = True
    return changed
