"""Where each quantity sits in the state vector y.

y = [q (D) | q̇ (D) | base velocity ḃ (3) | base displacement b (3) | base angular velocity ω (3)
     | base orientation (4: the quaternion (x, y, z, w) of R, world from rachis) | hinge dissipation (N)
     | coupling dissipation (C) | contact dissipation (1) | base work (1)]

ω and the orientation are there only when the rachis may turn (`ModelArrays.turning`, from the scene:
model/excitation.Excitation.turns): a rachis that only translates keeps R = I, and its runs carry (and the
integrator's error norm averages over) seven components fewer. ḃ and b are there only when it may move
(`ModelArrays.moving`, Excitation.moves; turning implies moving): a rachis held still stays at the origin, and
the runs of the paper's scenes carry 8 components rather than 14 (every stage, error and dense-output sum is
over y).

D is the number of degrees of freedom: one angle per planar berry, two per spherical one.
The rachis motion follows the angles so that the head of y a step's dense output is sampled on
(events, peaks, the broad phase) places every berry in the world frame too (obstacles are fixed there).
ḃ, b and ω are in the world frame (docs/model.md §1).
The energy integrals ride along in y so that the same error control that keeps the angles
accurate keeps the energy ledger closed. Per-pair impulse and dissipation are *not* in y:
a cluster has thousands of candidate pairs and almost all of them are idle, so the solver
integrates them by quadrature on the dense output of the steps where a pair is in contact.
"""
from __future__ import annotations

import functools
from typing import NamedTuple

import numpy as np

from .compiled import inline


class Layout(NamedTuple):
    n: int
    d: int
    c: int
    moving: bool
    turning: bool
    q: slice
    w: slice
    base_velocity: slice
    base: slice
    base_angular_velocity: slice
    base_orientation: slice
    d_hinge: slice
    d_coupling: slice
    d_contact: int
    work: int
    size: int


@inline
def offsets(n, d, c, moving, turning):
    """The first index of each block of y for N berries, D angles and C couplings, with the rachis' translation
    (moving) and rotation (turning, which implies moving) or without: (base velocity, base
    displacement, base angular velocity, base orientation, hinge dissipation, coupling dissipation, contact
    dissipation, base work, size). The head that places the berries is y[:hinge dissipation]. The one
    definition of the layout (compiled and not)."""
    o_bv = 2 * d
    o_b = o_bv + 3 if moving else o_bv
    o_om = o_b + 3 if moving else o_b
    o_rot = o_om + 3 if turning else o_om
    o_dh = o_rot + 4 if turning else o_rot
    o_dc = o_dh + n
    o_contact = o_dc + c
    return o_bv, o_b, o_om, o_rot, o_dh, o_dc, o_contact, o_contact + 1, o_contact + 2


@functools.cache  # every Solver, run and scene's layout_of asks for one: built once per shape
def layout(n: int, d: int, c: int, moving: bool = True, turning: bool = False) -> Layout:
    moving = bool(moving or turning)
    o_bv, o_b, o_om, o_rot, o_dh, o_dc, o_contact, o_w, size = offsets.py_func(n, d, c, moving, turning)
    return Layout(n, d, c, moving, bool(turning), slice(0, d), slice(d, 2 * d), slice(o_bv, o_b), slice(o_b, o_om),
                  slice(o_om, o_rot), slice(o_rot, o_dh), slice(o_dh, o_dc), slice(o_dc, o_contact), o_contact, o_w,
                  size)


@inline
def model_offsets(M):
    """offsets() of a model's arrays (compiled code)."""
    return offsets(M.berry.shape[0], M.n_dof, M.coupling.shape[0], M.moving, M.turning)


@inline
def model_head(M):
    """The length of the head of y that places every berry (angles, rates, the rachis motion): what a step's
    dense output is sampled on for events, peaks and the broad phase."""
    return model_offsets(M)[4]


def layout_of(scene) -> Layout:
    """The layout of a scene's runs: with the rachis' ḃ and b when it may move (Excitation.moves), its ω and
    orientation when it may turn (Excitation.turns)."""
    m, ex = scene.model, scene.excitation
    return layout(m.n_berries, m.n_dof, len(m.couplings), ex.moves, ex.turns)


def initial(lay: Layout, scene, extra: int = 0) -> np.ndarray:
    """y at a scene's start (with `extra` trailing zeros): its angles and rates, the rachis at the world origin at
    rest in translation, in its initial orientation and angular velocity, every energy integral zero."""
    y = np.zeros(lay.size + extra)
    y[: 2 * lay.d] = scene.initial_state
    if lay.turning:
        y[lay.base_orientation] = scene.excitation.orientation
        y[lay.base_angular_velocity] = scene.excitation.angular_velocity
    return y


#: the rachis' orientation, and its angular velocity or displacement, in a layout without them
LEVEL, STILL = np.array([0.0, 0.0, 0.0, 1.0]), np.zeros(3)


def displacement(lay: Layout, y) -> np.ndarray:
    """The rachis' displacements b (..., 3), world frame, m, in states y (..., size)."""
    return y[..., lay.base] if lay.moving else _constant(1, y.shape[:-1])


def orientation(lay: Layout, y) -> np.ndarray:
    """The rachis' orientation quaternions (..., 4) in states y (..., size)."""
    return y[..., lay.base_orientation] if lay.turning else _constant(0, y.shape[:-1])


def angular_velocity(lay: Layout, y) -> np.ndarray:
    """The rachis' angular velocities (..., 3), world frame, in states y (..., size)."""
    return y[..., lay.base_angular_velocity] if lay.turning else _constant(1, y.shape[:-1])


@functools.lru_cache(maxsize=64)
def _constant(which: int, shape: tuple) -> np.ndarray:
    """LEVEL (0) or STILL (1) broadcast to shape + its own (read-only, so shared): np.broadcast_to costs ~10 µs,
    twice per Solver (its snapshot's orientation and angular velocity)."""
    v = (LEVEL, STILL)[which]
    return np.broadcast_to(v, shape + v.shape)


#: the energy integrals that ride along in y, in the order ledger() returns them
LEDGER_TERMS = ("dissipated_energy_hinge", "dissipated_energy_coupling", "dissipated_energy_contact", "base_work")


def ledger(lay: Layout, y, out=None):
    """The energy integrals (..., 4) of LEDGER_TERMS, J, for y of shape (..., size), into `out` if given.
    They sit next to each other in y (hinges, couplings, contact, base work), so one product with a 0/1
    matrix sums them: a face reads the ledger after every step."""
    return np.matmul(y[..., lay.d_hinge.start: lay.work + 1], _sums(lay.n, lay.c), out=out)


@functools.cache
def _sums(n: int, c: int) -> np.ndarray:
    """(n + c + 2, 4): which of the ledger's entries in y add up to each of LEDGER_TERMS."""
    term = np.repeat(np.arange(4), [n, c, 1, 1])
    m = np.zeros((n + c + 2, 4))
    m[np.arange(n + c + 2), term] = 1.0
    m.flags.writeable = False
    return m
