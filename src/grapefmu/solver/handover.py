"""An island's state from the scene's and back (solver/islands.py): what its berries and pairs carry when islands
form and part, copied in compiled code (numpy copies record arrays field by field, which cost more than the
window's steps).

The scene's side `G` is (y, contacts, book_pair, ring, peak_tension, h, h_contact): y in the scene's layout, the
pairs' CONTACT, BOOK_PAIR and Zeno-ring rows, each berry's peak tension, and the step size and onset step size its
last island proposed. An island's berries, angles, pairs and couplings are scene indices (members, dofs, pairs,
couplings, each ascending).
"""
from __future__ import annotations

import numpy as np
from numba import literal_unroll

from ..physics.compiled import inline, jit
from ..physics.layout import model_offsets
from ..results.records import COUNTERS, COUNTS, PEAKS
from .session import restart
from .state import CHANGE

#: the work counters' names, for literal_unroll
COUNTED = tuple(COUNTERS.names)


@jit
def parts(label, which, pair_i, pair_j, coupled, dof):
    """The islands to form: island k of the berries whose label is which[k]. Returns their berries, angles, pairs
    and couplings (scene indices, each island's ascending), each concatenated over the islands with its offsets
    (island k's berries are members[m_off[k]:m_off[k + 1]], ...). A pair belongs to the island of both its
    berries, or of its berry where the other body is an obstacle (obstacles belong to every island). One call
    for a window's islands: a call unboxes its arrays again, which cost more than finding one island's parts."""
    n, K = label.shape[0], which.shape[0]
    slot = np.full(max(label.max(), which.max()) + 1, -1, np.int64)
    slot[which] = np.arange(K)
    island = slot[label]  # each berry's island among those formed, or -1
    pair_island = np.full(pair_i.shape[0], -1, np.int64)
    for p in range(pair_i.shape[0]):
        k = island[pair_i[p]]
        if k >= 0 and (pair_j[p] >= n or island[pair_j[p]] == k):
            pair_island[p] = k
    coupling_island = np.full(coupled.shape[0], -1, np.int64)
    for c in range(coupled.shape[0]):
        k = island[coupled[c, 0]]
        if k >= 0 and island[coupled[c, 1]] == k:
            coupling_island[c] = k
    members, m_off = _grouped(island, K)
    pairs, p_off = _grouped(pair_island, K)
    couplings, c_off = _grouped(coupling_island, K)
    d_off = np.zeros(K + 1, np.int64)
    for k in range(K):
        d_off[k + 1] = d_off[k]
        for m in members[m_off[k]:m_off[k + 1]]:
            d_off[k + 1] += dof[m + 1] - dof[m]
    dofs = np.empty(d_off[K], np.int64)
    r = 0
    for m in members:
        for a in range(dof[m], dof[m + 1]):
            dofs[r] = a
            r += 1
    return members, m_off, dofs, d_off, pairs, p_off, couplings, c_off


@inline
def _grouped(owner, K):
    """The items each of K groups owns (owner[i]: item i's group, or -1), ascending within each group and concatenated,
    and the groups' offsets in that."""
    off = np.zeros(K + 1, np.int64)
    for g in owner:
        if g >= 0:
            off[g + 1] += 1
    for k in range(K):
        off[k + 1] += off[k]
    out, at = np.empty(off[K], np.int64), off[:K].copy()
    for i in range(owner.shape[0]):
        if owner[i] >= 0:
            out[at[owner[i]]] = i
            at[owner[i]] += 1
    return out, off


@jit
def form_all(sessions, slots, P, G, parted, local, scene_offsets, t, grid_t0, grid_dt, k0, grid_end):
    """`form` of island k of `parted` (what `parts` returned) in sessions[slots[k]], for every k."""
    members, m_off, dofs, d_off, pairs, p_off, couplings, c_off = parted
    for k in range(slots.shape[0]):
        form(sessions[slots[k]], P, G, members[m_off[k]:m_off[k + 1]], dofs[d_off[k]:d_off[k + 1]],
             pairs[p_off[k]:p_off[k + 1]], couplings[c_off[k]:c_off[k + 1]], local, scene_offsets, t, grid_t0,
             grid_dt, k0, grid_end)


@jit
def form(s, P, G, members, dofs, pairs, couplings, local, scene_offsets, t, grid_t0, grid_dt, k0, grid_end):
    """Island session s over these berries, pairs and couplings of the scene's model P (local: scratch, scene body
    -> island's, berries first, then the obstacles) at time t, from the scene's G: nothing booked yet (totals,
    counters, the energy the contacts dissipated and the base did: the island's own from now on), its near list and
    derivative made, its recorder empty and its first sample k0 of the output grid (grid_t0, grid_dt, to the run's
    end grid_end)."""
    M, S = s.model, s.state
    n = P.berry.shape[0]
    dof = 0
    for m in range(members.shape[0]):
        M.berry[m] = P.berry[members[m]]
        M.berry[m].dof = dof
        dof += M.berry[m].n_angles
        local[members[m]] = m
    for o in range(n, local.shape[0]):
        local[o] = members.shape[0] + o - n
    for p in range(pairs.shape[0]):
        M.pair[p] = P.pair[pairs[p]]
        M.pair[p].i, M.pair[p].j = local[M.pair[p].i], local[M.pair[p].j]
    for c in range(couplings.shape[0]):
        M.coupling[c] = P.coupling[couplings[c]]
        M.coupling[c].i, M.coupling[c].j = local[M.coupling[c].i], local[M.coupling[c].j]
    y, contacts, book_pair, ring, peak_tension, h, h_contact = G
    o_contact, o_work = model_offsets(M)[6:8]
    rows = s.buffers.rows
    scene_rows(M, members, dofs, couplings, scene_offsets, rows)
    Y = S.physical.y
    for r in range(o_contact):
        Y[r] = y[rows[r]]
    for m in range(members.shape[0]):
        S.book.peak_tension[m] = peak_tension[members[m]]
    Y[o_contact] = 0.0
    Y[o_work] = 0.0
    for p in range(pairs.shape[0]):
        S.physical.contacts[p] = contacts[pairs[p]]
        S.book.pair[p] = book_pair[pairs[p]]
        S.book.ring[p, :] = ring[pairs[p], :]
    S.physical.t[0] = t
    tot = S.book.totals[0]
    tot.collision_count, tot.bruising_impacts, tot.berries_over_detachment_force = 0, 0, 0
    tot.peak_contact_force, tot.peak_pedicel_tension = 0.0, -np.inf
    cnt = S.book.counters[0]
    for f in literal_unroll(COUNTED):
        cnt[f] = 0
    inp = S.input[0]
    inp.held = False
    clk = S.integrator.clock[0]
    hmin, hc = np.inf, np.inf
    for m in range(members.shape[0]):
        hmin = min(hmin, h[members[m]])
        if h_contact[members[m]] > 0.0:
            hc = min(hc, h_contact[members[m]])
    clk.h = hmin
    clk.h_contact = hc if hc < np.inf else 0.0
    clk.after_onset = False
    clk.break_index = 0
    clk.t_prev = t
    clk.h_last = 0.0
    clk.err_last = 0.0  # the island's step-size control starts afresh
    restart(S, M, s.excitation, s.config[0].skin)
    R = s.scratch
    cur = R.cursor[0]
    cur.grid_t0, cur.grid_dt, cur.grid_k, cur.grid_end = grid_t0, grid_dt, k0, grid_end
    cur.n_out, cur.n_impacts, cur.n_changes = 0, 0, 0
    s.buffers.members[:] = members
    s.buffers.pairs[:] = pairs
    for p in range(pairs.shape[0]):
        R.logged[p] = S.physical.contacts[p]


@inline
def scene_rows(M, members, dofs, couplings, scene_offsets, rows):
    """rows[r]: the scene's component of island component r, for every component before the energy ledger (angles,
    rates, the rachis motion, the hinges' and couplings' dissipation). The one map between the two layouts: form,
    scatter and flush copy through it."""
    s_bv, s_dh, s_dc, d, _, _ = scene_offsets
    o_bv, _, _, _, o_dh, o_dc, _, _, _ = model_offsets(M)
    nd = M.n_dof
    for r in range(dofs.shape[0]):
        rows[r] = dofs[r]
        rows[nd + r] = d + dofs[r]
    for k in range(o_dh - o_bv):
        rows[o_bv + k] = s_bv + k
    for m in range(members.shape[0]):
        rows[o_dh + m] = s_dh + members[m]
    for c in range(couplings.shape[0]):
        rows[o_dc + c] = s_dc + couplings[c]


@jit
def scatter(s, G):
    """What island session s's state carries back into the scene's G (not its own totals: the caller keeps those)."""
    S, M, Z = s.state, s.model, s.buffers
    y, contacts, book_pair, ring, peak_tension, h, h_contact = G
    rows, members, pairs = Z.rows, Z.members, Z.pairs
    Y = S.physical.y
    for r in range(model_offsets(M)[6]):
        y[rows[r]] = Y[r]
    clk = S.integrator.clock[0]
    for m in range(members.shape[0]):
        peak_tension[members[m]] = S.book.peak_tension[m]
        h[members[m]] = clk.h
        h_contact[members[m]] = clk.h_contact
    for p in range(pairs.shape[0]):
        contacts[pairs[p]] = S.physical.contacts[p]
        book_pair[pairs[p]] = S.book.pair[p]
        ring[pairs[p], :] = S.book.ring[p, :]


@jit
def flush(s, scene_offsets, y, accel, totals):
    """The samples island session s recorded since its last flush into the run's arrays at their rows of the output
    grid: y (the scene's layout; the energy ledger's terms added, each island's own), accel, and totals, to which it
    adds its counts and where it raises the peaks. Its recorder is empty again, its grid position kept.
    Why at every window's start (flush_all) and not only when the island retires: its recorder then holds one window,
    so an islands run's memory grows with the run's own arrays alone (a recorder with room for the rest of the run
    took 2.4 times as much over 4 s at N = 300; docs/solver.md, "Multirate islands"). A window is flushed once it is
    final: a rollback (session.rollback) returns to its start, where the recorder was empty."""
    M, R, rows = s.model, s.scratch, s.buffers.rows
    s_contact, s_work = scene_offsets[4:6]
    o_contact, o_work = model_offsets(M)[6:8]
    cur = R.cursor[0]
    r = cur.n_out
    k0 = cur.grid_k - r  # the run's sample of the recorder's first row
    Ry, Ra, Rt = R.y, R.accel, R.totals
    for k in range(r):  # element by element: a row view or slice costs reference counts per sample
        row = k0 + k
        for a in range(o_contact):
            y[row, rows[a]] = Ry[k, a]
        y[row, s_contact] += Ry[k, o_contact]
        y[row, s_work] += Ry[k, o_work]
        for c in range(6):
            accel[row, c] = Ra[k, c]
        _add(totals[row], Rt[k])
    cur.n_out = 0


@jit
def flush_all(sessions, scene_offsets, y, accel, totals):
    """`flush` of every island in the list (a window's start)."""
    for k in range(len(sessions)):
        flush(sessions[k], scene_offsets, y, accel, totals)


@jit
def retire(s, G, scene_offsets, y, accel, totals, later, ledger_later, counters, changes):
    """Island session s's state back into the scene's G (scatter) and its last samples into the run's arrays
    (flush). What it closed with holds for every later sample: its totals go into `later` and its energy integrals
    (contacts, work) into `ledger_later`, at the sample after its last (the run sums and raises them over the samples
    after, Islands._assemble). Its work counters are added to `counters` ((1,) COUNTERS), its contact changes (each
    at its sample of the run's grid, its pair the scene's) written to `changes` from the start. Returns how many
    changes and its steps."""
    flush(s, scene_offsets, y, accel, totals)
    scatter(s, G)
    done, c = s.state.book.counters[0], counters[0]
    for f in literal_unroll(COUNTED):
        c[f] += done[f]
    S, M, R = s.state, s.model, s.scratch
    o_contact, o_work = model_offsets(M)[6:8]
    after = R.cursor[0].grid_k
    _add(later[after], S.book.totals[0])
    Y = S.physical.y
    ledger_later[after, 0] += Y[o_contact]
    ledger_later[after, 1] += Y[o_work]
    nc, pairs = R.cursor[0].n_changes, s.buffers.pairs
    for r in range(nc):
        changes[r] = R.changes[r]
        changes[r].pair = pairs[R.changes[r].pair]
    return nc, done.steps


@jit
def retire_all(sessions, slots, G, scene_offsets, y, accel, totals, later, ledger_later, counters):
    """`retire` of sessions[slots[k]] for every k, in that order. Returns their contact changes, concatenated, and
    each one's steps."""
    total = 0
    for k in range(slots.shape[0]):
        total += sessions[slots[k]].scratch.cursor[0].n_changes
    changes = np.empty(total, CHANGE)
    steps = np.empty(slots.shape[0], np.int64)
    at = 0
    for k in range(slots.shape[0]):
        nc, done = retire(sessions[slots[k]], G, scene_offsets, y, accel, totals, later, ledger_later, counters,
                          changes[at:])
        steps[k] = done
        at += nc
    return changes, steps


@inline
def _add(a, b):
    """Totals b into a: counts added, peaks raised (records.COUNTS, PEAKS)."""
    for f in literal_unroll(COUNTS):
        a[f] += b[f]
    for f in literal_unroll(PEAKS):
        a[f] = max(a[f], b[f])
