"""Stage 2, forces (docs/model.md §2–3): every force on a berry as one Cartesian vector F_i in the
rachis frame (gravity and the moving frame's fields, the k3/c3 coupling, contact), mapped to the
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
from .kinematics import contact_gap, fixed_in_world, to_rachis

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
def forces(acc, fr, contacts, M, W, pairs, n_pairs):
    """Stage 2: F_i of every berry into W.berry[i] (fx, fy, fz; needs stage 1 there and its Frame fr) under the
    rachis acceleration acc (a, α: ACCEL_COMPONENTS, world frame). Contact is evaluated for the first n_pairs
    entries of `pairs` (every pair that can push must be among them); the k-th one's force and dissipation
    power go to W.pair[k], each coupling's c3 ṡ² to W.coupling_power.
    Returns the total contact dissipation power and the base's power (§5): the frame's fields on the berries'
    motion relative to the rachis, and the obstacles fixed in the world on the berries as the rachis carries
    them past (§7: F n·(ḃ + ω × p) per berry–obstacle contact)."""
    berry, kin = M.berry, W.berry
    fields = frame_fields(acc, fr, M.gravity)
    work = 0.0
    for i in range(berry.shape[0]):
        work = field_force(berry[i].mass, kin[i], fields, fr, M.gravity, work)
    for k in range(M.coupling.shape[0]):
        sep_dot = coupling_push(M.coupling[k], berry, kin)
        W.coupling_power[k] = M.coupling[k].damping * sep_dot * sep_dot
    diss = 0.0
    for kk in range(n_pairs):
        p = pairs[kk]
        c = contacts[p]
        out = W.pair[kk]
        if not active(c):
            out.force = 0.0
            out.power = 0.0
            continue
        f, power, work = contact_push(M, M.pair[p], c, kin, fr, work)
        out.force = f
        out.power = power
        diss += power
    return diss, work


@inline
def berry_force(i, acc, fr, contacts, M, kin, pairs, n_pairs):
    """F_i of berry i alone into kin[i], as forces() computes it (the same terms in the same order, so the same
    number): needs stage 1 of berry i and of the berries that push it (its couplings, its pairs in contact among
    the first n_pairs of `pairs`). Their F gets its share too, which is not theirs whole: read kin[i] alone. A
    berry's peak tension is refined on it (solver/sampling.py), where forces() would cost every berry."""
    fields = frame_fields(acc, fr, M.gravity)
    field_force(M.berry[i].mass, kin[i], fields, fr, M.gravity, 0.0)
    for k in range(M.coupling.shape[0]):
        cp = M.coupling[k]
        if cp.i == i or cp.j == i:
            coupling_push(cp, M.berry, kin)
    for kk in range(n_pairs):
        p = pairs[kk]
        pr = M.pair[p]
        if (pr.i == i or pr.j == i) and active(contacts[p]):
            contact_push(M, pr, contacts[p], kin, fr, 0.0)


@inline
def frame_fields(acc, fr, g):
    """The fields of the moving rachis frame per unit mass, (e_x, e_y, e_z, α_x, α_y, α_z, spinning): g⃗ − a less the
    frame's own gravity (0, 0, −g), which field_force adds, and α, in the rachis frame; `spinning` when ω or α is not
    zero (Euler, centrifugal and Coriolis terms)."""
    if fr.turned == 0.0:  # R = I, ω = 0: the fields of a translating rachis (and α, which turns it from rest)
        ex, ey, ez = -acc[0], -acc[1], -acc[2]
        alx, aly, alz = acc[3], acc[4], acc[5]
    else:
        ax, ay, az = to_rachis(fr, acc[0], acc[1], acc[2])
        gx, gy, gz = to_rachis(fr, 0.0, 0.0, -g)
        ex, ey, ez = gx - ax, gy - ay, gz + g - az  # the field g⃗ − a, less the rachis-frame gravity (0, 0, −g)
        alx, aly, alz = to_rachis(fr, acc[3], acc[4], acc[5])
    spinning = fr.ox != 0.0 or fr.oy != 0.0 or fr.oz != 0.0 or alx != 0.0 or aly != 0.0 or alz != 0.0
    return ex, ey, ez, alx, aly, alz, spinning


@inline
def field_force(m, k, fields, fr, g, work):
    """F of a berry of mass m (stage 1 in k) from gravity and the frame's fields (frame_fields), into k; returns
    work plus the fields' power on its motion relative to the rachis."""
    ex, ey, ez, alx, aly, alz, spinning = fields
    ox, oy, oz = fr.ox, fr.oy, fr.oz
    fx, fy, fz = ex, ey, ez
    if spinning:  # Euler −α × p, centrifugal −ω × (ω × p); Coriolis −2 ω × ṗ below (it does no work)
        px, py, pz = k.px, k.py, k.pz
        cx, cy, cz = oy * pz - oz * py, oz * px - ox * pz, ox * py - oy * px
        fx -= aly * pz - alz * py + oy * cz - oz * cy
        fy -= alz * px - alx * pz + oz * cx - ox * cz
        fz -= alx * py - aly * px + ox * cy - oy * cx
    work += m * (fx * k.vx + fy * k.vy + fz * k.vz)
    k.fx = m * fx
    k.fy = m * fy
    k.fz = m * (fz - g)
    if spinning:
        k.fx -= 2.0 * m * (oy * k.vz - oz * k.vy)
        k.fy -= 2.0 * m * (oz * k.vx - ox * k.vz)
        k.fz -= 2.0 * m * (ox * k.vy - oy * k.vx)
    return work


@inline
def coupling_push(cp, berry, kin):
    """A coupling's force into its two berries' F (stage 1 in kin); returns its ṡ."""
    fc, _, sep_dot = coupling(cp, berry[cp.i], berry[cp.j], kin[cp.i], kin[cp.j])
    kin[cp.i].fx += fc
    kin[cp.j].fx -= fc
    return sep_dot


@inline
def contact_push(M, pr, c, kin, fr, work):
    """An active pair's force into its berries' F (−F n on i, +F n on j; an obstacle takes it): (F, its dissipation
    power, work plus the base's power through an obstacle fixed in the world)."""
    delta, delta_dot, nx, ny, nz = contact_gap(M, pr, kin)
    f, power = pair_force(pr, c, delta, delta_dot)
    if f != 0.0:
        ki = kin[pr.i]
        if fixed_in_world(M, pr):  # the normal of an obstacle fixed in the world is in the world frame
            # F n·(ẋ − R ṗ): the obstacle's push on the berry as the rachis carries it, ḃ + R (ω × p)
            work += f * (nx * ki.wvx + ny * ki.wvy + nz * ki.wvz)
            nx, ny, nz = to_rachis(fr, nx, ny, nz)
            work -= f * (nx * ki.vx + ny * ki.vy + nz * ki.vz)
        ki.fx -= f * nx
        ki.fy -= f * ny
        ki.fz -= f * nz
        if pr.j < M.berry.shape[0]:
            kj = kin[pr.j]
            kj.fx += f * nx
            kj.fy += f * ny
            kj.fz += f * nz
    return f, power, work


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
    """§5: T = m l |u̇|² + F·u, the berry's radial balance (F includes gravity and the frame's fields)."""
    return b.mass * b.twig_length * (k.dux * k.dux + k.duy * k.duy + k.duz * k.duz) + k.fx * k.ux + k.fy * k.uy \
        + k.fz * k.uz
