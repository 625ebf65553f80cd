"""The base acceleration a(t) = (a_x, a_z) of the rachis: the one evaluator of every excitation.

The solver asks for a(t) on the smooth piece that contains t_ref (its step's start), so that a step
ending exactly on a breakpoint still sees the acceleration of the piece it integrated; everything else
asks with t_ref = t (right-continuous). A held input (an FMU's or a ROS node's zero-order hold) takes
the place of the scene's excitation while it is set.
"""
from __future__ import annotations

import math

import numpy as np

from ..model.excitation import CHIRP, CONSTANT, Excitation
from .compiled import inline, jit

#: the held input: while `held`, (ax, az) replaces the scene's excitation
INPUT = np.dtype([("held", np.bool_), ("ax", np.float64), ("az", np.float64)])


@inline
def base_accel(X, t, t_ref):
    """a(t) of the scene's excitation X (model.excitation.ExcitationArrays), m/s². No array is bound on the
    constant and chirp paths: an array bound inside an inlined function costs two reference counts."""
    if X.kind == CONSTANT:
        return X.par[0], X.par[1]
    if X.kind == CHIRP:
        start = X.par[4]
        dur = X.par[5]
        if t_ref < start or t_ref >= start + dur:
            return 0.0, 0.0
        tau = t - start
        s = math.sin(2.0 * math.pi * (X.par[2] * tau + 0.5 * (X.par[3] - X.par[2]) * tau * tau / dur))
        return X.par[0] * s, X.par[1] * s
    return table_accel(X.table, t, t_ref)


@jit
def table_accel(tab, t, t_ref):
    """Linear in the row that holds t_ref (the last row with time ≤ t_ref), zero outside the table."""
    n = tab.shape[0]
    if t_ref < tab[0, 0] or t_ref >= tab[n - 1, 0]:
        return 0.0, 0.0
    lo, hi = 0, n - 1  # tab[lo, 0] <= t_ref < tab[hi, 0]
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if tab[mid, 0] <= t_ref:
            lo = mid
        else:
            hi = mid
    k = lo
    span = tab[k + 1, 0] - tab[k, 0]
    u = (t - tab[k, 0]) / span if span > 0.0 else 0.0
    return tab[k, 1] + u * (tab[k + 1, 1] - tab[k, 1]), tab[k, 2] + u * (tab[k + 1, 2] - tab[k, 2])


@inline
def applied_accel(X, inp, t, t_ref):
    """What the rachis does: the held input (inp, an INPUT record) while there is one, else the scene's
    excitation. A record, not its array: an array handed to an inlined function costs reference counts."""
    if inp.held:
        return inp.ax, inp.az
    return base_accel(X, t, t_ref)


@jit
def _series(X, t, out):
    for k in range(t.shape[0]):
        out[k, 0], out[k, 1] = base_accel(X, t[k], t[k])


def accel(excitation: Excitation, t) -> np.ndarray:
    """a(t) as an array (..., 2) of (a_x, a_z), m/s², for plots, controllers and checks."""
    t = np.asarray(t, dtype=float)
    flat = np.ascontiguousarray(t.reshape(-1))
    out = np.empty((flat.size, 2))
    _series(excitation.arrays, flat, out)
    return out.reshape(t.shape + (2,))


def held(ax: float = 0.0, az: float = 0.0, on: bool = True) -> np.ndarray:
    """An input record: (ax, az) held, or (on = False) the scene's excitation."""
    rec = np.zeros(1, dtype=INPUT)
    rec[0] = (on, ax, az)
    return rec
