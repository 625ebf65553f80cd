"""Stage 1, kinematics (docs/model.md §1): twig directions, berry positions and velocities (in the rachis
frame and in the world frame, which the rachis' displacement b separates), and the gap of a contact pair
(two berries, or a berry and an obstacle fixed in the world: §7), each computed once per evaluation into a
`Workspace`.

A planar berry has one angle s (its swing in the x–z plane); a spherical one has swing s and tilt t
in its twig's own frame, turned by the azimuth ψ about z:

    u_local = (sin s, −sin t cos s, −cos t cos s),  u = R_z(ψ) u_local,  p = h + l u,  ṗ = l u̇.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from .compiled import inline, jit
from ..model.model import BOX, PLANE
from .layout import model_offsets

#: what stage 1 (and stage 2's force) computes per berry, rachis frame
KINEMATICS = np.dtype([(f, "f8") for f in (
    "sin_s", "cos_s", "sin_t", "cos_t",   # of swing s and tilt t (t = 0 for a planar berry)
    "ux", "uy", "uz",                     # twig direction u
    "dux", "duy", "duz",                  # u̇, 1/s
    "px", "py", "pz",                     # position p = h + l u, m
    "vx", "vy", "vz",                     # velocity ṗ = l u̇, m/s
    "wx", "wy", "wz",                     # position in the world frame p + b, m
    "wvx", "wvy", "wvz",                  # velocity in the world frame ṗ + ḃ, m/s
    "fx", "fy", "fz")],                   # F: every force on the berry but its hinge's, N (stage 2)
    align=True)
#: what stage 2 computes per evaluated pair
PAIR_FORCE = np.dtype([("force", "f8"), ("power", "f8")])   # normal force N, dissipation (F − F_el) δ̇ W


class Workspace(NamedTuple):
    """What one evaluation's stages compute, each once (MuJoCo's mjData quantities of one forward pass)."""

    berry: np.ndarray           # (N,) KINEMATICS
    torque: np.ndarray          # (D,) generalized forces Q, N·m
    pair: np.ndarray            # (P,) PAIR_FORCE of the k-th evaluated pair
    coupling_power: np.ndarray  # (C,) c3 ṡ² of each coupling, W


@jit
def workspace(M) -> Workspace:
    return Workspace(np.zeros(M.berry.shape[0], dtype=KINEMATICS), np.zeros(M.n_dof),
                     np.zeros(M.pair.shape[0], dtype=PAIR_FORCE), np.zeros(M.coupling.shape[0]))


@inline
def berry_kinematics(b, k, s, sd, t, td, bx, bz, vbx, vbz):
    """§1 for berry b (a BERRY record): trig, u, u̇, p and ṗ into k (a KINEMATICS record) from its swing s,
    tilt t (ignored for a planar berry: t and ṫ are then any numbers) and their rates, and the world frame's
    p + b, ṗ + ḃ from the rachis displacement (bx, bz) and velocity (vbx, vbz). Records and numbers only: an
    array handed to an inlined function costs two reference counts per call."""
    ss, cs = math.sin(s), math.cos(s)
    if b.n_angles == 1:
        st, ct = 0.0, 1.0
        ux, uy, uz = ss, 0.0, -cs
        vx, vy, vz = cs * sd, 0.0, ss * sd
    else:
        st, ct = math.sin(t), math.cos(t)
        lx, ly, uz = ss, -st * cs, -ct * cs
        wx, wy, vz = cs * sd, st * ss * sd - ct * cs * td, ct * ss * sd + st * cs * td
        ca, sa = b.azimuth_cos, b.azimuth_sin
        ux, uy = ca * lx - sa * ly, sa * lx + ca * ly
        vx, vy = ca * wx - sa * wy, sa * wx + ca * wy
    k.sin_s, k.cos_s, k.sin_t, k.cos_t = ss, cs, st, ct
    k.ux, k.uy, k.uz = ux, uy, uz
    k.dux, k.duy, k.duz = vx, vy, vz
    l = b.twig_length
    k.px, k.py, k.pz = b.hinge_x + l * ux, b.hinge_y + l * uy, b.hinge_z + l * uz
    k.vx, k.vy, k.vz = l * vx, l * vy, l * vz
    k.wx, k.wy, k.wz = k.px + bx, k.py, k.pz + bz
    k.wvx, k.wvy, k.wvz = k.vx + vbx, k.vy, k.vz + vbz


@inline
def rachis_motion(y, M):
    """(b_x, b_z, ḃ_x, ḃ_z): the rachis displacement and velocity the state y holds (physics/layout.py)."""
    o_bv, o_b = model_offsets(M)[:2]
    return y[o_b], y[o_b + 1], y[o_bv], y[o_bv + 1]


@inline
def kinematics(y, M, kin):
    """Stage 1 for every berry into kin ((N,) KINEMATICS)."""
    berry = M.berry
    nd = M.n_dof
    bx, bz, vbx, vbz = rachis_motion(y, M)
    for i in range(berry.shape[0]):
        o = berry[i].dof  # a planar berry ignores t: y[o + 1] is then the next angle (y runs on past q̇)
        berry_kinematics(berry[i], kin[i], y[o], y[nd + o], y[o + 1], y[nd + o + 1], bx, bz, vbx, vbz)


@inline
def pair_gap(bi, bj, ki, kj):
    """§1: penetration δ = r_i + r_j − |p_j − p_i|, its rate δ̇ and the unit normal n from i to j
    (bi, bj BERRY records; ki, kj their KINEMATICS)."""
    dx = kj.px - ki.px
    dy = kj.py - ki.py
    dz = kj.pz - ki.pz
    d = math.sqrt(dx * dx + dy * dy + dz * dz)
    if d > 1e-15:
        nx, ny, nz = dx / d, dy / d, dz / d
    else:
        nx, ny, nz = 1.0, 0.0, 0.0
    vx = kj.vx - ki.vx
    vy = kj.vy - ki.vy
    vz = kj.vz - ki.vz
    delta = bi.radius + bj.radius - d
    delta_dot = -(nx * vx + ny * vy + nz * vz)
    return delta, delta_dot, nx, ny, nz


@inline
def obstacle_gap(b, k, ob):
    """§7: penetration δ of berry b (its KINEMATICS k) into obstacle ob (an OBSTACLE record), its rate δ̇ and the
    normal from the berry toward the obstacle, −m (m: the obstacle's outward normal at the nearest point, so
    the pair's rule "−F n on its first body" pushes the berry out). The berry is taken in the world frame, or
    in the rachis frame for an obstacle attached to the gripper; the obstacle does not move in its frame, so
    δ̇ = −m·(the berry's velocity there).

    plane: δ = r − m·(x − p); box: δ = r − |x − nearest point| outside, r + (depth to the nearest face) inside;
    capsule: δ = r + ρ − |x − nearest point of its axis|."""
    if ob.attached:
        x, y, z, vx, vy, vz = k.px, k.py, k.pz, k.vx, k.vy, k.vz
    else:
        x, y, z, vx, vy, vz = k.wx, k.wy, k.wz, k.wvx, k.wvy, k.wvz
    dx, dy, dz = x - ob.px, y - ob.py, z - ob.pz
    if ob.kind == PLANE:
        mx, my, mz = ob.ux, ob.uy, ob.uz
        delta = b.radius - (mx * dx + my * dy + mz * dz)
    elif ob.kind == BOX:
        c, s = ob.cos_yaw, ob.sin_yaw
        lx, ly, lz = c * dx + s * dy, -s * dx + c * dy, dz  # in the box's axes
        ex = lx - min(max(lx, -ob.hx), ob.hx)
        ey = ly - min(max(ly, -ob.hy), ob.hy)
        ez = lz - min(max(lz, -ob.hz), ob.hz)
        d = math.sqrt(ex * ex + ey * ey + ez * ez)
        if d > 0.0:
            ax, ay, az = ex / d, ey / d, ez / d
            delta = b.radius - d
        else:  # the centre inside: out through the nearest face
            fx, fy, fz = ob.hx - abs(lx), ob.hy - abs(ly), ob.hz - abs(lz)
            if fx <= fy and fx <= fz:
                ax, ay, az, depth = math.copysign(1.0, lx), 0.0, 0.0, fx
            elif fy <= fz:
                ax, ay, az, depth = 0.0, math.copysign(1.0, ly), 0.0, fy
            else:
                ax, ay, az, depth = 0.0, 0.0, math.copysign(1.0, lz), fz
            delta = b.radius + depth
        mx, my, mz = c * ax - s * ay, s * ax + c * ay, az
    else:  # CAPSULE
        uu = ob.ux * ob.ux + ob.uy * ob.uy + ob.uz * ob.uz
        t = min(max((dx * ob.ux + dy * ob.uy + dz * ob.uz) / uu, 0.0), 1.0)
        ex, ey, ez = dx - t * ob.ux, dy - t * ob.uy, dz - t * ob.uz
        d = math.sqrt(ex * ex + ey * ey + ez * ez)
        if d > 1e-15:
            mx, my, mz = ex / d, ey / d, ez / d
        else:
            mx, my, mz = 0.0, 0.0, 1.0
        delta = b.radius + ob.radius - d
    return delta, -(mx * vx + my * vy + mz * vz), -mx, -my, -mz


@inline
def contact_gap(M, pr, kin):
    """(δ, δ̇, n) of contact pair pr (a PAIR record) from stage 1 in kin: its body j is a berry (j < N) or
    obstacle j − N."""
    nb = M.berry.shape[0]
    if pr.j < nb:
        return pair_gap(M.berry[pr.i], M.berry[pr.j], kin[pr.i], kin[pr.j])
    return obstacle_gap(M.berry[pr.i], kin[pr.i], M.obstacle[pr.j - nb])


@jit
def pair_state(y, M, pr, kin):
    """Stage 1 for one pair alone (the event search's root finding needs no other berry), then its gap."""
    berry = M.berry
    nd = M.n_dof
    bx, bz, vbx, vbz = rachis_motion(y, M)
    for i in (pr.i, pr.j):
        if i < berry.shape[0]:
            o = berry[i].dof
            berry_kinematics(berry[i], kin[i], y[o], y[nd + o], y[o + 1], y[nd + o + 1], bx, bz, vbx, vbz)
    return contact_gap(M, pr, kin)


def _padded(y, M):
    """y = [q | q̇] (or longer) padded with a resting rachis at the origin (world frame = rachis frame)."""
    out = np.zeros(max(len(y), 2 * M.n_dof + 4))
    out[: len(y)] = y
    return out


def positions(y, M, out):
    """Berry centres p_i (N, 3) in the rachis frame at y = [q | q̇ | ...], for callers outside the compiled core."""
    _positions(_padded(y, M), M, out)


def penetrations(y, M, out):
    """δ of every candidate pair (P,) at y = [q | q̇ | ...] (negative: apart), for callers outside the compiled core."""
    _penetrations(_padded(y, M), M, out)


@jit
def _positions(y, M, out):
    kin = np.zeros(M.berry.shape[0], dtype=KINEMATICS)
    kinematics(y, M, kin)
    for i in range(kin.shape[0]):
        out[i, 0], out[i, 1], out[i, 2] = kin[i].px, kin[i].py, kin[i].pz


@jit
def _penetrations(y, M, out):
    kin = np.zeros(M.berry.shape[0], dtype=KINEMATICS)
    kinematics(y, M, kin)
    for p in range(M.pair.shape[0]):
        out[p] = contact_gap(M, M.pair[p], kin)[0]
