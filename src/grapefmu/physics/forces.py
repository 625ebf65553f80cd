"""Stage 2, forces (docs/model.md §2–3): every force on a berry as one Cartesian vector F_i in the
rachis frame (gravity and the rachis' inertial field, the k3/c3 coupling, contact), mapped to the
angles through the one generalized-force map Q = l Jᵀ R_z(−ψ) F; the hinge acts on the angles directly.

A contact pair carries a *mode* (§3): 0 apart, 1 loaded, 2 overlapping but unloaded. Inside a step
the mode is fixed, so the force is one smooth branch; a pair flagged `smooth` (the Zeno guard, or a
smooth law under step-size control) evaluates the clamped law inline instead.
"""
from __future__ import annotations

import math

import numpy as np

from ..model.contact import Law
from .compiled import inline
from .kinematics import contact_gap

#: the discrete contact state of a pair (part of the physical state)
CONTACT = np.dtype([("mode", "i8"),      # 0 apart, 1 loaded, 2 overlapping but unloaded
                    ("v_onset", "f8"),   # δ̇⁻, the approach speed at onset (Hunt–Crossley), m/s
                    ("smooth", "?")],    # the clamped law evaluated inline, no events
                   align=True)


@inline
def contact_law(law, k, c, clamp, delta, delta_dot, v_onset):
    """§3 table: (F, F_el, φ), the unclamped force, its elastic part and the sign function φ whose
    zero is where the clamped law unloads (φ ≡ 1 where the law cannot pull)."""
    if law == Law.KELVIN_VOIGT:
        f_el = k * delta
        f = f_el + c * delta_dot
        return f, f_el, (f if clamp else 1.0)
    dp = max(delta, 0.0)
    f_el = k * dp * math.sqrt(dp)
    if law == Law.HERTZ:
        return f_el, f_el, 1.0
    phi = 1.0 + c * delta_dot / v_onset
    return f_el * phi, f_el, (phi if clamp else 1.0)


@inline
def pair_law(pr, v_onset, delta, delta_dot):
    """contact_law with a pair's coefficients (pr, a PAIR record) and onset speed."""
    return contact_law(pr.law, pr.stiffness, pr.damping, pr.clamp, delta, delta_dot, v_onset)


@inline
def elastic_energy(pr, delta):
    """V_c(δ) = ∫F_el dδ (§3 table)."""
    if delta <= 0.0:
        return 0.0
    if pr.law == Law.KELVIN_VOIGT:
        return 0.5 * pr.stiffness * delta * delta
    return 0.4 * pr.stiffness * delta * delta * math.sqrt(delta)


@inline
def active(c):
    """Whether a pair (c, its CONTACT record) can push: in contact, or evaluated inline."""
    return c.mode != 0 or c.smooth


@inline
def pair_force(pr, c, delta, delta_dot):
    """The normal force a pair pushes with in its mode, and its dissipation power (F − F_el) δ̇."""
    f, f_el, phi = pair_law(pr, c.v_onset, delta, delta_dot)
    if c.smooth:
        if delta <= 0.0:
            f, f_el = 0.0, 0.0
        elif phi <= 0.0:
            f = 0.0
    elif c.mode == 2:
        f = 0.0
    return f, (f - f_el) * delta_dot


@inline
def hinge_torque(b, a, angle, rate):
    """The viscoelastic hinge on angle a of berry b: −k (q − q₀) − c q̇ (§2)."""
    return -b.hinge_stiffness * (angle - rest_angle(b, a)) - b.hinge_damping * rate


@inline
def rest_angle(b, a):
    """s₀ (a = 0) or t₀ (a = 1): where berry b's hinge exerts no torque."""
    return b.rest_swing if a == 0 else b.rest_tilt


@inline
def coupling(cp, bi, bj, ki, kj):
    """The k3/c3 spring–damper (cp, a COUPLING record) between berries bi, bj (stage 1 in ki, kj) on the
    change of horizontal separation s (§2): (force on i along x, s, ṡ)."""
    sep = bj.twig_length * kj.ux - bi.twig_length * ki.ux
    sep_dot = bj.twig_length * kj.dux - bi.twig_length * ki.dux
    return cp.stiffness * sep + cp.damping * sep_dot, sep, sep_dot


@inline
def forces(ax, az, contacts, M, W, pairs, n_pairs):
    """Stage 2: F_i of every berry into W.berry[i] (fx, fy, fz; needs stage 1 there). Contact is evaluated for
    the first n_pairs entries of `pairs` (every pair that can push must be among them); the k-th one's
    force and dissipation power go to W.pair[k], each coupling's c3 ṡ² to W.coupling_power.
    Returns the total contact dissipation power and the power of the obstacles on the berries as the rachis
    moves past them (§7: F n·ḃ per berry–obstacle contact, the ledger's share of the base's work)."""
    g = M.gravity
    berry, kin = M.berry, W.berry
    for i in range(berry.shape[0]):
        m = berry[i].mass
        k = kin[i]
        k.fx = -m * ax  # gravity and the rachis' inertial field m (g⃗ − a)
        k.fy = 0.0
        k.fz = -m * (g + az)
    for k in range(M.coupling.shape[0]):
        cp = M.coupling[k]
        fc, _, sep_dot = coupling(cp, berry[cp.i], berry[cp.j], kin[cp.i], kin[cp.j])
        kin[cp.i].fx += fc
        kin[cp.j].fx -= fc
        W.coupling_power[k] = cp.damping * sep_dot * sep_dot
    diss = 0.0
    work = 0.0
    nb = berry.shape[0]
    for kk in range(n_pairs):
        p = pairs[kk]
        c = contacts[p]
        out = W.pair[kk]
        if not active(c):
            out.force = 0.0
            out.power = 0.0
            continue
        pr = M.pair[p]
        delta, delta_dot, nx, ny, nz = contact_gap(M, pr, kin)
        f, power = pair_force(pr, c, delta, delta_dot)
        out.force = f
        out.power = power
        diss += power
        if f != 0.0:
            ki = kin[pr.i]  # −F n on i, +F n on j (an obstacle takes it)
            ki.fx -= f * nx
            ki.fy -= f * ny
            ki.fz -= f * nz
            if pr.j < nb:
                kj = kin[pr.j]
                kj.fx += f * nx
                kj.fy += f * ny
                kj.fz += f * nz
            elif not M.obstacle[pr.j - nb].attached:  # one fixed in the world moves past the berries
                work += f * (nx * (ki.wvx - ki.vx) + nz * (ki.wvz - ki.vz))  # F n·ḃ
    return diss, work


@inline
def generalized_forces(b, k):
    """(Q_s, Q_t) = l Jᵀ R_z(−ψ) F for berry b with stage 1–2 in k (§2: J_s, J_t; J = (cos s, 0, sin s)
    planar, Q_t = 0)."""
    l = b.twig_length
    ss, cs, st, ct = k.sin_s, k.cos_s, k.sin_t, k.cos_t
    fx, fy, fz = k.fx, k.fy, k.fz
    if b.n_angles == 1:
        return l * (cs * fx + ss * fz), 0.0
    ca, sa = b.azimuth_cos, b.azimuth_sin
    lx, ly = ca * fx + sa * fy, -sa * fx + ca * fy
    return l * (cs * lx + st * ss * ly + ct * ss * fz), l * cs * (-ct * ly + st * fz)


@inline
def pedicel_tension(b, k):
    """§5: T = m l |u̇|² + F·u, the berry's radial balance (F includes m (g⃗ − a))."""
    return b.mass * b.twig_length * (k.dux * k.dux + k.duy * k.duy + k.duz * k.duz) + k.fx * k.ux + k.fy * k.uy \
        + k.fz * k.uz
