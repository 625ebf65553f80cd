"""One Runge–Kutta step with its embedded error estimate and dense output (scipy's `_step_impl`)."""
from __future__ import annotations

import math

import numpy as np

from ..physics.dynamics import rhs, rhs_inline
from ..physics.compiled import inline, jit
from ..physics.layout import model_offsets


@inline
def dense(theta, y0, q, h, out):
    """y(t0 + θh) = y0 + h Σ_j Q[:, j] θ^(j+1)."""
    dense_head(theta, y0, q, h, out, y0.shape[0])


@inline
def dense_head(theta, y0, q, h, out, m):
    """dense() for the first m components only (the angles and rates that events and forces need)."""
    r = 0
    while r + 4 <= m:
        a0, a1, a2, a3 = horner4(theta, q, r)
        out[r], out[r + 1], out[r + 2], out[r + 3] = \
            y0[r] + h * a0, y0[r + 1] + h * a1, y0[r + 2] + h * a2, y0[r + 3] + h * a3
        r += 4
    while r < m:
        out[r] = dense_component(theta, y0, q, h, r)
        r += 1


@inline
def dense_rows(theta, n, y0, q, h, acc, out, o):
    """out[o + k, r] = dense(theta[k])[r] for k < n (acc: scratch of n): the output grid's samples of one step. Each
    component's Horner chain runs across the samples, which are independent, so the loop over them vectorises, where
    the grid ran one sample's components after another (dense_head). The same operations in the same order for each element, so
    the same numbers. The paper collision at rtol 1e-6 (benchmarks/run_breakdown.py "paper collision" 1e-6 1e-4,
    against the code before): 22 to 18–19 ns a sample on a 0.1 ms grid, the run 0.90–0.93 of its time; on the 1 ms
    grid 26 to 20–23 ns, about 1 % of the run."""
    for r in range(y0.shape[0]):
        for k in range(n):
            acc[k] = 0.0
        for j in range(q.shape[1] - 1, -1, -1):
            c = q[r, j]
            for k in range(n):
                acc[k] = (acc[k] + c) * theta[k]
        for k in range(n):
            out[o + k, r] = y0[r] + h * acc[k]


@inline
def dense_pair(theta, y0, q, h, out, M, pr):
    """dense_head() for what one pair's stage 1 reads (physics/kinematics.pair_state): its berries' four entries of
    y (berry_kinematics' s, ṡ, t, ṫ) and the rachis motion. The same numbers as dense_head(), for O(1) components
    where dense_head() computes the whole head: a cluster's event and peak searches evaluate one pair at a time."""
    for i in (pr.i, pr.j):
        if i < M.berry.shape[0]:
            dense_berry(theta, y0, q, h, out, M, i)
    dense_rachis(theta, y0, q, h, out, M)


@inline
def dense_berry(theta, y0, q, h, out, M, i):
    """dense_head() for berry i's four entries of y (berry_kinematics' s, ṡ, t, ṫ)."""
    nd = M.n_dof
    o = M.berry[i].dof
    for r in (o, o + 1, nd + o, nd + o + 1):  # o + 1 < nd + o: inside the head
        out[r] = dense_component(theta, y0, q, h, r)


@inline
def dense_rachis(theta, y0, q, h, out, M):
    """dense_head() for the rachis motion alone (what physics/kinematics.rachis_frame reads)."""
    off = model_offsets(M)
    for r in range(off[0], off[4]):
        out[r] = dense_component(theta, y0, q, h, r)


@inline
def horner4(theta, q, r):
    """Σ_j Q[r + i, j] θ^(j+1) for i = 0..3, dense_component's sums for four components with their Horner chains
    interleaved: each chain waits on its own multiplications, so four take about the time of one. The same operations
    in the same order, so the same numbers."""
    a0 = a1 = a2 = a3 = 0.0
    for j in range(q.shape[1] - 1, -1, -1):
        a0 = (a0 + q[r, j]) * theta
        a1 = (a1 + q[r + 1, j]) * theta
        a2 = (a2 + q[r + 2, j]) * theta
        a3 = (a3 + q[r + 3, j]) * theta
    return a0, a1, a2, a3


@inline
def dense_component(theta, y0, q, h, r):
    """Component r of dense(): y0[r] + h Σ_j Q[r, j] θ^(j+1), by Horner's rule."""
    acc = 0.0
    for j in range(q.shape[1] - 1, -1, -1):
        acc = (acc + q[r, j]) * theta
    return y0[r] + h * acc


@jit
def combine(coef, stages, count, out):
    """out = Σ_{m < count} coef[m] · stages[m], summed in m order for every element (from 0.0, as an `out[:] = 0;
    out += c · row` loop would). Four elements at a time in registers, then one at a time: a loop over the whole
    row per m vectorises only in multiples of four, and a state of 14 (a level rachis with two berries) spent
    about as long in its scalar remainder as in the rest."""
    n = out.shape[0]
    r = 0
    while r + 4 <= n:
        a0 = a1 = a2 = a3 = 0.0
        for m in range(count):
            c = coef[m]
            a0 += c * stages[m, r]
            a1 += c * stages[m, r + 1]
            a2 += c * stages[m, r + 2]
            a3 += c * stages[m, r + 3]
        out[r], out[r + 1], out[r + 2], out[r + 3] = a0, a1, a2, a3
        r += 4
    while r < n:
        a0 = 0.0
        for m in range(count):
            a0 += coef[m] * stages[m, r]
        out[r] = a0
        r += 1


@jit
def rms_norm(x, scale):
    s = 0.0
    for i in range(x.shape[0]):
        s += (x[i] / scale[i]) ** 2
    return math.sqrt(s / x.shape[0])


@jit
def initial_step(t0, y0, f0, args, cfg, order, t_stop):
    """Hairer's starting step size (scipy's select_initial_step)."""
    C, M, X, inp, W, pairs, n_pairs = args
    scale = cfg.atol + cfg.rtol * np.abs(y0)
    d0 = rms_norm(y0, scale)
    d1 = rms_norm(f0, scale)
    h0 = 1e-6 if (d0 < 1e-5 or d1 < 1e-5) else 0.01 * d0 / d1
    h0 = min(h0, t_stop - t0)
    y1 = y0 + h0 * f0
    f1 = np.empty(y0.shape[0])
    rhs(t0 + h0, t0, y1, f1, C, M, X, inp, W, pairs, n_pairs)
    d2 = rms_norm(f1 - f0, scale) / h0
    if d1 <= 1e-15 and d2 <= 1e-15:
        h1 = max(1e-6, h0 * 1e-3)
    else:
        h1 = (0.01 / max(d1, d2)) ** (1.0 / (order + 1))
    return min(100 * h0, h1, cfg.h_max)


@inline
def rk_step(t0, h, t_new, y, f, args, TB, stages, ynew, tmp, acc):
    """A trial step from (t0, y) with f = dy/dt there: ynew, and stages[s] = dy/dt at ynew (FSAL).
    The combinations run stage by stage over the whole vector; each element sums in the same order."""
    C, M, X, inp, W, pairs, n_pairs = args
    ns = TB.b.shape[0]
    ny = y.shape[0]
    stages[0, :] = f
    for st in range(1, ns):
        combine(TB.a[st], stages, st, acc)
        for r in range(ny):
            tmp[r] = y[r] + h * acc[r]
        rhs_inline(t0 + TB.c[st] * h, t0, tmp, stages[st], C, M, X, inp, W, pairs, n_pairs)
    combine(TB.b, stages, ns, acc)
    for r in range(ny):
        ynew[r] = y[r] + h * acc[r]
    rhs_inline(t_new, t0, ynew, stages[ns], C, M, X, inp, W, pairs, n_pairs)


@inline
def error_norm(h, y, ynew, TB, stages, cfg, err, scale, acc):
    """The embedded estimate's RMS norm against atol + rtol·max(|y|, |y_new|) (inf if y_new is not finite).
    With a third-order estimate (DOP853) the fifth-order one is tempered by it as in scipy:
    |h|·‖e5‖² / √((‖e5‖² + 0.01‖e3‖²)·n), so a fifth-order estimate that vanishes by accident does not pass."""
    n_fsal = TB.b.shape[0] + 1
    combine(TB.e, stages, n_fsal, acc)
    s5 = 0.0  # rms_norm's sum, in its order, in the pass that forms err and scale
    for r in range(y.shape[0]):
        if not math.isfinite(ynew[r]):
            return np.inf
        err[r] = h * acc[r]
        scale[r] = cfg.atol + cfg.rtol * max(abs(y[r]), abs(ynew[r]))
        s5 += (err[r] / scale[r]) ** 2
    if TB.e3.shape[0] == 0:
        return math.sqrt(s5 / y.shape[0])
    combine(TB.e3, stages, n_fsal, acc)
    s3 = 0.0
    for r in range(y.shape[0]):
        s3 += (h * acc[r] / scale[r]) ** 2
    if s5 == 0.0:  # 0 as the formula gives it, also where 0.01 s3 underflows (steps of 1e-158 s: 0/0, NaN)
        return 0.0
    return s5 / math.sqrt((s5 + 0.01 * s3) * y.shape[0])


@inline
def dense_coefficients(t0, h, y, args, TB, stages, q, tmp, acc):
    """q of the accepted step (dense()). DOP853's interpolant first needs its extra stages, evaluated here
    after the FSAL one (stages[s + 1 + i]; TB.c_extra.shape[0] more right-hand sides, which the caller counts)."""
    C, M, X, inp, W, pairs, n_pairs = args
    ny = y.shape[0]
    first = TB.b.shape[0] + 1
    for i in range(TB.c_extra.shape[0]):
        st = first + i
        combine(TB.a_extra[i], stages, st, acc)
        for r in range(ny):
            tmp[r] = y[r] + h * acc[r]
        rhs_inline(t0 + TB.c_extra[i] * h, t0, tmp, stages[st], C, M, X, inp, W, pairs, n_pairs)
    for j in range(TB.p.shape[1]):
        combine(TB.p[:, j], stages, TB.p.shape[0], acc)
        for r in range(acc.shape[0]):
            q[r, j] = acc[r]
