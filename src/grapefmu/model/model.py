"""The immutable model (what the system is) kept apart from the state that steps (MuJoCo's split).

A `Model` holds berries, contact pairs and couplings; a `Scene` adds what one run
needs: the initial state, the excitation, the solver settings and the thresholds
that turn forces into detachment and damage indicators.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from typing import NamedTuple

import numpy as np

from .contact import ContactLaw
from .excitation import Excitation, constant


@dataclass(frozen=True)
class Berry:
    """A point-mass berry on a massless twig hinged to the rigid rachis (all SI, z up).

    A planar berry swings in the x–z plane (one angle, 0 hanging). A spherical berry has two
    angles in its twig's own frame, turned by `azimuth` about z: swing s and tilt t give the twig
    direction u = (sin s, −sin t cos s, −cos t cos s), so (s, 0) is the planar pendulum and the
    only singular pose, s = ±90°, is a twig swung sideways flat, far from any rest pose."""

    name: str
    mass: float             # kg
    radius: float           # m
    twig_length: float      # m, hinge to berry centre
    hinge_x: float          # m, along the rod
    hinge_stiffness: float  # N·m/rad, torsional, per angle
    hinge_damping: float    # N·m·s/rad
    hinge_y: float = 0.0    # m
    hinge_z: float = 0.0    # m
    spherical: bool = False
    azimuth: float = 0.0    # rad, the twig frame's turn about z (spherical berries)
    rest_angles: tuple[float, float] = (0.0, 0.0)  # rad, where the hinge exerts no torque

    @property
    def ndof(self) -> int:
        return 2 if self.spherical else 1


@dataclass(frozen=True)
class ContactPair:
    i: int
    j: int
    law: ContactLaw


@dataclass(frozen=True)
class Coupling:
    """The paper's k3, c3: a spring–damper on the change of horizontal berry separation."""

    i: int
    j: int
    stiffness: float  # N/m
    damping: float    # N·s/m


class ModelArrays(NamedTuple):
    """The model as the compiled core reads it (one array per kind of parameter)."""

    berry: np.ndarray      # (N, 12): mass, radius, twig_length, hinge_x, hinge_stiffness, hinge_damping,
                           #          hinge_y, hinge_z, rest swing, rest tilt, cos(azimuth), sin(azimuth)
    dof: np.ndarray        # (N + 1,) int: berry i's angles are q[dof[i]:dof[i + 1]]
    pair_idx: np.ndarray   # (P, 2) int
    pair_law: np.ndarray   # (P,) int: 0 kelvin-voigt, 1 hertz, 2 hunt-crossley
    pair_par: np.ndarray   # (P, 3): stiffness, damping (c or χ), clamp (1.0 or 0.0)
    coup_idx: np.ndarray   # (C, 2) int
    coup_par: np.ndarray   # (C, 2): stiffness, damping
    gravity: float


@dataclass(frozen=True)
class Model:
    berries: tuple[Berry, ...]
    pairs: tuple[ContactPair, ...] = ()
    couplings: tuple[Coupling, ...] = ()
    gravity: float = 9.81
    pairs_pruned: int = 0   # listed or default pairs dropped because they can never touch

    @property
    def n_berries(self) -> int:
        return len(self.berries)

    @property
    def names(self) -> list[str]:
        return [b.name for b in self.berries]

    @property
    def n_dof(self) -> int:
        return sum(b.ndof for b in self.berries)

    @property
    def dof_names(self) -> list[str]:
        """One name per angle: the berry's name, or name_swing and name_tilt for a spherical berry."""
        return [n for b in self.berries for n in ((f"{b.name}_swing", f"{b.name}_tilt") if b.spherical else (b.name,))]

    @property
    def planar(self) -> bool:
        return not any(b.spherical for b in self.berries)

    def pair_name(self, p: int) -> str:
        pr = self.pairs[p]
        return f"{self.berries[pr.i].name}_{self.berries[pr.j].name}"

    @cached_property
    def arrays(self) -> ModelArrays:
        berry = np.array([[b.mass, b.radius, b.twig_length, b.hinge_x, b.hinge_stiffness, b.hinge_damping,
                           b.hinge_y, b.hinge_z, *b.rest_angles, np.cos(b.azimuth), np.sin(b.azimuth)]
                          for b in self.berries], dtype=float).reshape(-1, 12)
        dof = np.r_[0, np.cumsum([b.ndof for b in self.berries])].astype(np.int64)
        pair_idx = np.array([[p.i, p.j] for p in self.pairs], dtype=np.int64).reshape(-1, 2)
        pair_law = np.array([p.law.code for p in self.pairs], dtype=np.int64)
        pair_par = np.array([[p.law.stiffness, p.law.damping, 1.0 if p.law.clamp else 0.0]
                             for p in self.pairs], dtype=float).reshape(-1, 3)
        coup_idx = np.array([[c.i, c.j] for c in self.couplings], dtype=np.int64).reshape(-1, 2)
        coup_par = np.array([[c.stiffness, c.damping] for c in self.couplings], dtype=float).reshape(-1, 2)
        return ModelArrays(berry, dof, pair_idx, pair_law, pair_par, coup_idx, coup_par, float(self.gravity))


@dataclass(frozen=True)
class SolverSettings:
    """method: 'event' (ours), 'paper' (ode23-like, contact checked at step ends) or 'reference' (scipy).

    fixed_step > 0 switches off error control (used to measure convergence order and
    to imitate a fixed-step paper run); output_interval is the spacing of reported samples.
    """

    method: str = "event"
    rtol: float = 1e-8
    atol: float = 1e-10
    t_end: float = 2.0
    output_interval: float = 1e-3
    fixed_step: float = 0.0
    zeno_window: float = 1e-3
    zeno_max_events: int = 64
    #: "events": every contact onset and release is located (needed for Kelvin–Voigt's force jump);
    #: "step-control": the smooth laws (Hertz, Hunt–Crossley) are evaluated inline and the step-size
    #: control alone resolves their onsets (docs/benchmarks.md measures which is cheaper where)
    contact_location: str = "events"


@dataclass(frozen=True)
class Thresholds:
    """Damage and detachment thresholds; docs/parameters.md gives their sources and spread."""

    detachment_force: float = 3.4   # N, pedicel tension that detaches a berry
    bruise_force: float = 1.7       # N, peak contact force of one impact
    bruise_energy: float = 1e-3     # J, energy dissipated in one impact
    fatigue_fraction: float = 0.5   # impacts above this fraction of bruise_force count toward fatigue


@dataclass(frozen=True)
class Scene:
    model: Model
    angles: tuple[float, ...]             # one per degree of freedom (Model.dof_names)
    angular_velocities: tuple[float, ...]
    excitation: Excitation = field(default_factory=constant)
    solver: SolverSettings = field(default_factory=SolverSettings)
    thresholds: Thresholds = field(default_factory=Thresholds)
    source: str = ""          # the TOML text it was read from, kept for reproducible recordings
    name: str = "scene"

    @property
    def initial_state(self) -> np.ndarray:
        return np.array(self.angles + self.angular_velocities, dtype=float)
