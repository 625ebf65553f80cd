"""The equations of motion of berries on hinged twigs under base excitation (docs/model.md §2–6).

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
def twig(y, M, i, nd):
    """Berry i's twig direction u and its rate u̇ in the rachis frame (docs/model.md §6)."""
    o = M.dof[i]
    s, sd = y[o], y[nd + o]
    ss, cs = math.sin(s), math.cos(s)
    if M.dof[i + 1] - o == 1:
        return ss, 0.0, -cs, cs * sd, 0.0, ss * sd
    t, td = y[o + 1], y[nd + o + 1]
    st, ct = math.sin(t), math.cos(t)
    ux, uy, uz = ss, -st * cs, -ct * cs
    vx, vy, vz = cs * sd, st * ss * sd - ct * cs * td, ct * ss * sd + st * cs * td
    ca, sa = M.berry[i, 10], M.berry[i, 11]
    return ca * ux - sa * uy, sa * ux + ca * uy, uz, ca * vx - sa * vy, sa * vx + ca * vy, vz


@inline
def add_force(y, M, i, nd, fx, fy, fz, torque):
    """Generalized forces Q = l Jᵀ F of a force F (rachis frame) on berry i, added to torque."""
    o = M.dof[i]
    l = M.berry[i, 2]
    s = y[o]
    ss, cs = math.sin(s), math.cos(s)
    if M.dof[i + 1] - o == 1:
        torque[o] += l * (cs * fx + ss * fz)
        return
    t = y[o + 1]
    st, ct = math.sin(t), math.cos(t)
    ca, sa = M.berry[i, 10], M.berry[i, 11]
    lx, ly = ca * fx + sa * fy, -sa * fx + ca * fy
    torque[o] += l * (cs * lx + st * ss * ly + ct * ss * fz)
    torque[o + 1] += l * cs * (-ct * ly + st * fz)


@inline
def pair_kinematics(y, M, i, j, nd):
    """Penetration δ = r_i + r_j − |p_j − p_i|, its rate δ̇ and the unit normal n from i to j."""
    b = M.berry
    li, lj = b[i, 2], b[j, 2]
    uxi, uyi, uzi, vxi, vyi, vzi = twig(y, M, i, nd)
    uxj, uyj, uzj, vxj, vyj, vzj = twig(y, M, j, nd)
    # grouped as centre minus centre, so δ is bit for bit what centres() gives (the event search uses both)
    dx = (b[j, 3] + lj * uxj) - (b[i, 3] + li * uxi)
    dy = (b[j, 6] + lj * uyj) - (b[i, 6] + li * uyi)
    dz = (b[j, 7] + lj * uzj) - (b[i, 7] + li * uzi)
    d = math.sqrt(dx * dx + dy * dy + dz * dz)
    if d > 1e-15:
        nx, ny, nz = dx / d, dy / d, dz / d
    else:
        nx, ny, nz = 1.0, 0.0, 0.0
    vx = lj * vxj - li * vxi
    vy = lj * vyj - li * vyi
    vz = lj * vzj - li * vzi
    delta = b[i, 1] + b[j, 1] - d
    delta_dot = -(nx * vx + ny * vy + nz * vz)
    return delta, delta_dot, nx, ny, nz


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
        return 0.0, 0.0, -1.0, 0.0, 1.0, 0.0, 0.0
    i, j = M.pair_idx[p, 0], M.pair_idx[p, 1]
    delta, delta_dot, nx, ny, nz = pair_kinematics(y, M, i, j, M.dof[M.berry.shape[0]])
    f, f_el, phi = contact_law(M.pair_law[p], M.pair_par[p], delta, delta_dot, v_onset[p])
    if smooth[p]:
        if delta <= 0.0:
            f, f_el = 0.0, 0.0
        elif phi <= 0.0:
            f = 0.0
    elif mode[p] == 2:
        f = 0.0
    return f, (f - f_el) * delta_dot, delta, delta_dot, nx, ny, nz


@jit
def rhs(t, t_ref, y, dy, mode, v_onset, smooth, M, ekind, epar, etab):
    """dy/dt: Lagrange's equations of docs/model.md §2–6 with generalized forces Q = l Jᵀ F.

    A dy longer than the state by 2P also gets each pair's force and dissipation power at its end:
    the scipy reference integrates those per pair, the event solver by quadrature."""
    berry = M.berry
    n = berry.shape[0]
    nd = M.dof[n]
    nc = M.coup_idx.shape[0]
    npair = M.pair_idx.shape[0]
    g = M.gravity
    ax, az = base_accel(ekind, epar, etab, t, t_ref)
    o_dh = 2 * nd
    o_dc = o_dh + n
    o_w = o_dc + nc + 1
    torque = dy[nd:2 * nd]  # accumulate generalized forces in place, divide by the inertia at the end
    work = 0.0
    for i in range(n):
        m, l, kh, ch = berry[i, 0], berry[i, 2], berry[i, 4], berry[i, 5]
        o = M.dof[i]
        s, sd = y[o], y[nd + o]
        ss, cs = math.sin(s), math.cos(s)
        dy[o] = sd
        if M.dof[i + 1] - o == 1:
            torque[o] = -m * l * ((g + az) * ss + ax * cs) - kh * (s - berry[i, 8]) - ch * sd
            work -= m * l * (ax * cs + az * ss) * sd
            dy[o_dh + i] = ch * sd * sd
            continue
        t_, td = y[o + 1], y[nd + o + 1]
        st, ct = math.sin(t_), math.cos(t_)
        ca, sa = berry[i, 10], berry[i, 11]
        fx, fz = -m * ax, -m * (g + az)  # gravity and the rachis' inertial force, rachis frame
        lx, ly = ca * fx, -sa * fx
        torque[o] = l * (cs * lx + st * ss * ly + ct * ss * fz) - kh * (s - berry[i, 8]) - ch * sd
        torque[o + 1] = l * cs * (-ct * ly + st * fz) - kh * (t_ - berry[i, 9]) - ch * td
        vlx, vly = cs * sd, st * ss * sd - ct * cs * td
        work -= m * l * (ax * (ca * vlx - sa * vly) + az * (ct * ss * sd + st * cs * td))
        dy[o + 1] = td
        dy[o_dh + i] = ch * (sd * sd + td * td)
    for k in range(nc):
        i, j = M.coup_idx[k, 0], M.coup_idx[k, 1]
        oi, oj = M.dof[i], M.dof[j]
        li, lj = berry[i, 2], berry[j, 2]
        ci, cj = math.cos(y[oi]), math.cos(y[oj])
        sep = lj * math.sin(y[oj]) - li * math.sin(y[oi])
        sepd = lj * cj * y[nd + oj] - li * ci * y[nd + oi]
        fc = M.coup_par[k, 0] * sep + M.coup_par[k, 1] * sepd
        torque[oi] += fc * li * ci
        torque[oj] -= fc * lj * cj
        dy[o_dc + k] = M.coup_par[k, 1] * sepd * sepd
    diss = 0.0
    o_pair = o_dc + nc + 6  # the state's size
    per_pair = dy.shape[0] == o_pair + 2 * npair
    if per_pair:
        dy[o_pair:] = 0.0
    for p in range(npair):
        if mode[p] == 0 and not smooth[p]:
            continue
        f, power, _, _, nx, ny, nz = pair_force(p, y, mode, v_onset, smooth, M)
        diss += power
        if per_pair:
            dy[o_pair + p] = f
            dy[o_pair + npair + p] = power
        if f != 0.0:
            add_force(y, M, M.pair_idx[p, 1], nd, f * nx, f * ny, f * nz, torque)
            add_force(y, M, M.pair_idx[p, 0], nd, -f * nx, -f * ny, -f * nz, torque)
    for i in range(n):
        o = M.dof[i]
        inertia = berry[i, 0] * berry[i, 2] * berry[i, 2]
        if M.dof[i + 1] - o == 1:
            dy[nd + o] = torque[o] / inertia
            continue
        s, sd, td = y[o], y[nd + o], y[nd + o + 1]
        ss, cs = math.sin(s), math.cos(s)
        tt = torque[o + 1]
        dy[nd + o] = torque[o] / inertia - ss * cs * td * td
        dy[nd + o + 1] = tt / (inertia * cs * cs) + 2.0 * (ss / cs) * sd * td
    dy[o_w - 1] = diss
    dy[o_w] = work
    dy[o_w + 1] = ax
    dy[o_w + 2] = az
    dy[o_w + 3] = y[o_w + 1]
    dy[o_w + 4] = y[o_w + 2]


@jit
def centres(y, M, pos):
    """Berry centres relative to the rachis (N, 3)."""
    b = M.berry
    nd = M.dof[b.shape[0]]
    for i in range(b.shape[0]):
        ux, uy, uz, _, _, _ = twig(y, M, i, nd)
        pos[i, 0] = b[i, 3] + b[i, 2] * ux
        pos[i, 1] = b[i, 6] + b[i, 2] * uy
        pos[i, 2] = b[i, 7] + b[i, 2] * uz


@inline
def push_pair(fext, i, j, f, nx, ny, nz):
    """The pair's force on both berries: +F n on j, −F n on i."""
    fext[i, 0] -= f * nx
    fext[i, 1] -= f * ny
    fext[i, 2] -= f * nz
    fext[j, 0] += f * nx
    fext[j, 1] += f * ny
    fext[j, 2] += f * nz


@jit
def coupling_loads(y, M, fext):
    """Reset the per-berry inter-berry forces fext (N, 3) to the coupling forces alone."""
    berry = M.berry
    nd = M.dof[berry.shape[0]]
    fext[:, :] = 0.0
    for k in range(M.coup_idx.shape[0]):
        i, j = M.coup_idx[k, 0], M.coup_idx[k, 1]
        oi, oj = M.dof[i], M.dof[j]
        li, lj = berry[i, 2], berry[j, 2]
        sep = lj * math.sin(y[oj]) - li * math.sin(y[oi])
        sepd = lj * math.cos(y[oj]) * y[nd + oj] - li * math.cos(y[oi]) * y[nd + oi]
        fc = M.coup_par[k, 0] * sep + M.coup_par[k, 1] * sepd
        fext[i, 0] += fc
        fext[j, 0] -= fc


@jit
def berry_forces(y, mode, v_onset, smooth, M, force, penetration, fext):
    """Per pair: force and penetration; per berry: the summed inter-berry force (contact and coupling)."""
    coupling_loads(y, M, fext)
    for p in range(M.pair_idx.shape[0]):
        if mode[p] == 0 and not smooth[p]:
            force[p] = 0.0
            penetration[p] = 0.0
            continue
        f, _, delta, _, nx, ny, nz = pair_force(p, y, mode, v_onset, smooth, M)
        force[p] = f
        penetration[p] = max(delta, 0.0)
        push_pair(fext, M.pair_idx[p, 0], M.pair_idx[p, 1], f, nx, ny, nz)


@jit
def pedicel_tension(y, ax, az, fext, M, out):
    """T_i = m l |u̇|² + m (g − a)·u + F_i·u: the radial balance of the berry (docs/model.md §5)."""
    berry = M.berry
    n = berry.shape[0]
    nd = M.dof[n]
    for i in range(n):
        m, l = berry[i, 0], berry[i, 2]
        ux, uy, uz, vx, vy, vz = twig(y, M, i, nd)
        out[i] = (m * l * (vx * vx + vy * vy + vz * vz) + m * (-ax * ux - (M.gravity + az) * uz)
                  + fext[i, 0] * ux + fext[i, 1] * uy + fext[i, 2] * uz)


@jit
def derived(ts, ys, modes, accs, v_onsets, smooths, M, force, penetration, tension, energy):
    """Post-process samples: contact force and penetration per pair, tension per berry and the
    energy terms [kinetic, gravity, hinge, coupling, contact elastic] per sample."""
    berry = M.berry
    n = berry.shape[0]
    nd = M.dof[n]
    npair = M.pair_idx.shape[0]
    fext = np.zeros((n, 3))
    pos = np.zeros((n, 3))
    for s in range(ts.shape[0]):
        y = ys[s]
        berry_forces(y, modes[s], v_onsets[s], smooths[s], M, force[s], penetration[s], fext)
        pedicel_tension(y, accs[s, 0], accs[s, 1], fext, M, tension[s])
        centres(y, M, pos)
        ke = 0.0
        vg = 0.0
        vh = 0.0
        for i in range(n):
            m, l = berry[i, 0], berry[i, 2]
            _, _, uz, vx, vy, vz = twig(y, M, i, nd)
            ke += 0.5 * m * l * l * (vx * vx + vy * vy + vz * vz)
            vg += m * M.gravity * l * (1.0 + uz)
            for k in range(M.dof[i], M.dof[i + 1]):
                e = y[k] - berry[i, 8 + k - M.dof[i]]
                vh += 0.5 * berry[i, 4] * e * e
        vc = 0.0
        for k in range(M.coup_idx.shape[0]):
            i, j = M.coup_idx[k, 0], M.coup_idx[k, 1]
            sep = berry[j, 2] * math.sin(y[M.dof[j]]) - berry[i, 2] * math.sin(y[M.dof[i]])
            vc += 0.5 * M.coup_par[k, 0] * sep * sep
        ve = 0.0
        for p in range(npair):
            i, j = M.pair_idx[p, 0], M.pair_idx[p, 1]
            d = math.sqrt((pos[j, 0] - pos[i, 0]) ** 2 + (pos[j, 1] - pos[i, 1]) ** 2 + (pos[j, 2] - pos[i, 2]) ** 2)
            ve += elastic_energy(M.pair_law[p], M.pair_par[p], berry[i, 1] + berry[j, 1] - d)
        energy[s, 0] = ke
        energy[s, 1] = vg
        energy[s, 2] = vh
        energy[s, 3] = vc
        energy[s, 4] = ve


@jit
def observe(y, mode, v_onset, smooth, ax, az, M, peak_force, peak_tension, fext, out):
    """Everything a co-simulation face reports after a step, in one compiled call, as one vector:
    [angles (D), angular velocities (D), pedicel tensions (N), contact forces (P), penetrations (P),
     in contact (P, 1.0 or 0.0), largest contact force so far, largest tension so far, energy dissipated]."""
    n = M.berry.shape[0]
    nd = M.dof[n]
    npair = M.pair_idx.shape[0]
    nc = M.coup_idx.shape[0]
    o = 2 * nd + n
    force = out[o: o + npair]
    pen = out[o + npair: o + 2 * npair]
    berry_forces(y, mode, v_onset, smooth, M, force, pen, fext)
    tension = out[2 * nd: o]
    pedicel_tension(y, ax, az, fext, M, tension)
    out[: 2 * nd] = y[: 2 * nd]
    peak_f = 0.0
    for p in range(npair):
        out[o + 2 * npair + p] = 1.0 if mode[p] != 0 else 0.0
        peak_f = max(peak_f, peak_force[p])
    peak_t = -np.inf
    for i in range(n):
        peak_t = max(peak_t, peak_tension[i], tension[i])
    dissipated = 0.0
    for k in range(2 * nd, 2 * nd + n + nc + 1):
        dissipated += y[k]
    o += 3 * npair
    out[o] = peak_f
    out[o + 1] = peak_t
    out[o + 2] = dissipated
