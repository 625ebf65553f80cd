"""Generate cluster scenes as TOML documents (so every generated cluster is a reproducible file).

Spherical cluster: a rigid main rachis hangs from the gripper along −z; laterals branch off at
points spread down its length (golden-angle azimuths, shorter towards the tip, so the cluster
tapers). Each berry hangs on its own twig from a point on a lateral, as a spherical pendulum with a
viscoelastic hinge. Diameters, twig lengths and hinge coefficients are drawn from normal
distributions (mean and spread, as in the three-dimensional cluster model the paper builds on).
Each hinge's rest angles are set so that the placed pose is the static equilibrium under
gravity: a cluster at rest stays at rest until the gripper moves, unless it was placed with precompression (the
contact forces of pressed pairs are not part of the equilibrium: they push apart at the start). Berries are placed
one by one and a placement is redrawn while it overlaps a placed berry by more than `precompression`, or by more than
MAX_OVERLAP_FRACTION of the smaller radius (the most a scene's start may hold: a deeper pair is refused).

Planar row: N berries on one rod, the dual-twig–berry system generalised (a Newton's cradle of
pendulums when the pitch equals the diameter).
"""
from __future__ import annotations

import copy
import math
from dataclasses import dataclass, field
from numbers import Integral
from typing import Any

import numpy as np

from ..errors import SceneError
from ..model.bounds import bound
from ..model.model import MAX_OVERLAP_FRACTION, Berry

DENSITY = 1070.0  # kg/m³, grape berry (docs/parameters.md)
GOLDEN_ANGLE = math.pi * (3.0 - math.sqrt(5.0))
DEFAULT_MOVES = [{"displacement": [0.0, 0.10], "duration": 0.4}, {"displacement": [0.30, 0.0], "duration": 0.6},
                 {"displacement": [0.0, -0.10], "duration": 0.4}]


@dataclass(frozen=True)
class Spread:
    """A normal distribution, truncated to [mean − 3 sd, mean + 3 sd] and to positive values."""

    mean: float
    sd: float

    def draw(self, rng: np.random.Generator, lo: float = 0.0) -> float:
        x = rng.normal(self.mean, self.sd) if self.sd > 0 else self.mean
        return float(max(min(x, self.mean + 3 * self.sd), self.mean - 3 * self.sd, lo))


@dataclass(frozen=True)
class ClusterSpec:
    berries: int = 60
    seed: int = 1
    diameter: Spread = Spread(0.027, 0.0015)              # m
    twig_length: Spread = Spread(0.028, 0.004)            # m, hinge to berry centre
    hinge_stiffness: Spread = Spread(5e-3, 1e-3)          # N·m/rad
    hinge_damping: Spread = Spread(5e-5, 1e-5)            # N·m·s/rad
    precompression: float = 0.0                           # m, largest overlap of two berries at rest
    rachis_length: float = 0.0                            # m; 0: sized from the berries (see _size)
    lateral_length: float = 0.0                           # m, the longest (top) lateral; 0: sized
    tilt: tuple[float, float] = (0.3, 1.3)                # rad, twig angle from vertical, uniform
    contact: dict[str, Any] = field(default_factory=lambda: {"law": "kelvin-voigt", "stiffness": 2000.0,
                                                             "restitution": 0.5})
    excitation: dict[str, Any] = field(default_factory=lambda: {"kind": "pick-and-place", "start": 0.1,
                                                                "moves": DEFAULT_MOVES})
    solver: dict[str, Any] = field(default_factory=lambda: {"rtol": 1e-6, "atol": 1e-9, "t_end": 2.5,
                                                            "output_interval": 1e-3})
    name: str = "cluster"


#: each drawn quantity: the Berry field it becomes, and that field's bound in its units (a diameter is two radii)
DRAWN = {"diameter": ("radius", 2.0), "twig_length": ("twig_length", 1.0), "hinge_stiffness": ("hinge_stiffness", 1.0),
         "hinge_damping": ("hinge_damping", 1.0)}
#: drawn quantities that must be positive: a berry has a size, a hinge holds its twig (a twig is kept above 1.2 r)
POSITIVE = ("diameter", "hinge_stiffness")


def _integer(x: Any) -> bool:
    """An integer, not a bool: 2.5 berries (range) or seed 1.5 (numpy) failed with a TypeError naming no field."""
    return isinstance(x, Integral) and not isinstance(x, bool)


def _check(spec: ClusterSpec) -> None:
    if not (_integer(spec.berries) and 1 <= spec.berries <= 1000):
        raise SceneError("cluster.berries", f"expected an integer in [1, 1000], got {spec.berries!r}")
    if not (_integer(spec.seed) and 0 <= spec.seed < 2**63):
        raise SceneError("cluster.seed", f"expected an integer in [0, 2**63), got {spec.seed!r}")
    for key, (name, per) in DRAWN.items():
        s, b = getattr(spec, key), bound(Berry, name)
        if not (s.mean > 0 and s.sd >= 0 and math.isfinite(s.mean) and math.isfinite(s.sd)):
            raise SceneError(f"cluster.{key}", f"expected a mean > 0 and a spread ≥ 0, got {s.mean!r} ± {s.sd!r}")
        # the draws span mean ± 3 sd: each must be a value the berry's field holds, never one changed in silence
        if s.mean + 3 * s.sd > b.hi * per or (key in POSITIVE and s.mean - 3 * s.sd <= 0):
            span = f"mean ± 3 sd within (0, {b.hi * per:g}]" if key in POSITIVE else f"mean + 3 sd ≤ {b.hi * per:g}"
            raise SceneError(f"cluster.{key}", f"expected {span} {b.unit} (the range drawn from), "
                             f"got {s.mean!r} ± {s.sd!r}")
    if not 0 <= spec.precompression <= 0.2 * spec.diameter.mean / 2:
        raise SceneError("cluster.precompression",
                         f"expected a number in [0, {0.1 * spec.diameter.mean:g}] m (0.2 of the mean radius), "
                         f"got {spec.precompression!r}")
    if spec.twig_length.mean <= spec.diameter.mean / 2:
        raise SceneError("cluster.twig_length", "the mean twig must be longer than the mean berry radius")
    lo, hi = spec.tilt
    if not 0 <= lo <= hi < math.pi / 2:
        raise SceneError("cluster.tilt", f"expected 0 ≤ low ≤ high < π/2 rad, got {spec.tilt!r}")


#: a twig's rest angles (Berry.rest_angles): the bound a rest tilt must stay within
REST_TILT = bound(Berry, "rest_angles")
PACKING = 0.2  # berry volume over the cone's volume: a loose cluster that random placement can fill


def _size(spec: ClusterSpec) -> tuple[float, float]:
    """Rachis and top-lateral lengths of a cone (height 2.5 × radius) that holds the berries at PACKING."""
    r = spec.diameter.mean / 2
    volume = spec.berries * 4.0 / 3.0 * math.pi * r**3 / PACKING
    radius = (volume / (math.pi / 3 * 2.5)) ** (1 / 3)
    lateral = spec.lateral_length or max(0.01, radius - spec.twig_length.mean - r)
    return spec.rachis_length or 2.5 * radius, lateral


def cluster_scene(spec: ClusterSpec, max_tries: int = 400) -> dict[str, Any]:
    """The scene document of a seeded random cluster (spherical berries); raises SceneError when
    the berries do not fit (then lengthen the rachis or allow more precompression)."""
    _check(spec)
    rng = np.random.default_rng(spec.seed)
    n = spec.berries
    length, lateral = _size(spec)
    n_lat = max(2, n // 3)
    laterals = []
    for k in range(n_lat):
        z = -length * (k + 0.5) / n_lat
        reach = lateral * (1.0 - 0.6 * k / n_lat)
        phi = k * GOLDEN_ANGLE
        tip = np.array([reach * math.cos(phi), reach * math.sin(phi), z - 0.3 * reach])
        laterals.append((np.array([0.0, 0.0, z]), tip))
    weights = np.array([np.linalg.norm(t - b) for b, t in laterals])
    weights /= weights.sum()
    placed: list[tuple[np.ndarray, float]] = []
    berries = []
    g = 9.81
    for i in range(n):
        r = spec.diameter.draw(rng) / 2
        l_twig = spec.twig_length.draw(rng, lo=1.2 * r)
        k_h = spec.hinge_stiffness.draw(rng)
        c_h = spec.hinge_damping.draw(rng, lo=0.0)
        for _ in range(max_tries):
            base, tip = laterals[rng.choice(n_lat, p=weights)]
            hinge = base + rng.uniform(0.2, 1.0) * (tip - base)
            heading = rng.uniform(-math.pi, math.pi)
            tilt = rng.uniform(*spec.tilt)
            u = np.array([math.cos(heading) * math.sin(tilt), math.sin(heading) * math.sin(tilt), -math.cos(tilt)])
            centre = hinge + l_twig * u
            if all(np.linalg.norm(centre - c) >= r + rc - min(spec.precompression, MAX_OVERLAP_FRACTION * min(r, rc))
                   for c, rc in placed):
                break
        else:
            raise SceneError("cluster.berries", f"placed only {i} of {n} berries without overlapping more than "
                             f"{spec.precompression * 1e3:g} mm; lengthen the rachis (rachis_length) or allow "
                             "more precompression")
        placed.append((centre, r))
        mass = DENSITY * 4.0 / 3.0 * math.pi * r**3
        # the twig frame's −y axis points along the twig's heading: (swing, tilt) = (0, tilt) is the pose
        azimuth = heading + math.pi / 2
        rest_tilt = tilt + mass * g * l_twig * math.sin(tilt) / k_h
        if rest_tilt > REST_TILT.hi:  # the hinge's spring must hold the twig's weight at its tilt
            need = mass * g * l_twig * math.sin(tilt) / (REST_TILT.hi - tilt)
            raise SceneError("cluster.hinge_stiffness", f"berry {i}'s hinge of {k_h:.3g} N·m/rad cannot hold its twig "
                             f"at its tilt of {tilt:.3g} rad (a rest angle of {rest_tilt:.4g} rad); it needs at least "
                             f"{need:.3g} N·m/rad: raise the mean or narrow the spread")
        berries.append({"name": f"b{i:03d}", "kind": "spherical", "mass": mass, "radius": r, "twig_length": l_twig,
                        "hinge": [float(x) for x in hinge], "azimuth": math.remainder(azimuth, 2 * math.pi),
                        "rest_angles": [0.0, rest_tilt], "hinge_stiffness": k_h, "hinge_damping": c_h,
                        "angle": [0.0, tilt], "angular_velocity": [0.0, 0.0]})
    return {"name": spec.name, "gravity": g, "berries": berries, **_settings(spec)}


@dataclass(frozen=True)
class RowSpec:
    berries: int = 5
    mass: float = 0.011
    radius: float = 0.0135
    twig_length: float = 0.03
    pitch: float = 0.027                  # m between neighbouring hinges; 2·radius: touching at rest
    twig_spread: float = 0.0              # relative sd of the twig lengths (0: identical berries)
    seed: int = 1
    hinge_stiffness: float = 1e-3
    hinge_damping: float = 2e-5
    angles: tuple[float, ...] = ()        # rad per berry; default: the first pulled back 30°
    contact: dict[str, Any] = field(default_factory=lambda: {"law": "kelvin-voigt", "stiffness": 2000.0,
                                                             "restitution": 0.5})
    excitation: dict[str, Any] = field(default_factory=lambda: {"kind": "none"})
    solver: dict[str, Any] = field(default_factory=lambda: {"rtol": 1e-8, "atol": 1e-10, "t_end": 2.0,
                                                            "output_interval": 1e-3})
    name: str = "row"


def row_scene(spec: RowSpec) -> dict[str, Any]:
    """A row of identical berries on one rod; neighbours are the contact pairs that can touch."""
    n = spec.berries
    if not (_integer(n) and 1 <= n <= 1000):
        raise SceneError("row.berries", f"expected an integer in [1, 1000], got {n!r}")
    # hanging, neighbours may overlap by MAX_OVERLAP_FRACTION of a radius (the loader's limit) and the row must keep
    # its hinges within hinge_x's ±10 m: beyond either the loader refused a field the caller never set
    span, lo = bound(Berry, "hinge_x").hi * 2, (2 - MAX_OVERLAP_FRACTION) * spec.radius
    if (n - 1) * lo > span:
        raise SceneError("row.berries", f"expected at most {int(span / lo) + 1} berries of radius {spec.radius:g} m "
                         f"(their hinges within ±{span / 2:g} m), got {n}")
    hi = min(1.0, span / max(n - 1, 1))
    if not (math.isfinite(spec.pitch) and lo <= spec.pitch <= hi):
        raise SceneError("row.pitch", f"expected a hinge spacing in [{lo:.4g}, {hi:.4g}] m for {n} berries of radius "
                         f"{spec.radius:g} m, got {spec.pitch!r}")
    angles = list(spec.angles) or [-math.radians(30.0)] + [0.0] * (n - 1)
    if len(angles) != n:
        raise SceneError("row.angles", f"expected {n} angles (one per berry), got {len(angles)}")
    rng = np.random.default_rng(spec.seed)
    lengths = [Spread(spec.twig_length, spec.twig_spread * spec.twig_length).draw(rng, lo=1.2 * spec.radius)
               for _ in range(n)]
    berries = [{"name": f"b{i:03d}", "mass": spec.mass, "radius": spec.radius, "twig_length": lengths[i],
                "hinge_x": (i - (n - 1) / 2) * spec.pitch, "hinge_stiffness": spec.hinge_stiffness,
                "hinge_damping": spec.hinge_damping, "angle": float(angles[i]), "angular_velocity": 0.0}
               for i in range(n)]
    return {"name": spec.name, "gravity": 9.81, "berries": berries, **_settings(spec)}


def _settings(spec: ClusterSpec | RowSpec) -> dict[str, Any]:
    """The spec's contact, excitation and solver tables, copied through: a caller editing a document's moves
    must not edit the spec's (or every later default cluster's: DEFAULT_MOVES)."""
    return copy.deepcopy({"contact": spec.contact, "excitation": spec.excitation, "solver": spec.solver})

