"""The immutable model (what the system is) kept apart from the state that steps (MuJoCo's split).

A `Model` holds berries, contact pairs and couplings; a `Scene` adds what one run
needs: the initial state, the excitation, the solver settings and the thresholds
that turn forces into detachment and damage indicators.
"""
from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, field
from functools import cached_property
from numbers import Integral, Real
from typing import NamedTuple

import numpy as np

from .bounds import Bound, bound, bounded, refusal
from .contact import ContactLaw
from ..errors import SceneError
from .excitation import TABLE, Excitation, check_row_spacing, constant, rotation_matrix


@dataclass(frozen=True)
class Berry:
    """A point-mass berry on a massless twig hinged to the rigid rachis (all SI, z up).

    A planar berry swings in the x–z plane (one angle, 0 hanging). A spherical berry has two
    angles in its twig's own frame, turned by `azimuth` about z: swing s and tilt t give the twig
    direction u = (sin s, −sin t cos s, −cos t cos s), so (s, 0) is the planar pendulum and the
    only singular pose, s = ±90°, is a twig swung sideways flat, far from any rest pose."""

    name: str
    mass: float = bounded(0.0, 10.0, lo_open=True, unit="kg")
    radius: float = bounded(0.0, 0.1, lo_open=True, unit="m")
    twig_length: float = bounded(0.0, 1.0, lo_open=True, unit="m")       # hinge to berry centre
    hinge_x: float = bounded(-10.0, 10.0, unit="m")                      # along the rod
    hinge_stiffness: float = bounded(0.0, 1e3, unit="N·m/rad")           # torsional, per angle
    hinge_damping: float = bounded(0.0, 1e3, unit="N·m·s/rad")
    hinge_y: float = bounded(-10.0, 10.0, unit="m", default=0.0)
    hinge_z: float = bounded(-10.0, 10.0, unit="m", default=0.0)
    spherical: bool = False
    #: the twig frame's turn about z (spherical berries)
    azimuth: float = bounded(-2 * math.pi, 2 * math.pi, unit="rad", default=0.0)
    #: where the hinge exerts no torque
    rest_angles: tuple[float, float] = bounded(-2 * math.pi, 2 * math.pi, unit="rad", default=(0.0, 0.0))

    @property
    def ndof(self) -> int:
        return 2 if self.spherical else 1

    def refusal(self, key: str) -> tuple[str, str] | None:
        """(key.field, why) for a value outside its bound or a berry the model cannot hold, or None."""
        why = refusal(self, key)
        if why:
            return why
        if self.radius >= self.twig_length:
            return (f"{key}.radius", f"must be smaller than twig_length ({self.twig_length:g} m), got {self.radius:g} m")
        if len(self.rest_angles) != 2:
            return (f"{key}.rest_angles", f"expected [swing, tilt], got {self.rest_angles!r}")
        return self.refuses_swing(f"{key}.rest_angles[0]", "rest swing", self.rest_angles[0])

    def refuses_swing(self, key: str, what: str, swing: float) -> tuple[str, str] | None:
        """(key, why) if a spherical berry's swing leaves the chart (docs/model.md §1: singular at 90°), or None."""
        if self.spherical and abs(swing) > MAX_SWING:
            return (key, f"a spherical berry's {what} must stay within ±{math.degrees(MAX_SWING):g}° "
                    f"(±{MAX_SWING:.4g} rad), got {swing!r}")
        return None


#: a spherical twig this close to swinging sideways flat (cos s → 0) is outside the model's chart
MAX_SWING = math.radians(80.0)
#: a berry's initial angle (each of a spherical berry's two) and angular velocity
ANGLE = Bound(-math.pi, math.pi, unit="rad")
ANGULAR_VELOCITY = Bound(-1e3, 1e3, unit="rad/s")
#: the deepest overlap a start (and a planar scene file's hanging rest) may hold, as a fraction of the smaller radius:
#: a contact law means nothing far beyond it, and such a start flings the berries apart with energy nobody gave them;
#: a run whose samples pass it is warned (results/trust.py)
MAX_OVERLAP_FRACTION = 0.2


#: the shapes an obstacle can have (OBSTACLE.kind is the index)
OBSTACLE_KINDS = ("plane", "box", "capsule")
PLANE, BOX, CAPSULE = range(3)


@dataclass(frozen=True)
class Obstacle:
    """A body berries hit that is not a berry: a plane (a crate's floor, a conveyor: the side its normal
    points away from is solid), a box (a crate wall), or a capsule (a finger pad). Fixed in the world, or
    attached to the gripper (it moves with the rachis; its coordinates are then in the rachis frame). Berries
    touching it follow its own contact law and bruise at its own thresholds (padding foam against hard
    plastic; the laws sit on the berry–obstacle ContactPairs). The world frame's origin is the rachis origin at
    t = 0; its axes are the rachis' turned by the start orientation R₀ (docs/model.md §7)."""

    name: str
    kind: str                                             # OBSTACLE_KINDS
    #: a plane's point, a box's centre, a capsule's end
    point: tuple[float, float, float] = bounded(-100.0, 100.0, unit="m")
    #: plane: unit, out of the solid
    normal: tuple[float, float, float] = bounded(-1.0, 1.0, default=(0.0, 0.0, 1.0))
    #: box: edge lengths along its axes
    size: tuple[float, float, float] = bounded(0.0, 100.0, unit="m", default=(0.0, 0.0, 0.0))
    #: box: its axes turned about z
    yaw: float = bounded(-2 * math.pi, 2 * math.pi, unit="rad", default=0.0)
    #: capsule: the other end of its axis
    end: tuple[float, float, float] = bounded(-100.0, 100.0, unit="m", default=(0.0, 0.0, 0.0))
    radius: float = bounded(0.0, 10.0, unit="m", default=0.0)    # capsule
    attached: bool = False                                # moves with the gripper (rachis-frame coordinates)
    #: peak force of one impact on it that bruises
    bruise_force: float = bounded(0.0, 1e4, lo_open=True, unit="N", default=1.7)
    #: energy dissipated in one impact on it that bruises
    bruise_energy: float = bounded(0.0, 1e3, lo_open=True, unit="J", default=1e-3)

    def refusal(self, key: str) -> tuple[str, str] | None:
        """(key.field, why) for a value outside its bound or a shape the core cannot hold, or None."""
        if self.kind not in OBSTACLE_KINDS:
            return (f"{key}.kind", f"expected one of {', '.join(map(repr, OBSTACLE_KINDS))}, got {self.kind!r}")
        why = refusal(self, key, positive=OBSTACLE_SIZES.get(self.kind, ()))
        if why:
            return why
        if self.kind == "plane" and abs(math.hypot(*self.normal) - 1.0) > 1e-9:
            return (f"{key}.normal", f"expected a unit vector out of the solid, got {self.normal!r}")
        if self.kind == "capsule" and math.dist(self.point, self.end) < MIN_CAPSULE_LENGTH:
            return (f"{key}.end", f"the two ends must be at least {MIN_CAPSULE_LENGTH * 1e6:g} µm apart "
                    "(a sphere is a short capsule)")
        return None


#: the sizes each kind of obstacle needs greater than 0 (the others' default, which they do not read, is 0)
OBSTACLE_SIZES = {"box": ("size",), "capsule": ("radius",)}
#: a capsule's shortest axis (m)
MIN_CAPSULE_LENGTH = 1e-6


@dataclass(frozen=True)
class ContactPair:
    """Berry i and body j: berry j when j < N, else obstacle j − N (one index space for every body)."""

    i: int
    j: int
    law: ContactLaw


@dataclass(frozen=True)
class Coupling:
    """The paper's k3, c3: a spring–damper on the change of horizontal berry separation."""

    i: int
    j: int
    stiffness: float = bounded(0.0, 1e6, unit="N/m")
    damping: float = bounded(0.0, 1e4, unit="N·s/m")


#: one berry as the compiled core reads it (docs/model.md names); a field of M.berry is a named array per property
BERRY = np.dtype([("mass", "f8"), ("radius", "f8"), ("twig_length", "f8"), ("hinge_x", "f8"), ("hinge_y", "f8"),
                  ("hinge_z", "f8"), ("hinge_stiffness", "f8"), ("hinge_damping", "f8"), ("rest_swing", "f8"),
                  ("rest_tilt", "f8"), ("azimuth_cos", "f8"), ("azimuth_sin", "f8"), ("dof", "i8"), ("n_angles", "i8")],
                 align=True)
#: one candidate contact pair
PAIR = np.dtype([("i", "i8"), ("j", "i8"), ("law", "i8"), ("stiffness", "f8"), ("damping", "f8"), ("clamp", "?")],
                align=True)
#: one obstacle (Obstacle) as the compiled core reads it, with its bruise thresholds (a berry–berry pair's are
#: the scene's): point p; a plane's unit normal or a capsule's axis (end − point) in u; a box's half sizes h and
#: yaw; a capsule's radius
OBSTACLE = np.dtype([("kind", "i8"), ("attached", "?"), ("px", "f8"), ("py", "f8"), ("pz", "f8"), ("ux", "f8"),
                     ("uy", "f8"), ("uz", "f8"), ("hx", "f8"), ("hy", "f8"), ("hz", "f8"), ("cos_yaw", "f8"),
                     ("sin_yaw", "f8"), ("radius", "f8"), ("bruise_force", "f8"), ("bruise_energy", "f8")],
                    align=True)
#: one k3/c3 coupling
COUPLING = np.dtype([("i", "i8"), ("j", "i8"), ("stiffness", "f8"), ("damping", "f8")], align=True)


class ModelArrays(NamedTuple):
    """The model as the compiled core reads it (MuJoCo's mjModel): one named field per property, in
    docs/model.md's names; `M.berry["mass"]` is the array of masses. Record arrays rather than loose
    arrays, and scalar fields only, because every array (or array view) a compiled function touches costs
    a reference count.

    berry (N,) BERRY: mass kg, radius m, twig_length l m, hinge_x/y/z h m, hinge_stiffness k N·m/rad,
      hinge_damping c N·m·s/rad, rest_swing/rest_tilt (s₀, t₀) rad, azimuth_cos/sin (R_z(ψ)), dof (its first
      angle's index in q) and n_angles (1 planar, 2 spherical).
    pair (P,) PAIR: berries i < j, law (contact.Law), stiffness k (N/m) or K (N/m^1.5), damping c (N·s/m)
      or χ (hunt-crossley), clamp (the no-tension clamp).
    coupling (C,) COUPLING: berries i, j, stiffness k3 N/m, damping c3 N·s/m.
    obstacle (O,) OBSTACLE: kind (PLANE, BOX, CAPSULE), attached (to the gripper), point, normal or axis u,
      half sizes h and yaw, radius, bruise_force N, bruise_energy J; a pair whose j ≥ N touches obstacle j − N."""

    berry: np.ndarray
    pair: np.ndarray
    coupling: np.ndarray
    obstacle: np.ndarray
    gravity: float   # m/s²
    n_dof: int       # D: angles in q
    moving: bool = True    # the rachis may move: its ḃ and b ride in y (Scene.arrays sets it)
    turning: bool = False  # the rachis may turn: its ω and orientation ride in y too (Scene.arrays sets it)


#: the rachis' TF frame (recording/frames.py)
RACHIS_FRAME = "rachis"


@dataclass(frozen=True)
class Model:
    berries: tuple[Berry, ...]
    pairs: tuple[ContactPair, ...] = ()
    couplings: tuple[Coupling, ...] = ()
    gravity: float = bounded(0.0, 100.0, unit="m/s²", default=9.81)   # its magnitude; it points along −z (world)
    pairs_pruned: int = 0   # listed or default pairs dropped because they can never touch
    obstacles: tuple[Obstacle, ...] = ()

    @property
    def n_berries(self) -> int:
        return len(self.berries)

    @property
    def names(self) -> list[str]:
        return [b.name for b in self.berries]

    @cached_property
    def n_dof(self) -> int:
        """Asked by every layout, Solver and run: summed once per model."""
        return sum(b.ndof for b in self.berries)

    @property
    def frame_names(self) -> list[tuple[str, str]]:
        """Each berry's two TF frames, (berry, its hinge), children of RACHIS_FRAME (recording/frames.py prefixes
        them all)."""
        return [(b.name, f"{b.name}_hinge") for b in self.berries]

    @property
    def dof_names(self) -> list[str]:
        """One name per angle: the berry's name, or name_swing and name_tilt for a spherical berry."""
        return [n for b in self.berries for n in ((f"{b.name}_swing", f"{b.name}_tilt") if b.spherical else (b.name,))]

    def overlap_words(self, p: int, delta: float, bound: float, state: str) -> str:
        """What is wrong with pair p overlapping by delta (m) beyond bound (physics.kinematics.deepest_overlap) in the
        named state."""
        pr = self.pairs[p]
        a, nb = self.berries[pr.i], len(self.berries)
        if pr.j >= nb:
            return (f"berry {a.name!r} starts {delta * 1e3:.3g} mm inside obstacle {self.obstacles[pr.j - nb].name!r} "
                    f"in the {state} state; at most {bound * 1e3:.3g} mm ({MAX_OVERLAP_FRACTION:g} of its radius) "
                    "is allowed")
        return (f"berries {a.name!r} and {self.berries[pr.j].name!r} overlap by {delta * 1e3:.3g} mm in the {state} "
                f"state; at most {bound * 1e3:.3g} mm ({MAX_OVERLAP_FRACTION:g} of the smaller radius) is allowed")

    @property
    def planar(self) -> bool:
        return not any(b.spherical for b in self.berries)

    def plane_normal(self, excitation) -> tuple[float, float, float] | None:
        """The world direction of the rachis' y axis at the start, n = R₀ ŷ, if any berry is planar (its swing
        plane is the rachis' x–z plane), else None: R₀'s second column, in plain Python (every Solver and Scene
        asks, and scipy's Rotation costs ~0.1 ms a call)."""
        if all(b.spherical for b in self.berries):
            return None
        return rotation_matrix(*(float(c) for c in excitation.orientation))[1::3]

    def refuses_turn(self, excitation) -> tuple[str, str] | None:
        """(scene key, why) this model cannot follow the excitation's rotation, or None. A planar berry swings in
        the rachis' x–z plane: that plane must be vertical (n = R₀ ŷ horizontal) and the rachis may turn only
        about n (ω and α along n), which keeps it so."""
        n = self.plane_normal(excitation)
        if n is None:
            return None
        if abs(n[2]) > 1e-9:
            return ("excitation.orientation", f"the initial orientation tilts the rachis' y axis "
                    f"{math.degrees(math.asin(min(abs(n[2]), 1.0))):.3g}° out of the horizontal; planar berries swing "
                    "in the rachis' x–z plane, which must stay vertical (turn about y and z only; use spherical "
                    "berries for any orientation)")
        a = excitation.arrays
        if off_axis(tuple(map(float, excitation.angular_velocity)), n):
            key, what = "excitation.angular_velocity", "the initial angular velocity"
        elif a.kind == TABLE:
            rows = np.flatnonzero(across(a.table[:, 4:7], n))
            if not rows.size:
                return None
            # a table's key is the one that gives it: its file, its text, or the moves it was made from
            key, what = excitation.key, f"the angular acceleration at t = {a.table[rows[0], 0]:.9g} s"
        elif off_axis(tuple(float(c) for c in a.par[3:6]), n):
            key = {"constant": "angular_accel", "impulse": "angular_peak"}.get(excitation.kind, "angular_amplitude")
            key, what = f"excitation.{key}", "the angular acceleration"
        else:
            return None
        return (key, f"{what} turns the rachis about an axis other than its y axis {tuple(round(c, 6) for c in n)} "
                "(world); planar berries swing in the rachis' x–z plane and follow rotation about y only (use "
                "spherical berries for any rotation)")

    @property
    def body_names(self) -> list[str]:
        """Every body a contact pair can name: the berries, then the obstacles (ContactPair.j indexes this)."""
        return self.names + [o.name for o in self.obstacles]

    def pair_name(self, p: int) -> str:
        pr = self.pairs[p]
        names = self.body_names
        return f"{names[pr.i]}_{names[pr.j]}"

    @cached_property
    def refusal(self) -> tuple[str, str] | None:
        """(scene key, why) for the first value outside its bound (bounds.py) or body the core cannot hold, or None:
        asked once per model, by each Scene built on it."""
        return next((why for why in self._refusals() if why), None)

    def _refusals(self):
        N, O = self.n_berries, len(self.obstacles)
        yield refusal(self, "")
        for k, b in enumerate(self.berries):
            yield b.refusal(f"berries[{k}]")
        for k, o in enumerate(self.obstacles):
            yield o.refusal(f"obstacles[{k}]")
        for k, c in enumerate(self.couplings):
            if not (0 <= c.i < N and 0 <= c.j < N and c.i != c.j):
                yield (f"couplings[{k}]", f"expected two berries of {N}, got {c.i} and {c.j}")
            yield refusal(c, f"couplings[{k}]")
        for k, pr in enumerate(self.pairs):
            if not (0 <= pr.i < N and 0 <= pr.j < N + O and pr.i != pr.j):
                yield (f"contact[{k}]", f"expected a berry and another body of {N} berries and {O} obstacles, "
                       f"got {pr.i} and {pr.j}")
            name, why = pr.law.refusal() or (None, None)
            if name:
                yield (f"obstacles[{pr.j - N}].{name}" if pr.j >= N else f"contact[{k}].{name}",
                       f"{why} ({self.pair_name(k)})")

    def touches_obstacle(self, p: int) -> bool:
        return self.pairs[p].j >= self.n_berries

    @cached_property
    def mean_radius(self) -> float:
        """m: the berries' mean radius, which the broad phase's skin is a fraction of."""
        return float(np.mean([b.radius for b in self.berries]))

    @cached_property
    def obstacle_pairs(self) -> np.ndarray:
        """(P, O): 1.0 where pair p is a berry on obstacle o (sums per-pair quantities per obstacle)."""
        out = np.zeros((len(self.pairs), len(self.obstacles)))
        for p, pr in enumerate(self.pairs):
            if pr.j >= self.n_berries:
                out[p, pr.j - self.n_berries] = 1.0
        out.flags.writeable = False
        return out

    @cached_property
    def arrays(self) -> ModelArrays:
        dof = self.dof
        berry = np.zeros(self.n_berries, dtype=BERRY)
        for k, b in enumerate(self.berries):
            berry[k] = (b.mass, b.radius, b.twig_length, b.hinge_x, b.hinge_y, b.hinge_z, b.hinge_stiffness,
                        b.hinge_damping, *b.rest_angles, np.cos(b.azimuth), np.sin(b.azimuth), dof[k], b.ndof)
        pair = np.array([(p.i, p.j, int(p.law.law), p.law.stiffness, p.law.damping, p.law.clamp) for p in self.pairs],
                        dtype=PAIR)
        coupling = np.array([(c.i, c.j, c.stiffness, c.damping) for c in self.couplings], dtype=COUPLING)
        obstacle = np.array([(OBSTACLE_KINDS.index(o.kind), o.attached, *o.point,
                              *(o.normal if o.kind == "plane" else np.subtract(o.end, o.point)),
                              *(0.5 * np.array(o.size)), np.cos(o.yaw), np.sin(o.yaw), o.radius, o.bruise_force,
                              o.bruise_energy) for o in self.obstacles], dtype=OBSTACLE)
        return ModelArrays(berry, pair, coupling, obstacle, float(self.gravity), int(dof[-1]))

    @cached_property
    def contact_radius(self) -> np.ndarray:
        """(P,) m: each candidate pair's smaller radius (a berry's own against an obstacle), the scale its overlap is
        judged on (MAX_OVERLAP_FRACTION)."""
        r, nb = [b.radius for b in self.berries], len(self.berries)
        out = np.array([min(r[p.i], r[p.j]) if p.j < nb else r[p.i] for p in self.pairs], dtype=float)
        out.flags.writeable = False
        return out

    @cached_property
    def dof(self) -> np.ndarray:
        """(N + 1,): berry i's angles are q[dof[i]:dof[i + 1]]."""
        return np.r_[0, np.cumsum([b.ndof for b in self.berries])].astype(np.int64)


@dataclass(frozen=True)
class SolverSettings:
    """method: 'event' (ours), 'paper' (ode23-like, contact checked at step ends) or 'reference' (scipy).

    fixed_step > 0 switches off error control (used to measure convergence order and
    to imitate a fixed-step paper run); output_interval is the spacing of reported samples.
    """

    method: str = "event"                                         # METHODS
    rtol: float = bounded(1e-14, 0.1, default=1e-8)
    atol: float = bounded(1e-16, 1.0, lo_open=True, default=1e-10)
    t_end: float = bounded(0.0, 1e5, lo_open=True, unit="s", default=2.0)
    output_interval: float = bounded(1e-6, 1e5, unit="s", default=1e-3)   # and at most t_end
    fixed_step: float = bounded(0.0, 1.0, unit="s", default=0.0)
    zeno_window: float = bounded(0.0, 10.0, lo_open=True, unit="s", default=1e-3)
    zeno_max_events: int = bounded(2, 10**6, default=64)
    #: accepted steps one call may take, a run or a face's step, before it stops with a SolverError saying why: a stiff
    #: scene's way out (docs/reliability.md, "Known limits"). None: 10⁷ a run, 10⁵ a face's step
    #: (solver.solver.RUN_MAX_STEPS, FACE_MAX_STEPS)
    max_steps: int | None = bounded(1, 10**12, default=None)
    #: "events": every contact onset and release is located (needed for Kelvin–Voigt's force jump);
    #: "step-control": the smooth laws (Hertz, Hunt–Crossley) are evaluated inline and the step-size
    #: control alone resolves their onsets (docs/benchmarks.md measures which is cheaper where)
    contact_location: str = "events"
    #: integrate in multirate islands (solver/islands.py): each group of berries that cannot touch the others within
    #: a window takes its own steps. True or False, or "auto": in islands from ISLANDS_FROM berries on, where the
    #: method allows. 'event' method with adaptive steps only; the faces (FMU, node) always step the whole scene
    islands: bool | str = "auto"
    #: the Runge–Kutta pair of the 'event' method's adaptive steps: "auto" (by the tolerance and the scene,
    #: solver.integrator_for), "DOPRI5" or "DOP853" (pinned: a replay pins the one its recording was made with)
    integrator: str = "auto"

    def refusal(self) -> tuple[str, str] | None:
        """(scene key, why) for a setting outside its bound or choices, or None."""
        why = refusal(self, "solver")
        if why:
            return why
        for name, allowed in (("method", METHODS), ("contact_location", CONTACT_LOCATIONS),
                              ("integrator", INTEGRATORS)):
            if getattr(self, name) not in allowed:
                return (f"solver.{name}", f"expected one of {', '.join(map(repr, allowed))}, got {getattr(self, name)!r}")
        for name in ("zeno_max_events", "max_steps"):
            if not isinstance(getattr(self, name), Integral | None):
                return (f"solver.{name}", f"expected an integer, got {getattr(self, name)!r}")
        if self.output_interval > self.t_end:
            return ("solver.output_interval", f"expected at most t_end ({self.t_end:g} s), got {self.output_interval:g} s")
        if not (self.islands == "auto" or isinstance(self.islands, bool)):
            return ("solver.islands", f"expected true, false or \"auto\", got {self.islands!r}")
        why = islands_refusal(self.method, self.fixed_step) if self.islands is True else None
        if why:
            return "solver.islands", why
        if self.integrator != "auto" and self.method != "event":
            return ("solver.integrator", f"{self.integrator!r} is for the 'event' method; method = {self.method!r} "
                    "steps its own pair (leave integrator \"auto\")")
        if self.integrator != "auto" and self.fixed_step > 0.0:
            return ("solver.integrator", f"{self.integrator!r} is for adaptive steps; a fixed step "
                    f"({self.fixed_step:g} s) steps DOPRI5 (leave integrator \"auto\")")
        return None


#: the solver's methods (SolverSettings.method) and ways to locate a contact's onset (contact_location)
METHODS = ("event", "paper", "reference")
CONTACT_LOCATIONS = ("events", "step-control")
#: the pairs a scene may pin for the event method (SolverSettings.integrator), or "auto"
INTEGRATORS = ("auto", "DOPRI5", "DOP853")


#: berries from which `solver.islands = "auto"` runs a scene in multirate islands: below, islands cost more than one
#: step size in most scenes measured; from here on less, by more as N grows, except at loose tolerances and in compact
#: clusters (within 1.2×): `.venv/bin/python benchmarks/islands_crossover.py` (docs/solver.md "Multirate islands")
ISLANDS_FROM = 100


def runs_in_islands(islands: bool | str, n_berries: int, method: str, fixed_step: float) -> bool:
    """Whether `simulate` runs a scene (a group of it) of n_berries in multirate islands (`solver.islands`)."""
    if islands == "auto":
        islands = n_berries >= ISLANDS_FROM
    return islands is True and islands_refusal(method, fixed_step) is None


def islands_refusal(method: str, fixed_step: float) -> str | None:
    """Why multirate islands cannot run with this method and fixed step (None when they can)."""
    if method != "event":
        return f"multirate islands run the 'event' method, got method = {method!r}"
    if fixed_step > 0.0:
        return f"multirate islands take adaptive steps, got fixed_step = {fixed_step:g} s (use 0)"
    return None


@dataclass(frozen=True)
class Thresholds:
    """Damage and detachment thresholds; docs/parameters.md gives their sources and spread."""

    #: pedicel tension that detaches a berry
    detachment_force: float = bounded(0.0, 1e4, lo_open=True, unit="N", default=3.4)
    #: peak contact force of one impact
    bruise_force: float = bounded(0.0, 1e4, lo_open=True, unit="N", default=1.7)
    #: energy dissipated in one impact
    bruise_energy: float = bounded(0.0, 1e3, lo_open=True, unit="J", default=1e-3)
    #: impacts above this fraction of bruise_force count toward fatigue
    fatigue_fraction: float = bounded(0.0, 1.0, lo_open=True, default=0.5)


#: rad/s (of ω) or rad/s² (of α): a component across a planar scene's axis below this, or 1e-9 of the vector, is
#: rounding, not a turn (one turn in 2e5 years). Without it, a master that integrates α into ω component by component
#: sent a yawed scene's turn come back to rest as ω = (1.9e-16, -1.4e-16, 0) rad/s, all of it across the axis, and
#: the FMU refused the step
ACROSS_FLOOR = 1e-12


def off_axis(w, n) -> bool:
    """Whether any of the vectors w (..., 3) has a component across the unit axis n (beyond 1e-9 of it and
    ACROSS_FLOOR). One vector given as a tuple (what a face's step holds) is checked in plain Python: numpy's calls
    cost tens of µs."""
    if type(w) is tuple and len(w) == 3:
        (x, y, z), (nx, ny, nz) = w, n
        tol = max(1e-9 * max(abs(x), abs(y), abs(z)), ACROSS_FLOOR)
        return abs(y * nz - z * ny) > tol or abs(z * nx - x * nz) > tol or abs(x * ny - y * nx) > tol
    return bool(across(w, n).any())


def across(w, n) -> np.ndarray:
    """Which of the vectors w (..., 3) have a component across the unit axis n (off_axis), a bool each."""
    w = np.asarray(w, dtype=float).reshape(-1, 3)
    return np.any(np.abs(np.cross(w, n)) > np.maximum(1e-9 * np.abs(w).max(axis=1, keepdims=True), ACROSS_FLOOR),
                  axis=1)


@dataclass(frozen=True)
class Scene:
    model: Model
    angles: tuple[float, ...]             # one per degree of freedom (Model.dof_names)
    angular_velocities: tuple[float, ...]
    excitation: Excitation = field(default_factory=constant)
    solver: SolverSettings = field(default_factory=SolverSettings)
    thresholds: Thresholds = field(default_factory=Thresholds)
    source: str = ""          # the TOML text it was read from (scenefile.scene_toml: the text a recording keeps)
    name: str = "scene"
    #: the `key` of the scene `source` was read as: a scene built with a source is described by it, and one changed
    #: in code since (`dataclasses.replace`) keeps its old key, so a stale source is told from a current one
    source_key: bytes = b""

    def __post_init__(self):
        why = (self.model.refusal or self.refuses_state() or self.solver.refusal() or refusal(self.thresholds, "thresholds")
               or self.refuses_excitation() or self.model.refuses_turn(self.excitation))
        if why:
            raise SceneError(*why)
        if self.source and not self.source_key:
            object.__setattr__(self, "source_key", self.key)

    @cached_property
    def key(self) -> bytes:
        """A hash of every fact a scene file states: equal keys, the same scene. A face's `driven` is not one (a
        face drives a scene read from a file), nor are the excitation's description and the key its errors name
        (the words, and where its table was given: a file, or inline in a recording)."""
        X = self.excitation
        h = hashlib.blake2b(digest_size=16)
        h.update(repr((self.model, self.angles, self.angular_velocities, self.solver, self.thresholds, self.name,
                       X.kind, X.arrays.kind, X.defined_until, X.orientation, X.angular_velocity)).encode())
        for a in (X.arrays.par, X.arrays.table, X.arrays.breaks):
            h.update(np.ascontiguousarray(a, dtype=float).tobytes())
        return h.digest()

    def refuses_state(self) -> tuple[str, str] | None:
        """(key, why) for an initial angle or angular velocity outside its bound, a spherical swing off the chart, or
        a list of the wrong length; None if the state holds. A scene built in code (`dataclasses.replace`) skips the
        scene file's parser and meets the same bounds here."""
        m = self.model
        for key, values, b in (("angles", self.angles, ANGLE), ("angular_velocities", self.angular_velocities,
                                                                  ANGULAR_VELOCITY)):
            if len(values) != m.n_dof:
                return (key, f"one per angle, {m.n_dof} ({', '.join(m.dof_names)}), got {len(values)}")
            for k, x in enumerate(values):
                if isinstance(x, bool) or not isinstance(x, Real) or not b.holds(float(x)):
                    return (f"{key}[{k}]", f"expected {b.allowed} ({m.dof_names[k]}), got {x!r}")
        for b, first in zip(m.berries, m.dof[:-1]):
            why = b.refuses_swing(f"angles[{first}]", "swing", self.angles[first])
            if why:
                return why
        return None

    def refuses_excitation(self) -> tuple[str, str] | None:
        """(key, why) for a value of the excitation that is not finite, or a table (made in code: excitation.table,
        pick_and_place, not only read from a file) whose rows come closer than the solver steps (check_row_spacing,
        naming the row and the spacing allowed, before a run stops at the step floor naming no key); or None."""
        ex = self.excitation
        X = ex.arrays
        if not (np.isfinite(X.par).all() and np.isfinite(X.table).all()):
            return ("excitation", f"every value of the {ex.kind} excitation must be a finite number")
        if X.kind == TABLE:
            try:
                check_row_spacing(X.table[:, 0], f"the {ex.kind} excitation's table", ex.key)
            except SceneError as e:
                return (e.key, e.why)
        return None

    @cached_property
    def arrays(self) -> ModelArrays:
        """The model's arrays for this scene's runs: `moving` when its rachis may move, `turning` when it may turn."""
        return self.model.arrays._replace(moving=self.excitation.moves, turning=self.excitation.turns)

    @cached_property
    def digest(self) -> bytes:
        """A hash of what the compiled core reads of this scene (its model's and excitation's arrays): with the
        solver's settings, the fingerprint a solver state carries (Solver._fingerprint)."""
        M, X = self.arrays, self.excitation.arrays
        h = hashlib.blake2b(digest_size=16)
        for part in (M.berry, M.pair, M.coupling, M.obstacle, np.array([M.gravity]), X.par, X.table):
            for name in part.dtype.names or (None,):  # field by field: a record's padding bytes are not data
                h.update(np.ascontiguousarray(part if name is None else part[name]).tobytes())
        return h.digest()

    @cached_property
    def plane_normal(self) -> tuple[float, float, float] | None:
        """Model.plane_normal under this scene's excitation, asked once per scene rather than once per Solver."""
        return self.model.plane_normal(self.excitation)

    def driven(self) -> "Scene":
        """This scene with a rachis that may move and turn whatever its excitation does: a face's inputs drive it."""
        from dataclasses import replace
        return self if self.excitation.driven else replace(self, excitation=replace(self.excitation, driven=True))

    @property
    def initial_state(self) -> np.ndarray:
        return np.array(self.angles + self.angular_velocities, dtype=float)
