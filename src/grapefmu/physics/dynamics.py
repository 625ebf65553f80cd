"""Stage 3, accelerations, and the whole right-hand side (docs/model.md §4).

rhs runs the stages in order, each computing its quantities once (like MuJoCo's mj_forward):
the rachis' acceleration → kinematics → forces → generalized forces → accelerations, plus the rachis' own
motion (ḃ, b, ω and its orientation) and the rates of the energy integrals that ride along in y
(physics/layout.py).
"""
from __future__ import annotations

import numpy as np

from .compiled import inline, jit
from ..model.excitation import constant
from .excitation import applied_accel, held
from .forces import forces, generalized_forces, hinge_torque
from .kinematics import kinematics, workspace
from .layout import model_offsets, offsets


@jit
def rhs(t, t_ref, y, dy, contacts, M, X, inp, W, pairs, n_pairs):
    """dy/dt. Lagrange's equations: m l² s̈ = Q_s (planar); m l² s̈ + m l² sin s cos s ṫ² = Q_s and
    m l² cos² s ẗ − 2 m l² cos s sin s ṡ ṫ = Q_t (spherical), with Q from every force (the moving frame's fields
    among them, docs/model.md §2a) and the hinge; then the rachis' own motion and the energy integrals' rates.

    Contact is evaluated for the first n_pairs entries of `pairs` (the broad phase's near list holds
    every pair that can push). A dy longer than the state by 2P also gets each pair's force and
    dissipation power at its end: the scipy reference integrates those per pair, the event solver by
    quadrature."""
    berry, kin, torque = M.berry, W.berry, W.torque
    n = berry.shape[0]
    nd = M.n_dof
    nc = M.coupling.shape[0]
    npair = M.pair.shape[0]
    acc = applied_accel(X, inp, t, t_ref)
    fr = kinematics(y, M, kin)
    diss, work = forces(acc, fr, contacts, M, W, pairs, n_pairs)
    o_bv, o_b, o_om, o_rot, o_dh, o_dc, o_contact, o_w, size = model_offsets(M)
    for i in range(n):
        b, k = berry[i], kin[i]
        o = b.dof
        rate2 = 0.0
        q_s, q_t = generalized_forces(b, k)
        for a in range(b.n_angles):
            qd = y[nd + o + a]
            dy[o + a] = qd
            torque[o + a] = hinge_torque(b, a, y[o + a], qd) + (q_s if a == 0 else q_t)
            rate2 += qd * qd
        dy[o_dh + i] = b.hinge_damping * rate2
    for i in range(n):  # accelerations: the diagonal mass matrix m l² (1, cos² s) and the velocity terms
        b = berry[i]
        o = b.dof
        inertia = b.mass * b.twig_length * b.twig_length
        if b.n_angles == 1:
            dy[nd + o] = torque[o] / inertia
            continue
        ss, cs = kin[i].sin_s, kin[i].cos_s
        sd, td = y[nd + o], y[nd + o + 1]
        dy[nd + o] = torque[o] / inertia - ss * cs * td * td
        dy[nd + o + 1] = torque[o + 1] / (inertia * cs * cs) + 2.0 * (ss / cs) * sd * td
    for k in range(nc):
        dy[o_dc + k] = W.coupling_power[k]
    o_pair = size
    if dy.shape[0] == o_pair + 2 * npair:
        dy[o_pair:] = 0.0
        for kk in range(n_pairs):
            dy[o_pair + pairs[kk]] = W.pair[kk].force
            dy[o_pair + npair + pairs[kk]] = W.pair[kk].power
    dy[o_contact] = diss
    dy[o_w] = work
    if not M.moving:
        return
    for a in range(3):
        dy[o_bv + a] = acc[a]
        dy[o_b + a] = y[o_bv + a]
    if not M.turning:
        return
    for a in range(3):
        dy[o_om + a] = acc[3 + a]
    wx, wy, wz = y[o_om], y[o_om + 1], y[o_om + 2]  # q̇ = ½ (ω, 0) ⊗ q, ω in the world frame
    qx, qy, qz, qw = y[o_rot], y[o_rot + 1], y[o_rot + 2], y[o_rot + 3]
    dy[o_rot] = 0.5 * (wx * qw + wy * qz - wz * qy)
    dy[o_rot + 1] = 0.5 * (wy * qw + wz * qx - wx * qz)
    dy[o_rot + 2] = 0.5 * (wz * qw + wx * qy - wy * qx)
    dy[o_rot + 3] = -0.5 * (wx * qx + wy * qy + wz * qz)


#: the right-hand side inlined into the Runge–Kutta stage loop only: a compiled call passing a dozen
#: arrays costs more than two berries' arithmetic, and inlining it everywhere doubles compile time
rhs_inline = inline(rhs.py_func)

__all__ = ["rhs", "rhs_inline"]


def derivative(M, y, contacts, accel=(0.0,) * 6, t: float = 0.0):
    """dy/dt at one state for callers outside the compiled core (tests, checks): every pair evaluated,
    contacts a (P,) forces.CONTACT array, the rachis acceleration accel (ACCEL_COMPONENTS, world frame) held.
    y must have M's layout (a scene's y goes with scene.arrays): the compiled core does not check bounds."""
    size = offsets.py_func(M.berry.shape[0], M.n_dof, M.coupling.shape[0], M.moving, M.turning)[-1]
    if np.shape(y) != (size,) or np.shape(contacts) != M.pair.shape:
        raise ValueError(f"y, contacts: shapes {np.shape(y)}, {np.shape(contacts)} do not fit the model's layout "
                         f"({size},), ({M.pair.shape[0]},) (moving {M.moving}, turning {M.turning}): pass a scene's "
                         "y with scene.arrays")
    dy = np.zeros_like(y)
    rhs(t, t, y, dy, contacts, M, constant().arrays, held(accel)[0], workspace(M), np.arange(M.pair.shape[0]),
        M.pair.shape[0])
    return dy
