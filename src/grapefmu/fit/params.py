"""The scene parameters that `fit` estimates and `risk` draws, each with the transform that keeps it in range.

A parameter is a scene key in the sweep's syntax (docs/sweeps.md): `berries[*].hinge_stiffness` is one value
shared by every twig, `berries[1].hinge_stiffness` one twig's own. Positive parameters are estimated and drawn
as u = log p (a step in u is a relative change, p stays positive, and the standard error of u is the relative
error of p); the restitution e in (0, 1) as u = logit e. Fit and risk share this one table, so a covariance the
fit reports in u is the one risk samples from.
"""
from __future__ import annotations

import copy
import math
import re
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import SceneError
from ..sweep.spec import apply, same_value, values_at

#: the last part of a key (its table, its name) -> (transform, unit); the table's list may be indexed. The unit of
#: the contact law's coefficients depends on the law (UNITS).
FITTABLE: dict[tuple[str, str], tuple[str, str]] = {
    ("berries", "hinge_stiffness"): ("log", "N·m/rad"),
    ("berries", "hinge_damping"): ("log", "N·m·s/rad"),
    ("contact", "stiffness"): ("log", "N/m"),
    ("contact", "effective_modulus"): ("log", "Pa"),
    ("contact", "damping"): ("log", "N·s/m"),
    ("contact", "restitution"): ("logit", ""),
    ("coupling", "stiffness"): ("log", "N/m"),
    ("coupling", "damping"): ("log", "N·s/m"),
}
#: what risk may also draw: the damage thresholds, which no swing test measures (docs/parameters.md's ranges)
DRAWN_ONLY: dict[tuple[str, str], tuple[str, str]] = {
    ("thresholds", "bruise_force"): ("log", "N"),
    ("thresholds", "bruise_energy"): ("log", "J"),
    ("thresholds", "detachment_force"): ("log", "N"),
}
#: the contact coefficients' units under the laws other than kelvin-voigt
UNITS = {"stiffness": "N/m^1.5", "damping": "χ, dimensionless"}
KEY = re.compile(r"(berries)\[(\d{1,9}|\*)\]\.(\w+)|(contact|coupling|thresholds)\.(\w+)")


def allowed(table: dict[tuple[str, str], tuple[str, str]] = FITTABLE) -> str:
    return ", ".join(f"{t}[*].{n}" if t == "berries" else f"{t}.{n}" for t, n in table)


@dataclass(frozen=True)
class Parameter:
    """One scene key as an unknown: its transform (`log` or `logit`) and unit."""

    key: str
    transform: str
    unit: str

    def to_u(self, p: float | np.ndarray) -> Any:
        p = np.asarray(p, dtype=float)
        return np.log(p) if self.transform == "log" else np.log(p / (1.0 - p))

    def to_p(self, u: float | np.ndarray) -> Any:
        u = np.asarray(u, dtype=float)
        return np.exp(u) if self.transform == "log" else 1.0 / (1.0 + np.exp(-u))

    def dp_du(self, u: float) -> float:
        """How p changes with u: the delta method's factor from a standard error in u to one in p."""
        p = float(self.to_p(u))
        return p if self.transform == "log" else p * (1.0 - p)

    def start(self, doc: dict[str, Any], where: str = "--param") -> float:
        """The scene's value as the starting point, in u: the mean of u over the elements a [*] key reaches."""
        values = values_at(doc, self.key, where)
        for v in values:
            ok = isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and v > 0 and (
                self.transform == "log" or v < 1)
            if not ok:
                need = "a number in (0, 1)" if self.transform == "logit" else "a positive number"
                raise SceneError(self.key, f"the scene gives {v!r}; {where} needs {need} to start from "
                                           f"(it works with {self.transform} of the value)")
        return float(np.mean(self.to_u(values)))

    def set(self, doc: dict[str, Any], value: float) -> None:
        apply(doc, self.key, float(value))


def parameter(key: str, doc: dict[str, Any], where: str = "--param", drawn: bool = False) -> Parameter:
    """A key named on the command line as a Parameter; refused unless it is fittable (or, `drawn`, one risk may
    draw) and in the scene."""
    m = KEY.fullmatch(key)
    table, name = (m[1], m[3]) if m and m[1] else (m[4], m[5]) if m else (None, None)
    known = {**FITTABLE, **DRAWN_ONLY} if drawn else FITTABLE
    if (table, name) not in known:
        raise SceneError(where, f"{key!r} is not a parameter {'risk may draw' if drawn else 'fit can estimate'}; "
                                f"allowed: {allowed(known)} (berries[i]. for one twig)")
    transform, unit = known[(table, name)]
    law = doc.get("contact", {}).get("law", "kelvin-voigt") if isinstance(doc.get("contact"), dict) else ""
    if table == "contact" and name in UNITS and law != "kelvin-voigt":
        unit = UNITS[name]
    p = Parameter(key, transform, unit)
    p.start(doc, where)  # exists in the scene with a usable value
    return p


def parameters(keys: list[str], doc: dict[str, Any], where: str = "--param") -> list[Parameter]:
    """Keys as Parameters, none of them reaching a value another one reaches (a twig fitted twice)."""
    if not keys:
        raise SceneError(where, f"name at least one parameter to estimate; allowed: {allowed()}")
    out = [parameter(k, doc, where) for k in keys]
    same_value(doc, [p.key for p in out], where)
    return out


def scene_with(doc: dict[str, Any], params: list[Parameter], u: np.ndarray) -> dict[str, Any]:
    """A copy of the scene document with each parameter set from its u."""
    out = copy.deepcopy(doc)
    for p, x in zip(params, u):
        p.set(out, float(p.to_p(x)))
    return out
