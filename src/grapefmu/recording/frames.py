"""The cluster's coordinate frames (REP-103: x along the rod, y left, z up), as TF transforms and as a URDF.

    world ─ rachis ─┬─ <berry>_hinge     static: the hinge on the rod
                    └─ <berry>           the berry's centre; its z axis points along the twig to the hinge

Frame names carry a prefix (the node's namespace, "grape_cluster/" by default) so they never collide with
a robot's own frames; `world` is the robot's fixed frame. The URDF draws the same links (a sphere per
berry, a cylinder per twig) with floating joints whose poses come from the TF transforms above, so
RViz and Foxglove place the cluster without a robot_state_publisher."""
from __future__ import annotations

from xml.sax.saxutils import quoteattr

import numpy as np

from ..model.model import RACHIS_FRAME, Model
from ..results import catalogue

WORLD = "world"
PREFIX = "grape_cluster/"


def rachis(prefix: str = PREFIX) -> str:
    return f"{prefix}{RACHIS_FRAME}"


def hinges(model: Model) -> np.ndarray:
    """(N, 3) hinge positions in the rachis frame, m."""
    b = model.arrays.berry
    return np.column_stack([b["hinge_x"], b["hinge_y"], b["hinge_z"]])


def quaternion_z_to(v: np.ndarray) -> np.ndarray:
    """(x, y, z, w) of the shortest rotation taking +z onto the unit vectors v (..., 3)."""
    v = v / np.linalg.norm(v, axis=-1, keepdims=True)
    w = 1.0 + v[..., 2]
    q = np.stack([-v[..., 1], v[..., 0], np.zeros_like(w), w], axis=-1)
    flip = w < 1e-12  # v = −z: a half turn about x
    q[flip] = (1.0, 0.0, 0.0, 0.0)
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def compose(q_a, q_b) -> np.ndarray:
    """(x, y, z, w) of R_a R_b: the turn q_b, then q_a (both quaternions x, y, z, w)."""
    from scipy.spatial.transform import Rotation
    return (Rotation.from_quat(q_a) * Rotation.from_quat(q_b)).as_quat()


def static_transforms(model: Model, prefix: str = PREFIX) -> list[tuple[str, str, np.ndarray, np.ndarray]]:
    """(parent, child, translation, quaternion xyzw) of every transform that never changes."""
    return [(rachis(prefix), f"{prefix}{hinge}", h, np.array([0.0, 0.0, 0.0, 1.0]))
            for (_, hinge), h in zip(model.frame_names, hinges(model))]


def transforms(model: Model, snap: catalogue.Snapshot, k: int, prefix: str = PREFIX, world: str = WORLD):
    """(parent, child, translation, quaternion xyzw) of every moving transform at sample k, the rachis' in the fixed
    frame `world`."""
    q = snap.base_orientation[k]
    out = [(world, rachis(prefix), np.array(snap.base_displacement[k], dtype=float), q / np.linalg.norm(q))]
    p = snap.observation.position[k]
    q = quaternion_z_to(hinges(model) - p)
    out += [(rachis(prefix), f"{prefix}{berry}", p[i], q[i]) for i, (berry, _) in enumerate(model.frame_names)]
    return out


def urdf(model: Model, prefix: str = PREFIX) -> str:
    """A URDF of the cluster consistent with `transforms` (floating joints: TF gives their poses)."""
    root = rachis(prefix)
    lines = ['<?xml version="1.0"?>', f'<robot name={quoteattr(prefix.strip("/") or "grape_cluster")}>',
             f'  <link name={quoteattr(root)}/>']
    for (berry, hinge), h, b in zip(model.frame_names, hinges(model), model.berries):
        link, hinge = f"{prefix}{berry}", f"{prefix}{hinge}"
        lines += [
            f'  <link name={quoteattr(hinge)}/>',
            f'  <joint name={quoteattr(hinge + "_joint")} type="fixed"><parent link={quoteattr(root)}/>'
            f'<child link={quoteattr(hinge)}/><origin xyz="{h[0]!r} {h[1]!r} {h[2]!r}"/></joint>',
            f'  <link name={quoteattr(link)}>',
            f'    <visual><geometry><sphere radius="{b.radius!r}"/></geometry>'
            f'<material name="grape"><color rgba="0.45 0.1 0.5 1"/></material></visual>',
            f'    <visual><origin xyz="0 0 {b.twig_length / 2!r}"/><geometry><cylinder radius="0.001" '
            f'length="{b.twig_length!r}"/></geometry><material name="twig"><color rgba="0.35 0.5 0.2 1"/>'
            f'</material></visual>',
            f'    <inertial><mass value="{b.mass!r}"/><inertia ixx="{0.4 * b.mass * b.radius ** 2!r}" ixy="0" ixz="0" '
            f'iyy="{0.4 * b.mass * b.radius ** 2!r}" iyz="0" izz="{0.4 * b.mass * b.radius ** 2!r}"/></inertial>',
            '  </link>',
            f'  <joint name={quoteattr(link + "_joint")} type="floating"><parent link={quoteattr(root)}/>'
            f'<child link={quoteattr(link)}/></joint>',
        ]
    lines.append('</robot>')
    return "\n".join(lines) + "\n"
