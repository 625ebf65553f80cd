"""Contact laws between berries and their calibration from a coefficient of restitution.

Each law gives the normal force F(δ, δ̇) for penetration δ > 0. The force is
split into an elastic part F_el(δ) (stored, returned on unloading) and the rest
(dissipated); docs/model.md explains why this split closes the energy ledger
even when the no-tension clamp cuts the force to zero while the berries still
overlap.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntEnum
from functools import lru_cache

from .bounds import Bound


class Law(IntEnum):
    """The contact laws of docs/model.md §3; the compiled core reads the same members as integers."""

    KELVIN_VOIGT = 0
    HERTZ = 1
    HUNT_CROSSLEY = 2

    @property
    def label(self) -> str:
        """The name scene files and interfaces use (``kelvin-voigt``)."""
        return self.name.lower().replace("_", "-")

    @classmethod
    def from_label(cls, label: str) -> Law:
        return cls[label.upper().replace("-", "_")]


LAWS = tuple(law.label for law in Law)

#: Floor for the Hunt–Crossley onset speed δ̇⁻ (m/s). Without it a pair that starts
#: pre-compressed, or touches at almost zero speed, would see unbounded damping.
HC_MIN_APPROACH_SPEED = 1e-3


@dataclass(frozen=True)
class ContactLaw:
    """A resolved law for one pair: every coefficient is a number, nothing is left to infer.

    stiffness: k in N/m (kelvin-voigt) or K in N/m^1.5 (hertz, hunt-crossley).
    damping:   c in N·s/m (kelvin-voigt) or the dimensionless χ (hunt-crossley); 0 for hertz.
    clamp:     True forbids a pulling force (F = max(0, ·)); False is the paper's literal law.
    restitution: the target e the damping was calibrated for, if it was.
    """

    kind: str
    stiffness: float
    damping: float
    clamp: bool = True
    restitution: float | None = None

    @property
    def law(self) -> Law:
        return Law.from_label(self.kind)

    def refusal(self) -> tuple[str, str] | None:
        """(field, why) for a coefficient outside its law's bound (LAW_BOUNDS), or None."""
        if self.kind not in LAWS:
            return ("law", f"expected one of {', '.join(map(repr, LAWS))}, got {self.kind!r}")
        for name, b in LAW_BOUNDS[self.law].items():
            x = getattr(self, name)
            if not b.holds(float(x)):
                return (name, f"expected {b.allowed} for the {self.kind} law, got {x!r}")
        if self.restitution is not None and not RESTITUTION.holds(self.restitution):
            return ("restitution", f"expected {RESTITUTION.allowed}, got {self.restitution!r}")
        why = refuses_tension(self.kind, self.clamp)
        return ("allow_tension", why) if why else None


def refuses_tension(kind: str, clamp: bool) -> str | None:
    """Why a law cannot pull (clamp False), or None."""
    return None if clamp or kind == "kelvin-voigt" else "only the kelvin-voigt law has a pulling branch to allow"


#: each law's coefficients: stiffness k N/m or K N/m^1.5, damping c N·s/m or the dimensionless χ (hertz: none)
LAW_BOUNDS = {
    Law.KELVIN_VOIGT: {"stiffness": Bound(0.0, 1e9, lo_open=True, unit="N/m"),
                       "damping": Bound(0.0, 1e6, unit="N·s/m")},
    Law.HERTZ: {"stiffness": Bound(0.0, 1e12, lo_open=True, unit="N/m^1.5"),
                "damping": Bound(0.0, 0.0)},
    Law.HUNT_CROSSLEY: {"stiffness": Bound(0.0, 1e12, lo_open=True, unit="N/m^1.5"),
                        "damping": Bound(0.0, 1e3, unit="(χ, dimensionless)")},
}
#: the coefficient of restitution a law's damping is calibrated for
RESTITUTION = Bound(0.0, 1.0, lo_open=True)
#: E* of the Hertz laws, from which K = 4/3 E* √R*
EFFECTIVE_MODULUS = Bound(0.0, 1e12, lo_open=True, unit="Pa")


def kelvin_voigt_damping_ratio(e: float) -> float:
    """ζ of the linear spring–dashpot whose free (tension-allowed) impact returns e."""
    if e >= 1.0:
        return 0.0
    le = math.log(e)
    return -le / math.sqrt(math.pi**2 + le**2)


def kelvin_voigt_damping(e: float, stiffness: float, effective_mass: float) -> float:
    """c = 2 ζ(e) √(k m*). Under the no-tension clamp the realised e comes out higher
    (0.5 → about 0.55, 0.3 → about 0.40): the dashpot would pull during restitution and the
    clamp forbids it (Schwager & Pöschel 2007). tests/test_restitution.py measures it."""
    return 2.0 * kelvin_voigt_damping_ratio(e) * math.sqrt(stiffness * effective_mass)


def hertz_stiffness(effective_modulus: float, r_i: float, r_j: float) -> float:
    """K = 4/3 E* √R* for two spheres, R* = r_i r_j / (r_i + r_j); a sphere on a plane has r_j = ∞, R* = r_i."""
    r_eff = r_i if math.isinf(r_j) else r_i * r_j / (r_i + r_j)
    return 4.0 / 3.0 * effective_modulus * math.sqrt(r_eff)


def hunt_crossley_restitution(chi: float) -> float:
    """Realised e of a 1-D impact under F = K δ^1.5 (1 + χ δ̇/δ̇⁻), clamped at F ≥ 0.

    Scaled to K/m* = 1 and δ̇⁻ = 1 the answer depends on χ alone, which is why one
    root find per target e suffices for every mass, stiffness and speed.
    """
    from scipy.integrate import solve_ivp

    def rhs(_t, s):
        x, v = s
        f = max(x, 0.0) ** 1.5 * (1.0 + chi * v)
        return (v, -max(f, 0.0))

    def separated(_t, s):
        return s[0]

    def unloaded(_t, s):
        return 1.0 + chi * s[1]

    separated.terminal = unloaded.terminal = True
    separated.direction = unloaded.direction = -1
    sol = solve_ivp(rhs, (0.0, 100.0), (0.0, 1.0), method="DOP853", rtol=1e-12, atol=1e-14,
                    events=(separated, unloaded))
    # After an unloading event the berries fly apart at constant speed: that speed is e.
    return -float(sol.y[1, -1])


@lru_cache(maxsize=256)
def hunt_crossley_chi(e: float) -> float:
    """χ whose single impact returns the target e (closed forms miss by up to 0.3 in e)."""
    from scipy.optimize import brentq

    if e >= 1.0:
        return 0.0
    hi = 1.0
    while hunt_crossley_restitution(hi) > e:
        hi *= 4.0
    return brentq(lambda c: hunt_crossley_restitution(c) - e, 0.0, hi, xtol=1e-12, rtol=1e-12)
