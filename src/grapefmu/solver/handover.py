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

from ..physics.compiled import jit
from ..physics.layout import model_offsets
from .solver import restart


@jit
def gather(S, M, X, skin, G, members, dofs, pairs, couplings, scene_offsets, t):
    """Island state S (model M) at time t from the scene's G: nothing booked yet (totals, counters, the energy the
    contacts dissipated and the base did: the island's own from now on), its near list and derivative made."""
    y, contacts, book_pair, ring, peak_tension, h, h_contact = G
    s_bv, s_dh, s_dc, d = scene_offsets
    o_bv, _, _, _, o_dh, o_dc, o_contact, o_work, _ = model_offsets(M)
    nd = M.n_dof
    Y = S.physical.y
    for r in range(dofs.shape[0]):
        Y[r] = y[dofs[r]]
        Y[nd + r] = y[d + dofs[r]]
    for k in range(o_dh - o_bv):
        Y[o_bv + k] = y[s_bv + k]
    for m in range(members.shape[0]):
        Y[o_dh + m] = y[s_dh + members[m]]
        S.book.peak_tension[m] = peak_tension[members[m]]
    for c in range(couplings.shape[0]):
        Y[o_dc + c] = y[s_dc + couplings[c]]
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
    cnt.steps, cnt.rejected, cnt.rhs_evaluations, cnt.switches = 0, 0, 0, 0
    cnt.zeno_activations, cnt.near_pairs_sum, cnt.near_list_rebuilds, cnt.quiet_steps = 0, 0, 0, 0
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
    restart(S, M, X, skin)


@jit
def scatter(S, M, G, members, dofs, pairs, couplings, scene_offsets):
    """What island state S (model M) carries back into the scene's G (not its own totals: the caller keeps those)."""
    y, contacts, book_pair, ring, peak_tension, h, h_contact = G
    s_bv, s_dh, s_dc, d = scene_offsets
    o_bv, _, _, _, o_dh, o_dc, _, _, _ = model_offsets(M)
    nd = M.n_dof
    Y = S.physical.y
    for r in range(dofs.shape[0]):
        y[dofs[r]] = Y[r]
        y[d + dofs[r]] = Y[nd + r]
    for k in range(o_dh - o_bv):
        y[s_bv + k] = Y[o_bv + k]
    clk = S.integrator.clock[0]
    for m in range(members.shape[0]):
        y[s_dh + members[m]] = Y[o_dh + m]
        peak_tension[members[m]] = S.book.peak_tension[m]
        h[members[m]] = clk.h
        h_contact[members[m]] = clk.h_contact
    for c in range(couplings.shape[0]):
        y[s_dc + couplings[c]] = Y[o_dc + c]
    for p in range(pairs.shape[0]):
        contacts[pairs[p]] = S.physical.contacts[p]
        book_pair[pairs[p]] = S.book.pair[p]
        ring[pairs[p], :] = S.book.ring[p, :]
