"""The rachis' acceleration (a(t), α(t)): the linear acceleration of its origin and its angular acceleration,
both in the world frame (m/s², rad/s²), the one evaluator of every excitation.

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

#: the components of the rachis acceleration, in the order every face and array (..., 6) holds them
ACCEL_COMPONENTS = ("ax", "ay", "az", "alpha_x", "alpha_y", "alpha_z")
#: the held input: while `held`, (a, α) replaces the scene's excitation
INPUT = np.dtype([("held", np.bool_), *((c, np.float64) for c in ACCEL_COMPONENTS)])


@inline
def base_accel(X, t, t_ref):
    """(a_x, a_y, a_z, α_x, α_y, α_z)(t) of the scene's excitation X (model.excitation.ExcitationArrays). No array
    is bound on the constant and chirp paths: an array bound inside an inlined function costs two reference
    counts."""
    if X.kind == CONSTANT:
        return X.par[0], X.par[1], X.par[2], X.par[3], X.par[4], X.par[5]
    if X.kind == CHIRP:
        start = X.par[8]
        dur = X.par[9]
        if t_ref < start or t_ref >= start + dur:
            return 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
        tau = t - start
        s = math.sin(2.0 * math.pi * (X.par[6] * tau + 0.5 * (X.par[7] - X.par[6]) * tau * tau / dur))
        return X.par[0] * s, X.par[1] * s, X.par[2] * s, X.par[3] * s, X.par[4] * s, X.par[5] * s
    return table_accel(X.table, t, t_ref)


@inline
def table_accel(tab, t, t_ref):
    """Linear in the row that holds t_ref (the last row with time ≤ t_ref), zero outside the table. Inlined: it runs on
    every stage and sample of every island, and as a call it was 3 % of an islands run (perf)."""
    n = tab.shape[0]
    if t_ref < tab[0, 0] or t_ref >= tab[n - 1, 0]:
        return 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
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
    v = 1.0 - u
    return (v * tab[k, 1] + u * tab[k + 1, 1], v * tab[k, 2] + u * tab[k + 1, 2], v * tab[k, 3] + u * tab[k + 1, 3],
            v * tab[k, 4] + u * tab[k + 1, 4], v * tab[k, 5] + u * tab[k + 1, 5], v * tab[k, 6] + u * tab[k + 1, 6])


@inline
def applied_accel(X, inp, t, t_ref):
    """What the rachis does: the held input (inp, an INPUT record) while there is one, else the scene's
    excitation. A record, not its array: an array handed to an inlined function costs reference counts."""
    if inp.held:
        return inp.ax, inp.ay, inp.az, inp.alpha_x, inp.alpha_y, inp.alpha_z
    return base_accel(X, t, t_ref)


@inline
def pull_bound(X, inp, t0, t1, g):
    """An upper bound on |a + g ẑ| over [t0, t1] on the piece that holds t0 (as the solver evaluates a step), the
    largest pull per unit mass that gravity and the moving rachis put on a berry (forces.frame_fields), or inf where
    the rachis turns (α ≠ 0) or no bound is known. Exact for a held or constant acceleration; a table's row is linear
    in t, so |a + g ẑ| is largest at a step end; a chirp's sine lies in [−1, 1], so at ± its amplitude."""
    if inp.held:
        if inp.alpha_x != 0.0 or inp.alpha_y != 0.0 or inp.alpha_z != 0.0:
            return np.inf
        return math.sqrt(inp.ax * inp.ax + inp.ay * inp.ay + (inp.az + g) ** 2)
    if X.kind == CONSTANT or X.kind == CHIRP:
        p = X.par
        if p[3] != 0.0 or p[4] != 0.0 or p[5] != 0.0:
            return np.inf
        up = math.sqrt(p[0] * p[0] + p[1] * p[1] + (p[2] + g) ** 2)
        if X.kind == CONSTANT:
            return up
        return max(up, math.sqrt(p[0] * p[0] + p[1] * p[1] + (g - p[2]) ** 2), g)
    worst = 0.0
    for t in (t0, t1):
        ax, ay, az, alx, aly, alz = table_accel(X.table, t, t0)
        if alx != 0.0 or aly != 0.0 or alz != 0.0:
            return np.inf
        worst = max(worst, math.sqrt(ax * ax + ay * ay + (az + g) ** 2))
    return worst


@jit
def _series(X, t, out):
    for k in range(t.shape[0]):
        out[k, 0], out[k, 1], out[k, 2], out[k, 3], out[k, 4], out[k, 5] = base_accel(X, t[k], t[k])


def accel(excitation: Excitation, t) -> np.ndarray:
    """(a, α)(t) as an array (..., 6) of ACCEL_COMPONENTS (m/s², rad/s², world frame), for plots, controllers and
    checks."""
    t = np.asarray(t, dtype=float)
    flat = np.ascontiguousarray(t.reshape(-1))
    out = np.empty((flat.size, 6))
    _series(excitation.arrays, flat, out)
    return out.reshape(t.shape + (6,))


def held(accel=(0.0,) * 6, on: bool = True) -> np.ndarray:
    """An input record: the rachis acceleration `accel` (ACCEL_COMPONENTS) held, or (on = False) the scene's
    excitation."""
    rec = np.zeros(1, dtype=INPUT)
    rec[0] = (on, *accel)
    return rec
