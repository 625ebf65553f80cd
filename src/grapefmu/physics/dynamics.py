"""The equations of motion of berries on hinged twigs under base excitation (docs/model.md §2–4).

Everything here is compiled with numba and reads the model as `ModelArrays`. A contact
pair carries a *mode*: 0 apart (δ ≤ 0), 1 loaded (δ > 0 and the law pushes), 2 overlapping
but unloaded (δ > 0 and the clamped law would pull). Inside a step the mode is fixed, so
the right-hand side is smooth and the Runge–Kutta method keeps its order; the solver
switches modes at located events. A pair flagged `smooth` (the Zeno guard) evaluates the
clamped law inline instead.
"""
from __future__ import annotations

import math

import numba as nb
import numpy as np

from ..model.contact import HC_MIN_APPROACH_SPEED  # noqa: F401  (re-exported for the core)

KV, HERTZ, HC = 0, 1, 2
CONSTANT, CHIRP, TABLE = 0, 1, 2
jit = nb.njit(cache=True, error_model="numpy")
#: small helpers are inlined into their callers: a call boundary costs more than their arithmetic
inline = nb.njit(cache=True, error_model="numpy", inline="always")


@inline
def base_accel(kind, par, tab, t, t_ref):
    """a(t) on the smooth piece that contains t_ref (the step's start), so that a step ending
    exactly on a breakpoint still sees the acceleration of the piece it integrated."""
    if kind == CONSTANT:
        return par[0], par[1]
    if kind == CHIRP:
        start = par[4]
        dur = par[5]
        if t_ref < start or t_ref >= start + dur:
            return 0.0, 0.0
        tau = t - start
        s = math.sin(2.0 * math.pi * (par[2] * tau + 0.5 * (par[3] - par[2]) * tau * tau / dur))
        return par[0] * s, par[1] * s
    n = tab.shape[0]
    if t_ref < tab[0, 0] or t_ref >= tab[n - 1, 0]:
        return 0.0, 0.0
    k = np.searchsorted(tab[:, 0], t_ref, side="right") - 1
    span = tab[k + 1, 0] - tab[k, 0]
    u = (t - tab[k, 0]) / span if span > 0.0 else 0.0
    return tab[k, 1] + u * (tab[k + 1, 1] - tab[k, 1]), tab[k, 2] + u * (tab[k + 1, 2] - tab[k, 2])


@inline
def pair_kinematics(y, berry, i, j, n):
    """Penetration δ = r_i + r_j − |p_j − p_i|, its rate δ̇ and the unit normal n from i to j."""
    qi, qj = y[i], y[j]
    wi, wj = y[n + i], y[n + j]
    li, lj = berry[i, 2], berry[j, 2]
    si, ci, sj, cj = math.sin(qi), math.cos(qi), math.sin(qj), math.cos(qj)
    dx = berry[j, 3] + lj * sj - berry[i, 3] - li * si
    dy = -lj * cj + li * ci
    d = math.sqrt(dx * dx + dy * dy)
    if d > 1e-15:
        nx, ny = dx / d, dy / d
    else:
        nx, ny = 1.0, 0.0
    vx = lj * cj * wj - li * ci * wi
    vy = lj * sj * wj - li * si * wi
    delta = berry[i, 1] + berry[j, 1] - d
    delta_dot = -(nx * vx + ny * vy)
    return delta, delta_dot, nx, ny


@inline
def contact_law(code, par, delta, delta_dot, v_onset):
    """(F, F_el, φ): the unclamped force, its elastic part and the sign function φ whose
    zero is where the clamped law unloads (φ ≡ 1 where the law cannot pull)."""
    k = par[0]
    c = par[1]
    clamp = par[2] > 0.5
    if code == KV:
        f_el = k * delta
        f = f_el + c * delta_dot
        return f, f_el, (f if clamp else 1.0)
    dp = max(delta, 0.0)
    f_el = k * dp * math.sqrt(dp)
    if code == HERTZ:
        return f_el, f_el, 1.0
    phi = 1.0 + c * delta_dot / v_onset
    return f_el * phi, f_el, (phi if clamp else 1.0)


@inline
def elastic_energy(code, par, delta):
    if delta <= 0.0:
        return 0.0
    if code == KV:
        return 0.5 * par[0] * delta * delta
    return 0.4 * par[0] * delta * delta * math.sqrt(delta)


@inline
def pair_force(p, y, mode, v_onset, smooth, M):
    """Normal force the pair pushes with in its current mode, and the dissipation power."""
    if mode[p] == 0 and not smooth[p]:
        return 0.0, 0.0, -1.0, 0.0, 1.0, 0.0
    i, j = M.pair_idx[p, 0], M.pair_idx[p, 1]
    n = M.berry.shape[0]
    delta, delta_dot, nx, ny = pair_kinematics(y, M.berry, i, j, n)
    f, f_el, phi = contact_law(M.pair_law[p], M.pair_par[p], delta, delta_dot, v_onset[p])
    if smooth[p]:
        if delta <= 0.0:
            f, f_el = 0.0, 0.0
        elif phi <= 0.0:
            f = 0.0
    elif mode[p] == 2:
        f = 0.0
    return f, (f - f_el) * delta_dot, delta, delta_dot, nx, ny


@jit
def rhs(t, t_ref, y, dy, mode, v_onset, smooth, M, ekind, epar, etab):
    """dy/dt. Generalized forces follow Q_i = F_i · ∂p_i/∂q_i with ∂p_i/∂q_i = l_i (cos q_i, sin q_i)."""
    berry = M.berry
    n = berry.shape[0]
    nc = M.coup_idx.shape[0]
    npair = M.pair_idx.shape[0]
    g = M.gravity
    ax, ay = base_accel(ekind, epar, etab, t, t_ref)
    o_dc = 3 * n
    o_dk = o_dc + nc
    o_j = o_dk + npair
    o_w = o_j + npair
    torque = dy[n:2 * n]  # accumulate generalized forces in place, divide by m l² at the end
    work = 0.0
    for i in range(n):
        m, l, kh, ch = berry[i, 0], berry[i, 2], berry[i, 4], berry[i, 5]
        q, w = y[i], y[n + i]
        s, c = math.sin(q), math.cos(q)
        torque[i] = -m * l * ((g + ay) * s + ax * c) - kh * q - ch * w
        work -= m * l * (ax * c + ay * s) * w
        dy[i] = w
        dy[2 * n + i] = ch * w * w
    for k in range(nc):
        i, j = M.coup_idx[k, 0], M.coup_idx[k, 1]
        li, lj = berry[i, 2], berry[j, 2]
        ci, cj = math.cos(y[i]), math.cos(y[j])
        s = lj * math.sin(y[j]) - li * math.sin(y[i])
        sd = lj * cj * y[n + j] - li * ci * y[n + i]
        fc = M.coup_par[k, 0] * s + M.coup_par[k, 1] * sd
        torque[i] += fc * li * ci
        torque[j] -= fc * lj * cj
        dy[o_dc + k] = M.coup_par[k, 1] * sd * sd
    for p in range(npair):
        f, power, _, _, nx, ny = pair_force(p, y, mode, v_onset, smooth, M)
        dy[o_dk + p] = power
        dy[o_j + p] = f
        if f != 0.0:
            i, j = M.pair_idx[p, 0], M.pair_idx[p, 1]
            li, lj = berry[i, 2], berry[j, 2]
            torque[i] -= f * li * (nx * math.cos(y[i]) + ny * math.sin(y[i]))
            torque[j] += f * lj * (nx * math.cos(y[j]) + ny * math.sin(y[j]))
    for i in range(n):
        dy[n + i] = torque[i] / (berry[i, 0] * berry[i, 2] * berry[i, 2])
    dy[o_w] = work
    dy[o_w + 1] = ax
    dy[o_w + 2] = ay
    dy[o_w + 3] = y[o_w + 1]
    dy[o_w + 4] = y[o_w + 2]


@jit
def berry_forces(y, mode, v_onset, smooth, M, force, penetration, fext):
    """Per pair: force and penetration; per berry: the summed inter-berry force (contact and coupling)."""
    berry = M.berry
    n = berry.shape[0]
    fext[:, :] = 0.0
    for k in range(M.coup_idx.shape[0]):
        i, j = M.coup_idx[k, 0], M.coup_idx[k, 1]
        li, lj = berry[i, 2], berry[j, 2]
        s = lj * math.sin(y[j]) - li * math.sin(y[i])
        sd = lj * math.cos(y[j]) * y[n + j] - li * math.cos(y[i]) * y[n + i]
        fc = M.coup_par[k, 0] * s + M.coup_par[k, 1] * sd
        fext[i, 0] += fc
        fext[j, 0] -= fc
    for p in range(M.pair_idx.shape[0]):
        f, _, delta, _, nx, ny = pair_force(p, y, mode, v_onset, smooth, M)
        force[p] = f
        penetration[p] = max(delta, 0.0)
        i, j = M.pair_idx[p, 0], M.pair_idx[p, 1]
        fext[i, 0] -= f * nx
        fext[i, 1] -= f * ny
        fext[j, 0] += f * nx
        fext[j, 1] += f * ny


@jit
def pedicel_tension(y, ax, ay, fext, M, out):
    """T_i = m l q̇² + m[(g + a_y) cos q − a_x sin q] + F_i · e_r (radial balance of the berry)."""
    berry = M.berry
    n = berry.shape[0]
    for i in range(n):
        m, l = berry[i, 0], berry[i, 2]
        q, w = y[i], y[n + i]
        s, c = math.sin(q), math.cos(q)
        out[i] = m * l * w * w + m * ((M.gravity + ay) * c - ax * s) + fext[i, 0] * s - fext[i, 1] * c


@jit
def derived(ts, ys, modes, accs, v_onsets, smooths, M, force, penetration, tension, energy):
    """Post-process samples: contact force and penetration per pair, tension per berry and the
    energy terms [kinetic, gravity, hinge, coupling, contact elastic] per sample."""
    berry = M.berry
    n = berry.shape[0]
    npair = M.pair_idx.shape[0]
    fext = np.zeros((n, 2))
    for s in range(ts.shape[0]):
        y = ys[s]
        berry_forces(y, modes[s], v_onsets[s], smooths[s], M, force[s], penetration[s], fext)
        pedicel_tension(y, accs[s, 0], accs[s, 1], fext, M, tension[s])
        ke = 0.0
        vg = 0.0
        vh = 0.0
        for i in range(n):
            m, l = berry[i, 0], berry[i, 2]
            ke += 0.5 * m * l * l * y[n + i] ** 2
            vg += m * M.gravity * l * (1.0 - math.cos(y[i]))
            vh += 0.5 * berry[i, 4] * y[i] ** 2
        vc = 0.0
        for k in range(M.coup_idx.shape[0]):
            i, j = M.coup_idx[k, 0], M.coup_idx[k, 1]
            sep = berry[j, 2] * math.sin(y[j]) - berry[i, 2] * math.sin(y[i])
            vc += 0.5 * M.coup_par[k, 0] * sep * sep
        ve = 0.0
        for p in range(npair):
            i, j = M.pair_idx[p, 0], M.pair_idx[p, 1]
            delta, _, _, _ = pair_kinematics(y, berry, i, j, n)
            ve += elastic_energy(M.pair_law[p], M.pair_par[p], delta)
        energy[s, 0] = ke
        energy[s, 1] = vg
        energy[s, 2] = vh
        energy[s, 3] = vc
        energy[s, 4] = ve



@jit
def observe(y, mode, v_onset, smooth, ax, ay, M, peak_force, peak_tension, fext, out):
    """Everything a co-simulation face reports after a step, in one compiled call, as one vector:
    [angles (N), angular velocities (N), pedicel tensions (N), contact forces (P), penetrations (P),
     in contact (P, 1.0 or 0.0), largest contact force so far, largest tension so far, energy dissipated]."""
    n = M.berry.shape[0]
    npair = M.pair_idx.shape[0]
    nc = M.coup_idx.shape[0]
    force = out[3 * n: 3 * n + npair]
    pen = out[3 * n + npair: 3 * n + 2 * npair]
    berry_forces(y, mode, v_onset, smooth, M, force, pen, fext)
    tension = out[2 * n: 3 * n]
    pedicel_tension(y, ax, ay, fext, M, tension)
    out[: 2 * n] = y[: 2 * n]
    peak_f = 0.0
    for p in range(npair):
        out[3 * n + 2 * npair + p] = 1.0 if mode[p] != 0 else 0.0
        peak_f = max(peak_f, peak_force[p])
    peak_t = -np.inf
    for i in range(n):
        peak_t = max(peak_t, peak_tension[i], tension[i])
    dissipated = 0.0
    for k in range(2 * n, 3 * n + nc + npair):
        dissipated += y[k]
    o = 3 * n + 3 * npair
    out[o] = peak_f
    out[o + 1] = peak_t
    out[o + 2] = dissipated
