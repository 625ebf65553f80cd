"""The output catalogue: every channel grapefmu reports, defined once.

A channel has a name, a unit, what it is per (angle, berry, pair or the whole cluster), a type, where it
goes in ROS (topic) and FMI (initial), and how its value follows from a `Snapshot`, the samples of a
run or the one state a face reports after a step. The FMU's variables, the ROS messages, the MCAP
recordings, a run's columns (CSV, Parquet) and its summary are all generated from CHANNELS.
"""
from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ..model.excitation import rotation_matrix
from ..model.model import Model
from ..physics.excitation import ACCEL_COMPONENTS
from ..physics.layout import LEDGER_TERMS
from ..physics.observe import ENERGY_TERMS, Observation

#: a scene with more candidate pairs than this (a cluster) reports pairs only while in contact
PER_PAIR_LIMIT = 16


class Snapshot(NamedTuple):
    """Samples (leading axis) of everything a channel can be computed from."""

    t: np.ndarray                  # (S,) s
    angles: np.ndarray             # (S, D) rad
    angular_velocities: np.ndarray  # (S, D) rad/s
    in_contact: np.ndarray         # (S, P) bool
    accel: np.ndarray              # (S, 6) ACCEL_COMPONENTS of the rachis: m/s², rad/s², world frame
    base_displacement: np.ndarray  # (S, 3) m, the rachis origin's displacement from its start, world frame
    base_angular_velocity: np.ndarray  # (S, 3) rad/s, ω of the rachis, world frame
    base_orientation: np.ndarray   # (S, 4) the quaternion (x, y, z, w) of R, world from rachis
    ledger: np.ndarray             # (S, 4) J, physics.layout.LEDGER_TERMS: dissipated so far, work done by the base
    totals: np.ndarray             # (S,) records.TOTALS
    observation: Observation
    obstacle_pairs: np.ndarray     # (P, O) 1.0 where pair p is a berry on obstacle o (Model.obstacle_pairs)


@dataclass(frozen=True)
class Channel:
    name: str
    unit: str          # SI, as FMI writes it ("" for a count or a flag)
    per: str           # "angle", "berry", "pair", "obstacle" or "cluster"
    type: str          # "real", "integer" or "boolean"
    description: str
    value: Callable[[Snapshot], np.ndarray]  # (S, count) per angle, berry or pair; (S,) per cluster
    topic: str | None = None     # the ROS topic that carries it (docs/ros.md)
    fmu: bool = True             # an FMU variable
    fmi_causality: str = "output"

    def element_names(self, model: Model) -> list[str]:
        if self.per == "angle":
            return list(model.dof_names)
        if self.per == "berry":
            return list(model.names)
        if self.per == "pair":
            return [model.pair_name(p) for p in range(len(model.pairs))]
        if self.per == "obstacle":
            return [o.name for o in model.obstacles]
        return [""]

    def column(self, element: str) -> str:
        """The one name of this channel's element everywhere (FMU variable, ROS field, plot label); a file's
        column adds the unit (file_column)."""
        return f"{self.name}_{element}" if element else self.name

    def file_column(self, element: str) -> str:
        """This channel's element as a CSV or Parquet column: its name with its unit (`angle_left_rad`)."""
        return file_column(self.column(element), self.unit)


def unit_suffix(unit: str) -> str:
    """A unit as a name suffix: lower case, every other character run as one "_" (N -> n, rad/s -> rad_s,
    N.m -> n_m, m/s2 -> m_s2); "" for a count or a flag."""
    return re.sub(r"[^a-z0-9]+", "_", unit.lower()).strip("_")


def file_column(column: str, unit: str) -> str:
    """The one rule for a column name in a file (CSV, Parquet) or a summary key: the name, then its unit as a
    suffix (`angle_left_rad`, `contact_force_left_right_n`, `energy_kinetic_j`, `time_s`); a count or a flag
    (unit "") keeps its bare name (`collision_count`, `in_contact_left_right`)."""
    suffix = unit_suffix(unit)
    return f"{column}_{suffix}" if suffix else column


def rotations(quaternions: np.ndarray) -> np.ndarray:
    """(S, 3, 3) R of quaternions (S, 4) (x, y, z, w; normalised here): model.excitation.rotation_matrix, the one
    formula, on whole columns."""
    q = np.asarray(quaternions, dtype=float).reshape(-1, 4)
    return np.stack(rotation_matrix(*q.T), axis=-1).reshape(-1, 3, 3)


def world(s: Snapshot, points: np.ndarray) -> np.ndarray:
    """Points (S, K, 3) in the rachis frame in the world frame, x = b + R p (docs/model.md §1)."""
    points = np.asarray(points, dtype=float)
    q = s.base_orientation
    if q[:, :3].any():
        points = np.einsum("sij,skj->ski", rotations(q), points)
    return points + s.base_displacement[:, None, :]


def _world(axis: int) -> Callable[[Snapshot], np.ndarray]:
    return lambda s: world(s, s.observation.position)[:, :, axis]


def _total(field: str) -> Callable[[Snapshot], np.ndarray]:
    return lambda s: s.totals[field]


def _peak(field: str, now: Callable[[Snapshot], np.ndarray]) -> Callable[[Snapshot], np.ndarray]:
    """The largest so far: the solver's peak (refined on the dense output, as of the step before each sample) or
    any sample's value up to this one, whichever is larger. Without the samples' running maximum the column fell
    back to the step's booked peak at the next sample of the same step (4.9 % below the last one on a cluster)."""
    return lambda s: np.maximum.accumulate(np.maximum(s.totals[field], now(s)))


def _largest(values: Callable[[Snapshot], np.ndarray]) -> Callable[[Snapshot], np.ndarray]:
    return lambda s: np.maximum.reduce(values(s), axis=1, initial=0.0)


def dissipated(s: Snapshot) -> np.ndarray:
    """Energy dissipated so far by hinges, couplings and contacts (J)."""
    return np.add.reduce(s.ledger[:, :3], axis=1)


def stored(s: Snapshot) -> np.ndarray:
    """The stored energy terms' sum (J)."""
    return s.observation.energy.sum(axis=1)


def _balance(s: Snapshot) -> np.ndarray:
    """stored + dissipated − work done by the base: constant in exact arithmetic."""
    return stored(s) + dissipated(s) - s.ledger[:, 3]


_force = lambda s: s.observation.contact_force  # noqa: E731
_tension = lambda s: s.observation.pedicel_tension  # noqa: E731
_max_tension = lambda s: np.maximum.reduce(_tension(s), axis=1)  # noqa: E731

CHANNELS: tuple[Channel, ...] = (
    Channel("angle", "rad", "angle", "real", "Twig angle (0 hanging; swing and tilt for a spherical twig)",
            lambda s: s.angles, "joint_states"),
    Channel("angular_velocity", "rad/s", "angle", "real", "Twig angular velocity", lambda s: s.angular_velocities,
            "joint_states"),
    Channel("hinge_torque", "N.m", "angle", "real", "Torque of the viscoelastic hinge on the twig, −k (q − q₀) − c q̇",
            lambda s: s.observation.hinge_torque, "joint_states", fmu=False),
    Channel("pedicel_tension", "N", "berry", "real", "Pedicel (twig) tension, positive pulling; negative (the twig "
            "in compression) while a contact or the base's acceleration pushes the berry toward its hinge", _tension,
            "pedicel_tension"),
    Channel("position_x", "m", "berry", "real", "Berry centre x, world frame", _world(0), "markers", fmu=False),
    Channel("position_y", "m", "berry", "real", "Berry centre y, world frame", _world(1), "markers", fmu=False),
    Channel("position_z", "m", "berry", "real", "Berry centre z (up), world frame", _world(2), "markers", fmu=False),
    Channel("contact_force", "N", "pair", "real", "Normal contact force between the pair", _force, "contacts"),
    Channel("penetration", "m", "pair", "real", "Penetration of the pair while in contact",
            lambda s: s.observation.penetration, "contacts"),
    Channel("in_contact", "", "pair", "boolean", "True while the pair is in contact", lambda s: s.in_contact, "contacts"),
    Channel("obstacle_force", "N", "obstacle", "real", "Sum of the contact forces of the berries on the obstacle",
            lambda s: _force(s) @ s.obstacle_pairs),
    *(Channel(f"base_{c}", unit, "cluster", "real", f"Rachis (gripper) {what}, world frame, held over a step",
              lambda s, k=k: s.accel[:, k], "rachis/accel", fmi_causality="input")
      for k, (c, unit, what) in enumerate(zip(ACCEL_COMPONENTS, ("m/s2",) * 3 + ("rad/s2",) * 3, (
          "acceleration along x", "acceleration along y", "acceleration along z (up)",
          "angular acceleration about x", "angular acceleration about y", "angular acceleration about z")))),
    *(Channel(f"base_omega_{c}", "rad/s", "cluster", "real", f"Rachis (gripper) angular velocity about {c}, world "
              "frame, set at the start of a step", lambda s, k=k: s.base_angular_velocity[:, k], "rachis/twist",
              fmi_causality="input") for k, c in enumerate("xyz")),
    Channel("active_pairs", "", "cluster", "integer", "Pairs in contact now (two berries, or a berry and an obstacle)",
            lambda s: s.in_contact.sum(axis=1), "summary"),
    Channel("max_contact_force", "N", "cluster", "real", "Largest contact force now", _largest(_force), "summary"),
    Channel("max_pedicel_tension", "N", "cluster", "real", "Largest pedicel tension now", _max_tension, "summary"),
    Channel("collision_count", "", "cluster", "integer",
            "Impacts so far (pairs coming into contact: two berries, or a berry and an obstacle)",
            _total("collision_count"), "summary"),
    Channel("bruising_impacts", "", "cluster", "integer",
            "Impacts so far whose peak force or dissipated energy reached the bruise threshold",
            _total("bruising_impacts"), "summary"),
    Channel("berries_over_detachment_force", "", "cluster", "integer",
            "Berries whose pedicel tension has exceeded the detachment force so far",
            _total("berries_over_detachment_force"), "summary"),
    Channel("detachment_risk", "", "cluster", "boolean",
            "True once any pedicel tension has exceeded the scene's detachment force",
            lambda s: s.totals["berries_over_detachment_force"] > 0, "summary"),
    Channel("peak_contact_force", "N", "cluster", "real", "Largest contact force so far",
            _peak("peak_contact_force", _largest(_force)), "summary"),
    Channel("peak_pedicel_tension", "N", "cluster", "real", "Largest pedicel tension so far",
            _peak("peak_pedicel_tension", _max_tension), "summary"),
    Channel("dissipated_energy", "J", "cluster", "real", "Energy dissipated so far by hinges, couplings and contacts",
            dissipated, "summary"),
    *(Channel(f"energy_{k}", "J", "cluster", "real", f"Stored energy: {k.replace('_', ' ')}",
              lambda s, k=k: s.observation.energy[:, ENERGY_TERMS.index(k)], fmu=False) for k in ENERGY_TERMS),
    *(Channel(k, "J", "cluster", "real", f"Energy ledger: {k.replace('_', ' ')} so far",
              lambda s, k=k: s.ledger[:, LEDGER_TERMS.index(k)], fmu=False) for k in LEDGER_TERMS),
    Channel("energy_stored", "J", "cluster", "real", "Stored energy: the sum of the stored terms",
            stored, fmu=False),
    Channel("energy_residual", "J", "cluster", "real",
            "What the energy ledger fails to account for since the first sample (docs/model.md §5)",
            lambda s: _balance(s) - _balance(s)[:1], fmu=False),
)

BY_NAME = {c.name: c for c in CHANNELS}


def channel(name: str) -> Channel:
    return BY_NAME[name]


def on_topic(topic: str) -> list[Channel]:
    return [c for c in CHANNELS if c.topic == topic]


def table(snap: Snapshot, model: Model, pairs: list[int] | None = None,
          only: list[Channel] | tuple[Channel, ...] = CHANNELS, units: bool = False) -> dict[str, np.ndarray]:
    """Channels (all unless told) as named columns of samples; per-pair channels for `pairs` only (default: all).
    Named by Channel.column, or with `units` by Channel.file_column (what CSV and Parquet files carry)."""
    cols: dict[str, np.ndarray] = {}
    for c in only:
        name = c.file_column if units else c.column
        v = np.asarray(c.value(snap))
        if c.per == "cluster":
            cols[name("")] = v
            continue
        names = c.element_names(model)
        idx = range(len(names)) if c.per != "pair" or pairs is None else pairs
        for k in idx:
            cols[name(names[k])] = v[:, k]
    return cols


def markdown() -> str:
    """The catalogue as a Markdown table (docs/outputs.md; `grapefmu outputs`)."""
    rows = ["| channel | unit | CSV / Parquet column | per | type | ROS topic | FMU | description |",
            "|---|---|---|---|---|---|---|---|"]
    for c in CHANNELS:
        fmu = c.fmi_causality if c.fmu else "—"
        column = c.file_column("" if c.per == "cluster" else f"<{c.per}>")
        rows.append(f"| `{c.name}` | {c.unit or '—'} | `{column}` | {c.per} | {c.type} | {c.topic or '—'} | {fmu} | "
                    f"{c.description} |")
    return "\n".join(rows) + "\n"
