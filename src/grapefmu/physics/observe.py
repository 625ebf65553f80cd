"""What a state shows: the observation every face reports, from the same stages as the right-hand side.

`observe` fills an `Observation` for a batch of samples (a whole run, or the one state an FMU or a ROS
node reports after a step), with the stored-energy terms of the ledger (docs/model.md §5).
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .compiled import jit
from .forces import active, coupling, elastic_energy, forces, hinge_torque, pedicel_tension, rest_angle
from .kinematics import contact_gap, fixed_in_world, kinematics, to_rachis, workspace

ENERGY_TERMS = ("kinetic", "gravity", "hinge_elastic", "coupling_elastic", "contact_elastic")


class Observation(NamedTuple):
    """Per sample (leading axis), in the rachis frame."""

    hinge_torque: np.ndarray     # (S, D) N·m: the hinge's torque on each angle, −k (q − q₀) − c q̇
    pedicel_tension: np.ndarray  # (S, N) N: positive pulling
    position: np.ndarray         # (S, N, 3) m: berry centres
    contact_force: np.ndarray    # (S, P) N: normal force of each pair
    penetration: np.ndarray      # (S, P) m: δ while the pair is in contact, else 0
    contact_normal: np.ndarray   # (S, P, 3): unit normal from the pair's first berry to its second (or obstacle)
    energy: np.ndarray           # (S, 5) J: ENERGY_TERMS


@jit
def empty(n_samples: int, n_berries: int, n_dof: int, n_pairs: int) -> Observation:
    s, n, p = n_samples, n_berries, n_pairs
    return Observation(np.zeros((s, n_dof)), np.zeros((s, n)), np.zeros((s, n, 3)), np.zeros((s, p)),
                       np.zeros((s, p)), np.zeros((s, p, 3)), np.zeros((s, 5)))


@jit
def observe(ys, contacts, accels, M, out):
    """Fill `out` for each sample s of the state ys[s] in contact state contacts[s] ((P,) CONTACT) under the
    rachis acceleration accels[s] (ACCEL_COMPONENTS, world frame)."""
    berry, pairs = M.berry, M.pair
    npair = pairs.shape[0]
    W = workspace(M)
    kin = W.berry
    every = np.arange(npair)
    for s in range(ys.shape[0]):
        y = ys[s]
        C = contacts[s]
        fr = kinematics(y, M, kin)
        a = accels[s]
        forces((a[0], a[1], a[2], a[3], a[4], a[5]), fr, C, M, W, every, npair)
        ve = 0.0
        for p in range(npair):
            pr = pairs[p]
            delta, _, nx, ny, nz = contact_gap(M, pr, kin)
            if fixed_in_world(M, pr):
                nx, ny, nz = to_rachis(fr, nx, ny, nz)
            ve += elastic_energy(pairs[p], delta)
            out.contact_force[s, p] = W.pair[p].force
            out.penetration[s, p] = max(delta, 0.0) if active(C[p]) else 0.0
            out.contact_normal[s, p, 0], out.contact_normal[s, p, 1], out.contact_normal[s, p, 2] = nx, ny, nz
        ke = 0.0
        vg = 0.0
        vh = 0.0
        nd = M.n_dof
        for i in range(berry.shape[0]):
            b, k = berry[i], kin[i]
            out.position[s, i, 0], out.position[s, i, 1], out.position[s, i, 2] = k.px, k.py, k.pz
            out.pedicel_tension[s, i] = pedicel_tension(b, k)
            ke += 0.5 * b.mass * b.twig_length * b.twig_length * (k.dux * k.dux + k.duy * k.duy + k.duz * k.duz)
            vg += b.mass * M.gravity * b.twig_length * (1.0 + k.uz)
            for a in range(b.n_angles):
                q = b.dof + a
                e = y[q] - rest_angle(b, a)
                vh += 0.5 * b.hinge_stiffness * e * e
                out.hinge_torque[s, q] = hinge_torque(b, a, y[q], y[nd + q])
        vc = 0.0
        for k in range(M.coupling.shape[0]):
            cp = M.coupling[k]
            _, sep, _ = coupling(cp, berry[cp.i], berry[cp.j], kin[cp.i], kin[cp.j])
            vc += 0.5 * cp.stiffness * sep * sep
        out.energy[s, 0] = ke
        out.energy[s, 1] = vg
        out.energy[s, 2] = vh
        out.energy[s, 3] = vc
        out.energy[s, 4] = ve
