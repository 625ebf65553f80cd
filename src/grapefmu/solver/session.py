"""One compiled object per solver, so that a face's step pays for physics, not for the call.

Calling a compiled function costs numba about 0.2 µs per array it unboxes; the model, excitation,
tableau, state and scratch recorder are about forty arrays. A `Session` (a numba StructRef) holds them
all once, and `advance` takes it as a single argument. The state's arrays are views on one byte buffer
(state.zeros), so saving it before a step and restoring it after a failure are one copy each.
"""
from __future__ import annotations

import numpy as np
from numba.core import types
from numba.experimental import structref
from numba.extending import overload
from numba.typed import List

from ..model.contact import HC_MIN_APPROACH_SPEED, Law
from ..model.excitation import MAX_ACCEL, MAX_ANGULAR_ACCEL, MAX_ANGULAR_VELOCITY
from ..model.model import BERRY, COUPLING, PAIR, ModelArrays
from ..physics.compiled import jit
from ..physics.dynamics import rhs
from ..physics.excitation import applied_accel
from ..physics.layout import model_offsets, offsets
from ..physics.kinematics import kinematics, workspace
from ..physics.observe import empty, observe
from .broadphase import rebuild
from .drift import anchor, predict
from .events import classify, open_impact
from .loop import DONE, REFUSED, buffers, integrate
from .state import CHANGE, TOTALS, Recorder, recorder, zeros

__all__ = ["Session", "advance", "derivative", "grow", "island", "labels", "listed", "model", "preview", "previews",
           "put", "outputs", "recording", "refresh", "restart", "resume", "rollback", "run", "start", "take_impacts",
           "take_last", "views", "windows"]

_KELVIN_VOIGT = int(Law.KELVIN_VOIGT)


@structref.register
class SessionType(types.StructRef):
    def preprocess_fields(self, fields):
        return tuple((name, types.unliteral(t)) for name, t in fields)


class Session(structref.StructRefProxy):
    """The compiled side of a Solver: model, excitation, tableau, settings, state, scratch recorder and the
    state's byte buffer with its backup (fields as `new` names them)."""


structref.define_boxing(SessionType, Session)


def _new(model, excitation, tableau, config, state, scratch, buffers, memory, backup, now):
    raise NotImplementedError  # compiled only (the overload below)


@overload(_new)
def _new_impl(model, excitation, tableau, config, state, scratch, buffers, memory, backup, now):
    kind = SessionType([("model", model), ("excitation", excitation), ("tableau", tableau), ("config", config),
                        ("state", state), ("scratch", scratch), ("buffers", buffers), ("memory", memory),
                        ("backup", backup), ("now", now)])

    def impl(model, excitation, tableau, config, state, scratch, buffers, memory, backup, now):
        s = structref.new(kind)
        s.model, s.excitation, s.tableau, s.config = model, excitation, tableau, config
        s.state, s.scratch, s.buffers, s.memory, s.backup, s.now = state, scratch, buffers, memory, backup, now
        return s

    return impl


@jit
def start(model, excitation, tableau, config, y, t, fingerprint, zeno_max):
    """A Session over the state at time t with y, started: every pair's mode from y (a pair that starts in contact
    opens an impact at t), the first near list and the derivative; with the state's backup, a one-sample scratch
    recorder, the loop's buffers and a one-sample `now` (Observation, accel (1, 6), in_contact (1, P)): what
    `refresh` fills. One compiled call, where five unboxed the model and state again and again and boxed what
    Python never reads (docs/solver.md, "A Solver starts in one call"); `views` and `outputs` give Python the
    arrays it reads."""
    n, npair, ny = model.berry.shape[0], model.pair.shape[0], y.shape[0]
    memory, S = zeros(ny, npair, n, tableau.p.shape[0], tableau.p.shape[1], zeno_max)
    S.physical.t[0] = t
    S.physical.y[:] = y
    S.integrator.y_prev[:] = y
    S.fingerprint[0] = fingerprint
    S.book.totals[0].peak_pedicel_tension = -np.inf
    S.book.peak_tension[:] = -np.inf
    S.book.ring[:] = -np.inf
    C, W = S.physical.contacts, workspace(model)
    for p in range(npair):
        C[p].v_onset = HC_MIN_APPROACH_SPEED
        if config[0].step_control and model.pair[p].law != _KELVIN_VOIGT:
            S.book.pair[p].smooth_until = np.inf  # no force jump at onset
        mode, ddot = classify(p, y, model, C, W.berry, 0)  # pair p's own records and y alone
        C[p].mode = mode
        if mode != 0:
            open_impact(S.book.pair[p], S.book.totals[0], t, ddot)
    restart(S, model, excitation, config[0].skin)
    S.book.counters[0].near_list_rebuilds = 0
    now = (empty(1, n, model.n_dof, npair), np.zeros((1, 6)), np.zeros((1, npair), np.bool_))
    return _new(model, excitation, tableau, config, S, recorder(1, ny, npair, max(npair, 1) * 4),
                buffers(model, ny, False), memory, np.zeros_like(memory), now)


@jit
def restart(S, M, X, skin):
    """A near list and the derivative for a state whose modes are set (a start, or an island formed from others)."""
    W = workspace(M)
    kinematics(S.physical.y, M, W.berry)
    rebuild(M, S.physical.contacts, S.book, S.broad_phase, W.berry, skin)
    derivative(S, M, X)


@jit
def island(template, n, n_dof, n_couplings, n_pairs, rows):
    """A Session for an island of n berries (n_dof angles, n_couplings couplings, n_pairs pairs) of the scene whose
    Session is `template`: the scene's excitation, tableau, settings and obstacles; a model of zeros with room for
    the island's rows (handover.form fills them), a state of zeros with its backup, a recorder of `rows` samples
    and the loop's buffers, all made here (made in Python, they took 0.11 ms a system: 0.05 ms here, docs/solver.md).
    An island is never refreshed (its Run is assembled from its recorder), so it shares the template's `now`."""
    P = template.model
    M = ModelArrays(np.zeros(n, BERRY), np.zeros(n_pairs, PAIR), np.zeros(n_couplings, COUPLING), P.obstacle,
                    P.gravity, n_dof, P.moving, P.turning)
    ny = offsets(n, n_dof, n_couplings, P.moving, P.turning)[-1]
    p, ring = template.tableau.p, template.state.book.ring
    memory, state = zeros(ny, n_pairs, n, p.shape[0], p.shape[1], ring.shape[1])
    scratch = recorder(rows, ny, n_pairs, max(n_pairs, 1) * 64)
    return _new(M, template.excitation, template.tableau, template.config, state, scratch,
                buffers(M, ny, True), memory, np.zeros_like(memory), template.now)


@jit
def grow(s):
    """Twice the room in island session s's recorder (samples and contact changes), what it holds kept."""
    old = s.scratch
    cur = old.cursor[0]
    rows, n, nc = 2 * old.t.shape[0], cur.n_out, cur.n_changes
    t, y = np.empty(rows), np.empty((rows, old.y.shape[1]))
    accel, totals = np.empty((rows, 6)), np.empty(rows, TOTALS)
    changes = np.empty(2 * old.changes.shape[0], CHANGE)
    t[:n] = old.t[:n]
    y[:n] = old.y[:n]
    accel[:n] = old.accel[:n]
    totals[:n] = old.totals[:n]
    changes[:nc] = old.changes[:nc]
    s.scratch = Recorder(t, y, accel, totals, changes, old.logged, old.impacts, old.cursor)


@jit
def take_impacts(s):
    """The finished impacts in session s's recorder, copied, and the recorder's list emptied."""
    R = s.scratch
    out = R.impacts[:R.cursor[0].n_impacts].copy()
    R.cursor[0].n_impacts = 0
    return out


@jit
def rollback(s, saved):
    """Session s back to its last save: its state from the backup, its recorder's cursor from `saved` (a CURSOR
    record, windows' saved[k])."""
    s.memory[:] = s.backup
    cur = s.scratch.cursor[0]
    cur.grid_t0, cur.grid_dt, cur.grid_k, cur.n_out = saved.grid_t0, saved.grid_dt, saved.grid_k, saved.n_out
    cur.n_impacts, cur.n_changes = saved.n_impacts, saved.n_changes


@jit
def views(s):
    """(state, memory, backup) of session s as Python reads them (views, not copies)."""
    return s.state, s.memory, s.backup


@jit
def model(s):
    """Session s's model arrays (an island's: its berries' and pairs' rows, handover.form), for a failure's words."""
    return s.model


@jit
def outputs(s):
    """(scratch recorder, now) of session s: what a face reads after a step, boxed only for one (each array numba
    hands Python costs about a microsecond, and a whole run reads neither)."""
    return s.scratch, s.now


@jit
def recording(s, samples, dt_out, t_end):
    """A recorder for `samples` samples on the output grid every dt_out from the current time to t_end (sampled too,
    off the grid: loop.grid_last), holding the first:
    the state now (time, y, the rachis' acceleration acting, totals) and each pair's contact record (what the
    samples from here on hold). Solver.run's; one call where Python set the fields one by one."""
    S = s.state
    t, y, npair = S.physical.t[0], S.physical.y, S.physical.contacts.shape[0]
    R = recorder(samples, y.shape[0], npair, max(npair, 1) * 256)
    cur = R.cursor[0]
    cur.grid_t0, cur.grid_dt, cur.grid_k, cur.n_out, cur.grid_end = t, dt_out, 1, 1, t_end
    R.t[0] = t
    R.y[0] = y
    R.accel[0, 0], R.accel[0, 1], R.accel[0, 2], R.accel[0, 3], R.accel[0, 4], R.accel[0, 5] = applied_accel(
        s.excitation, S.input[0], t, t)
    R.totals[0] = S.book.totals[0]
    R.logged[:] = S.physical.contacts
    return R


@jit
def derivative(S, M, X):
    """dy/dt at the current state into the integrator's memory (after the input or the modes changed)."""
    t = S.physical.t[0]
    rhs(t, t, S.physical.y, S.integrator.f, S.physical.contacts, M, X, S.input[0], workspace(M), S.broad_phase.near,
        S.broad_phase.count[0])


@jit
def advance(s, dt, held, a, omega_set, omega, max_steps):
    """Save the state, hold the input (held, a: ACCEL_COMPONENTS), set the rachis' angular velocity to omega
    (world, rad/s) if omega_set, integrate dt. Returns (status, t_target, finished impacts in the scratch
    recorder); the caller restores the state (memory <- backup) if the status is a failure. REFUSED, with the
    state untouched, for an input out of its bounds (model/excitation.py) or a turn of a rachis that does not
    turn, or a dt that would not move t: the caller says which (one check here, in the call a face makes every
    step, instead of in Python)."""
    for k in range(6):
        bound = MAX_ACCEL if k < 3 else MAX_ANGULAR_ACCEL
        if not (-bound <= a[k] <= bound):
            return REFUSED, 0.0, 0
    if omega_set:
        for k in range(3):
            if not (-MAX_ANGULAR_VELOCITY <= omega[k] <= MAX_ANGULAR_VELOCITY):
                return REFUSED, 0.0, 0
    if not s.model.turning and (a[3] != 0.0 or a[4] != 0.0 or a[5] != 0.0 or (omega_set and (
            omega[0] != 0.0 or omega[1] != 0.0 or omega[2] != 0.0))):
        return REFUSED, 0.0, 0
    if not s.model.moving and (a[0] != 0.0 or a[1] != 0.0 or a[2] != 0.0):
        return REFUSED, 0.0, 0
    if s.state.physical.t[0] + dt == s.state.physical.t[0]:  # a dt below t's resolution would not move it
        return REFUSED, 0.0, 0
    s.backup[:] = s.memory
    S = s.state
    inp = S.input[0]
    changed = False
    if (inp.held != held or inp.ax != a[0] or inp.ay != a[1] or inp.az != a[2] or inp.alpha_x != a[3]
            or inp.alpha_y != a[4] or inp.alpha_z != a[5]):
        inp.held, inp.ax, inp.ay, inp.az, inp.alpha_x, inp.alpha_y, inp.alpha_z = held, a[0], a[1], a[2], a[3], a[4], a[5]
        changed = True
    if omega_set and s.model.turning:  # Solver.advance refuses a non-zero ω for a rachis that does not turn
        y = S.physical.y
        o = model_offsets(s.model)[2]
        for k in range(3):
            if y[o + k] != omega[k]:
                y[o + k] = omega[k]
                changed = True
    if changed:
        derivative(S, s.model, s.excitation)
    t_target = S.physical.t[0] + dt
    status = integrate(s.model, s.excitation, s.tableau, S, s.config, s.scratch, s.buffers, t_target, max_steps)
    return status, t_target, s.scratch.cursor[0].n_impacts


@jit
def refresh(s):
    """What the current state shows into s.now: the observation, the rachis acceleration acting now and which
    pairs are in contact (one compiled call per step for a face, whatever it reads)."""
    S = s.state
    observation, accel, in_contact = s.now
    t = S.physical.t[0]
    accel[0, 0], accel[0, 1], accel[0, 2], accel[0, 3], accel[0, 4], accel[0, 5] = applied_accel(
        s.excitation, S.input[0], t, t)
    C = S.physical.contacts
    for p in range(C.shape[0]):
        in_contact[0, p] = C[p].mode != 0
    observe(S.physical.y.reshape((1, S.physical.y.shape[0])), C.reshape((1, C.shape[0])), accel, s.model, observation)


@jit
def run(s, R, t_target, max_steps):
    """Integrate towards t_target, recording into R (Solver.run's recorder, sized for the run, not the session's
    scratch). Returns integrate's status."""
    return integrate(s.model, s.excitation, s.tableau, s.state, s.config, R, s.buffers, t_target, max_steps)


@jit
def resume(s, t_target, max_steps):
    """Go on towards t_target (after the caller emptied a full impact list; or one step of Solver.step, with
    max_steps = 1). Returns what advance returns."""
    status = integrate(s.model, s.excitation, s.tableau, s.state, s.config, s.scratch, s.buffers, t_target,
                       max_steps)
    return status, t_target, s.scratch.cursor[0].n_impacts


@jit
def windows(sessions, first, t_target, max_steps, base, fresh, saved, status, n_impacts, drifted, engaged):
    """Islands' windows (solver/islands.py) in one call, from island `first` on. Each island, if fresh[k], saves its
    state (memory -> backup) and its recorder's cursor (into saved[k]) and anchors its path (drift.anchor); it
    integrates towards t_target, its berries' steps since the run's start (base[k], taken before it formed, and its
    own) held to max_steps, then puts its berries' drift into drifted and whether its pairs are engaged (in
    contact or in a Zeno window) into engaged (scene indices, through its buffers' members and pairs). status[k] is
    integrate's status, n_impacts[k] the finished impacts in its recorder; stops at the first island whose status is
    not DONE and returns its index (len(sessions) when all are done)."""
    for k in range(first, len(sessions)):
        s = sessions[k]
        S = s.state
        if fresh[k]:
            cur, sv = s.scratch.cursor[0], saved[k]
            sv.grid_t0, sv.grid_dt, sv.grid_k, sv.n_out = cur.grid_t0, cur.grid_dt, cur.grid_k, cur.n_out
            sv.n_impacts, sv.n_changes = cur.n_impacts, cur.n_changes
            s.backup[:] = s.memory
            anchor(S.physical.y, S.integrator.f, S.physical.t[0], s.model, s.buffers.path, s.buffers.drifted)
        left = max_steps - base[k] - S.book.counters[0].steps
        st = integrate(s.model, s.excitation, s.tableau, S, s.config, s.scratch, s.buffers, t_target, left)
        status[k] = st
        n_impacts[k] = s.scratch.cursor[0].n_impacts
        if st != DONE:
            return k
        Z = s.buffers
        for m in range(Z.members.shape[0]):
            drifted[Z.members[m]] = Z.drifted[m]
        C = S.physical.contacts
        for p in range(Z.pairs.shape[0]):
            engaged[Z.pairs[p]] = C[p].mode != 0 or C[p].smooth
    return len(sessions)


@jit
def preview(s, span, rows, lin, reach):
    """Session s's berries on the path a window of length span starts on (drift.predict), into the scene's lin
    ((K, N, 3)) and reach ((N, 2)) at rows (their scene indices)."""
    S, Z = s.state, s.buffers
    predict(S.physical.y, S.integrator.f, s.model, span, Z.work, Z.W.berry, lin, reach, rows)


@jit
def previews(sessions, span, lin, reach):
    """`preview` of every island, at its berries' rows."""
    for k in range(len(sessions)):
        s = sessions[k]
        preview(s, span, s.buffers.members, lin, reach)


@jit
def labels(sessions, label):
    """label[i] = the index of the island berry i is in."""
    for k in range(len(sessions)):
        members = sessions[k].buffers.members
        for m in range(members.shape[0]):
            label[members[m]] = k


@jit
def listed(s):
    """A numba list holding session s, for `windows` and `previews`. The islands' list is built and changed by
    compiled functions (listed, put, take_last) and never from Python: numba compiles a typed list's methods called
    from Python anew in every process (1.5 to 3 s on a process's first islands run), but caches these."""
    out = List()
    out.append(s)
    return out


@jit
def put(sessions, k, s):
    """sessions[k] = s, or s appended where k is the list's length."""
    if k == len(sessions):
        sessions.append(s)
    else:
        sessions[k] = s


@jit
def take_last(sessions, k):
    """The last session into slot k, and the list one shorter."""
    last = len(sessions) - 1
    if k != last:
        sessions[k] = sessions[last]
    sessions.pop()
