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
    """A point-mass berry on a massless twig hinged to the rachis at x = hinge_x (all SI)."""

    name: str
    mass: float             # kg
    radius: float           # m
    twig_length: float      # m, hinge to berry centre
    hinge_x: float          # m, along the rod
    hinge_stiffness: float  # N·m/rad, torsional, rest angle 0 (hanging)
    hinge_damping: float    # N·m·s/rad


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

    berry: np.ndarray      # (N, 6): mass, radius, twig_length, hinge_x, hinge_stiffness, hinge_damping
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

    @property
    def n_berries(self) -> int:
        return len(self.berries)

    @property
    def names(self) -> list[str]:
        return [b.name for b in self.berries]

    def pair_name(self, p: int) -> str:
        pr = self.pairs[p]
        return f"{self.berries[pr.i].name}_{self.berries[pr.j].name}"

    @cached_property
    def arrays(self) -> ModelArrays:
        berry = np.array([[b.mass, b.radius, b.twig_length, b.hinge_x, b.hinge_stiffness, b.hinge_damping]
                          for b in self.berries], dtype=float).reshape(-1, 6)
        pair_idx = np.array([[p.i, p.j] for p in self.pairs], dtype=np.int64).reshape(-1, 2)
        pair_law = np.array([p.law.code for p in self.pairs], dtype=np.int64)
        pair_par = np.array([[p.law.stiffness, p.law.damping, 1.0 if p.law.clamp else 0.0]
                             for p in self.pairs], dtype=float).reshape(-1, 3)
        coup_idx = np.array([[c.i, c.j] for c in self.couplings], dtype=np.int64).reshape(-1, 2)
        coup_par = np.array([[c.stiffness, c.damping] for c in self.couplings], dtype=float).reshape(-1, 2)
        return ModelArrays(berry, pair_idx, pair_law, pair_par, coup_idx, coup_par, float(self.gravity))


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
    angles: tuple[float, ...]
    angular_velocities: tuple[float, ...]
    excitation: Excitation = field(default_factory=constant)
    solver: SolverSettings = field(default_factory=SolverSettings)
    thresholds: Thresholds = field(default_factory=Thresholds)
    source: str = ""          # the TOML text it was read from, kept for reproducible recordings
    name: str = "scene"

    @property
    def initial_state(self) -> np.ndarray:
        return np.array(self.angles + self.angular_velocities, dtype=float)
