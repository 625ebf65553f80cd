"""Stage 1, kinematics (docs/model.md §1): the rachis frame (its pose R, b and twist ḃ, ω), twig directions,
berry positions and velocities (in the rachis frame and in the world frame, x = b + R p), and the gap of a
contact pair (two berries, or a berry and an obstacle: §7), each computed once per evaluation into a
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
from ..model.excitation import rotation_matrix
from ..model.model import BOX, PLANE
from .layout import model_head, model_offsets

#: what stage 1 (and stage 2's force) computes per berry, rachis frame
KINEMATICS = np.dtype([(f, "f8") for f in (
    "sin_s", "cos_s", "sin_t", "cos_t",   # of swing s and tilt t (t = 0 for a planar berry)
    "ux", "uy", "uz",                     # twig direction u
    "dux", "duy", "duz",                  # u̇, 1/s
    "px", "py", "pz",                     # position p = h + l u, m
    "vx", "vy", "vz",                     # velocity ṗ = l u̇, m/s
    "wx", "wy", "wz",                     # position in the world frame b + R p, m
    "wvx", "wvy", "wvz",                  # velocity in the world frame ḃ + R (ω_r × p + ṗ), m/s
    "fx", "fy", "fz")],                   # F: every force on the berry but its hinge's, N (stage 2)
    align=True)
#: what stage 2 computes per evaluated pair
PAIR_FORCE = np.dtype([("force", "f8"), ("power", "f8")])   # normal force N, dissipation (F − F_el) δ̇ W


class Frame(NamedTuple):
    """The rachis frame at one instant: R (world from rachis, row-major), the origin b and its velocity ḃ (world),
    ω in the rachis frame, and `turned` (1.0 when R ≠ I or ω ≠ 0: else the world frame is the rachis frame
    shifted by b, and stage 1 skips the rotation)."""

    r00: float
    r01: float
    r02: float
    r10: float
    r11: float
    r12: float
    r20: float
    r21: float
    r22: float
    bx: float
    by: float
    bz: float
    vx: float
    vy: float
    vz: float
    ox: float
    oy: float
    oz: float
    turned: float


_rotation = inline(rotation_matrix)


@inline
def rachis_frame(y, M):
    """The rachis frame y holds (physics/layout.py): R from the orientation quaternion (normalised here: the
    integrator carries it only to its tolerance), ω turned into the rachis frame, ω_r = Rᵀ ω."""
    o_bv, o_b, o_om, o_rot = model_offsets(M)[:4]
    if not M.moving:
        return Frame(1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    if not M.turning:
        return Frame(1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, y[o_b], y[o_b + 1], y[o_b + 2],
                     y[o_bv], y[o_bv + 1], y[o_bv + 2], 0.0, 0.0, 0.0, 0.0)
    qx, qy, qz, qw = y[o_rot], y[o_rot + 1], y[o_rot + 2], y[o_rot + 3]
    wx, wy, wz = y[o_om], y[o_om + 1], y[o_om + 2]
    if qx == 0.0 and qy == 0.0 and qz == 0.0 and wx == 0.0 and wy == 0.0 and wz == 0.0:
        return Frame(1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, y[o_b], y[o_b + 1], y[o_b + 2],
                     y[o_bv], y[o_bv + 1], y[o_bv + 2], 0.0, 0.0, 0.0, 0.0)
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = _rotation(qx, qy, qz, qw)
    return Frame(r00, r01, r02, r10, r11, r12, r20, r21, r22, y[o_b], y[o_b + 1], y[o_b + 2],
                 y[o_bv], y[o_bv + 1], y[o_bv + 2],
                 r00 * wx + r10 * wy + r20 * wz, r01 * wx + r11 * wy + r21 * wz, r02 * wx + r12 * wy + r22 * wz, 1.0)


@inline
def to_rachis(fr, x, y, z):
    """Rᵀ v: a world vector in the rachis frame."""
    return (fr.r00 * x + fr.r10 * y + fr.r20 * z, fr.r01 * x + fr.r11 * y + fr.r21 * z,
            fr.r02 * x + fr.r12 * y + fr.r22 * z)


@inline
def to_world(fr, x, y, z):
    """R v: a rachis-frame vector in the world frame."""
    return (fr.r00 * x + fr.r01 * y + fr.r02 * z, fr.r10 * x + fr.r11 * y + fr.r12 * z,
            fr.r20 * x + fr.r21 * y + fr.r22 * z)


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


#: sin and cos from a table on a grid of 1/16 rad over |x| ≤ 16 rad (`sincos`)
TRIG_GRID = 16.0
TRIG_POINTS = 256
TRIG = np.array([(math.sin(k / TRIG_GRID), math.cos(k / TRIG_GRID)) for k in range(-TRIG_POINTS, TRIG_POINTS + 1)])


@inline
def sincos(x):
    """(sin x, cos x) to within 2.5e-16: x = g + d with g the nearest point of TRIG's grid and |d| ≤ 1/32, then
    sin x = sin g cos d + cos g sin d by Taylor series in d whose first terms left out are below 1e-19 (libm
    beyond the table, and for NaN). A pure function of x, so results do not depend on what was evaluated
    before. Every angle on every stage and sample passes here: libm's sincos (11 ns against 6) was a quarter of
    a 100-berry cluster's run."""
    if abs(x) <= TRIG_POINTS / TRIG_GRID:
        i = int(x * TRIG_GRID + (TRIG_POINTS + 0.5))  # the nearest point's index: the sum is > 0, int() floors it
        d = x - (i - TRIG_POINTS) * (1.0 / TRIG_GRID)  # exact where x is within a factor 2 of it
        sg, cg = TRIG[i, 0], TRIG[i, 1]
        d2 = d * d
        sd = d + d * d2 * (-1.0 / 6.0 + d2 * (1.0 / 120.0 + d2 * (-1.0 / 5040.0)))
        cd = 1.0 + d2 * (-0.5 + d2 * (1.0 / 24.0 + d2 * (-1.0 / 720.0 + d2 * (1.0 / 40320.0))))
        return sg * cd + cg * sd, cg * cd - sg * sd
    return math.sin(x), math.cos(x)


@inline
def berry_kinematics(b, k, s, sd, t, td, fr):
    """§1 for berry b (a BERRY record): trig, u, u̇, p and ṗ into k (a KINEMATICS record) from its swing s,
    tilt t (ignored for a planar berry: t and ṫ are then any numbers) and their rates, and the world frame's
    x = b + R p, ẋ = ḃ + R (ω × p + ṗ) from the rachis frame fr (a Frame). Records and numbers only: an array
    handed to an inlined function costs two reference counts per call."""
    ss, cs = sincos(s)
    if b.n_angles == 1:
        st, ct = 0.0, 1.0
        ux, uy, uz = ss, 0.0, -cs
        vx, vy, vz = cs * sd, 0.0, ss * sd
    else:
        st, ct = sincos(t)
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
    if fr.turned == 0.0:
        k.wx, k.wy, k.wz = k.px + fr.bx, k.py + fr.by, k.pz + fr.bz
        k.wvx, k.wvy, k.wvz = k.vx + fr.vx, k.vy + fr.vy, k.vz + fr.vz
        return
    px, py, pz = to_world(fr, k.px, k.py, k.pz)
    k.wx, k.wy, k.wz = px + fr.bx, py + fr.by, pz + fr.bz
    ex = fr.oy * k.pz - fr.oz * k.py + k.vx  # ω × p + ṗ, rachis frame
    ey = fr.oz * k.px - fr.ox * k.pz + k.vy
    ez = fr.ox * k.py - fr.oy * k.px + k.vz
    vx, vy, vz = to_world(fr, ex, ey, ez)
    k.wvx, k.wvy, k.wvz = vx + fr.vx, vy + fr.vy, vz + fr.vz


@inline
def kinematics(y, M, kin):
    """Stage 1 for every berry into kin ((N,) KINEMATICS); returns the rachis Frame."""
    berry = M.berry
    nd = M.n_dof
    fr = rachis_frame(y, M)
    for i in range(berry.shape[0]):
        o = berry[i].dof  # a planar berry ignores t: y[o + 1] is then the next angle (y runs on past q̇)
        berry_kinematics(berry[i], kin[i], y[o], y[nd + o], y[o + 1], y[nd + o + 1], fr)
    return fr


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
    in the rachis frame for an obstacle attached to the gripper, and the normal is in that frame; the obstacle
    does not move in its frame, so δ̇ = −m·(the berry's velocity there).

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
    obstacle j − N. n is in the rachis frame, but in the world frame for an obstacle fixed there."""
    nb = M.berry.shape[0]
    if pr.j < nb:
        return pair_gap(M.berry[pr.i], M.berry[pr.j], kin[pr.i], kin[pr.j])
    return obstacle_gap(M.berry[pr.i], kin[pr.i], M.obstacle[pr.j - nb])


@inline
def fixed_in_world(M, pr):
    """Whether pair pr's body j is an obstacle fixed in the world (its gap's normal is then in the world frame)."""
    nb = M.berry.shape[0]
    return pr.j >= nb and not M.obstacle[pr.j - nb].attached


@jit
def pair_state(y, M, pr, kin):
    """Stage 1 for one pair alone (the event search's root finding needs no other berry), then its gap."""
    berry = M.berry
    nd = M.n_dof
    fr = rachis_frame(y, M)
    for i in (pr.i, pr.j):
        if i < berry.shape[0]:
            o = berry[i].dof
            berry_kinematics(berry[i], kin[i], y[o], y[nd + o], y[o + 1], y[nd + o + 1], fr)
    return contact_gap(M, pr, kin)


def _padded(y, M):
    """y = [q | q̇] (or longer) padded with a resting rachis at the origin (world frame = rachis frame)."""
    head = model_head.py_func(M)
    out = np.zeros(max(len(y), head))
    out[: len(y)] = y
    if len(y) < head and M.turning:
        out[head - 1] = 1.0  # the orientation quaternion's w
    return out


def positions(y, M, out):
    """Berry centres p_i (N, 3) in the rachis frame at y = [q | q̇ | ...], for callers outside the compiled core."""
    _positions(_padded(y, M), M, out)


def penetrations(y, M, out):
    """δ of every candidate pair (P,) at y = [q | q̇ | ...] (negative: apart), for callers outside the compiled core."""
    _penetrations(_padded(y, M), M, out)


def overlaps(y, M) -> np.ndarray:
    """δ of every candidate pair at y, m (penetrations, into a new array)."""
    out = np.empty(M.pair.shape[0])
    penetrations(y, M, out)
    return out


def deepest_overlap(delta: np.ndarray, bound: np.ndarray) -> tuple[int, int, float, float] | None:
    """(row, pair, δ, bound) of the overlap in delta (rows of every pair's δ, m: states or samples) that passes its
    pair's bound (m, (P,): a fraction of Model.contact_radius) by the most, or None."""
    if not delta.size:
        return None
    excess = delta - bound
    k, p = divmod(int(excess.argmax()), excess.shape[1])
    return (k, p, float(delta[k, p]), float(bound[p])) if excess[k, p] > 0.0 else None


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
