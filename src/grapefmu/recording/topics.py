"""What the recorded and published topics carry, shared by `grapefmu simulate` and the ROS node.

The rachis frame is REP-103: x forward along the rod, y left, z up. A scene with more than
PER_PAIR_TOPIC_LIMIT candidate pairs (a cluster) gets no per-pair wrench topics: its contacts go
out as one `contacts` array holding only the pairs in contact, so a 100-berry cluster with
thousands of idle candidate pairs does not flood the graph or the recording.
"""
from __future__ import annotations

import numpy as np

from ..model.model import Model

PER_PAIR_TOPIC_LIMIT = 16
CONTACT_FIELDS = ("pair_index", "force_n", "penetration_m")
SUMMARY_FIELDS = ("time_s", "active_pairs", "max_contact_force_n", "max_pedicel_tension_n", "peak_contact_force_n",
                  "peak_pedicel_tension_n", "energy_dissipated_j")


def joint_names(model: Model) -> list[str]:
    return [f"twig_{n}" for n in model.dof_names]


def per_pair_topics(model: Model) -> bool:
    return len(model.pairs) <= PER_PAIR_TOPIC_LIMIT


def hinge_effort(model: Model, q: np.ndarray, w: np.ndarray) -> np.ndarray:
    """The torque each viscoelastic hinge exerts on its twig, per angle (N·m): −k (q − q_rest) − c q̇."""
    M = model.arrays
    out = np.empty(np.shape(q))
    for i in range(model.n_berries):
        a, b = M.dof[i], M.dof[i + 1]
        out[..., a:b] = -M.berry[i, 4] * (q[..., a:b] - M.berry[i, 8:8 + b - a]) - M.berry[i, 5] * w[..., a:b]
    return out


def contact_values(force: np.ndarray, penetration: np.ndarray, in_contact: np.ndarray) -> list[float]:
    """[pair, force, penetration] for each pair in contact, flattened."""
    out: list[float] = []
    for p in np.flatnonzero(in_contact):
        out += [float(p), float(force[p]), float(penetration[p])]
    return out


def summary_values(t: float, force, tension, peak_force: float, peak_tension: float, dissipated: float,
                   in_contact) -> list[float]:
    return [float(t), float(np.count_nonzero(in_contact)), float(np.max(force, initial=0.0)), float(np.max(tension, initial=0.0)),
            float(peak_force), float(peak_tension), float(dissipated)]
